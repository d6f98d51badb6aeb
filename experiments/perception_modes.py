"""The perception modes the closed loop can fly with, each a perception module (dodt.protocol).

A perception module receives each sensor frame (and, only if it declares ``uses_ground_truth``, the
simulator's truth for that frame) and returns a ``PerceptionOutput``: the moving obstacles for the
planner and the boxes the static map must clear. The protocol and its output type live beside DODT's
output types in ``dodt/protocol.py`` (re-exported here); your own module plugs in as ``module:Class``
(experiments.plugins; examples/custom_perception.py).

Modes:
- ``dodt`` (and any DODT preset name, e.g. ``dodt-no-coast``): our DODT library on the frames.
- ``oracle``: people from ground truth, as the DODT authors' simulations use a fake detector: a
  person is known while inside the camera's horizontal field of view within ``max_range``, and for
  ``memory`` seconds after leaving it (perfect tracking through occlusion), with exact position,
  size and velocity, and the acceleration the true velocity shows over the last 0.1 s (a tracker's
  estimate, without its noise and lag). ``oracle.half_view`` widens (or narrows) the view it sees
  people in: what a planner would gain from a wider camera, or from more of them; ``oracle.confirm_time``
  reports a person coming into view only once that long has passed, as a tracker confirms a new track.
- ``oracle-360``: the same without the field of view: every person within ``max_range`` in any
  direction. Not a sensor anyone has; it measures the planner alone (with it, collisions are the
  planner's, since nothing comes from where the camera does not look).
  Both see through structure unless ``oracle.line_of_sight`` is set: then a person counts as seen only
  while a straight line from the camera to their body (its centre or either side, at the camera's
  height within their height) passes no static obstacle's box. That is the perfect perception a real
  rig could have: a person standing behind a column is not known until they step out (the rig's
  sensors sit within centimetres of the camera; other people, and the corridor's walls, occlude
  nobody here).
- ``oracle-noisy``: ``oracle`` with a wandering error on each person's velocity, of a tracker's
  size (``NOISY_ORACLE_VELOCITY_NOISE``: a larger median than DODT's, a like tail): how much a
  planner suffers from the velocity errors of a real tracker alone, everything else being perfect.
- ``static-only``: no dynamic perception; people enter the map as static obstacles.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from dodt.config import DODTConfig
from dodt.context import CameraSensor, EpisodeContext, LidarSensor
from dodt.frames import SensorFrame
from dodt.geometry import half_view, wrap_angle
from dodt.pipeline import DODT
from dodt.presets import preset
from dodt.protocol import PerceptionModule, PerceptionOutput, TrackReport  # also importable from here
from planner.types import ObstaclePrediction

MODES = ("dodt", "oracle", "oracle-360", "oracle-noisy", "static-only")
# m/s per axis (correlation time 0.5 s): the oracle-noisy mode's velocity error, the size of a tracker's
# velocity error on walkers near the drone (a larger median than DODT's, a like tail)
NOISY_ORACLE_VELOCITY_NOISE = 0.3


def horizontal_view(T_world_camera: np.ndarray, K) -> tuple[np.ndarray, float, float]:
    """(camera position (3,), heading [rad], half horizontal field of view [rad]) of a forward camera."""
    fwd = T_world_camera[:3, 2]
    return T_world_camera[:3, 3], math.atan2(fwd[1], fwd[0]), half_view(K)


def segment_blocked(p0: np.ndarray, p1: np.ndarray, boxes_lo: np.ndarray, boxes_hi: np.ndarray) -> bool:
    """Whether the segment p0 -> p1 (3,) passes through any axis-aligned box (lo, hi: (n, 3)): the slab
    test, the segment's parameter range inside every axis' slab overlapping within [0, 1]."""
    if len(boxes_lo) == 0:
        return False
    d = p1 - p0
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t0 = (boxes_lo - p0) * inv
        t1 = (boxes_hi - p0) * inv
    # an axis the segment does not move along: inside the slab (all t), or outside it (none)
    flat = d == 0.0
    inside = (p0 >= boxes_lo) & (p0 <= boxes_hi)
    lo = np.where(flat, np.where(inside, -np.inf, np.inf), np.minimum(t0, t1))
    hi = np.where(flat, np.where(inside, np.inf, -np.inf), np.maximum(t0, t1))
    enter = np.maximum(lo.max(axis=1), 0.0)
    leave = np.minimum(hi.min(axis=1), 1.0)
    return bool(np.any(enter < leave))


def line_of_sight(eye: np.ndarray, person, boxes_lo: np.ndarray, boxes_hi: np.ndarray, side: float = 0.2) -> bool:
    """Whether some straight line from ``eye`` (3,) reaches ``person`` (an ObstacleTruth) past the static
    boxes: to its centre or to a point ``side`` m either way across the line, at the eye's height clipped
    to the body's (0.2 m inside its bottom and top)."""
    c = np.asarray(person.center, float)
    lo_z, hi_z = float(person.aabb_min[2]), float(person.aabb_max[2])
    z = min(max(float(eye[2]), lo_z + 0.2), max(hi_z - 0.2, lo_z + 0.2))
    d = c[:2] - eye[:2]
    n = np.hypot(*d)
    across = np.array([-d[1], d[0]]) / n if n > 1e-9 else np.zeros(2)
    for s in (0.0, side, -side):
        target = np.array([c[0] + s * across[0], c[1] + s * across[1], z])
        if not segment_blocked(np.asarray(eye, float), target, boxes_lo, boxes_hi):
            return True
    return False


