"""Recorded RGB-D sequences on disk: reading them as sensor frames, and writing the TUM format.

Two layouts are read:

- TUM RGB-D (the format of the TUM RGB-D benchmark): ``rgb/`` and ``depth/`` PNG folders listed by
  ``rgb.txt`` and ``depth.txt`` (lines ``timestamp path``, ``#`` comments), depth as 16-bit PNG
  at ``depth_factor`` units per metre (5000), colour registered to depth, and optionally camera
  poses as lines ``timestamp tx ty tz qx qy qz qw`` (the optical frame in the world, quaternion
  x, y, z, w; ``groundtruth.txt``). Each depth image is a frame; it takes the colour image of
  the nearest stamp within ``max_difference`` (0.02 s) and the pose interpolated at its stamp
  between poses at most ``max_pose_gap`` (0.1 s) apart.
- This project's ``dodt-nav simulate`` output: ``sensor.json`` with the intrinsics and each
  frame's stamp, pose and image paths (depth in millimetres).
- A plain folder of frames: ``depth/`` 16-bit PNGs (at ``depth_factor`` units per metre, 5000 by
  default as in TUM) and optionally ``rgb/`` (or ``color/``) PNG or JPEG images of the same names, no list
  files. File names that are timestamps (a number with a decimal point, as TUM names its images)
  are the frames' stamps; other names (``000123.png``) are taken in numerical order at a frame rate
  the caller gives (``rate``, Hz: the sequence has no per-frame timestamps).

In every layout the colour image must be registered to the depth image: the same size, and pixel
(u, v) of both seeing the same point (a RealSense's colour aligned to depth, a Kinect's registered
colour). A colour image of another size is not used (counted ``no_color``).

Depth in whole millimetres (every value of a frame a multiple of depth_factor / 1000: a millimetre
sensor's depth converted, as ``simulate --format tum`` writes it) is read as millimetres, so its
metres are bit for bit those the sensor's millimetres give.

Intrinsics come from a small file (JSON ``{"fx", "fy", "cx", "cy"}``, optionally ``width``,
``height`` and ``depth_factor``; or a text line ``fx fy cx cy``), from options, or from an
``intrinsics.json`` in the sequence folder. Frames whose files cannot be read, or that have no
pose where poses are given, are skipped and counted (``Sequence.counters``).

``write_tum`` writes frames in the TUM layout, with stamps at full precision and the intrinsics
in ``intrinsics.json``: ``dodt-nav simulate --format tum``.
"""
from __future__ import annotations

import bisect
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from dodt.frames import CameraIntrinsics, SensorFrame
from experiments.config import TextFileError
from experiments.config import read_text as read_bounded

TUM_DEPTH_FACTOR = 5000.0  # depth units per metre in the TUM RGB-D format
MAX_TEXT_BYTES = 16 << 20  # a list, pose or sensor file larger than this is refused unread
MAX_SMALL_BYTES = 1 << 20  # an intrinsics file larger than this is refused unread
MAX_PNG_BYTES = 256 << 20  # an image file larger than this is skipped as unreadable
MAX_FOCAL = 1e6  # px: the largest focal length (and principal point offset) taken from a file or option
MAX_SIDE = 65536  # px: the largest image width or height
MAX_DEPTH_FACTOR = 1e7  # depth units per metre


class SequenceError(ValueError):
    """The sequence or its options cannot be read (a user's mistake): the message names the file."""


# --------------------------------------------------------------------------- small readers


def read_text(path: Path, limit: int = MAX_TEXT_BYTES) -> str:
    """A small UTF-8 text file of a sequence, read no further than ``limit`` bytes; SequenceError naming
    the file when it is not a regular file, is larger, is not UTF-8 or holds NUL bytes."""
    try:
        return read_bounded(path, limit, "a sequence's text file")
    except TextFileError as e:
        raise SequenceError(str(e)) from None


def read_json(path: Path):
    """A sequence's JSON file (read_text's limits); SequenceError naming the file when it is not JSON."""
    try:
        return json.loads(read_text(path))
    except json.JSONDecodeError as e:
        raise SequenceError(f"{path}: not valid JSON ({e})") from None
    except RecursionError:
        raise SequenceError(f"{path}: nested too deep") from None
    except ValueError as e:  # an integer of more digits than Python converts
        raise SequenceError(f"{path}: {e}") from None


