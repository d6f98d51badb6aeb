"""YOLO-MAD without the network: MAD lifting of a 2D box on synthetic depth, and the fusion rules."""
from dataclasses import replace

import numpy as np
import pytest

from dodt.config import LearnedConfig
from dodt.detection import Detection
from dodt.frames import CameraIntrinsics
from dodt.learned.fusion import fuse_learned
from dodt.learned.lifting import farthest_person_depth, lift_box, mad_depth_range, size_sanity

K = CameraIntrinsics()
CFG = LearnedConfig()
# Optical frame -> world (x forward, y left, z up), camera at 1.2 m height.
T = np.array([[0.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 1.2], [0.0, 0.0, 0.0, 1.0]])


def _scene(person_x: float, person_y: float, radius: float = 0.17, height: float = 1.75, seed: int = 0):
    """Depth of a room (floor, back wall at 9 m, a pillar at the person's side) with a person: a
    vertical cylinder of ``radius`` centred at world (person_x, person_y), and its 2D box grown as a
    detector's loose box (15 % of the width on each side, 5 % of the height) to take in background."""
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:K.height, 0:K.width].astype(np.float64)
    rx, ry = (u - K.cx) / K.fx, (v - K.cy) / K.fy  # optical ray (rx, ry, 1)
    # world ray direction: forward 1, left -rx, up -ry
    depth = np.full(u.shape, 9.0)  # back wall
    floor = np.where(ry > 1e-6, 1.2 / np.maximum(ry, 1e-6), np.inf)
    depth = np.minimum(depth, floor)
    # a pillar 0.6 m to the person's right and 1.5 m behind: clutter inside the box margin
    for cx, cy, r, h, in ((person_x + 1.5, person_y - 0.6, 0.3, 3.0), (person_x, person_y, radius, height)):
        # ray p = t (1, -rx, -ry) + (0, 0, 1.2) in world; solve |(t - cx, -t rx - cy)| = r
        a = 1 + rx ** 2
        b = -2 * cx + 2 * rx * cy
        c = cx ** 2 + cy ** 2 - r ** 2
        disc = b ** 2 - 4 * a * c
        t = np.where(disc >= 0, (-b - np.sqrt(np.maximum(disc, 0))) / (2 * a), np.inf)
        z = 1.2 - t * ry
        hit = (disc >= 0) & (t > 0) & (z >= 0) & (z <= h)
        depth = np.where(hit, np.minimum(depth, t), depth)
    depth = depth + rng.normal(0, 0.002 * depth ** 2)  # stereo-like noise growing with depth squared
    depth[rng.random(depth.shape) < 0.03] = 0.0  # dropouts
    # 2D box of the person, loose
    pts = np.array([[person_x - radius, person_y + s * radius, z] for s in (-1, 1) for z in (0.0, height)])
    cam = (pts - T[:3, 3]) @ T[:3, :3]
    uu = K.fx * cam[:, 0] / cam[:, 2] + K.cx
    vv = K.fy * cam[:, 1] / cam[:, 2] + K.cy
    mw, mh = 0.15 * (uu.max() - uu.min()), 0.05 * (vv.max() - vv.min())
    box = (uu.min() - mw, vv.min() - mh, uu.max() + mw, vv.max() + mh)
    return depth.astype(np.float32), box


@pytest.mark.parametrize("x,y", [(2.0, 0.0), (4.0, 0.5), (6.5, -0.8), (8.0, 0.3)])
def test_mad_lifting_finds_the_person_among_clutter(x, y):
    depth, box = _scene(x, y)
    det = lift_box(depth, box, K, T, CFG)
    assert det is not None and det.is_person and det.source == "learned"
    # the person's depth: its surface facing the camera (world x - radius) within 10 cm, the box
    # centred center_behind_median behind it; sideways within 10 cm
    assert abs(det.center[0] - CFG.center_behind_median - (x - 0.17)) < 0.10, det.center
    assert abs(det.center[1] - y) < 0.10, det.center
    assert 0.2 < det.size[0] < 1.0 and 0.2 < det.size[1] < 1.0
    assert det.lower[2] < 0.15 and 1.5 < det.upper[2] < 2.0


def test_without_mad_the_background_drags_the_box_away():
    """The same box's plain depth range spans wall and floor: MAD is what isolates the person."""
    depth, box = _scene(6.5, -0.8)
    x1, y1, x2, y2 = (int(round(b)) for b in box)
    d = depth[y1:y2, x1:x2]
    d = d[(d > 0.2) & (d < 10)]
    med, lo, hi = mad_depth_range(d, 1.5)
    assert hi - lo < 0.6 and d.max() - d.min() > 2.0
    assert abs(med - 6.5) < 0.3 and abs(np.mean(d) - 6.5) > 0.3  # the mean is dragged, the median is not


