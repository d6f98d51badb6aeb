"""Detectors on analytic depth images: boxes at known poses are found within 10 cm."""
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

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


# --------------------------------------------------------------------------- DBSCAN vs brute force


def _brute_force_dbscan(points, eps, min_points):
    """DBSCAN from all pairwise distances (O(n^2)), with the kernel's numbering and border rule."""
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    n = len(pts)
    labels = np.full(n, -1, np.int64)
    if n == 0:
        return labels
    d = pts[:, None, :] - pts[None, :, :]
    near = d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2] <= eps * eps  # the kernel's sum
    core = near.sum(axis=1) >= min_points  # the point itself included
    # Components of the core points: spread the lowest index over core-core edges until it settles.
    edge = near & core[:, None] & core[None, :]
    comp = np.arange(n)
    while True:
        nxt = np.minimum(comp, np.where(edge, comp[None, :], n).min(axis=1))
        if np.array_equal(nxt, comp):
            break
        comp = nxt
    # comp is the component's first core point, so sorting the roots numbers them in that order
    labels[core] = np.unique(comp[core], return_inverse=True)[1]
    # Border point: the cluster of the core neighbour in the lowest cell (x, y, z), then lowest index.
    cell = ((pts - pts.min(axis=0)) / eps).astype(np.int64)
    for i in np.flatnonzero(~core):
        cand = np.flatnonzero(near[i] & core)
        if len(cand):
            j = cand[np.lexsort((cand, cell[cand, 2], cell[cand, 1], cell[cand, 0]))[0]]
            labels[i] = labels[j]
    return labels


