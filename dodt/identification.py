"""Dynamic obstacle identification (paper Sec. III-D; ref classificationCB).

Per track and frame, a candidate test:
1. the filtered horizontal speed must reach T_vel;
2. point voting: each current point is matched to its nearest neighbour in the cloud k frames
   back (the whole filtered cloud: see ``vote``); its velocity (horizontal) votes dynamic when above T_vote. Points are left out
   of the vote when their velocity points against the box's (angle >= 90 deg, an invalid match)
   or when they were outside the camera's view k frames back (newly seen parts of an obstacle,
   the paper's Fig. 8), or had no plausible match back then (ours: nearest neighbour farther
   than a person walks, or the point was near the end of the depth range); too many left out
   and the frame says nothing;
3. candidate if votes / valid points >= T_ratio.
A track is dynamic once every frame within the last ``consistency_span`` seconds was a candidate,
and stays dynamic while at least ``force_dynamic_fraction`` of its frames over the last
``force_dynamic_span`` were dynamic (windows of time: dodt.windows). A
track flagged a person by a learned detector is dynamic at once, for as long as the flag lasts:
the flag does not enter the candidates or that history (ours), so it cannot lock a standing
obstacle dynamic.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from dodt.config import IdentificationConfig
from dodt.frames import CameraIntrinsics
from dodt.geometry import in_field_of_view
from dodt.windows import FrameClock


def match_reach(dt: float, cfg: IdentificationConfig) -> float:
    """The farthest a point's correspondence k frames back can lie [m]: as far as anything
    walks in dt, plus a voxel."""
    return cfg.max_point_speed * dt + 0.1


def vote(points_now: np.ndarray, cloud_then, dt: float, v_box: np.ndarray, T_world_camera_then,
         K: CameraIntrinsics, max_depth: float, cfg: IdentificationConfig) -> tuple[int, int, int]:
    """(votes, valid, skipped) of the point voting.

    ``cloud_then`` is a k-d tree (or an (M, 3) array) of the whole filtered cloud k frames back,
    or of the part of it within ``match_reach`` of the points (the matches are the same).
    Matching against the whole cloud, not only the track's own points back then, keeps a
    static obstacle static when its box grows (more of it seen, or split from a neighbour):
    its points find their unmoved twins wherever they were.
    """
    n = len(points_now)
    if not isinstance(cloud_then, cKDTree):
        cloud_then = cKDTree(np.asarray(cloud_then).reshape(-1, 3)) if len(cloud_then) else None
    if n == 0 or cloud_then is None or dt <= 0:
        return 0, 0, n
    # In view back then, and not at the edge of the depth range, where the filtered cloud thins out.
    seen = in_field_of_view(points_now, T_world_camera_then, K, max_depth - cfg.range_margin, margin_px=cfg.fov_margin_px)
    # A nearest neighbour farther than anything walks in dt is no correspondence: that surface
    # was not in the cloud back then (occluded, too sparse, out of range). The search stops at
    # that bound (much faster); beyond it the tree answers distance inf and index M.
    reach = match_reach(dt, cfg)
    dist, idx = cloud_then.query(points_now, distance_upper_bound=reach * (1 + 1e-9))
    seen &= dist <= reach
    v = (points_now - cloud_then.data[np.minimum(idx, cloud_then.n - 1)])[:, :2] / dt
    vb = v_box[:2]
    agree = (v @ vb) > 0 if np.linalg.norm(vb) > 1e-9 else np.ones(n, bool)
    valid = seen & agree
    votes = int(np.sum(np.linalg.norm(v[valid], axis=1) > cfg.vote_velocity))
    n_valid = int(valid.sum())
    return votes, n_valid, n - n_valid


def is_candidate(speed: float, votes: int, valid: int, skipped: int, cfg: IdentificationConfig) -> bool:
    if speed < cfg.velocity_threshold:
        return False
    if cfg.method == "velocity":
        return True
    if valid == 0 or skipped / max(valid, 1) >= cfg.max_skip_ratio:
        return False
    return votes / valid >= cfg.vote_ratio


def size_ok(size: np.ndarray, cfg: IdentificationConfig) -> bool:
    if not cfg.constrain_size:
        return True
    return bool(np.all(np.abs(np.asarray(size) - np.asarray(cfg.target_size)) <= cfg.target_size_tolerance))


def decide(candidates: list[bool], dynamic_history: list[bool], cfg: IdentificationConfig,
           clock: FrameClock | None = None) -> bool:
    """Consistency over frames, with the reference code's hysteresis, and ours: a dynamic track
    turns static only when no frame over ``release_span`` was a candidate.

    candidates: of the frames with a detection, up to this one; dynamic_history: the labels of
    the frames before this one. The spans are counted in frames at ``clock``'s frame period
    (default: the reference rate)."""
    clock = clock or FrameClock()
    n = clock.frames_within(cfg.consistency_span)
    if len(candidates) >= n and all(candidates[-n:]):
        return True
    if cfg.release_span is not None and dynamic_history and dynamic_history[-1] and \
            any(candidates[-(clock.intervals(cfg.release_span) + 1):]):
        return True
    if cfg.force_dynamic_span is None:
        return False
    w = clock.intervals(cfg.force_dynamic_span) + 1
    return len(dynamic_history) >= w and sum(dynamic_history[-w:]) >= cfg.force_dynamic_fraction * w - 1e-9