def test_mad_range_rules():
    assert mad_depth_range(np.array([]), 1.5) is None
    med, lo, hi = mad_depth_range(np.array([4.0, 4.1, 4.05, 3.95, 9.0, 1.0, 4.02]), 1.5)
    assert med == pytest.approx(4.02) and lo == pytest.approx(3.95) and hi == pytest.approx(4.1)


def test_depths_farther_than_a_person_of_the_box_height_are_not_read():
    """A far person with most of his depths lost to edge holes: the wall behind him holds most of the
    valid depths in the box. The box's height says how far a person can stand, which keeps the wall out."""
    x = 6.0
    depth, (x1, y1, x2, y2) = _scene(x, 0.0, seed=3)
    box = (x1 - (x2 - x1), y1, x2 + (x2 - x1), y2)  # as wide as a walker's swinging arms and legs
    person = np.abs(depth - (x - 0.17)) < 0.5
    holes = person & (np.random.default_rng(1).random(depth.shape) < 0.85)
    depth[holes] = 0.0
    unbounded = lift_box(depth, box, K, T, replace(CFG, max_person_height=None))
    assert unbounded is not None and unbounded.center[0] > x + 1.0  # lifted onto the wall at 9 m
    det = lift_box(depth, box, K, T, CFG)
    assert det is not None and abs(det.center[0] - CFG.center_behind_median - (x - 0.17)) < 0.10, det.center
    assert farthest_person_depth(box, K, 2.0) == pytest.approx(K.fy * 2.0 / (box[3] - box[1]))


def test_a_box_lifted_beyond_the_lift_range_is_dropped():
    depth, box = _scene(8.0, 0.3)
    assert lift_box(depth, box, K, T, CFG) is not None
    assert lift_box(depth, box, K, T, replace(CFG, max_lift_range=7.5)) is None


def test_too_few_depths_give_no_box():
    depth = np.zeros((K.height, K.width), np.float32)
    depth[100:103, 100:103] = 4.0  # 9 valid pixels < min_depth_pixels
    assert lift_box(depth, (90, 90, 120, 120), K, T, CFG) is None


def test_size_sanity_replaces_implausible_dimensions():
    lo, hi = size_sanity(np.array([0.0, 0.0, 0.5]), np.array([3.0, 0.4, 0.9]), CFG)  # 3 m long, 0.4 m tall
    size, center = hi - lo, (lo + hi) / 2
    assert size == pytest.approx([0.5, 0.4, 1.8])
    assert center[0] == pytest.approx(1.5) and center[2] == pytest.approx(0.9)  # height stands on the floor


def _box(c, s=(0.5, 0.5, 1.7), person=False, source="ensemble"):
    d = Detection(center=np.array(c, float), size=np.array(s, float), source=source)
    d.is_person = person
    return d


def test_fusion_mutual_best_match_marks_the_fused_box_a_person():
    fused = [_box((3, 0, 0.85)), _box((3, 2, 0.85))]
    learned = [_box((3.2, 0.1, 0.9), (0.5, 0.5, 1.8), True, "learned")]
    out = fuse_learned(fused, learned, np.zeros(3), CFG)  # default: the geometric box is kept
    assert len(out) == 2 and out[1] is fused[1]
    assert out[0].is_person and np.allclose(out[0].center, fused[0].center) and np.allclose(out[0].size, fused[0].size)
    out = fuse_learned(fused, learned, np.zeros(3), LearnedConfig(match_box="union"))  # the reference's union
    m = out[0]
    assert m.is_person and np.allclose(m.lower, np.minimum(fused[0].lower, learned[0].lower))
    assert np.allclose(m.upper, np.maximum(fused[0].upper, learned[0].upper))
    assert not fused[0].is_person  # the inputs are not changed


def test_fusion_unmatched_far_box_is_added_near_one_dropped():
    fused = [_box((2, 1.5, 0.85))]
    far = _box((7, -1, 0.9), (0.5, 0.5, 1.8), True, "learned")
    near = _box((2, -1, 0.9), (0.5, 0.5, 1.8), True, "learned")  # 2.2 m < overwrite_distance 3 m
    out = fuse_learned(fused, [far, near], np.zeros(3), CFG)
    assert out[0] is fused[0] and out[1:] == [far]
    assert fuse_learned([], [far, near], np.zeros(3), CFG) == [far]


