"""The tracker's physical bounds (track.max_speed, track.jump_margin, track.camera_body_radius):
no track faster than a person, no prediction running away from its last measurement, a jump
re-initialises the track, nothing passes through the camera."""
import dataclasses

import numpy as np
import pytest

from dodt.config import DODTConfig, TrackConfig
from dodt.detection import Detection
from dodt.tracker import Tracker

FPS = 30.0
SIZE = np.array([0.5, 0.5, 1.7])
CAMERA = np.array([0.0, 0.0, 1.2])


def det(center, size=SIZE, seed=0) -> Detection:
    c = np.asarray(center, float)
    s = np.asarray(size, float)
    pts = c + (np.random.default_rng(seed).random((60, 3)) - 0.5) * s
    return Detection(center=c.copy(), size=s.copy(), source="dbscan", points=pts.astype(np.float32))


def with_track(**track) -> DODTConfig:
    return DODTConfig(track=dataclasses.replace(TrackConfig(), **track))


def step(tracker: Tracker, k: int, dets, pairs=None, camera=CAMERA) -> None:
    """One frame as DODT.process runs it; ``pairs`` forces the association."""
    if k:
        tracker.predict(1 / FPS)
    if pairs is None:
        pairs = tracker.associate(dets, camera)
    tracker.correct(dets, pairs, k, k / FPS, camera)


@pytest.mark.parametrize("max_speed", [2.5, None])
def test_no_track_is_reported_faster_than_a_person(max_speed):
    """A box stepping 0.2 m a frame (6 m/s at 30 Hz): bounded, the filter's state and every report
    stay at most track.max_speed; unbounded (None), the filter follows the box."""
    tracker = Tracker(with_track(max_speed=max_speed))
    speeds, state = [], []
    for k in range(20):
        step(tracker, k, [det((3.0, -2.0 + 0.2 * k, 0.9), seed=k)], pairs=[(0, 0)] if k else [])
        o = tracker.tracks[0].output(k / FPS)
        speeds += [float(np.hypot(*o.velocity[:2])), float(np.hypot(*o.filter_velocity[:2]))]
        state.append(float(np.hypot(*tracker.tracks[0].kf.velocity)))
    assert len(tracker.tracks) == 1 and tracker.restarts == 0
    if max_speed is None:
        assert max(state) > 4.0
    else:
        assert max(speeds) <= max_speed + 1e-9 and max(state) <= max_speed + 1e-9
        assert max(state) > 0.9 * max_speed  # bounded, not zeroed
        assert tracker.tracks[0].filter_speed > 4.0  # what the filter said before the bound


@pytest.mark.parametrize("max_speed", [2.5, None])
def test_a_coasting_prediction_stays_within_max_speed_of_its_last_measurement(max_speed):
    """A hidden velocity of 10 m/s and an acceleration in the state: the prediction moves at most
    max_speed x the time since the last measurement away from where it was measured."""
    tracker = Tracker(with_track(max_speed=max_speed))
    step(tracker, 0, [det((3.0, 0.0, 0.9))])
    tr = tracker.tracks[0]
    tr.kf.x[2:4] = (0.0, 10.0)
    tr.kf.x[4:6] = (0.0, 5.0)
    seen = tr.kf.position.copy()
    far = 0.0
    for k in range(1, 10):
        step(tracker, k, [], camera=None)
        moved = float(np.hypot(*(tracker.tracks[0].kf.position - seen)))
        far = max(far, moved)
        if max_speed is not None:
            assert tracker.tracks[0].coasting and moved <= max_speed * k / FPS + 1e-9
            assert np.hypot(*tracker.tracks[0].kf.velocity) <= max_speed + 1e-9
    if max_speed is None:
        assert far > 2.5  # unbounded, it runs 10 m/s x 0.3 s and more
    else:
        assert far > 0.9 * max_speed * 9 / FPS


