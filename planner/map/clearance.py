"""Static clearance on the map's column grid: metres from each column's centre to the edge of the
nearest blocked column (which columns count as blocked, and at which altitudes, is the caller's choice).
The cells whose centres lie outside the geofence, the known walls of the flight area, count as blocked.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from planner.map.distance import exact_distance


def outside_geofence(shape: tuple[int, int], origin_xy, resolution: float, geofence) -> np.ndarray:
    """(nx, ny) bool: the cells of a grid at origin_xy whose centres lie outside the geofence
    (lo (2,), hi (2,)) in x or y."""
    lo, hi = (np.asarray(x, float).reshape(-1)[:2] for x in geofence)
    cx = origin_xy[0] + (np.arange(shape[0]) + 0.5) * resolution
    cy = origin_xy[1] + (np.arange(shape[1]) + 0.5) * resolution
    return ((cx < lo[0]) | (cx > hi[0]))[:, None] | ((cy < lo[1]) | (cy > hi[1]))[None, :]


def static_clearance(blocked: np.ndarray, resolution: float, origin_xy=None, geofence=None,
                     distance: Callable[[np.ndarray], np.ndarray] = exact_distance) -> np.ndarray:
    """(nx, ny) metres from each column centre to the nearest blocked column's edge; 1e3 everywhere when
    no column is blocked. With a geofence (origin_xy given too), the cells outside it count as blocked.
    distance: the transform, in cells (planner.map.distance: exact_distance, or opencv_distance, the
    shield's)."""
    blocked = np.asarray(blocked, dtype=bool)
    if geofence is not None:
        blocked = blocked | outside_geofence(blocked.shape, origin_xy, resolution, geofence)
    if not blocked.any():
        return np.full(blocked.shape, 1e3)
    return distance(blocked) * resolution - 0.5 * resolution
