"""A planner or perception module that fails is seen: counted, its first traceback printed and kept in the
episode folder, `run` and `sweep` exit non-zero; malformed output is a counted error, not a crash."""
import json
import textwrap

import pytest

from experiments.cli import main

PLUGINS = textwrap.dedent('''
    import numpy as np
    from dodt.protocol import PerceptionOutput
    from planner.types import Trajectory

    class Raises:
        def reset(self): pass
        def plan(self, inp): raise RuntimeError("my planner is broken")

    class WrongShape:
        def reset(self): pass
        def plan(self, inp):
            return Trajectory(t0=inp.stamp, dt=0.1, positions=np.zeros((5, 2)), velocities=np.zeros((5, 3)),
                              accelerations=np.zeros((4, 3)))

    class NaNStep:
        def reset(self, context): pass
        def plan(self, inp):
            return Trajectory(t0=inp.stamp, dt=float("nan"), positions=np.zeros((2, 3)), velocities=np.zeros((2, 3)),
                              accelerations=np.zeros((1, 3)))

    class ResetRaises:
        def reset(self, context): raise KeyError("no such thing")
        def plan(self, inp): raise RuntimeError("unused")

    class Exits:
        def reset(self): pass
        def plan(self, inp): raise SystemExit(0)

    class PerceptionRaises:
        name = "broken-eyes"
        uses_images = False
        def reset(self): pass
        def update(self, frame, truth=None): raise ValueError("my perception is broken")

    class PerceptionNone:
        uses_images = False
        def reset(self): pass
        def update(self, frame, truth=None): return None

    class BadTracks:
        uses_images = False
        def reset(self): pass
        def update(self, frame, truth=None):
            return PerceptionOutput(stamp=frame.stamp, obstacles=(), tracks=({"id": 1, "center": "here"},))
''')


@pytest.fixture
def plugins(tmp_path, monkeypatch):
    (tmp_path / "broken_plugins.py").write_text(PLUGINS)
    monkeypatch.syspath_prepend(str(tmp_path))
    return "broken_plugins"


def _run(tmp_path, *options):
    out = tmp_path / "out"
    rc = main(["run", "corridor", "--seed", "0", "--duration", "1", "--map", "truth", "--perception", "oracle",
               "--out", str(out), *options])
    return rc, out, json.loads((out / "summary.json").read_text())


def test_a_planner_that_raises_is_shown_and_the_run_fails(plugins, tmp_path, capsys):
    rc, out, s = _run(tmp_path, "--planner", f"{plugins}:Raises")
    err = capsys.readouterr().err
    assert rc == 1
    assert err.count("RuntimeError: my planner is broken") == 1 and "Traceback" in err  # printed once
    e = s["module_errors"]["planner"]
    assert e["count"] == s["planner_stats"]["plans"] == 10 and e["kinds"] == {"RuntimeError": 10}
    assert "broken_plugins.py" in e["first"] and "my planner is broken" in (out / "errors.txt").read_text()
    assert s["planner_stats"]["errors"] == 10 and s["path_length"] < 0.3  # it braked and held


FAILURES = [  # (option, class, what the error says)
    ("--planner", "WrongShape", "Trajectory.positions (N+1, 3) with N = 4: wrong shape (5, 2)"),
    ("--planner", "NaNStep", "Trajectory.dt: expected a finite number, got nan"),
    ("--planner", "Exits", "SystemExit"),
    ("--planner", "ResetRaises", "KeyError: 'no such thing'"),
    ("--perception", "PerceptionRaises", "ValueError: my perception is broken"),
    ("--perception", "PerceptionNone", "update() returned NoneType, not a dodt.protocol.PerceptionOutput"),
    ("--perception", "BadTracks", "PerceptionOutput.tracks[0]: not a track"),
]


@pytest.mark.parametrize("option, cls, fragment", FAILURES)
def test_a_failing_or_malformed_module_is_a_counted_error(plugins, tmp_path, capsys, option, cls, fragment):
    """A planner's failure is a brake-and-hold plan; a perception module's, a skipped frame."""
    rc, out, s = _run(tmp_path, option, f"{plugins}:{cls}")
    module = option[2:]
    e = s["module_errors"][module]
    assert rc == 1 and fragment in e["first"] and fragment in capsys.readouterr().err
    if module == "planner":
        assert e["count"] - (cls == "ResetRaises") == s["planner_stats"]["plans"] == 10 and s["path_length"] < 0.3
    else:
        assert e["count"] == s["perception_stats"]["frames"] == s["perception_stats"]["skipped"] >= 29


