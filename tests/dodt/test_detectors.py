"""Detectors on analytic depth images: boxes at known poses are found within 10 cm."""
import numpy as np
import pytest

from dodt.config import DBSCANConfig, DepthConfig, EnsembleConfig, UDepthConfig, VoxelConfig
from dodt.dbscan import DBSCANDetector, dbscan_labels
from dodt.ensemble import ensemble
from dodt.frames import CameraIntrinsics
from dodt.pointcloud import VoxelCloud, depth_to_points
from dodt.udepth import UDepthDetector
from synthetic import camera_pose, render_depth

K = CameraIntrinsics()
# A person-sized box 3 m ahead, and a pillar to the right 4 m ahead.
# (Off the 0.1 m voxel grid, so that no face lies exactly on a voxel boundary.)
PERSON = (np.array([2.83, 0.21, 0.0]), np.array([3.23, 0.71, 1.7]))
PILLAR = (np.array([3.93, -1.31, 0.0]), np.array([4.33, -0.91, 2.0]))
T = camera_pose()


def _truth(box):
    lo, hi = box
    return (lo + hi) / 2, hi - lo


@pytest.fixture(scope="module")
def depth():
    return render_depth(K, T, [PERSON, PILLAR])


def _match(dets, box):
    c, s = _truth(box)
    best = min(dets, key=lambda d: np.linalg.norm(d.center - c))
    return best, c, s


def test_point_cloud_lies_on_the_surfaces(depth):
    pts = depth_to_points(depth, K, T, DepthConfig())
    assert len(pts) > 10000
    on_floor = np.abs(pts[:, 2]) < 1e-4
    in_boxes = np.zeros(len(pts), bool)
    for lo, hi in (PERSON, PILLAR):
        in_boxes |= np.all((pts >= lo - 1e-4) & (pts <= hi + 1e-4), axis=1)
    assert np.all(on_floor | in_boxes)


def test_voxel_filter_keeps_one_point_per_occupied_voxel_above_the_ground(depth):
    vc = VoxelCloud(DepthConfig(), VoxelConfig())
    pts = vc(depth, K, T)
    assert len(pts) > 50
    assert np.all(pts[:, 2] >= VoxelConfig().ground_height - 1e-6)  # floor removed
    keys = np.floor(pts / 0.1).astype(int)
    assert len(np.unique(keys, axis=0)) == len(pts)
    again = vc(depth, K, T)  # the reused grid is left clean between frames
    np.testing.assert_array_equal(np.sort(pts, axis=0), np.sort(again, axis=0))


def _check_visible_extent(d, box, floor_cut=0.0):
    """The camera looks along +x: a box built from what it sees must match the obstacle's near
    face (x), its width (y) and its height (z) within 10 cm; its far side (x) lies between the
    near and the far face (a side face is seen only at a grazing angle)."""
    lo, hi = box[0].copy(), box[1].copy()
    lo[2] = max(lo[2], floor_cut)
    assert abs(d.lower[0] - lo[0]) < 0.10
    np.testing.assert_allclose(d.lower[1:], lo[1:], atol=0.10)
    np.testing.assert_allclose(d.upper[1:], hi[1:], atol=0.10)
    assert lo[0] - 0.1 <= d.upper[0] <= hi[0] + 0.1


@pytest.mark.parametrize("box", [PERSON, PILLAR])
def test_udepth_finds_the_visible_part_of_boxes_within_10cm(depth, box):
    dets = UDepthDetector(UDepthConfig(), DepthConfig())(depth, K, T)
    d, c, s = _match(dets, box)
    _check_visible_extent(d, box)


def test_hidden_depth_completion_recovers_the_box_centre(depth):
    from dodt.geometry import complete_hidden_depth

    dets = UDepthDetector(UDepthConfig(), DepthConfig())(depth, K, T)
    d, c, s = _match(dets, PERSON)  # 0.4 deep, 0.5 wide: seen from the front only
    assert np.linalg.norm(d.center - c) > 0.15
    c2, s2 = complete_hidden_depth(d.center, d.size, T[:3, 3], max_depth=0.6)
    assert np.linalg.norm(c2 - c) < 0.10
    np.testing.assert_allclose(s2[:2], [0.5, 0.5], atol=0.15)  # about as deep as wide


@pytest.mark.parametrize("box", [PERSON, PILLAR])
def test_dbscan_finds_boxes_within_10cm(depth, box):
    pts = VoxelCloud(DepthConfig(), VoxelConfig())(depth, K, T)
    dets = DBSCANDetector(DBSCANConfig())(pts)
    d, c, s = _match(dets, box)
    _check_visible_extent(d, box, floor_cut=VoxelConfig().ground_height)  # no points below 0.2 m


def test_ensemble_of_both_detectors_finds_each_box_once(depth):
    from dodt.geometry import complete_hidden_depth

    ud = UDepthDetector(UDepthConfig(), DepthConfig())(depth, K, T)
    pts = VoxelCloud(DepthConfig(), VoxelConfig())(depth, K, T)
    db = DBSCANDetector(DBSCANConfig())(pts)
    for d in ud + db:  # as the pipeline does before fusing
        d.center, d.size = complete_hidden_depth(d.center, d.size, T[:3, 3], 0.6)
    fused = ensemble(ud, db, EnsembleConfig())
    for box in (PERSON, PILLAR):
        c, _ = _truth(box)
        near = [f for f in fused if np.linalg.norm(f.center[:2] - c[:2]) < 0.10]
        assert len(near) == 1
    assert len(fused) == 2  # nothing else (the floor gives no box)


def test_dbscan_separates_clusters_and_labels_noise():
    rng = np.random.default_rng(0)
    a = rng.normal([0, 0, 1], 0.05, (100, 3))
    b = rng.normal([1.5, 0, 1], 0.05, (100, 3))
    noise = np.array([[5.0, 5.0, 5.0], [-5.0, 3.0, 1.0]])
    labels = dbscan_labels(np.vstack([a, b, noise]), 0.3, 8)
    assert len(set(labels[:100])) == 1 and len(set(labels[100:200])) == 1
    assert labels[0] != labels[100] and labels[0] >= 0 and labels[100] >= 0
    assert np.all(labels[200:] == -1)
