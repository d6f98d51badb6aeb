"""The closed loop's own settings (configuration section ``episode``), checked where they are made."""
from __future__ import annotations

import math
from dataclasses import dataclass

from sim.scenario import MAX_DURATION, RENDERER_CHOICES

STATIC_MAPS = ("depth", "truth")
MAX_FRAME_LATENCY = 100  # camera periods; the command line's --frame-latency has the same limit


@dataclass(frozen=True)
class EpisodeConfig:
    plan_rate: float = 10.0  # Hz; reference planners replan at 10-20 Hz
    map_every: int = 2  # camera frames per map update: 15 Hz at 30 Hz (reference map timer: 20 Hz)
    max_yaw_rate: float = 1.2  # rad/s, heading changes toward the planner's yaw
    map_snapshot_period: float = 1.0  # s between occupied-voxel snapshots in the log
    duration: float | None = None  # s; None: the scenario's duration
    # "depth": the static map is built from the camera's depth frames (the paper's setup); "truth": it holds
    # the scenario's static geometry from the start and depth is not used (sim.static_grid), which isolates
    # a planner from the mapping; with a perception mode that needs no images (the oracles, static-only)
    # nothing is rendered then, and an episode runs several times faster
    static_map: str = "depth"
    # camera periods between a frame's capture and its arrival at perception (stamps, poses and truth stay the
    # capture's; moving obstacles are extrapolated to the planning time). 1: the camera and perception pipeline's
    # delay, and with render_process the next frame renders in a second process while this one is perceived and
    # planned on (results bit-identical to rendering in one process with the same latency)
    frame_latency: int = 1
    render_process: bool = True
    seen_band: tuple[float, float] = (0.8, 1.6)  # m, world z: a ray crossing a floor cell at these heights saw
    # nobody there (the planner's seen space; a person's torso)
    launch_radius: float = 2.0  # m around the start that counts as seen free when the episode begins
    # the camera's renderer (sim.camera: auto, gl, pybullet, tiny); None: the scenario's. Changes the images
    # (gl and pybullet draw the same geometry, shaded differently), so outcomes are compared per renderer
    renderer: str | None = None

    def __post_init__(self):
        def bad(key, want, got):
            raise ValueError(f"episode.{key}: expected {want}, got {got!r}")

        if not (isinstance(self.plan_rate, (int, float)) and 0.1 <= self.plan_rate <= 100.0):
            bad("plan_rate", "Hz in [0.1, 100]", self.plan_rate)
        if not (isinstance(self.map_every, int) and 1 <= self.map_every <= 1000):
            bad("map_every", "a whole number of frames in [1, 1000]", self.map_every)
        if not (isinstance(self.max_yaw_rate, (int, float)) and 0.0 < self.max_yaw_rate <= 20.0):
            bad("max_yaw_rate", "rad/s in (0, 20]", self.max_yaw_rate)
        if not (isinstance(self.map_snapshot_period, (int, float)) and 0.05 <= self.map_snapshot_period <= 3600.0):
            bad("map_snapshot_period", "seconds in [0.05, 3600]", self.map_snapshot_period)
        if self.duration is not None and not (isinstance(self.duration, (int, float))
                                              and 0.0 < self.duration <= MAX_DURATION):
            bad("duration", f"seconds in (0, {MAX_DURATION:g}] or none", self.duration)
        if self.static_map not in STATIC_MAPS:
            bad("static_map", " or ".join(STATIC_MAPS), self.static_map)
        if not (isinstance(self.frame_latency, int) and 0 <= self.frame_latency <= MAX_FRAME_LATENCY):
            bad("frame_latency", f"a whole number of camera periods in [0, {MAX_FRAME_LATENCY}]", self.frame_latency)
        if not isinstance(self.render_process, bool):
            bad("render_process", "true or false", self.render_process)
        band = self.seen_band
        if not (len(band) == 2 and all(isinstance(z, (int, float)) and math.isfinite(z) for z in band)
                and 0.0 <= band[0] < band[1] <= 10.0):
            bad("seen_band", "[low, high] heights in metres with 0 <= low < high <= 10", list(band))
        if not (isinstance(self.launch_radius, (int, float)) and 0.0 <= self.launch_radius <= 100.0):
            bad("launch_radius", "metres in [0, 100]", self.launch_radius)
        if self.renderer is not None and self.renderer not in RENDERER_CHOICES:
            bad("renderer", f"one of {', '.join(RENDERER_CHOICES)} or none", self.renderer)
