"""The paper's Algorithm 1 (ensemble detection) and the 3D IoU it is built on.

Hand-computed boxes: every expected number below can be checked with pencil and paper.
"""
from __future__ import annotations

import numpy as np
import pytest

from dodt.config import EnsembleConfig
from dodt.detection import Detection
from dodt.ensemble import ensemble, fuse, mutual_best_pairs
from dodt.geometry import iou_matrix


def box(center, size=(1.0, 1.0, 1.0), source="udepth", n_points=0, seed=0):
    c = np.asarray(center, float)
    s = np.asarray(size, float)
    rng = np.random.default_rng(seed)
    pts = (c + (rng.random((n_points, 3)) - 0.5) * s).astype(np.float32)
    return Detection(center=c, size=s, source=source, points=pts)


def iou(a: Detection, b: Detection) -> float:
    m = iou_matrix([a.center], [a.size], [b.center], [b.size])
    assert m.shape == (1, 1)
    return float(m[0, 0])


# --------------------------------------------------------------------------- IoU


def test_iou_identical_boxes_is_one():
    a = box((1.0, -2.0, 0.5), (0.4, 0.6, 1.7))
    assert iou(a, a) == pytest.approx(1.0)


def test_iou_disjoint_boxes_is_zero():
    assert iou(box((0, 0, 0)), box((3, 0, 0))) == 0.0
    assert iou(box((0, 0, 0)), box((0, 0, 1.5))) == 0.0  # apart along z only
    # boxes that only touch along a face share no volume
    assert iou(box((0, 0, 0)), box((1.0, 0, 0))) == 0.0


def test_iou_half_overlap_along_one_axis_is_one_third():
    # unit cubes shifted by half a side: intersection 0.5, union 1 + 1 - 0.5 = 1.5
    assert iou(box((0, 0, 0)), box((0.5, 0, 0))) == pytest.approx(1 / 3)
    assert iou(box((0, 0, 0)), box((0, -0.5, 0))) == pytest.approx(1 / 3)
    assert iou(box((0, 0, 0)), box((0, 0, 0.5))) == pytest.approx(1 / 3)


def test_iou_nested_boxes_is_the_volume_ratio():
    outer = box((0, 0, 0), (2.0, 2.0, 2.0))  # volume 8
    inner = box((0.3, -0.2, 0.1), (1.0, 1.0, 1.0))  # volume 1, inside the outer box
    assert iou(outer, inner) == pytest.approx(1 / 8)
    assert iou(inner, outer) == pytest.approx(1 / 8)
    flat = box((0, 0, 0), (2.0, 2.0, 0.5))  # volume 2, inside the outer box
    assert iou(outer, flat) == pytest.approx(2 / 8)


def test_iou_general_overlap_by_hand():
    # a = [0, 2] x [0, 1] x [0, 1], b = [1, 3] x [0.5, 1.5] x [0, 1]
    # intersection = 1 x 0.5 x 1 = 0.5; union = 2 + 2 - 0.5 = 3.5
    a = Detection.from_bounds((0, 0, 0), (2, 1, 1), "udepth")
    b = Detection.from_bounds((1, 0.5, 0), (3, 1.5, 1), "dbscan")
    assert iou(a, b) == pytest.approx(0.5 / 3.5)


def test_iou_matrix_shape_and_symmetry():
    A = [box((0, 0, 0)), box((0.5, 0, 0)), box((5, 5, 5))]
    B = [box((0, 0, 0)), box((0, 0, 0.5))]
    m = iou_matrix([a.center for a in A], [a.size for a in A], [b.center for b in B], [b.size for b in B])
    mt = iou_matrix([b.center for b in B], [b.size for b in B], [a.center for a in A], [a.size for a in A])
    assert m.shape == (3, 2)
    np.testing.assert_allclose(m, mt.T)
    np.testing.assert_allclose(m, [[1.0, 1 / 3], [1 / 3, 1 / 7], [0.0, 0.0]])
    # [1, 1] above: offsets (0.5, 0, 0) vs (0, 0, 0.5): intersection 0.5 * 1 * 0.5 = 0.25, union 1.75


def test_iou_of_degenerate_boxes_is_zero_not_nan():
    flat = box((0, 0, 0), (0.0, 1.0, 1.0))  # zero volume
    m = iou_matrix([flat.center, flat.center], [flat.size, flat.size], [flat.center], [flat.size])
    assert np.all(np.isfinite(m))
    np.testing.assert_array_equal(m, 0.0)


