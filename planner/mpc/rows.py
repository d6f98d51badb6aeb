"""Half-space rows of the MPC's obstacle constraints (planner.mpc.solver's module docstring, (4) and (5)).

Moving obstacles: tangent planes of each predicted ellipsoid at the radial projection of the
linearisation point c_k, after the tie-break offset that picks the passing side. Occupied voxels:
greedy separating planes from c_k. Every function takes the MPCConfig and the linearisation points
c (N, 3) and returns unit normals and right-hand sides (n . p_k >= b).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from planner.mpc.config import MPCConfig


@njit(cache=True, nogil=True, inline="always")
def _tie_break(d0, d1, d2, s, bias):
    """The offset d from an obstacle to c_k after the tie-break (dynamic_rows): d's component along the
    side s (3,) below bias is raised to bias, on d's side (left if 0)."""
    lat = (d0 * s[0] + d1 * s[1]) + d2 * s[2]
    sgn = -1.0 if lat < 0 else 1.0
    m = abs(lat)
    if not (m >= bias or m != m) or bias != bias:  # np.maximum's: NaN if either is
        m = bias
    e = sgn * m - lat
    return d0 + e * s[0], d1 + e * s[1], d2 + e * s[2]


def within_reach(cfg: MPCConfig, c, obstacles, T: float) -> np.ndarray:
    """Indices of the obstacles that may come within dynamic_range of the plan ``c`` (N, 3) in T seconds:
    culled by reach, not by count. An obstacle moves at most (|v| + |a| T) T from its centre in T seconds
    (constant acceleration; the prediction's speed cap and acceleration horizon only shorten that), and its
    ellipsoid's largest semi-axis is at most its half size plus the clearances plus z_std times its largest
    standard deviation; one whose centre stays farther than the sum from every point of the plan is one
    dynamic_candidates would refuse, so the cull changes no plan."""
    if not len(obstacles):
        return np.zeros(0, dtype=int)
    centers = np.array([np.asarray(ob.center, dtype=float) for ob in obstacles])
    speed = np.array([np.linalg.norm(np.asarray(ob.velocity, dtype=float)) for ob in obstacles])
    accel = np.array([np.linalg.norm(np.asarray(ob.acceleration, dtype=float)) for ob in obstacles])
    half = np.array([np.max(np.asarray(ob.size, dtype=float)) / 2 for ob in obstacles])
    std = np.array([max(float(ob.position_std) + float(ob.std_growth) * T, float(ob.position_std))
                    for ob in obstacles])
    reach = (speed + accel * T) * T + half + cfg.robot_radius + cfg.dynamic_margin + cfg.z_std * np.abs(std)
    gap = np.sqrt(np.min(((centers[:, None, :] - np.asarray(c, dtype=float)[None]) ** 2).sum(axis=2), axis=1))
    keep = ~(gap - reach > cfg.dynamic_range + 1e-6)  # NaN stays in: dynamic_candidates decides as before
    return np.flatnonzero(keep)


def dynamic_candidates(cfg: MPCConfig, c, obstacles, side, v_plan=None):
    """The obstacles (4) applies to, nearest first: (distance from the plan to the ellipsoid, index in
    `obstacles`, predicted centres (N, 3), semi-axes (N, 3), tie-break side (3,)), at most max_dynamic.
    The obstacles within reach are measured together, each value as for the obstacle alone."""
    N = cfg.horizon
    t = cfg.dt * np.arange(1, N + 1)
    near = within_reach(cfg, c, obstacles, t[-1])
    if not len(near):
        return []
    o = np.empty((len(near), N, 3))
    ax = np.empty((len(near), N, 3))
    for j, idx in enumerate(near):
        ob = obstacles[idx]
        o[j] = ob.predict(t)
        ax[j] = np.asarray(ob.size, dtype=float) / 2 + cfg.robot_radius + cfg.dynamic_margin
        ax[j, :, :2] += cfg.z_std * ob.std_at(t)[:, None]
    dist = np.min(np.linalg.norm(c - o, axis=2) - ax.max(axis=2), axis=1)  # to the ellipsoid, roughly
    cand = []
    for j in np.flatnonzero(dist <= cfg.dynamic_range):
        ob = obstacles[near[j]]
        sd = side
        if cfg.relative_side and v_plan is not None:
            vo = np.asarray(ob.velocity, dtype=float)
            vr = (vo - v_plan)[:2]
            if np.hypot(*vr) > 0.2:
                sd = np.array([-vr[1], vr[0], 0.0]) / np.hypot(*vr)
                lead = float(sd @ vo)  # the tie goes behind the obstacle; left of travel if it is neither
                sd = -sd if lead > 0.05 or (lead >= -0.05 and float(sd @ side) < 0) else sd
        cand.append((float(dist[j]), int(near[j]), o[j], ax[j], sd))
    return sorted(cand, key=lambda e: e[:2])[:cfg.max_dynamic]


def dynamic_rows(cfg: MPCConfig, c, cand, p0, bias=None):
    """(4): unit normals (N, J, 3) and right-hand sides (N, J) for the candidates (dynamic_candidates).

    Tie-break: offsets d from obstacle j to c_k whose component along its side (dynamic_candidates: left
    of the obstacle's velocity relative to the planned motion, else left of travel) is below side_bias
    get it raised to side_bias, on their side (left if 0): a symmetric head-on plan would otherwise only
    ever brake or push through on slack, and every plane then asks the plan to pass the obstacle there.
    Any tangent plane is conservative."""
    N = cfg.horizon
    if not cand:
        return np.zeros((N, 0, 3)), np.zeros((N, 0))
    o = np.stack([e[2] for e in cand], axis=1)  # (N, J, 3)
    ax = np.stack([e[3] for e in cand], axis=1)
    side = np.stack([e[4] for e in cand])  # (J, 3)
    J = len(cand)
    n, b = np.empty((N, J, 3)), np.empty((N, J))
    _planes(np.ascontiguousarray(c, dtype=float), o, ax, np.ascontiguousarray(side, dtype=float),
            np.asarray(p0, dtype=float), float(cfg.side_bias if bias is None else bias), float(cfg.z_min),
            float(cfg.z_max), n, b)
    return n, b


