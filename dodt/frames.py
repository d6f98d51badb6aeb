"""Sensor-side messages: what a robot (real or simulated) hands to perception.

Only what a real robot has: depth, optional color, intrinsics, the camera pose from
odometry and a timestamp; a LiDAR's returns with the sensor pose from odometry and a
timestamp. Ground truth never travels in these messages.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# D435i depth stream at 640x480 as used by the DODT authors
# (onboard_detector cfg/detector_param.yaml, `depth_intrinsics`).
D435I_DEPTH_FX = 387.1537
D435I_DEPTH_FY = 387.1537
D435I_DEPTH_CX = 321.3246
D435I_DEPTH_CY = 233.5472


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics, pixel centres at integer coordinates (OpenCV / librealsense).

    A point (X, Y, Z) in the optical frame (x right, y down, z forward) projects to
    u = fx X / Z + cx, v = fy Y / Z + cy, with u the column and v the row.
    """

    width: int = 640
    height: int = 480
    fx: float = D435I_DEPTH_FX
    fy: float = D435I_DEPTH_FY
    cx: float = D435I_DEPTH_CX
    cy: float = D435I_DEPTH_CY

    def matrix(self) -> np.ndarray:
        """The 3x3 camera matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def backproject(self, u: np.ndarray, v: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Pixels (u, v) with planar depth z [m] -> (N, 3) points in the optical frame."""
        z = np.asarray(z, dtype=np.float64)
        x = (np.asarray(u, dtype=np.float64) - self.cx) * z / self.fx
        y = (np.asarray(v, dtype=np.float64) - self.cy) * z / self.fy
        return np.stack([x, y, z], axis=-1)

    def project(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) optical-frame points -> (N, 2) pixel coordinates (u, v)."""
        p = np.asarray(points, dtype=np.float64)
        return np.stack([self.fx * p[:, 0] / p[:, 2] + self.cx, self.fy * p[:, 1] / p[:, 2] + self.cy], axis=1)


@dataclass(frozen=True, eq=False)
class SensorFrame:
    """One RGB-D frame as a robot sees it.

    depth: (H, W) uint16 millimetres (0 = invalid), as a RealSense reports it; or float32
        metres (0 or NaN = invalid) for recorded data already converted.
    color: (H, W, 3) uint8 RGB aligned to depth, or None.
    intrinsics: the depth camera's intrinsics (color is aligned to depth).
    T_world_camera: (4, 4) pose of the optical frame in the world from odometry.
    stamp: time of capture [s].
    seq: frame counter.
    """

    depth: np.ndarray
    color: np.ndarray | None
    intrinsics: CameraIntrinsics
    T_world_camera: np.ndarray
    stamp: float
    seq: int = 0
    depth_scale: float = 0.001  # metres per unit of a uint16 depth image

    def depth_m(self) -> np.ndarray:
        """Depth as float32 metres with 0 for invalid pixels."""
        return self.depth_m_counted()[0]

    def depth_m_counted(self) -> tuple[np.ndarray, int]:
        """(depth as float32 metres with 0 for invalid pixels, how many NaN / inf / negative
        pixels were made 0). A uint16 image has none."""
        if self.depth.dtype == np.uint16:
            return self.depth.astype(np.float32) * np.float32(self.depth_scale), 0
        d = self.depth.astype(np.float32, copy=True)
        bad = ~np.isfinite(d) | (d < 0)
        n_bad = int(np.count_nonzero(bad))
        if n_bad:
            d[bad] = 0.0
        return d, n_bad


@dataclass(frozen=True, eq=False)
class LidarScan:
    """One scan of a 3D LiDAR as a robot sees it: its returns, one row per point.

    Sensor frame: x forward, y left, z up (the Livox convention). A ray's direction is
    (cos el cos az, cos el sin az, sin el) for azimuth az (from x towards y) and elevation el
    (up from the xy plane); its point is ``ranges * direction``. Rays that gave no return
    (nothing within range, the blind zone, a dropout) have no row.

    points: (N, 3) float32 metres, the returns in the sensor frame.
    ranges: (N,) float32 metres from the sensor's origin.
    azimuth, elevation: (N,) float32 radians of each return's ray.
    stamp: time of the scan [s].
    T_world_sensor: (4, 4) pose of the sensor frame in the world from odometry.
    seq: scan counter.
    n_rays: rays the scan cast, returns and misses together (>= N).
    """

    points: np.ndarray
    ranges: np.ndarray
    azimuth: np.ndarray
    elevation: np.ndarray
    stamp: float
    T_world_sensor: np.ndarray
    seq: int = 0
    n_rays: int = 0

    def __len__(self) -> int:
        return int(self.ranges.shape[0])

    def points_world(self) -> np.ndarray:
        """(N, 3) float64 returns in the world frame, through ``T_world_sensor``."""
        T = self.T_world_sensor
        return self.points.astype(np.float64) @ T[:3, :3].T + T[:3, 3]
