"""Scenario files: every validation error names the file, the key path and the reason.

Each error test starts from one valid base scenario (``BASE``) and applies one change, given
as ``{"key.path": value}`` (``DELETE`` removes the key), so that exactly one check fails.
"""
from __future__ import annotations

import copy
import json
import math
import re
from typing import Any

import numpy as np
import pytest

from conftest import make_scenario
from sim.scenario import (
    Scenario,
    ScenarioError,
    circle_waypoints,
    load_scenario,
    parse_scenario,
    shipped_scenarios,
)

SOURCE = "s.toml"
DELETE = object()  # marker: remove the key instead of setting it
INF, NAN = math.inf, math.nan

# A valid scenario that exercises every section: a box and a pillar, one person of each
# path family (waypoints, random walk, circle), explicit drone / camera / noise / rates.
BASE: dict[str, Any] = {
    "name": "base",
    "seed": 0,
    "duration": 10.0,
    "corridor": {"length": 15.0, "width": 4.0, "height": 3.0},
    "obstacles": [
        {"kind": "box", "center": [5.0, 1.2], "size": [0.8, 0.8, 1.0]},  # x 4.6..5.4, y 0.8..1.6
        {"kind": "pillar", "center": [10.0, -1.2], "radius": 0.25, "height": 2.0},
    ],
    "people": [
        {"behaviour": "waypoint_loop", "speed": 1.0, "waypoints": [[2.0, -0.5], [8.0, -0.5]]},
        {"behaviour": "random_walk", "speed": 0.8, "region": [11.0, -1.0, 14.0, 1.0], "start": [12.0, 0.0]},
        {"behaviour": "circle", "speed": 0.7, "center": [7.5, 0.0], "radius": 0.6},
    ],
    "drone": {"start": [0.5, 0.0, 1.2], "goal": [14.5, 0.0, 1.2]},
    "camera": {"renderer": "tiny"},
    "noise": {"enabled": True},
    "rates": {"physics": 240, "control": 120, "camera": 30},
}

KEYFRAMES = [[0.0, 1.0, 0.0, 1.2, 0.0], [5.0, 10.0, 0.0, 1.2, 90.0]]


# --------------------------------------------------------------------------- helpers


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(v)


def to_toml(data: dict[str, Any]) -> str:
    """Minimal TOML writer: scalars first, then [tables] and [[arrays of tables]]."""
    lines, tables = [], []
    for k, v in data.items():
        if isinstance(v, dict):
            tables.append(f"[{k}]")
            tables += [f"{kk} = {_toml_value(vv)}" for kk, vv in v.items()]
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            for item in v:
                tables.append(f"[[{k}]]")
                tables += [f"{kk} = {_toml_value(vv)}" for kk, vv in item.items()]
        else:
            lines.append(f"{k} = {_toml_value(v)}")
    return "\n".join(lines + tables) + "\n"


def _apply(data: dict[str, Any], path: str, value: Any) -> None:
    """Set (or DELETE) ``path`` such as ``corridor.length`` or ``people[0].speed``."""
    steps: list[str | int] = []
    for part in path.split("."):
        m = re.fullmatch(r"(\w+)((?:\[\d+\])*)", part)
        assert m, part
        steps.append(m.group(1))
        steps += [int(i) for i in re.findall(r"\[(\d+)\]", m.group(2))]
    node: Any = data
    for s in steps[:-1]:
        if isinstance(s, str) and s not in node:
            node[s] = {}
        node = node[s]
    if value is DELETE:
        del node[steps[-1]]
    else:
        node[steps[-1]] = value


def scenario_text(changes: dict[str, Any] | None = None) -> str:
    data = copy.deepcopy(BASE)
    for path, value in (changes or {}).items():
        _apply(data, path, value)
    return to_toml(data)


def parse(changes: dict[str, Any] | None = None) -> Scenario:
    return parse_scenario(scenario_text(changes), source=SOURCE)


def assert_error(changes: dict[str, Any], key: str, reason: str | tuple[str, ...]) -> str:
    """The change makes parsing fail with '<source>: <key>: ...<reason>...'
    (``reason`` may be a tuple of fragments that must all appear)."""
    with pytest.raises(ScenarioError) as ei:
        parse(changes)
    msg = str(ei.value)
    assert msg.startswith(f"{SOURCE}: {key}: "), msg
    for fragment in (reason,) if isinstance(reason, str) else reason:
        assert fragment in msg, msg
    return msg


def test_base_scenario_is_valid():
    sc = parse()
    assert sc.name == "base" and sc.source == SOURCE
    assert [o.kind for o in sc.obstacles] == ["box", "pillar"]
    assert [p.behaviour for p in sc.people] == ["waypoint_loop", "random_walk", "circle"]


# --------------------------------------------------------------------------- TOML syntax


@pytest.mark.parametrize("text", ["name = ", "[corridor\nlength = 3", "seed = 1\nseed = 2", "x = [1, 2"])
def test_invalid_toml(text):
    with pytest.raises(ScenarioError) as ei:
        parse_scenario(text, source=SOURCE)
    assert str(ei.value).startswith(f"{SOURCE}: not valid TOML: "), str(ei.value)


# --------------------------------------------------------------------------- unknown keys


