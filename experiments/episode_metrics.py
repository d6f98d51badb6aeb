"""Episode metrics, computed from the log after the run (experiments.episode_log).

Outcome fields are deterministic for a scenario and seed; wall-clock figures (solve and
perception times, real-time factor) live under ``timing`` so comparisons can leave them out.
The records are read in one pass, one at a time (``summarize_log`` reads the file): what is kept
per record is one number (a step's length, a solve time), so the metrics of an hour's episode fit
in a few megabytes.

``min_clearance``: the least distance [m] from the drone's collision box to static obstacles
(``static``), to people (``person``) and to the corridor's walls, floor and ceiling (``structure``)
over the control periods, as the simulator measures them (exact below its 1 m reporting cap,
sim.world.CLEARANCE_CAP; the cap itself means "at least this far"), and the least of the three
(``overall``). ``structure`` leaves out the periods in which the drone is within ``END_ZONE_RADIUS``
(horizontally) of its start or its goal: both sit in front of the corridor's end walls (0.5 m off
in the shipped scenarios), and counted there the wall behind the drone at take-off would set it
in every episode, whatever the flight. It is None when the drone never left those zones. A touch
of any structure is a collision all the same (``collisions``).

``track_life``: the perception benchmark's track-life figures (experiments.perception_metrics.TrackLife)
from the frames' records: the tracks perception reported against the people of the ground truth, the
drone's position standing for the sensor's (continuity counts the people within 5 m of the drone).
With it, the time to moving (``moving_latency_*``, and the episode's ``moving_latencies`` to pool): for
each stretch in which a walking person is 0.5-5 m from the drone and inside the horizontal view of one
of the rig's cameras (any direction with a LiDAR; occlusion is not checked), the time from its first
such frame to the first in which a track labelled dynamic is matched to the person
(experiments.perception_metrics.MovingLatency): how long the planner flies before it avoids a person it
could see as a moving one.
"""
from __future__ import annotations

import math
from array import array
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from experiments.episode_log import iter_log
from experiments.fault import at_fault, classify
from experiments.collision_report import logged_view_test
from experiments.perception_metrics import RECALL_BINS, WALKING_SPEED, MovingLatency, PerceptionMetrics, TrackLife, \
    match_pairs

END_ZONE_RADIUS = 1.0  # m, horizontal, around the start and the goal: structure clearance is not counted there