def test_fusion_drops_an_unmatched_box_right_beside_a_fused_one():
    fused = [_box((6, 0, 0.85))]
    beside = _box((6.7, 0.0, 0.9), (0.5, 0.5, 1.8), True, "learned")  # 0.2 m from the fused box's face
    away = _box((8.0, 0.0, 0.9), (0.5, 0.5, 1.8), True, "learned")
    assert fuse_learned(fused, [beside, away], np.zeros(3), CFG)[1:] == [away]
    assert fuse_learned(fused, [beside], np.zeros(3), LearnedConfig(duplicate_gate=0.0))[1:] == [beside]


def test_fusion_adds_one_box_per_far_person_when_two_views_of_them_survive_nms():
    first = _box((7.0, 0.0, 0.9), (0.5, 0.5, 1.8), True, "learned")  # the better-scored 2D box
    second = _box((7.3, 0.1, 0.9), (0.5, 0.5, 1.8), True, "learned")  # the same person, lifted again
    other = _box((7.0, 1.5, 0.9), (0.5, 0.5, 1.8), True, "learned")  # a second person beside them
    assert fuse_learned([], [first, second, other], np.zeros(3), CFG) == [first, other]
    assert fuse_learned([], [first, second], np.zeros(3), LearnedConfig(duplicate_gate=0.0)) == [first, second]


def test_fusion_overlap_without_mutual_best_match_is_dropped():
    fused = [_box((5, 0, 0.85))]
    a = _box((5.05, 0, 0.9), (0.5, 0.5, 1.8), True, "learned")  # the fused box's best match
    b = _box((5.4, 0.1, 0.9), (0.5, 0.5, 1.8), True, "learned")  # overlaps it, beaten by a
    out = fuse_learned(fused, [a, b], np.zeros(3), CFG)
    assert len(out) == 1 and out[0].is_person


def test_a_track_is_a_person_only_when_person_boxes_recur():
    from dodt.config import DODTConfig
    from dodt.tracker import Track

    cfg = DODTConfig()
    assert (cfg.learned.person_span, cfg.learned.person_fraction) == (2 / 30, 1.0)  # 3 of 3 frames at 30 Hz
    tr = Track(1, _box((3, 0, 0.85), person=True), 0, 0.0, cfg)
    assert not tr.is_person  # one box: the votes do not reach back over person_span
    tr.update(_box((3, 0, 0.85), person=True), 1, 0.033)
    assert not tr.is_person  # 2 of 3
    tr.update(_box((3, 0, 0.85), person=True), 2, 0.067)
    assert tr.is_person  # 3 of the last 3: labelled at its third frame
    tr.update(_box((3, 0, 0.85)), 3, 0.1)
    assert not tr.is_person  # a false box does not label a static obstacle for good
    loose = replace(cfg, learned=replace(cfg.learned, person_fraction=2 / 3))
    tr = Track(2, _box((3, 0, 0.85), person=True), 0, 0.0, loose)
    tr.update(_box((3, 0, 0.85)), 1, 0.033)
    tr.update(_box((3, 0, 0.85), person=True), 2, 0.067)
    assert tr.is_person  # 2 of the last 3 with person_fraction = 2 / 3


@pytest.mark.parametrize("rate", [15.0, 10.0, 5.0])
def test_the_person_label_needs_two_boxes_at_a_low_frame_rate(rate):
    """person_span is time: below 30 Hz the label needs the boxes of two frames, never one."""
    from dodt.config import DODTConfig
    from dodt.tracker import Track

    from dodt.windows import FrameClock

    clock = FrameClock()
    clock.observe(1 / rate)  # the pipeline's clock, at this rate
    tr = Track(1, _box((3, 0, 0.85), person=True), 0, 0.0, DODTConfig(), clock)
    assert not tr.is_person
    n = 1
    while not tr.is_person:
        tr.update(_box((3, 0, 0.85), person=True), n, n / rate)
        n += 1
    assert n == 2  # frames of boxes when labelled


def test_fusion_does_not_mark_the_wall_behind_a_person_a_person():
    """A person 0.3 m in front of a wall segment: his lifted box overlaps the segment's fused box
    (their mutual best match), but the centres lie 0.6 m apart, beyond person_match_gate (0.5 m):
    the wall stays unmarked. With the gate off (0), the reference's rule marks it."""
    wall = _box((4.1, 0.0, 1.0), (0.4, 1.2, 2.0))
    person = _box((3.5, 0.0, 0.9), (1.2, 0.5, 1.8), True, "learned")  # thick: MAD kept some wall depths
    assert CFG.person_match_gate == 0.5
    out = fuse_learned([wall], [person], np.zeros(3), CFG)
    assert out == [wall] and not out[0].is_person  # overlapping, so not added either
    out = fuse_learned([wall], [person], np.zeros(3), LearnedConfig(person_match_gate=0.0))
    assert out[0].is_person


