"""Several views of one image through the person detector, fused into one set of boxes.

The network sees a 640x480 image at 352x256: a person 8-10 m away is some 10 px wide there, and
its one box per stride-16 cell places people standing side by side badly. Running it also on the
mirrored image and on an enlarged central crop, and fusing the three sets of boxes, raises the
precision and places far people better, at three times the inference time (`dodt-nav
eval-detector --views ...` measures it). Off by default (`LearnedConfig.views`).

A view is a region of the image (fractions of its width and height) and whether it is mirrored.
The region is cut from the image as given, resized to the network's input and run; its boxes are
mapped back to fractions of the whole image. Boxes that touch a side of the region lying inside
the image are dropped: they are people cut by the crop, whose box would be too small.

Fusion (weighted box fusion): boxes of all views, best score first, join the first cluster whose
fused box they overlap by more than ``iou``; a cluster's box is the score-weighted mean of its
boxes, and its score is the sum over views of each view's best score in it, divided by the
number of views that could have seen the whole box. A person found by one view of three scores
a third of that view's score: single-view boxes, most of them false, fall below the threshold.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import cv2
import numpy as np

from dodt.learned import layout

EDGE = 0.01  # a box within this fraction of a region's inner side touches it


@dataclass(frozen=True)
class View:
    x0: float
    y0: float
    w: float
    h: float
    mirrored: bool = False

    @property
    def is_whole(self) -> bool:
        return self.x0 <= 0.0 and self.y0 <= 0.0 and self.x0 + self.w >= 1.0 and self.y0 + self.h >= 1.0


CENTER_CROP = 2.0 / 3.0
VIEWS = {
    "full": View(0.0, 0.0, 1.0, 1.0),
    "flip": View(0.0, 0.0, 1.0, 1.0, mirrored=True),
    "center": View((1.0 - CENTER_CROP) / 2, (1.0 - CENTER_CROP) / 2, CENTER_CROP, CENTER_CROP),
    "center-flip": View((1.0 - CENTER_CROP) / 2, (1.0 - CENTER_CROP) / 2, CENTER_CROP, CENTER_CROP, mirrored=True),
}


def parse_views(names: Sequence[str] | str) -> tuple[View, ...]:
    """Views by name ("full", "flip", "center", "center-flip"), from a sequence or a comma list."""
    if isinstance(names, str):
        names = [n.strip() for n in names.split(",") if n.strip()]
    names = list(names)
    if not names:
        raise ValueError("views: expected at least one of " + ", ".join(VIEWS))
    unknown = [n for n in names if n not in VIEWS]
    if unknown:
        raise ValueError(f"views: unknown {', '.join(map(repr, unknown))}; expected names from {', '.join(VIEWS)}")
    if len(set(names)) != len(names):
        raise ValueError(f"views: {names} names a view twice")
    return tuple(VIEWS[n] for n in names)


def view_region(color: np.ndarray, view: View) -> np.ndarray:
    """The part of ``color`` one view shows (mirrored if it is), at the image's resolution."""
    if view.is_whole:
        img = color
    else:
        h, w = color.shape[:2]
        x0, x1 = int(round(view.x0 * w)), int(round((view.x0 + view.w) * w))
        y0, y1 = int(round(view.y0 * h)), int(round((view.y0 + view.h) * h))
        img = color[y0:y1, x0:x1]
    if view.mirrored:
        img = img[:, ::-1]
    return np.ascontiguousarray(img)


def view_image(color: np.ndarray, view: View) -> np.ndarray:
    """The shipped network's input image (INPUT_H, INPUT_W, 3) uint8 for one view of ``color``."""
    return layout.resize_for_network(view_region(color, view))


def _inner_sides(view: View) -> tuple[bool, bool, bool, bool]:
    return view.x0 > 0.0, view.y0 > 0.0, view.x0 + view.w < 1.0, view.y0 + view.h < 1.0


def to_image(boxes: np.ndarray, scores: np.ndarray, view: View) -> tuple[np.ndarray, np.ndarray]:
    """A view's decoded boxes (fractions of the view) as fractions of the whole image, without
    the boxes that touch a side of the region lying inside the image."""
    b = np.asarray(boxes, np.float64).reshape(-1, 4).copy()
    s = np.asarray(scores, np.float32).reshape(-1)
    if view.mirrored:
        b[:, [0, 2]] = 1.0 - b[:, [2, 0]]
    left, top, right, bottom = _inner_sides(view)
    keep = np.ones(len(b), bool)
    if left:
        keep &= b[:, 0] > EDGE
    if top:
        keep &= b[:, 1] > EDGE
    if right:
        keep &= b[:, 2] < 1.0 - EDGE
    if bottom:
        keep &= b[:, 3] < 1.0 - EDGE
    b, s = b[keep], s[keep]
    b[:, [0, 2]] = view.x0 + b[:, [0, 2]] * view.w
    b[:, [1, 3]] = view.y0 + b[:, [1, 3]] * view.h
    return b, s


