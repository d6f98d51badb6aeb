"""Data association between predicted tracks and new detections (paper Sec. III-C).

feature (paper): feat = [position, dimensions, point count, point spread]; each difference is
normalised by a scale (position: grown by the track's predicted uncertainty, so a track coasting
through an occlusion still finds its obstacle again), similarity = exp(-||d||^2), accepted above
a threshold. The position of the track is its prediction (the paper's linear propagation).
cosine (ref code): cosine similarity of weighted raw features, plus overlapping boxes.
center: nearest predicted centre within a gate (w/o FAT, baselines).
Assignment is one-to-one, best pairs first (the reference code lets two detections take one
track).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from dodt.config import AssociationConfig
from dodt.detection import Detection
from dodt.geometry import iou_matrix


@dataclass
class TrackView:
    """What association needs to know about a track."""

    center: np.ndarray  # (3,) predicted
    size: np.ndarray
    count: int
    spread: np.ndarray  # (3,) point standard deviation
    position_variance: float


@njit(cache=True, nogil=True)
def _mean_columns_f32(pts, n_cols):
    """Mean of each of the first n_cols columns of an (N, C) float32 array, as numpy's
    mean(axis=0) computes it: float32 sums accumulated row after row from 0, divided by N."""
    n = pts.shape[0]
    out = np.empty(n_cols, np.float32)
    nf = np.float32(n)
    for a in range(n_cols):
        acc = np.float32(0.0)
        for i in range(n):
            acc += pts[i, a]
        out[a] = acc / nf
    return out


@njit(cache=True, nogil=True)
def _std_columns_f32(pts):
    """Per-column standard deviation of an (N, 3) float32 array, as numpy's std(axis=0) computes
    it: the mean (_mean_columns_f32), the squared deviations summed in float32 row after row from
    0, divided by N, the square root; as float64."""
    n = pts.shape[0]
    out = np.empty(3)
    nf = np.float32(n)
    mean = _mean_columns_f32(pts, 3)
    for a in range(3):
        acc = np.float32(0.0)
        for i in range(n):
            d = pts[i, a] - mean[a]
            acc += d * d
        out[a] = np.sqrt(acc / nf)
    return out


def mean_columns(pts: np.ndarray, n_cols: int | None = None) -> np.ndarray:
    """np.mean(pts[:, :n_cols], axis=0), the same values (compiled for float32 points)."""
    if pts.dtype == np.float32 and pts.ndim == 2 and len(pts) and pts.flags.c_contiguous:
        return _mean_columns_f32(pts, pts.shape[1] if n_cols is None else min(n_cols, pts.shape[1]))
    return np.mean(pts if n_cols is None else pts[:, :n_cols], axis=0)


def _std_columns(pts: np.ndarray) -> np.ndarray:
    """pts.std(axis=0) as float64."""
    if pts.dtype == np.float32 and pts.ndim == 2 and pts.shape[1] == 3 and pts.flags.c_contiguous:
        return _std_columns_f32(pts)
    return pts.std(axis=0).astype(float)


def features(det: Detection) -> tuple[int, np.ndarray]:
    """(point count, per-axis standard deviation of the points). Association and the track's
    update both ask for a detection's features; they are kept on the detection for as long as
    its ``points`` stay the same array."""
    pts = det.points
    kept = getattr(det, "_features", None)
    if kept is not None and kept[0] is pts:
        return kept[1]
    f = (len(pts), _std_columns(pts)) if len(pts) >= 2 else (len(pts), np.zeros(3))
    det._features = (pts, f)
    return f


def similarity_matrix(tracks: list[TrackView], dets: list[Detection], cfg: AssociationConfig,
                      camera: np.ndarray) -> tuple[np.ndarray, float]:
    """(T, D) scores and the acceptance threshold for the configured method."""
    T, D = len(tracks), len(dets)
    if T == 0 or D == 0:
        return np.zeros((T, D)), 0.0
    tc = np.array([t.center for t in tracks])
    dc = np.array([d.center for d in dets])
    if cfg.method == "center":
        dist = np.linalg.norm(tc[:, None, :2] - dc[None, :, :2], axis=2)
        return np.where(dist < cfg.center_gate, -dist, -np.inf), -np.inf
    ts = np.array([t.size for t in tracks])
    ds = np.array([d.size for d in dets])
    dfeat = [features(d) for d in dets]
    dn = np.array([f[0] for f in dfeat], float)
    dstd = np.array([f[1] for f in dfeat])
    tn = np.array([t.count for t in tracks], float)
    tstd = np.array([t.spread for t in tracks])
    if cfg.method == "cosine":
        def vec(c, s, n, sd):
            return np.hstack([2.0 * (c - camera), s, 0.5 * n[:, None], 0.5 * sd])
        a, b = vec(tc, ts, tn, tstd), vec(dc, ds, dn, dstd)
        a /= np.maximum(np.linalg.norm(a, axis=1, keepdims=True), 1e-12)
        b /= np.maximum(np.linalg.norm(b, axis=1, keepdims=True), 1e-12)
        sim = a @ b.T
        overlap = iou_matrix(tc, ts, dc, ds) > 0
        return np.where(overlap, sim, -np.inf), cfg.cosine_threshold
    pos_scale = np.sqrt(cfg.position_scale**2 + np.array([t.position_variance for t in tracks]))
    d2 = _feature_distances(tc, dc, pos_scale, cfg.position_scale**2, ts, ds, cfg.size_scale**2, tn, dn,
                            float(cfg.count_scale), tstd, dstd, cfg.spread_scale**2)
    return np.exp(-d2), cfg.similarity_threshold


@njit(cache=True, nogil=True)
def _feature_distances(tc, dc, pos_scale, pos2, ts, ds, size2, tn, dn, count_scale, tstd, dstd, spread2):
    """(T, D) squared feature distances, each term as the array expressions computed it (squares
    as products, sums over x, y, z from left to right):
    (dx^2 + dy^2) / pos_scale^2 + dz^2 / pos2 + |size diff|^2 / size2
    + (|n_t - n_d| / max(n_t, n_d, 1) / count_scale)^2 + |spread diff|^2 / spread2."""
    T, D = tc.shape[0], dc.shape[0]
    d2 = np.empty((T, D))
    for i in range(T):
        ps2 = pos_scale[i] * pos_scale[i]
        for j in range(D):
            dx = tc[i, 0] - dc[j, 0]
            dy = tc[i, 1] - dc[j, 1]
            dz = tc[i, 2] - dc[j, 2]
            e = (dx * dx + dy * dy) / ps2 + dz * dz / pos2
            s0 = ts[i, 0] - ds[j, 0]
            s1 = ts[i, 1] - ds[j, 1]
            s2 = ts[i, 2] - ds[j, 2]
            e = e + (s0 * s0 + s1 * s1 + s2 * s2) / size2
            big = tn[i] if tn[i] >= dn[j] or tn[i] != tn[i] else dn[j]  # np.maximum
            big = big if big >= 1.0 or big != big else 1.0
            r = abs(tn[i] - dn[j]) / big / count_scale
            e = e + r * r
            p0 = tstd[i, 0] - dstd[j, 0]
            p1 = tstd[i, 1] - dstd[j, 1]
            p2 = tstd[i, 2] - dstd[j, 2]
            d2[i, j] = e + (p0 * p0 + p1 * p1 + p2 * p2) / spread2
    return d2


def assign(scores: np.ndarray, threshold: float) -> list[tuple[int, int]]:
    """One-to-one pairs (track, detection), best scores first, each above the threshold."""
    pairs = []
    if scores.size == 0:
        return pairs
    s = scores.copy()
    order = np.argsort(-s, axis=None, kind="stable")
    used_t, used_d = set(), set()
    for flat in order:
        t, d = divmod(int(flat), s.shape[1])
        if not s[t, d] > threshold:
            break
        if t in used_t or d in used_d:
            continue
        pairs.append((t, d))
        used_t.add(t)
        used_d.add(d)
    return pairs
