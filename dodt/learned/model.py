"""The 2D person detector at run time: an ONNX model through onnxruntime (PyTorch is never imported).

Every model file has a JSON record beside it (same name, ``.json``) with the file's SHA-256, the
input size, the recommended score threshold and how it was trained; the checksum is verified
on load, so a truncated or swapped file is refused with a message naming it.
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from dodt.config import LearnedConfig
from dodt.learned import layout
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
    """People in a color image: boxes (K, 4) as (x1, y1, x2, y2) pixels of that image, and scores."""

    def __init__(self, model_path: str | Path | None = None, score_threshold: float | None = None,
                 nms_iou: float = 0.45, threads: int = 1, views=("full",), soft_sigma: float | None = None):
        try:
            self.views = parse_views(views)
        except ValueError as e:
            raise ModelError(f"learned detector: {e}") from None
        # soft-NMS sigma (0: NMS at nms_iou); None: the run time's (LearnedConfig.soft_nms_sigma)
        self.soft_sigma = float(LearnedConfig().soft_nms_sigma if soft_sigma is None else soft_sigma)
        if not self.soft_sigma >= 0:
            raise ModelError(f"learned detector: soft_nms_sigma must be 0 (NMS) or more, got {soft_sigma}")
        self.model_path = Path(model_path) if model_path else SHIPPED_MODEL
        self.record = load_record(self.model_path)
        self.session = open_session(self.model_path, threads)
        inputs, outputs = self.session.get_inputs(), self.session.get_outputs()
        want_in = [1, 3, layout.INPUT_H, layout.INPUT_W]
        want_out = [list(layout.output_shape(s)) for s in layout.STRIDES]
        if len(inputs) != 1 or list(inputs[0].shape) != want_in:
            raise ModelError(f"{self.model_path}: input {[(i.name, i.shape) for i in inputs]} is not {want_in}")
        if len(outputs) != 1 or list(outputs[0].shape) not in want_out:
            raise ModelError(f"{self.model_path}: output {[(o.name, o.shape) for o in outputs]} is not one of "
                             f"{want_out} (strides {', '.join(map(str, layout.STRIDES))})")
        self._input = inputs[0].name
        rec_thr = self.record.get("score_threshold", 0.5)
        self.score_threshold = float(rec_thr if score_threshold is None else score_threshold)
        self.nms_iou = float(nms_iou)

    def raw(self, color: np.ndarray) -> np.ndarray:
        """The network's (5, GH, GW) output for one RGB uint8 image."""
        return self._run(layout.resize_for_network(color))

    def _run(self, x: np.ndarray) -> np.ndarray:
        """The raw output for one image already at the network size."""
        return self.session.run(None, {self._input: layout.to_tensor(x)})[0][0]

    def __call__(self, color: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        boxes, scores = detect(self._run, color, self.views, self.score_threshold, self.nms_iou,
                               floor=self.score_threshold, soft_sigma=self.soft_sigma)
        h, w = color.shape[:2]
        return boxes * np.array([w, h, w, h], np.float32), scores
