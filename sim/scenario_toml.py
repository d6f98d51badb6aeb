"""Reading scenario files: finding them, their TOML text, and their tables into a scenario's parts.

Every key is checked as it is read; a wrong one raises ScenarioError naming the file, the key path and the
reason, and a key nobody read is an unknown key. The format is documented in the README ("Scenario format").
"""
from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from sim.lidar_model import LidarModel
from sim.rig import LIDAR_MOUNTS, SensorMount, mounted_model
from sim.scenario_bounds import (MAX_ANGLE_DEG, MAX_COORDINATE, MAX_DURATION, MAX_FILE_BYTES, MAX_KEY_PARTS,
                                 MAX_MOUNT_OFFSET, MAX_NAME_CHARS, MAX_OBSTACLE_SIZE, MAX_OBSTACLES, MAX_PEOPLE,
                                 MAX_POINTS, MAX_SENSORS, SEED_MAX, ScenarioError, finite_number, short_repr)
from sim.scenario_checks import check_geometry
from sim.scenario_parts import (BEHAVIOURS, OBSTACLE_KINDS, PERSON_HEIGHT_RANGE, PERSON_SPEED_RANGE,
                                RENDERER_CHOICES, Camera, CameraPath, Corridor, Crowd, Drone, Noise, Obstacle,
                                Person, Rates)
from sim.toml_keys import longest_key

SCENARIO_DIR = Path(__file__).resolve().parent / "scenarios"


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
    """The names of the scenarios shipped in SCENARIO_DIR."""
    return sorted(s.stem for s in SCENARIO_DIR.glob("*.toml"))


def read_text(path: Path) -> str:
    """The text of a scenario file, refused when it cannot be read, is larger than MAX_FILE_BYTES or is not
    UTF-8."""
    try:
        with open(path, "rb") as fh:
            data = fh.read(MAX_FILE_BYTES + 1)  # no more, whatever the path is (/dev/zero)
        if len(data) > MAX_FILE_BYTES:
            raise ScenarioError(f"{path}: more than {MAX_FILE_BYTES} bytes; a scenario file holds at most "
                                f"{MAX_FILE_BYTES} (1 MiB)")
        return data.decode("utf-8-sig")  # a byte-order mark, as some editors write, is no error
    except OSError as e:
        raise ScenarioError(f"{path}: cannot read: {e.strerror}") from None
    except UnicodeDecodeError as e:
        raise ScenarioError(f"{path}: not a UTF-8 text file (byte {e.start}: {e.reason})") from None


