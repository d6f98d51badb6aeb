"""Average precision of the person detector, measured through the run-time decode.

The network's raw output goes through `dodt.learned.layout.decode` and `layout.nms` (IoU 0.45),
exactly as at run time, so the figures here are those of the shipped model. Ground truth: the
person boxes of a dataset file (`experiments.detector.dataset`); people within ``max_distance``
are the ones to find. A detection matched to a person beyond ``max_distance`` (or overlapping
one by IoU >= ``iou`` without matching anyone) is ignored, neither a true nor a false positive:
far people are neither required nor punished.

AP is VOC's all-point interpolated AP: the area under the precision envelope of the
precision-recall curve, detections of all images ranked by score together.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dodt.learned import layout, views as view_fusion
from dodt.learned.model import open_session

NMS_IOU = 0.45
DISTANCE_BINS = (0.0, 2.0, 4.0, 6.0, 8.0, 10.0)  # m
DEFAULT_OPERATING_THRESHOLD = 0.3  # where the model's json does not recommend one


# --------------------------------------------------------------------------- pure functions


def box_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(len(a), len(b)) IoU of (x1, y1, x2, y2) boxes."""
    a = np.asarray(a, np.float64).reshape(-1, 4)
    b = np.asarray(b, np.float64).reshape(-1, 4)
    x1 = np.maximum(a[:, None, 0], b[None, :, 0])
    y1 = np.maximum(a[:, None, 1], b[None, :, 1])
    x2 = np.minimum(a[:, None, 2], b[None, :, 2])
    y2 = np.minimum(a[:, None, 3], b[None, :, 3])
    inter = np.clip(x2 - x1, 0, None) * np.clip(y2 - y1, 0, None)
    area_a = (a[:, 2] - a[:, 0]) * (a[:, 3] - a[:, 1])
    area_b = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    return inter / np.maximum(area_a[:, None] + area_b[None, :] - inter, 1e-12)


@dataclass(frozen=True)
class ImageMatch:
    """One image's detections after matching: the ones that count (score, true positive?) and,
    for every ground-truth box, the score of the detection that found it (-inf: none)."""

    scores: np.ndarray  # (D,) float64, counted detections only
    tp: np.ndarray  # (D,) bool
    gt_found_score: np.ndarray  # (G,) float64


def match_image(det_boxes: np.ndarray, det_scores: np.ndarray, gt_boxes: np.ndarray, gt_ignore: np.ndarray,
                iou: float = 0.5) -> ImageMatch:
    """Greedy matching, best score first (VOC). A detection takes the unmatched counted box it
    overlaps most (IoU >= ``iou``): a true positive. Failing that, if it overlaps an ignored box
    by IoU >= ``iou`` (matched or not) it is dropped; otherwise it is a false positive (which
    includes a second detection of a counted person)."""
    det_boxes = np.asarray(det_boxes, np.float64).reshape(-1, 4)
    det_scores = np.asarray(det_scores, np.float64).reshape(-1)
    gt_boxes = np.asarray(gt_boxes, np.float64).reshape(-1, 4)
    gt_ignore = np.asarray(gt_ignore, bool).reshape(-1)
    order = np.argsort(-det_scores, kind="stable")
    ious = box_iou(det_boxes, gt_boxes)
    taken = np.zeros(len(gt_boxes), bool)
    found = np.full(len(gt_boxes), -np.inf)
    scores, tps = [], []
    for d in order:
        row = ious[d]
        free = (~gt_ignore) & (~taken) & (row >= iou)
        if free.any():
            g = int(np.argmax(np.where(free, row, -1.0)))
            taken[g] = True
            found[g] = det_scores[d]
            scores.append(det_scores[d])
            tps.append(True)
        elif np.any(gt_ignore & (row >= iou)):
            continue
        else:
            scores.append(det_scores[d])
            tps.append(False)
    return ImageMatch(np.asarray(scores, np.float64), np.asarray(tps, bool), found)


