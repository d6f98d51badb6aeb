"""A LiDAR scan as depth images: what lets a depth-image consumer (the voxel map's ray caster, the seen
space) take LiDAR returns.

``scan_depth_views`` projects a scan's returns into ``views`` pinhole depth images around the sensor's z
axis (each 2 pi / views wide, tall enough for the scan's vertical field at its sides), keeping the nearest
return per pixel. The pixel pitch (``width``) is chosen coarser than the scan's angular spacing (about 1 deg
for a Mid-360-like scan), so nearly every pixel holds a return; a pixel without one takes the nearest of
its 8 neighbours' (``fill_holes``): a consumer that reads 0 as "nothing within range", as the voxel map's
ray caster does, would otherwise carve free space through every gap between returns and every dropout.
"""
from __future__ import annotations

import math

import numpy as np

from dodt.frames import CameraIntrinsics, LidarScan

# sensor FLU (x forward, y left, z up) <- optical (x right, y down, z forward)
_R_FLU_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def view_rotations(views: int) -> np.ndarray:
    """(views, 3, 3): each view's optical frame in the sensor frame, turned about z by 2 pi k / views."""
    out = []
    for k in range(views):
        a = 2 * math.pi * k / views
        Rz = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])
        out.append(Rz @ _R_FLU_OPTICAL)
    return np.array(out)


def view_intrinsics(views: int, width: int, elevation_min: float, elevation_max: float) -> CameraIntrinsics:
    """A pinhole model ``width`` pixels across 2 pi / views, tall enough for [elevation_min, elevation_max]
    at the view's sides."""
    half = math.pi / views
    f = (width / 2) / math.tan(half)
    y_top = min(-math.tan(elevation_max) / c for c in (1.0, math.cos(half)))
    y_bottom = max(-math.tan(elevation_min) / c for c in (1.0, math.cos(half)))
    height = max(int(math.ceil(f * (y_bottom - y_top))) + 1, 16)
    return CameraIntrinsics(width, height, f, f, (width - 1) / 2.0, -f * y_top)


def fill_holes(depth: np.ndarray) -> np.ndarray:
    """``depth`` with each 0 pixel set to the smallest positive value among its 8 neighbours (0 if none)."""
    big = np.float32(np.inf)
    d = np.where(depth > 0, depth, big)
    pad = np.pad(d, 1, constant_values=big)
    H, W = depth.shape
    near = np.min([pad[1 + dv:1 + dv + H, 1 + du:1 + du + W] for dv in (-1, 0, 1) for du in (-1, 0, 1)], axis=0)
    out = np.where(depth > 0, depth, near)
    return np.where(np.isfinite(out), out, 0.0).astype(np.float32)


def scan_depth_views(scan: LidarScan, elevation_min: float, elevation_max: float, views: int = 4,
                     width: int = 60) -> list[tuple[np.ndarray, CameraIntrinsics, np.ndarray]]:
    """[(depth float32 (H, W) m, 0 where no return; intrinsics; T_world_view 4x4)] of ``scan`` (module
    docstring). The field [elevation_min, elevation_max] [rad] sizes the images (a LiDAR model's)."""
    K = view_intrinsics(views, width, elevation_min, elevation_max)
    R_views = view_rotations(views)
    T_ws = np.asarray(scan.T_world_sensor, dtype=np.float64)
    q = np.asarray(scan.points, dtype=np.float64).reshape(-1, 3)
    az = np.arctan2(q[:, 1], q[:, 0]) if len(q) else np.empty(0)
    which = np.floor((az + math.pi / views) / (2 * math.pi / views)).astype(np.int64) % views
    out = []
    for k in range(views):
        pts = q[which == k] @ R_views[k]  # optical frame of view k
        depth = np.zeros((K.height, K.width), np.float32)
        front = pts[:, 2] > 1e-3
        pts = pts[front]
        u = np.floor(K.fx * pts[:, 0] / pts[:, 2] + K.cx + 0.5).astype(np.int64)
        v = np.floor(K.fy * pts[:, 1] / pts[:, 2] + K.cy + 0.5).astype(np.int64)
        ok = (u >= 0) & (u < K.width) & (v >= 0) & (v < K.height)
        u, v, z = u[ok], v[ok], pts[ok, 2].astype(np.float32)
        order = np.argsort(-z, kind="stable")  # farthest first: the nearest return is written last
        depth[v[order], u[order]] = z[order]
        depth = fill_holes(depth)
        T = np.eye(4)
        T[:3, :3] = T_ws[:3, :3] @ R_views[k]
        T[:3, 3] = T_ws[:3, 3]
        out.append((depth, K, T))
    return out
