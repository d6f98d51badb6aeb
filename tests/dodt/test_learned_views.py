"""Several views of an image through the person detector, fused (dodt.learned.views)."""
import numpy as np
import pytest

from dodt.learned import layout
from dodt.learned.views import VIEWS, View, detect, fuse, parse_views, suppress, to_image, view_image


def test_views_by_name_and_bad_names():
    assert parse_views("full, flip,center") == (VIEWS["full"], VIEWS["flip"], VIEWS["center"])
    with pytest.raises(ValueError, match="unknown 'side'"):
        parse_views(["full", "side"])
    with pytest.raises(ValueError, match="twice"):
        parse_views(["full", "full"])
    with pytest.raises(ValueError, match="at least one"):
        parse_views([])


def test_mirrored_and_cropped_boxes_map_back_to_the_image():
    b, s = to_image(np.array([[0.1, 0.2, 0.3, 0.9]]), np.array([0.8]), VIEWS["flip"])
    assert np.allclose(b, [[0.7, 0.2, 0.9, 0.9]]) and s.tolist() == pytest.approx([0.8])
    c = VIEWS["center"]  # the central two thirds
    b, _ = to_image(np.array([[0.25, 0.25, 0.75, 0.75]]), np.array([0.9]), c)
    assert np.allclose(b, [[1 / 3, 1 / 3, 2 / 3, 2 / 3]])
    # a box cut by the crop's inner side is dropped: its extent would be the crop's, not the person's
    b, _ = to_image(np.array([[0.0, 0.3, 0.2, 0.8], [0.3, 0.3, 0.5, 0.8]]), np.array([0.9, 0.9]), c)
    assert len(b) == 1


def test_view_images_have_the_network_size_and_show_the_region():
    img = np.zeros((480, 640, 3), np.uint8)
    img[:, 320:] = 200  # right half bright
    full, flip = view_image(img, VIEWS["full"]), view_image(img, VIEWS["flip"])
    assert full.shape == flip.shape == (layout.INPUT_H, layout.INPUT_W, 3)
    assert full[:, -5:].mean() > 150 and flip[:, :5].mean() > 150 and flip[:, -5:].mean() < 50


def test_fusion_scores_agreement_over_the_views_that_could_see():
    views = (VIEWS["full"], VIEWS["flip"], VIEWS["center"])
    person = np.array([[0.45, 0.4, 0.55, 0.6]])  # inside the central crop: all three could see it
    lone = np.array([[0.02, 0.1, 0.1, 0.5]])  # outside the crop: two views could see it
    per_view = [(np.vstack([person, lone]), np.array([0.9, 0.6])), (person + 0.005, np.array([0.8])),
                (person, np.array([0.7]))]
    boxes, scores = fuse(per_view, views, iou=0.45)
    assert len(boxes) == 2
    assert scores[0] == pytest.approx((0.9 + 0.8 + 0.7) / 3, abs=1e-6)
    assert scores[1] == pytest.approx(0.6 / 2, abs=1e-6)  # one of the two views that could see it
    assert np.all(np.abs(boxes[0] - person[0]) < 0.005)
    with pytest.raises(ValueError, match="2 sets of boxes for 3 views"):
        fuse(per_view[:2], views, iou=0.45)


def test_one_full_view_is_the_plain_decode_and_nms():
    rng = np.random.default_rng(0)
    raw = rng.normal(0, 2, (layout.CHANNELS, layout.GRID_H, layout.GRID_W)).astype(np.float32)
    img = rng.integers(0, 255, (480, 640, 3)).astype(np.uint8)
    got_b, got_s = detect(lambda x: raw, img, (VIEWS["full"],), 0.5, 0.45)
    b, s = layout.decode(raw, 0.5)
    keep = layout.nms(b, s, 0.45)
    assert np.array_equal(got_b, b[keep]) and np.array_equal(got_s, s[keep])
    assert isinstance(VIEWS["full"], View) and VIEWS["full"].is_whole


def test_soft_nms_lowers_overlapping_scores_instead_of_dropping_the_boxes():
    """Two people whose boxes overlap by an IoU of 0.6 (one partly behind the other): NMS at 0.45
    keeps one; soft-NMS keeps both, the second scored 0.9 x exp(-0.6^2 / sigma), a box apart
    keeps its score, and a near-duplicate (IoU 0.9) falls under the floor (0.3) and is dropped."""
    boxes = np.array([[0.10, 0.1, 0.30, 0.9],   # score 0.95
                      [0.15, 0.1, 0.35, 0.9],   # IoU 0.6 with the first
                      [0.60, 0.1, 0.80, 0.9],   # apart
                      [0.11, 0.1, 0.31, 0.9]],  # a near-duplicate of the first
                     np.float32)
    scores = np.array([0.95, 0.9, 0.7, 0.8], np.float32)
    iou = layout.iou_one(boxes[0], boxes)
    assert iou[1] == pytest.approx(0.6, abs=1e-5) and iou[3] > 0.9
    assert list(layout.nms(boxes, scores, 0.45)) == [0, 2]
    kept_b, kept_s = layout.soft_nms(boxes, scores, sigma=0.5, floor=0.3)
    assert np.array_equal(kept_b, boxes[[0, 2, 1]])
    assert kept_s == pytest.approx([0.95, 0.7, 0.9 * np.exp(-0.36 / 0.5)], rel=1e-5)
    # the same through the run-time detection path, and NMS there without a sigma
    assert np.array_equal(suppress(boxes, scores, 0.45, 0.5, 0.3)[0], kept_b)
    assert np.array_equal(suppress(boxes, scores, 0.45, 0.0, 0.3)[0], boxes[[0, 2]])
    assert np.array_equal(suppress(boxes, scores, 0.45, 0.5, 0.5)[0], boxes[[0, 2]])  # 0.44 < 0.5


def test_a_negative_soft_nms_sigma_is_refused_by_name():
    from dodt.learned.model import ModelError, PersonDetector2D

    with pytest.raises(ModelError, match="soft_nms_sigma"):
        PersonDetector2D(soft_sigma=-0.5)
