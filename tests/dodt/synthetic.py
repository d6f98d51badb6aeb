"""Analytic depth images of axis-aligned boxes on a floor, for perception tests (no simulator)."""
import numpy as np

from dodt.frames import CameraIntrinsics

# Optical frame looking along world +x, from a camera at height h.
R_LOOK_X = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def camera_pose(x=0.0, y=0.0, z=1.2, yaw=0.0):
    c, s = np.cos(yaw), np.sin(yaw)
    Rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    T = np.eye(4)
    T[:3, :3] = Rz @ R_LOOK_X
    T[:3, 3] = [x, y, z]
    return T


def render_depth(K: CameraIntrinsics, T: np.ndarray, boxes, floor: bool = True) -> np.ndarray:
    """Planar depth [m] (float32, 0 = nothing) of boxes given as (lo, hi) world corners."""
    v, u = np.mgrid[0:K.height, 0:K.width]
    rays_c = np.stack([(u - K.cx) / K.fx, (v - K.cy) / K.fy, np.ones_like(u, float)], axis=-1)  # z = 1
    d = rays_c @ T[:3, :3].T  # world directions, scaled so that planar depth = t
    o = T[:3, 3]
    best = np.full(u.shape, np.inf)
    for lo, hi in boxes:
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (lo - o) / d, (hi - o) / d
        tn = np.nanmax(np.minimum(t1, t2), axis=-1)
        tf = np.nanmin(np.maximum(t1, t2), axis=-1)
        hit = (tn <= tf) & (tn > 0)
        best = np.where(hit & (tn < best), tn, best)
    if floor:
        with np.errstate(divide="ignore", invalid="ignore"):
            tfloor = -o[2] / d[..., 2]
        ok = (d[..., 2] < 0) & (tfloor > 0)
        best = np.where(ok & (tfloor < best), tfloor, best)
    best[~np.isfinite(best)] = 0.0
    return best.astype(np.float32)
