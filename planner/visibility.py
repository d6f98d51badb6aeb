"""Where a person the camera has not seen could be: the earliest time one could stand on each floor cell.

A grid over the floor (the voxel map's columns) holds, per cell, the earliest time a person nobody has
seen could be there (``arrival``). Every depth frame shows cells free at a person's height (``band``,
world z): the rays that cross a cell before reaching what they hit. Where the camera has not looked,
someone may stand; from there they walk at up to ``speed`` (1.6 m/s), so a cell seen free now can hold
such a person only once one could have walked to it from the cells that could hold one now:

    arrival(c) = earliest arrival(p) + |c - p| / speed  over the cells p that may hold a person now

(p the nearest such cell; the field is kept with OpenCV's distance transform and its nearest-cell
labels). Cells outside the walkable area (beyond the walls, inside structure) never hold anyone. At
the start, the place the drone starts from is known to be clear within ``reset``'s radius.

Two ways to feed it, one per frame: ``observe_depth`` reads a depth frame (each image column's nearest
point at person height ends its ray: what is behind it is hidden); ``observe_map`` casts rays across the
camera's horizontal field of view on a known occupancy grid, for a closed loop that renders no images.
The planner (planner.safe_planner) reads ``reach``: how far a hidden person still is from each cell.
"""
from __future__ import annotations

import math

import cv2
import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _mark(seen, ox, oy, res, x0, y0, x1, y1):
    """Set every cell the segment (x0, y0) -> (x1, y1) crosses (2D DDA walk)."""
    nx, ny = seen.shape
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
            seen[i, j] = True
        if i == i1 and j == j1:
            break
        if tx < ty:
            i += si
            tx += tdx
        else:
            j += sj
            ty += tdy


@njit(cache=True, nogil=True)
def _mark_rays(seen, ox, oy, res, cx, cy, ends):
    for k in range(ends.shape[0]):
        _mark(seen, ox, oy, res, cx, cy, ends[k, 0], ends[k, 1])


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


def nearest(mask: np.ndarray, res: float) -> tuple[np.ndarray, np.ndarray]:
    """(distance (nx, ny) m from each cell's centre to the nearest cell of ``mask`` (inf where the mask is
    empty), that cell's flat index (nx, ny) int64)."""
    if not mask.any():
        return np.full(mask.shape, np.inf), np.zeros(mask.shape, np.int64)
    d, labels = cv2.distanceTransformWithLabels((~mask).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_5,
                                                labelType=cv2.DIST_LABEL_PIXEL)
    flat = np.flatnonzero(mask)  # label k (from 1) is the k-th cell of the mask in row-major order
    return d.astype(float) * res, flat[labels - 1]


