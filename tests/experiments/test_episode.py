"""The closed loop: one short episode with a person crossing the drone's way."""
import json
from dataclasses import replace

import numpy as np
import pytest

from conftest import make_scenario
from experiments.episode import EpisodeConfig, run_episode
from experiments.episode_log import map_snapshots, read_log
from experiments.episode_metrics import summarize
from experiments.perception_modes import PerceptionOutput
from experiments.registry import make_perception
from planner.types import ObstaclePrediction

# A person walks across the corridor at x = 5 while the drone flies from x = 1 to x = 9: without
# avoidance the two meet (the person reaches the centre line about when the drone does).
CROSSING = """
[[people]]
behaviour = "crossing"
speed = 0.8
waypoints = [[5.0, 1.7], [5.0, -1.7]]
start_delay = 0.5
"""


def _scenario():
    return make_scenario(CROSSING)


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["dodt", "oracle"])
def test_crossing_person_episode_reaches_the_goal_without_collision(mode, tmp_path):
    s = run_episode(_scenario(), seed=0, perception=mode, out=tmp_path, cfg=EpisodeConfig(duration=14.0))
    assert s["reached_goal"], s
    assert not s["collided"], s["collisions"]
    assert s["success"]
    assert s["min_clearance"]["person"] > 0.0
    assert s["planner_stats"]["fallbacks"] == 0
    # The drone had to deal with the person: it was tracked as a moving obstacle at some point.
    recs = read_log(tmp_path / "log.jsonl.gz")
    plans = [p for p in recs if p["k"] == "plan"]
    assert any(p["n_obst"] > 0 for p in plans)
    # the shield says which discs it kept the plans from: the person's among them while reported
    assert all("threats" in p for p in plans) and any(len(p["threats"]) >= p["n_obst"] > 0 for p in plans)
    # Summary on disk = summary recomputed from the log (metrics come from the log alone).
    on_disk = json.loads((tmp_path / "summary.json").read_text())
    again = summarize(recs)
    for key in ("success", "collision_count", "time_to_goal", "path_length", "min_clearance", "mean_speed"):
        assert on_disk[key] == again[key]


class _Blind:
    """A perception plug-in that sees nothing: the interface a user's detector implements."""

    name = "blind"
    uses_ground_truth = False

    def reset(self):
        self.frames = 0

    def update(self, frame, truth=None):
        self.frames += 1
        return PerceptionOutput(stamp=frame.stamp, obstacles=())


class _Raising:
    """A planner plug-in that fails: the loop must brake and hold, not raise."""

    def reset(self):
        self.calls = 0

    def plan(self, inp):
        self.calls += 1
        self.geofence = inp.geofence
        raise RuntimeError("planner bug")


def test_foreign_perception_and_failing_planner_plug_in(tmp_path):
    perc, planner = _Blind(), _Raising()
    s = run_episode(make_scenario(), seed=0, perception=perc, planner=planner, out=tmp_path,
                    cfg=EpisodeConfig(duration=1.0))
    assert perc.frames >= 30 and planner.calls >= 10
    co = make_scenario().corridor  # the planner is told the corridor's walls
    np.testing.assert_allclose(np.concatenate(planner.geofence), [0.0, -co.width / 2, co.length, co.width / 2])
    assert s["planner_stats"]["errors"] == s["planner_stats"]["plans"] > 0
    assert not s["reached_goal"] and s["timeout"]
    recs = read_log(tmp_path / "log.jsonl.gz")
    states = [r for r in recs if r["k"] == "s"]
    start = np.array(make_scenario().drone.start)
    # Brake and hold at the start: the drone stays put.
    assert max(np.linalg.norm(np.array(r["p"]) - start) for r in states) < 0.1
    assert all("threats" not in r for r in recs if r["k"] == "plan")  # a plug-in planner says none


def test_same_seed_gives_the_same_episode():
    sc = make_scenario(CROSSING)
    a = run_episode(sc, seed=3, perception="oracle", cfg=EpisodeConfig(duration=2.0))
    b = run_episode(sc, seed=3, perception="oracle", cfg=EpisodeConfig(duration=2.0))
    a.pop("timing"), b.pop("timing")
    assert a == b
    # each summary says what computed it, since outcomes agree only within one environment
    env = a["environment"]
    assert env["packages"]["numpy"] == np.__version__ and env["renderer"] in ("gl", "pybullet", "tiny")
    assert env["cpu"] and env["python"].count(".") == 2


