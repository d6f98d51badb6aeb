"""Axis-aligned boxes, 3D IoU, and the camera field-of-view test."""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from dodt.frames import CameraIntrinsics


def wrap_angle(a: float) -> float:
    """The angle a [rad] brought into [-pi, pi)."""
    return (a + math.pi) % (2 * math.pi) - math.pi


def box_bounds(center: np.ndarray, size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c, s = np.asarray(center, float), np.asarray(size, float)
    return c - s / 2, c + s / 2


def iou_matrix(centers_a: np.ndarray, sizes_a: np.ndarray, centers_b: np.ndarray, sizes_b: np.ndarray) -> np.ndarray:
    """(N, M) 3D IoU of axis-aligned boxes: intersection volume over union volume."""
    ca, sa = np.asarray(centers_a, float).reshape(-1, 3), np.asarray(sizes_a, float).reshape(-1, 3)
    cb, sb = np.asarray(centers_b, float).reshape(-1, 3), np.asarray(sizes_b, float).reshape(-1, 3)
    return _iou_matrix(ca, sa, cb, sb)


@njit(cache=True, nogil=True)
def _maximum(x, y):
    """np.maximum of two floats (NaN propagates)."""
    return x if x != x or x >= y else y


@njit(cache=True, nogil=True)
def _minimum(x, y):
    """np.minimum of two floats (NaN propagates)."""
    return x if x != x or x <= y else y


@njit(cache=True, nogil=True)
def _iou_matrix(ca, sa, cb, sb):
    """iou_matrix's arithmetic, pair by pair in numpy's order: bounds c -+ s / 2, overlap per axis
    clipped at 0, volumes as products x y z from left to right, union va + vb - inter."""
    n, m = ca.shape[0], cb.shape[0]
    out = np.empty((n, m))
    va = np.empty(n)
    vb = np.empty(m)
    for i in range(n):
        va[i] = sa[i, 0] * sa[i, 1] * sa[i, 2]
    for j in range(m):
        vb[j] = sb[j, 0] * sb[j, 1] * sb[j, 2]
    for i in range(n):
        for j in range(m):
            inter = 1.0
            for a in range(3):
                lo = _maximum(ca[i, a] - sa[i, a] / 2, cb[j, a] - sb[j, a] / 2)
                hi = _minimum(ca[i, a] + sa[i, a] / 2, cb[j, a] + sb[j, a] / 2)
                w = hi - lo
                inter = inter * (w if w > 0.0 or w != w else 0.0)
            union = va[i] + vb[j] - inter
            out[i, j] = inter / union if union > 0 else 0.0
    return out


def half_view(K: CameraIntrinsics) -> float:
    """Half the camera's horizontal field of view [rad], to the wider of the image's sides."""
    return math.atan2(max(K.cx, K.width - K.cx), K.fx)


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


def box_cut_by_view_side(center: np.ndarray, size: np.ndarray, K: CameraIntrinsics, T_world_camera: np.ndarray) -> bool:
    """Whether a world box seen from the camera crosses the image's left or right edge, or reaches
    behind the camera: only part of it can be in view. (The corners of a box lifted from a 2D box
    that lie nearer than its median depth project wider than the 2D box, so a 2D box touching the
    edge gives a cut 3D box.)"""
    lo, hi = box_bounds(center, size)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    R, t = T_world_camera[:3, :3], T_world_camera[:3, 3]
    pc = (corners - t) @ R
    if np.any(pc[:, 2] <= 1e-6):
        return True
    u = K.fx * pc[:, 0] / pc[:, 2] + K.cx
    return bool(u.min() < 0.0 or u.max() > K.width - 1)


@njit(cache=True, nogil=True)
def column_bounds(pts):
    """Per-column minimum and maximum of an (N, 3) array as float64, the values numpy's
    min(axis=0) and max(axis=0) give (a NaN in a column makes both NaN)."""
    n = pts.shape[0]
    if n == 0:
        raise ValueError("no points")
    lo = np.empty(3)
    hi = np.empty(3)
    for a in range(3):
        mn = pts[0, a]
        mx = mn
        for i in range(1, n):
            v = pts[i, a]
            if v != v:  # NaN wins, as in numpy
                mn = v
                mx = v
                break
            if v < mn:
                mn = v
            elif v > mx:
                mx = v
        if mn != mn:
            mx = mn
        lo[a] = mn
        hi[a] = mx
    return lo, hi


@njit(cache=True, nogil=True)
def crop_to_box(points, lo, hi):
    """points[np.all((points >= lo) & (points <= hi), axis=1)] of (N, 3) points: the rows within
    the bounds, in order, as a new array."""
    n = points.shape[0]
    keep = np.empty(n, np.bool_)
    m = 0
    for i in range(n):
        ok = True
        for a in range(3):
            x = points[i, a]
            ok = ok and x >= lo[a] and x <= hi[a]
        keep[i] = ok
        m += ok
    out = np.empty((m, 3), points.dtype)
    j = 0
    for i in range(n):
        if keep[i]:
            out[j] = points[i]
            j += 1
    return out


def points_in_box(points: np.ndarray, center: np.ndarray, size: np.ndarray, grow: float = 0.0) -> np.ndarray:
    lo, hi = box_bounds(center, np.asarray(size) + 2 * grow)
    return np.all((points >= lo) & (points <= hi), axis=1)


def complete_hidden_depth(center: np.ndarray, size: np.ndarray, camera: np.ndarray,
                          max_depth: float) -> tuple[np.ndarray, np.ndarray]:
    """Extend a box seen only from the front away from the camera.

    A depth camera sees the near surface of an obstacle, so a box built from its points is
    thinner along the viewing direction than the obstacle. When the box's horizontal extent
    along the ray from the camera is smaller than its extent across it (capped at
    ``max_depth``), its far side is pushed back until the two match: the obstacle is assumed
    about as deep as it is wide. Axis-aligned in, axis-aligned out.
    """
    c, s = np.asarray(center, float).copy(), np.asarray(size, float).copy()
    ray = c[:2] - np.asarray(camera, float)[:2]
    n = np.linalg.norm(ray)
    if n < 1e-6:
        return c, s
    r = np.abs(ray / n)
    along = r[0] * s[0] + r[1] * s[1]
    across = r[1] * s[0] + r[0] * s[1]
    missing = min(across, max_depth) - along
    if missing <= 0:
        return c, s
    # grow each horizontal axis in proportion to its share of the ray, on the far side
    for a in range(2):
        grow = missing * r[a]
        s[a] += grow
        c[a] += np.sign(ray[a]) * grow / 2
    return c, s
