"""Reference trajectories for demos and controller tests (planners produce their own)."""
from __future__ import annotations

import math

import numpy as np

from sim.controller import Reference


def straight_line(start, goal, speed: float, accel: float = 1.0):
    """A trapezoidal-speed straight flight from start to goal facing the goal.

    Returns (reference_at(t), duration).
    """
    a, b = np.asarray(start, float), np.asarray(goal, float)
    d = b - a
    L = float(np.linalg.norm(d))
    u = d / L if L > 0 else np.array([1.0, 0.0, 0.0])
    yaw = math.atan2(u[1], u[0]) if L > 0 else 0.0
    t_acc = speed / accel
    if accel * t_acc**2 > L:  # triangular profile: never reaches cruise speed
        t_acc = math.sqrt(L / accel)
        speed = accel * t_acc
    t_cruise = (L - accel * t_acc**2) / speed if speed > 0 else 0.0
    T = 2 * t_acc + t_cruise

    def at(t: float) -> Reference:
        if t <= 0:
            s, v, acc = 0.0, 0.0, 0.0
        elif t < t_acc:
            s, v, acc = 0.5 * accel * t * t, accel * t, accel
        elif t < t_acc + t_cruise:
            s, v, acc = 0.5 * accel * t_acc**2 + speed * (t - t_acc), speed, 0.0
        elif t < T:
            r = T - t
            s, v, acc = L - 0.5 * accel * r * r, accel * r, -accel
        else:
            s, v, acc = L, 0.0, 0.0
        return Reference(position=a + s * u, velocity=v * u, acceleration=acc * u, yaw=yaw)

    return at, T


def figure_eight(center, radius: float, period: float, yaw: float = 0.0):
    """A horizontal lemniscate of Gerono: x = r sin(wt), y = r sin(wt) cos(wt); returns reference_at(t)."""
    c = np.asarray(center, float)
    w = 2 * math.pi / period

    def at(t: float) -> Reference:
        s, co = math.sin(w * t), math.cos(w * t)
        s2, c2 = math.sin(2 * w * t), math.cos(2 * w * t)
        pos = c + radius * np.array([s, 0.5 * s2, 0.0])
        vel = radius * w * np.array([co, c2, 0.0])
        acc = radius * w * w * np.array([-s, -2 * s2, 0.0])
        return Reference(position=pos, velocity=vel, acceleration=acc, yaw=yaw)

    return at


def scenario_reference(scenario):
    """What the drone flies in a scenario without a planner: None at every time for a scripted
    camera path (the world follows the path itself), else the straight line from the drone's
    start to its goal at the cruise speed. Returns reference_at(t)."""
    if scenario.camera_path is not None:
        return lambda t: None
    at, _ = straight_line(scenario.drone.start, scenario.drone.goal, scenario.drone.cruise_speed)
    return at
