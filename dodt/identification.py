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
and stays dynamic while at least ``force_dynamic_fraction`` of its last frames with a detection, as
many as ``force_dynamic_span`` holds at the measuring sensor's rate, were dynamic (windows of time:
dodt.windows; frames it coasted through hold its label and are not counted). A
track flagged a person by a learned detector is dynamic at once, for as long as the flag lasts:
the flag does not enter the candidates or that history (ours), so it cannot lock a standing
obstacle dynamic.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from dodt.config import IdentificationConfig
from dodt.frames import CameraIntrinsics
from dodt.geometry import in_field_of_view
from dodt.windows import FrameClock


def match_reach(dt: float, cfg: IdentificationConfig) -> float:
    """The farthest a point's correspondence k frames back can lie [m]: as far as anything
    walks in dt, plus a voxel."""
    return cfg.max_point_speed * dt + 0.1


_BRUTE_FORCE_PAIRS = 20000  # vote: below this many (point, cloud point) pairs, no k-d tree


@njit(cache=True, nogil=True)
def _nearest(points, data, reach):
    """Each point's nearest neighbour in data (M, 3) float64: (distance, index, tie). The squared
    distance is summed over x, y, z in that order from the float64 coordinates, as
    scipy's cKDTree does, so the distances are the tree's. Beyond ``reach`` the answer is
    (inf, M); tie: a point within reach has two nearest neighbours at the same distance."""
    n = points.shape[0]
    m = data.shape[0]
    dist = np.empty(n)
    idx = np.empty(n, np.int64)
    tie = False
    for i in range(n):
        x0 = np.float64(points[i, 0])
        x1 = np.float64(points[i, 1])
        x2 = np.float64(points[i, 2])
        best = np.inf
        best_j = m
        tied = False
        for j in range(m):
            d0 = x0 - data[j, 0]
            d1 = x1 - data[j, 1]
            d2 = x2 - data[j, 2]
            s = d0 * d0 + d1 * d1 + d2 * d2
            if s < best:
                best = s
                best_j = j
                tied = False
            elif s == best:
                tied = True
        d = np.sqrt(best)
        if d <= reach:
            dist[i] = d
            idx[i] = best_j
            tie = tie or tied
        else:
            dist[i] = np.inf
            idx[i] = m
    return dist, idx, tie


def vote(points_now: np.ndarray, cloud_then, dt: float, v_box: np.ndarray, T_world_camera_then,
         K: CameraIntrinsics, max_depth: float, cfg: IdentificationConfig,
         seen_then: np.ndarray | None = None) -> tuple[int, int, int]:
    """(votes, valid, skipped) of the point voting.

    ``cloud_then`` is a k-d tree (or an (M, 3) array) of the whole filtered cloud k frames back,
    or of the part of it within ``match_reach`` of the points (the matches are the same).
    Matching against the whole cloud, not only the track's own points back then, keeps a
    static obstacle static when its box grows (more of it seen, or split from a neighbour):
    its points find their unmoved twins wherever they were. ``K`` None: the cloud is an all-round
    LiDAR's (dodt.lidar_detector), in whose view every point was. ``seen_then`` (n,) bool: which points
    could have been seen back then (``faced_then``); the others are skipped.
    """
    n = len(points_now)
    tree = cloud_then if isinstance(cloud_then, cKDTree) else None
    if tree is not None:
        data = tree.data
    else:
        data = np.ascontiguousarray(np.asarray(cloud_then).reshape(-1, 3), dtype=np.float64)
        if not len(data):
            data = None
    if n == 0 or data is None or dt <= 0:
        return 0, 0, n
    # In view back then, and not at the edge of the depth range, where the filtered cloud thins out (K None:
    # an all-round sensor's cloud, cropped to its range by its detector: every point was in view).
    if K is None:
        seen = np.ones(n, bool)
    else:
        seen = in_field_of_view(points_now, T_world_camera_then, K, max_depth - cfg.range_margin,
                                margin_px=cfg.fov_margin_px)
    if seen_then is not None:
        seen &= np.asarray(seen_then, bool)
    # A nearest neighbour farther than anything walks in dt is no correspondence: that surface
    # was not in the cloud back then (occluded, too sparse, out of range). The search stops at
    # that bound (much faster); beyond it the tree answers distance inf and index M.
    reach = match_reach(dt, cfg)
    dist = idx = None
    if tree is None and n * len(data) <= _BRUTE_FORCE_PAIRS:
        # few pairs: every distance, as the tree computes it, instead of building the tree; a tie
        # for the nearest (which the tree may break otherwise) sends the query to the tree
        dist, idx, tie = _nearest(np.ascontiguousarray(points_now), data, reach)
        if tie:
            dist = idx = None
    if dist is None:
        if tree is None:
            tree = cKDTree(data)
        dist, idx = tree.query(points_now, distance_upper_bound=reach * (1 + 1e-9))
    seen &= dist <= reach
    v = (points_now - data[np.minimum(idx, len(data) - 1)])[:, :2] / dt
    vb = v_box[:2]
    agree = (v @ vb) > 0 if np.linalg.norm(vb) > 1e-9 else np.ones(n, bool)
    valid = seen & agree
    votes = int(np.sum(np.linalg.norm(v[valid], axis=1) > cfg.vote_velocity))
    n_valid = int(valid.sum())
    return votes, n_valid, n - n_valid


