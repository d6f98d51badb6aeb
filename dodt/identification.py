"""Dynamic obstacle identification (paper Sec. III-D; ref classificationCB).

Per track and frame, a candidate test:
1. the filtered horizontal speed must reach T_vel;
2. point voting: each current point is matched to its nearest neighbour in the track's cloud k
   frames back; its velocity (horizontal) votes dynamic when above T_vote. Points are left out
   of the vote when their velocity points against the box's (angle >= 90 deg, an invalid match)
   or when they were outside the camera's view k frames back (newly seen parts of an obstacle,
   the paper's Fig. 8); too many left out and the frame says nothing;
3. candidate if votes / valid points >= T_ratio.
A track is dynamic once the last ``consistency`` frames were candidates, and stays dynamic while
at least ``force_dynamic_count`` of the last ``force_dynamic_window`` frames were dynamic. A
track flagged a person by a learned detector is dynamic at once.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from dodt.config import IdentificationConfig
from dodt.frames import CameraIntrinsics
from dodt.geometry import in_field_of_view


def vote(points_now: np.ndarray, points_then: np.ndarray, dt: float, v_box: np.ndarray, T_world_camera_then,
         K: CameraIntrinsics, max_depth: float, cfg: IdentificationConfig) -> tuple[int, int, int]:
    """(votes, valid, skipped) of the point voting."""
    n = len(points_now)
    if n == 0 or len(points_then) == 0 or dt <= 0:
        return 0, 0, n
    seen = in_field_of_view(points_now, T_world_camera_then, K, max_depth, margin_px=2.0)
    _, idx = cKDTree(points_then).query(points_now)
    v = (points_now - points_then[idx])[:, :2] / dt
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


def decide(candidates: list[bool], dynamic_history: list[bool], cfg: IdentificationConfig) -> bool:
    """Consistency over frames, with the reference code's hysteresis."""
    n = cfg.consistency
    if len(candidates) >= n and all(candidates[-n:]):
        return True
    window = dynamic_history[-cfg.force_dynamic_window:]
    return len(dynamic_history) >= cfg.force_dynamic_window and sum(window) >= cfg.force_dynamic_count
