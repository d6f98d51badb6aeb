"""2D person box + aligned depth -> 3D world box, by the median absolute deviation (paper Sec. III-B).

The paper: the depths inside the box are the person's and whatever is behind or in front of it;
d~ is their median, MAD = median |d - d~|, the person's depths are those within d~ +- n MAD
(n = 1.5, the reference code's value), from d_min to d_max, and the box is the 2D box's corners
back-projected at d~, as deep as d_max - d_min.

Ours, measured on our renders: a walking person fills about half of the box (background between
the legs and beside the torso), and the whole box's median lay 0.4-0.9 m behind people. So the
depths are read from the box's central part, where the torso is (``core_x``, ``core_y``; the
whole box when that holds too few valid depths), and d~ is their 30th percentile
(``depth_percentile``; 50 is the paper's median), which leans to the nearer surface, the person
before the background. The box is at least ``min_thickness`` deep and
centred ``center_behind_median`` behind d~ (a body seen from the front shows only its front).
Depths farther than a person of ``max_person_height`` showing as high as the 2D box could stand
are dropped first (the background past a narrow far person, whose edges the depth camera leaves
as holes), and a box whose d~ lies beyond ``max_lift_range`` is dropped (near the camera's range
limit the far half of the noisy depths is missing). The world box then passes the reference
code's size sanity rule: a dimension less than half or more than twice the person size is
replaced by it, and a replaced height stands on the floor.

People in front (ours, `lift_boxes`): a box overlapped by the box of a person nearer on the same
floor (`in_front`) reads no depth inside that box that is not farther than that person's own
depth range, so a person half hidden behind another is not lifted onto him.
"""
from __future__ import annotations

import numpy as np

from dodt.config import LearnedConfig
from dodt.detection import Detection
from dodt.frames import CameraIntrinsics


def mad_depth_range(depths: np.ndarray, n: float, percentile: float = 50.0) -> tuple[float, float, float] | None:
    """(d~, d_min, d_max) of the depths within d~ +- n MAD, d~ their median (or another
    ``percentile``), or None for no depths."""
    d = np.asarray(depths, dtype=np.float64).ravel()
    if d.size == 0:
        return None
    med = float(np.median(d)) if percentile == 50.0 else float(np.percentile(d, percentile))
    mad = float(np.median(np.abs(d - med)))
    inside = d[np.abs(d - med) <= n * mad]
    return med, float(inside.min()), float(inside.max())


def core_box(box_px, cfg: LearnedConfig) -> tuple[float, float, float, float]:
    """The central part of a person box where the torso is (fractions ``core_x``, ``core_y``)."""
    x1, y1, x2, y2 = (float(v) for v in box_px)
    w, h = x2 - x1, y2 - y1
    return (x1 + cfg.core_x[0] * w, y1 + cfg.core_y[0] * h, x1 + cfg.core_x[1] * w, y1 + cfg.core_y[1] * h)


def box_depths(depth_m: np.ndarray, box_px, cfg: LearnedConfig, hidden=()) -> np.ndarray:
    """The valid depths inside a 2D box, less ``margin_px`` on each side, less those inside each
    ``hidden`` (x1, y1, x2, y2, d) box (pixels) that are not farther than d."""
    h, w = depth_m.shape
    x1, y1, x2, y2 = box_px
    c0 = int(np.clip(np.floor(x1) + cfg.margin_px, 0, w))
    c1 = int(np.clip(np.ceil(x2) - cfg.margin_px, 0, w))
    r0 = int(np.clip(np.floor(y1) + cfg.margin_px, 0, h))
    r1 = int(np.clip(np.ceil(y2) - cfg.margin_px, 0, h))
    patch = depth_m[r0:r1, c0:c1]
    keep = (patch >= cfg.depth_min) & (patch <= cfg.depth_max)
    for hx1, hy1, hx2, hy2, d in hidden:
        a0, a1 = int(np.clip(np.floor(hx1), c0, c1)) - c0, int(np.clip(np.ceil(hx2), c0, c1)) - c0
        b0, b1 = int(np.clip(np.floor(hy1), r0, r1)) - r0, int(np.clip(np.ceil(hy2), r0, r1)) - r0
        keep[b0:b1, a0:a1] &= patch[b0:b1, a0:a1] > d
    return patch[keep]


def in_front(box_px, other_px, margin: float) -> bool:
    """Whether ``other`` (pixels) is the box of a person in front of the one in ``box`` and covers
    part of it: the two overlap, ``other``'s bottom edge is lower and it is taller, each by
    ``margin`` times ``box``'s height (nearer on the same floor), and ``box`` reaches past one of
    its sides by ``margin`` of its width (a box within the other's sides is a part of that person)."""
    x1, y1, x2, y2 = (float(v) for v in box_px)
    ox1, oy1, ox2, oy2 = (float(v) for v in other_px)
    h, w = y2 - y1, x2 - x1
    overlap = min(x2, ox2) > max(x1, ox1) and min(y2, oy2) > max(y1, oy1)
    sticks_out = x1 < ox1 - margin * w or x2 > ox2 + margin * w
    return overlap and sticks_out and oy2 > y2 + margin * h and (oy2 - oy1) > (1.0 + margin) * h


