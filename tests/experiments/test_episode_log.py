"""The episode log streamed to disk: nothing kept in memory while it is written, metrics computed from
the file in one pass, a temporary file when the episode has no output folder."""
from __future__ import annotations

import gzip
import json
import math
import tempfile
import tracemalloc

import numpy as np
import pytest

from conftest import make_scenario
from experiments.episode import EpisodeConfig, run_episode
from experiments.episode_log import EpisodeLog, MapChanges, iter_log, map_snapshots, read_log
from experiments.episode_metrics import summarize, summarize_log

HEADER = {"k": "header", "scenario": "s", "seed": 0, "perception": "oracle", "planner": "P", "people": []}


def _records(n_states: int):
    """A synthetic episode: a header, n_states control periods with a frame every 4th and a plan every
    12th, a collision, the end."""
    yield HEADER
    for i in range(n_states):
        t = i / 120
        yield {"k": "s", "t": t, "p": [0.01 * i, 0.5 * math.sin(i / 50), 1.2], "v": [1.2, 0.0, 0.0],
               "r": [0.01 * i, 0.0, 1.2], "c": [1.0, 0.5 + 0.4 * math.cos(i / 70), 0.9]}
        if i % 4 == 0:
            yield {"k": "f", "t": t, "perc_ms": 0.1 + (i % 7) * 0.01, "map_ms": None if i % 8 else 2.0,
                   "skipped": "no_depth" if i % 400 == 0 else None, "tracks": [], "people": []}
        if i % 12 == 0:
            yield {"k": "plan", "t": t, "status": "fallback:x" if i % 1200 == 0 else "solved", "ms": 5.0 + i % 11,
                   "pos": [], "path": None, "n_obst": 0}
        if i == n_states // 2:
            yield {"k": "collision", "t": t, "kind": "static", "other_id": 1, "position": [1.0, 0.0, 1.2],
                   "v": [1.0, 0.0, 0.0], "point": [1.3, 0.0, 1.2], "other_v": [0.0, 0.0, 0.0]}
    yield {"k": "end", "t": n_states / 120, "reason": "timeout", "reached_goal": False, "time_to_goal": None}


def _traced_peak(fn) -> int:
    """Bytes allocated by Python at the peak of fn(), above what was allocated before."""
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        fn()
        return tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()


@pytest.mark.slow
def test_writing_a_long_log_keeps_no_record_in_memory(tmp_path):
    """An hour at 120 Hz is 432,000 state records; 100,000 here. Kept in memory they took about 2.3 MiB
    per simulated second; streamed, what is allocated does not grow with their number."""
    def write(n):
        with EpisodeLog(tmp_path / f"{n}.jsonl.gz") as log:
            for r in _records(n):
                log.add(r)

    small, large = _traced_peak(lambda: write(1_000)), _traced_peak(lambda: write(100_000))
    assert large < small + 2**20, (small, large)
    assert sum(1 for _ in iter_log(tmp_path / "100000.jsonl.gz")) > 100_000


def test_metrics_from_the_file_in_one_pass_equal_those_of_the_records(tmp_path):
    path = tmp_path / "log.jsonl.gz"
    with EpisodeLog(path) as log:
        for r in _records(5_000):
            log.add(r)
    from_list = summarize(list(_records(5_000)))
    assert summarize_log(path) == from_list == summarize(iter(_records(5_000)))  # one pass over an iterator
    assert from_list["planner_stats"] == {"plans": 417, "fallbacks": 5, "errors": 0}
    assert from_list["perception_stats"] == {"frames": 1250, "skipped": 13}
    assert from_list["collision_count"] == 1 and from_list["timeout"] and from_list["sim_time"] == round(5000 / 120, 3)
    assert from_list["min_clearance"]["person"] == pytest.approx(0.1, abs=1e-3)


def _state(t, x, clearances):
    return {"k": "s", "t": t, "p": [x, 0.0, 1.2], "v": [1.0, 0.0, 0.0], "r": [x, 0.0, 1.2], "c": clearances}


def test_structure_clearance_leaves_out_the_zones_around_start_and_goal():
    """Start and goal sit 0.5 m in front of the corridor's end walls: the wall behind the drone at take-off
    is no close call, and the summary's structure clearance is what the flight came to."""
    head = dict(HEADER, start=[0.5, 0.0, 1.2], goal=[15.5, 0.0, 1.2])
    states = [_state(0.0, 0.5, [1.0, 1.0, 0.2449]),  # at the start: the end wall 0.24 m behind
              _state(1.0, 1.4, [1.0, 1.0, 0.5]),  # still within 1 m of the start
              _state(5.0, 6.0, [0.7, 0.9, 0.8]),  # mid-corridor, near a side wall
              _state(9.0, 15.2, [1.0, 1.0, 0.55])]  # arriving at the goal, before its end wall
    end = {"k": "end", "t": 9.0, "reason": "goal", "reached_goal": True, "time_to_goal": 9.0}
    mc = summarize([head, *states, end])["min_clearance"]
    assert mc == {"static": 0.7, "person": 0.9, "structure": 0.8, "overall": 0.7}
    # A drone that never left the start's zone has no structure clearance to report.
    mc = summarize([head, *states[:2], end])["min_clearance"]
    assert mc == {"static": 1.0, "person": 1.0, "structure": None, "overall": 1.0}
    # Records without a start or goal in their header leave nothing out.
    assert summarize([HEADER, *states, end])["min_clearance"]["structure"] == 0.2449