def test_iou_matrix_of_empty_inputs():
    m = iou_matrix(np.empty((0, 3)), np.empty((0, 3)), [(0, 0, 0)], [(1, 1, 1)])
    assert m.shape == (0, 1)


# --------------------------------------------------------------------------- Algorithm 1 on IoU matrices


def test_mutual_best_pairs_on_a_hand_matrix():
    m = np.array([[0.5, 0.1, 0.0],
                  [0.2, 0.6, 0.0],
                  [0.0, 0.0, 0.0]])
    assert mutual_best_pairs(m, 0.05) == [(0, 0), (1, 1)]


def test_pair_below_or_at_the_threshold_is_dropped():
    assert mutual_best_pairs(np.array([[0.04]]), 0.05) == []
    assert mutual_best_pairs(np.array([[0.05]]), 0.05) == []  # strictly above the threshold
    assert mutual_best_pairs(np.array([[0.06]]), 0.05) == [(0, 0)]
    # a higher threshold drops a pair a lower one keeps
    m = np.array([[0.3, 0.0], [0.0, 0.7]])
    assert mutual_best_pairs(m, 0.5) == [(1, 1)]


def test_one_sided_best_match_is_not_fused():
    # detector 1: A (row 0), C (row 1); detector 2: B (column 0), D (column 1).
    # A's best is B (0.30 > 0.20), but B's best is C (0.60): A is not fused, even though D's
    # best is A and their IoU is above the threshold.
    m = np.array([[0.30, 0.20],
                  [0.60, 0.00]])
    assert mutual_best_pairs(m, 0.05) == [(1, 0)]


def test_mutual_best_pairs_of_empty_matrices():
    assert mutual_best_pairs(np.zeros((0, 3)), 0.05) == []
    assert mutual_best_pairs(np.zeros((3, 0)), 0.05) == []
    assert mutual_best_pairs(np.zeros((0, 0)), 0.05) == []


# --------------------------------------------------------------------------- Algorithm 1 on detections


def test_ensemble_fuses_boxes_both_detectors_agree_on_and_drops_the_rest():
    cfg = EnsembleConfig()
    person_u = box((2.0, 0.0, 0.9), (0.5, 0.5, 1.7), "udepth")
    person_d = box((2.05, 0.02, 0.95), (0.45, 0.5, 1.6), "dbscan", n_points=30)
    only_udepth = box((4.0, 2.0, 0.9), (0.5, 0.5, 1.7), "udepth")  # the other detector misses it
    only_dbscan = box((1.0, -2.0, 0.9), (0.5, 0.5, 1.7), "dbscan", n_points=10)
    out = ensemble([person_u, only_udepth], [only_dbscan, person_d], cfg)
    assert len(out) == 1
    f = out[0]
    assert f.source == "ensemble"
    np.testing.assert_allclose(f.center, (person_u.center + person_d.center) / 2)
    np.testing.assert_allclose(f.size, np.maximum(person_u.size, person_d.size))


def test_ensemble_drops_a_pair_below_the_threshold():
    a = box((0, 0, 0))
    b = box((0.9, 0, 0), source="dbscan")  # IoU 0.1 / 1.9 = 0.0526
    assert iou(a, b) == pytest.approx(0.1 / 1.9)
    assert len(ensemble([a], [b], EnsembleConfig(iou_threshold=0.05))) == 1
    assert ensemble([a], [b], EnsembleConfig(iou_threshold=0.06)) == []


def test_ensemble_one_sided_best_match_is_not_fused():
    # A's best in detector 2 is B, but B's best in detector 1 is C; D overlaps A a little
    B = box((0.0, 0, 0), source="dbscan", n_points=5)
    C = box((0.05, 0, 0), source="udepth")  # IoU(C, B) = 0.95 / 1.05
    A = box((0.6, 0, 0), source="udepth")  # IoU(A, B) = 0.4 / 1.6 = 0.25
    D = box((1.4, 0, 0), source="dbscan", n_points=5)  # IoU(A, D) = 0.2 / 1.8 = 0.11
    assert iou(A, B) > iou(A, D) > 0.05
    assert iou(C, B) > iou(A, B)
    out = ensemble([A, C], [B, D], EnsembleConfig())
    assert len(out) == 1
    np.testing.assert_allclose(out[0].center, (B.center + C.center) / 2)


