"""Hostile --set values and --config files, for every command that takes them: each configuration key
given values of the wrong type, not finite, out of its range; malformed assignments; configuration files
that are not text, not TOML, too large, too deep, or a device. Each is refused in one line naming the key
(or the file) before any work starts.

The keys come from experiments.config_limits.LIMITS (every key of the built-in sections); each key gets one
bad value, keys alike taking turns through the bad values of their kind, and the commands take turns so
that every command's path is tried.
"""
from __future__ import annotations

import pytest
from hostile_cli import assert_refused, cli, no_work  # noqa: F401 - no_work is a fixture

from experiments.config_limits import LIMITS, Limit


def _numbers(lim: Limit) -> list[str]:
    below = lim.lo - (1.0 if lim.integer else max(abs(lim.lo), 1.0)) if lim.lo is not None else None
    above = lim.hi * 10 + 1 if lim.hi is not None else None
    out = ["nan", "inf", "-inf", "1e308", "-1e308", '"abc"', "true", "{a = 1}"]
    out += [repr(int(below) if lim.integer else below), repr(int(above) if lim.integer else above)]
    if lim.integer:
        out.append(repr(float(lim.lo) + 0.5))
    if lim.lo_open:
        out.append(repr(lim.lo))
    return out


def _bad_values(lim: Limit) -> list[str]:
    if lim.kind == "bool":
        out = ["1", '"yes"', "nan", "[true]", "{a = true}"]
    elif lim.kind == "string":
        out = ["5", "nan", "[1, 2]", "true", "{a = 1}"] + (['"not-a-choice"', '""'] if lim.choices else [])
    else:
        out = _numbers(lim)
    if lim.length is not None:
        least, most = lim.length
        good = "0.5" if lim.kind == "number" else ('"x"' if lim.kind == "string" else "true")
        out = ["[" + ", ".join(["nan"] * max(least, 1)) + "]", "[" + ", ".join([good] * (most + 1)) + "]"] + \
            (["[]"] if least > 0 else []) + ["[[1.0]]", "5" if lim.kind != "number" else '"abc"']
    if lim.optional:
        out = [v for v in out if v != "none"]
    return out


COMMANDS = {
    "run": lambda out: ["run", "corridor", "--out", out],
    "sweep": lambda out: ["sweep", "corridor", "--out", out, "--seeds", "0:2", "--jobs", "1", "--quiet"],
    "benchmark": lambda out: ["benchmark", "nav", "--out", out, "--quick", "--quiet"],
    "reproduce": lambda out: ["reproduce", "--out", out, "--quick"],
}


def _set_cases() -> list[tuple[str, str, str, str]]:
    """(id, command, --set text, the key the error must name): one bad value per key. Keys whose values
    are alike (the same kind, the same list of bad values) take turns through that list, so every kind of
    bad value is tried; the commands take turns over all keys."""
    cases, turns = [], {}
    names = list(COMMANDS)
    for n, (key, lim) in enumerate(sorted(LIMITS.items())):
        values = _bad_values(lim)
        shape = (lim.kind, lim.integer, lim.lo_open, lim.length is not None, len(values))
        turn = turns[shape] = turns.get(shape, -1) + 1
        v = values[turn % len(values)]
        cmd = names[n % len(names)]
        if key.startswith("oracle.") and cmd == "reproduce":  # reproduce runs DODT and the oracle together
            cmd = names[0]
        cases.append((f"{cmd} {key}={v}", cmd, f"{key}={v}", key))
    return cases


SET_CASES = _set_cases()


def _extra(cmd: str, key: str) -> list[str]:
    """The options a key's section needs: the oracle's section exists with an oracle perception only."""
    if key.startswith("oracle.") and cmd in ("run", "sweep"):
        return ["--perception", "oracle"]
    if key.startswith("oracle.") and cmd == "benchmark":
        return ["--perception", "oracle"]
    return []


