"""Bounded work when a scenario is read: keys too deep for the TOML parser refused before it runs, draws that
copy and read only the parts holding ranges, and a bound on the geometry checks of repeated draws."""
from __future__ import annotations

import copy
import math
import random
import re
import tomllib

import numpy as np
import pytest

from sim import scenario_toml
from sim.scenario import MAX_CHECK_POINTS, ScenarioError, load_scenario, parse_scenario, shipped_scenarios
from sim.scenario_checks import _sample_segments
from sim.scenario_ranges import _range_of, draw, ranged_nodes, seeded_pick
from sim.scenario_toml import read_toml, scenario_path
from sim.toml_keys import longest_key

CORRIDOR = '[corridor]\nlength = 200.0\nwidth = 4.0\nheight = 3.0\n'
DRONE = '[drone]\nstart = [0.5, 0.0, 1.2]\ngoal = [15.5, 0.0, 1.2]\n'


# ------------------------------------------------------------------------------------------- deep keys

@pytest.mark.parametrize("text, parts", [
    ("a = 1", 1), ("a.b.c = 1.5", 3), ('[x.y]\nz = [1.5, 2.5]', 2), ('a."b.c".d = "e.f.g.h"', 3),
    ('x = """a.b.c.d\n.e.f"""  # g.h.i', 1), ("a . b . c = 1", 3), ("'a.b'.c = '''x.y.z'''", 2),
    ("d = 1979-05-27T07:32:00.999", 2), ("p = {q.r.s = 1}", 3), ('"x y"."x y"."x y" = 1', 3),
    ('x = """a\\"""b"""\na.a.a.a = 1', 4),  # an escaped quote does not end the string
    ('p = {a = """x"""", b.b.b.b = 1}', 4),  # nor do the quotes before the closing three
    ("x = '''a.b''''\nc.d.e = 1", 3),
])
def test_the_longest_key_is_counted_outside_strings_and_comments(text, parts):
    tomllib.loads(text)  # each one valid TOML
    assert longest_key(text) == parts


_PATHOLOGICAL = {  # name: (text, parts): long runs of what a string, a word or a key is made of
    "quotes": ('"' * 200_000, 1), "apostrophes": ("'" * 200_000, 1), "one word": ("a" * 200_000, 1),
    "dots": ("." * 200_000, 1), "dotted": ("a." * 100_000 + "a", 100_001),
    "unterminated string": ('"""' + "a." * 100_000, 1), "unterminated lines": ('"\n' * 100_000, 1),
    "backslashes": ('"' + "\\" * 200_000, 1), "escaped closers": ('"""\\"""' * 30_000, 1), "tabs": ("a\t" * 100_000, 1),
}


@pytest.mark.parametrize("name", sorted(_PATHOLOGICAL))
def test_long_runs_are_counted_right(name):
    text, parts = _PATHOLOGICAL[name]
    assert longest_key(text) == parts


