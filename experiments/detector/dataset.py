"""Training data for the learned person detector: simulator images with person boxes.

Each scene seed builds one random corridor (size, floor and wall colours, 2-8 static
distractors, 1-5 walking people with random shirts, heights, paths and gait phases) and
renders ``images_per_seed`` colour images from camera poses drawn around the people: at
0.5-12 m from a chosen person, from any side (front, side, back), 0.5-2.0 m high, with the
drone's roll and pitch up to 15 degrees and a random light direction. About 7 % of the images
are posed to look away from every person, down the corridor; with the aimed views in which the
person is hidden or out of frame, about 10 % have no box (negatives). Boxes come from the
full-resolution ground-truth segmentation: the extent of each person's visible pixels.

The images are stored as the network sees them (``dodt.learned.layout.resize_for_network``),
boxes as fractions of the image, so they hold at any resolution. Everything follows from the
seeds: the same seeds give byte-identical arrays. Train and validation sets are told apart by
seed only (``check_disjoint``).

How the camera is posed: the scene's camera path is "carried" (the body is moved kinematically,
level, through one keyframe per image, held for 0.1 s around the image time), and the drone's
roll and pitch are applied by setting ``World.T_body_camera`` before each image; the body sits
CAMERA_AHEAD metres behind the camera so that it never shows in the image. The camera pose
reported by the ground truth is checked against the intended one for every image.
"""
from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from dodt.geometry import wrap_angle
from dodt.learned.layout import INPUT_H, INPUT_W, resize_for_network
from sim.ground_truth import GroundTruth
from sim.people import WalkPath, plan_path
from sim.scenario import (OBSTACLE_KINDS, PERSON_RADIUS, Camera, CameraPath, Corridor, Drone, Noise, Obstacle,
                          Person, Rates, Scenario, circle_waypoints)

GENERATOR_VERSION = 1

# Rules for a kept box (recorded in every file's meta).
MIN_VISIBLE_PIXELS = 20  # visible pixels of the person at full resolution
MIN_BOX_HEIGHT_PX = 6  # box height at full resolution
MIN_DISTANCE = 0.1  # m: a person whose centre is (nearly) beside the camera gets this distance

# Scene ranges.
CORRIDOR_LENGTH = (14.0, 22.0)  # m
CORRIDOR_WIDTH = (3.0, 8.0)  # m
CORRIDOR_HEIGHT = (2.6, 3.6)  # m
CEILING_PROB = 0.4
OBSTACLE_COUNT = (2, 8)  # inclusive
PEOPLE_COUNT = (1, 5)  # inclusive
PERSON_SPEED = (0.5, 1.6)  # m/s (the simulator's walking band)
COMPANION_PROB = 0.3  # a person walks the path of an earlier one, offset and a little behind
STANDING_START_PROB = 0.15  # a person stands for 0.5-4 s before walking

# Camera ranges.
FOCUS_DISTANCE = (0.5, 12.0)  # m, horizontal, from the camera to the person it is aimed at
CAMERA_HEIGHT = (0.5, 2.0)  # m
MAX_TILT = math.radians(15.0)  # roll and pitch, each
AIM_SPREAD = 0.75  # the aimed-at person lies within this fraction of the half field of view
NEGATIVE_PROB = 0.07  # images posed to look away from every person (with the aimed views in which the
# person is hidden or out of frame, about 10 % of the images have no box)
NEGATIVE_VIEW_DEPTH = 2.5  # m of corridor ahead of a negative view
LIGHT_ELEVATION = (math.radians(15.0), math.radians(85.0))
CAMERA_AHEAD = 0.3  # m: the camera sits this far ahead of the body, which stays out of view
WALL_MARGIN = 0.3  # m: camera to walls and obstacles
PERSON_MARGIN = 0.45  # m: camera to any person (horizontal)

IMAGE_PERIOD = 0.5  # s of simulated time between two images of a scene
_RATES = Rates(physics=120, control=120, camera=2)  # one frame per IMAGE_PERIOD, cheap carried steps
_HOLD = 0.05  # s: each camera keyframe is held this long either side of its image time
_CAMERA = Camera(mount_xyz=(CAMERA_AHEAD, 0.0, 0.0))
_R_FLU_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
_SCENE_STREAM, _VIEW_STREAM = 0x5CE, 0x71E  # keys mixed with the seed: scene and view random streams

