"""Person detectors a user brings (dodt.learned.yolo): the YOLO output layouts decoded from crafted
outputs, the preprocessing, and tiny ONNX models of each layout built here (no download) run
through PersonDetector2D and the pipeline's lifting and fusion."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from dodt.config import DODTConfig, LearnedConfig
from dodt.learned import yolo
from dodt.learned.model import ModelError, PersonDetector2D

N640 = 8400  # cells of strides 8, 16, 32 over a 640 x 640 input


def fmt(layout: str, width=640, height=480, classes=3, **kw) -> yolo.YoloFormat:
    defaults = dict(zip(("channels", "pixel_scale", "letterbox"), yolo.PREPROCESS[layout]))
    return yolo.YoloFormat(layout, width, height, classes, **(defaults | kw))


# --------------------------------------------------------------------------- layouts from shapes


@pytest.mark.parametrize("shape, layout, classes, transposed", [
    ((1, 84, N640), "yolov8", 80, False),  # Ultralytics YOLOv8 / YOLO11, COCO
    ((1, N640, 85), "yolox", 80, False),  # YOLOX's export, COCO
    ((1, 3 * N640, 85), "yolov5", 80, False),  # YOLOv5: three anchors per cell
    ((1, 5, N640), "yolov8", 1, False),  # a one-class (person) YOLOv8
])
def test_auto_tells_the_layouts_apart_by_their_candidates(shape, layout, classes, transposed):
    f = yolo.resolve(shape, 640, 640)
    assert (f.layout, f.classes, f.transposed) == (layout, classes, transposed)
    assert (f.channels, f.pixel_scale, f.letterbox) == yolo.PREPROCESS[layout]


def test_a_named_layout_reads_the_transposed_yolov8_and_overrides_preprocessing():
    f = yolo.resolve((1, N640, 84), 640, 640, layout="yolov8", channels="bgr", pixel_scale=1.0, letterbox="none")
    assert (f.layout, f.classes, f.transposed) == ("yolov8", 80, True)
    assert (f.channels, f.pixel_scale, f.letterbox) == ("bgr", 1.0, "none")


@pytest.mark.parametrize("shape, kw, match", [
    ((1, 10, 7), {}, r"output shape \[1, 10, 7\] fits no layout for a 640x640 input \(8400 cells"),
    ((1, 84, N640, 1), {}, r"no YOLO layout"),
    ((2, 84, N640), {}, r"no YOLO layout"),
    ((1, 84, N640), {"person_class": 80}, r"person class 80 is not among the model's 80 classes"),
    ((1, 84, N640), {"layout": "yolov9"}, r"unknown layout 'yolov9'"),
    ((1, 100, 85), {"layout": "yolox"}, r"one row per cell .* 8400 for a 640x640 input, not 100"),
    ((1, 84, N640), {"channels": "rgba"}, r"channels must be rgb or bgr"),
    ((1, 84, N640), {"letterbox": "middle"}, r"letterbox must be"),
    ((1, 84, N640), {"pixel_scale": 0.0}, r"pixel_scale must be above 0"),
])
def test_shapes_and_options_that_fit_no_layout_are_refused_by_name(shape, kw, match):
    with pytest.raises(yolo.LayoutError, match=match):
        yolo.resolve(shape, 640, 640, **kw)


# --------------------------------------------------------------------------- decoding crafted outputs


def _yolov8_output(candidates, classes=3, n=6) -> np.ndarray:
    """(1, 4 + classes, n): candidates [(cx, cy, w, h, class, score)], the rest zero."""
    out = np.zeros((4 + classes, n), np.float32)
    for i, (cx, cy, w, h, c, s) in enumerate(candidates):
        out[:4, i] = cx, cy, w, h
        out[4 + c, i] = s
    return out[None]


def test_yolov8_decode_reads_the_person_class_only():
    out = _yolov8_output([(320, 240, 100, 200, 0, 0.9),   # a person
                          (100, 100, 50, 50, 2, 0.95),    # another class, scoring higher
                          (500, 300, 40, 80, 0, 0.1)])    # a person below the threshold
    boxes, scores = yolo.decode(out, fmt("yolov8"), 0.3)
    np.testing.assert_allclose(boxes, [[270, 140, 370, 340]])
    np.testing.assert_allclose(scores, [0.9])
    # the transposed layout gives the same; another person class index reads class 2
    t = yolo.decode(out[0].T[None], fmt("yolov8", transposed=True), 0.3)
    np.testing.assert_array_equal(t[0], boxes)
    other, _ = yolo.decode(out, fmt("yolov8", person_class=2), 0.3)
    np.testing.assert_allclose(other, [[75, 75, 125, 125]])


def test_yolov5_decode_scores_objectness_times_class():
    out = np.zeros((1, 3, 8), np.float32)
    out[0, 0, :6] = [320, 240, 100, 200, 0.5, 0.9]   # 0.45: kept
    out[0, 1, :6] = [100, 100, 50, 50, 0.9, 0.2]     # 0.18: dropped
    out[0, 2, :4] = [50, 60, 10, 20]
    out[0, 2, 4], out[0, 2, 7] = 0.99, 0.99          # another class
    boxes, scores = yolo.decode(out, fmt("yolov5"), 0.3)
    np.testing.assert_allclose(boxes, [[270, 140, 370, 340]])
    np.testing.assert_allclose(scores, [0.45], rtol=1e-6)


def test_yolox_decode_places_raw_offsets_on_the_stride_grids():
    """A 64 x 64 input has 8 x 8 + 4 x 4 + 2 x 2 = 84 cells, row by row per stride. A candidate of
    the stride-16 cell at column 1, row 2, offset by half a cell, 2 x 4 strides large, is the box
    (24 -+ 16, 40 -+ 32)."""
    f = fmt("yolox", width=64, height=64, classes=2)
    out = np.zeros((1, yolo.cells(64, 64), 7), np.float32)
    assert out.shape[1] == 84
    row = 64 + 2 * 4 + 1
    out[0, row] = [0.5, 0.5, math.log(2.0), math.log(4.0), 0.9, 0.8, 0.0]
    out[0, 0] = [0.0, 0.0, 200.0, 0.0, 1.0, 1.0, 0.0]  # an absurd log size: capped, and finite
    boxes, scores = yolo.decode(out, f, 0.3)
    assert np.all(np.isfinite(boxes))
    np.testing.assert_allclose(boxes[1], [8, 8, 40, 72], atol=1e-4)
    np.testing.assert_allclose(scores[1], 0.72, rtol=1e-6)


def test_non_finite_outputs_give_no_boxes():
    out = _yolov8_output([(np.nan, 240, 100, 200, 0, 0.9), (320, 240, np.inf, 200, 0, 0.9), (1, 1, 1, 1, 0, np.nan)])
    boxes, scores = yolo.decode(out, fmt("yolov8"), 0.3)
    assert boxes.shape == (0, 4) and scores.shape == (0,)


# --------------------------------------------------------------------------- preprocessing


def test_letterbox_centres_the_image_and_boxes_map_back():
    img = np.zeros((480, 640, 3), np.uint8)
    img[..., 0] = 200  # red
    x, place = yolo.prepare(img, fmt("yolov8", width=640, height=640))
    assert x.shape == (1, 3, 640, 640) and x.dtype == np.float32
    assert (place.sx, place.sy, place.ox, place.oy) == (1.0, 1.0, 0.0, 80.0)
    assert x[0, 0, 80:560].min() == pytest.approx(200 / 255) and x[0, 0, :80].max() == pytest.approx(114 / 255)
    b = yolo.to_fractions(np.array([[100, 180, 200, 380]]), place, 640, 480)
    np.testing.assert_allclose(b, [[100 / 640, 100 / 480, 200 / 640, 300 / 480]], rtol=1e-6)


def test_yolox_pads_at_the_bottom_right_and_feeds_bgr_0_to_255():
    img = np.zeros((480, 640, 3), np.uint8)
    img[..., 0] = 200  # red
    x, place = yolo.prepare(img, fmt("yolox", width=320, height=320))
    assert (place.sx, place.sy, place.ox, place.oy) == (0.5, 0.5, 0.0, 0.0)
    assert x[0, 2, :240].min() == 200.0 and x[0, 0, :240].max() == 0.0  # red is the last channel
    assert x[0, 2, 240:].max() == 114.0  # the grey border below the image
    b = yolo.to_fractions(np.array([[32, 24, 64, 120]]), place, 640, 480)
    np.testing.assert_allclose(b, [[0.1, 0.1, 0.2, 0.5]], rtol=1e-6)


def test_no_letterbox_stretches_the_image():
    x, place = yolo.prepare(np.zeros((480, 640, 3), np.uint8), fmt("yolov8", width=320, height=320, letterbox="none"))
    assert x.shape == (1, 3, 320, 320) and (place.sx, place.sy) == (0.5, 320 / 480)


# --------------------------------------------------------------------------- tiny ONNX models


def tiny_model(path, output: np.ndarray, width: int | None, height: int | None) -> str:
    """An ONNX model of one input image (1, 3, height, width) that outputs ``output`` whatever
    the image (the image feeds the graph through a term multiplied by 0); None: a dynamic size."""
    onnx = pytest.importorskip("onnx", reason="building the tiny test models needs the onnx package")
    from onnx import TensorProto, helper, numpy_helper

    dims = [1, 3, height if height else "height", width if width else "width"]
    graph = helper.make_graph(
        [helper.make_node("ReduceMean", ["images"], ["mean"], keepdims=0),
         helper.make_node("Mul", ["mean", "zero"], ["nothing"]),
         helper.make_node("Add", ["const", "nothing"], ["output0"])],
        "tiny", [helper.make_tensor_value_info("images", TensorProto.FLOAT, dims)],
        [helper.make_tensor_value_info("output0", TensorProto.FLOAT, list(output.shape))],
        initializer=[numpy_helper.from_array(output.astype(np.float32), "const"),
                     numpy_helper.from_array(np.zeros((), np.float32), "zero")])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.save(model, str(path))
    return str(path)


def person_output(layout: str, width: int, height: int, box_px, score=0.9, classes=4) -> np.ndarray:
    """A model output of ``layout`` for a width x height input holding one person box (input pixels
    x1, y1, x2, y2; for yolox it is placed on its stride-8 cell) and a box of class 1 elsewhere."""
    x1, y1, x2, y2 = box_px
    cx, cy, w, h = (x1 + x2) / 2, (y1 + y2) / 2, x2 - x1, y2 - y1
    n = yolo.cells(width, height)
    if layout == "yolov8":
        out = np.zeros((1, 4 + classes, n), np.float32)
        out[0, :, 0] = [cx, cy, w, h, score] + [0.0] * (classes - 1)
        out[0, :, 1] = [10, 10, 8, 8, 0.0, 0.99] + [0.0] * (classes - 2)
        return out
    rows = 3 * n if layout == "yolov5" else n
    out = np.zeros((1, rows, 5 + classes), np.float32)
    out[0, 1] = [10, 10, 8, 8, 0.99, 0.0, 0.99] + [0.0] * (classes - 2)
    if layout == "yolov5":
        out[0, 0] = [cx, cy, w, h, 1.0, score] + [0.0] * (classes - 1)
    else:  # yolox: raw offsets from the stride-8 cell holding the centre
        gx, gy = int(cx // 8), int(cy // 8)
        i = gy * -(-width // 8) + gx
        out[0, i] = [cx / 8 - gx, cy / 8 - gy, math.log(w / 8), math.log(h / 8), 1.0, score] + [0.0] * (classes - 1)
        out[0, 1] = [0.2, 0.2, 0.0, 0.0, 0.99, 0.0, 0.99] + [0.0] * (classes - 2)
    return out


@pytest.mark.parametrize("layout", ["yolov8", "yolov5", "yolox"])
def test_tiny_models_of_each_layout_find_the_person_where_it_is(tmp_path, layout):
    """A 320 x 256 model whose output holds a person box: PersonDetector2D reads the input size from
    the model, tells the layout from the output (auto), and returns the box in the pixels of a
    640 x 480 image through the layout's letterbox."""
    W, H = 320, 256
    image_box = np.array([300.0, 120.0, 380.0, 400.0])  # in the 640 x 480 image
    probe = yolo.YoloFormat(layout, W, H, 4, 0, False, *yolo.PREPROCESS[layout])
    _, place = yolo.prepare(np.zeros((480, 640, 3), np.uint8), probe)
    in_px = image_box * [place.sx, place.sy, place.sx, place.sy] + [place.ox, place.oy, place.ox, place.oy]
    path = tiny_model(tmp_path / f"{layout}.onnx", person_output(layout, W, H, in_px), W, H)
    det = PersonDetector2D(path)
    assert det.format.layout == layout and (det.format.width, det.format.height) == (W, H)
    assert det.score_threshold == yolo.DEFAULT_SCORE_THRESHOLD  # no record beside it
    boxes, scores = det(np.zeros((480, 640, 3), np.uint8))
    assert len(boxes) == 1 and scores[0] == pytest.approx(0.9, rel=1e-5)
    np.testing.assert_allclose(boxes[0], image_box, atol=1.0)
    # views work for these models too: the mirrored image finds the same person
    both = PersonDetector2D(path, views=("full", "flip"))
    b2, _ = both(np.zeros((480, 640, 3), np.uint8))
    assert len(b2) >= 1 and np.abs(b2 - image_box).max(axis=1).min() < 2.0


