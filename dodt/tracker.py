"""Track management: prediction, association, Kalman updates, coasting, identification.

Each frame: every track is predicted to the frame's time; tracks and detections are associated
(dodt.association); a matched track is updated with its detection (position measured, velocity
and acceleration as pseudo-measurements over up to ``averaging_time`` seconds of detection
history, paper eq. for V_t and A_t); an unmatched track coasts on its prediction for up to
``coast_time`` seconds (the paper drops it at once) and keeps its id if its obstacle comes
back; unmatched detections start tracks. Then each track is identified static or dynamic.

Physical bounds (track.max_speed, track.jump_margin, track.camera_body_radius; ours): no filter
velocity exceeds a person's top speed, a prediction stays within that speed of where the track was
last measured, a detection farther from the track than a person could have moved re-initialises
it, and a coasting prediction passes neither through the camera's body nor through a wall of the
geofence.

Every window is a span of time (dodt.config's module docstring, dodt.windows).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace
from itertools import islice

import numpy as np
from numba import njit

from dodt.association import TrackView, assign, features, mean_columns, similarity_matrix
from dodt.config import DODTConfig
from dodt.detection import Detection
from dodt.frames import CameraIntrinsics, LidarScan
from dodt.geometry import column_bounds, crop_to_box, wrap_angle
from dodt.identification import (decide, faced_then, in_lidar_field, is_candidate, lock_window, match_reach,
                                 size_ok, vote)
from dodt.kalman import KalmanFilter
from dodt.learned.layout import iou_one
from dodt.result import TrackedObstacle
from dodt.windows import FrameClock, blend, keep_last


# times the measurement variance along the line of sight of a detection cut by the image's side
# (dodt.view_edge): its visible part's mean depth moves as more or less of it is in view
CUT_RANGE_NOISE = 5.0


@dataclass
class _Observation:
    seq: int
    stamp: float
    center: np.ndarray
    velocity: np.ndarray | None  # pseudo-measured velocity at this observation (None: none measured)
    lifted: bool = False  # measured on a learned box alone (its points: depths lifted from the box)
    sensor: str = ""  # the sensor of the detection ("": the first camera; dodt.detection.Detection.sensor)


def _anchor(det: Detection, source: str) -> np.ndarray:
    """The horizontal point the filter measures: the box centre, or the mean or median of the
    obstacle's points (steadier: swinging limbs move the box more than the body)."""
    if source in ("mean", "median") and len(det.points) >= 10:
        if source == "mean":
            return mean_columns(det.points, 2).astype(float)
        return np.median(det.points[:, :2], axis=0).astype(float)
    return det.center[:2].astype(float)


@njit(cache=True, nogil=True)
def _count_behind(depth, v0, v1, u0, u1, step, far):
    """(count of depth[v0:v1:step, u0:u1:step] > 0, count of those > far)."""
    n_valid = 0
    n_behind = 0
    for v in range(v0, min(v1, depth.shape[0]), step):
        for u in range(u0, min(u1, depth.shape[1]), step):
            d = depth[v, u]
            if d > 0:
                n_valid += 1
                if d > far:
                    n_behind += 1
    return n_valid, n_behind


