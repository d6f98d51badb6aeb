"""RealSense-like depth noise on a planar depth image, seeded and switchable.

Components (each off when its magnitude is 0, all off with ``enabled = false``):
- axial noise, Gaussian with sigma growing with the square of depth. Default: Intel's stereo
  RMS formula (Grunnet-Jepsen et al., "Tuning depth cameras for best performance"):
  sigma(z) = z^2 * subpixel / (f_px * baseline). Option: Nguyen, Izadi, Lovell (3DIMPVT 2012)
  sigma(z) = 0.0012 + 0.0019 (z - 0.4)^2 [m];
- holes and flying pixels at depth edges (pixels whose 3x3 neighbourhood spans a relative
  depth jump above a threshold): invalid with one probability, a depth mixed between the near
  and far surface with another; the D400 datasheet publishes no edge model, this is empirical;
- random dropout of valid pixels;
- 1 mm quantisation happens at the sensor boundary (uint16 millimetres, sim.camera).
Invalid pixels are 0.
"""
from __future__ import annotations

import cv2
import numpy as np
from numba import njit

from sim.scenario_parts import Noise

_INVALID_FAR = np.float32(1e4)  # m added to invalid pixels for the neighbourhood minimum


@njit(cache=True, nogil=True, inline="always")
def _for_minimum(d):
    """A pixel's depth as the neighbourhood minimum takes it: invalid ones (<= 0) pushed 1e4 m away."""
    return d + _INVALID_FAR if d <= 0 else d


@njit(cache=True, nogil=True)
def _edge_pixels(z, threshold, idx):
    """Write into ``idx`` the flat indices, in row-major order, of the valid pixels of z whose 3x3
    neighbourhood (clipped to the image) spans a depth jump above ``threshold`` times their depth; return
    how many. The jump is the neighbourhood's maximum minus its minimum over valid pixels: invalid ones
    (z <= 0) count 1e4 m farther for the minimum and as they are for the maximum. The sign of
    max - min - threshold z is taken exactly (float64 holds the float32 product exactly).

    Row by row: the extremes over the three rows per column, then over three columns (the interior
    without clamping, so that both loops vectorise), then the row's edge flags, gathered eight at a time
    (edges are few: a zero word of eight flags is skipped at once)."""
    H, W = z.shape
    lo_c = np.empty(W, np.float32)  # per column, over rows v-1..v+1 (clipped: a border row counts twice)
    hi_c = np.empty(W, np.float32)
    lo_r = np.empty(W, np.float32)  # ... then over columns u-1..u+1
    hi_r = np.empty(W, np.float32)
    nw = W // 8
    edge = np.zeros(8 * (nw + 1), np.uint8)
    words = edge[:8 * nw].view(np.uint64)
    t = np.float64(-threshold)
    n = 0
    for v in range(H):
        za, zb, zc = z[max(v - 1, 0)], z[v], z[min(v + 1, H - 1)]
        for u in range(W):  # branch-free selects, so that the loop vectorises
            a, b, c = za[u], zb[u], zc[u]
            fa, fb, fc = _for_minimum(a), _for_minimum(b), _for_minimum(c)
            lo = fa if fa < fb else fb
            lo_c[u] = lo if lo < fc else fc
            hi = a if a > b else b
            hi_c[u] = hi if hi > c else c
        for u in range(1, W - 1):
            l0, l1, l2 = lo_c[u - 1], lo_c[u], lo_c[u + 1]
            lo = l0 if l0 < l1 else l1
            lo_r[u] = lo if lo < l2 else l2
            h0, h1, h2 = hi_c[u - 1], hi_c[u], hi_c[u + 1]
            hi = h0 if h0 > h1 else h1
            hi_r[u] = hi if hi > h2 else h2
        for u in (0, W - 1):
            ua, ub = max(u - 1, 0), min(u + 1, W - 1)
            lo = lo_c[ua] if lo_c[ua] < lo_c[u] else lo_c[u]
            lo_r[u] = lo if lo < lo_c[ub] else lo_c[ub]
            hi = hi_c[ua] if hi_c[ua] > hi_c[u] else hi_c[u]
            hi_r[u] = hi if hi > hi_c[ub] else hi_c[ub]
        for u in range(W):
            d = zb[u]
            edge[u] = (d > 0) & (np.float64(d) * t + np.float64(hi_r[u] - lo_r[u]) > 0.0)
        base = v * W
        for w in range(nw):
            if words[w] != 0:
                for u in range(8 * w, 8 * w + 8):
                    if edge[u]:
                        idx[n] = base + u
                        n += 1
        for u in range(8 * nw, W):
            if edge[u]:
                idx[n] = base + u
                n += 1
    return n


