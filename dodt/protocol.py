"""The perception protocol: what a perception module implements to fly in the closed loop.

A perception module receives each sensor frame (dodt.frames.SensorFrame) and returns a
``PerceptionOutput``: the moving obstacles the planner avoids and the boxes the static map must clear.
DODT is one such module once wrapped (experiments.perception_modes.DODTPerception, which turns DODT's
own output, dodt.result.PerceptionResult, into a PerceptionOutput); any other detector and tracker is
another. A module's class plugs into every command as ``--perception module:Class`` (experiments.plugins;
built with no arguments) or into ``experiments.episode.run_episode(perception=...)`` as an instance.

The moving obstacles are ``planner.types.ObstaclePrediction``s, the planner's input type. This package
does not import the planner (it runs on its own on recorded frames), so the field is typed loosely here.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from dodt.frames import SensorFrame


@dataclass(frozen=True, eq=False)
class PerceptionOutput:
    """What a perception module reports for one frame."""

    stamp: float  # s, sim or sensor time of the frame the output describes
    obstacles: tuple[Any, ...]  # planner.types.ObstaclePrediction each: moving obstacles, state at ``stamp``
    clear_boxes: tuple[tuple[np.ndarray, np.ndarray], ...] = ()  # (center (3,), size (3,)) [m] the map must free
    tracks: list[dict] = field(default_factory=list)  # everything reported, JSON-ready, for the episode log
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

    def reset(self) -> None: ...

    def update(self, frame: SensorFrame, truth=None) -> PerceptionOutput: ...
