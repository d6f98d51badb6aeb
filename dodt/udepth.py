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


@njit(cache=True, nogil=True)
def _u_map(half, lo, hi, bw, bins, col_scale, fx, fy, cx, cy, R, t, zlo, zhi):
    """Column histograms of depth; with zlo < zhi, pixels whose world height lies outside
    [zlo, zhi] (the floor, the ceiling) are left out. A pixel's height is linear in its depth:
    z = d (row term + column term) + t_z."""
    cols_idx = np.arange(half.shape[1])
    return _u_map_columns(half, cols_idx, lo, hi, bw, bins, col_scale, fx, fy, cx, cy, R, t, zlo, zhi)


@njit(cache=True, nogil=True)
def _bins_of_row(d_row, row_term, col_term, tz, lo, hi, bw, bins, zlo, zhi, band, out):
    """The U-map bin of each pixel of one row, -1 for a pixel left out. Branch-free, so that
    the compiler can vectorise it."""
    for c in range(d_row.shape[0]):
        d = d_row[c]
        z = d * (row_term + col_term[c]) + tz
        outside = (z < zlo) | (z > zhi)
        ok = (d > lo) & (d < hi) & ((not band) | (not outside))
        out[c] = min(np.int64((d - lo) / bw if ok else -1.0), bins - 1)


@njit(cache=True, nogil=True)
def _u_map_columns(depth, cols_idx, lo, hi, bw, bins, col_scale, fx, fy, cx, cy, R, t, zlo, zhi):
    """_u_map of the image made of the columns ``cols_idx`` of ``depth``, read in place."""
    rows = depth.shape[0]
    cols = cols_idx.shape[0]
    U = np.zeros((bins, cols), np.float32)
    band = zlo < zhi
    col_term = np.empty(cols)
    for c in range(cols):
        col_term[c] = R[2, 0] * (c / col_scale - cx) / fx
    d_row = np.empty(cols)
    b_row = np.empty(cols, np.int64)
    for r in range(rows):
        row_term = R[2, 1] * (r - cy) / fy + R[2, 2]
        for c in range(cols):
            d_row[c] = depth[r, cols_idx[c]]
        _bins_of_row(d_row, row_term, col_term, t[2], lo, hi, bw, bins, zlo, zhi, band, b_row)
        for c in range(cols):
            b = b_row[c]
            if b >= 0 and U[b, c] < 255.0:  # the reference map saturates at 255 (8-bit)
                U[b, c] += 1.0
    return U


