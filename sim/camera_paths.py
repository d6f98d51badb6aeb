"""Scripted camera paths (a scenario's ``[camera_path]``): where the drone is at each time.

A path is a function ``t -> (position (3,), velocity (3,), yaw)``: through keyframes (linear in position
and in unwrapped yaw), or following a person ``follow_distance`` behind along their route, looking at
them. A carried path poses the drone on it at every physics step; a flown one is the controller's
reference (sim.world.World.reference_for).
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from sim.crowd import Crowd
from sim.people import Walker
from sim.scenario import Scenario

CameraPath = Callable[[float], tuple[np.ndarray, np.ndarray, float]]


def make_camera_path(scenario: Scenario, walkers: list[Walker], crowd: Crowd) -> CameraPath | None:
    """The scenario's camera path, or None when it has none."""
    cp = scenario.camera_path
    if cp is None:
        return None
    if cp.keyframes:
        return _keyframe_path(np.array(cp.keyframes))

    i = cp.follow_person
    path = walkers[i].path

    def follow(t):
        # Walk the person's route, follow_distance behind the point the person has reached, looking at
        # the person (as the crowd has moved it, at the latest control period).
        s = crowd.progress[i]
        xy = path.trail_point(s - cp.follow_distance)
        target = crowd.pos[i]
        v = crowd.vel[i]
        d = target - xy
        yaw = math.atan2(d[1], d[0])
        return np.array([xy[0], xy[1], cp.follow_height]), np.array([v[0], v[1], 0.0]), yaw
    return follow


def _keyframe_path(kf: np.ndarray) -> CameraPath:
    """kf: (K, 5) rows of [t, x, y, z, yaw]."""
    t_k = kf[:, 0]
    yaw_k = np.unwrap(kf[:, 4])

    def at(t):
        pos = np.array([np.interp(t, t_k, kf[:, i]) for i in (1, 2, 3)])
        if len(t_k) > 1 and t_k[0] <= t < t_k[-1]:
            i = int(np.searchsorted(t_k, t, side="right")) - 1
            vel = (kf[i + 1, 1:4] - kf[i, 1:4]) / (t_k[i + 1] - t_k[i])
        else:
            vel = np.zeros(3)
        return pos, vel, float(np.interp(t, t_k, yaw_k))
    return at
