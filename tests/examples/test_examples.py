"""The examples run through `dodt-nav sweep` as a user would run them: the rows record what flew."""
import json
from pathlib import Path

from experiments.cli import main

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def _sweep(tmp_path, *options):
    out = tmp_path / "sweep"
    rc = main(["sweep", "corridor", "--seeds", "0:2", "--jobs", "1", "--quiet", "--frame-latency", "0",
               "--out", str(out), *options])
    rows = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]
    return rc, rows, json.loads((out / "summary.json").read_text())


def test_custom_planner_flies_in_a_sweep(tmp_path):
    spec = f"{EXAMPLES / 'custom_planner.py'}:StraightLine"
    rc, rows, summary = _sweep(tmp_path, "--planner", spec, "--perception", "oracle", "--map", "truth",
                               "--set", "episode.duration=3")
    assert rc == 0
    assert sorted(r["seed"] for r in rows) == [0, 1] and summary["episodes"] == 2
    assert {r["planner"] for r in rows} == {spec} and summary["planner"] == spec
    assert all(r["planner_stats"]["plans"] == 30 and r["planner_stats"]["errors"] == 0 for r in rows)
    assert all(r["path_length"] > 1.0 for r in rows)  # it flew toward the goal


def test_custom_perception_flies_in_a_sweep(tmp_path):
    spec = f"{EXAMPLES / 'custom_perception.py'}:NearDODT"
    rc, rows, summary = _sweep(tmp_path, "--perception", spec, "--set", "episode.duration=1.0")
    assert rc == 0
    assert summary["episodes"] == 2 and summary["perception"] == spec and summary["planner"] == "PassiveSafetyShield"
    assert {r["perception"] for r in rows} == {spec}
    assert all(r["perception_stats"]["frames"] >= 29 and r["perception_stats"]["skipped"] == 0 for r in rows)


def test_near_dodt_drops_far_obstacles():
    import importlib.util

    import numpy as np

    from experiments.perception_modes import PerceptionOutput
    from planner.types import ObstaclePrediction

    spec = importlib.util.spec_from_file_location("custom_perception_example", EXAMPLES / "custom_perception.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    near = mod.NearDODT.__new__(mod.NearDODT)  # without DODT itself: its output is faked below

    class Fake:
        def update(self, frame):
            return PerceptionOutput(stamp=0.0, obstacles=tuple(
                ObstaclePrediction(id=i, center=np.array([x, 0.0, 1.0]), size=np.ones(3)) for i, x in enumerate((2, 5))))

    near.dodt = Fake()

    class Frame:
        T_world_camera = np.eye(4)

    assert [o.id for o in near.update(Frame()).obstacles] == [0]
