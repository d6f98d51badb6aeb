"""The trajectory follower: samples the current plan into the controller's references.

Between plans the loop tracks the latest trajectory: at every control period it samples the position and
velocity the plan gives for that time, and the acceleration ``lead`` seconds later, and turns the heading
toward the plan's yaw (or, when the plan sets none, toward where the plan will be one second later) no
faster than the yaw-rate limit.

Why the lead: the acceleration is fed forward to a controller that reaches it by tilting, and the tilt
follows late. Fed at its own time, the end of a stop finds the drone still tilted to brake when its speed
reaches zero, and it moves back at 0.13-0.18 m/s: more than the fault rule's at-rest speed, in a drone
the planner meant to be at rest. Fed that much ahead, the tilt is gone when the speed is
(tests/experiments/test_follower.py).
"""
from __future__ import annotations

import math

import numpy as np

from dodt.geometry import wrap_angle
from planner.types import Trajectory
from sim.controller import Reference

LOOK_AHEAD = 1.0  # s: with no yaw in the plan, the heading points where the plan is this much later
MIN_LOOK_DISTANCE = 0.3  # m: ... if that is this far away at least (else the heading is kept)


class TrajectoryFollower:
    """Holds the plan being flown and the commanded heading."""

    def __init__(self, yaw: float, max_yaw_rate: float, control_dt: float, lead: float = 0.0):
        self.yaw = float(yaw)  # rad, the heading last commanded
        self.max_yaw_rate = float(max_yaw_rate)  # rad/s
        self.control_dt = float(control_dt)  # s
        self.lead = float(lead)  # s the acceleration fed forward is taken ahead
        self.trajectory: Trajectory | None = None
        self.acceleration = np.zeros(3)  # m/s^2, the acceleration last commanded (the planner's input)

    def follow(self, trajectory: Trajectory) -> None:
        self.trajectory = trajectory

    def reference(self, t: float, position: np.ndarray) -> Reference:
        """The controller's reference at time ``t`` for a drone at ``position``."""
        traj = self.trajectory
        p_ref, v_ref, a_ref = traj.sample(t)
        self.acceleration = a_ref
        if self.lead > 0.0:
            a_ref = traj.sample(t + self.lead)[2]
        want = traj.yaw
        if want is None:
            d = traj.sample(t + LOOK_AHEAD)[0][:2] - position[:2]
            want = math.atan2(d[1], d[0]) if np.hypot(*d) > MIN_LOOK_DISTANCE else self.yaw
        err = wrap_angle(want - self.yaw)
        step = self.max_yaw_rate * self.control_dt
        yaw_rate = float(np.clip(err, -step, step)) / self.control_dt
        self.yaw = self.yaw + yaw_rate * self.control_dt
        return Reference(position=p_ref, velocity=v_ref, acceleration=a_ref, yaw=self.yaw, yaw_rate=yaw_rate)
