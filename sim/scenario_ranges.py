"""Values of a scenario file written as ranges, drawn anew for every seed.

Any number in a scenario may be written as a range:
  speed = {uniform = [0.5, 1.6]}          a float drawn uniformly in [lo, hi]
  start_delay = {choice = [0.0, 2.0, 4.0]}  one of the listed values (numbers, strings or booleans)
or follow another value of the same draw, times a factor plus an offset (both optional):
  x = {same_as = "obstacles.0.center.0", times = 1.0, plus = 0.7}
Draws follow the file's order from a generator seeded by the episode's seed (``seeded_pick``), so a
seed always gives the same scenario. A draw whose geometry fails the checks (a person starting inside
an obstacle, ...) is drawn again (sim.scenario), up to MAX_DRAWS times.

Everything here works on the file's tables as read (dicts and lists), before they become a scenario.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from sim.scenario_bounds import MAX_CHOICES, ScenarioError, finite_number, short_repr

_RANGE_KINDS = ("uniform", "choice", "same_as")
MAX_DRAWS = 100  # draws of one seed tried before its scenario is refused


def _range_of(v: Any) -> str | None:
    if not isinstance(v, dict) or not v:
        return None
    if "same_as" in v and set(v) <= {"same_as", "times", "plus"}:
        return "same_as"
    return next(iter(v)) if len(v) == 1 and next(iter(v)) in ("uniform", "choice") else None


def _lookup(tables: Any, path: str) -> Any:
    node = tables
    for part in path.split("."):
        if isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        elif isinstance(node, dict) and part in node:
            node = node[part]
        else:
            return None
    return node


def _follow(tables: Any, drawn: Any, source: str, key: str = "", fresh: set | None = None) -> Any:
    """Replace every {same_as = ...} by the value it names in ``drawn``, times and plus applied. fresh: the ids
    of the tables and lists a draw made anew (draw); any other holds no range and is returned as it is."""
    if _range_of(tables) == "same_as":
        v = _lookup(drawn, tables["same_as"])
        if not finite_number(v):
            raise ScenarioError(f"{source}: {key}: same_as {short_repr(tables['same_as'])} does not name a number of the "
                                f"scenario (got {short_repr(v)})")
        return v * tables.get("times", 1.0) + tables.get("plus", 0.0)
    if fresh is not None and id(tables) not in fresh:
        return tables
    if isinstance(tables, dict):
        return {k: _follow(x, drawn, source, f"{key}.{k}" if key else k, fresh) for k, x in tables.items()}
    if isinstance(tables, list):
        return [_follow(x, drawn, source, f"{key}[{i}]", fresh) for i, x in enumerate(tables)]
    return tables


def has_ranges(v: Any) -> bool:
    """Whether some value of the tables is a range."""
    if _range_of(v):
        return True
    if isinstance(v, dict):
        return any(has_ranges(x) for x in v.values())
    if isinstance(v, list):
        return any(has_ranges(x) for x in v)
    return False


def check_ranges(v: Any, source: str, key: str = "") -> None:
    """Every range table well formed: uniform = [lo, hi] finite with lo <= hi; choice = a non-empty list."""
    kind = _range_of(v)
    if kind == "uniform":
        r = v[kind]
        if (not isinstance(r, list) or len(r) != 2
                or any(not finite_number(x) for x in r)):
            raise ScenarioError(f"{source}: {key}: expected {{uniform = [lo, hi]}} with two finite numbers, got {short_repr(r)}")
        if r[0] > r[1]:
            raise ScenarioError(f"{source}: {key}: uniform range [{r[0]}, {r[1]}] has lo > hi")
    elif kind == "choice":
        r = v[kind]
        if not isinstance(r, list) or not r or any(isinstance(x, (dict, list)) for x in r):
            raise ScenarioError(f"{source}: {key}: expected {{choice = [a, b, ...]}} with at least one plain value, "
                                f"got {short_repr(r)}")
        if len(r) > MAX_CHOICES:
            raise ScenarioError(f"{source}: {key}: at most {MAX_CHOICES} values to choose from, got {len(r)}")
    elif kind == "same_as":
        if not isinstance(v["same_as"], str):
            raise ScenarioError(f"{source}: {key}: same_as must name a value, as \"obstacles.0.center.0\"")
        for k in ("times", "plus"):
            x = v.get(k, 0.0)
            if not finite_number(x):
                raise ScenarioError(f"{source}: {key}.{k}: expected a finite number, got {short_repr(x)}")
    elif isinstance(v, dict):
        for k, x in v.items():
            check_ranges(x, source, f"{key}.{k}" if key else k)
    elif isinstance(v, list):
        for i, x in enumerate(v):
            check_ranges(x, source, f"{key}[{i}]")


def longest_choice(v: Any) -> int:
    """The most values of one {choice = [...]} in the tables (0 without one)."""
    if _range_of(v) == "choice":
        return len(v["choice"])
    if isinstance(v, dict):
        return max((longest_choice(x) for x in v.values()), default=0)
    if isinstance(v, list):
        return max((longest_choice(x) for x in v), default=0)
    return 0


def ranged_nodes(v: Any, out: set | None = None) -> set:
    """The ids of the tables and lists of ``v`` that are a range or hold one somewhere (for draw)."""
    out = set() if out is None else out
    if _range_of(v):
        out.add(id(v))
        return out
    if isinstance(v, (dict, list)):
        for x in (v.values() if isinstance(v, dict) else v):
            ranged_nodes(x, out)
            if id(x) in out:
                out.add(id(v))
    return out


def draw(v: Any, pick, source: str = "", ranged: set | None = None) -> Any:
    """The tables with every range replaced by pick(kind, values), then every same_as by what it names.
    Parts that hold no range are not copied: the result shares them with ``v`` (read them, do not change
    them). ranged: ranged_nodes(v), when the caller draws ``v`` many times."""
    ranged = ranged_nodes(v) if ranged is None else ranged
    fresh: set = set()
    drawn = _draw(v, pick, ranged, fresh)
    return _follow(drawn, drawn, source, fresh=fresh)


def _draw(v: Any, pick, ranged: set, fresh: set) -> Any:
    if id(v) not in ranged:
        return v
    kind = _range_of(v)
    if kind == "same_as":
        return v  # resolved once everything is drawn
    if kind:
        return pick(kind, v[kind])
    out = ({k: _draw(x, pick, ranged, fresh) for k, x in v.items()} if isinstance(v, dict)
           else [_draw(x, pick, ranged, fresh) for x in v])
    fresh.add(id(out))
    return out


def extreme_pick(i: int):
    """A ``draw`` pick that takes end ``i % 2`` of every uniform range and value ``i`` (or the last) of every
    choice: the i-th of the draws that together reach every value a range can take."""
    return lambda kind, r: r[i % 2] if kind == "uniform" else r[min(i, len(r) - 1)]


def seeded_pick(seed: int):
    """A ``draw`` pick drawing from a generator seeded by ``seed``: successive draws with it go on in one
    stream."""
    rng = np.random.default_rng([int(seed), 0x5CE4A])

    def pick(kind, r):
        if kind == "uniform":
            if r[0] < r[1]:
                return float(rng.uniform(r[0], r[1]))
            rng.random()  # lo == hi (numpy refuses uniform(0.0, -0.0)): the same draws follow as from uniform
            return float(r[0])
        return r[int(rng.integers(len(r)))]

    return pick
