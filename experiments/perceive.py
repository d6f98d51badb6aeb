"""`dodt-nav perceive SEQUENCE --out DIR`: DODT on a recorded RGB-D sequence.

Reads a TUM RGB-D folder, a `dodt-nav simulate` output or a plain folder of depth (and colour)
images (experiments.sequences), runs a DODT configuration on every frame (or on the frames decimated
to ``--rate``; a folder whose frames have no timestamps was recorded at ``--rate``), and writes into DIR:

    tracks.jsonl     one line per frame: seq, stamp, skipped (why, or null), bad pixels, and
                     every reported obstacle (TrackedObstacle.to_json)
    timings.csv      per frame, each module's milliseconds
    summary.json     the sequence, the configuration (every value), where the poses came from
                     (the floor fit's height, pitch and roll), frames read / processed / skipped
                     and why, where the stamps came from, per-module median and p95
                     milliseconds (after the first frame, which compiles the pipeline's kernels),
                     track counts, the warnings (a floor fit that puts the camera at an
                     implausible height: a wrong depth scale), and, for a simulated sequence
                     with its ground truth, the perception benchmark's figures
    annotated/       with --images: each frame with the tracks' boxes drawn (red dynamic, green
                     static, thin while coasting; id and speed), and the learned detector's 2D boxes
    annotated.mp4    with --video: the same as a video

Camera poses: a trajectory file (``--poses``; the folder's groundtruth.txt by default), the poses
of a simulated run, a fixed camera's ``--camera-height`` and ``--pitch`` / ``--roll``, or
``--fit-floor``: the floor in the first frames gives a fixed camera's height, pitch and roll
(dodt.floor) and a z-up world; with poses, it turns their world so that z is up and the floor is
at 0.
"""
from __future__ import annotations

import csv
import json
import math
import sys
import time
from dataclasses import asdict
from pathlib import Path

import cv2
import numpy as np

from dodt.config import override
from dodt.floor import camera_pose, fit_floor_frames
from dodt.pipeline import DODT, MODULES
from dodt.presets import PRESETS, preset
from dodt.protocol import TrackReport
from experiments.config_limits import check_config
from experiments.sequences import MAX_DEPTH_FACTOR, MAX_FOCAL, MAX_SIDE, SequenceError, open_sequence

FLOOR_FRAMES = 10  # the first readable frames the floor is fitted on
# m: the heights above the floor a camera plausibly has (a drone's, a handheld's, a mounted one's).
# A fit outside them most likely read the depth at the wrong scale: millimetre images read at TUM's
# 5000 units per metre put a camera 2.35 m up at 0.47 m. A ground robot's camera lower than the
# lower bound gets the warning too, which its user can then ignore.
PLAUSIBLE_CAMERA_HEIGHT = (0.5, 3.0)
DEPTH_FACTORS = (1000.0, 5000.0)  # depth units per metre of millimetre images and of TUM RGB-D's


def depth_scale_warning(height: float, factor: float) -> str | None:
    """One line when a floor fit's camera ``height`` (m) is implausible (PLAUSIBLE_CAMERA_HEIGHT) for
    depth read at ``factor`` units per metre, naming the common factors that would put it in range;
    None when it is plausible."""
    lo, hi = PLAUSIBLE_CAMERA_HEIGHT
    if lo <= height <= hi:
        return None
    fixes = [f"--depth-factor {f:g} would put it {height * factor / f:.2f} m up" for f in DEPTH_FACTORS
             if abs(f - factor) > 1e-9 and lo <= height * factor / f <= hi]
    return (f"the floor fit puts the camera {height:.2f} m above the floor, outside the plausible {lo:g}-{hi:g} m: "
            f"is the depth scale right? The depth was read at {factor:g} units per metre"
            + (f"; {'; '.join(fixes)}" if fixes else "; give the right one with --depth-factor"))


def build_config(name: str, assignments=(), detector: str | None = None, layout: str = "auto",
                 person_class: int = 0, input_size: tuple[int, int] | None = None):
    """A preset with ``--set`` assignments and the ``--detector`` options applied."""
    if name not in PRESETS:
        raise SequenceError(f"--config: unknown configuration {name!r}; known: {', '.join(PRESETS)}")
    cfg = preset(name)
    if detector is not None:
        if not Path(detector).is_file():
            raise SequenceError(f"--detector: {detector}: no such model file")
        cfg = override(cfg, ["learned.enabled=true", f"learned.model={detector}", f"learned.layout={layout}",
                             f"learned.person_class={person_class}"])
        if input_size is not None:
            cfg = override(cfg, [f"learned.input_size={input_size[0]},{input_size[1]}"])
    try:
        cfg = override(cfg, assignments)
    except ValueError as e:
        raise SequenceError(str(e)) from None
    if assignments:
        try:
            check_config("dodt", cfg)  # every value in its range (experiments.config_limits), as run's --set dodt.*
        except ValueError as e:
            raise SequenceError(f"--set: {e}") from None
    return cfg