def test_the_set_corpus_covers_every_key():
    assert {c[3] for c in SET_CASES} == set(LIMITS)
    assert len({c[0] for c in SET_CASES}) == len(SET_CASES)


def test_the_set_corpus_tries_every_kind_of_bad_value_on_every_command():
    values = {c[2].split("=", 1)[1] for c in SET_CASES}
    for kind in ("nan", "inf", "-inf", "1e308", "-1e308", '"abc"', "true", "{a = 1}", "1", '"yes"', "[true]",
                 "{a = true}", "5", "[1, 2]", '"not-a-choice"', '""', "[]", "[[1.0]]"):
        assert kind in values, kind
    assert any(v.endswith(".5") for v in values)  # a fraction for a whole number
    assert any(v.startswith("[nan") for v in values)  # a list holding NaN
    assert {c[1] for c in SET_CASES} == set(COMMANDS)


@pytest.fixture(scope="module")
def outs(tmp_path_factory):
    """A folder for the output folders the --set cases name (each its own; none may be made)."""
    return tmp_path_factory.mktemp("set")


@pytest.mark.parametrize("case", SET_CASES, ids=[c[0] for c in SET_CASES])
def test_a_bad_set_value_is_one_line_naming_the_key(case, outs, capsys, no_work):
    _, cmd, assignment, key = case
    out = outs / f"out{SET_CASES.index(case)}"
    code, err, _ = cli(COMMANDS[cmd](str(out)) + _extra(cmd, key) + ["--set", assignment], capsys)
    assert_refused(code, err, key, status=2)
    assert not out.exists()


# --------------------------------------------------------------------------- malformed assignments

MALFORMED_SETS = [
    ("no equals", "shield.a_brake", "shield.a_brake"), ("empty", "", "--set"), ("only equals", "=", "--set"),
    ("no key", "=3", "--set"), ("no value", "shield.a_brake=", "shield.a_brake"),
    ("no section", "a_brake=3", "a_brake"), ("unknown section", "warp.speed=9", "warp"),
    ("unknown key", "shield.warp=1", "shield.warp"), ("section as value", "navigator.mpc=3", "navigator.mpc"),
    ("value as section", "shield.a_brake.x=3", "shield.a_brake"), ("deep key", "shield." + ".".join("a" * 20) + "=1",
                                                                       "shield"),
    ("long key", "shield." + "k" * 5000 + "=1", "shield"), ("long value", "episode.renderer=" + "x" * 100000, "renderer"),
    ("NUL in value", "episode.renderer=ti\x00ny", "NUL"), ("newline", "shield.a_brake=3\nshield.v_max=1",
                                                                           "line break"),
    ("toml table", "shield={a_brake = 3}", "shield"), ("unicode key", "shield.ä=1", "shield"),
    ("spaces", "shield . a_brake = nan", "a_brake"), ("huge int", "navigator.mpc.horizon=" + "9" * 5000,
                                                      "digits"),
    ("big int", "navigator.mpc.horizon=100000000", "navigator.mpc.horizon"),
    ("negative zero res", "map.resolution=-0.0", "map.resolution"), ("tiny res", "map.resolution=1e-9", "map.resolution"),
    ("huge map", "map.size=[1e9, 1e9, 1e9]", "map.size"), ("map 2d", "map.size=[10, 10]", "map.size"),
    ("seen band nan", "episode.seen_band=[nan, 1.0]", "episode.seen_band"),
    ("seen band reversed", "episode.seen_band=[2.0, 1.0]", "episode.seen_band"),
    ("latency", "episode.frame_latency=100000", "episode.frame_latency"),
    ("renderer", 'episode.renderer="vulkan"', "episode.renderer"),
    ("duration 0", "episode.duration=0", "episode.duration"), ("speeds empty", "shield.speeds=[]", "shield.speeds"),
    ("speeds nan", "shield.speeds=[nan]", "shield.speeds"), ("directions 0", "shield.directions=0", "shield.directions"),
    ("directions -3", "shield.directions=-3", "shield.directions"), ("shield dt 0", "shield.dt=0", "shield.dt"),
    ("a_brake 0", "shield.a_brake=0", "shield.a_brake"), ("a_brake -1", "shield.a_brake=-1", "shield.a_brake"),
    ("plan rate inf", "episode.plan_rate=inf", "episode.plan_rate"), ("memory inf", "shield.memory=inf", "shield.memory"),
    ("launch -1", "episode.launch_radius=-1", "episode.launch_radius"),
    ("q_pos nan", "dodt.kalman.q_pos=nan", "dodt.kalman.q_pos"), ("v_max nan", "shield.v_max=nan", "shield.v_max"),
    ("yaw rate nan", "episode.max_yaw_rate=nan", "episode.max_yaw_rate"),
    ("cruise nan", "navigator.cruise_speed=nan", "navigator.cruise_speed"),
    ("person speed nan", "shield.person_speed=nan", "shield.person_speed"),
    ("horizon -1", "navigator.mpc.horizon=-1", "navigator.mpc.horizon"),
    ("horizon 1e8", "navigator.mpc.horizon=100000000", "navigator.mpc.horizon"),
    ("planner section of the default", "planner.speed=1", "planner"),
    ("perception section of dodt", "perception.x=1", "perception"),
]


