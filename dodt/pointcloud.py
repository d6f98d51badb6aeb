"""Depth image -> world point cloud -> voxel filter (paper Sec. III-A, after Eppenberger et al.).

One compiled pass over the sampled pixels (border margin, pixel skip, depth range) projects
each pixel with the camera pose and accumulates it into a voxel grid around the camera; a voxel
with enough points emits one point, the centroid of its points (the reference code emits its
N-th point; the centroid is less noisy). "Enough" is ``occupied_threshold`` at
``threshold_reference_distance`` from the camera, scaled with the square of the distance as the
sampling density is (the reference code's fixed count loses far obstacles first). Points below the ground
height, above the ceiling height or beyond the local range are dropped. Voxels are aligned to
the world grid, so the same surface gives the same voxels from frame to frame.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from dodt.config import DepthConfig, VoxelConfig
from dodt.frames import CameraIntrinsics


@njit(cache=True, nogil=True)
def _project_row(d_row, u_off, v_off, fx, fy, R, t, origin, res, dmin, dmax, zlo, zhi, nf, xyz, keys):
    """World points and voxel keys of one row's sampled pixels (key -1: the pixel is dropped).
    Branch-free, so that the compiler can vectorise it."""
    r00, r01, r02 = R[0, 0], R[0, 1], R[0, 2]
    r10, r11, r12 = R[1, 0], R[1, 1], R[1, 2]
    r20, r21, r22 = R[2, 0], R[2, 1], R[2, 2]
    t0, t1, t2 = t[0], t[1], t[2]
    o0, o1, o2 = origin[0], origin[1], origin[2]
    for j in range(d_row.shape[0]):
        d = d_row[j]
        xc = u_off[j] * d / fx
        yc = v_off * d / fy
        x = r00 * xc + r01 * yc + r02 * d + t0
        y = r10 * xc + r11 * yc + r12 * d + t1
        z = r20 * xc + r21 * yc + r22 * d + t2
        ix = np.floor((x - o0) / res)
        iy = np.floor((y - o1) / res)
        iz = np.floor((z - o2) / res)
        # the depth range (also false for NaN), the height band, the grid
        ok = ((d >= dmin) & (d <= dmax) & (z >= zlo) & (z <= zhi) & (ix >= 0.0) & (iy >= 0.0) & (iz >= 0.0)
              & (ix < nf) & (iy < nf) & (iz < nf))
        xyz[0, j] = x
        xyz[1, j] = y
        xyz[2, j] = z
        keys[j] = np.int64(((ix * nf + iy) * nf + iz) if ok else -1.0)


@njit(cache=True, nogil=True)
def _cloud_voxel_kernel(depth, fx, fy, cx, cy, R, t, margin, skip, dmin, dmax, res, thresh, ref_dist, min_thresh,
                        zlo, zhi, origin, n, counts, sums, touched):
    H, W = depth.shape
    n_touched = 0
    # Row by row: the sampled pixels are projected in one vectorised pass, then accumulated into
    # their voxels in pixel order.
    nu = max(0, (W - 2 * margin + skip - 1) // skip)
    u_off = np.empty(nu)
    for j in range(nu):
        u_off[j] = (margin + j * skip) - cx
    d_row = np.empty(nu)
    xyz = np.empty((3, nu))
    keys = np.empty(nu, np.int64)
    nf = float(n)
    for v in range(margin, H - margin, skip):
        for j in range(nu):
            d_row[j] = depth[v, margin + j * skip]
        _project_row(d_row, u_off, v - cy, fx, fy, R, t, origin, res, dmin, dmax, zlo, zhi, nf, xyz, keys)
        for j in range(nu):
            k = keys[j]
            if k < 0:
                continue
            if counts[k] == 0:
                touched[n_touched] = k
                n_touched += 1
            counts[k] += 1
            sums[k, 0] += xyz[0, j]
            sums[k, 1] += xyz[1, j]
            sums[k, 2] += xyz[2, j]
    # A voxel's count threshold: fixed, or scaled with the sampling density, which falls with
    # the square of the distance (pixels per voxel face ~ (f res / (skip d))^2).
    keep = np.zeros(n_touched, np.bool_)
    m = 0
    for i in range(n_touched):
        k = touched[i]
        c = counts[k]
        th = float(thresh)
        if ref_dist > 0:
            dx = sums[k, 0] / c - t[0]
            dy = sums[k, 1] / c - t[1]
            dz = sums[k, 2] / c - t[2]
            d2 = dx * dx + dy * dy + dz * dz
            th = max(float(min_thresh), thresh * ref_dist * ref_dist / max(d2, 1e-6))
        if c >= th:
            keep[i] = True
            m += 1
    out = np.empty((m, 3), np.float32)
    j = 0
    for i in range(n_touched):
        k = touched[i]
        c = counts[k]
        if keep[i]:
            out[j, 0] = sums[k, 0] / c
            out[j, 1] = sums[k, 1] / c
            out[j, 2] = sums[k, 2] / c
            j += 1
        counts[k] = 0  # leave the grid clean for the next frame
        sums[k, 0] = 0.0
        sums[k, 1] = 0.0
        sums[k, 2] = 0.0
    return out


class VoxelCloud:
    """Builds the voxel-filtered world point cloud of a depth frame; reuses its grid."""

    def __init__(self, depth_cfg: DepthConfig, voxel_cfg: VoxelConfig):
        self.d = depth_cfg
        self.v = voxel_cfg
        self.n = int(np.ceil(2 * voxel_cfg.local_range / voxel_cfg.resolution)) + 1
        cells = self.n ** 3
        self._counts = np.zeros(cells, np.int32)
        self._sums = np.zeros((cells, 3), np.float64)
        self._touched = np.empty(0, np.int64)

    def __call__(self, depth_m: np.ndarray, K: CameraIntrinsics, T_world_camera: np.ndarray) -> np.ndarray:
        """(M, 3) float32 world points, at most one per occupied voxel."""
        H, W = depth_m.shape
        need = ((H + self.d.skip - 1) // self.d.skip) * ((W + self.d.skip - 1) // self.d.skip)
        if self._touched.size < need:
            self._touched = np.empty(need, np.int64)
        res = self.v.resolution
        cam = T_world_camera[:3, 3]
        origin = np.floor((cam - self.v.local_range) / res) * res
        return _cloud_voxel_kernel(
            np.ascontiguousarray(depth_m, dtype=np.float32), K.fx, K.fy, K.cx, K.cy,
            np.ascontiguousarray(T_world_camera[:3, :3], dtype=np.float64),
            np.ascontiguousarray(cam, dtype=np.float64), self.d.margin, self.d.skip,
            self.d.depth_min, self.d.depth_max, res, self.v.occupied_threshold,
            self.v.threshold_reference_distance, self.v.min_occupied_threshold, self.v.ground_height, self.v.ceiling_height, origin, self.n, self._counts, self._sums, self._touched)


def depth_to_points(depth_m: np.ndarray, K: CameraIntrinsics, T_world_camera: np.ndarray,
                    cfg: DepthConfig) -> np.ndarray:
    """All valid sampled pixels (margin, skip, range) as (N, 3) world points (no voxel filter)."""
    H, W = depth_m.shape
    v, u = np.mgrid[cfg.margin:H - cfg.margin:cfg.skip, cfg.margin:W - cfg.margin:cfg.skip]
    d = depth_m[v, u]
    ok = (d >= cfg.depth_min) & (d <= cfg.depth_max)
    pc = K.backproject(u[ok], v[ok], d[ok])
    return pc @ T_world_camera[:3, :3].T + T_world_camera[:3, 3]
