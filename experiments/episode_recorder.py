"""The episode recorder: the one writer of the episode log's records (experiments.episode_log stores and
reads them; its docstring lists the record kinds and their fields).

Each method writes one record kind from the loop's objects, so the loop itself holds no log schema.
"""
from __future__ import annotations

import math

import numpy as np

from dodt.frames import LidarScan
from dodt.protocol import PerceptionOutput
from experiments.episode_log import EpisodeLog, MapChanges, r4
from planner.types import Trajectory

CLEARANCE_CAP = 9.0  # m: clearances in the ``s`` records are capped here (farther is "far")
ABOVE_FLOOR = 0.1  # m: map snapshots keep the occupied voxels from this height up
LIDAR_POINTS = 1500  # points of a LiDAR scan kept in a ``lidar`` record


class EpisodeRecorder:
    def __init__(self, log: EpisodeLog, snapshot_period: float, map_changes_stop: bool):
        self.log = log
        self.snapshot_period = snapshot_period
        self.map_changes_stop = map_changes_stop  # a map known from the start never changes: one snapshot
        self._changes = MapChanges()
        self._next_snapshot = 0.0
        self._next_lidar = 0.0
        self._collisions = 0

    def header(self, **fields) -> None:
        self.log.add({"k": "header", **fields})

    def frame(self, stamp: float, truth, po: PerceptionOutput, perc_ms: float, map_ms: float | None) -> None:
        q = truth.T_world_body  # the drone at the frame's capture, as its truth and tracks
        people = [o for o in truth.obstacles if o.kind == "person"]
        self.log.add({"k": "f", "t": round(stamp, 4), "p": r4(q[:3, 3]), "R": r4(q[:3, :3]),
                      "tracks": [tr.to_json() for tr in po.tracks],
                      "people": [{"id": o.id, "lo": r4(o.aabb_min), "hi": r4(o.aabb_max), "v": r4(o.velocity[:2])}
                                 for o in people],
                      "perc_ms": round(perc_ms, 3), "map_ms": None if map_ms is None else round(map_ms, 3),
                      "skipped": po.skipped})

    def map_snapshot(self, t: float, vmap) -> None:
        """A ``map`` record when the snapshot period has passed."""
        if t < self._next_snapshot:
            return
        idx = vmap.occupied_indices()
        above_floor = idx[:, 2] * vmap.cfg.resolution + vmap.cfg.origin[2] >= ABOVE_FLOOR
        self.log.add(self._changes.record(round(t, 4), idx[above_floor]))
        self._next_snapshot = math.inf if self.map_changes_stop else t + self.snapshot_period

    def lidar(self, scan: LidarScan) -> None:
        """A ``lidar`` record (the scan's world points, decimated to LIDAR_POINTS, cm) at most once per
        snapshot period: what the HTML replay shows of the LiDAR."""
        if scan.stamp < self._next_lidar:
            return
        step = max(1, -(-len(scan) // LIDAR_POINTS))
        points = scan.points_world()[::step]
        self.log.add({"k": "lidar", "t": round(scan.stamp, 4), "pts": np.round(points, 2).tolist()})
        self._next_lidar = scan.stamp + self.snapshot_period

    def plan(self, t: float, traj: Trajectory, n_obstacles: int, telemetry: dict) -> None:
        path = telemetry.get("path")
        rec = {"k": "plan", "t": round(t, 4), "status": traj.status, "ms": round(traj.solve_ms, 3),
               "pos": np.round(traj.positions[::2], 3).tolist(),
               "path": None if path is None else np.round(path, 2).tolist(), "n_obst": n_obstacles}
        if "threats" in telemetry:
            rec["threats"] = np.round(telemetry["threats"], 2).tolist()
            gone = [[round(x, 2), round(y, 2), why] for x, y, why in telemetry.get("forgotten", ())]
            if gone:
                rec["forgot"] = gone
        self.log.add(rec)

    def step(self, world, p_ref: np.ndarray) -> None:
        """The ``s`` record after a control step, and a ``collision`` record for each new contact."""
        cl = world.clearance_log[-1]
        after = world.state()
        self.log.add({"k": "s", "t": round(world.time, 5), "p": r4(after.position), "v": r4(after.velocity),
                      "r": r4(p_ref), "c": [round(min(x, CLEARANCE_CAP), 4) for x in cl[1:]]})
        for ev in world.collisions[self._collisions:]:
            self.log.add({"k": "collision", "t": round(ev.time, 5), "kind": ev.other_kind, "other_id": ev.other_id,
                          "position": r4(ev.position), "v": r4(ev.drone_velocity),
                          "point": None if ev.contact_point is None else r4(ev.contact_point),
                          "other_v": r4(ev.other_velocity)})
        self._collisions = len(world.collisions)

    def end(self, t: float, reason: str, time_to_goal: float | None) -> None:
        self.log.add({"k": "end", "t": round(t, 5), "reason": reason, "reached_goal": reason == "goal",
                      "time_to_goal": None if time_to_goal is None else round(time_to_goal, 5)})
