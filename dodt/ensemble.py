"""Ensemble detection, the paper's Algorithm 1: keep the boxes two detectors agree on.

For each box of detector 1, its best-IoU box in detector 2 and that box's best-IoU box back in
detector 1; when the two are each other's best match and both IoUs exceed the threshold, the
pair is fused. Paper fusion: the larger dimension per axis, the mean position ("conservative");
the reference code's union box is an option. Boxes without agreement are dropped.
"""
from __future__ import annotations

import numpy as np

from dodt.config import EnsembleConfig
from dodt.detection import Detection
from dodt.geometry import iou_matrix


def mutual_best_pairs(iou: np.ndarray, threshold: float) -> list[tuple[int, int]]:
    """Algorithm 1's matches (i in detector 1, j in detector 2)."""
    pairs = []
    if iou.size == 0:
        return pairs
    best_j = np.argmax(iou, axis=1)
    best_i = np.argmax(iou, axis=0)
    for i, j in enumerate(best_j):
        s1 = iou[i, j]
        s2 = iou[best_i[j], j]
        if best_i[j] == i and s1 > threshold and s2 > threshold:
            pairs.append((i, int(j)))
    return pairs


def fuse(a: Detection, b: Detection, how: str) -> Detection:
    if how == "union":
        lo, hi = np.minimum(a.lower, b.lower), np.maximum(a.upper, b.upper)
        center, size = (lo + hi) / 2, hi - lo
    else:
        center, size = (a.center + b.center) / 2, np.maximum(a.size, b.size)
    points = b.points if len(b.points) >= len(a.points) else a.points
    return Detection(center=center, size=size, source="ensemble", points=points,
                     is_person=a.is_person or b.is_person)


def ensemble(d1: list[Detection], d2: list[Detection], cfg: EnsembleConfig) -> list[Detection]:
    if not d1 or not d2:
        return []
    iou = iou_matrix([d.center for d in d1], [d.size for d in d1], [d.center for d in d2], [d.size for d in d2])
    return [fuse(d1[i], d2[j], cfg.fusion) for i, j in mutual_best_pairs(iou, cfg.iou_threshold)]