def read_list(path: Path) -> list[tuple[float, str]]:
    """A TUM list file: (stamp, rest of the line) per line, sorted by stamp; ``#`` lines skipped."""
    out = []
    lines = read_text(path).splitlines()
    for i, line in enumerate(lines, 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.split()
        try:
            stamp = float(parts[0])
        except ValueError:
            raise SequenceError(f"{path}, line {i}: expected 'timestamp ...', got {line[:60]!r}") from None
        if not math.isfinite(stamp):
            raise SequenceError(f"{path}, line {i}: the timestamp {parts[0]!r} is not a finite number")
        out.append((stamp, " ".join(parts[1:])))
    out.sort(key=lambda e: e[0])
    return out


def quaternion_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a quaternion (x, y, z, w: TUM's order, scipy's scalar-last), normalised first."""
    return Rotation.from_quat(np.asarray(q, float)).as_matrix()


def matrix_to_quaternion(R: np.ndarray) -> np.ndarray:
    """Quaternion (x, y, z, w), w >= 0, of a rotation matrix."""
    q = Rotation.from_matrix(np.asarray(R, float)).as_quat()
    return q if q[3] >= 0 else -q


def read_poses(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(stamps (N,), quaternion-and-translation rows (N, 7) as tx ty tz qx qy qz qw) of a TUM
    trajectory file."""
    rows = read_list(path)
    stamps, vals = [], []
    for stamp, rest in rows:
        parts = rest.split()
        try:
            v = [float(x) for x in parts]
        except ValueError:
            v = []
        if len(v) != 7 or not all(math.isfinite(x) for x in v) or np.linalg.norm(v[3:]) < 1e-6:
            raise SequenceError(f"{path}: the line of stamp {stamp!r} is not 'timestamp tx ty tz qx qy qz qw'")
        stamps.append(stamp)
        vals.append(v)
    if not stamps:
        raise SequenceError(f"{path}: no poses")
    return np.array(stamps), np.array(vals)


class PoseTrack:
    """Camera poses at any stamp, interpolated between the two nearest poses (translation linearly,
    rotation by spherical interpolation) when they are at most ``max_gap`` apart."""

    def __init__(self, stamps: np.ndarray, rows: np.ndarray, max_gap: float = 0.1):
        self.stamps, self.rows, self.max_gap = stamps, rows, max_gap

    def at(self, stamp: float) -> np.ndarray | None:
        s = self.stamps
        i = bisect.bisect_left(s, stamp)
        if i < len(s) and abs(s[i] - stamp) < 1e-9:
            return self._matrix(self.rows[i][:3], self.rows[i][3:])
        if i == 0 or i == len(s) or s[i] - s[i - 1] > self.max_gap:
            return None
        a = (stamp - s[i - 1]) / (s[i] - s[i - 1])
        t = (1 - a) * self.rows[i - 1][:3] + a * self.rows[i][:3]
        return self._matrix(t, _slerp(self.rows[i - 1][3:], self.rows[i][3:], a))

    @staticmethod
    def _matrix(t, q) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = quaternion_to_matrix(q)
        T[:3, 3] = t
        return T


def _slerp(q0: np.ndarray, q1: np.ndarray, a: float) -> np.ndarray:
    q0, q1 = q0 / np.linalg.norm(q0), q1 / np.linalg.norm(q1)
    d = float(q0 @ q1)
    if d < 0:
        q1, d = -q1, -d
    if d > 0.9995:
        q = q0 + a * (q1 - q0)
        return q / np.linalg.norm(q)
    th = math.acos(d)
    return (math.sin((1 - a) * th) * q0 + math.sin(a * th) * q1) / math.sin(th)


def read_intrinsics(path: Path) -> dict:
    """{"fx", "fy", "cx", "cy"} and any of "width", "height", "depth_factor" from a JSON file, or
    fx fy cx cy from the first line of a text file."""
    text = read_text(path, MAX_SMALL_BYTES)
    try:
        data = json.loads(text)
    except RecursionError:
        raise SequenceError(f"{path}: nested too deep") from None
    except ValueError:
        parts = text.split()
        try:
            vals = [float(x) for x in parts[:4]]
        except ValueError:
            vals = []
        if len(vals) != 4:
            raise SequenceError(f"{path}: expected JSON with fx, fy, cx, cy or a line 'fx fy cx cy'") from None
        data = dict(zip(("fx", "fy", "cx", "cy"), vals))
    if not isinstance(data, dict):
        raise SequenceError(f"{path}: expected a JSON object with fx, fy, cx, cy")
    missing = [k for k in ("fx", "fy", "cx", "cy") if k not in data]
    if missing:
        raise SequenceError(f"{path}: no {', '.join(missing)}")
    out = {}
    for k in ("fx", "fy", "cx", "cy", "width", "height", "depth_factor"):
        if k in data:
            try:
                out[k] = float(data[k])
            except (TypeError, ValueError):
                raise SequenceError(f"{path}: {k} must be a number, got {data[k]!r}") from None
            if not math.isfinite(out[k]):
                raise SequenceError(f"{path}: {k} must be finite, got {data[k]!r}")
    check_intrinsics(out, str(path))
    return out


def check_intrinsics(values: dict, where: str) -> None:
    """SequenceError naming ``where`` and the key when a value is out of its range: fx, fy in (0, 1e6] px,
    cx, cy within +-1e6 px, width and height whole numbers in [1, 65536], depth_factor in (0, 1e7]."""
    for k, v in values.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise SequenceError(f"{where}: {k} must be a finite number, got {v!r}")
        if k in ("fx", "fy") and not 0 < v <= MAX_FOCAL:
            raise SequenceError(f"{where}: {k} must be above 0 and at most {MAX_FOCAL:g} px, got {v!r}")
        if k in ("cx", "cy") and not abs(v) <= MAX_FOCAL:
            raise SequenceError(f"{where}: {k} must lie within +-{MAX_FOCAL:g} px, got {v!r}")
        if k in ("width", "height") and not (v == int(v) and 1 <= v <= MAX_SIDE):
            raise SequenceError(f"{where}: {k} must be a whole number of pixels in [1, {MAX_SIDE}], got {v!r}")
        if k == "depth_factor" and not 0 < v <= MAX_DEPTH_FACTOR:
            raise SequenceError(f"{where}: {k} must be above 0 and at most {MAX_DEPTH_FACTOR:g} units per metre, "
                                f"got {v!r}")


# --------------------------------------------------------------------------- sequences


@dataclass
class FrameRef:
    """Where one frame's data is: depth file, colour file (or None), stamp, pose (or None)."""

    seq: int
    stamp: float
    depth: Path
    color: Path | None
    T_world_camera: np.ndarray | None


@dataclass
class Sequence:
    """A sequence ready to be read frame by frame (``frames()``)."""

    root: Path
    format: str  # tum | dodt-sim
    intrinsics: CameraIntrinsics
    depth_scale: float  # metres per depth unit
    refs: list[FrameRef]
    pose_source: str | None  # the file the poses come from, or None
    # where the stamps come from: "per-frame" (listed or named with each frame), or the frame rate
    # the caller gave for a sequence without them
    stamp_source: str = "per-frame"
    counters: dict = field(default_factory=lambda: {"unreadable": 0, "no_pose": 0, "no_color": 0})

    def frames(self, fixed_pose: np.ndarray | None = None, pose_transform: np.ndarray | None = None,
               color: bool = True) -> Iterator[tuple[FrameRef, SensorFrame | None]]:
        """(reference, frame) per frame; the frame is None where its images cannot be read or it
        has no pose (counted). ``fixed_pose``: the pose of every frame (a fixed camera);
        ``pose_transform``: a transform applied to every pose from the file (T_new_world);
        ``color``: False leaves the colour images unread (frames without colour, not counted)."""
        want_color = color
        K = self.intrinsics
        per_mm = 0.001 / self.depth_scale  # depth units per millimetre
        mm_units = int(round(per_mm)) if per_mm >= 2 and abs(per_mm - round(per_mm)) < 1e-9 else None
        for ref in self.refs:
            depth = _read_png(ref.depth, np.uint16)
            if depth is None or depth.shape != (K.height, K.width):
                self.counters["unreadable"] += 1
                yield ref, None
                continue
            scale = self.depth_scale
            if mm_units is not None and not np.any(depth % mm_units):  # whole millimetres
                depth, scale = depth // mm_units, 0.001
            color = None
            if want_color and ref.color is not None:
                bgr = _read_png(ref.color, np.uint8, color=True)
                if bgr is not None and bgr.shape[:2] == depth.shape:
                    color = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
            if want_color and color is None:
                self.counters["no_color"] += 1
            T = fixed_pose if fixed_pose is not None else ref.T_world_camera
            if T is None:
                self.counters["no_pose"] += 1
                yield ref, None
                continue
            if pose_transform is not None and fixed_pose is None:
                T = pose_transform @ T
            yield ref, SensorFrame(depth=depth, color=color, intrinsics=K, T_world_camera=np.array(T, float),
                                   stamp=ref.stamp, seq=ref.seq, depth_scale=scale)

    def depth_m(self, ref: FrameRef) -> np.ndarray | None:
        """One frame's depth in metres (0: none), or None when it cannot be read."""
        d = _read_png(ref.depth, np.uint16)
        if d is None or d.shape != (self.intrinsics.height, self.intrinsics.width):
            return None
        return d.astype(np.float32) * np.float32(self.depth_scale)


def _read_png(path: Path, dtype, color: bool = False) -> np.ndarray | None:
    """The image, or None when it cannot be read: missing, not a file, larger than MAX_PNG_BYTES, broken.
    OpenCV's own log lines about a broken file are silenced: the frame is counted as unreadable instead."""
    flags = cv2.IMREAD_COLOR if color else cv2.IMREAD_UNCHANGED
    try:
        if not path.is_file() or path.stat().st_size > MAX_PNG_BYTES:
            return None
    except OSError:
        return None
    log = cv2.utils.logging
    level = log.getLogLevel()
    log.setLogLevel(log.LOG_LEVEL_SILENT)
    try:
        img = cv2.imread(str(path), flags)
    except cv2.error:
        return None
    finally:
        log.setLogLevel(level)
    if img is None or img.dtype != dtype or (not color and img.ndim != 2):
        return None
    return img


def _intrinsics(root: Path, options: dict, intrinsics_file: Path | None, size: tuple[int, int]) -> tuple[CameraIntrinsics, dict]:
    """The camera intrinsics: options override the file given, which overrides the folder's
    intrinsics.json. Returns them and the values read (for the depth factor)."""
    values: dict = {}
    file = intrinsics_file or (root / "intrinsics.json" if (root / "intrinsics.json").is_file() else None)
    if file is not None:
        if not Path(file).is_file():
            raise SequenceError(f"--intrinsics: {file}: no such file" if intrinsics_file else
                                f"{file}: no such intrinsics file")
        values.update(read_intrinsics(Path(file)))
    given = {k: float(v) for k, v in options.items() if v is not None}
    check_intrinsics({f"--{k}": v for k, v in given.items()}, "options")
    values.update(given)
    missing = [k for k in ("fx", "fy", "cx", "cy") if k not in values]
    if missing:
        raise SequenceError(f"{root}: no camera intrinsics ({', '.join(missing)} missing): give --intrinsics FILE "
                            "or --fx, --fy, --cx, --cy")
    w, h = size
    if ("width" in values and int(values["width"]) != w) or ("height" in values and int(values["height"]) != h):
        raise SequenceError(f"{root}: the intrinsics are for {int(values.get('width', w))}x{int(values.get('height', h))} "
                            f"but the depth images are {w}x{h}")
    for k in ("fx", "fy"):
        if not values[k] > 0:
            raise SequenceError(f"{root}: intrinsics {k} must be above 0, got {values[k]}")
    return CameraIntrinsics(width=w, height=h, fx=values["fx"], fy=values["fy"], cx=values["cx"], cy=values["cy"]), values


def _first_size(paths) -> tuple[int, int]:
    for p in paths:
        d = _read_png(p, np.uint16)
        if d is not None:
            return d.shape[1], d.shape[0]
    raise SequenceError(f"{Path(paths[0]).parent if paths else '?'}: no readable 16-bit depth PNG")


def open_sequence(path: str | Path, intrinsics_file: str | Path | None = None, fx=None, fy=None, cx=None,
                  cy=None, depth_factor: float | None = None, poses: str | Path | None = None,
                  max_difference: float = 0.02, max_pose_gap: float = 0.1, rate: float | None = None) -> Sequence:
    """A TUM RGB-D folder, a ``dodt-nav simulate`` output folder or a plain folder of frames, ready
    to be read.

    ``poses``: a TUM trajectory file (relative to the folder or absolute; default: the folder's
    groundtruth.txt if there is one; "none": no poses). ``depth_factor``: depth units per metre
    (default: the intrinsics file's, else 5000 for TUM and a plain folder). ``rate``: the frame rate
    (Hz) of a plain folder whose file names are no timestamps; a sequence with per-frame timestamps
    keeps them."""
    root = Path(path)
    if not root.is_dir():
        raise SequenceError(f"{root}: no such sequence folder")
    opts = {"fx": fx, "fy": fy, "cx": cx, "cy": cy}
    if (root / "depth.txt").is_file():
        return _open_tum(root, intrinsics_file, opts, depth_factor, poses, max_difference, max_pose_gap)
    if (root / "sensor.json").is_file():
        return _open_sim(root, intrinsics_file, opts, depth_factor, poses, max_pose_gap)
    if (root / "depth").is_dir():
        return _open_folder(root, intrinsics_file, opts, depth_factor, poses, max_pose_gap, rate)
    raise SequenceError(f"{root}: neither a TUM RGB-D sequence (depth.txt), a dodt-nav simulate output "
                        "(sensor.json) nor a folder of frames (depth/)")


def _pose_track(root: Path, poses, max_pose_gap: float) -> tuple[PoseTrack | None, str | None]:
    if poses == "none":
        return None, None
    if poses is None:
        if not (root / "groundtruth.txt").is_file():
            return None, None
        poses = "groundtruth.txt"
    p = Path(poses)
    p = p if p.is_absolute() or p.is_file() else root / p
    if not p.is_file():
        raise SequenceError(f"--poses: {p}: {'not a regular file' if p.exists() else 'no such file'}")
    stamps, rows = read_poses(p)
    return PoseTrack(stamps, rows, max_pose_gap), str(p)


def _depth_factor(depth_factor: float | None, values: dict) -> float:
    """Depth units per metre: the option's, else the intrinsics file's, else TUM's 5000."""
    factor = depth_factor if depth_factor is not None else values.get("depth_factor", TUM_DEPTH_FACTOR)
    if not (math.isfinite(factor) and 0 < factor <= MAX_DEPTH_FACTOR):
        raise SequenceError(f"--depth-factor: must be a number of depth units per metre above 0, got {factor}")
    return factor


def _stamp_of_name(stem: str) -> float | None:
    """The timestamp a file name holds ("1305031102.175304"), or None (no decimal point, not a number)."""
    if "." not in stem:
        return None
    try:
        t = float(stem)
    except ValueError:
        return None
    return t if math.isfinite(t) else None


def _name_order(path: Path):
    """Sort key: file names by the number they hold (frame 10 after frame 9), then by name."""
    digits = "".join(c for c in path.stem if c.isdigit())
    return (int(digits) if digits else -1, path.name)


def _open_folder(root, intrinsics_file, opts, depth_factor, poses, max_pose_gap, rate) -> Sequence:
    """A plain folder of frames (module docstring): depth/*.png, colour of the same names."""
    depth = sorted((p for p in (root / "depth").iterdir() if p.suffix.lower() == ".png"), key=_name_order)
    if not depth:
        raise SequenceError(f"{root / 'depth'}: no PNG depth images")
    named = [_stamp_of_name(p.stem) for p in depth]
    if all(t is not None for t in named):
        order = sorted(range(len(depth)), key=lambda i: named[i])
        depth, stamps = [depth[i] for i in order], [named[i] for i in order]
        if any(b <= a for a, b in zip(stamps, stamps[1:])):
            raise SequenceError(f"{root / 'depth'}: two images are named with the same timestamp")
        stamp_source = "per-frame"
    elif rate is None:
        raise SequenceError(f"{root}: its frames have no timestamps (file names such as {depth[0].name}): give the "
                            "frame rate they were recorded at, --rate HZ")
    else:
        stamps = [k / rate for k in range(len(depth))]
        stamp_source = f"--rate {rate:g} Hz"
    color_dir = next((root / d for d in ("rgb", "color") if (root / d).is_dir()), None)
    colors = {} if color_dir is None else {p.stem: p for p in sorted(color_dir.iterdir())
                                           if p.suffix.lower() in (".png", ".jpg", ".jpeg")}
    K, values = _intrinsics(root, opts, Path(intrinsics_file) if intrinsics_file else None, _first_size(depth[:20]))
    track, pose_source = _pose_track(root, poses, max_pose_gap)
    refs = []
    for seq, (stamp, d) in enumerate(zip(stamps, depth)):
        refs.append(FrameRef(seq, stamp, d, colors.get(d.stem), track.at(stamp) if track is not None else None))
    return Sequence(root, "folder", K, 1.0 / _depth_factor(depth_factor, values), refs, pose_source, stamp_source)


def _open_tum(root, intrinsics_file, opts, depth_factor, poses, max_difference, max_pose_gap) -> Sequence:
    depth_list = read_list(root / "depth.txt")
    if not depth_list:
        raise SequenceError(f"{root / 'depth.txt'}: lists no depth images")
    rgb_list = read_list(root / "rgb.txt") if (root / "rgb.txt").is_file() else []
    K, values = _intrinsics(root, opts, Path(intrinsics_file) if intrinsics_file else None,
                            _first_size([root / p for _, p in depth_list[:20]]))
    factor = _depth_factor(depth_factor, values)
    track, pose_source = _pose_track(root, poses, max_pose_gap)
    rgb_stamps = [s for s, _ in rgb_list]
    refs = []
    for seq, (stamp, rel) in enumerate(depth_list):
        color = None
        if rgb_stamps:
            i = bisect.bisect_left(rgb_stamps, stamp)
            best = min((j for j in (i - 1, i) if 0 <= j < len(rgb_stamps)), key=lambda j: abs(rgb_stamps[j] - stamp))
            if abs(rgb_stamps[best] - stamp) <= max_difference:
                color = root / rgb_list[best][1]
        T = track.at(stamp) if track is not None else None
        refs.append(FrameRef(seq, stamp, root / rel, color, T))
    return Sequence(root, "tum", K, 1.0 / factor, refs, pose_source)


def _field(d, key: str, kind: str, where: str):
    """``d[key]`` checked: "number" a finite number, "whole" a whole number >= 0, "path" a relative path
    (text); SequenceError naming ``where`` and the key otherwise."""
    if not isinstance(d, dict) or key not in d:
        raise SequenceError(f"{where}: no {key}")
    v = d[key]
    if kind == "path":
        if not isinstance(v, str) or not v or "\x00" in v:
            raise SequenceError(f"{where}: {key} must be a file path (text), got {v!r}"[:300])
        return v
    ok = not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)
    if kind == "whole":
        ok = ok and v == int(v) and 0 <= v < 2**53
    if not ok:
        raise SequenceError(f"{where}: {key} must be a {'whole number >= 0' if kind == 'whole' else 'finite number'}, "
                            f"got {v!r}"[:300])
    return int(v) if kind == "whole" else float(v)


