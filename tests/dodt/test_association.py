"""Data association (similarity and one-to-one assignment) and the tracker built on it."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from dodt.association import TrackView, assign, features, similarity_matrix
from dodt.config import AssociationConfig, DODTConfig, KalmanConfig
from dodt.detection import Detection
from dodt.protocol import TrackReport
from dodt.presets import preset
from dodt.tracker import Tracker

SIZE = np.array([0.5, 0.5, 1.7])
CAMERA = np.zeros(3)
FPS = 30.0


def det(center, size=SIZE, n=60, seed=0, spread=None) -> Detection:
    """A detection with a small seeded point cloud: uniform in the box, or normal with the given
    per-axis standard deviation."""
    c = np.asarray(center, float)
    s = np.asarray(size, float)
    rng = np.random.default_rng(seed)
    if spread is None:
        pts = c + (rng.random((n, 3)) - 0.5) * s
    else:
        pts = c + rng.normal(0.0, 1.0, (n, 3)) * np.asarray(spread, float)
    return Detection(center=c.copy(), size=s.copy(), source="dbscan", points=pts.astype(np.float32))


def view_of(d: Detection, position_variance: float = 0.0, **change) -> TrackView:
    """The track view of a track that saw exactly this detection."""
    count, spread = features(d)
    v = TrackView(center=d.center.copy(), size=d.size.copy(), count=count, spread=spread,
                  position_variance=position_variance)
    for k, val in change.items():
        setattr(v, k, val)
    return v


def shifted(d: Detection, offset) -> Detection:
    o = np.asarray(offset, float)
    return Detection(center=d.center + o, size=d.size.copy(), source=d.source, points=(d.points + o).astype(np.float32))


# --------------------------------------------------------------------------- feature similarity


def test_identical_features_have_similarity_one():
    cfg = AssociationConfig()
    d = det((3.0, 0.5, 0.9))
    s, thr = similarity_matrix([view_of(d)], [d], cfg, CAMERA)
    assert s.shape == (1, 1)
    assert s[0, 0] == 1.0  # exp(0)
    assert thr == cfg.similarity_threshold


def test_each_feature_difference_by_hand():
    cfg = AssociationConfig()
    d = det((3.0, 0.5, 0.9))
    base = view_of(d)
    count, spread = features(d)
    cases = {
        # horizontal position: normalised by position_scale (0.4 m)
        "x": (view_of(shifted(d, (0.4, 0, 0))), math.exp(-1)),
        "xy": (view_of(shifted(d, (0.3, 0.4, 0))), math.exp(-(0.5 / 0.4) ** 2)),
        # vertical position: position_scale, not grown by the uncertainty
        "z": (view_of(shifted(d, (0, 0, 0.4)), position_variance=1.0), math.exp(-1)),
        # size: size_scale (0.5 m)
        "size": (view_of(d, size=SIZE + np.array([0.5, 0, 0])), math.exp(-1)),
        # point count: relative difference over count_scale (0.6)
        "count": (view_of(d, count=2 * count), math.exp(-(0.5 / 0.6) ** 2)),
        # point spread: spread_scale (0.15 m)
        "spread": (view_of(d, spread=spread + np.array([0.0, 0.15, 0.0])), math.exp(-1)),
    }
    got = similarity_matrix([c[0] for c in cases.values()] + [base], [d], cfg, CAMERA)[0][:, 0]
    np.testing.assert_allclose(got, [c[1] for c in cases.values()] + [1.0], rtol=1e-6)


def test_the_position_gate_grows_with_the_tracks_uncertainty():
    cfg = AssociationConfig()
    d = det((3.0, 0.5, 0.9))
    far = shifted(d, (0.5, 0.0, 0.0))
    certain = view_of(d, position_variance=0.0)
    uncertain = view_of(d, position_variance=0.09)  # scale^2 = 0.16 + 0.09 = 0.25
    s, _ = similarity_matrix([certain, uncertain], [far], cfg, CAMERA)
    assert s[1, 0] == pytest.approx(math.exp(-1))
    assert s[0, 0] == pytest.approx(math.exp(-(0.5 / 0.4) ** 2))
    assert s[1, 0] > s[0, 0]


def test_larger_differences_give_lower_similarity():
    cfg = AssociationConfig()
    d = det((3.0, 0.5, 0.9))
    offsets = [0.0, 0.1, 0.3, 0.6, 1.0, 2.0]
    dets = [shifted(d, (0.0, o, 0.0)) for o in offsets]
    s, thr = similarity_matrix([view_of(d)], dets, cfg, CAMERA)
    assert np.all(np.diff(s[0]) < 0)
    assert s[0, 0] == 1.0
    assert s[0, -1] < thr  # 2 m away: below the acceptance threshold
    sizes = [SIZE + np.array([g, g, 0.0]) for g in (0.0, 0.2, 0.5, 1.0)]
    s, _ = similarity_matrix([view_of(d)], [Detection(d.center, sz, "dbscan", d.points) for sz in sizes], cfg, CAMERA)
    assert np.all(np.diff(s[0]) < 0)


def test_similarity_matrix_shapes():
    cfg = AssociationConfig()
    d = det((3.0, 0.5, 0.9))
    assert similarity_matrix([], [d, d], cfg, CAMERA)[0].shape == (0, 2)
    assert similarity_matrix([view_of(d)], [], cfg, CAMERA)[0].shape == (1, 0)
    s, _ = similarity_matrix([view_of(d)] * 3, [d, shifted(d, (1, 0, 0))], cfg, CAMERA)
    assert s.shape == (3, 2)


def test_features_of_a_detection():
    d = det((1.0, 2.0, 0.9), n=200, spread=(0.1, 0.2, 0.3), seed=5)
    n, sd = features(d)
    assert n == 200
    np.testing.assert_allclose(sd, (0.1, 0.2, 0.3), rtol=0.15)
    assert features(Detection(np.zeros(3), SIZE, "dbscan"))[0] == 0
    np.testing.assert_array_equal(features(Detection(np.zeros(3), SIZE, "dbscan"))[1], 0.0)


# --------------------------------------------------------------------------- assignment


def test_assign_takes_the_best_pairs_first_one_to_one():
    scores = np.array([[0.9, 0.8],
                       [0.85, 0.1]])
    # greedy: (0, 0) first; then track 0 and detection 0 are taken, so (1, 1)
    assert assign(scores, 0.05) == [(0, 0), (1, 1)]


def test_assign_respects_the_threshold():
    scores = np.array([[0.9, 0.8],
                       [0.85, 0.1]])
    assert assign(scores, 0.2) == [(0, 0)]  # (1, 1) is below it
    assert assign(scores, 0.9) == []  # strictly above
    assert assign(scores, 0.95) == []


def test_assign_is_one_to_one_on_random_scores():
    rng = np.random.default_rng(7)
    for _ in range(50):
        T, D = rng.integers(1, 7, 2)
        scores = rng.random((T, D))
        pairs = assign(scores, 0.3)
        ts = [p[0] for p in pairs]
        ds = [p[1] for p in pairs]
        assert len(set(ts)) == len(ts) and len(set(ds)) == len(ds)
        assert all(scores[t, d] > 0.3 for t, d in pairs)
        # greedy order: scores of accepted pairs come out in decreasing order
        got = [scores[t, d] for t, d in pairs]
        assert got == sorted(got, reverse=True)
        # maximal: nothing left that could still be paired above the threshold
        free_t = set(range(T)) - set(ts)
        free_d = set(range(D)) - set(ds)
        assert not any(scores[t, d] > 0.3 for t in free_t for d in free_d)


def test_assign_of_empty_scores():
    assert assign(np.zeros((0, 3)), 0.0) == []
    assert assign(np.zeros((2, 0)), 0.0) == []


# --------------------------------------------------------------------------- centre and cosine methods


def test_center_method_matches_the_nearest_centre_within_the_gate():
    cfg = AssociationConfig(method="center")
    track = view_of(det((3.0, 0.0, 0.9)))
    near = det((3.2, 0.0, 0.9))  # 0.2 m
    nearer_but_taken = det((3.0, 0.5, 0.9))  # 0.5 m
    s, thr = similarity_matrix([track], [nearer_but_taken, near], cfg, CAMERA)
    np.testing.assert_allclose(s, [[-0.5, -0.2]])
    assert assign(s, thr) == [(0, 1)]


def test_center_method_matches_nothing_beyond_the_gate():
    cfg = AssociationConfig(method="center", center_gate=1.0)
    track = view_of(det((3.0, 0.0, 0.9)))
    inside = det((3.0, 0.99, 0.9))
    outside = det((3.0, 1.01, 0.9))
    s, thr = similarity_matrix([track], [outside], cfg, CAMERA)
    assert s[0, 0] == -np.inf
    assert assign(s, thr) == []
    s, thr = similarity_matrix([track], [inside, outside], cfg, CAMERA)
    assert assign(s, thr) == [(0, 0)]


def test_center_method_pairs_two_tracks_with_their_own_detections():
    cfg = AssociationConfig(method="center")
    tracks = [view_of(det((3.0, 0.0, 0.9))), view_of(det((3.0, 2.0, 0.9)))]
    dets = [det((3.1, 2.1, 0.9)), det((2.9, -0.1, 0.9))]
    s, thr = similarity_matrix(tracks, dets, cfg, CAMERA)
    assert sorted(assign(s, thr)) == [(0, 1), (1, 0)]


def test_cosine_method_requires_overlapping_boxes():
    cfg = AssociationConfig(method="cosine")
    d = det((3.0, 0.0, 0.9))
    s, thr = similarity_matrix([view_of(d)], [d], cfg, CAMERA)
    assert thr == cfg.cosine_threshold
    assert s[0, 0] == pytest.approx(1.0)
    assert assign(s, thr) == [(0, 0)]
    # the same detection moved so that the boxes no longer overlap: no match, however similar
    apart = shifted(d, (0.0, 0.55, 0.0))
    s, thr = similarity_matrix([view_of(d)], [apart], cfg, CAMERA)
    assert s[0, 0] == -np.inf
    assert assign(s, thr) == []
    # touching boxes do not overlap either
    s, _ = similarity_matrix([view_of(d)], [shifted(d, (0.0, 0.5, 0.0))], cfg, CAMERA)
    assert s[0, 0] == -np.inf
    # overlapping: a finite cosine similarity below 1
    s, _ = similarity_matrix([view_of(d)], [shifted(d, (0.0, 0.25, 0.0))], cfg, CAMERA)
    assert np.isfinite(s[0, 0]) and thr < s[0, 0] < 1.0


# --------------------------------------------------------------------------- the tracker


class Feed:
    """Drives a Tracker the way DODT.process does: predict by the time step, associate, correct."""

    def __init__(self, cfg: DODTConfig, seed: int = 0):
        self.tracker = Tracker(cfg)
        self.last: float | None = None
        self.k = 0
        self.rng = np.random.default_rng(seed)

    def __call__(self, stamp: float, centers, person: bool = False) -> list:
        dets = [det(c, seed=int(self.rng.integers(1 << 30))) for c in centers]
        for d in dets:
            d.is_person = person  # as the learned detector marks its boxes
        if self.last is not None:
            self.tracker.predict(stamp - self.last)
        pairs = self.tracker.associate(dets, CAMERA)
        self.tracker.correct(dets, pairs, self.k, stamp)
        self.last = stamp
        self.k += 1
        return [t.output(stamp) for t in self.tracker.tracks]


def walker(t: float) -> np.ndarray:
    """A person-sized box walking at 1 m/s along y, 3 m in front of the camera."""
    return np.array([3.0, -1.0 + 1.0 * t, 0.9])


PRESETS = ["dodt", "dodt-no-fat"]  # feature association + CA filter; centre association + CV filter


@pytest.mark.parametrize("name", PRESETS)
def test_one_moving_box_keeps_one_id(name):
    feed = Feed(preset(name))
    for k in range(60):
        t = k / FPS
        out = feed(t, [walker(t)])
        assert [o.id for o in out] == [1]
        assert not out[0].coasting
    o = out[0]
    np.testing.assert_allclose(o.center, walker(t), atol=0.05)
    np.testing.assert_allclose(o.filter_velocity, (0.0, 1.0, 0.0), atol=0.1)
    assert o.age == pytest.approx(59 / FPS)
    assert o.history.shape[1] == 4 and len(o.history) == 60
    np.testing.assert_allclose(o.history[-1, 1:], walker(t), atol=0.05)  # filtered centres
    np.testing.assert_allclose(o.history[:, 0], np.arange(60) / FPS)


@pytest.mark.parametrize("name", PRESETS)
def test_track_coasts_through_a_short_gap_and_keeps_its_id(name):
    cfg = preset(name)
    feed = Feed(cfg)
    for k in range(30):  # 1 s seen
        out = feed(k / FPS, [walker(k / FPS)])
    assert [o.id for o in out] == [1]
    for k in range(30, 45):  # 0.5 s without detections
        t = k / FPS
        out = feed(t, [])
        assert len(out) == 1 and out[0].id == 1
        assert out[0].coasting
        assert feed.tracker.tracks[0].coasting
        # the prediction follows the motion
        np.testing.assert_allclose(out[0].center[:2], walker(t)[:2], atol=0.1)
    assert out[0].position_std > 0.25  # uncertainty grew while coasting
    for k in range(45, 60):  # it reappears along its motion
        t = k / FPS
        out = feed(t, [walker(t)])
        assert [o.id for o in out] == [1]
        assert not out[0].coasting
    np.testing.assert_allclose(out[0].filter_velocity[:2], (0.0, 1.0), atol=0.1)


@pytest.mark.parametrize("name", PRESETS)
def test_track_is_dropped_after_the_coast_time(name):
    cfg = preset(name)
    assert cfg.track.coast_time == 1.0
    feed = Feed(cfg)
    for k in range(30):
        feed(k / FPS, [walker(k / FPS)])
    last_seen = 29 / FPS
    k = 30
    while (k / FPS) - last_seen < 0.9:
        out = feed(k / FPS, [])
        assert len(out) == 1 and out[0].coasting
        k += 1
    while (k / FPS) - last_seen < 1.1:
        out = feed(k / FPS, [])
        k += 1
    assert out == [] and feed.tracker.tracks == []
    # the box coming back now starts a new track
    out = feed(k / FPS, [walker(k / FPS)])
    assert [o.id for o in out] == [2]


def test_a_person_track_faster_than_people_walk_is_dropped_not_coasted():
    """A young person track whose boxes stepped 0.25 m a frame (a far lifted box's depth jitter)
    has a filtered speed of several m/s: missing its box, it is dropped at once. The same boxes
    without the person label, and a person walking at 1 m/s, coast."""
    cfg = DODTConfig()
    outcome = {}
    for person in (True, False):
        fast = Feed(cfg)
        for k, x in enumerate((6.0, 6.25, 6.5)):
            fast(k / FPS, [np.array([x, 0.0, 0.9])], person=person)
        # the filter said faster than people walk; its state holds at most track.max_speed
        assert fast.tracker.tracks[0].filter_speed > cfg.track.max_coast_speed
        assert np.linalg.norm(fast.tracker.tracks[0].kf.velocity) <= cfg.track.max_speed + 1e-9
        assert fast.tracker.tracks[0].is_person == person
        outcome[person] = [o.coasting for o in fast(3 / FPS, [])]
    assert outcome == {True: [], False: [True]}
    slow = Feed(cfg)
    for k in range(30):
        slow(k / FPS, [walker(k / FPS)], person=True)
    out = slow(30 / FPS, [])
    assert len(out) == 1 and out[0].coasting


def test_a_box_appearing_elsewhere_starts_a_new_track_while_the_old_one_coasts():
    feed = Feed(DODTConfig())
    for k in range(30):
        feed(k / FPS, [walker(k / FPS)])
    out = feed(30 / FPS, [np.array([4.5, 3.0, 0.9])])  # far from where the walker should be
    by_id = {o.id: o for o in out}
    assert set(by_id) == {1, 2}
    assert by_id[1].coasting and not by_id[2].coasting


def test_two_boxes_keep_their_ids():
    feed = Feed(DODTConfig(), seed=3)
    for k in range(60):
        t = k / FPS
        a = np.array([3.0, -1.0 + t, 0.9])
        b = np.array([4.0, 1.0 - t, 0.9])  # the two cross in y, 1 m apart in x
        out = feed(t, [a, b] if k % 2 else [b, a])  # detection order changes every frame
        assert len(out) == 2
        by_id = {o.id: o for o in out}
        assert set(by_id) == {1, 2}
        if k == 0:  # detections start tracks in their order: b first
            id_a, id_b = 2, 1
        np.testing.assert_allclose(by_id[id_a].center[:2], a[:2], atol=0.05)
        np.testing.assert_allclose(by_id[id_b].center[:2], b[:2], atol=0.05)


def test_fallback_stage_matches_a_changed_shape_nearby_but_not_another_size():
    cfg = DODTConfig()
    tracker = Tracker(cfg)
    first = det((3.0, 0.0, 0.9), spread=(0.05, 0.05, 0.3))
    tracker.correct([first], [], 0, 0.0)
    # same place, same size, but a very different point spread: the features reject it ...
    changed = det((3.1, 0.0, 0.9), spread=(0.3, 0.3, 0.6), seed=2)
    s, thr = similarity_matrix([tracker.tracks[0].view()], [changed], cfg.association, CAMERA)
    assert s[0, 0] < thr
    # ... and the second stage (predicted position within the gate) takes it
    assert tracker.associate([changed], CAMERA) == [(0, 0)]
    # a wall-sized box at the same place is no match
    wall = det((3.1, 0.0, 0.9), size=(0.5, 4.0, 2.5), spread=(0.3, 1.0, 0.6), seed=3)
    assert tracker.associate([wall], CAMERA) == []
    # with the second stage turned off nothing is matched
    off = DODTConfig(association=AssociationConfig(fallback_gate=0.0))
    t2 = Tracker(off)
    t2.correct([first], [], 0, 0.0)
    assert t2.associate([changed], CAMERA) == []


def test_fallback_stage_compares_tops_not_bottoms():
    # A track fed by boxes whose lower part a sensor's field cut off (a LiDAR's lowest ray above a near
    # person's legs): 0.6 m tall, its top at 1.75 m.
    cfg = DODTConfig()
    tracker = Tracker(cfg)
    tracker.correct([det((3.0, 0.0, 1.45), size=(0.5, 0.5, 0.6))], [], 0, 0.0)
    # the whole person at the same place, 1.75 m tall: the features reject it (another size) ...
    whole = det((3.05, 0.0, 0.875), size=(0.5, 0.5, 1.75), seed=2)
    s, thr = similarity_matrix([tracker.tracks[0].view()], [whole], cfg.association, CAMERA)
    assert s[0, 0] < thr
    # ... the second stage takes it: same footprint, same top
    assert tracker.associate([whole], CAMERA) == [(0, 0)]
    # a 3 m pillar of the same footprint there is no match (its top is 1.25 m higher), nor a 0.5 m box
    pillar = det((3.05, 0.0, 1.5), size=(0.5, 0.5, 3.0), seed=3)
    low_box = det((3.05, 0.0, 0.25), size=(0.5, 0.5, 0.5), seed=4)
    assert tracker.associate([pillar], CAMERA) == []
    assert tracker.associate([low_box], CAMERA) == []


def test_constant_velocity_target_does_not_overshoot():
    # Box centres measured (exact here), so that only the pseudo-measurements' construction is
    # tested: no spurious acceleration from a velocity that was never measured.
    cfg = DODTConfig(kalman=KalmanConfig(model="ca", position_source="box"))
    feed = Feed(cfg)
    speeds = []
    for k in range(40):
        t = k / FPS
        out = feed(t, [walker(t)])
        speeds.append(out[0].filter_velocity[1])
    assert max(speeds) < 1.1


@pytest.mark.parametrize("wall_x, learned, dropped", [
    (10.0, True, True),  # the camera sees the wall 2 m behind where the person should be: not there
    (7.3, True, False),  # something nearer hides the place: the person may be behind it
    (10.0, False, False),  # without the learned module nothing is tracked beyond the cloud's range
])
def test_a_far_person_track_seen_through_is_dropped(wall_x, learned, dropped):
    """A person track 8 m away, beyond the point cloud's 5.5 m but within the learned detector's
    10 m, loses its boxes. From seen_through_after (7 frames) after its last box it is dropped when the depth
    image shows clearly farther than it in its image region, and coasts on otherwise."""
    import dataclasses

    from tests.dodt.synthetic import camera_pose, render_depth
    from dodt.frames import CameraIntrinsics

    cfg = DODTConfig()
    cfg = dataclasses.replace(cfg, learned=dataclasses.replace(cfg.learned, enabled=learned))
    K, T = CameraIntrinsics(), camera_pose(z=1.2)
    depth = render_depth(K, T, [((wall_x, -3.0, 0.0), (wall_x + 0.2, 3.0, 3.0))])
    feed = Feed(cfg)
    for k in range(5):  # standing, so the coasting prediction stays put
        feed(k / FPS, [np.array([8.0, 0.0, 0.9])], person=True)
    assert feed.tracker.tracks[0].is_person
    for k in range(5, 5 + round(cfg.track.seen_through_after * FPS) + 1):
        feed(k / FPS, [])
        feed.tracker.drop_seen_through(depth, K, T)
    assert (feed.tracker.tracks == []) == dropped


@pytest.mark.parametrize("case, dropped", [
    ("open", True),  # in full view, nothing in front of it, no person box over it: not there
    ("box", False),  # the learned detector finds a person over it: it may be him, missed by the association
    ("hidden", False),  # something nearer covers its place: the person may be behind it
    ("off", False),  # the rule turned off (learned.unseen_after = 0)
    ("static", False),  # not a person track: left to the seen-through rule
])
def test_an_unseen_coasting_person_track_is_dropped(case, dropped):
    """A standing person track 4 m in front of the camera loses its detections. After
    learned.unseen_after (4 frames here) it is dropped when its place is in full view, nothing
    nearer hides it and no 2D person box of the frame overlaps its image box."""
    from tests.dodt.synthetic import camera_pose, render_depth
    from dodt.frames import CameraIntrinsics

    cfg = DODTConfig()
    after = 0 if case == "off" else 4 / FPS
    cfg = replace(cfg, learned=replace(cfg.learned, enabled=True, unseen_after=after))
    K, T = CameraIntrinsics(), camera_pose(z=1.2)
    boxes = [((9.0, -3.0, 0.0), (9.2, 3.0, 3.0))]  # a wall 5 m behind the place
    if case == "hidden":
        boxes.append(((2.0, -1.0, 0.0), (2.2, 1.0, 2.5)))
    depth = render_depth(K, T, boxes)
    feed = Feed(cfg)
    for k in range(5):
        feed(k / FPS, [np.array([4.0, 0.0, 0.9])], person=(case != "static"))
    assert feed.tracker.tracks[0].is_person == (case != "static")
    # the person's image box at 4 m: centre column cx, about 0.5 m wide and 1.8 m tall
    u, half_w, half_h = K.cx, 0.25 * K.fx / 4.0, 0.9 * K.fy / 4.0
    v = K.cy + K.fy * (1.2 - 0.9) / 4.0
    box = np.array([[u - half_w, v - half_h, u + half_w, v + half_h]]) if case == "box" else np.zeros((0, 4))
    gone = []
    for k in range(5, 5 + 4 + 1):
        feed(k / FPS, [])
        feed.tracker.drop_unseen_people(box, depth, K, T)
        gone.append(feed.tracker.tracks == [])
    assert gone[-1] == dropped
    assert not any(gone[:3])  # never before unseen_after missed frames


class _StandInLearned:
    """A learned module that adds one person box 4 m ahead for the first ``frames`` frames and finds
    no 2D person box after that (``last_boxes_2d`` is what DODT.process reads)."""

    def __init__(self, frames: int):
        self.frames, self.k = frames, 0
        self.last_boxes_2d = np.zeros((0, 4), np.float32)
        self.last_3d = []

    def __call__(self, frame, depth_m, fused):
        self.k += 1
        if self.k > self.frames:
            return list(fused)
        d = det((4.0, 0.0, 0.85), seed=self.k)
        d.source, d.is_person = "learned", True
        return list(fused) + [d]


@pytest.mark.parametrize("after, gone", [(6, True), (0, False)])
def test_the_pipeline_drops_an_unseen_person_track(after, gone):
    """DODT.process applies the unseen-person rule with the learned module's 2D boxes of the frame:
    a person track whose boxes stop, with nothing behind it within the camera's range (no valid
    depth: the seen-through rule cannot drop it), is gone 8 frames later with
    learned.unseen_after = 6 frames, and still coasting with the rule off."""
    from dodt.frames import CameraIntrinsics, SensorFrame
    from dodt.pipeline import DODT
    from tests.dodt.synthetic import camera_pose

    cfg = DODTConfig()
    cfg = replace(cfg, learned=replace(cfg.learned, enabled=True, unseen_after=after / FPS))
    K, T = CameraIntrinsics(), camera_pose(z=1.2)
    depth_mm = np.zeros((K.height, K.width), np.uint16)
    color = np.zeros((K.height, K.width, 3), np.uint8)
    pipe = DODT(cfg, learned_detector=_StandInLearned(frames=5))
    people = []
    for k in range(5 + 8):
        r = pipe.process(SensorFrame(depth=depth_mm, color=color, intrinsics=K, T_world_camera=T,
                                     stamp=k / FPS, seq=k))
        people.append([o for o in r.obstacles if o.is_person])
    assert len(people[4]) == 1  # the person track stands 4 m ahead
    assert (people[-1] == []) == gone
    assert not gone or people[-1] == [] and people[-4] != []  # not before 6 missed frames


@pytest.mark.parametrize("x, person, coasts", [
    (7.0, True, 0.4),   # a person beyond the depth range (5.5 m): its learned boxes were its only detections
    (3.0, True, 1.0),   # within it the ensemble sees him too: the usual coast time
    (7.0, False, 1.0),  # not a person track: as before
])
def test_a_far_person_track_coasts_briefly(x, person, coasts):
    """A person track farther than depth.depth_max from the camera coasts learned.far_coast_time
    (0.4 s) after its last box; others coast track.coast_time (1 s)."""
    cfg = DODTConfig()
    assert cfg.learned.far_coast_time == 0.4 and cfg.depth.depth_max == 5.5 and cfg.track.coast_time == 1.0
    tracker = Tracker(cfg)
    for k in range(4):
        d = det([x, 0.0, 0.9])
        d.is_person = person
        tracker.correct([d], tracker.associate([d], CAMERA), k, k / FPS, CAMERA)
    assert len(tracker.tracks) == 1 and tracker.tracks[0].is_person == person
    last_seen = 3 / FPS
    alive, k = [], 4
    while k / FPS - last_seen < 1.5:
        tracker.predict(1 / FPS)
        tracker.correct([], [], k, k / FPS, CAMERA)
        alive.append((k / FPS - last_seen, bool(tracker.tracks)))
        k += 1
    lived = max(t for t, a in alive if a)
    assert coasts - 1 / FPS < lived <= coasts + 1e-9
    # without the camera's position the far rule cannot apply: every track coasts the full time
    if person and x > 5.5:
        t2 = Tracker(cfg)
        for k in range(4):
            d = det([x, 0.0, 0.9])
            d.is_person = True
            t2.correct([d], t2.associate([d], CAMERA), k, k / FPS)
        t2.correct([], [], 4, 3 / FPS + 0.5)
        assert len(t2.tracks) == 1


@pytest.mark.parametrize("same_kind", [True, False])
def test_velocity_is_differenced_between_detections_of_one_kind(same_kind):
    """A walker at 1 m/s seen as a cluster of points two frames in three and as a learned box the
    third, whose lifted depths sit 0.3 m farther than the cluster: with same-kind differences the
    filtered velocity stays within 0.05 m/s of the truth; differenced across kinds it reads the
    offset as motion (0.27 m/s off on average here)."""
    cfg = DODTConfig()
    cfg = replace(cfg, kalman=replace(cfg.kalman, same_kind_differences=same_kind))
    tracker, rng, errs = Tracker(cfg), np.random.default_rng(0), []
    for k in range(60):
        t = k / FPS
        learned = k % 3 == 2
        c = np.array([4.0, -1.0 + t, 0.9]) + (np.array([0.3, 0.0, 0.0]) if learned else 0.0)
        pts = c + rng.normal(0.0, 0.05, (60, 3)) * [0.25, 0.25, 0.9]
        d = Detection(center=c, size=SIZE.copy(), source="learned" if learned else "ensemble", points=pts)
        if k:
            tracker.predict(1 / FPS)
        tracker.correct([d], tracker.associate([d], CAMERA), k, t, CAMERA)
        assert len(tracker.tracks) == 1
        if k >= 30:
            errs.append(float(np.linalg.norm(tracker.tracks[0].kf.velocity - [0.0, 1.0])))
    if same_kind:
        assert max(errs) < 0.05
    else:
        assert np.mean(errs) > 0.15


def test_a_track_handed_from_one_sensor_to_another_reads_no_motion_from_their_offset():
    """A walker coming head-on at 1.5 m/s, boxed by the LiDAR (10 Hz) 0.3 m to its left of where the
    camera (30 Hz) boxes it once it comes into the camera's depth range: no velocity difference spans
    the two sensors, so the hand-over adds no sideways motion (differenced across them, the offset read
    as 1.2-1.8 m/s across for 0.4 s, a head-on walker taken for one crossing away from the drone)."""
    tracker, rng, lateral, ahead = Tracker(DODTConfig()), np.random.default_rng(1), [], []
    for k in range(40):
        t = k / FPS
        true = np.array([6.0 - 1.5 * t, 0.0, 0.9])
        by_lidar = k < 15
        if by_lidar and k % 3:
            dets = []  # the LiDAR boxes one frame in three
        else:
            c = true + (np.array([0.0, 0.3, 0.0]) if by_lidar else 0.0)
            pts = c + rng.normal(0.0, 0.05, (60, 3)) * [0.25, 0.25, 0.9]
            d = Detection(center=c, size=SIZE.copy(), source="lidar" if by_lidar else "ensemble", points=pts)
            d.sensor = "lidar" if by_lidar else ""
            dets = [d]
        if k:
            tracker.predict(1 / FPS)
        tracker.correct(dets, tracker.associate(dets, CAMERA), k, t, CAMERA)
        assert len(tracker.tracks) == 1
        if k >= 15:
            v = tracker.tracks[0].kf.velocity
            lateral.append(abs(float(v[1])))
            ahead.append(float(v[0]))
    assert max(lateral) < 0.3, lateral
    assert abs(ahead[-1] + 1.5) < 0.2  # and it keeps the walk toward the camera


def test_a_static_track_reports_the_velocity_its_filter_holds():
    """A track that identification has not called dynamic (here: never identified) reports the
    velocity and acceleration its filter holds, which move its prediction: no velocity hides
    behind a zero report."""
    feed = Feed(DODTConfig())
    for k in range(20):
        out = feed(k / FPS, [walker(k / FPS)])
    o = out[0]
    assert not o.dynamic
    assert o.velocity[1] > 0.5 and np.array_equal(o.velocity, o.filter_velocity)
    assert np.array_equal(o.acceleration, o.filter_acceleration) and o.acceleration.shape == (3,)
    np.testing.assert_array_equal(o.velocity[:2], feed.tracker.tracks[0].kf.velocity)
    report = TrackReport.from_tracked(o).to_json()  # what the log records of it
    assert report["velocity"] == report["filter_velocity"] and report["velocity"][1] > 0.5
    # dynamic, it reports the filter's velocity
    feed.tracker.tracks[0].geometric_dynamic = True
    o = feed.tracker.tracks[0].output(19 / FPS)
    assert o.dynamic and np.array_equal(o.velocity, o.filter_velocity)
