"""The passive-safety check of motions that end at rest (docs/planner.md).

A motion (positions P and velocities V sampled every dt, the first sample where the drone is) is safe
when at every later sample, the stop included:
- the drone keeps ``need_static`` from static structure (``clear``: metres to the nearest occupied
  column of the map at the flight altitude, the geofence's outside counting as occupied);
- it is at rest, or moving away from every person, or outside the space the person can reach: at time
  t after now a person is inside the disc of centre c + v t and radius r0 + g t + a_p t^2 / 2 and inside
  the disc of centre c and radius r0 + g t + v_p t (r0 from the body and the position error, g from the
  velocity error, a_p a person's acceleration, v_p their top speed);
"Moving away": the threat lies more than the away angle (120 deg) off the drone's motion, the fault
rule's "hit from behind" (experiments.fault). Times are shifted by ``lag``: the controller follows the
plan late by about that much.
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
def check(P, V, dt, clear, ox, oy, res, C0, Vp, R0, G, a_p, v_p, need_static, r_contact, at_rest, cos_away, lag):
    """Check motions P, V (C, N+1, 2) sampled every dt (module docstring).

    clear: (nx, ny) m to static structure. People (M): centres C0 (M, 2), velocities Vp (M, 2), disc
    radius now R0 (M,) and its growth G (M,) m/s. need_static: the least static clearance; r_contact:
    the drone's radius (a person's disc includes the body). The first sample is not checked.

    Returns safe (C,) bool and violation (C,) m: the deepest intrusion of a sample that is not exempt."""
    C, K = P.shape[0], P.shape[1]
    M = C0.shape[0]
    safe = np.ones(C, dtype=np.bool_)
    violation = np.zeros(C)
    for c in range(C):
        worst = 0.0
        for k in range(1, K):  # the first sample is where the drone is: the same for every motion
            x, y = P[c, k, 0], P[c, k, 1]
            ux, uy = V[c, k, 0], V[c, k, 1]
            speed = math.sqrt(ux * ux + uy * uy)
            moving = speed > at_rest
            s = _field(clear, ox, oy, res, x, y, -1.0) - need_static
            if s < 0.0:
                worst = max(worst, -s)
            if not moving:
                continue
            t = k * dt + lag
            for m in range(M):
                cx, cy = C0[m, 0] + Vp[m, 0] * t, C0[m, 1] + Vp[m, 1] * t
                dx, dy = cx - x, cy - y
                d = math.sqrt(dx * dx + dy * dy)
                gap = d - (R0[m] + G[m] * t + 0.5 * a_p * t * t) - r_contact
                d0 = math.sqrt((C0[m, 0] - x) ** 2 + (C0[m, 1] - y) ** 2)
                gap = max(gap, d0 - (R0[m] + G[m] * t + v_p * t) - r_contact)
                if gap < 0.0 and not (ux * dx + uy * dy < cos_away * speed * d):
                    worst = max(worst, -gap)
        violation[c] = worst
        safe[c] = worst <= 0.0
    return safe, violation


@njit(cache=True, nogil=True)
def in_the_way(P, dt, C0, Vp, reach, look):
    """(C,) how deep each motion's resting place (its last sample) lies in a person's way: over the
    ``look`` seconds after the motion comes to rest, the least distance from its resting place to each
    moving person's mean prediction (c + v t), below its ``reach`` (M,) (the body and the drone), summed
    over people (m). A drone standing where a walker is going is walked into: not its fault, but the
    episode fails all the same."""
    C, K = P.shape[0], P.shape[1]
    M = C0.shape[0]
    out = np.zeros(C)
    n = int(look / dt) + 1
    for c in range(C):
        x, y = P[c, K - 1, 0], P[c, K - 1, 1]
        t0 = (K - 1) * dt
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
