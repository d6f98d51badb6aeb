"""The boundary between the closed loop and the modules it calls: nothing a planner or a perception module
does (raise, return the wrong thing) stops an episode or goes unreported.

- ``PlannerGuard``: a plan that raises or is not a well-formed ``Trajectory`` becomes a brake-and-hold
  trajectory (status ``error:<what>``), counted.
- ``PerceptionGuard``: an update that raises or is not a well-formed ``PerceptionOutput`` becomes a
  skipped frame (``error:<what>``), counted; the last good obstacles stay.
- ``ModuleErrors``: the counts and the first error of each module, with its traceback: printed once,
  written to the episode folder (``errors.txt``) and into the summary.
- ``planner_telemetry``: what a planner tells the log about its latest plan, through its one optional
  ``telemetry()`` method.
"""
from __future__ import annotations

import json
import math
import sys
import traceback
from dataclasses import dataclass, field, replace

import numpy as np

from dodt.context import reset_with_context
from dodt.protocol import PerceptionOutput, TrackReport
from planner.fallback import brake_and_hold
from planner.types import ObstaclePrediction, PlannerInput, Trajectory

DEFAULT_BRAKE_ACCEL = 2.0  # m/s^2: the brake-and-hold's deceleration for a planner that states none
MAX_TRAJECTORY_STEPS = 100_000  # steps of one plan: more is a runaway plan, refused before it is copied
MAX_OBSTACLES = 10_000  # obstacles or tracks of one perception output (a crowd is some hundreds)


class BadOutput(ValueError):
    """A module's output that does not follow its protocol; the message names the field."""


@dataclass
class ModuleErrors:
    """Errors of one module (``planner`` or ``perception``) in one episode."""

    module: str  # "planner" or "perception"
    label: str  # the module's name or spec
    count: int = 0
    first: str | None = None  # the first error's traceback (or the bad output's description)
    first_time: float | None = None  # s, sim time of the first error
    kinds: dict[str, int] = field(default_factory=dict)

    def add(self, t: float, kind: str, text: str) -> None:
        self.count += 1
        self.kinds[kind] = self.kinds.get(kind, 0) + 1
        if self.first is None:
            self.first, self.first_time = text, t
            print(f"{self.module} {self.label} failed at t = {t:.2f} s ({kind}); later failures are counted:\n"
                  f"{text.rstrip()}", file=sys.stderr, flush=True)

    def summary(self) -> dict:
        return {"count": self.count, "kinds": dict(self.kinds), "first_time": self.first_time,
                "first": self.first}


def _error_text(e: BaseException) -> str:
    return "".join(traceback.format_exception(type(e), e, e.__traceback__))


