"""A generated corpus of malformed scenario files and command options: every one exits with status 2
and one line naming the file (or option) and the key, never a traceback, and nothing is run.

Scenario cases start from one valid scenario (``BASE``, every section present) and break one key in
one way: wrong type, NaN, infinities, huge, negative, empty, wrong length, a malformed range
(``{uniform = ...}``, ``{choice = ...}``, ``{same_as = ...}``); others break the file itself
(encodings, nesting, sizes and counts beyond the documented bounds). Option cases give each
numeric option of each command values out of its bounds. Most run in this process through
``experiments.cli.main`` (fast); a sample runs the real command in a subprocess.
"""
from __future__ import annotations

import copy
import json
import math
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from cli_in_process import run_main
from sim.scenario import MAX_OBSTACLES, MAX_PEOPLE, MAX_POINTS, parse_scenario

NAN, INF = math.nan, math.inf

BASE: dict[str, Any] = {
    "name": "base",
    "seed": 0,
    "duration": 10.0,
    "description": "every section of the format",
    "segmentation": False,
    "corridor": {"length": 15.0, "width": 4.0, "height": 3.0, "ceiling": False},
    "obstacles": [
        {"kind": "box", "center": [5.0, 1.2], "size": [0.8, 0.8, 1.0], "yaw_deg": 0.0, "color": [0.2, 0.4, 0.8]},
        {"kind": "pillar", "center": [10.0, -1.2], "radius": 0.25, "height": 2.0},
    ],
    "people": [
        {"behaviour": "waypoint_loop", "speed": 1.0, "start_delay": 0.0, "waypoints": [[2.0, -0.5], [8.0, -0.5]]},
        {"behaviour": "random_walk", "speed": 0.8, "region": [11.0, -1.0, 14.0, 1.0], "start": [12.0, 0.0]},
        {"behaviour": "circle", "speed": 0.7, "center": [7.5, 0.0], "radius": 0.6, "clockwise": False},
    ],
    "drone": {"start": [0.5, 0.0, 1.2], "goal": [14.5, 0.0, 1.2], "yaw_deg": 0.0, "cruise_speed": 1.0},
    "camera": {"width": 640, "height": 480, "fx": 387.0, "fy": 387.0, "cx": 320.0, "cy": 240.0, "min_range": 0.2,
               "max_range": 10.0, "mount_xyz": [0.065, 0.01, 0.12], "mount_rpy_deg": [0.0, 0.0, 0.0],
               "color": True, "renderer": "tiny"},
    "noise": {"enabled": True, "axial_model": "intel_rms", "baseline": 0.05, "subpixel": 0.08,
              "edge_threshold": 0.05, "edge_hole_prob": 0.4, "flying_pixel_prob": 0.3, "dropout": 0.005,
              "odom_position_std": 0.0, "odom_rotation_std": 0.0},
    "rates": {"physics": 240, "control": 120, "camera": 30},
    "crowd": {"sees_drone": False, "relaxation_time": 0.5, "strength": 2.1, "range": 0.3, "step_time": 1.0,
              "view_angle_deg": 100.0, "behind_weight": 0.5, "max_speed_factor": 1.3},
    "camera_path": {"mode": "carried", "keyframes": [[0.0, 1.0, 0.0, 1.2, 0.0], [5.0, 9.0, 0.0, 1.2, 0.0]]},
}


# --------------------------------------------------------------------------- writing TOML


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # JSON's escapes are TOML basic-string escapes
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(v)


def to_toml(data: dict) -> str:
    head, tables = [], []
    for k, v in data.items():
        if isinstance(v, dict):
            tables += [f"[{k}]"] + [f"{kk} = {_value(vv)}" for kk, vv in v.items()]
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            for item in v:
                tables += [f"[[{k}]]"] + [f"{kk} = {_value(vv)}" for kk, vv in item.items()]
        else:
            head.append(f"{k} = {_value(v)}")
    return "\n".join(head + tables) + "\n"


def _set(data: dict, path: str, value: Any) -> dict:
    """A copy of data with ``path`` (``people[0].speed``, ``obstacles[0].center[1]``) set to value."""
    data = copy.deepcopy(data)
    steps: list = []
    for part in path.split("."):
        name, idx = re.fullmatch(r"(\w+)((?:\[\d+\])*)", part).groups()
        steps += [name] + [int(i) for i in re.findall(r"\d+", idx)]
    node = data
    for s in steps[:-1]:
        node = node[s]
    node[steps[-1]] = copy.deepcopy(value)
    return data


