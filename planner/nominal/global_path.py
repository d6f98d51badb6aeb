"""Global path: A* on a 2D occupancy grid at the flight altitude, then shortcutting.

The grid is the voxel map's column view (a cell is blocked when any voxel of the altitude band
is occupied, inflated by the robot size). Unknown space counts as free: the path is optimistic
and the MPC, which sees the map too, keeps the drone off whatever appears. The search is an
8-connected A* with the octile-distance heuristic (admissible, so the path is shortest on the
grid), compiled with numba.
"""
from __future__ import annotations

import math

import cv2
import numpy as np
from numba import njit
from scipy.ndimage import distance_transform_edt

_SQRT2 = math.sqrt(2.0)


@njit(cache=True, nogil=True)
def block_discs(blocked, centres, radii, ox, oy, res):
    """Marks in blocked (nx, ny) every cell whose centre, origin + (i + 0.5, j + 0.5) res, lies within
    radii[m] of centres[m] (M, 2); discs off the grid, or not finite, mark nothing."""
    nx, ny = blocked.shape
    for m in range(centres.shape[0]):
        cx, cy, r = centres[m, 0], centres[m, 1], radii[m]
        if not (math.isfinite(cx) and math.isfinite(cy) and math.isfinite(r)):
            continue
        # clamped as floats, converted after: a coordinate beyond int64 never reaches the conversion
        i0, j0 = max(np.floor((cx - r - ox) / res), 0.0), max(np.floor((cy - r - oy) / res), 0.0)
        i1, j1 = min(np.floor((cx + r - ox) / res), nx - 1.0), min(np.floor((cy + r - oy) / res), ny - 1.0)
        if i0 > i1 or j0 > j1:
            continue
        for i in range(int(i0), int(i1) + 1):
            x = ox + (i + 0.5) * res
            for j in range(int(j0), int(j1) + 1):
                if math.hypot(x - cx, oy + (j + 0.5) * res - cy) <= r:
                    blocked[i, j] = True


@njit(cache=True)
def _heap_push(heap_f, heap_i, n, f, i):
    heap_f[n] = f
    heap_i[n] = i
    k = n
    while k > 0:
        parent = (k - 1) // 2
        if heap_f[parent] <= heap_f[k]:
            break
        heap_f[parent], heap_f[k] = heap_f[k], heap_f[parent]
        heap_i[parent], heap_i[k] = heap_i[k], heap_i[parent]
        k = parent
    return n + 1


@njit(cache=True)
def _heap_pop(heap_f, heap_i, n):
    top = heap_i[0]
    n -= 1
    heap_f[0] = heap_f[n]
    heap_i[0] = heap_i[n]
    k = 0
    while True:
        left = 2 * k + 1
        if left >= n:
            break
        child = left
        if left + 1 < n and heap_f[left + 1] < heap_f[left]:
            child = left + 1
        if heap_f[k] <= heap_f[child]:
            break
        heap_f[child], heap_f[k] = heap_f[k], heap_f[child]
        heap_i[child], heap_i[k] = heap_i[k], heap_i[child]
        k = child
    return top, n


@njit(cache=True)
def _step(blocked, ci, cj, di, dj):
    """Length (cells) of the 8-connected move from (ci, cj) by (di, dj), or -1 where it is not allowed: off
    the grid, into a blocked cell, or cutting a blocked corner."""
    nx, ny = blocked.shape
    ni, nj = ci + di, cj + dj
    if (di == 0 and dj == 0) or ni < 0 or nj < 0 or ni >= nx or nj >= ny or blocked[ni, nj]:
        return -1.0
    if di != 0 and dj != 0:
        if blocked[ci + di, cj] or blocked[ci, cj + dj]:
            return -1.0  # no corner cutting
        return math.sqrt(2.0)
    return 1.0