@pytest.mark.parametrize("size", [40_000, 100_000])
def test_a_scenario_of_one_deep_dotted_key_is_refused_before_parsing(size, monkeypatch):
    text = 'name = "x"\n' + ".".join(["a"] * (size // 2)) + " = 1\n"

    def never(*a, **k):
        raise AssertionError("the TOML parser was reached")

    monkeypatch.setattr(scenario_toml.tomllib, "loads", never)
    with pytest.raises(ScenarioError, match=r"s\.toml: a key of \d+ dotted parts; a scenario's keys have at most 16"):
        read_toml(text, "s.toml")


def test_every_shipped_scenario_has_shallow_keys():
    for name in shipped_scenarios():
        assert longest_key(scenario_path(name).read_text()) <= 4, name


# ------------------------------------------------------------------------------------------- draws

def _draw_by_copying(v, pick):
    """draw as it was: every table copied, every range replaced in the file's order (same_as left out)."""
    kind = _range_of(v)
    if kind in ("uniform", "choice"):
        return pick(kind, v[kind])
    if isinstance(v, dict):
        return {k: _draw_by_copying(x, pick) for k, x in v.items()}
    if isinstance(v, list):
        return [_draw_by_copying(x, pick) for x in v]
    return v


@pytest.mark.parametrize("name", [n for n in shipped_scenarios()
                                  if not tomllib.loads(scenario_path(n).read_text()).get("people") is None][:6])
def test_a_draw_copies_only_the_ranges_and_draws_the_same_values(name):
    data = tomllib.loads(scenario_path(name).read_text())
    if "same_as" in scenario_path(name).read_text():
        pytest.skip("same_as resolved by draw only")
    before = copy.deepcopy(data)
    ranged = ranged_nodes(data)
    for seed in range(3):
        a, b = draw(data, seeded_pick(seed), "s", ranged), _draw_by_copying(data, seeded_pick(seed))
        assert a == b
        for key, part in data.items():
            if id(part) not in ranged:
                assert a[key] is part  # shared, not copied
    assert data == before  # the tables themselves unchanged


def _walkers(with_obstacles: bool, last_only: bool = False) -> str:
    """100 people of 100 waypoints each in a 200 m corridor; with_obstacles: 4 obstacles at ranged places
    at x 3-13 that some path walks through (last_only: only the last person's)."""
    rng = random.Random(0)
    obstacles = ""
    if with_obstacles:
        obstacles = ('[[obstacles]]\nkind = "box"\ncenter = [{uniform = [3.5, 5.0]}, {uniform = [0.8, 1.5]}]\n'
                     'size = [0.8, 0.8, 1.6]\n'
                     '[[obstacles]]\nkind = "pillar"\ncenter = [{uniform = [6.0, 7.5]}, {uniform = [-1.5, -0.9]}]\n'
                     'radius = 0.25\nheight = 3.0\n')
    people = []
    for i in range(100):
        x0 = 20.0 if last_only else 1.0
        if last_only and i == 99:
            wps = "[2.0, 1.1], [14.0, 1.1]"
        else:
            wps = ", ".join(f"[{rng.uniform(x0, 199):.3f}, {rng.uniform(-1.5, 1.5):.3f}]" for _ in range(100))
        people.append(f'[[people]]\nbehaviour = "waypoint_loop"\nspeed = 1.0\nwaypoints = [{wps}]\n')
    return 'name = "walkers"\nduration = 10.0\n' + CORRIDOR + obstacles + "\n".join(people) + DRONE


def test_a_hundred_walkers_of_a_hundred_waypoints_pass():
    sc = parse_scenario(_walkers(False), "w.toml")
    assert len(sc.people) == 100 and all(len(p.waypoints) == 100 for p in sc.people)


@pytest.mark.parametrize("last_only", [False, True])
def test_redraws_of_long_paths_stop_at_the_bound_of_checked_points(last_only):
    """Every draw fails (a path through an obstacle): draws stop once the checks have sampled
    MAX_CHECK_POINTS path points, with the last draw's error and how many were tried."""
    with pytest.raises(ScenarioError) as e:
        parse_scenario(_walkers(True, last_only), "w.toml")
    msg = str(e.value)
    assert msg.startswith("w.toml: people[") and "walks through obstacles[" in msg
    tries, points = (int(x) for x in
                     re.search(r"in (\d+) tr(?:y|ies), all that .* \((\d+) path points", msg).groups())
    assert 1 <= tries < 100 and points > MAX_CHECK_POINTS
    assert (tries == 1) == last_only  # every draw samples all 99 long paths before the last one's


def test_path_samples_are_those_of_linspace():
    rng = np.random.default_rng(0)
    for i in range(50):
        p = rng.uniform(-20, 20, (int(rng.integers(2, 20)), 2))
        if i % 5 == 0:
            p[1] = p[0]  # a repeated point: one segment of length 0
        for closed in (False, True):
            q = np.vstack([p, p[:1]]) if closed else p
            ref = [q[:1]] + [a + np.linspace(0, 1, max(2, int(math.ceil(np.linalg.norm(b - a) / 0.05)) + 1))[1:, None]
                             * (b - a) for a, b in zip(q[:-1], q[1:])]
            assert np.array_equal(_sample_segments(p, closed), np.vstack(ref))


def test_points_read_at_once_are_those_read_one_by_one():
    s = scenario_toml._Section({"w": [[1, 2.5], [3, -4.0]]}, "p", "s.toml")
    assert s.points("w", 2) == ((1.0, 2.5), (3.0, -4.0))
    for bad, why in (([[1, True]], "expected 2 finite numbers"), ([[1, 2e3]], "must lie within"),
                     ([[1, 10**400]], "expected 2 finite numbers"), ([[1, 2, 3]], "expected 2 finite numbers")):
        with pytest.raises(ScenarioError, match=why):
            scenario_toml._Section({"w": bad}, "p", "s.toml").points("w", 2)


def test_shipped_scenarios_still_load():
    for name in shipped_scenarios():
        assert load_scenario(name).name