@njit(cache=True, nogil=True)
def _planes(c, o, ax, side, p0, bias, z_min, z_max, n_out, b_out):
    """dynamic_rows' tangent planes, each computed as the numpy definition computes it, operation for
    operation (sums over x, y, z in that order, as numpy's reductions over 3 do): the same floats.
    An ellipsoid spanning the whole altitude band (a person) is treated as its elliptic cylinder
    (horizontal offsets, so the plan goes around it rather than climbing along its shoulder); c_k at the
    centre (only with side_bias = 0) is moved toward the drone, else +y; the plane touches the
    ellipsoid where the offset from its centre meets its surface."""
    N, J = o.shape[0], o.shape[1]
    for k in range(N):
        for j in range(J):
            o0, o1, o2 = o[k, j, 0], o[k, j, 1], o[k, j, 2]
            a0, a1, a2 = ax[k, j, 0], ax[k, j, 1], ax[k, j, 2]
            fl = 0.0 if (o2 - a2 <= z_min) and (o2 + a2 >= z_max) else 1.0
            d0, d1, d2 = _tie_break(c[k, 0] - o0, c[k, 1] - o1, (c[k, 2] - o2) * fl, side[j], bias)
            w0, w1, w2 = p0[0] - o0, p0[1] - o1, (p0[2] - o2) * fl
            if not math.sqrt((w0 * w0 + w1 * w1) + w2 * w2) > 1e-9:
                w0, w1, w2 = 0.0, 1.0, 0.0
            if math.sqrt((d0 * d0 + d1 * d1) + d2 * d2) < 1e-9:
                d0, d1, d2 = w0, w1, w2
            q0, q1, q2 = d0 / a0, d1 / a1, d2 / a2
            r = math.sqrt((q0 * q0 + q1 * q1) + q2 * q2)
            s0, s1, s2 = o0 + d0 / r, o1 + d1 / r, o2 + d2 / r
            g0, g1, g2 = (s0 - o0) / (a0 * a0), (s1 - o1) / (a1 * a1), (s2 - o2) / (a2 * a2)
            ng = math.sqrt((g0 * g0 + g1 * g1) + g2 * g2)
            n0, n1, n2 = g0 / ng, g1 / ng, g2 / ng
            n_out[k, j, 0], n_out[k, j, 1], n_out[k, j, 2] = n0, n1, n2
            b_out[k, j] = (n0 * s0 + n1 * s1) + n2 * s2


def slide_clear(cfg: MPCConfig, c, PT, d2, req, side):
    """Move each c_k along +-side (the shorter way, left on ties) to the nearest spot at least req from
    every point; q blocks the shifts sgn*(q - c).side +- sqrt(req^2 - |q - c|_perp^2) (d2 = |q - c|^2).
    Where no spot lies within req plus a voxel, c_k stays: such a spot lies beyond the structure on either
    side (c_k in a gap narrower than twice req), and planes facing it would bar the gap; from c_k itself
    they ask only the room the gap lacks."""
    along = (side @ PT)[None] - (c @ side)[:, None]
    perp2 = d2 - along ** 2
    keep = np.any(perp2 < req * req, axis=0)
    along, perp2 = along[:, keep], perp2[:, keep]
    h = np.sqrt(np.maximum(req * req - perp2, 0.0))
    shift = _shifts(np.ascontiguousarray(along), np.ascontiguousarray(perp2), np.ascontiguousarray(h), req)
    s = np.where(shift[0] <= shift[1], shift[0], -shift[1])
    return c + np.where(np.abs(s) <= req + cfg.voxel_size, s, 0.0)[:, None] * side


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
                   np.asarray(p0, float), np.asarray(side, float), r, req, cfg.voxel_size, n_out, b_out)
    return n_out, b_out


@njit(cache=True, nogil=True)
def _greedy_planes(c, pts, d2, p0, side, r, req, through, n_out, b_out):
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
            # from the drone to c_k passes through q's voxel (within ``through``), orient the plane from the
            # drone's position instead, which is on the free side. A line that only passes near q (a plan
            # rounding a corner, or through a gap narrower than twice the clearance) keeps its plane: from
            # the drone's side, it would bar the way the plan goes.
            s0, s1, s2 = c[k, 0] - p0[0], c[k, 1] - p0[1], c[k, 2] - p0[2]
            w = ((q0 - p0[0]) * s0 + (q1 - p0[1]) * s1 + (q2 - p0[2]) * s2) / max(s0 * s0 + s1 * s1 + s2 * s2, 1e-12)
            w = min(max(w, 0.0), 1.0)
            e0, e1, e2 = p0[0] + w * s0 - q0, p0[1] + w * s1 - q1, p0[2] + w * s2 - q2
            a0, a1, a2 = p0[0] - q0, p0[1] - q1, p0[2] - q2
            if math.sqrt(e0 * e0 + e1 * e1 + e2 * e2) < through and n0 * a0 + n1 * a1 + n2 * a2 < 0.0:
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
