"""A LiDAR's model and mount (sim.lidar simulates its scans): plain data, light to import.

The defaults are the Livox Mid-360's specification (sim.lidar's module docstring states the sources
and the scan pattern these parameters shape).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

GOLDEN_FRACTION = (math.sqrt(5.0) - 1.0) / 2.0  # the golden ratio's fractional part, 0.618...
TOP_MOUNT_HEIGHT = 0.12  # m above the body's centre: the -7 deg edge of the view then clears the drone's box
BELOW_MOUNT_DEPTH = 0.12  # m below the body's centre, upside down: the +7 deg edge then clears the box's bottom


@dataclass(frozen=True)
class LidarModel:
    """A Livox Mid-360-like LiDAR (the defaults: its specification; see the module's docstring). Angles in
    radians in the sensor frame (x forward, y left, z up), ranges in metres."""

    name: str = "mid360-like"
    points_per_scan: int = 20_000  # 200,000 points/s at 10 scans/s
    scan_rate: float = 10.0  # Hz
    horizontal_fov: float = 2.0 * math.pi  # rad: all round
    elevation_min: float = math.radians(-7.0)  # rad
    elevation_max: float = math.radians(52.0)  # rad
    min_range: float = 0.1  # m: the blind zone
    max_range: float = 40.0  # m: at 10 % reflectivity
    range_std: float = 0.02  # m, 1 sigma
    grazing_start: float = math.radians(80.0)  # rad of incidence where dropouts begin (ours)
    grazing_full: float = math.radians(89.0)  # rad of incidence from which every return is dropped (ours)
    channels: int = 4  # beams of the approximated pattern
    spins_per_scan: float = 1.0  # turns of the beams per scan
    zigzags_per_spin: float = 45.0 + GOLDEN_FRACTION  # vertical sweeps per turn: about 1 deg between lines

    def __post_init__(self):
        checks = [
            (self.points_per_scan >= 1, "points_per_scan must be >= 1"),
            (self.scan_rate > 0, "scan_rate must be > 0"),
            (0 < self.horizontal_fov <= 2 * math.pi, "horizontal_fov must lie in (0, 2 pi]"),
            (-math.pi / 2 <= self.elevation_min < self.elevation_max <= math.pi / 2,
             "elevation_min < elevation_max must lie within [-pi/2, pi/2]"),
            (0 <= self.min_range < self.max_range, "0 <= min_range < max_range"),
            (self.range_std >= 0, "range_std must be >= 0"),
            (0 <= self.grazing_start < self.grazing_full <= math.pi / 2,
             "0 <= grazing_start < grazing_full <= pi/2"),
            (self.channels >= 1, "channels must be >= 1"),
            (self.spins_per_scan > 0 and self.zigzags_per_spin > 0, "spins_per_scan and zigzags_per_spin must be > 0"),
        ]
        for ok, why in checks:
            if not ok:
                raise ValueError(f"LidarModel {self.name!r}: {why}")


def upside_down(model: LidarModel) -> LidarModel:
    """The model of the same sensor mounted upside down, its field in the body's (upright) frame: the
    elevations mirrored (a Mid-360's -7 to +52 deg becomes -52 to +7 deg); the scan pattern's shape is
    symmetric, so nothing else changes."""
    return replace(model, elevation_min=-model.elevation_max, elevation_max=-model.elevation_min)


def below_mount(depth: float = BELOW_MOUNT_DEPTH) -> np.ndarray:
    """(4, 4) T_body_sensor of a LiDAR hung under the body, ``depth`` m below its centre, x forward, its frame
    kept upright (the field of an upside-down sensor is upside_down(model)'s). Its highest rays (+7 deg)
    pass under the drone's box (its bottom lies 0.06 m below the centre) to the box's corners."""
    T = np.eye(4)
    T[2, 3] = -depth
    return T


def top_mount(height: float = TOP_MOUNT_HEIGHT) -> np.ndarray:
    """(4, 4) T_body_sensor of a LiDAR on top of the body, ``height`` m above its centre, x forward.

    Rays meet the drone's own collision box (its top lies 0.06 m above the centre) when the mount is lower
    than about 0.113 m: the lowest rays (-7 deg) then return points on it, as a real sensor sees its carrier.
    A sensor inside a collision shape does not see that shape (a ray leaving a convex shape does not hit it)."""
    T = np.eye(4)
    T[2, 3] = height
    return T


