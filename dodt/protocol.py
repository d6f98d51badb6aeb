"""The perception protocol: what a perception module implements to fly in the closed loop.

A perception module receives each sensor frame (dodt.frames.SensorFrame) and returns a
``PerceptionOutput``: the moving obstacles the planner avoids and the boxes the static map must clear.
DODT is one such module once wrapped (experiments.perception_modes.DODTPerception, which turns DODT's
own output, dodt.result.PerceptionResult, into a PerceptionOutput); any other detector and tracker is
another. A module's class plugs into every command as ``--perception module:Class`` (experiments.plugins;
built with no arguments, or with its configuration) or into ``experiments.episode.run_episode(perception=...)``
as an instance. Before each episode the loop calls ``reset(context)`` with the episode's
``dodt.context.EpisodeContext`` (the rig's camera models and mounts, the vehicle, read-only map views);
a ``reset()`` without a parameter is called without it.

The moving obstacles are ``planner.types.ObstaclePrediction``s, the planner's input type. This package
does not import the planner (it runs on its own on recorded frames), so the field is typed loosely here.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from dodt.context import EpisodeContext
from dodt.frames import SensorFrame
from dodt.result import TrackedObstacle


def _rounded(a) -> list[float]:
    """The values as floats rounded to 4 decimals (the log's precision)."""
    return [round(float(x), 4) for x in np.asarray(a, dtype=float).reshape(-1).tolist()]


@dataclass(frozen=True, eq=False)
class TrackReport:
    """One track a perception module reports for a frame: what the episode log, the viewers, the plots
    and the collision report read (its JSON form, ``to_json``, is the log's schema). World frame, SI.

    The optional fields are left out of the JSON when None.
    """

    id: int
    center: np.ndarray  # (3,) m
    size: np.ndarray  # (3,) m, full extents of the axis-aligned box
    velocity: np.ndarray  # (3,) m/s, the velocity reported (DODT: its filter's, whatever the label)
    dynamic: bool  # labelled a moving object
    coasting: bool = False  # not measured this frame: a prediction
    acceleration: np.ndarray | None = None  # (3,) m/s^2
    age: float | None = None  # s since the track began
    is_person: bool | None = None  # a person detector's label
    filter_velocity: np.ndarray | None = None  # (3,) m/s: the tracking filter's velocity, whatever the label

    def to_json(self) -> dict:
        out = {"id": int(self.id), "center": _rounded(self.center), "size": _rounded(self.size),
               "velocity": _rounded(self.velocity)}
        if self.acceleration is not None:
            out["acceleration"] = _rounded(self.acceleration)
        out.update(dynamic=bool(self.dynamic), coasting=bool(self.coasting))
        if self.age is not None:
            out["age"] = round(float(self.age), 3)
        if self.is_person is not None:
            out["is_person"] = bool(self.is_person)
        if self.filter_velocity is not None:
            out["filter_velocity"] = _rounded(self.filter_velocity)
        return out

    @classmethod
    def from_json(cls, d: dict) -> "TrackReport":
        """A record from its JSON form (a log's ``tracks`` entry); KeyError/ValueError when malformed."""
        def vec(key):
            v = d.get(key)
            return None if v is None else _vec3(v, key)

        return cls(id=int(d["id"]), center=_vec3(d["center"], "center"), size=_vec3(d["size"], "size"),
                   velocity=_vec3(d.get("velocity", (0.0, 0.0, 0.0)), "velocity"), dynamic=bool(d["dynamic"]),
                   coasting=bool(d.get("coasting", False)), acceleration=vec("acceleration"),
                   age=None if d.get("age") is None else float(d["age"]),
                   is_person=None if d.get("is_person") is None else bool(d["is_person"]),
                   filter_velocity=vec("filter_velocity"))

    @classmethod
    def from_tracked(cls, o: TrackedObstacle) -> "TrackReport":
        """DODT's track as reported (its filter velocity stands in for the label's where it has none)."""
        return cls(id=o.id, center=o.center, size=o.size, velocity=o.velocity, dynamic=o.dynamic,
                   coasting=o.coasting, acceleration=o.acceleration, age=o.age, is_person=o.is_person,
                   filter_velocity=o.velocity if o.filter_velocity is None else o.filter_velocity)


def _vec3(v, key: str) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{key}: expected 3 finite numbers, got {v!r}")
    return a


@dataclass(frozen=True, eq=False)
class PerceptionOutput:
    """What a perception module reports for one frame."""

    stamp: float  # s, sim or sensor time of the frame the output describes
    obstacles: tuple[Any, ...]  # planner.types.ObstaclePrediction each: moving obstacles, state at ``stamp``
    clear_boxes: tuple[tuple[np.ndarray, np.ndarray], ...] = ()  # (center (3,), size (3,)) [m] the map must free
    tracks: tuple[TrackReport, ...] = ()  # every track, moving or not, for the log, viewers and metrics
    timings_ms: dict[str, float] = field(default_factory=dict)  # wall time per stage (benchmarks)
    skipped: str | None = None  # why the frame was not processed, if it was not (bad data is skipped, not raised)


@runtime_checkable
class PerceptionModule(Protocol):
    """The closed loop calls ``reset()`` before an episode and ``update`` on every frame, in order.

    The attributes are optional for a plug-in (the defaults given): ``name`` (the class name) labels
    results; ``uses_ground_truth`` (False): ``update`` receives the simulator's truth of the frame
    (sim.ground_truth.GroundTruth) as ``truth``, else None; ``uses_images`` (True): False when ``update``
    reads neither depth nor colour (with a known static map the simulator then renders nothing);
    ``uses_color`` (True): False when it reads no colour (frames then come without one, and the gl
    renderer draws depth only).
    """

    name: str
    uses_ground_truth: bool
    uses_images: bool
    uses_color: bool

    def reset(self, context: EpisodeContext | None = None) -> None: ...

    def update(self, frame: SensorFrame, truth=None) -> PerceptionOutput: ...