@njit(cache=True)
def _search(blocked, si, sj, gi, gj):
    """Best-first search over the 8-connected grid from (si, sj): A* toward (gi, gj) with the octile
    heuristic (admissible: shortest on the grid), stopping there; with gi < 0, Dijkstra over every cell
    reachable. Returns (g, parent), flattened: path length in cells from the start, previous cell (-1)."""
    nx, ny = blocked.shape
    total = nx * ny
    g = np.full(total, np.inf)
    parent = np.full(total, -1, dtype=np.int64)
    closed = np.zeros(total, dtype=np.bool_)
    cap = 8 * total + 1
    heap_f = np.empty(cap)
    heap_i = np.empty(cap, dtype=np.int64)
    start, goal = si * ny + sj, (gi * ny + gj if gi >= 0 else -1)
    g[start] = 0.0
    n = _heap_push(heap_f, heap_i, 0, 0.0, start)
    sqrt2 = math.sqrt(2.0)
    while n > 0:
        cur, n = _heap_pop(heap_f, heap_i, n)
        if closed[cur]:
            continue
        if cur == goal:
            break
        closed[cur] = True
        ci, cj = cur // ny, cur % ny
        for di in range(-1, 2):
            for dj in range(-1, 2):
                step = _step(blocked, ci, cj, di, dj)
                if step < 0.0:
                    continue
                ni, nj = ci + di, cj + dj
                nb = ni * ny + nj
                if closed[nb]:
                    continue
                ng = g[cur] + step
                if ng < g[nb]:
                    g[nb] = ng
                    parent[nb] = cur
                    h = 0.0
                    if goal >= 0:
                        dx, dy = abs(ni - gi), abs(nj - gj)
                        h = (dx + dy) + (sqrt2 - 2.0) * min(dx, dy)
                    n = _heap_push(heap_f, heap_i, n, ng + h, nb)
    return g, parent


@njit(cache=True)
def _astar(blocked, si, sj, gi, gj):
    """Cell indices (flattened, start first) of a shortest 8-connected path; empty if none."""
    g, parent = _search(blocked, si, sj, gi, gj)
    goal = gi * blocked.shape[1] + gj
    if not np.isfinite(g[goal]):
        return np.empty(0, dtype=np.int64)
    count = 0
    k = goal
    while k != -1:
        count += 1
        k = parent[k]
    out = np.empty(count, dtype=np.int64)
    k = goal
    for m in range(count - 1, -1, -1):
        out[m] = k
        k = parent[k]
    return out


@njit(cache=True, nogil=True)
def _field(blocked, si, sj):
    """Path length in cells (flattened (nx, ny); inf where unreachable) from (si, sj) to every cell over the
    8-connected grid, moves as in _step: Dijkstra with unit-wide buckets (Dial). Every move is at least one
    cell long, so no cell of a bucket can lower another of the same bucket: each cell's length is the least,
    over its neighbours, of the neighbour's length plus the move, exactly the values _search gives."""
    nx, ny = blocked.shape
    total = nx * ny
    g = np.full(total, np.inf)
    done = np.zeros(total, dtype=np.bool_)
    # three buckets suffice: from bucket b every move lands in b + 1 or b + 2 (moves are 1 or sqrt 2 long)
    cap = 8 * total + 1
    buf = np.empty((3, cap), dtype=np.int64)
    count = np.zeros(3, dtype=np.int64)
    start = si * ny + sj
    g[start] = 0.0
    buf[0, 0] = start
    count[0] = 1
    pending = 1
    sqrt2 = math.sqrt(2.0)
    b = 0
    while pending > 0:
        q = b % 3
        while count[q] > 0:
            count[q] -= 1
            pending -= 1
            cur = buf[q, count[q]]
            if done[cur]:
                continue
            done[cur] = True
            ci, cj = cur // ny, cur % ny
            for di in range(-1, 2):
                for dj in range(-1, 2):
                    ni, nj = ci + di, cj + dj
                    if (di == 0 and dj == 0) or ni < 0 or nj < 0 or ni >= nx or nj >= ny or blocked[ni, nj]:
                        continue
                    step = 1.0
                    if di != 0 and dj != 0:
                        if blocked[ci + di, cj] or blocked[ci, cj + dj]:
                            continue
                        step = sqrt2
                    nb = ni * ny + nj
                    if done[nb]:
                        continue
                    ng = g[cur] + step
                    if ng < g[nb]:
                        g[nb] = ng
                        r = int(ng) % 3
                        buf[r, count[r]] = nb
                        count[r] += 1
                        pending += 1
        b += 1
    return g


def cost_to_go(blocked: np.ndarray, origin_xy, resolution: float, goal_xy) -> np.ndarray:
    """(nx, ny) metres still to fly from each cell's centre to the goal on the grid (8-connected, around
    blocked cells). A blocked cell, or one cut off from the goal, gets the value of the nearest reachable
    cell plus twice the distance to it: the field stays finite and falls toward free space, so a drone
    inside the inflation margin is led out of it. All inf only when no cell reaches the goal."""
    return CostToGo().compute(blocked, origin_xy, resolution, goal_xy)[0]