def sees_whole(view: View, box: np.ndarray) -> bool:
    """Whether ``box`` (image fractions) lies inside the view's region, clear of its inner sides."""
    left, top, right, bottom = _inner_sides(view)
    return ((not left or box[0] > view.x0 + EDGE * view.w) and (not top or box[1] > view.y0 + EDGE * view.h)
            and (not right or box[2] < view.x0 + (1.0 - EDGE) * view.w)
            and (not bottom or box[3] < view.y0 + (1.0 - EDGE) * view.h))


def fuse(per_view: Sequence[tuple[np.ndarray, np.ndarray]], views: Sequence[View],
         iou: float) -> tuple[np.ndarray, np.ndarray]:
    """Weighted box fusion of the views' boxes (image fractions), as the module docstring says.
    Returns boxes (K, 4) float32 and scores (K,) float32, best score first."""
    if len(per_view) != len(views):
        raise ValueError(f"fuse: {len(per_view)} sets of boxes for {len(views)} views")
    boxes = np.concatenate([np.asarray(b, np.float64).reshape(-1, 4) for b, _ in per_view])
    scores = np.concatenate([np.asarray(s, np.float64).reshape(-1) for _, s in per_view])
    which = np.concatenate([np.full(len(s), j) for j, (_, s) in enumerate(per_view)]).astype(np.int64)
    if len(scores) == 0:
        return np.zeros((0, 4), np.float32), np.zeros(0, np.float32)
    fused = np.zeros((len(scores), 4))
    weight = np.zeros(len(scores))
    weighted = np.zeros((len(scores), 4))
    best = np.zeros((len(scores), len(views)))  # per cluster, each view's best score
    n = 0
    for k in np.argsort(-scores, kind="stable"):
        c = -1
        if n:
            overlap = layout.iou_one(boxes[k], fused[:n])
            c = int(np.argmax(overlap)) if overlap.max() > iou else -1
        if c < 0:
            c = n
            n += 1
        weighted[c] += scores[k] * boxes[k]
        weight[c] += scores[k]
        fused[c] = weighted[c] / weight[c]
        best[c, which[k]] = max(best[c, which[k]], scores[k])
    out_boxes = fused[:n]
    seen_by = np.array([sum(sees_whole(v, b) for v in views) for b in out_boxes])
    found_by = np.count_nonzero(best[:n] > 0, axis=1)
    out_scores = best[:n].sum(axis=1) / np.maximum(seen_by, found_by)
    order = np.argsort(-out_scores, kind="stable")
    return out_boxes[order].astype(np.float32), out_scores[order].astype(np.float32)


def suppress(boxes: np.ndarray, scores: np.ndarray, iou: float, soft_sigma: float,
             score_threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """Non-maximum suppression at ``iou``, or soft-NMS with ``soft_sigma`` when it is above 0, then
    the boxes scoring at least ``score_threshold``."""
    if soft_sigma > 0:
        return layout.soft_nms(boxes, scores, soft_sigma, score_threshold)
    keep = layout.nms(boxes, scores, iou)
    boxes, scores = boxes[keep], scores[keep]
    good = scores >= score_threshold
    return boxes[good], scores[good]


def detect(run: Callable[[np.ndarray], np.ndarray] | None, color: np.ndarray, views: Sequence[View],
           score_threshold: float, iou: float, floor: float = 0.05, soft_sigma: float = 0.0,
           infer: Callable[[np.ndarray, float], tuple[np.ndarray, np.ndarray]] | None = None
           ) -> tuple[np.ndarray, np.ndarray]:
    """People in ``color``: boxes (K, 4) as fractions of the image and scores, after fusion and
    non-maximum suppression at ``iou`` (soft-NMS with ``soft_sigma`` when it is above 0), at least
    ``score_threshold``. ``run`` maps the shipped network's input image to its raw (5, GRID_H,
    GRID_W) output; or ``infer`` maps an image region and a score floor to boxes (fractions of the
    region) and scores, for a model of another layout (dodt.learned.yolo). One whole, unmirrored
    view is the plain decode and suppression; several views' boxes from ``floor`` up are fused
    first."""
    if infer is None:
        def infer(region, thr):
            return layout.decode(run(layout.resize_for_network(region)), thr)
    views = tuple(views)
    if len(views) == 1 and views[0].is_whole and not views[0].mirrored:
        boxes, scores = infer(color, score_threshold)
        return suppress(boxes, scores, iou, soft_sigma, score_threshold)
    per_view = [to_image(*infer(view_region(color, v), floor), v) for v in views]
    boxes, scores = fuse(per_view, views, iou)
    return suppress(boxes, scores, iou, soft_sigma, score_threshold)