@pytest.mark.parametrize(
    "changes, key",
    [
        ({"colour": "red"}, "colour"),  # top level
        ({"person": {"speed": 1.0}}, "person"),  # misspelt [table] at top level
        ({"corridor.lenght": 15.0}, "corridor.lenght"),  # inside a [table]
        ({"corridor.extra": {"a": 1}}, "corridor.extra"),  # nested table
        ({"people[0].sped": 1.0}, "people[0].sped"),  # inside an [[array of tables]] entry
        ({"people[2].colour": [1.0, 0.0, 0.0]}, "people[2].colour"),
        ({"obstacles[0].radius": 0.3}, "obstacles[0].radius"),  # radius belongs to pillars
        ({"obstacles[1].size": [0.5, 0.5, 1.0]}, "obstacles[1].size"),  # size does not apply to pillars
        ({"people[0].region": [1.0, -1.0, 3.0, 1.0]}, "people[0].region"),  # random_walk key on a loop
        ({"people[1].waypoints": [[11.0, 0.0], [13.0, 0.0]]}, "people[1].waypoints"),  # loop key on a random walk
        ({"people[0].clockwise": True}, "people[0].clockwise"),  # circle key on a loop
        ({"drone.speed": 1.0}, "drone.speed"),
        ({"camera.fov": 90}, "camera.fov"),
        ({"camera.mount_rpy": [0.0, 0.0, 0.0]}, "camera.mount_rpy"),  # the key is mount_rpy_deg
        ({"noise.sigma": 0.1}, "noise.sigma"),
        ({"rates.render": 30}, "rates.render"),
        ({"camera_path.keyframes": KEYFRAMES, "camera_path.follow_distance": 2.0}, "camera_path.follow_distance"),
    ],
)
def test_unknown_key(changes, key):
    assert_error(changes, key, "unknown key")


def test_several_unknown_keys_are_all_named():
    msg = assert_error({"zzz": 1, "aaa": 2, "mmm": 3}, "aaa", "unknown key")
    assert "also unknown: mmm, zzz" in msg


# --------------------------------------------------------------------------- structure


@pytest.mark.parametrize(
    "changes, key, reason",
    [
        ({"corridor": 5}, "corridor", "expected a table, got int"),
        ({"camera_path": "follow"}, "camera_path", "expected a table, got str"),
        ({"obstacles": 5}, "obstacles", "expected an array of tables ([[obstacles]])"),
        ({"people": "alice"}, "people", "expected an array of tables ([[people]])"),
        ({"obstacles": [1, 2]}, "obstacles[0]", "expected a table, got int"),
    ],
)
def test_wrong_structure(changes, key, reason):
    assert_error(changes, key, reason)


def test_array_of_tables_where_table_expected():
    text = scenario_text({"corridor": DELETE}) + "[[corridor]]\nlength = 15.0\n"
    with pytest.raises(ScenarioError) as ei:
        parse_scenario(text, source=SOURCE)
    assert str(ei.value).startswith(f"{SOURCE}: corridor: expected a table, got list"), str(ei.value)


# --------------------------------------------------------------------------- wrong types


@pytest.mark.parametrize(
    "changes, key, reason",
    [
        # string / bool where a number is expected
        ({"corridor.length": "15"}, "corridor.length", "expected a number, got '15'"),
        ({"people[0].speed": "fast"}, "people[0].speed", "expected a number, got 'fast'"),
        ({"people[0].speed": True}, "people[0].speed", "expected a number, got True"),
        ({"duration": False}, "duration", "expected a number, got False"),
        ({"obstacles[1].radius": [0.25]}, "obstacles[1].radius", "expected a number, got [0.25]"),
        # non-integer where an integer is expected
        ({"seed": 1.5}, "seed", "expected an integer, got 1.5"),
        ({"rates.physics": 240.0}, "rates.physics", "expected an integer, got 240.0"),
        ({"camera.width": 640.5}, "camera.width", "expected an integer, got 640.5"),
        ({"camera_path.follow_person": 0.0}, "camera_path.follow_person", "expected an integer, got 0.0"),
        # non-finite numbers
        ({"corridor.width": INF}, "corridor.width", "must be finite, got inf"),
        ({"duration": NAN}, "duration", "must be finite, got nan"),
        ({"people[0].speed": -INF}, "people[0].speed", "must be finite, got -inf"),
        # booleans
        ({"corridor.ceiling": "yes"}, "corridor.ceiling", "expected true or false, got 'yes'"),
        ({"segmentation": 1}, "segmentation", "expected true or false, got 1"),
        ({"people[2].clockwise": 0}, "people[2].clockwise", "expected true or false, got 0"),
        ({"noise.enabled": "false"}, "noise.enabled", "expected true or false, got 'false'"),
        # strings
        ({"name": 5}, "name", "expected a string, got 5"),
        ({"description": ["a"]}, "description", "expected a string, got ['a']"),
        ({"obstacles[0].kind": 3}, "obstacles[0].kind", "expected a string, got 3"),
        # vectors: not a list, wrong length, bad elements
        ({"drone.start": 1.0}, "drone.start", "expected a list of 3 numbers, got 1.0"),
        ({"drone.goal": [14.5, 0.0]}, "drone.goal", "expected a list of 3 numbers, got [14.5, 0.0]"),
        ({"obstacles[0].center": [5.0, 1.2, 0.0]}, "obstacles[0].center", "expected a list of 2 numbers"),
        ({"obstacles[0].size": "big"}, "obstacles[0].size", "expected a list of 3 numbers"),
        ({"people[1].region": [11.0, -1.0, 14.0]}, "people[1].region", "expected a list of 4 numbers"),
        ({"camera.mount_rpy_deg": [0.0, 15.0]}, "camera.mount_rpy_deg", "expected a list of 3 numbers"),
        ({"obstacles[0].center": [5.0, "1.2"]}, "obstacles[0].center", "expected a list of 2 finite numbers"),
        ({"obstacles[0].size": [0.8, 0.8, INF]}, "obstacles[0].size", "expected a list of 3 finite numbers"),
        ({"camera.mount_xyz": [0.0, True, 0.0]}, "camera.mount_xyz", "expected a list of 3 finite numbers"),
        ({"people[1].start": [NAN, 0.0]}, "people[1].start", "expected a list of 2 finite numbers"),
        ({"obstacles[0].color": [1.0, 0.5]}, "obstacles[0].color", "expected a list of 3 numbers"),
        # point lists
        ({"people[0].waypoints": "a"}, "people[0].waypoints", "expected a list of at least 2 points [x, y]"),
        ({"people[0].waypoints": [[2.0, -0.5]]}, "people[0].waypoints", "expected a list of at least 2 points"),
        ({"people[0].waypoints": [[2.0, -0.5], [8.0]]}, "people[0].waypoints[1]", "expected 2 finite numbers, got [8.0]"),
        ({"people[0].waypoints": [[2.0, -0.5], [NAN, -0.5]]}, "people[0].waypoints[1]", "expected 2 finite numbers"),
        ({"people[0].waypoints": [[2.0, -0.5], 8.0]}, "people[0].waypoints[1]", "expected 2 finite numbers, got 8.0"),
        ({"people[0].waypoints": [[True, -0.5], [8.0, -0.5]]}, "people[0].waypoints[0]", "expected 2 finite numbers"),
        ({"camera_path.keyframes": [[0.0, 1.0, 0.0, 1.2]]}, "camera_path.keyframes[0]", "expected 5 finite numbers"),
        ({"camera_path.keyframes": []}, "camera_path.keyframes", "expected a list of at least 1 points"),
        ({"camera_path.keyframes": 3}, "camera_path.keyframes", "expected a list of at least 1 points"),
    ],
)
def test_wrong_type(changes, key, reason):
    assert_error(changes, key, reason)