@pytest.mark.parametrize("case", MALFORMED_SETS, ids=[c[0] for c in MALFORMED_SETS])
@pytest.mark.parametrize("cmd", ["run", "sweep"])
def test_a_malformed_assignment_is_one_line(case, cmd, tmp_path, capsys, no_work):
    _, assignment, name = case
    code, err, _ = cli(COMMANDS[cmd](str(tmp_path / "out")) + ["--set", assignment], capsys)
    assert_refused(code, err, name, status=2)
    assert not (tmp_path / "out").exists()


def test_an_option_and_the_same_key_both_given_is_refused(tmp_path, capsys, no_work):
    code, err, _ = cli(COMMANDS["run"](str(tmp_path / "out")) + ["--frame-latency", "2", "--set",
                                                                    "episode.frame_latency=3"], capsys)
    assert_refused(code, err, "--frame-latency", status=2)


# --------------------------------------------------------------------------- --config files

def _config_files() -> list[tuple[str, bytes | str, str]]:
    """(id, the file's bytes or a path to use as it is, what the error names besides the file)."""
    ok = "[shield]\na_brake = 3.0\n"
    return [
        ("empty table of nothing known", "[warp]\nspeed = 1\n", "warp"),
        ("bad value", "[shield]\na_brake = nan\n", "shield.a_brake"),
        ("inf value", "[navigator.mpc]\nhorizon = inf\n", "navigator.mpc.horizon"),
        ("string for a number", '[map]\nresolution = "fine"\n', "map.resolution"),
        ("negative", "[episode]\nplan_rate = -5\n", "episode.plan_rate"),
        ("unknown key", "[shield]\nwarp = 1\n", "shield.warp"),
        ("value as section", "[shield.a_brake]\nx = 1\n", "shield.a_brake"),
        ("section as value", "[navigator]\nmpc = 1\n", "navigator.mpc"),
        ("top-level value", "a_brake = 3\n", "a_brake"),
        ("array of tables", "[[shield]]\na_brake = 3\n", "shield"),
        ("not TOML", "[shield\na_brake = 3\n", "not valid TOML"),
        ("duplicate key", ok + "a_brake = 4\n", "not valid TOML"),
        ("utf-16", ok.encode("utf-16"), "not a UTF-8 text file"),
        ("latin-1", "# caf\u00e9\n".encode("latin-1") + ok.encode(), "not a UTF-8 text file"),
        ("binary", bytes(range(256)) * 8, "not"),
        ("NUL", ok.encode() + b"\x00", "NUL"),
        ("deep tables", "[" + ".".join(["a"] * 50) + "]\nx = 1\n", "nested"),
        ("deep arrays", "x = " + "[" * 100000 + "]" * 100000 + "\n", "nested"),
        ("deep inline", "x = " + "{a = " * 3000 + "1" + "}" * 3000 + "\n", "nested"),
        ("2 MiB", ok + "# " + "x" * (2 << 20) + "\n", "larger than"),
        ("long integer", "[navigator.mpc]\nhorizon = " + "9" * 4000 + "\n", "navigator.mpc.horizon"),
        ("huge integer", "[navigator.mpc]\nhorizon = " + "9" * 5000 + "\n", "digits"),
        ("map size huge", "[map]\nsize = [1e9, 1e9, 1e9]\n", "map.size"),
        ("horizon 1e8", "[navigator.mpc]\nhorizon = 100000000\n", "navigator.mpc.horizon"),
        ("speeds empty", "[shield]\nspeeds = []\n", "shield.speeds"),
        ("seen band", "[episode]\nseen_band = [nan, 1.0]\n", "episode.seen_band"),
        ("latency", "[episode]\nframe_latency = 100000\n", "episode.frame_latency"),
        ("renderer", '[episode]\nrenderer = "vulkan"\n', "episode.renderer"),
        ("bool for a number", "[shield]\na_brake = true\n", "shield.a_brake"),
        ("table for a number", "[shield]\na_brake = {x = 1}\n", "shield.a_brake"),
        ("date for a number", "[shield]\na_brake = 1979-05-27\n", "shield.a_brake"),
        ("list for a number", "[shield]\na_brake = [1, 2]\n", "shield.a_brake"),
        ("many keys", "".join(f"[s{i}]\nx = 1\n" for i in range(3000)), "s0"),
    ]


