"""RGB-D rendering through PyBullet with a pinhole model matching given intrinsics.

The OpenGL projection is built from (fx, fy, cx, cy) directly, so the rendered image obeys
u = fx X/Z + cx, v = fy Y/Z + cy with pixel centres at integer coordinates, including an
off-centre principal point. Depth is metric planar z (along the optical axis, not the ray
length), recovered from the depth buffer d as z = f n / (f - (f - n) d) (PyBullet's
pointCloudFromCameraImage example; bullet3 issue 1932).
"""
from __future__ import annotations

import contextlib
import os
import pkgutil
import sys
from dataclasses import dataclass

import cv2
import numpy as np
from numba import njit

from dodt.frames import CameraIntrinsics
from sim.scenario_parts import RENDERER_CHOICES, RENDERERS  # noqa: F401 (RENDERERS: re-exported)

# Optical frame (x right, y down, z forward) -> OpenGL camera frame (x right, y up, z back).
_OPTICAL_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])
NEAR_PLANE = 0.15  # m: sets the depth buffer's precision (EGL: 0.75 mm at 2.5 m vs 1.4 mm at 0.05 m); scenarios keep min_range >= this
FAR_PLANE = 30.0  # m


_ALIASES = {"egl": "pybullet"}


def renderer_name(name: str) -> str:
    """A renderer setting's canonical name ("egl" -> "pybullet"); ValueError naming the choices if unknown."""
    if name not in RENDERER_CHOICES:
        raise ValueError(f"renderer: {name!r} is not one of {', '.join(RENDERER_CHOICES)}")
    return _ALIASES.get(name, name)


# Where each renderer samples pixel (i, j), relative to its centre, in (u, v) pixels. OpenGL (ours
# and PyBullet's EGL plugin) samples the centre. TinyRenderer samples half a pixel left of and below
# it: measured by back-projecting a rendered box and the floor (tests/sim/test_camera.py), whose
# residuals drop from 1.5-3 mm to 0.2 mm with this correction.
PIXEL_SAMPLE_OFFSET = {"gl": (0.0, 0.0), "pybullet": (0.0, 0.0), "egl": (0.0, 0.0), "tiny": (-0.5, 0.5)}


def projection_matrix(K: CameraIntrinsics, near: float = NEAR_PLANE, far: float = FAR_PLANE,
                      sample_offset: tuple[float, float] = (0.0, 0.0)) -> list[float]:
    """Column-major OpenGL projection (PyBullet's layout) reproducing the intrinsics."""
    W, H = K.width, K.height
    P = np.zeros((4, 4))
    P[0, 0] = 2.0 * K.fx / W
    P[1, 1] = 2.0 * K.fy / H
    P[0, 2] = 1.0 - 2.0 * (K.cx + 0.5 + sample_offset[0]) / W
    P[1, 2] = 2.0 * (K.cy + 0.5 + sample_offset[1]) / H - 1.0
    P[2, 2] = -(far + near) / (far - near)
    P[2, 3] = -2.0 * far * near / (far - near)
    P[3, 2] = -1.0
    return P.T.reshape(-1).tolist()


def view_matrix(T_world_camera: np.ndarray) -> list[float]:
    """Column-major OpenGL view matrix for an optical-frame camera pose."""
    T_world_gl = T_world_camera @ _OPTICAL_TO_GL
    return np.linalg.inv(T_world_gl).T.reshape(-1).tolist()


def linearize_depth(buffer: np.ndarray, near: float = NEAR_PLANE, far: float = FAR_PLANE) -> np.ndarray:
    """Depth buffer in [0, 1] -> planar depth [m] as float32, 0 where nothing was hit."""
    d = np.ascontiguousarray(buffer, dtype=np.float32)
    return _linearize(d, np.float32(-(far - near)), np.float32(far), np.float32(far * near),
                      np.float32(1.0 - 1e-6))


@njit(cache=True, nogil=True)
def _linearize(d, minus_range, far, far_near, background):
    """f n / (f - (f - n) d) in float32, in this order; 0 where d >= background (the far plane)."""
    z = np.empty(d.shape, np.float32)
    src, dst = d.reshape(-1), z.reshape(-1)
    for i in range(src.size):
        x = src[i]
        dst[i] = np.float32(0.0) if x >= background else far_near / (x * minus_range + far)
    return z


