"""The perception metrics' counting rules on hand-made frames: recall by distance and the 5 m
range of Table I's errors."""
from types import SimpleNamespace

import numpy as np
import pytest

from dodt.frames import CameraIntrinsics
from experiments.perception_metrics import RECALL_BINS, PerceptionMetrics, bin_labels
from sim.ground_truth import ObstacleTruth

K = CameraIntrinsics()
T = np.array([[0.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 1.2], [0.0, 0.0, 0.0, 1.0]])


def _person(pid, x, y, vx=1.0):
    return ObstacleTruth(pid, "person", "person", np.array([x - 0.2, y - 0.2, 0.0]), np.array([x + 0.2, y + 0.2, 1.8]),
                         np.array([vx, 0.0, 0.0]))


def _track(tid, x, y, vx):
    return SimpleNamespace(id=tid, center=np.array([x, y, 0.9]), velocity=np.array([vx, 0.0, 0.0]), dynamic=True)


def _frame(people, tracks):
    truth = SimpleNamespace(obstacles=tuple(people), T_world_camera=T, segmentation=None, stamp=0.0)
    return SimpleNamespace(dynamic=tuple(tracks)), truth


def test_recall_by_distance_and_errors_within_table_range():
    m = PerceptionMetrics()
    people = [_person(1, 1.5, 0.0), _person(2, 3.5, 0.5), _person(3, 7.5, -0.5), _person(4, 9.0, 0.0),
              _person(5, 12.0, 0.0), _person(6, 3.0, 0.0, vx=0.0)]  # beyond 10 m / standing: not counted
    tracks = [_track(11, 1.6, 0.0, 0.9), _track(13, 7.8, -0.5, 0.5)]  # person 2 and 4 are missed
    m.add(*_frame(people, tracks), K)
    s = m.summary()
    labels = bin_labels()
    assert s["visible_by_distance"] == {lab: int(lab in ("0.5-2", "3-4", "7-8", "8-10")) for lab in labels}
    assert s["recall_by_distance"]["0.5-2"] == 1.0 and s["recall_by_distance"]["7-8"] == 1.0
    assert s["recall_by_distance"]["3-4"] == 0.0 and s["recall_by_distance"]["8-10"] == 0.0
    assert np.isnan(s["recall_by_distance"]["4-5"])
    assert s["recall_beyond_4m"] == pytest.approx(0.5)
    assert s["recall"] == pytest.approx(0.5)  # Table I's recall: 0.5-5 m only
    # Table I's errors: only the pair within 5 m; the 7.5 m pair is scored apart
    assert s["pos_err"] == pytest.approx(0.1) and s["vel_err"] == pytest.approx(0.1)
    assert s["pos_err_beyond"] == pytest.approx(0.3) and s["vel_err_beyond"] == pytest.approx(0.5)
    assert s["matched"] == 1 and s["matched_beyond"] == 1
    both = PerceptionMetrics.combine([m, m])
    assert both["visible_by_distance"]["7-8"] == 2 and both["recall_beyond_4m"] == pytest.approx(0.5)
    assert both["matched_beyond"] == 2
    assert RECALL_BINS[0] == 0.5 and RECALL_BINS[-1] == 10.0


def test_std_scale_divides_each_error_by_its_tracks_reported_std_within_table_range():
    m = PerceptionMetrics()
    people = [_person(1, 1.5, 0.0), _person(2, 3.5, 1.0), _person(3, 7.5, -0.5)]
    tracks = [_track(11, 1.6, 0.0, 1.0), _track(12, 3.5, 1.3, 1.0), _track(13, 7.8, -0.5, 1.0)]
    for t, std in zip(tracks, (0.2, 0.1, 0.01)):  # the 7.5 m pair lies beyond table_range: not counted
        t.position_std = std
    m.add(*_frame(people, tracks), K)
    assert m.std_ratio == pytest.approx([0.5, 3.0])
    assert m.summary()["std_scale"] == pytest.approx(1.75 / np.sqrt(2 * np.log(2)))
    assert PerceptionMetrics.combine([m, m])["std_scale"] == pytest.approx(m.summary()["std_scale"])
    assert np.isnan(PerceptionMetrics().summary()["std_scale"])  # no pairs: no figure