class CostToGo:
    """cost_to_go that keeps its last field and gives it again while it cannot have changed.

    The search from the goal cell reads, for every cell it reaches, only the cells around it (the move's
    target and, for a diagonal move, the two cells beside it): while the goal cell is the same and no
    cell whose blocked state changed lies next to (or on) a reached cell, the search runs as before and
    the field is the same. The fill of the unreached cells depends only on which cells were reached (and
    the resolution), and is kept on those too."""

    def __init__(self):
        self._last = None  # (key, blocked, cells next to a reached one, field)
        self._fill = None  # (resolution, unreached cells, their nearest reached cells' i, j, 2 res distance)

    def __call__(self, blocked: np.ndarray, origin_xy, resolution: float, goal_xy) -> np.ndarray:
        """The field cost_to_go gives, read-only: it is shared with later calls."""
        blocked = np.ascontiguousarray(blocked, dtype=np.bool_)
        key = (blocked.shape, np.asarray(origin_xy, dtype=float).tobytes(), float(resolution),
               _goal_cell(blocked, origin_xy, resolution, goal_xy))
        last = self._last
        if last is not None and key[3] is not None and last[0] == key and (
                last[1] is blocked or not (last[2] & (last[1] != blocked)).any()):
            return last[3]
        field, near = self.compute(blocked, origin_xy, resolution, goal_xy, key[3])
        field.flags.writeable = False
        self._last = (key, blocked, near, field)
        return field

    def compute(self, blocked: np.ndarray, origin_xy, resolution: float, goal_xy, goal_cell=False):
        """(field, the cells on or next to a reached cell) computed afresh (goal_cell: _goal_cell's answer
        when known)."""
        blocked = np.ascontiguousarray(blocked, dtype=np.bool_)
        nx, ny = blocked.shape
        g = _goal_cell(blocked, origin_xy, resolution, goal_xy) if goal_cell is False else goal_cell
        if g is None:
            return np.full((nx, ny), np.inf), None
        field = _field(blocked, g[0], g[1]).reshape(nx, ny) * resolution
        bad = ~np.isfinite(field)
        if bad.any():
            f = self._fill
            if f is None or f[0] != float(resolution) or f[1].shape != bad.shape or not np.array_equal(f[1], bad):
                dist, (ii, jj) = distance_transform_edt(bad, return_indices=True)
                f = self._fill = (float(resolution), bad, ii[bad], jj[bad], 2.0 * resolution * dist[bad])
            field[bad] = field[f[2], f[3]] + f[4]
        near = cv2.dilate((~bad).view(np.uint8), np.ones((3, 3), np.uint8)).view(bool)
        return field, near


def _goal_cell(blocked: np.ndarray, origin_xy, resolution: float, goal_xy) -> tuple[int, int] | None:
    """The cell the cost-to-go is measured from: the goal's (clipped to the grid), or the free cell nearest
    it; None when there is none near."""
    nx, ny = blocked.shape
    ij = np.floor((np.asarray(goal_xy, dtype=float)[:2] - np.asarray(origin_xy, dtype=float)) / resolution).astype(int)
    return _nearest_free(blocked, int(np.clip(ij[0], 0, nx - 1)), int(np.clip(ij[1], 0, ny - 1)))


@njit(cache=True)
def _line_free(blocked, i0, j0, i1, j1):
    """True if the straight segment between two cell centres crosses no blocked cell."""
    steps = int(max(abs(i1 - i0), abs(j1 - j0)) * 2) + 1
    for s in range(steps + 1):
        t = s / steps
        i = int(round(i0 + (i1 - i0) * t))
        j = int(round(j0 + (j1 - j0) * t))
        if blocked[i, j]:
            return False
    return True


@njit(cache=True)
def _shortcut(blocked, ij):
    """Indices into the path's cells ij (K, 2) kept by greedy line-of-sight shortcutting: from each kept
    cell, the farthest later cell the straight line reaches free (the next cell if none)."""
    K = ij.shape[0]
    keep = np.empty(K, np.int64)
    keep[0] = 0
    n = 1
    while keep[n - 1] < K - 1:
        a = keep[n - 1]
        b = K - 1
        while b > a + 1 and not _line_free(blocked, ij[a, 0], ij[a, 1], ij[b, 0], ij[b, 1]):
            b -= 1
        keep[n] = b
        n += 1
    return keep[:n]


