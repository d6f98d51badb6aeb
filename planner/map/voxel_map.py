"""Log-odds occupancy voxel map with dynamic-region clearing (after the DODT authors' map_manager).

Sources: shared/reference/dodt-reference-code.md section 10; "ref" below = map_manager's
occupancyMap/dynamicMap code and yaml, "ours" = chosen here, with the reason beside it.

Each depth frame is ray-cast into a fixed world grid by one compiled kernel: every sampled pixel's ray
is walked voxel by voxel (Amanatides & Woo) from its endpoint back toward the camera, counting a hit at
the endpoint and a miss in each voxel crossed; then each touched voxel takes one log-odds step. A ray
stops at a voxel already crossed this frame (ref), so converging rays are not walked twice; ours limits
"already crossed" to rays of the same small pixel block, since the reference rule (any ray of the frame)
leaves much of the frustum uncarved in a frame (rays of distant pixels diverge after sharing a voxel;
docs/experiments.md). Boxes of dynamic obstacles free their region (grown by a margin, from the map's
floor up) and, for a few frames, keep depth points inside it from being inserted: a walker leaves no
trail. Ours: a voxel is left alone by both rules when it has been occupied for ``static_after`` updates,
or when it was occupied for ``protect_before`` updates already when a dynamic region first came over it
(it stays so while regions keep covering it). The reference frees everything in the region, so a person
walking past a shelf or a pillar erases its near face from the map, and then a drone flies into it; a
walker's own voxels are as young as its box when the box first covers them. Also ours: a region frees
observed voxels only (unknown ones stay unknown), and a depth point inside it counts as neither hit nor
miss, so structure a person stands beside before it was ever seen stays unknown, not seen free.
Voxel (i, j, k) covers origin + res * [i, i + 1) per axis. No result depends on the wall clock.
"""
from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass

import cv2
import numpy as np
from numba import njit


def _logit(p: float) -> float:
    """log(p / (1 - p)), rounded to float32 as the map stores it, so that every comparison agrees."""
    return float(np.float32(math.log(p / (1.0 - p))))


MAX_MAP_CELLS = 50_000_000  # voxels: a map's arrays take about 20 bytes a voxel, so 1 GB at most


@dataclass(frozen=True)
class MapConfig:
    resolution: float = 0.1  # m, ref map_resolution
    origin: tuple[float, float, float] = (-20.0, -20.0, -0.1)  # m, map min corner; ref map_size/2, ground_height
    size: tuple[float, float, float] = (40.0, 40.0, 3.0)  # m, ref map_size
    p_hit: float = 0.70  # ref p_hit
    p_miss: float = 0.35  # ref p_miss
    p_min: float = 0.12  # ref p_min (free floor of the clamp)
    p_max: float = 0.97  # ref p_max
    p_occ: float = 0.80  # ref p_occ (occupied threshold)
    unknown_offset: float = 0.01  # unknown = logit(p_min) - this, ref UNKNOWN_FLAG
    depth_min: float = 0.2  # m, closer pixels dropped, ref map yaml depth_min_value
    depth_max: float = 5.0  # m, farther pixels (and 0) become free rays, ref depth_max_value
    # ours: a pixel without a return (0) that has returns within this many pixels is free only up to the
    # nearest of them, less a voxel; 0: the reference (a free ray of raycast_max). A RealSense-like sensor
    # leaves holes at depth edges, and a free ray of 5 m from one carves through the structure behind
    hole_window: int = 2  # px
    raycast_max: float = 5.0  # m, longest ray; longer ones are shortened and end free, ref raycast_max_length
    skip_pixel: int = 2  # every n-th row and column, ref map yaml depth_skip_pixel
    # ours: a ray stops at a voxel crossed by an earlier ray of its own ray_bundle_px-square pixel block
    # this frame; 0 = any earlier ray of the frame (ref), which leaves much of the frustum uncarved
    ray_bundle_px: int = 8
    margin: int = 2  # px border skipped, ref map yaml depth_filter_margin
    local_update_range: tuple[float, float, float] = (5.0, 5.0, 5.0)  # m around the camera, ref
    robot_size: tuple[float, float, float] = (0.5, 0.5, 0.3)  # m, ref robot_size -> (3, 3, 2) voxels
    dynamic_margin: float = 0.3  # m added around a dynamic box, ref dynamicMap freeMapCB
    dynamic_history: int = 6  # frames a freed region keeps blocking insertion, ref histFreeRegions_
    static_after: int = 15  # updates (1 s at the closed loop's 15 Hz) after which an occupied voxel is no
    # longer freed by dynamic regions; ours (module docstring); 0: the reference (always freed)
    protect_before: int = 3  # updates: a voxel occupied this long when a dynamic region first covers it is
    # kept (0: never; with static_after 0, the reference)

    def __post_init__(self):
        if not self.resolution > 0 or min(self.size) <= 0 or min(self.local_update_range) <= 0:
            raise ValueError("MapConfig: resolution, size and local_update_range must be positive")
        if not 0 < self.p_min < self.p_miss < 0.5 < self.p_hit < 1 or not self.p_min < self.p_occ < self.p_max < 1:
            raise ValueError("MapConfig: need 0 < p_min < p_miss < 0.5 < p_hit < 1 and p_min < p_occ < p_max < 1")
        if not self.unknown_offset >= 1e-4:
            raise ValueError(f"MapConfig: unknown_offset must be >= 1e-4 (unknown and free voxels must differ), "
                             f"got {self.unknown_offset}")
        if self.skip_pixel < 1 or self.margin < 0 or self.dynamic_history < 1 or self.ray_bundle_px < 0 \
                or self.ray_bundle_px % self.skip_pixel or self.static_after < 0 or self.protect_before < 0 \
                or self.hole_window < 0:
            raise ValueError("MapConfig: need skip_pixel >= 1, margin >= 0, dynamic_history >= 1, "
                             "static_after >= 0, hole_window >= 0 and ray_bundle_px a non-negative multiple of "
                             "skip_pixel")
        cells = math.prod(max(round(x / self.resolution), 1) for x in self.size)
        if cells > MAX_MAP_CELLS:
            raise ValueError(f"MapConfig: size / resolution gives {cells:.3g} voxels, more than {MAX_MAP_CELLS:.0e} "
                             f"(about 20 bytes each); a coarser resolution or a smaller size")