def timing_stats(values) -> dict:
    """n, median, p95, p99, max of the finite values (rounded to 1e-3); {'n': 0} when there are none."""
    a = np.asarray([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    if a.size == 0:
        return {"n": 0}
    return {"n": int(a.size), "median": round(float(np.median(a)), 3), "p95": round(float(np.percentile(a, 95)), 3),
            "p99": round(float(np.percentile(a, 99)), 3), "max": round(float(a.max()), 3)}


def end_zones(header: dict) -> list[tuple[float, float]]:
    """The (x, y) centres of the zones around an episode's start and goal (those its header gives)."""
    return [(float(header[k][0]), float(header[k][1])) for k in ("start", "goal") if header.get(k) is not None]


def in_end_zone(p, zones) -> bool:
    """Whether position ``p`` lies within END_ZONE_RADIUS, horizontally, of one of ``zones`` (end_zones)."""
    return any(math.hypot(p[0] - x, p[1] - y) <= END_ZONE_RADIUS for x, y in zones)


IN_REACH = (RECALL_BINS[0], PerceptionMetrics.table_range)  # m from the drone: the perception benchmark's range


def _in_view_latency(latency: MovingLatency, r: dict, people: list, in_view, match_distance: float) -> None:
    """The time to moving's bookkeeping for a frame record ``r`` whose people are ``people`` ((id, centre)
    each, in the record's order); ``in_view``: collision_report.logged_view_test's."""
    if "R" not in r or in_view is None:
        return
    dyn = [o["center"][:2] for o in r.get("tracks", ()) if o["dynamic"]]
    walking = []
    for (pid, c), o in zip(people, r.get("people", ())):
        v = o.get("v", (0.0, 0.0))
        d = math.dist(c, r["p"])
        if math.hypot(v[0], v[1]) > WALKING_SPEED and IN_REACH[0] <= d <= IN_REACH[1] and in_view(r, c):
            walking.append((pid, c[:2]))
    if not walking:
        return
    matched = {j for _, j in match_pairs(np.array(dyn, dtype=float).reshape(-1, 2),
                                         np.array([c for _, c in walking], dtype=float), match_distance)}
    for j, (pid, _) in enumerate(walking):
        latency.add(r["t"], pid, j in matched)


def summarize_log(path: Path) -> dict:
    """The metrics of the episode log at ``path``, read one record at a time."""
    return summarize(iter_log(path))


def _finite_times(values: array, v) -> None:
    if v is not None and math.isfinite(v):
        values.append(v)


def summarize(records: Iterable[dict]) -> dict:
    """The metrics of an episode's records (a list, or an iterator over a log file), in one pass."""
    header = end = None
    n_states, last_state_t, prev = 0, None, None
    zones, n_away = [], 0  # n_away: the states outside the end zones, those structure clearance counts
    steps = array("d")  # the length of every step of the path, summed at the end as numpy sums an array
    min_clear = [math.inf, math.inf, math.inf]
    statuses = {"plans": 0, "fallbacks": 0, "errors": 0}
    solve_ms, perc_ms, map_ms = array("d"), array("d"), array("d")
    n_frames = n_skipped = 0
    collisions = []
    life = TrackLife()
    latency, in_view = MovingLatency(), None
    for r in records:
        k = r["k"]
        if k == "s":
            n_states += 1
            last_state_t = r["t"]
            p = r["p"]
            if prev is not None:  # (sqrt of the squares summed in order: what the norm of an array's rows gives)
                dx, dy, dz = p[0] - prev[0], p[1] - prev[1], p[2] - prev[2]
                steps.append(math.sqrt(dx * dx + dy * dy + dz * dz))
            prev = p
            away = not in_end_zone(p, zones)
            n_away += away
            for i, c in enumerate(r["c"][:3]):
                if c < min_clear[i] and (i < 2 or away):
                    min_clear[i] = c
        elif k == "f":
            n_frames += 1
            n_skipped += bool(r.get("skipped"))
            _finite_times(perc_ms, r.get("perc_ms"))
            _finite_times(map_ms, r.get("map_ms"))
            if "p" in r:  # the drone's position, which the recorder writes with every frame
                people = [(o["id"], [(a + b) / 2 for a, b in zip(o["lo"], o["hi"])]) for o in r.get("people", ())]
                life.add(r["t"], r["p"], [(o["id"], o["center"], o.get("velocity", (0.0, 0.0, 0.0)), o["dynamic"])
                                          for o in r.get("tracks", ())], people)
                _in_view_latency(latency, r, people, in_view, life.match_distance)
        elif k == "plan":
            statuses["plans"] += 1
            statuses["fallbacks"] += r["status"].startswith("fallback")
            statuses["errors"] += r["status"].startswith("error")
            _finite_times(solve_ms, r.get("ms"))
        elif k == "collision":
            collisions.append(r)
        elif k == "end":
            end = r
        elif k == "header" and header is None:
            header = r
            zones = end_zones(header)
            in_view = logged_view_test(header)
    if header is None:
        raise ValueError("an episode's records start with its header")

    path_length = float(np.frombuffer(steps, dtype=float).sum()) if len(steps) else 0.0
    counted = (n_states, n_states, n_away)
    min_clear = {k: (round(float(min_clear[i]), 4) if counted[i] else None)
                 for i, k in enumerate(("static", "person", "structure"))}
    finite = [v for v in min_clear.values() if v is not None]
    min_clear["overall"] = min(finite) if finite else None

    reached = bool(end and end.get("reached_goal"))
    t_end = end["t"] if end else (last_state_t if n_states else 0.0)
    time_to_goal = end.get("time_to_goal") if reached else None
    flown = time_to_goal if reached else t_end
    collided = bool(collisions)
    rows = []
    for c in collisions:
        v = c.get("v")
        cls = classify(c["kind"], c["position"], v if v is not None else [math.nan] * 3, c.get("point"))
        rows.append({"t": c["t"], "kind": c["kind"], "other_id": c["other_id"], "fault": cls,
                     "drone_speed": None if v is None else round(float(np.linalg.norm(v)), 3)})
    n_at_fault = sum(at_fault(r["fault"]) for r in rows)
    failure = None  # a collision is named first: an episode that collided and then timed out failed by colliding
    if n_at_fault:
        failure = "at_fault_collision"
    elif collided:
        failure = "collision"
    elif end and end.get("reason") not in (None, "goal"):
        failure = end["reason"]
    return {
        "scenario": header["scenario"], "seed": header["seed"], "perception": header["perception"],
        "planner": header.get("planner"), "rig": header.get("rig", "front"),
        "static_map": header.get("static_map", "depth"),
        "frame_latency": header.get("frame_latency", 0),
        "people_see_drone": any(p.get("sees_drone", False) for p in header.get("people", [])),
        "success": reached and not collided,
        "reached_goal": reached, "collided": collided, "collision_count": len(collisions),
        "collisions": rows,
        # experiments.fault: an at-fault collision is the drone's; an episode with only not-at-fault ones was hit
        "at_fault": n_at_fault > 0, "at_fault_count": n_at_fault,
        "not_at_fault_only": collided and n_at_fault == 0,
        "timeout": bool(end and end.get("reason") == "timeout"),
        "failure_reason": failure,
        "time_to_goal": None if time_to_goal is None else round(time_to_goal, 3),
        "path_length": round(path_length, 3),
        "mean_speed": round(path_length / flown, 3) if flown and flown > 0 else 0.0,
        "min_clearance": min_clear,
        "sim_time": round(t_end, 3),
        "planner_stats": statuses,
        "perception_stats": {"frames": n_frames, "skipped": n_skipped},
        "track_life": {**life.summary(), **{k: None if isinstance(v, float) and math.isnan(v) else v
                                            for k, v in latency.summary().items()},
                       "moving_latencies": [round(x, 4) for x in latency.latencies]},
        "timing": {
            "planner_solve_ms": timing_stats(solve_ms),
            "perception_ms": timing_stats(perc_ms),
            "map_update_ms": timing_stats(map_ms),
        },
    }
