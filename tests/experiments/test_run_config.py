"""--config FILE.toml and --set section.key=value: parsing, checks, and what reaches the episode."""
import gzip
import json
import pickle

import pytest

from experiments.cli import main
from experiments.config import ConfigError, Settings
from experiments.registry import configured, make_perception, make_planner
from experiments.registry import settings_for as build


def test_file_then_sets_in_order_last_wins(tmp_path):
    f = tmp_path / "c.toml"
    f.write_text('[shield]\na_brake = 3.0\n[navigator.mpc]\nhorizon = 30\n[dodt.kalman]\nq_pos = 0.02\n')
    s = build(f, ["shield.a_brake=2.5", "navigator.block_times=[0.0, 1.0]", "episode.static_map=truth"])
    assert s.assignments() == {"episode.static_map": "truth", "shield.a_brake": 2.5, "navigator.mpc.horizon": 30,
                               "navigator.block_times": [0.0, 1.0], "dodt.kalman.q_pos": 0.02}
    assert pickle.loads(pickle.dumps(s)) == s and s == build(f, ["shield.a_brake=2.5", "navigator.block_times=[0.0, 1.0]",
                                                                "episode.static_map=truth"])
    assert not build(None, []) and Settings() == build(None, [])


def test_sections_apply_to_their_configurations():
    from experiments.episode_config import EpisodeConfig
    from planner.map.voxel_map import MapConfig

    s = build(None, ["shield.a_brake=3", "navigator.mpc.horizon=30", "navigator.cruise_speed=1.2", "map.p_hit=0.75",
                     "dodt.kalman.q_pos=0.02", "dodt.ensemble.detectors=[\"udepth\"]", "episode.plan_rate=5",
                     "episode.duration=none"])
    p = make_planner("default", 0.43, s)
    assert p.cfg.a_brake == 3.0 and isinstance(p.cfg.a_brake, float) and p.cfg.drone_radius == 0.43
    assert p.planner.cfg.mpc.horizon == 30 and p.planner.cfg.cruise_speed == 1.2 and p.planner.cfg.mpc.robot_radius == 0.43
    assert configured(s, "map", MapConfig()).p_hit == 0.75 and configured(s, "episode", EpisodeConfig()).plan_rate == 5.0
    d = make_perception("dodt-no-fat", settings=s).dodt.cfg
    assert d.kalman.q_pos == 0.02 and d.ensemble.detectors == ("udepth",) and d.association.method == "center"
    assert make_perception("dodt").dodt.cfg.kalman.q_pos != 0.02  # nothing leaks into the presets


def test_perception_sections_apply_on_top_of_each_modes_own():
    from dodt.config import MotionConfig
    from experiments.perception_modes import NOISY_ORACLE_VELOCITY_NOISE, OracleConfig

    s = build(None, ["dodt.motion.min_speed=0.7", "dodt.motion.height=[0.9, 2.4]", "oracle.max_range=8",
                     "oracle.accel_window=none"])
    assert make_perception("dodt", settings=s).dodt.cfg.motion == MotionConfig(min_speed=0.7, height=(0.9, 2.4))
    assert make_perception("dodt-no-coast", settings=s).dodt.cfg.motion.min_speed == 0.7
    oracle, noisy, around = (make_perception(m, settings=s) for m in ("oracle", "oracle-noisy", "oracle-360"))
    assert oracle.cfg == OracleConfig(max_range=8.0, accel_window=None) and oracle.name == "oracle"
    assert noisy.cfg.velocity_noise == NOISY_ORACLE_VELOCITY_NOISE and noisy.cfg.max_range == 8.0
    assert around.all_around and around.cfg.max_range == 8.0 and around.name == "oracle-360"
    quiet = build(None, ["oracle.velocity_noise=0.1"])
    assert make_perception("oracle-noisy", settings=quiet).cfg.velocity_noise == 0.1
    # nothing leaks into the modes' own configurations
    assert make_perception("oracle").cfg == OracleConfig() and make_perception("dodt").dodt.cfg.motion == MotionConfig()
    assert make_perception("oracle-noisy").cfg == OracleConfig(velocity_noise=NOISY_ORACLE_VELOCITY_NOISE)