@contextlib.contextmanager
def quiet_stdout():
    """Silence C-level stdout and stderr (PyBullet and its EGL plugin print banners there)."""
    try:
        sys.stdout.flush()
        sys.stderr.flush()
        fds = (sys.stdout.fileno(), sys.stderr.fileno())
    except (AttributeError, ValueError, OSError):
        yield
        return
    saved = [os.dup(fd) for fd in fds]
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        for fd in fds:
            os.dup2(null, fd)
        yield
    finally:
        for fd, s in zip(fds, saved):
            os.dup2(s, fd)
            os.close(s)
        os.close(null)


def load_egl(p, client: int) -> bool:
    """Load PyBullet's EGL renderer plugin into a client; False when it cannot load.

    Must run before any body is created: bodies made earlier are invisible to the plugin.
    """
    loader = pkgutil.get_loader("eglRenderer")
    if loader is None:
        return False
    with quiet_stdout():
        plugin = p.loadPlugin(loader.get_filename(), "_eglRendererPlugin", physicsClientId=client)
    return plugin >= 0


@dataclass
class RenderOutput:
    depth: np.ndarray  # (H, W) float32 planar depth [m], 0 = no surface
    color: np.ndarray | None  # (H, W, 3) uint8 RGB; None from a depth-only render
    segmentation: np.ndarray | None  # (H, W) int32 PyBullet body ids, -1 = background


def render_buffers(p, client: int, K: CameraIntrinsics, T_world_camera: np.ndarray, renderer: str,
                   segmentation: bool, light_direction=None) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """PyBullet's renderers' raw buffers ("pybullet"/"egl" or "tiny"): RGBA (H, W, 4) uint8, the depth
    buffer (H, W) float32 in [0, 1], PyBullet body ids (H, W) int32 or None. ``decode_render`` turns
    them into images (sim.gl_renderer gives the same buffers for "gl").

    light_direction: optional (3,) world vector for PyBullet's light (both renderers honour
    it; EGL keeps the last one given for later frames of the client, so pass it every frame or
    never). Colour, ambient, diffuse and specular light settings have no effect under EGL."""
    flags = 0 if segmentation else p.ER_NO_SEGMENTATION_MASK
    if renderer not in ("pybullet", "egl", "tiny"):
        raise ValueError(f"render_buffers: renderer {renderer!r} is not one of PyBullet's (pybullet, tiny)")
    r = p.ER_TINY_RENDERER if renderer == "tiny" else p.ER_BULLET_HARDWARE_OPENGL
    light = {} if light_direction is None else {"lightDirection": [float(x) for x in light_direction]}
    with quiet_stdout():  # the EGL plugin prints on its first frame
        w, h, rgba, depth, seg = p.getCameraImage(
            K.width, K.height, view_matrix(T_world_camera),
            projection_matrix(K, sample_offset=PIXEL_SAMPLE_OFFSET[renderer]),
            renderer=r, flags=flags, shadow=0, physicsClientId=client, **light)
    return (np.asarray(rgba, dtype=np.uint8).reshape(h, w, 4), np.asarray(depth, dtype=np.float32).reshape(h, w),
            np.asarray(seg, dtype=np.int32).reshape(h, w) if segmentation else None)


def decode_render(rgba: np.ndarray | None, zbuf: np.ndarray, seg: np.ndarray | None) -> RenderOutput:
    color = None if rgba is None else cv2.cvtColor(rgba, cv2.COLOR_RGBA2RGB)
    return RenderOutput(depth=linearize_depth(zbuf), color=color, segmentation=seg)


def render(p, client: int, K: CameraIntrinsics, T_world_camera: np.ndarray, renderer: str,
           segmentation: bool, light_direction=None) -> RenderOutput:
    """Render one frame at the camera pose (``render_buffers``, then ``decode_render``)."""
    return decode_render(*render_buffers(p, client, K, T_world_camera, renderer, segmentation, light_direction))
