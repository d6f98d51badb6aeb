"""The learned person detector's network, training loop, ONNX export and AP computation."""
import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("onnx")

from dodt.learned import layout  # noqa: E402
from dodt.learned.model import sha256_of  # noqa: E402
from experiments.detector import evaluate  # noqa: E402
from experiments.detector.net import build_model, count_parameters  # noqa: E402
from experiments.detector import train as tr  # noqa: E402
from experiments.detector.augment import augment  # noqa: E402


def synthetic_split(path, n: int, seed: int) -> None:
    """A dataset file in the generator's format: grey noise with 0-2 bright upright rectangles
    (the "people") per image, their distances from their heights."""
    rng = np.random.default_rng(seed)
    H, W = layout.INPUT_H, layout.INPUT_W
    images = (rng.integers(40, 110, (n, H, W, 3))).astype(np.uint8)
    rows = []
    for i in range(n):
        for _ in range(int(rng.integers(0, 3))):
            h = rng.uniform(0.25, 0.7)
            w = h * rng.uniform(0.25, 0.4) * H / W
            x1, y1 = rng.uniform(0, 1 - w), rng.uniform(0, 1 - h)
            c = rng.integers(180, 255, 3)
            images[i, int(y1 * H):int((y1 + h) * H), int(x1 * W):int((x1 + w) * W)] = c
            rows.append([i, x1, y1, x1 + w, y1 + h, 1.7 / h * 0.6, 1000])
    meta = {"generator": "synthetic", "seeds": [seed], "counts": {"images": n, "boxes": len(rows)}}
    np.savez(path, images=images, boxes=np.array(rows, np.float32).reshape(-1, 7),
             seeds=np.full(n, seed, np.int32), meta=np.array(json.dumps(meta)))


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("detdata")
    synthetic_split(d / "train.npz", 48, 1)
    synthetic_split(d / "val.npz", 8, 2)
    return d