@pytest.mark.parametrize("sets", [["dodt.motion.min_speed=3.0", "dodt.motion.max_speed=4.0"],
                                  ["dodt.motion.max_speed=4.0", "dodt.motion.min_speed=3.0"]])
def test_values_checked_together_can_be_set_in_any_order(sets):
    from dodt.presets import preset

    rule = configured(build(None, sets), "dodt", preset("dodt")).motion
    assert (rule.min_speed, rule.max_speed) == (3.0, 4.0)
    with pytest.raises(ConfigError, match=r"^dodt.motion.min_speed, dodt.motion.max_speed: motion: need"):
        build(None, ["dodt.motion.min_speed=3.0", "dodt.motion.max_speed=2.0"])


@pytest.mark.parametrize("sets, fragment", [
    (["shield.nope=1"], "shield.nope: unknown key; ShieldConfig has no field 'nope'"),
    (["navigator.mpc.horizon=2.5"], "navigator.mpc.horizon: expected a whole number, got 2.5"),
    (["navigator.mpc=3"], "navigator.mpc: is a section"),
    (["shield.a_brake=fast"], "shield.a_brake: expected a number, got 'fast'"),
    (["shield.speeds=1.0"], "shield.speeds: expected a list"),
    (["episode.static_map=xyz"], "episode.static_map: 'xyz' is not one of depth, truth"),
    (["planner.x=1"], "planner.x: the built-in planner 'default' declares no configuration"),
    (["dodt.kalman.q_pos=abc"], "dodt.kalman.q_pos: expected a number"),
    (["dodt.kalman.nope=1"], "dodt.kalman.nope: unknown key; KalmanConfig has no field 'nope'"),
    (["map.p_hit=2.0"], "map.p_hit: 2.0 is not a number in (0.5, 1)"),
    (["shield.a_brake"], "expected section.key=value"),
    (["navigator.mpc.horizon=30", "navigator.mpc=3"], "a key is a value or a section, not both"),
    (["dodt.motion.nope=1"], "dodt.motion.nope: unknown key; MotionConfig has no field 'nope'"),
    (["dodt.motion.min_speed=3.0"], "dodt.motion.min_speed: motion: need 0 <= min_speed <= max_speed"),
    (["dodt.motion.height=[2.0, 1.0]"], "dodt.motion.height: [2.0, 1.0] is not in increasing order"),
    (["dodt.motion.height=1.5"], "dodt.motion.height: expected a list"),
    (["dodt.motion.on_structure=2"], "dodt.motion.on_structure: 2.0 is not a number in [0, 1]"),
    (["moving_rule.min_speed=0.7"], "moving_rule.min_speed: the moving-track rule is DODT's motion label now"),
    (["oracle.max_range=0"], "oracle.max_range: 0.0 is not a number in (0, 100]"),
    (["oracle.noise_seed=1.5"], "oracle.noise_seed: expected a whole number, got 1.5"),
    (["oracle.all_around=true"], "oracle.all_around: unknown key; OracleConfig has no field 'all_around'"),
])
def test_bad_keys_and_values_are_one_line_errors(tmp_path, capsys, sets, fragment):
    with pytest.raises(ConfigError, match=None) as e:
        build(None, sets)
    assert fragment in str(e.value)
    rc = main(["run", "corridor", "--out", str(tmp_path / "o"), *[x for s in sets for x in ("--set", s)]])
    err = capsys.readouterr().err
    assert rc == 2 and fragment in err and err.count("\n") == 1 and "Traceback" not in err


@pytest.mark.parametrize("text, fragment", [(None, "no such file"), ("[shield\n", "not valid TOML"),
                                            ("[shield]\nnope = 1\n", "shield.nope: unknown key")])
def test_bad_files_are_one_line_errors(tmp_path, capsys, text, fragment):
    f = tmp_path / "c.toml"
    if text is not None:
        f.write_text(text)
    rc = main(["sweep", "corridor", "--out", str(tmp_path / "o"), "--config", str(f)])
    err = capsys.readouterr().err
    assert rc == 2 and fragment in err and err.count("\n") == 1


