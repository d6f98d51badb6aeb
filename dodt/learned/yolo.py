"""Person detectors a user brings: ONNX models with the common YOLO output layouts.

The shipped model is ours (dodt.learned.layout, layout "dodt"). A COCO-trained detector exported
to ONNX by its own tools can stand in for it (LearnedConfig.model and .layout); only its person
class is read (LearnedConfig.person_class, 0 in COCO). The network's input size is read from the
model (a dynamic input takes LearnedConfig.input_size). Layouts of the one output:

- ``yolov8``: Ultralytics YOLOv8 / YOLO11 detection export, (1, 4 + C, N): per candidate the box
  centre x, y, width and height in input pixels, then the C class scores (sigmoid applied); no
  objectness. The transposed (1, N, 4 + C) is read too when the layout is named ("auto" takes
  an output of N rows for yolox).
- ``yolov5``: (1, N, 5 + C): box as above, objectness, C class scores, all decoded in the graph
  (YOLOv5, YOLOv7, and YOLOX exported with its decoding in the graph); score = objectness x class.
- ``yolox``: YOLOX's own export, whose graph stops before the decoding: (1, N, 5 + C) per cell of
  the stride 8, 16 and 32 grids, row by row: x, y offsets from the cell in strides, log width and
  height in strides, objectness and class scores (sigmoid applied).

Preprocessing follows each family's tools: Ultralytics and YOLOv5 letterbox the image into the
input, centred on a grey (114) border, RGB scaled to [0, 1]; YOLOX pads at the bottom and right,
BGR in 0-255 (its current preprocessing, without the older mean / std normalisation).
LearnedConfig.channels, pixel_scale and letterbox override these.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

LAYOUTS = ("dodt", "yolov8", "yolov5", "yolox")
STRIDES = (8, 16, 32)
PAD_VALUE = 114  # the grey both families pad with
# The score above which a box counts, for a model without a record: YOLOX's demo uses 0.3,
# Ultralytics predicts from 0.25; ours, not measured on recorded data.
DEFAULT_SCORE_THRESHOLD = 0.3
PREPROCESS = {  # layout -> (channels, pixel scale, letterbox)
    "yolov8": ("rgb", 1.0 / 255.0, "center"),
    "yolov5": ("rgb", 1.0 / 255.0, "center"),
    "yolox": ("bgr", 1.0, "top-left"),
}


class LayoutError(ValueError):
    """The model's output does not fit the layout asked for (or any, for "auto")."""