@pytest.fixture(scope="module")
def trained(data_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("dettrain")
    info = tr.train(data_dir, out, epochs=4, seed=3, batch_size=8, threads=1, progress=lambda s: None,
                    eval_every=0)
    return out, info


def test_network_size_and_output_shape():
    model = build_model().eval()
    assert count_parameters(model) <= 500_000
    with torch.no_grad():
        out = model(torch.zeros(1, 3, layout.INPUT_H, layout.INPUT_W))
    assert tuple(out.shape) == (1, layout.CHANNELS, layout.GRID_H, layout.GRID_W) == (1, 5, 16, 22)


def test_targets_follow_the_decode():
    # a box centred at grid (5.3, 7.6): the centre cell and the lower neighbour can reach it,
    # the right neighbour needs an offset of 0.7 in x and 0.6 in y (kept), all within MAX_OFFSET
    cx, cy, w, h = 5.3 / layout.GRID_W, 7.6 / layout.GRID_H, 0.1, 0.3
    box = np.array([[cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2]])
    tbox, pos, ign = tr.build_targets([box], [np.zeros((0, 4))])
    assert set(zip(*np.nonzero(pos[0]))) == {(7, 5), (7, 6), (8, 5), (8, 6)}
    # a centre near a cell's corner: the far neighbours would need an offset of 0.95, so they are ignored
    cx, cy = 5.05 / layout.GRID_W, 7.05 / layout.GRID_H
    box = np.array([[cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2]])
    tbox, pos, ign = tr.build_targets([box], [np.zeros((0, 4))])
    assert set(zip(*np.nonzero(pos[0]))) == {(7, 5)}
    assert set(zip(*np.nonzero(ign[0]))) == {(7, 6), (8, 5), (8, 6)}
    # a positive cell's target box, pushed through the decode with the ideal raw values, is the box
    gy, gx = 7, 5
    t = tbox[0, gy, gx]
    c = ((t[0] + t[2]) / 2 * layout.GRID_W - gx, (t[1] + t[3]) / 2 * layout.GRID_H - gy)
    raw = np.zeros((5, layout.GRID_H, layout.GRID_W), np.float32)
    raw[0] = -20
    raw[0, gy, gx] = 20
    raw[1, gy, gx], raw[2, gy, gx] = np.arctanh(c[0]), np.arctanh(c[1])
    raw[3, gy, gx] = np.log((t[2] - t[0]) / (1 - (t[2] - t[0])))
    raw[4, gy, gx] = np.log((t[3] - t[1]) / (1 - (t[3] - t[1])))
    boxes, scores = layout.decode(raw, 0.5)
    np.testing.assert_allclose(boxes[0], t, atol=1e-5)


def test_targets_follow_the_decode_on_the_stride_8_grid():
    grid = tuple(layout.output_shape(8)[2:])
    assert grid == (32, 44)
    gh, gw = grid
    cx, cy, w, h = 20.4 / gw, 11.7 / gh, 0.03, 0.09  # a small, far person
    box = np.array([[cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2]])
    tbox, pos, ign = tr.build_targets([box], [np.zeros((0, 4))], grid)
    assert pos.shape == (1, gh, gw)
    assert set(zip(*np.nonzero(pos[0]))) == {(11, 20), (11, 21), (12, 20), (12, 21)}
    gy, gx = 12, 21
    t = tbox[0, gy, gx]
    raw = np.full((5, gh, gw), -20, np.float32)
    raw[0, gy, gx] = 20
    raw[1, gy, gx] = np.arctanh((t[0] + t[2]) / 2 * gw - gx)
    raw[2, gy, gx] = np.arctanh((t[1] + t[3]) / 2 * gh - gy)
    raw[3, gy, gx] = np.log((t[2] - t[0]) / (1 - (t[2] - t[0])))
    raw[4, gy, gx] = np.log((t[3] - t[1]) / (1 - (t[3] - t[1])))
    boxes, _ = layout.decode(raw, 0.5)
    np.testing.assert_allclose(boxes[0], box[0], atol=1e-5)
    with pytest.raises(ValueError, match="expected \\(5, GH, GW\\)"):
        layout.decode(raw[:4], 0.5)


@pytest.mark.slow
def test_stride_8_model_trains_exports_and_runs_at_run_time(data_dir, tmp_path):
    from dodt.learned.model import PersonDetector2D

    info = tr.train(data_dir, tmp_path, epochs=2, seed=1, batch_size=8, threads=1, progress=lambda s: None,
                    eval_every=0, arch="wide8")
    assert info["output"]["shape"] == [1, 5, 32, 44] and "stride-8 head" in info["architecture"]
    assert info["parameters"] == count_parameters(build_model("wide8")) <= 500_000
    assert info["onnx_max_abs_diff"] < 1e-3
    model = build_model("wide8")
    model.load_state_dict(torch.load(tmp_path / "person_detector.pt"))
    image = evaluate.load_split(data_dir / "val.npz")["images"][0]
    det = PersonDetector2D(tmp_path / "person_detector.onnx", score_threshold=0.05, soft_sigma=0)
    raw = det.raw(image)
    assert raw.shape == (5, 32, 44)
    np.testing.assert_allclose(raw, tr.predict(model, image[None])[0], atol=1e-3)
    # the run time decodes on the model's own grid: its boxes are those of the stride-8 decode
    boxes, scores = det(image)
    b, s = layout.decode(raw, 0.05)
    keep = layout.nms(b, s, 0.45)
    np.testing.assert_allclose(boxes, b[keep] * np.array([352, 256, 352, 256], np.float32), atol=1e-3)
    np.testing.assert_allclose(scores, s[keep], atol=1e-6)


def test_a_model_on_another_grid_is_refused_at_run_time(tmp_path):
    from dodt.learned.model import ModelError, PersonDetector2D

    path = tmp_path / "stride32.onnx"
    tr.export_onnx(torch.nn.Conv2d(3, 5, 32, 32), path)  # a (1, 5, 8, 11) output: stride 32
    (tmp_path / "stride32.json").write_text(json.dumps({"sha256": sha256_of(path)}))
    with pytest.raises(ModelError, match=r"stride32.onnx: output .*\[1, 5, 8, 11\].* is not one of .*strides 16, 8"):
        PersonDetector2D(path)


def test_network_sizes_and_training_options_are_checked(data_dir, tmp_path):
    assert count_parameters(build_model("base")) == count_parameters(build_model()) < count_parameters(build_model("wide")) <= 500_000
    with pytest.raises(ValueError, match="unknown 'huge'"):
        build_model("huge")
    with pytest.raises(ValueError, match="arch: unknown 'huge'"):
        tr.train(data_dir, tmp_path, epochs=1, seed=0, arch="huge")
    with pytest.raises(ValueError, match="device"):
        tr.train(data_dir, tmp_path, epochs=1, seed=0, device="tpu")
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="sees no CUDA device"):
            tr.train(data_dir, tmp_path, epochs=1, seed=0, device="cuda")


