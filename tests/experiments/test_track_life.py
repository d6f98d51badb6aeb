"""Track-life metrics (experiments.perception_metrics.TrackLife) on hand-made frames whose figures are
known by construction: in the perception benchmark's summary and in the closed-loop summary read
from an episode log."""
from types import SimpleNamespace

import numpy as np
import pytest

from dodt.frames import CameraIntrinsics
from experiments.episode_log import EpisodeLog
from experiments.episode_metrics import summarize, summarize_log
from experiments.perception_metrics import PerceptionMetrics, TrackLife
from sim.ground_truth import ObstacleTruth

FPS = 30.0
N = 61  # frames: 2 s at 30 Hz
DRONE = (0.0, 0.0, 1.2)
# people: 1 at 2 m, 2 at 3 m, 3 at 8 m (beyond the 5 m reach: not counted)
PEOPLE = {1: (2.0, 0.0), 2: (3.0, 1.0), 3: (8.0, 0.0)}


def scene(k: int) -> tuple[list, list]:
    """Frame k's tracks [(id, centre, velocity, dynamic)] and people [(id, centre)].

    Person 1: track 1 (dynamic) in frames 0-29, track 2 (dynamic) from 30 on: one identity switch, always
    reported and reported moving. Person 2: track 5 (static, reporting 3 m/s) in frames 0-44, then nothing.
    Person 3: never reported. Track 9: dynamic, 2 m from everyone, in frames 10-19 and 40-49 (two
    phantom-moving reports, 19 frame intervals of 1/30 s each in a row).
    """
    tracks = [(1 if k < 30 else 2, (2.1, 0.0, 0.9), (1.2, 0.0, 0.0), True)]
    if k < 45:
        tracks.append((5, (3.0, 1.2, 0.9), (0.0, 3.0, 0.0), False))
    if 10 <= k < 20 or 40 <= k < 50:
        tracks.append((9, (2.0, -2.0, 0.9), (0.5, 0.0, 0.0), True))
    people = [(pid, (x, y, 0.9)) for pid, (x, y) in PEOPLE.items()]
    return tracks, people


def expect(s: dict, rel: float = 1e-6) -> None:
    """``rel``: the tolerance of the figures made of time (a log rounds its stamps to 0.1 ms)."""
    assert s["continuity_frames"] == 2 * N
    assert s["continuity"] == pytest.approx((N + 45) / (2 * N))
    assert s["continuity_moving"] == pytest.approx(N / (2 * N))  # person 2's track is static
    assert s["track_id_switches"] == 1
    assert s["phantom_moving"] == 2
    assert s["phantom_moving_s"] == pytest.approx(18 / FPS, rel=rel)  # 9 intervals in each stretch
    assert s["phantom_moving_per_min"] == pytest.approx(2 / ((N - 1) / FPS / 60), rel=rel)
    assert s["drifted_moving"] == 0  # track 9 was never on a person
    assert s["max_reported_speed"] == pytest.approx(3.0)


def test_track_life_counts_known_by_construction():
    life = TrackLife()
    for k in range(N):
        tracks, people = scene(k)
        life.add(k / FPS, DRONE, tracks, people)
    expect(life.summary())
    both = TrackLife.combine([life, life]).summary()
    assert both["continuity"] == life.summary()["continuity"] and both["phantom_moving"] == 4
    assert both["phantom_moving_per_min"] == pytest.approx(life.summary()["phantom_moving_per_min"])
    empty = TrackLife().summary()
    assert empty["continuity"] is None and empty["phantom_moving_per_min"] is None