CONFIG_FILES = _config_files()
CONFIG_PATHS = [("missing", "NOWHERE/c.toml", "no such file"), ("folder", "TMP", "folder"),
                ("dev zero", "/dev/zero", "not a regular file"), ("dev null", "/dev/null", "/dev/null"),
                ("proc", "/proc/self/mem", "/proc/self/mem"), ("empty name", "", "--config")]


# Each file is given to two commands, the commands taking turns over the files.
CONFIG_CASES = [(case, list(COMMANDS)[(i + j) % len(COMMANDS)]) for i, case in enumerate(CONFIG_FILES)
                for j in (0, 1)]


@pytest.mark.parametrize("case,cmd", CONFIG_CASES, ids=[f"{c[0]}-{cmd}" for c, cmd in CONFIG_CASES])
def test_a_bad_config_file_is_one_line_naming_it(case, cmd, tmp_path, capsys, no_work):
    _, data, name = case
    path = tmp_path / "c.toml"
    if isinstance(data, bytes):
        path.write_bytes(data)
    else:
        path.write_text(data)
    code, err, _ = cli(COMMANDS[cmd](str(tmp_path / "out")) + ["--config", path], capsys)
    assert_refused(code, err, name, status=2)
    assert str(path) in err or "--config" in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("case", CONFIG_PATHS, ids=[c[0] for c in CONFIG_PATHS])
@pytest.mark.parametrize("cmd", ["run", "sweep"])
def test_a_config_path_that_is_no_file_is_one_line(case, cmd, tmp_path, capsys, no_work):
    _, path, name = case
    path = path.replace("TMP", str(tmp_path)).replace("NOWHERE", str(tmp_path / "nowhere"))
    if path.startswith(("/dev", "/proc")) and not __import__("os").path.exists(path):
        pytest.skip(f"no {path} here")
    code, err, _ = cli(COMMANDS[cmd](str(tmp_path / "out")) + ["--config", path], capsys)
    assert_refused(code, err, name, status=2)
    assert not (tmp_path / "out").exists()


def test_the_settings_corpus_is_large():
    n = len(SET_CASES) + 2 * len(MALFORMED_SETS) + len(CONFIG_CASES) + 2 * len(CONFIG_PATHS)
    assert n >= 450