def _open_sim(root, intrinsics_file, opts, depth_factor, poses, max_pose_gap) -> Sequence:
    path = root / "sensor.json"
    sensor = read_json(path)
    if not isinstance(sensor, dict) or not isinstance(sensor.get("intrinsics"), dict) \
            or not isinstance(sensor.get("frames"), list):
        raise SequenceError(f"{path}: not a dodt-nav simulate sensor file (an object with intrinsics and a list of "
                            "frames)")
    k, frames = sensor["intrinsics"], sensor["frames"]
    if not frames:
        raise SequenceError(f"{path}: lists no frames")
    bad = next((i for i, f in enumerate(frames) if not isinstance(f, dict)), None)
    if bad is not None:
        raise SequenceError(f"{path}: frames[{bad}]: not an object")
    values = {key: _field(k, key, "number", f"{path}: intrinsics") for key in ("fx", "fy", "cx", "cy")}
    size = {key: _field(k, key, "number", f"{path}: intrinsics") for key in ("width", "height")}
    check_intrinsics(values | size, f"{path}: intrinsics")
    given = {key: float(v) for key, v in opts.items() if v is not None}
    check_intrinsics({f"--{key}": v for key, v in given.items()}, "options")
    values.update(given)
    if intrinsics_file:
        if not Path(intrinsics_file).is_file():
            raise SequenceError(f"--intrinsics: {intrinsics_file}: no such file")
        values.update({key: v for key, v in read_intrinsics(Path(intrinsics_file)).items()
                       if key in ("fx", "fy", "cx", "cy")})
    K = CameraIntrinsics(width=int(size["width"]), height=int(size["height"]), **values)
    w, h = _first_size([root / f["depth"] for f in frames[:20] if isinstance(f, dict) and isinstance(f.get("depth"), str)])
    if (w, h) != (K.width, K.height):
        raise SequenceError(f"{path}: the intrinsics are for {K.width}x{K.height} but the depth images are {w}x{h}")
    if depth_factor is None:
        scale = _field(sensor, "depth_scale", "number", str(path)) if "depth_scale" in sensor else 0.001
        if not 0 < scale <= 1.0:
            raise SequenceError(f"{path}: depth_scale must be metres per depth unit in (0, 1], got {scale!r}")
    else:
        scale = 1.0 / depth_factor
    # the poses the frames carry, unless a trajectory file is named
    track, pose_source = _pose_track(root, poses, max_pose_gap) if poses not in (None, "none") else (None, None)
    refs = []
    for i, f in enumerate(frames):
        where = f"{path}: frames[{i}]"
        if not isinstance(f, dict):
            raise SequenceError(f"{where}: not an object")
        stamp = _field(f, "stamp", "number", where)
        if track is not None:
            T = track.at(stamp)
        else:
            try:
                T = np.array(f["T_world_camera"], float)
            except KeyError:
                raise SequenceError(f"{where}: no T_world_camera") from None
            except (TypeError, ValueError, OverflowError):
                T = None
            if T is None or T.shape != (4, 4) or not np.all(np.isfinite(T)):
                raise SequenceError(f"{where}: T_world_camera must be a 4x4 matrix of finite numbers")
        color = f.get("color")
        if color is not None and (not isinstance(color, str) or "\x00" in color):
            raise SequenceError(f"{where}: color must be a file path (text) or null, got {color!r}"[:300])
        refs.append(FrameRef(_field(f, "seq", "whole", where), stamp, root / _field(f, "depth", "path", where),
                             root / color if color else None, T))
    return Sequence(root, "dodt-sim", K, scale, refs, pose_source or str(path))


