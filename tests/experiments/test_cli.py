"""The dodt-nav command line: simulate output, and clean errors for user mistakes."""
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "experiments.cli", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=300)


def test_simulate_writes_depth_in_mm_color_truth_and_summary(tmp_path):
    out = tmp_path / "run"
    r = _cli("simulate", "wall_pass", "--seed", "1", "--out", str(out), "--duration", "0.5", "--save-every", "5")
    assert r.returncode == 0, r.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["seed"] == 1 and summary["frames_saved"] == 4  # frames 0, 5, 10, 15
    sensor = json.loads((out / "sensor.json").read_text())
    truth = json.loads((out / "ground_truth.json").read_text())
    assert [f["seq"] for f in sensor["frames"]] == [0, 5, 10, 15]
    assert sensor["intrinsics"]["fx"] == pytest.approx(387.1537)
    d = cv2.imread(str(out / sensor["frames"][-1]["depth"]), cv2.IMREAD_UNCHANGED)
    assert d.dtype == np.uint16 and d.shape == (480, 640)
    assert 500 < np.median(d[d > 0]) < 10000  # millimetres
    c = cv2.imread(str(out / sensor["frames"][-1]["color"]))
    assert c.shape == (480, 640, 3)
    seg = cv2.imread(str(out / "segmentation" / "000015.png"), cv2.IMREAD_UNCHANGED)
    ids = {o["id"] for o in truth["frames"][-1]["obstacles"]}
    assert ids == {1, 2, 3} and set(np.unique(seg)) - {0, 1} <= {i + 1 for i in ids}
    person = [o for o in truth["frames"][-1]["obstacles"] if o["kind"] == "person"][0]
    assert np.linalg.norm(person["velocity"]) == pytest.approx(1.0)
    assert "T_world_camera" in sensor["frames"][0] and "obstacles" not in sensor["frames"][0]


@pytest.mark.parametrize("args, fragment", [
    (["simulate", "no_such_scenario", "--out", "x"], "no_such_scenario: no such file, and not a shipped scenario"),
    (["simulate", "corridor", "--out", "x", "--save-every", "0"], "--save-every: must be >= 1"),
    (["validate", "BAD"], "BAD.toml: corridor.width: must be >= 1.0, got 0.5"),
    (["validate", "UNKNOWN"], "UNKNOWN.toml: drone.colour: unknown key"),
])
def test_user_mistakes_exit_2_with_one_line_and_no_traceback(tmp_path, args, fragment):
    (tmp_path / "BAD.toml").write_text("[corridor]\nwidth = 0.5\n")
    (tmp_path / "UNKNOWN.toml").write_text("[drone]\ncolour = 'red'\n")
    args = [a if a not in ("BAD", "UNKNOWN") else str(tmp_path / f"{a}.toml") for a in args]
    r = _cli(*args, cwd=tmp_path)
    assert r.returncode == 2
    assert fragment in r.stderr
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_scenarios_lists_every_shipped_scenario():
    r = _cli("scenarios")
    assert r.returncode == 0
    names = {line.split()[0] for line in r.stdout.splitlines()}
    assert {"corridor", "circles", "follow_person", "wall_pass", "partial_obstacle", "static_only"} <= names


def test_reproduce_options_reach_the_report(monkeypatch, tmp_path):
    """The command line hands its options to experiments.reproduce (the report itself: test_reproduce)."""
    import experiments.reproduce
    from experiments.cli import main

    from experiments.config import Settings

    calls = []
    monkeypatch.setattr(experiments.reproduce, "reproduce",
                        lambda out, quick, jobs, settings, planner, perception, shield:
                        calls.append((out, quick, jobs, settings, planner, perception, shield)))
    assert main(["reproduce", "--out", str(tmp_path / "rep"), "--quick", "--jobs", "1"]) == 0
    assert calls == [(tmp_path / "rep", True, 1, Settings(), None, (), False)]
    assert main(["reproduce", "--out", str(tmp_path / "rep"), "--set", "shield.a_brake=3.0"]) == 0
    assert calls[-1][3].assignments() == {"shield.a_brake": 3.0}
    near = str(Path(__file__).resolve().parents[2] / "examples" / "custom_perception.py") + ":NearDODT"
    assert main(["reproduce", "--out", str(tmp_path / "rep"), "--perception", near]) == 0
    assert calls[-1][5] == (near,)
    assert main(["reproduce", "--out", str(tmp_path / "rep"), "--perception", "oracle"]) == 2  # flown already
    assert main(["reproduce", "--out", str(tmp_path / "rep"), "--perception", "nowhere:Nothing"]) == 2


