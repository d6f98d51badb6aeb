"""Dynamic identification (dodt.identification): point voting, the candidate test, consistency."""
import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from dodt.config import IdentificationConfig
from dodt.frames import CameraIntrinsics
from dodt.identification import decide, is_candidate, vote
from dodt.windows import FrameClock
from tests.dodt.synthetic import camera_pose

K = CameraIntrinsics()
CFG = IdentificationConfig()
T_CAM = camera_pose(0.0, 0.0, 1.2)  # looking along +x


def slab(x0: float, y0: float, n: int = 60, seed: int = 0, width: float = 0.5) -> np.ndarray:
    """Points of an upright slab facing the camera (default person-sized)."""
    rng = np.random.default_rng(seed)
    return np.column_stack([np.full(n, x0) + rng.normal(0, 0.01, n), y0 + rng.uniform(-width / 2, width / 2, n),
                            rng.uniform(0.3, 1.8, n)])


def test_static_points_cast_no_votes_and_are_all_valid():
    then = slab(3.0, 0.0)
    now = then + np.random.default_rng(1).normal(0, 0.005, then.shape)  # noise only
    votes, valid, skipped = vote(now, cKDTree(then), 0.15, np.array([0.0, 0.0, 0.0]), T_CAM, K, 5.0, CFG)
    assert (votes, valid, skipped) == (0, len(now), 0)


def test_moving_points_vote_dynamic():
    then = slab(3.0, 0.0, width=0.1)  # narrower than its displacement: each point's nearest neighbour is its twin
    dt, v = 0.15, np.array([0.0, 1.2, 0.0])  # walking across the view at 1.2 m/s
    now = then + v * dt
    votes, valid, skipped = vote(now, cKDTree(then), dt, v, T_CAM, K, 5.0, CFG)
    assert valid >= 0.8 * len(now) and votes / valid >= CFG.vote_ratio
    assert is_candidate(1.2, votes, valid, skipped, CFG)


def test_points_out_of_view_back_then_are_skipped_not_voted():
    then = slab(3.0, 0.0)
    now = slab(3.0, 0.0, seed=3) + [0.0, 0.3, 0.0]
    T_away = camera_pose(0.0, 0.0, 1.2, yaw=np.pi)  # back then the camera looked the other way
    votes, valid, skipped = vote(now, cKDTree(then), 0.15, np.array([0.0, 2.0, 0.0]), T_away, K, 5.0, CFG)
    assert (votes, valid, skipped) == (0, 0, len(now))


def test_nearest_neighbour_beyond_walking_reach_is_no_correspondence():
    then = slab(3.0, 0.0)
    dt = 0.15
    reach = CFG.max_point_speed * dt + 0.1
    near = slab(3.0, 0.0, seed=4) + [0.0, 0.0, 0.0]
    far = then[:20] + [0.0, 0.3 + reach, 0.0]  # these have no point within reach back then
    votes, valid, skipped = vote(np.vstack([near, far]), cKDTree(then), dt, np.array([0.0, 1.0, 0.0]), T_CAM, K,
                                 5.0, CFG)
    assert skipped >= len(far)
    # ... and an array in place of the tree gives the same answer
    assert vote(np.vstack([near, far]), then, dt, np.array([0.0, 1.0, 0.0]), T_CAM, K, 5.0, CFG) == \
        (votes, valid, skipped)


def test_points_moving_against_the_box_are_invalid():
    then = slab(3.0, 0.0, width=0.1)
    dt = 0.15
    now = then + np.array([0.0, -1.0, 0.0]) * dt
    votes, valid, skipped = vote(now, cKDTree(then), dt, np.array([0.0, 1.0, 0.0]), T_CAM, K, 5.0, CFG)
    assert valid == 0 and skipped == len(now)


def test_empty_inputs_vote_nothing():
    then = slab(3.0, 0.0)
    assert vote(np.zeros((0, 3)), cKDTree(then), 0.1, np.zeros(3), T_CAM, K, 5.0, CFG) == (0, 0, 0)
    assert vote(then, np.zeros((0, 3)), 0.1, np.zeros(3), T_CAM, K, 5.0, CFG) == (0, 0, len(then))
    assert vote(then, cKDTree(then), 0.0, np.zeros(3), T_CAM, K, 5.0, CFG) == (0, 0, len(then))


