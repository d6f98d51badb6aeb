"""The safe fallback of every planner: brake at full deceleration along -velocity, then hold."""
from __future__ import annotations

import numpy as np

from planner.types import Trajectory


def brake_and_hold(t0: float, position, velocity, a_max: float = 2.0, dt: float = 0.1, horizon: int = 25,
                   status: str = "fallback") -> Trajectory:
    """A trajectory that decelerates at ``a_max`` until stopped and then holds that position.

    Non-finite inputs give a hold at the last finite position (or the origin), and so do values so
    large that braking from them overflows: the result is always finite. Knots every ``dt`` for
    ``horizon`` steps; the stop falls inside a step, so that step's acceleration is scaled to end
    exactly at rest.
    """
    p = np.asarray(position, dtype=float).copy()
    v = np.asarray(velocity, dtype=float).copy()
    if not np.all(np.isfinite(p)):
        p = np.where(np.isfinite(p), p, 0.0)
    with np.errstate(over="ignore", invalid="ignore"):
        if not np.isfinite(np.linalg.norm(v)):
            v = np.zeros(3)
        P, V, A = [p.copy()], [v.copy()], []
        for _ in range(horizon):
            speed = float(np.linalg.norm(v))
            if speed > 1e-9:
                dv = min(a_max * dt, speed)
                a = -v / speed * (dv / dt)
            else:
                a = np.zeros(3)
            p = p + v * dt + 0.5 * a * dt * dt
            v = v + a * dt
            if float(np.linalg.norm(v)) < 1e-9:
                v = np.zeros(3)
            P.append(p.copy())
            V.append(v.copy())
            A.append(a)
        P, V, A = np.array(P), np.array(V), np.array(A)
    if not (np.all(np.isfinite(P)) and np.all(np.isfinite(V)) and np.all(np.isfinite(A))):
        P, V, A = np.repeat(P[:1], horizon + 1, axis=0), np.zeros((horizon + 1, 3)), np.zeros((horizon, 3))
    return Trajectory(t0=float(t0) if np.isfinite(t0) else 0.0, dt=dt, positions=P,
                      velocities=V, accelerations=A, status=status)
