"""experiments.collision_report and `dodt-nav collisions`: rows computed from hand-made episode records."""
import math
import gzip
import json

import numpy as np
import pytest

from experiments.cli import main
from experiments.collision_report import collision_rows, logged_half_view, logged_views

EYE = np.eye(3).ravel().tolist()  # heading +x


def _person(centre, v):
    x, y = centre
    return {"id": 5, "lo": [x - 0.25, y - 0.25, 0.0], "hi": [x + 0.25, y + 0.25, 1.7], "v": [v[0], v[1], 0.0]}


def _records():
    recs = [{"k": "header", "seed": 3}]
    recs += [{"k": "s", "t": t, "p": [0.0, 0.0, 1.2], "v": [1.0, 0.0, 0.0], "r": [0, 0, 1.2], "c": [1, 1, 1]}
             for t in np.arange(0.0, 2.01, 0.5)]
    for t in (0.5, 1.0, 1.5, 2.0):
        ahead = t <= 1.0  # 1 m ahead (in view, tracked moving), then 1 m to the right (out of view, untracked)
        centre = (1.0, 0.0) if ahead else (0.0, -1.0)
        tracks = [{"id": 1, "center": [centre[0], centre[1], 0.85], "dynamic": True}] if ahead else []
        recs.append({"k": "f", "t": t, "p": [0.0, 0.0, 1.2], "R": EYE, "tracks": tracks,
                     "people": [_person(centre, (0.0, 1.0))]})
    recs.append({"k": "collision", "t": 2.0, "kind": "person", "other_id": 5, "position": [0.0, 0.0, 1.2]})
    recs.append({"k": "collision", "t": 2.0, "kind": "static", "other_id": 2, "position": [0.0, 0.0, 1.2]})
    return recs


def test_rows_say_who_closed_in_and_whether_the_person_was_seen():
    person, static = collision_rows(_records())
    assert person["seed"] == 3 and person["kind"] == "person" and person["drone_speed"] == 1.0
    assert person["drone_closing"] == 0.0  # the drone flies along x; the person is beside it
    assert person["person_closing"] == 1.0  # walking straight at the drone
    assert person["in_view"] == person["tracked"] == person["reported_moving"] == 0.5
    assert collision_rows(_records(), window=0.9)[0]["in_view"] == 0.0  # only the last frames: out of view
    assert static["kind"] == "static" and "in_view" not in static
    assert person["off_heading"] == static["off_heading"] == 0.0  # flying where the camera looks


def test_the_view_is_the_logged_cameras_and_the_default_cameras_without_one():
    # a person 41 degrees off the heading: outside the default camera's 39.7 degree half view, inside a
    # wider camera's
    recs = _records()
    off = (np.cos(np.radians(41.0)), -np.sin(np.radians(41.0)))
    for r in recs:
        if r["k"] == "f":
            r["people"] = [_person(off, (0.0, 1.0))]
            r["tracks"] = []
    assert logged_half_view(recs[0]) == pytest.approx(np.radians(39.69), abs=1e-3)
    assert collision_rows(recs)[0]["in_view"] == 0.0
    recs[0]["camera"] = {"width": 640, "height": 480, "fx": 300.0, "fy": 300.0, "cx": 320.0, "cy": 240.0}
    assert logged_half_view(recs[0]) == pytest.approx(np.arctan2(320.0, 300.0))
    assert collision_rows(recs)[0]["in_view"] == 1.0


def test_rows_give_the_fault_class_and_the_persons_lowest_speed():
    recs = _records()
    walk = iter((0.0, 0.2, 1.0, 1.0))  # standing, then walking into the drone's side
    for r in recs:
        if r["k"] == "f":
            r["people"][0]["v"] = [0.0, next(walk), 0.0]
    person, static = collision_rows(recs)
    assert person["person_min_speed"] == 0.0 and "fault" not in person  # no contact velocity logged
    assert collision_rows(recs, window=0.6)[0]["person_min_speed"] == 1.0
    for c in (r for r in recs if r["k"] == "collision"):
        c["v"], c["point"] = [1.0, 0.0, 0.0], [0.0, -0.4, 1.2]  # touched on the right while flying on
    person, static = collision_rows(recs)
    assert person["fault"] == "drone_at_fault" and static["fault"] == "structure"
    for c in (r for r in recs if r["k"] == "collision"):
        c["v"] = [0.05, 0.0, 0.0]
    assert collision_rows(recs)[0]["fault"] == "drone_at_rest"


def test_off_heading_is_the_motion_against_the_camera_and_empty_at_rest():
    recs = _records()
    for r in recs:
        if r["k"] == "s":
            r["v"] = [-0.6, 0.6, 0.0]  # backing off to the left, the camera still looking along +x
    person, _ = collision_rows(recs)
    assert person["off_heading"] == 135.0
    for r in recs:
        if r["k"] == "s":
            r["v"] = [0.05, 0.0, 0.0]
    assert all("off_heading" not in row for row in collision_rows(recs))