@njit(cache=True, nogil=True)
def _extremes_at(z, flat_idx):
    """(minimum over valid pixels, maximum) of z's 3x3 neighbourhoods at the given flat indices, as
    ``_edge_pixels`` takes them."""
    H, W = z.shape
    lo = np.empty(flat_idx.size, np.float32)
    hi = np.empty(flat_idx.size, np.float32)
    for m in range(flat_idx.size):
        v, u = flat_idx[m] // W, flat_idx[m] % W
        a = np.float32(np.inf)
        b = np.float32(-np.inf)
        for r in range(max(v - 1, 0), min(v + 1, H - 1) + 1):
            for c in range(max(u - 1, 0), min(u + 1, W - 1) + 1):
                d = z[r, c]
                a = min(a, _for_minimum(d))
                b = max(b, d)
        lo[m], hi[m] = a, b
    return lo, hi


@njit(cache=True, nogil=True)
def _add_axial_noise(out, normals, c):
    """out += (c out) out normals: the Intel RMS model's sigma = c z^2 (0 on invalid pixels) times
    standard normal draws, in float32 in this order."""
    flat, nrm = out.reshape(-1), normals.reshape(-1)
    for i in range(flat.size):
        z = flat[i]
        flat[i] = z + ((c * z) * z) * nrm[i]


def axial_sigma(z: np.ndarray, noise: Noise, focal_px: float) -> np.ndarray:
    """Standard deviation [m] of the depth noise at planar depth z [m]."""
    z = np.asarray(z, dtype=np.float32)
    if noise.axial_model == "intel_rms":
        return z * z * np.float32(noise.subpixel / (focal_px * noise.baseline))
    if noise.axial_model == "nguyen":
        return np.float32(0.0012) + np.float32(0.0019) * (z - np.float32(0.4)) ** 2
    return np.zeros_like(z)


class DepthNoiseModel:
    """Applies ``Noise`` to float32 depth images of one size, reusing its work buffers.

    Whole-image passes are compiled loops (the edge search, the axial noise) or OpenCV calls writing
    into preallocated buffers (no temporaries: fresh 1.2 MB arrays cost page faults every frame).
    ``apply`` returns a buffer that the next call overwrites.
    """

    def __init__(self, noise: Noise, focal_px: float):
        self.noise = noise
        self.focal_px = focal_px
        self._shape = None

    def _buffers(self, shape):
        if self._shape != shape:
            self._shape = shape
            self._out, self._zmin, self._n = (np.empty(shape, np.float32) for _ in range(3))
            self._idx = np.empty(shape[0] * shape[1], np.int64)

    def apply(self, z: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        noise = self.noise
        if not noise.enabled:
            return z
        z = np.ascontiguousarray(z, dtype=np.float32)
        self._buffers(z.shape)
        out, zmin, n = self._out, self._zmin, self._n
        np.copyto(out, z)
        if noise.edge_hole_prob > 0 or noise.flying_pixel_prob > 0:
            idx = self._idx[:_edge_pixels(z, np.float32(noise.edge_threshold), self._idx)]
            if idx.size:
                u = rng.random(idx.size, dtype=np.float32)
                flat = out.reshape(-1)
                hole = u < noise.edge_hole_prob
                fly = (~hole) & (u < noise.edge_hole_prob + noise.flying_pixel_prob)
                fi = idx[fly]
                w = rng.random(fi.size, dtype=np.float32)
                lo, hi = _extremes_at(z, fi)
                flat[fi] = lo + w * (hi - lo)
                flat[idx[hole]] = 0.0
        if noise.axial_model != "none":
            # OpenCV's generator (about 4x faster than NumPy's for 300k float32 normals),
            # seeded from the world's generator every frame so results stay repeatable.
            cv2.setRNGSeed(int(rng.integers(0, 2**31 - 1)))
            cv2.randn(n, 0.0, 1.0)
            if noise.axial_model == "intel_rms":  # sigma = c z^2, which is 0 on invalid pixels
                _add_axial_noise(out, n, np.float32(noise.subpixel / (self.focal_px * noise.baseline)))
            else:
                np.multiply(axial_sigma(out, noise, self.focal_px), out > 0, out=zmin)
                cv2.multiply(zmin, n, dst=zmin)
                cv2.add(out, zmin, dst=out)
        if noise.dropout > 0:
            k = rng.binomial(out.size, noise.dropout)
            out.reshape(-1)[rng.integers(0, out.size, size=k)] = 0.0
        cv2.max(out, 0.0, dst=out)
        return out


def apply_depth_noise(z: np.ndarray, noise: Noise, focal_px: float, rng: np.random.Generator) -> np.ndarray:
    """One-off convenience: a noisy copy of the float32 depth image z [m] (0 = invalid)."""
    out = DepthNoiseModel(noise, focal_px).apply(z, rng)
    return out if out is not z else z.copy()