ProgressFn = Callable[[int, int], None]


def _rules() -> dict:
    return {
        "box": "x1, y1 = min column / W, min row / H; x2, y2 = (max column + 1) / W, (max row + 1) / H of the "
               "person's visible pixels in the full-resolution ground-truth segmentation (W x H = 640 x 480)",
        "min_visible_pixels": MIN_VISIBLE_PIXELS,
        "min_box_height_px": MIN_BOX_HEIGHT_PX,
        "distance": "depth of the person's axis-aligned box centre along the camera's optical axis (m), "
                    f"at least {MIN_DISTANCE}; people beyond 10 m are kept",
        "negative": "an image with no kept box (people with fewer pixels than the rules may still show)",
        "image": f"resize_for_network(color): RGB uint8 {INPUT_H} x {INPUT_W} (bilinear, each axis on its own)",
        "columns": ["image", "x1", "y1", "x2", "y2", "distance_m", "visible_pixels"],
    }


def _scene_ranges() -> dict:
    return {
        "corridor_length_m": CORRIDOR_LENGTH, "corridor_width_m": CORRIDOR_WIDTH,
        "corridor_height_m": CORRIDOR_HEIGHT, "ceiling_prob": CEILING_PROB, "obstacles": OBSTACLE_COUNT,
        "people": PEOPLE_COUNT, "person_speed_mps": PERSON_SPEED, "companion_prob": COMPANION_PROB,
        "focus_distance_m": FOCUS_DISTANCE, "camera_height_m": CAMERA_HEIGHT,
        "max_roll_pitch_deg": math.degrees(MAX_TILT), "negative_prob": NEGATIVE_PROB,
        "negative_view_depth_m": NEGATIVE_VIEW_DEPTH,
        "image_period_s": IMAGE_PERIOD,
        "light": "random direction per image (PyBullet's EGL renderer honours only the light direction)",
    }


# --------------------------------------------------------------------------- scenes


@dataclass(frozen=True)
class View:
    """One image of a scene: when, and the camera's pose (body yaw, then pitch, then roll)."""

    time: float  # s
    position: tuple[float, float, float]  # camera optical centre, world [m]
    yaw: float  # rad
    pitch: float  # rad, FLU: positive tilts the view down
    roll: float  # rad
    light: tuple[float, float, float]  # light direction, world
    negative: bool  # posed to look away from every person

    def R_body(self) -> np.ndarray:
        return _rot_z(self.yaw) @ _rot_y(self.pitch) @ _rot_x(self.roll)

    def T_body_camera(self) -> np.ndarray:
        """Camera in the level, yawed body that the carried path moves (attitude in the mount)."""
        T = np.eye(4)
        T[:3, :3] = _rot_y(self.pitch) @ _rot_x(self.roll) @ _R_FLU_OPTICAL
        T[:3, 3] = (CAMERA_AHEAD, 0.0, 0.0)
        return T

    def T_world_camera(self) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = self.R_body() @ _R_FLU_OPTICAL
        T[:3, 3] = self.position
        return T

    def body_position(self) -> tuple[float, float, float]:
        x, y, z = self.position
        return (x - CAMERA_AHEAD * math.cos(self.yaw), y - CAMERA_AHEAD * math.sin(self.yaw), z)


@dataclass(frozen=True)
class Scene:
    seed: int
    scenario: Scenario
    views: tuple[View, ...]


def _rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _color(rng, lo=0.05, hi=0.95) -> tuple[float, float, float]:
    return tuple(float(x) for x in rng.uniform(lo, hi, 3))


def _tinted(rng, lo: float, hi: float, tint: float) -> tuple[float, float, float]:
    """A mostly grey colour with a random tint (floors, walls)."""
    base = rng.uniform(lo, hi)
    return tuple(float(x) for x in np.clip(base + rng.uniform(-tint, tint, 3), 0.0, 1.0))