def test_a_sweep_counts_and_lists_the_errored_episodes(plugins, tmp_path, capsys):
    out = tmp_path / "sweep"
    rc = main(["sweep", "corridor", "--seeds", "0:2", "--jobs", "1", "--quiet", "--map", "truth", "--perception",
               "oracle", "--set", "episode.duration=0.5", "--planner", f"{plugins}:Raises", "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 1 and "failed in 2 episodes (seeds 0, 1)" in err
    agg = json.loads((out / "summary.json").read_text())
    assert [e["seed"] for e in agg["module_errors"]] == [0, 1] and agg["module_errors"][0]["planner"] == 5
    assert "Episodes with planner or perception errors: 2 (seeds 0, 1" in (out / "summary.md").read_text()
    assert (out / "episodes" / "seed_0000" / "errors.txt").exists()


@pytest.mark.parametrize("assignment, fragment", [
    ("shield.a_brake=nan", "shield.a_brake: expected a finite number, got nan"),
    ("shield.a_brake=-1", "shield.a_brake: -1.0 is not a number in"),
    ("shield.a_brake=1e400", "shield.a_brake: expected a finite number, got inf"),
    ("episode.renderer=foo", "episode.renderer: 'foo' is not one of"),
    ("navigator.mpc.dt=0", "navigator.mpc.dt: 0.0 is not a number in"),
    ("navigator.mpc.horizon=0", "navigator.mpc.horizon: 0 is not"),
    ("episode.frame_latency=100000", "episode.frame_latency: 100000 is not"),
])
def test_bad_values_are_refused_before_the_run(tmp_path, capsys, assignment, fragment):
    rc = main(["run", "corridor", "--out", str(tmp_path / "o"), "--set", assignment])
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith(f"dodt-nav: error: {fragment}") and err.count("\n") == 1
    assert not (tmp_path / "o" / "summary.json").exists()


def test_a_summary_holds_the_whole_configuration_the_commit_and_the_timings(plugins, tmp_path):
    rc, out, s = _run(tmp_path, "--perception", f"{plugins}:PerceptionNone")
    c = s["config"]
    assert c["set"] == {} and {"episode", "shield", "navigator", "map"} <= set(c)
    assert c["episode"]["static_map"] == "truth" and c["navigator"]["mpc"]["horizon"] > 0
    assert s["source"]["version"] and "commit" in s["source"] and s["environment"]["packages"]
    t = s["timing"]
    assert {"wall_s", "startup_s", "compile_s", "loop_s", "real_time_factor"} <= set(t)
    assert 0 < t["loop_s"] <= t["wall_s"] and t["real_time_factor"] == pytest.approx(s["sim_time"] / t["loop_s"],
                                                                                       rel=0.05)
    assert s["perception_name"] == "PerceptionNone" and s["perception"] == f"{plugins}:PerceptionNone"


def test_a_plugin_name_is_recorded_beside_its_spec(plugins, tmp_path):
    rc, out, s = _run(tmp_path, "--perception", f"{plugins}:PerceptionRaises")
    assert s["perception_name"] == "broken-eyes" and s["perception"] == f"{plugins}:PerceptionRaises"


def test_a_benchmark_lists_the_failed_episodes_and_exits_1(plugins, tmp_path, capsys):
    out = tmp_path / "bench"
    rc = main(["benchmark", "nav", "--split", "dev", "--seeds", "1", "--families", "static_clutter", "--people",
               "blind", "--perception", "oracle", "--map", "truth", "--set", "episode.duration=0.5", "--jobs", "1",
               "--quiet", "--planner", f"{plugins}:Raises", "--out", str(out)])
    assert rc == 1 and "failed in 1 episodes" in capsys.readouterr().err
    assert "static_clutter / blind / oracle seed" in (out / "report.md").read_text()


def test_a_map_too_large_to_allocate_is_refused(tmp_path, capsys):
    rc = main(["run", "corridor", "--out", str(tmp_path / "o"), "--set", "map.size=[200, 200, 3]",
               "--set", "map.resolution=0.02"])
    err = capsys.readouterr().err
    assert rc == 2 and "voxels, more than 5e+07" in err and err.count("\n") == 1