@pytest.mark.parametrize("text, sets, message", [
    ("[navigator.mpc]\nhorizon = 2.5\n", [], "navigator.mpc.horizon: expected a whole number, got 2.5"),
    ("[shield]\nnope = 1\n", [], "shield.nope: unknown key; ShieldConfig has no field 'nope'"),
    ("[planner]\nx = 1\n", [], "planner.x: the built-in planner 'default' declares no configuration"),
    ("[dodt.kalman]\nq_pos = 'abc'\n", [], "dodt.kalman.q_pos: expected a number"),
    ("[dodt.motion]\nmin_speed = 3.0\n", ["dodt.motion.max_speed=2.0"],
     "dodt.motion.min_speed, dodt.motion.max_speed: motion: need 0 <= min_speed <= max_speed"),
    ("[episode]\nframe_latency = -1\n", [], "episode.frame_latency: -1 is not"),
], ids=["type", "unknown key", "unknown section", "dodt value", "checked together", "section"])
def test_an_error_in_the_config_file_starts_with_its_path(tmp_path, capsys, text, sets, message):
    f = tmp_path / "cfg.toml"
    f.write_text(text)
    with pytest.raises(ConfigError) as e:
        build(f, sets)
    assert str(e.value).startswith(f"{f}: {message}")
    rc = main(["run", "corridor", "--out", str(tmp_path / "o"), "--config", str(f),
               *[x for s in sets for x in ("--set", s)]])
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith(f"dodt-nav: error: {f}: {message}") and err.count("\n") == 1


def test_an_error_in_a_set_that_overrides_the_file_names_no_file(tmp_path):
    f = tmp_path / "cfg.toml"
    f.write_text("[navigator.mpc]\nhorizon = 2.5\n")
    with pytest.raises(ConfigError, match=r"^navigator.mpc.horizon: expected a whole number, got 3.5"):
        build(f, ["navigator.mpc.horizon=3.5"])
    f.write_text("[shield]\na_brake = 3.0\n")
    with pytest.raises(ConfigError, match=r"^shield.nope: unknown key"):
        build(f, ["shield.nope=1"])


def test_a_config_file_that_is_not_utf8_is_a_one_line_error(tmp_path, capsys):
    f = tmp_path / "cfg.toml"
    f.write_bytes("[shield]\na_brake = 3.0  # caf\u00e9\n".encode("latin-1"))
    rc = main(["run", "corridor", "--out", str(tmp_path / "o"), "--config", str(f)])
    err = capsys.readouterr().err
    assert rc == 2 and f"{f}: not a UTF-8 text file (byte 0xe9" in err and err.count("\n") == 1


def test_an_option_and_its_key_together_are_refused(tmp_path, capsys):
    rc = main(["run", "corridor", "--out", str(tmp_path / "o"), "--map", "truth", "--set", "episode.static_map=depth"])
    assert rc == 2 and "--map and episode.static_map" in capsys.readouterr().err


def test_run_records_the_effective_configuration(tmp_path):
    out = tmp_path / "o"
    rc = main(["run", "corridor", "--seed", "0", "--perception", "oracle", "--out", str(out), "--set",
               "episode.static_map=truth", "--set", "episode.duration=1.5", "--set", "shield.a_brake=3.0",
               "--set", "navigator.mpc.horizon=20", "--set", "map.p_hit=0.75", "--set", "oracle.max_range=6",
               "--set", "dodt.motion.min_speed=0.6"])
    assert rc == 0
    s = json.loads((out / "summary.json").read_text())
    c = s["config"]
    assert c["set"] == {"episode.static_map": "truth", "episode.duration": 1.5, "shield.a_brake": 3.0,
                        "navigator.mpc.horizon": 20, "map.p_hit": 0.75, "oracle.max_range": 6,
                        "dodt.motion.min_speed": 0.6}
    assert c["oracle"] == {"max_range": 6.0, "half_view": None, "memory": 1.0, "confirm_time": 0.0,
                           "accel_window": 0.1, "velocity_noise": 0.0, "noise_time": 0.5, "noise_seed": 0,
                           "line_of_sight": False}
    assert c["shield"]["a_brake"] == 3.0 and c["shield"]["drone_radius"] > 0 and "v_max" in c["shield"]
    assert c["navigator"]["mpc"]["horizon"] == 20 and "cruise_speed" in c["navigator"]
    assert c["map"]["p_hit"] == 0.75 and c["map"]["size"][0] > 15  # sized to the corridor, then overridden
    assert c["episode"]["duration"] == 1.5 and "dodt" not in c and s["static_map"] == "truth"  # set, not used
    assert s["sim_time"] == pytest.approx(1.5, abs=0.02)
    with gzip.open(out / "log.jsonl.gz", "rt") as fh:
        assert json.loads(fh.readline())["config"] == c