def test_rows_say_how_long_the_planner_knew_the_person():
    """At 0.5 and 1.0 s a disc holds the person (1 m ahead); at 1.5 s none does; at 2.0 s one again."""
    recs = _records()
    discs = {0.5: [[1.1, 0.0, 0.5]], 1.0: [[1.0, 0.1, 0.4], [5.0, 0.0, 1.0]], 1.5: [[1.0, 0.0, 0.4]],
             2.0: [[0.1, -1.0, 0.3]]}
    recs += [{"k": "plan", "t": t, "status": "solved", "threats": d} for t, d in discs.items()]
    person, static = collision_rows(recs)
    assert person["planner_knew"] == 0.75 and person["known_for"] == 0.0
    assert "planner_knew" not in static
    recs = [r for r in recs if not (r["k"] == "plan" and r["t"] == 2.0)]
    recs.append({"k": "plan", "t": 2.0, "status": "solved", "threats": []})
    assert collision_rows(recs)[0]["planner_knew"] == 0.5
    for r in recs:
        if r["k"] == "plan" and r["t"] >= 1.5:
            r["threats"] = [[0.0, -1.0, 0.5]]  # on the person once they are to the right
    assert collision_rows(recs)[0]["known_for"] == 1.5  # known from 0.5 s on, without a break
    assert "planner_knew" not in collision_rows(_records())[0]  # a log without threats: nothing said


def test_rows_say_why_the_planner_forgot_the_person():
    """The person walks out of the view to the drone's right (at 1.5 s); a prediction dropped near them
    says why, one dropped far from them does not."""
    recs = _records()
    recs += [{"k": "plan", "t": 1.0, "status": "solved", "threats": [[1.0, 0.0, 0.4]]},
             {"k": "plan", "t": 1.5, "status": "solved", "threats": [],
              "forgot": [[6.0, 3.0, "memory"], [0.8, -0.5, "seen_free"]]},
             {"k": "plan", "t": 2.0, "status": "solved", "threats": [], "forgot": [[5.0, 5.0, "merged"]]}]
    person, static = collision_rows(recs)
    assert person["forgot"] == "seen_free" and person["forgot_s"] == 0.5
    assert "forgot" not in static
    assert "forgot" not in collision_rows(recs, lost_match=0.5)[0]  # 0.94 m off the person: not them
    assert "forgot" not in collision_rows(_records())[0]  # a log that does not say: nothing said


def test_cli_prints_a_table_and_names_a_folder_without_logs(tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    with gzip.open(run / "log.jsonl.gz", "wt", encoding="utf-8") as fh:
        fh.write("\n".join(json.dumps(r) for r in _records()) + "\n")
    assert main(["collisions", str(run)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("| seed | t | kind") and len(out) == 4  # header, rule, two collisions
    assert main(["collisions", str(tmp_path / "empty")]) == 2
    assert "no episode log" in capsys.readouterr().err


def test_the_view_a_collision_is_judged_in_is_the_logged_rigs():
    assert logged_views({}) == ([0.0], False)  # a log from before rigs: the forward camera
    yaws, all_round = logged_views({"sensors": [{"kind": "rgbd", "yaw": 0.0}, {"kind": "rgbd", "yaw": 180.0}]})
    assert yaws == [0.0, pytest.approx(math.pi)] and not all_round
    assert logged_views({"sensors": [{"kind": "rgbd", "yaw": 0.0}, {"kind": "lidar", "yaw": 0.0}]}) == ([0.0], True)


def test_rows_say_whether_the_shield_flew_instead_and_whether_the_person_had_a_flank():
    """overruled: the share of plans over the window with a shield status; flanked: 0.5 s before the contact
    (the frame at 1.5 s: the person 1 m to the drone's right) another person within 1.6 m on the other
    side, more than 120 deg from the first."""
    recs = _records()
    recs += [{"k": "plan", "t": float(t), "status": "solved" if t < 1.0 else "shield:hold"}
             for t in np.arange(0.0, 2.01, 0.1).round(1)]
    person, static = collision_rows(recs)
    assert person["overruled"] == static["overruled"] == pytest.approx(11 / 21, abs=0.005)
    assert person["flanked"] == 0 and "flanked" not in static  # nobody else near
    other = {"id": 6, "lo": [-0.25, 0.95, 0.0], "hi": [0.25, 1.45, 1.7], "v": [0.0, 0.0, 0.0]}  # 1.2 m left
    frame = next(r for r in recs if r["k"] == "f" and r["t"] == 1.5)
    frame["people"].append(other)
    assert collision_rows(recs)[0]["flanked"] == 1
    assert collision_rows(recs, flank_range=1.1)[0]["flanked"] == 0  # beyond the range
    other["lo"], other["hi"] = [0.75, -0.25, 0.0], [1.25, 0.25, 1.7]  # ahead: 90 deg from the first
    assert collision_rows(recs)[0]["flanked"] == 0
    assert "overruled" not in collision_rows(_records())[0]  # no plan records