@pytest.mark.parametrize("speed,votes,valid,skipped,expected", [
    (0.1, 10, 10, 0, False),   # below T_vel
    (0.5, 9, 10, 0, True),     # 90 % of valid points vote
    (0.5, 7, 10, 0, False),    # 70 % < T_ratio
    (0.5, 9, 10, 6, False),    # too many points left out of the vote
    (0.5, 0, 0, 10, False),    # nothing valid
])
def test_candidate_rule(speed, votes, valid, skipped, expected):
    assert is_candidate(speed, votes, valid, skipped, CFG) is expected


def test_velocity_method_needs_speed_only():
    cfg = IdentificationConfig(method="velocity")
    assert is_candidate(0.5, 0, 0, 10, cfg) and not is_candidate(0.1, 0, 0, 0, cfg)


def frames_of(span: float, rate: float = 30.0) -> int:
    """How many frames a window of ``span`` seconds holds at ``rate``: the intervals it covers
    (rounded up beyond a quarter period), at least one once it spans time, plus one."""
    return 1 + max(math.ceil(span * rate - 0.25), 1 if span > 0 else 0)


def decide_at(candidates: list[bool], history: list[bool], cfg=CFG, rate: float = 30.0) -> bool:
    """decide() at a steady frame ``rate``."""
    clock = FrameClock()
    for _ in range(3):
        clock.observe(1.0 / rate)
    return decide(candidates, [(h, clock.period) for h in history], cfg, clock)


def test_consistency_and_hysteresis():
    n = frames_of(CFG.consistency_span)
    assert n == 3  # the reference code's 3 frames at 30 Hz
    assert not decide_at([True] * (n - 1), [])
    assert decide_at([False] + [True] * n, [])
    # once dynamic for long enough, a few non-candidate frames keep it dynamic ...
    w = frames_of(CFG.force_dynamic_span)
    assert w == 30
    history = [True] * w
    assert decide_at([True] * 20 + [False] * 3, history)
    # ... but not when it was dynamic in fewer than a third of the window (10 of 30 frames)
    history = [False] * (w - 10 + 1) + [True] * (10 - 1)
    assert not decide_at([False], history)
    assert decide_at([False], [False] * (w - 10) + [True] * 10)


@pytest.mark.parametrize("rate", [60.0, 20.0, 15.0, 10.0, 5.0])
def test_consistency_is_a_span_of_time(rate):
    """At any frame rate a track turns dynamic once every frame within consistency_span (2 / 30 s)
    was a candidate: 3 frames at 30 Hz, 5 at 60 Hz, 2 at 15 and 20 Hz, and at 10 Hz and below,
    where a frame interval is longer than the span, the frame itself."""
    n = {60.0: 5, 20.0: 2, 15.0: 2, 10.0: 1, 5.0: 1}[rate]
    assert not decide_at([True] * (n - 1) if n > 1 else [False], [], rate=rate)
    assert decide_at([True] * n, [], rate=rate)
    assert not decide_at([True] * n + [False], [], rate=rate)
    w = frames_of(CFG.force_dynamic_span, rate)
    assert decide_at([False], [True] * w, rate=rate)
    assert not decide_at([False], [False] * w, rate=rate)


def test_a_young_dynamic_track_is_released_only_after_release_frames_non_candidates():
    n, r = frames_of(CFG.consistency_span), frames_of(CFG.release_span)
    assert r == 3
    cand = [True] * n
    history = [False] * (n - 1) + [True]  # dynamic since the last frame, far younger than the window
    # one, or r - 1, frames that are no candidates keep it dynamic ...
    assert decide_at(cand + [False], history)
    assert decide_at(cand + [False] * (r - 1), history + [True] * (r - 2))
    # ... r in a row release it, and a track that was static is not held dynamic by the rule
    assert not decide_at(cand + [False] * r, history + [True] * (r - 1))
    assert not decide_at(cand[:-1] + [False], [False] * n)
    # release_span = None is the reference code's rule: released at the first non-candidate frame
    ref = IdentificationConfig(release_span=None)
    assert not decide_at(cand + [False], history, ref)