def test_a_model_of_dynamic_input_size_needs_input_size(tmp_path):
    out = person_output("yolov8", 320, 320, (100, 100, 140, 200))
    path = tiny_model(tmp_path / "dyn.onnx", out, None, None)
    with pytest.raises(ModelError, match=r"dyn.onnx: the input size is not fixed .* give input_size"):
        PersonDetector2D(path)
    det = PersonDetector2D(path, input_size=(320, 320))
    assert (det.format.width, det.format.height) == (320, 320)
    with pytest.raises(ModelError, match=r"the model's input is 320x320, not the input_size \(640, 640\)"):
        PersonDetector2D(tiny_model(tmp_path / "fixed.onnx", out, 320, 320), input_size=(640, 640))


def test_models_that_fit_no_layout_are_refused_with_the_file_name(tmp_path):
    path = tiny_model(tmp_path / "odd.onnx", np.zeros((1, 7, 10), np.float32), 320, 320)
    with pytest.raises(ModelError, match=r"odd.onnx: output shape \[1, 7, 10\] fits no layout"):
        PersonDetector2D(path)
    ok = tiny_model(tmp_path / "v8.onnx", person_output("yolov8", 320, 320, (1, 1, 9, 9)), 320, 320)
    with pytest.raises(ModelError, match=r"v8.onnx: person class 7 is not among the model's 4 classes"):
        PersonDetector2D(ok, person_class=7)
    with pytest.raises(ModelError, match=r"unknown layout 'yolo'"):
        PersonDetector2D(ok, layout="yolo")
    with pytest.raises(ModelError, match=r"v8.onnx has no record v8.json"):  # ours carry their record
        PersonDetector2D(ok, layout="dodt")


