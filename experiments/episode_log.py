"""The episode log: one gzip-compressed JSON record per line, written as the episode runs.

Record kinds (field ``k``):
- ``header``: scenario, seed, perception, planner, duration, rates, corridor {length, width,
  height}, start, goal, map_resolution, map_origin, camera (its intrinsics: width, height, fx, fy,
  cx, cy; logs written before 2026-11-27 have none), static (truth boxes: id, kind, label, aabb_min,
  aabb_max), people [{id, height, sees_drone}].
- ``s`` (every control period): t, drone position p, velocity v, reference position r,
  clearance c = [static, person, structure] (m, capped at 9).
- ``f`` (every camera frame): t, drone position p, attitude R (3x3 row-major, body FLU -> world),
  tracks (perception's report: id, center, size, velocity, dynamic, coasting, ...), people from
  ground truth [{id, lo, hi, v}], perc_ms, map_ms (None when the map was not updated), skipped.
- ``plan`` (every planning period): t, status, ms (solve time), pos (every 2nd knot of the plan,
  starting at the current position), path (the global path, (K, 2), or None), n_obst, and, from a planner
  that says (the default one's shield), threats: [x, y, radius] of each reported or remembered person's
  disc it kept the plan from, at the plan's time.
- ``map`` (every ``map_snapshot_period``): the occupied voxels above the floor, as their change since
  the previous map record: added = the indices (i, j, k) occupied now and not then, removed = those
  occupied then and not now (the first record adds them all); ``map_snapshots`` rebuilds the full sets.
  Centre = map_origin + (index + 0.5) * map_resolution. (Logs written before 2026-11-27 hold the full
  set in every record, as voxels; ``map_snapshots`` reads both.)
- ``lidar`` (with a LiDAR in the rig, every ``map_snapshot_period``): t, pts: a scan's returns in the
  world frame, decimated to at most 1,500 points, rounded to the centimetre.
- ``collision``: t, kind (person | static | structure), other_id, position (the drone's), v (the
  drone's velocity), point (the point of the other body nearest the drone), other_v (the other
  body's velocity): what experiments.fault classes the collision by.
- ``end``: t, reason (goal | timeout | crashed), reached_goal, time_to_goal.

Metrics and viewers read this file after the run (``read_log``, or ``iter_log`` one record at a
time); nothing computed during the run is needed to evaluate it. The records are written as they
come and none is kept in memory: an episode of an hour needs no more memory than one of a minute.
"""
from __future__ import annotations

import gzip
import json
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np


def r4(a) -> list:
    return [round(float(x), 4) for x in np.ravel(a)]


_KEY_BITS = 21  # voxel indices below 2^21 per axis (the map's grid is a few hundred cells a side)


def _keys(ijk: np.ndarray) -> np.ndarray:
    return (ijk[:, 0] << (2 * _KEY_BITS)) | (ijk[:, 1] << _KEY_BITS) | ijk[:, 2]


def _ijk(keys: np.ndarray) -> np.ndarray:
    mask = (1 << _KEY_BITS) - 1
    return np.column_stack([keys >> (2 * _KEY_BITS), (keys >> _KEY_BITS) & mask, keys & mask])


class MapChanges:
    """Makes the ``map`` records: the voxels that became occupied and those that stopped being occupied
    since the previous record. The map's occupied set (tens of thousands of voxels) changes little in a
    second: written whole every second it was half of a log's bytes and most of its writing time."""

    def __init__(self):
        self._prev = np.zeros(0, np.int64)

    def record(self, t: float, voxels: np.ndarray) -> dict:
        """The map record at ``t`` of the occupied voxel indices ``voxels`` (M, 3)."""
        ijk = np.asarray(voxels, dtype=np.int64).reshape(-1, 3)
        if ijk.size and (ijk.min() < 0 or ijk.max() >> _KEY_BITS):
            raise ValueError(f"map record at t = {t}: voxel indices outside [0, 2^{_KEY_BITS})")
        now = np.unique(_keys(ijk))
        added = np.setdiff1d(now, self._prev, assume_unique=True)
        removed = np.setdiff1d(self._prev, now, assume_unique=True)
        self._prev = now
        return {"k": "map", "t": t, "added": _ijk(added).tolist(), "removed": _ijk(removed).tolist()}


def map_snapshots(records) -> list[tuple[float, np.ndarray]]:
    """(t, occupied voxel indices (M, 3), sorted) at every map record of a log's records."""
    occupied: set = set()
    out = []
    for r in records:
        if r.get("k") != "map":
            continue
        if "voxels" in r:  # a log written before the records held changes
            occupied = set(map(tuple, r["voxels"]))
        else:
            occupied.difference_update(map(tuple, r["removed"]))
            occupied.update(map(tuple, r["added"]))
        out.append((r["t"], np.array(sorted(occupied), dtype=np.int64).reshape(-1, 3)))
    return out


class EpisodeLog:
    """Streams the records to a gzip JSON-lines file as they come. Without a path the file is a
    temporary one, removed by ``close()`` (the episode's metrics are read from it before:
    ``experiments.episode_metrics.summarize_log(log.finish())``)."""

    def __init__(self, path: Path | None = None):
        self._tmp = None
        if path is None:
            self._tmp = tempfile.mkdtemp(prefix="dodt-nav-log-")
            path = Path(self._tmp) / "log.jsonl.gz"
        self.path = Path(path)
        self._fh = gzip.open(self.path, "wt", encoding="utf-8", compresslevel=6)

    def add(self, record: dict) -> None:
        if self._fh is None:
            raise ValueError(f"{self.path}: the episode log is finished; no record can be added")
        self._fh.write(json.dumps(record, separators=(",", ":")))
        self._fh.write("\n")

    def finish(self) -> Path:
        """Ends the file (complete and readable from here on); returns its path."""
        if self._fh is not None:
            self._fh.close()
            self._fh = None
        return self.path

    def close(self) -> None:
        """Finishes the file; a temporary one is removed."""
        self.finish()
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None

    def __enter__(self) -> "EpisodeLog":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def iter_log(path: Path) -> Iterator[dict]:
    """The records of an episode log one at a time (a log cut short by a kill ends at its last
    complete record); a clear error when the file is not one."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such episode log")
    n = 0
    try:
        with gzip.open(path, "rt", encoding="utf-8") as fh:
            for line in fh:
                if not line.strip():
                    continue
                try:
                    record = json.loads(line)
                except json.JSONDecodeError as e:
                    raise ValueError(f"{path}: line {n + 1}: not JSON ({e.msg})") from None
                if n == 0 and (not isinstance(record, dict) or record.get("k") != "header"):
                    raise ValueError(f"{path}: not an episode log (no header record)")
                n += 1
                yield record
    except (OSError, EOFError) as e:
        if n == 0:
            raise ValueError(f"{path}: not a gzip-compressed episode log ({e})") from None
        # A log cut short (the run was killed): the complete records were given.
    if n == 0:
        raise ValueError(f"{path}: not an episode log (no header record)")


def read_log(path: Path) -> list[dict]:
    """All records of an episode log; a clear error when the file is not one."""
    return list(iter_log(path))
