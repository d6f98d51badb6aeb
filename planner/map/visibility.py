"""Where the camera has seen the floor free at a person's height, and since when.

A grid over the floor (the voxel map's columns) holds, per cell, the last time the camera saw through
it at a person's height (``band``, world z) and found nobody: a ray of a depth frame crossed the cell
before reaching what it hit. planner.shield.shield forgets a person it no longer gets reports of once the
camera has seen that person's predicted place free. At the start, the place the drone starts from
counts as seen free within ``reset``'s radius.

Two ways to feed it, one per frame: ``observe_depth`` reads a depth frame (each image column's nearest
point at person height ends its ray: what is behind it is hidden); ``observe_map`` casts rays across the
camera's horizontal field of view on a known occupancy grid, for a closed loop that renders no images.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _mark(last, ox, oy, res, x0, y0, x1, y1, stamp):
    """Set ``last`` to stamp in every cell the segment (x0, y0) -> (x1, y1) crosses (2D DDA walk)."""
    nx, ny = last.shape
    gx0, gy0 = (x0 - ox) / res, (y0 - oy) / res
    gx1, gy1 = (x1 - ox) / res, (y1 - oy) / res
    i, j = int(math.floor(gx0)), int(math.floor(gy0))
    i1, j1 = int(math.floor(gx1)), int(math.floor(gy1))
    dx, dy = gx1 - gx0, gy1 - gy0
    si = 1 if dx > 0 else -1
    sj = 1 if dy > 0 else -1
    tdx = abs(1.0 / dx) if dx != 0 else 1e30
    tdy = abs(1.0 / dy) if dy != 0 else 1e30
    tx = ((i + 1 - gx0) if dx > 0 else (gx0 - i)) * tdx
    ty = ((j + 1 - gy0) if dy > 0 else (gy0 - j)) * tdy
    for _ in range(abs(i1 - i) + abs(j1 - j) + 1):
        if 0 <= i < nx and 0 <= j < ny:
            last[i, j] = stamp
        if i == i1 and j == j1:
            break
        if tx < ty:
            i += si
            tx += tdx
        else:
            j += sj
            ty += tdy


@njit(cache=True, nogil=True)
def _mark_rays(last, ox, oy, res, cx, cy, ends, stamp):
    for k in range(ends.shape[0]):
        _mark(last, ox, oy, res, cx, cy, ends[k, 0], ends[k, 1], stamp)


@njit(cache=True, nogil=True)
def _cast(blocked, ox, oy, res, cx, cy, angles, max_range):
    """End points of rays from (cx, cy) at the given angles: the first blocked cell, or max_range."""
    nx, ny = blocked.shape
    ends = np.empty((angles.shape[0], 2))
    step = 0.5 * res
    for k in range(angles.shape[0]):
        ca, sa = math.cos(angles[k]), math.sin(angles[k])
        r = 0.0
        while r < max_range:
            i = int(math.floor((cx + ca * (r + step) - ox) / res))
            j = int(math.floor((cy + sa * (r + step) - oy) / res))
            if i < 0 or j < 0 or i >= nx or j >= ny or blocked[i, j]:
                break
            r += step
        ends[k, 0] = cx + ca * r
        ends[k, 1] = cy + sa * r
    return ends


class SeenSpace:
    """Last time each floor cell was seen free at person height (seconds, -inf: never).

    origin_xy, shape, resolution: the grid (cell (i, j) covers origin + res * [i, i + 1) x [j, j + 1)),
    the voxel map's columns. band: the heights (world z, m) a ray must cross a cell at to count (a person's torso). max_range: how far
    the depth is trusted (m). short: a ray stops this much before what it hit."""

    def __init__(self, origin_xy, shape, resolution: float, band=(0.8, 1.6), max_range: float = 5.0,
                 short: float = 0.15, pixel_step: int = 4):
        self.origin = np.asarray(origin_xy, dtype=float)[:2].copy()
        self.shape = (int(shape[0]), int(shape[1]))
        self.res = float(resolution)
        self.band = (float(band[0]), float(band[1]))
        self.max_range, self.short, self.pixel_step = float(max_range), float(short), int(pixel_step)
        self.last = np.full(self.shape, -np.inf)

    def centres(self) -> np.ndarray:
        """(nx, ny, 2) world x, y of the cell centres."""
        i, j = np.meshgrid(np.arange(self.shape[0]), np.arange(self.shape[1]), indexing="ij")
        return self.origin + (np.stack([i, j], axis=-1) + 0.5) * self.res

    def reset(self, start_xy=None, radius: float = 0.0, stamp: float = 0.0) -> None:
        """Forget everything; cells within ``radius`` of ``start_xy`` count as seen free at ``stamp``."""
        self.last.fill(-np.inf)
        if start_xy is not None and radius > 0:
            c = self.centres()
            self.last[np.hypot(c[..., 0] - start_xy[0], c[..., 1] - start_xy[1]) <= radius] = stamp

    def observe_depth(self, depth_m: np.ndarray, K, T_world_camera: np.ndarray, stamp: float) -> int:
        """Mark what a depth frame (float32 (H, W) m, 0 = no return) saw free; returns the rays cast."""
        T = np.asarray(T_world_camera, dtype=float)
        if not (np.all(np.isfinite(T)) and math.isfinite(stamp)):
            return 0
        s = self.pixel_step
        d = np.asarray(depth_m, dtype=np.float32)[::s, ::s].astype(float)
        v, u = np.mgrid[0:depth_m.shape[0]:s, 0:depth_m.shape[1]:s]
        with np.errstate(invalid="ignore"):
            valid = np.isfinite(d) & (d > 0)
        d = np.where(valid, d, 0.0)
        rays = np.stack([(u - K.cx) / K.fx * d, (v - K.cy) / K.fy * d, d], axis=-1)
        p = rays @ T[:3, :3].T + T[:3, 3]
        inband = valid & (p[..., 2] >= self.band[0]) & (p[..., 2] <= self.band[1])
        r = np.where(inband, np.hypot(p[..., 0] - T[0, 3], p[..., 1] - T[1, 3]), np.inf)
        k = np.argmin(r, axis=0)  # per image column, the nearest point at person height
        cols = np.arange(r.shape[1])
        rmin = r[k, cols]
        ok = np.isfinite(rmin) & (rmin > 1e-3)
        if not ok.any():
            return 0
        dx, dy = p[k, cols, 0][ok] - T[0, 3], p[k, cols, 1][ok] - T[1, 3]
        reach = np.minimum(rmin[ok] - self.short, self.max_range) / rmin[ok]
        ends = np.stack([T[0, 3] + dx * reach, T[1, 3] + dy * reach], axis=1)[reach > 0]
        _mark_rays(self.last, self.origin[0], self.origin[1], self.res, float(T[0, 3]), float(T[1, 3]),
                   np.ascontiguousarray(ends), float(stamp))
        return len(ends)

    def observe_map(self, blocked: np.ndarray, K, T_world_camera: np.ndarray, stamp: float, occluders=(),
                    angle_step: float = math.radians(1.0)) -> int:
        """Mark what the camera would see free on a known grid ``blocked`` (nx, ny bool: structure at person
        height), rays across its horizontal field of view; ``occluders`` ((center, size) world boxes, the
        people perception reports) stop rays too. Returns the rays cast."""
        T = np.asarray(T_world_camera, dtype=float)
        if not (np.all(np.isfinite(T)) and math.isfinite(stamp)):
            return 0
        grid = np.array(blocked, dtype=np.bool_)
        if len(occluders):
            c = self.centres()
            for centre, size in occluders:
                centre, size = np.asarray(centre, float), np.asarray(size, float)
                if np.all(np.isfinite(centre[:2])) and np.all(np.isfinite(size[:2])):
                    rr = 0.5 * float(np.hypot(size[0], size[1]))
                    grid |= np.hypot(c[..., 0] - centre[0], c[..., 1] - centre[1]) <= rr
        fwd = T[:3, 2]
        heading = math.atan2(fwd[1], fwd[0])
        left, right = math.atan2(K.cx, K.fx), math.atan2(K.width - K.cx, K.fx)
        angles = heading + np.arange(-right, left + 1e-9, angle_step)
        ends = _cast(grid, self.origin[0], self.origin[1], self.res, float(T[0, 3]), float(T[1, 3]), angles,
                     self.max_range)
        _mark_rays(self.last, self.origin[0], self.origin[1], self.res, float(T[0, 3]), float(T[1, 3]), ends,
                   float(stamp))
        return len(ends)