def read_toml(text: str, source: str) -> dict:
    """The tables of a scenario's TOML text (``source`` names it in messages). A key of more than MAX_KEY_PARTS
    dotted parts is refused before the text is parsed (the parser's work grows with their square)."""
    if len(text) > MAX_FILE_BYTES:
        raise ScenarioError(f"{source}: {len(text)} characters; a scenario holds at most {MAX_FILE_BYTES}")
    parts = longest_key(text)
    if parts > MAX_KEY_PARTS:
        raise ScenarioError(f"{source}: a key of {parts} dotted parts; a scenario's keys have at most {MAX_KEY_PARTS}")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(f"{source}: not valid TOML: {e}") from None
    except RecursionError:
        raise ScenarioError(f"{source}: not valid TOML: arrays or tables nested too deeply") from None


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
            self.fail(self.key(name), f"expected a number, got {short_repr(v)}")
        if integer and not isinstance(v, int):
            self.fail(self.key(name), f"expected an integer, got {short_repr(v)}")
        if not integer and not finite_number(v):
            self.fail(self.key(name), f"must be finite, got {short_repr(v)}")
        if lo is not None and (v <= lo if lo_open else v < lo):
            self.fail(self.key(name), f"must be {'>' if lo_open else '>='} {lo}, got {short_repr(v)}")
        if hi is not None and v > hi:
            self.fail(self.key(name), f"must be <= {hi}, got {short_repr(v)}")
        return int(v) if integer else float(v)

    def boolean(self, name, default):
        v = self.raw(name, default)
        if not isinstance(v, bool):
            self.fail(self.key(name), f"expected true or false, got {short_repr(v)}")
        return v

    def string(self, name, default=None, choices=None):
        v = self.raw(name, default)
        if v is None:
            self.fail(self.key(name), "is required")
        if not isinstance(v, str):
            self.fail(self.key(name), f"expected a string, got {short_repr(v)}")
        if choices is not None and v not in choices:
            self.fail(self.key(name), f"must be one of {', '.join(choices)}; got {short_repr(v)}")
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
            self.fail(self.key(name), f"expected a list of {n} numbers, got {short_repr(v)}")
        out = []
        for x in v:
            if not finite_number(x):
                self.fail(self.key(name), f"expected a list of {n} finite numbers, got {short_repr(v)}")
            if abs(x) > bound:
                self.fail(self.key(name), f"{what} must lie within +-{bound:g}, got {short_repr(v)}")
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
        plain = _plain_points(v, n, bounds)
        if plain is not None:
            return plain
        out = []
        for i, p in enumerate(v):
            if (not isinstance(p, list) or len(p) != n
                    or any(not finite_number(x) for x in p)):
                self.fail(f"{self.key(name)}[{i}]", f"expected {n} finite numbers, got {short_repr(p)}")
            for field_name, x, b in zip(names, p, bounds):
                if abs(x) > b:
                    self.fail(f"{self.key(name)}[{i}]", f"{field_name} must lie within +-{b:g}, got {short_repr(x)}")
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


def _plain_points(v: list, n: int, bounds) -> tuple | None:
    """The points of ``v`` as Section.points gives them when every one is a list of n finite numbers (no
    booleans) within bounds, checked at once; None otherwise (Section.points then finds the first fault)."""
    if not all(type(p) is list and len(p) == n for p in v):
        return None
    flat = [x for p in v for x in p]
    if not all(type(x) is float or type(x) is int for x in flat):
        return None
    try:
        a = np.array(flat, dtype=float).reshape(len(v), n)
    except OverflowError:  # an integer beyond any float
        return None
    if not (np.all(np.isfinite(a)) and np.all(np.abs(a) <= np.asarray(bounds, dtype=float))):
        return None
    return tuple(map(tuple, a.tolist()))


def _read_once(read, s: "_Section", memo: dict | None):
    """read(s), or what it gave for the very same table before (memo: id -> (table, result); holding the table
    keeps its id from being reused): draws of a scenario share the tables that hold no range."""
    if memo is None:
        return read(s)
    hit = memo.get(id(s.data))
    if hit is not None and hit[0] is s.data:
        return hit[1]
    out = read(s)
    memo[id(s.data)] = (s.data, out)
    return out


def read_fields(data: dict, source: str, geometry: bool = True, memo: dict | None = None,
                work: list[int] | None = None) -> dict[str, Any]:
    """The fields of a sim.scenario.Scenario from the file's tables (its ranges drawn already), each key checked;
    geometry: the parts' geometry checked too (sim.scenario_checks). memo: a dict kept from draw to draw of
    one scenario, so that an obstacle or a person holding no range is read once (_read_once); work: the
    geometry checks' count of path points (check_geometry)."""
    top = _Section(data, "", source)
    name = top.string("name", Path(source).stem)
    if not name or len(name) > MAX_NAME_CHARS or not name.isprintable():
        top.fail("name", f"expected 1 to {MAX_NAME_CHARS} printable characters on one line, got {short_repr(name)}")
    seed = top.number("seed", 0, lo=0, hi=SEED_MAX, integer=True)
    duration = top.number("duration", 20.0, lo=0.0, lo_open=True, hi=MAX_DURATION)
    description = top.string("description", "")
    segmentation = top.boolean("segmentation", True)

    corridor = _read_corridor(top.sub("corridor"))
    obstacles = tuple(_read_once(_read_obstacle, s, memo) for s in _array_of_tables(top, "obstacles", MAX_OBSTACLES))
    people = tuple(_read_once(_read_person, s, memo) for s in _array_of_tables(top, "people", MAX_PEOPLE))
    drone = _read_drone(top.sub("drone"))
    camera = _read_camera(top.sub("camera"))
    noise = _read_noise(top.sub("noise"))
    rates = _read_rates(top.sub("rates"))
    crowd = _read_crowd(top.sub("crowd"))
    camera_path = _read_camera_path(top.sub("camera_path")) if top.has("camera_path") else None
    sensors = _read_sensors(top)
    top.done()

    if geometry:
        check_geometry(corridor, obstacles, people, drone, camera_path, top.fail, work)
    return dict(name=name, source=source, seed=seed, duration=duration, description=description,
                corridor=corridor, obstacles=obstacles, people=people, drone=drone, camera=camera,
                noise=noise, rates=rates, camera_path=camera_path, segmentation=segmentation, crowd=crowd,
                sensors=sensors)