def test_the_base_scenario_is_valid():
    sc = parse_scenario(to_toml(BASE), "base.toml")
    assert len(sc.people) == 3 and len(sc.obstacles) == 2 and sc.camera_path is not None


# --------------------------------------------------------------------------- the scenario corpus

WRONG_TYPES = ["abc", True, [1.0], {"a": 1}]
NONFINITE = [NAN, INF, -INF]
HUGE = [1e308, -1e308]

# key: (lo, hi): each value out of [lo, hi] is refused; None: no bound on that side.
NUMBERS = {
    "duration": (0.0, 3600.0), "corridor.length": (2.0, 200.0), "corridor.width": (1.0, 50.0),
    "corridor.height": (1.0, 20.0), "obstacles[0].yaw_deg": (-360.0, 360.0), "obstacles[1].radius": (0.02, 5.0),
    "obstacles[1].height": (0.05, 20.0), "people[0].speed": (0.5, 1.6), "people[0].height": (1.6, 1.85),
    "people[0].start_delay": (0.0, 3600.0), "people[2].radius": (0.3, 20.0), "drone.yaw_deg": (-360.0, 360.0),
    "drone.cruise_speed": (0.0, 5.0), "camera.fx": (1.0, 1e5), "camera.fy": (1.0, 1e5), "camera.cx": (0.0, 640.0),
    "camera.cy": (0.0, 480.0), "camera.min_range": (0.15, 5.0), "camera.max_range": (0.5, 100.0),
    "noise.baseline": (0.0, 1.0), "noise.subpixel": (0.0, 2.0), "noise.edge_threshold": (0.0, 10.0),
    "noise.edge_hole_prob": (0.0, 1.0), "noise.flying_pixel_prob": (0.0, 1.0), "noise.dropout": (0.0, 1.0),
    "noise.odom_position_std": (0.0, 1.0), "noise.odom_rotation_std": (0.0, 0.5),
    "crowd.relaxation_time": (0.05, 10.0), "crowd.strength": (0.0, 100.0), "crowd.range": (0.01, 5.0),
    "crowd.step_time": (0.0, 10.0), "crowd.view_angle_deg": (0.0, 180.0), "crowd.behind_weight": (0.0, 1.0),
    "crowd.max_speed_factor": (1.0, 3.0),
}
INTEGERS = {"seed": (0, None), "camera.width": (16, 4096), "camera.height": (16, 4096), "rates.physics": (60, 2000),
            "rates.control": (100, 2000), "rates.camera": (1, 120)}
VECTORS = {"obstacles[0].center": 2, "obstacles[0].size": 3, "obstacles[0].color": 3, "obstacles[1].center": 2,
           "people[1].region": 4, "people[1].start": 2, "people[2].center": 2, "people[0].color": 3,
           "drone.start": 3, "drone.goal": 3, "camera.mount_xyz": 3, "camera.mount_rpy_deg": 3}
POINTS = {"people[0].waypoints": 2, "camera_path.keyframes": 5}
STRINGS = {"name": None, "description": None, "obstacles[0].kind": "box", "people[0].behaviour": "waypoint_loop",
           "camera.renderer": "tiny", "noise.axial_model": "intel_rms", "camera_path.mode": "carried"}
BOOLEANS = ["segmentation", "corridor.ceiling", "camera.color", "noise.enabled", "people[2].clockwise",
            "people[0].sees_drone", "crowd.sees_drone"]
TABLES = ["corridor", "drone", "camera", "noise", "rates", "crowd", "camera_path"]
ARRAYS = ["obstacles", "people"]
RANGED = ["duration", "people[0].speed", "obstacles[0].center[0]", "camera.width", "drone.goal[2]",
          "crowd.strength"]
MALFORMED_RANGES = [
    {"uniform": [1.0, NAN]}, {"uniform": [-INF, 1.0]}, {"uniform": [2.0, 1.0]}, {"uniform": [0.0, 1e308]},
    {"uniform": "x"}, {"uniform": [1.0]}, {"uniform": [True, 1.0]}, {"uniform": []},
    {"choice": []}, {"choice": [[1.0]]}, {"choice": [NAN]}, {"choice": ["a"]}, {"choice": [1e308]},
    {"choice": list(range(101))}, {"same_as": "nowhere"}, {"same_as": 5}, {"same_as": "duration", "times": NAN},
    {"same_as": "duration", "plus": 1e308}, {"same_as": "name"}, {"uniform": [0.5, 1.6], "extra": 1},
]