def _finite_array(a, shape_ok, what: str) -> np.ndarray:
    try:
        x = np.asarray(a, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise BadOutput(f"{what}: not an array of numbers ({type(a).__name__})") from None
    if not shape_ok(x.shape):
        raise BadOutput(f"{what}: wrong shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise BadOutput(f"{what}: holds NaN or infinite values")
    return x


def _finite_number(v, what: str) -> float:
    ok = not isinstance(v, bool) and isinstance(v, (int, float, np.floating, np.integer))
    try:
        x = float(v) if ok else math.nan
    except OverflowError:  # an int beyond any float
        x = math.nan
    if not math.isfinite(x):
        raise BadOutput(f"{what}: expected a finite number, got {v!r}"[:300])
    return x


def _whole_number(v, what: str) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not -2**63 <= v < 2**63:
        raise BadOutput(f"{what}: expected a whole number, got {v!r}"[:300])
    return int(v)


def _check_track(tr: TrackReport, what: str) -> None:
    """A track the log can write: an integer id, finite (3,) vectors, flags that are booleans."""
    _whole_number(tr.id, f"{what}.id")
    for name in ("center", "size", "velocity"):
        _finite_array(getattr(tr, name), lambda s: s == (3,), f"{what}.{name} (3,)")
    for name in ("acceleration", "filter_velocity"):
        if getattr(tr, name) is not None:
            _finite_array(getattr(tr, name), lambda s: s == (3,), f"{what}.{name} (3,)")
    for name in ("dynamic", "coasting") + (("is_person",) if tr.is_person is not None else ()):
        if not isinstance(getattr(tr, name), (bool, np.bool_)):
            raise BadOutput(f"{what}.{name}: expected true or false, got {getattr(tr, name)!r}"[:300])
    if tr.age is not None:
        _finite_number(tr.age, f"{what}.age")
    if type(tr) is TrackReport:  # its JSON form is made of the fields checked above, all writable
        return
    try:  # a subclass's may hold more
        json.dumps(tr.to_json(), allow_nan=False)
    except (TypeError, ValueError, OverflowError) as e:
        raise BadOutput(f"{what}: cannot be written to the log ({type(e).__name__}: {e})"[:300]) from None


def check_trajectory(traj) -> Trajectory:
    """``traj`` if it is a well-formed Trajectory (shapes, finite values, dt > 0); BadOutput otherwise."""
    if not isinstance(traj, Trajectory):
        raise BadOutput(f"plan() returned {type(traj).__name__}, not a planner.types.Trajectory")
    _finite_number(traj.t0, "Trajectory.t0")
    if not _finite_number(traj.dt, "Trajectory.dt") > 0.0:
        raise BadOutput(f"Trajectory.dt: expected seconds > 0, got {traj.dt!r}")
    a = _finite_array(traj.accelerations, lambda s: len(s) == 2 and s[1] == 3 and 1 <= s[0] <= MAX_TRAJECTORY_STEPS,
                      f"Trajectory.accelerations (N, 3) with 1 <= N <= {MAX_TRAJECTORY_STEPS}")
    n = a.shape[0]
    _finite_array(traj.positions, lambda s: s == (n + 1, 3), f"Trajectory.positions (N+1, 3) with N = {n}")
    _finite_array(traj.velocities, lambda s: s == (n + 1, 3), f"Trajectory.velocities (N+1, 3) with N = {n}")
    if traj.yaw is not None:
        _finite_number(traj.yaw, "Trajectory.yaw")
    _finite_number(traj.solve_ms, "Trajectory.solve_ms")
    if not isinstance(traj.status, str):
        raise BadOutput(f"Trajectory.status: expected a string, got {traj.status!r}")
    return traj


def planner_telemetry(planner) -> dict:
    """The planner's ``telemetry()`` (nothing for a planner without one): ``path`` (K, 2 or 3) or None,
    ``threats`` (M, 3) x, y, radius of the people it kept its plan from, ``forgotten`` [(x, y, why)],
    ``brake_accel`` m/s^2. Malformed entries are dropped, not raised."""
    get = getattr(planner, "telemetry", None)
    if not callable(get):
        return {}
    try:
        raw = get()
    except Exception:  # noqa: BLE001 - telemetry is a report, never a failure of the loop
        return {}
    if not isinstance(raw, dict):
        return {}
    out = {}
    p = _floats(raw.get("path"))
    if p is not None and p.ndim == 2 and p.shape[1] in (2, 3) and np.all(np.isfinite(p)):
        out["path"] = p
    th = _floats(raw.get("threats"))
    if th is not None and th.ndim == 2 and th.shape[1] == 3:
        out["threats"] = th[np.all(np.isfinite(th), axis=1)]
    gone = []
    for g in raw.get("forgotten") or ():
        try:
            x, y, why = g
            if math.isfinite(float(x)) and math.isfinite(float(y)):
                gone.append((float(x), float(y), str(why)))
        except (TypeError, ValueError):
            continue
    if gone:
        out["forgotten"] = gone
    b = raw.get("brake_accel")
    if isinstance(b, (int, float)) and not isinstance(b, bool) and math.isfinite(b) and b > 0:
        out["brake_accel"] = float(b)
    return out


def _floats(a) -> np.ndarray | None:
    """``a`` as a float array; None when it is None or not numbers."""
    if a is None:
        return None
    try:
        return np.asarray(a, dtype=float)
    except (TypeError, ValueError):
        return None


def _guarded(call, errors: ModuleErrors, stamp: float):
    """(``call()``, None), or (None, what went wrong) with the failure counted in ``errors``. A module's
    ``sys.exit`` (or any other exception outside the Exception family) is a failure like any other; only a
    keyboard interrupt goes through."""
    try:
        return call(), None
    except KeyboardInterrupt:
        raise
    except BadOutput as e:
        errors.add(stamp, "bad output", f"{e}\n")
        return None, "bad-output"
    except BaseException as e:  # noqa: BLE001 - a module's failure: the loop goes on without it
        errors.add(stamp, type(e).__name__, _error_text(e))
        return None, type(e).__name__


class PlannerGuard:
    """Calls ``planner.plan`` and returns a trajectory the loop can fly, whatever happens."""

    def __init__(self, planner, label: str):
        self.planner = planner
        self.errors = ModuleErrors("planner", label)

    def reset(self, context) -> None:
        """The planner's reset(context); a failure is counted, and the episode goes on (its plans are guarded)."""
        _guarded(lambda: reset_with_context(self.planner, context), self.errors, 0.0)

    def plan(self, inp: PlannerInput) -> Trajectory:
        traj, kind = _guarded(lambda: check_trajectory(self.planner.plan(inp)), self.errors, inp.stamp)
        if traj is not None:
            return traj
        brake = planner_telemetry(self.planner).get("brake_accel", DEFAULT_BRAKE_ACCEL)
        return brake_and_hold(inp.stamp, inp.position, inp.velocity, a_max=brake, status=f"error:{kind}")


def check_output(out) -> PerceptionOutput:
    """``out`` if it is a well-formed PerceptionOutput, its tracks as TrackReports (a plug-in may give their
    JSON form); BadOutput naming the field otherwise."""
    if not isinstance(out, PerceptionOutput):
        raise BadOutput(f"update() returned {type(out).__name__}, not a dodt.protocol.PerceptionOutput")
    _finite_number(out.stamp, "PerceptionOutput.stamp")
    for name in ("obstacles", "clear_boxes", "tracks"):
        seq = getattr(out, name)
        if isinstance(seq, (tuple, list)) and len(seq) > MAX_OBSTACLES:
            raise BadOutput(f"PerceptionOutput.{name}: {len(seq)} entries, more than {MAX_OBSTACLES}")
    if not isinstance(out.obstacles, (tuple, list)):
        raise BadOutput(f"PerceptionOutput.obstacles: expected a tuple, got {type(out.obstacles).__name__}")
    for i, o in enumerate(out.obstacles):
        if not isinstance(o, ObstaclePrediction):
            raise BadOutput(f"PerceptionOutput.obstacles[{i}]: {type(o).__name__}, not a "
                            f"planner.types.ObstaclePrediction")
        _whole_number(o.id, f"PerceptionOutput.obstacles[{i}].id")
        for name in ("center", "size", "velocity", "acceleration"):
            _finite_array(getattr(o, name), lambda s: s == (3,), f"PerceptionOutput.obstacles[{i}].{name} (3,)")
        for name in ("position_std", "std_growth", "accel_horizon", "max_speed"):
            _finite_number(getattr(o, name), f"PerceptionOutput.obstacles[{i}].{name}")
    if not isinstance(out.clear_boxes, (tuple, list)):
        raise BadOutput("PerceptionOutput.clear_boxes: expected a tuple of (center, size)")
    for i, box in enumerate(out.clear_boxes):
        if not (isinstance(box, (tuple, list)) and len(box) == 2):
            raise BadOutput(f"PerceptionOutput.clear_boxes[{i}]: expected (center (3,), size (3,))")
        for part, name in zip(box, ("center", "size")):
            _finite_array(part, lambda s: s == (3,), f"PerceptionOutput.clear_boxes[{i}] {name} (3,)")
    if not isinstance(out.tracks, (tuple, list)):
        raise BadOutput("PerceptionOutput.tracks: expected a tuple of dodt.protocol.TrackReport")
    tracks = []
    for i, tr in enumerate(out.tracks):
        if isinstance(tr, TrackReport):
            tracks.append(tr)
            continue
        if not isinstance(tr, dict):
            raise BadOutput(f"PerceptionOutput.tracks[{i}]: {type(tr).__name__}, not a TrackReport")
        try:
            tracks.append(TrackReport.from_json(tr))
        except (KeyError, TypeError, ValueError, OverflowError) as e:
            raise BadOutput(f"PerceptionOutput.tracks[{i}]: not a track ({type(e).__name__}: {e})") from None
    for i, tr in enumerate(tracks):
        _check_track(tr, f"PerceptionOutput.tracks[{i}]")
    if not isinstance(out.timings_ms, dict) or not all(
            isinstance(k, str) and isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
            for k, v in out.timings_ms.items()):
        raise BadOutput("PerceptionOutput.timings_ms: expected {stage name: finite milliseconds}")
    if out.skipped is not None and not isinstance(out.skipped, str):
        raise BadOutput(f"PerceptionOutput.skipped: expected a reason (text) or None, got {out.skipped!r}")
    return out if all(a is b for a, b in zip(tracks, out.tracks)) else replace(out, tracks=tuple(tracks))


class PerceptionGuard:
    """Calls ``perception.update`` and returns an output the loop can use, whatever happens."""

    def __init__(self, perception, label: str):
        self.perception = perception
        self.errors = ModuleErrors("perception", label)

    def reset(self, context) -> None:
        """The module's reset(context); a failure is counted, and the episode goes on (its updates are guarded)."""
        _guarded(lambda: reset_with_context(self.perception, context), self.errors, 0.0)

    def observe(self, method: str, data, stamp: float) -> None:
        """The module's ``observe_lidar(scan)`` or ``observe_cameras(frames)`` when it has one (a module
        without it reads the first camera alone); a failure is counted, and the episode goes on."""
        observe = getattr(self.perception, method, None)
        if callable(observe):
            _guarded(lambda: observe(data), self.errors, stamp)

    def update(self, frame, truth) -> PerceptionOutput:
        out, kind = _guarded(lambda: check_output(self.perception.update(frame, truth)), self.errors, frame.stamp)
        if out is not None:
            return out
        return PerceptionOutput(stamp=frame.stamp, obstacles=(), skipped=f"error:{kind}")
