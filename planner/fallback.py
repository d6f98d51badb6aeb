"""The safe fallback of every planner: brake at full deceleration along -velocity, then hold; and the
check of a planner's input that decides when nothing but that fallback can be planned."""
from __future__ import annotations

import math

import numpy as np

from planner.types import PlannerInput, Trajectory


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


def braking_1d(x0: float, v0: float, a: float, dt: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """One axis braked from (x0, v0) at ``a`` to rest and held: positions and velocities (n + 1,) at the knots
    0, dt, ..., n dt (the speed falls by a dt per step, to zero; positions by the trapezoid of the speeds)."""
    v = np.sign(v0) * np.maximum(abs(v0) - a * dt * np.arange(n + 1), 0.0)
    return x0 + np.r_[0.0, np.cumsum(0.5 * dt * (v[:-1] + v[1:]))], v


# m, m/s, m/s^2: larger positions, velocities or accelerations are not a vehicle's (a position of 1e308 m,
# finite, left a path of infinite length behind that failed the next plan); NaN compares false: refused too
_PLAUSIBLE = 1e6


def valid_input(inp: PlannerInput) -> bool:
    """Whether a plan can be made from ``inp``: stamp, position, velocity, acceleration, goal and heading
    finite (3,) values of a size some vehicle reaches (_PLAUSIBLE)."""
    try:
        return (all(np.shape(x) == (3,) and np.all(np.abs(np.asarray(x, dtype=float)) <= _PLAUSIBLE)
                    for x in (inp.position, inp.velocity, inp.acceleration, inp.goal))
                and abs(float(inp.stamp)) <= 1e9 and (inp.yaw is None or abs(float(inp.yaw)) <= 1e3))
    except (TypeError, ValueError):
        return False


def invalid_input_stop(inp: PlannerInput, a_max: float) -> Trajectory:
    """Brake and hold on what of ``inp`` is finite, status ``fallback:invalid_input``."""
    return brake_and_hold(_finite_or(inp.stamp, 0.0), _vector_or_zero(inp.position), _vector_or_zero(inp.velocity),
                          a_max=a_max, status="fallback:invalid_input")


def _finite_or(x, default: float) -> float:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return default
    return x if math.isfinite(x) else default


def _vector_or_zero(x) -> np.ndarray:
    """x as a (3,) float vector (the fallback holds what is not finite), or zeros when it is not one."""
    try:
        a = np.asarray(x, dtype=float).reshape(3)
    except (TypeError, ValueError):
        return np.zeros(3)
    return a