def bearing_and_distance(cam: np.ndarray, heading: float, xy) -> tuple[float, float]:
    """|angle| between the heading and the direction from the camera to a world point (x, y), and the
    horizontal distance to it."""
    d = np.asarray(xy, dtype=float)[:2] - cam[:2]
    return abs(wrap_angle(math.atan2(d[1], d[0]) - heading)), float(np.hypot(*d))


def oracle_view(cam: np.ndarray, heading: float, half_fov: float, obstacle, max_range: float,
                all_around: bool = False) -> tuple[bool, float, float]:
    """Whether the oracle sees ``obstacle`` (a sim.ground_truth.ObstacleTruth): any part of its body within
    the horizontal cone of half angle ``half_fov`` about the heading (any direction if ``all_around``) and
    its near side within ``max_range``; with the bearing of its centre and the distance to its near side."""
    bearing, dist = bearing_and_distance(cam, heading, obstacle.center)
    radius = 0.5 * float(np.hypot(*obstacle.size[:2]))
    in_cone = all_around or bearing <= half_fov + math.atan2(radius, max(dist, 1e-6))
    return dist - radius <= max_range and in_cone, bearing, dist - radius


PERSON_CLEAR_SPEED = 0.4  # m/s: a person-labelled track frees the map only when moving this fast


class DODTPerception:
    uses_ground_truth = False
    uses_images = True

    def __init__(self, config_name: str = "dodt", learned_detector=None, config: DODTConfig | None = None):
        self.name = config_name
        # config: DODT's configuration (default: the preset of that name), e.g. with --set dodt.* applied
        self.dodt = DODT(preset(config_name) if config is None else config, learned_detector=learned_detector)

    @property
    def uses_color(self) -> bool:
        """Only the learned person detector looks at colour; DODT without it reads depth alone."""
        return self.dodt.learned_detector is not None

    def reset(self, context: EpisodeContext | None = None) -> None:
        self.dodt.reset()
        smap = None if context is None else context.static_map
        lidar = next((s for s in context.sensors if isinstance(s, LidarSensor)), None) if context else None
        # the map lets DODT's motion label tell a static obstacle's edge from a person (dodt.motion_label)
        self.dodt.set_scene(smap, None if context is None else context.geofence,
                            None if lidar is None else lidar.model.elevation_min,
                            None if lidar is None else lidar.model.elevation_max)

    def observe_lidar(self, scan) -> None:
        self.dodt.observe_lidar(scan)

    def observe_cameras(self, frames) -> None:
        self.dodt.observe_cameras(frames)

    def update(self, frame: SensorFrame, truth=None) -> PerceptionOutput:
        r = self.dodt.process(frame)
        preds, boxes = [], []
        for o in r.obstacles:
            if not o.dynamic:
                continue
            v = o.velocity if o.filter_velocity is None else o.filter_velocity
            a = o.acceleration if o.filter_acceleration is None else o.filter_acceleration
            # The filter's position std is not passed (the prediction's own default growth is): DODT's
            # filter states two to three times the error it makes (the perception benchmark's std_scale), and
            # the planner, which adds the std to a person's radius, then backs away from walkers it could
            # pass (docs/planner.md, "Where it stands").
            preds.append(ObstaclePrediction(id=o.id, center=o.center, size=o.size, velocity=v, acceleration=a))
            # The map is freed under DODT's dynamic tracks, but not under one dynamic by its motion alone
            # (dodt.motion_label), which the map keeps as structure while it is there; under one the learned
            # detector labels a person, only while it moves: a misplaced person box lifted onto a wall
            # would otherwise open a hole in the wall.
            if o.evidence != "motion" and (not o.is_person or float(np.hypot(o.velocity[0], o.velocity[1])) >= PERSON_CLEAR_SPEED):
                boxes.append((o.center, o.size))
        return PerceptionOutput(stamp=r.stamp, obstacles=tuple(preds), clear_boxes=tuple(boxes),
                                tracks=tuple(TrackReport.from_tracked(o) for o in r.obstacles),
                                timings_ms=dict(r.timings_ms),
                                skipped=r.skipped)


