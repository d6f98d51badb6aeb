"""The 2D person detector at run time: an ONNX model through onnxruntime (PyTorch is never imported).

The shipped model (dodt/models/person_detector.onnx) is ours, trained on this project's simulator
renders only (dodt-nav train-detector): it has never seen a real camera's images, and on them it
misses people and boxes things that are not people. For real data bring a detector trained on
real images: any ONNX model with a common YOLO output layout (dodt.learned.yolo), e.g. one
trained on COCO and exported by Ultralytics or YOLOX, whose person class is read.

Our models have a JSON record beside them (same name, ``.json``) with the file's SHA-256, the
input size, the recommended score threshold and how it was trained; the checksum is verified on
load, so a truncated or swapped file is refused with a message naming it. A model of another
layout needs no record; when one is there (with a ``sha256`` and, optionally, a
``score_threshold``), it is checked and read the same way.
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from dodt.config import LearnedConfig
from dodt.learned import layout as ours_layout, yolo
from dodt.learned.views import detect, parse_views

SHIPPED_MODEL = Path(__file__).resolve().parent.parent / "models" / "person_detector.onnx"


class ModelError(ValueError):
    """The model file or its record is missing, corrupt or does not fit the run-time contract."""


def sha256_of(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def load_record(model_path: Path) -> dict:
    """The model's JSON record, after checking that the file is the one it describes."""
    model_path = Path(model_path)
    record_path = model_path.with_suffix(".json")
    if not model_path.is_file():
        raise ModelError(f"learned detector model not found: {model_path}")
    if not record_path.is_file():
        raise ModelError(f"learned detector model {model_path} has no record {record_path.name} beside it "
                         "(it holds the checksum and input size)")
    try:
        record = json.loads(record_path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ModelError(f"{record_path}: not a readable JSON record ({e})") from None
    if not isinstance(record, dict) or not isinstance(record.get("sha256"), str):
        raise ModelError(f"{record_path}: the record has no 'sha256' string")
    got = sha256_of(model_path)
    if got != record["sha256"]:
        raise ModelError(f"{model_path}: SHA-256 {got} does not match {record['sha256']} recorded in "
                         f"{record_path.name}; the file is corrupt or not the recorded model")
    return record


def open_session(model_path: Path, threads: int = 1):
    """An onnxruntime CPU session on the model file, sequential, with ``threads`` intra-op threads."""
    import onnxruntime as ort

    opts = ort.SessionOptions()
    opts.intra_op_num_threads = max(1, int(threads))
    opts.inter_op_num_threads = 1
    opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    opts.log_severity_level = 3
    try:
        return ort.InferenceSession(str(model_path), sess_options=opts, providers=["CPUExecutionProvider"])
    except Exception as e:  # onnxruntime raises its own exception types for unreadable graphs
        raise ModelError(f"{model_path}: onnxruntime cannot load it ({e})") from None


class PersonDetector2D:
    """People in a color image: boxes (K, 4) as (x1, y1, x2, y2) pixels of that image, and scores.

    ``layout``: the model's output layout, "dodt" (ours), "yolov8", "yolov5", "yolox", or "auto"
    (ours when the output is ours, else a YOLO layout told by its shape: dodt.learned.yolo);
    ``person_class``, ``input_size`` (width, height; for a model whose input size is not fixed),
    ``channels``, ``pixel_scale`` and ``letterbox`` apply to YOLO layouts (None: the layout's).
    """

    def __init__(self, model_path: str | Path | None = None, score_threshold: float | None = None,
                 nms_iou: float = 0.45, threads: int = 1, views=("full",), soft_sigma: float | None = None,
                 layout: str = "auto", person_class: int = 0, input_size: tuple[int, int] | None = None,
                 channels: str | None = None, pixel_scale: float | None = None, letterbox: str | None = None):
        try:
            self.views = parse_views(views)
        except ValueError as e:
            raise ModelError(f"learned detector: {e}") from None
        # soft-NMS sigma (0: NMS at nms_iou); None: the run time's (LearnedConfig.soft_nms_sigma)
        self.soft_sigma = float(LearnedConfig().soft_nms_sigma if soft_sigma is None else soft_sigma)
        if not self.soft_sigma >= 0:
            raise ModelError(f"learned detector: soft_nms_sigma must be 0 (NMS) or more, got {soft_sigma}")
        if layout not in ("auto",) + yolo.LAYOUTS:
            raise ModelError(f"learned detector: unknown layout {layout!r}; known: auto, {', '.join(yolo.LAYOUTS)}")
        self.model_path = Path(model_path) if model_path else SHIPPED_MODEL
        if not self.model_path.is_file():
            raise ModelError(f"learned detector model not found: {self.model_path}")
        has_record = self.model_path.with_suffix(".json").is_file()
        if layout == "dodt" or has_record:
            self.record = load_record(self.model_path)  # checks the file before onnxruntime reads it
        else:
            self.record = {}
        self.session = open_session(self.model_path, threads)
        inputs, outputs = self.session.get_inputs(), self.session.get_outputs()
        if len(inputs) != 1:
            raise ModelError(f"{self.model_path}: {len(inputs)} inputs {[(i.name, i.shape) for i in inputs]}; "
                             "a person detector takes one image")
        self._input = inputs[0].name
        want_out = [list(ours_layout.output_shape(st)) for st in ours_layout.STRIDES]
        # auto: a grid output (rank 4) is our layout, checked against our strides; YOLO outputs are rank 3
        ours = layout == "dodt" or (layout == "auto" and len(outputs) == 1 and len(outputs[0].shape) == 4)
        self.format: yolo.YoloFormat | None = None
        if ours:
            if not has_record:
                load_record(self.model_path)  # refused: our models carry their record
            want_in = [1, 3, ours_layout.INPUT_H, ours_layout.INPUT_W]
            if list(inputs[0].shape) != want_in:
                raise ModelError(f"{self.model_path}: input {[(i.name, i.shape) for i in inputs]} is not {want_in}")
            if len(outputs) != 1 or list(outputs[0].shape) not in want_out:
                raise ModelError(f"{self.model_path}: output {[(o.name, o.shape) for o in outputs]} is not one of "
                                 f"{want_out} (strides {', '.join(map(str, ours_layout.STRIDES))})")
            default_threshold = 0.5
        else:
            width, height = self._input_size(inputs[0].shape, input_size)
            if len(outputs) != 1:
                raise ModelError(f"{self.model_path}: {len(outputs)} outputs {[(o.name, o.shape) for o in outputs]}; "
                                 "a YOLO layout has one")
            shape = outputs[0].shape
            if not all(isinstance(d, int) for d in shape):  # a dynamic output: its shape from one run
                shape = self.session.run(None, {self._input: np.zeros((1, 3, height, width), np.float32)})[0].shape
            try:
                self.format = yolo.resolve(shape, width, height, layout, person_class, channels, pixel_scale,
                                           letterbox)
            except yolo.LayoutError as e:
                raise ModelError(f"{self.model_path}: {e}") from None
            default_threshold = yolo.DEFAULT_SCORE_THRESHOLD
        rec_thr = self.record.get("score_threshold", default_threshold)
        self.score_threshold = float(rec_thr if score_threshold is None else score_threshold)
        if not 0.0 < self.score_threshold < 1.0:
            raise ModelError(f"learned detector: score_threshold must lie between 0 and 1, got {self.score_threshold}")
        self.nms_iou = float(nms_iou)

    def _input_size(self, shape, input_size) -> tuple[int, int]:
        """(width, height) of the network input: the model's, or ``input_size`` where it is not fixed."""
        if len(shape) != 4 or (isinstance(shape[1], int) and shape[1] != 3):
            raise ModelError(f"{self.model_path}: input shape {shape} is not (1, 3, height, width)")
        h, w = shape[2], shape[3]
        if isinstance(h, int) and isinstance(w, int):
            if input_size is not None and tuple(input_size) != (w, h):
                raise ModelError(f"{self.model_path}: the model's input is {w}x{h}, not the input_size {input_size}")
            return w, h
        if input_size is None:
            raise ModelError(f"{self.model_path}: the input size is not fixed ({shape}); give input_size "
                             "(width, height), e.g. learned.input_size=640,640")
        w, h = (int(x) for x in input_size)
        if w < 32 or h < 32:
            raise ModelError(f"learned detector: input_size {input_size} is too small")
        return w, h

    def raw(self, color: np.ndarray) -> np.ndarray:
        """The shipped layout's (5, GH, GW) output for one RGB uint8 image."""
        return self._run(ours_layout.resize_for_network(color))

    def _run(self, x: np.ndarray) -> np.ndarray:
        """The raw output for one image already at the network size."""
        return self.session.run(None, {self._input: ours_layout.to_tensor(x)})[0][0]

    def _infer(self, region: np.ndarray, threshold: float) -> tuple[np.ndarray, np.ndarray]:
        """A YOLO model's person boxes in an image region (fractions of it) and scores."""
        x, place = yolo.prepare(region, self.format)
        out = self.session.run(None, {self._input: x})[0]
        boxes, scores = yolo.decode(out, self.format, threshold)
        return yolo.to_fractions(boxes, place, region.shape[1], region.shape[0]), scores

    def __call__(self, color: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        infer = None if self.format is None else self._infer
        boxes, scores = detect(self._run, color, self.views, self.score_threshold, self.nms_iou,
                               floor=self.score_threshold, soft_sigma=self.soft_sigma, infer=infer)
        h, w = color.shape[:2]
        return boxes * np.array([w, h, w, h], np.float32), scores

