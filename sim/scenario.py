"""Declarative scenarios: TOML files validated on load into frozen dataclasses.

Every user mistake (unknown key, wrong type, value out of range, a person walking out
of the corridor or starting inside an obstacle) raises ``ScenarioError`` with one
message that names the file, the key and the reason. The format is documented in the
README ("Scenario format").
"""
from __future__ import annotations

import copy
import math
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

SCENARIO_DIR = Path(__file__).resolve().parent / "scenarios"

OBSTACLE_KINDS = ("box", "pillar", "shelf", "wall")
BEHAVIOURS = ("waypoint_loop", "back_and_forth", "crossing", "random_walk", "circle")
PERSON_SPEED_RANGE = (0.5, 1.6)  # m/s, the walking-speed band
PERSON_HEIGHT_RANGE = (1.6, 1.85)  # m
PERSON_RADIUS = 0.25  # m, footprint half-width used for the corridor and obstacle checks

# Bounds on what a scenario may ask of the machine (README, "Scenario format", bounds). Beyond them a run
# would not fit in memory or time (a waypoint 1e8 m away: a path sampled every 5 cm; 1,000 people: minutes
# before the first frame), so they are refused on load like any other mistake.
MAX_FILE_BYTES = 1 << 20  # a scenario file: 1 MiB
MAX_DURATION = 3600.0  # s, duration, start_delay and keyframe times
MAX_COORDINATE = 1000.0  # m, |x|, |y|, |z| of every position given (the corridor itself is at most 200 m long)
MAX_OBSTACLE_SIZE = 200.0  # m, each dimension of an obstacle
MAX_MOUNT_OFFSET = 1.0  # m, |x|, |y|, |z| of the camera in the body frame
MAX_ANGLE_DEG = 360.0  # |angle| in degrees
MAX_OBSTACLES = 200
MAX_PEOPLE = 100
MAX_POINTS = 100  # waypoints of a person, keyframes of a camera path
MAX_CHOICES = 100  # values of one {choice = [...]}
MAX_NAME_CHARS = 200
SEED_MAX = 2**63 - 1  # the largest TOML integer


class ScenarioError(ValueError):
    """A scenario file is wrong: the message names the file, the key and the reason."""


def _finite(x: Any) -> bool:
    """A number (not a boolean) that is finite as a float (an integer too large for one is not)."""
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return False
    try:
        return math.isfinite(x)
    except OverflowError:
        return False


def _short(v: Any, limit: int = 80) -> str:
    """repr(v) cut to ``limit`` characters: a message quotes what it refuses, on one line of bounded length."""
    r = repr(v)
    return r if len(r) <= limit else r[:limit] + "..."


# --------------------------------------------------------------------------- dataclasses


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


@dataclass(frozen=True)
class Scenario:
    name: str
    source: str  # file the scenario came from
    seed: int = 0
    duration: float = 20.0  # s
    description: str = ""
    corridor: Corridor = field(default_factory=Corridor)
    obstacles: tuple[Obstacle, ...] = ()
    people: tuple[Person, ...] = ()
    drone: Drone = field(default_factory=Drone)
    camera: Camera = field(default_factory=Camera)
    noise: Noise = field(default_factory=Noise)
    rates: Rates = field(default_factory=Rates)
    camera_path: CameraPath | None = None
    segmentation: bool = True  # render the ground-truth segmentation image every frame
    crowd: Crowd = field(default_factory=Crowd)
    # the file's tables as read (ranges included): for_seed draws them again, with_values changes them
    tables: dict | None = field(default=None, compare=False, repr=False)
    drawn_seed: int | None = field(default=None, compare=False)  # the seed its ranges were drawn for

    @property
    def randomized(self) -> bool:
        """Whether some of its values are ranges, drawn anew for each seed."""
        return self.tables is not None and _has_ranges(self.tables)

    def for_seed(self, seed: int) -> "Scenario":
        """The scenario with its ranges drawn for ``seed`` (itself when it has none, or when they were
        drawn for that seed)."""
        if not self.randomized or int(seed) == self.drawn_seed:
            return self
        if _from_tables(self.tables, self.source, self.drawn_seed) != self:
            raise ScenarioError(f"{self.source}: this scenario's values are drawn by the seed, and some were changed "
                                f"after it was read (dataclasses.replace?): another seed's draw would lose them; "
                                f"change it with Scenario.with_values instead")
        return _from_tables(self.tables, self.source, int(seed))

    def with_values(self, values: dict[str, Any]) -> "Scenario":
        """The scenario with the given keys set, as if the file said so: {"crowd.sees_drone": True,
        "duration": 30.0}. Keys are dotted paths of the file's tables; arrays of tables take an index
        ("people.0.speed"). Checked like the file (ScenarioError naming the key)."""
        if self.tables is None:
            raise ScenarioError(f"{self.source}: this scenario was not read from a file; its values cannot be set")
        tables = copy.deepcopy(self.tables)
        for key, value in values.items():
            node, parts = tables, key.split(".")
            for i, part in enumerate(parts[:-1]):
                if isinstance(node, list):
                    if not part.isdigit() or int(part) >= len(node):
                        raise ScenarioError(f"{self.source}: {key}: {'.'.join(parts[:i])} has no item {_short(part)}")
                    node = node[int(part)]
                else:
                    node = node.setdefault(part, {})
                if not isinstance(node, (dict, list)):
                    raise ScenarioError(f"{self.source}: {key}: {'.'.join(parts[:i + 1])} is a value, not a table")
            if isinstance(node, list):
                raise ScenarioError(f"{self.source}: {key}: give an index into {'.'.join(parts[:-1])}")
            node[parts[-1]] = value
        return _from_tables(tables, self.source, None)


