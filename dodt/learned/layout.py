"""The contract between training (experiments.detector, PyTorch) and run time (onnxruntime).

Input: the color image (RGB uint8, any size) resized to INPUT_W x INPUT_H with bilinear
interpolation (each axis scaled on its own), scaled to [0, 1], NCHW float32, ONNX input "images".
Output "preds": (1, 5, GH, GW) raw values per cell of a stride-16 grid (GRID_H x GRID_W, as
FastestDet) or a stride-8 grid (twice as fine each way); one anchor-free head, one class: channel
0 the objectness logit, channels 1-4 (tx, ty, tw, th) decoded as in FastestDet:
cx = (gx + tanh(tx)) / GW, cy = (gy + tanh(ty)) / GH, w = sigmoid(tw), h = sigmoid(th), all as
fractions of the image's width and height. The grid is read from the output's shape.
"""
from __future__ import annotations

import cv2
import numpy as np

INPUT_W, INPUT_H = 352, 256
STRIDE = 16
GRID_W, GRID_H = INPUT_W // STRIDE, INPUT_H // STRIDE
STRIDES = (16, 8)  # the head strides a model may have
CHANNELS = 5  # objectness, tx, ty, tw, th


def output_shape(stride: int) -> tuple[int, int, int, int]:
    """The (1, CHANNELS, GH, GW) output of a model whose head has ``stride``."""
    return (1, CHANNELS, INPUT_H // stride, INPUT_W // stride)


def resize_for_network(color: np.ndarray) -> np.ndarray:
    """(INPUT_H, INPUT_W, 3) uint8: what the dataset stores and the network sees."""
    if color.shape[:2] == (INPUT_H, INPUT_W):
        return color
    return cv2.resize(color, (INPUT_W, INPUT_H), interpolation=cv2.INTER_LINEAR)


def to_tensor(images: np.ndarray) -> np.ndarray:
    """(N, H, W, 3) or (H, W, 3) uint8 at the network size -> (N, 3, H, W) float32 in [0, 1]."""
    x = np.asarray(images)
    if x.ndim == 3:
        x = x[None]
    return np.ascontiguousarray(x.transpose(0, 3, 1, 2), dtype=np.float32) * np.float32(1.0 / 255.0)


def decode(preds: np.ndarray, score_threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """Boxes (K, 4) as (x1, y1, x2, y2) fractions of the image, and scores (K,), from one image's
    raw (5, GH, GW) output, before non-maximum suppression."""
    p = np.asarray(preds, dtype=np.float32)
    p = p.reshape(p.shape[-3:])
    if p.shape[0] != CHANNELS:
        raise ValueError(f"decode: expected ({CHANNELS}, GH, GW) raw output, got shape {np.shape(preds)}")
    grid_h, grid_w = p.shape[1:]
    score = 1.0 / (1.0 + np.exp(-p[0]))
    gy, gx = np.nonzero(score >= score_threshold)
    if len(gx) == 0:
        return np.zeros((0, 4), np.float32), np.zeros(0, np.float32)
    t = p[1:, gy, gx]
    cx = (gx + np.tanh(t[0])) / grid_w
    cy = (gy + np.tanh(t[1])) / grid_h
    w = 1.0 / (1.0 + np.exp(-t[2]))
    h = 1.0 / (1.0 + np.exp(-t[3]))
    boxes = np.stack([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2], axis=1).clip(0.0, 1.0)
    return boxes.astype(np.float32), score[gy, gx].astype(np.float32)


def iou_one(box: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """IoU of one (x1, y1, x2, y2) box with each row of ``boxes`` (K, 4)."""
    x1 = np.maximum(box[0], boxes[:, 0])
    y1 = np.maximum(box[1], boxes[:, 1])
    x2 = np.minimum(box[2], boxes[:, 2])
    y2 = np.minimum(box[3], boxes[:, 3])
    inter = np.clip(x2 - x1, 0, None) * np.clip(y2 - y1, 0, None)
    area = (box[2] - box[0]) * (box[3] - box[1])
    areas = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
    return inter / np.maximum(area + areas - inter, 1e-12)


def nms(boxes: np.ndarray, scores: np.ndarray, iou_threshold: float) -> np.ndarray:
    """Indices kept by greedy non-maximum suppression, best score first."""
    order = np.argsort(-scores, kind="stable")
    keep = []
    while len(order):
        i = order[0]
        keep.append(int(i))
        rest = order[1:]
        order = rest[iou_one(boxes[i], boxes[rest]) <= iou_threshold]
    return np.asarray(keep, dtype=np.int64)


def soft_nms(boxes: np.ndarray, scores: np.ndarray, sigma: float, floor: float) -> tuple[np.ndarray, np.ndarray]:
    """Gaussian soft non-maximum suppression (Bodla et al., 2017): the best box is kept and every
    other box's score is multiplied by exp(-IoU^2 / sigma) with it, again with the best of the
    rest, and so on; boxes whose score falls below ``floor`` are dropped. A person partly hidden
    behind another keeps his box with a lowered score instead of losing it to a fixed IoU cut.
    Returns the kept boxes (K, 4) and their lowered scores, best first."""
    b = np.asarray(boxes, dtype=np.float32).reshape(-1, 4)
    s = np.asarray(scores, dtype=np.float64).reshape(-1).copy()
    alive = s >= floor
    b, s = b[alive], s[alive]
    kept_b, kept_s = [], []
    while len(s):
        i = int(np.argmax(s))
        kept_b.append(b[i])
        kept_s.append(s[i])
        rest = np.ones(len(s), bool)
        rest[i] = False
        b, s = b[rest], s[rest]
        if len(s):
            s = s * np.exp(-iou_one(kept_b[-1], b) ** 2 / sigma)
            alive = s >= floor
            b, s = b[alive], s[alive]
    return np.asarray(kept_b, np.float32).reshape(-1, 4), np.asarray(kept_s, np.float32)
