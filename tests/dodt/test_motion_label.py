"""dodt.motion_label: the last step of identification (tall tracks at walking speed are dynamic)."""
from dataclasses import replace
from functools import lru_cache
from types import SimpleNamespace

import numpy as np
import pytest

from dodt.config import IdentificationConfig, MotionConfig
from dodt.frames import CameraIntrinsics, SensorFrame
from dodt.motion_label import MotionLabel, person_tall
from dodt.pipeline import DODT
from dodt.presets import PRESETS, preset
from dodt.result import TrackedObstacle
from tests.dodt.synthetic import camera_pose, render_depth


def _track(coasting=False, speed=0.8, dynamic=False, size=(0.5, 0.5, 1.7), id=7, age=1.0, sensor=""):
    v = np.array([speed, 0.0, 0.0])
    return TrackedObstacle(id=id, center=np.array([3.0, 0.0, 0.85]), size=np.array(size), velocity=v,
                           acceleration=np.zeros(3), dynamic=dynamic, coasting=coasting, age=age,
                           history=np.zeros((0, 4)), filter_velocity=v, evidence="voting" if dynamic else "",
                           sensor=sensor)


def _label(cfg=MotionConfig()):
    """The label with a map that holds no structure anywhere."""
    label = MotionLabel(cfg)
    label.structure_test = lambda center, size: 0.0
    return label


def test_person_like_tracks_at_walking_speed_are_dynamic_by_motion():
    label = _label()
    out = label((_track(), _track(id=8, speed=0.2), _track(id=9, size=(2.5, 0.3, 1.7)), _track(id=10, age=0.1)))
    assert [(o.id, o.dynamic, o.evidence) for o in out] == [(7, True, "motion"), (8, False, ""), (9, False, ""),
                                                            (10, False, "")]
    assert label((_track(coasting=True, id=11),))[0].dynamic  # coasting too
    assert out[0].velocity[0] == pytest.approx(0.8)  # the filter's velocity, unchanged


def test_a_track_dynamic_once_stays_so_when_it_slows_down():
    """A walker slowing to turn or stop keeps the label (labelled by voting or by motion before); one never
    seen walking does not get it; the shape and top speed tests still apply."""
    label = _label()
    assert not label.moving(_track(speed=0.1))  # never seen walking
    assert label.moving(_track(speed=1.0))
    assert label.moving(_track(speed=0.1)) and label.moving(_track(speed=0.0))
    assert not label.moving(_track(speed=0.1, size=(2.5, 0.3, 1.7)))  # not a person's footprint
    assert not label.moving(_track(speed=3.0))  # faster than anyone walks
    label((_track(id=4, dynamic=True, speed=1.0),))  # voted dynamic
    slow = label((_track(id=4, speed=0.2),))[0]
    assert slow.dynamic and slow.evidence == "motion"
    label.reset()
    assert not label((_track(id=4, speed=0.2),))[0].dynamic


def test_a_voted_track_keeps_its_evidence():
    o = _label()((_track(dynamic=True),))[0]
    assert o.dynamic and o.evidence == "voting"


def test_a_track_once_seen_on_long_held_structure_is_never_dynamic_by_motion():
    label = MotionLabel(MotionConfig(on_structure=0.2))
    share = {"v": 0.0}
    label.structure_test = lambda c, s: share["v"]
    assert label.moving(_track())
    share["v"] = 0.5  # measured on a static obstacle's edge: dropped, and for good
    assert not label.moving(_track())
    share["v"] = 0.0
    assert not label.moving(_track(coasting=True)) and not label.moving(_track())


def test_tracks_report_the_sensor_that_measured_them_last():
    from tests.dodt.test_rig_fusion import run
    d = DODT(preset("dodt"))
    d.set_scene(lidar_elevation_min=np.radians(-7.0))
    res = run(d, 10, lambda t: (-2.5, 0.5))
    assert [o.sensor for o in res.obstacles] == ["lidar"]


def test_disabled_or_without_a_map_labels_nothing():
    assert not _label(MotionConfig(enabled=False))((_track(speed=1.0),))[0].dynamic
    assert not MotionLabel(MotionConfig())((_track(speed=1.0),))[0].dynamic


def _camera_frame():
    """A camera at (0, 0, 1.2) looking along +x, as a frame's pose and intrinsics."""
    return SimpleNamespace(T_world_camera=camera_pose(), intrinsics=CameraIntrinsics())


def _cut_person(distance, bottom_raise=0.0):
    """A track on a person whose near side is `distance` ahead of the camera, its box from the lowest
    height in view there (plus bottom_raise) up to 1.65 m."""
    k = CameraIntrinsics()
    low = max(1.2 - distance * (k.height - 1 - k.cy) / k.fy, 0.0) + bottom_raise
    return TrackedObstacle(id=8, center=np.array([distance + 0.15, 0.0, (low + 1.65) / 2]),
                           size=np.array([0.3, 0.5, 1.65 - low]), velocity=np.array([-0.9, 0.0, 0.0]),
                           acceleration=np.zeros(3), dynamic=False, coasting=False, age=1.0, history=np.zeros((0, 4)))