def _nearest_free(blocked: np.ndarray, i: int, j: int, max_radius: int = 15) -> tuple[int, int] | None:
    if not blocked[i, j]:
        return i, j
    nx, ny = blocked.shape
    for r in range(1, max_radius + 1):
        i0, i1, j0, j1 = max(i - r, 0), min(i + r, nx - 1), max(j - r, 0), min(j + r, ny - 1)
        ii, jj = np.nonzero(~blocked[i0:i1 + 1, j0:j1 + 1])
        if len(ii):
            d = (ii + i0 - i) ** 2 + (jj + j0 - j) ** 2
            k = int(np.argmin(d))  # row-major order breaks ties: deterministic
            return int(ii[k] + i0), int(jj[k] + j0)
    return None


def grid_path(blocked: np.ndarray, origin_xy, resolution: float, start_xy, goal_xy) -> np.ndarray | None:
    """Shortest collision-free polyline (K, 2) in world x, y from start to goal on the grid.

    ``blocked[i, j]`` covers the cell whose centre is origin + (i + 0.5, j + 0.5) * resolution.
    A start or goal inside a blocked cell moves to the nearest free cell (the drone may sit inside
    the inflation margin). The polyline starts at ``start_xy`` and ends at ``goal_xy`` (or the
    nearest free cell to it); corners are shortcut where the straight line stays free. Returns
    None when no path exists.
    """
    blocked = np.ascontiguousarray(blocked, dtype=np.bool_)
    o = np.asarray(origin_xy, dtype=float)
    nx, ny = blocked.shape

    def cell(xy):
        ij = np.floor((np.asarray(xy, dtype=float)[:2] - o) / resolution).astype(int)
        return int(np.clip(ij[0], 0, nx - 1)), int(np.clip(ij[1], 0, ny - 1))

    s = _nearest_free(blocked, *cell(start_xy))
    g = _nearest_free(blocked, *cell(goal_xy))
    if s is None or g is None:
        return None
    cells = _astar(blocked, s[0], s[1], g[0], g[1])
    if len(cells) == 0:
        return None
    ij = np.stack([cells // ny, cells % ny], axis=1)
    pts = o + (ij[_shortcut(blocked, ij)] + 0.5) * resolution
    pts[0] = np.asarray(start_xy, dtype=float)[:2]
    if g == cell(goal_xy):
        pts[-1] = np.asarray(goal_xy, dtype=float)[:2]
    return pts


class PathFollower:
    """Arc-length view of a polyline: project a position on it and sample points ahead."""

    def __init__(self, points: np.ndarray):
        pts = np.asarray(points, dtype=float)
        seg = np.diff(pts, axis=0)
        keep = np.concatenate([[True], np.linalg.norm(seg, axis=1) > 1e-9])
        self.points = pts[keep]
        if len(self.points) == 1:
            self.points = np.vstack([self.points, self.points[-1] + 1e-6])
        self.seg = np.diff(self.points, axis=0)
        self.seg_len = np.linalg.norm(self.seg, axis=1)
        self.cum = np.concatenate([[0.0], np.cumsum(self.seg_len)])
        self.length = float(self.cum[-1])

    def project(self, p) -> float:
        """Arc length of the point of the path nearest to p (x, y)."""
        p = np.asarray(p, dtype=float)[: self.points.shape[1]]
        rel = p - self.points[:-1]
        t = np.clip(np.einsum("ij,ij->i", rel, self.seg) / np.maximum(self.seg_len**2, 1e-12), 0.0, 1.0)
        d = np.linalg.norm(rel - t[:, None] * self.seg, axis=1)
        k = int(np.argmin(d))
        return float(self.cum[k] + t[k] * self.seg_len[k])

    def at(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points (K, D) and unit tangents (K, D) at arc lengths s (clipped to the path)."""
        s = np.clip(np.asarray(s, dtype=float), 0.0, self.length)
        k = np.clip(np.searchsorted(self.cum, s, side="right") - 1, 0, len(self.seg) - 1)
        frac = (s - self.cum[k]) / np.maximum(self.seg_len[k], 1e-12)
        pts = self.points[k] + frac[:, None] * self.seg[k]
        tang = self.seg[k] / np.maximum(self.seg_len[k], 1e-12)[:, None]
        return pts, tang
