"""The DODT pipeline: a sensor frame in, tracked obstacles out (paper Fig. 2).

    perception = DODT(preset("dodt"))
    result = perception.process(frame)   # dodt.frames.SensorFrame
    for ob in result.dynamic: ...

Detectors -> ensemble -> association -> Kalman filter -> identification (point voting, then the
motion label of dodt.motion_label: one label, ``dynamic``, whose ``evidence`` says which), each timed. Input
is checked: a wrong shape or dtype, intrinsics that do not match the image, a depth scale that is
not a positive number or a pose whose rotation is a reflection raise a ValueError naming the
problem; bad data is skipped and counted instead (NaN / inf / negative depth pixels are invalid
pixels; a frame with a non-finite pose or a timestamp that does not move forward is skipped; so
is a stamp that jumps ahead by more than ``depth.max_time_jump``, until
``depth.confirm_jump_frames`` frames in a row confirm the new time, which then restarts the
tracks; a gap longer than the coasting time restarts the tracks).
Every history window is a span of time (dodt.config), so any frame rate works with one
configuration.
On a rig (docs/sensing.md): a LiDAR scan handed to ``observe_lidar`` and the other cameras' frames
handed to ``observe_cameras`` join the next frame's detections (dodt.lidar_detector's boxes of what the
cameras' detectors did not find, LV-DOT's LiDAR-visual ensemble), so that obstacles beside and behind
the camera are measured by the same tracker; a track votes in the view of the sensor that measured it
(dodt.tracker).
The learned person detector (YOLO-MAD, dodt.learned) runs when ``cfg.learned.enabled``; any
callable (frame, depth_m, ensemble_detections) -> detections can stand in for it through
``learned_detector``. Its time is the "learned" module's.
"""
from __future__ import annotations

import math
import time
from collections import deque

import numpy as np

from dodt.config import DODTConfig
from dodt.dbscan import DBSCANDetector
from dodt.detection import Detection
from dodt.ensemble import ensemble
from dodt.frames import LidarScan, SensorFrame
from dodt.geometry import box_cut_by_view_side, complete_hidden_depth, points_in_box
from dodt.identification import LidarCloud
from dodt.lidar_detector import LidarDetector
from dodt.motion_label import MotionLabel
from dodt.pointcloud import VoxelCloud
from dodt.result import PerceptionResult
from dodt.tracker import Tracker
from dodt.udepth import UDepthDetector
from dodt.view_edge import view_sides

MODULES = ("point_cloud", "udepth", "dbscan", "ensemble", "learned", "other_cameras", "lidar", "association",
           "kalman", "identification")


_LAST_ROW = np.array([0.0, 0.0, 0.0, 1.0])
_LAST_ROW_TOL = 1e-8 + 1e-5 * np.abs(_LAST_ROW)
_EYE3 = np.eye(3)
_EYE3_TOL = 1e-3 + 1e-5 * np.abs(_EYE3)


def validate_frame(frame: SensorFrame) -> None:
    """Raise ValueError for malformed frames (a programming or configuration error)."""
    d = frame.depth
    K = frame.intrinsics
    if not isinstance(d, np.ndarray) or d.ndim != 2:
        raise ValueError(f"depth must be a 2-D array, got {type(d).__name__} with shape {getattr(d, 'shape', None)}")
    if d.dtype not in (np.uint16, np.float32, np.float64):
        raise ValueError(f"depth must be uint16 millimetres or float32/float64 metres, got dtype {d.dtype}")
    if K.width < 16 or K.height < 16:
        raise ValueError(f"images must be at least 16x16 pixels, the intrinsics say {K.width}x{K.height}")
    if d.shape != (K.height, K.width):
        raise ValueError(f"depth image is {d.shape[1]}x{d.shape[0]} but the intrinsics are for "
                         f"{K.width}x{K.height}")
    if not (math.isfinite(K.fx) and math.isfinite(K.fy) and K.fx > 0 and K.fy > 0):
        raise ValueError(f"intrinsics fx, fy must be finite and positive, got {K.fx}, {K.fy}")
    if not (math.isfinite(K.cx) and math.isfinite(K.cy)):
        raise ValueError(f"intrinsics cx, cy must be finite, got {K.cx}, {K.cy}")
    scale = frame.depth_scale
    if not (isinstance(scale, (int, float, np.floating)) and math.isfinite(scale) and scale > 0):
        raise ValueError(f"depth_scale (metres per unit of a uint16 depth image) must be a finite number above 0, "
                         f"got {scale!r}")
    if frame.color is not None:
        c = frame.color
        if not isinstance(c, np.ndarray) or c.shape != (K.height, K.width, 3) or c.dtype != np.uint8:
            raise ValueError(f"color must be a ({K.height}, {K.width}, 3) uint8 array aligned to depth, got "
                             f"{getattr(c, 'shape', None)} {getattr(c, 'dtype', None)}")
    T = np.asarray(frame.T_world_camera)
    if T.shape != (4, 4):
        raise ValueError(f"T_world_camera must be 4x4, got shape {T.shape}")
    if np.isfinite(T).all():  # a non-finite pose is bad data (skipped and counted), not an error
        # np.allclose's test (|a - b| <= atol + rtol |b|, rtol 1e-5) against precomputed bounds
        if not (np.abs(T[3] - _LAST_ROW) <= _LAST_ROW_TOL).all():
            raise ValueError(f"T_world_camera's last row must be [0, 0, 0, 1], got {T[3].tolist()}")
        R = T[:3, :3]
        if not (np.abs(R @ R.T - _EYE3) <= _EYE3_TOL).all():
            raise ValueError("T_world_camera's rotation is not orthonormal")
        # near-orthonormal here: the determinant is about +-1, its sign that of the triple product
        (a, b, c), (d, e, f), (g, h, i) = R.tolist()
        if a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) < 0:
            raise ValueError("T_world_camera's rotation has determinant -1: a reflection, not a rotation "
                             "(a left-handed camera or world frame?)")


