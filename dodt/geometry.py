"""Axis-aligned boxes, 3D IoU, and the camera field-of-view test."""
from __future__ import annotations

import numpy as np

from dodt.frames import CameraIntrinsics


def box_bounds(center: np.ndarray, size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c, s = np.asarray(center, float), np.asarray(size, float)
    return c - s / 2, c + s / 2


def iou_matrix(centers_a: np.ndarray, sizes_a: np.ndarray, centers_b: np.ndarray, sizes_b: np.ndarray) -> np.ndarray:
    """(N, M) 3D IoU of axis-aligned boxes: intersection volume over union volume."""
    ca, sa = np.asarray(centers_a, float).reshape(-1, 3), np.asarray(sizes_a, float).reshape(-1, 3)
    cb, sb = np.asarray(centers_b, float).reshape(-1, 3), np.asarray(sizes_b, float).reshape(-1, 3)
    lo = np.maximum((ca - sa / 2)[:, None, :], (cb - sb / 2)[None, :, :])
    hi = np.minimum((ca + sa / 2)[:, None, :], (cb + sb / 2)[None, :, :])
    inter = np.prod(np.clip(hi - lo, 0.0, None), axis=2)
    va, vb = np.prod(sa, axis=1), np.prod(sb, axis=1)
    union = va[:, None] + vb[None, :] - inter
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(union > 0, inter / union, 0.0)
    return out


def in_field_of_view(points_world: np.ndarray, T_world_camera: np.ndarray, K: CameraIntrinsics,
                     max_depth: float, margin_px: float = 0.0) -> np.ndarray:
    """Mask of the points that project inside the image of a camera at T_world_camera.

    The reference code hard-codes a 84 x 56 degree cone; here the test uses the intrinsics, so
    it is right for any camera.
    """
    R, t = T_world_camera[:3, :3], T_world_camera[:3, 3]
    pc = (np.asarray(points_world, float) - t) @ R  # world -> optical frame
    z = pc[:, 2]
    ok = (z > 1e-6) & (z <= max_depth)
    zs = np.where(ok, z, 1.0)
    u = K.fx * pc[:, 0] / zs + K.cx
    v = K.fy * pc[:, 1] / zs + K.cy
    return ok & (u >= margin_px) & (u <= K.width - 1 - margin_px) & (v >= margin_px) & (v <= K.height - 1 - margin_px)


def points_in_box(points: np.ndarray, center: np.ndarray, size: np.ndarray, grow: float = 0.0) -> np.ndarray:
    lo, hi = box_bounds(center, np.asarray(size) + 2 * grow)
    return np.all((points >= lo) & (points <= hi), axis=1)