@pytest.mark.parametrize("distance", [0.6, 0.7, 0.8])
def test_a_near_person_cut_by_the_image_bottom_is_tall(distance):
    """Within a metre the camera sees a person from 0.6-0.8 m up only: the box is under the 1 m minimum but
    reaches the image's lower edge, so it is a person's (without the frame it fails the plain test). A box
    of the same top whose bottom is 0.3 m above that edge is not."""
    cfg, frame = MotionConfig(), _camera_frame()
    track = _cut_person(distance)
    assert track.size[2] < cfg.height[0]
    assert person_tall(track, cfg, frame) and not person_tall(track, cfg)
    assert not person_tall(_cut_person(distance, bottom_raise=0.3), cfg, frame)


def test_the_height_test_is_plain_for_whole_boxes():
    cfg, frame = MotionConfig(), _camera_frame()
    assert person_tall(_track(), cfg, frame)  # 1.7 m tall, 3 m ahead
    assert not person_tall(_track(size=(0.5, 0.5, 0.6)), cfg, frame)  # a short box 3 m ahead, floor in view
    assert not person_tall(_track(size=(0.5, 0.5, 2.6)), cfg, frame)  # taller than a person


NO_STRUCTURE = SimpleNamespace(established_fraction=lambda c, s: 0.0)


@lru_cache(maxsize=64)
def _walker_depth(i: int, y: float) -> np.ndarray:
    """Frame i's depth image of a person walking towards the camera at 1 m/s from 5 m, ``y`` to the side."""
    x = 5.0 - i / 30
    return render_depth(CameraIntrinsics(), camera_pose(), [((x - 0.25, y - 0.25, 0.0), (x + 0.25, y + 0.25, 1.7))])


def _walk(cfg, scene=NO_STRUCTURE, frames=15, y=0.0, geofence=None):
    """DODT on a synthetic person walking towards the camera at 1 m/s, ``y`` to the side: each frame's
    (dynamic, evidence)."""
    d = DODT(cfg)
    if scene is not None:
        d.set_scene(scene, geofence)
    K, T, out = CameraIntrinsics(), camera_pose(), []
    for i in range(frames):
        depth = _walker_depth(i, y)
        r = d.process(SensorFrame(depth=depth, color=None, intrinsics=K, T_world_camera=T, stamp=i / 30, seq=i))
        assert len(r.obstacles) == 1
        out.append((r.obstacles[0].dynamic, r.obstacles[0].evidence))
    return out


def test_dodt_labels_a_walker_the_vote_misses_dynamic_by_motion():
    """With the vote switched off (no speed reaches its threshold), the walker is dynamic by motion from
    min_age on; without the label, or without a map, it never is; on a map's long-held structure it is not."""
    no_vote = replace(preset("dodt"), identification=IdentificationConfig(velocity_threshold=10.0))
    labels = _walk(no_vote)
    first = labels.index((True, "motion"))
    assert 6 <= first <= 12 and all(lab == (True, "motion") for lab in labels[first:])
    assert not any(d for d, _ in _walk(replace(no_vote, motion=MotionConfig(enabled=False))))
    assert not any(d for d, _ in _walk(no_vote, scene=None))
    on_structure = SimpleNamespace(established_fraction=lambda c, s: 1.0)
    assert not any(d for d, _ in _walk(no_vote, scene=on_structure))
    assert _walk(preset("dodt"))[-1] == (True, "voting")
    walls = (np.array([0.0, -1.2]), np.array([16.0, 1.2]))
    assert _walk(no_vote, y=-0.5, geofence=walls)[-1] == (True, "motion")
    assert not any(d for d, _ in _walk(no_vote, y=-1.1, geofence=walls))  # centre 0.1 m off a wall


def test_the_baselines_do_without_the_motion_label():
    assert all(c.motion.enabled == n.startswith("dodt") for n, c in PRESETS.items())


def test_a_box_on_a_wall_of_the_geofence_is_never_dynamic_by_motion():
    """A box whose centre lies within wall_margin of the geofence's side (a wall fragment tracked moving
    along the wall) is never labelled, not even when later measured away from it; one 0.3 m off is."""
    label = _label()
    label.geofence = (np.array([0.0, -2.0]), np.array([16.0, 2.0]))
    on_wall = replace(_track(id=3), center=np.array([6.0, 1.9, 0.9]))
    assert not label.moving(on_wall) and not label.moving(replace(on_wall, center=np.array([6.0, 1.0, 0.9])))
    assert not label.moving(replace(_track(id=4), center=np.array([6.0, -2.3, 0.9])))  # beyond the wall
    assert label.moving(replace(_track(id=5), center=np.array([6.0, 1.7, 0.9])))
