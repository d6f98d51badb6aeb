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

from sim.scenario import Noise

_KERNEL = np.ones((3, 3), np.uint8)


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

    Whole-image arithmetic goes through OpenCV into preallocated buffers (no temporaries:
    fresh 1.2 MB arrays cost page faults every frame), which keeps a 640x480 frame near a
    millisecond. ``apply`` returns a buffer that the next call overwrites.
    """

    def __init__(self, noise: Noise, focal_px: float):
        self.noise = noise
        self.focal_px = focal_px
        self._shape = None

    def _buffers(self, shape):
        if self._shape != shape:
            self._shape = shape
            self._out, self._zmin, self._zmax, self._n = (np.empty(shape, np.float32) for _ in range(4))
            self._invalid, self._edge = np.empty(shape, np.uint8), np.empty(shape, np.uint8)

    def apply(self, z: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        noise = self.noise
        if not noise.enabled:
            return z
        z = np.ascontiguousarray(z, dtype=np.float32)
        self._buffers(z.shape)
        out, zmin, zmax, n = self._out, self._zmin, self._zmax, self._n
        np.copyto(out, z)
        if noise.edge_hole_prob > 0 or noise.flying_pixel_prob > 0:
            # Neighbourhood extremes over valid pixels only: invalid pixels are pushed far away
            # for the minimum and are 0 for the maximum, so they make no edges by themselves.
            invalid, edge = self._invalid, self._edge
            cv2.compare(out, 0.0, cv2.CMP_LE, dst=invalid)
            np.copyto(n, out)
            cv2.add(n, 1e4, dst=n, mask=invalid)
            cv2.erode(n, _KERNEL, dst=zmin)
            cv2.dilate(out, _KERNEL, dst=zmax)
            cv2.subtract(zmax, zmin, dst=n)
            cv2.scaleAdd(out, -noise.edge_threshold, n, dst=n)  # jump - threshold * z
            cv2.compare(n, 0.0, cv2.CMP_GT, dst=edge)
            cv2.subtract(edge, invalid, dst=edge)  # saturating: invalid pixels are no edges
            idx = np.flatnonzero(edge.view(np.bool_))  # 255 bytes read as True
            if idx.size:
                u = rng.random(idx.size, dtype=np.float32)
                flat = out.reshape(-1)
                hole = u < noise.edge_hole_prob
                fly = (~hole) & (u < noise.edge_hole_prob + noise.flying_pixel_prob)
                fi = idx[fly]
                w = rng.random(fi.size, dtype=np.float32)
                lo, hi = zmin.reshape(-1)[fi], zmax.reshape(-1)[fi]
                flat[fi] = lo + w * (hi - lo)
                flat[idx[hole]] = 0.0
        if noise.axial_model != "none":
            # OpenCV's generator (about 4x faster than NumPy's for 300k float32 normals),
            # seeded from the world's generator every frame so results stay repeatable.
            cv2.setRNGSeed(int(rng.integers(0, 2**31 - 1)))
            cv2.randn(n, 0.0, 1.0)
            if noise.axial_model == "intel_rms":  # sigma = c z^2, which is 0 on invalid pixels
                cv2.multiply(out, out, dst=zmin, scale=noise.subpixel / (self.focal_px * noise.baseline))
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