def voc_ap(scores: np.ndarray, tp: np.ndarray, n_gt: int) -> float:
    """All-point interpolated average precision of ranked detections (VOC 2010+)."""
    if n_gt <= 0:
        return float("nan")
    scores = np.asarray(scores, np.float64)
    tp = np.asarray(tp, bool)
    if len(scores) == 0:
        return 0.0
    order = np.argsort(-scores, kind="stable")
    tp = tp[order]
    ctp = np.cumsum(tp)
    cfp = np.cumsum(~tp)
    recall = ctp / n_gt
    precision = ctp / np.maximum(ctp + cfp, 1)
    mrec = np.concatenate([[0.0], recall, [1.0]])
    mpre = np.concatenate([[1.0], precision, [0.0]])
    mpre = np.maximum.accumulate(mpre[::-1])[::-1]  # the precision envelope
    i = np.flatnonzero(mrec[1:] != mrec[:-1])
    return float(np.sum((mrec[i + 1] - mrec[i]) * mpre[i + 1]))


def best_f1_threshold(matches: list[ImageMatch], n_gt: int, grid=np.arange(0.05, 0.951, 0.05)) -> float:
    """The score threshold on ``grid`` with the best F1 (the smaller one on ties)."""
    scores = np.concatenate([m.scores for m in matches]) if matches else np.zeros(0)
    tp = np.concatenate([m.tp for m in matches]) if matches else np.zeros(0, bool)
    best, best_t = -1.0, float(grid[0])
    for t in grid:
        keep = scores >= t
        ntp = int(np.sum(tp[keep]))
        p = ntp / max(int(np.sum(keep)), 1)
        r = ntp / max(n_gt, 1)
        f1 = 2 * p * r / max(p + r, 1e-12)
        if f1 > best + 1e-12:
            best, best_t = f1, float(t)
    return round(best_t, 4)


def summarize(matches: list[ImageMatch], gt_distances: list[np.ndarray], gt_ignore: list[np.ndarray],
              operating_threshold: float) -> dict:
    """AP over all images, and precision / recall (overall and per distance bin) at one threshold."""
    scores = np.concatenate([m.scores for m in matches]) if matches else np.zeros(0)
    tp = np.concatenate([m.tp for m in matches]) if matches else np.zeros(0, bool)
    counted = [~ig for ig in gt_ignore]
    n_gt = int(sum(int(np.sum(c)) for c in counted))
    found = np.concatenate([m.gt_found_score[c] for m, c in zip(matches, counted)]) if matches else np.zeros(0)
    dist = np.concatenate([d[c] for d, c in zip(gt_distances, counted)]) if matches else np.zeros(0)
    keep = scores >= operating_threshold
    n_det = int(np.sum(keep))
    n_tp = int(np.sum(tp[keep]))
    recalled = found >= operating_threshold
    bins = {}
    for lo, hi in zip(DISTANCE_BINS[:-1], DISTANCE_BINS[1:]):
        inside = (dist >= lo) & ((dist < hi) if hi < DISTANCE_BINS[-1] else (dist <= hi))
        n = int(np.sum(inside))
        bins[f"{lo:g}-{hi:g}"] = {"boxes": n, "recall": float(np.mean(recalled[inside])) if n else None}
    return {
        "ap50": voc_ap(scores, tp, n_gt),
        "operating_threshold": float(operating_threshold),
        "precision": n_tp / n_det if n_det else None,
        "recall": n_tp / n_gt if n_gt else None,
        "recall_by_distance": bins,
        "images": len(matches),
        "boxes": n_gt,
        "boxes_ignored": int(sum(int(np.sum(ig)) for ig in gt_ignore)),
        "detections_counted": int(len(scores)),
    }


# --------------------------------------------------------------------------- data and model