def _out_of_bounds(lo, hi) -> list:
    out = []
    if lo is not None:
        out.append(lo - 1.0 if lo > -1e300 else -INF)  # negative / below
    if hi is not None:
        out.append(hi * 10 + 1.0)
    return out


def _key(path: str) -> str:
    """The key an error names: a list element's errors name the list (``obstacles[0].center``)."""
    return re.sub(r"\[\d+\]$", "", path) if "[" in path.split(".")[-1] else path


def _scenario_cases() -> list[tuple[str, dict | bytes, str]]:
    """(case id, scenario tables or raw file bytes, the key the error must name; '' for the file alone)."""
    cases: list[tuple[str, dict | bytes, str]] = []

    def add(path: str, value: Any, key: str | None = None, what: str = "") -> None:
        cases.append((f"{path}={what or _value(value)[:30]}", _set(BASE, path, value), key or path))

    for path, (lo, hi) in NUMBERS.items():
        for v in WRONG_TYPES + NONFINITE + HUGE + _out_of_bounds(lo, hi):
            add(path, v)
    for path, (lo, hi) in INTEGERS.items():
        for v in WRONG_TYPES + NONFINITE + HUGE + [1.5] + [int(x) for x in _out_of_bounds(lo, hi)]:
            add(path, v)
    add("seed", 2**63, what="2**63")  # beyond a TOML integer (tomllib reads it)
    add("seed", 10**400, what="10**400")
    for path, n in VECTORS.items():
        for v in ["abc", 5, [], [0.5] * (n - 1), [0.5] * (n + 1), [NAN] * n, [INF] * n, [-INF] * n, [1e308] * n,
                  [-1e308] * n, [1e8] * n, ["a"] * n, [True] * n, [[0.5]] * n]:
            add(path, v)
    for path, n in POINTS.items():
        line = [[2.0 + 0.05 * i, -0.5] if n == 2 else [0.1 * i, 1.0 + 0.05 * i, 0.0, 1.2, 0.0]
                for i in range(MAX_POINTS + 1)]
        for v in ["abc", [], [[NAN] * n, [1.0] * n], [[1e308] * n, [2.0] * n], [[1e8] * n, [2.0] * n],
                  [[2.0] * (n - 1), [3.0] * (n - 1)], [["a"] * n, ["b"] * n], [5, 6]]:
            add(path, v)
        add(path, line, what=f"{MAX_POINTS + 1} points")
    add("people[0].waypoints", [[1e8, -0.5], [2.0, -0.5]], what="1e8 first")  # the audit's: a 14.9 GiB path
    add("people[0].waypoints", [[2.0, -0.5], [1e308, -0.5]], what="1e308 last")  # the audit's: OverflowError
    for path, choice in STRINGS.items():
        for v in [5, True, [], {"a": 1}, NAN] + (["nonexistent", ""] if choice else []):
            add(path, v)
    for v in ["", "x" * 201, "a\nb", "tab\there"]:
        add("name", v, what=repr(v)[:20])
    for path in BOOLEANS:
        for v in ["yes", 1, NAN, [], {"a": 1}]:
            add(path, v)
    for path in TABLES:
        for v in [5, "x", [1, 2], True]:
            add(path, v)
    for path in ARRAYS:
        for v in [5, "x", {"a": 1}, [1, 2], [[1]]]:
            add(path, v)
    for path in TABLES + ["", "obstacles[0]", "people[0]"]:
        key = f"{path}.colour" if path else "colour"
        add(key, "red")
    for path in RANGED:
        for v in MALFORMED_RANGES:
            add(path, v, key=_key(path))
    # counts beyond the documented bounds
    box = {"kind": "box", "center": [7.0, 0.0], "size": [0.1, 0.1, 0.1]}
    cases.append(("obstacles x201", {**copy.deepcopy(BASE), "obstacles": [box] * (MAX_OBSTACLES + 1)}, "obstacles"))
    cases.append(("people x101", {**copy.deepcopy(BASE), "people": [BASE["people"][0]] * (MAX_PEOPLE + 1)}, "people"))
    cases.append(("people x1000", {**copy.deepcopy(BASE), "people": [BASE["people"][1]] * 1000}, "people"))
    # the file itself: encodings, structure, size
    text = to_toml(BASE)
    for name, data in [
        ("utf-16", text.encode("utf-16")), ("utf-16-le no BOM", text.encode("utf-16-le")),
        ("latin-1", text.replace("every section", "caf\u00e9").encode("latin-1")),
        ("binary", bytes(range(256)) * 4), ("NUL bytes", text.encode() + b"\x00\x00name = 1\n"),
        ("not TOML", b"[corridor\nlength = 15\n"), ("duplicate key", (text + "seed = 1\n").encode()),
        ("nested arrays", ("x = " + "[" * 5000 + "]" * 5000 + "\n").encode()),
        ("nested tables", ("x = " + "{a = " * 3000 + "1" + "}" * 3000 + "\n").encode()),
        ("2 MiB", (text + "# " + "x" * (2 << 20) + "\n").encode()),
    ]:
        cases.append((f"file: {name}", data, ""))
    many = text.replace("[[2.0, -0.5], [8.0, -0.5]]", "[" + ", ".join(
        f"[{2 + i * 1e-4:.5f}, -0.5]" for i in range(20_000)) + "]").encode()
    cases.append(("file: 20000 waypoints", many, "people[0].waypoints"))
    return cases