def test_a_person_reported_again_by_the_same_track_is_no_switch_and_a_nearer_one_takes_the_match():
    """Matching is one-to-one by nearest centres: of two tracks on a person, the nearer is matched; a
    person missed for a while and found again by the same id has not switched."""
    life = TrackLife()
    person = [(1, (2.0, 0.0, 0.9))]
    life.add(0.0, DRONE, [(4, (2.05, 0.0, 0.9), (0, 0, 0), True), (7, (2.3, 0.0, 0.9), (0, 0, 0), True)], person)
    life.add(0.1, DRONE, [], person)
    life.add(0.2, DRONE, [(4, (2.1, 0.0, 0.9), (0, 0, 0), False)], person)
    s = life.summary()
    assert s["track_id_switches"] == 0 and s["continuity"] == pytest.approx(2 / 3)
    assert s["continuity_moving"] == pytest.approx(1 / 3) and s["phantom_moving"] == 0  # 7 lies 0.3 m off


def test_a_track_that_followed_a_person_and_drifted_off_is_drifted_not_phantom():
    """Track 4 follows the person, then its prediction runs on 1 m past them (a person lost, not one
    invented): one drifted-moving report. Track 6 appears 1 m from the person and was never on anyone:
    one phantom-moving report. Both count the same way again once they are back on and off."""
    life = TrackLife()
    person = [(1, (2.0, 0.0, 0.9))]
    on, off = (2.05, 0.0, 0.9), (3.0, 0.0, 0.9)
    frames = [[(4, on, (1, 0, 0), True)], [(4, off, (1, 0, 0), True), (6, (2.0, 1.0, 0.9), (1, 0, 0), True)],
              [(4, off, (1, 0, 0), True), (6, (2.0, 1.0, 0.9), (1, 0, 0), True)],
              [(4, on, (1, 0, 0), True)], [(4, off, (1, 0, 0), True)]]
    for k, tracks in enumerate(frames):
        life.add(0.1 * k, DRONE, tracks, person)
    s = life.summary()
    assert s["phantom_moving"] == 1 and s["phantom_moving_s"] == pytest.approx(0.1)
    assert s["drifted_moving"] == 2 and s["drifted_moving_s"] == pytest.approx(0.1)
    assert s["drifted_moving_per_min"] == pytest.approx(2 / (0.4 / 60))
    assert TrackLife.combine([life, life]).summary()["drifted_moving"] == 4


def test_the_benchmark_summary_has_the_track_life_figures():
    T = np.eye(4)
    T[:3, 3] = DRONE
    m = PerceptionMetrics()
    for k in range(N):
        tracks, people = scene(k)
        obstacles = tuple(SimpleNamespace(id=i, center=np.array(c), velocity=np.array(v), dynamic=d)
                          for i, c, v, d in tracks)
        truth_people = [ObstacleTruth(pid, "person", "person", np.array(c) - (0.2, 0.2, 0.9),
                                      np.array(c) + (0.2, 0.2, 0.9), np.zeros(3)) for pid, c in people]
        result = SimpleNamespace(obstacles=obstacles, dynamic=tuple(o for o in obstacles if o.dynamic))
        m.add(result, SimpleNamespace(obstacles=tuple(truth_people), T_world_camera=T, segmentation=None,
                                      stamp=k / FPS), CameraIntrinsics())
    expect(m.summary())
    expect(PerceptionMetrics.combine([m]))


def _log_records():
    yield {"k": "header", "scenario": "s", "seed": 0, "perception": "dodt", "planner": "P", "people": []}
    for k in range(N):
        tracks, people = scene(k)
        yield {"k": "f", "t": round(k / FPS, 4), "p": list(DRONE), "perc_ms": 1.0, "map_ms": None, "skipped": None,
               "tracks": [{"id": i, "center": list(c), "size": [0.5, 0.5, 1.7], "velocity": list(v), "dynamic": d,
                           "coasting": False} for i, c, v, d in tracks],
               "people": [{"id": pid, "lo": [c[0] - 0.2, c[1] - 0.2, 0.0], "hi": [c[0] + 0.2, c[1] + 0.2, 1.8],
                           "v": [0.0, 0.0]} for pid, c in people]}
    yield {"k": "end", "t": N / FPS, "reason": "timeout", "reached_goal": False, "time_to_goal": None}


