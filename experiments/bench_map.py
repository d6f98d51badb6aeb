"""The voxel map's update benchmark (``python3 -m experiments.bench_map``; the CLI's ``bench planner``)."""
from __future__ import annotations

import time
from types import SimpleNamespace

import numpy as np

from planner.map.voxel_map import MapConfig, VoxelMap


def bench_update(n: int = 60) -> dict:
    """Median and p95 update time [ms] of 640x480 frames from a camera 1.2 m up flying along a 4 m wide,
    16 m long corridor (floor, side walls, end wall, three boxes, one walker passed as dynamic)."""
    W, H, f, cx, cy = 640, 480, 387.1537, 321.3246, 233.5472  # ref D435i depth intrinsics
    intrinsics = SimpleNamespace(fx=f, fy=f, cx=cx, cy=cy, width=W, height=H)
    boxes = [((-1, -2.2, -0.1), (15, -2.0, 3)), ((-1, 2.0, -0.1), (15, 2.2, 3)), ((15, -2, -0.1), (15.2, 2, 3)),
             ((-1, -2, -0.1), (15, 2, 0.0)), ((4, -1.5, 0), (4.5, -0.9, 1.0)), ((6, 0.8, 0), (6.6, 1.6, 1.8)),
             ((9, -0.5, 0), (9.4, 0.3, 1.2))]
    v, u = np.mgrid[0:H, 0:W]
    R = np.array([[0.0, 0, 1], [-1, 0, 0], [0, -1, 0]])  # optical -> world, looking along +x
    dw = np.stack([(u - cx) / f, (v - cy) / f, np.ones((H, W))], -1) @ R.T  # world rays, planar depth 1
    m, times = VoxelMap(MapConfig(origin=(-1.5, -2.5, -0.1), size=(17.0, 5.0, 3.0))), []
    for it in range(n + 1):
        cam, walker = np.array([0.1 * it, 0.0, 1.2]), np.array([3.0, -1.5 + 0.05 * it, 0.85])
        depth = np.full((H, W), np.inf)
        for lo, hi in boxes + [(walker - (0.25, 0.25, 0.85), walker + (0.25, 0.25, 0.85))]:
            with np.errstate(divide="ignore", invalid="ignore"):
                ta, tb = (np.asarray(lo) - cam) / dw, (np.asarray(hi) - cam) / dw
            tn, tf = np.nanmax(np.minimum(ta, tb), -1), np.nanmin(np.maximum(ta, tb), -1)
            depth = np.where((tn <= tf) & (tn > 0), np.minimum(depth, tn), depth)
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, cam
        depth = np.where(np.isfinite(depth), depth, 0).astype(np.float32)
        t0 = time.perf_counter()
        m.update(depth, intrinsics, T, dynamic_boxes=[(walker, np.array([0.5, 0.5, 1.7]))])
        if it > 0:  # the first call may compile
            times.append((time.perf_counter() - t0) * 1e3)
    out = dict(median_ms=float(np.median(times)), p95_ms=float(np.percentile(times, 95)), n=n)
    print(f"VoxelMap.update 640x480: median {out['median_ms']:.2f} ms, p95 {out['p95_ms']:.2f} ms over {n} frames")
    return out



if __name__ == "__main__":
    bench_update()
