"""Sensor rigs: which sensors a drone carries and where (``--rig``, episode.rig).

A rig is a tuple of ``SensorMount``s: cameras (the scenario's RGB-D camera model, each turned about the
body's z axis by its ``yaw``) and LiDARs (sim.lidar's Mid-360-like model on top of the body, or upside down
under it). The named rigs:

- ``front``: the paper's one forward D435-class camera (the default);
- ``front_back``: that camera and one looking back;
- ``surround4``: four cameras 90 deg apart (87 deg each: the horizon with small overlaps);
- ``lidar``: a Mid-360-like LiDAR on top of the body and the forward camera;
- ``lidar_below``: the same LiDAR upside down under the body (-52 to +7 deg) and the forward camera. On top,
  the lowest ray (-7 deg) passes over a person beside the drone: flying at 1.6 m, over the heads of most
  people within 1 m; under the body, the field reaches the floor a metre away.

Every camera renders at the scenario's camera rate, a LiDAR scans at its model's rate (10 Hz).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim.lidar_model import LidarModel, below_mount, top_mount, upside_down


LIDAR_MOUNTS = ("top", "below")


def mounted_model(mount: str) -> LidarModel:
    """The Mid-360-like defaults as mounted: on top, or upside down under the body (the field mirrored)."""
    return LidarModel() if mount == "top" else upside_down(LidarModel())


@dataclass(frozen=True)
class SensorMount:
    """One sensor of a rig: ``kind`` "camera" or "lidar", its name, and its yaw on the body [deg]
    (cameras: the optical axis' heading from the body's x axis; a LiDAR: its x axis'); a LiDAR's ``mount``:
    "top" (on top of the body) or "below" (upside down under it)."""

    kind: str
    name: str
    yaw: float = 0.0
    lidar: LidarModel | None = None  # a LiDAR's model, its field in the body's frame (None: sim.lidar_model's
    # Mid-360-like defaults, upside_down under the body)
    mount: str = "top"

    def __post_init__(self):
        if self.kind not in ("camera", "lidar"):
            raise ValueError(f"sensor {self.name!r}: kind must be 'camera' or 'lidar', got {self.kind!r}")
        if not (isinstance(self.yaw, (int, float)) and math.isfinite(self.yaw) and -360.0 <= self.yaw <= 360.0):
            raise ValueError(f"sensor {self.name!r}: yaw must be a finite angle in [-360, 360] deg, got {self.yaw!r}")
        if self.mount not in LIDAR_MOUNTS:
            raise ValueError(f"sensor {self.name!r}: mount must be one of {', '.join(LIDAR_MOUNTS)}, "
                             f"got {self.mount!r}")

    def lidar_model(self) -> LidarModel:
        return mounted_model(self.mount) if self.lidar is None else self.lidar

    def T_body_lidar(self) -> np.ndarray:
        """The LiDAR's frame in the body frame: on top or under the body (``mount``), turned by ``yaw``."""
        T = top_mount() if self.mount == "top" else below_mount()
        T[:3, :3] = yaw_matrix(self.yaw)
        return T


def yaw_matrix(yaw_deg: float) -> np.ndarray:
    """The rotation about z by ``yaw_deg`` degrees."""
    a = math.radians(yaw_deg)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def camera_mount(T_body_camera: np.ndarray, yaw_deg: float) -> np.ndarray:
    """(4, 4) a camera mounted like ``T_body_camera``, turned about the body's z axis by ``yaw_deg``."""
    T = np.eye(4)
    R = yaw_matrix(yaw_deg)
    T_bc = np.asarray(T_body_camera, dtype=np.float64)
    T[:3, :3] = R @ T_bc[:3, :3]
    T[:3, 3] = R @ T_bc[:3, 3]
    return T


def frames_per_scan(camera_rate: float, model: LidarModel) -> int:
    """Camera frames per LiDAR scan: the loop scans every this many frames."""
    return max(1, int(round(camera_rate / model.scan_rate)))


RIGS: dict[str, tuple[SensorMount, ...]] = {
    "front": (SensorMount("camera", "front"),),
    "front_back": (SensorMount("camera", "front"), SensorMount("camera", "back", 180.0)),
    "surround4": (SensorMount("camera", "front"), SensorMount("camera", "left", 90.0),
                  SensorMount("camera", "back", 180.0), SensorMount("camera", "right", -90.0)),
    "lidar": (SensorMount("camera", "front"), SensorMount("lidar", "top")),
    "lidar_below": (SensorMount("camera", "front"), SensorMount("lidar", "below", mount="below")),
}
RIG_NAMES = tuple(RIGS)


def rig(name: str) -> tuple[SensorMount, ...]:
    """The named rig's sensors (ValueError naming the rigs for an unknown name)."""
    try:
        return RIGS[name]
    except KeyError:
        raise ValueError(f"unknown rig {name!r}; the rigs are {', '.join(RIG_NAMES)}") from None


def rig_of(name: str | None, scenario) -> tuple[str, tuple[SensorMount, ...]]:
    """(the rig's name, its sensors): the named rig, or with ``name`` None the scenario's [[sensors]]
    ("scenario") if it declares them, else ``front``."""
    if name is None:
        return ("scenario", scenario.sensors) if scenario.sensors else ("front", RIGS["front"])
    return name, rig(name)


def cameras(sensors) -> tuple[SensorMount, ...]:
    return tuple(s for s in sensors if s.kind == "camera")


def lidars(sensors) -> tuple[SensorMount, ...]:
    return tuple(s for s in sensors if s.kind == "lidar")
