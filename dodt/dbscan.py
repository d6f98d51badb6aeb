"""DBSCAN detector on the voxel-filtered cloud (paper Sec. III-A; ref dbscan.cpp).

Core points have at least ``min_points`` neighbours within ``eps`` (the point itself
included, as in the reference); clusters are the connected core points plus the border
points next to them; everything else is noise. Neighbour search by a k-d tree (SciPy).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from dodt.config import DBSCANConfig
from dodt.detection import Detection


@njit(cache=True, nogil=True)
def _find(parent, a):
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@njit(cache=True, nogil=True)
def _dbscan_kernel(points, eps, min_points):
    n = points.shape[0]
    labels = -np.ones(n, np.int64)
    if n == 0:
        return labels
    # Grid of eps-sized cells: neighbours within eps lie in the 27 cells around a point's cell.
    mn = np.empty(3)
    for a in range(3):
        mn[a] = points[:, a].min()
    cell = np.empty((n, 3), np.int64)
    dims = np.zeros(3, np.int64)
    for i in range(n):
        for a in range(3):
            c = int((points[i, a] - mn[a]) / eps)
            cell[i, a] = c
            if c + 1 > dims[a]:
                dims[a] = c + 1
    key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    order = np.argsort(key)
    n_cells = dims[0] * dims[1] * dims[2]
    start = np.zeros(n_cells + 1, np.int64)
    for i in range(n):
        start[key[i] + 1] += 1
    for k in range(n_cells):
        start[k + 1] += start[k]
    eps2 = eps * eps
    # One pass finds every point's neighbours (a CSR list); the second pass reuses it.
    cap = 64 * n
    nbr = np.empty(cap, np.int64)
    ptr = np.zeros(n + 1, np.int64)
    m = 0
    for i in range(n):
        xi, yi, zi = points[i, 0], points[i, 1], points[i, 2]
        for dx in (-1, 0, 1):
            x = cell[i, 0] + dx
            if x < 0 or x >= dims[0]:
                continue
            for dy in (-1, 0, 1):
                y = cell[i, 1] + dy
                if y < 0 or y >= dims[1]:
                    continue
                k0 = (x * dims[1] + y) * dims[2]
                z0 = max(cell[i, 2] - 1, 0)
                z1 = min(cell[i, 2] + 1, dims[2] - 1)
                for s in range(start[k0 + z0], start[k0 + z1 + 1]):  # the z-neighbours are contiguous
                    j = order[s]
                    d0 = xi - points[j, 0]
                    d1 = yi - points[j, 1]
                    d2 = zi - points[j, 2]
                    if d0 * d0 + d1 * d1 + d2 * d2 <= eps2:
                        if m == cap:
                            cap *= 2
                            grown = np.empty(cap, np.int64)
                            grown[:m] = nbr[:m]
                            nbr = grown
                        nbr[m] = j
                        m += 1
        ptr[i + 1] = m
    core = np.empty(n, np.bool_)
    for i in range(n):
        core[i] = ptr[i + 1] - ptr[i] >= min_points  # the point itself included, as the reference does
    parent = np.arange(n)
    border_of = -np.ones(n, np.int64)
    for i in range(n):
        for s in range(ptr[i], ptr[i + 1]):
            j = nbr[s]
            if not core[j]:
                continue
            if core[i]:
                a = _find(parent, i)
                b = _find(parent, j)
                if a != b:
                    parent[max(a, b)] = min(a, b)
            elif border_of[i] < 0:
                border_of[i] = j
    next_label = 0
    root_label = -np.ones(n, np.int64)
    for i in range(n):
        if core[i]:
            r = _find(parent, i)
            if root_label[r] < 0:
                root_label[r] = next_label
                next_label += 1
            labels[i] = root_label[r]
    for i in range(n):
        if not core[i] and border_of[i] >= 0:
            labels[i] = labels[border_of[i]]
    return labels


def dbscan_labels(points: np.ndarray, eps: float, min_points: int) -> np.ndarray:
    """Cluster label per point (0, 1, ... in order of first core point), -1 for noise."""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    return _dbscan_kernel(pts, float(eps), int(min_points))


class DBSCANDetector:
    def __init__(self, cfg: DBSCANConfig):
        self.cfg = cfg

    def __call__(self, points: np.ndarray) -> list[Detection]:
        labels = dbscan_labels(points, self.cfg.eps, self.cfg.min_points)
        dets = []
        if labels.size == 0 or labels.max() < 0:
            return dets
        order = np.argsort(labels, kind="stable")
        sl = labels[order]
        starts = np.searchsorted(sl, np.arange(sl.max() + 1))
        ends = np.append(starts[1:], len(sl))
        for s, e in zip(starts, ends):
            if e <= s or sl[s] < 0:
                continue
            pts = points[order[s:e]]
            lo, hi = pts.min(axis=0).astype(float), pts.max(axis=0).astype(float)
            grow = np.maximum(self.cfg.min_size_xy - (hi - lo)[:2], 0.0) / 2
            lo[:2] -= grow
            hi[:2] += grow
            dets.append(Detection.from_bounds(lo, hi, "dbscan", pts))
        return dets