def _random_obstacle(rng, co: Corridor) -> Obstacle:
    kind = OBSTACLE_KINDS[int(rng.integers(len(OBSTACLE_KINDS)))]
    top = co.height - 0.05
    if kind == "box":
        size = (rng.uniform(0.3, 1.5), rng.uniform(0.3, 1.5), rng.uniform(0.3, min(2.0, top)))
    elif kind == "pillar":
        d = rng.uniform(0.2, 0.7)
        size = (d, d, co.height if rng.random() < 0.5 else rng.uniform(1.0, top))
    elif kind == "shelf":
        size = (rng.uniform(0.6, 2.0), rng.uniform(0.3, 0.6), rng.uniform(1.0, min(2.2, top)))
    else:  # wall: a partition
        size = (rng.uniform(0.6, min(3.0, 0.6 * co.width)), rng.uniform(0.08, 0.25), rng.uniform(1.2, min(2.6, top)))
    if kind in ("shelf", "wall") and rng.random() < 0.5:
        yaw = (math.pi / 2) * int(rng.integers(2))  # along or across the corridor
    else:
        yaw = rng.uniform(-math.pi, math.pi)
    center = (rng.uniform(0.0, co.length), rng.uniform(-co.width / 2, co.width / 2))
    return Obstacle(kind=kind, center=tuple(float(x) for x in center), size=tuple(float(x) for x in size),
                    yaw=float(yaw), color=_color(rng))


def _obstacles(rng, co: Corridor) -> tuple[Obstacle, ...]:
    out: list[Obstacle] = []
    for _ in range(int(rng.integers(OBSTACLE_COUNT[0], OBSTACLE_COUNT[1] + 1))):
        for _attempt in range(30):
            o = _random_obstacle(rng, co)
            lo, hi = o.aabb()
            if lo[0] < 0.05 or hi[0] > co.length - 0.05 or lo[1] < -co.width / 2 + 0.05 or hi[1] > co.width / 2 - 0.05:
                continue
            gap = 0.6  # m left free between obstacles, so that people get through
            if any(np.all(lo[:2] < b_hi[:2] + gap) and np.all(hi[:2] > b_lo[:2] - gap)
                   for b_lo, b_hi in (b.aabb() for b in out)):
                continue
            out.append(o)
            break
    return tuple(out)


def _free(co: Corridor, obstacles: Sequence[Obstacle], xy: np.ndarray, margin: float) -> np.ndarray:
    """Mask of the (N, 2) points inside the corridor and outside every obstacle, by ``margin``."""
    xy = np.atleast_2d(xy)
    ok = ((xy[:, 0] >= margin) & (xy[:, 0] <= co.length - margin) & (np.abs(xy[:, 1]) <= co.width / 2 - margin))
    for o in obstacles:
        ok &= ~o.footprint_contains(xy, margin)
    return ok


def _path_clear(co, obstacles, points, closed: bool, margin: float = PERSON_RADIUS + 0.05) -> bool:
    pts = np.asarray(points, float)
    if closed:
        pts = np.vstack([pts, pts[:1]])
    samples = [pts[:1]]
    for a, b in zip(pts[:-1], pts[1:]):
        n = max(2, int(math.ceil(np.linalg.norm(b - a) / 0.05)) + 1)
        samples.append(a + np.linspace(0.0, 1.0, n)[1:, None] * (b - a))
    return bool(np.all(_free(co, obstacles, np.vstack(samples), margin)))


def _free_point(rng, co, obstacles, margin: float = PERSON_RADIUS + 0.05) -> np.ndarray | None:
    for _ in range(200):
        q = np.array([rng.uniform(0.0, co.length), rng.uniform(-co.width / 2, co.width / 2)])
        if _free(co, obstacles, q, margin)[0]:
            return q
    return None


def _wander(rng, co, obstacles, need: float) -> tuple[tuple[float, float], ...] | None:
    """A random polyline through free space at least ``need`` metres long (if it can be found)."""
    cur = _free_point(rng, co, obstacles)
    if cur is None:
        return None
    pts, total = [cur], 0.0
    for _leg in range(100):
        if total >= need:
            break
        for _ in range(100):
            goal = _free_point(rng, co, obstacles)
            if (goal is not None and np.linalg.norm(goal - cur) >= 1.0
                    and _path_clear(co, obstacles, [cur, goal], False)):
                break
        else:
            break  # boxed in: the person stops here
        total += float(np.linalg.norm(goal - cur))
        pts.append(goal)
        cur = goal
    if len(pts) < 2:
        return None
    return tuple((float(x), float(y)) for x, y in pts)