def _footprints_meet(a: Detection, b: Detection, grow: float) -> bool:
    """Whether two detections' horizontal footprints overlap (each grown by ``grow`` / 2 m)."""
    return bool(np.all(np.abs(a.center[:2] - b.center[:2]) <= (a.size[:2] + b.size[:2]) / 2 + grow))


def _with_points(dets: list[Detection], points: np.ndarray) -> None:
    """Every detection carries the filtered points inside its box: its features and votes."""
    for d in dets:
        if len(d.points) == 0 and len(points):
            d.points = points[points_in_box(points, d.center, d.size, grow=0.05)]


def mark_cut(dets: list[Detection], K, T_world_camera: np.ndarray) -> None:
    """Set each detection's ``cut``: its box crosses the image's left or right edge."""
    for d in dets:
        d.cut = box_cut_by_view_side(d.center, d.size, K, T_world_camera)


class DODT:
    def __init__(self, cfg: DODTConfig | None = None, learned_detector=None):
        self.cfg = cfg or DODTConfig()
        self.cloud = VoxelCloud(self.cfg.depth, self.cfg.voxel)
        self.udepth = UDepthDetector(self.cfg.udepth, self.cfg.depth,
                                     (self.cfg.voxel.ground_height, self.cfg.voxel.ceiling_height))
        self.dbscan = DBSCANDetector(self.cfg.dbscan)
        if learned_detector is None and self.cfg.learned.enabled:
            from dodt.learned.fusion import YoloMAD  # loads onnxruntime and the model only when asked
            learned_detector = YoloMAD(self.cfg.learned)
        self.learned_detector = learned_detector
        self.tracker = Tracker(self.cfg)
        self.motion = MotionLabel(self.cfg.motion)  # the last step of identification
        self.lidar = LidarDetector(self.cfg.lidar, self.cfg.voxel.ground_height, self.cfg.voxel.ceiling_height)
        self._scan = None  # the latest LiDAR scan not yet fused (observe_lidar)
        self._others: tuple = ()  # the rig's other cameras' frames for the next frame (observe_cameras)
        # the recent scans' filtered clouds, to vote with
        self.lidar_clouds: deque[LidarCloud] = deque()
        # the rig's other cameras' poses and clouds by frame seq, to vote with: {sensor: (poses, clouds, K)}
        self.other_views: dict[str, tuple[dict, dict, object]] = {}
        self._lidar_view = (None, None, None, None)  # static map, geofence, lowest and highest rays: set_scene
        self.last_stamp: float | None = None
        self.poses: dict[int, np.ndarray] = {}
        self.clouds: dict[int, np.ndarray] = {}  # seq -> that frame's filtered cloud
        self._pose_order: deque[int] = deque()  # the frames kept for voting
        self._jump: list[float] = []  # stamps of the frames in a row that jumped away from last_stamp
        self.counters = {"frames": 0, "skipped_bad_pose": 0, "skipped_time": 0, "restarted_after_gap": 0,
                         "bad_pixels": 0, "frames_with_bad_pixels": 0}
        self._seq = 0

    def reset(self) -> None:
        self.tracker.reset()
        self.motion.reset()
        self._scan = None
        self._others = ()
        self.lidar_clouds.clear()
        self.other_views.clear()
        self.last_stamp = None
        self.poses.clear()
        self.clouds.clear()
        self._pose_order.clear()
        self._jump = []

    def _stamp_ok(self, stamp: float) -> bool:
        """Whether a frame's stamp may be processed: it moves forward from the last processed
        frame by at most depth.max_time_jump. A frame that jumps (forward farther, or back) is
        refused; when depth.confirm_jump_frames such frames come in a row, each moving forward
        from the one before by a plausible step, the new time is taken (the tracks restart)."""
        if not math.isfinite(stamp):
            return False
        last = self.last_stamp
        if last is None or last < stamp <= last + self.cfg.depth.max_time_jump:
            self._jump = []
            return True
        dc = self.cfg.depth
        if self._jump and not self._jump[-1] < stamp <= self._jump[-1] + dc.max_time_jump:
            self._jump = []
        self._jump.append(stamp)
        if len(self._jump) < max(dc.confirm_jump_frames, 1):
            return False
        # the clock did jump: start again from this frame
        self.reset()
        self.counters["restarted_after_gap"] += 1
        return True

    def set_scene(self, static_map=None, geofence=None, lidar_elevation_min: float | None = None,
                  lidar_elevation_max: float | None = None) -> None:
        """What the LiDAR detector knows of the scene (dodt.lidar_detector): the static map
        (a dodt.context.StaticMapView), the geofence ((x, y) low, (x, y) high; its sides are walls),
        the LiDAR's lowest and highest rays' elevations [rad]. The motion label checks its tracks against
        the static map's long-held structure (``established_fraction``) and the geofence's walls
        (dodt.motion_label); the tracker holds coasting tracks off those walls (track.wall_clearance)."""
        self._lidar_view = (static_map, geofence, lidar_elevation_min, lidar_elevation_max)
        self.motion.structure_test = getattr(static_map, "established_fraction", None)
        walls = None if geofence is None else (np.asarray(geofence[0], float), np.asarray(geofence[1], float))
        self.motion.geofence = self.tracker.walls = walls

    def observe_lidar(self, scan) -> None:
        """Keep a LiDAR scan (dodt.frames.LidarScan) for the next frame: its boxes join that frame's
        detections."""
        self._scan = scan

    def observe_cameras(self, frames) -> None:
        """Keep the rig's other cameras' frames (dodt.frames.SensorFrame, depth only) of the next frame's
        instant: their depth detectors' boxes join that frame's detections, and tracks seen through in them
        are dropped as in the first camera's."""
        self._others = tuple(frames)

    def _other_cameras(self, dets: list[Detection], seq: int) -> tuple[list[Detection], list]:
        """(the other cameras' detections, each merged into one it overlaps; [(depth m, K, T)] of each)."""
        frames, self._others = self._others, ()
        views, out = [], []
        for k, f in enumerate(frames):
            validate_frame(f)
            T = np.asarray(f.T_world_camera, dtype=np.float64)
            if not np.all(np.isfinite(T)):
                continue
            depth_m, _ = f.depth_m_counted()
            points = self.cloud(depth_m, f.intrinsics, T)
            name = f"camera{k + 1}"
            poses, clouds, _ = self.other_views.setdefault(name, ({}, {}, f.intrinsics))
            poses[seq], clouds[seq] = T, points
            for old in [q for q in poses if q not in self.poses and q != seq]:  # the first camera's window
                poses.pop(old)
                clouds.pop(old, None)
            found = self._depth_detections(f, depth_m, T, points)
            for d in found:
                d.sensor = name
                other = next((c for c in dets + out if _footprints_meet(d, c, 0.0)), None)
                if other is None:
                    out.append(d)
                else:  # one obstacle across two cameras' views: one box around both parts
                    lo, hi = np.minimum(other.lower, d.lower), np.maximum(other.upper, d.upper)
                    other.center, other.size = (lo + hi) / 2, hi - lo
                    other.points = np.concatenate([other.points, d.points]).astype(np.float32)
            views.append((depth_m, f.intrinsics, T))
        return out, views

    def _lidar_detections(self, dets: list[Detection], stamp: float) -> tuple[list[Detection], LidarScan | None]:
        """The kept scan's boxes whose footprints meet none of the camera's detections' (those are the
        camera's to measure), and the scan fused (None: none this frame); its filtered cloud joins
        ``lidar_clouds`` at ``stamp``."""
        scan, self._scan = self._scan, None
        if scan is None or not np.all(np.isfinite(scan.T_world_sensor)):
            return [], None
        static_map, geofence, el_min, el_max = self._lidar_view
        out = []
        grow = self.cfg.lidar.voxel
        found = self.lidar(scan, static_map, geofence, el_min)
        if self.lidar_clouds:
            self.tracker.lidar_clock.observe(stamp - self.lidar_clouds[-1].stamp)
        self.lidar_clouds.append(LidarCloud(stamp, self.lidar.last_cloud, np.array(scan.T_world_sensor, float), el_min,
                                           el_max))
        # s: the voting's reach back and its scans (at 10 Hz), and a period to spare
        span = self.cfg.lidar.vote_span + 0.1 * (self.cfg.lidar.vote_scans + 1)
        while self.lidar_clouds and self.lidar_clouds[0].stamp < stamp - span:
            self.lidar_clouds.popleft()
        for d in found:
            if not any(_footprints_meet(d, c, grow) for c in dets):
                out.append(d)
        return out, scan

    def _depth_detections(self, frame, depth_m, T, points) -> list[Detection]:
        """The depth detectors' ensemble on another camera's frame (``_detect``'s, without the learned
        detector: no colour)."""
        cfg = self.cfg.ensemble
        ud = self.udepth(depth_m, frame.intrinsics, T) if "udepth" in cfg.detectors else []
        db = self.dbscan(points) if "dbscan" in cfg.detectors else []
        self._complete(ud + db, T)
        dets = self._ensemble(ud, db)
        _with_points(dets, points)
        return dets

    def _complete(self, dets: list[Detection], T: np.ndarray) -> None:
        """Give each box the depth the camera cannot see (ensemble.complete_depth), before fusion, so that
        both detectors' boxes have volume."""
        depth = self.cfg.ensemble.complete_depth
        if depth > 0:
            for d in dets:
                d.center, d.size = complete_hidden_depth(d.center, d.size, T[:3, 3], depth)

    def _ensemble(self, ud: list[Detection], db: list[Detection]) -> list[Detection]:
        """The detectors' boxes as the configuration combines them (the paper's ensemble, or one alone)."""
        cfg = self.cfg.ensemble
        if len(cfg.detectors) == 2:
            return ensemble(ud, db, cfg)
        return ud if cfg.detectors == ("udepth",) else db

    # ------------------------------------------------------------------ helpers

    def _skip(self, frame: SensorFrame, why: str, bad_pixels: int = 0) -> PerceptionResult:
        self.counters[why] += 1
        stamp = self.last_stamp if self.last_stamp is not None else 0.0
        return PerceptionResult(stamp=stamp, seq=frame.seq, obstacles=self.motion((t.output(stamp) for t in self.tracker.tracks), frame),
                                timings_ms={m: 0.0 for m in MODULES} | {"total": 0.0}, skipped=why,
                                bad_pixels=bad_pixels)

    def _detect(self, frame, depth_m, T, points) -> tuple[list[Detection], dict]:
        cfg = self.cfg.ensemble
        timings = {}
        t0 = time.perf_counter()
        ud = self.udepth(depth_m, frame.intrinsics, T) if "udepth" in cfg.detectors else []
        t1 = time.perf_counter()
        db = self.dbscan(points) if "dbscan" in cfg.detectors else []
        self._complete(ud + db, T)
        t2 = time.perf_counter()
        dets = self._ensemble(ud, db)
        t3 = time.perf_counter()
        if self.learned_detector is not None:
            dets = self.learned_detector(frame, depth_m, dets)
        t4 = time.perf_counter()
        _with_points(dets, points)
        if self.learned_detector is not None and not self.cfg.learned.cut_boxes_vote:
            mark_cut(dets, frame.intrinsics, T)
        if self.cfg.kalman.cut_half_width > 0:
            for d in dets:
                d.sides = view_sides(d.points, frame.intrinsics, T, self.cfg.depth.margin, self.cfg.voxel.resolution)
        t5 = time.perf_counter()
        timings.update(udepth=(t1 - t0) * 1e3, dbscan=(t2 - t1) * 1e3, ensemble=(t3 - t2 + t5 - t4) * 1e3,
                       learned=(t4 - t3) * 1e3 if self.learned_detector is not None else 0.0)
        learned = list(getattr(self.learned_detector, "last_3d", []))
        return dets, {"udepth": ud, "dbscan": db, "learned": learned, "ensemble": dets, "timings": timings}

    # ------------------------------------------------------------------ main entry

    def process(self, frame: SensorFrame) -> PerceptionResult:
        validate_frame(frame)
        t_start = time.perf_counter()
        self.counters["frames"] += 1
        T = np.asarray(frame.T_world_camera, dtype=np.float64)
        stamp = float(frame.stamp)
        depth_m, n_bad = frame.depth_m_counted()
        if n_bad:
            self.counters["bad_pixels"] += n_bad
            self.counters["frames_with_bad_pixels"] += 1
        if not np.all(np.isfinite(T)):
            return self._skip(frame, "skipped_bad_pose", n_bad)
        if not self._stamp_ok(stamp):
            return self._skip(frame, "skipped_time", n_bad)
        dt = 0.0 if self.last_stamp is None else stamp - self.last_stamp
        if dt > max(self.cfg.depth.max_frame_gap, self.cfg.track.coast_time):
            self.tracker.reset()  # frames were lost for longer than tracks survive: start again
            self.motion.reset()
            self.counters["restarted_after_gap"] += 1
            dt = 0.0
        if dt > 0:
            self.tracker.clock.observe(dt)
        self.last_stamp = stamp
        seq = self._seq
        self._seq += 1
        self.poses[seq] = T
        self._pose_order.append(seq)
        # the frames a track may vote against: vote_span back (Track.identify)
        while len(self._pose_order) > self.tracker.clock.intervals(self.cfg.identification.vote_span) + 1:
            old = self._pose_order.popleft()
            self.poses.pop(old, None)
            self.clouds.pop(old, None)

        t0 = time.perf_counter()
        points = self.cloud(depth_m, frame.intrinsics, T)
        t_cloud = (time.perf_counter() - t0) * 1e3
        self.clouds[seq] = points
        dets, debug = self._detect(frame, depth_m, T, points)
        t0 = time.perf_counter()
        other_dets, other_views = self._other_cameras(dets, seq) if self._others else ([], [])
        t_other = (time.perf_counter() - t0) * 1e3
        t0 = time.perf_counter()
        lidar_dets, scan = self._lidar_detections(dets + other_dets, stamp)
        dets = dets + other_dets + lidar_dets
        t_lidar = (time.perf_counter() - t0) * 1e3

        t0 = time.perf_counter()
        if dt > 0:
            self.tracker.predict(dt)
        pairs = self.tracker.associate(dets, T[:3, 3])
        t1 = time.perf_counter()
        self.tracker.correct(dets, pairs, seq, stamp, T[:3, 3])
        self.tracker.drop_seen_through(depth_m, frame.intrinsics, T)
        for d_k, K_k, T_k in other_views:
            self.tracker.drop_seen_through(d_k, K_k, T_k)
        if scan is not None:
            self.tracker.drop_seen_through_lidar(scan)
        boxes_2d = getattr(self.learned_detector, "last_boxes_2d", None)
        if boxes_2d is not None and frame.color is not None:
            self.tracker.drop_unseen_people(boxes_2d, depth_m, frame.intrinsics, T)
        t2 = time.perf_counter()
        for tr in self.tracker.tracks:
            tr.identify(seq, self.poses, self.clouds.get, frame.intrinsics, self.cfg.depth.depth_max, self.lidar_clouds,
                        {k: (v[0], v[1].get, v[2]) for k, v in self.other_views.items()}, self.tracker.lidar_clock)
        obstacles = self.motion((t.output(stamp) for t in self.tracker.tracks), frame)
        t3 = time.perf_counter()
        timings = {"point_cloud": t_cloud, **debug["timings"], "other_cameras": t_other, "lidar": t_lidar,
                   "association": (t1 - t0) * 1e3,
                   "kalman": (t2 - t1) * 1e3, "identification": (t3 - t2) * 1e3,
                   "total": (t3 - t_start) * 1e3}
        debug["lidar"], debug["other_cameras"] = lidar_dets, other_dets
        boxes = {k: [(d.center.copy(), d.size.copy()) for d in debug[k]]
                 for k in ("udepth", "dbscan", "learned", "ensemble", "other_cameras", "lidar")}
        return PerceptionResult(stamp=stamp, seq=frame.seq, obstacles=obstacles,
                                timings_ms=timings, detections=boxes, bad_pixels=n_bad)
