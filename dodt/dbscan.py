"""DBSCAN detector on the voxel-filtered cloud (paper Sec. III-A; ref dbscan.cpp).

Core points have at least ``min_points`` neighbours within ``eps`` (the point itself
included, as in the reference); clusters are the connected core points plus the border
points next to them; everything else is noise. Neighbour search by a k-d tree (SciPy).
"""
from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from dodt.config import DBSCANConfig
from dodt.detection import Detection


def dbscan_labels(points: np.ndarray, eps: float, min_points: int) -> np.ndarray:
    """Cluster label per point, -1 for noise."""
    n = len(points)
    labels = -np.ones(n, np.int64)
    if n == 0:
        return labels
    tree = cKDTree(points)
    counts = tree.query_ball_point(points, eps, return_length=True)
    core = counts >= min_points
    if not np.any(core):
        return labels
    pairs = tree.query_pairs(eps, output_type="ndarray")
    if len(pairs):
        both = core[pairs[:, 0]] & core[pairs[:, 1]]
        cp = pairs[both]
    else:
        cp = np.empty((0, 2), np.int64)
    core_idx = np.flatnonzero(core)
    slot = -np.ones(n, np.int64)
    slot[core_idx] = np.arange(core_idx.size)
    g = coo_matrix((np.ones(len(cp)), (slot[cp[:, 0]], slot[cp[:, 1]])), shape=(core_idx.size, core_idx.size))
    _, comp = connected_components(g, directed=False)
    labels[core_idx] = comp
    if len(pairs):  # border points join the cluster of a core neighbour
        a, b = pairs[:, 0], pairs[:, 1]
        m1 = core[a] & ~core[b]
        labels[b[m1]] = labels[a[m1]]
        m2 = core[b] & ~core[a]
        labels[a[m2]] = labels[b[m2]]
    return labels


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
