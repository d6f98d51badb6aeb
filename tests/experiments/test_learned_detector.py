"""The shipped learned person detector (YOLO-MAD) through onnxruntime: it loads only when its
checksum matches, finds people in rendered images, and joins the DODT pipeline when switched on."""
import json
import shutil
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from dodt.config import LearnedConfig
from dodt.learned import layout
from dodt.learned.model import SHIPPED_MODEL, ModelError, PersonDetector2D, load_record, sha256_of
from dodt.pipeline import DODT
from dodt.presets import PRESETS, preset
from experiments.cli import main
from sim import World, load_scenario


def _iou(a, b) -> float:
    ix = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = ix * iy
    return inter / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter)


@pytest.fixture(scope="module")
def rendered():
    """A few frames of the circles scenario (three people 2.5-6 m away) with segmentation."""
    sc = load_scenario("circles")
    out = []
    with World(sc, seed=0, segmentation=True) as w:
        for t in (1.0, 4.0, 7.0):
            w.advance(t - w.time)
            out.append((w.latest_frame(), w.ground_truth()))
    return out


def test_shipped_model_is_small_recorded_and_checked():
    rec = load_record(SHIPPED_MODEL)
    assert SHIPPED_MODEL.stat().st_size <= 2_000_000
    assert rec["sha256"] == sha256_of(SHIPPED_MODEL)
    assert rec["parameters"] <= 500_000
    assert rec["input"]["shape"] == [1, 3, layout.INPUT_H, layout.INPUT_W]
    assert rec["output"]["shape"] in [list(layout.output_shape(s)) for s in layout.STRIDES]
    assert PersonDetector2D().raw(np.zeros((480, 640, 3), np.uint8)).shape == tuple(rec["output"]["shape"][1:])
    assert rec["validation"]["ap50"] > 0.5 and rec["validation"]["boxes"] > 1000  # measured on held-out seeds
    assert not set(rec["train_data"]["seeds"]) & set(rec["val_data"]["seeds"])
    assert "train-detector" in rec["command"] and "seed" in rec
    assert 0.0 < rec["score_threshold"] < 1.0


def test_several_views_find_the_people_and_bad_view_names_are_refused(rendered):
    det = PersonDetector2D(views=("full", "flip", "center"))
    found = 0
    for frame, truth in rendered:
        boxes, scores = det(frame.color)
        assert np.all(scores >= det.score_threshold)
        people = [o for o in truth.obstacles if o.kind == "person"]
        for o in people:
            mask = truth.segmentation == o.id
            if np.count_nonzero(mask) < 2000:
                continue
            r, c = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
            gt = (c[0], r[0], c[-1] + 1, r[-1] + 1)
            found += any(_iou(b, gt) > 0.5 for b in boxes)
    assert found >= 3
    with pytest.raises(ModelError, match="unknown 'side'"):
        PersonDetector2D(views=("full", "side"))