# --------------------------------------------------------------------------- missing required keys


@pytest.mark.parametrize(
    "key",
    [
        "obstacles[0].kind",
        "obstacles[0].center",
        "obstacles[0].size",
        "obstacles[1].radius",
        "obstacles[1].height",
        "people[0].behaviour",
        "people[0].speed",
        "people[1].region",
        "people[2].center",
        "people[2].radius",
    ],
)
def test_missing_required_key(key):
    assert_error({key: DELETE}, key, "is required")


def test_missing_waypoints():
    assert_error({"people[0].waypoints": DELETE}, "people[0].waypoints", "expected a list of at least 2 points")


# --------------------------------------------------------------------------- numeric ranges


@pytest.mark.parametrize(
    "changes, key, reason",
    [
        ({"people[0].speed": 2.0}, "people[0].speed", "must be <= 1.6, got 2.0"),
        ({"people[0].speed": 0.4}, "people[0].speed", "must be >= 0.5, got 0.4"),
        ({"people[0].height": 1.5}, "people[0].height", "must lie in [1.6, 1.85] m, got 1.5"),
        ({"people[0].height": 1.9}, "people[0].height", "must lie in [1.6, 1.85] m, got 1.9"),
        ({"people[0].height": -1.0}, "people[0].height", "must lie in [1.6, 1.85] m, got -1.0"),
        ({"people[0].start_delay": -1.0}, "people[0].start_delay", "must be >= 0.0, got -1.0"),
        ({"people[0].start_delay": 4000.0}, "people[0].start_delay", "must be <= 3600.0"),
        ({"people[2].radius": 0.1}, "people[2].radius", "must be >= 0.3, got 0.1"),
        ({"corridor.length": 1.0}, "corridor.length", "must be >= 2.0, got 1.0"),
        ({"corridor.length": 500.0}, "corridor.length", "must be <= 200.0, got 500.0"),
        ({"corridor.width": 0.5}, "corridor.width", "must be >= 1.0, got 0.5"),
        ({"corridor.height": 25.0}, "corridor.height", "must be <= 20.0, got 25.0"),
        ({"camera.width": 8}, "camera.width", "must be >= 16, got 8"),
        ({"camera.width": 5000}, "camera.width", "must be <= 4096, got 5000"),
        ({"camera.height": 0}, "camera.height", "must be >= 16, got 0"),
        ({"camera.fx": 0.5}, "camera.fx", "must be >= 1.0, got 0.5"),
        ({"camera.cx": 700.0}, "camera.cx", "must be <= 640.0, got 700.0"),
        ({"camera.min_range": 0.01}, "camera.min_range", ("must be >= ", "got 0.01")),
        ({"camera.max_range": 200.0}, "camera.max_range", "must be <= 100.0, got 200.0"),
        ({"seed": -1}, "seed", "must be >= 0, got -1"),
        ({"duration": 0.0}, "duration", "must be > 0.0, got 0.0"),
        ({"duration": 4000.0}, "duration", "must be <= 3600.0, got 4000.0"),
        ({"drone.cruise_speed": 0.0}, "drone.cruise_speed", "must be > 0.0, got 0.0"),
        ({"drone.yaw_deg": 400.0}, "drone.yaw_deg", "must be <= 360.0, got 400.0"),
        ({"obstacles[0].yaw_deg": -400.0}, "obstacles[0].yaw_deg", "must be >= -360.0, got -400.0"),
        ({"obstacles[1].radius": 0.01}, "obstacles[1].radius", "must be >= 0.02, got 0.01"),
        ({"obstacles[1].height": 0.0}, "obstacles[1].height", "must be >= 0.05, got 0.0"),
        ({"noise.baseline": 0.0}, "noise.baseline", "must be > 0.0, got 0.0"),
        ({"noise.dropout": 1.5}, "noise.dropout", "must be <= 1.0, got 1.5"),
        ({"noise.subpixel": -0.1}, "noise.subpixel", "must be >= 0.0, got -0.1"),
        ({"noise.odom_rotation_std": 0.6}, "noise.odom_rotation_std", "must be <= 0.5, got 0.6"),
        ({"rates.control": 60}, "rates.control", "must be >= 100, got 60"),  # 240 % 60 == 0: only the range fails
        ({"rates.physics": 50}, "rates.physics", "must be >= 60, got 50"),
        ({"rates.camera": 0}, "rates.camera", "must be >= 1, got 0"),
        ({"camera_path.follow_person": -1}, "camera_path.follow_person", "must be >= 0, got -1"),
        ({"camera_path.follow_person": 0, "camera_path.follow_distance": 0.2},
         "camera_path.follow_distance", "must be >= 0.5, got 0.2"),
    ],
)
def test_out_of_range(changes, key, reason):
    assert_error(changes, key, reason)