def _person(rng, co: Corridor, obstacles, duration: float, earlier: list[Person]) -> Person | None:
    """One random walker, or None where the draw does not fit the scene (the caller draws again)."""
    speed = float(rng.uniform(*PERSON_SPEED))
    delay = float(rng.uniform(0.5, 4.0)) if rng.random() < STANDING_START_PROB else 0.0
    shirt = _color(rng)
    leaders = [q for q in earlier if q.behaviour in ("crossing", "back_and_forth")]
    if leaders and rng.random() < COMPANION_PROB:
        lead = leaders[int(rng.integers(len(leaders)))]
        off = rng.uniform(-0.8, 0.8, 2)
        wps = tuple((x + float(off[0]), y + float(off[1])) for x, y in lead.waypoints)
        if np.linalg.norm(off) < 0.4 or not _path_clear(co, obstacles, wps, False):
            return None
        return Person(behaviour=lead.behaviour, speed=lead.speed, waypoints=wps, color=shirt,
                      start_delay=lead.start_delay + float(rng.uniform(0.3, 1.5)))
    kind = rng.random()
    if kind < 0.7:
        wps = _wander(rng, co, obstacles, speed * duration + 3.0)
        if wps is None:
            return None
        return Person(behaviour="crossing", speed=speed, waypoints=wps, start_delay=delay, color=shirt)
    if kind < 0.85:
        a = _free_point(rng, co, obstacles)
        b = _free_point(rng, co, obstacles)
        if a is None or b is None or np.linalg.norm(b - a) < 2.0 or not _path_clear(co, obstacles, [a, b], False):
            return None
        return Person(behaviour="back_and_forth", speed=speed, start_delay=delay, color=shirt,
                      waypoints=(tuple(map(float, a)), tuple(map(float, b))))
    c = _free_point(rng, co, obstacles)
    r = float(rng.uniform(0.8, 2.0))
    cw = bool(rng.random() < 0.5)
    if c is None:
        return None
    c = (float(c[0]), float(c[1]))
    if not _path_clear(co, obstacles, circle_waypoints(c, r, cw, n=72), True):
        return None
    return Person(behaviour="circle", speed=speed, start_delay=delay, color=shirt, center=c, radius=r, clockwise=cw)


def _people(rng, co: Corridor, obstacles, duration: float) -> tuple[Person, ...]:
    out: list[Person] = []
    for _ in range(int(rng.integers(PEOPLE_COUNT[0], PEOPLE_COUNT[1] + 1))):
        for _attempt in range(20):
            person = _person(rng, co, obstacles, duration, out)
            if person is not None:
                out.append(person)
                break
    if not out:  # always at least one person: a walk with no constraint but the corridor
        wps = _wander(rng, co, (), 40.0)
        out.append(Person(behaviour="crossing", speed=1.0, waypoints=wps, color=_color(rng)))
    return tuple(out)


def _hfov_half(cam: Camera) -> float:
    return math.atan2(max(cam.cx, cam.width - cam.cx), cam.fx)


def _camera_free(co, obstacles, xy, t_people: np.ndarray) -> bool:
    if not _free(co, obstacles, xy, WALL_MARGIN)[0]:
        return False
    return len(t_people) == 0 or bool(np.min(np.linalg.norm(t_people - xy, axis=1)) >= PERSON_MARGIN)


def _light(rng) -> tuple[float, float, float]:
    az = rng.uniform(-math.pi, math.pi)
    el = rng.uniform(*LIGHT_ELEVATION)
    return (math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el))


def _open_ahead(co: Corridor, xy: np.ndarray, yaw: float) -> float:
    """Distance from xy along the heading yaw to the corridor's walls."""
    c, s = math.cos(yaw), math.sin(yaw)
    ts = [math.inf]
    if abs(c) > 1e-9:
        ts.append(((co.length if c > 0 else 0.0) - xy[0]) / c)
    if abs(s) > 1e-9:
        ts.append(((co.width / 2 if s > 0 else -co.width / 2) - xy[1]) / s)
    return min(ts)


