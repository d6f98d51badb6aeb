"""--config FILE.toml and --set section.key=value: parsing, checks, and what reaches the episode."""
import gzip
import json
import pickle

import pytest

from experiments.cli import main
from experiments.config import ConfigError, Settings, build


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
    from experiments.episode import EpisodeConfig, default_planner
    from experiments.perception_modes import make_perception
    from planner.voxel_map import MapConfig

    s = build(None, ["shield.a_brake=3", "navigator.mpc.horizon=30", "navigator.cruise_speed=1.2", "map.p_hit=0.75",
                     "dodt.kalman.q_pos=0.02", "dodt.ensemble.detectors=[\"udepth\"]", "episode.plan_rate=5",
                     "episode.duration=none"])
    p = default_planner(0.43, s)
    assert p.cfg.a_brake == 3.0 and isinstance(p.cfg.a_brake, float) and p.cfg.drone_radius == 0.43
    assert p.planner.cfg.mpc.horizon == 30 and p.planner.cfg.cruise_speed == 1.2 and p.planner.cfg.mpc.robot_radius == 0.43
    assert s.map_config(MapConfig()).p_hit == 0.75 and s.episode_config(EpisodeConfig()).plan_rate == 5.0
    d = make_perception("dodt-no-fat", dodt_set=s.dodt_assignments()).dodt.cfg
    assert d.kalman.q_pos == 0.02 and d.ensemble.detectors == ("udepth",) and d.association.method == "center"
    assert make_perception("dodt").dodt.cfg.kalman.q_pos != 0.02  # nothing leaks into the presets


@pytest.mark.parametrize("sets, fragment", [
    (["shield.nope=1"], "shield.nope: unknown key; ShieldConfig has no field 'nope'"),
    (["navigator.mpc.horizon=2.5"], "navigator.mpc.horizon: expected a whole number, got 2.5"),
    (["navigator.mpc=3"], "navigator.mpc: is a section"),
    (["shield.a_brake=fast"], "shield.a_brake: expected a number, got 'fast'"),
    (["shield.speeds=1.0"], "shield.speeds: expected a list"),
    (["episode.static_map=xyz"], "episode.static_map: 'xyz' is not one of depth, truth"),
    (["planner.x=1"], "planner.x: unknown section 'planner'"),
    (["dodt.kalman.q_pos=abc"], "dodt.kalman.q_pos=abc: expected a number"),
    (["dodt.kalman.nope=1"], "dodt.kalman.nope: KalmanConfig has no field 'nope'"),
    (["map.p_hit=2.0"], "map.p_hit: MapConfig"),
    (["shield.a_brake"], "expected section.key=value"),
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


def test_an_option_and_its_key_together_are_refused(tmp_path, capsys):
    rc = main(["run", "corridor", "--out", str(tmp_path / "o"), "--map", "truth", "--set", "episode.static_map=depth"])
    assert rc == 2 and "--map and episode.static_map" in capsys.readouterr().err


def test_run_records_the_effective_configuration(tmp_path):
    out = tmp_path / "o"
    rc = main(["run", "corridor", "--seed", "0", "--perception", "oracle", "--out", str(out), "--set",
               "episode.static_map=truth", "--set", "episode.duration=1.5", "--set", "shield.a_brake=3.0",
               "--set", "navigator.mpc.horizon=20", "--set", "map.p_hit=0.75"])
    assert rc == 0
    s = json.loads((out / "summary.json").read_text())
    c = s["config"]
    assert c["set"] == {"episode.static_map": "truth", "episode.duration": 1.5, "shield.a_brake": 3.0,
                        "navigator.mpc.horizon": 20, "map.p_hit": 0.75}
    assert c["shield"]["a_brake"] == 3.0 and c["shield"]["drone_radius"] > 0 and "v_max" in c["shield"]
    assert c["navigator"]["mpc"]["horizon"] == 20 and "cruise_speed" in c["navigator"]
    assert c["map"]["p_hit"] == 0.75 and c["map"]["size"][0] > 15  # sized to the corridor, then overridden
    assert c["episode"]["duration"] == 1.5 and "dodt" not in c and s["static_map"] == "truth"
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