def test_the_closed_loop_summary_has_the_track_life_figures_from_the_log(tmp_path):
    with EpisodeLog(tmp_path / "log.jsonl.gz") as log:
        for r in _log_records():
            log.add(r)
    s = summarize_log(tmp_path / "log.jsonl.gz")
    assert s == summarize(_log_records())
    expect(s["track_life"], rel=1e-3)


def _view_records(sensors, yaw=0.0):
    """Drone at the origin facing +x (yaw 0), a 640 x 480 camera with fx 385 (half view 39.7 deg).
    Person 1 walks 2 m ahead, a dynamic track on it from frame 6 (0.2 s) on; person 2 walks 3 m behind, a
    dynamic track on it from frame 3; person 3 walks 4 m ahead, 1 m to the side (14 deg), only a static
    track on it; person 4 stands 2.5 m ahead, never reported."""
    yield {"k": "header", "scenario": "s", "seed": 0, "perception": "dodt", "planner": "P", "people": [],
           "sensors": sensors, "camera": {"width": 640, "height": 480, "fx": 385.0, "fy": 385.0, "cx": 320.0,
                                          "cy": 240.0}}
    people = {1: ((2.0, 0.0), (1.0, 0.0)), 2: ((-3.0, 0.0), (1.0, 0.0)), 3: ((4.0, 1.0), (0.0, 1.0)),
              4: ((2.5, 0.5), (0.0, 0.0))}
    for k in range(30):
        tracks = [(3, (4.0, 1.0, 0.9), False)]
        if k >= 6:
            tracks.append((1, (2.1, 0.0, 0.9), True))
        if k >= 3:
            tracks.append((2, (-3.1, 0.0, 0.9), True))
        yield {"k": "f", "t": round(k / FPS, 4), "p": [0.0, 0.0, 1.2], "R": _yaw(yaw), "perc_ms": 1.0,
               "map_ms": None, "skipped": None,
               "tracks": [{"id": i, "center": list(c), "size": [0.5, 0.5, 1.7], "velocity": [0.0, 0.0, 0.0],
                           "dynamic": d, "coasting": False} for i, c, d in tracks],
               "people": [{"id": pid, "lo": [x - 0.2, y - 0.2, 0.0], "hi": [x + 0.2, y + 0.2, 1.8], "v": list(v)}
                          for pid, ((x, y), v) in people.items()]}
    yield {"k": "end", "t": 1.0, "reason": "timeout", "reached_goal": False, "time_to_goal": None}


def _yaw(a):
    """A body rotation about z by ``a`` radians, row by row, as the log records it."""
    c, s = np.cos(a), np.sin(a)
    return [c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0]


def test_the_closed_loop_time_to_moving_counts_walkers_in_the_rigs_view():
    front = summarize(_view_records([{"name": "front", "kind": "rgbd", "yaw": 0.0}]))["track_life"]
    assert front["moving_latencies"] == pytest.approx([0.2])  # person 1; 2 is behind, 3 unreported, 4 stands
    assert front["moving_latency_n"] == 1 and front["moving_latency_unreported"] == 1
    back = summarize(_view_records([{"name": "back", "kind": "rgbd", "yaw": 180.0}]))["track_life"]
    assert back["moving_latencies"] == pytest.approx([0.1]) and back["moving_latency_unreported"] == 0
    turned = summarize(_view_records([{"name": "front", "kind": "rgbd", "yaw": 0.0}], yaw=np.pi))["track_life"]
    assert turned["moving_latencies"] == back["moving_latencies"]  # the drone turned round sees person 2
    lidar = summarize(_view_records([{"name": "front", "kind": "rgbd", "yaw": 0.0},
                                     {"name": "lidar", "kind": "lidar", "yaw": 0.0}]))["track_life"]
    assert sorted(lidar["moving_latencies"]) == pytest.approx([0.1, 0.2]) and lidar["moving_latency_unreported"] == 1
    assert lidar["moving_latency_median"] == pytest.approx(0.15)
