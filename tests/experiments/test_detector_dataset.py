"""The detector's training-data generator: file layout, box rules, determinism, seed splits."""
import json
import math

import numpy as np
import pytest

from dodt.learned.layout import INPUT_H, INPUT_W, resize_for_network
from experiments.detector import dataset as D

SEEDS = [3, 8]
PER_SEED = 3


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    calls = []
    path = D.generate(tmp_path_factory.mktemp("det"), "train", SEEDS, images_per_seed=PER_SEED,
                      progress=lambda done, total: calls.append((done, total)))
    return path, D.load(path), calls


def test_file_layout_and_meta(generated):
    path, data, calls = generated
    n = len(SEEDS) * PER_SEED
    assert path.name == "train.npz" and path.exists()
    assert data["images"].shape == (n, INPUT_H, INPUT_W, 3) and data["images"].dtype == np.uint8
    assert data["seeds"].dtype == np.int32 and data["seeds"].tolist() == [s for s in SEEDS for _ in range(PER_SEED)]
    boxes = data["boxes"]
    assert boxes.dtype == np.float32 and boxes.ndim == 2 and boxes.shape[1] == 7 and len(boxes) > 0
    meta = data["meta"]
    assert meta["split"] == "train" and meta["seeds"] == SEEDS and meta["images_per_seed"] == PER_SEED
    assert meta["version"] == D.GENERATOR_VERSION
    assert meta["rules"]["min_visible_pixels"] == D.MIN_VISIBLE_PIXELS == 20
    assert meta["rules"]["min_box_height_px"] == D.MIN_BOX_HEIGHT_PX == 6
    c = meta["counts"]
    assert c["images"] == n and c["boxes"] == len(boxes)
    assert c["boxes_within_10m"] == int(np.sum(boxes[:, 5] <= 10.0))
    assert c["negatives"] == n - len(np.unique(boxes[:, 0]))
    assert calls == [(i + 1, n) for i in range(n)]
    # images are real renders, not blank: they vary within each image and between images
    assert all(data["images"][i].std() > 5 for i in range(n))
    assert not np.array_equal(data["images"][0], data["images"][1])


def test_box_values_are_in_range(generated):
    _, data, _ = generated
    b = data["boxes"]
    idx = b[:, 0]
    assert np.all(idx == np.round(idx)) and idx.min() >= 0 and idx.max() < len(data["images"])
    assert np.all(np.diff(idx) >= 0)  # grouped by image
    assert np.all((b[:, 1:5] >= 0) & (b[:, 1:5] <= 1))
    assert np.all(b[:, 1] < b[:, 3]) and np.all(b[:, 2] < b[:, 4])
    assert np.all(b[:, 4] - b[:, 2] >= D.MIN_BOX_HEIGHT_PX / 480 - 1e-6)
    assert np.all(b[:, 5] > 0)
    assert np.all(b[:, 6] >= D.MIN_VISIBLE_PIXELS) and np.all(b[:, 6] == np.round(b[:, 6]))
    # a box cannot hold more visible pixels than its own area at 640 x 480
    area_px = (b[:, 3] - b[:, 1]) * 640 * (b[:, 4] - b[:, 2]) * 480
    assert np.all(b[:, 6] <= area_px + 0.5)


def test_same_seeds_give_identical_arrays(generated, tmp_path):
    _, a, _ = generated
    b = D.load(D.generate(tmp_path, "again", SEEDS, images_per_seed=PER_SEED))
    for k in ("images", "boxes", "seeds"):
        assert a[k].dtype == b[k].dtype and a[k].shape == b[k].shape
        assert a[k].tobytes() == b[k].tobytes(), k
    assert {**a["meta"], "split": None} == {**b["meta"], "split": None}


def test_boxes_are_the_extent_of_the_visible_person_pixels(generated):
    _, data, _ = generated
    seed = SEEDS[0]
    scene = D.build_scene(seed, PER_SEED)
    first_person_id = len(scene.scenario.obstacles) + 1
    person_ids = range(first_person_id, first_person_id + len(scene.scenario.people))
    n_boxes = 0
    for k, sample in enumerate(D.render_scene(seed, PER_SEED)):
        seg = sample.segmentation
        assert seg.shape == (480, 640) and sample.color.shape == (480, 640, 3)
        # the stored image is the network-size resize of this very render
        assert np.array_equal(data["images"][k], resize_for_network(sample.color))
        stored = data["boxes"][data["boxes"][:, 0] == k]
        assert np.array_equal(stored[:, 1:], sample.boxes.astype(np.float32))
        expected = []
        for pid in person_ids:
            rows, cols = np.nonzero(seg == pid)
            if len(rows) >= 20 and rows.max() - rows.min() + 1 >= 6:
                expected.append((cols.min() / 640, rows.min() / 480, (cols.max() + 1) / 640, (rows.max() + 1) / 480,
                                 len(rows)))
        got = [tuple(r[:4]) + (r[5],) for r in sample.boxes]
        assert np.allclose(sorted(got), sorted(expected)) if expected else got == []
        for x1, y1, x2, y2, *_ in sample.boxes:
            inside = seg[round(y1 * 480):round(y2 * 480), round(x1 * 640):round(x2 * 640)]
            assert np.any(np.isin(inside, list(person_ids)))
            n_boxes += 1
    assert n_boxes > 0


