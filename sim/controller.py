"""Cascaded quadrotor controller: position/velocity -> thrust vector and attitude -> torques.

The outer loop is a PID on position with velocity and acceleration feed-forward that
produces a desired force vector; its direction and the reference yaw give the desired
attitude, its projection on the body z axis the collective thrust. The inner loop is the
geometric attitude controller on SO(3) of Lee, Leok and McClamroch (CDC 2010, eqs. 10-12):
e_R = 1/2 vee(R_d^T R - R^T R_d), M = -k_R e_R - k_w e_w + w x J w. A mixer turns thrust and
moments into four rotor thrusts within the actuator limits.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from sim.vehicle import GRAVITY, VehicleParams


@dataclass(frozen=True)
class Reference:
    """What the controller tracks: world position, velocity, acceleration feed-forward, yaw."""

    position: np.ndarray
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    acceleration: np.ndarray = field(default_factory=lambda: np.zeros(3))
    yaw: float = 0.0
    yaw_rate: float = 0.0

    @staticmethod
    def hover(position, yaw: float = 0.0) -> "Reference":
        return Reference(position=np.asarray(position, dtype=float), yaw=yaw)


@dataclass(frozen=True)
class DroneState:
    """Rigid-body state in the world frame; R maps body (FLU) vectors to world."""

    position: np.ndarray
    velocity: np.ndarray
    R: np.ndarray
    omega: np.ndarray  # body angular velocity [rad/s]

    @property
    def yaw(self) -> float:
        return math.atan2(self.R[1, 0], self.R[0, 0])


@dataclass(frozen=True)
class ControllerGains:
    # Outer loop, per unit mass (m/s^2 per m, per m/s, per m s).
    kp: tuple[float, float, float] = (6.0, 6.0, 10.0)
    kv: tuple[float, float, float] = (4.5, 4.5, 6.0)
    ki: tuple[float, float, float] = (1.0, 1.0, 2.0)
    integral_limit: float = 2.0  # m/s^2
    integral_zone: float = 0.1  # m
    max_tilt: float = math.radians(35.0)
    # Inner loop, natural frequency [rad/s] and damping of the attitude error dynamics.
    attitude_wn: tuple[float, float, float] = (18.0, 18.0, 8.0)
    attitude_zeta: float = 0.85


def _vee(S: np.ndarray) -> np.ndarray:
    return np.array([S[2, 1], S[0, 2], S[1, 0]])


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """3-vector cross product (np.cross costs ~15 us of overhead per call)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


class CascadedController:
    """Computes the four rotor thrusts [N] from the state and a reference."""

    def __init__(self, vehicle: VehicleParams, gains: ControllerGains = ControllerGains()):
        self.v = vehicle
        self.g = gains
        self.kp = np.array(gains.kp)
        self.kv = np.array(gains.kv)
        self.ki = np.array(gains.ki)
        wn = np.array(gains.attitude_wn)
        self.kR = vehicle.inertia * wn**2
        self.kw = vehicle.inertia * 2.0 * gains.attitude_zeta * wn
        self.mix_inv = np.linalg.inv(vehicle.allocation)
        self.integral = np.zeros(3)

    def reset(self) -> None:
        self.integral[:] = 0.0

    def __call__(self, state: DroneState, ref: Reference, dt: float) -> np.ndarray:
        v = self.v
        e_p = ref.position - state.position
        e_v = ref.velocity - state.velocity
        # Integral action only near the reference (|e| < integral_zone per axis), so that large
        # steps do not wind it up into an overshoot; it exists to remove small steady biases.
        near = np.abs(e_p) < self.g.integral_zone
        self.integral = np.clip(self.integral + near * self.ki * e_p * dt, -self.g.integral_limit, self.g.integral_limit)
        # Desired acceleration, then force; the drag of the reference velocity is fed forward.
        a_des = self.kp * e_p + self.kv * e_v + self.integral + ref.acceleration
        drag_world = state.R @ (v.drag * (state.R.T @ ref.velocity))
        F = v.mass * (a_des + np.array([0.0, 0.0, GRAVITY])) + drag_world
        # Keep the force within the tilt limit and above a small positive vertical component.
        F[2] = max(F[2], 0.2 * v.mass * GRAVITY)
        horiz = math.hypot(F[0], F[1])
        max_h = F[2] * math.tan(self.g.max_tilt)
        if horiz > max_h:
            F[0] *= max_h / horiz
            F[1] *= max_h / horiz
        b3 = F / np.linalg.norm(F)
        b1c = np.array([math.cos(ref.yaw), math.sin(ref.yaw), 0.0])
        b2 = _cross(b3, b1c)
        b2 /= np.linalg.norm(b2)
        Rd = np.column_stack([_cross(b2, b3), b2, b3])
        thrust = float(F @ state.R[:, 2])

        R = state.R
        e_R = 0.5 * _vee(Rd.T @ R - R.T @ Rd)
        omega_d = R.T @ Rd @ np.array([0.0, 0.0, ref.yaw_rate])
        e_w = state.omega - omega_d
        J = v.inertia
        M = -self.kR * e_R - self.kw * e_w + _cross(state.omega, J * state.omega)
        return self.mix(thrust, M)

    def mix(self, thrust: float, moments: np.ndarray) -> np.ndarray:
        """Rotor thrusts for a collective thrust and body moments, within [0, max].

        Priorities when a rotor would saturate: collective thrust first, then roll and pitch
        moments (scaled down together if needed), then as much of the yaw moment as fits.
        """
        f_max = self.v.max_rotor_thrust
        thrust = min(max(thrust, 0.0), 4 * f_max)
        f = self.mix_inv @ np.array([thrust, moments[0], moments[1], moments[2]])
        if f.min() >= 0.0 and f.max() <= f_max:
            return f
        base = np.full(4, thrust / 4.0)
        f_rp = base + _largest_fit(base, self.mix_inv @ np.array([0.0, moments[0], moments[1], 0.0]), f_max)
        return np.clip(f_rp + _largest_fit(f_rp, self.mix_inv @ np.array([0.0, 0.0, 0.0, moments[2]]), f_max),
                       0.0, f_max)


def _largest_fit(f0: np.ndarray, df: np.ndarray, f_max: float) -> np.ndarray:
    """s * df with the largest s in [0, 1] that keeps f0 + s * df within [0, f_max]."""
    s = 1.0
    for a, d in zip(f0, df):
        if d > 1e-12:
            s = min(s, (f_max - a) / d)
        elif d < -1e-12:
            s = min(s, a / -d)
    return max(s, 0.0) * df