def _array_of_tables(top: _Section, name: str, most: int) -> list[_Section]:
    v = top.raw(name, [])
    if not isinstance(v, list):
        top.fail(name, "expected an array of tables ([[%s]])" % name)
    if len(v) > most:
        top.fail(name, f"at most {most} {name}, got {len(v)}")
    return [_Section(item, f"{name}[{i}]", top.source) for i, item in enumerate(v)]


def _read_sensors(top: _Section) -> tuple[SensorMount, ...]:
    """[[sensors]]: the drone's rig (sim.rig), each a camera like [camera] turned by ``yaw_deg`` on the body,
    or a LiDAR (its model's parameters; sim.lidar_model) on top of the body or, with ``mount = "below"``,
    upside down under it (its elevations in the body's frame, by default -52 to +7 deg). The first is the
    [camera] itself: a camera with ``yaw_deg`` 0. Empty when the file has none (then ``--rig``, front by
    default, decides)."""
    out = []
    for s in _array_of_tables(top, "sensors", MAX_SENSORS):
        kind = s.string("kind", choices=("camera", "lidar"))
        if kind is None:
            s.fail(s.key("kind"), "required: camera or lidar")
        name = s.string("name", f"{kind}{len(out)}")
        if not name or len(name) > MAX_NAME_CHARS or not name.isprintable() or name in {m.name for m in out}:
            s.fail(s.key("name"), f"expected a unique printable name, got {short_repr(name)}")
        yaw = s.number("yaw_deg", 0.0, lo=-180.0, hi=180.0)
        lidar, mount = None, "top"
        if kind == "lidar":
            mount = s.string("mount", "top", choices=LIDAR_MOUNTS)
            d = mounted_model(mount)
            el_min = s.number("elevation_min_deg", math.degrees(d.elevation_min), lo=-90.0, hi=90.0)
            el_max = s.number("elevation_max_deg", math.degrees(d.elevation_max), lo=-90.0, hi=90.0)
            if el_max <= el_min:
                s.fail(s.key("elevation_max_deg"), f"must exceed elevation_min_deg ({el_min}), got {el_max}")
            lidar = LidarModel(name=name, points_per_scan=s.number("points_per_scan", d.points_per_scan, lo=100,
                                                                    hi=200_000, integer=True),
                               scan_rate=s.number("scan_rate", d.scan_rate, lo=1.0, hi=30.0),
                               elevation_min=math.radians(el_min), elevation_max=math.radians(el_max),
                               max_range=s.number("max_range", d.max_range, lo=1.0, hi=200.0),
                               range_std=s.number("range_std", d.range_std, lo=0.0, hi=1.0))
        s.done()
        out.append(SensorMount(kind, name, yaw, lidar, mount))
    if out and (out[0].kind != "camera" or out[0].yaw != 0.0):
        top.fail("sensors[0]", "the first sensor is the [camera] table's: kind = \"camera\" with yaw_deg = 0")
    return tuple(out)


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