def test_fusion_does_not_mark_a_box_taller_than_a_person_a_person():
    """A 2D box cut by the image's side edge reads the obstacle behind the person, and its lifted
    box lands on that 3 m tall obstacle, within person_match_gate of its centre: the obstacle is
    no person (person_box_max_height 2.5 m). With the bound off (0), it is marked."""
    obstacle = _box((6.87, -2.95, 1.48), (1.15, 0.47, 2.96))
    lifted = _box((6.55, -2.88, 0.9), (0.5, 0.45, 1.8), True, "learned")
    assert CFG.person_box_max_height == 2.5
    out = fuse_learned([obstacle], [lifted], np.zeros(3), CFG)
    assert out == [obstacle] and not out[0].is_person
    out = fuse_learned([obstacle], [lifted], np.zeros(3), LearnedConfig(person_box_max_height=0.0))
    assert out[0].is_person


def test_fusion_replaces_a_fragment_of_the_person_by_the_union():
    """Near the depth range's end the geometric detectors see the part of a person within range,
    a box a metre lower than the person's lifted box: the union of the two replaces it (marked a
    person, its points gathered later by the pipeline), so a track fed by the lifted box can take
    it. A fused box as high as the learned one stays as it is."""
    fragment = _box((5.9, 1.18, 0.71), (0.44, 0.27, 0.51))
    lifted = _box((5.91, 1.21, 0.85), (0.35, 0.8, 1.8), True, "learned")
    out = fuse_learned([fragment], [lifted], np.zeros(3), CFG)
    assert len(out) == 1 and out[0].is_person and out[0].source == "ensemble+learned"
    assert np.allclose(out[0].lower, np.minimum(fragment.lower, lifted.lower))
    assert np.allclose(out[0].upper, np.maximum(fragment.upper, lifted.upper))
    assert len(out[0].points) == 0
    out = fuse_learned([fragment], [lifted], np.zeros(3), LearnedConfig(fragment_height=0.0))
    assert out[0].is_person and np.allclose(out[0].size, fragment.size)  # the rule off: the fragment kept
    whole = _box((5.9, 1.18, 0.85), (0.5, 0.5, 1.7))
    out = fuse_learned([whole], [lifted], np.zeros(3), CFG)
    assert out[0].is_person and np.allclose(out[0].size, whole.size)


def test_a_person_half_hidden_behind_another_is_lifted_to_his_own_depth():
    from dodt.learned.lifting import in_front, lift_boxes

    back_depth, back = _scene(6.0, 0.3, seed=1)
    front_depth, front = _scene(3.5, 0.0, seed=2)
    depth = np.where((back_depth > 0) & (front_depth > 0), np.minimum(back_depth, front_depth), 0.0).astype(np.float32)
    assert in_front(back, front, CFG.occluder_margin) and not in_front(front, back, CFG.occluder_margin)
    # read through the person in front, the percentile depth of the box behind is his
    alone = lift_box(depth, back, K, T, CFG)
    assert alone is not None and abs(alone.center[0] - 3.5) < 0.5
    lifted_front, lifted_back = lift_boxes(depth, [front, back], K, T, CFG)
    assert abs(lifted_front.center[0] - CFG.center_behind_median - (3.5 - 0.17)) < 0.10
    assert abs(lifted_back.center[0] - CFG.center_behind_median - (6.0 - 0.17)) < 0.15, lifted_back.center
    # a box on a part of the front person (his upper half, within his box's sides) is lifted onto
    # him, not onto the background seen past him
    x1, y1, x2, y2 = front
    part = (x1 + 0.1 * (x2 - x1), y1, x2 - 0.1 * (x2 - x1), (y1 + y2) / 2)
    assert not in_front(part, front, CFG.occluder_margin)
    assert abs(lift_boxes(depth, [front, part], K, T, CFG)[1].center[0] - 3.5) < 0.3
    # switched off, each box is lifted on its own
    off = replace(CFG, occluder_margin=None)
    assert np.allclose(lift_boxes(depth, [front, back], K, T, off)[1].center, lift_box(depth, back, K, T, off).center)