@pytest.mark.parametrize("renderer", ["gl", "pybullet", "egl", "tiny", None])
def test_sweep_renderer_option_reaches_every_episode(monkeypatch, tmp_path, renderer):
    """sweep --renderer sets EpisodeConfig.renderer, which every episode (in any worker) builds its world with."""
    from experiments import sweep
    from experiments.cli import main

    seen = []

    def fake(scenario, seeds, perception, out, jobs, dask_address, keep_logs, progress, cfg, settings=None, planner=None,
             shield=False):
        seen.append(cfg.renderer)
        return sweep.aggregate([], scenario, perception)

    monkeypatch.setattr(sweep, "run_sweep", fake)
    args = ["sweep", "corridor", "--seeds", "0:2", "--out", str(tmp_path)] + (["--renderer", renderer] if renderer else [])
    assert main(args) == 0
    assert seen == [renderer]


COMMANDS = ("run", "simulate", "perceive", "replay", "plot", "collisions", "sweep", "benchmark", "compare",
            "reproduce", "bench", "scenarios", "validate", "ceiling", "train-detector", "eval-detector", "pack-detector-data")


def test_every_command_is_listed_in_the_help(capsys):
    from experiments.cli import main

    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    assert "examples:" in out
    for name in COMMANDS:
        assert f"\n    {name} " in out


@pytest.mark.parametrize("command", COMMANDS)
def test_each_command_help_has_a_description_and_examples(capsys, command):
    from experiments.cli import main

    assert main([command, "--help"]) == 0
    out = capsys.readouterr().out
    usage, description = out.split("\n\n")[:2]
    assert usage.startswith(f"usage: dodt-nav {command}")
    assert len(description.split()) >= 20  # a paragraph, before the options
    examples = out.split("\nexamples:\n")[1].split("\n\n")[0].splitlines()
    assert 1 <= len(examples) <= 3 and all(line.startswith("  dodt-nav ") for line in examples)


@pytest.mark.parametrize("command", ["run", "sweep", "benchmark"])
def test_episode_commands_help_lists_modes_presets_and_the_planner(capsys, command):
    from dodt.presets import PRESETS
    from experiments.cli import main
    from experiments.registry import DEFAULT_PLANNER, known_modes

    assert main([command, "--help"]) == 0
    epilog = capsys.readouterr().out.split("\nexamples:\n")[1]
    listed = " ".join(epilog.split())  # names wrapped over lines
    for name in known_modes() + tuple(PRESETS):
        assert f" {name}," in listed or f" {name} " in listed or listed.endswith(f" {name}")
    assert f"built-in planners (--planner): {DEFAULT_PLANNER} (" in listed and ", nmpc (" in listed


# An option of `bench` and a bench it does not apply to, with the benches it does.
BENCH_MISFITS = [
    ("perception", ["--scenario", "corridor"], "sim, runtime, planner, loop"),
    ("perception", ["--seconds", "3"], "sim, runtime, loop"),
    ("sim", ["--out", "OUT"], "perception"),
    ("sim", ["--seeds", "2"], "perception, planner"),
    ("runtime", ["--scenarios", "circles"], "perception"),
    ("loop", ["--configs", "dodt"], "perception"),
    ("sim", ["--duration", "2"], "perception"),
    ("sim", ["--quick"], "perception"),
    ("runtime", ["--rates", "15"], "perception"),
    ("sim", ["--config", "oracle"], "runtime, planner, loop"),
    ("runtime", ["--frames", "5"], "sim"),
    ("perception", ["--json", "OUT.json"], "sim, runtime, planner"),
    ("sim", ["--renderer", "tiny"], "loop"),
    ("sim", ["--rig", "lidar"], "perception, runtime, loop"),
    ("planner", ["--split", "test"], "perception"),
]