@st.composite
def dbscan_clouds(draw):
    """A small random cloud (n <= 300, float32 or float64) with eps and min_points."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    n = draw(st.integers(0, 300))
    kind = draw(st.sampled_from(["uniform", "clustered", "duplicates", "lattice", "sparse"]))
    if kind == "uniform":
        pts = rng.uniform(-1.0, 1.0, (n, 3)) * draw(st.sampled_from([0.05, 0.5, 2.0]))
    elif kind == "clustered":
        centres = rng.uniform(0.0, 3.0, (draw(st.integers(1, 6)), 3))
        spread = draw(st.sampled_from([0.03, 0.1, 0.3]))
        pts = centres[rng.integers(0, len(centres), n)] + rng.normal(0.0, spread, (n, 3))
    elif kind == "duplicates":  # few distinct points, many times each
        base = rng.uniform(0.0, 1.0, (max(n // draw(st.integers(1, 30)), 1), 3))
        pts = base[rng.integers(0, len(base), n)]
    elif kind == "lattice":  # many distances exactly at eps: the boundary case
        pts = rng.integers(0, 8, (n, 3)) * 0.1
    else:  # at least 1 apart: all noise unless eps >= 1 or min_points == 1
        pts = np.stack(np.unravel_index(rng.choice(1000, n, replace=False), (10, 10, 10)), axis=1) * 1.0
    eps = draw(st.sampled_from([0.1, 0.2, 0.3, 0.5, 20.0]))  # 20: larger than any cloud's extent
    pts = pts.astype(draw(st.sampled_from([np.float32, np.float64])))
    return pts, eps, draw(st.integers(1, 12))


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(dbscan_clouds())
def test_dbscan_labels_equal_brute_force(cloud):
    pts, eps, min_points = cloud
    np.testing.assert_array_equal(dbscan_labels(pts, eps, min_points), _brute_force_dbscan(pts, eps, min_points))


@pytest.mark.parametrize("n, min_points, expect", [(0, 8, []), (1, 1, [0]), (1, 2, [-1])])
def test_dbscan_empty_and_single_point(n, min_points, expect):
    labels = dbscan_labels(np.zeros((n, 3), np.float32), 0.3, min_points)
    assert labels.dtype == np.int64 and labels.tolist() == expect


def test_dbscan_all_noise_duplicates_and_large_eps():
    far = np.arange(30.0)[:, None] * np.array([1.0, 0.5, 0.0])  # 1.1 m apart
    assert np.all(dbscan_labels(far, 0.3, 2) == -1)
    assert np.all(dbscan_labels(np.ones((8, 3)), 0.3, 8) == 0)  # 8 copies of one point: one cluster
    assert np.all(dbscan_labels(np.ones((7, 3)), 0.3, 8) == -1)
    rng = np.random.default_rng(1)
    assert np.all(dbscan_labels(rng.uniform(0, 1, (50, 3)), 5.0, 8) == 0)  # eps beyond the extent


def test_dbscan_border_between_two_clusters_joins_the_lower_cell():
    """A border point next to two clusters joins the one whose core neighbour lies in the lower
    grid cell (here the left one, cell x = 0), although the right one has the lower index."""
    right = [2.0, 2.08, 2.09, 2.1]  # cluster 0 (its points come first)
    left = [0.0, 0.01, 0.02, 0.1]  # cluster 1
    x = np.array(right + [1.05] + left)  # 1.05 is within eps = 1 of 0.1 and 2.0 only: 3 < min_points
    pts = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    labels = dbscan_labels(pts, 1.0, 4)
    assert labels.tolist() == [0, 0, 0, 0, 1, 1, 1, 1, 1]
    np.testing.assert_array_equal(labels, _brute_force_dbscan(pts, 1.0, 4))


def _column(cx, cy, rng, width=0.4, depth=0.25, step=0.1):
    """Voxel-like points filling an upright person-sized column (0.3-1.8 m high)."""
    g = np.mgrid[-width / 2:width / 2 + 1e-9:step, -depth / 2:depth / 2 + 1e-9:step, 0.3:1.8 + 1e-9:step]
    p = g.reshape(3, -1).T + [cx, cy, 0.0]
    return p + rng.normal(0, 0.01, p.shape)


def _rot(points, yaw, about):
    c, s = np.cos(yaw), np.sin(yaw)
    q = points - about
    return np.column_stack([c * q[:, 0] - s * q[:, 1], s * q[:, 0] + c * q[:, 1], q[:, 2]]) + about


@pytest.mark.parametrize("yaw", [0.0, np.pi / 4, np.pi / 2])
def test_dbscan_splits_two_people_linked_by_an_arm(yaw):
    rng = np.random.default_rng(0)
    a, b = np.array([4.0, -0.35, 0.0]), np.array([4.0, 0.35, 0.0])  # 0.7 m apart, side by side
    arm = np.column_stack([np.full(3, 4.0), [-0.1, 0.0, 0.1], np.full(3, 1.2)])  # bridges the 0.3 m gap
    pts = np.vstack([_column(*a[:2], rng), _column(*b[:2], rng), arm])
    about = (a + b) / 2
    pts = _rot(pts, yaw, about)
    assert dbscan_labels(pts, 0.3, 8).max() == 0  # one DBSCAN cluster ...
    dets = DBSCANDetector(DBSCANConfig())(pts.astype(np.float32))
    assert len(dets) == 2  # ... cut into two obstacles
    truth = _rot(np.array([a, b]), yaw, about)[:, :2]
    found = [d.center[:2] for d in dets]
    for t in truth:
        assert min(np.linalg.norm(f - t) for f in found) < 0.1
    assert len(DBSCANDetector(DBSCANConfig(split_width=0.0))(pts.astype(np.float32))) == 1  # off


def test_dbscan_does_not_split_an_even_wall_or_a_single_person():
    rng = np.random.default_rng(1)
    g = np.mgrid[3.0:3.01:0.1, -1.5:1.5 + 1e-9:0.1, 0.3:2.0 + 1e-9:0.1]
    wall = g.reshape(3, -1).T + rng.normal(0, 0.01, (g[0].size, 3))
    dets = DBSCANDetector(DBSCANConfig())(wall.astype(np.float32))
    assert len(dets) == 1 and dets[0].size[1] > 2.9
    person = _column(4.0, 0.0, rng, width=0.6)
    assert len(DBSCANDetector(DBSCANConfig())(person.astype(np.float32))) == 1


def test_udepth_height_band_keeps_the_floor_out_of_the_u_map():
    """In a corridor, the floor's nearest band puts several image rows of every column into
    one depth bin: a line across the U-depth map that joins both walls into one box as wide as
    the corridor. With the pipeline's height band (the voxel filter's ground and ceiling
    heights) the floor stays out of the map: each wall and the person are found apart, the
    person within 10 cm."""
    walls = [(np.array([0.5, 1.93, 0.0]), np.array([12.0, 2.13, 3.0])),
             (np.array([0.5, -2.13, 0.0]), np.array([12.0, -1.93, 3.0]))]
    depth = render_depth(K, T, walls + [PERSON])
    band = (VoxelConfig().ground_height, VoxelConfig().ceiling_height)
    for depth_max in (5.0, 5.5):
        dcfg = DepthConfig(depth_max=depth_max)
        unfiltered = UDepthDetector(UDepthConfig(height_filter=False), dcfg, band)(depth, K, T)
        assert any(d.size[1] > 3.5 for d in unfiltered)  # wall to wall
        dets = UDepthDetector(UDepthConfig(), dcfg, band)(depth, K, T)
        assert len(dets) == 3 and all(d.size[1] < 1.0 for d in dets)
        _check_visible_extent(_match(dets, PERSON)[0], PERSON)