CASES = _scenario_cases()


def test_the_corpus_is_large():
    assert len(CASES) >= 150
    assert len({c[0] for c in CASES}) == len(CASES)  # ids unique


def _cli(args: list[str], capsys) -> tuple[int, str]:
    """main(args) in this process: (exit status, stderr). An exception escaping it fails the test (it
    would be a traceback)."""
    code = run_main(args)
    out = capsys.readouterr()
    return code, out.err


def _assert_one_line(code: int, err: str, *names: str) -> None:
    assert code == 2, (code, err)
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    for name in names:
        assert name in lines[0], (name, lines[0])
    assert len(lines[0]) < 1000, lines[0][:300]


@pytest.fixture(scope="module")
def case_dir(tmp_path_factory):
    """One folder for the scenario cases, each its own file and output name in it (a folder per case
    cost more than most cases)."""
    return tmp_path_factory.mktemp("malformed")


@pytest.mark.parametrize("case", range(len(CASES)), ids=[c[0] for c in CASES])
def test_a_malformed_scenario_exits_2_naming_the_file_and_key(case, case_dir, capsys):
    _, data, key = CASES[case]
    path = case_dir / f"case{case}.toml"
    if isinstance(data, bytes):
        path.write_bytes(data)
    else:
        path.write_text(to_toml(data))
    # the scenario is read by every command that takes one; validate, run and sweep take turns
    out = case_dir / f"out{case}"
    command = [["validate", str(path)],
               ["run", str(path), "--out", str(out), "--perception", "oracle"],
               ["sweep", str(path), "--out", str(out), "--seeds", "0:2", "--jobs", "1", "--quiet"]]
    code, err = _cli(command[case % 3], capsys)
    path.unlink()  # (the largest are megabytes)
    _assert_one_line(code, err, f"{path}: {key}" if key else str(path))
    assert not out.exists()  # refused before any work


@pytest.mark.parametrize("path", ["/dev/zero", "/dev/urandom", "/proc/self/mem", "/"])
def test_a_path_that_is_not_a_scenario_file_is_refused(path, capsys):
    """Read no further than a scenario file's bound, whatever the path (/dev/zero never ends)."""
    if not __import__("os").path.exists(path):
        pytest.skip(f"no {path} here")
    code, err = _cli(["validate", path], capsys)
    _assert_one_line(code, err, f"{path}: ")


def test_a_utf8_file_with_a_byte_order_mark_is_read(tmp_path, capsys):
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + to_toml(BASE).encode())
    code, err = _cli(["validate", str(path)], capsys)
    assert code == 0, err


def test_a_non_utf8_file_names_the_byte(tmp_path, capsys):
    path = tmp_path / "latin.toml"
    path.write_bytes(to_toml(BASE).replace("every section", "caf\u00e9").encode("latin-1"))
    code, err = _cli(["validate", str(path)], capsys)
    _assert_one_line(code, err, f"{path}: not a UTF-8 text file (byte ")


