"""DODT on a rig: LiDAR boxes and other cameras' detections join the first camera's in one tracker."""
import numpy as np

from dodt.frames import CameraIntrinsics, SensorFrame
from dodt.pipeline import DODT
from dodt.presets import preset
from tests.dodt.synthetic import camera_pose, render_depth
from tests.dodt.test_lidar_detector import column, floor, make_scan

K = CameraIntrinsics()
DT = 1 / 30


def frame(t, seq, boxes, yaw=0.0):
    T = camera_pose(yaw=yaw)
    return SensorFrame(depth=render_depth(K, T, boxes), color=None, intrinsics=K, T_world_camera=T, stamp=t, seq=seq)


def person_box(xy):
    return (np.array([xy[0] - 0.2, xy[1] - 0.2, 0.0]), np.array([xy[0] + 0.2, xy[1] + 0.2, 1.7]))


def run(dodt, n, behind_xy, ahead_box=None, lidar_every=3, camera_yaws=()):
    """n frames at 30 Hz; a person at behind_xy(t) (world), scanned by the LiDAR every lidar_every frames."""
    res = None
    for k in range(n):
        t = k * DT
        boxes = [] if ahead_box is None else [ahead_box]
        xy = behind_xy(t)
        if camera_yaws:
            dodt.observe_cameras([frame(t, k, boxes + [person_box(xy)], yaw) for yaw in camera_yaws])
        if lidar_every and k % lidar_every == 0:
            dodt.observe_lidar(make_scan(np.concatenate([column(xy, 1.0, 1.75, facing=(0.0, 0.0)), floor()]),
                                         sensor=(0.0, 0.0, 1.3)))
        res = dodt.process(frame(t, k, boxes))
    return res


def test_a_person_walking_behind_the_camera_is_tracked_moving_by_the_lidar():
    d = DODT(preset("dodt"))
    d.set_scene(lidar_elevation_min=np.radians(-7.0))
    res = run(d, 45, lambda t: (-2.5, -1.0 + 1.0 * t))
    near = [o for o in res.obstacles if np.hypot(o.center[0] + 2.5, o.center[1] - 0.5) < 0.3]
    assert len(near) == 1, [(o.center, o.dynamic) for o in res.obstacles]
    o = near[0]
    assert o.dynamic
    assert abs(o.velocity[1] - 1.0) < 0.3 and abs(o.velocity[0]) < 0.3
    assert o.center[2] - o.size[2] / 2 < 0.05  # extended to the floor
    assert res.timings_ms["lidar"] >= 0.0


def test_a_standing_person_behind_is_tracked_static_and_not_lost_between_scans():
    d = DODT(preset("dodt"))
    res = run(d, 45, lambda t: (-2.0, 0.5))
    near = [o for o in res.obstacles if np.hypot(o.center[0] + 2.0, o.center[1] - 0.5) < 0.3]
    assert len(near) == 1 and not near[0].dynamic


def test_a_lidar_box_where_the_camera_sees_the_obstacle_is_left_to_the_camera():
    d = DODT(preset("dodt"))
    box = person_box((3.0, 0.0))

    def scan_of_box(t):
        return (3.0, 0.0)
    res = run(d, 20, scan_of_box, ahead_box=box)
    near = [o for o in res.obstacles if np.hypot(o.center[0] - 3.0, o.center[1]) < 0.6]
    assert len(near) == 1, "one track, not one per sensor"
    assert res.detections["lidar"] == []


def test_without_other_sensors_the_pipeline_is_the_one_camera_pipeline():
    a, b = DODT(preset("dodt")), DODT(preset("dodt"))
    box = person_box((3.0, 0.0))
    for k in range(10):
        t = k * DT
        box_k = (box[0] + [0, 0.03 * k, 0], box[1] + [0, 0.03 * k, 0])
        ra, rb = a.process(frame(t, k, [box_k])), b.process(frame(t, k, [box_k]))
        assert [(o.id, o.center.tolist(), o.velocity.tolist(), o.dynamic) for o in ra.obstacles] == \
            [(o.id, o.center.tolist(), o.velocity.tolist(), o.dynamic) for o in rb.obstacles]
    assert ra.detections["lidar"] == [] and ra.detections["other_cameras"] == []


def test_a_back_camera_measures_a_person_walking_behind_as_the_front_one_would_ahead():
    back = DODT(preset("dodt"))
    res = run(back, 45, lambda t: (-3.0, -0.8 + 0.9 * t), lidar_every=0, camera_yaws=(np.pi,))
    y_end = -0.8 + 0.9 * 44 * DT
    near = [o for o in res.obstacles if np.hypot(o.center[0] + 3.0, o.center[1] - y_end) < 0.4]
    assert len(near) == 1, [(o.center, o.dynamic) for o in res.obstacles]
    assert abs(near[0].filter_velocity[1] - 0.9) < 0.35 and abs(near[0].filter_velocity[0]) < 0.35
    # the same walk ahead of the first camera, mirrored: the same label
    front = DODT(preset("dodt"))
    for k in range(45):
        r = front.process(frame(k * DT, k, [person_box((3.0, 0.8 - 0.9 * k * DT))]))
    assert [o.dynamic for o in r.obstacles] == [near[0].dynamic]
