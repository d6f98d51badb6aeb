"""The closed loop's own settings (configuration section ``episode``), checked where they are made."""
from __future__ import annotations

from dataclasses import dataclass

from experiments.config_limits import MAX_FRAME_LATENCY, STATIC_MAPS, check_config

__all__ = ["EpisodeConfig", "MAX_FRAME_LATENCY", "STATIC_MAPS"]


@dataclass(frozen=True)
class EpisodeConfig:
    plan_rate: float = 10.0  # Hz; reference planners replan at 10-20 Hz
    map_every: int = 2  # camera frames per map update: 15 Hz at 30 Hz (reference map timer: 20 Hz)
    max_yaw_rate: float = 1.2  # rad/s, heading changes toward the planner's yaw
    # s: the controller's acceleration feedforward is the plan's this much ahead (experiments.follower); ours: the
    # sim's attitude loop (sim.controller, 18 rad/s, damping 0.85) tilts that late, and a stop fed forward without
    # lead leaves the drone tilted at zero speed, moving back at 0.13-0.18 m/s
    accel_lead: float = 0.08
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
    # the drone's sensors (sim.rig): front (the paper's forward camera), front_back, surround4, lidar,
    # lidar_below; None: the scenario's [[sensors]] if it declares them, else front
    rig: str | None = None

    def __post_init__(self):
        # each value's type and range: experiments.config_limits, the one table of the configuration's limits
        check_config("episode", self)
