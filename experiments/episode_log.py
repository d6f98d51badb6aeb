"""The episode log: one gzip-compressed JSON record per line, written as the episode runs.

Record kinds (field ``k``):
- ``header``: scenario, seed, perception, planner, duration, rates, corridor {length, width,
  height}, start, goal, map_resolution, map_origin, static (truth boxes: id, kind, label,
  aabb_min, aabb_max), people [{id, height, sees_drone}].
- ``s`` (every control period): t, drone position p, velocity v, reference position r,
  clearance c = [static, person, structure] (m, capped at 9).
- ``f`` (every camera frame): t, drone position p, attitude R (3x3 row-major, body FLU -> world),
  tracks (perception's report: id, center, size, velocity, dynamic, coasting, ...), people from
  ground truth [{id, lo, hi, v}], perc_ms, map_ms (None when the map was not updated), skipped.
- ``plan`` (every planning period): t, status, ms (solve time), pos (every 2nd knot of the plan,
  starting at the current position), path (the global path, (K, 2), or None), n_obst.
- ``map`` (every ``map_snapshot_period``): voxels = occupied voxel indices above the floor; centre =
  map_origin + (index + 0.5) * map_resolution.
- ``collision``: t, kind (person | static | structure), other_id, position (the drone's), v (the
  drone's velocity), point (the point of the other body nearest the drone), other_v (the other
  body's velocity): what experiments.fault classes the collision by.
- ``end``: t, reason (goal | timeout | crashed), reached_goal, time_to_goal.

Metrics and viewers read this file after the run (``read_log``); nothing computed during the
run is needed to evaluate it.
"""
from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np


def r4(a) -> list:
    return [round(float(x), 4) for x in np.ravel(a)]


class EpisodeLog:
    """Keeps the records in memory and, given a path, streams them to a gzip JSON-lines file."""

    def __init__(self, path: Path | None = None):
        self.records: list[dict] = []
        self.path = path
        self._fh = gzip.open(path, "wt", encoding="utf-8", compresslevel=6) if path is not None else None

    def add(self, record: dict) -> None:
        self.records.append(record)
        if self._fh is not None:
            self._fh.write(json.dumps(record, separators=(",", ":")))
            self._fh.write("\n")

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None


def read_log(path: Path) -> list[dict]:
    """All records of an episode log; a clear error when the file is not one."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such episode log")
    out = []
    try:
        with gzip.open(path, "rt", encoding="utf-8") as fh:
            for n, line in enumerate(fh, 1):
                if line.strip():
                    out.append(json.loads(line))
    except (OSError, EOFError) as e:
        if not out:
            raise ValueError(f"{path}: not a gzip-compressed episode log ({e})") from None
        # A log cut short (the run was killed): keep the complete records.
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: line {n}: not JSON ({e.msg})") from None
    if not out or out[0].get("k") != "header":
        raise ValueError(f"{path}: not an episode log (no header record)")
    return out