def test_prediction_error_scores_where_a_track_puts_its_person_a_horizon_later():
    m = PerceptionMetrics(horizon=1.0)
    for k in range(25):  # a person walking at 1 m/s along x; a track 0.1 m behind, velocity exact
        t = k * 0.1
        track = _track(11, 1.4 + t, 0.0, 1.0)
        track.acceleration = np.array([0.6, 0.0, 0.0])  # an acceleration the person does not have
        if k == 13:  # a missing frame: what is due at 1.3 s is scored at 1.4 s (within max_lag)
            continue
        result, truth = _frame([_person(1, 1.5 + t, 0.0)], [track])
        truth.stamp = t
        m.add(result, truth, K)
    s = m.summary()
    # made at 0 .. 2.4 s but 1.3: due at 1.0 .. 2.4 s but 2.3 are scored, those due later wait
    assert s["predicted"] == 14 and len(m.pending) == 10
    late = 3  # the one due at 1.3 s, scored 0.1 s (0.1 m of walking) late
    cv, ca = np.array(m.pred_cv), np.array(m.pred_ca)
    assert np.delete(cv, late) == pytest.approx(0.1)  # the track's own 0.1 m lag, carried at the right speed
    assert np.delete(ca, late) == pytest.approx(0.2)  # 0.5 * 0.6 m/s^2 * (1 s)^2 ahead, less the lag
    assert (cv[late], ca[late]) == pytest.approx((0.2, 0.1))
    assert s["pred_err_cv"] == pytest.approx(cv.mean()) and s["pred_err_ca"] == pytest.approx(ca.mean())
    assert PerceptionMetrics.combine([m, m])["predicted"] == 28


def test_prediction_error_skips_a_person_who_has_left_or_a_frame_too_late():
    m = PerceptionMetrics(horizon=0.5, max_lag=0.1)
    result, truth = _frame([_person(1, 1.5, 0.0), _person(2, 3.0, 0.0)], [_track(11, 1.5, 0.0, 1.0),
                                                                             _track(12, 3.0, 0.0, 1.0)])
    m.add(result, truth, K)
    later, truth2 = _frame([_person(1, 2.0, 0.0)], [])  # person 2 gone; 0.7 s later: 0.2 s past due
    truth2.stamp = 0.7
    m.add(later, truth2, K)
    assert m.summary()["predicted"] == 0 and m.pending == []
    m.add(result, truth, K)
    truth2.stamp = 0.55
    m.add(later, truth2, K)
    assert m.summary()["predicted"] == 1 and m.summary()["pred_err_cv"] == pytest.approx(0.0)


def test_time_to_moving_per_stretch_in_view():
    """Person 1 is reported moving 0.3 s after coming into view, leaves the view for 1 s and, back, is reported
    after 0.2 s; person 2 is reported from its first frame; person 3 never is, in either of its two stretches
    (the first closed by its absence, the second open at the end); a standing person does not count."""
    m = PerceptionMetrics()
    for k in range(13):  # 30 Hz: t = 0 .. 0.4 s
        t = k / 30.0
        people = [_person(1, 2.0, 0.0), _person(2, 3.0, 1.0), _person(3, 4.0, -1.0), _person(4, 2.5, 0.5, vx=0.0)]
        tracks = [_track(12, 3.0, 1.0, 1.0)] + ([_track(11, 2.0, 0.1, 1.0)] if k >= 9 else [])
        result, truth = _frame(people, tracks)
        m.add(result, SimpleNamespace(**{**vars(truth), "stamp": t}), K)
    for k in range(10):  # t = 1.4 .. 1.7 s: person 1 back in view, reported from t = 1.6
        t = 1.4 + k / 30.0
        tracks = [_track(11, 2.0, 0.1, 1.0)] if t >= 1.6 - 1e-9 else []
        result, truth = _frame([_person(1, 2.0, 0.0), _person(3, 4.0, -1.0)], tracks)
        m.add(result, SimpleNamespace(**{**vars(truth), "stamp": t}), K)
    assert sorted(m.latency.latencies) == pytest.approx([0.0, 0.2, 0.3])
    s = m.summary()
    assert s["moving_latency_n"] == 3 and s["moving_latency_median"] == pytest.approx(0.2)
    assert s["moving_latency_unreported"] == 2  # person 3, twice
    both = PerceptionMetrics.combine([m, m])
    assert both["moving_latency_n"] == 6 and both["moving_latency_unreported"] == 4
    assert np.isnan(PerceptionMetrics().summary()["moving_latency_median"])


def test_matching_keeps_the_near_pair_when_the_overall_nearest_assignment_would_not():
    """Unconstrained, pairing track 0 with person 1 and track 1 with person 0 costs less in all (7.2 against
    7.27 m), and neither pair is within the gate; gated, track 0 is matched to person 0."""
    from experiments.perception_metrics import match_pairs
    assert match_pairs(np.array([[2.1, 0.0], [-3.1, 0.0]]), np.array([[2.0, 0.0], [4.0, 1.0]]), 0.5) == [(0, 0)]