def faced_then(points: np.ndarray, origin_now, origins_then, cos_min: float | None, k: int = 8) -> np.ndarray | None:
    """(n,) bool: whether each point's surface faced at least one of ``origins_then`` (the sensor's earlier
    positions) by a cosine of at least ``cos_min``. A point's normal is the least-spread axis of its ``k``
    nearest points of ``points``, turned towards ``origin_now`` (the surface is seen from there). None when
    ``cos_min`` is None or there are too few points for normals (every point may vote)."""
    n = len(points)
    if cos_min is None or n < 3 or not len(origins_then):
        return None
    P = np.asarray(points, dtype=np.float64)
    k = min(k, n)
    _, idx = cKDTree(P).query(P, k=k)
    nb = P[idx] - P[idx].mean(axis=1, keepdims=True)  # (n, k, 3)
    _, vecs = np.linalg.eigh(np.einsum("nki,nkj->nij", nb, nb))
    normal = vecs[:, :, 0]  # the eigenvector of the smallest eigenvalue
    to_now = np.asarray(origin_now, dtype=np.float64) - P
    normal *= np.where(np.einsum("ni,ni->n", normal, to_now) < 0, -1.0, 1.0)[:, None]
    faced = np.zeros(n, bool)
    for o in origins_then:
        to_then = np.asarray(o, dtype=np.float64) - P
        cos = np.einsum("ni,ni->n", normal, to_then) / np.maximum(np.linalg.norm(to_then, axis=1), 1e-9)
        faced |= cos >= cos_min
    return faced


class LidarCloud(NamedTuple):
    """One LiDAR scan's filtered cloud as the vote reads it back: the frame stamp it was fused at, the
    detector's filtered world points (dodt.lidar_detector), the scan's pose, and its lowest and highest
    rays' elevations [rad] in the sensor frame (None: not known)."""

    stamp: float
    points: np.ndarray
    T_world_sensor: np.ndarray
    elevation_min: float | None
    elevation_max: float | None = None

    @property
    def origin(self) -> np.ndarray:
        return self.T_world_sensor[:3, 3]


def in_lidar_field(points: np.ndarray, scans, min_range: float, margin: float) -> np.ndarray:
    """(n,) bool: whether each point lay, by ``margin`` m, inside the field of at least one of ``scans``
    (LidarCloud): above the scan's lowest ray, below its highest and beyond ``min_range`` (the detector's
    blind zone). A static box the sensor passes close by is below its lowest ray (-7 deg: 0.2 m under the
    sensor at 1.6 m) until the sensor is past it; its top face then comes into the field at once, points
    that were in no cloud back then, and would vote moving. (The detector's horizontal range is left out:
    what it cuts comes in a strip at a time, beside what the cloud held, and the points of a walker coming
    into it vote moving against its own nearer side, as they should.)"""
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    inside = np.zeros(len(P), bool)
    for s in scans:
        T = np.asarray(s.T_world_sensor, dtype=np.float64)
        d = P - T[:3, 3]
        ok = np.linalg.norm(d, axis=1) >= min_range + margin
        if s.elevation_min is not None or s.elevation_max is not None:
            q = d @ T[:3, :3]  # the sensor frame
            h = np.hypot(q[:, 0], q[:, 1])
            if s.elevation_min is not None:
                ok &= q[:, 2] - h * np.tan(s.elevation_min) >= margin
            if s.elevation_max is not None:  # a sensor under the body: what rises above its highest ray
                ok &= h * np.tan(s.elevation_max) - q[:, 2] >= margin
        inside |= ok
    return inside


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


def decide(candidates: list[bool], dynamic_history, cfg: IdentificationConfig,
           clock: FrameClock | None = None, lock_clock: FrameClock | None = None, lock: bool = True) -> bool:
    """Consistency over frames, with the reference code's hysteresis, and ours: a dynamic track
    turns static only when no frame over ``release_span`` was a candidate.

    candidates: of the frames with a detection, up to this one; dynamic_history: (label, seconds) of
    the frames with a detection before this one, oldest first: each frame's label and the time it
    stands for, the period of the sensor that measured it (a coasting track's label is held, not
    evidence: counted, the frames a dynamic track coasted through locked it). The spans are counted
    in frames at ``clock``'s frame period (default: the reference rate). The force-dynamic lock reads
    the newest labels that stand for its window, as many frames as ``force_dynamic_span`` holds at
    ``lock_clock``'s period (the sensor that measures the track now, a LiDAR's scans for a track its
    boxes update; default ``clock``): it locks once the history fills the window and the dynamic
    labels stand for ``force_dynamic_fraction`` of it. At one rate that is the reference code's count
    (10 of the last 30 frames at 30 Hz); a track measured by a camera and a LiDAR in turn counts
    each label for its sensor's period. ``lock`` False: the force-dynamic lock does not hold this frame
    (the caller's reason: dodt.tracker.Track._decide)."""
    clock = clock or FrameClock()
    n = clock.frames_within(cfg.consistency_span)
    if len(candidates) >= n and all(candidates[-n:]):
        return True
    if cfg.release_span is not None and dynamic_history and dynamic_history[-1][0] and \
            any(candidates[-(clock.intervals(cfg.release_span) + 1):]):
        return True
    if cfg.force_dynamic_span is None or not lock:
        return False
    window = lock_window(cfg.force_dynamic_span, lock_clock or clock)
    filled = dynamic = 0.0
    for label, seconds in reversed(dynamic_history):
        if filled >= window * (1.0 - 1e-9):
            break
        filled += seconds
        dynamic += seconds if label else 0.0
    return filled >= window * (1.0 - 1e-9) and dynamic >= cfg.force_dynamic_fraction * window * (1.0 - 1e-9)


def lock_window(span: float, clock: FrameClock) -> float:
    """The force-dynamic window [s]: as many frames as ``span`` holds at ``clock``'s period, each standing
    for one period."""
    return (clock.intervals(span) + 1) * clock.period
