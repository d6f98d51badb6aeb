"""DBSCAN detector on the voxel-filtered cloud (paper Sec. III-A; ref dbscan.cpp).

Core points have at least ``min_points`` neighbours within ``eps`` (the point itself
included, as in the reference); clusters are the connected core points plus the border
points next to them; everything else is noise. Clusters are numbered 0, 1, ... in order of
their first core point (by index). A border point next to several clusters joins the one of
its core neighbour in the lowest grid cell (cells of size eps from the cloud's minimum,
ordered by x, then y, then z), the lowest index within that cell. Neighbour search on that
grid (numba).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from dodt.config import DBSCANConfig
from dodt.detection import Detection
from dodt.geometry import column_bounds


@njit(cache=True, nogil=True)
def _find(parent, a):
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@njit(cache=True, nogil=True)
def _grown(a, cap):
    out = np.empty(cap, a.dtype)
    out[: a.shape[0]] = a
    return out


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
    # Counting sort by cell key (x, y, z): cell k holds positions start[k] .. start[k + 1] - 1,
    # and the cells of one (x, y) column are contiguous in z.
    key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    n_cells = dims[0] * dims[1] * dims[2]
    start = np.zeros(n_cells + 1, np.int64)
    for i in range(n):
        start[key[i] + 1] += 1
    for k in range(n_cells):
        start[k + 1] += start[k]
    order = np.empty(n, np.int64)  # position -> point index
    fill = start[:-1].copy()
    for i in range(n):
        order[fill[key[i]]] = i
        fill[key[i]] += 1
    # Coordinates copied in cell order, one array per axis: the pair loop reads them sequentially.
    xs = np.empty(n)
    ys = np.empty(n)
    zs = np.empty(n)
    for p in range(n):
        xs[p] = points[order[p], 0]
        ys[p] = points[order[p], 1]
        zs[p] = points[order[p], 2]
    eps2 = eps * eps
    # Each pair of neighbouring cells is visited once ("half neighbourhood"): a cell with itself and
    # with the 13 cells after it in key order, so each pair within eps is found once, as p < q.
    # The pairs are kept as a CSR list (the q of position p at nbr[ptr[p]:ptr[p + 1]]) for the
    # union pass, which needs the core flags of both ends.
    cap = 32 * n
    nbr = np.empty(cap, np.int32)
    ptr = np.zeros(n + 1, np.int64)
    m = 0
    lo = np.empty(5, np.int64)  # the 5 runs of positions (contiguous in z) a cell is paired with
    hi = np.empty(5, np.int64)
    b = 0
    while b < n:  # one occupied cell, positions b .. e - 1
        i = order[b]
        cx, cy, cz = cell[i, 0], cell[i, 1], cell[i, 2]
        k = key[i]
        e = start[k + 1]
        # run 0: this cell and the one above it (the positions after p, see below)
        hi[0] = start[k + 2] if cz + 1 < dims[2] else e
        # runs 1-4: the columns (x, y+1), (x+1, y-1), (x+1, y), (x+1, y+1), z-1 .. z+1
        z0 = max(cz - 1, 0)
        z1 = min(cz + 1, dims[2] - 1)
        r = 1
        for dx, dy in ((0, 1), (1, -1), (1, 0), (1, 1)):
            x = cx + dx
            y = cy + dy
            if x < dims[0] and 0 <= y < dims[1]:
                k0 = (x * dims[1] + y) * dims[2]
                lo[r] = start[k0 + z0]
                hi[r] = start[k0 + z1 + 1]
                if hi[r] > lo[r]:
                    r += 1
        for p in range(b, e):
            xp, yp, zp = xs[p], ys[p], zs[p]
            lo[0] = p + 1
            for run in range(r):
                q0 = lo[run]
                q1 = hi[run]
                if m + q1 - q0 > cap:  # rare: amortised doubling
                    cap = 2 * cap + q1 - q0
                    nbr = _grown(nbr, cap)
                for q in range(q0, q1):
                    d0 = xp - xs[q]
                    d1 = yp - ys[q]
                    d2 = zp - zs[q]
                    # Branch-free: about 40 % of the candidates are within eps, so a branch would be
                    # mispredicted often; q is always written and kept by advancing m.
                    nbr[m] = q
                    m += d0 * d0 + d1 * d1 + d2 * d2 <= eps2
            ptr[p + 1] = m
        b = e
    count = np.ones(n, np.int64)  # the point itself included, as the reference does
    for p in range(n):
        count[p] += ptr[p + 1] - ptr[p]
    for s in range(m):
        count[nbr[s]] += 1
    core = count >= min_points
    # Union the core-core pairs (the root of a set is its lowest position). A border point takes
    # the cluster of its core neighbour at the lowest position: the one in the lowest cell (by key),
    # the lowest index within that cell.
    parent = np.arange(n)
    border_of = np.full(n, n, np.int64)  # position of that neighbour; n: none yet
    for p in range(n):
        if core[p]:
            rp = _find(parent, p)
            for s in range(ptr[p], ptr[p + 1]):
                q = nbr[s]
                if core[q]:
                    rq = _find(parent, q)
                    if rq > rp:
                        parent[rq] = rp
                    elif rq < rp:
                        parent[rp] = rq
                        rp = rq
                elif p < border_of[q]:
                    border_of[q] = p
        else:
            for s in range(ptr[p], ptr[p + 1]):
                q = nbr[s]
                if core[q] and q < border_of[p]:
                    border_of[p] = q
    # Clusters numbered in order of their first core point (by index), then the border points.
    pos = np.empty(n, np.int64)  # point index -> position
    for p in range(n):
        pos[order[p]] = p
    next_label = 0
    root_label = -np.ones(n, np.int64)
    for i in range(n):
        p = pos[i]
        if core[p]:
            r = _find(parent, p)
            if root_label[r] < 0:
                root_label[r] = next_label
                next_label += 1
            labels[i] = root_label[r]
    for i in range(n):
        p = pos[i]
        if not core[p] and border_of[p] < n:
            labels[i] = root_label[_find(parent, border_of[p])]
    return labels


def dbscan_labels(points: np.ndarray, eps: float, min_points: int) -> np.ndarray:
    """Cluster label per point (0, 1, ... in order of first core point), -1 for noise; the border
    rule is in the module docstring."""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    return _dbscan_kernel(pts, float(eps), int(min_points))


@njit(cache=True, nogil=True)
def _valley_split(xy, idx, split_width, split_bin, valley_ratio, min_bins, min_points):
    """One cut of the points xy[idx] at their deepest valley: (left, right) index arrays, or two
    empty arrays when there is none (see _split_parts)."""
    n = idx.shape[0]
    none = (idx[:0], idx[:0])
    mx, my = 0.0, 0.0
    for i in range(n):
        mx += xy[idx[i], 0]
        my += xy[idx[i], 1]
    mx /= n
    my /= n
    c = np.empty((n, 2))
    for i in range(n):
        c[i, 0] = xy[idx[i], 0] - mx
        c[i, 1] = xy[idx[i], 1] - my
    axis = np.linalg.eigh(c.T @ c)[1][:, 1]  # the long axis: the larger eigenvalue's vector
    s = c @ axis
    s_min, s_max = s.min(), s.max()
    if s_max - s_min <= split_width:
        return none
    # Each point counts for the two nearest slice centres in proportion to its nearness (linear
    # binning): voxel centroids lie near a 0.1 m lattice, and hard slices of the same width would
    # count 0, 2, 0, 2 ... rows along an axis-aligned obstacle.
    t = (s - s_min) / split_bin
    n_bins = int(np.floor(t.max())) + 2
    counts = np.zeros(n_bins)
    for i in range(n):
        k0 = int(np.floor(t[i]))
        f = t[i] - k0
        counts[k0] += 1 - f
        counts[k0 + 1] += f
    left_peak = np.empty(n_bins)
    right_peak = np.empty(n_bins)
    left_n = np.empty(n_bins)  # points up to each slice centre, about
    run, acc = 0.0, 0.0
    for k in range(n_bins):
        run = max(run, counts[k])
        acc += counts[k]
        left_peak[k] = run
        left_n[k] = acc
    run = 0.0
    for k in range(n_bins - 1, -1, -1):
        run = max(run, counts[k])
        right_peak[k] = run
    best, best_ratio, best_peak = -1, np.inf, 0.0
    for k in range(min_bins, n_bins - min_bins):
        peak = min(left_peak[k - 1], right_peak[k + 1])
        if peak > 0 and left_n[k - 1] >= min_points and n - left_n[k] >= min_points:
            r = counts[k] / peak
            if r < best_ratio:  # the deepest valley, the first of equals
                best, best_ratio, best_peak = k, r, peak
    if best < 0 or best_ratio > valley_ratio:
        return none
    # The valley is the run of slices around the deepest one that stay below the ratio; its points
    # (an arm or a thin link between the two) go to neither part, so the boxes do not reach across.
    floor = valley_ratio * best_peak
    lo = hi = best
    while lo - 1 >= 0 and counts[lo - 1] <= floor:
        lo -= 1
    while hi + 1 < n_bins and counts[hi + 1] <= floor:
        hi += 1
    return idx[t < lo - 0.5], idx[t >= hi + 0.5]


_SPLIT_MAX_DEPTH = 4  # a cluster is cut at most 5 levels deep


@njit(cache=True, nogil=True)
def _split_parts(xy, split_width, split_bin, valley_ratio, min_bins, min_points, max_depth):
    """The parts of one cluster (horizontal coordinates xy), cut at sparse slices (see
    DBSCANConfig.split_width): part number per point (-1: in a valley), parts numbered depth first,
    left part first.

    The long axis is the principal axis of xy. Slices of ``split_bin`` along it are counted; a slice
    is a valley when its count is at most ``valley_ratio`` of the highest slice on each side of it,
    and each side is at least ``min_bins`` slices long and has ``min_points`` points. The cluster is
    cut at its deepest valley, and each part again (at most ``max_depth`` + 1 levels deep); the
    valley's own points belong to neither part."""
    n = xy.shape[0]
    labels = -np.ones(n, np.int64)
    stack = [(np.arange(n), 0)]
    part = 0
    while len(stack) > 0:
        idx, depth = stack.pop()
        cut = False
        if split_width > 0 and idx.shape[0] >= 2 * min_points and depth <= max_depth:
            ex = xy[idx, 0].max() - xy[idx, 0].min()
            ey = xy[idx, 1].max() - xy[idx, 1].min()
            if np.hypot(ex, ey) > split_width:
                left, right = _valley_split(xy, idx, split_width, split_bin, valley_ratio, min_bins, min_points)
                if left.shape[0] + right.shape[0] > 0:
                    stack.append((right, depth + 1))
                    stack.append((left, depth + 1))
                    cut = True
        if not cut:
            for i in idx:
                labels[i] = part
            part += 1
    return labels