def test_metrics_of_a_long_log_need_no_memory_per_record(tmp_path):
    """Summarizing keeps one number per state (a step's length) and per timing, not the records."""
    def run(n):
        return lambda: summarize(_records(n))

    small, large = _traced_peak(run(1_000)), _traced_peak(run(100_000))
    assert large < small + 4 * 2**20, (small, large)  # 100,000 steps and 41,667 timings: about 1.1 MB


def test_a_finished_log_takes_no_more_records(tmp_path):
    log = EpisodeLog(tmp_path / "log.jsonl.gz")
    log.add(HEADER)
    assert log.finish() == tmp_path / "log.jsonl.gz"
    with pytest.raises(ValueError, match="finished"):
        log.add(HEADER)
    log.close()
    assert read_log(tmp_path / "log.jsonl.gz") == [HEADER]


def test_a_log_cut_short_gives_its_complete_records(tmp_path):
    path = tmp_path / "log.jsonl.gz"
    with gzip.open(path, "wt") as fh:
        for r in _records(2_000):
            fh.write(json.dumps(r) + "\n")
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])  # killed while writing
    recs = read_log(path)
    assert recs[0] == HEADER and 10 < len(recs) < 3_000
    s = summarize_log(path)  # without an end record: up to the last state
    assert s["sim_time"] == round([r for r in recs if r["k"] == "s"][-1]["t"], 3) and s["timeout"] is False


@pytest.mark.parametrize("content, message", [
    (b"not gzip", "not a gzip-compressed episode log"),
    (gzip.compress(b'{"k": "s"}\n'), "no header record"),
    (gzip.compress(b'[1, 2]\n'), "no header record"),
    (gzip.compress(b""), "no header record"),
    (gzip.compress(json.dumps(HEADER).encode() + b"\n{oops\n"), "line 2: not JSON"),
])
def test_what_is_not_an_episode_log_is_named(tmp_path, content, message):
    path = tmp_path / "log.jsonl.gz"
    path.write_bytes(content)
    with pytest.raises(ValueError, match=message) as e:
        summarize_log(path)
    assert str(path) in str(e.value)


def test_an_episode_without_an_output_folder_streams_to_a_temporary_file_and_removes_it(tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    s = run_episode(make_scenario(), seed=0, perception="oracle", cfg=EpisodeConfig(duration=1.0, static_map="truth"))
    assert s["sim_time"] == pytest.approx(1.0, abs=0.01) and s["planner_stats"]["plans"] == 10
    assert list(tmp_path.iterdir()) == []  # the temporary log is gone


def test_an_episode_summary_is_the_metrics_of_its_log_file(tmp_path):
    s = run_episode(make_scenario(), seed=0, perception="oracle", out=tmp_path,
                    cfg=EpisodeConfig(duration=1.0, static_map="truth"))
    again = summarize_log(tmp_path / "log.jsonl.gz")
    for key, value in again.items():
        if key != "timing":
            assert s[key] == value, key
    assert {k: v for k, v in s["timing"].items() if k in again["timing"]} == again["timing"]


def test_a_duration_that_is_not_a_number_of_seconds_is_refused(tmp_path):
    for bad in (math.nan, math.inf, -1.0, 0.0, 3601.0):
        with pytest.raises(ValueError, match="duration"):
            run_episode(make_scenario(), seed=0, perception="oracle", out=tmp_path / "x",
                        cfg=EpisodeConfig(duration=bad, static_map="truth"))


def test_map_records_hold_changes_and_rebuild_every_snapshot():
    """Each map record holds what changed since the previous one; map_snapshots rebuilds the full sets,
    sorted as the map lists them, and reads logs whose records hold the full set too."""
    rng = np.random.default_rng(1)
    grid = np.argwhere(np.ones((60, 20, 12), bool))
    sets = [grid[rng.random(len(grid)) < f] for f in (0.05, 0.06, 0.06, 0.0, 0.04)]
    sets[2] = sets[1]  # nothing changed
    changes = MapChanges()
    records = [HEADER] + [changes.record(float(t), s) for t, s in enumerate(sets)]
    as_set = lambda a: set(map(tuple, np.asarray(a).reshape(-1, 3).tolist()))  # noqa: E731
    assert as_set(records[1]["added"]) == as_set(sets[0]) and records[1]["removed"] == []
    assert as_set(records[2]["added"]) == as_set(sets[1]) - as_set(sets[0])
    assert as_set(records[2]["removed"]) == as_set(sets[0]) - as_set(sets[1])
    assert records[3]["added"] == [] and records[3]["removed"] == []
    assert records[4]["added"] == [] and as_set(records[4]["removed"]) == as_set(sets[2])
    snaps = map_snapshots(records)
    assert [t for t, _ in snaps] == [0.0, 1.0, 2.0, 3.0, 4.0]
    for (_, got), want in zip(snaps, sets):
        assert np.array_equal(got, want)
    # a record that holds the whole set (logs written before) replaces it
    old = records[:3] + [{"k": "map", "t": 9.0, "voxels": sets[4].tolist()}]
    assert np.array_equal(map_snapshots(old)[-1][1], sets[4])
    with pytest.raises(ValueError, match="voxel indices"):
        MapChanges().record(0.0, np.array([[-1, 0, 0]]))