@dataclass(frozen=True)
class OracleConfig:
    """The oracle modes' settings (configuration section ``oracle``; oracle-noisy starts from
    ``velocity_noise = NOISY_ORACLE_VELOCITY_NOISE``)."""

    max_range: float = 5.0  # m: a person is seen within this horizontal distance of the camera (nearest side)
    # deg: half the horizontal view a person is seen in, about the camera's heading (180: all around);
    # None: the camera's own (39.7 for the simulated D435 at 640x480). What a wider camera, or more of them,
    # would give a planner.
    half_view: float | None = None
    memory: float = 1.0  # s: a person out of view is still reported this long after last seen
    # s: a person coming into view (unseen for longer than memory) is reported once this long has passed
    # since, if still seen, like a tracker confirming a new track; 0: at once
    confirm_time: float = 0.0
    # s: each person's acceleration is the change of its true velocity over this window (the truth holds
    # no acceleration); None: zero acceleration (constant-velocity predictions)
    accel_window: float | None = 0.1
    # m/s per horizontal axis: the reported velocity is the truth plus a random error that wanders with
    # correlation time noise_time s (a Gauss-Markov process per person, from noise_seed and the person's
    # id, so an episode is repeatable); 0: exact
    velocity_noise: float = 0.0
    noise_time: float = 0.5
    noise_seed: int = 0
    # a person is seen only along a line from the camera that no static obstacle's box cuts (module
    # docstring); False: through structure, as the DODT authors' simulated detector
    line_of_sight: bool = False

    def __post_init__(self):
        if not self.max_range > 0.0:
            raise ValueError(f"OracleConfig: max_range must be > 0, got {self.max_range}")
        if not self.memory >= 0.0 or not self.velocity_noise >= 0.0 or not self.confirm_time >= 0.0:
            raise ValueError(f"OracleConfig: memory, velocity_noise and confirm_time must be >= 0, got {self.memory}, "
                             f"{self.velocity_noise} and {self.confirm_time}")
        if self.half_view is not None and not 0.0 < self.half_view <= 180.0:
            raise ValueError(f"OracleConfig: half_view must be in (0, 180] degrees (or none), got {self.half_view}")
        if self.accel_window is not None and not self.accel_window > 0.0:
            raise ValueError(f"OracleConfig: accel_window must be > 0 (or none), got {self.accel_window}")
        if not self.noise_time > 0.0:
            raise ValueError(f"OracleConfig: noise_time must be > 0, got {self.noise_time}")


