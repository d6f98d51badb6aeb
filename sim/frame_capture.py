"""From a render to a sensor frame: the depth noise and the sensor's units, and delivery after a latency.

``ImageFinisher`` turns a renderer's raw buffers into what the camera reports: depth with the scenario's
noise, cut to the camera's range, in uint16 millimetres; colour; segmentation as obstacle ids.
``FrameQueue`` holds captured frames until they are due (``frame_latency`` camera periods after their
capture) and delivers each as a SensorFrame with the GroundTruth of its capture.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from numba import njit

from dodt.frames import CameraIntrinsics, SensorFrame
from sim.camera import decode_render
from sim.controller import DroneState
from sim.depth_noise import DepthNoiseModel
from sim.ground_truth import GroundTruth, ObstacleTruth
from sim.scenario_parts import Camera

MAX_DEPTH = 65.535  # m: the largest depth that uint16 millimetres hold


@njit(cache=True, nogil=True)
def _millimetres(z, lo, hi):
    """float32 metres -> uint16 millimetres, rounded to the nearest; 0 outside [lo, hi] (float32 bounds)."""
    out = np.empty(z.shape, np.uint16)
    src, dst = z.reshape(-1), out.reshape(-1)
    for i in range(src.size):
        x = src[i]
        dst[i] = 0 if (x < lo or x > hi) else np.uint16(x * np.float32(1000.0) + np.float32(0.5))
    return out


class ImageFinisher:
    """Draws the depth noise from ``rng``: finish frames in capture order for a repeatable noise stream."""

    def __init__(self, camera: Camera, noise: DepthNoiseModel, rng: np.random.Generator, seg_lut: np.ndarray,
                 color: bool):
        self.camera = camera
        self.noise = noise
        self.rng = rng
        self.seg_lut = seg_lut  # PyBullet body uid + 1 -> obstacle id
        self.color = color
        self.last_images = None  # (depth mm, colour, segmentation) of the last frame finished

    def __call__(self, rgba: np.ndarray, zbuf: np.ndarray, seg_ids: np.ndarray | None):
        """The renderer's buffers -> (depth in mm uint16 with the depth noise, colour or None, segmentation as
        obstacle ids or None)."""
        cam = self.camera
        out = decode_render(rgba, zbuf, seg_ids)
        z = self.noise.apply(out.depth, self.rng)
        depth_mm = _millimetres(z, np.float32(cam.min_range), np.float32(min(cam.max_range, MAX_DEPTH)))
        color = out.color if self.color else None
        seg = None
        if out.segmentation is not None:
            s = out.segmentation
            lut = self.seg_lut
            s = np.where((s >= -1) & (s + 1 < len(lut)), s, -1)
            seg = lut[s + 1]
        self.last_images = (depth_mm, color, seg)
        return depth_mm, color, seg


@dataclass
class Capture:
    """A frame captured and not yet delivered."""
    seq: int
    stamp: float
    images: tuple | None  # (depth mm, colour, segmentation); None: still with the render process
    T_odom: np.ndarray  # the pose the frame carries (odometry)
    T_true: np.ndarray  # the camera's true pose
    T_body: np.ndarray  # the drone's true pose
    state: DroneState
    obstacles: tuple[ObstacleTruth, ...]
    # the rig's other cameras (sim.extra_cameras): (depth mm, T_camera_other: that camera in the first's frame);
    # depth None: drawn by the render process, its images follow the first camera's
    extra: tuple = ()


class FrameQueue:
    """Captured frames in order; each delivered ``latency`` camera periods after its capture."""

    def __init__(self, latency: int, intrinsics: CameraIntrinsics):
        self.latency = latency
        self.intrinsics = intrinsics
        self.pending: list[Capture] = []
        self.frame: SensorFrame | None = None  # the latest delivered
        self.truth: GroundTruth | None = None  # ... and the truth of its capture
        self.extra: tuple[SensorFrame, ...] = ()  # ... and the rig's other cameras' frames of its capture

    def add(self, capture: Capture, fetch: Callable[[int], tuple] | None = None) -> SensorFrame | None:
        """Queue a capture; deliver (and return the last of) those now due. ``fetch(seq)`` gives the images of
        a capture queued without them (the render process's result)."""
        self.pending.append(capture)
        delivered = None
        while self.pending and self.pending[0].seq <= capture.seq - self.latency:
            c = self.pending.pop(0)
            images = c.images
            if images is None:  # rendered beside us, the noise drawn there (in capture order, as in one process)
                images = fetch(c.seq)
            depth_mm, color, seg = images[:3]
            drawn_beside = iter(images[3:])  # the other cameras' images, when the render process drew them
            extra = [(next(drawn_beside) if d is None else d, T_rel) for d, T_rel in c.extra]
            self.frame = SensorFrame(depth=depth_mm, color=color, intrinsics=self.intrinsics,
                                     T_world_camera=c.T_odom, stamp=c.stamp, seq=c.seq)
            self.truth = GroundTruth(stamp=c.stamp, seq=c.seq, obstacles=c.obstacles, T_world_camera=c.T_true,
                                     drone_position=c.state.position, drone_velocity=c.state.velocity,
                                     segmentation=seg, T_world_body=c.T_body)
            self.extra = tuple(SensorFrame(depth=d, color=None, intrinsics=self.intrinsics,
                                           T_world_camera=c.T_odom @ T_rel, stamp=c.stamp, seq=c.seq)
                               for d, T_rel in extra)
            delivered = self.frame
        return delivered