@pytest.mark.parametrize("jump_margin", [0.4, None])
def test_a_track_whose_centre_jumps_is_reinitialised(jump_margin):
    """A still box matched next frame to a detection 1.6 m away (a static track matched to a new
    obstacle): re-initialised there, with no velocity, a fresh history and age, under a new id.
    Without the rule the filter takes the jump for tens of m/s."""
    tracker = Tracker(with_track(jump_margin=jump_margin))
    for k in range(10):
        step(tracker, k, [det((3.0, 0.0, 0.9), seed=k)], pairs=[(0, 0)] if k else [])
    tid = tracker.tracks[0].id
    step(tracker, 10, [det((3.0, 1.6, 0.9), seed=10)], pairs=[(0, 0)])
    tr = tracker.tracks[0]
    o = tr.output(10 / FPS)
    assert len(tracker.tracks) == 1
    if jump_margin is None:
        assert o.id == tid and tracker.restarts == 0 and np.hypot(*tr.kf.velocity) > 2.0 and len(o.history) == 11
        return
    assert tracker.restarts == 1 and o.id != tid
    np.testing.assert_allclose(o.center[:2], tr.kf.position + tr.offset)
    assert abs(o.center[1] - 1.6) < 0.1
    assert np.all(o.velocity == 0) and np.all(tr.kf.velocity == 0)
    assert o.age == 0 and len(o.history) == 1 and len(tr.observations) == 1
    # the next frame measures from the new place: no velocity from the jump
    step(tracker, 11, [det((3.0, 1.6, 0.9), seed=11)], pairs=[(0, 0)])
    assert np.hypot(*tracker.tracks[0].kf.velocity) < 1.0  # the points' noise over one frame, no more


def test_a_walker_and_a_box_growing_into_view_are_no_jump():
    """A person walking at 2 m/s, and a wall whose box centre moves 0.5 m as it grows from 1 m to
    2 m wide, are updated, not re-initialised; a missed frame widens the reach by max_speed x dt."""
    tracker = Tracker(DODTConfig())
    for k in range(20):
        step(tracker, k, [det((3.0, -1.0 + 2.0 * k / FPS, 0.9), seed=k)], pairs=[(0, 0)] if k else [])
    wall = Tracker(DODTConfig())
    step(wall, 0, [det((4.0, 0.0, 1.0), size=(0.3, 1.0, 2.0))])
    step(wall, 1, [det((4.0, 0.5, 1.0), size=(0.3, 2.0, 2.0), seed=1)], pairs=[(0, 0)])
    assert tracker.restarts == 0 and wall.restarts == 0
    # 0.9 m after 10 frames missed: within 2.5 m/s x 1/3 s + 0.4 + 0.25
    tr = tracker.tracks[0]
    last = tr.last_center.copy()
    for k in range(20, 30):
        step(tracker, k, [], camera=None)
    step(tracker, 30, [det((last[0], last[1] + 0.9, 0.9), seed=30)], pairs=[(0, 0)])
    assert tracker.restarts == 0


@pytest.mark.parametrize("radius", [0.3, None])
def test_a_coasting_track_is_not_predicted_through_the_camera(radius):
    """A track coasting straight at the camera at 2 m/s stops short of its body (radius plus its
    half width) and loses its velocity toward the camera; without the rule it passes through."""
    tracker = Tracker(with_track(camera_body_radius=radius))
    step(tracker, 0, [det((1.2, 0.0, 0.9))])
    tracker.tracks[0].kf.x[2:4] = (-2.0, 0.0)
    nearest = np.inf
    for k in range(1, 25):
        step(tracker, k, [])
        tr = tracker.tracks[0]
        nearest = min(nearest, float(np.hypot(*(tr.center_xy - CAMERA[:2]))))
    if radius is None:
        assert nearest < 0.1
        return
    assert nearest >= radius + tr.half_width - 1e-9
    assert tr.coasting and abs(tr.kf.velocity[0]) < 1e-9
    assert tr.output(24 / FPS).center[0] > 0  # never behind the camera


