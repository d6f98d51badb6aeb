"""`dodt-nav simulate`: fly a scenario headless and write what the camera saw and the truth.

Output folder:
    depth/NNNNNN.png         16-bit depth in millimetres (0 = invalid), as a RealSense gives it
    color/NNNNNN.png         8-bit color aligned to depth
    segmentation/NNNNNN.png  16-bit obstacle id + 1 (0 = nothing, 1 = floor/walls, k+1 = obstacle k)
    sensor.json              intrinsics and, per frame, stamp and odometry camera pose
    ground_truth.json        per frame: true camera pose, obstacles (id, kind, box, velocity);
                             collision events
    summary.json             scenario, seed, frames, collisions, clearance, timing

With ``fmt = "tum"`` the camera's frames are written as a TUM RGB-D sequence instead
(experiments.sequences.TumWriter: rgb/, depth/ at 5000 per metre, rgb.txt, depth.txt,
groundtruth.txt with the true camera poses, odometry.txt with the poses the frames carry,
intrinsics.json), beside segmentation/, ground_truth.json and summary.json as above: `dodt-nav
perceive` reads it like a recording and scores it against the truth.
"""
from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path

import cv2
import numpy as np

from experiments.pcd import write_scan
from experiments.sequences import TumWriter, matrix_to_quaternion
from sim import World, load_scenario
from sim.rig import frames_per_scan, lidars, rig
from sim.trajectories import scenario_reference


def simulate(scenario_name: str, seed: int | None, out: Path, duration: float | None = None,
             save_every: int = 1, renderer: str | None = None, segmentation: bool = True, fmt: str = "dodt",
             lidar: bool = False) -> dict:
    """``lidar``: also a Mid-360-like LiDAR on top of the body (sim.rig's ``lidar`` rig), scanned at its rate
    and written as PCD files (lidar/NNNNNN.pcd, binary, the sensor frame with the scan's pose as the
    VIEWPOINT) with lidar.txt: one line 'stamp tx ty tz qx qy qz qw file' per scan (the pose from odometry)."""
    if fmt not in ("dodt", "tum"):
        raise ValueError(f"unknown output format {fmt!r}; known: dodt, tum")
    sc = load_scenario(scenario_name)
    seed = sc.seed if seed is None else seed
    duration = sc.duration if duration is None else duration
    out.mkdir(parents=True, exist_ok=True)
    for sub in ("depth", "color", "segmentation") if fmt == "dodt" else ("segmentation",):
        (out / sub).mkdir(exist_ok=True)
    t_wall = time.perf_counter()
    world = World(sc, seed=seed, renderer=renderer, segmentation=segmentation)
    tum = TumWriter(out, world.intrinsics) if fmt == "tum" else None
    ref_at = scenario_reference(sc)
    sensor_frames, truth_frames = [], []
    scans = LidarWriter(out, sc.rates.camera) if lidar else None
    frame = world.latest_frame()
    n_steps = int(round(duration / (world.dt * world.steps_per_control)))
    for k in range(n_steps + 1):
        if scans is not None and frame is not None:
            scans.add(world, frame.seq)
        if frame is not None and frame.seq % save_every == 0:
            truth = world.ground_truth()
            if tum is not None:
                tum.add(frame, truth.T_world_camera)
                _save_truth(out, truth, truth_frames, exact=True)
            else:
                _save_frame(out, frame, truth, sensor_frames, truth_frames)
        if k == n_steps:
            break
        frame = world.step(ref_at(world.time))
    wall = time.perf_counter() - t_wall
    st = world.state()
    K = world.intrinsics
    if scans is not None:
        scans.close()
    if tum is not None:
        tum.close()
    else:
        (out / "sensor.json").write_text(json.dumps({
            "intrinsics": asdict(K), "depth_scale": 0.001, "frames": sensor_frames}, indent=1))
    (out / "ground_truth.json").write_text(json.dumps({
        "frames": truth_frames, "collisions": [c.to_json() for c in world.collisions]}, indent=1))
    summary = {
        "scenario": sc.name, "source": sc.source, "seed": seed, "sim_time": round(world.time, 4),
        "format": fmt, "frames_saved": len(truth_frames), "renderer": world.renderer,
        "lidar_scans_saved": 0 if scans is None else scans.count,
        "collided": world.collided, "collision_count": len(world.collisions),
        "min_clearance": {k: round(v, 4) for k, v in world.min_clearance.items()},
        "final_position": np.round(st.position, 4).tolist(),
        "wall_time_s": round(wall, 3), "real_time_factor_incl_png_writing": round(world.time / wall, 3),
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    world.close()
    return summary


class LidarWriter:
    """The scans of a LiDAR on top of the body, one every camera_rate / scan_rate camera frames."""

    def __init__(self, out: Path, camera_rate: float):
        mount = lidars(rig("lidar"))[0]
        self.model, self.T_body = mount.lidar_model(), mount.T_body_lidar()
        self.every = frames_per_scan(camera_rate, self.model)
        self.dir = out / "lidar"
        self.dir.mkdir(exist_ok=True)
        self.lines = ["# stamp tx ty tz qx qy qz qw file (the LiDAR's pose from odometry; points in its frame)"]
        self.count = 0
        self.out = out

    def add(self, world, seq: int) -> None:
        if seq % self.every:
            return
        scan = world.lidar_scan(self.model, self.T_body, method="auto")
        name = f"lidar/{self.count:06d}.pcd"
        write_scan(self.out / name, scan)
        T = scan.T_world_sensor
        q = matrix_to_quaternion(T[:3, :3])  # x, y, z, w
        self.lines.append(f"{scan.stamp:.6f} " + " ".join(f"{v:.6f}" for v in (*T[:3, 3], *q)) + f" {name}")
        self.count += 1

    def close(self) -> None:
        (self.out / "lidar.txt").write_text("\n".join(self.lines) + "\n")


def _save_frame(out: Path, frame, truth, sensor_frames: list, truth_frames: list) -> None:
    name = f"{frame.seq:06d}.png"
    cv2.imwrite(str(out / "depth" / name), frame.depth)
    if frame.color is not None:
        cv2.imwrite(str(out / "color" / name), cv2.cvtColor(frame.color, cv2.COLOR_RGB2BGR))
    sensor_frames.append({"seq": frame.seq, "stamp": round(frame.stamp, 6), "depth": f"depth/{name}",
                          "color": f"color/{name}" if frame.color is not None else None,
                          "T_world_camera": np.round(frame.T_world_camera, 6).tolist()})
    _save_truth(out, truth, truth_frames)


def _save_truth(out: Path, truth, truth_frames: list, exact: bool = False) -> None:
    """The frame's segmentation image and truth record; ``exact``: every number at full precision
    (the TUM export, which `perceive` scores to the benchmark's figures), not rounded."""
    if truth.segmentation is not None:
        cv2.imwrite(str(out / "segmentation" / f"{truth.seq:06d}.png"), (truth.segmentation + 1).astype(np.uint16))
    if not exact:
        truth_frames.append(truth.to_json())
        return
    vec = lambda a: [float(x) for x in np.ravel(a)]  # noqa: E731
    truth_frames.append({
        "stamp": float(truth.stamp), "seq": truth.seq, "T_world_camera": np.asarray(truth.T_world_camera, float).tolist(),
        "drone_position": vec(truth.drone_position), "drone_velocity": vec(truth.drone_velocity),
        "obstacles": [{"id": o.id, "kind": o.kind, "label": o.label, "aabb_min": vec(o.aabb_min),
                       "aabb_max": vec(o.aabb_max), "velocity": vec(o.velocity)} for o in truth.obstacles]})