def test_a_waypoint_far_away_is_refused_at_once(tmp_path, capsys):
    """The audit's 1e8 m waypoint asked for a 14.9 GiB path sample; now its coordinate is refused."""
    for far in (1e8, 1e308):
        path = tmp_path / "far.toml"
        path.write_text(to_toml(_set(BASE, "people[0].waypoints", [[2.0, -0.5], [far, -0.5]])))
        code, err = _cli(["validate", str(path)], capsys)
        _assert_one_line(code, err, f"{path}: people[0].waypoints[1]: x must lie within +-1000")


# --------------------------------------------------------------------------- the option corpus

NUMBERS_BAD = ["nan", "inf", "-inf", "1e308", "abc", ""]


def _option_cases(tmp: str) -> list[tuple[str, list[str], str]]:
    """(case id, arguments, the option the error must name)."""
    sc = "corridor"
    out = f"{tmp}/out"
    cmds = {
        "run": ["run", sc, "--out", out, "--perception", "oracle"],
        "simulate": ["simulate", sc, "--out", out],
        "sweep": ["sweep", sc, "--out", out, "--perception", "oracle", "--seeds", "0:2", "--jobs", "1", "--quiet"],
        "benchmark": ["benchmark", "nav", "--out", out, "--quick", "--quiet"],
        "bench": ["bench", "sim", "--scenario", sc],
        "collisions": ["collisions", f"{tmp}/nothing"],
        "replay": ["replay", f"{tmp}/log.jsonl.gz"],
        "compare": ["compare", f"{tmp}/a", f"{tmp}/b"],
        "reproduce": ["reproduce", "--out", out],
        "train-detector": ["train-detector", "--data", f"{tmp}/data", "--out", out],
        "eval-detector": ["eval-detector", "--data", f"{tmp}/data"],
        "pack-detector-data": ["pack-detector-data", f"{tmp}/x.npz", "--out", f"{tmp}/x.packed"],
    }
    bad = {
        ("run", "--seed"): ["-1", "1.5", str(2**63), "abc", "", "1e3", "nan"],
        ("run", "--duration"): NUMBERS_BAD + ["-1", "0", "3601", "1e-400", "-0"],
        ("run", "--frame-latency"): ["-1", "101", "1.5", "abc"],
        ("run", "--map"): ["nowhere"], ("run", "--renderer"): ["vulkan"], ("run", "--viz"): ["3d"],
        ("run", "--perception"): ["telepathy"],
        ("simulate", "--seed"): ["-1", "abc"], ("simulate", "--duration"): NUMBERS_BAD + ["-5"],
        ("simulate", "--save-every"): ["0", "-1", "abc", "1e3"], ("simulate", "--renderer"): ["opengl"],
        ("sweep", "--perception"): ["telepathy", ""], ("sweep", "--map"): ["lidar"],
        ("benchmark", "--perception"): ["psychic"], ("benchmark", "--families"): ["nowhere", ","],
        ("benchmark", "--people"): ["deaf", ""], ("benchmark", "--frame-latency"): ["-2", "1e9"],
        ("sweep", "--seeds"): ["-1", "a:b", "5:5", "nan", "", "1e3", str(2**64), "0:2000000", "0:-5", "1,,x", "3:1"],
        ("sweep", "--jobs"): ["0", "-1", "257", "abc", "nan"],
        ("sweep", "--max-collision-rate"): ["nan", "inf", "2", "-0.1"],
        ("sweep", "--max-at-fault-rate"): ["nan", "-inf", "1.5"],
        ("sweep", "--frame-latency"): ["-1", "nan"],
        ("sweep", "--junit"): [f"{tmp}/no/such/folder/j.xml", tmp, "/proc/version/j.xml"],
        ("benchmark", "--seeds"): ["0", "1001", "nan", "-3"], ("benchmark", "--jobs"): ["0", "abc"],
        ("benchmark", "--split"): ["val"],
        ("bench", "--seconds"): NUMBERS_BAD + ["0", "-1"], ("bench", "--frames"): ["0", "-1", "abc"],
        ("bench", "--seeds"): ["0"], ("bench", "--duration"): ["nan", "0"],
        ("bench", "--json"): [f"{tmp}/no/such/folder/b.json", tmp],
        ("collisions", "--window"): ["nan", "inf", "0", "-1", "abc", "1e308"],
        ("replay", "--out"): [f"{tmp}/no/such/folder/r.html"],
        ("compare", "--fail-if-worse"): ["nan", "0", "2", "-1"],
        ("reproduce", "--jobs"): ["0", "nan", "-1", "1e9"], ("reproduce", "--out"): ["/proc/version/out"],
        ("train-detector", "--epochs"): ["0", "abc"], ("train-detector", "--lr"): ["nan", "0", "-1", "inf"],
        ("train-detector", "--warmup-epochs"): ["nan", "-1"], ("train-detector", "--batch-size"): ["1", "0"],
        ("train-detector", "--threads"): ["0"], ("train-detector", "--eval-every"): ["-1"],
        ("train-detector", "--images-per-seed"): ["0", "nan"], ("train-detector", "--seed"): ["-1"],
        ("eval-detector", "--max-distance"): ["nan", "0", "-1"], ("eval-detector", "--nms-iou"): ["nan", "0", "1.5"],
        ("eval-detector", "--score-floor"): ["nan", "1", "0"], ("eval-detector", "--soft-nms"): ["nan", "-1", "inf"],
        ("eval-detector", "--min-visible-px"): ["-1", "abc"],
        ("pack-detector-data", "--quality"): ["0", "102", "abc", "nan"],
    }
    cases = []
    for (cmd, option), values in bad.items():
        for v in values:
            cases.append((f"{cmd} {option} {v!r}", cmds[cmd] + [f"{option}={v}"], option))
    return cases