def test_a_track_passing_beside_the_camera_keeps_going_and_one_held_slides_past():
    """Coasting past the camera 1 m to its side is no hold; coasting across its body keeps the
    velocity along the body's edge, none toward the camera."""
    beside = Tracker(DODTConfig())
    step(beside, 0, [det((0.5, -1.0, 0.9))])
    beside.tracks[0].kf.x[2:4] = (-1.5, 0.0)
    for k in range(1, 29):
        step(beside, k, [])
    assert beside.tracks[0].center_xy[0] < -0.8  # went on past the camera's side
    across = Tracker(DODTConfig())
    step(across, 0, [det((0.3, -1.0, 0.9))])
    across.tracks[0].kf.x[2:4] = (0.0, 2.0)
    for k in range(1, 15):
        step(across, k, [])
        tr = across.tracks[0]
        c = tr.center_xy - CAMERA[:2]
        assert np.hypot(*c) >= 0.3 + tr.half_width - 1e-9
    assert float(tr.kf.velocity @ (c / np.hypot(*c))) >= -1e-9  # nothing toward the camera
    assert np.hypot(*tr.kf.velocity) > 0.1  # still sliding along


@pytest.mark.parametrize("clearance", [0.2, None])
def test_a_coasting_track_is_not_predicted_through_a_wall(clearance):
    """A track coasting at 1.5 m/s along x and 1 m/s toward the wall at y = 2 (the geofence's side) stops
    short of it by the clearance at most one frame's step past, loses its velocity into the wall and
    keeps going along it; without the rule (or without a geofence) it passes through."""
    tracker = Tracker(with_track(wall_clearance=clearance))
    tracker.walls = (np.array([0.0, -2.0]), np.array([16.0, 2.0]))
    step(tracker, 0, [det((4.0, 1.2, 0.9))])
    tracker.tracks[0].kf.x[2:4] = (1.5, 1.0)
    farthest = -np.inf
    for k in range(1, 25):
        step(tracker, k, [])
        tr = tracker.tracks[0]
        farthest = max(farthest, float(tr.center_xy[1]))
    if clearance is None:
        assert farthest > 2.0
        return
    assert farthest < 2.0 - clearance + 1.0 / FPS + 1e-9  # at most one step past the clearance
    assert abs(tr.kf.velocity[1]) < 1e-9 and tr.kf.velocity[0] > 1.0  # sliding along the wall
    assert tr.center_xy[0] > 4.5


def test_a_track_measured_at_a_wall_is_not_held():
    """A static piece of wall (centre on the geofence's side, no velocity) is tracked where it is measured."""
    tracker = Tracker(DODTConfig())
    tracker.walls = (np.array([0.0, -2.0]), np.array([16.0, 2.0]))
    for k in range(5):
        step(tracker, k, [det((6.0, 2.0, 0.9), size=(1.0, 0.1, 1.7))])
    assert tracker.tracks[0].center_xy[1] == pytest.approx(2.0, abs=0.05)


@pytest.mark.parametrize("radius", [0.25, None])
def test_a_track_beside_one_measured_now_is_the_same_obstacle_and_dropped(radius):
    """Two tracks on one walker, which take its boxes in turn: the one left without a detection while the
    other, 0.15 m from it, was measured is dropped (track.duplicate_radius), not coasted off the walker.
    A dynamic track beside a measured static one is kept (its label is the walker's), and so is a track
    farther than the radius (two people side by side)."""
    tracker = Tracker(with_track(duplicate_radius=radius))
    step(tracker, 0, [det([3.0, 0.0, 0.85]), det([3.15, 0.0, 0.85], seed=1), det([3.0, 0.6, 0.85], seed=2)],
         pairs=[])
    a, b, far = tracker.tracks
    step(tracker, 1, [det([3.15, 0.0, 0.85], seed=3), det([3.0, 0.6, 0.85], seed=4)], pairs=[(1, 0), (2, 1)])
    ids = {t.id for t in tracker.tracks}
    assert {b.id, far.id} <= ids
    assert (a.id in ids) == (radius is None)
    assert tracker.duplicates_dropped == (0 if radius is None else 1)
    dyn = Tracker(with_track(duplicate_radius=radius))
    step(dyn, 0, [det([3.0, 0.0, 0.85]), det([3.15, 0.0, 0.85], seed=1)], pairs=[])
    dyn.tracks[0].geometric_dynamic = True
    step(dyn, 1, [det([3.15, 0.0, 0.85], seed=3)], pairs=[(1, 0)])
    assert len(dyn.tracks) == 2, "a dynamic track is not dropped for a static one"