def _floor_pose(seq, sensor_poses: bool) -> tuple[np.ndarray | None, np.ndarray | None, dict]:
    """(fixed pose, pose transform, the fit's record) from the floor in the first frames."""
    depths, refs = [], []
    for ref in seq.refs:
        d = seq.depth_m(ref)
        if d is not None and (not sensor_poses or ref.T_world_camera is not None):
            depths.append(d)
            refs.append(ref)
        if len(depths) == FLOOR_FRAMES:
            break
    fit, i = fit_floor_frames(depths, seq.intrinsics, return_index=True)
    if fit is None:
        raise SequenceError(f"--fit-floor: no floor plane in the first {len(depths)} frames of {seq.root} "
                            "(the floor must fill part of the view below the camera)")
    record = fit.to_json() | {"frame_seq": refs[i].seq}
    T_floor = fit.T_world_camera()
    if not sensor_poses:
        return T_floor, None, record
    # the first pose's world turned so that the floor is at z = 0 and z is up
    return None, T_floor @ np.linalg.inv(refs[i].T_world_camera), record


def _truth_frames(root: Path) -> dict | None:
    """A simulated sequence's ground truth: stamp -> (seq, frame record), or None."""
    f = root / "ground_truth.json"
    if not f.is_file():
        return None
    try:
        frames = json.loads(f.read_text(encoding="utf-8"))["frames"]
    except (json.JSONDecodeError, KeyError, TypeError):
        raise SequenceError(f"{f}: not a dodt-nav ground truth file") from None
    return {float(t["stamp"]): t for t in frames}


class _Truth:
    """One frame's ground truth as experiments.perception_metrics reads it."""

    class Obstacle:
        def __init__(self, d: dict):
            self.id, self.kind = int(d["id"]), d["kind"]
            lo, hi = np.array(d["aabb_min"], float), np.array(d["aabb_max"], float)
            self.center, self.size = (lo + hi) / 2, hi - lo
            self.velocity = np.array(d["velocity"], float)

    def __init__(self, rec: dict, segmentation: np.ndarray | None):
        self.stamp = float(rec["stamp"])
        self.T_world_camera = np.array(rec["T_world_camera"], float)
        self.obstacles = tuple(self.Obstacle(o) for o in rec["obstacles"])
        self.segmentation = segmentation


def _truth_for(truth: dict, root: Path, stamp: float) -> _Truth | None:
    keys = list(truth)
    k = min(keys, key=lambda s: abs(s - stamp)) if keys else None
    if k is None or abs(k - stamp) > 5e-4:  # the truth of this frame (stamps rounded to 1 us, or exact)
        return None
    rec = truth[k]
    seg_png = root / "segmentation" / f"{int(rec['seq']):06d}.png"
    seg = cv2.imread(str(seg_png), cv2.IMREAD_UNCHANGED) if seg_png.is_file() else None
    return _Truth(rec, None if seg is None else seg.astype(np.int32) - 1)


