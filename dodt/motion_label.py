"""The motion label (ours; configuration ``motion``, dodt.config.MotionConfig): the last step of
identification, deciding with the point voting which tracks DODT reports dynamic.

A track the voting and the learned detector leave static is labelled dynamic when it is a standing
person's box (height, footprint) tracked at walking speed for ``min_age`` at least, and does not lie on
structure the static map has held for a while, nor on a wall of the geofence. The label needs that map
(``structure_test``): without one it labels nothing, since a static pillar or a box's edge seen from a
moving camera is often tracked at walking speed too (docs/perception.md). Once labelled dynamic, by any route, a track keeps the
label however slowly it moves while it stays person-shaped. Every track says which evidence labelled
it (``TrackedObstacle.evidence``): a consumer that frees space under dynamic tracks (the planner's map)
may trust the voting more than motion alone.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np

from dodt.config import MotionConfig
from dodt.result import TrackedObstacle

# (box centre (3,), size (3,)) -> the share of its footprint on long-held structure
StructureTest = Callable[[np.ndarray, np.ndarray], float]


def person_tall(o: TrackedObstacle, cfg: MotionConfig, frame=None) -> bool:
    """The height test, for a box cut by the image's lower edge too.

    Near the camera a person's box is only what the vertical field of view shows: at 1 m a camera
    1.2 m up sees down to 0.57 m, so the box of a person there is about 1.1 m tall, at 0.7 m 0.9 m,
    short of the plain height test. A box that reaches down to the lowest height the camera sees at
    its near side (``frame``'s pose and intrinsics) is taken to reach the floor: it passes when its
    top is at least the minimum height.
    """
    lo, hi = cfg.height
    h = float(o.size[2])
    if h > hi:
        return False
    if h >= lo:
        return True
    if frame is None:
        return False
    bottom, top = float(o.center[2]) - h / 2, float(o.center[2]) + h / 2
    T, K = np.asarray(frame.T_world_camera, dtype=float), frame.intrinsics
    q = T[:3, :3].T @ (np.array([o.center[0], o.center[1], bottom]) - T[:3, 3])  # optical: x right, y down
    near = q[2] - 0.5 * float(np.hypot(o.size[0], o.size[1]))  # depth of the box's near side
    if near <= 0.05:
        return False  # beside or behind the camera: nothing to tell from the image
    lowest = T[:3, :3] @ np.array([q[0] * near / q[2], (K.height - 1 - K.cy) * near / K.fy, near]) + T[:3, 3]
    return bottom <= lowest[2] + cfg.bottom_edge_tolerance and top >= lo


class MotionLabel:
    """Per-track state of the label over an episode (which tracks were labelled dynamic, which lay on
    structure); ``reset`` between sequences."""

    def __init__(self, cfg: MotionConfig):
        self.cfg = cfg
        self.structure_test: StructureTest | None = None
        self.geofence: tuple[np.ndarray, np.ndarray] | None = None  # (x, y) low, high: its sides are walls
        self._on_structure: set[int] = set()
        self._dynamic: set[int] = set()  # labelled dynamic once, by any route

    def reset(self) -> None:
        self._on_structure.clear()
        self._dynamic.clear()

    def moving(self, o: TrackedObstacle, frame=None) -> bool:
        """Whether a track the voting leaves static is labelled dynamic by its motion (and remembered)."""
        m = self.cfg
        if not m.enabled or self.structure_test is None or o.age < m.min_age or not person_tall(o, m, frame):
            return False
        v = o.velocity if o.filter_velocity is None else o.filter_velocity
        speed = float(np.hypot(v[0], v[1]))
        fast_enough = m.min_speed <= speed or o.id in self._dynamic  # a walker slowing to turn or stop is one still
        if not (max(o.size[0], o.size[1]) <= m.max_footprint and fast_enough and speed <= m.max_speed):
            return False
        if o.id in self._on_structure:
            return False
        if not o.coasting and (self.structure_test(o.center, o.size) >= m.on_structure or self._on_wall(o)):
            self._on_structure.add(o.id)
            return False
        self._dynamic.add(o.id)
        return True

    def _on_wall(self, o: TrackedObstacle) -> bool:
        """The box's centre lies within wall_margin of a side of the geofence, or beyond it."""
        if self.geofence is None:
            return False
        lo, hi = self.geofence
        c, m = o.center[:2], self.cfg.wall_margin
        return bool(np.any(c <= lo + m) or np.any(c >= hi - m))

    def __call__(self, obstacles, frame=None) -> tuple[TrackedObstacle, ...]:
        """The tracks with their final label and its evidence."""
        out = []
        for o in obstacles:
            if o.dynamic:
                self._dynamic.add(o.id)
            elif self.moving(o, frame):
                o = replace(o, dynamic=True, evidence="motion")
            out.append(o)
        return tuple(out)