def size_sanity(lo: np.ndarray, hi: np.ndarray, cfg: LearnedConfig) -> tuple[np.ndarray, np.ndarray]:
    """The reference code's rule on a world box, dimension by dimension."""
    center, size = (lo + hi) / 2, hi - lo
    person = np.asarray(cfg.person_size, dtype=np.float64)
    for k in range(3):
        ratio = size[k] / person[k]
        if ratio >= 2.0 or ratio <= 0.5:
            size[k] = person[k]
            if k == 2:
                center[2] = person[2] / 2
    return center - size / 2, center + size / 2


def farthest_person_depth(box_px, K: CameraIntrinsics, height: float) -> float:
    """The depth [m] beyond which a person ``height`` tall would show shorter than the box."""
    return K.fy * height / max(float(box_px[3]) - float(box_px[1]), 1.0)


def lift_boxes(depth_m: np.ndarray, boxes_px, K: CameraIntrinsics, T_world_camera: np.ndarray,
               cfg: LearnedConfig) -> list[Detection | None]:
    """`lift_box` for each of one image's person boxes. A box with people in front of him
    (`in_front`) reads no depth inside their boxes within their own depth range."""
    boxes = [tuple(float(v) for v in b) for b in boxes_px]
    ranges = [box_depth_range(depth_m, b, K, cfg) for b in boxes]
    out = []
    for i, b in enumerate(boxes):
        hidden = () if cfg.occluder_margin is None else tuple(
            (*o, ranges[j][2] + cfg.occluder_depth_margin) for j, o in enumerate(boxes)
            if j != i and ranges[j] is not None and in_front(b, o, cfg.occluder_margin))
        # a box with nobody in front keeps the range read above
        rng = box_depth_range(depth_m, b, K, cfg, hidden) if hidden else ranges[i]
        out.append(None if rng is None else box_at_range(b, rng, K, T_world_camera, cfg))
    return out


def box_depth_range(depth_m: np.ndarray, box_px, K: CameraIntrinsics, cfg: LearnedConfig,
                    hidden=()) -> tuple[float, float, float] | None:
    """(d~, d_min, d_max) of the person in a 2D box, or None (too few depths, or too far)."""
    depths = box_depths(depth_m, core_box(box_px, cfg), cfg, hidden)
    if depths.size < cfg.min_depth_pixels:
        depths = box_depths(depth_m, box_px, cfg, hidden)
    if cfg.max_person_height is not None:
        depths = depths[depths <= farthest_person_depth(box_px, K, cfg.max_person_height)]
    if depths.size < cfg.min_depth_pixels:
        return None
    med, d_min, d_max = mad_depth_range(depths, cfg.mad_n, cfg.depth_percentile)
    if cfg.max_lift_range is not None and med > cfg.max_lift_range:
        return None
    return med, d_min, d_max


def lift_box(depth_m: np.ndarray, box_px, K: CameraIntrinsics, T_world_camera: np.ndarray,
             cfg: LearnedConfig, hidden=()) -> Detection | None:
    """The 3D world box of one 2D person box, or None when the box holds too few valid depths
    (``hidden``: see `box_depths`)."""
    rng = box_depth_range(depth_m, box_px, K, cfg, hidden)
    return None if rng is None else box_at_range(box_px, rng, K, T_world_camera, cfg)


def box_at_range(box_px, rng: tuple[float, float, float], K: CameraIntrinsics, T_world_camera: np.ndarray,
                 cfg: LearnedConfig) -> Detection:
    """The 3D world box of a 2D person box whose depths give ``rng`` (d~, d_min, d_max)."""
    med, d_min, d_max = rng
    # The paper centres the box on the median plane; a body's visible surface lies in front of its
    # centre, so ours sits ``center_behind_median`` further back. Its depth is the MAD range's.
    mid = med + cfg.center_behind_median
    half = max(d_max - d_min, cfg.min_thickness) / 2
    x1, y1, x2, y2 = (float(v) for v in box_px)
    # Optical frame (x right, y down, z forward): the sides are the 2D corners at the median depth.
    (xa, ya, _), (xb, yb, _) = K.backproject(np.array([x1, x2]), np.array([y1, y2]), np.array([med, med]))
    corners = np.array([[x, y, z] for x in (xa, xb) for y in (ya, yb) for z in (mid - half, mid + half)])
    T = np.asarray(T_world_camera, dtype=np.float64)
    world = corners @ T[:3, :3].T + T[:3, 3]
    lo, hi = size_sanity(world.min(axis=0), world.max(axis=0), cfg)
    det = Detection.from_bounds(lo, hi, source="learned")
    det.is_person = True
    return det