def load_split(npz_path) -> dict:
    """images (N, H, W, 3) uint8, per-image box arrays (K, 6): x1, y1, x2, y2, distance, visible
    pixels, and the meta dictionary, from a dataset file, as generated or packed."""
    with np.load(Path(npz_path)) as z:
        if "webp" in z:  # experiments.detector.packed
            from experiments.detector.packed import unpack_images

            images = unpack_images(z["webp"], z["offsets"], str(npz_path))
        else:
            images = z["images"]
        boxes = z["boxes"].astype(np.float64)
        meta = json.loads(str(z["meta"])) if "meta" in z else {}
    idx = boxes[:, 0].astype(np.int64) if len(boxes) else np.zeros(0, np.int64)
    per_image = [boxes[idx == i, 1:7] for i in range(len(images))]
    return {"images": images, "boxes": per_image, "meta": meta}


def decode_all(preds: np.ndarray, score_threshold: float, nms_iou: float = NMS_IOU) -> list[tuple[np.ndarray, np.ndarray]]:
    """The run-time decode (layout.decode then layout.nms) of each image's raw output."""
    out = []
    for p in preds:
        boxes, scores = layout.decode(p, score_threshold)
        keep = layout.nms(boxes, scores, nms_iou)
        out.append((boxes[keep], scores[keep]))
    return out


def evaluate_detections(detections, gt_boxes: list[np.ndarray], max_distance: float = 10.0, iou: float = 0.5,
                        operating_threshold: float | None = None, min_visible_px: int = 0) -> dict:
    """Figures for decoded detections [(boxes, scores)] against per-image ground truth (K, >=5)
    rows (x1, y1, x2, y2, distance, visible pixels). Without ``operating_threshold`` the best-F1
    one is used (and reported as ``best_f1_threshold``). People showing fewer than
    ``min_visible_px`` pixels (at 640x480) are ignored like people beyond ``max_distance``."""
    matches, dists, ignores = [], [], []
    for (boxes, scores), gt in zip(detections, gt_boxes):
        gt = np.asarray(gt, np.float64)
        gt = gt if gt.ndim == 2 else gt.reshape(-1, 5)
        ignore = gt[:, 4] > max_distance
        if min_visible_px > 0 and gt.shape[1] > 5:
            ignore |= gt[:, 5] < min_visible_px
        matches.append(match_image(boxes, scores, gt[:, :4], ignore, iou))
        dists.append(gt[:, 4])
        ignores.append(ignore)
    n_gt = int(sum(int(np.sum(~ig)) for ig in ignores))
    best = best_f1_threshold(matches, n_gt)
    out = summarize(matches, dists, ignores, best if operating_threshold is None else operating_threshold)
    out["best_f1_threshold"] = best
    out["max_distance"] = float(max_distance)
    out["iou"] = float(iou)
    out["min_visible_px"] = int(min_visible_px)
    return out


def nms_ceiling(gt_boxes: list[np.ndarray], max_distance: float = 10.0, iou: float = 0.5,
                nms_iou: float = NMS_IOU) -> float:
    """The AP of a perfect detector whose boxes go through the same NMS: the ground-truth boxes
    themselves, nearer people scored higher. Visible-pixel boxes of people walking close
    together overlap, and NMS keeps one of each pair that overlaps by more than ``nms_iou``."""
    dets = []
    for gt in gt_boxes:
        gt = np.asarray(gt, np.float64)
        gt = gt if gt.ndim == 2 else gt.reshape(-1, 5)
        boxes = gt[:, :4].astype(np.float32)
        scores = (1.0 / (1.0 + gt[:, 4])).astype(np.float32)
        keep = layout.nms(boxes, scores, nms_iou) if len(gt) else np.zeros(0, np.int64)
        dets.append((boxes[keep], scores[keep]))
    return evaluate_detections(dets, gt_boxes, max_distance, iou, operating_threshold=0.0)["ap50"]


def onnx_session(model_path, threads: int = 2):
    """The run time's session (dodt.learned.model.open_session) without the record check: training
    evaluates its model before writing the record."""
    return open_session(Path(model_path), threads)


