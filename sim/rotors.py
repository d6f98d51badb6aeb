"""The drone's rotors: their speed response to commanded thrusts, and the forces they put on the body.

Each physics step the rotor speeds approach the speeds of the commanded thrusts with a first-order lag
(``tau_up`` spinning up, ``tau_down`` spinning down; sim.vehicle), and the thrusts they give, the yaw
moment of their drag and the body's linear air drag are applied to the drone before PyBullet steps.
"""
from __future__ import annotations

import math

import numpy as np

from sim.camera import quiet_stdout

with quiet_stdout():  # PyBullet prints its build time on import
    import pybullet as p

from sim.vehicle import GRAVITY, VehicleParams


class Rotors:
    """Rotor state of one drone, starting at hover."""

    def __init__(self, vehicle: VehicleParams):
        self.vehicle = vehicle
        self.speed = np.full(4, math.sqrt(vehicle.mass * GRAVITY / (4 * vehicle.kf)))  # rad/s
        self.thrust_cmd = np.full(4, vehicle.mass * GRAVITY / 4)  # N per rotor, set by the controller
        self._positions = [r.tolist() for r in vehicle.rotor_positions]
        self._yaw_row = vehicle.allocation[3]

    def update(self, dt: float) -> np.ndarray:
        """Advance the rotor speeds by ``dt`` towards the commanded thrusts; returns the thrusts they give."""
        v = self.vehicle
        cmd = np.sqrt(np.clip(self.thrust_cmd, 0.0, v.max_rotor_thrust) / v.kf)
        tau = np.where(cmd > self.speed, v.tau_up, v.tau_down)
        self.speed = cmd + (self.speed - cmd) * np.exp(-dt / tau)
        return v.kf * self.speed**2

    def step(self, client: int, drone: int, dt: float) -> None:
        """One physics step of ``dt``: rotor speeds, then forces and torques on ``drone``, then PyBullet's step."""
        c, v = client, self.vehicle
        thrusts = self.update(dt)
        pos, quat = p.getBasePositionAndOrientation(drone, physicsClientId=c)
        lin, _ = p.getBaseVelocity(drone, physicsClientId=c)
        R = np.array(p.getMatrixFromQuaternion(quat)).reshape(3, 3)
        for i in range(4):
            p.applyExternalForce(drone, -1, [0.0, 0.0, float(thrusts[i])], self._positions[i], p.LINK_FRAME,
                                 physicsClientId=c)
        yaw_moment = float(self._yaw_row @ thrusts)
        drag = -(R @ (v.drag * (R.T @ np.array(lin))))
        p.applyExternalTorque(drone, -1, (R[:, 2] * yaw_moment).tolist(), p.WORLD_FRAME, physicsClientId=c)
        p.applyExternalForce(drone, -1, drag.tolist(), list(pos), p.WORLD_FRAME, physicsClientId=c)
        p.stepSimulation(physicsClientId=c)