def _negative_view(rng, co, obstacles, where: np.ndarray, hfov_half: float):
    """A camera pose from which no person falls within the field of view (plus margins), looking
    at least NEGATIVE_VIEW_DEPTH metres into the corridor (not at a wall filling the image)."""
    for _ in range(300):
        xy = np.array([rng.uniform(0.0, co.length), rng.uniform(-co.width / 2, co.width / 2)])
        if not _camera_free(co, obstacles, xy, where):
            continue
        yaw = rng.uniform(-math.pi, math.pi)
        if _open_ahead(co, xy, yaw) < NEGATIVE_VIEW_DEPTH:
            continue
        d = where - xy
        dist = np.linalg.norm(d, axis=1)
        off = np.abs([wrap_angle(math.atan2(v[1], v[0]) - yaw) for v in d])
        # the tilt can bring a person 15-20 degrees beyond the level field of view; a body is ~0.5 m wide
        if np.all(off > hfov_half + math.radians(20.0) + np.arctan2(0.5, dist)):
            return xy, yaw
    return None


def _focus_view(rng, co, obstacles, where: np.ndarray, headings: list[float], hfov_half: float):
    """A camera pose aimed near one person, at a random distance, from a random side."""
    for _ in range(20):
        j = int(rng.integers(len(where)))
        d = rng.uniform(*FOCUS_DISTANCE)
        for _ in range(60):
            side = headings[j] + rng.uniform(-math.pi, math.pi)  # 0: in front of the person
            xy = where[j] + d * np.array([math.cos(side), math.sin(side)])
            if _camera_free(co, obstacles, xy, where):
                to = where[j] - xy
                yaw = math.atan2(to[1], to[0]) + rng.uniform(-AIM_SPREAD, AIM_SPREAD) * hfov_half
                return xy, yaw
    return None


def _views(rng, scenario: Scenario, paths: list[WalkPath], n: int) -> tuple[View, ...]:
    co, obstacles = scenario.corridor, scenario.obstacles
    hfov_half = _hfov_half(scenario.camera)
    views = []
    for k in range(n):
        t = (k + 1) * IMAGE_PERIOD
        where = np.array([path.position(t) for path in paths])
        headings = [path.heading(t) for path in paths]
        negative = bool(rng.random() < NEGATIVE_PROB)
        pose = _negative_view(rng, co, obstacles, where, hfov_half) if negative else None
        if pose is None:
            negative = False
            pose = _focus_view(rng, co, obstacles, where, headings, hfov_half)
        if pose is None:  # nowhere free near anyone (not seen in practice): anywhere free
            for _ in range(1000):
                xy = np.array([rng.uniform(0.0, co.length), rng.uniform(-co.width / 2, co.width / 2)])
                if _camera_free(co, obstacles, xy, where):
                    pose = (xy, rng.uniform(-math.pi, math.pi))
                    break
            else:
                raise RuntimeError(f"scene seed {scenario.seed}: no free camera position at t = {t}")
        xy, yaw = pose
        z = float(rng.uniform(*CAMERA_HEIGHT))
        roll, pitch = (float(a) for a in rng.uniform(-MAX_TILT, MAX_TILT, 2))
        views.append(View(time=t, position=(float(xy[0]), float(xy[1]), z), yaw=float(wrap_angle(yaw)), pitch=pitch,
                          roll=roll, light=_light(rng), negative=negative))
    return tuple(views)


