"""Property tests of two boundaries: what a plug-in returns (experiments.guards) and what a user configures
(experiments.config). Arbitrary values give a valid result or the boundary's own clean error, never another
exception. Derandomized: the same examples on every run."""
from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
from hypothesis import HealthCheck, example, given, settings, strategies as st

from dodt.protocol import PerceptionOutput, TrackReport
from experiments.config import ConfigError
from experiments.guards import BadOutput, PlannerGuard, check_output, check_trajectory
from experiments.registry import builtin_sections, settings_for
from planner.types import ObstaclePrediction, PlannerInput, Trajectory

_SETTINGS = settings(derandomize=True, max_examples=150, deadline=None,
                     suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

# values a careless plug-in may put anywhere: numbers of every kind, text, None, containers, arrays
_SCALARS = st.one_of(st.none(), st.booleans(), st.integers(-2**70, 2**70), st.floats(allow_nan=True),
                     st.text(max_size=5), st.binary(max_size=5))
_ARRAYS = st.builds(lambda shape, fill: np.full(shape, fill),
                    st.lists(st.integers(0, 4), max_size=3).map(tuple),
                    st.floats(allow_nan=True, allow_infinity=True))
_VALUES = st.recursive(st.one_of(_SCALARS, _ARRAYS),
                       lambda inner: st.one_of(st.lists(inner, max_size=4), st.tuples(inner, inner),
                                               st.dictionaries(st.text(max_size=4), inner, max_size=3)),
                       max_leaves=8)
_VECTORS = st.one_of(_VALUES, st.lists(st.floats(allow_nan=True), min_size=3, max_size=3).map(np.array))


_OBSTACLES = st.builds(
    lambda oid, center, size, velocity, acc, std: ObstaclePrediction(id=oid, center=center, size=size,
                                                                     velocity=velocity, acceleration=acc,
                                                                     position_std=std),
    st.one_of(st.integers(-2**70, 2**70), _SCALARS), _VECTORS, _VECTORS, _VECTORS, _VECTORS, _SCALARS)
_TRACKS = st.one_of(
    _VALUES,
    st.builds(lambda oid, c, s, v, dyn, age: TrackReport(id=oid, center=c, size=s, velocity=v, dynamic=dyn, age=age),
              st.one_of(st.integers(-2**70, 2**70), _SCALARS), _VECTORS, _VECTORS, _VECTORS, _SCALARS, _SCALARS),
    st.dictionaries(st.sampled_from(["id", "center", "size", "velocity", "dynamic", "age", "coasting"]), _VALUES,
                    max_size=7))


@_SETTINGS
@given(st.one_of(_VALUES, st.builds(
    lambda stamp, obstacles, boxes, tracks, timings, skipped: PerceptionOutput(
        stamp=stamp, obstacles=obstacles, clear_boxes=boxes, tracks=tracks, timings_ms=timings, skipped=skipped),
    _SCALARS, st.one_of(_VALUES, st.lists(st.one_of(_OBSTACLES, _VALUES), max_size=3).map(tuple)),
    st.one_of(_VALUES, st.lists(st.tuples(_VECTORS, _VECTORS), max_size=2).map(tuple)),
    st.one_of(_VALUES, st.lists(_TRACKS, max_size=3).map(tuple)), _VALUES, _SCALARS)))
def test_any_perception_output_is_accepted_whole_or_refused_naming_a_field(out):
    try:
        good = check_output(out)
    except BadOutput as e:
        assert str(e) and "\n" not in str(e)
        return
    assert isinstance(good, PerceptionOutput) and math.isfinite(good.stamp)
    for o in good.obstacles:
        assert np.all(np.isfinite(np.asarray(o.center, dtype=float)))
    for tr in good.tracks:
        assert isinstance(tr, TrackReport)
        json.dumps(tr.to_json(), allow_nan=False)  # what the log writes: a track accepted is writable


_FINITE3 = st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=3, max_size=3).map(np.array)


@_SETTINGS
@given(st.builds(lambda oid, c, s, v, dyn, co, acc, age, person, fv: TrackReport(
    id=oid, center=c, size=s, velocity=v, dynamic=dyn, coasting=co, acceleration=acc, age=age, is_person=person,
    filter_velocity=fv), st.integers(-2**63, 2**63 - 1), _FINITE3, _FINITE3, _FINITE3, st.booleans(), st.booleans(),
    st.one_of(st.none(), _FINITE3), st.one_of(st.none(), st.floats(allow_nan=False, allow_infinity=False)),
    st.one_of(st.none(), st.booleans()), st.one_of(st.none(), _FINITE3)))
def test_every_well_formed_track_is_accepted_and_writable(tr):
    """The guard does not serialise a plain TrackReport to check it: its checked fields must make it
    writable, at any magnitude."""
    good = check_output(PerceptionOutput(stamp=0.0, obstacles=(), clear_boxes=(), tracks=(tr,)))
    json.dumps(good.tracks[0].to_json(), allow_nan=False)