def _box_edges() -> list[tuple[int, int]]:
    return [(a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]


EDGES = _box_edges()


def annotate(image: np.ndarray, result, frame, boxes_2d=None) -> np.ndarray:
    """The frame's image (BGR) with the tracked obstacles' boxes and the 2D person boxes drawn."""
    K = frame.intrinsics
    T = np.asarray(frame.T_world_camera, float)
    R, t = T[:3, :3], T[:3, 3]
    out = image.copy()
    for b in (boxes_2d if boxes_2d is not None else ()):
        x1, y1, x2, y2 = (int(round(v)) for v in b)
        cv2.rectangle(out, (x1, y1), (x2, y2), (0, 215, 255), 1)
    for o in result.obstacles:
        lo, hi = o.center - o.size / 2, o.center + o.size / 2
        corners = np.array([[(lo, hi)[(i >> 0) & 1][0], (lo, hi)[(i >> 1) & 1][1], (lo, hi)[(i >> 2) & 1][2]]
                            for i in range(8)])
        pc = (corners - t) @ R
        if np.any(pc[:, 2] < 0.1):
            continue  # reaching behind the camera
        uv = np.stack([K.fx * pc[:, 0] / pc[:, 2] + K.cx, K.fy * pc[:, 1] / pc[:, 2] + K.cy], axis=1)
        if not np.all(np.isfinite(uv)) or np.abs(uv).max() > 1e5:
            continue
        color = (40, 40, 230) if o.dynamic else (60, 190, 60)
        thick = 1 if o.coasting else 2
        for a, b in EDGES:
            cv2.line(out, tuple(int(round(v)) for v in uv[a]), tuple(int(round(v)) for v in uv[b]), color, thick)
        speed = float(np.hypot(*o.velocity[:2]))
        label = f"{o.id}{' P' if o.is_person else ''} {speed:.1f} m/s" if o.dynamic else f"{o.id}"
        top = uv[np.argmin(uv[:, 1])]
        cv2.putText(out, label, (int(top[0]), max(12, int(top[1]) - 4)), cv2.FONT_HERSHEY_SIMPLEX, 0.45, color, 1,
                    cv2.LINE_AA)
    cv2.putText(out, f"t {result.stamp:.3f} s" + (f"  skipped: {result.skipped}" if result.skipped else ""),
                (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return out


def _background(frame) -> np.ndarray:
    """The colour image as BGR, or the depth as a grey image when there is none."""
    if frame.color is not None:
        return cv2.cvtColor(frame.color, cv2.COLOR_RGB2BGR)
    d = frame.depth_m()
    g = np.clip(255 - d * (255 / 8.0), 0, 255).astype(np.uint8)
    g[d <= 0] = 0
    return cv2.cvtColor(g, cv2.COLOR_GRAY2BGR)


def _stats(values) -> dict:
    v = [x for x in values if x is not None and math.isfinite(x)]
    if not v:
        return {"median": None, "p95": None}
    return {"median": round(float(np.median(v)), 3), "p95": round(float(np.percentile(v, 95)), 3)}


def perceive(sequence: str | Path, out: str | Path, config: str = "dodt", assignments=(), intrinsics: str | None = None,
             fx=None, fy=None, cx=None, cy=None, depth_factor: float | None = None, poses: str | None = None,
             fit_floor: bool = False, camera_height: float | None = None, pitch: float | None = None,
             roll: float = 0.0, rate: float | None = None, max_frames: int | None = None, images: bool = False,
             video: bool = False, detector: str | None = None, detector_layout: str = "auto",
             person_class: int = 0, detector_input: tuple[int, int] | None = None,
             progress: bool = False, warn=None) -> dict:
    """Run DODT on a recorded sequence and write what the module docstring lists. Returns the
    summary. Mistakes in the options or the sequence raise a SequenceError naming them. ``warn``:
    called with each warning (one line) as it arises; the summary lists them too."""
    if rate is not None and not (math.isfinite(rate) and rate > 0):
        raise SequenceError(f"--rate: must be a frame rate above 0 Hz, got {rate}")
    if max_frames is not None and max_frames < 1:
        raise SequenceError(f"--max-frames: must be at least 1, got {max_frames}")
    if (camera_height is None) != (pitch is None):
        raise SequenceError("--camera-height and --pitch go together (a fixed camera's pose)")
    if camera_height is not None and (fit_floor or poses not in (None, "none")):
        raise SequenceError("--camera-height/--pitch give a fixed camera's pose: not with --fit-floor or --poses")
    if camera_height is not None and not (math.isfinite(camera_height) and camera_height > 0):
        raise SequenceError(f"--camera-height: must be above 0 m, got {camera_height}")
    cfg = build_config(config, assignments, detector, detector_layout, person_class, detector_input)
    seq = open_sequence(sequence, intrinsics, fx, fy, cx, cy, depth_factor,
                        "none" if camera_height is not None else poses, rate=rate)
    warnings: list[str] = []
    has_poses = any(r.T_world_camera is not None for r in seq.refs)
    fixed, transform, floor = None, None, None
    if camera_height is not None:
        fixed = camera_pose(camera_height, pitch, roll)
        pose_source = f"fixed: height {camera_height} m, pitch {pitch} deg, roll {roll} deg"
    elif fit_floor:
        fixed, transform, floor = _floor_pose(seq, has_poses)
        w = depth_scale_warning(floor["height_m"], 1.0 / seq.depth_scale)
        if w is not None:
            warnings.append(w)
            if warn is not None:
                warn(w)
        pose_source = ("floor fit, fixed camera" if fixed is not None else f"{seq.pose_source}, turned to the floor fit")
    elif has_poses:
        pose_source = seq.pose_source
    else:
        raise SequenceError(f"{seq.root}: no camera poses: give --poses FILE, --fit-floor (a fixed camera that sees the "
                            "floor), or --camera-height and --pitch")
    try:
        pipeline = DODT(cfg)
    except ValueError as e:  # a model that cannot be loaded, a configuration value out of range
        raise SequenceError(str(e)) from None
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if images:
        (out / "annotated").mkdir(exist_ok=True)
    truth = _truth_frames(seq.root)
    metrics = None
    if truth is not None:
        from experiments.perception_metrics import PerceptionMetrics

        metrics = PerceptionMetrics()
    writer = None
    slot = None  # (first stamp, next slot index) of the decimation to --rate
    read = processed = 0
    skipped: dict[str, int] = {}
    timings = {m: [] for m in MODULES + ("total",)}
    dynamic_ids, track_ids, frames_with_dynamic = set(), set(), 0
    stamps = []
    t_wall = time.perf_counter()
    with open(out / "tracks.jsonl", "w") as tracks_file, open(out / "timings.csv", "w", newline="") as tf:
        tw = csv.writer(tf)
        tw.writerow(["seq", "stamp"] + list(MODULES) + ["total"])
        need_color = cfg.learned.enabled or images or video
        for ref, frame in seq.frames(fixed_pose=fixed, pose_transform=transform, color=need_color):
            if rate is not None:
                t0, k = slot if slot is not None else (ref.stamp, 0)
                if ref.stamp < t0 + k / rate - 1e-6:
                    continue
                slot = (t0, int(math.floor((ref.stamp - t0) * rate + 1e-6)) + 1)
            read += 1
            if frame is None:
                continue
            try:
                r = pipeline.process(frame)
            except ValueError as e:  # a frame that does not fit the intrinsics or the pipeline's checks
                raise SequenceError(f"{ref.depth}: {e}") from None
            stamps.append(ref.stamp)
            if r.skipped:
                skipped[r.skipped] = skipped.get(r.skipped, 0) + 1
            else:
                processed += 1
                tw.writerow([ref.seq, repr(ref.stamp)] + [round(r.timings_ms.get(m, 0.0), 3) for m in MODULES]
                            + [round(r.timings_ms["total"], 3)])
                for m in timings:
                    timings[m].append(r.timings_ms.get(m, 0.0))
            tracks_file.write(json.dumps({"seq": ref.seq, "stamp": ref.stamp, "skipped": r.skipped,
                                          "bad_pixels": r.bad_pixels,
                                          "obstacles": [TrackReport.from_tracked(o).to_json() for o in r.obstacles]}) + "\n")
            dyn = [o.id for o in r.obstacles if o.dynamic]
            dynamic_ids.update(dyn)
            track_ids.update(o.id for o in r.obstacles)
            frames_with_dynamic += bool(dyn)
            if metrics is not None and not r.skipped:
                t = _truth_for(truth, seq.root, ref.stamp)
                if t is not None:
                    metrics.add(r, t, frame.intrinsics)
            if images or video:
                boxes = getattr(pipeline.learned_detector, "last_boxes_2d", None) if pipeline.learned_detector else None
                img = annotate(_background(frame), r, frame, boxes)
                if images:
                    cv2.imwrite(str(out / "annotated" / f"{ref.seq:06d}.png"), img)
                if video:
                    if writer is None:
                        fps = rate or _frame_rate([r_.stamp for r_ in seq.refs[:50]]) or 30.0
                        writer = cv2.VideoWriter(str(out / "annotated.mp4"), cv2.VideoWriter_fourcc(*"mp4v"),
                                                 float(fps), (img.shape[1], img.shape[0]))
                    writer.write(img)
            if progress and read % 100 == 0:
                print(f"  {read} frames", flush=True)
            if max_frames is not None and read >= max_frames:
                break
    if writer is not None:
        writer.release()
    wall = time.perf_counter() - t_wall
    summary = {
        "sequence": str(seq.root), "format": seq.format, "frames_listed": len(seq.refs), "frames_read": read,
        "frames_processed": processed, "skipped": dict(sorted(skipped.items())),
        "sequence_counters": dict(seq.counters), "pipeline_counters": dict(pipeline.counters),
        "frame_rate_hz": _frame_rate(stamps), "rate_asked_hz": rate, "stamps": seq.stamp_source,
        "intrinsics": asdict(seq.intrinsics), "depth_scale_m": seq.depth_scale, "poses": pose_source,
        "floor_fit": floor, "configuration": config, "set": list(assignments), "config": _jsonable(asdict(cfg)),
        # the first frame compiles the pipeline's numba kernels: not counted when there are others
        "timings_ms": {m: _stats(v[1:] if len(v) > 1 else v) for m, v in timings.items()},
        "tracks": len(track_ids), "dynamic_tracks": len(dynamic_ids), "frames_with_dynamic": frames_with_dynamic,
        "wall_time_s": round(wall, 2), "warnings": warnings,
    }
    if cfg.learned.enabled and not cfg.learned.model and seq.format in ("tum", "folder"):
        summary["note"] = ("the shipped person detector is trained on simulator renders only; on a real camera's "
                           "images bring a detector trained on real ones (--detector)")
    if metrics is not None:
        summary["metrics"] = _jsonable(metrics.summary())
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return summary


def _frame_rate(stamps) -> float | None:
    d = np.diff(np.asarray(stamps, float))
    d = d[d > 0]
    return round(float(1.0 / np.median(d)), 3) if len(d) else None


def _jsonable(x):
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, (np.floating, np.integer)):
        return _jsonable(x.item())
    return x


# --------------------------------------------------------------------------- command line


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().replace("x", ",").split(","))
    except ValueError:
        raise SequenceError(f"--detector-input: expected WIDTHxHEIGHT, got {text!r}") from None
    if not (1 <= w <= MAX_SIDE and 1 <= h <= MAX_SIDE):
        raise SequenceError(f"--detector-input: each side must be 1 to {MAX_SIDE} pixels, got {text!r}")
    return w, h


def add_parser(sub, real, whole, output_folder) -> None:
    """The ``perceive`` command's options (registered by experiments.commands.episode, which passes the
    command line's checked number types ``real`` and ``whole`` and its ``output_folder`` check: this module
    does not import the commands, which import it)."""
    p = sub.add_parser("perceive", help="run DODT on a recorded RGB-D sequence (TUM format, a simulate "
                                        "output or a folder of frames); write tracks, timings, a summary and "
                                        "annotated images")
    p.add_argument("sequence", help="a TUM RGB-D folder (rgb/, depth/, rgb.txt, depth.txt), a `dodt-nav simulate` "
                                    "output folder, or a folder of frames (depth/ 16-bit PNGs, rgb/ or color/ images "
                                    "of the same names; timestamps as file names, else give --rate). Colour must be "
                                    "registered to depth: the same size, pixel (u, v) of both images seeing the same "
                                    "point (e.g. a RealSense's colour aligned to depth); a colour image of another "
                                    "size is not used")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--config", default="dodt", help="a DODT configuration (default dodt; see dodt.presets)")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                   help="change one configuration value, e.g. --set kalman.q_pos=0.02 (repeatable)")
    p.add_argument("--intrinsics", default=None, metavar="FILE",
                   help="JSON {fx, fy, cx, cy[, depth_factor]} or a line 'fx fy cx cy' (default: the folder's "
                        "intrinsics.json)")
    for k in ("fx", "fy", "cx", "cy"):
        p.add_argument(f"--{k}", type=real(0.0, MAX_FOCAL, lo_open=True) if k in ("fx", "fy") else
                       real(-MAX_FOCAL, MAX_FOCAL), default=None, help=f"the depth camera's {k} [px]")
    p.add_argument("--depth-factor", type=real(0.0, MAX_DEPTH_FACTOR, lo_open=True), default=None,
                   help="depth units per metre (default: the intrinsics file's, else 5000 as in TUM RGB-D; "
                        "millimetre images: 1000). With --fit-floor a camera height outside "
                        f"{PLAUSIBLE_CAMERA_HEIGHT[0]:g}-{PLAUSIBLE_CAMERA_HEIGHT[1]:g} m is warned of: most likely a "
                        "wrong depth factor")
    p.add_argument("--poses", default=None, metavar="FILE",
                   help="camera poses, lines 'timestamp tx ty tz qx qy qz qw' (default: the folder's groundtruth.txt)")
    p.add_argument("--fit-floor", action="store_true",
                   help="the camera's height, pitch and roll from the floor in the first frames, a z-up world "
                        "(a fixed camera without poses; with poses, their world turned to the floor)")
    p.add_argument("--camera-height", type=real(0.0, 100.0, lo_open=True), default=None,
                   help="a fixed camera's height above the floor [m]")
    p.add_argument("--pitch", type=real(-90.0, 90.0), default=None, help="a fixed camera's tilt below the horizon [deg]")
    p.add_argument("--roll", type=real(-180.0, 180.0), default=0.0, help="a fixed camera's roll [deg] (default 0)")
    p.add_argument("--rate", type=real(0.0, 1000.0, lo_open=True), default=None, metavar="HZ",
                   help="frames with per-frame timestamps (TUM's lists, timestamp file names, a simulate output) "
                        "are decimated to this rate; a folder of frames without timestamps (depth/000123.png) was "
                        "recorded at this rate, its stamps are frame number / HZ")
    p.add_argument("--max-frames", type=whole(1), default=None, help="stop after this many frames")
    p.add_argument("--images", action="store_true", help="write annotated images into OUT/annotated/")
    p.add_argument("--video", action="store_true", help="write OUT/annotated.mp4")
    p.add_argument("--detector", default=None, metavar="ONNX",
                   help="a person detector to run (turns the learned module on): an ONNX export of a YOLOv8 / "
                        "YOLO11 / YOLOv5 / YOLOX model, or one of ours")
    p.add_argument("--detector-layout", default="auto", choices=("auto", "dodt", "yolov8", "yolov5", "yolox"),
                   help="the detector's output layout (default: told from its output)")
    p.add_argument("--person-class", type=whole(0, 100_000), default=0, help="the detector's person class (COCO: 0)")
    p.add_argument("--detector-input", default=None, metavar="WxH",
                   help="the detector's input size, for a model whose input size is not fixed")
    p.set_defaults(func=run_cli, output_folder=output_folder)


def run_cli(args) -> int:
    args.output_folder(args.out)  # refused before the sequence is read
    s = perceive(args.sequence, args.out, config=args.config, assignments=args.set, intrinsics=args.intrinsics,
                 fx=args.fx, fy=args.fy, cx=args.cx, cy=args.cy, depth_factor=args.depth_factor, poses=args.poses,
                 fit_floor=args.fit_floor, camera_height=args.camera_height, pitch=args.pitch, roll=args.roll,
                 rate=args.rate, max_frames=args.max_frames, images=args.images, video=args.video,
                 detector=args.detector, detector_layout=args.detector_layout, person_class=args.person_class,
                 detector_input=_size(args.detector_input) if args.detector_input else None, progress=True,
                 warn=lambda w: print(f"warning: {w}", file=sys.stderr, flush=True))
    skipped = ", ".join(f"{k} {v}" for k, v in s["skipped"].items()) or "none"
    print(f"{s['sequence']} ({s['format']}): {s['frames_read']} frames read, {s['frames_processed']} processed "
          f"(skipped: {skipped}; unreadable {s['sequence_counters']['unreadable']}, without a pose "
          f"{s['sequence_counters']['no_pose']}), {s['frame_rate_hz']} Hz (stamps: {s['stamps']}), poses: {s['poses']}")
    if s["floor_fit"]:
        f = s["floor_fit"]
        print(f"floor fit: camera {f['height_m']:.3f} m above the floor, pitch {f['pitch_deg']:.1f} deg, roll "
              f"{f['roll_deg']:.1f} deg ({f['inliers']} of {f['points']} points on the plane)")
    print(f"tracks {s['tracks']}, dynamic {s['dynamic_tracks']}, frames with a dynamic track "
          f"{s['frames_with_dynamic']}; per frame {s['timings_ms']['total']['median']} ms median, "
          f"{s['timings_ms']['total']['p95']} ms p95")
    if "metrics" in s:
        m = s["metrics"]
        print(f"against the ground truth: pos. err. {_f(m['pos_err'])} m, vel. err. {_f(m['vel_err'])} m/s, "
              f"FP {_f(100 * m['fp_rate'] if m['fp_rate'] is not None else None, 2)} %, recall 0.5-5 m "
              f"{_f(100 * m['recall'] if m['recall'] is not None else None, 1)} %, ID switches {m['id_switches']}, "
              f"static speed p95 {_f(m['static_speed_p95'])} m/s")
    if "note" in s:
        print(f"note: {s['note']}")
    print(f"wrote {args.out}/tracks.jsonl, timings.csv, summary.json" + (", annotated/" if args.images else "")
          + (", annotated.mp4" if args.video else ""))
    return 0


def _f(x, nd=3) -> str:
    return "n/a" if x is None else f"{x:.{nd}f}"