def test_run_time_never_imports_pytorch():
    code = ("import sys, numpy as np; from dodt.pipeline import DODT; from dodt.presets import preset; "
            "from dodt.frames import CameraIntrinsics, SensorFrame; K = CameraIntrinsics(); "
            "f = SensorFrame(depth=np.full((K.height, K.width), 3000, np.uint16), "
            "color=np.full((K.height, K.width, 3), 90, np.uint8), intrinsics=K, T_world_camera=np.eye(4), stamp=0.0); "
            "r = DODT(preset('dodt+yolo')).process(f); assert r.timings_ms['learned'] > 0; "
            "print('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "False"


def test_shipped_model_finds_the_people_in_rendered_images(rendered):
    det = PersonDetector2D()
    found = visible = 0
    for frame, truth in rendered:
        boxes, scores = det(frame.color)
        assert boxes.shape[1] == 4 and np.all(scores >= det.score_threshold)
        for p in (o for o in truth.obstacles if o.kind == "person"):
            rows, cols = np.nonzero(truth.segmentation == p.id)
            if len(rows) < 1500:  # mostly hidden or out of view
                continue
            visible += 1
            gt = (cols.min(), rows.min(), cols.max() + 1, rows.max() + 1)
            found += any(_iou(gt, b) >= 0.5 for b in boxes)
    assert visible >= 4
    assert found >= visible - 1, (found, visible)
    # and nothing on an empty image
    boxes, _ = det(np.full((480, 640, 3), 128, np.uint8))
    assert len(boxes) == 0


def test_corrupt_or_missing_model_is_refused_with_its_name(tmp_path):
    bad = tmp_path / "person_detector.onnx"
    data = bytearray(SHIPPED_MODEL.read_bytes())
    data[len(data) // 2] ^= 0xFF
    bad.write_bytes(bytes(data))
    shutil.copy(SHIPPED_MODEL.with_suffix(".json"), tmp_path / "person_detector.json")
    with pytest.raises(ModelError, match=r"person_detector.onnx: SHA-256 .* does not match"):
        PersonDetector2D(bad)
    with pytest.raises(ModelError, match="SHA-256"):  # the pipeline refuses it at construction
        DODT(replace(preset("dodt+yolo"), learned=LearnedConfig(enabled=True, model=str(bad))))
    with pytest.raises(ModelError, match="not found: .*nothing.onnx"):
        PersonDetector2D(tmp_path / "nothing.onnx")
    lone = tmp_path / "lone.onnx"
    shutil.copy(SHIPPED_MODEL, lone)
    with pytest.raises(ModelError, match="no record lone.json"):
        PersonDetector2D(lone)
    (tmp_path / "lone.json").write_text("{not json")
    with pytest.raises(ModelError, match="lone.json: not a readable JSON record"):
        PersonDetector2D(lone)
    (tmp_path / "lone.json").write_text(json.dumps({"sha256": sha256_of(SHIPPED_MODEL)}))
    assert PersonDetector2D(lone).score_threshold == 0.5  # a record without a threshold: 0.5


def test_cli_reports_a_corrupt_model_in_one_line(tmp_path, capsys):
    bad = tmp_path / "m.onnx"
    bad.write_bytes(b"not a model")
    (tmp_path / "m.json").write_text(json.dumps({"sha256": "0" * 64}))
    assert main(["eval-detector", "--model", str(bad), "--data", str(tmp_path / "data")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "m.onnx: SHA-256" in err


def test_pipeline_without_the_module_needs_no_model(monkeypatch, rendered):
    monkeypatch.setattr("dodt.learned.model.SHIPPED_MODEL", SHIPPED_MODEL.parent / "absent.onnx")
    r = DODT(preset("dodt")).process(rendered[0][0])
    assert r.timings_ms["learned"] == 0.0
    with pytest.raises(ModelError, match="absent.onnx"):
        DODT(preset("dodt+yolo"))


def test_dodt_yolo_marks_people_dynamic_from_the_first_frames():
    """With the module on, a walking person is labelled dynamic within a few frames (a person box
    is dynamic at once); point voting alone needs its consistency window first."""
    assert "dodt+yolo" in PRESETS and preset("dodt+yolo").learned.enabled
    sc = load_scenario("circles")
    first_dynamic = {}
    with World(sc, seed=0, segmentation=False) as w:
        pipes = {c: DODT(preset(c)) for c in ("dodt", "dodt+yolo")}
        frames = [w.latest_frame()] + [f for f in w.advance(1.0) if f is not None]
    for c, pipe in pipes.items():
        for i, f in enumerate(frames):
            r = pipe.process(f)
            if r.dynamic and c not in first_dynamic:
                first_dynamic[c] = i
        if c == "dodt+yolo":
            assert r.timings_ms["learned"] > 0.0
            assert any(o.is_person for o in r.obstacles)
    assert first_dynamic["dodt+yolo"] <= 3
    assert first_dynamic["dodt+yolo"] < first_dynamic.get("dodt", len(frames))


def test_evaluation_ignores_fragments_only_when_asked():
    """A person showing 100 pixels and missed costs recall; with min_visible_px 400 it is ignored,
    and a detection on it is neither a true nor a false positive."""
    from experiments.detector.evaluate import evaluate_detections

    gt = [np.array([[0.1, 0.1, 0.3, 0.6, 4.0, 5000.0], [0.6, 0.2, 0.62, 0.3, 5.0, 100.0]])]
    hit = [(np.array([[0.1, 0.1, 0.3, 0.6]], np.float32), np.array([0.9], np.float32))]
    strict = evaluate_detections(hit, gt, operating_threshold=0.5)
    lenient = evaluate_detections(hit, gt, operating_threshold=0.5, min_visible_px=400)
    assert strict["recall"] == 0.5 and strict["ap50"] == pytest.approx(0.5)
    assert lenient["recall"] == 1.0 and lenient["ap50"] == pytest.approx(1.0) and lenient["boxes_ignored"] == 1
    both = [(np.array([[0.1, 0.1, 0.3, 0.6], [0.6, 0.2, 0.62, 0.3]], np.float32), np.array([0.9, 0.8], np.float32))]
    assert evaluate_detections(both, gt, operating_threshold=0.5, min_visible_px=400)["precision"] == 1.0


def test_eval_detector_renders_only_the_missing_validation_split_and_refuses_other_seeds(tmp_path, capsys):
    data = str(tmp_path / "data")
    opts = ["--data", data, "--images-per-seed", "1"]
    assert main(["eval-detector", "--val-seeds", "1000:1001", *opts]) == 0
    out = capsys.readouterr().out
    assert "person_detector.onnx on" in out and "ap50" in out
    assert (tmp_path / "data" / "val.npz").is_file()
    assert not (tmp_path / "data" / "train.npz").exists()  # evaluation needs no training images
    assert main(["eval-detector", "--val-seeds", "1000:1002", *opts]) == 2
    assert "val.npz was rendered from other seeds" in capsys.readouterr().err
    assert main(["eval-detector", "--val-seeds", "1000:1001", "--train-seeds", "0:1001", *opts]) == 2
    assert "overlap: 1000" in capsys.readouterr().err
    # the suppression and the score floor are reported, and bad values refused by name
    assert main(["eval-detector", "--val-seeds", "1000:1001", "--soft-nms", "0", "--score-floor", "0.001", *opts]) == 0
    out = capsys.readouterr().out
    assert "soft_nms_sigma 0.000" in out and "score_threshold 0.001" in out
    assert main(["eval-detector", "--val-seeds", "1000:1001", "--score-floor", "0", *opts]) == 2
    assert "--score-floor" in capsys.readouterr().err
    assert main(["eval-detector", "--val-seeds", "1000:1001", "--soft-nms", "-1", *opts]) == 2
    assert "--soft-nms" in capsys.readouterr().err


def test_train_detector_refuses_a_training_split_rendered_from_other_seeds(tmp_path, capsys):
    pytest.importorskip("torch")
    from experiments.detector.dataset import generate

    generate(tmp_path / "data", "train", [0], 1)
    opts = ["--data", str(tmp_path / "data"), "--val-seeds", "1000:1001", "--images-per-seed", "1", "--epochs", "1"]
    assert main(["train-detector", "--train-seeds", "0:2", *opts]) == 2
    assert "train.npz was rendered from other seeds" in capsys.readouterr().err
    assert not (tmp_path / "data" / "val.npz").exists()  # refused before rendering anything else


def test_map_is_freed_under_a_person_label_only_while_it_moves(monkeypatch):
    """A person-labelled track that stands (e.g. a person box lifted onto a wall) is avoided by the
    planner but does not free the map; a walking one, or one dynamic by DODT's voting, does."""
    from dodt.result import PerceptionResult, TrackedObstacle
    from experiments.perception_modes import PERSON_CLEAR_SPEED, DODTPerception

    def track(tid, speed, person):
        return TrackedObstacle(id=tid, center=np.array([3.0, tid, 0.9]), size=np.array([0.5, 0.5, 1.8]),
                               velocity=np.array([speed, 0.0, 0.0]), acceleration=np.zeros(3), dynamic=True,
                               coasting=False, age=1.0, history=np.zeros((0, 4)), is_person=person)

    perc = DODTPerception("dodt")
    tracks = (track(1, 0.1, True), track(2, 1.0, True), track(3, 0.1, False))
    monkeypatch.setattr(perc.dodt, "process", lambda frame: PerceptionResult(0.0, 0, tracks, {}))
    out = perc.update(None)
    assert [p.id for p in out.obstacles] == [1, 2, 3]  # all three are avoided
    assert [c[1] for c, _ in out.clear_boxes] == [2.0, 3.0]  # the standing person label frees nothing
    assert 0.1 < PERSON_CLEAR_SPEED < 1.0
