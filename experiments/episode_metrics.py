"""Episode metrics, computed from the log after the run (experiments.episode_log).

Outcome fields are deterministic for a scenario and seed; wall-clock figures (solve and
perception times, real-time factor) live under ``timing`` so comparisons can leave them out.
"""
from __future__ import annotations

import math

import numpy as np

from experiments.fault import at_fault, classify


def timing_stats(values) -> dict:
    """n, median, p95, p99, max of the finite values (rounded to 1e-3); {'n': 0} when there are none."""
    a = np.asarray([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    if a.size == 0:
        return {"n": 0}
    return {"n": int(a.size), "median": round(float(np.median(a)), 3), "p95": round(float(np.percentile(a, 95)), 3),
            "p99": round(float(np.percentile(a, 99)), 3), "max": round(float(a.max()), 3)}


def summarize(records: list[dict]) -> dict:
    header = records[0]
    end = next((r for r in reversed(records) if r["k"] == "end"), None)
    states = [r for r in records if r["k"] == "s"]
    plans = [r for r in records if r["k"] == "plan"]
    frames = [r for r in records if r["k"] == "f"]
    collisions = [r for r in records if r["k"] == "collision"]

    p = np.array([s["p"] for s in states]) if states else np.zeros((0, 3))
    path_length = float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()) if len(p) > 1 else 0.0
    clear = np.array([s["c"] for s in states]) if states else np.full((0, 3), np.inf)
    min_clear = {k: (round(float(clear[:, i].min()), 4) if len(clear) else None)
                 for i, k in enumerate(("static", "person", "structure"))}
    finite = [v for v in min_clear.values() if v is not None]
    min_clear["overall"] = min(finite) if finite else None

    reached = bool(end and end.get("reached_goal"))
    t_end = end["t"] if end else (states[-1]["t"] if states else 0.0)
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
    statuses = [pl["status"] for pl in plans]
    return {
        "scenario": header["scenario"], "seed": header["seed"], "perception": header["perception"],
        "planner": header.get("planner"), "static_map": header.get("static_map", "depth"),
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
        "planner_stats": {"plans": len(plans), "fallbacks": sum(s.startswith("fallback") for s in statuses),
                          "errors": sum(s.startswith("error") for s in statuses)},
        "perception_stats": {"frames": len(frames), "skipped": sum(1 for f in frames if f.get("skipped"))},
        "timing": {
            "planner_solve_ms": timing_stats(pl.get("ms") for pl in plans),
            "perception_ms": timing_stats(f.get("perc_ms") for f in frames),
            "map_update_ms": timing_stats(f.get("map_ms") for f in frames),
        },
    }