class Track:
    def __init__(self, tid: int, det: Detection, seq: int, stamp: float, cfg: DODTConfig,
                 clock: FrameClock | None = None):
        self.id = tid
        self.cfg = cfg
        self.clock = clock or FrameClock(cfg.reference_rate)
        # m: lateral distances from the anchor to the obstacle's left and right sides, measured while
        # it was wholly in view (dodt.view_edge); None until then
        self.side_widths: np.ndarray | None = None
        anchor, cut = self._measure(det)
        # box centre relative to the measured point (a cut box's centre is not the obstacle's)
        self.offset = np.zeros(2) if cut else det.center[:2] - anchor
        self.kf = KalmanFilter(cfg.kalman, anchor)
        self.born = stamp
        self.last_seen = stamp
        self.z = float(det.center[2])
        self.size = det.size.copy()  # smoothed, for the output
        if cut:  # at least the assumed width across
            np.maximum(self.size[:2], 2 * cfg.kalman.cut_half_width, out=self.size[:2])
        self.det_size = det.size.copy()  # the latest detection's, for association
        self.count, self.spread = features(det)
        # The histories hold what their windows (spans of time, as frames at the current frame
        # period: dodt.windows) need.
        self.observations: deque[_Observation] = deque()  # for the pseudo-measurements
        self.observations.append(_Observation(seq, stamp, anchor.copy(), None, det.source == "learned", det.sensor))
        self.clouds: deque[tuple[int, float, np.ndarray]] = deque()  # (seq, stamp, points) to vote with
        self.clouds.append((seq, stamp, det.points))
        # [t, x, y, z] centres over track.output_history: rows _h0 .. _h1 - 1 of a buffer that
        # grows as needed (the output copies them at once)
        self._hist = np.empty((16, 4))
        self._h0 = self._h1 = 0
        self.add_history(stamp, float(det.center[0]), float(det.center[1]), self.z)
        self.candidates: deque[bool] = deque()  # of the frames with a detection
        # (the geometric label, which sensor measured it: 0 a camera, 1 the LiDAR) of every frame with a
        # detection; a label stands for that sensor's frame period (_decide)
        self.dynamic_history: deque[tuple[bool, int]] = deque()
        self.geometric_dynamic = False  # the label from speed and point voting alone
        # A person box from the learned detector makes the track a person (dynamic at once) only
        # when it recurs: person_fraction of its matched detections over person_span (ours; a
        # single false box would otherwise label a static obstacle dynamic for good).
        # A person box cut by the view's side casts no vote (learned.cut_boxes_vote).
        self.person_votes: deque[bool] = deque()
        self._vote_person(det)
        self.coasting = False
        # the sensor of the latest detection ("": the first camera) and whether it was a LiDAR box
        self.sensor = det.sensor
        self.by_lidar = det.source == "lidar"
        self.missed = 0  # consecutive frames without a detection
        # the physical bounds (module docstring): where the filter put the track at its last
        # measurement, the time predicted since, the box centre and widest horizontal side of the
        # last detection, the filter's speed before it was bounded (m/s), and the position before
        # the latest prediction (None: not predicted yet)
        self.seen_xy = self.kf.position.copy()
        self.unseen_time = 0.0
        self.last_center = det.center[:2].astype(float)
        self.last_extent = float(max(det.size[0], det.size[1]))
        self.filter_speed = 0.0
        self.before_predict: np.ndarray | None = None
        self.headings: deque[tuple[float, float]] = deque()  # (stamp, heading of the pseudo-measured velocity)

    @property
    def history(self) -> list[tuple[float, float, float, float]]:
        """The kept (t, x, y, z) centres, oldest first."""
        return [tuple(float(v) for v in row) for row in self._hist[self._h0:self._h1]]

    def add_history(self, stamp: float, x: float, y: float, z: float) -> None:
        if self._h1 == len(self._hist):
            n = self._h1 - self._h0
            buf = self._hist if 2 * n <= len(self._hist) else np.empty((2 * len(self._hist), 4))
            buf[:n] = self._hist[self._h0:self._h1]
            self._hist, self._h0, self._h1 = buf, 0, n
        self._hist[self._h1] = (stamp, x, y, z)
        self._h1 += 1

    def trim_history(self, oldest: float) -> None:
        """Drop the centres from before ``oldest``, from the front (the newest stays)."""
        while self._hist[self._h0, 0] < oldest:
            self._h0 += 1
            if self._h0 == self._h1:
                raise IndexError("the track's whole history is older than its window")

    @property
    def is_person(self) -> bool:
        """person_fraction of the votes over learned.person_span (3 at 30 Hz) were person boxes."""
        n = self.clock.intervals(self.cfg.learned.person_span) + 1
        votes = self.person_votes
        return len(votes) >= n and \
            sum(islice(votes, len(votes) - n, None)) >= self.cfg.learned.person_fraction * n - 1e-9

    @property
    def dynamic(self) -> bool:
        """A person (dynamic at once, while the label lasts) or dynamic by speed and voting."""
        return bool(self.is_person or self.geometric_dynamic)

    @property
    def center_xy(self) -> np.ndarray:
        return self.kf.position + self.offset

    @property
    def center(self) -> np.ndarray:
        """The 3D centre: x, y filtered, z from the latest detection (a new array)."""
        c = np.empty(3)
        np.add(self.kf.position, self.offset, out=c[:2])
        c[2] = self.z
        return c

    @property
    def half_width(self) -> float:
        """Half the obstacle's widest horizontal side [m]."""
        return 0.5 * max(self.size[0], self.size[1])

    def view(self) -> TrackView:
        return TrackView(center=self.center, size=self.det_size, count=self.count, spread=self.spread,
                         position_variance=self.kf.position_variance)

    def _turn_compensated(self, v: np.ndarray, stamp: float, span: float) -> np.ndarray:
        """The difference quotient over ``span`` is the velocity of the middle of the span: on
        a turn its direction lags the current one by turn rate x span / 2, so it is rotated
        forward by that. The turn rate is the change of the quotient's heading over
        ``turn_window`` seconds (about a gait cycle or more, over which the body's sway
        cancels), and only a sustained turn counts: the rates of the window's two halves must
        agree in sign, and the smaller is taken (a corner already turned, or sway, gives none)."""
        k = self.cfg.kalman
        if k.turn_window <= 0:
            return v
        if float(np.hypot(v[0], v[1])) < k.turn_min_speed:
            self.headings.clear()
            return v
        heading = math.atan2(v[1], v[0])
        self.headings.append((stamp, heading))
        while len(self.headings) > 2 and stamp - self.headings[1][0] >= k.turn_window:
            self.headings.popleft()
        t0, h0 = self.headings[0]
        if stamp - t0 < 0.8 * k.turn_window:
            return v
        tm, hm = min(self.headings, key=lambda e: abs(e[0] - 0.5 * (t0 + stamp)))
        if not t0 < tm < stamp:
            return v
        w1 = wrap_angle(hm - h0) / (tm - t0)
        w2 = wrap_angle(heading - hm) / (stamp - tm)
        if w1 * w2 <= 0:
            return v
        omega = math.copysign(min(abs(w1), abs(w2)), w1)
        ang = omega * span / 2
        c, s_ = math.cos(ang), math.sin(ang)
        return np.array([c * v[0] - s_ * v[1], s_ * v[0] + c * v[1]])

    def _measure(self, det: Detection) -> tuple[np.ndarray, bool]:
        """(the point the filter measures, whether it was measured from a cut detection's side in view).

        The point is _anchor's. Of a detection cut by one side of the image, it is moved across the line
        of sight to where the side in view puts it; a detection wholly in view updates the side widths
        that takes (dodt.view_edge)."""
        anchor = _anchor(det, self.cfg.kalman.position_source)
        s, half = det.sides, self.cfg.kalman.cut_half_width
        if s is None or not half > 0 or s.cut == 2:
            return anchor, False
        a = s.lateral(anchor)
        if s.cut == 0:
            widths = np.array([a - s.low, s.high - a])
            if self.side_widths is None:
                self.side_widths = widths
            else:
                w = blend(self.cfg.track.size_smoothing, self.clock.steps(self.clock.period))
                self.side_widths = (1 - w) * self.side_widths + w * widths
            return anchor, False
        widths = self.side_widths if self.side_widths is not None else (half, half)
        target = s.high - widths[1] if s.cut < 0 else s.low + widths[0]  # from the side in view
        return anchor + (target - a) * s.axis, True

    def _vote_person(self, det: Detection) -> None:
        """Count whether the detection is a person box, unless it is cut by the view's side
        (learned.cut_boxes_vote)."""
        if self.cfg.learned.cut_boxes_vote or not det.cut:
            self.person_votes.append(det.is_person)
            keep_last(self.person_votes, self.clock.intervals(self.cfg.learned.person_span) + 1)

    def jumped(self, det: Detection, stamp: float) -> bool:
        """Whether ``det``'s centre lies farther from the last detection's than a person moves in
        the time between them (track.max_speed), plus track.jump_margin, plus half the larger
        horizontal extent of the two boxes."""
        tc = self.cfg.track
        if tc.jump_margin is None or tc.max_speed is None:
            return False
        reach = tc.max_speed * max(stamp - self.last_seen, 0.0) + tc.jump_margin \
            + 0.5 * max(self.last_extent, float(max(det.size[0], det.size[1])))
        return float(np.hypot(*(det.center[:2] - self.last_center))) > reach

    def restart(self, tid: int, det: Detection, seq: int, stamp: float) -> None:
        """Re-initialise the track at ``det`` (filter, velocity, histories, labels, age) under the new id
        ``tid``: what a consumer keeps by id (a moving-track rule's memory, a planner's) belonged to
        the obstacle it tracked before."""
        self.__init__(tid, det, seq, stamp, self.cfg, self.clock)
        self._h0 = self._h1 = 0  # Tracker.correct adds this frame's centre, as to every matched track

    def bound_prediction(self, dt: float) -> None:
        """After a prediction over ``dt`` seconds: the velocity at most track.max_speed, and the
        position within max_speed x the time predicted since the last measurement of where the
        filter put the track then."""
        v_max = self.cfg.track.max_speed
        self.filter_speed = max(self.filter_speed, self.kf.limit_speed(v_max))
        self.unseen_time += dt
        if v_max is None:
            return
        d = self.kf.position - self.seen_xy
        dist, reach = float(np.hypot(d[0], d[1])), v_max * self.unseen_time
        if dist > reach:
            self.kf.x[:2] = self.seen_xy + d * (reach / dist)

    def hold_off_camera(self, camera: np.ndarray) -> bool:
        """Hold a prediction that would pass through the camera's body: when the centre's path
        over the latest prediction comes nearer the camera (horizontally) than
        track.camera_body_radius plus the track's half width, and nearer than it started, the
        position goes back to where it was and the velocity toward the camera is removed. Returns
        whether it was held."""
        r_body = self.cfg.track.camera_body_radius
        if r_body is None or self.before_predict is None:
            return False
        cam = np.asarray(camera, float)[:2]
        c0, c1 = self.before_predict + self.offset, self.center_xy
        step = c1 - c0
        n2 = float(step @ step)
        s_closest = 0.0 if n2 == 0.0 else min(max(float((cam - c0) @ step) / n2, 0.0), 1.0)
        nearest = float(np.hypot(*(c0 + s_closest * step - cam)))
        start = float(np.hypot(*(c0 - cam)))
        if not (nearest < r_body + self.half_width and nearest < start - 1e-9):
            return False
        self.kf.x[:2] = self.before_predict
        v = self.kf.x[2:4]
        if start > 0.0:
            out = (c0 - cam) / start  # unit vector from the camera to the track
            toward = float(v @ out)
            if toward < 0.0:
                v -= toward * out
        else:
            v[:] = 0.0
        return True

    def hold_inside(self, lo: np.ndarray, hi: np.ndarray) -> bool:
        """Hold a prediction that would take the centre into a wall of the geofence ((x, y) ``lo``, ``hi``):
        on each axis where the centre lies within track.wall_clearance of a side, or beyond it, and moves
        toward that side, the position goes back to where it was on that axis and the velocity into the
        wall is removed. Returns whether it was held."""
        r = self.cfg.track.wall_clearance
        if r is None or self.before_predict is None:
            return False
        c, v, held = self.center_xy, self.kf.x[2:4], False
        for k in (0, 1):
            if (c[k] < lo[k] + r and v[k] < 0.0) or (c[k] > hi[k] - r and v[k] > 0.0):
                self.kf.x[k] = self.before_predict[k]
                v[k] = 0.0
                held = True
        return held

    def update(self, det: Detection, seq: int, stamp: float) -> None:
        k = self.cfg.kalman
        n_avg = max(1, self.clock.intervals(k.averaging_time))  # 10 observations back at 30 Hz
        keep_last(self.observations, n_avg)
        obs = list(self.observations)
        first = max(0, len(obs) - n_avg)  # up to averaging_time back
        # The difference is taken to an observation of the same kind where the window holds one: a
        # learned box's anchor (depths lifted from the box) sits apart from the same person's cluster
        # of points, and a track switching between them would read that offset as motion. Likewise
        # each sensor sees a body from its own place (the LiDAR from above, all round; a camera its near
        # face, completed behind): a track handed from one sensor to another (a walker coming within
        # the camera's depth range, or leaving its view) would read the offset between their boxes as
        # motion (a head-on walker read as crossing at 1.2-1.8 m/s for 0.4 s), so a difference never
        # spans two sensors; with none of this sensor in the window only the position is measured.
        lifted = det.source == "learned"
        if k.same_kind_differences:
            same = [i for i in range(first, len(obs)) if obs[i].sensor == det.sensor]
            first = next((i for i in same if obs[i].lifted == lifted), same[0] if same else None)
        prev = None if first is None else obs[first]
        anchor, cut = self._measure(det)
        per_frame = self.clock.steps(self.clock.period)  # reference frames per frame
        if not cut:
            w_off = blend(0.3, per_frame)
            self.offset = (1 - w_off) * self.offset + w_off * (det.center[:2] - anchor)
        # a cut detection's range is unsure: its visible part's depth changes with how much is in view
        ray = None if not cut else np.array([-det.sides.axis[1], det.sides.axis[0]])
        v = None
        if prev is None:  # nothing from this sensor to difference against
            self.kf.update(anchor, position_only=True, weak_axis=ray, weak_factor=CUT_RANGE_NOISE)
        else:
            dt = stamp - prev.stamp
            if dt > 1e-6:
                v = self._turn_compensated((anchor - prev.center[:2]) / dt, stamp, dt)
            else:
                v = self.kf.velocity.copy()
            # Acceleration needs a velocity measured back then; until there is one, measure none
            # (the filter's own estimate, so the update adds no innovation there).
            a = (v - prev.velocity) / dt if prev.velocity is not None and dt > 1e-6 else self.kf.acceleration.copy()
            window = (len(obs) - first) / n_avg  # observations spanned / full window
            self.kf.update(np.array([anchor[0], anchor[1], v[0], v[1], a[0], a[1]]), window=window, weak_axis=ray,
                           weak_factor=CUT_RANGE_NOISE)
        self.filter_speed = self.kf.limit_speed(self.cfg.track.max_speed)
        self.seen_xy = self.kf.position.copy()
        self.unseen_time = 0.0
        self.before_predict = None  # measured since: no prediction to hold back
        self.last_center = det.center[:2].astype(float)
        self.last_extent = float(max(det.size[0], det.size[1]))
        self.observations.append(_Observation(seq, stamp, anchor.copy(), v, lifted, det.sensor))
        self.z = float(det.center[2])
        # Output size: smoothed over frames (the reference code freezes a stable size instead,
        # which then cannot follow a person whose box changes as they turn or swing their arms).
        w_new = blend(self.cfg.track.size_smoothing, per_frame)
        if cut:  # a cut box is narrower than its obstacle: only the height is measured
            self.size[2] = (1 - w_new) * self.size[2] + w_new * det.size[2]
        else:
            self.size = (1 - w_new) * self.size + w_new * det.size
        self.det_size = det.size.copy()
        self.count, self.spread = features(det)
        self.clouds.append((seq, stamp, det.points))
        n_vote = self.clock.intervals(self.cfg.identification.vote_span)
        while self.clouds[0][0] < seq - n_vote:
            self.clouds.popleft()
        self.last_seen = stamp
        self.missed = 0
        self._vote_person(det)
        self.coasting = False
        self.sensor = det.sensor
        self.by_lidar = det.source == "lidar"

    def identify(self, seq: int, poses: dict, clouds, K: CameraIntrinsics, max_depth: float,
                 lidar_clouds=(), other_cameras=None, lidar_clock: FrameClock | None = None) -> None:
        """clouds(seq) -> that frame's whole filtered cloud, or None. lidar_clouds: the recent LiDAR scans'
        dodt.identification.LidarCloud, oldest first (a track a LiDAR box updated votes against them).
        other_cameras: {sensor: (poses, clouds, K)} of the rig's other cameras (a track another camera
        measured votes in that camera's view). lidar_clock: the LiDAR's scan period, which the force-dynamic
        window of a track a LiDAR box updated is counted in (default: the camera's frame period)."""
        cfg = self.cfg.identification
        if self.coasting:
            return  # no new points: the label stays, and enters no history (dodt.identification.decide)
        speed = float(np.linalg.norm(self.kf.velocity))
        cur_seq, cur_t, cur_pts = self.clouds[-1]
        if self.by_lidar:
            self._identify_by_lidar(speed, cur_t, cur_pts, lidar_clouds, lidar_clock or self.clock)
            return
        # the cloud from k frames back (vote_span), or the oldest one kept since then
        k_back = self.clock.intervals(cfg.vote_span)
        old = [c for c in self.clouds if cur_seq - k_back <= c[0] < cur_seq]
        votes, valid, skipped = 0, 0, len(cur_pts)
        # voting only for what moves fast enough to be a candidate at all, and is not wider
        # than any walking person or pair of people (saves the work; neither can be a candidate)
        wide = 0 < cfg.max_vote_extent < float(np.hypot(self.det_size[0], self.det_size[1]))
        if self.sensor and other_cameras and self.sensor in other_cameras:
            poses, clouds, K = other_cameras[self.sensor]  # vote in the view of the camera that measured it
        if old and cfg.method != "velocity" and speed >= cfg.velocity_threshold and not wide:
            o_seq, o_t, o_pts = old[0]
            T_then = poses.get(o_seq)
            cloud_then = clouds(o_seq) if T_then is not None else None
            if cloud_then is not None and len(cloud_then) and len(o_pts) and len(cur_pts):
                dt = cur_t - o_t
                v_box = (mean_columns(cur_pts) - mean_columns(o_pts)) / max(dt, 1e-6)
                voters = cur_pts
                if 0 < cfg.max_vote_points < len(cur_pts):  # an even sample of a large obstacle
                    voters = cur_pts[::-(-len(cur_pts) // cfg.max_vote_points)]
                # only the part of the old cloud within matching reach of the points can hold
                # their nearest neighbours: the same matches, from a much smaller k-d tree
                r = match_reach(dt, cfg)
                lo, hi = column_bounds(voters)  # voters.min(axis=0), voters.max(axis=0)
                lo, hi = lo.astype(voters.dtype) - r, hi.astype(voters.dtype) + r
                near = crop_to_box(cloud_then, lo, hi)
                votes, valid, skipped = vote(voters, near, dt, v_box, T_then, K, max_depth, cfg)
        # The geometric label (candidates, consistency, the hysteresis and the force-dynamic lock)
        # sees only the geometric evidence; the person label adds to it and does not feed it. Fed
        # into it, ten person frames locked a static obstacle dynamic for good (force_dynamic):
        # on circles a 3 m tall obstacle 5 m away, mutual best match of a passing person's box
        # for a while, stayed dynamic for 8 s after its last person box.
        self._decide(is_candidate(speed, votes, valid, skipped, cfg) and size_ok(self.size, cfg), lidar_clock)

    def _identify_by_lidar(self, speed: float, now: float, points: np.ndarray, lidar_clouds,
                           lidar_clock: FrameClock) -> None:
        """``identify`` for a track a LiDAR box updated: the same point voting, at ``lidar.vote_velocity``
        (dodt.config), against the union of the clouds of the ``lidar.vote_scans`` newest scans at least
        ``lidar.vote_span`` old (one scan's pattern leaves gaps of a few degrees that the next ones fill), the
        LiDAR's view all round (every point was in it)."""
        lc = self.cfg.lidar
        cfg = replace(self.cfg.identification, vote_velocity=lc.vote_velocity)
        then = [c for c in lidar_clouds if c.stamp <= now - lc.vote_span + 1e-6][-lc.vote_scans:]
        votes, valid, skipped = 0, 0, len(points)
        if then and speed >= cfg.velocity_threshold and len(points):
            t_then = then[-1].stamp
            cloud = np.concatenate([c.points for c in then]) if len(then) > 1 else then[0].points
            old = [c for c in self.clouds if c[1] <= t_then + 1e-6]
            dt = now - t_then
            if len(cloud) and dt > 0:
                ref = old[-1][2] if old and len(old[-1][2]) else points
                v_box = (mean_columns(points) - mean_columns(ref)) / dt
                r = match_reach(dt, cfg)
                lo, hi = column_bounds(points)
                near = crop_to_box(cloud, lo.astype(cloud.dtype) - r, hi.astype(cloud.dtype) + r)
                # what lay outside those scans' field (under the lowest ray) was not in their clouds:
                # the frame votes on the rest when that is most of it; otherwise it is no evidence either way,
                # and the track's label stays as it is, as through a frame it coasted
                field = np.ones(len(points), bool) if lc.field_margin is None else \
                    in_lidar_field(points, then, lc.min_range, lc.field_margin)
                if field.mean() < lc.min_field_share:
                    return
                # a surface that faced away from every scan voted against was not seen then (another face of
                # the obstacle, come into view as the sensor passed it): its points do not vote
                here = [c.origin for c in lidar_clouds if abs(c.stamp - now) <= 1e-6]  # the scan that measured it
                facing = faced_then(points, here[-1], [c.origin for c in then], lc.face_cos) if here else None
                votes, valid, skipped = vote(points[field], near, dt, v_box, None, None, 0.0, cfg,
                                             seen_then=None if facing is None else facing[field])
        self._decide(is_candidate(speed, votes, valid, skipped, cfg) and size_ok(self.size, cfg), lidar_clock,
                     by_lidar=True)

    def _decide(self, cand: bool, lidar_clock: FrameClock | None = None, by_lidar: bool = False) -> None:
        """Add this frame's candidate test and label the track (dodt.identification.decide). Each label of
        the force-dynamic history stands for the frame period of the sensor that measured it, the camera's
        (``self.clock``) or the LiDAR's (``lidar_clock``, default the camera's), as each clock has it now;
        the window is the measuring sensor's. The labels are kept for the longer of the camera's window and
        the LiDAR's: one history for a track both measure.
        The lock holds a track a LiDAR box measured only while its box is as tall as a standing person
        (``motion.height``'s lower bound; ours). A person's LiDAR box reaches the floor (the detector extends
        a box the lowest ray cuts), so a person's track keeps that height. A sparse scan of a shelf or a
        box shows a different part of it every scan (slivers 0.04-1.8 m tall): a track of a person who went
        out of range can be carried along such fragments, its box shrinking, and the lock kept the label
        its person had earned on a static obstacle."""
        cfg = self.cfg.identification
        lidar_clock = lidar_clock or self.clock
        periods = (self.clock.period, lidar_clock.period)
        self.candidates.append(cand)
        keep_last(self.candidates, max(self.clock.frames_within(cfg.consistency_span),
                                       self.clock.intervals(cfg.release_span) + 1))
        self.geometric_dynamic = decide(list(self.candidates), [(x, periods[k]) for x, k in self.dynamic_history],
                                        cfg, self.clock, lidar_clock if by_lidar else self.clock,
                                        lock=not by_lidar or float(self.size[2]) >= self.cfg.motion.height[0])
        self.dynamic_history.append((self.geometric_dynamic, int(by_lidar)))
        span = cfg.force_dynamic_span
        if span is None:
            keep_last(self.dynamic_history, 1)
            return
        window = max(lock_window(span, lidar_clock), lock_window(span, self.clock))
        total = sum(periods[k] for _, k in self.dynamic_history)
        while len(self.dynamic_history) > 1 and total - periods[self.dynamic_history[0][1]] >= window * (1.0 - 1e-9):
            total -= periods[self.dynamic_history.popleft()[1]]

    def camera_point(self, R: np.ndarray, t: np.ndarray) -> np.ndarray:
        """The predicted centre in the camera frame of pose (R, t)."""
        return (self.center - t) @ R

    def image_box(self, pc: np.ndarray, K: CameraIntrinsics) -> tuple[float, float, float, float]:
        """(u, v, half width, half height) in pixels of the obstacle's box seen with its centre
        at ``pc`` (camera frame, in front of the camera), its widest horizontal side facing it."""
        half_w = self.half_width * K.fx / pc[2]
        half_h = 0.5 * self.size[2] * K.fy / pc[2]
        return K.fx * pc[0] / pc[2] + K.cx, K.fy * pc[1] / pc[2] + K.cy, half_w, half_h

    def output(self, stamp: float) -> TrackedObstacle:
        """The track as reported: with the velocity and acceleration the filter holds (bounded by
        track.max_speed), whatever its label. A track identified static reports them too: a zero
        report would hide a velocity that still moves its prediction (``filter_velocity`` and
        ``filter_acceleration`` are the same)."""
        h = self._hist[self._h0:self._h1]
        recent = h[:, 0] >= stamp - self.cfg.track.output_history
        h = h.copy() if recent.all() else h[recent]
        person, dynamic = self.is_person, self.dynamic
        v = np.zeros(3)
        v[:2] = self.kf.velocity
        a = np.zeros(3)
        a[:2] = self.kf.acceleration
        return TrackedObstacle(
            id=self.id, center=self.center, size=self.size.copy(),
            velocity=v, acceleration=a,
            dynamic=dynamic, coasting=self.coasting, age=stamp - self.born,
            history=h, is_person=person,
            position_std=float(np.sqrt(self.kf.position_variance)), filter_velocity=v.copy(), filter_acceleration=a.copy(),
            evidence="voting" if self.geometric_dynamic else "person" if person else "", sensor=self.sensor or "")


def _footprint_and_top(boxes) -> np.ndarray:
    """(n, 3): each box's x and y size and its top's height (objects with center and size (3,))."""
    return np.array([[b.size[0], b.size[1], b.center[2] + 0.5 * b.size[2]] for b in boxes], float).reshape(-1, 3)


class Tracker:
    def __init__(self, cfg: DODTConfig):
        self.cfg = cfg
        self.tracks: list[Track] = []
        self._next_id = 1
        self.clock = FrameClock(cfg.reference_rate)
        self.lidar_clock = FrameClock(cfg.reference_rate)  # the LiDAR's scan period (DODT observes it)
        self.restarts = 0  # tracks re-initialised after a jump (Track.jumped)
        self.duplicates_dropped = 0  # tracks dropped beside a measured one (track.duplicate_radius)
        self.walls: tuple[np.ndarray, np.ndarray] | None = None  # the geofence, (x, y) low and high

    def reset(self) -> None:
        self.tracks = []

    def predict(self, dt: float) -> None:
        q_scale = self.clock.steps(dt)  # the reference code's Q is per 30 Hz frame
        for t in self.tracks:
            if t.coasting and t.kf.ca:
                t.kf.x[4:6] = 0.0  # unobserved acceleration would run away: coast at constant velocity
            t.before_predict = t.kf.position.copy()
            t.kf.predict(dt, q_scale)
            t.bound_prediction(dt)

    def _drop_seen_through(self, seen_past) -> int:
        """Delete the coasting tracks due for a seen-through test (``track.seen_through_after`` since their
        last detection) that ``seen_past(track)`` finds seen through. Returns how many."""
        due = self.clock.intervals(self.cfg.track.seen_through_after)
        keep = [tr for tr in self.tracks if not (tr.coasting and tr.missed >= due and seen_past(tr))]
        dropped = len(self.tracks) - len(keep)
        self.tracks = keep
        return dropped

    def drop_seen_through(self, depth_m: np.ndarray, K: CameraIntrinsics, T_world_camera: np.ndarray) -> int:
        """Delete coasting tracks whose predicted place is in view and seen through: the camera
        sees clearly farther than where the obstacle should be, so it is not there (it is
        occluded when something nearer is seen, and then it keeps coasting). Returns how many.

        Within the depth range of the point cloud (``depth.depth_max``) for every track; with the
        learned module on, person tracks out to its range (``learned.depth_max``), where its
        boxes are the only detections. Beyond ``depth.depth_max`` the margin grows with the
        square of the depth, as stereo depth noise does."""
        tc, dc = self.cfg.track, self.cfg.depth
        R, t = T_world_camera[:3, :3], T_world_camera[:3, 3]
        H, W = depth_m.shape
        person_reach = max(self.cfg.learned.depth_max, dc.depth_max) if self.cfg.learned.enabled else dc.depth_max

        def seen_past(tr: Track) -> bool:
            pc = tr.camera_point(R, t)
            if not dc.depth_min <= pc[2] <= (person_reach if tr.is_person else dc.depth_max):
                return False
            margin = tc.seen_through_margin * max(1.0, (pc[2] / dc.depth_max) ** 2)
            u, v, half_w, half_h = tr.image_box(pc, K)
            u0, u1 = int(max(u - half_w, 0)), int(min(u + half_w, W - 1))
            v0, v1 = int(max(v - half_h, 0)), int(min(v + half_h, H - 1))
            inside = (u1 - u0) >= 0.6 * 2 * half_w and (v1 - v0) >= 0.6 * 2 * half_h
            if not (inside and u1 > u0 and v1 > v0):
                return False
            # of the valid depths (> 0) in every other pixel of the box's image region, how many lie
            # behind it (farther than its centre by the margin); seen through: nearly all of them
            n_valid, n_behind = _count_behind(depth_m, v0, v1 + 1, u0, u1 + 1, 2, pc[2] + margin)
            return n_valid >= 20 and n_behind / n_valid > tc.seen_through_fraction

        return self._drop_seen_through(seen_past)

    def drop_seen_through_lidar(self, scan: LidarScan) -> int:
        """drop_seen_through for a LiDAR scan: delete coasting tracks whose predicted box the scan's rays
        pass through. Of the returns whose rays cross the middle of the box as seen from the sensor (0.6 of
        its widest side and of its height), at least 10, more
        than ``track.seen_through_fraction`` end farther than the box's centre by
        ``track.seen_through_margin`` (horizontally): the scan sees past where the obstacle should be, so
        it is not there; occluded, something nearer is seen, and it keeps coasting. The whole scan is in
        view (all round). The window is taken in the sensor's frame from the box's world size, which
        holds for a level sensor. Returns how many."""
        tc = self.cfg.track
        T = np.asarray(scan.T_world_sensor, dtype=np.float64)
        if len(scan.ranges) == 0 or not np.all(np.isfinite(T)):
            return 0
        R, origin = T[:3, :3], T[:3, 3]
        az = np.asarray(scan.azimuth, dtype=np.float64)
        el = np.asarray(scan.elevation, dtype=np.float64)
        ranges = np.asarray(scan.ranges, dtype=np.float64)

        def seen_past(tr: Track) -> bool:
            q = R.T @ (tr.center - origin)  # the box's centre in the sensor frame
            d = float(np.hypot(q[0], q[1]))
            if d <= tr.half_width:  # the sensor is inside the box
                return False
            half_az = math.atan2(0.6 * tr.half_width, d)
            half_h = 0.6 * 0.5 * float(tr.size[2])
            off = np.abs(wrap_angle(az - math.atan2(q[1], q[0])))
            ray = (off <= half_az) & (el >= math.atan2(q[2] - half_h, d)) & (el <= math.atan2(q[2] + half_h, d))
            n_valid = int(np.count_nonzero(ray))
            if n_valid < 10:
                return False
            reach = ranges[ray] * np.cos(el[ray])  # the horizontal range of those returns
            return np.count_nonzero(reach > d + tc.seen_through_margin) > tc.seen_through_fraction * n_valid

        return self._drop_seen_through(seen_past)

    def drop_unseen_people(self, boxes_2d: np.ndarray, depth_m: np.ndarray, K: CameraIntrinsics,
                           T_world_camera: np.ndarray) -> int:
        """Delete coasting person tracks that the learned detector should see and does not: from
        ``learned.unseen_after`` seconds after its last detection, the track's image box lies
        wholly in the view, less than ``learned.unseen_occluder_fraction`` of the valid depths in
        it lie in front of the track (nearer than its centre by half its width and 0.3 m: nothing
        hides it), and no 2D person box of this frame (``boxes_2d``, pixels) overlaps it by
        ``learned.unseen_iou``. Returns how many."""
        lc, dc = self.cfg.learned, self.cfg.depth
        if lc.unseen_after <= 0:
            return 0
        R, t = T_world_camera[:3, :3], T_world_camera[:3, 3]
        H, W = depth_m.shape
        boxes = np.asarray(boxes_2d, dtype=np.float64).reshape(-1, 4)
        keep, dropped = [], 0
        for tr in self.tracks:
            if tr.coasting and tr.is_person and tr.missed >= self.clock.intervals(lc.unseen_after):
                pc = tr.camera_point(R, t)
                if dc.depth_min <= pc[2] <= lc.depth_max:
                    u, v, half_w, half_h = tr.image_box(pc, K)
                    b = np.array([u - half_w, v - half_h, u + half_w, v + half_h])
                    if b[0] >= 0 and b[1] >= 0 and b[2] <= W - 1 and b[3] <= H - 1:
                        win = depth_m[int(b[1]):int(b[3]) + 1:2, int(b[0]):int(b[2]) + 1:2]
                        win = win[win > 0]
                        front = pc[2] - tr.half_width - 0.3
                        hidden = win.size > 0 and np.mean(win < front) >= lc.unseen_occluder_fraction
                        if not hidden and not np.any(iou_one(b, boxes) >= lc.unseen_iou):
                            dropped += 1
                            continue
            keep.append(tr)
        self.tracks = keep
        return dropped

    def associate(self, dets: list[Detection], camera: np.ndarray) -> list[tuple[int, int]]:
        views = [t.view() for t in self.tracks]
        scores, thr = similarity_matrix(views, dets, self.cfg.association, camera)
        pairs = assign(scores, thr)
        gate = self.cfg.association.fallback_gate
        if gate > 0 and self.cfg.association.method != "center":
            # Second stage: what the features left unmatched, matched by predicted position within
            # the gate grown by the prediction's uncertainty (a partly seen obstacle changes shape).
            ut = [i for i in range(len(views)) if i not in {p[0] for p in pairs}]
            ud = [j for j in range(len(dets)) if j not in {p[1] for p in pairs}]
            if ut and ud:
                tc = np.array([views[i].center[:2] for i in ut])
                dc = np.array([dets[j].center[:2] for j in ud])
                dist = np.linalg.norm(tc[:, None] - dc[None], axis=2)
                g = gate + 2.0 * np.sqrt([views[i].position_variance for i in ut])
                # ... but never to something of another size: a wall is no person (paper Fig. 7). The
                # footprints and the tops are compared, not the bottoms: a sensor's field cuts a near
                # person's lower part (the LiDAR's lowest ray, the camera's lower edge), so a track fed
                # by one sensor's partial boxes and a detection of the whole person differ there.
                ts = _footprint_and_top([views[i] for i in ut])
                ds = _footprint_and_top([dets[j] for j in ud])
                similar = np.max(np.abs(ts[:, None] - ds[None]), axis=2) < self.cfg.association.size_scale
                cost = np.where((dist < g[:, None]) & similar, -dist, -np.inf)
                pairs += [(ut[a], ud[b]) for a, b in assign(cost, -np.inf)]
        return pairs

    def _coast_time(self, tr: Track, camera: np.ndarray | None) -> float:
        """How long ``tr`` may coast: a person track beyond the ensemble's depth range, seen by the
        learned boxes alone, for learned.far_coast_time; any other for track.coast_time."""
        far = self.cfg.learned.far_coast_time
        if far > 0 and camera is not None and tr.is_person:
            d = float(np.hypot(*(tr.center_xy - np.asarray(camera, float)[:2])))
            if d > self.cfg.depth.depth_max:
                return min(far, self.cfg.track.coast_time)
        return self.cfg.track.coast_time

    def correct(self, dets: list[Detection], pairs: list[tuple[int, int]], seq: int, stamp: float,
                camera: np.ndarray | None = None) -> None:
        """camera: the camera's position in the world (without it every track coasts for track.coast_time)."""
        matched_t = {t for t, _ in pairs}
        matched_d = {d for _, d in pairs}
        for ti, di in pairs:
            tr = self.tracks[ti]
            if tr.jumped(dets[di], stamp):  # no person moves that far: an obstacle seen anew
                tr.restart(self._next_id, dets[di], seq, stamp)
                self._next_id += 1
                self.restarts += 1
            else:
                tr.update(dets[di], seq, stamp)
        survivors = []
        dup_r = self.cfg.track.duplicate_radius
        measured = np.array([self.tracks[t].center_xy for t in matched_t]).reshape(-1, 2)
        measured_dyn = np.array([self.tracks[t].dynamic for t in matched_t], bool)
        for i, tr in enumerate(self.tracks):
            if i not in matched_t:
                if stamp - tr.last_seen > self._coast_time(tr, camera):
                    continue  # lost for too long
                if dup_r is not None and np.any((np.hypot(*(measured - tr.center_xy).T) < dup_r)
                                                & (measured_dyn | (not tr.dynamic))):
                    self.duplicates_dropped += 1
                    continue  # the obstacle a track beside it measured now (a dynamic one, or both static)
                # the filter's speed before track.max_speed bounded it
                if tr.is_person and tr.filter_speed > self.cfg.track.max_coast_speed:
                    continue  # a person faster than people walk: a velocity made of noise
                tr.coasting = True
                tr.missed += 1
                if camera is not None:
                    tr.hold_off_camera(camera)
                if self.walls is not None:
                    tr.hold_inside(*self.walls)
            survivors.append(tr)
            c = tr.center_xy
            tr.add_history(stamp, float(c[0]), float(c[1]), tr.z)
            tr.trim_history(stamp - self.cfg.track.output_history)
        for di, det in enumerate(dets):
            if di not in matched_d:
                survivors.append(Track(self._next_id, det, seq, stamp, self.cfg, self.clock))
                self._next_id += 1
        self.tracks = survivors

