"""Half-space rows of the MPC's obstacle constraints (planner.mpc's module docstring, (4) and (5)).

Moving obstacles: tangent planes of each predicted ellipsoid at the radial projection of the
linearisation point c_k, after the tie-break offset that picks the passing side. Occupied voxels:
greedy separating planes from c_k. Every function takes the MPCConfig and the linearisation points
c (N, 3) and returns unit normals and right-hand sides (n . p_k >= b).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from planner.mpc_config import MPCConfig


def tie_break(cfg: MPCConfig, d, side, forced=None, bias=None):
    """Offsets d (N, J, 3) from obstacle j to c_k whose component along side[j] is below side_bias get
    it raised to side_bias (on their side, left if 0): a symmetric head-on plan would otherwise only
    ever brake or push through on slack. Any tangent plane is conservative. `side`: left of the
    obstacle's velocity relative to the planned motion (relative_side), else left of travel.
    forced (J,) in {-1, 0, +1}: where non-zero, the offset is put on that side (mirrored across the
    line if it lies on the other), so every plane asks the plan to pass the obstacle there."""
    lat = np.sum(d * side, axis=-1)
    sgn = np.where(lat < 0, -1.0, 1.0)
    if forced is not None:
        sgn = np.where(forced != 0, forced, sgn)
    bias = cfg.side_bias if bias is None else bias
    return d + (sgn * np.maximum(np.abs(lat), bias) - lat)[..., None] * side


def dynamic_candidates(cfg: MPCConfig, c, obstacles, side, v_plan=None):
    """The obstacles (4) applies to, nearest first: (distance from the plan to the ellipsoid, index in
    `obstacles`, predicted centres (N, 3), semi-axes (N, 3), tie-break side (3,)), at most max_dynamic."""
    N = cfg.horizon
    t = cfg.dt * np.arange(1, N + 1)
    cand = []
    for idx, ob in enumerate(obstacles):
        sd = side
        if cfg.relative_side and v_plan is not None:
            vo = np.asarray(ob.velocity, dtype=float)
            vr = (vo - v_plan)[:2]
            if np.hypot(*vr) > 0.2:
                sd = np.array([-vr[1], vr[0], 0.0]) / np.hypot(*vr)
                lead = float(sd @ vo)  # the tie goes behind the obstacle; left of travel if it is neither
                sd = -sd if lead > 0.05 or (lead >= -0.05 and float(sd @ side) < 0) else sd
        o = ob.predict(t)
        half = np.asarray(ob.size, dtype=float) / 2 + cfg.robot_radius + cfg.dynamic_margin
        ax = np.repeat(half[None], N, axis=0)
        ax[:, :2] += cfg.z_std * ob.std_at(t)[:, None]
        dist = float(np.min(np.linalg.norm(c - o, axis=1) - ax.max(axis=1)))  # to the ellipsoid, roughly
        if dist <= cfg.dynamic_range:
            cand.append((dist, idx, o, ax, sd))
    return sorted(cand, key=lambda e: e[:2])[:cfg.max_dynamic]


def dynamic_rows(cfg: MPCConfig, c, cand, p0, forced=None, bias=None):
    """(4): unit normals (N, J, 3) and right-hand sides (N, J) for the candidates (dynamic_candidates);
    forced (J,): the side each must be passed on (0: the tie-break rule's)."""
    N = cfg.horizon
    if not cand:
        return np.zeros((N, 0, 3)), np.zeros((N, 0))
    o = np.stack([e[2] for e in cand], axis=1)  # (N, J, 3)
    ax = np.stack([e[3] for e in cand], axis=1)
    side = np.stack([e[4] for e in cand])  # (J, 3)
    # an ellipsoid spanning the whole altitude band (a person) is treated as its elliptic cylinder:
    # horizontal normals, so the plan goes around it rather than climbing along its shoulder
    tall = ((o[..., 2] - ax[..., 2] <= cfg.z_min) & (o[..., 2] + ax[..., 2] >= cfg.z_max))[..., None]
    flat = np.where(tall, np.array([1.0, 1.0, 0.0]), 1.0)
    d = tie_break(cfg, (c[:, None, :] - o) * flat, side, forced, bias)
    away = (p0 - o) * flat  # c_k at the centre (only with side_bias = 0): toward the drone, else +y
    away = np.where(np.linalg.norm(away, axis=-1, keepdims=True) > 1e-9, away, np.array([0.0, 1.0, 0.0]))
    d = np.where(np.linalg.norm(d, axis=-1, keepdims=True) < 1e-9, away, d)
    cs = o + d / np.sqrt(np.sum((d / ax) ** 2, axis=-1, keepdims=True))  # on the surface
    g = (cs - o) / ax ** 2
    n = g / np.linalg.norm(g, axis=-1, keepdims=True)
    return n, np.sum(n * cs, axis=-1)


def slide_clear(cfg: MPCConfig, c, PT, d2, req, side):
    """Move each c_k along +-side (the shorter way, left on ties) to the nearest spot at least req from
    every point; q blocks the shifts sgn*(q - c).side +- sqrt(req^2 - |q - c|_perp^2) (d2 = |q - c|^2).
    Where no spot lies within static_radius, c_k stays."""
    along = (side @ PT)[None] - (c @ side)[:, None]
    perp2 = d2 - along ** 2
    keep = np.any(perp2 < req * req, axis=0)
    along, perp2 = along[:, keep], perp2[:, keep]
    h = np.sqrt(np.maximum(req * req - perp2, 0.0))
    shift = _shifts(np.ascontiguousarray(along), np.ascontiguousarray(perp2), np.ascontiguousarray(h), req)
    s = np.where(shift[0] <= shift[1], shift[0], -shift[1])
    return c + np.where(np.abs(s) <= cfg.static_radius, s, 0.0)[:, None] * side


@njit(cache=True, nogil=True)
def _shifts(along, perp2, h, req):
    """slide_clear's shortest free shifts (2, K) along +side (row 0) and -side (row 1): from 0, every point q
    whose blocked interval (sgn along - h, sgn along + h) (where perp2 < req^2) holds the shift pushes it
    to the farthest such interval's end plus 1e-6, at most 20 times; inf if still blocked then."""
    K, M = along.shape
    out = np.empty((2, K))
    for r in range(2):
        sgn = 1.0 if r == 0 else -1.0
        for k in range(K):
            d = 0.0
            blocked = False
            for _ in range(20):
                blocked = False
                top = -math.inf
                for m in range(M):
                    if perp2[k, m] < req * req:
                        if sgn * along[k, m] - h[k, m] < d and sgn * along[k, m] + h[k, m] > d:
                            blocked = True
                            top = max(top, sgn * along[k, m] + h[k, m])
                if not blocked:
                    break
                d = top + 1e-6
            out[r, k] = math.inf if blocked else d
    return out


@njit(cache=True, nogil=True)
def _kept_rows(pts, keep, n):
    """The n rows of pts (M, 3) where keep (M,) is True, in order."""
    out = np.empty((n, 3))
    j = 0
    for m in range(pts.shape[0]):
        if keep[m]:
            out[j, 0], out[j, 1], out[j, 2] = pts[m, 0], pts[m, 1], pts[m, 2]
            j += 1
    return out


@njit(cache=True, nogil=True)
def finite_rows(pts):
    """The rows of pts (M, 3) whose three values are all finite, in order."""
    M = pts.shape[0]
    keep = np.zeros(M, np.bool_)
    n = 0
    for m in range(M):
        if np.isfinite(pts[m, 0]) and np.isfinite(pts[m, 1]) and np.isfinite(pts[m, 2]):
            keep[m] = True
            n += 1
    return _kept_rows(pts, keep, n)


@njit(cache=True, nogil=True)
def _inside(pts, lo, hi):
    """The rows of pts (M, 3) within the box lo <= p <= hi (3,) each, in order."""
    M = pts.shape[0]
    keep = np.zeros(M, np.bool_)
    n = 0
    for m in range(M):
        if (pts[m, 0] >= lo[0] and pts[m, 1] >= lo[1] and pts[m, 2] >= lo[2] and pts[m, 0] <= hi[0]
                and pts[m, 1] <= hi[1] and pts[m, 2] <= hi[2]):
            keep[m] = True
            n += 1
    return _kept_rows(pts, keep, n)


def static_rows(cfg: MPCConfig, c, pts, side, p0):
    """(5): greedy separating planes, normals (N, Ks, 3) (zeros where unused) and rhs (N, Ks) (_greedy_planes).
    The distances are matrix products against the contiguous (3, M) transpose."""
    N, Ks = cfg.horizon, cfg.static_per_step
    n_out, b_out = np.zeros((N, Ks, 3)), np.full((N, Ks), -np.inf)
    r, req = cfg.static_radius, cfg.robot_radius + cfg.voxel_size / 2 + cfg.static_margin
    pts = _inside(np.asarray(pts, dtype=float), c.min(axis=0) - r, c.max(axis=0) + r)
    if len(pts) == 0:
        return n_out, b_out
    PT = np.ascontiguousarray(pts.T)
    sq = np.sum(PT * PT, axis=0)[None]

    def sqdist(c):  # (K, M) |c_k - q|^2, in place (large temporaries cost page faults)
        d = c @ PT
        d *= -2.0
        d += sq
        d += np.sum(c * c, axis=1)[:, None]
        return d

    d2 = sqdist(c)
    pen = np.min(d2, axis=1) < req * req
    if pen.any():  # the previous plan runs through voxels there: linearise beside them instead
        c = c.copy()
        c[pen] = slide_clear(cfg, c[pen], PT, d2[pen], req, side)
        d2[pen] = sqdist(c[pen])
    _greedy_planes(np.ascontiguousarray(c, dtype=float), np.ascontiguousarray(pts, dtype=float), d2,
                   np.asarray(p0, float), np.asarray(side, float), r, req, n_out, b_out)
    return n_out, b_out


@njit(cache=True, nogil=True)
def _greedy_planes(c, pts, d2, p0, side, r, req, n_out, b_out):
    """static_rows' planes into n_out (N, Ks, 3), b_out (N, Ks): for each c_k, Ks times, the nearest point q
    not yet covered (within r; d2 (N, M): |c_k - q|^2) gives the plane through q, normal from q toward
    c_k, moved out by req; the points behind that plane are covered."""
    N, M = d2.shape
    Ks = n_out.shape[1]
    # the points of row k not covered yet, in index order: their coordinates and d2, packed; bi: the
    # nearest of them (the first of equals), found while packing
    lx, ly, lz, ld = np.empty(M), np.empty(M), np.empty(M), np.empty(M)
    for k in range(N):
        n_live, best, bi = 0, math.inf, -1
        for m in range(M):
            if d2[k, m] <= r * r:
                lx[n_live], ly[n_live], lz[n_live], ld[n_live] = pts[m, 0], pts[m, 1], pts[m, 2], d2[k, m]
                if ld[n_live] < best:
                    best, bi = ld[n_live], n_live
                n_live += 1
        for j in range(Ks):
            if n_live == 0 or bi < 0:
                break  # every point covered
            q0, q1, q2 = lx[bi], ly[bi], lz[bi]
            n0, n1, n2 = c[k, 0] - q0, c[k, 1] - q1, c[k, 2] - q2
            # A linearisation point beyond the voxel, seen from the drone (the previous plan went through
            # a wall on slack), would give a plane keeping the plan beyond the wall: where the straight line
            # from the drone to c_k passes within the clearance of q, orient the plane from the drone's
            # position instead, which is on the free side. (A plan through a gap passes its edge voxels
            # farther than that and keeps its planes.)
            s0, s1, s2 = c[k, 0] - p0[0], c[k, 1] - p0[1], c[k, 2] - p0[2]
            w = ((q0 - p0[0]) * s0 + (q1 - p0[1]) * s1 + (q2 - p0[2]) * s2) / max(s0 * s0 + s1 * s1 + s2 * s2, 1e-12)
            w = min(max(w, 0.0), 1.0)
            e0, e1, e2 = p0[0] + w * s0 - q0, p0[1] + w * s1 - q1, p0[2] + w * s2 - q2
            a0, a1, a2 = p0[0] - q0, p0[1] - q1, p0[2] - q2
            if math.sqrt(e0 * e0 + e1 * e1 + e2 * e2) < req and n0 * a0 + n1 * a1 + n2 * a2 < 0.0:
                n0, n1, n2 = a0, a1, a2
            nn = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
            if nn < 1e-9:  # c_k on a voxel centre (no clear spot found): left
                n0, n1, n2, nn = side[0], side[1], side[2], 1.0
            n0, n1, n2 = n0 / nn, n1 / nn, n2 / nn
            nq = n0 * q0 + n1 * q1 + n2 * q2
            n_out[k, j, 0], n_out[k, j, 1], n_out[k, j, 2] = n0, n1, n2
            b_out[k, j] = nq + req
            kept, best, bi = 0, math.inf, -1
            for a in range(n_live):  # the points behind the plane through q are covered
                if n0 * lx[a] + n1 * ly[a] + n2 * lz[a] > nq + 1e-9:
                    lx[kept], ly[kept], lz[kept], ld[kept] = lx[a], ly[a], lz[a], ld[a]
                    if ld[kept] < best:
                        best, bi = ld[kept], kept
                    kept += 1
            n_live = kept
