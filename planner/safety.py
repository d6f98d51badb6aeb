"""The safety check of candidate motions, and the soft costs that rank the safe ones.

A candidate (planner.candidates) is safe when at every sample, stop included (docs/planner.md):
- the drone keeps ``drone_radius + static_margin`` from static structure (``clear``: a field of metres
  to the nearest occupied column, the geofence's outside counting as occupied);
- it is outside every person's reach, or at rest, or moving away from it: at time t after now a person
  is inside the disc of centre c + v t and radius r0 + g t + a_p t^2 / 2 and inside the disc of centre
  c and radius r0 + g t + v_p t (planner.safe_planner builds r0 from the body and the position error, g
  from the velocity error; a_p is a person's acceleration, v_p its top speed);
- at rest, or moving away from where an unseen person may be, or out of their reach: the distance such a
  person still has to walk (planner.visibility) exceeds the contact distance plus ``hidden_speed`` t.
"Moving away": the threat lies more than the away angle (120 deg) off the drone's motion, the fault
rule's "hit from behind" (experiments.fault). Times are shifted by ``lag`` (the controller follows the
plan late by about that much).

One compiled pass scores every candidate; it returns, per candidate, whether it is safe, how deep its
worst violation goes (for choosing the least bad when none is safe), and the soft costs.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _field(F, ox, oy, res, x, y, outside):
    """Nearest-cell value of a (nx, ny) field at world (x, y); ``outside`` off the grid."""
    i = int(math.floor((x - ox) / res))
    j = int(math.floor((y - oy) / res))
    if i < 0 or j < 0 or i >= F.shape[0] or j >= F.shape[1]:
        return outside
    return F[i, j]


@njit(cache=True, nogil=True)
def bilinear(F, ox, oy, res, x, y):
    """Bilinear value of a (nx, ny) cell-centred field at world (x, y), clamped to the grid."""
    gx = min(max((x - ox) / res - 0.5, 0.0), F.shape[0] - 1.000001)
    gy = min(max((y - oy) / res - 0.5, 0.0), F.shape[1] - 1.000001)
    i, j = int(gx), int(gy)
    fx, fy = gx - i, gy - j
    return ((1 - fx) * (1 - fy) * F[i, j] + fx * (1 - fy) * F[i + 1, j] + (1 - fx) * fy * F[i, j + 1]
            + fx * fy * F[i + 1, j + 1])


@njit(cache=True, nogil=True)
def check(P, V, dt, clear, hidden, hidden_near, ox, oy, res, C0, Vp, R0, G, a_p, v_p, need_static, r_contact,
          hidden_contact, hidden_speed, at_rest, cos_away, lag):
    """Score candidates P, V (C, N+1, 2) sampled every dt.

    clear: (nx, ny) m to static structure; hidden: (nx, ny) m an unseen person still has to walk to each
    cell (planner.visibility.SeenSpace.reach), hidden_near the flat index of the nearest cell where one may
    be now (-1: none). People (M): centres C0 (M, 2), velocities Vp (M, 2), disc radius now R0 (M,)
    and its growth G (M,) m/s. need_static: the least static clearance (a drone already closer may not
    come closer: the caller passes the lesser); r_contact: the drone's radius (a person's disc includes
    the body); hidden_contact: the drone's radius plus a person's. The first sample (where the drone is)
    is not checked.

    Returns safe (C,) bool and violation (C,) m: the deepest intrusion of a non-exempt sample."""
    C, K = P.shape[0], P.shape[1]
    M = C0.shape[0]
    safe = np.ones(C, dtype=np.bool_)
    violation = np.zeros(C)
    for c in range(C):
        worst = 0.0
        for k in range(1, K):  # the first sample is where the drone is: the same for every candidate
            x, y = P[c, k, 0], P[c, k, 1]
            ux, uy = V[c, k, 0], V[c, k, 1]
            speed = math.sqrt(ux * ux + uy * uy)
            moving = speed > at_rest
            s = _field(clear, ox, oy, res, x, y, -1.0) - need_static
            if s < 0.0:
                worst = max(worst, -s)
            t = k * dt + lag
            for m in range(M):
                cx, cy = C0[m, 0] + Vp[m, 0] * t, C0[m, 1] + Vp[m, 1] * t
                dx, dy = cx - x, cy - y
                d = math.sqrt(dx * dx + dy * dy)
                gap = d - (R0[m] + G[m] * t + 0.5 * a_p * t * t) - r_contact
                # ... and no farther from where it is now than its top speed takes it
                d0 = math.sqrt((C0[m, 0] - x) ** 2 + (C0[m, 1] - y) ** 2)
                gap = max(gap, d0 - (R0[m] + G[m] * t + v_p * t) - r_contact)
                if gap < 0.0 and moving and not (ux * dx + uy * dy < cos_away * speed * d):
                    worst = max(worst, -gap)
            gap = _field(hidden, ox, oy, res, x, y, 0.0) - hidden_contact - hidden_speed * t
            if gap < 0.0 and moving:
                i = min(max(int(math.floor((x - ox) / res)), 0), hidden.shape[0] - 1)
                j = min(max(int(math.floor((y - oy) / res)), 0), hidden.shape[1] - 1)
                q = hidden_near[i, j]
                away = False
                if q >= 0:  # the nearest cell someone unseen may stand on now: moving away from it?
                    hx = ox + (q // hidden.shape[1] + 0.5) * res - x
                    hy = oy + (q % hidden.shape[1] + 0.5) * res - y
                    away = ux * hx + uy * hy < cos_away * speed * math.sqrt(hx * hx + hy * hy)
                if not away:
                    worst = max(worst, -gap)
        violation[c] = worst
        safe[c] = worst <= 0.0
    return safe, violation


@njit(cache=True, nogil=True)
def proximity(P, dt, C0, Vp, reach, scale):
    """(C,) how close each candidate passes to where the people are expected (their mean predictions
    c + v t): the sum over people of exp(-gap / scale), gap the least distance over the candidate's samples
    less the person's ``reach`` (M,) (body and drone), at least 0."""
    C, K = P.shape[0], P.shape[1]
    M = C0.shape[0]
    out = np.zeros(C)
    for c in range(C):
        for m in range(M):
            best = 1e9
            for k in range(1, K):
                t = k * dt
                dx, dy = C0[m, 0] + Vp[m, 0] * t - P[c, k, 0], C0[m, 1] + Vp[m, 1] * t - P[c, k, 1]
                best = min(best, math.sqrt(dx * dx + dy * dy))
            out[c] += math.exp(-max(best - reach[m], 0.0) / scale)
    return out