def test_the_old_cloud_cropped_to_matching_reach_gives_the_same_vote():
    """The tracker votes against the part of the old cloud within match_reach of the points:
    the nearest neighbours within reach, and so the votes, are the same as against the whole."""
    from dodt.identification import match_reach

    rng = np.random.default_rng(5)
    clutter = np.column_stack([rng.uniform(1.0, 5.0, 3000), rng.uniform(-2.0, 2.0, 3000), rng.uniform(0.2, 2.5, 3000)])
    dt = 0.15
    for v in (np.zeros(3), np.array([0.0, 1.0, 0.0]), np.array([-0.8, 0.3, 0.0])):
        then = slab(3.0, 0.2, n=300, width=0.6)
        now = then + v * dt + rng.normal(0, 0.01, then.shape)
        cloud = np.vstack([clutter, then])
        r = match_reach(dt, CFG)
        lo, hi = now.min(axis=0) - r, now.max(axis=0) + r
        near = cloud[np.all((cloud >= lo) & (cloud <= hi), axis=1)]
        assert len(near) < len(cloud)
        assert vote(now, near, dt, v, T_CAM, K, 5.0, CFG) == vote(now, cKDTree(cloud), dt, v, T_CAM, K, 5.0, CFG)


def measure_slab(cfg, track, clouds: dict, k: int, pts: np.ndarray, velocity):
    """Frame k (30 Hz) of a track measured by one detection of ``pts`` (the first one makes the track),
    its filtered velocity held at ``velocity`` (past the velocity test: the votes decide), identified;
    ``clouds`` gathers the frames' clouds. Returns the track."""
    from dodt.detection import Detection
    from dodt.tracker import Track

    dt = 1 / 30
    clouds[k] = pts
    det = Detection(center=pts.mean(axis=0), size=np.ptp(pts, axis=0) + 0.05, source="dbscan", points=pts)
    if track is None:
        track = Track(1, det, k, k * dt, cfg)
    else:
        track.kf.predict(dt)
        track.update(det, k, k * dt)
    track.kf.x[2:4] = velocity
    track.identify(k, {j: T_CAM for j in clouds}, clouds.get, K, 5.0)
    return track


def _slab_track_candidates(cfg, frame_points, velocity) -> list[bool]:
    """Feed a track one detection per frame (30 Hz) of the given points (measure_slab); its candidates."""
    clouds, track, candidates = {}, None, []
    for k, pts in enumerate(frame_points):
        track = measure_slab(cfg, track, clouds, k, pts, velocity)
        candidates.append(track.candidates[-1])
    return candidates


@pytest.mark.parametrize("moving", [False, True])
def test_a_large_obstacle_votes_with_a_sample_and_decides_as_with_all_its_points(moving):
    """1200 points vote with an even sample of max_vote_points: a moving slab is a candidate
    and a standing one (whose filter says it moves) is not, frame by frame as with all points."""
    from dodt.config import DODTConfig

    v = np.array([0.0, 1.0, 0.0]) if moving else np.zeros(3)
    frames = [slab(3.0, 0.0, n=1200, seed=k, width=0.15) + v * k / 30 for k in range(12)]  # thin: twins are neighbours
    decisions = [_slab_track_candidates(DODTConfig(identification=IdentificationConfig(max_vote_points=n)),
                                        frames, [0.0, 1.0]) for n in (0, 200)]
    assert decisions[0] == decisions[1]
    assert any(decisions[0]) == moving


def test_an_obstacle_wider_than_any_walker_is_not_voted_on():
    """A 3 m wide slab moving at 1 m/s: voted on (max_vote_extent 0) it is a candidate; with the
    default extent limit it is not voted on and is no candidate, whatever its filter says."""
    from dodt.config import DODTConfig

    frames = []
    for k in range(8):  # moving along its thin axis: each point's neighbour back then is its twin
        pts = slab(3.0, 0.0, n=400, seed=k, width=3.0)
        pts[:, 0] = 3.0 + k / 30 + np.random.default_rng(k).normal(0, 0.005, len(pts))
        frames.append(pts)
    outcome = {limit: any(_slab_track_candidates(DODTConfig(identification=IdentificationConfig(max_vote_extent=limit)),
                                                 frames, [1.0, 0.0]))
               for limit in (0.0, IdentificationConfig().max_vote_extent)}
    assert outcome == {0.0: True, IdentificationConfig().max_vote_extent: False}


