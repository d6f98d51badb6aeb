"""The LiDAR detector (dodt.lidar_detector) and a scan as depth images (dodt.lidar_views)."""
import math

import numpy as np
import pytest

from dodt.config import LidarDetectorConfig
from dodt.frames import LidarScan
from dodt.lidar_detector import LidarDetector, voxel_filter
from dodt.lidar_views import fill_holes, scan_depth_views

SENSOR_Z = 1.3
EL_MIN = math.radians(-7.0)


def make_scan(points_world, sensor=(0.0, 0.0, SENSOR_Z)) -> LidarScan:
    T = np.eye(4)
    T[:3, 3] = sensor
    q = np.asarray(points_world, float) - np.asarray(sensor, float)
    r = np.linalg.norm(q, axis=1)
    return LidarScan(points=q.astype(np.float32), ranges=r.astype(np.float32),
                     azimuth=np.arctan2(q[:, 1], q[:, 0]).astype(np.float32),
                     elevation=np.arcsin(q[:, 2] / r).astype(np.float32), stamp=0.0, T_world_sensor=T, n_rays=len(q))


def column(xy, z_lo, z_hi, radius=0.2, step=0.05, facing=None):
    """Points on a vertical cylinder's surface (a person-sized column); ``facing`` (x, y): only the half
    that faces that point (what a sensor there sees)."""
    pts = []
    toward = None if facing is None else np.arctan2(facing[1] - xy[1], facing[0] - xy[0])
    for z in np.arange(z_lo, z_hi, step):
        for a in np.linspace(0, 2 * np.pi, 24, endpoint=False):
            if toward is None or np.cos(a - toward) > 0:
                pts.append((xy[0] + radius * np.cos(a), xy[1] + radius * np.sin(a), z))
    return np.array(pts)


def floor(extent=4.0, step=0.1):
    g = np.arange(-extent, extent, step)
    x, y = np.meshgrid(g, g)
    return np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)


def detector(**kw):
    return LidarDetector(LidarDetectorConfig(**kw), ground_height=0.2, ceiling_height=2.8)


def test_a_person_behind_the_sensor_is_one_box_and_the_floor_is_none():
    # seen from the waist up: the lowest ray (-7 deg) from 1.3 m meets a person 2 m away at about 1.05 m
    person = column((-2.0, 0.5), 1.05, 1.75)
    dets = detector()(make_scan(np.concatenate([person, floor()])), elevation_min=EL_MIN)
    assert len(dets) == 1
    d = dets[0]
    assert d.source == "lidar" and d.sensor == "lidar"
    assert np.allclose(d.center[:2], (-2.0, 0.5), atol=0.1)
    assert d.lower[2] == 0.0, "a box cut by the lowest ray is taken to reach the floor"
    assert d.upper[2] == pytest.approx(1.75, abs=0.1)


def test_a_box_seen_whole_keeps_its_bottom():
    hanging = column((1.5, 0.0), 1.2, 1.7)  # well above what the lowest ray reaches at 1.5 m (about 1.1 m)
    dets = detector()(make_scan(hanging), elevation_min=math.radians(-30.0))
    assert len(dets) == 1 and dets[0].lower[2] == pytest.approx(1.2, abs=0.1)


def test_walls_far_returns_and_wide_clusters_are_structure():
    wall = np.array([(x, 1.95, z) for x in np.arange(-3, 3, 0.05) for z in np.arange(0.3, 2.5, 0.1)])
    far_person = column((7.5, 0.0), 0.5, 1.7)
    long_shelf = np.array([(x, -1.0, z) for x in np.arange(-1.5, 1.5, 0.05) for z in np.arange(0.3, 1.5, 0.1)])
    scan = make_scan(np.concatenate([wall, far_person, long_shelf]))
    fence = (np.array([-10.0, -2.0]), np.array([10.0, 2.0]))
    assert detector()(scan, geofence=fence) == []
    # without the geofence the wall is one wide cluster: still structure (wider than max_footprint)
    assert detector()(scan) == []


class EstablishedEverywhere:
    def established_fraction(self, center, size):
        return 1.0


def test_a_cluster_on_established_structure_is_dropped():
    scan = make_scan(column((2.0, 0.0), 0.5, 1.7))
    assert len(detector()(scan)) == 1
    assert detector()(scan, static_map=EstablishedEverywhere()) == []


def test_voxel_filter_keeps_one_mean_point_per_cell():
    pts = np.array([[0.01, 0.01, 0.01], [0.03, 0.05, 0.07], [0.51, 0.0, 0.0]])
    out = voxel_filter(pts, 0.1)
    assert out.shape == (2, 3)
    assert np.allclose(sorted(out[:, 0]), [0.02, 0.51], atol=1e-6)
    assert voxel_filter(np.empty((0, 3)), 0.1).shape == (0, 3)


def test_scan_depth_views_put_each_return_at_its_depth_in_its_view():
    # a wall 3 m ahead (x) and one 2 m behind, sampled finely
    ahead = np.array([(3.0, y, z) for y in np.arange(-1, 1, 0.02) for z in np.arange(0.8, 1.8, 0.02)])
    behind = np.array([(-2.0, y, z) for y in np.arange(-1, 1, 0.02) for z in np.arange(0.8, 1.8, 0.02)])
    views = scan_depth_views(make_scan(np.concatenate([ahead, behind])), EL_MIN, math.radians(52.0))
    assert len(views) == 4
    (d0, K, T0), (_, _, _), (d2, _, T2), (d3, _, _) = views
    assert np.allclose(T0[:3, 2], (1, 0, 0)) and np.allclose(T2[:3, 2], (-1, 0, 0))  # optical axes
    assert np.median(d0[d0 > 0]) == pytest.approx(3.0, abs=0.02)
    assert np.median(d2[d2 > 0]) == pytest.approx(2.0, abs=0.02)
    assert not d3.any()  # nothing to the right


def test_fill_holes_takes_the_nearest_neighbour():
    d = np.array([[0, 0, 0, 0], [0, 2.0, 0, 0], [0, 0, 3.0, 0], [0, 0, 0, 0]], np.float32)
    f = fill_holes(d)
    assert f[1, 1] == 2.0 and f[2, 2] == 3.0 and f[1, 2] == 2.0 and f[3, 3] == 3.0
    assert f[0, 3] == 0.0  # no neighbour with a return