def test_rendering_beside_the_loop_changes_nothing_and_frames_are_logged_at_capture(tmp_path):
    """The default episode renders in a second process with one frame of latency: its log equals the
    one-process run's record for record, and each frame record carries its capture's stamp and pose."""
    sc = make_scenario(CROSSING)
    cfg = EpisodeConfig(duration=1.5, frame_latency=1)
    a = run_episode(sc, seed=3, perception="dodt", out=tmp_path / "a", cfg=replace(cfg, render_process=True))
    b = run_episode(sc, seed=3, perception="dodt", out=tmp_path / "b", cfg=replace(cfg, render_process=False))
    assert a["timing"]["renderer"].endswith("(render process)") and "process" not in b["timing"]["renderer"]
    # the wall times differ, and the header's configuration records render_process
    strip = lambda r: {k: v for k, v in r.items() if k not in ("perc_ms", "map_ms", "ms", "config")}  # noqa: E731
    ra, rb = read_log(tmp_path / "a" / "log.jsonl.gz"), read_log(tmp_path / "b" / "log.jsonl.gz")
    assert [strip(r) for r in ra] == [strip(r) for r in rb]
    assert ra[0]["frame_latency"] == 1 and a["frame_latency"] == 1
    frames = [r for r in ra if r["k"] == "f"]
    assert [f["t"] for f in frames[:3]] == [0.0, 0.0333, 0.0667] and frames[-1]["t"] == pytest.approx(1.5 - 1 / 30, abs=1e-3)
    st_t = np.array([r["t"] for r in ra if r["k"] == "s"])
    st_p = np.array([r["p"] for r in ra if r["k"] == "s"])
    for f in frames[1:]:  # the pose logged with a frame is the drone's at that frame's capture, not at arrival
        i = int(np.argmin(np.abs(st_t - f["t"])))
        assert np.allclose(f["p"], st_p[i], atol=2e-4) and abs(st_t[i] - f["t"]) < 1e-3
    assert not np.allclose(frames[-1]["p"], st_p[-1], atol=2e-4)  # the drone has moved on by the arrival


def test_obstacles_are_extrapolated_to_the_planning_time():
    from experiments.episode import _extrapolate

    o = ObstaclePrediction(id=1, center=np.array([1.0, 0.0, 0.9]), size=np.array([0.5, 0.5, 1.8]),
                           velocity=np.array([1.0, 0.0, 0.0]))
    (moved,) = _extrapolate((o,), stamp=2.0, now=2.5)
    np.testing.assert_allclose(moved.center, [1.5, 0.0, 0.9])
    assert moved.position_std == pytest.approx(o.std_growth * 0.5)


def test_known_static_map_renders_nothing_and_holds_the_geometry(tmp_path):
    """static_map="truth": the map is the scenario's geometry from the start, the oracle needs no images,
    so nothing is rendered; a DODT episode still renders (it needs the frames)."""
    sc = make_scenario(CROSSING + '\n[[obstacles]]\nkind = "box"\ncenter = [3.0, 1.2]\nsize = [0.6, 0.6, 1.6]\n')
    s = run_episode(sc, seed=0, perception="oracle", out=tmp_path, cfg=EpisodeConfig(duration=2.0, static_map="truth"))
    assert s["timing"]["renderer"] == "none" and s["static_map"] == "truth"
    recs = read_log(tmp_path / "log.jsonl.gz")
    assert recs[0]["static_map"] == "truth"
    maps = map_snapshots(recs)
    assert len(maps) == 1  # a known map never changes: one snapshot
    vox = maps[0][1]
    centres = recs[0]["map_origin"] + (vox + 0.5) * recs[0]["map_resolution"]
    in_box = np.all(np.abs(centres[:, :2] - [3.0, 1.2]) < 0.3, axis=1) & (centres[:, 2] < 1.6)
    assert in_box.sum() >= 25 * 14  # the box's footprint (6 x 6 columns, some halved) up to 1.6 m
    assert np.any(centres[:, 1] > sc.corridor.width / 2)  # the side wall
    assert not any(r["map_ms"] for r in recs if r["k"] == "f")  # no depth went into the map
    d = run_episode(sc, seed=0, perception="dodt", cfg=EpisodeConfig(duration=0.5, static_map="truth"))
    assert d["timing"]["renderer"] != "none"
    with pytest.raises(ValueError, match="static_map"):
        run_episode(sc, seed=0, perception="oracle", cfg=EpisodeConfig(duration=0.5, static_map="lidar"))