# --------------------------------------------------------------------------- reading


class _Section:
    """Reads one TOML table, remembering which keys were used, naming errors by path."""

    def __init__(self, data: Any, path: str, source: str):
        self.source = source
        self.path = path
        if not isinstance(data, dict):
            self.fail(path, f"expected a table, got {type(data).__name__}")
        self.data = data
        self.used: set[str] = set()

    def key(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name

    def fail(self, key: str, reason: str):
        raise ScenarioError(f"{self.source}: {key or '<top level>'}: {reason}")

    def has(self, name: str) -> bool:
        return name in self.data

    def raw(self, name: str, default: Any = None) -> Any:
        self.used.add(name)
        return self.data.get(name, default)

    def number(self, name, default=None, lo=None, hi=None, lo_open=False, integer=False):
        if name not in self.data:
            if default is None:
                self.fail(self.key(name), "is required")
            self.used.add(name)
            return default
        v = self.raw(name)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.fail(self.key(name), f"expected a number, got {_short(v)}")
        if integer and not isinstance(v, int):
            self.fail(self.key(name), f"expected an integer, got {_short(v)}")
        if not integer and not _finite(v):
            self.fail(self.key(name), f"must be finite, got {_short(v)}")
        if lo is not None and (v <= lo if lo_open else v < lo):
            self.fail(self.key(name), f"must be {'>' if lo_open else '>='} {lo}, got {_short(v)}")
        if hi is not None and v > hi:
            self.fail(self.key(name), f"must be <= {hi}, got {_short(v)}")
        return int(v) if integer else float(v)

    def boolean(self, name, default):
        v = self.raw(name, default)
        if not isinstance(v, bool):
            self.fail(self.key(name), f"expected true or false, got {_short(v)}")
        return v

    def string(self, name, default=None, choices=None):
        v = self.raw(name, default)
        if v is None:
            self.fail(self.key(name), "is required")
        if not isinstance(v, str):
            self.fail(self.key(name), f"expected a string, got {_short(v)}")
        if choices is not None and v not in choices:
            self.fail(self.key(name), f"must be one of {', '.join(choices)}; got {_short(v)}")
        return v

    def vector(self, name, n, default=None, required=False, bound=MAX_COORDINATE, what="coordinates"):
        """A list of n finite numbers, each within +-bound (``what`` names them in the message)."""
        if name not in self.data:
            if required:
                self.fail(self.key(name), "is required")
            self.used.add(name)
            return default
        v = self.raw(name)
        if not isinstance(v, list) or len(v) != n:
            self.fail(self.key(name), f"expected a list of {n} numbers, got {_short(v)}")
        out = []
        for x in v:
            if not _finite(x):
                self.fail(self.key(name), f"expected a list of {n} finite numbers, got {_short(v)}")
            if abs(x) > bound:
                self.fail(self.key(name), f"{what} must lie within +-{bound:g}, got {_short(v)}")
            out.append(float(x))
        return tuple(out)

    def points(self, name, n, min_count=1, names=("x", "y"), bounds=None):
        """A list of at least min_count and at most MAX_POINTS points of n finite numbers; bounds: the
        largest |value| of each field (default: MAX_COORDINATE for all)."""
        v = self.raw(name, [])
        if not isinstance(v, list) or len(v) < min_count:
            self.fail(self.key(name), f"expected a list of at least {min_count} points [{', '.join(names)}]")
        if len(v) > MAX_POINTS:
            self.fail(self.key(name), f"at most {MAX_POINTS} points, got {len(v)}")
        bounds = bounds or (MAX_COORDINATE,) * n
        out = []
        for i, p in enumerate(v):
            if (not isinstance(p, list) or len(p) != n
                    or any(not _finite(x) for x in p)):
                self.fail(f"{self.key(name)}[{i}]", f"expected {n} finite numbers, got {_short(p)}")
            for field_name, x, b in zip(names, p, bounds):
                if abs(x) > b:
                    self.fail(f"{self.key(name)}[{i}]", f"{field_name} must lie within +-{b:g}, got {_short(x)}")
            out.append(tuple(float(x) for x in p))
        return tuple(out)

    def color(self, name):
        c = self.vector(name, 3, bound=math.inf)
        if c is not None and any(not 0.0 <= x <= 1.0 for x in c):
            self.fail(self.key(name), f"color components must lie in [0, 1], got {list(c)}")
        return c

    def sub(self, name) -> "_Section":
        self.used.add(name)
        return _Section(self.data.get(name, {}), self.key(name), self.source)

    def done(self):
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            self.fail(self.key(unknown[0]), "unknown key" + (f" (also unknown: {', '.join(unknown[1:])})" if len(unknown) > 1 else ""))


def scenario_path(name_or_path: str | Path) -> Path:
    """A path as given, or the name of a shipped scenario (``corridor`` or ``corridor.toml``)."""
    p = Path(name_or_path)
    if p.exists():
        return p
    shipped = SCENARIO_DIR / (p.name if p.suffix == ".toml" else p.name + ".toml")
    if p.parent == Path(".") and shipped.exists():
        return shipped
    names = ", ".join(sorted(s.stem for s in SCENARIO_DIR.glob("*.toml")))
    raise ScenarioError(f"{name_or_path}: no such file, and not a shipped scenario (shipped: {names})")


def shipped_scenarios() -> list[str]:
    return sorted(s.stem for s in SCENARIO_DIR.glob("*.toml"))


def load_scenario(name_or_path: str | Path, seed: int | None = None) -> Scenario:
    """Read and validate a scenario file (or a shipped scenario by name). Values given as ranges
    are drawn for ``seed`` (default: the file's own seed); ``Scenario.for_seed`` draws another."""
    path = scenario_path(name_or_path)
    try:
        with open(path, "rb") as fh:
            data = fh.read(MAX_FILE_BYTES + 1)  # no more, whatever the path is (/dev/zero)
        if len(data) > MAX_FILE_BYTES:
            raise ScenarioError(f"{path}: more than {MAX_FILE_BYTES} bytes; a scenario file holds at most "
                                f"{MAX_FILE_BYTES} (1 MiB)")
        text = data.decode("utf-8-sig")  # a byte-order mark, as some editors write, is no error
    except OSError as e:
        raise ScenarioError(f"{path}: cannot read: {e.strerror}") from None
    except UnicodeDecodeError as e:
        raise ScenarioError(f"{path}: not a UTF-8 text file (byte {e.start}: {e.reason})") from None
    return parse_scenario(text, source=str(path), seed=seed)


def parse_scenario(text: str, source: str = "<string>", seed: int | None = None) -> Scenario:
    if len(text) > MAX_FILE_BYTES:
        raise ScenarioError(f"{source}: {len(text)} characters; a scenario holds at most {MAX_FILE_BYTES}")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(f"{source}: not valid TOML: {e}") from None
    except RecursionError:
        raise ScenarioError(f"{source}: not valid TOML: arrays or tables nested too deeply") from None
    try:
        return _from_tables(data, source, seed)
    except RecursionError:
        raise ScenarioError(f"{source}: arrays or tables nested too deeply") from None


# --------------------------------------------------------------------------- ranges drawn by the seed
#
# Any number in a scenario may be written as a range, drawn anew for every seed:
#   speed = {uniform = [0.5, 1.6]}          a float drawn uniformly in [lo, hi]
#   start_delay = {choice = [0.0, 2.0, 4.0]}  one of the listed values (numbers, strings or booleans)
# or follow another value of the same draw, times a factor plus an offset (both optional):
#   x = {same_as = "obstacles.0.center.0", times = 1.0, plus = 0.7}
# Draws follow the file's order from a generator seeded by the episode's seed, so a seed always gives
# the same scenario. A draw whose geometry fails the checks (a person starting inside an obstacle, ...)
# is drawn again, up to _MAX_DRAWS times.

_RANGE_KINDS = ("uniform", "choice", "same_as")
_MAX_DRAWS = 100


def _range_of(v: Any) -> str | None:
    if not isinstance(v, dict) or not v:
        return None
    if "same_as" in v and set(v) <= {"same_as", "times", "plus"}:
        return "same_as"
    return next(iter(v)) if len(v) == 1 and next(iter(v)) in ("uniform", "choice") else None


def _lookup(tables: Any, path: str) -> Any:
    node = tables
    for part in path.split("."):
        if isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        elif isinstance(node, dict) and part in node:
            node = node[part]
        else:
            return None
    return node


def _follow(tables: Any, drawn: Any, source: str, key: str = "") -> Any:
    """Replace every {same_as = ...} by the value it names in ``drawn``, times and plus applied."""
    if _range_of(tables) == "same_as":
        v = _lookup(drawn, tables["same_as"])
        if not _finite(v):
            raise ScenarioError(f"{source}: {key}: same_as {_short(tables['same_as'])} does not name a number of the "
                                f"scenario (got {_short(v)})")
        return v * tables.get("times", 1.0) + tables.get("plus", 0.0)
    if isinstance(tables, dict):
        return {k: _follow(x, drawn, source, f"{key}.{k}" if key else k) for k, x in tables.items()}
    if isinstance(tables, list):
        return [_follow(x, drawn, source, f"{key}[{i}]") for i, x in enumerate(tables)]
    return tables


def _has_ranges(v: Any) -> bool:
    if _range_of(v):
        return True
    if isinstance(v, dict):
        return any(_has_ranges(x) for x in v.values())
    if isinstance(v, list):
        return any(_has_ranges(x) for x in v)
    return False


def _check_ranges(v: Any, source: str, key: str = "") -> None:
    """Every range table well formed: uniform = [lo, hi] finite with lo <= hi; choice = a non-empty list."""
    kind = _range_of(v)
    if kind == "uniform":
        r = v[kind]
        if (not isinstance(r, list) or len(r) != 2
                or any(not _finite(x) for x in r)):
            raise ScenarioError(f"{source}: {key}: expected {{uniform = [lo, hi]}} with two finite numbers, got {_short(r)}")
        if r[0] > r[1]:
            raise ScenarioError(f"{source}: {key}: uniform range [{r[0]}, {r[1]}] has lo > hi")
    elif kind == "choice":
        r = v[kind]
        if not isinstance(r, list) or not r or any(isinstance(x, (dict, list)) for x in r):
            raise ScenarioError(f"{source}: {key}: expected {{choice = [a, b, ...]}} with at least one plain value, "
                                f"got {_short(r)}")
        if len(r) > MAX_CHOICES:
            raise ScenarioError(f"{source}: {key}: at most {MAX_CHOICES} values to choose from, got {len(r)}")
    elif kind == "same_as":
        if not isinstance(v["same_as"], str):
            raise ScenarioError(f"{source}: {key}: same_as must name a value, as \"obstacles.0.center.0\"")
        for k in ("times", "plus"):
            x = v.get(k, 0.0)
            if not _finite(x):
                raise ScenarioError(f"{source}: {key}.{k}: expected a finite number, got {_short(x)}")
    elif isinstance(v, dict):
        for k, x in v.items():
            _check_ranges(x, source, f"{key}.{k}" if key else k)
    elif isinstance(v, list):
        for i, x in enumerate(v):
            _check_ranges(x, source, f"{key}[{i}]")


def _longest_choice(v: Any) -> int:
    if _range_of(v) == "choice":
        return len(v["choice"])
    if isinstance(v, dict):
        return max((_longest_choice(x) for x in v.values()), default=0)
    if isinstance(v, list):
        return max((_longest_choice(x) for x in v), default=0)
    return 0


def _draw(v: Any, pick, source: str = "", root: Any = None) -> Any:
    """The tables with every range replaced by pick(kind, values), then every same_as by what it names."""
    if root is None:
        drawn = _draw(v, pick, source, v)
        return _follow(drawn, drawn, source)
    kind = _range_of(v)
    if kind == "same_as":
        return v  # resolved once everything is drawn
    if kind:
        return pick(kind, v[kind])
    if isinstance(v, dict):
        return {k: _draw(x, pick, source, root) for k, x in v.items()}
    if isinstance(v, list):
        return [_draw(x, pick, source, root) for x in v]
    return v


def _from_tables(data: dict, source: str, seed: int | None) -> Scenario:
    if not _has_ranges(data):
        return replace(_build(data, source), tables=data)
    _check_ranges(data, source)
    # Every value a range can give must pass the checks of its key: build with the ranges at both ends
    # of every uniform range and at every value of every choice.
    for i in range(max(2, _longest_choice(data))):
        try:
            _build(_draw(data, lambda kind, r, i=i: r[i % 2] if kind == "uniform" else r[min(i, len(r) - 1)],
                         source), source, geometry=False)
        except ScenarioError as e:
            raise ScenarioError(f"{e} (a value one of the scenario's ranges can take)") from None
    if seed is None:
        seed = data.get("seed", 0)
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            seed = 0  # _build below reports the bad seed by name
    rng = np.random.default_rng([int(seed), 0x5CE4A])

    def pick(kind, r):
        if kind == "uniform":
            if r[0] < r[1]:
                return float(rng.uniform(r[0], r[1]))
            rng.random()  # lo == hi (numpy refuses uniform(0.0, -0.0)): the same draws follow as from uniform
            return float(r[0])
        return r[int(rng.integers(len(r)))]

    error = None
    for _ in range(_MAX_DRAWS):
        try:
            sc = _build(_draw(data, pick, source), source)
        except ScenarioError as e:
            error = e
            continue
        return replace(sc, tables=data, drawn_seed=int(seed))
    raise ScenarioError(f"{error} (seed {seed}: no draw of the scenario's ranges passed the checks in {_MAX_DRAWS} tries)")


def _build(data: dict, source: str, geometry: bool = True) -> Scenario:
    top = _Section(data, "", source)
    name = top.string("name", Path(source).stem)
    if not name or len(name) > MAX_NAME_CHARS or not name.isprintable():
        top.fail("name", f"expected 1 to {MAX_NAME_CHARS} printable characters on one line, got {_short(name)}")
    seed = top.number("seed", 0, lo=0, hi=SEED_MAX, integer=True)
    duration = top.number("duration", 20.0, lo=0.0, lo_open=True, hi=MAX_DURATION)
    description = top.string("description", "")
    segmentation = top.boolean("segmentation", True)

    corridor = _read_corridor(top.sub("corridor"))
    obstacles = tuple(_read_obstacle(s) for s in _array_of_tables(top, "obstacles", MAX_OBSTACLES))
    people = tuple(_read_person(s) for s in _array_of_tables(top, "people", MAX_PEOPLE))
    drone = _read_drone(top.sub("drone"))
    camera = _read_camera(top.sub("camera"))
    noise = _read_noise(top.sub("noise"))
    rates = _read_rates(top.sub("rates"))
    crowd = _read_crowd(top.sub("crowd"))
    camera_path = _read_camera_path(top.sub("camera_path")) if top.has("camera_path") else None
    top.done()

    sc = Scenario(name=name, source=source, seed=seed, duration=duration, description=description,
                  corridor=corridor, obstacles=obstacles, people=people, drone=drone, camera=camera,
                  noise=noise, rates=rates, camera_path=camera_path, segmentation=segmentation, crowd=crowd)
    if geometry:
        _check_geometry(sc, top)
    return sc


def _array_of_tables(top: _Section, name: str, most: int) -> list[_Section]:
    v = top.raw(name, [])
    if not isinstance(v, list):
        top.fail(name, "expected an array of tables ([[%s]])" % name)
    if len(v) > most:
        top.fail(name, f"at most {most} {name}, got {len(v)}")
    return [_Section(item, f"{name}[{i}]", top.source) for i, item in enumerate(v)]


def _read_corridor(s: _Section) -> Corridor:
    c = Corridor(length=s.number("length", 15.0, lo=2.0, hi=200.0),
                 width=s.number("width", 4.0, lo=1.0, hi=50.0),
                 height=s.number("height", 3.0, lo=1.0, hi=20.0),
                 ceiling=s.boolean("ceiling", False))
    s.done()
    return c


def _read_obstacle(s: _Section) -> Obstacle:
    kind = s.string("kind", choices=OBSTACLE_KINDS)
    center = s.vector("center", 2, required=True)
    if kind == "pillar":
        r = s.number("radius", lo=0.02, hi=5.0)
        h = s.number("height", lo=0.05, hi=20.0)
        size = (2 * r, 2 * r, h)
    else:
        size = s.vector("size", 3, required=True, bound=MAX_OBSTACLE_SIZE, what="dimensions")
        if any(x <= 0 for x in size):
            s.fail(s.key("size"), f"every dimension must be > 0, got {list(size)}")
    yaw = math.radians(s.number("yaw_deg", 0.0, lo=-360.0, hi=360.0))
    o = Obstacle(kind=kind, center=center, size=size, yaw=yaw, color=s.color("color"))
    s.done()
    return o


def _read_person(s: _Section) -> Person:
    b = s.string("behaviour", choices=BEHAVIOURS)
    speed = s.number("speed", lo=PERSON_SPEED_RANGE[0], hi=PERSON_SPEED_RANGE[1])
    height = s.number("height", 0.0) if s.has("height") else None
    if height is not None and not PERSON_HEIGHT_RANGE[0] <= height <= PERSON_HEIGHT_RANGE[1]:
        s.fail(s.key("height"), f"must lie in [{PERSON_HEIGHT_RANGE[0]}, {PERSON_HEIGHT_RANGE[1]}] m, got {height}")
    kw: dict[str, Any] = dict(behaviour=b, speed=speed, height=height,
                              start_delay=s.number("start_delay", 0.0, lo=0.0, hi=MAX_DURATION),
                              color=s.color("color"))
    if b in ("waypoint_loop", "back_and_forth", "crossing"):
        kw["waypoints"] = s.points("waypoints", 2, min_count=2)
        for i in range(len(kw["waypoints"]) - 1):
            if math.dist(kw["waypoints"][i], kw["waypoints"][i + 1]) < 1e-6:
                s.fail(f"{s.key('waypoints')}[{i + 1}]", "repeats the previous waypoint")
    elif b == "random_walk":
        region = s.vector("region", 4, required=True)
        if region[2] - region[0] < 0.1 or region[3] - region[1] < 0.1:
            s.fail(s.key("region"), f"expected [x_min, y_min, x_max, y_max] with max > min, got {list(region)}")
        kw["region"] = region
        kw["start"] = s.vector("start", 2)
    elif b == "circle":
        kw["center"] = s.vector("center", 2, required=True)
        kw["radius"] = s.number("radius", lo=0.3, hi=20.0)
        kw["clockwise"] = s.boolean("clockwise", False)
    if s.has("sees_drone"):
        kw["sees_drone"] = s.boolean("sees_drone", False)
    s.done()
    return Person(**kw)


def _read_crowd(s: _Section) -> Crowd:
    d = Crowd()
    c = Crowd(sees_drone=s.boolean("sees_drone", d.sees_drone),
              relaxation_time=s.number("relaxation_time", d.relaxation_time, lo=0.05, hi=10.0),
              strength=s.number("strength", d.strength, lo=0.0, hi=100.0),
              range=s.number("range", d.range, lo=0.01, hi=5.0),
              step_time=s.number("step_time", d.step_time, lo=0.0, hi=10.0),
              view_angle=math.radians(s.number("view_angle_deg", math.degrees(d.view_angle), lo=0.0, hi=180.0)),
              behind_weight=s.number("behind_weight", d.behind_weight, lo=0.0, hi=1.0),
              max_speed_factor=s.number("max_speed_factor", d.max_speed_factor, lo=1.0, hi=3.0))
    s.done()
    return c


def _read_drone(s: _Section) -> Drone:
    d = Drone(start=s.vector("start", 3, Drone.start), goal=s.vector("goal", 3, Drone.goal),
              yaw=math.radians(s.number("yaw_deg", 0.0, lo=-360.0, hi=360.0)),
              cruise_speed=s.number("cruise_speed", 1.0, lo=0.0, lo_open=True, hi=5.0))
    s.done()
    return d


def _read_camera(s: _Section) -> Camera:
    w = s.number("width", 640, lo=16, hi=4096, integer=True)
    h = s.number("height", 480, lo=16, hi=4096, integer=True)
    c = Camera(width=w, height=h,
               fx=s.number("fx", Camera.fx, lo=1.0, hi=1e5), fy=s.number("fy", Camera.fy, lo=1.0, hi=1e5),
               cx=s.number("cx", Camera.cx * w / 640, lo=0.0, hi=float(w)),
               cy=s.number("cy", Camera.cy * h / 480, lo=0.0, hi=float(h)),
               min_range=s.number("min_range", Camera.min_range, lo=0.15, hi=5.0),  # >= the near plane
               max_range=s.number("max_range", Camera.max_range, lo=0.5, hi=100.0),
               mount_xyz=s.vector("mount_xyz", 3, Camera.mount_xyz, bound=MAX_MOUNT_OFFSET, what="offsets [m]"),
               mount_rpy=tuple(math.radians(a) for a in s.vector("mount_rpy_deg", 3, (0.0, 0.0, 0.0),
                                                                 bound=MAX_ANGLE_DEG, what="angles [deg]")),
               color=s.boolean("color", True),
               renderer=s.string("renderer", "auto", choices=RENDERER_CHOICES))
    if c.max_range <= c.min_range:
        s.fail(s.key("max_range"), f"must exceed min_range ({c.min_range}), got {c.max_range}")
    s.done()
    return c


def _read_noise(s: _Section) -> Noise:
    n = Noise(enabled=s.boolean("enabled", True),
              axial_model=s.string("axial_model", Noise.axial_model, choices=("intel_rms", "nguyen", "none")),
              baseline=s.number("baseline", Noise.baseline, lo=0.0, lo_open=True, hi=1.0),
              subpixel=s.number("subpixel", Noise.subpixel, lo=0.0, hi=2.0),
              edge_threshold=s.number("edge_threshold", Noise.edge_threshold, lo=0.0, lo_open=True, hi=10.0),
              edge_hole_prob=s.number("edge_hole_prob", Noise.edge_hole_prob, lo=0.0, hi=1.0),
              flying_pixel_prob=s.number("flying_pixel_prob", Noise.flying_pixel_prob, lo=0.0, hi=1.0),
              dropout=s.number("dropout", Noise.dropout, lo=0.0, hi=1.0),
              odom_position_std=s.number("odom_position_std", 0.0, lo=0.0, hi=1.0),
              odom_rotation_std=s.number("odom_rotation_std", 0.0, lo=0.0, hi=0.5))
    if n.edge_hole_prob + n.flying_pixel_prob > 1.0:
        s.fail(s.key("flying_pixel_prob"), "edge_hole_prob + flying_pixel_prob must not exceed 1")
    s.done()
    return n


def _read_rates(s: _Section) -> Rates:
    r = Rates(physics=s.number("physics", 240, lo=60, hi=2000, integer=True),
              control=s.number("control", 120, lo=100, hi=2000, integer=True),
              camera=s.number("camera", 30, lo=1, hi=120, integer=True))
    if r.physics % r.control:
        s.fail(s.key("control"), f"physics rate {r.physics} Hz must be a multiple of the control rate {r.control} Hz")
    if r.control % r.camera:
        s.fail(s.key("camera"), f"control rate {r.control} Hz must be a multiple of the camera rate {r.camera} Hz "
               "(frames are captured at control-period boundaries)")
    s.done()
    return r


def _read_camera_path(s: _Section) -> CameraPath:
    mode = s.string("mode", "carried", choices=("carried", "flown"))
    has_kf, has_follow = s.has("keyframes"), s.has("follow_person")
    if has_kf == has_follow:
        s.fail(s.path, "give exactly one of keyframes or follow_person")
    kw: dict[str, Any] = dict(mode=mode)
    if has_kf:
        kf = s.points("keyframes", 5, min_count=1, names=("t", "x", "y", "z", "yaw_deg"),
                      bounds=(MAX_DURATION, MAX_COORDINATE, MAX_COORDINATE, MAX_COORDINATE, MAX_ANGLE_DEG))
        for i in range(1, len(kf)):
            if kf[i][0] <= kf[i - 1][0]:
                s.fail(f"{s.key('keyframes')}[{i}]", "times must increase")
        kw["keyframes"] = tuple((t, x, y, z, math.radians(yaw)) for t, x, y, z, yaw in kf)
    else:
        kw["follow_person"] = s.number("follow_person", lo=0, integer=True)
        kw["follow_distance"] = s.number("follow_distance", 2.5, lo=0.5, hi=10.0)
        kw["follow_height"] = s.number("follow_height", 1.3, lo=0.3, hi=5.0)
    cp = CameraPath(**kw)
    s.done()
    return cp


# --------------------------------------------------------------------------- geometry checks


def _inside_corridor(c: Corridor, xy: np.ndarray, margin: float) -> np.ndarray:
    xy = np.atleast_2d(xy)
    return ((xy[:, 0] >= margin) & (xy[:, 0] <= c.length - margin)
            & (np.abs(xy[:, 1]) <= c.width / 2 - margin))


def _sample_segments(points: np.ndarray, closed: bool, step: float = 0.05) -> np.ndarray:
    pts = np.asarray(points, dtype=float)
    if closed:
        pts = np.vstack([pts, pts[:1]])
    out = [pts[:1]]
    for a, b in zip(pts[:-1], pts[1:]):
        n = max(2, int(math.ceil(np.linalg.norm(b - a) / step)) + 1)
        out.append(a + np.linspace(0, 1, n)[1:, None] * (b - a))
    return np.vstack(out)


def circle_waypoints(center, radius, clockwise=False, n=24) -> tuple[tuple[float, float], ...]:
    a = np.linspace(0, 2 * np.pi, n, endpoint=False) * (-1 if clockwise else 1)
    return tuple((center[0] + radius * math.cos(t), center[1] + radius * math.sin(t)) for t in a)


def _near_box(o: Obstacle, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """An axis-aligned (x, y) box holding the footprint grown by ``margin`` (a rotated box grows its
    corners by up to margin * sqrt(2) along the axes)."""
    lo, hi = o.aabb()
    g = margin * 1.5 + 1e-9
    return lo[:2] - g, hi[:2] + g


def _first_hit(obstacles, points: np.ndarray, margin: float) -> tuple[int, int] | None:
    """(j, i): the first obstacle, in order, whose footprint grown by margin holds one of the (N, 2) points,
    and the first such point; None when there is none. Each obstacle is tested only against the points
    in its box (points sorted by x, its range found by bisection): a path of many points past many
    obstacles costs about what its points near obstacles cost."""
    if not obstacles or not len(points):
        return None
    order = np.argsort(points[:, 0], kind="stable")
    xs = points[order, 0]
    for j, o in enumerate(obstacles):
        lo, hi = _near_box(o, margin)
        near = order[np.searchsorted(xs, lo[0], "left"):np.searchsorted(xs, hi[0], "right")]
        near = near[(points[near, 1] >= lo[1]) & (points[near, 1] <= hi[1])]
        hit = near[o.footprint_contains(points[near], margin)] if len(near) else near
        if len(hit):
            return j, int(hit.min())
    return None


def _region_covered(obstacles, region, margin: float, most: int = 256) -> bool:
    """Whether the obstacles' footprints grown by margin cover every point of a grid over the region
    [x0, y0, x1, y1]: every 0.1 m, or coarser on a side longer than ``most`` points (25.6 m). Each
    obstacle is tested against the grid points in its box only."""
    x0, y0, x1, y1 = region
    xs = np.arange(x0, x1 + 1e-9, max(0.1, (x1 - x0) / most))
    ys = np.arange(y0, y1 + 1e-9, max(0.1, (y1 - y0) / most))
    covered = np.zeros((len(ys), len(xs)), bool)
    for o in obstacles:
        lo, hi = _near_box(o, margin)
        ix = slice(np.searchsorted(xs, lo[0], "left"), np.searchsorted(xs, hi[0], "right"))
        iy = slice(np.searchsorted(ys, lo[1], "left"), np.searchsorted(ys, hi[1], "right"))
        gx, gy = np.meshgrid(xs[ix], ys[iy])
        if gx.size:
            inside = o.footprint_contains(np.stack([gx.ravel(), gy.ravel()], axis=1), margin)
            covered[iy, ix] |= inside.reshape(gx.shape)
    return bool(covered.all())


def _check_geometry(sc: Scenario, top: _Section) -> None:
    c = sc.corridor
    for i, o in enumerate(sc.obstacles):
        lo, hi = o.aabb()
        if lo[0] < 0 or hi[0] > c.length or lo[1] < -c.width / 2 or hi[1] > c.width / 2:
            top.fail(f"obstacles[{i}].center", f"the {o.kind} at {list(o.center)} sticks out of the corridor")
        if hi[2] > c.height + 1e-9 and c.ceiling:
            top.fail(f"obstacles[{i}].size", f"taller than the corridor ({c.height} m)")

    def in_obstacle(xy, margin):
        for j, o in enumerate(sc.obstacles):
            if np.any(o.footprint_contains(xy, margin)):
                return j
        return None

    for i, p in enumerate(sc.people):
        key = f"people[{i}]"
        if p.behaviour == "random_walk":
            x0, y0, x1, y1 = p.region
            corners = np.array([[x0, y0], [x1, y1]])
            if not np.all(_inside_corridor(c, corners, PERSON_RADIUS)):
                top.fail(f"{key}.region", f"region {list(p.region)} leaves the corridor "
                         f"(x in [0, {c.length}], |y| <= {c.width / 2}, minus {PERSON_RADIUS} m body radius)")
            if _region_covered(sc.obstacles, p.region, PERSON_RADIUS):
                top.fail(f"{key}.region", f"no free space in the region {list(p.region)}: obstacles cover all of it")
            if p.start is not None:
                if not (x0 <= p.start[0] <= x1 and y0 <= p.start[1] <= y1):
                    top.fail(f"{key}.start", f"start {list(p.start)} is outside the region {list(p.region)}")
                j = in_obstacle(np.array(p.start), PERSON_RADIUS)
                if j is not None:
                    top.fail(f"{key}.start", f"starts inside obstacles[{j}] ({sc.obstacles[j].kind})")
            continue
        if p.behaviour == "circle":
            wps = np.array(circle_waypoints(p.center, p.radius, p.clockwise))
            path_key = f"{key}.center"
        else:
            wps = np.array(p.waypoints)
            path_key = f"{key}.waypoints"
        j = in_obstacle(wps[0], PERSON_RADIUS)
        if j is not None:
            top.fail(path_key, f"the person starts inside obstacles[{j}] ({sc.obstacles[j].kind})")
        # the waypoints first, then the path between them sampled every 5 cm (inside the corridor: bounded)
        samples = wps
        outside = ~_inside_corridor(c, wps, PERSON_RADIUS)
        if not np.any(outside):
            samples = _sample_segments(wps, closed=p.behaviour in ("waypoint_loop", "circle"))
            outside = ~_inside_corridor(c, samples, PERSON_RADIUS)
        if np.any(outside):
            q = samples[np.argmax(outside)]
            top.fail(path_key, f"the path leaves the corridor near ({q[0]:.2f}, {q[1]:.2f}) "
                     f"(x in [0, {c.length}], |y| <= {c.width / 2}, minus {PERSON_RADIUS} m body radius)")
        hit = _first_hit(sc.obstacles, samples, PERSON_RADIUS)
        if hit is not None:
            j, q = hit[0], samples[hit[1]]
            top.fail(path_key, f"the path walks through obstacles[{j}] ({sc.obstacles[j].kind}) near "
                     f"({q[0]:.2f}, {q[1]:.2f}) (the body is {PERSON_RADIUS} m wide each side)")

    for name in ("start", "goal"):
        pos = getattr(sc.drone, name)
        if not _inside_corridor(c, np.array(pos[:2]), 0.3)[0] or not 0.2 <= pos[2] <= c.height - 0.2:
            top.fail(f"drone.{name}", f"{list(pos)} is not inside the corridor with 0.3 m to the walls and 0.2 m to floor and top")
        j = in_obstacle(np.array(pos[:2]), 0.3)
        if j is not None and pos[2] <= sc.obstacles[j].size[2] + 0.3:
            top.fail(f"drone.{name}", f"{list(pos)} is inside obstacles[{j}] ({sc.obstacles[j].kind})")

    cp = sc.camera_path
    if cp is not None:
        if cp.follow_person is not None and cp.follow_person >= len(sc.people):
            top.fail("camera_path.follow_person", f"there is no people[{cp.follow_person}] ({len(sc.people)} people)")
        for k, (t, x, y, z, _) in enumerate(cp.keyframes):
            if not _inside_corridor(c, np.array([x, y]), 0.1)[0] or not 0.1 <= z <= c.height:
                top.fail(f"camera_path.keyframes[{k}]", f"({x}, {y}, {z}) is outside the corridor")
        if cp.keyframes:
            pts = np.array([kf[1:4] for kf in cp.keyframes])
            for k in range(len(pts)):
                seg = pts[k:k + 2]
                n = max(2, int(np.linalg.norm(seg[-1] - seg[0]) / 0.05) + 1)
                samples = seg[0] + np.linspace(0, 1, n)[:, None] * (seg[-1] - seg[0])
                for j, o in enumerate(sc.obstacles):
                    lo, hi = o.aabb()
                    inside = np.all((samples >= lo - 0.1) & (samples <= hi + 0.1), axis=1)
                    if np.any(inside):
                        q = samples[np.argmax(inside)]
                        top.fail(f"camera_path.keyframes[{k}]", f"the camera path passes through obstacles[{j}] "
                                 f"({o.kind}) near ({q[0]:.2f}, {q[1]:.2f}, {q[2]:.2f})")
