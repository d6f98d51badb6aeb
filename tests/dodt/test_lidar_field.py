"""The LiDAR vote leaves out what lay outside the scans it votes against (dodt.identification.in_lidar_field):
a static box the sensor passes close by is under its lowest ray, and comes into its field as the sensor
moves away; its points, new to the field, would find no twin within reach and vote moving."""
import numpy as np

from dodt.identification import LidarCloud, in_lidar_field
from dodt.pipeline import DODT
from dodt.presets import preset
from tests.dodt.test_lidar_detector import make_scan
from tests.dodt.test_rig_fusion import DT, frame

EL_MIN = np.radians(-7.0)
POLE = (np.array([-2.1, 2.0, 0.0]), np.array([-1.9, 2.2, 2.2]))  # 0.5 m beyond the box
SENSOR_Z = 1.42


def pose(xyz, pitch=0.0):
    T = np.eye(4)
    c, s = np.cos(pitch), np.sin(pitch)
    T[:3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]  # about y: positive pitch turns x down
    T[:3, 3] = xyz
    return T


def test_under_the_lowest_ray_or_in_the_blind_zone_is_outside_the_field():
    scans = [LidarCloud(0.0, np.empty((0, 3)), pose((0.0, 0.0, SENSOR_Z)), EL_MIN)]
    pts = np.array([[1.0, 0.0, 1.0],   # the lowest ray passes 1.28 m up at 1 m: under it
                    [5.0, 0.0, 1.0],   # at 5 m it passes 0.81 m up: 0.19 m above it
                    [6.5, 0.0, 1.5],   # beyond the detector's range: in the field
                    [0.2, 0.0, 1.5],   # in the 0.35 m blind zone
                    [-3.0, 2.0, 1.3]])  # behind and beside, above the ray: all round
    assert in_lidar_field(pts, scans, 0.35, 0.1).tolist() == [False, True, True, False, True]
    # the margin: 0.19 m above the ray is in by 0.1 m, not by 0.25 m
    assert not in_lidar_field(pts[1:2], scans, 0.35, 0.25)[0]
    # no lowest ray known: the blind zone alone
    scans_any = [scans[0]._replace(elevation_min=None)]
    assert in_lidar_field(pts, scans_any, 0.35, 0.1).tolist() == [True, True, True, False, True]
    # pitched down 20 deg, the sensor's lowest ray ahead is 27 deg down: 1 m ahead it passes 0.91 m up
    tilted = [LidarCloud(0.0, np.empty((0, 3)), pose((0.0, 0.0, SENSOR_Z), np.radians(20.0)), EL_MIN)]
    assert in_lidar_field(pts[:1], tilted, 0.35, 0.05)[0]
    # in the field of any one of the scans is in
    assert in_lidar_field(pts[:1], scans + tilted, 0.35, 0.05)[0]


def test_over_the_highest_ray_of_a_sensor_under_the_body_is_outside_the_field():
    """Upside down under the body (-52 to +7 deg), the sensor misses what rises above its highest ray: a
    box's top close by, which comes into the field as it moves away."""
    below = [LidarCloud(0.0, np.empty((0, 3)), pose((0.0, 0.0, 1.08)), np.radians(-52.0), np.radians(7.0))]
    pts = np.array([[1.0, 0.0, 1.6],   # the highest ray passes 1.20 m up at 1 m: 0.4 m over it
                    [1.0, 0.0, 1.0],   # between the rays (the lowest passes 1.28 m under the sensor at 1 m)
                    [4.0, 0.0, 1.5],   # the highest ray passes 1.57 m up at 4 m: 0.07 m under it
                    [0.5, 0.0, 0.3]])  # the lowest ray passes 0.44 m up at 0.5 m: under it
    assert in_lidar_field(pts, below, 0.35, 0.05).tolist() == [False, True, True, False]
    assert not in_lidar_field(pts[2:3], below, 0.35, 0.1)[0]  # within the margin of the highest ray
    # no highest ray known (a cloud of an older caller): what lies over it counts as in
    assert in_lidar_field(pts[:1], [below[0]._replace(elevation_max=None)], 0.35, 0.05)[0]


def visible_box_points(lo, hi, sensor, step=0.04):
    """The points of a box's faces that face the sensor and lie above its lowest ray, within 6 m."""
    lo, hi, sensor = (np.asarray(v, float) for v in (lo, hi, sensor))
    pts, normals = [], []
    for axis in range(3):
        others = [a for a in range(3) if a != axis]
        g = [np.arange(lo[a], hi[a] + 1e-9, step) for a in others]
        u, v = np.meshgrid(*g)
        for side, value in ((-1.0, lo[axis]), (1.0, hi[axis])):
            p = np.zeros((u.size, 3))
            p[:, axis], p[:, others[0]], p[:, others[1]] = value, u.ravel(), v.ravel()
            n = np.zeros(3)
            n[axis] = side
            pts.append(p)
            normals.append(np.tile(n, (len(p), 1)))
    P, N = np.concatenate(pts), np.concatenate(normals)
    d = P - sensor
    h = np.hypot(d[:, 0], d[:, 1])
    keep = (np.einsum("ij,ij->i", N, -d) > 0) & (d[:, 2] >= h * np.tan(EL_MIN)) & (h <= 6.0)
    return P[keep]


def test_a_static_box_the_sensor_passes_close_by_is_not_reported_moving():
    """The sensor flies past a 1.2 m box 1.1 m to its side at 1 m/s, 1.42 m up: the box's top comes into
    its field 1.8 m after it passed, its sides lower and lower as it moves away. A pole 0.5 m beyond it, in
    the field all along, gives the box's new points a neighbour within reach: without the field test,
    they vote moving."""
    d = DODT(preset("dodt"))
    d.set_scene(lidar_elevation_min=EL_MIN)
    lo, hi = np.array([-2.2, 1.1, 0.0]), np.array([-1.8, 1.5, 1.2])
    labels = []
    for k in range(150):
        t = k * DT
        sensor = np.array([-1.0 - 1.0 * t, 0.0, SENSOR_Z])
        if k % 3 == 0:  # with a tall pole beside the box, in the field all along
            pts = np.concatenate([visible_box_points(lo, hi, sensor), visible_box_points(*POLE, sensor)])
            d.observe_lidar(make_scan(pts, sensor=tuple(sensor)))
        res = d.process(frame(t, k, []))
        near = [o for o in res.obstacles if np.hypot(o.center[0] + 2.0, o.center[1] - 1.3) < 0.6]
        labels += [o.dynamic for o in near]
    assert len(labels) > 30  # the box was tracked
    assert not any(labels)