class _Looking(_Blind):
    """Records whether its frames carried colour; ``uses_color`` as given."""

    def __init__(self, uses_color):
        self.uses_color = uses_color
        self.colors = []

    def update(self, frame, truth=None):
        self.colors.append(frame.color is not None)
        return super().update(frame, truth)


@pytest.mark.parametrize("renderer", ["gl", pytest.param("tiny", marks=pytest.mark.slow)])
def test_frames_carry_colour_only_for_a_perception_that_reads_it(renderer):
    """A module declaring uses_color = False gets depth-only frames (the gl renderer then skips colour); one
    that reads colour, or does not say, gets it. EpisodeConfig.renderer picks the renderer."""
    from conftest import RENDERERS

    if renderer not in RENDERERS:
        pytest.skip(f"{renderer} not available here")
    cfg = EpisodeConfig(duration=0.3, renderer=renderer, render_process=False)
    for uses_color in (False, True):
        perc = _Looking(uses_color)
        s = run_episode(make_scenario(), seed=0, perception=perc, cfg=cfg)
        assert s["environment"]["renderer"] == renderer
        assert len(perc.colors) >= 8 and set(perc.colors) == {uses_color}
    silent = _Looking(True)
    del silent.uses_color  # says nothing: taken to read colour
    run_episode(make_scenario(), seed=0, perception=silent, cfg=cfg)
    assert all(silent.colors)
    watched = _Looking(False)  # a viewer (on_frame) may show the colour
    run_episode(make_scenario(), seed=0, perception=watched, cfg=cfg, on_frame=lambda view: None)
    assert all(watched.colors)
    from experiments.registry import make_perception

    assert make_perception("dodt").uses_color is False and make_perception("oracle").uses_color is False


def test_a_lidar_rig_episode_fuses_the_scans_and_says_its_rig(tmp_path):
    sc = make_scenario(CROSSING)
    seen = []

    class Spy:
        """DODT, counting the scans it is handed and keeping the context's sensors."""
        name = "spy"

        def __init__(self):
            self.inner = make_perception("dodt")
            self.scans = 0

        def reset(self, context):
            seen.extend(type(s).__name__ for s in context.sensors)
            self.inner.reset(context)

        def observe_lidar(self, scan):
            self.scans += 1
            self.inner.observe_lidar(scan)

        def update(self, frame, truth=None):
            return self.inner.update(frame, truth)

    spy = Spy()
    s = run_episode(sc, seed=3, perception=spy, cfg=EpisodeConfig(duration=1.5, rig="lidar"), out=tmp_path)
    assert s["rig"] == "lidar" and s["config"]["episode"]["rig"] == "lidar"
    assert seen == ["CameraSensor", "LidarSensor"]
    assert 14 <= spy.scans <= 16  # 10 Hz over 1.5 s
    header = read_log(tmp_path / "log.jsonl.gz")[0]
    assert header["rig"] == "lidar" and [x["kind"] for x in header["sensors"]] == ["rgbd", "lidar"]


def test_the_summary_times_how_soon_a_person_in_view_is_known_moving():
    """The oracle reports the crossing person at once from the first frame it is in the camera's view within
    5 m: one stretch, known moving at once. The figure comes from the log's frames, as the flight saw them."""
    s = run_episode(_scenario(), seed=0, perception="oracle", cfg=EpisodeConfig(duration=3.0))
    life = s["track_life"]
    assert life["moving_latency_n"] == 1 and life["moving_latencies"] == [0.0]
    assert life["moving_latency_unreported"] == 0
    blind = run_episode(_scenario(), seed=0, perception="static-only", cfg=EpisodeConfig(duration=3.0))
    assert blind["track_life"]["moving_latency_n"] == 0 and blind["track_life"]["moving_latency_unreported"] == 1