def build_scene(seed: int, images_per_seed: int) -> Scene:
    """The random scene of one seed and the camera views of its images (no rendering)."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), _SCENE_STREAM]))
    co = Corridor(length=float(rng.uniform(*CORRIDOR_LENGTH)), width=float(rng.uniform(*CORRIDOR_WIDTH)),
                  height=float(rng.uniform(*CORRIDOR_HEIGHT)), ceiling=bool(rng.random() < CEILING_PROB),
                  floor_color=_tinted(rng, 0.2, 0.8, 0.12), wall_color=_tinted(rng, 0.35, 0.95, 0.15))
    duration = images_per_seed * IMAGE_PERIOD + 1.0
    obstacles = _obstacles(rng, co)
    people = _people(rng, co, obstacles, duration)
    base = Scenario(name=f"detector-{seed}", source=f"<detector dataset seed {seed}>", seed=int(seed),
                    duration=duration, corridor=co, obstacles=obstacles, people=people, camera=_CAMERA,
                    noise=Noise(enabled=False), rates=_RATES, segmentation=True)
    # The same paths the World will walk (these behaviours use no random numbers in plan_path).
    paths = [plan_path(p, base, None, duration + 5.0) for p in people]
    views = _views(np.random.default_rng(np.random.SeedSequence([int(seed), _VIEW_STREAM])), base, paths,
                   images_per_seed)
    keyframes = []
    for v in views:
        x, y, z = v.body_position()
        keyframes += [(v.time - _HOLD, x, y, z, v.yaw), (v.time + _HOLD, x, y, z, v.yaw)]
    x, y, z = views[0].body_position()
    scenario = replace(base, camera_path=CameraPath(mode="carried", keyframes=tuple(keyframes)),
                       drone=Drone(start=(x, y, z), goal=(x, y, z), yaw=views[0].yaw))
    return Scene(seed=int(seed), scenario=scenario, views=views)


# --------------------------------------------------------------------------- rendering and boxes


def person_boxes(segmentation: np.ndarray, truth: GroundTruth) -> np.ndarray:
    """(K, 6) float64 rows (x1, y1, x2, y2, distance, visible pixels) for the people that pass
    the rules, in id order. Coordinates are fractions of the segmentation image."""
    H, W = segmentation.shape
    T_camera_world = np.linalg.inv(truth.T_world_camera)
    rows = []
    for o in truth.obstacles:
        if o.kind != "person":
            continue
        mask = segmentation == o.id
        count = int(np.count_nonzero(mask))
        if count < MIN_VISIBLE_PIXELS:
            continue
        r = np.flatnonzero(mask.any(axis=1))
        c = np.flatnonzero(mask.any(axis=0))
        if r[-1] - r[0] + 1 < MIN_BOX_HEIGHT_PX:
            continue
        z = float(T_camera_world[2, :3] @ o.center + T_camera_world[2, 3])
        rows.append([c[0] / W, r[0] / H, (c[-1] + 1) / W, (r[-1] + 1) / H, max(z, MIN_DISTANCE), count])
    return np.array(rows, dtype=np.float64).reshape(-1, 6)


@dataclass(frozen=True)
class Sample:
    color: np.ndarray  # (480, 640, 3) uint8 RGB, full resolution
    segmentation: np.ndarray  # (480, 640) int32 obstacle ids
    boxes: np.ndarray  # (K, 6) see person_boxes
    view: View
    renderer: str


def render_scene(seed: int, images_per_seed: int) -> Iterator[Sample]:
    """Render the images of one scene seed (one World, closed at the end)."""
    from sim.world import World

    scene = build_scene(seed, images_per_seed)
    world = World(scene.scenario, seed=scene.seed, light_direction=scene.views[0].light)
    try:
        for view in scene.views:
            world.T_body_camera = view.T_body_camera()
            world.light_direction = view.light
            frame = None
            while frame is None:
                frame = world.step()
            truth = world.ground_truth()
            if abs(frame.stamp - view.time) > 1e-6 or not np.allclose(truth.T_world_camera, view.T_world_camera(),
                                                                      atol=1e-6):
                raise RuntimeError(f"scene seed {seed}: the World did not pose the camera as asked at t = {view.time} "
                                   "(sim.World's carried camera path or T_body_camera handling changed?)")
            yield Sample(color=frame.color, segmentation=truth.segmentation,
                         boxes=person_boxes(truth.segmentation, truth), view=view, renderer=world.renderer)
    finally:
        world.close()


# --------------------------------------------------------------------------- the data set files


def _seed_list(seeds, name: str) -> list[int]:
    out = []
    for s in seeds:
        if isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 0:
            raise ValueError(f"{name}: seeds must be non-negative integers, got {s!r}")
        out.append(int(s))
    if not out:
        raise ValueError(f"{name}: no seeds given")
    dup = sorted({s for s in out if out.count(s) > 1})
    if dup:
        raise ValueError(f"{name}: repeated seeds {_preview(dup)}")
    return out


def _preview(xs: list[int], n: int = 10) -> str:
    return ", ".join(map(str, xs[:n])) + (f", ... ({len(xs)} in all)" if len(xs) > n else "")


def check_disjoint(train_seeds, val_seeds) -> None:
    """Raise ValueError naming the seeds that the train and validation splits share."""
    common = sorted(set(int(s) for s in train_seeds) & set(int(s) for s in val_seeds))
    if common:
        raise ValueError(f"train and validation seeds overlap: {_preview(common)}; "
                         "the splits must use disjoint scene seeds")


def generate(out_dir: Path, split: str, seeds: range | list[int], images_per_seed: int = 20,
             progress: ProgressFn | None = None) -> Path:
    """Render ``images_per_seed`` images for each scene seed and write ``out_dir/{split}.npz``.

    Arrays: images (N, 256, 352, 3) uint8 RGB; boxes (M, 7) float32 rows (image index, x1, y1,
    x2, y2 as fractions of the image, distance m, visible pixels); seeds (N,) int32; meta, a JSON
    string. ``progress(done, total)`` is called after every image. Returns the file's path.
    """
    if not isinstance(split, str) or not re.fullmatch(r"[A-Za-z0-9_.-]+", split):
        raise ValueError(f"split: expected a name of letters, digits, '_', '.' or '-', got {split!r}")
    if isinstance(images_per_seed, bool) or not isinstance(images_per_seed, (int, np.integer)) or images_per_seed < 1:
        raise ValueError(f"images_per_seed: expected a positive integer, got {images_per_seed!r}")
    seed_list = _seed_list(seeds, "seeds")
    images_per_seed = int(images_per_seed)
    total = len(seed_list) * images_per_seed
    images = np.empty((total, INPUT_H, INPUT_W, 3), dtype=np.uint8)
    image_seeds = np.repeat(np.array(seed_list, dtype=np.int32), images_per_seed)
    boxes: list[np.ndarray] = []
    renderers: set[str] = set()
    posed_negative = 0
    i = 0
    for seed in seed_list:
        for sample in render_scene(seed, images_per_seed):
            images[i] = resize_for_network(sample.color)
            if len(sample.boxes):
                boxes.append(np.hstack([np.full((len(sample.boxes), 1), i, dtype=np.float64), sample.boxes]))
            renderers.add(sample.renderer)
            posed_negative += sample.view.negative
            i += 1
            if progress is not None:
                progress(i, total)
    box_array = (np.vstack(boxes) if boxes else np.zeros((0, 7))).astype(np.float32)
    with_boxes = np.unique(box_array[:, 0].astype(np.int64)) if len(box_array) else np.zeros(0, np.int64)
    dist = box_array[:, 5]
    meta = {
        "generator": "experiments.detector.dataset", "version": GENERATOR_VERSION, "split": split,
        "seeds": seed_list, "images_per_seed": images_per_seed,
        "render_size": [_CAMERA.width, _CAMERA.height], "image_size": [INPUT_W, INPUT_H],
        "renderers": sorted(renderers),
        "counts": {"images": total, "boxes": int(len(box_array)), "boxes_within_10m": int(np.sum(dist <= 10.0)),
                   "negatives": int(total - len(with_boxes)), "posed_negative": int(posed_negative)},
        "rules": _rules(), "scenes": _scene_ranges(),
    }
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"{split}.npz"
    tmp = out_dir / f".{split}.npz.partial"
    with open(tmp, "wb") as f:
        np.savez(f, images=images, boxes=box_array, seeds=image_seeds,
                 meta=np.array(json.dumps(meta, sort_keys=True)))
    os.replace(tmp, path)
    return path


def load(path: Path) -> dict:
    """The arrays of a generated file, with meta decoded."""
    with np.load(Path(path)) as z:
        out = {k: z[k] for k in ("images", "boxes", "seeds")}
        out["meta"] = json.loads(str(z["meta"]))
    return out