@njit(cache=True, nogil=True)
def in_the_way(P, V, commit, dt, C0, Vp, reach, look, at_rest):
    """(C,) how deep each candidate's resting place lies in a person's way: over the ``look`` seconds after
    the candidate comes to rest, the least distance from its resting place to each moving person's mean
    prediction (c + v t), below its ``reach`` (M,) (the body and the drone), summed over people (m). A drone
    standing where a walker is going is walked into: not its fault, but no success either."""
    C, K = P.shape[0], P.shape[1]
    M = C0.shape[0]
    out = np.zeros(C)
    for c in range(C):
        k_rest = K - 1
        for k in range(K):
            if k >= commit[c] and V[c, k, 0] * V[c, k, 0] + V[c, k, 1] * V[c, k, 1] <= at_rest * at_rest:
                k_rest = k
                break
        x, y = P[c, k_rest, 0], P[c, k_rest, 1]
        t0 = k_rest * dt
        n = int(look / dt) + 1
        for m in range(M):
            if Vp[m, 0] * Vp[m, 0] + Vp[m, 1] * Vp[m, 1] < 0.04:
                continue
            best = 1e9
            for q in range(n):
                t = t0 + q * dt
                dx, dy = C0[m, 0] + Vp[m, 0] * t - x, C0[m, 1] + Vp[m, 1] * t - y
                best = min(best, math.sqrt(dx * dx + dy * dy))
            if best < reach[m]:
                out[c] += reach[m] - best
    return out


@njit(cache=True, nogil=True)
def guide_index(ctg, clear, ox, oy, res, x, y, pts, need):
    """Index of the point of pts (K, 2) the cost-to-go falls toward most steeply from (x, y) (its drop per
    metre), among those the straight line from (x, y) reaches keeping ``need`` from structure (among all of
    them when none is reachable)."""
    here = bilinear(ctg, ox, oy, res, x, y)
    best, k_best, any_ok = 1e18, 0, False
    for k in range(pts.shape[0]):
        dx, dy = pts[k, 0] - x, pts[k, 1] - y
        dist = math.sqrt(dx * dx + dy * dy)
        n = int(dist / (0.5 * res)) + 1
        ok = True
        for q in range(1, n + 1):
            f = q / n
            if _field(clear, ox, oy, res, x + f * dx, y + f * dy, -1.0) < need:
                ok = False
                break
        v = (bilinear(ctg, ox, oy, res, pts[k, 0], pts[k, 1]) - here) / max(dist, 1e-9)
        if ok and not any_ok:
            best, k_best, any_ok = v, k, True
        elif ok == any_ok and v < best:
            best, k_best = v, k
    return k_best