def test_a_person_label_does_not_lock_a_standing_obstacle_dynamic():
    """A standing obstacle that a learned detector called a person for 15 frames is dynamic while
    the label lasts (from its third frame: all boxes over learned.person_span),
    and static again at its first frame without one: the person label does not feed the
    geometric label's force-dynamic lock (10 dynamic frames of the last 30)."""
    from dodt.config import DODTConfig
    from dodt.detection import Detection
    from dodt.tracker import Track

    cfg = DODTConfig()
    dt = 1 / 30
    clouds, track, labels = {}, None, []
    for k in range(40):
        pts = slab(3.0, 0.0, n=300, seed=k)
        clouds[k] = pts
        det = Detection(center=pts.mean(axis=0), size=np.ptp(pts, axis=0) + 0.05, source="dbscan", points=pts)
        det.is_person = k < 15
        if track is None:
            track = Track(1, det, k, k * dt, cfg)
        else:
            track.kf.predict(dt)
            track.update(det, k, k * dt)
        track.identify(k, {j: T_CAM for j in clouds}, clouds.get, K, 5.0)
        labels.append(track.dynamic)
    assert (cfg.learned.person_span, cfg.learned.person_fraction) == (2 / 30, 1.0)
    assert not any(labels[:2]) and all(labels[2:15])  # the last 3 boxes were person boxes: dynamic
    assert not any(labels[15:])  # one of the last 3 was not
    assert not track.geometric_dynamic


def test_a_box_cut_by_the_view_side_is_told_from_one_in_view():
    """A person-sized box 3 m ahead is in view at the image's centre, cut when it straddles the
    left or right edge of the 87-degree view, and cut when it reaches behind the camera."""
    from dodt.geometry import box_cut_by_view_side

    size = np.array([0.5, 0.5, 1.7])
    half_fov = np.arctan2(K.cx, K.fx)  # the left edge's bearing (x right in the image is -y in the world)
    edge_y = 3.0 * np.tan(half_fov)
    assert not box_cut_by_view_side(np.array([3.0, 0.0, 1.2]), size, K, T_CAM)
    assert box_cut_by_view_side(np.array([3.0, edge_y, 1.2]), size, K, T_CAM)
    assert box_cut_by_view_side(np.array([3.0, -edge_y, 1.2]), size, K, T_CAM)
    assert not box_cut_by_view_side(np.array([3.0, edge_y - 0.6, 1.2]), size, K, T_CAM)
    assert box_cut_by_view_side(np.array([0.1, 0.0, 1.2]), size, K, T_CAM)


@pytest.mark.parametrize("cut_boxes_vote", [False, True])
def test_person_boxes_cut_by_the_view_side_cast_no_vote(cut_boxes_vote):
    """A track whose person boxes are cut by the view's side (a person walking into view) is no
    person until 3 boxes in full view have come; one already a person keeps its label while its
    boxes are cut (walking out of view), a cut box that is no person box taking no vote away
    either. With learned.cut_boxes_vote every box votes, as before."""
    from dataclasses import replace

    from dodt.config import DODTConfig
    from dodt.detection import Detection
    from dodt.tracker import Track

    cfg = DODTConfig()
    cfg = replace(cfg, learned=replace(cfg.learned, cut_boxes_vote=cut_boxes_vote))
    dt = 1 / 30

    def run(cut_pattern, person_pattern):
        track, labels = None, []
        for k, (cut, person) in enumerate(zip(cut_pattern, person_pattern)):
            pts = slab(3.0, 0.0, n=200, seed=k)
            det = Detection(center=pts.mean(axis=0), size=np.ptp(pts, axis=0) + 0.05, source="learned", points=pts)
            det.is_person, det.cut = person, cut
            if track is None:
                track = Track(1, det, k, k * dt, cfg)
            else:
                track.kf.predict(dt)
                track.update(det, k, k * dt)
            labels.append(track.is_person)
        return labels

    entering = run([True] * 5 + [False] * 5, [True] * 10)
    leaving = run([False] * 4 + [True] * 6, [True] * 5 + [False] * 5)
    if cut_boxes_vote:
        assert entering == [False, False] + [True] * 8
        assert leaving == [False, False, True, True, True] + [False] * 5  # lost at the first non-person box
    else:
        assert entering == [False] * 7 + [True] * 3  # labelled at the third box in full view
        assert leaving == [False, False] + [True] * 8