def cells(width: int, height: int, strides=STRIDES) -> int:
    """Candidates of one anchor per cell of grids at ``strides`` over a width x height input."""
    return sum(-(-width // s) * -(-height // s) for s in strides)


@dataclass(frozen=True)
class YoloFormat:
    """How to feed a YOLO model and read its output."""

    layout: str  # yolov8 | yolov5 | yolox
    width: int  # network input [px]
    height: int
    classes: int
    person_class: int = 0
    transposed: bool = False  # yolov8 only: (1, N, 4 + C) instead of (1, 4 + C, N)
    channels: str = "rgb"  # rgb | bgr
    pixel_scale: float = 1.0 / 255.0
    letterbox: str = "center"  # center | top-left | none (stretched to the input)


def resolve(output_shape, width: int, height: int, layout: str = "auto", person_class: int = 0,
            channels: str | None = None, pixel_scale: float | None = None,
            letterbox: str | None = None) -> YoloFormat:
    """The YoloFormat of a model with one output of ``output_shape`` and a width x height input.
    ``layout`` "auto" tells yolov8 (4 + C rows, N columns), yolox (N rows of 5 + C) and yolov5
    (3 N rows) apart by N; a shape none fits raises a LayoutError naming it."""
    shape = tuple(output_shape)
    if len(shape) != 3 or shape[0] != 1 or not all(isinstance(d, (int, np.integer)) and d > 0 for d in shape[1:]):
        raise LayoutError(f"output shape {list(shape)} is no YOLO layout: expected (1, 4 + classes, N) or "
                          f"(1, N, 5 + classes) with fixed sizes")
    a, b = int(shape[1]), int(shape[2])
    n = cells(width, height)
    if layout == "auto":
        if b == n and a >= 5:
            layout = "yolov8"
        elif a == n and b >= 6:
            layout = "yolox"
        elif a == 3 * n and b >= 6:
            layout = "yolov5"
        else:
            raise LayoutError(f"output shape {list(shape)} fits no layout for a {width}x{height} input "
                              f"({n} cells of strides 8, 16, 32): name it (yolov8, yolov5 or yolox)")
    if layout == "yolov8":
        transposed = a > b  # (1, N, 4 + C): more candidates than channels
        classes = (b if transposed else a) - 4
    elif layout in ("yolov5", "yolox"):
        transposed = False
        classes = b - 5
        if layout == "yolox" and a != n:
            raise LayoutError(f"output shape {list(shape)}: a YOLOX output has one row per cell of the "
                              f"stride 8, 16 and 32 grids, {n} for a {width}x{height} input, not {a}")
    else:
        raise LayoutError(f"unknown layout {layout!r}; known: auto, {', '.join(LAYOUTS)}")
    if classes < 1:
        raise LayoutError(f"output shape {list(shape)} leaves no class scores for layout {layout}")
    if not 0 <= person_class < classes:
        raise LayoutError(f"person class {person_class} is not among the model's {classes} classes")
    ch, scale, box = PREPROCESS[layout]
    channels = ch if channels is None else channels
    if channels not in ("rgb", "bgr"):
        raise LayoutError(f"channels must be rgb or bgr, got {channels!r}")
    letterbox = box if letterbox is None else letterbox
    if letterbox not in ("center", "top-left", "none"):
        raise LayoutError(f"letterbox must be center, top-left or none, got {letterbox!r}")
    scale = scale if pixel_scale is None else float(pixel_scale)
    if not scale > 0:
        raise LayoutError(f"pixel_scale must be above 0, got {pixel_scale!r}")
    return YoloFormat(layout, int(width), int(height), int(classes), int(person_class), transposed, channels, scale,
                      letterbox)


@dataclass(frozen=True)
class Placement:
    """Where an image went in the network's input: input pixel = image pixel x scale + offset."""

    sx: float
    sy: float
    ox: float
    oy: float


def prepare(image: np.ndarray, fmt: YoloFormat) -> tuple[np.ndarray, Placement]:
    """(1, 3, H, W) float32 network input from an RGB uint8 image, and where the image lies in it."""
    h, w = image.shape[:2]
    W, H = fmt.width, fmt.height
    if fmt.letterbox == "none":
        canvas = cv2.resize(image, (W, H), interpolation=cv2.INTER_LINEAR)
        place = Placement(W / w, H / h, 0.0, 0.0)
    else:
        r = min(W / w, H / h)
        nw, nh = max(1, min(W, int(round(w * r)))), max(1, min(H, int(round(h * r))))
        left, top = ((W - nw) // 2, (H - nh) // 2) if fmt.letterbox == "center" else (0, 0)
        canvas = np.full((H, W, 3), PAD_VALUE, np.uint8)
        canvas[top:top + nh, left:left + nw] = cv2.resize(image, (nw, nh), interpolation=cv2.INTER_LINEAR)
        place = Placement(nw / w, nh / h, float(left), float(top))
    if fmt.channels == "bgr":
        canvas = canvas[..., ::-1]
    x = np.ascontiguousarray(canvas.transpose(2, 0, 1)[None], dtype=np.float32)
    return x * np.float32(fmt.pixel_scale), place


def _grid(width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2) cell corners (x, y) and (N,) strides of the YOLOX grids, in its row order."""
    xy, st = [], []
    for s in STRIDES:
        gh, gw = -(-height // s), -(-width // s)
        yv, xv = np.mgrid[0:gh, 0:gw]
        xy.append(np.stack([xv.ravel(), yv.ravel()], axis=1))
        st.append(np.full(gh * gw, s))
    return np.concatenate(xy).astype(np.float32), np.concatenate(st).astype(np.float32)


def decode(output: np.ndarray, fmt: YoloFormat, score_threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """Person boxes (K, 4) as (x1, y1, x2, y2) input pixels and their scores (K,), from the model's
    output for one image (with or without its batch axis), before non-maximum suppression."""
    p = np.asarray(output, dtype=np.float32)
    if p.ndim == 3:
        p = p[0]
    if fmt.layout == "yolov8":
        rows = p if fmt.transposed else p.T  # (N, 4 + C)
        box, score = rows[:, :4], rows[:, 4 + fmt.person_class]
    else:
        box, score = p[:, :4], p[:, 4] * p[:, 5 + fmt.person_class]
    keep = np.nonzero(score >= score_threshold)[0]
    box, score = box[keep], score[keep]
    if fmt.layout == "yolox":
        xy, stride = _grid(fmt.width, fmt.height)
        xy, stride = xy[keep], stride[keep, None]
        centre = (box[:, :2] + xy) * stride
        size = np.exp(np.minimum(box[:, 2:4], 20.0)) * stride  # a raw log size; capped against overflow
    else:
        centre, size = box[:, :2], box[:, 2:4]
    out = np.concatenate([centre - size / 2, centre + size / 2], axis=1)
    good = np.all(np.isfinite(out), axis=1) & np.isfinite(score)
    return out[good].astype(np.float32), score[good].astype(np.float32)


def to_fractions(boxes: np.ndarray, place: Placement, width: int, height: int) -> np.ndarray:
    """Input-pixel boxes as (x1, y1, x2, y2) fractions of the width x height image, clipped to it."""
    b = np.asarray(boxes, np.float64).reshape(-1, 4).copy()
    b[:, [0, 2]] = (b[:, [0, 2]] - place.ox) / place.sx / width
    b[:, [1, 3]] = (b[:, [1, 3]] - place.oy) / place.sy / height
    return b.clip(0.0, 1.0).astype(np.float32)