@njit(cache=True, nogil=True)
def _cluster_parts(points, labels, split_width, split_bin, valley_ratio, min_bins, min_points, max_depth, min_size_xy):
    """The parts of every cluster (clusters by label, each cluster's points in index order, its
    parts as _split_parts gives them) and their boxes: (the parts' points one after another,
    offsets (P + 1,), lower corners (P, 3), upper corners (P, 3)); the boxes at least
    ``min_size_xy`` wide, grown about their middle."""
    n = labels.shape[0]
    n_clusters = 0
    for i in range(n):
        if labels[i] + 1 > n_clusters:
            n_clusters = labels[i] + 1
    start = np.zeros(n_clusters + 1, np.int64)
    for i in range(n):
        if labels[i] >= 0:
            start[labels[i] + 1] += 1
    for c in range(n_clusters):
        start[c + 1] += start[c]
    order = np.empty(start[n_clusters], np.int64)
    fill = start[:-1].copy()
    for i in range(n):
        if labels[i] >= 0:
            order[fill[labels[i]]] = i
            fill[labels[i]] += 1
    out = np.empty((start[n_clusters], 3), points.dtype)
    offsets = [0]
    los = []
    his = []
    m = 0
    for c in range(n_clusters):
        cluster = points[order[start[c]:start[c + 1]]]
        xy = np.empty((cluster.shape[0], 2))
        for i in range(cluster.shape[0]):
            xy[i, 0] = cluster[i, 0]
            xy[i, 1] = cluster[i, 1]
        part = _split_parts(xy, split_width, split_bin, valley_ratio, min_bins, min_points, max_depth)
        n_parts = part.max() + 1 if part.shape[0] else 0
        for p in range(n_parts):
            m0 = m
            for i in range(part.shape[0]):
                if part[i] == p:
                    out[m] = cluster[i]
                    m += 1
            lo, hi = column_bounds(out[m0:m])
            for a in range(2):
                g = min_size_xy - (hi[a] - lo[a])
                if not (g >= 0.0 or g != g):  # np.maximum(g, 0.0)
                    g = 0.0
                g = g / 2
                lo[a] -= g
                hi[a] += g
            offsets.append(m)
            los.append(lo)
            his.append(hi)
    n_out = len(los)
    lo_all = np.empty((n_out, 3))
    hi_all = np.empty((n_out, 3))
    for k in range(n_out):
        lo_all[k] = los[k]
        hi_all[k] = his[k]
    return out[:m], np.array(offsets), lo_all, hi_all


class DBSCANDetector:
    def __init__(self, cfg: DBSCANConfig):
        self.cfg = cfg

    def __call__(self, points: np.ndarray) -> list[Detection]:
        labels = dbscan_labels(points, self.cfg.eps, self.cfg.min_points)
        if labels.size == 0 or labels.max() < 0:
            return []
        c = self.cfg
        # every cluster in label order, cut into its parts (_split_parts), each part's box
        pts, offsets, lo, hi = _cluster_parts(
            np.asarray(points).reshape(-1, 3), labels, float(c.split_width), float(c.split_bin),
            float(c.split_valley_ratio), int(np.ceil(c.split_min_part / c.split_bin)), int(c.min_points),
            _SPLIT_MAX_DEPTH, float(c.min_size_xy))
        return [Detection.from_bounds(lo[k], hi[k], "dbscan", pts[offsets[k]:offsets[k + 1]].copy())
                for k in range(len(lo))]
