"""Motions that end at rest: a target velocity (or a given motion) held for a commit time, then a stop.

Every motion is sampled on the planner's 0.1 s grid with piecewise-constant accelerations, as the
closed loop flies them (planner.types.Trajectory): each step takes the acceleration that reaches the
step's target velocity, its norm at most ``a_max`` (``a_brake`` once braking).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _step(px, py, vx, vy, ax, ay, lim, dt):
    """One dt step with acceleration (ax, ay) clamped to norm lim: (px, py, vx, vy, ax, ay) after it."""
    n = math.sqrt(ax * ax + ay * ay)
    if n > lim:
        ax, ay = ax * lim / n, ay * lim / n
    px += vx * dt + 0.5 * ax * dt * dt
    py += vy * dt + 0.5 * ay * dt * dt
    return px, py, vx + ax * dt, vy + ay * dt, ax, ay


@njit(cache=True, nogil=True)
def _roll(p0, v0, targets, commit, N, dt, a_max, a_brake):
    """(P (C, N+1, 2), V (C, N+1, 2), A (C, N, 2)): from (p0, v0), target velocity targets[c] for commit[c]
    steps, then braking to rest (then resting)."""
    C = targets.shape[0]
    P, V, A = np.empty((C, N + 1, 2)), np.empty((C, N + 1, 2)), np.empty((C, N, 2))
    for c in range(C):
        px, py, vx, vy = p0[0], p0[1], v0[0], v0[1]
        P[c, 0, 0], P[c, 0, 1], V[c, 0, 0], V[c, 0, 1] = px, py, vx, vy
        for k in range(N):
            if k < commit[c]:
                ax, ay, lim = (targets[c, 0] - vx) / dt, (targets[c, 1] - vy) / dt, a_max
            else:
                ax, ay, lim = -vx / dt, -vy / dt, a_brake
            px, py, vx, vy, ax, ay = _step(px, py, vx, vy, ax, ay, lim, dt)
            if k >= commit[c] and vx * vx + vy * vy < 1e-12:
                vx = vy = 0.0
            A[c, k, 0], A[c, k, 1] = ax, ay
            P[c, k + 1, 0], P[c, k + 1, 1], V[c, k + 1, 0], V[c, k + 1, 1] = px, py, vx, vy
    return P, V, A


def horizon_steps(commit_times, v_max: float, a_brake: float, dt: float) -> int:
    """Steps that hold the longest commit and a full stop from v_max after it."""
    return int(math.ceil(max(commit_times) / dt - 1e-9) + math.ceil(v_max / (a_brake * dt) - 1e-9) + 2)


class Candidates:
    """The candidate motions of one planning call: arrays P, V, A as _roll returns, and per candidate its
    target velocity (C, 2) and commit steps (C,)."""

    def __init__(self, P, V, A, targets, commit):
        self.P, self.V, self.A = P, V, A
        self.targets, self.commit = targets, commit

    def __len__(self) -> int:
        return len(self.targets)


def target_velocities(guide: float, speeds, n_directions: int) -> np.ndarray:
    """(C, 2): standing still, then every 360/n_directions degrees around the guide direction (rad) at
    each speed."""
    angles = guide + 2 * np.pi * np.arange(n_directions) / n_directions
    dirs = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    return np.concatenate([np.zeros((1, 2))] + [dirs * s for s in speeds])


def roll(p0, v0, targets: np.ndarray, commit_time: float, dt: float, a_max: float, a_brake: float,
         v_max: float) -> Candidates:
    """Each target velocity held for commit_time, then a stop; sampled until every candidate rests."""
    k = int(round(commit_time / dt))
    N = horizon_steps((commit_time,), v_max, a_brake, dt)
    commit = np.full(len(targets), k, dtype=np.int64)
    p0 = np.asarray(p0, dtype=float)[:2].copy()
    v0 = np.asarray(v0, dtype=float)[:2].copy()
    P, V, A = _roll(p0, v0, np.ascontiguousarray(targets, dtype=float), commit, N, dt, a_max, a_brake)
    return Candidates(P, V, A, targets, commit)


@njit(cache=True, nogil=True)
def _brake_from(P, V, k, N, dt, a_brake):
    """(P, V, A) of every candidate (C, N+1, 2) flown as given for k steps (P, V: (C, >k, 2) including the
    start at index 0), then braked to rest at a_brake."""
    C = P.shape[0]
    Pb, Vb, Ab = np.empty((C, N + 1, 2)), np.empty((C, N + 1, 2)), np.zeros((C, N, 2))
    for c in range(C):
        for q in range(k + 1):
            Pb[c, q, 0], Pb[c, q, 1], Vb[c, q, 0], Vb[c, q, 1] = P[c, q, 0], P[c, q, 1], V[c, q, 0], V[c, q, 1]
            if q > 0:
                Ab[c, q - 1, 0] = (V[c, q, 0] - V[c, q - 1, 0]) / dt
                Ab[c, q - 1, 1] = (V[c, q, 1] - V[c, q - 1, 1]) / dt
        px, py, vx, vy = P[c, k, 0], P[c, k, 1], V[c, k, 0], V[c, k, 1]
        for q in range(k, N):
            px, py, vx, vy, ax, ay = _step(px, py, vx, vy, -vx / dt, -vy / dt, a_brake, dt)
            if vx * vx + vy * vy < 1e-12:
                vx = vy = 0.0
            Ab[c, q, 0], Ab[c, q, 1] = ax, ay
            Pb[c, q + 1, 0], Pb[c, q + 1, 1], Vb[c, q + 1, 0], Vb[c, q + 1, 1] = px, py, vx, vy
    return Pb, Vb, Ab


def backups(P, V, commit_time: float, dt: float, a_brake: float, v_max: float) -> Candidates:
    """Each candidate (P, V: (C, K+1, 2) with the start at index 0) flown for commit_time, then a stop:
    the motion the drone commits to (planner.shield.shield)."""
    k = int(round(commit_time / dt))
    N = horizon_steps((commit_time,), v_max, a_brake, dt)
    Pb, Vb, Ab = _brake_from(np.ascontiguousarray(P), np.ascontiguousarray(V), k, N, dt, a_brake)
    return Candidates(Pb, Vb, Ab, np.zeros((len(P), 2)), np.full(len(P), k, dtype=np.int64))