@pytest.mark.parametrize("what, option, benches", BENCH_MISFITS, ids=[f"{c[0]} {c[1][0]}" for c in BENCH_MISFITS])
def test_bench_refuses_an_option_that_does_not_apply_to_it(monkeypatch, tmp_path, capsys, what, option, benches):
    import experiments.commands.bench as bench
    from experiments.cli import main

    def ran(*a, **k):
        raise AssertionError("the bench started")

    monkeypatch.setattr(bench, "load_scenario", ran)
    option = [a.replace("OUT", str(tmp_path / "out")) for a in option]
    assert main(["bench", what, *option]) == 2
    err = capsys.readouterr().err
    assert err == f"dodt-nav: error: bench {what}: {option[0]} applies only to bench {benches}\n"
    assert not (tmp_path / "out").exists() and not (tmp_path / "out.json").exists()


@pytest.mark.parametrize("what, names", [("runtime", "a DODT configuration"), ("loop", "unknown mode"),
                                          ("planner", "unknown mode")])
def test_bench_refuses_an_unknown_config_before_it_starts(monkeypatch, capsys, what, names):
    """--config names a DODT configuration (runtime) or a perception mode (loop, planner): a file name
    there is one line on stderr and exit 2, not a traceback from deep inside the bench."""
    import experiments.commands.bench as bench
    from experiments.cli import main

    def ran(*a, **k):
        raise AssertionError("the bench started")

    monkeypatch.setattr(bench, "load_scenario", ran)
    assert main(["bench", what, "--config", "mine.toml"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"dodt-nav: error: bench {what}: --config") and "mine.toml" in err and names in err
    assert len(err.strip().splitlines()) == 1


def test_bench_takes_the_options_of_its_bench_and_fills_in_the_defaults():
    from experiments.cli import build_parser
    from experiments.commands.bench import check_applies

    args = build_parser().parse_args(["bench", "loop", "--seconds", "5", "--renderer", "tiny"])
    check_applies(args)
    assert (args.seconds, args.renderer, args.scenario, args.config) == (5.0, "tiny", "corridor", "dodt")
    args = build_parser().parse_args(["bench", "perception", "--quick", "--seeds", "2"])
    check_applies(args)
    assert (args.quick, args.seeds, args.out, args.duration) == (True, 2, "runs/bench_perception", None)


@pytest.mark.parametrize("split, seeds", [([], [0, 1, 2]), (["--split", "test"], [1000, 1001, 1002])])
def test_bench_perception_runs_the_seeds_of_its_split(monkeypatch, tmp_path, split, seeds):
    import experiments.bench_perception as bp
    from experiments.cli import main

    got = {}
    monkeypatch.setattr(bp, "run", lambda out, seeds, *a, **k: got.setdefault("seeds", seeds))
    assert main(["bench", "perception", "--seeds", "3", *split, "--configs", "dodt", "--scenarios", "circles",
                 "--out", str(tmp_path / "out")]) == 0
    assert got["seeds"] == seeds


def test_version_prints_the_package_version(capsys):
    import importlib.metadata

    from experiments.cli import main

    assert main(["--version"]) == 0
    assert capsys.readouterr().out == f"dodt-nav {importlib.metadata.version('dodt-nav')}\n"


def test_version_from_a_source_tree_that_was_never_installed(monkeypatch, capsys):
    import importlib.metadata

    from experiments.cli import main

    def missing(name):
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(importlib.metadata, "version", missing)
    assert main(["--version"]) == 0
    assert capsys.readouterr().out == "dodt-nav unknown (not installed)\n"
