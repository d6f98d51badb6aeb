"""Obstacles in a 3D LiDAR's scan: the LiDAR detector of a rig's ensemble (after LV-DOT, Xu et al. 2025).

LV-DOT adds a LiDAR detector beside DODT's depth detectors; its boxes join the same association and
Kalman tracking. Ours, per scan (``LidarDetector.__call__``):

1. the returns in the world frame (the scan's pose from odometry), kept within ``max_range``
   horizontally (a LiDAR's returns thin out with range: 20,000 points over 360 x 59 deg are about one
   per square degree) and ``min_range`` of the sensor (returns from the vehicle's own frame);
2. floor and ceiling removed: what lies below ``voxel.ground_height`` or above
   ``voxel.ceiling_height`` (the depth detectors' bounds), and outside the geofence shrunk by
   ``wall_margin`` (the corridor's walls and ends, known structure);
3. a voxel filter (``voxel`` m cells, one mean point per cell), then DBSCAN (dodt.dbscan, with this
   detector's ``eps`` and ``min_points``: a LiDAR's points are sparser than a depth image's);
4. known static structure removed: a cluster whose box lies mostly (``structure_fraction``) on voxels the
   static map holds as established structure (``StaticMapView.established_fraction``), or whose
   footprint is wider than ``max_footprint`` (a wall or a shelf, not a person);
5. a box cut by the lowest ray: mounted above the people's heads' height a LiDAR sees the floor only
   from some distance on (at -7 deg from 1.3 m up, from 10 m), so a person near it is seen from the
   waist up. A cluster whose lowest point lies at most ``floor_tolerance`` above the lowest height the
   scan's lowest ray reaches at the cluster's near side is taken to reach the floor (its box extended to
   it), as the camera's moving-track rule does for boxes cut by the image's lower edge.

Returns ``Detection``s with ``source = "lidar"`` (world boxes and their points) and keeps the filtered
cloud (the voxel-filtered points of step 3, before clustering) as ``last_cloud``, which dynamic
identification votes with.
"""
from __future__ import annotations

import math

import numpy as np

from dodt.config import DBSCANConfig, LidarDetectorConfig
from dodt.dbscan import DBSCANDetector
from dodt.detection import Detection
from dodt.frames import LidarScan


def voxel_filter(points: np.ndarray, voxel: float) -> np.ndarray:
    """(M, 3) float32: the mean of the points in each ``voxel``-sized cell, cells in key order."""
    if len(points) == 0:
        return np.empty((0, 3), np.float32)
    cells = np.floor(points / voxel).astype(np.int64)
    cells -= cells.min(axis=0)
    dims = cells.max(axis=0) + 1
    key = (cells[:, 0] * dims[1] + cells[:, 1]) * dims[2] + cells[:, 2]
    uniq, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    sums = np.zeros((len(uniq), 3))
    np.add.at(sums, inverse, points)
    return (sums / counts[:, None]).astype(np.float32)


class LidarDetector:
    """Obstacle boxes from one LiDAR scan (the module's docstring). ``ground_height`` and
    ``ceiling_height`` [m]: the floor and ceiling bounds (DODT's voxel filter's)."""

    def __init__(self, cfg: LidarDetectorConfig, ground_height: float, ceiling_height: float):
        self.cfg = cfg
        self.ground, self.ceiling = float(ground_height), float(ceiling_height)
        self.dbscan = DBSCANDetector(DBSCANConfig(eps=cfg.eps, min_points=cfg.min_points, min_size_xy=0.1,
                                                  split_width=0.8))
        self.last_cloud = np.empty((0, 3), np.float32)

    def filtered_points(self, scan: LidarScan, geofence=None) -> np.ndarray:
        """Steps 1-3 of the module's docstring: the scan's voxel-filtered world points off floor, ceiling
        and walls."""
        c = self.cfg
        P = scan.points_world()
        origin = np.asarray(scan.T_world_sensor, float)[:3, 3]
        r = np.hypot(P[:, 0] - origin[0], P[:, 1] - origin[1])
        keep = (r <= c.max_range) & (np.linalg.norm(P - origin, axis=1) >= c.min_range)
        keep &= (P[:, 2] > self.ground) & (P[:, 2] < self.ceiling)
        if geofence is not None:
            lo, hi = np.asarray(geofence[0], float), np.asarray(geofence[1], float)
            m = c.wall_margin
            keep &= (P[:, 0] > lo[0] + m) & (P[:, 0] < hi[0] - m) & (P[:, 1] > lo[1] + m) & (P[:, 1] < hi[1] - m)
        return voxel_filter(P[keep], c.voxel)

    def __call__(self, scan: LidarScan, static_map=None, geofence=None,
                 elevation_min: float | None = None) -> list[Detection]:
        """Boxes of the obstacles in ``scan``; ``static_map``: a dodt.context.StaticMapView (or None),
        ``geofence``: ((x, y) low, (x, y) high) whose sides are walls (or None), ``elevation_min``: the
        lowest ray's elevation [rad] in the sensor frame (None: no box is extended to the floor)."""
        c = self.cfg
        cloud = self.filtered_points(scan, geofence)
        self.last_cloud = cloud
        dets = self.dbscan(cloud) if len(cloud) else []
        origin = np.asarray(scan.T_world_sensor, float)[:3, 3]
        out = []
        for d in dets:
            if max(d.size[0], d.size[1]) > c.max_footprint:
                continue
            if static_map is not None and static_map.established_fraction(d.center, d.size) >= c.structure_fraction:
                continue
            if elevation_min is not None:
                near = max(float(np.hypot(*(d.center[:2] - origin[:2]))) - 0.5 * max(d.size[0], d.size[1]), 0.0)
                lowest_seen = origin[2] + near * math.tan(elevation_min)
                lo, hi = d.lower, d.upper
                if lo[2] <= max(lowest_seen, self.ground) + c.floor_tolerance:
                    lo = np.array([lo[0], lo[1], 0.0])
                    d = Detection.from_bounds(lo, hi, "lidar", d.points)
            d.source, d.sensor = "lidar", "lidar"
            out.append(d)
        return out