OPTION_CASES = _option_cases("TMP")


def test_the_option_corpus_is_large():
    assert len(OPTION_CASES) >= 150
    assert len({c[0] for c in OPTION_CASES}) == len(OPTION_CASES)


@pytest.mark.parametrize("case", range(len(OPTION_CASES)), ids=[c[0] for c in OPTION_CASES])
def test_a_bad_option_exits_2_naming_it_before_any_work(case, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _, args, option = OPTION_CASES[case]
    args = [a.replace("TMP", str(tmp_path)) for a in args]
    code, err = _cli(args, capsys)
    _assert_one_line(code, err, option)
    assert not (tmp_path / "out").exists()  # refused before any work


# --------------------------------------------------------------------------- the real command

def _installed_cases(tmp: Path) -> list[tuple[list[str], str]]:
    far, latin = tmp / "far.toml", tmp / "latin.toml"
    far.write_text(to_toml(_set(BASE, "people[0].waypoints", [[2.0, -0.5], [1e308, -0.5]])))
    latin.write_bytes(to_toml(BASE).replace("every section", "caf\u00e9").encode("latin-1"))
    out = str(tmp / "out")
    return [
        (["run", "corridor", "--out", out, "--seed", "-1"], "argument --seed: must be a seed, a whole number >= 0"),
        (["run", "corridor", "--out", out, "--duration", "nan"], "argument --duration: must be a number of seconds"),
        (["validate", str(far)], f"{far}: people[0].waypoints[1]: x must lie within +-1000"),
        (["validate", str(latin)], f"{latin}: not a UTF-8 text file"),
        (["sweep", "corridor", "--out", out, "--junit", str(tmp / "no/such/j.xml"), "--seeds", "0:2"],
         "--junit: cannot write"),
    ]


@pytest.mark.parametrize("case", range(5))
def test_the_installed_command_exits_2_with_one_line(tmp_path, case):
    args, fragment = _installed_cases(tmp_path)[case]
    r = subprocess.run([sys.executable, "-m", "experiments.cli", *args], capture_output=True, text=True, timeout=300)
    _assert_one_line(r.returncode, r.stderr, fragment)
    assert not (tmp_path / "out").exists()


def test_the_scenario_format_states_the_bounds():
    """The bounds the corpus tests are written where users read the format (README, "Scenario format")."""
    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    section = readme.split("## Scenario format", 1)[1].split("\n## ", 1)[0]
    for fragment in (f"{MAX_PEOPLE} people", f"{MAX_OBSTACLES} obstacles", "3600 s", "1000 m", "1 MiB",
                     f"{MAX_POINTS} waypoints"):
        assert fragment in section, fragment
