"""Learned person boxes joined to the ensemble's boxes, by the reference code's rules (ref section 4,
step 2), and the module the pipeline calls.

- A learned box that is the mutual best match of a fused box (both IoUs above the threshold)
  marks it a person (dynamic in identification once the track's person boxes recur); the box
  stays the geometric one, measured from depth (``match_box = "union"``: the reference's union).
  Ours: only when their centres lie within ``person_match_gate`` of each other and the fused
  box is no taller than ``person_box_max_height``; otherwise the fused box is the wall or
  obstacle behind the person and stays as it is. And where the fused box is lower than
  ``fragment_height`` times the learned box, it is a fragment of the person (the part within the
  depth range, or in view): the union of the two replaces it.
- A learned box that overlaps no fused box is added when it is at least ``overwrite_distance``
  from the camera: there the depth is too sparse for the geometric detectors, which is what the
  module is for; closer, the geometric detectors should have seen it, and it is taken for a
  learned detector's mistake. Ours: also dropped when it lies within ``duplicate_gate`` of a
  fused box or of a learned box added before it, a second, misplaced view of an obstacle
  already there.
- A learned box that overlaps fused boxes without being a mutual best match is dropped.
"""
from __future__ import annotations

import time

import numpy as np

from dodt.config import LearnedConfig
from dodt.detection import Detection
from dodt.ensemble import mutual_best_pairs
from dodt.geometry import iou_matrix
from dodt.learned.lifting import lift_boxes


def fuse_learned(fused: list[Detection], learned: list[Detection], camera: np.ndarray,
                 cfg: LearnedConfig) -> list[Detection]:
    """The ensemble's boxes with the learned boxes joined in (a new list; inputs are not changed)."""
    out = list(fused)
    if not learned:
        return out
    if fused:
        iou = iou_matrix([d.center for d in learned], [d.size for d in learned],
                         [d.center for d in fused], [d.size for d in fused])
    else:
        iou = np.zeros((len(learned), 0))
    for i, j in mutual_best_pairs(iou, cfg.iou_threshold):
        a, b = learned[i], fused[j]
        if cfg.person_match_gate > 0 and float(np.hypot(*(a.center[:2] - b.center[:2]))) > cfg.person_match_gate:
            continue
        if cfg.person_box_max_height > 0 and float(b.size[2]) > cfg.person_box_max_height:
            continue
        fragment = float(b.size[2]) < cfg.fragment_height * float(a.size[2])
        if cfg.match_box == "union" or fragment:
            lo, hi = np.minimum(a.lower, b.lower), np.maximum(a.upper, b.upper)
            merged = Detection.from_bounds(lo, hi, source="ensemble+learned")  # no points: the pipeline adds them
        else:
            merged = Detection(center=b.center.copy(), size=b.size.copy(), source="ensemble+learned", points=b.points)
        merged.is_person = True
        out[j] = merged
    for i, d in enumerate(learned):
        overlaps = iou.shape[1] > 0 and bool(np.any(iou[i] > 0))
        if overlaps or np.linalg.norm(d.center - camera) < cfg.overwrite_distance:
            continue
        # against the fused boxes and the learned boxes added before it (best score first: two
        # 2D boxes of one far person that both passed NMS lift to nearly the same place)
        if min((_gap_xy(d.center, f) for f in out), default=np.inf) < cfg.duplicate_gate:
            continue
        out.append(d)
    return out


def _gap_xy(point: np.ndarray, box: Detection) -> float:
    """Horizontal distance from a point to a box (0 inside it)."""
    d = np.maximum(np.abs(point[:2] - box.center[:2]) - box.size[:2] / 2, 0.0)
    return float(np.hypot(d[0], d[1]))


class YoloMAD:
    """The pipeline's learned module: (frame, depth_m, ensemble boxes) -> boxes with people joined in.

    Keeps the last frame's 2D boxes, 3D boxes and timings for benchmarks and viewers.
    """

    def __init__(self, cfg: LearnedConfig, detector=None):
        from dodt.learned.model import PersonDetector2D

        self.cfg = cfg
        self.detector = detector or PersonDetector2D(
            cfg.model or None, cfg.score_threshold, cfg.nms_iou, cfg.threads, views=cfg.views,
            soft_sigma=cfg.soft_nms_sigma, layout=cfg.layout, person_class=cfg.person_class,
            input_size=cfg.input_size, channels=cfg.channels, pixel_scale=cfg.pixel_scale, letterbox=cfg.letterbox)
        self.frames_without_color = 0
        self._keep(np.zeros((0, 4), np.float32), np.zeros(0, np.float32), [], 0.0, 0.0)

    def _keep(self, boxes_2d, scores, learned: list[Detection], inference_ms: float, lifting_ms: float) -> None:
        self.last_boxes_2d, self.last_scores, self.last_3d = boxes_2d, scores, learned
        self.last_timings_ms = {"inference": inference_ms, "lifting": lifting_ms}

    def __call__(self, frame, depth_m: np.ndarray, fused: list[Detection]) -> list[Detection]:
        if frame.color is None:  # a depth-only frame: the module has nothing to look at
            self.frames_without_color += 1
            self._keep(np.zeros((0, 4), np.float32), np.zeros(0, np.float32), [], 0.0, 0.0)
            return list(fused)
        t0 = time.perf_counter()
        boxes, scores = self.detector(frame.color)
        t1 = time.perf_counter()
        T = np.asarray(frame.T_world_camera, dtype=np.float64)
        lifted = lift_boxes(depth_m, boxes, frame.intrinsics, T, self.cfg)
        learned = [d for d in lifted if d is not None]
        out = fuse_learned(fused, learned, T[:3, 3], self.cfg)
        t2 = time.perf_counter()
        self._keep(boxes, scores, learned, (t1 - t0) * 1e3, (t2 - t1) * 1e3)
        return out
