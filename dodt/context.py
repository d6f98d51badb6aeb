"""The episode context: what every planner and perception module is told once per episode.

The closed loop builds one ``EpisodeContext`` before an episode and hands it to each module's
``reset(context)``; per step a planner gets an immutable ``planner.types.PlannerInput`` and a perception
module a ``dodt.frames.SensorFrame``. The context is frozen: the vehicle and its limits, the sensors with
their models and mounts, the rates, the geofence, the start and goal, and read-only views of the static
map and of the seen space, which the loop keeps updating during the episode (the views are live; a module
may only query them).

It lives in ``dodt`` because it is the lowest layer: the simulator, the planner and perception all read
it, and ``dodt`` imports none of them. Units SI; world frame x along the corridor, y left, z up; a
transform ``T_a_b`` maps points from frame b into frame a.
"""
from __future__ import annotations

import inspect
import math
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from dodt.frames import CameraIntrinsics
from dodt.geometry import half_view


@dataclass(frozen=True, eq=False)
class VehicleLimits:
    """The vehicle's size and physical limits."""

    radius: float  # m: the horizontal circumscribed radius of its collision box (what planners keep clear)
    collision_size: np.ndarray  # (3,) m: its collision box, body frame FLU
    mass: float  # kg
    thrust_to_weight: float  # the rotors' total thrust at full speed over the weight
    max_tilt_accel: float  # m/s^2: the horizontal acceleration the thrust allows while holding altitude

    @staticmethod
    def from_thrust(radius: float, collision_size, mass: float, thrust_to_weight: float,
                    gravity: float = 9.81) -> "VehicleLimits":
        """Limits of a multirotor whose rotors give ``thrust_to_weight`` times its weight."""
        horizontal = gravity * math.sqrt(max(thrust_to_weight ** 2 - 1.0, 0.0))
        return VehicleLimits(radius=float(radius), collision_size=np.asarray(collision_size, float).copy(),
                             mass=float(mass), thrust_to_weight=float(thrust_to_weight), max_tilt_accel=horizontal)


@dataclass(frozen=True, eq=False)
class CameraSensor:
    """An RGB-D camera on the body: its model, mount and rate."""

    name: str  # e.g. "front"
    intrinsics: CameraIntrinsics  # the depth stream's pinhole model (colour is registered to it)
    T_body_sensor: np.ndarray  # (4, 4) the optical frame (x right, y down, z forward) in the body frame FLU
    rate: float  # Hz
    max_depth: float  # m: beyond this the depth is invalid
    kind: str = "rgbd"

    @property
    def half_view(self) -> float:
        """Half the horizontal field of view [rad] (to the wider of the image's sides)."""
        return half_view(self.intrinsics)

    @property
    def yaw_on_body(self) -> float:
        """The optical axis' heading relative to the body's x axis [rad]."""
        z = self.T_body_sensor[:3, 2]
        return math.atan2(z[1], z[0])


@runtime_checkable
class LidarModelView(Protocol):
    """What a module may read of a LiDAR's model (``sim.lidar.LidarModel`` is one): its field of view and
    range. Angles in the sensor frame (x forward, y left, z up), radians; ranges in metres."""

    name: str
    horizontal_fov: float  # rad, centred on the sensor's x axis (2 pi: all round)
    elevation_min: float  # rad, the lowest ray (negative: below the sensor's xy plane)
    elevation_max: float  # rad, the highest ray
    min_range: float  # m: the blind zone; nearer surfaces give no return
    max_range: float  # m: farther surfaces give no return
    points_per_scan: int  # rays cast per scan


@dataclass(frozen=True, eq=False)
class LidarSensor:
    """A 3D LiDAR on the body: its model, mount and rate."""

    name: str  # e.g. "top"
    model: LidarModelView
    T_body_sensor: np.ndarray  # (4, 4) the sensor frame (x forward, y left, z up) in the body frame FLU
    rate: float  # Hz: scans per second
    kind: str = "lidar"

    def in_view(self, points_sensor) -> np.ndarray:
        """(N, 3) points in the sensor frame -> (N,) bool: within the field of view and range."""
        q = np.asarray(points_sensor, dtype=np.float64).reshape(-1, 3)
        m = self.model
        r = np.linalg.norm(q, axis=1)
        el = np.arcsin(np.clip(q[:, 2] / np.maximum(r, 1e-12), -1.0, 1.0))
        az = np.arctan2(q[:, 1], q[:, 0])
        return ((r >= m.min_range) & (r <= m.max_range) & (el >= m.elevation_min) & (el <= m.elevation_max)
                & (np.abs(az) <= 0.5 * m.horizontal_fov))


