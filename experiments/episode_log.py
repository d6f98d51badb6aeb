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


class EpisodeLog:
    """Streams the records to a gzip JSON-lines file as they come. Without a path the file is a
    temporary one, removed by ``close()`` (the episode's metrics are read from it before)."""

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

    def summarize(self) -> dict:
        """The episode's metrics (experiments.episode_metrics), read back from the finished file."""
        from experiments.episode_metrics import summarize_log

        return summarize_log(self.finish())

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
