"""U-depth detector (paper Sec. III-A; ref uvDetector.cpp).

1. U-depth map: for every column of the (half-width) depth image, a histogram of its depths:
   U[bin, column] counts the pixels of that column whose depth falls in that bin. An upright
   obstacle puts many pixels of a column at one depth, a bright line in the map.
2. Line grouping: runs of strong cells along each depth bin (row of the map) become line
   segments; segments of neighbouring bins that overlap in columns are joined into one group;
   each group's rectangle gives the obstacle's columns (width) and depth range (thickness).
3. Depth continuity: in those columns of the full depth image, pixels within the group's depth
   range that belong to vertical runs of continuous depth give the obstacle's rows (height).
The pixels found are back-projected and transformed to the world; the box spans their robust
extent (2nd-98th percentiles). The reference code instead builds the box from the rectangles'
pixel extents at the mean depth.
"""
from __future__ import annotations

import math

import cv2
import numpy as np
from numba import njit

from dodt.config import DepthConfig, UDepthConfig
from dodt.detection import Detection
from dodt.frames import CameraIntrinsics


@njit(cache=True, nogil=True)
def _group_lines(U, u_min, min_len):
    """Runs of cells >= u_min per row, merged across rows when their columns overlap.

    Returns (M, 4) int32 rows: left column, right column (inclusive), first row, last row.
    """
    rows, cols = U.shape
    max_runs = rows * (cols // 2 + 1)
    run_row = np.empty(max_runs, np.int32)
    run_l = np.empty(max_runs, np.int32)
    run_r = np.empty(max_runs, np.int32)
    parent = np.empty(max_runs, np.int32)
    label_prev = -np.ones(cols, np.int32)
    label_cur = -np.ones(cols, np.int32)
    n = 0
    for r in range(rows):
        for c in range(cols):
            label_cur[c] = -1
        c = 0
        while c < cols:
            if U[r, c] >= u_min:
                start = c
                s = 0.0
                mx = 0.0
                while c < cols and U[r, c] >= u_min:
                    s += U[r, c]
                    if U[r, c] > mx:
                        mx = U[r, c]
                    c += 1
                if c - start > min_len and s > 2.0 * mx:
                    run_row[n] = r
                    run_l[n] = start
                    run_r[n] = c - 1
                    parent[n] = n
                    for k in range(start, c):
                        label_cur[k] = n
                        p = label_prev[k]
                        if p >= 0:  # union with the overlapping run of the previous row
                            a = n
                            while parent[a] != a:
                                a = parent[a]
                            b = p
                            while parent[b] != b:
                                b = parent[b]
                            if a != b:
                                if a < b:
                                    parent[b] = a
                                else:
                                    parent[a] = b
                    n += 1
            else:
                c += 1
        for k in range(cols):
            label_prev[k] = label_cur[k]
    # rectangles per root
    out = np.empty((n, 4), np.int32)
    root_slot = -np.ones(n, np.int32)
    m = 0
    for i in range(n):
        a = i
        while parent[a] != a:
            a = parent[a]
        if root_slot[a] < 0:
            root_slot[a] = m
            out[m, 0] = run_l[i]
            out[m, 1] = run_r[i]
            out[m, 2] = run_row[i]
            out[m, 3] = run_row[i]
            m += 1
        else:
            j = root_slot[a]
            out[j, 0] = min(out[j, 0], run_l[i])
            out[j, 1] = max(out[j, 1], run_r[i])
            out[j, 2] = min(out[j, 2], run_row[i])
            out[j, 3] = max(out[j, 3], run_row[i])
    return out[:m]


class UDepthDetector:
    def __init__(self, cfg: UDepthConfig, depth_cfg: DepthConfig):
        self.cfg = cfg
        self.dcfg = depth_cfg
        self._kernel = np.ones((cfg.continuity_rows + 1, 1), np.uint8)

    def u_map(self, depth_m: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
        """(bins, W/2) float32 U-depth map, the bin width [m] and the half-width depth image."""
        c = self.cfg
        H, W = depth_m.shape
        half = cv2.resize(depth_m, (int(W * c.col_scale), H), interpolation=cv2.INTER_NEAREST)
        bins = H // c.row_downsample
        lo, hi = c.min_dist, self.dcfg.depth_max
        bw = math.ceil((hi - lo) * 1000.0 / bins) / 1000.0
        Wh = half.shape[1]
        valid = (half > lo) & (half < hi)
        b = ((half[valid] - lo) / bw).astype(np.int64)
        np.minimum(b, bins - 1, out=b)
        cols = np.nonzero(valid)[1]
        U = np.bincount(b * Wh + cols, minlength=bins * Wh).reshape(bins, Wh).astype(np.float32)
        np.minimum(U, 255.0, out=U)  # the reference map saturates at 255 (8-bit)
        U = cv2.GaussianBlur(U, c.blur_size, c.blur_sigma)
        return U, bw, half

    def __call__(self, depth_m: np.ndarray, K: CameraIntrinsics, T_world_camera: np.ndarray) -> list[Detection]:
        c = self.cfg
        U, bw, half = self.u_map(depth_m)
        rects = _group_lines(U, float(c.threshold_point * c.row_downsample), c.min_line_length)
        dets = []
        H, W = depth_m.shape
        R, t = T_world_camera[:3, :3], T_world_camera[:3, 3]
        margin = self.dcfg.margin
        for left, right, b0, b1 in rects:
            if (right - left) * (b1 - b0) < c.min_area:
                continue
            near = b0 * bw + c.min_dist
            far = near + c.occlusion_factor * (b1 - b0 + 1) * bw
            u0 = max(int(left / c.col_scale), margin)
            u1 = min(int((right + 1) / c.col_scale), W - margin)
            if u1 <= u0:
                continue
            sub = depth_m[:, u0:u1]
            mask = ((sub >= near) & (sub <= far)).astype(np.uint8)
            mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, self._kernel)  # vertical runs >= continuity_rows+1
            mask[:margin] = 0
            mask[H - margin:] = 0
            vs, us = np.nonzero(mask[::2, ::2])
            if vs.size < 20:
                continue
            vs, us = vs * 2, us * 2 + u0
            d = depth_m[vs, us]
            pc = K.backproject(us, vs, d)
            pw = pc @ R.T + t
            q = c.extent_percentile
            lo = np.percentile(pw, q, axis=0)
            hi = np.percentile(pw, 100 - q, axis=0)
            dets.append(Detection.from_bounds(lo, hi, "udepth"))
        return dets
