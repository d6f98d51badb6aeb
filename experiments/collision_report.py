"""Why did the drone collide? One row per collision of a saved episode log (experiments.episode_log).

For each collision: the drone's horizontal speed, who closed the gap (the drone's and, for a person,
the person's velocity along the line between them: positive = moving toward the other), and, over the
``window`` seconds before it, the fraction of camera frames in which the person was inside the
horizontal view of a camera of the rig (or anywhere, with a LiDAR) within ``view_range``, tracked by
perception (a reported box centre within ``match`` metres) and reported as a moving obstacle. A person hit from outside the view was never
seen coming; one seen and reported moving points at the planner. ``person_min_speed``: the person's
lowest speed over the window (a walker standing, or slowing to turn, before walking into the drone).
``fault``: the collision's class (experiments.fault), where the log records the contact's velocity and
point. For every collision, ``off_heading``:
the angle (degrees) between the drone's horizontal motion and the camera's heading at the contact,
empty when the drone was at rest (0.1 m/s): over the half view, it flew where the camera did not look
(over 90, it was backing off).
Where the log's plan records hold the planner's ``threats`` (the default planner's shield), a person
collision also gets ``planner_knew``: the fraction of plans over the window at which the person's centre
lay inside a disc the planner kept its plan from, and ``known_for``: for how long before the contact
(s, at most the window) it had known them without a break (0 when not at the last plan). A person
known only a moment before was too close to stop for, whatever the planner; one known long before
points at the planner. Where the plan records also say whom the planner stopped remembering (the
shield's ``forgot``), ``forgot`` is the reason it last dropped a person predicted within ``lost_match``
metres of this one in the window (planner.shield.shield.FORGET_REASONS), and ``forgot_s`` how long before the
contact: a person forgotten as "seen_free" a moment before the contact was where the prediction was not.
``overruled``: the fraction of plans over the window the shield flew instead of the planner's (a status
``shield:...``): a drone walked into at rest after its stops and holds. For a person collision,
``flanked``: whether, ``flank_lead`` seconds before the contact, another person within ``flank_range`` of
the drone lay more than the fault rule's behind angle (120 deg) from this one as seen from the drone: one
ahead, one behind, every sideways motion toward both, and passive safety leaves only the hold.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from dodt.frames import CameraIntrinsics
from dodt.geometry import half_view, wrap_angle
from experiments.fault import AT_REST_SPEED, BEHIND_ANGLE, classify


def logged_half_view(header: dict) -> float:
    """The camera's horizontal half field of view (rad) from a log header's intrinsics; a log without
    them (written before 2026-11-27) was flown with the default camera (dodt.frames.CameraIntrinsics:
    the simulated D435 at 640x480, 39.7 degrees)."""
    return half_view(CameraIntrinsics(**header["camera"]) if isinstance(header.get("camera"), dict)
                     else CameraIntrinsics())


def _centre(person: dict) -> np.ndarray:
    return (np.asarray(person["lo"], float) + np.asarray(person["hi"], float)) / 2


def logged_views(header: dict) -> tuple[list[float], bool]:
    """(each camera's heading on the body [rad], whether a LiDAR sees all round) of the logged rig; a log
    without its sensors (written before 2026-11-28) was flown with the forward camera alone."""
    sensors = header.get("sensors") or [{"kind": "rgbd", "yaw": 0.0}]
    yaws = [math.radians(float(s.get("yaw", 0.0))) for s in sensors if s.get("kind") != "lidar"]
    return yaws or [0.0], any(s.get("kind") == "lidar" for s in sensors)


def _heading(frame: dict) -> float:
    """The camera's heading (rad) in a frame record: the body's x axis."""
    fwd = np.asarray(frame["R"], float).reshape(3, 3)[:2, 0]
    return math.atan2(fwd[1], fwd[0])


def logged_view_test(header: dict, half_fov: float | None = None):
    """(frame record, point (x, y)) -> whether the point lies inside the horizontal view of one of the
    logged rig's cameras from the frame's drone pose (any direction with a LiDAR). ``half_fov`` (rad):
    None, the logged camera's (logged_half_view)."""
    half = logged_half_view(header) if half_fov is None else half_fov
    yaws, all_round = logged_views(header)

    def test(frame: dict, q) -> bool:
        if all_round:
            return True
        bearing = math.atan2(q[1] - frame["p"][1], q[0] - frame["p"][0]) - _heading(frame)
        return any(abs(wrap_angle(bearing - y)) <= half for y in yaws)
    return test


def collision_rows(records: list[dict], window: float = 2.0, view_range: float = 5.0, match: float = 0.5,
                   half_fov: float | None = None, lost_match: float = 1.2, flank_range: float = 1.6,
                   flank_lead: float = 0.5) -> list[dict]:
    """The collisions of one episode's records, as dicts (see the module docstring). ``half_fov``
    (rad): the camera's half view; None: the logged camera's (logged_half_view)."""
    header = records[0]
    in_view = logged_view_test(header, half_fov)
    states = [r for r in records if r["k"] == "s"]
    frames = [r for r in records if r["k"] == "f"]
    plans = [r for r in records if r["k"] == "plan" and "threats" in r]
    statuses = [(r["t"], str(r.get("status", ""))) for r in records if r["k"] == "plan"]
    rows = []
    for c in (r for r in records if r["k"] == "collision"):
        t = c["t"]
        s = min(states, key=lambda r: abs(r["t"] - t)) if states else None
        v = np.asarray(s["v"], float)[:2] if s else np.zeros(2)
        row = {"seed": header.get("seed"), "t": round(t, 3), "kind": c["kind"], "other_id": c["other_id"],
               "position": [round(float(x), 2) for x in c["position"]], "drone_speed": round(float(np.hypot(*v)), 2)}
        if "v" in c:
            row["fault"] = classify(c["kind"], c["position"], c["v"], c.get("point"))
        last = min(frames, key=lambda r: abs(r["t"] - t)) if frames else None  # the frame of the contact
        if last is not None and float(np.hypot(*v)) > AT_REST_SPEED:  # at rest: no direction of motion
            fwd = _heading(last)
            row["off_heading"] = round(math.degrees(abs(wrap_angle(math.atan2(v[1], v[0]) - fwd))), 1)
        recent = [st for (pt, st) in statuses if t - window <= pt <= t]
        if recent:
            row["overruled"] = round(sum(st.startswith("shield:") for st in recent) / len(recent), 2)
        if c["kind"] == "person" and frames:
            seen, tracked, moving, speeds, where = [], [], [], [], []
            for f in (f for f in frames if t - window <= f["t"] <= t):
                person = next((q for q in f["people"] if q["id"] == c["other_id"]), None)
                if person is None:
                    continue
                centre = _centre(person)[:2]
                where.append((f["t"], centre))
                speeds.append(float(np.hypot(*np.asarray(person["v"], float)[:2])))
                d = centre - np.asarray(f["p"], float)[:2]
                seen.append(in_view(f, centre) and float(np.hypot(*d)) <= view_range)
                near = [tr for tr in f["tracks"] if float(np.hypot(*(np.asarray(tr["center"][:2]) - centre))) <= match]
                tracked.append(bool(near))
                moving.append(any(tr.get("dynamic") for tr in near))
            person = next((q for q in last["people"] if q["id"] == c["other_id"]), None)
            if person is not None and s is not None:
                d = _centre(person)[:2] - np.asarray(s["p"], float)[:2]
                u = d / max(float(np.hypot(*d)), 1e-9)
                pv = np.asarray(person["v"], float)[:2]
                row.update(drone_closing=round(float(v @ u), 2), person_closing=round(float(-pv @ u), 2))
            n = max(len(seen), 1)
            row.update(in_view=round(sum(seen) / n, 2), tracked=round(sum(tracked) / n, 2),
                       reported_moving=round(sum(moving) / n, 2))
            if speeds:
                row["person_min_speed"] = round(min(speeds), 2)
            row.update(_flanked(frames, c["other_id"], t - flank_lead, flank_range))
            row.update(_planner_knew(plans, where, t, window))
            row.update(_forgot(plans, where, t, window, lost_match))
        rows.append(row)
    return rows


def _flanked(frames: list[dict], pid, t: float, reach: float) -> dict:
    """flanked of a collision with person ``pid`` (module docstring), from the frame nearest t: {} when
    that person is not in it or not within reach of the drone."""
    f = min(frames, key=lambda r: abs(r["t"] - t))
    p = np.asarray(f["p"], float)[:2]
    bearings, own = [], None
    for q in f["people"]:
        d = _centre(q)[:2] - p
        if float(np.hypot(*d)) > reach:
            continue
        if q["id"] == pid:
            own = math.atan2(d[1], d[0])
        else:
            bearings.append(math.atan2(d[1], d[0]))
    if own is None:
        return {}
    return {"flanked": int(any(abs(wrap_angle(b - own)) > BEHIND_ANGLE for b in bearings))}


def _centre_at(where: list[tuple[float, np.ndarray]], t: float) -> np.ndarray:
    """The person's centre in the frame nearest to time t (``where``: frame time, centre)."""
    return min(where, key=lambda w: abs(w[0] - t))[1]


def _planner_knew(plans: list[dict], where: list[tuple[float, np.ndarray]], t: float, window: float) -> dict:
    """planner_knew and known_for of a person collision at t (module docstring), from the person's centre
    in the window's frames (``where``: frame time, centre); {} without threats or frames."""
    if not where:
        return {}
    known, stamps = [], []
    for p in (p for p in plans if t - window <= p["t"] <= t):
        x, y = _centre_at(where, p["t"])
        known.append(any(math.hypot(x - d[0], y - d[1]) <= d[2] for d in p["threats"]))
        stamps.append(p["t"])
    if not known:
        return {}
    trailing = len(known) - next((k for k in range(len(known) - 1, -1, -1) if not known[k]), -1) - 1
    return {"planner_knew": round(sum(known) / len(known), 2),
            "known_for": round(t - stamps[-trailing], 2) if trailing else 0.0}


def _forgot(plans: list[dict], where: list[tuple[float, np.ndarray]], t: float, window: float,
            lost_match: float) -> dict:
    """forgot and forgot_s of a person collision at t (module docstring); {} when no plan record says so."""
    if not where:
        return {}
    for p in reversed(plans):  # the log's plans are in time order: the latest first
        if p["t"] > t or not p.get("forgot"):
            continue
        if p["t"] < t - window:
            break
        x, y = _centre_at(where, p["t"])
        near = [g for g in p["forgot"] if math.hypot(x - g[0], y - g[1]) <= lost_match]
        if near:
            return {"forgot": near[0][2], "forgot_s": round(t - p["t"], 2)}
    return {}


def logs_under(path: Path) -> list[Path]:
    """An episode log itself, the log of a run folder, or every episode log of a sweep folder."""
    path = Path(path)
    if path.is_file():
        return [path]
    if (path / "log.jsonl.gz").is_file():
        return [path / "log.jsonl.gz"]
    found = sorted(path.glob("episodes/*/log.jsonl.gz"))
    if not found:
        raise ValueError(f"{path}: no episode log (log.jsonl.gz) and no sweep episodes/ with logs")
    return found


def format_table(rows: list[dict]) -> str:
    cols = ["seed", "t", "kind", "other_id", "fault", "drone_speed", "off_heading", "drone_closing",
            "person_closing", "person_min_speed", "in_view", "tracked", "reported_moving", "planner_knew", "known_for",
            "forgot", "forgot_s", "overruled", "flanked"]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        lines.append("| " + " | ".join("" if r.get(k) is None else str(r[k]) for k in cols) + " |")
    return "\n".join(lines)