_TRAJECTORIES = st.builds(
    lambda t0, dt, pos, vel, acc, status, ms, yaw: Trajectory(t0=t0, dt=dt, positions=pos, velocities=vel,
                                                              accelerations=acc, status=status, solve_ms=ms, yaw=yaw),
    _SCALARS, _SCALARS, _VECTORS, _VECTORS, st.one_of(_VECTORS, st.integers(0, 3).map(lambda n: np.zeros((n, 3)))),
    _SCALARS, _SCALARS, _SCALARS)


@_SETTINGS
@given(st.one_of(_VALUES, _TRAJECTORIES))
def test_any_plan_is_accepted_whole_or_refused_and_the_guard_always_flies(traj):
    try:
        good = check_trajectory(traj)
    except BadOutput as e:
        assert str(e) and "\n" not in str(e)
    else:
        assert good is traj and good.dt > 0 and len(good.positions) == len(good.accelerations) + 1

    class Planner:
        def plan(self, inp):
            return traj

    guard = PlannerGuard(Planner(), "hostile")
    inp = PlannerInput(stamp=1.0, position=np.array([0.5, 0.0, 1.2]), velocity=np.array([1.0, 0.0, 0.0]),
                       acceleration=np.zeros(3), goal=np.array([15.5, 0.0, 1.2]), obstacles=(), yaw=0.0)
    flown = guard.plan(inp)
    assert check_trajectory(flown) is flown  # whatever the plug-in returned, the loop gets a flyable plan


# ------------------------------------------------------------------------------------------- configuration

_SECTIONS = builtin_sections()


def _leaves(obj, prefix=""):
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if dataclasses.is_dataclass(v):
            yield from _leaves(v, f"{prefix}{f.name}.")
        else:
            yield f"{prefix}{f.name}"


KEYS = sorted(f"{s}.{k}" for s, cfg in _SECTIONS.items() for k in _leaves(cfg))
_WORDS = st.text(alphabet=st.characters(codec="utf-8", exclude_categories=("Cs",)), max_size=12)
_LITERALS = st.one_of(_WORDS, st.sampled_from(["nan", "inf", "-inf", "1e400", "-1", "0", "1e-9", "1e9", "true",
                                                "none", "[]", "[1, 2]", "[nan, 1.0]", '"x"', "{a = 1}", "[[1]]",
                                                "1" * 5000, "2.5", "[0.5, 1.5]"]))


@_SETTINGS
@given(st.lists(st.tuples(st.one_of(st.sampled_from(KEYS), _WORDS), _LITERALS).map(lambda kv: f"{kv[0]}={kv[1]}"),
                max_size=4))
@example(["0\n0=0"])
@example(["navigator.mpc.horizon=1e8", "map.size=[1e9, 1e9, 1e9]", "episode.seen_band=[nan, 1.0]"])
def test_any_set_options_give_settings_or_one_config_error(sets):
    try:
        s = settings_for(sets=sets)
    except ConfigError as e:
        assert str(e) and "\n" not in str(e)
        return
    for name in s.names():
        s.apply(name, _SECTIONS[name])  # what was accepted applies again, cleanly


_TOML_VALUES = st.recursive(
    st.one_of(st.booleans(), st.integers(-2**63, 2**63 - 1), st.floats(allow_nan=True), _WORDS),
    lambda inner: st.one_of(st.lists(inner, max_size=3), st.dictionaries(_WORDS, inner, max_size=3)), max_leaves=6)


def _toml(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if v != v else ("inf" if v == math.inf else "-inf" if v == -math.inf else repr(v))
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return '"' + v.encode("unicode_escape").decode("ascii").replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    return "{" + ", ".join(f"{_toml(k)} = {_toml(x)}" for k, x in v.items()) + "}"


@settings(derandomize=True, max_examples=100, deadline=None)
@given(st.dictionaries(st.sampled_from(sorted(_SECTIONS) + ["bogus"]),
                       st.dictionaries(st.one_of(st.sampled_from([k.split(".", 1)[1] for k in KEYS]), _WORDS),
                                       _TOML_VALUES, max_size=3), max_size=3))
@example({"navigator": {"a\nb": 1}})
@example({"x\ny": {"z": 1}})
def test_any_config_file_gives_settings_or_one_config_error(tmp_path_factory, tables):
    lines = []
    for section, items in tables.items():
        lines.append(f"[{section}]")
        lines += [f"{_toml(k)} = {_toml(v)}" for k, v in items.items()]
    path = tmp_path_factory.mktemp("cfg") / "c.toml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    try:
        settings_for(config_file=path)
    except ConfigError as e:
        assert str(e) and "\n" not in str(e)
