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
    rc, rows, summary = _sweep(tmp_path, "--perception", spec, "--set", "episode.duration=1.0",
                               "--set", "perception.max_distance=2.5")
    assert rc == 0
    # its own configuration reached it and is recorded, with its name beside the spec
    assert all(r["config"]["perception"]["max_distance"] == 2.5 for r in rows)
    assert all(r["config"]["set"] == {"episode.duration": 1.0, "perception.max_distance": 2.5} for r in rows)
    assert {r["perception_name"] for r in rows} == {"dodt-near"}
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
    near.reach, near.half_view = 3.0, np.pi  # as reset(context) sets them from the camera and the config

    class Frame:
        T_world_camera = np.eye(4)

    assert [o.id for o in near.update(Frame()).obstacles] == [0]


def _load(name: str):
    import importlib.util

    spec = importlib.util.spec_from_file_location(f"{name}_example", EXAMPLES / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_examples_read_the_episode_context():
    """The planner example brakes for the static map the context holds and for people inside the camera's
    view; the perception example takes its reach and view from the context's camera."""
    import math
    from dataclasses import replace

    import numpy as np

    from context_factory import example_context
    from planner.types import ObstaclePrediction, PlannerInput
    from planner.map.voxel_map import MapConfig, VoxelMap

    planner = _load("custom_planner").StraightLine()
    vmap = VoxelMap(MapConfig(origin=(0.0, -2.0, 0.0), size=(10.0, 4.0, 3.0)))
    ctx = example_context(static_map=vmap)
    planner.reset(ctx)
    inp = PlannerInput(stamp=0.0, position=np.array([1.0, 0.0, 1.2]), velocity=np.zeros(3),
                       acceleration=np.zeros(3), goal=np.array([9.0, 0.0, 1.2]), obstacles=())
    assert planner.plan(inp).status == "straight"
    wall = np.zeros(tuple(vmap.dims), bool)
    wall[int(2.0 / vmap.res), :, :] = True  # a wall 1 m ahead, known to the context's map only
    vmap.set_known(wall)
    assert planner.plan(inp).status == "braking"
    vmap.set_known(np.zeros_like(wall))
    side = math.radians(60.0)  # a person 1 m away, 60 deg off the flight line: outside a 40 deg half view
    person = ObstaclePrediction(id=1, center=np.array([1.0 + math.cos(side), math.sin(side), 1.2]),
                                size=np.array([0.5, 0.5, 1.7]))
    assert planner.plan(replace(inp, obstacles=(person,))).status == "straight"
    ahead = replace(person, center=np.array([2.0, 0.1, 1.2]))
    assert planner.plan(replace(inp, obstacles=(ahead,))).status == "braking"

    near = _load("custom_perception").NearDODT(_load("custom_perception").NearConfig(max_distance=20.0))
    near.reset(ctx)
    assert near.reach == ctx.camera.max_depth == 10.0
    assert near.half_view == ctx.camera.half_view - near.cfg.view_margin


def test_the_plugins_run_in_run_and_benchmark_with_their_configuration(tmp_path):
    planner = f"{EXAMPLES / 'custom_planner.py'}:StraightLine"
    out = tmp_path / "run"
    rc = main(["run", "corridor", "--seed", "1", "--perception", "oracle", "--map", "truth", "--duration", "2",
               "--planner", planner, "--set", "planner.cruise_speed=0.5", "--shield", "--out", str(out)])
    s = json.loads((out / "summary.json").read_text())
    assert rc == 0 and s["planner"] == f"shield+{planner}" and s["config"]["planner"]["cruise_speed"] == 0.5
    assert "shield" in s["config"] and s["mean_speed"] <= 0.55
    perception = f"{EXAMPLES / 'custom_perception.py'}:NearDODT"
    bench = tmp_path / "bench"
    rc = main(["benchmark", "nav", "--split", "dev", "--seeds", "1", "--families", "static_clutter", "--people", "blind",
               "--perception", perception, "--planner", planner, "--set", "perception.max_distance=2.0",
               "--set", "planner.stop_distance=1.0", "--set", "episode.duration=1.0", "--frame-latency", "0",
               "--jobs", "1", "--quiet", "--out", str(bench)])
    assert rc == 0
    rows = [json.loads(line) for f in bench.rglob("results.jsonl") for line in f.read_text().splitlines()]
    assert len(rows) == 1 and rows[0]["config"]["perception"]["max_distance"] == 2.0
    assert rows[0]["config"]["planner"]["stop_distance"] == 1.0 and rows[0]["planner"] == planner


def test_a_plugin_setting_outside_its_range_is_one_line(tmp_path, capsys):
    planner = f"{EXAMPLES / 'custom_planner.py'}:StraightLine"
    rc = main(["run", "corridor", "--planner", planner, "--set", "planner.cruise_speed=30", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 2 and "planner.cruise_speed: 30.0 is outside [0.1, 3]" in err and err.count("\n") == 1
    rc = main(["run", "corridor", "--set", "planner.cruise_speed=0.5", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 2 and "declares no configuration" in err and err.count("\n") == 1