def test_augmentation_keeps_boxes_on_the_people():
    rng = np.random.default_rng(0)
    img = np.zeros((layout.INPUT_H, layout.INPUT_W, 3), np.uint8)
    box = np.array([[0.4, 0.3, 0.5, 0.8]])
    img[int(0.3 * 256):int(0.8 * 256), int(0.4 * 352):int(0.5 * 352)] = 255
    for _ in range(20):
        x, b, ig = augment(img, box, rng)
        assert x.shape == img.shape and x.dtype == np.float32 and 0 <= x.min() and x.max() <= 1
        for x1, y1, x2, y2 in b:  # the box's inside is bright, its surroundings dark
            inner = x[int(y1 * 256) + 2:int(y2 * 256) - 2, int(x1 * 352) + 2:int(x2 * 352) - 2].mean()
            assert inner > x.mean()


def test_training_lowers_the_loss_and_is_reproducible(data_dir, trained, tmp_path):
    out, info = trained
    curve = [row["loss"] for row in info["curve"]]
    assert curve[-1] < 0.8 * curve[0]
    again = tr.train(data_dir, tmp_path, epochs=4, seed=3, batch_size=8, threads=1, progress=lambda s: None,
                     eval_every=0)
    assert [row["loss"] for row in again["curve"]] == curve
    a = torch.load(out / "person_detector.pt")
    b = torch.load(tmp_path / "person_detector.pt")
    assert a.keys() == b.keys()
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert again["sha256"] == info["sha256"]


def test_onnx_export_round_trips(data_dir, trained):
    out, info = trained
    path = out / "person_detector.onnx"
    assert path.stat().st_size <= 2 * 1024 * 1024
    meta = json.loads((out / "person_detector.json").read_text())
    assert meta["sha256"] == sha256_of(path) and meta["parameters"] == count_parameters(build_model())
    assert meta["onnx_max_abs_diff"] < 1e-3
    model = build_model()
    model.load_state_dict(torch.load(out / "person_detector.pt"))
    images = evaluate.load_split(data_dir / "val.npz")["images"][:3]
    got = evaluate.run_onnx(evaluate.onnx_session(path), images)
    ref = tr.predict(model, images)
    assert got.shape == (3, 5, 16, 22)
    assert np.max(np.abs(got - ref)) < 1e-3
    assert np.std(ref) > 0  # not a constant output


def test_average_precision_of_the_onnx_model(data_dir, trained, tmp_path):
    out, _ = trained
    res = evaluate.average_precision(out / "person_detector.onnx", data_dir / "val.npz")
    assert res["images"] == 8 and 0.0 <= res["ap50"] <= 1.0
    assert set(res["recall_by_distance"]) == {"0-2", "2-4", "4-6", "6-8", "8-10"}
    # a broken model (all-background objectness) finds nothing
    model = build_model()
    with torch.no_grad():
        model.head.obj[-1].bias.fill_(-30.0)
        model.head.obj[-1].weight.zero_()
    tr.export_onnx(model, tmp_path / "broken.onnx")
    broken = evaluate.average_precision(tmp_path / "broken.onnx", data_dir / "val.npz")
    assert broken["ap50"] == 0.0 and broken["recall"] == 0.0


# --------------------------------------------------------------------------- the AP computation


def _gt(*rows):
    return np.array(rows, np.float64).reshape(-1, 5)


def test_perfect_detections_give_ap_one():
    gts = [_gt([0.1, 0.1, 0.3, 0.6, 3.0], [0.5, 0.2, 0.6, 0.5, 7.5]), _gt([0.2, 0.2, 0.4, 0.9, 1.0]), _gt()]
    dets = [(g[:, :4].copy(), np.linspace(0.9, 0.8, len(g))) for g in gts]
    res = evaluate.evaluate_detections(dets, gts, operating_threshold=0.5)
    assert res["ap50"] == pytest.approx(1.0)
    assert res["precision"] == 1.0 and res["recall"] == 1.0 and res["boxes"] == 3
    assert res["recall_by_distance"]["2-4"] == {"boxes": 1, "recall": 1.0}
    assert res["recall_by_distance"]["4-6"] == {"boxes": 0, "recall": None}