@runtime_checkable
class StaticMapView(Protocol):
    """Read-only queries of the episode's static voxel map (world frame, metres).

    Voxel (i, j, k) covers ``origin + res * [i, i + 1)`` per axis over ``dims`` voxels. The default map
    (the planner's voxel map) implements these; the context holds the live map, so answers change as the
    map is built from depth. A module must not call anything else on it, nor change it.
    """

    res: float  # m, voxel edge
    origin: np.ndarray  # (3,) m, the map's lower corner
    dims: np.ndarray  # (3,) voxels per axis

    def is_occupied(self, points) -> np.ndarray: ...  # (N, 3) -> (N,) bool

    def is_free(self, points) -> np.ndarray: ...  # (N, 3) -> (N,) bool: seen free

    def is_unknown(self, points) -> np.ndarray: ...  # (N, 3) -> (N,) bool: never observed (or outside)

    def occupied_centers(self, lo, hi) -> np.ndarray: ...  # (K, 3) centres of occupied voxels in [lo, hi]

    def established_fraction(self, center, size) -> float: ...
    # share (0 to 1) of a box's footprint on structure the map has held for a while

    def column_blocked(self, z_lo: float, z_hi: float, inflate: bool = True) -> np.ndarray: ...
    # (nx, ny) bool: a voxel column holds an occupied voxel within heights [z_lo, z_hi]

    def world_to_cell(self, xy) -> np.ndarray: ...  # (M, 2) x, y -> (M, 2) column indices

    def cell_to_world(self, ij) -> np.ndarray: ...  # (M, 2) column indices -> (M, 2) x, y of the centres


@runtime_checkable
class SeenSpaceView(Protocol):
    """Read-only: when each floor cell (the map's columns) was last seen free at a person's height."""

    origin: np.ndarray  # (2,) m, the grid's lower corner in x, y
    shape: tuple[int, int]
    res: float  # m, cell edge
    last: np.ndarray  # (nx, ny) s: the stamp each cell was last seen free, -inf where never

    def centres(self) -> np.ndarray: ...  # (nx, ny, 2) x, y of the cell centres


@dataclass(frozen=True, eq=False)
class Rates:
    """The loop's rates [Hz]."""

    control: float
    plan: float
    map: float


@dataclass(frozen=True, eq=False)
class EpisodeContext:
    """Everything about an episode a module may know before it starts (see the module's docstring)."""

    scenario: str  # the scenario's name
    seed: int
    duration: float  # s: the episode's time limit
    vehicle: VehicleLimits
    sensors: tuple[CameraSensor, ...]  # the rig: today one forward camera
    rates: Rates
    start: np.ndarray  # (3,) m
    goal: np.ndarray  # (3,) m
    geofence: tuple[np.ndarray, np.ndarray] | None  # known walls of the flight area: (lo, hi) in x, y [m]
    static_map: StaticMapView | None = None  # live, read-only
    seen: SeenSpaceView | None = None  # live, read-only

    @property
    def camera(self) -> CameraSensor:
        """The first camera of the rig (the paper's forward camera)."""
        for s in self.sensors:
            if isinstance(s, CameraSensor):
                return s
        raise LookupError("this episode's rig has no camera")


def reset_with_context(module, context: EpisodeContext | None) -> None:
    """``module.reset(context)``; ``module.reset()`` for a module whose ``reset`` takes no parameter (the
    protocol before the episode context existed)."""
    reset = module.reset
    try:
        params = [p for p in inspect.signature(reset).parameters.values()
                  if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD, p.VAR_POSITIONAL)]
    except (TypeError, ValueError):  # a builtin or C callable: the protocol's form
        params = [None]
    if params:
        reset(context)
    else:
        reset()
