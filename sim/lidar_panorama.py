"""A LiDAR's rays looked up in depth images drawn around the sensor: a faster stand-in for rayTestBatch.

``PanoramaCaster`` draws the scene with the gl renderer (sim.gl_renderer: the visual shapes the camera
sees, walkers included, as posed now) into ``views`` depth images around the sensor's z axis, each
2 pi / views wide and tall enough for the model's vertical field at its edges, and finds each ray's
hit where the ray crosses its image. The cost grows with the pixels drawn, not with the rays; the rest of
a scan (noise, dropouts, limits) is ``sim.lidar.simulate_scan``'s, with this caster passed to it.

How a ray's hit is found: the depth buffer (24 bits, affine in the inverse depth) is interpolated
bilinearly between the four pixel centres around the ray, which is exact on a plane; the range is the
planar depth over the cosine between the ray and the view's axis. Where the four pixels do not lie on one
plane (an edge between surfaces, or the background), the nearest of them decides alone: no range mixes
two surfaces. The surface normal (for the grazing dropouts) is that of the four pixels' points: at an
edge it is the normal of no surface, and the incidence it gives is arbitrary there.

How it differs from casting rays (sim.lidar.cast_rays): it sees visual shapes, not collision shapes
(the quadrotor's drawn body is smaller than its collision box; spheres, capsules and cylinders are drawn
as polyhedra a little inside them); depth is quantised (24 bits between the near and far planes: a few
millimetres at 40 m, below the range noise); a surface nearer than the near plane (a fraction of
min_range) is not drawn; and, like the camera's images, the results depend on the OpenGL implementation
(Mesa's llvmpipe without a GPU), while the ray casts do not.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from dodt.frames import CameraIntrinsics
from dodt.lidar_views import view_rotations
from sim.gl_renderer import GLRenderer
from sim.lidar import LidarModel

MARGIN_PX = 2  # pixels around each image beyond the field it must cover: bilinear lookups stay inside
PLANE_TOLERANCE = 2e-3  # the four pixels lie on one plane when their inverse depths do, to this share


class PanoramaCaster:
    """Depth images of a PyBullet client's scene around a LiDAR; call it as ``simulate_scan``'s caster.

    Build it after the last body was created (the gl renderer's rule); ``release`` frees its GL objects.
    GLUnavailable (sim.gl_renderer) when no OpenGL context can be made; ValueError when the model's vertical
    field is too close to the poles for side views (within about 20 deg of them)."""

    def __init__(self, p, client: int, model: LidarModel, views: int = 4, width: int = 256):
        if views < 3 or width < 16:
            raise ValueError(f"PanoramaCaster: needs views >= 3 and width >= 16, got {views}, {width}")
        if model.horizontal_fov < 2 * math.pi:
            raise ValueError("PanoramaCaster: draws all round; the model's horizontal field must be 2 pi")
        self.views, self.model = int(views), model
        half = math.pi / self.views  # half a view's width [rad]
        f = (width / 2 - MARGIN_PX) / math.tan(half)
        # normalised image y (down) of the highest and lowest rays: at the view's axis or at its side edges
        y_top = min(-math.tan(model.elevation_max) / c for c in (1.0, math.cos(half)))
        y_bottom = max(-math.tan(model.elevation_min) / c for c in (1.0, math.cos(half)))
        height = int(math.ceil(f * (y_bottom - y_top))) + 2 * MARGIN_PX + 1
        if height > 4 * width:
            raise ValueError(f"PanoramaCaster: the vertical field ({math.degrees(model.elevation_min):.0f} to "
                             f"{math.degrees(model.elevation_max):.0f} deg) is too close to the poles for side views")
        self.K = CameraIntrinsics(width, height, f, f, (width - 1) / 2.0, MARGIN_PX - f * y_top)
        # planar depth of a ray at min_range, at the image's farthest corner from its axis
        corner = math.sqrt(1.0 + math.tan(half) ** 2 + max(y_top ** 2, y_bottom ** 2))
        self.near = model.min_range / corner * 0.5
        self.far = model.max_range
        # R_sensor_view for each view: the optical frame turned about the sensor's z axis by 2 pi k / views
        self._R = view_rotations(self.views)
        self._renderer = GLRenderer(p, client, self.K, near=self.near, far=self.far, depth_bits=24)

    def release(self) -> None:
        self._renderer.release()

    def draw(self, T_world_sensor: np.ndarray) -> np.ndarray:
        """(views, H, W) float32 depth buffers in [0, 1] (1: nothing) around the sensor's pose."""
        T = np.asarray(T_world_sensor, dtype=np.float64)
        poses = []
        for R in self._R:
            T_view = np.eye(4)
            T_view[:3, :3] = T[:3, :3] @ R
            T_view[:3, 3] = T[:3, 3]
            poses.append(T_view)
        return self._renderer.render_depth_views(poses)

    def __call__(self, T_world_sensor: np.ndarray, dirs: np.ndarray, reach: float) -> tuple[np.ndarray, np.ndarray]:
        """(range (N,) m, inf where nothing was hit within ``reach``; unit normal (N, 3) world frame, towards
        the sensor) of rays along ``dirs`` (N, 3), unit vectors in the sensor frame."""
        T = np.asarray(T_world_sensor, dtype=np.float64)
        K = self.K
        return _lookup(self.draw(T), np.ascontiguousarray(dirs, dtype=np.float64), self._R,
                       np.ascontiguousarray(T[:3, :3]), K.fx, K.fy, K.cx, K.cy, self.near, self.far, float(reach),
                       PLANE_TOLERANCE)


@njit(cache=True, nogil=True, inline="always")
def _inverse_depth(img, u, v, w_near, w_slope):
    """1 / planar depth [1/m] at pixel (u, v) of a depth buffer, w_near - w_slope * the buffer's value (with
    w_near = 1 / near, w_slope = (far - near) / (far near): 0 at the far plane); 0 for the background."""
    d = img[v, u]
    if d >= np.float32(1.0 - 1e-6):
        return 0.0
    return w_near - w_slope * d


@njit(cache=True, nogil=True)
def _edge_normal(img, uc, vc, fx, fy, cx, cy, w_near, w_slope, c):
    """The unit normal (optical frame, not yet oriented) at pixel (uc, vc) from its own surface, written into
    ``c`` (3,): of its left and right neighbours the one nearer in depth, likewise above and below; zeros
    where it has none on either side."""
    H, W = img.shape
    wc = _inverse_depth(img, uc, vc, w_near, w_slope)
    zc = 1.0 / wc
    a0 = a1 = a2 = b0 = b1 = b2 = 0.0
    for axis in range(2):
        gap = np.inf
        e0 = e1 = e2 = 0.0
        for step in (-1, 1):
            un, vn = (uc + step, vc) if axis == 0 else (uc, vc + step)
            if un < 0 or vn < 0 or un >= W or vn >= H:
                continue
            wn = _inverse_depth(img, un, vn, w_near, w_slope)
            if wn <= 0.0 or abs(1.0 / wn - zc) >= gap:
                continue
            gap = abs(1.0 / wn - zc)
            zn = 1.0 / wn
            e0 = (un - cx) / fx * zn - (uc - cx) / fx * zc
            e1 = (vn - cy) / fy * zn - (vc - cy) / fy * zc
            e2 = zn - zc
        if gap == np.inf:
            c[0], c[1], c[2] = 0.0, 0.0, 0.0
            return
        if axis == 0:
            a0, a1, a2 = e0, e1, e2
        else:
            b0, b1, b2 = e0, e1, e2
    x, y, z = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
    norm = math.sqrt(x * x + y * y + z * z)
    if norm > 0.0:
        c[0], c[1], c[2] = x / norm, y / norm, z / norm
    else:
        c[0], c[1], c[2] = 0.0, 0.0, 0.0


@njit(cache=True, nogil=True)
def _lookup(zbuf, dirs, R_views, R_world, fx, fy, cx, cy, near, far, reach, tol):
    """Per ray (sensor frame): (range [m], inf for none within reach; unit normal in the world frame, towards
    the sensor), from the depth buffers ``zbuf`` of the views R_views (sensor <- optical each)."""
    n, n_views = dirs.shape[0], zbuf.shape[0]
    H, W = zbuf.shape[1], zbuf.shape[2]
    out = np.full(n, np.inf)
    normal = np.zeros((n, 3))
    w = np.empty(4)
    c = np.empty(3)
    w_near, w_slope = 1.0 / near, (far - near) / (far * near)  # _inverse_depth's
    for i in range(n):
        # the view whose axis is nearest the ray's azimuth (their optical z axes lie in the sensor's xy plane)
        k, best = 0, -np.inf
        for j in range(n_views):
            dot = R_views[j, 0, 2] * dirs[i, 0] + R_views[j, 1, 2] * dirs[i, 1]
            if dot > best:
                k, best = j, dot
        R = R_views[k]
        X = R[0, 0] * dirs[i, 0] + R[1, 0] * dirs[i, 1] + R[2, 0] * dirs[i, 2]  # the ray in the view's frame
        Y = R[0, 1] * dirs[i, 0] + R[1, 1] * dirs[i, 1] + R[2, 1] * dirs[i, 2]
        Z = R[0, 2] * dirs[i, 0] + R[1, 2] * dirs[i, 1] + R[2, 2] * dirs[i, 2]
        if Z <= 1e-9:
            continue
        u = fx * X / Z + cx
        v = fy * Y / Z + cy
        # the four pixel centres around (u, v); a ray outside the image (not one of the model's) reads its edge
        u0 = min(max(int(math.floor(u)), 0), W - 2)
        v0 = min(max(int(math.floor(v)), 0), H - 2)
        fu, fv = min(max(u - u0, 0.0), 1.0), min(max(v - v0, 0.0), 1.0)
        img = zbuf[k]
        ok = True
        for j in range(4):
            w[j] = _inverse_depth(img, u0 + (j & 1), v0 + (j >> 1), w_near, w_slope)
            ok = ok and w[j] > 0.0
        if ok:  # one plane: the inverse depth is affine in the image, so w00 + w11 = w01 + w10
            ok = abs(w[0] + w[3] - w[1] - w[2]) <= tol * max(w[0], w[1], w[2], w[3])
        if ok:
            wi = (1 - fv) * ((1 - fu) * w[0] + fu * w[1]) + fv * ((1 - fu) * w[2] + fu * w[3])
            # the plane's normal: with 1/z = w0 + a (u - u0) + b (v - v0) and u = fx x / z + cx, v = fy y / z + cy,
            # its points (x, y, z) satisfy (a fx, b fy, w0 + a (cx - u0) + b (cy - v0)) . (x, y, z) = 1
            a = 0.5 * (w[1] - w[0] + w[3] - w[2])
            b = 0.5 * (w[2] - w[0] + w[3] - w[1])
            c[0], c[1], c[2] = a * fx, b * fy, w[0] + a * (cx - u0) + b * (cy - v0)
            norm = math.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2])
            c /= norm
        else:  # an edge or the background: the nearest pixel alone, the normal of its own surface
            j = int(fu >= 0.5) + 2 * int(fv >= 0.5)
            wi = w[j]
            if wi > 0.0:
                _edge_normal(img, u0 + (j & 1), v0 + (j >> 1), fx, fy, cx, cy, w_near, w_slope, c)
        if wi <= 0.0 or 1.0 / wi / Z > reach:
            continue
        out[i] = 1.0 / wi / Z
        if c[0] == 0.0 and c[1] == 0.0 and c[2] == 0.0:  # no neighbour on its surface: taken head on
            c[0], c[1], c[2] = X, Y, Z
        s = -1.0 if c[0] * X + c[1] * Y + c[2] * Z > 0.0 else 1.0  # towards the sensor
        for r in range(3):  # optical -> sensor -> world
            m = s * (R[r, 0] * c[0] + R[r, 1] * c[1] + R[r, 2] * c[2])
            normal[i, 0] += R_world[0, r] * m
            normal[i, 1] += R_world[1, r] * m
            normal[i, 2] += R_world[2, r] * m
    return out, normal
