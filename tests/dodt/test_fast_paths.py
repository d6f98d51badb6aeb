"""The compiled fast paths give the values of the plain code they replace, bit for bit."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from numba import njit

from dodt.association import _std_columns, mean_columns
from dodt.config import DepthConfig, UDepthConfig, VoxelConfig
from dodt.geometry import column_bounds as _bounds
from dodt.frames import CameraIntrinsics
from dodt.pointcloud import VoxelCloud
from dodt.udepth import UDepthDetector


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def test_bounds_are_numpys_min_and_max():
    rng = np.random.default_rng(0)
    for n in (1, 2, 3, 17, 400, 3000):
        pts = (rng.normal(0, 3, (n, 3)) + rng.uniform(-20, 20, 3)).astype(np.float32)
        lo, hi = _bounds(pts)
        assert _same(lo, pts.min(axis=0).astype(float)) and _same(hi, pts.max(axis=0).astype(float))
    pts = rng.normal(0, 1, (50, 3)).astype(np.float32)
    pts[7, 1] = np.nan
    lo, hi = _bounds(pts)
    assert _same(lo, pts.min(axis=0).astype(float)) and _same(hi, pts.max(axis=0).astype(float))
    with pytest.raises(ValueError):
        _bounds(np.empty((0, 3), np.float32))


def test_std_is_numpys():
    rng = np.random.default_rng(1)
    for n in (2, 3, 10, 255, 1000, 9000):
        for scale in (0.01, 1.0, 300.0):
            pts = (rng.normal(0, scale, (n, 3)) + rng.uniform(-50, 50, 3)).astype(np.float32)
            assert _same(_std_columns(pts), pts.std(axis=0).astype(float))
            grid = np.round(pts, 1)  # voxel-centre-like values, many ties
            assert _same(_std_columns(grid), grid.std(axis=0).astype(float))
    strided = rng.normal(0, 1, (100, 6)).astype(np.float32)[:, ::2]
    assert _same(_std_columns(strided), strided.std(axis=0).astype(float))
    as64 = rng.normal(0, 1, (100, 3))
    assert _same(_std_columns(as64), as64.std(axis=0).astype(float))


def test_column_means_are_numpys():
    rng = np.random.default_rng(2)
    for n in (1, 2, 9, 200, 1500, 12000):
        for scale in (0.05, 2.0, 500.0):
            pts = (rng.normal(0, scale, (n, 3)) + rng.uniform(-60, 60, 3)).astype(np.float32)
            assert _same(mean_columns(pts), np.mean(pts, axis=0))
            assert _same(mean_columns(pts, 2), np.mean(pts[:, :2], axis=0))
            assert _same(mean_columns(pts, 2).astype(float), np.mean(pts[:, :2], axis=0).astype(float))
    as64 = rng.normal(0, 1, (100, 3))
    assert _same(mean_columns(as64, 2), np.mean(as64[:, :2], axis=0))


@njit(cache=False)
def _voxel_reference(depth, fx, fy, cx, cy, R, t, margin, skip, dmin, dmax, res, thresh, ref_dist, min_thresh,
                     zlo, zhi, origin, n):
    """The voxel filter pixel by pixel, as it was first written (a dict grid)."""
    H, W = depth.shape
    order = []
    counts = {}
    sums = {}
    for v in range(margin, H - margin, skip):
        for u in range(margin, W - margin, skip):
            d = depth[v, u]
            if not (d >= dmin and d <= dmax):
                continue
            xc = (u - cx) * d / fx
            yc = (v - cy) * d / fy
            x = R[0, 0] * xc + R[0, 1] * yc + R[0, 2] * d + t[0]
            y = R[1, 0] * xc + R[1, 1] * yc + R[1, 2] * d + t[1]
            z = R[2, 0] * xc + R[2, 1] * yc + R[2, 2] * d + t[2]
            if z < zlo or z > zhi:
                continue
            ix = int(np.floor((x - origin[0]) / res))
            iy = int(np.floor((y - origin[1]) / res))
            iz = int(np.floor((z - origin[2]) / res))
            if ix < 0 or iy < 0 or iz < 0 or ix >= n or iy >= n or iz >= n:
                continue
            k = (ix * n + iy) * n + iz
            if k not in counts:
                order.append(k)
                counts[k] = 0
                sums[k] = (0.0, 0.0, 0.0)
            counts[k] += 1
            s = sums[k]
            sums[k] = (s[0] + x, s[1] + y, s[2] + z)
    out = []
    for k in order:
        c = counts[k]
        s = sums[k]
        th = float(thresh)
        if ref_dist > 0:
            dx = s[0] / c - t[0]
            dy = s[1] / c - t[1]
            dz = s[2] / c - t[2]
            d2 = dx * dx + dy * dy + dz * dz
            th = max(float(min_thresh), thresh * ref_dist * ref_dist / max(d2, 1e-6))
        if c >= th:
            out.append((np.float32(s[0] / c), np.float32(s[1] / c), np.float32(s[2] / c)))
    res_ = np.empty((len(out), 3), np.float32)
    for i in range(len(out)):
        res_[i, 0], res_[i, 1], res_[i, 2] = out[i]
    return res_


def _pose(rng) -> np.ndarray:
    yaw, pitch = rng.uniform(-np.pi, np.pi), rng.uniform(-0.3, 0.3)
    # optical frame: x right, y down, z forward; a camera looking along world +x rotated by yaw
    base = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    cy_, sy_ = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch), np.sin(pitch)
    Rz = np.array([[cy_, -sy_, 0], [sy_, cy_, 0], [0, 0, 1]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    T = np.eye(4)
    T[:3, :3] = Rz @ Ry @ base
    T[:3, 3] = [rng.uniform(-30, 30), rng.uniform(-30, 30), rng.uniform(0.5, 2.0)]
    return T


def _depth(rng, H, W) -> np.ndarray:
    d = rng.uniform(0.2, 7.0, (H, W)).astype(np.float32)
    d[rng.random((H, W)) < 0.1] = 0.0
    # smooth patches, so that voxels collect many points
    d[H // 4:H // 2, W // 5:W // 2] = np.float32(rng.uniform(1.0, 5.0))
    d[rng.random((H, W)) < 0.01] = np.nan
    return d


@pytest.mark.parametrize("H, W, margin, skip", [(480, 640, 10, 2), (120, 161, 3, 3), (64, 90, 0, 1), (40, 30, 20, 2)])
def test_voxel_cloud_is_the_pixel_loop(H, W, margin, skip):
    rng = np.random.default_rng(H + W)
    K = CameraIntrinsics(width=W, height=H, fx=0.6 * W, fy=0.6 * W, cx=W / 2 - 0.3, cy=H / 2 + 0.2)
    dcfg = DepthConfig(margin=margin, skip=skip)
    for vcfg in (VoxelConfig(), VoxelConfig(threshold_reference_distance=0.0, occupied_threshold=2)):
        cloud = VoxelCloud(dcfg, vcfg)
        for _ in range(3):
            depth, T = _depth(rng, H, W), _pose(rng)
            got = cloud(depth, K, T)
            cam = T[:3, 3]
            origin = np.floor((cam - vcfg.local_range) / vcfg.resolution) * vcfg.resolution
            want = _voxel_reference(depth, K.fx, K.fy, K.cx, K.cy, np.ascontiguousarray(T[:3, :3]),
                                    np.ascontiguousarray(cam), margin, skip, dcfg.depth_min, dcfg.depth_max,
                                    vcfg.resolution, vcfg.occupied_threshold, vcfg.threshold_reference_distance,
                                    vcfg.min_occupied_threshold, vcfg.ground_height, vcfg.ceiling_height, origin,
                                    cloud.n)
            assert _same(got, want)


@njit(cache=False)
def _u_map_reference(half, lo, hi, bw, bins, col_scale, fx, fy, cx, cy, R, t, zlo, zhi):
    """The U-depth map pixel by pixel, as it was first written."""
    rows, cols = half.shape
    U = np.zeros((bins, cols), np.float32)
    band = zlo < zhi
    for r in range(rows):
        for c in range(cols):
            d = half[r, c]
            if d > lo and d < hi:
                if band:
                    z = d * (R[2, 1] * (r - cy) / fy + R[2, 2] + R[2, 0] * (c / col_scale - cx) / fx) + t[2]
                    if z < zlo or z > zhi:
                        continue
                b = int((d - lo) / bw)
                if b >= bins:
                    b = bins - 1
                if U[b, c] < 255.0:
                    U[b, c] += 1.0
    return U


@pytest.mark.parametrize("H, W", [(480, 640), (121, 333), (48, 64)])
@pytest.mark.parametrize("col_scale", [0.5, 0.4])
@pytest.mark.parametrize("height_filter", [True, False])
def test_u_map_read_in_place_is_the_resized_one(H, W, col_scale, height_filter):
    rng = np.random.default_rng(W)
    K = CameraIntrinsics(width=W, height=H, fx=0.6 * W, fy=0.6 * W, cx=W / 2 - 0.3, cy=H / 2 + 0.2)
    det = UDepthDetector(UDepthConfig(col_scale=col_scale, height_filter=height_filter), DepthConfig(),
                         (0.2, 2.8))
    for _ in range(3):
        depth, T = _depth(rng, H, W), _pose(rng)
        U_resized, bw, half = det.u_map(depth, K, T)
        U_in_place, bw2 = det._u_map(depth, K, T)
        assert half.shape == (H, int(W * col_scale)) and bw == bw2
        assert _same(U_in_place, U_resized)
        c = det.cfg
        if height_filter:
            R, t, f, cx, cy = np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]), K.fx, K.cx, K.cy
            zlo, zhi = 0.2, 2.8
        else:
            R, t, f, cx, cy, zlo, zhi = np.eye(3), np.zeros(3), 1.0, 0.0, 0.0, 0.0, 0.0
        U = _u_map_reference(half, c.min_dist, 5.5, bw, H // c.row_downsample, half.shape[1] / W, f, f, cx, cy,
                             R, t, zlo, zhi)
        assert _same(U_in_place, cv2.GaussianBlur(U, c.blur_size, c.blur_sigma))


def _validate_reference(T: np.ndarray) -> str | None:
    """The pose checks with np.allclose and np.linalg.det, as first written."""
    if np.all(np.isfinite(T)):
        if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0]):
            return "last row"
        if not np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-3):
            return "orthonormal"
        if np.linalg.det(T[:3, :3]) < 0:
            return "determinant"
    return None


def test_pose_checks_decide_as_allclose_and_det():
    from dodt.frames import SensorFrame
    from dodt.pipeline import validate_frame

    rng = np.random.default_rng(3)
    K = CameraIntrinsics(width=32, height=24, fx=20.0, fy=20.0, cx=16.0, cy=12.0)
    depth = np.ones((24, 32), np.float32)
    seen = set()
    for i in range(3000):
        T = _pose(rng)
        kind = i % 6
        if kind == 1:
            T[3, rng.integers(4)] += rng.choice([1e-9, 5e-9, 1.5e-8, 1e-6, -2e-5])
        elif kind == 2:
            T[:3, :3] += rng.normal(0, rng.choice([1e-4, 3e-4, 6e-4, 1e-3]), (3, 3))
        elif kind == 3:
            T[:3, :3] = T[:3, :3] @ np.diag([1.0, -1.0, 1.0])
        elif kind == 4:
            T[rng.integers(4), rng.integers(4)] = rng.choice([np.nan, np.inf])
        elif kind == 5:
            T = T.astype(np.float32)
        want = _validate_reference(T)
        try:
            validate_frame(SensorFrame(depth=depth, color=None, intrinsics=K, T_world_camera=T, stamp=0.0))
            got = None
        except ValueError as e:
            msg = str(e)
            got = "last row" if "last row" in msg else "orthonormal" if "orthonormal" in msg else \
                "determinant" if "determinant" in msg else msg
        assert got == want
        seen.add(want)
    assert seen == {None, "last row", "orthonormal", "determinant"}


def test_json_rounding_is_round_of_float():
    import json

    from dodt.protocol import _rounded

    rng = np.random.default_rng(4)
    for dtype in (np.float64, np.float32, np.int64):
        for _ in range(500):
            a = (rng.normal(0, 10, 3) * 10 ** rng.uniform(-6, 3)).astype(dtype)
            assert json.dumps(_rounded(a)) == json.dumps([round(float(x), 4) for x in a])
    special = np.array([np.nan, np.inf, -0.0, 0.00005, -0.00015])
    assert json.dumps(_rounded(special)) == json.dumps([round(float(x), 4) for x in special])
    assert _rounded([1, 2.5]) == [1.0, 2.5]


def test_vote_without_tree_is_the_trees():
    from scipy.spatial import cKDTree

    from dodt.config import IdentificationConfig
    from dodt.identification import _nearest, vote

    rng = np.random.default_rng(5)
    cfg = IdentificationConfig()
    K = CameraIntrinsics()
    for trial in range(400):
        T = _pose(rng)
        ahead = T[:3, 3] + T[:3, 2] * rng.uniform(1.0, 4.0)
        m = int(rng.integers(1, 200))
        then = (ahead + rng.normal(0, 0.4, (m, 3))).astype(np.float32)
        if trial % 4 == 0:
            then = np.round(then, 1)  # a lattice: many equal distances
        if trial % 5 == 0:
            then = np.concatenate([then, then[:3]])  # duplicates: ties for the nearest
        n = int(rng.integers(1, 120))
        now = (then[rng.integers(0, len(then), n)] + rng.normal(0.02, 0.05, (n, 3))).astype(np.float32)
        if trial % 3 == 0:
            now = now[::2]  # a strided view, as the voters are
        v_box = rng.normal(0, 1, 3).astype(np.float32)
        dt = float(rng.choice([1 / 30, 5 / 30, 0.2]))
        got = vote(now, then, dt, v_box, T, K, 5.5, cfg)
        want = vote(now, cKDTree(then), dt, v_box, T, K, 5.5, cfg)
        assert got == want
        tree = cKDTree(then)
        reach = 0.3
        dist, idx, tie = _nearest(np.ascontiguousarray(now), tree.data, reach)
        td, ti = tree.query(now, distance_upper_bound=reach * (1 + 1e-9))
        ok = td <= reach
        assert _same(dist[ok], td[ok]) and np.all(np.isinf(dist[~ok]))
        if not tie:
            assert _same(idx[ok], ti[ok])


@njit(cache=False)
def _partition_kth(a, k):
    return np.partition(a, k)[k]  # numba's np.partition, as _box_points called it


@pytest.mark.slow
def test_kth_smallest_is_partitions():
    from dodt.udepth import _kth_smallest

    rng = np.random.default_rng(6)
    for trial in range(3000):
        n = int(rng.integers(1, 3000))
        kind = trial % 5
        a = rng.normal(0, 1, n)
        if kind == 1:
            a = np.round(a * 3) / 3  # many ties, -0.0 and 0.0 among them
        elif kind == 2:
            a = np.sort(a)
        elif kind == 3:
            a = np.sort(a)[::-1].copy()
        elif kind == 4:
            a[rng.integers(0, n, 1 + n // 50)] = np.nan
        q = float(rng.choice([0.0, 0.5, 2.0, 5.0, 20.0, 30.0, 50.0]))
        for k in (int(q / 100.0 * (n - 1)), int((100.0 - q) / 100.0 * (n - 1))):
            assert _same(np.float64(_kth_smallest(a, k)), np.float64(_partition_kth(a, k)))


def _iou_reference(centers_a, sizes_a, centers_b, sizes_b):
    """iou_matrix in numpy, as first written."""
    ca, sa = np.asarray(centers_a, float).reshape(-1, 3), np.asarray(sizes_a, float).reshape(-1, 3)
    cb, sb = np.asarray(centers_b, float).reshape(-1, 3), np.asarray(sizes_b, float).reshape(-1, 3)
    lo = np.maximum((ca - sa / 2)[:, None, :], (cb - sb / 2)[None, :, :])
    hi = np.minimum((ca + sa / 2)[:, None, :], (cb + sb / 2)[None, :, :])
    inter = np.prod(np.clip(hi - lo, 0.0, None), axis=2)
    va, vb = np.prod(sa, axis=1), np.prod(sb, axis=1)
    union = va[:, None] + vb[None, :] - inter
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(union > 0, inter / union, 0.0)


def test_iou_matrix_is_the_numpy_one():
    from dodt.geometry import iou_matrix

    rng = np.random.default_rng(7)
    for trial in range(2000):
        n, m = int(rng.integers(0, 8)), int(rng.integers(0, 8))
        ca = rng.uniform(-3, 3, (n, 3))
        cb = np.concatenate([ca[: m // 2] + rng.normal(0, 0.2, (min(m // 2, n), 3)),
                             rng.uniform(-3, 3, (m - min(m // 2, n), 3))])
        sa, sb = rng.uniform(0, 2, (n, 3)), rng.uniform(0, 2, (len(cb), 3))
        if trial % 7 == 0 and n:
            sa[0, rng.integers(3)] = 0.0  # a flat box
        if trial % 11 == 0 and n and len(cb):
            cb[0], sb[0] = ca[0] + sa[0], sa[0]  # touching corners
        want = _iou_reference(ca, sa, cb, sb)
        got = iou_matrix(list(ca), list(sa), list(cb), list(sb))
        assert _same(got, want)


def test_frame_period_is_numpys_median():
    from collections import deque

    from dodt.windows import _median

    rng = np.random.default_rng(9)
    for _ in range(5000):
        n = int(rng.integers(1, 10))
        vals = deque(float(x) for x in rng.choice([1 / 30, 1 / 15, 0.1, 1 / 29.97, 0.0333], n) *
                     rng.uniform(0.9, 1.1, n))
        assert _same(np.float64(_median(vals)), np.float64(float(np.median(vals))))


def test_seen_through_counts():
    from dodt.tracker import _count_behind

    rng = np.random.default_rng(10)
    depth = rng.uniform(0, 6, (48, 64)).astype(np.float32)
    depth[rng.random((48, 64)) < 0.2] = 0.0
    depth[rng.random((48, 64)) < 0.02] = np.nan
    for _ in range(500):
        v0, u0 = int(rng.integers(0, 47)), int(rng.integers(0, 63))
        v1, u1 = int(rng.integers(v0 + 1, 48)), int(rng.integers(u0 + 1, 64))
        far = np.float64(rng.uniform(0, 6))
        win = depth[v0:v1 + 1:2, u0:u1 + 1:2]
        win = win[win > 0]
        n_valid, n_behind = _count_behind(depth, v0, v1 + 1, u0, u1 + 1, 2, far)
        assert n_valid == win.size
        if win.size:
            assert n_behind / n_valid == np.mean(win > far)


def test_crop_to_box_is_the_mask():
    from dodt.geometry import crop_to_box

    rng = np.random.default_rng(11)
    for _ in range(300):
        pts = rng.normal(0, 1, (int(rng.integers(0, 400)), 3)).astype(np.float32)
        lo = (rng.normal(0, 1, 3) - 0.5).astype(np.float32)
        hi = lo + rng.uniform(0, 2, 3).astype(np.float32)
        want = pts[np.all((pts >= lo) & (pts <= hi), axis=1)]
        assert _same(crop_to_box(pts, lo, hi), want)


def test_feature_similarity_is_the_array_expression():
    from dodt.association import TrackView, similarity_matrix
    from dodt.config import AssociationConfig
    from dodt.detection import Detection

    rng = np.random.default_rng(12)
    cfg = AssociationConfig()
    for _ in range(300):
        T, D = int(rng.integers(1, 9)), int(rng.integers(1, 9))
        tracks = [TrackView(center=rng.normal(0, 3, 3), size=rng.uniform(0.1, 2, 3), count=int(rng.integers(0, 500)),
                            spread=rng.uniform(0, 1, 3), position_variance=float(rng.uniform(0, 2)))
                  for _ in range(T)]
        dets = [Detection(center=rng.normal(0, 3, 3), size=rng.uniform(0.1, 2, 3), source="dbscan",
                          points=rng.normal(0, 0.5, (int(rng.integers(0, 300)), 3)).astype(np.float32))
                for _ in range(D)]
        got, thr = similarity_matrix(tracks, dets, cfg, np.zeros(3))
        tc = np.array([t.center for t in tracks])
        dc = np.array([d.center for d in dets])
        ts = np.array([t.size for t in tracks])
        ds = np.array([d.size for d in dets])
        dn = np.array([len(d.points) for d in dets], float)
        dstd = np.array([d.points.std(axis=0).astype(float) if len(d.points) >= 2 else np.zeros(3) for d in dets])
        tn = np.array([t.count for t in tracks], float)
        tstd = np.array([t.spread for t in tracks])
        pos_scale = np.sqrt(cfg.position_scale**2 + np.array([t.position_variance for t in tracks]))
        dpos = (tc[:, None, :] - dc[None, :, :])
        d2 = (dpos[..., 0] ** 2 + dpos[..., 1] ** 2) / pos_scale[:, None] ** 2 + dpos[..., 2] ** 2 / cfg.position_scale**2
        d2 += np.sum((ts[:, None, :] - ds[None, :, :]) ** 2, axis=2) / cfg.size_scale**2
        rel = np.abs(tn[:, None] - dn[None, :]) / np.maximum(np.maximum(tn[:, None], dn[None, :]), 1.0)
        d2 += (rel / cfg.count_scale) ** 2
        d2 += np.sum((tstd[:, None, :] - dstd[None, :, :]) ** 2, axis=2) / cfg.spread_scale**2
        assert _same(got, np.exp(-d2)) and thr == cfg.similarity_threshold
