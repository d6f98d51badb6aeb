"""The parts of a scenario (sim.scenario.Scenario): corridor, obstacles, people, drone, camera, depth
noise, rates, camera path and crowd, as frozen dataclasses whose defaults are the file's defaults."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

OBSTACLE_KINDS = ("box", "pillar", "shelf", "wall")
BEHAVIOURS = ("waypoint_loop", "back_and_forth", "crossing", "random_walk", "circle")
PERSON_SPEED_RANGE = (0.5, 1.6)  # m/s, the walking-speed band
PERSON_HEIGHT_RANGE = (1.6, 1.85)  # m
PERSON_RADIUS = 0.25  # m, footprint half-width used for the corridor and obstacle checks


@dataclass(frozen=True)
class Corridor:
    length: float = 15.0  # m, along world x, from x = 0
    width: float = 4.0  # m, along world y, centred on y = 0
    height: float = 3.0  # m, wall height
    ceiling: bool = False
    # Optional RGB in [0, 1] (set from code, e.g. the detector's data generator; not read from
    # TOML). None keeps the defaults: a grey floor, off-white walls jittered by the seed.
    floor_color: tuple[float, float, float] | None = None
    wall_color: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class Obstacle:
    """A static obstacle standing on the floor.

    box / shelf / wall: ``size`` = (length along its x, depth along its y, height), rotated by
    ``yaw`` about its centre. pillar: a cylinder, ``size`` = (diameter, diameter, height).
    """

    kind: str
    center: tuple[float, float]
    size: tuple[float, float, float]
    yaw: float = 0.0  # rad
    color: tuple[float, float, float] | None = None

    def footprint_contains(self, xy: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Boolean mask of the (N, 2) points inside the footprint grown by ``margin``."""
        d = np.atleast_2d(np.asarray(xy, dtype=float)) - np.asarray(self.center)
        if self.kind == "pillar":
            return np.hypot(d[:, 0], d[:, 1]) <= self.size[0] / 2 + margin
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        lx = c * d[:, 0] + s * d[:, 1]
        ly = -s * d[:, 0] + c * d[:, 1]
        return (np.abs(lx) <= self.size[0] / 2 + margin) & (np.abs(ly) <= self.size[1] / 2 + margin)

    def aabb(self) -> tuple[np.ndarray, np.ndarray]:
        """World axis-aligned box (min, max) of the obstacle."""
        if self.kind == "pillar":
            hx = hy = self.size[0] / 2
        else:
            c, s = abs(math.cos(self.yaw)), abs(math.sin(self.yaw))
            hx = c * self.size[0] / 2 + s * self.size[1] / 2
            hy = s * self.size[0] / 2 + c * self.size[1] / 2
        lo = np.array([self.center[0] - hx, self.center[1] - hy, 0.0])
        hi = np.array([self.center[0] + hx, self.center[1] + hy, self.size[2]])
        return lo, hi


@dataclass(frozen=True)
class Person:
    behaviour: str
    speed: float  # m/s
    height: float | None = None  # m; None -> drawn from the seed in PERSON_HEIGHT_RANGE
    start_delay: float = 0.0  # s standing before walking
    waypoints: tuple[tuple[float, float], ...] = ()
    region: tuple[float, float, float, float] | None = None  # x_min, y_min, x_max, y_max
    start: tuple[float, float] | None = None  # random_walk start (None -> drawn in region)
    center: tuple[float, float] | None = None  # circle
    radius: float | None = None  # circle
    clockwise: bool = False  # circle
    color: tuple[float, float, float] | None = None
    sees_drone: bool | None = None  # None: the scenario's crowd.sees_drone


@dataclass(frozen=True)
class Drone:
    start: tuple[float, float, float] = (0.5, 0.0, 1.2)
    goal: tuple[float, float, float] = (14.5, 0.0, 1.2)
    yaw: float = 0.0  # rad, initial heading
    cruise_speed: float = 1.0  # m/s along the straight demo reference


# The renderers: "gl", ours (sim.gl_renderer: OpenGL through moderngl on EGL); "pybullet", PyBullet's
# EGL renderer plugin; "tiny", PyBullet's TinyRenderer (software, no EGL needed). "auto" takes the first
# of these that works here. "egl" is the older name of "pybullet".
RENDERERS = ("gl", "pybullet", "tiny")
RENDERER_CHOICES = ("auto",) + RENDERERS + ("egl",)


