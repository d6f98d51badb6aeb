"""Messages between perception, the map and planners.

A planner receives an immutable snapshot (``PlannerInput``) and returns a ``Trajectory``: the
closed loop samples that trajectory into controller references until the next plan. Moving
obstacles reach a planner as ``ObstaclePrediction``s, whatever produced them (DODT tracks, ground
truth, someone else's detector). Units SI, world frame (x along the corridor, y left, z up).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np
from numba import njit


def _vec3(x) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.shape != (3,):
        raise ValueError(f"ObstaclePrediction: a centre, velocity or acceleration must have 3 values, not {a.shape}")
    return a


@njit(cache=True, nogil=True)
def _predict(times, c, v, a, horizon, vmax):
    """ObstaclePrediction.predict's centres (K, 3), computed as its definition does in numpy, operation for
    operation (the speed's norm summed x, y, then z, as numpy's reduction does): the same floats."""
    K = times.shape[0]
    out = np.empty((K, 3))
    ve = np.empty(3)
    for k in range(K):
        t = times[k]
        ta = t if t < horizon or t != t else horizon  # np.minimum's: NaN if either is
        if horizon != horizon:
            ta = horizon
        for d in range(3):
            ve[d] = v[d] + a[d] * ta
        speed = np.sqrt((ve[0] * ve[0] + ve[1] * ve[1]) + ve[2] * ve[2])
        f = 1.0
        if speed > vmax:
            f = vmax / (speed if speed > 1e-9 or speed != speed else 1e-9)
        for d in range(3):
            out[k, d] = c[d] + ((v[d] * ta + 0.5 * a[d] * ta * ta) + (ve[d] * f) * (t - ta))
    return out


def finite_obstacle(ob) -> bool:
    """Whether an obstacle can be used: (3,) finite centre, size, velocity and acceleration, and finite
    position_std, std_growth, accel_horizon and max_speed. A planner drops the others at its boundary (a NaN
    there would reach a division and poison the whole plan)."""
    try:
        vecs = np.asarray((ob.center, ob.size, ob.velocity, ob.acceleration), dtype=float)
        total = float(vecs.sum()) + float(ob.position_std) + float(ob.std_growth) + float(ob.accel_horizon) \
            + float(ob.max_speed)
    except (AttributeError, TypeError, ValueError, OverflowError):
        return False
    return vecs.shape == (4, 3) and math.isfinite(total)  # a NaN or an infinity anywhere makes the sum one


def usable_obstacles(inp: "PlannerInput") -> tuple["PlannerInput", int]:
    """``inp`` without the obstacles finite_obstacle refuses, and how many it dropped."""
    kept = tuple(ob for ob in inp.obstacles if finite_obstacle(ob))
    dropped = len(inp.obstacles) - len(kept)
    return (replace(inp, obstacles=kept) if dropped else inp), dropped


@dataclass(frozen=True, eq=False)
class ObstaclePrediction:
    """A moving obstacle: axis-aligned box now, and how to extrapolate it.

    Prediction: constant acceleration for ``accel_horizon`` seconds, constant velocity after
    (an acceleration estimate held for several seconds sends predictions anywhere), speed capped at
    ``max_speed``. Uncertainty: position_std now, growing by ``std_growth`` per second ahead.
    """

    id: int
    center: np.ndarray  # (3,) [m]
    size: np.ndarray  # (3,) [m] full extents
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))  # (3,) [m/s]
    acceleration: np.ndarray = field(default_factory=lambda: np.zeros(3))  # (3,) [m/s^2]
    position_std: float = 0.0  # [m]
    std_growth: float = 0.1  # [m/s]
    accel_horizon: float = 1.0  # [s]
    max_speed: float = 2.5  # [m/s]

    def predict(self, times: np.ndarray) -> np.ndarray:
        """Centres at ``times`` seconds ahead (K,) -> (K, 3)."""
        return _predict(np.asarray(times, dtype=float), _vec3(self.center), _vec3(self.velocity),
                        _vec3(self.acceleration), float(self.accel_horizon), float(self.max_speed))

    def std_at(self, times: np.ndarray) -> np.ndarray:
        """Position standard deviation at ``times`` seconds ahead (K,)."""
        return self.position_std + self.std_growth * np.asarray(times, dtype=float)

    def advanced(self, lag: float) -> "ObstaclePrediction":
        """The same prediction made ``lag`` seconds later: centre, velocity and standard deviation as
        predicted then (the closed loop brings a report from its frame's stamp to a plan's)."""
        c = self.predict(np.array([lag]))[0]
        v = self.velocity + self.acceleration * min(lag, self.accel_horizon)
        return replace(self, center=c, velocity=v, position_std=float(self.std_at(np.array([lag]))[0]))


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Piecewise-constant acceleration: on [t0 + k dt, t0 + (k+1) dt) the acceleration is
    accelerations[k]; positions/velocities are the knot states (N+1, 3)."""

    t0: float
    dt: float
    positions: np.ndarray  # (N+1, 3)
    velocities: np.ndarray  # (N+1, 3)
    accelerations: np.ndarray  # (N, 3)
    status: str = "solved"  # solved | fallback:<why> | hold
    solve_ms: float = 0.0
    yaw: float | None = None  # heading the vehicle should hold [rad]; None: face along the motion

    @property
    def duration(self) -> float:
        return self.dt * len(self.accelerations)

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(position, velocity, acceleration) at absolute time t (held at the end)."""
        n = len(self.accelerations)
        tau = t - self.t0
        if n == 0 or tau >= n * self.dt:
            return self.positions[-1].copy(), self.velocities[-1].copy(), np.zeros(3)
        tau = max(tau, 0.0)
        k = min(int(tau / self.dt), n - 1)
        s = tau - k * self.dt
        a = self.accelerations[k]
        v = self.velocities[k] + a * s
        p = self.positions[k] + self.velocities[k] * s + 0.5 * a * s * s
        return p, v, a.copy()

    def sample_many(self, times) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(positions, velocities, accelerations) (K, 3) at absolute times (K,): ``sample`` at each, the
        same arithmetic element by element."""
        t = np.asarray(times, dtype=float)
        n = len(self.accelerations)
        if n == 0:
            return (np.repeat(self.positions[-1:], len(t), axis=0), np.repeat(self.velocities[-1:], len(t), axis=0),
                    np.zeros((len(t), 3)))
        tau = t - self.t0
        end = (tau >= n * self.dt)[:, None]
        tau = np.where(tau < 0.0, 0.0, tau)  # max(tau, 0.0)
        k = np.minimum((tau / self.dt).astype(np.int64), n - 1)
        s = (tau - k * self.dt)[:, None]
        a = self.accelerations[k]
        v = self.velocities[k] + a * s
        p = self.positions[k] + self.velocities[k] * s + 0.5 * a * s * s
        return (np.where(end, self.positions[-1], p), np.where(end, self.velocities[-1], v),
                np.where(end, 0.0, a))


@dataclass(frozen=True, eq=False)
class PlannerInput:
    """What a planner sees at one planning instant."""

    stamp: float  # sim time [s]
    position: np.ndarray  # (3,) estimated drone position
    velocity: np.ndarray  # (3,)
    acceleration: np.ndarray  # (3,) last commanded acceleration
    goal: np.ndarray  # (3,)
    obstacles: tuple[ObstaclePrediction, ...]  # moving obstacles
    occupancy: object | None = None  # a planner.map.voxel_map.VoxelMap (static map), or None
    yaw: float | None = None  # current heading of the vehicle (and its forward camera) [rad]
    geofence: tuple[np.ndarray, np.ndarray] | None = None  # known walls of the flight area: (lo, hi) in x, y [m]
    seen: object | None = None  # a planner.map.visibility.SeenSpace: when the camera last saw each floor cell free


class Planner(Protocol):
    """What the closed loop calls. Implement these two methods to plug in another planner."""

    def reset(self) -> None: ...

    def plan(self, inp: PlannerInput) -> Trajectory: ...
