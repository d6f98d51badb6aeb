"""Track management: prediction, association, Kalman updates, coasting, identification.

Each frame: every track is predicted to the frame's time; tracks and detections are associated
(dodt.association); a matched track is updated with its detection (position measured, velocity
and acceleration as pseudo-measurements over up to ``averaging_frames`` frames of detection
history, paper eq. for V_t and A_t); an unmatched track coasts on its prediction for up to
``coast_time`` seconds (the paper drops it at once) and keeps its id if its obstacle comes
back; unmatched detections start tracks. Then each track is identified static or dynamic.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from dodt.association import TrackView, assign, features, similarity_matrix
from dodt.config import DODTConfig
from dodt.detection import Detection
from dodt.frames import CameraIntrinsics
from dodt.identification import decide, is_candidate, size_ok, vote
from dodt.kalman import KalmanFilter
from dodt.result import TrackedObstacle


@dataclass
class _Observation:
    seq: int
    stamp: float
    center: np.ndarray
    velocity: np.ndarray  # pseudo-measured velocity at this observation


class Track:
    def __init__(self, tid: int, det: Detection, seq: int, stamp: float, cfg: DODTConfig):
        self.id = tid
        self.cfg = cfg
        self.kf = KalmanFilter(cfg.kalman, det.center)
        self.born = stamp
        self.last_seen = stamp
        self.z = float(det.center[2])
        self.size = det.size.copy()
        self.count, self.spread = features(det)
        self.observations: deque[_Observation] = deque(maxlen=cfg.kalman.averaging_frames + 1)
        self.observations.append(_Observation(seq, stamp, det.center.copy(), np.zeros(2)))
        self.clouds: deque[tuple[int, float, np.ndarray]] = deque(maxlen=cfg.identification.frame_skip + 1)
        self.clouds.append((seq, stamp, det.points))
        self.history: deque[tuple[float, float, float, float]] = deque(maxlen=cfg.track.history)
        self.history.append((stamp, float(det.center[0]), float(det.center[1]), self.z))
        self.n_detections = 1
        self.size_stable = 0
        self.candidates: deque[bool] = deque(maxlen=cfg.identification.force_dynamic_window)
        self.dynamic_history: deque[bool] = deque(maxlen=cfg.identification.force_dynamic_window)
        self.dynamic = False
        self.is_person = det.is_person
        self.coasting = False

    def view(self) -> TrackView:
        c = np.array([self.kf.position[0], self.kf.position[1], self.z])
        return TrackView(center=c, size=self.size, count=self.count, spread=self.spread,
                         position_variance=self.kf.position_variance)

    def update(self, det: Detection, seq: int, stamp: float) -> None:
        k = self.cfg.kalman
        obs = list(self.observations)
        prev = obs[max(0, len(obs) - k.averaging_frames)]  # up to averaging_frames back
        dt = stamp - prev.stamp
        if dt > 1e-6:
            v = (det.center[:2] - prev.center[:2]) / dt
            a = (v - prev.velocity) / dt
        else:
            v, a = np.zeros(2), np.zeros(2)
        if len(obs) == 1:  # one earlier observation: no velocity estimate to difference yet
            a = np.zeros(2)
        self.kf.update(np.array([det.center[0], det.center[1], v[0], v[1], a[0], a[1]]))
        self.observations.append(_Observation(seq, stamp, det.center.copy(), v))
        self.z = float(det.center[2])
        # The reference code's size freezing: a stable box keeps its size.
        change = np.abs(det.size - self.size) / np.maximum(self.size, 1e-3)
        self.size_stable = self.size_stable + 1 if np.all(change <= self.cfg.track.fix_size_change) else 0
        if self.size_stable < self.cfg.track.fix_size_frames:
            self.size = det.size.copy()
        self.count, self.spread = features(det)
        self.clouds.append((seq, stamp, det.points))
        self.last_seen = stamp
        self.n_detections += 1
        self.is_person = self.is_person or det.is_person
        self.coasting = False

    def identify(self, seq: int, poses: dict, K: CameraIntrinsics, max_depth: float) -> None:
        cfg = self.cfg.identification
        if self.is_person:
            cand = True
        elif self.coasting:
            self.dynamic_history.append(self.dynamic)
            return  # no new points: the label stays
        else:
            speed = float(np.linalg.norm(self.kf.velocity))
            cur_seq, cur_t, cur_pts = self.clouds[-1]
            # the cloud from k frames back, or the oldest one kept since then
            old = [c for c in self.clouds if cur_seq - cfg.frame_skip <= c[0] < cur_seq]
            votes, valid, skipped = 0, 0, len(cur_pts)
            if old and cfg.method != "velocity":
                o_seq, o_t, o_pts = old[0]
                T_then = poses.get(o_seq)
                center_then = np.mean(o_pts, axis=0) if len(o_pts) else None
                if T_then is not None and center_then is not None:
                    v_box = (np.mean(cur_pts, axis=0) - center_then) / max(cur_t - o_t, 1e-6) if len(cur_pts) else np.zeros(3)
                    votes, valid, skipped = vote(cur_pts, o_pts, cur_t - o_t, v_box, T_then, K, max_depth, cfg)
            cand = is_candidate(speed, votes, valid, skipped, cfg) and size_ok(self.size, cfg)
        self.candidates.append(cand)
        self.dynamic = bool(self.is_person or decide(list(self.candidates), list(self.dynamic_history), cfg))
        self.dynamic_history.append(self.dynamic)

    def output(self, stamp: float) -> TrackedObstacle:
        h = [e for e in self.history if e[0] >= stamp - self.cfg.track.output_history]
        return TrackedObstacle(
            id=self.id, center=np.array([self.kf.position[0], self.kf.position[1], self.z]), size=self.size.copy(),
            velocity=np.array([self.kf.velocity[0], self.kf.velocity[1], 0.0]),
            acceleration=np.array([self.kf.acceleration[0], self.kf.acceleration[1], 0.0]),
            dynamic=self.dynamic, coasting=self.coasting, age=stamp - self.born,
            history=np.array(h, float).reshape(-1, 4), is_person=self.is_person,
            position_std=float(np.sqrt(self.kf.position_variance)))


class Tracker:
    def __init__(self, cfg: DODTConfig):
        self.cfg = cfg
        self.tracks: list[Track] = []
        self._next_id = 1

    def reset(self) -> None:
        self.tracks = []

    def predict(self, dt: float) -> None:
        for t in self.tracks:
            t.kf.predict(dt)

    def associate(self, dets: list[Detection], camera: np.ndarray) -> list[tuple[int, int]]:
        scores, thr = similarity_matrix([t.view() for t in self.tracks], dets, self.cfg.association, camera)
        return assign(scores, thr)

    def correct(self, dets: list[Detection], pairs: list[tuple[int, int]], seq: int, stamp: float) -> None:
        matched_t = {t for t, _ in pairs}
        matched_d = {d for _, d in pairs}
        for ti, di in pairs:
            self.tracks[ti].update(dets[di], seq, stamp)
        survivors = []
        for i, tr in enumerate(self.tracks):
            if i not in matched_t:
                if stamp - tr.last_seen > self.cfg.track.coast_time:
                    continue  # lost for too long
                tr.coasting = True
            survivors.append(tr)
            tr.history.append((stamp, float(tr.kf.position[0]), float(tr.kf.position[1]), tr.z))
        for di, det in enumerate(dets):
            if di not in matched_d:
                survivors.append(Track(self._next_id, det, seq, stamp, self.cfg))
                self._next_id += 1
        self.tracks = survivors