def test_ensemble_of_empty_inputs_gives_no_boxes():
    cfg = EnsembleConfig()
    a = box((0, 0, 0))
    assert ensemble([], [], cfg) == []
    assert ensemble([a], [], cfg) == []
    assert ensemble([], [a], cfg) == []


def test_ensemble_keeps_the_order_of_detector_one():
    cfg = EnsembleConfig()
    u = [box((0, 0, 0)), box((5, 0, 0)), box((10, 0, 0))]
    d = [box((10.1, 0, 0), source="dbscan"), box((0.1, 0, 0), source="dbscan"), box((5.1, 0, 0), source="dbscan")]
    out = ensemble(u, d, cfg)
    np.testing.assert_allclose([o.center[0] for o in out], [0.05, 5.05, 10.05])


# --------------------------------------------------------------------------- fusion rules


def test_paper_fusion_takes_the_larger_size_per_axis_and_the_mean_centre():
    a = box((0.0, 0.0, 1.0), (1.0, 2.0, 1.0))
    b = box((0.2, 0.4, 0.8), (1.2, 1.0, 0.8), source="dbscan")
    f = fuse(a, b, "paper")
    np.testing.assert_allclose(f.center, (0.1, 0.2, 0.9))
    np.testing.assert_allclose(f.size, (1.2, 2.0, 1.0))
    assert f.source == "ensemble"


def test_union_fusion_takes_the_union_box():
    a = Detection.from_bounds((0, 0, 0), (1, 2, 1), "udepth")
    b = Detection.from_bounds((0.5, -1, 0.2), (2, 1, 1.5), "dbscan")
    f = fuse(a, b, "union")
    np.testing.assert_allclose(f.lower, (0, -1, 0))
    np.testing.assert_allclose(f.upper, (2, 2, 1.5))
    np.testing.assert_allclose(f.center, (1.0, 0.5, 0.75))
    np.testing.assert_allclose(f.size, (2.0, 3.0, 1.5))


def test_ensemble_uses_the_configured_fusion():
    a = Detection.from_bounds((0, 0, 0), (1, 1, 1), "udepth")
    b = Detection.from_bounds((0.5, 0.0, 0.0), (1.5, 1, 1), "dbscan")
    paper = ensemble([a], [b], EnsembleConfig(fusion="paper"))[0]
    union = ensemble([a], [b], EnsembleConfig(fusion="union"))[0]
    np.testing.assert_allclose(paper.size, (1, 1, 1))
    np.testing.assert_allclose(paper.center, (0.75, 0.5, 0.5))
    np.testing.assert_allclose(union.size, (1.5, 1, 1))
    np.testing.assert_allclose(union.center, (0.75, 0.5, 0.5))


@pytest.mark.parametrize("how", ["paper", "union"])
def test_fused_detection_carries_the_points_of_the_input_with_more_points(how):
    few = box((0, 0, 0), n_points=5, seed=1)
    many = box((0.1, 0, 0), source="dbscan", n_points=40, seed=2)
    assert fuse(few, many, how).points is many.points
    assert fuse(many, few, how).points is many.points


def test_fusion_keeps_the_person_flag():
    a = box((0, 0, 0))
    b = box((0.1, 0, 0), source="learned")
    b.is_person = True
    assert fuse(a, b, "paper").is_person
    assert fuse(b, a, "union").is_person
    assert not fuse(a, box((0.1, 0, 0)), "paper").is_person


@pytest.mark.parametrize("seed", range(5))
def test_fused_boxes_cover_their_inputs(seed):
    """Union fusion contains both boxes; paper fusion is at least as large as each per axis."""
    rng = np.random.default_rng(seed)
    for _ in range(20):
        a = box(rng.uniform(-1, 1, 3), rng.uniform(0.1, 2, 3))
        b = box(a.center + rng.uniform(-0.5, 0.5, 3), rng.uniform(0.1, 2, 3))
        u = fuse(a, b, "union")
        for x in (a, b):
            assert np.all(u.lower <= x.lower + 1e-12) and np.all(u.upper >= x.upper - 1e-12)
            assert iou(u, x) == pytest.approx(np.prod(x.size) / np.prod(u.size))  # nested
        p = fuse(a, b, "paper")
        assert np.all(p.size >= a.size) and np.all(p.size >= b.size)