@pytest.mark.parametrize("speed", [0.5, 1.6])
def test_person_speed_band_is_inclusive(speed):
    assert parse({"people[0].speed": speed}).people[0].speed == speed


@pytest.mark.parametrize("height", [1.6, 1.85])
def test_person_height_band_is_inclusive(height):
    assert parse({"people[0].height": height}).people[0].height == height


# --------------------------------------------------------------------------- choices


@pytest.mark.parametrize(
    "changes, key, reason",
    [
        ({"obstacles[0].kind": "cube"}, "obstacles[0].kind", "must be one of box, pillar, shelf, wall; got 'cube'"),
        ({"people[0].behaviour": "run"}, "people[0].behaviour",
         "must be one of waypoint_loop, back_and_forth, crossing, random_walk, circle; got 'run'"),
        ({"camera.renderer": "opengl"}, "camera.renderer", "must be one of auto, gl, pybullet, tiny, egl; got 'opengl'"),
        ({"noise.axial_model": "gauss"}, "noise.axial_model", "must be one of intel_rms, nguyen, none; got 'gauss'"),
        ({"camera_path.keyframes": KEYFRAMES, "camera_path.mode": "drive"}, "camera_path.mode",
         "must be one of carried, flown; got 'drive'"),
    ],
)
def test_unknown_choice(changes, key, reason):
    assert_error(changes, key, reason)


# --------------------------------------------------------------------------- value checks


@pytest.mark.parametrize("size", [[0.8, 0.0, 1.0], [-0.8, 0.8, 1.0], [0.8, 0.8, -1.0]])
def test_obstacle_size_must_be_positive(size):
    assert_error({"obstacles[0].size": size}, "obstacles[0].size", "every dimension must be > 0")


@pytest.mark.parametrize(
    "key, color",
    [("obstacles[0].color", [1.2, 0.0, 0.0]), ("obstacles[1].color", [0.0, 0.0, -0.01]),
     ("people[0].color", [-0.1, 0.5, 0.5]), ("people[2].color", [0.5, 2.0, 0.5])],
)
def test_color_component_outside_unit_interval(key, color):
    assert_error({key: color}, key, "color components must lie in [0, 1]")


def test_color_is_read():
    sc = parse({"obstacles[0].color": [0.0, 0.5, 1.0], "people[0].color": [1, 0, 0]})
    assert sc.obstacles[0].color == (0.0, 0.5, 1.0)
    assert sc.people[0].color == (1.0, 0.0, 0.0)
    assert sc.obstacles[1].color is None


@pytest.mark.parametrize("min_range, max_range", [(2.0, 1.0), (2.0, 2.0)])
def test_max_range_must_exceed_min_range(min_range, max_range):
    assert_error({"camera.min_range": min_range, "camera.max_range": max_range},
                 "camera.max_range", f"must exceed min_range ({min_range}), got {max_range}")


def test_edge_probabilities_must_not_exceed_one():
    # flying_pixel_prob defaults to 0.3, so 0.8 + 0.3 > 1
    assert_error({"noise.edge_hole_prob": 0.8}, "noise.flying_pixel_prob",
                 "edge_hole_prob + flying_pixel_prob must not exceed 1")


def test_edge_probabilities_summing_to_one_are_accepted():
    n = parse({"noise.edge_hole_prob": 0.5, "noise.flying_pixel_prob": 0.5}).noise
    assert (n.edge_hole_prob, n.flying_pixel_prob) == (0.5, 0.5)


@pytest.mark.parametrize(
    "changes, key, reason",
    [
        ({"rates.physics": 250}, "rates.control", "physics rate 250 Hz must be a multiple of the control rate 120 Hz"),
        ({"rates.control": 160}, "rates.control", "physics rate 240 Hz must be a multiple of the control rate 160 Hz"),
        ({"rates.camera": 70}, "rates.camera", "control rate 120 Hz must be a multiple of the camera rate 70 Hz"),
        # a camera faster than the control loop would lose frames between control periods
        ({"rates.physics": 600, "rates.control": 100, "rates.camera": 120}, "rates.camera",
         "control rate 100 Hz must be a multiple of the camera rate 120 Hz"),
    ],
)
def test_rates_must_divide_physics(changes, key, reason):
    assert_error(changes, key, reason)


def test_repeated_waypoint():
    assert_error({"people[0].waypoints": [[2.0, -0.5], [8.0, -0.5], [8.0, -0.5]]},
                 "people[0].waypoints[2]", "repeats the previous waypoint")


# --------------------------------------------------------------------------- camera path


def test_camera_path_with_keyframes_and_follow_person():
    assert_error({"camera_path.keyframes": KEYFRAMES, "camera_path.follow_person": 0},
                 "camera_path", "give exactly one of keyframes or follow_person")


def test_camera_path_with_neither_keyframes_nor_follow_person():
    assert_error({"camera_path.mode": "carried"}, "camera_path", "give exactly one of keyframes or follow_person")


@pytest.mark.parametrize("t1", [0.0, -1.0])
def test_keyframe_times_must_increase(t1):
    kf = [[0.0, 1.0, 0.0, 1.2, 0.0], [2.0, 3.0, 0.0, 1.2, 0.0], [t1, 5.0, 0.0, 1.2, 0.0]]
    assert_error({"camera_path.keyframes": kf}, "camera_path.keyframes[2]", "times must increase")