def test_a_sweep_folder_keeps_one_configuration(tmp_path, capsys):
    base = ["sweep", "corridor", "--seeds", "0", "--jobs", "1", "--quiet", "--perception", "oracle", "--map", "truth",
            "--out", str(tmp_path / "o")]
    assert main(base + ["--set", "episode.duration=1"]) == 0
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["config"]["set"] == {"episode.duration": 1} and summary["config"]["episode"]["duration"] == 1.0
    capsys.readouterr()
    assert main(base + ["--set", "episode.duration=1", "--set", "shield.a_brake=3.0"]) == 2
    assert "other configuration overrides" in capsys.readouterr().err


def test_a_dodt_run_records_its_dodt_section(tmp_path):
    out = tmp_path / "o"
    assert main(["run", "corridor", "--seed", "0", "--duration", "0.5", "--frame-latency", "0", "--out", str(out),
                 "--set", "dodt.motion.min_speed=0.6", "--set", "dodt.motion.height=[0.9, 2.4]"]) == 0
    c = json.loads((out / "summary.json").read_text())["config"]
    assert c["set"] == {"dodt.motion.min_speed": 0.6, "dodt.motion.height": [0.9, 2.4]}
    motion = c["dodt"]["motion"]
    assert motion["min_speed"] == 0.6 and motion["height"] == [0.9, 2.4]
    # every section the episode used, overridden or not, with its full values; none it did not use
    assert motion["max_speed"] == 2.5 and "oracle" not in c and c["dodt"]["kalman"]["q_pos"] > 0
    assert {"episode", "shield", "navigator", "map", "dodt"} <= set(c)
    with gzip.open(out / "log.jsonl.gz", "rt") as fh:
        assert json.loads(fh.readline())["config"] == c


def test_a_sweep_records_the_perception_sections(tmp_path):
    out = tmp_path / "o"
    assert main(["sweep", "corridor", "--seeds", "0", "--jobs", "1", "--quiet", "--perception", "oracle-noisy",
                 "--map", "truth", "--out", str(out), "--set", "episode.duration=1",
                 "--set", "oracle.memory=0.5"]) == 0
    c = json.loads((out / "summary.json").read_text())["config"]
    assert c["set"] == {"episode.duration": 1, "oracle.memory": 0.5}
    assert c["oracle"]["memory"] == 0.5 and c["oracle"]["velocity_noise"] == 0.3


@pytest.mark.parametrize("make, fragment", [
    (lambda d: "/dev/zero", "is not a regular file"),
    (lambda d: _write(d / "deep.toml", "a = " + "[" * 100_000 + "]" * 100_000), "nested too deep"),
    (lambda d: _write(d / "tables.toml", "[" + ".".join("t" * 1 for _ in range(12)) + "]\nx = 1\n"),
     "nested more than 8 deep"),
    (lambda d: _write(d / "big.toml", "# " + "x" * (1 << 20) + "\n"), "larger than 1 MiB"),
])
def test_hostile_config_files_are_one_line_errors(tmp_path, capsys, make, fragment):
    path = make(tmp_path)
    rc = main(["run", "corridor", "--out", str(tmp_path / "o"), "--config", str(path)])
    err = capsys.readouterr().err
    assert rc == 2 and fragment in err and err.count("\n") == 1


def _write(path, text):
    path.write_text(text)
    return path


def test_the_people_give_way_example_turns_the_walkers_other_futures_off():
    from pathlib import Path

    f = Path(__file__).resolve().parents[2] / "examples" / "people_give_way.toml"
    m = make_planner("default", 0.43, build(f, [])).planner.cfg.maneuvers
    assert (m.p_keep, m.p_turn, m.p_stop, m.worst_case) == (1.0, 0.0, 0.0, 0.0)