def test_false_positives_misses_and_duplicates_lower_ap():
    gt = _gt([0.1, 0.1, 0.3, 0.6, 3.0], [0.5, 0.2, 0.6, 0.5, 5.0])
    # a confident false positive ranked first, then the two people: precision 1/2, 2/3 at recall 0.5, 1,
    # so the envelope is 2/3 all along
    dets = [(np.array([[0.7, 0.7, 0.9, 0.9], [0.1, 0.1, 0.3, 0.6], [0.5, 0.2, 0.6, 0.5]]), np.array([0.9, 0.8, 0.7]))]
    assert evaluate.evaluate_detections(dets, [gt])["ap50"] == pytest.approx(2 / 3)
    # one person missed: AP 0.5
    dets = [(np.array([[0.1, 0.1, 0.3, 0.6]]), np.array([0.9]))]
    res = evaluate.evaluate_detections(dets, [gt], operating_threshold=0.5)
    assert res["ap50"] == pytest.approx(0.5) and res["recall"] == 0.5
    assert res["recall_by_distance"]["4-6"]["recall"] == 0.0
    # a duplicate of a found person is a false positive
    m = evaluate.match_image(np.array([[0.1, 0.1, 0.3, 0.6], [0.11, 0.1, 0.3, 0.6]]), np.array([0.9, 0.8]),
                             gt[:1, :4], np.array([False]))
    assert m.tp.tolist() == [True, False]
    # a poorly placed box (IoU < 0.5) does not count
    m = evaluate.match_image(np.array([[0.1, 0.1, 0.3, 0.3]]), np.array([0.9]), gt[:1, :4], np.array([False]))
    assert m.tp.tolist() == [False]


def test_far_people_are_ignored():
    gt = _gt([0.1, 0.1, 0.3, 0.6, 3.0], [0.5, 0.2, 0.6, 0.5, 14.0])
    # detecting the far person is neither a hit nor a false positive; missing them costs nothing
    both = [(gt[:, :4].copy(), np.array([0.6, 0.9]))]
    res = evaluate.evaluate_detections(both, [gt], operating_threshold=0.5)
    assert res["ap50"] == pytest.approx(1.0) and res["precision"] == 1.0
    assert res["boxes"] == 1 and res["boxes_ignored"] == 1
    near_only = [(gt[:1, :4].copy(), np.array([0.6]))]
    assert evaluate.evaluate_detections(near_only, [gt])["ap50"] == pytest.approx(1.0)
    # with a longer range the far person counts again
    assert evaluate.evaluate_detections(near_only, [gt], max_distance=15.0)["ap50"] == pytest.approx(0.5)


def test_voc_ap_interpolates_the_envelope():
    # ranks: TP FP TP, 2 people: precision 1, 1/2, 2/3 -> envelope 1 on (0, 0.5], 2/3 on (0.5, 1]
    assert evaluate.voc_ap([0.9, 0.8, 0.7], [True, False, True], 2) == pytest.approx(0.5 + 0.5 * 2 / 3)
    assert evaluate.voc_ap([], [], 3) == 0.0
    assert np.isnan(evaluate.voc_ap([0.5], [False], 0))


def test_nms_ceiling_counts_people_lost_to_nms():
    # two people overlapping by IoU 0.6: NMS at 0.45 keeps one of them, at 0.7 both
    a, b = [0.1, 0.1, 0.3, 0.9, 3.0], [0.15, 0.1, 0.35, 0.9, 4.0]
    assert evaluate.box_iou(np.array([a[:4]]), np.array([b[:4]]))[0, 0] == pytest.approx(0.6)
    gts = [_gt(a, b), _gt([0.6, 0.1, 0.7, 0.5, 2.0])]
    assert evaluate.nms_ceiling(gts, nms_iou=0.45) == pytest.approx(2 / 3)
    assert evaluate.nms_ceiling(gts, nms_iou=0.7) == pytest.approx(1.0)