@pytest.mark.parametrize(
    "point", [[1.0, 3.0, 1.2], [16.0, 0.0, 1.2], [0.05, 0.0, 1.2], [5.0, 0.0, 3.5], [5.0, 0.0, 0.05]]
)
def test_keyframe_outside_corridor(point):
    kf = [[0.0, 1.0, 0.0, 1.2, 0.0], [5.0, *point, 0.0]]
    x, y, z = (float(v) for v in point)
    assert_error({"camera_path.keyframes": kf}, "camera_path.keyframes[1]", f"({x}, {y}, {z}) is outside the corridor")


@pytest.mark.parametrize("index", [3, 10])
def test_follow_person_index_out_of_range(index):
    assert_error({"camera_path.follow_person": index}, "camera_path.follow_person",
                 f"there is no people[{index}] (3 people)")


def test_camera_path_keyframes_are_read_with_yaw_in_radians():
    cp = parse({"camera_path.keyframes": KEYFRAMES, "camera_path.mode": "flown"}).camera_path
    assert cp.mode == "flown" and cp.follow_person is None
    assert cp.keyframes[0] == (0.0, 1.0, 0.0, 1.2, 0.0)
    assert cp.keyframes[1][:4] == (5.0, 10.0, 0.0, 1.2)
    assert cp.keyframes[1][4] == pytest.approx(math.pi / 2)


def test_camera_path_follow_person_defaults():
    cp = parse({"camera_path.follow_person": 2}).camera_path
    assert (cp.mode, cp.follow_person, cp.follow_distance, cp.follow_height, cp.keyframes) == ("carried", 2, 2.5, 1.3, ())


# --------------------------------------------------------------------------- random walk


@pytest.mark.parametrize(
    "region", [[11.0, -1.0, 14.9, 1.0], [11.0, -1.9, 14.0, 1.0], [0.1, -1.0, 14.0, 1.0], [11.0, -1.0, 14.0, 1.8]]
)
def test_random_walk_region_leaves_corridor(region):
    assert_error({"people[1].region": region}, "people[1].region", "leaves the corridor")


@pytest.mark.parametrize("region", [[12.0, -1.0, 12.05, 1.0], [11.0, 0.5, 14.0, 0.5], [14.0, -1.0, 11.0, 1.0]])
def test_random_walk_region_degenerate(region):
    assert_error({"people[1].region": region}, "people[1].region",
                 "expected [x_min, y_min, x_max, y_max] with max > min")


@pytest.mark.parametrize("start", [[10.0, 0.0], [12.0, 1.5], [14.5, 0.0]])
def test_random_walk_start_outside_region(start):
    assert_error({"people[1].start": start}, "people[1].start", "is outside the region [11.0, -1.0, 14.0, 1.0]")


def test_random_walk_start_inside_obstacle():
    # move the pillar onto the random walker's start (12, 0)
    assert_error({"obstacles[1].center": [12.0, 0.0]}, "people[1].start", "starts inside obstacles[1] (pillar)")


def test_random_walk_start_is_optional():
    p = parse({"people[1].start": DELETE}).people[1]
    assert p.start is None and p.region == (11.0, -1.0, 14.0, 1.0)


# --------------------------------------------------------------------------- person paths


@pytest.mark.parametrize(
    "behaviour, waypoints",
    [
        ("waypoint_loop", [[2.0, -0.5], [16.0, -0.5]]),
        ("waypoint_loop", [[2.0, -1.9], [8.0, -1.9]]),
        ("back_and_forth", [[0.1, -0.5], [8.0, -0.5]]),
        ("crossing", [[3.0, -1.0], [3.0, 1.9]]),
    ],
)
def test_waypoint_path_leaves_corridor(behaviour, waypoints):
    assert_error({"people[0].behaviour": behaviour, "people[0].waypoints": waypoints},
                 "people[0].waypoints", "the path leaves the corridor near")


def test_person_starts_inside_obstacle():
    assert_error({"people[0].waypoints": [[5.0, 1.2], [8.0, -0.5]]}, "people[0].waypoints",
                 "the person starts inside obstacles[0] (box)")


def test_person_start_within_body_radius_of_obstacle():
    # (5.0, 0.65) is 0.15 m from the box edge (y = 0.8): inside the 0.25 m body radius
    assert_error({"people[0].waypoints": [[5.0, 0.65], [8.0, -0.5]]}, "people[0].waypoints",
                 "the person starts inside obstacles[0] (box)")


@pytest.mark.parametrize("behaviour", ["waypoint_loop", "back_and_forth", "crossing"])
def test_path_walks_through_obstacle(behaviour):
    assert_error({"people[0].behaviour": behaviour, "people[0].waypoints": [[2.0, 1.2], [8.0, 1.2]]},
                 "people[0].waypoints", "the path walks through obstacles[0] (box) near")


# An open U around the box: clear as a back-and-forth, but closing the loop walks through it.
U_AROUND_BOX = [[3.0, 1.2], [3.0, -1.0], [7.0, -1.0], [7.0, 1.2]]


def test_closing_segment_of_loop_is_checked():
    assert_error({"people[0].waypoints": U_AROUND_BOX}, "people[0].waypoints",
                 "the path walks through obstacles[0] (box)")


def test_open_path_is_not_closed():
    p = parse({"people[0].behaviour": "back_and_forth", "people[0].waypoints": U_AROUND_BOX}).people[0]
    assert p.waypoints == tuple(tuple(w) for w in U_AROUND_BOX)


@pytest.mark.parametrize("changes", [{"people[2].radius": 2.0}, {"people[2].center": [0.4, 0.0]},
                                     {"people[2].center": [7.5, 1.3]}])
def test_circle_leaves_corridor(changes):
    assert_error(changes, "people[2].center", "the path leaves the corridor near")