def run_onnx(session, images: np.ndarray) -> np.ndarray:
    """Raw outputs (N, 5, GH, GW) for uint8 images at the network size, one at a time (the model's
    input shape is fixed at batch 1; the grid is the model's output's)."""
    out = np.empty((len(images), *session.get_outputs()[0].shape[1:]), np.float32)
    for i, img in enumerate(images):
        x = layout.to_tensor(layout.resize_for_network(img))
        out[i] = session.run(["preds"], {"images": x})[0][0]
    return out


def detect_all(session, images: np.ndarray, views, score_threshold: float,
               nms_iou: float = NMS_IOU, soft_sigma: float = 0.0) -> list[tuple[np.ndarray, np.ndarray]]:
    """The run time's detections (`dodt.learned.views.detect`) of each image through ``views``."""
    def run(x: np.ndarray) -> np.ndarray:
        return session.run(["preds"], {"images": layout.to_tensor(x)})[0][0]

    return [view_fusion.detect(run, img, views, score_threshold, nms_iou, floor=score_threshold,
                               soft_sigma=soft_sigma) for img in images]


def recommended_threshold(model_path) -> float | None:
    meta = Path(model_path).with_suffix(".json")
    if meta.is_file():
        value = json.loads(meta.read_text()).get("score_threshold")
        return None if value is None else float(value)
    return None


def average_precision(model_path, npz_path, max_distance: float = 10.0, iou: float = 0.5,
                      score_threshold: float = 0.05, operating_threshold: float | None = None,
                      threads: int = 2, nms_iou: float = NMS_IOU, min_visible_px: int = 0,
                      views=("full",), soft_sigma: float = 0.0) -> dict:
    """AP@``iou`` (VOC all-point) of the ONNX model on a dataset file, for the people within
    ``max_distance``; detections below ``score_threshold`` are dropped before NMS (IoU ``nms_iou``,
    FastestDet's 0.45 by default), or soft-NMS with ``soft_sigma`` when it is above 0.

    Precision, recall and recall per distance bin (0-2, 2-4, 4-6, 6-8, 8-10 m) are given at
    ``operating_threshold``: by default the one recommended in the model's json (its
    ``score_threshold``), else 0.3. ``views`` (names or `dodt.learned.views.View`s) runs the
    model on several views of each image and fuses them as at run time; the boxes of each view
    from ``score_threshold`` up are fused, and ``nms_iou`` is the fusion's IoU too. Returns a dict: ap50, precision, recall,
    recall_by_distance {bin: {boxes, recall}}, images, boxes (counted), boxes_ignored,
    operating_threshold, best_f1_threshold, max_distance, iou, score_threshold, nms_iou.
    """
    if not Path(model_path).is_file():
        raise FileNotFoundError(f"{model_path}: no such model file")
    if not Path(npz_path).is_file():
        raise FileNotFoundError(f"{npz_path}: no such dataset file")
    if operating_threshold is None:
        operating_threshold = recommended_threshold(model_path)
        if operating_threshold is None:
            operating_threshold = DEFAULT_OPERATING_THRESHOLD
    view_list = tuple(v if isinstance(v, view_fusion.View) else view_fusion.parse_views([v])[0] for v in views)
    data = load_split(npz_path)
    # one full view is the plain decode and NMS (decode_all's), several are fused as at run time
    detections = detect_all(onnx_session(model_path, threads), data["images"], view_list, score_threshold, nms_iou,
                            soft_sigma)
    out = evaluate_detections(detections, data["boxes"], max_distance, iou, operating_threshold, min_visible_px)
    out["score_threshold"] = float(score_threshold)
    out["nms_iou"] = float(nms_iou)
    out["soft_nms_sigma"] = float(soft_sigma)
    out["views"] = [name for v in view_list for name, known in view_fusion.VIEWS.items() if known == v]
    return out
