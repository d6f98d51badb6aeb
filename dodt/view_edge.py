"""Which sides of a detection the image's left and right edges cut, and where its sides lie.

An obstacle partly out of view is detected as the part in view. The centre of that part slides
along the image's edge as the obstacle walks into or out of the view, or as the camera turns: a
person crossing the edge sideways moves the centre of their visible part at about half their own
sideways speed. A track measured on those centres reports that slide as its velocity, and carries
it when it coasts on out of view. The side of the detection inside the view, though, is a true side
of the obstacle. The tracker measures a cut obstacle from that side (dodt.tracker.Track), at the
distance it measured from that side to the obstacle's anchor while the whole obstacle was in view.

Sides are measured across the line of sight: a point's lateral coordinate is its horizontal offset
from the camera along the unit vector perpendicular to the ray to the detection's points (to the
image's right).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from dodt.frames import CameraIntrinsics

MIN_POINTS = 5


@dataclass(frozen=True)
class ViewSides:
    cut: int  # 0: the whole detection is in view; -1: cut by the image's left edge; 1: by its right; 2: both
    origin: np.ndarray  # (2,) the camera's horizontal position
    axis: np.ndarray  # (2,) horizontal unit vector across the line of sight, to the image's right
    low: float  # m, lateral coordinate of the detection's left side (view_sides)
    high: float  # m, ... of its right side

    def lateral(self, xy: np.ndarray) -> float:
        return float((np.asarray(xy, float)[:2] - self.origin) @ self.axis)


def view_sides(points: np.ndarray, K: CameraIntrinsics, T_world_camera: np.ndarray, margin_px: float,
               voxel: float) -> ViewSides | None:
    """The detection's sides and which image edges cut it, from its points (world, (M, 3)).

    ``margin_px``: the border the point cloud skips; ``voxel``: its voxel size (m). A side is cut
    when some point lies within its voxel's image width of that border. None: too few points, or a
    point behind the camera."""
    if len(points) < MIN_POINTS:
        return None
    T = np.asarray(T_world_camera, dtype=np.float64)
    r = _sides(np.asarray(points), T[:3, :3], T[:3, 3], float(K.fx), float(K.cx), float(K.width), float(margin_px),
               float(voxel))
    if r[0] == 9:
        return None
    cut, ax, ay, low, high = r
    return ViewSides(cut=int(cut), origin=T[:2, 3].copy(), axis=np.array([ax, ay]), low=low, high=high)


@njit(cache=True, nogil=True)
def _sides(p, R, t, fx, cx, width, margin, voxel):
    """view_sides' work: (cut, axis x, axis y, low, high); cut 9: no sides (a point behind the
    camera, or the points on the camera's vertical). A side is the median, over horizontal slices a
    voxel high, of each slice's extreme lateral coordinate: swinging arms and legs move the extremes
    of their own slices only."""
    n = p.shape[0]
    left = False
    right = False
    mx = 0.0
    my = 0.0
    zmin = np.inf
    zmax = -np.inf
    for i in range(n):
        dx, dy, dz = p[i, 0] - t[0], p[i, 1] - t[1], p[i, 2] - t[2]
        xc = dx * R[0, 0] + dy * R[1, 0] + dz * R[2, 0]
        zc = dx * R[0, 2] + dy * R[1, 2] + dz * R[2, 2]
        if not zc > 1e-6:
            return 9, 0.0, 0.0, 0.0, 0.0
        u = fx * xc / zc + cx
        reach = fx * voxel / zc  # a voxel's width in pixels there
        if u - reach < margin:
            left = True
        if u + reach > width - 1 - margin:
            right = True
        mx += dx
        my += dy
        zmin = min(zmin, p[i, 2])
        zmax = max(zmax, p[i, 2])
    norm = math.hypot(mx, my)
    if not norm > 1e-9:
        return 9, 0.0, 0.0, 0.0, 0.0
    ax, ay = my / norm, -mx / norm  # the ray to the points' mean turned 90 degrees clockwise (from above)
    if ax * R[0, 0] + ay * R[1, 0] < 0:  # the camera rolled over: keep "right" the image's right
        ax, ay = -ax, -ay
    base = math.floor(zmin / voxel)
    m = int(math.floor(zmax / voxel) - base) + 1
    lo = np.full(m, np.inf)
    hi = np.full(m, -np.inf)
    for i in range(n):
        b = int(math.floor(p[i, 2] / voxel) - base)
        lat = (p[i, 0] - t[0]) * ax + (p[i, 1] - t[1]) * ay
        if lat < lo[b]:
            lo[b] = lat
        if lat > hi[b]:
            hi[b] = lat
    used = lo <= hi
    cut = 2 if left and right else -1 if left else 1 if right else 0
    return cut, ax, ay, float(np.median(lo[used])), float(np.median(hi[used]))