def test_circle_starts_inside_obstacle():
    # the circle starts at center + (radius, 0) = (8.1, 0): move the box there
    assert_error({"obstacles[0].center": [8.1, 0.0], "obstacles[0].size": [0.2, 0.2, 1.0]}, "people[2].center",
                 "the person starts inside obstacles[0] (box)")


def test_circle_walks_through_obstacle():
    # the box at (7.5, 0.6) sits on the circle's top, away from its start (8.1, 0)
    assert_error({"obstacles[0].center": [7.5, 0.6], "obstacles[0].size": [0.2, 0.2, 1.0]},
                 "people[2].center", "the path walks through obstacles[0] (box)")


# --------------------------------------------------------------------------- obstacles in the corridor


@pytest.mark.parametrize(
    "changes, key, kind",
    [
        ({"obstacles[0].center": [5.0, 1.8]}, "obstacles[0].center", "box"),
        ({"obstacles[0].center": [0.3, -1.0]}, "obstacles[0].center", "box"),
        ({"obstacles[0].center": [14.8, 0.0]}, "obstacles[0].center", "box"),
        ({"obstacles[0].size": [0.4, 2.0, 1.0]}, "obstacles[0].center", "box"),
        ({"obstacles[0].yaw_deg": 45.0, "obstacles[0].center": [5.0, 1.5]}, "obstacles[0].center", "box"),
        ({"obstacles[1].center": [10.0, -1.9]}, "obstacles[1].center", "pillar"),
        ({"obstacles[1].radius": 1.0}, "obstacles[1].center", "pillar"),
    ],
)
def test_obstacle_sticks_out_of_corridor(changes, key, kind):
    assert_error(changes, key, (f"the {kind} at ", "sticks out of the corridor"))


def test_obstacle_yaw_is_used_for_the_corridor_check():
    # 0.4 x 2.0 at y = 1.2 sticks out (previous test); turned by 90 deg it lies along the wall
    o = parse({"obstacles[0].size": [0.4, 2.0, 1.0], "obstacles[0].yaw_deg": 90.0}).obstacles[0]
    assert o.yaw == pytest.approx(math.pi / 2)


def test_obstacle_taller_than_corridor_with_ceiling():
    assert_error({"corridor.ceiling": True, "obstacles[1].height": 3.5}, "obstacles[1].size",
                 "taller than the corridor (3.0 m)")


def test_obstacle_taller_than_open_corridor_is_accepted():
    sc = parse({"obstacles[1].height": 3.5})
    assert sc.obstacles[1].size == (0.5, 0.5, 3.5)


# --------------------------------------------------------------------------- drone


@pytest.mark.parametrize(
    "name, pos",
    [
        ("start", [0.1, 0.0, 1.2]),
        ("start", [0.5, 1.9, 1.2]),
        ("start", [0.5, 0.0, 0.1]),
        ("goal", [14.9, 0.0, 1.2]),
        ("goal", [14.5, -1.8, 1.2]),
        ("goal", [14.5, 0.0, 2.9]),
        ("goal", [20.0, 0.0, 1.2]),
    ],
)
def test_drone_outside_corridor(name, pos):
    assert_error({f"drone.{name}": pos}, f"drone.{name}", "is not inside the corridor")


@pytest.mark.parametrize(
    "name, pos, j, kind",
    [
        ("start", [5.0, 1.2, 0.5], 0, "box"),
        ("start", [5.0, 0.6, 1.2], 0, "box"),  # 0.2 m beside the box, 0.1 m above its top + 0.3 margin
        ("goal", [10.0, -1.2, 1.2], 1, "pillar"),
    ],
)
def test_drone_inside_obstacle(name, pos, j, kind):
    assert_error({f"drone.{name}": pos}, f"drone.{name}", f"is inside obstacles[{j}] ({kind})")


def test_drone_above_obstacle_is_accepted():
    # box top at 1.0 m, margin 0.3 m
    assert parse({"drone.start": [5.0, 1.2, 1.5]}).drone.start == (5.0, 1.2, 1.5)


# --------------------------------------------------------------------------- files