def test_views_are_varied_and_inside_the_corridor():
    heights, tilts, dists, negatives, people = [], [], [], 0, []
    for seed in range(12):
        scene = D.build_scene(seed, 10)
        co = scene.scenario.corridor
        assert 14.0 <= co.length <= 22.0 and 3.0 <= co.width <= 8.0
        assert 2 <= len(scene.scenario.obstacles) <= 8
        assert 1 <= len(scene.scenario.people) <= 5
        people.append(len(scene.scenario.people))
        assert all(p.color is not None for p in scene.scenario.people)
        for v in scene.views:
            x, y, z = v.position
            assert 0.0 < x < co.length and abs(y) < co.width / 2
            heights.append(z)
            tilts += [v.roll, v.pitch]
            negatives += v.negative
            if v.negative:  # looks into the corridor, not at a wall filling the image
                assert D._open_ahead(co, np.array(v.position[:2]), v.yaw) >= D.NEGATIVE_VIEW_DEPTH
    assert min(heights) >= 0.5 and max(heights) <= 2.0 and max(heights) - min(heights) > 1.0
    assert max(abs(t) for t in tilts) <= math.radians(15.0) + 1e-12 and max(abs(t) for t in tilts) > math.radians(10)
    assert 0 < negatives < 30  # ~7 % of 120 posed to look away
    assert max(people) > 1


def test_check_disjoint_names_the_shared_seeds():
    D.check_disjoint(range(0, 10), range(10, 20))  # no overlap: no error
    with pytest.raises(ValueError, match=r"overlap: 7, 9\b") as e:
        D.check_disjoint(range(0, 10), [7, 9, 12])
    assert "12" not in str(e.value)


def test_bad_arguments_are_refused(tmp_path):
    with pytest.raises(ValueError, match="repeated seeds 4"):
        D.generate(tmp_path, "train", [4, 4])
    with pytest.raises(ValueError, match="split"):
        D.generate(tmp_path, "../x", [1])
    with pytest.raises(ValueError, match="images_per_seed"):
        D.generate(tmp_path, "train", [1], images_per_seed=0)
    assert not list(tmp_path.iterdir())


def test_meta_is_json_with_the_rules(generated):
    path, _, _ = generated
    with np.load(path) as z:
        meta = json.loads(str(z["meta"]))
    assert meta["rules"]["columns"] == ["image", "x1", "y1", "x2", "y2", "distance_m", "visible_pixels"]
    assert meta["image_size"] == [INPUT_W, INPUT_H] and meta["render_size"] == [640, 480]


def test_box_rules_on_a_synthetic_segmentation():
    from sim.ground_truth import GroundTruth, ObstacleTruth

    seg = np.full((480, 640), -1, np.int32)
    seg[100:105, 10:16] = 5  # 30 pixels but 5 rows: too short
    seg[200:219, 50] = 6  # 19 rows, 19 pixels: too few
    seg[300:310, 600:602] = 7  # 20 pixels, 10 rows: kept
    seg[0:240, 0:3] = 2  # a static obstacle: never a box
    seg[400:420, 300:302] = 8  # kept, centre behind the camera
    T = np.eye(4)  # camera at the origin looking along world +z (optical frame = world)

    def person(i, centre):
        c = np.array(centre, float)
        return ObstacleTruth(i, "person", "person", c - 0.2, c + 0.2, np.zeros(3))

    obstacles = (ObstacleTruth(2, "static", "box", np.zeros(3), np.ones(3), np.zeros(3)),
                 person(5, [0, 0, 3]), person(6, [0, 0, 3]), person(7, [1.0, 0.5, 4.25]), person(8, [0, 0, -1]))
    truth = GroundTruth(0.0, 0, obstacles, T, np.zeros(3), np.zeros(3), seg)
    b = D.person_boxes(seg, truth)
    assert b.shape == (2, 6)
    np.testing.assert_allclose(b[0], [600 / 640, 300 / 480, 602 / 640, 310 / 480, 4.25, 20])
    np.testing.assert_allclose(b[1], [300 / 640, 400 / 480, 302 / 640, 420 / 480, D.MIN_DISTANCE, 40])