# --------------------------------------------------------------------------- writing


class TumWriter:
    """Writes frames as a TUM RGB-D sequence: rgb/, depth/ (16-bit PNG at 5000 per metre), rgb.txt,
    depth.txt, the frames' poses as groundtruth.txt (the true camera pose, when given) and
    odometry.txt (the pose each frame carries), intrinsics.json. Stamps at full precision."""

    def __init__(self, out: Path, intrinsics: CameraIntrinsics):
        self.out = Path(out)
        for sub in ("rgb", "depth"):
            (self.out / sub).mkdir(parents=True, exist_ok=True)
        self.K = intrinsics
        self.lines = {"rgb": [], "depth": [], "groundtruth": [], "odometry": []}

    def add(self, frame: SensorFrame, T_true: np.ndarray | None = None) -> None:
        stamp = repr(float(frame.stamp))
        name = f"{stamp}.png"
        # depth the format cannot hold (beyond 65535 / 5000 = 13.1 m) is written as none (0)
        if frame.depth.dtype == np.uint16 and frame.depth_scale == 0.001:  # millimetres: exactly 5 units each
            units = frame.depth.astype(np.uint32) * 5
        else:
            units = np.round(frame.depth_m().astype(np.float64) * TUM_DEPTH_FACTOR)
        units = np.where(units <= 65535, units, 0).astype(np.uint16)
        cv2.imwrite(str(self.out / "depth" / name), units)
        self.lines["depth"].append(f"{stamp} depth/{name}")
        if frame.color is not None:
            cv2.imwrite(str(self.out / "rgb" / name), cv2.cvtColor(frame.color, cv2.COLOR_RGB2BGR))
            self.lines["rgb"].append(f"{stamp} rgb/{name}")
        for key, T in (("odometry", frame.T_world_camera), ("groundtruth", T_true)):
            if T is not None:
                T = np.asarray(T, float)
                q = matrix_to_quaternion(T[:3, :3])
                self.lines[key].append(stamp + " " + " ".join(repr(float(x)) for x in (*T[:3, 3], *q)))

    def close(self) -> None:
        heads = {"rgb": "# color images\n# timestamp filename\n", "depth": "# depth images\n# timestamp filename\n",
                 "groundtruth": "# true camera poses\n# timestamp tx ty tz qx qy qz qw\n",
                 "odometry": "# camera poses the frames carry (odometry)\n# timestamp tx ty tz qx qy qz qw\n"}
        for key, lines in self.lines.items():
            if lines or key in ("rgb", "depth"):
                (self.out / f"{key}.txt").write_text(heads[key] + "".join(line + "\n" for line in lines))
        K = self.K
        (self.out / "intrinsics.json").write_text(json.dumps(
            {"width": K.width, "height": K.height, "fx": K.fx, "fy": K.fy, "cx": K.cx, "cy": K.cy,
             "depth_factor": TUM_DEPTH_FACTOR}, indent=1))