@dataclass(frozen=True)
class Camera:
    """RealSense D435i depth stream as configured by the DODT authors (see dodt.frames)."""

    width: int = 640
    height: int = 480
    fx: float = 387.1537
    fy: float = 387.1537
    cx: float = 321.3246
    cy: float = 233.5472
    min_range: float = 0.2  # m; D435 minimum Z is about 0.11-0.2 m depending on resolution
    max_range: float = 10.0  # m
    # Body (FLU) -> camera optical frame offset: the reference code's D435i extrinsic
    # t = (0.065, 0.01, 0.12) m; rpy is the extra mount rotation (roll, pitch, yaw) [rad].
    mount_xyz: tuple[float, float, float] = (0.065, 0.01, 0.12)
    mount_rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    color: bool = True
    renderer: str = "auto"  # auto | gl | pybullet | tiny (sim.camera.RENDERERS; egl = pybullet)


@dataclass(frozen=True)
class Noise:
    """Depth noise (sim.depth_noise) and odometry noise; ``enabled = false`` is exact."""

    enabled: bool = True
    axial_model: str = "intel_rms"  # intel_rms | nguyen | none
    baseline: float = 0.050  # m, D435 stereo baseline
    subpixel: float = 0.08  # px RMS disparity error (Intel: < 0.1 typical)
    edge_threshold: float = 0.05  # relative depth jump that marks a depth edge
    edge_hole_prob: float = 0.4  # edge pixel -> invalid (0)
    flying_pixel_prob: float = 0.3  # edge pixel -> mixed depth between the two surfaces
    dropout: float = 0.005  # fraction of valid pixels randomly invalid
    odom_position_std: float = 0.0  # m, per-frame odometry position noise
    odom_rotation_std: float = 0.0  # rad, per-frame odometry rotation noise


@dataclass(frozen=True)
class Rates:
    physics: int = 240  # Hz
    control: int = 120  # Hz
    camera: int = 30  # Hz


@dataclass(frozen=True)
class CameraPath:
    """A scripted camera path (perception scenarios): no planner needed.

    mode = "carried": the body is moved kinematically along the path, level (hand-held).
    mode = "flown": the controller flies the path, so the image tilts with the body.
    Either ``keyframes`` [[t, x, y, z, yaw_deg], ...] interpolated linearly, or
    ``follow_person`` (index) walking ``follow_distance`` behind that person's trail.
    """

    mode: str = "carried"
    keyframes: tuple[tuple[float, float, float, float, float], ...] = ()
    follow_person: int | None = None
    follow_distance: float = 2.5
    follow_height: float = 1.3


@dataclass(frozen=True)
class Crowd:
    """How people move around each other and the drone (sim.crowd).

    Every person follows its behaviour's route and keeps clear of the other people by the social
    force model of Helbing & Molnar (1995); people who ``see`` the drone also keep clear of it.
    The defaults are that paper's values but for step_time (sim.crowd says why)."""

    sees_drone: bool = False  # default of every person (a person's own ``sees_drone`` overrides it)
    relaxation_time: float = 0.5  # s, tau: how fast a person returns to its desired velocity
    strength: float = 2.1  # m^2/s^2, V0 of the repulsive potential V(b) = V0 exp(-b / sigma)
    range: float = 0.3  # m, sigma
    step_time: float = 1.0  # s, Delta t: the other's step v Delta t stretches the potential along its motion
    view_angle: float = math.radians(100.0)  # rad, half angle of the field of view (2 phi = 200 deg)
    behind_weight: float = 0.5  # c: weight of what is outside the field of view
    max_speed_factor: float = 1.3  # a person walks at most this times its route speed (and never over 1.6 m/s)


def circle_waypoints(center, radius, clockwise=False, n=24) -> tuple[tuple[float, float], ...]:
    """The route of a person walking a circle: ``n`` points on it, from angle 0, counter-clockwise or not."""
    a = np.linspace(0, 2 * np.pi, n, endpoint=False) * (-1 if clockwise else 1)
    return tuple((center[0] + radius * math.cos(t), center[1] + radius * math.sin(t)) for t in a)
