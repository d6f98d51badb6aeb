"""Odometry: the camera pose a frame carries, the true pose with the scenario's odometry noise.

Each call draws a position error (normal, ``odom_position_std`` per axis) and a rotation error (a rotation
vector, normal, ``odom_rotation_std`` per axis) from its own generator, independently frame by frame.
"""
from __future__ import annotations

import math

import numpy as np

from sim.scenario_parts import Noise


class OdometryNoise:
    def __init__(self, noise: Noise, rng: np.random.Generator):
        self.noise = noise
        self.rng = rng

    def __call__(self, T_true: np.ndarray) -> np.ndarray:
        """The pose reported for the true pose ``T_true`` (4x4); a copy of it when the noise is off."""
        nz = self.noise
        if not nz.enabled or (nz.odom_position_std == 0 and nz.odom_rotation_std == 0):
            return T_true.copy()
        T = T_true.copy()
        T[:3, 3] += self.rng.normal(0.0, nz.odom_position_std, 3)
        rv = self.rng.normal(0.0, nz.odom_rotation_std, 3)
        angle = float(np.linalg.norm(rv))
        if angle > 0:
            k = rv / angle
            Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
            T[:3, :3] = (np.eye(3) + math.sin(angle) * Kx + (1 - math.cos(angle)) * Kx @ Kx) @ T[:3, :3]
        return T
