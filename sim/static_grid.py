"""The scenario's static geometry as a voxel grid: what a map built from perfect sensing would hold.

A voxel is occupied when it overlaps a solid of the world the simulator builds (``sim.scene``): the
floor slab, the side and end walls, the ceiling when there is one, and each obstacle's footprint up
to its height (a shelf counts as solid: its boards and posts leave no gap a drone fits through).
People are not static and are left out. Used to plan against a known map (``dodt-nav run --map
truth``), which isolates a planner from the mapping and skips rendering.
"""
from __future__ import annotations

import numpy as np

from sim.scenario import Scenario

WALL_THICKNESS = 0.1  # m, as sim.world builds the corridor


def static_occupancy(scenario: Scenario, origin, dims, resolution: float) -> np.ndarray:
    """(nx, ny, nz) bool over voxels origin + resolution * [i, i + 1) per axis: True where a voxel
    overlaps a static solid of ``scenario``."""
    origin = np.asarray(origin, dtype=float).reshape(3)
    dims = tuple(int(d) for d in np.asarray(dims).reshape(3))
    r = float(resolution)
    lo = [origin[a] + r * np.arange(dims[a]) for a in range(3)]  # voxel lower faces per axis
    occ = np.zeros(dims, bool)

    def box(b_lo, b_hi):  # voxels overlapping the open box (b_lo, b_hi)
        sl = []
        for a in range(3):
            m = np.flatnonzero((lo[a] < b_hi[a]) & (lo[a] + r > b_lo[a]))
            if len(m) == 0:
                return
            sl.append(slice(m[0], m[-1] + 1))
        occ[tuple(sl)] = True

    co, t = scenario.corridor, WALL_THICKNESS
    L, W, H = co.length, co.width, co.height
    box((-t, -W / 2 - t, -t), (L + t, W / 2 + t, 0.0))  # floor
    for side in (-1, 1):
        y0 = W / 2 if side > 0 else -W / 2 - t
        box((-t, y0, -t), (L + t, y0 + t, H))
    box((-t, -W / 2, -t), (0.0, W / 2, H))  # end walls
    box((L, -W / 2, -t), (L + t, W / 2, H))
    if co.ceiling:
        box((-t, -W / 2 - t, H), (L + t, W / 2 + t, H + t))
    # obstacles: voxel columns whose square overlaps the footprint (its centre within the footprint
    # grown by half a voxel's diagonal is a close, slightly generous test), up to the obstacle's height
    cx, cy = lo[0] + r / 2, lo[1] + r / 2
    for o in scenario.obstacles:
        olo, ohi = o.aabb()
        ix = np.flatnonzero((cx > olo[0] - r) & (cx < ohi[0] + r))
        iy = np.flatnonzero((cy > olo[1] - r) & (cy < ohi[1] + r))
        iz = np.flatnonzero((lo[2] < ohi[2]) & (lo[2] + r > 0.0))
        if not (len(ix) and len(iy) and len(iz)):
            continue
        gx, gy = np.meshgrid(cx[ix], cy[iy], indexing="ij")
        inside = o.footprint_contains(np.column_stack([gx.ravel(), gy.ravel()]), r / np.sqrt(2)).reshape(gx.shape)
        ii, jj = np.nonzero(inside)
        occ[ix[ii], iy[jj], iz[0]:iz[-1] + 1] = True
    return occ