@njit(cache=True, nogil=True)
def _kth_smallest(a, k):
    """np.partition(a, k)[k], the k-th smallest value (0-based), for k near either end of a
    (a percentile of a few per cent) from a part of a: a threshold t is read off a small sorted
    sample so that the values <= t (or >= t) hold the k-th smallest; when they do (counted, not
    assumed), it is selected among them, else (and for an array with NaN) in the whole array."""
    n = a.shape[0]
    if n < 128 or k < 0 or k >= n or 4 * min(k + 1, n - k) > n:
        return np.partition(a, k)[k]
    s = 32
    stride = n // s
    sample = np.empty(s)
    for i in range(s):
        sample[i] = a[i * stride]
    sample.sort()
    part = np.empty(n)
    m = 0
    nan = False
    if 2 * k < n:
        # the values <= t: the k-th smallest is among them once there are k + 1 of them
        t = sample[min((k + 1) * s // n + 4, s - 1)]
        for i in range(n):
            x = a[i]
            part[m] = x
            m += x <= t
            nan |= x != x
        if nan or m < k + 1:
            return np.partition(a, k)[k]
        r = np.partition(part[:m], k)[k]
    else:
        # the values >= t: with at most k values below t, the k-th smallest is among them, at k - below
        t = sample[max(k * s // n - 4, 0)]
        for i in range(n):
            x = a[i]
            part[m] = x
            m += x >= t
            nan |= x != x
        below = n - m
        if nan or below > k:
            return np.partition(a, k)[k]
        r = np.partition(part[:m], k - below)[k - below]
    # equal values are the same value, but for -0.0 and 0.0, which np.partition may order otherwise
    return np.partition(a, k)[k] if r == 0.0 else r


@njit(cache=True, nogil=True)
def _box_points(depth, u0, u1, near, far, run_len, margin, step, fx, fy, cx, cy, R, t, q):
    """Pixels of columns [u0, u1) whose depth lies in [near, far] within vertical runs of at
    least run_len rows; every step-th of them back-projected to the world. Returns (n, lo, hi)
    with lo, hi the q-th and (100-q)-th percentiles per axis."""
    H = depth.shape[0]
    cap = ((u1 - u0) // step + 1) * (H // step + 1)
    xs = np.empty(cap)
    ys = np.empty(cap)
    zs = np.empty(cap)
    n = 0
    for u in range(u0, u1, step):
        v = margin
        while v < H - margin:
            d = depth[v, u]
            if d >= near and d <= far:
                start = v
                while v < H - margin and depth[v, u] >= near and depth[v, u] <= far:
                    v += 1
                if v - start >= run_len:
                    for r in range(start, v, step):
                        z = depth[r, u]
                        xc = (u - cx) * z / fx
                        yc = (r - cy) * z / fy
                        xs[n] = R[0, 0] * xc + R[0, 1] * yc + R[0, 2] * z + t[0]
                        ys[n] = R[1, 0] * xc + R[1, 1] * yc + R[1, 2] * z + t[1]
                        zs[n] = R[2, 0] * xc + R[2, 1] * yc + R[2, 2] * z + t[2]
                        n += 1
            else:
                v += 1
    lo = np.zeros(3)
    hi = np.zeros(3)
    if n == 0:
        return 0, lo, hi
    k_lo = int(q / 100.0 * (n - 1))
    k_hi = int((100.0 - q) / 100.0 * (n - 1))
    for a, arr in enumerate((xs[:n], ys[:n], zs[:n])):
        lo[a] = _kth_smallest(arr, k_lo)
        hi[a] = _kth_smallest(arr, k_hi)
    return n, lo, hi


@njit(cache=True, nogil=True)
def _rect_boxes(depth, rects, bw, min_area, min_dist, occlusion_factor, col_scale, margin, run_len, fx, fy, cx,
                cy, R, t, q):
    """_box_points of each U-map rectangle (left, right, first bin, last bin): its columns of the
    image between its near and far depth. Returns (n, lo, hi) per rectangle, n = 0 for one too
    small or without columns."""
    H, W = depth.shape
    m = rects.shape[0]
    n_out = np.zeros(m, np.int64)
    lo_out = np.zeros((m, 3))
    hi_out = np.zeros((m, 3))
    for i in range(m):
        left, right, b0, b1 = rects[i, 0], rects[i, 1], rects[i, 2], rects[i, 3]
        if (right - left) * (b1 - b0) < min_area:
            continue
        near = b0 * bw + min_dist
        far = near + occlusion_factor * (b1 - b0 + 1) * bw
        u0 = max(int(left / col_scale), margin)
        u1 = min(int((right + 1) / col_scale), W - margin)
        if u1 <= u0:
            continue
        # sample about 3000 pixels at most: wide boxes (walls) would cost milliseconds
        step = max(2, int(math.sqrt((u1 - u0) * H / 3000.0)) + 1)
        n, lo, hi = _box_points(depth, u0, u1, near, far, run_len, margin, step, fx, fy, cx, cy, R, t, q)
        n_out[i] = n
        lo_out[i] = lo
        hi_out[i] = hi
    return n_out, lo_out, hi_out


class UDepthDetector:
    def __init__(self, cfg: UDepthConfig, depth_cfg: DepthConfig, height_band: tuple[float, float] | None = None):
        """``height_band``: (floor, ceiling) world heights [m]; pixels outside it stay out of the
        U-depth map when ``cfg.height_filter`` is on (the pipeline passes the voxel filter's
        ground and ceiling heights)."""
        self.cfg = cfg
        self.dcfg = depth_cfg
        self.height_band = height_band
        self._columns: dict[tuple[int, int], np.ndarray | None] = {}  # (H, W) -> _half_columns

    def u_map(self, depth_m: np.ndarray, K: CameraIntrinsics | None = None,
              T_world_camera: np.ndarray | None = None) -> tuple[np.ndarray, float, np.ndarray]:
        """(bins, W/2) float32 U-depth map, the bin width [m] and the half-width depth image.
        With K and the pose, the height band (if any) applies."""
        H, W = depth_m.shape
        half = cv2.resize(depth_m, (int(W * self.cfg.col_scale), H), interpolation=cv2.INTER_NEAREST)
        U, bw = self._u_map(depth_m, K, T_world_camera, half)
        return U, bw, half

    def _half_columns(self, H: int, W: int) -> np.ndarray | None:
        """The columns of a (H, W) image that cv2.resize's nearest neighbour keeps at the half
        width (found by resizing an image of column numbers, once per size), or None when the
        resize does not simply pick columns."""
        key = (H, W)
        if key not in self._columns:
            w = int(W * self.cfg.col_scale)
            cols = None
            if 0 < W < 1 << 24:
                numbers = np.broadcast_to(np.arange(W, dtype=np.float32), (H, W))
                picked = cv2.resize(np.ascontiguousarray(numbers), (w, H), interpolation=cv2.INTER_NEAREST)
                if picked.shape == (H, w) and np.all(picked == picked[:1]):
                    cols = picked[0].astype(np.int64)
            self._columns[key] = cols
        return self._columns[key]

    def _u_map(self, depth_m: np.ndarray, K: CameraIntrinsics | None, T_world_camera: np.ndarray | None,
               half: np.ndarray | None = None) -> tuple[np.ndarray, float]:
        """(U-depth map, bin width) as ``u_map``; without ``half`` the half-width image's
        columns are read from ``depth_m`` in place (the same pixels, no resized copy)."""
        c = self.cfg
        H, W = depth_m.shape
        cols = None
        if half is None:
            cols = self._half_columns(H, W)
            if cols is None:
                half = cv2.resize(depth_m, (int(W * c.col_scale), H), interpolation=cv2.INTER_NEAREST)
        bins = H // c.row_downsample
        lo, hi = c.min_dist, self.dcfg.depth_max
        bw = math.ceil((hi - lo) * 1000.0 / bins) / 1000.0
        zlo, zhi = (0.0, 0.0)  # empty band: no height filter
        R, t = np.eye(3), np.zeros(3)
        fx = fy = 1.0
        cx = cy = 0.0
        if c.height_filter and self.height_band is not None and K is not None and T_world_camera is not None:
            zlo, zhi = self.height_band
            R = np.ascontiguousarray(T_world_camera[:3, :3], dtype=np.float64)
            t = np.ascontiguousarray(T_world_camera[:3, 3], dtype=np.float64)
            fx, fy, cx, cy = K.fx, K.fy, K.cx, K.cy
        if cols is not None:
            U = _u_map_columns(depth_m, cols, lo, hi, bw, bins, float(cols.shape[0]) / W, fx, fy, cx, cy, R, t,
                               float(zlo), float(zhi))
        else:
            U = _u_map(half, lo, hi, bw, bins, float(half.shape[1]) / W, fx, fy, cx, cy, R, t, float(zlo), float(zhi))
        U = cv2.GaussianBlur(U, c.blur_size, c.blur_sigma)
        return U, bw

    def __call__(self, depth_m: np.ndarray, K: CameraIntrinsics, T_world_camera: np.ndarray) -> list[Detection]:
        c = self.cfg
        U, bw = self._u_map(depth_m, K, T_world_camera)
        rects = _group_lines(U, float(c.threshold_point * c.row_downsample), c.min_line_length)
        R = np.ascontiguousarray(T_world_camera[:3, :3], dtype=np.float64)
        t = np.ascontiguousarray(T_world_camera[:3, 3], dtype=np.float64)
        depth_m = np.ascontiguousarray(depth_m, dtype=np.float32)
        n, lo, hi = _rect_boxes(depth_m, rects, bw, c.min_area, c.min_dist, c.occlusion_factor, c.col_scale,
                                self.dcfg.margin, c.continuity_rows + 1, K.fx, K.fy, K.cx, K.cy, R, t,
                                c.extent_percentile)
        return [Detection.from_bounds(lo[i], hi[i], "udepth") for i in range(len(rects))
                if not (n[i] < 20 or hi[i, 2] - lo[i, 2] < c.min_height)]