class SeenSpace:
    """The earliest time an unseen person could be on each floor cell (``arrival``, s of sim time).

    origin_xy, shape, resolution: the grid (cell (i, j) covers origin + res * [i, i + 1) x [j, j + 1)),
    the voxel map's columns; walkable (nx, ny) bool: where people can be (the corridor's inside). band:
    the heights (world z, m) a ray must cross a cell at to see it free (a person's torso). max_range: how
    far the depth is trusted (m). short: a ray stops this much before what it hit. speed: how fast an
    unseen person may walk (m/s)."""

    def __init__(self, origin_xy, shape, resolution: float, walkable: np.ndarray | None = None,
                 band=(0.8, 1.6), max_range: float = 5.0, short: float = 0.15, pixel_step: int = 4,
                 speed: float = 1.6):
        self.origin = np.asarray(origin_xy, dtype=float)[:2].copy()
        self.shape = (int(shape[0]), int(shape[1]))
        self.res = float(resolution)
        self.walkable = np.ones(self.shape, bool) if walkable is None else np.asarray(walkable, bool).copy()
        self.band = (float(band[0]), float(band[1]))
        self.max_range, self.short, self.pixel_step = float(max_range), float(short), int(pixel_step)
        self.speed = float(speed)
        self.arrival = np.zeros(self.shape)
        self.stamp = 0.0

    def centres(self) -> np.ndarray:
        """(nx, ny, 2) world x, y of the cell centres."""
        i, j = np.meshgrid(np.arange(self.shape[0]), np.arange(self.shape[1]), indexing="ij")
        return self.origin + (np.stack([i, j], axis=-1) + 0.5) * self.res

    def reset(self, start_xy=None, radius: float = 0.0, stamp: float = 0.0) -> None:
        """Anyone may be anywhere at ``stamp``, but within ``radius`` of ``start_xy`` (known clear)."""
        self.stamp = float(stamp)
        self.arrival = np.full(self.shape, self.stamp)
        if start_xy is not None and radius > 0:
            c = self.centres()
            d = np.hypot(c[..., 0] - start_xy[0], c[..., 1] - start_xy[1])
            self.arrival = self.stamp + np.maximum(radius - d, 0.0) / self.speed
        self.arrival[~self.walkable] = np.inf

    def _update(self, seen: np.ndarray, stamp: float, structure: np.ndarray | None) -> None:
        """The cells ``seen`` free at ``stamp`` hold nobody then; propagate everything else."""
        walkable = self.walkable if structure is None else self.walkable & ~structure
        may = (self.arrival <= stamp) & ~seen & walkable  # could hold someone now
        d, near = nearest(may, self.res)
        arrival = self.arrival.ravel()[near] + d / self.speed
        self.arrival = np.where(may, self.arrival, np.maximum(arrival, stamp))
        self.arrival[~walkable] = np.inf
        self.stamp = float(stamp)

    def observe_depth(self, depth_m: np.ndarray, K, T_world_camera: np.ndarray, stamp: float,
                      structure: np.ndarray | None = None) -> int:
        """Take in what a depth frame (float32 (H, W) m, 0 = no return) saw free at ``stamp``; structure:
        (nx, ny) cells that hold static structure (nobody stands there). Returns the rays cast."""
        T = np.asarray(T_world_camera, dtype=float)
        if not (np.all(np.isfinite(T)) and math.isfinite(stamp)) or stamp < self.stamp:
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
        ends = np.zeros((0, 2))
        if ok.any():
            dx, dy = p[k, cols, 0][ok] - T[0, 3], p[k, cols, 1][ok] - T[1, 3]
            reach = np.minimum(rmin[ok] - self.short, self.max_range) / rmin[ok]
            ends = np.stack([T[0, 3] + dx * reach, T[1, 3] + dy * reach], axis=1)[reach > 0]
        return self._observe(np.ascontiguousarray(ends), T, stamp, structure)

    def observe_map(self, blocked: np.ndarray, K, T_world_camera: np.ndarray, stamp: float,
                    occluders=(), structure: np.ndarray | None = None, angle_step: float = math.radians(1.0)) -> int:
        """Take in what the camera would see free on a known grid ``blocked`` (nx, ny bool: structure at
        person height), rays across its horizontal field of view; ``occluders`` ((center, size) world boxes,
        the people perception reports) stop rays too. Returns the rays cast."""
        T = np.asarray(T_world_camera, dtype=float)
        if not (np.all(np.isfinite(T)) and math.isfinite(stamp)) or stamp < self.stamp:
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
        return self._observe(ends, T, stamp, blocked if structure is None else structure)

    def _observe(self, ends: np.ndarray, T: np.ndarray, stamp: float, structure) -> int:
        seen = np.zeros(self.shape, np.bool_)
        _mark_rays(seen, self.origin[0], self.origin[1], self.res, float(T[0, 3]), float(T[1, 3]), ends)
        self._update(seen, float(stamp), structure)
        return len(ends)

    def reach(self, now: float) -> tuple[np.ndarray, np.ndarray]:
        """(how far (nx, ny) m an unseen person still is from each cell at ``now``: speed times the time
        until one could be there, 0 where one may already be, inf where nobody can; the flat index of the
        nearest cell that may hold one now, or -1 when none does)."""
        left = np.maximum(self.arrival - now, 0.0) * self.speed
        may = self.arrival <= now
        if not may.any():
            return left, np.full(self.shape, -1, np.int64)
        return left, nearest(may, self.res)[1]