def test_a_user_model_lifts_a_person_through_the_pipeline(tmp_path):
    """The same MAD lifting and fusion as the shipped model: a tiny YOLOv8 model boxing the synthetic
    pillar (a person-sized cylinder 2 m ahead) makes its track a person, dynamic from its third
    frame, standing still."""
    from dodt.frames import SensorFrame
    from dodt.pipeline import DODT
    from tests.dodt.test_bad_input import K, T0, scene

    depth = scene((2.0, 0.0))
    rows, cols = np.nonzero((depth > 0) & (depth < 2.5))
    image_box = np.array([cols.min(), rows.min(), cols.max() + 1, rows.max() + 1], float)
    W = H = 320
    probe = yolo.YoloFormat("yolov8", W, H, 4, 0, False, *yolo.PREPROCESS["yolov8"])
    _, place = yolo.prepare(np.zeros((K.height, K.width, 3), np.uint8), probe)
    in_px = image_box * [place.sx, place.sy, place.sx, place.sy] + [place.ox, place.oy, place.ox, place.oy]
    path = tiny_model(tmp_path / "person.onnx", person_output("yolov8", W, H, in_px), W, H)
    cfg = replace(DODTConfig(), learned=replace(LearnedConfig(), enabled=True, model=path, layout="yolov8"))
    p = DODT(cfg)
    color = np.zeros((K.height, K.width, 3), np.uint8)
    labels = []
    for k in range(5):
        r = p.process(SensorFrame(depth=depth, color=color, intrinsics=K, T_world_camera=T0, stamp=k / 30, seq=k))
        near = [o for o in r.obstacles if abs(o.center[0] - 2.0) < 0.5 and abs(o.center[1]) < 0.5]
        assert len(near) == 1
        labels.append(near[0].is_person and near[0].dynamic)
        assert len(p.learned_detector.last_3d) == 1  # the lifted box
    assert labels == [False, False, True, True, True]
    np.testing.assert_allclose(p.learned_detector.last_3d[0].center[:2], [2.0, 0.0], atol=0.3)