class OraclePerception:
    uses_ground_truth = True
    uses_images = False
    uses_color = False

    def __init__(self, cfg: OracleConfig = OracleConfig(), all_around: bool = False, name: str | None = None):
        """all_around: see every person in range whatever the camera's view (oracle-360)."""
        self.cfg = cfg
        self.all_around = all_around
        self.name = name or ("oracle-360" if all_around else "oracle")
        self.reset()

    def reset(self, context: EpisodeContext | None = None) -> None:
        # the rig's other sensors: (yaw of each other camera from the first [rad]; whether a LiDAR sees all round)
        sensors = () if context is None else context.sensors
        cams = [s for s in sensors if isinstance(s, CameraSensor)]
        self._other_yaws = tuple(wrap_angle(c.yaw_on_body - cams[0].yaw_on_body) for c in cams[1:])
        self._lidar = any(isinstance(s, LidarSensor) for s in sensors)
        self._last_seen: dict[int, float] = {}
        self._first_seen: dict[int, float] = {}  # id -> when it came into view after being lost
        self._velocities: dict[int, deque] = {}  # id -> (stamp, true velocity) over accel_window
        self._noise: dict[int, tuple[np.random.Generator, float, np.ndarray]] = {}  # id -> (rng, stamp, error)

    def _velocity_error(self, oid: int, stamp: float) -> np.ndarray:
        if self.cfg.velocity_noise <= 0:
            return np.zeros(3)
        if oid not in self._noise:
            rng = np.random.default_rng([self.cfg.noise_seed, oid])
            self._noise[oid] = (rng, stamp, np.array([*(self.cfg.velocity_noise * rng.standard_normal(2)), 0.0]))
        rng, last, e = self._noise[oid]
        if stamp > last:
            a = math.exp(-(stamp - last) / self.cfg.noise_time)
            e = a * e + self.cfg.velocity_noise * math.sqrt(1.0 - a * a) * np.array([*rng.standard_normal(2), 0.0])
            self._noise[oid] = (rng, stamp, e)
        return e

    def _acceleration(self, oid: int, stamp: float, velocity: np.ndarray) -> np.ndarray:
        if self.cfg.accel_window is None:
            return np.zeros(3)
        hist = self._velocities.setdefault(oid, deque())
        hist.append((stamp, velocity.copy()))
        while len(hist) > 2 and stamp - hist[1][0] >= self.cfg.accel_window - 1e-9:
            hist.popleft()
        dt = stamp - hist[0][0]
        return (velocity - hist[0][1]) / dt if dt >= 0.5 * self.cfg.accel_window else np.zeros(3)

    def update(self, frame: SensorFrame, truth=None) -> PerceptionOutput:
        if truth is None:
            raise ValueError("the oracle perception mode needs the simulator's ground truth")
        cam, heading, half_fov = horizontal_view(truth.T_world_camera, frame.intrinsics)
        if self.cfg.half_view is not None:
            half_fov = math.radians(self.cfg.half_view)
        preds, boxes, tracks = [], [], []
        if self.cfg.line_of_sight:
            statics = [o for o in truth.obstacles if o.kind != "person"]
            s_lo = np.array([o.aabb_min for o in statics], float).reshape(-1, 3)
            s_hi = np.array([o.aabb_max for o in statics], float).reshape(-1, 3)
        for o in truth.obstacles:
            if o.kind != "person":
                continue
            acc = self._acceleration(o.id, truth.stamp, o.velocity)
            vel = o.velocity + self._velocity_error(o.id, truth.stamp)
            in_view = oracle_view(cam, heading, half_fov, o, self.cfg.max_range, self.all_around or self._lidar)[0] \
                or any(oracle_view(cam, heading + y, half_fov, o, self.cfg.max_range)[0] for y in self._other_yaws)
            if in_view and self.cfg.line_of_sight:
                in_view = line_of_sight(cam, o, s_lo, s_hi)
            seen = self._last_seen.get(o.id)
            if in_view:
                if seen is None or truth.stamp - seen > self.cfg.memory:
                    self._first_seen[o.id] = truth.stamp
                self._last_seen[o.id] = seen = truth.stamp
            if seen is None or truth.stamp - seen > self.cfg.memory:
                continue
            if seen - self._first_seen[o.id] < self.cfg.confirm_time - 1e-9:
                continue
            preds.append(ObstaclePrediction(id=o.id, center=o.center.copy(), size=o.size.copy(),
                                            velocity=vel, acceleration=acc))
            boxes.append((o.center.copy(), o.size.copy()))
            tracks.append(TrackReport(id=o.id, center=o.center.copy(), size=o.size.copy(), velocity=vel, dynamic=True,
                                      coasting=truth.stamp > seen))
        return PerceptionOutput(stamp=truth.stamp, obstacles=tuple(preds), clear_boxes=tuple(boxes),
                                tracks=tuple(tracks))


class StaticOnlyPerception:
    name = "static-only"
    uses_ground_truth = False
    uses_images = False  # the map looks at the depth, not this module
    uses_color = False

    def reset(self, context: EpisodeContext | None = None) -> None:
        pass

    def update(self, frame: SensorFrame, truth=None) -> PerceptionOutput:
        return PerceptionOutput(stamp=frame.stamp, obstacles=())