def test_error_in_file_names_the_path(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(scenario_text({"people[0].speed": 2.0}), encoding="utf-8")
    with pytest.raises(ScenarioError) as ei:
        load_scenario(path)
    assert str(ei.value) == f"{path}: people[0].speed: must be <= 1.6, got 2.0"


def test_missing_file(tmp_path):
    path = tmp_path / "nope.toml"
    with pytest.raises(ScenarioError) as ei:
        load_scenario(path)
    msg = str(ei.value)
    assert msg.startswith(f"{path}: no such file"), msg


def test_missing_relative_file(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ScenarioError) as ei:
        load_scenario("sub/nope.toml")
    assert str(ei.value).startswith("sub/nope.toml: no such file"), str(ei.value)


@pytest.mark.parametrize("name", ["no_such_scenario", "no_such_scenario.toml"])
def test_unknown_shipped_name(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ScenarioError) as ei:
        load_scenario(name)
    msg = str(ei.value)
    assert msg.startswith(f"{name}: no such file, and not a shipped scenario"), msg
    assert "shipped: " + ", ".join(shipped_scenarios()) in msg


def test_unreadable_path(tmp_path):
    with pytest.raises(ScenarioError) as ei:
        load_scenario(tmp_path)  # a directory
    assert str(ei.value).startswith(f"{tmp_path}: cannot read"), str(ei.value)


def test_load_from_file_defaults_name_to_stem(tmp_path):
    path = tmp_path / "my_scene.toml"
    path.write_text(scenario_text({"name": DELETE}), encoding="utf-8")
    sc = load_scenario(str(path))
    assert sc.name == "my_scene" and sc.source == str(path)


# --------------------------------------------------------------------------- shipped scenarios


def test_there_are_shipped_scenarios():
    assert "corridor" in shipped_scenarios()


@pytest.mark.parametrize("name", shipped_scenarios())
def test_shipped_scenario_loads(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # resolve by name, not by a file in the working directory
    sc = load_scenario(name)
    assert isinstance(sc, Scenario)
    assert sc.source.endswith(f"{name}.toml")
    assert load_scenario(f"{name}.toml") == sc


# --------------------------------------------------------------------------- defaults and conversions


def test_minimal_scenario_gets_documented_defaults():
    sc = parse_scenario("", source="dir/minimal.toml")
    assert sc.name == "minimal" and sc.seed == 0 and sc.duration == 20.0 and sc.segmentation
    assert (sc.corridor.length, sc.corridor.width, sc.corridor.height, sc.corridor.ceiling) == (15.0, 4.0, 3.0, False)
    assert sc.obstacles == () and sc.people == () and sc.camera_path is None
    cam = sc.camera
    assert (cam.width, cam.height) == (640, 480)
    assert cam.fx == 387.1537 and cam.fy == 387.1537
    assert cam.cx == pytest.approx(321.3246) and cam.cy == pytest.approx(233.5472)
    assert (cam.min_range, cam.max_range, cam.renderer, cam.color) == (0.2, 10.0, "auto", True)
    assert cam.mount_xyz == (0.065, 0.01, 0.12) and cam.mount_rpy == (0.0, 0.0, 0.0)
    assert (sc.rates.physics, sc.rates.control, sc.rates.camera) == (240, 120, 30)
    assert sc.drone.start == (0.5, 0.0, 1.2) and sc.drone.goal == (14.5, 0.0, 1.2)
    assert sc.drone.yaw == 0.0 and sc.drone.cruise_speed == 1.0
    assert sc.noise.enabled and sc.noise.axial_model == "intel_rms"


def test_default_principal_point_scales_with_resolution():
    cam = parse({"camera.width": 320, "camera.height": 240}).camera
    assert cam.cx == pytest.approx(321.3246 / 2) and cam.cy == pytest.approx(233.5472 / 2)


def test_integers_are_accepted_for_floats_and_converted():
    sc = parse({"people[0].speed": 1, "corridor.length": 15})
    assert isinstance(sc.people[0].speed, float) and isinstance(sc.corridor.length, float)
    assert isinstance(sc.rates.physics, int)


def test_degrees_are_converted_to_radians():
    sc = parse({"obstacles[0].yaw_deg": 90.0, "drone.yaw_deg": -180.0, "camera.mount_rpy_deg": [0.0, 15.0, 90.0]})
    assert sc.obstacles[0].yaw == pytest.approx(math.pi / 2)
    assert sc.obstacles[1].yaw == 0.0
    assert sc.drone.yaw == pytest.approx(-math.pi)
    assert sc.camera.mount_rpy == pytest.approx((0.0, math.radians(15.0), math.pi / 2))


def test_pillar_size_from_radius():
    assert parse().obstacles[1].size == (0.5, 0.5, 2.0)


def test_circle_fills_center_and_radius():
    p = parse({"people[2].clockwise": True}).people[2]
    assert p.behaviour == "circle"
    assert p.center == (7.5, 0.0) and p.radius == 0.6 and p.clockwise is True
    assert p.waypoints == () and p.region is None
    wps = circle_waypoints(p.center, p.radius, p.clockwise)
    assert wps[0] == pytest.approx((8.1, 0.0))
    assert all(math.dist(w, p.center) == pytest.approx(0.6) for w in wps)


def test_person_fields():
    sc = parse({"people[0].height": 1.7, "people[0].start_delay": 2.0})
    p0, p1 = sc.people[0], sc.people[1]
    assert (p0.height, p0.start_delay, p0.waypoints) == (1.7, 2.0, ((2.0, -0.5), (8.0, -0.5)))
    assert p1.height is None and p1.start == (12.0, 0.0) and p1.region == (11.0, -1.0, 14.0, 1.0)


# --------------------------------------------------------------------------- gaps found in review


def test_path_brushing_past_an_obstacle_counts_the_body_width():
    # the box edge is at y = 0.8; a path at y = 0.7 is clear of the footprint but not of the body
    assert_error({"people[0].waypoints": [[2.0, 0.7], [8.0, 0.7]]}, "people[0].waypoints",
                 "the path walks through obstacles[0] (box)")


def test_random_walk_region_covered_by_obstacles():
    assert_error({"obstacles[1]": {"kind": "box", "center": [12.5, 0.0], "size": [3.0, 3.0, 1.0]},
                  "people[1].start": DELETE},
                 "people[1].region", "no free space in the region")


def test_camera_keyframes_through_an_obstacle():
    assert_error({"camera_path": {"keyframes": [[0.0, 1.0, 1.2, 0.5, 0.0], [5.0, 9.0, 1.2, 0.5, 0.0]]}},
                 "camera_path.keyframes[0]", "the camera path passes through obstacles[0] (box)")


def test_keyframes_error_names_their_fields():
    assert_error({"camera_path": {"keyframes": []}}, "camera_path.keyframes", "[t, x, y, z, yaw_deg]")


# --------------------------------------------------------------------------- values drawn by the seed

FAMILIES = ("corridor", "corridor4", "crossing", "head_on", "step_out", "overtaking", "static_clutter")


def test_ranges_are_drawn_per_seed_within_their_bounds_and_repeat_for_a_seed():
    sc = make_scenario('[[people]]\nbehaviour = "crossing"\nspeed = {uniform = [0.5, 1.6]}\n'
                       'start_delay = {choice = [0.0, 2.0]}\n'
                       'waypoints = [[{uniform = [2.0, 3.0]}, 0.0], [{same_as = "people.0.waypoints.0.0", plus = 4.0}, 1.0]]\n')
    assert sc.randomized
    draws = [sc.for_seed(s) for s in range(30)]
    speeds = [d.people[0].speed for d in draws]
    assert all(0.5 <= v <= 1.6 for v in speeds) and len(set(speeds)) == 30
    assert {d.people[0].start_delay for d in draws} == {0.0, 2.0}
    for d in draws:
        (x0, _), (x1, _) = d.people[0].waypoints
        assert 2.0 <= x0 <= 3.0 and x1 == pytest.approx(x0 + 4.0)
    assert sc.for_seed(7) == sc.for_seed(7) and sc.for_seed(7) != sc.for_seed(8)


@pytest.mark.parametrize("value,message", [
    ("{uniform = [1.0]}", "speed: expected {uniform = [lo, hi]} with two finite numbers"),
    ("{uniform = [1.2, 0.8]}", "speed: uniform range [1.2, 0.8] has lo > hi"),
    ("{uniform = [0.8, nan]}", "speed: expected {uniform = [lo, hi]} with two finite numbers"),
    ("{choice = []}", "speed: expected {choice = [a, b, ...]}"),
    ("{uniform = [0.8, 2.5]}", "people[0].speed: must be <= 1.6, got 2.5 (a value one of the scenario's ranges can take)"),
    ("{choice = [0.8, 0.2]}", "people[0].speed: must be >= 0.5, got 0.2"),
    ('{same_as = "people.0.nothing"}', "same_as 'people.0.nothing' does not name a number"),
    ('{same_as = "people.0.speed", times = "2"}', "speed.times: expected a finite number"),
])
def test_bad_ranges_are_refused_naming_the_key(value, message):
    with pytest.raises(ScenarioError) as e:
        make_scenario(f'[[people]]\nbehaviour = "crossing"\nspeed = {value}\nwaypoints = [[2.0, 0.0], [4.0, 0.0]]\n')
    assert "test.toml" in str(e.value) and message in str(e.value)


def test_a_draw_that_fails_the_geometry_checks_is_drawn_again():
    # Half of the starts fall inside the box: every seed still gives a person starting outside it.
    sc = make_scenario('[[obstacles]]\nkind = "box"\ncenter = [5.0, 0.0]\nsize = [1.0, 1.0, 1.0]\n'
                       '[[people]]\nbehaviour = "crossing"\nspeed = 1.0\n'
                       'waypoints = [[{uniform = [4.0, 6.0]}, 1.5], [{uniform = [4.0, 6.0]}, {uniform = [-1.0, 1.0]}]]\n')
    ends = [sc.for_seed(s).people[0].waypoints[1] for s in range(20)]
    assert all(not sc.obstacles[0].footprint_contains(np.array(e), 0.25)[0] for e in ends)


def test_a_range_that_can_never_pass_the_checks_is_refused_naming_the_seed():
    with pytest.raises(ScenarioError, match=r"people\[0\].waypoints: the person starts inside obstacles\[0\] \(box\) "
                                            r"\(seed 0: no draw of the scenario's ranges passed the checks"):
        make_scenario('[[obstacles]]\nkind = "box"\ncenter = [5.0, 0.0]\nsize = [1.0, 1.0, 1.0]\n'
                      '[[people]]\nbehaviour = "crossing"\nspeed = 1.0\n'
                      'waypoints = [[{uniform = [4.9, 5.1]}, 0.0], [8.0, 0.0]]\n')  # drawn for the file's seed


def test_with_values_sets_keys_as_the_file_would_and_checks_them():
    sc = load_scenario("corridor")
    seen = sc.with_values({"crowd.sees_drone": True, "people.1.speed": 1.1, "duration": 30.0})
    assert seen.crowd.sees_drone and seen.duration == 30.0
    assert all(p.speed == 1.1 for p in (seen.for_seed(s).people[1] for s in range(3)))  # a range replaced
    with pytest.raises(ScenarioError, match="crowd.bogus: unknown key"):
        sc.with_values({"crowd.bogus": 1})
    with pytest.raises(ScenarioError, match="people.9.speed: people has no item '9'"):
        sc.with_values({"people.9.speed": 1.0})
    with pytest.raises(ScenarioError, match=r"crowd.sees_drone: expected true or false"):
        sc.with_values({"crowd.sees_drone": "yes"})


def test_a_drawn_scenario_changed_behind_its_back_is_refused_for_another_seed():
    import dataclasses

    sc = dataclasses.replace(load_scenario("corridor"), duration=5.0)
    assert sc.for_seed(sc.drawn_seed) is sc  # its own seed: itself
    with pytest.raises(ScenarioError, match="with Scenario.with_values instead"):
        sc.for_seed(sc.drawn_seed + 1)


@pytest.mark.parametrize("table,message", [
    ("sees_drone = 1", "crowd.sees_drone: expected true or false"),
    ("relaxation_time = 0.0", "crowd.relaxation_time: must be >= 0.05"),
    ("strength = -1.0", "crowd.strength: must be >= 0.0"),
    ("view_angle_deg = 270.0", "crowd.view_angle_deg: must be <= 180.0"),
    ("stregth = 2.0", "crowd.stregth: unknown key"),
])
def test_crowd_settings_are_checked(table, message):
    with pytest.raises(ScenarioError, match=message):
        make_scenario(f"[crowd]\n{table}\n")


@pytest.mark.parametrize("name", FAMILIES)
def test_the_shipped_families_differ_by_seed_as_situations(name):
    sc = load_scenario(name)
    assert sc.randomized
    draws = [sc.for_seed(s) for s in range(5)]
    layouts = {tuple(o.center for o in d.obstacles) for d in draws}
    people = {tuple((p.speed, p.start_delay) for p in d.people) for d in draws}
    assert len(layouts) == 5 and (not sc.people or len(people) == 5)
    for d in draws:
        assert all(0.5 <= p.speed <= 1.6 for p in d.people)
