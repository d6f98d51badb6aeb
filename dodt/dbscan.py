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
    counts = np.zeros(n, np.int64)
    for i in range(n):
        for dx in (-1, 0, 1):
            x = cell[i, 0] + dx
            if x < 0 or x >= dims[0]:
                continue
            for dy in (-1, 0, 1):
                y = cell[i, 1] + dy
                if y < 0 or y >= dims[1]:
                    continue
                for dz in (-1, 0, 1):
                    z = cell[i, 2] + dz
                    if z < 0 or z >= dims[2]:
                        continue
                    k = (x * dims[1] + y) * dims[2] + z
                    for s in range(start[k], start[k + 1]):
                        j = order[s]
                        d0 = points[i, 0] - points[j, 0]
                        d1 = points[i, 1] - points[j, 1]
                        d2 = points[i, 2] - points[j, 2]
                        if d0 * d0 + d1 * d1 + d2 * d2 <= eps2:
                            counts[i] += 1  # the point itself included, as the reference does
    core = counts >= min_points
    parent = np.arange(n)
    border_of = -np.ones(n, np.int64)
    for i in range(n):
        for dx in (-1, 0, 1):
            x = cell[i, 0] + dx
            if x < 0 or x >= dims[0]:
                continue
            for dy in (-1, 0, 1):
                y = cell[i, 1] + dy
                if y < 0 or y >= dims[1]:
                    continue
                for dz in (-1, 0, 1):
                    z = cell[i, 2] + dz
                    if z < 0 or z >= dims[2]:
                        continue
                    k = (x * dims[1] + y) * dims[2] + z
                    for s in range(start[k], start[k + 1]):
                        j = order[s]
                        if not core[j]:
                            continue
                        d0 = points[i, 0] - points[j, 0]
                        d1 = points[i, 1] - points[j, 1]
                        d2 = points[i, 2] - points[j, 2]
                        if d0 * d0 + d1 * d1 + d2 * d2 > eps2:
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