@njit(cache=True, nogil=True)
def _in_regions(i, j, k, regions):
    for r in range(regions.shape[0]):
        if regions[r, 0] <= i <= regions[r, 3] and regions[r, 1] <= j <= regions[r, 4] \
                and regions[r, 2] <= k <= regions[r, 5]:
            return True
    return False


@njit(cache=True, nogil=True)
def _nearest_return(depth, v, u, r):
    """The least positive finite depth within r pixels of (v, u); inf when there is none."""
    H, W = depth.shape
    near = np.inf
    for vv in range(max(v - r, 0), min(v + r + 1, H)):
        for uu in range(max(u - r, 0), min(u + r + 1, W)):
            d = depth[vv, uu]
            if d > 0.0 and d < near:
                near = d
    return near


@njit(cache=True, nogil=True)
def _cast_frame(depth, fx, fy, cx, cy, R, cv, margin, skip, bundle, dmin, dmax, rmax, res, dims, blo, bhi,
                regions, stamp, hits, misses, touched, base, protected, hole):
    """Ray-cast one frame, counting hits and misses per voxel (cv: camera in voxel units). A point inside
    a dynamic region, unless its voxel is ``protected`` (VoxelMap._established), counts as neither: the
    voxels before the region are seen free, the region's are left as they were (a walker, or structure
    beside it; depth noise puts points behind a face, and their rays would carve it). A pixel
    without a return is a free ray of raycast_max, or, with returns within ``hole`` pixels, a free ray up
    to a voxel short of the nearest of them.

    stamp[k] holds the id of the last ray bundle that crossed voxel k; ids grow across frames, so
    stamp[k] >= base means "counted this frame" and stamp[k] == bid "crossed by this bundle", where
    the ray stops. Returns (touched voxels, bundles used, rays, hits, skipped_in_dynamic, bad_pixels)."""
    H, W = depth.shape
    sj, si = dims[2], dims[1] * dims[2]
    ci, cj, ck = int(math.floor(cv[0])), int(math.floor(cv[1])), int(math.floor(cv[2]))
    pv = np.empty(3)
    n, bid = 0, base - 1
    rays = nhit = skipped = bad = 0
    for v0 in range(margin, H - margin, bundle):
        for u0 in range(margin, W - margin, bundle):
            bid += 1
            for v in range(v0, min(v0 + bundle, H - margin), skip):
                for u in range(u0, min(u0 + bundle, W - margin), skip):
                    d = depth[v, u]
                    if not (d >= 0.0 and d < np.inf):  # NaN, inf, negative: bad data, counted
                        bad += 1
                        continue
                    free = d == 0.0 or d > dmax  # no return: a free ray of raycast_max (ref)
                    if free:
                        near = _nearest_return(depth, v, u, hole) if d == 0.0 and hole > 0 else np.inf
                        d = min(near - res, rmax + 0.1)  # a hole beside returns: free up to them (ours)
                        if d < dmin:
                            continue
                    elif d < dmin:
                        continue
                    xc, yc = (u - cx) * d / fx, (v - cy) * d / fy
                    s = 1.0
                    length = math.sqrt(xc * xc + yc * yc + d * d)
                    if length > rmax:  # shortened to raycast_max, ending free (ref)
                        s, free = rmax / length, True
                    for a in range(3):
                        pv[a] = cv[a] + s * (R[a, 0] * xc + R[a, 1] * yc + R[a, 2] * d) / res
                    t_exit = 1.0  # clip camera -> endpoint to the update box, which holds the camera
                    for a in range(3):
                        if pv[a] < blo[a]:
                            t_exit = min(t_exit, (blo[a] - cv[a]) / (pv[a] - cv[a]))
                        elif pv[a] > bhi[a] + 1:
                            t_exit = min(t_exit, (bhi[a] + 1 - cv[a]) / (pv[a] - cv[a]))
                    if t_exit < 1.0:
                        free = True
                        for a in range(3):
                            pv[a] = cv[a] + t_exit * (pv[a] - cv[a])
                    i = min(max(int(math.floor(pv[0])), blo[0]), bhi[0])
                    j = min(max(int(math.floor(pv[1])), blo[1]), bhi[1])
                    k = min(max(int(math.floor(pv[2])), blo[2]), bhi[2])
                    idx = i * si + j * sj + k
                    unseen = False  # an endpoint in a dynamic region: person or what is behind, not known
                    if not free and _in_regions(i, j, k, regions) and not protected[idx]:
                        free = unseen = True
                        skipped += 1
                    rays += 1
                    st = stamp[idx]
                    if st < base:
                        hits[idx] = misses[idx] = 0
                        touched[n] = idx
                        n += 1
                    if not free:
                        nhit += 1
                        hits[idx] = min(hits[idx] + 1, 32767)
                    if st == bid:  # this bundle already walked from here to the camera
                        continue
                    stamp[idx] = bid
                    if free and not unseen:
                        misses[idx] = min(misses[idx] + 1, 32767)
                    # Amanatides & Woo toward the camera; per-axis step counts end it in the camera voxel
                    ri, rj, rk = abs(ci - i), abs(cj - j), abs(ck - k)
                    di = si if ci > i else -si
                    dj = sj if cj > j else -sj
                    dk = 1 if ck > k else -1
                    tx = ty = tz = dx = dy = dz = np.inf
                    e = cv[0] - pv[0]
                    if ri > 0:
                        tx, dx = ((i + 1 if e > 0 else i) - pv[0]) / e, abs(1.0 / e)
                    e = cv[1] - pv[1]
                    if rj > 0:
                        ty, dy = ((j + 1 if e > 0 else j) - pv[1]) / e, abs(1.0 / e)
                    e = cv[2] - pv[2]
                    if rk > 0:
                        tz, dz = ((k + 1 if e > 0 else k) - pv[2]) / e, abs(1.0 / e)
                    while ri + rj + rk > 0:
                        if ri > 0 and tx <= ty and tx <= tz:
                            idx += di
                            ri -= 1
                            tx = tx + dx if ri > 0 else np.inf
                        elif rj > 0 and ty <= tz:
                            idx += dj
                            rj -= 1
                            ty = ty + dy if rj > 0 else np.inf
                        else:
                            idx += dk
                            rk -= 1
                            tz = tz + dz if rk > 0 else np.inf
                        st = stamp[idx]
                        if st == bid:
                            break
                        if st < base:
                            hits[idx] = misses[idx] = 0
                            touched[n] = idx
                            n += 1
                        stamp[idx] = bid
                        if unseen:  # from a point in a dynamic region: its voxels are not seen free (ours)
                            if _in_regions(idx // si, (idx // sj) % dims[1], idx % sj, regions):
                                continue
                            unseen = False
                        misses[idx] = min(misses[idx] + 1, 32767)
    return n, bid - base + 1, rays, nhit, skipped, bad


@njit(cache=True, nogil=True)
def _apply(L, touched, n, hits, misses, regions, dims, l_hit, l_miss, l_min, l_max, l_occ, since, update,
           protected):
    """One log-odds step per touched voxel (ref): a hit if hits >= misses and hits > 0, else a miss; an
    unknown voxel seen free becomes free; clamped to [logit p_min, logit p_max]. Hits are rays ending in
    the voxel, misses ray bundles crossing it. since[idx]: the update in which the voxel last became
    occupied (ours, for the protection rules)."""
    for m in range(n):
        idx = touched[m]
        h, ms = hits[idx], misses[idx]
        if h > 0 and h >= ms:
            val = min(max(L[idx] + l_hit, l_min), l_max)
        elif ms > 0:
            val = l_min if L[idx] < l_min else min(max(L[idx] + l_miss, l_min), l_max)  # unknown seen free
        else:
            continue
        was = L[idx] >= l_occ
        if val >= l_occ and not (was and protected[idx]) \
                and _in_regions(idx // (dims[1] * dims[2]), (idx // dims[2]) % dims[1], idx % dims[2], regions):
            val = l_min  # never occupied inside a recent dynamic region (ref), unless protected (ours)
        if val >= l_occ and not was:
            since[idx] = update
        L[idx] = val


@njit(cache=True, nogil=True)
def _any_in_window(L, l_occ, idx, r):
    nx, ny, nz = L.shape
    out = np.zeros(idx.shape[0], np.bool_)
    for m in range(idx.shape[0]):
        for i in range(max(idx[m, 0] - r[0], 0), min(idx[m, 0] + r[0] + 1, nx)):
            for j in range(max(idx[m, 1] - r[1], 0), min(idx[m, 1] + r[1] + 1, ny)):
                for k in range(max(idx[m, 2] - r[2], 0), min(idx[m, 2] + r[2] + 1, nz)):
                    if L[i, j, k] >= l_occ:
                        out[m] = True
    return out


@njit(cache=True, nogil=True)
def _column_bits(L, l_occ):
    """(nx, ny) uint64: bit k of a column set where L[i, j, k] >= l_occ (nz <= 64)."""
    nx, ny, nz = L.shape
    out = np.zeros((nx, ny), np.uint64)
    for i in range(nx):
        for j in range(ny):
            m = np.uint64(0)
            for k in range(nz):
                if L[i, j, k] >= l_occ:
                    m |= np.uint64(1) << np.uint64(k)
            out[i, j] = m
    return out


@njit(cache=True, nogil=True)
def _occupied_centres(L, l_occ, a, b, origin, res):
    """(K, 3) world centres origin + (ijk + 0.5) res of the voxels of L[a0:b0, a1:b1, a2:b2] >= l_occ, in
    index order (np.argwhere's)."""
    n = 0
    for i in range(a[0], b[0]):
        for j in range(a[1], b[1]):
            for k in range(a[2], b[2]):
                if L[i, j, k] >= l_occ:
                    n += 1
    out = np.empty((n, 3))
    n = 0
    for i in range(a[0], b[0]):
        for j in range(a[1], b[1]):
            for k in range(a[2], b[2]):
                if L[i, j, k] >= l_occ:
                    out[n, 0] = origin[0] + (i + 0.5) * res
                    out[n, 1] = origin[1] + (j + 0.5) * res
                    out[n, 2] = origin[2] + (k + 0.5) * res
                    n += 1
    return out


@njit(cache=True, nogil=True)
def _occupied_centres_bits(bits, a, b, origin, res):
    """_occupied_centres from the column bits (_column_bits): the same centres in the same order, reading
    one word per column."""
    band = np.uint64(0)
    for k in range(a[2], b[2]):
        band |= np.uint64(1) << np.uint64(k)
    n = 0
    for i in range(a[0], b[0]):
        for j in range(a[1], b[1]):
            m = bits[i, j] & band
            while m:
                m &= m - np.uint64(1)
                n += 1
    out = np.empty((n, 3))
    n = 0
    for i in range(a[0], b[0]):
        x = origin[0] + (i + 0.5) * res
        for j in range(a[1], b[1]):
            m = bits[i, j] & band
            if m == 0:
                continue
            y = origin[1] + (j + 0.5) * res
            for k in range(a[2], b[2]):
                if (m >> np.uint64(k)) & np.uint64(1):
                    out[n, 0], out[n, 1], out[n, 2] = x, y, origin[2] + (k + 0.5) * res
                    n += 1
    return out


@njit(cache=True, nogil=True)
def _column_any(L, value, k0, k1, at_most=False):
    """(nx, ny) bool: any of L[i, j, k0:k1 + 1] >= value (<= value when ``at_most``), in one pass."""
    nx, ny = L.shape[0], L.shape[1]
    out = np.zeros((nx, ny), np.bool_)
    for i in range(nx):
        for j in range(ny):
            for k in range(k0, k1 + 1):
                if (L[i, j, k] <= value) if at_most else (L[i, j, k] >= value):
                    out[i, j] = True
                    break
    return out


class VoxelMap:
    """Occupancy grid over [origin, origin + size); voxel (i, j, k) covers origin + res*[i, i+1) per axis.

    Occupied: L >= logit(p_occ); free: logit(p_min) <= L < logit(p_occ); unknown: below logit(p_min).
    """

    def __init__(self, cfg: MapConfig = MapConfig()):
        self.cfg = cfg
        self.res = float(cfg.resolution)
        self.origin = np.asarray(cfg.origin, dtype=np.float64)
        self.dims = np.maximum(np.round(np.asarray(cfg.size) / self.res).astype(np.int64), 1)
        self.l_hit, self.l_miss = _logit(cfg.p_hit), _logit(cfg.p_miss)
        self.l_min, self.l_max, self.l_occ = _logit(cfg.p_min), _logit(cfg.p_max), _logit(cfg.p_occ)
        self.l_unknown = np.float32(self.l_min - cfg.unknown_offset)
        self.inflation = np.ceil(np.asarray(cfg.robot_size) / (2 * self.res) - 1e-9).astype(np.int64)
        self.log_odds = np.empty(tuple(self.dims), np.float32)  # (nx, ny, nz)
        self._stamp = np.empty(self.log_odds.size, np.int32)  # last ray bundle through each voxel
        self._hits = np.zeros(self.log_odds.size, np.int16)  # this frame's counts (valid where stamped)
        self._misses = np.zeros(self.log_odds.size, np.int16)
        self._since = np.zeros(self.log_odds.shape, np.int32)  # update in which each voxel became occupied
        self._covered = np.zeros(self.log_odds.shape, bool)  # under a dynamic region in the last update
        self._held = np.zeros(self.log_odds.shape, bool)  # occupied protect_before updates when first covered
        self._protection = np.zeros(self.log_odds.shape, bool)  # update's work mask: _established in its box
        self._static_after = cfg.static_after or int(np.iinfo(np.int32).max)  # 0: never protected
        box = np.minimum(self.dims, 2 * np.ceil(np.asarray(cfg.local_update_range) / self.res) + 2)
        self._touched = np.empty(int(np.prod(box)), np.int64)
        self._history: deque[np.ndarray] = deque(maxlen=cfg.dynamic_history)
        self.version = 0  # grows whenever the map may have changed (reset, update, set_known): for caches
        self._columns: dict = {}  # column_blocked's results (and the columns' bits, "bits") at _columns_version
        self._columns_version = -1
        self.reset()

    def reset(self) -> None:
        self.log_odds.fill(self.l_unknown)
        self._stamp.fill(-1)
        self._next_bundle = 0
        self._history.clear()
        self._since.fill(0)
        self._covered.fill(False)
        self._held.fill(False)
        self._cover_box = np.array([0, 0, 0, -1, -1, -1], np.int64)  # _regions_box_of the last cover
        self._updates = 0  # update() calls so far: the clock of the protection rules
        self.version += 1

    def set_known(self, occupied: np.ndarray) -> None:
        """Replace the map by known geometry: voxels where ``occupied`` (nx, ny, nz) bool is True become
        occupied at the clamp's maximum and count as long established (dynamic regions never free them),
        the rest free. For planning against a map given beforehand instead of one built from depth."""
        occ = np.asarray(occupied, dtype=bool)
        if occ.shape != self.log_odds.shape:
            raise ValueError(f"VoxelMap.set_known: grid of shape {occ.shape}, the map is {self.log_odds.shape}")
        self.reset()
        self.log_odds[...] = np.where(occ, np.float32(self.l_max), np.float32(self.l_min))
        self._since[...] = -self._static_after if self._static_after < np.iinfo(np.int32).max else 0
        self.version += 1

    # -- update ----------------------------------------------------------------------------------------
    def _region(self, center, size) -> np.ndarray:
        c, s = np.asarray(center, float), np.asarray(size, float)
        if not (np.all(np.isfinite(c)) and np.all(np.isfinite(s))):
            return np.array([0, 0, 0, -1, -1, -1], np.int32)  # bad box: an empty region
        half = s / 2 + self.cfg.dynamic_margin
        lo = np.array([c[0] - half[0], c[1] - half[1], -np.inf])  # from the map's floor up (ref: z from 0)
        hi = c + half
        ilo = np.clip(np.floor((lo - self.origin) / self.res), 0, self.dims).astype(np.int32)
        ihi = np.clip(np.floor((hi - self.origin) / self.res), -1, self.dims - 1).astype(np.int32)
        return np.concatenate([ilo, ihi])  # inclusive voxel index ranges; empty if any hi < lo

    def update(self, depth_m, intrinsics, T_world_camera, dynamic_boxes=(), stamp=None) -> dict:
        """Free this frame's dynamic regions, then ray-cast the depth frame (float32 (H, W) m, 0 = none).

        ``T_world_camera`` maps optical-frame points into the world; ``dynamic_boxes`` are (center, size)
        world AABBs. ``stamp`` is carried for the caller's logs only. Returns counters."""
        return self.update_views([(depth_m, intrinsics, T_world_camera)], dynamic_boxes, stamp)

    def update_views(self, views, dynamic_boxes=(), stamp=None) -> dict:
        """``update`` with several depth images of one instant (a rig's sensors: [(depth_m, intrinsics,
        T_world_camera)]): one update of the map (its dynamic regions and the counts of updates its rules
        use), each image ray-cast in turn. Returns the counters summed over the images."""
        t0 = time.perf_counter()
        self._updates += 1
        self.version += 1
        regions = np.array([self._region(c, s) for c, s in dynamic_boxes], np.int32).reshape(-1, 6)
        self._history.append(regions)
        hist = np.concatenate(list(self._history))
        # Everything below that concerns dynamic regions happens inside `box`: it holds this update's and
        # the history's regions and the last cover, and outside it the cover, the held voxels and the
        # protection mask are all False (protection is consulted only inside regions).
        box, lo = self._regions_box(np.concatenate([hist, self._cover_box[None]]))
        cover = np.zeros(tuple(s.stop - s.start for s in box), bool)
        for r in regions:
            if np.all(r[3:] >= r[:3]):
                a, b = r[:3] - lo, r[3:] + 1 - lo
                cover[a[0]:b[0], a[1]:b[1], a[2]:b[2]] = True
        covered, held = self._covered[box], self._held[box]
        first = cover & ~covered  # regions reaching these voxels now: were they there before?
        held[first] = (self.log_odds[box][first] >= self.l_occ) & (self.cfg.protect_before > 0) & \
            (self._updates - self._since[box][first] >= self.cfg.protect_before)
        held &= cover
        covered[...] = cover
        self._cover_box = self._regions_box_of(regions)
        protected = self._protection
        protected[box] = self._established(box)
        sub = self.log_odds[box]
        sub[cover & ~protected[box] & (sub > self.l_unknown)] = np.float32(self.l_min)  # unknown stays unknown
        out = dict(rays=0, hits=0, skipped_in_dynamic=0, bad_pixels=0, stamp=stamp)
        for depth_m, intrinsics, T_world_camera in views:
            for k, v in self._cast_view(depth_m, intrinsics, T_world_camera, hist, protected).items():
                out[k] += v
        protected[box] = False
        out["ms"] = (time.perf_counter() - t0) * 1e3
        self.version += 1  # (also bumped on entry: nothing cached while the update ran is kept)
        return out

    def _cast_view(self, depth_m, intrinsics, T_world_camera, hist, protected) -> dict:
        """Ray-cast one depth image into the map (``update_views``); its counters."""
        T = np.asarray(T_world_camera, dtype=np.float64)
        cam = np.ascontiguousarray(T[:3, 3])
        with np.errstate(invalid="ignore"):
            cam_v = np.floor((cam - self.origin) / self.res)
        out = dict(rays=0, hits=0, skipped_in_dynamic=0, bad_pixels=0)
        if np.all(np.isfinite(T)) and np.all((cam_v >= 0) & (cam_v < self.dims)):
            rng = np.asarray(self.cfg.local_update_range)
            blo = np.maximum(np.floor((cam - rng - self.origin) / self.res), 0).astype(np.int64)
            bhi = np.minimum(np.floor((cam + rng - self.origin) / self.res), self.dims - 1).astype(np.int64)
            c = self.cfg
            H, W = np.shape(depth_m)
            bundle = c.ray_bundle_px if c.ray_bundle_px > 0 else max(H, W)
            if self._next_bundle > np.iinfo(np.int32).max - (H // bundle + 1) * (W // bundle + 1):
                self._stamp.fill(-1)  # bundle ids would wrap: forget the stamps
                self._next_bundle = 0
            r = _cast_frame(np.ascontiguousarray(depth_m, dtype=np.float32), float(intrinsics.fx),
                            float(intrinsics.fy), float(intrinsics.cx), float(intrinsics.cy),
                            np.ascontiguousarray(T[:3, :3]), (cam - self.origin) / self.res, c.margin,
                            c.skip_pixel, bundle, c.depth_min, c.depth_max, c.raycast_max, self.res, self.dims,
                            blo, bhi, hist, self._stamp, self._hits, self._misses, self._touched,
                            self._next_bundle, protected.reshape(-1), c.hole_window)
            self._next_bundle += int(r[1])
            _apply(self.log_odds.reshape(-1), self._touched, r[0], self._hits, self._misses, hist, self.dims,
                   self.l_hit, self.l_miss, self.l_min, self.l_max, self.l_occ, self._since.reshape(-1),
                   self._updates, protected.reshape(-1))
            out.update(rays=int(r[2]), hits=int(r[3]), skipped_in_dynamic=int(r[4]), bad_pixels=int(r[5]))
        else:  # a camera outside the map (or a non-finite pose) casts nothing; bad pixels are still counted
            m, sk = self.cfg.margin, self.cfg.skip_pixel
            d = np.asarray(depth_m, np.float32)
            d = d[m:d.shape[0] - m:sk, m:d.shape[1] - m:sk]
            out["bad_pixels"] = int(np.count_nonzero(~(np.isfinite(d) & (d >= 0))))
        return out

    def _regions_box_of(self, regions: np.ndarray) -> np.ndarray:
        """[lo, hi] inclusive index bounds of the non-empty regions (rows of lo, hi); empty: hi < lo."""
        r = regions[np.all(regions[:, 3:] >= regions[:, :3], axis=1)]
        if not len(r):
            return np.array([0, 0, 0, -1, -1, -1], np.int64)
        return np.concatenate([r[:, :3].min(axis=0), r[:, 3:].max(axis=0)]).astype(np.int64)

    def _regions_box(self, regions: np.ndarray) -> tuple[tuple[slice, ...], np.ndarray]:
        """(slices, their start) of the smallest box holding the non-empty regions (empty slices if none)."""
        b = self._regions_box_of(regions)
        lo, hi = b[:3], np.maximum(b[3:] + 1, b[:3])
        return tuple(slice(int(a), int(c)) for a, c in zip(lo, hi)), lo

    # -- queries ---------------------------------------------------------------------------------------
    def _index(self, points) -> tuple[np.ndarray, np.ndarray]:
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        with np.errstate(invalid="ignore"):
            f = np.floor((p - self.origin) / self.res)
            inside = np.all((f >= 0) & (f < self.dims), axis=1)
        return np.where(inside[:, None], f, 0).astype(np.int64), inside

    def _values(self, points) -> tuple[np.ndarray, np.ndarray]:
        idx, inside = self._index(points)
        return self.log_odds[idx[:, 0], idx[:, 1], idx[:, 2]], inside

    def is_occupied(self, points) -> np.ndarray:
        """(M, 3) world points -> (M,) bool; outside the map: False."""
        L, inside = self._values(points)
        return inside & (L >= self.l_occ)

    def is_free(self, points) -> np.ndarray:
        """(M,) bool: seen free; outside the map: False."""
        L, inside = self._values(points)
        return inside & (L >= self.l_min) & (L < self.l_occ)

    def is_unknown(self, points) -> np.ndarray:
        """(M,) bool: never observed; outside the map counts as unknown (True)."""
        L, inside = self._values(points)
        return ~inside | (L < self.l_min)

    def occupied(self) -> np.ndarray:
        """(nx, ny, nz) bool occupied voxels."""
        return self.log_odds >= self.l_occ

    def occupied_indices(self) -> np.ndarray:
        """(K, 3) int64 (i, j, k) of the occupied voxels, in index order (for logs and viewers)."""
        return np.argwhere(self.occupied())

    def occupied_count(self) -> int:
        return int(np.count_nonzero(self.occupied()))

    def _centre_range(self, lo, hi) -> tuple[np.ndarray, np.ndarray]:
        """Index ranges [a, b) per axis of the voxels whose centres lie in the world AABB [lo, hi], clipped
        to the map (empty where any b <= a)."""
        a = np.clip(np.ceil((np.asarray(lo, float) - self.origin) / self.res - 0.5), 0, self.dims).astype(int)
        b = np.clip(np.floor((np.asarray(hi, float) - self.origin) / self.res - 0.5) + 1, 0, self.dims).astype(int)
        return a, b

    def _established(self, box) -> np.ndarray:
        """Bool mask over the slice `box`: voxels occupied for static_after updates or more, or held (kept
        since a dynamic region first came over them)."""
        return ((self.log_odds[box] >= self.l_occ) & (self._updates - self._since[box] >= self._static_after)) \
            | self._held[box]

    def occupied_centers(self, lo, hi) -> np.ndarray:
        """(K, 3) float64 world centres of occupied voxels whose centres lie in the AABB [lo, hi]."""
        a, b = self._centre_range(lo, hi)
        if np.any(b <= a):
            return np.zeros((0, 3))
        if self.dims[2] <= 64:
            return _occupied_centres_bits(self._column_bits(), a.astype(np.int64), b.astype(np.int64), self.origin,
                                          self.res)
        return _occupied_centres(self.log_odds, self.l_occ, a.astype(np.int64), b.astype(np.int64), self.origin,
                                 self.res)

    def established_fraction(self, center, size) -> float:
        """Share of the box's footprint columns (voxel columns whose centres lie in the world AABB
        center +- size/2) holding a voxel occupied for static_after updates or more, within the box's
        height: how much of the box lies on long-seen structure. 0 for an empty or invalid box."""
        c, h = np.asarray(center, float), np.asarray(size, float) / 2
        if not (np.all(np.isfinite(c)) and np.all(np.isfinite(h))):
            return 0.0
        a, b = self._centre_range(c - h, c + h)
        if np.any(b <= a):
            return 0.0
        old = self._established(np.s_[a[0]:b[0], a[1]:b[1], a[2]:b[2]])
        return float(np.count_nonzero(old.any(axis=2))) / float((b[0] - a[0]) * (b[1] - a[1]))

    def inflated_occupied(self, points) -> np.ndarray:
        """(M,) bool: an occupied voxel lies within the robot-size inflation of the point's voxel
        (points outside the map: False)."""
        idx, inside = self._index(points)
        return inside & _any_in_window(self.log_odds, self.l_occ, idx, self.inflation)

    @property
    def xy_origin(self) -> np.ndarray:
        return self.origin[:2].copy()

    def world_to_cell(self, xy) -> np.ndarray:
        """(M, 2) world x, y -> (M, 2) int64 column indices (may lie outside [0, nx) x [0, ny))."""
        return np.floor((np.asarray(xy, float).reshape(-1, 2) - self.origin[:2]) / self.res).astype(np.int64)

    def cell_to_world(self, ij) -> np.ndarray:
        """(M, 2) column indices -> (M, 2) world x, y of the column centres."""
        return self.origin[:2] + (np.asarray(ij, float).reshape(-1, 2) + 0.5) * self.res

    def _columns_current(self) -> None:
        """Drops the column caches of an earlier map version."""
        if self._columns_version != self.version:
            self._columns.clear()
            self._columns_version = self.version

    def _column_bits(self) -> np.ndarray:
        """(nx, ny) uint64: each column's occupied voxels as bits (nz <= 64), once per map version."""
        self._columns_current()
        bits = self._columns.get("bits")
        if bits is None:
            bits = self._columns["bits"] = _column_bits(self.log_odds, self.l_occ)
        return bits

    def column_unobserved(self, z_lo: float, z_hi: float) -> np.ndarray:
        """(nx, ny) bool: a column is unobserved if a voxel overlapping the band [z_lo, z_hi] was never
        observed (neither free nor occupied); a band wholly outside the map's height: none is, as
        column_blocked finds none blocked. Read-only and cached per map version, as column_blocked."""
        k0, k1 = self._band(z_lo, z_hi)
        self._columns_current()
        key = ("unobserved", k0, k1)
        col = self._columns.get(key)
        if col is None:  # unknown voxels hold l_unknown exactly; observed ones float32(l_min) or more
            col = _column_any(self.log_odds, self.l_unknown, k0, k1, True)
            col.flags.writeable = False
            self._columns[key] = col
        return col

    def _band(self, z_lo: float, z_hi: float, grow: int = 0) -> tuple[int, int]:
        """The voxel layers k0..k1 (inclusive) overlapping [z_lo, z_hi], grown by ``grow`` layers each way and
        clipped to the map (k1 < k0: none)."""
        k0 = int(np.floor((z_lo - self.origin[2]) / self.res)) - grow
        k1 = int(np.floor((z_hi - self.origin[2]) / self.res)) + grow
        return max(k0, 0), min(k1, int(self.dims[2]) - 1)

    def column_blocked(self, z_lo: float, z_hi: float, inflate: bool = True) -> np.ndarray:
        """(nx, ny) bool: a column is blocked if a voxel overlapping the band [z_lo, z_hi] is occupied,
        the occupied set first grown by the robot-size inflation in x, y and z when ``inflate``.
        Read-only: the result is shared by every caller until the map changes (copy it to edit; writing it
        raises). Code that writes ``log_odds`` itself must bump ``version`` after."""
        r = self.inflation if inflate else np.zeros(3, np.int64)
        k0, k1 = self._band(z_lo, z_hi, int(r[2]))
        self._columns_current()
        key = (k0, k1, bool(inflate))
        col = self._columns.get(key)
        if col is None:
            if k1 < k0:
                col = np.zeros(tuple(self.dims[:2]), bool)
            elif self.dims[2] <= 64:  # every band from one pass: each column's occupied voxels as bits
                col = (self._column_bits() & np.uint64(((1 << (int(k1) + 1)) - 1) ^ ((1 << int(k0)) - 1))) != 0
            else:
                col = _column_any(self.log_odds, self.l_occ, k0, k1)
            if inflate and k1 >= k0:  # a rectangle of ones: the same cells as a binary dilation with it
                kernel = np.ones((2 * int(r[0]) + 1, 2 * int(r[1]) + 1), np.uint8)
                col = cv2.dilate(col.view(np.uint8), kernel).view(bool)
            col.flags.writeable = False
            self._columns[key] = col
        return col

