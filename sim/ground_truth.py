"""Ground truth from the simulator: kept apart from what a robot sees (dodt.frames)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

STRUCTURE_ID = 0  # floor, walls, ceiling in segmentation images
NOTHING_ID = -1  # no surface (or the drone itself)


def person_id(n_obstacles: int, i: int) -> int:
    """The obstacle id of a scenario's person ``i`` (0-based): the static obstacles take 1..n_obstacles in
    the file's order, the people the ids after them (sim.scene builds them so)."""
    return n_obstacles + 1 + i


@dataclass(frozen=True, eq=False)
class ObstacleTruth:
    id: int  # >= 1, stable for the episode
    kind: str  # "person" or "static"
    label: str  # person | box | pillar | shelf | wall
    aabb_min: np.ndarray  # (3,) world [m]
    aabb_max: np.ndarray  # (3,) world [m]
    velocity: np.ndarray  # (3,) world [m/s]

    @property
    def center(self) -> np.ndarray:
        return (self.aabb_min + self.aabb_max) / 2

    @property
    def size(self) -> np.ndarray:
        return self.aabb_max - self.aabb_min

    def to_json(self) -> dict:
        return {"id": self.id, "kind": self.kind, "label": self.label,
                "aabb_min": [round(float(x), 4) for x in self.aabb_min],
                "aabb_max": [round(float(x), 4) for x in self.aabb_max],
                "velocity": [round(float(x), 4) for x in self.velocity]}


@dataclass(frozen=True, eq=False)
class GroundTruth:
    """Truth at one camera frame.

    segmentation: (H, W) int32 obstacle ids (STRUCTURE_ID, NOTHING_ID or an ObstacleTruth id),
    or None when the scenario turns segmentation off.
    """

    stamp: float
    seq: int
    obstacles: tuple[ObstacleTruth, ...]
    T_world_camera: np.ndarray  # true camera pose (the sensor frame carries odometry)
    drone_position: np.ndarray
    drone_velocity: np.ndarray
    segmentation: np.ndarray | None
    T_world_body: np.ndarray | None = None  # the drone's true pose at the frame's capture

    def to_json(self) -> dict:
        return {"stamp": round(self.stamp, 6), "seq": self.seq,
                "T_world_camera": np.round(self.T_world_camera, 6).tolist(),
                "drone_position": np.round(self.drone_position, 5).tolist(),
                "drone_velocity": np.round(self.drone_velocity, 5).tolist(),
                "obstacles": [o.to_json() for o in self.obstacles]}


@dataclass(frozen=True)
class CollisionEvent:
    """The drone's collision volume started touching something.

    The states at the contact are what a collision's fault is judged from
    (experiments.fault): the drone's velocity, the point of the other body nearest the drone,
    and that body's velocity (zero for static bodies)."""

    time: float
    other_id: int  # obstacle id, or STRUCTURE_ID
    other_kind: str  # person | static | structure
    position: tuple[float, float, float]  # drone position at the event
    drone_velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    contact_point: tuple[float, float, float] | None = None  # on the other body, world frame
    other_velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def to_json(self) -> dict:
        def r(v):
            return None if v is None else [round(float(x), 4) for x in v]

        return {"time": round(self.time, 5), "other_id": self.other_id, "other_kind": self.other_kind,
                "position": r(self.position), "drone_velocity": r(self.drone_velocity),
                "contact_point": r(self.contact_point), "other_velocity": r(self.other_velocity)}
