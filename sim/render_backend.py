"""Which renderer a world draws its camera with, and the resources that renderer holds.

In order of preference for ``auto``: our OpenGL renderer (sim.gl_renderer, over the bodies of the main
client), PyBullet's EGL plugin (loaded into the main client before any body exists), PyBullet's
TinyRenderer. Or a render process (sim.render_process): a second process with its own copy of the
world renders there, and this one renders nothing.

A world opens its backend before building its bodies (``RenderBackend.open``: the render process, the
shared GL context, the EGL plugin) and attaches it to them after (``attach``: the gl renderer's scene).
"""
from __future__ import annotations

import time
import warnings
import weakref

import numpy as np

from dodt.frames import CameraIntrinsics
from sim.camera import load_egl, quiet_stdout, render_buffers
from sim import gl_renderer
from sim.gl_renderer import GLRenderer, GLUnavailable, GLUnsupportedScene
from sim.render_process import RenderProcess

with quiet_stdout():  # PyBullet prints its build time on import
    import pybullet as p

_egl_owner = None  # weakref to the one RenderBackend that renders with PyBullet's EGL plugin


class RenderBackend:
    """The renderer of one world's main client; ``name`` says which ("gl", "pybullet", "tiny", "none" when the
    world renders nothing, or "<name> (render process)")."""

    def __init__(self, client: int, intrinsics: CameraIntrinsics):
        self.client = client
        self.intrinsics = intrinsics
        self.name = "none"
        self.gl = None  # sim.gl_renderer.GLRenderer once attached, when the renderer is "gl"
        self.process = None  # sim.render_process.RenderProcess when rendering in a second process
        self._want_gl = False
        self._wall_time = 0.0  # s spent inside the renderer in this process (benchmarks)

    @classmethod
    def open(cls, client: int, intrinsics: CameraIntrinsics, want: str, render: bool, render_process: bool,
             process_args: tuple = ()) -> RenderBackend:
        """The backend for renderer ``want`` ("auto", "gl", "pybullet" or "tiny"), made before any body exists.
        render=False: nothing is drawn. render_process: start sim.render_process.RenderProcess(*process_args).
        RuntimeError when the renderer asked for by name cannot be had."""
        b = cls(client, intrinsics)
        b.name = "tiny" if render else "none"
        if render_process:
            b.process = RenderProcess(*process_args)
            b.name = f"{b.process.renderer} (render process)"
            return b
        if render and want in ("auto", "gl"):
            try:
                gl_renderer.shared_context()  # made once per process, before any body: PyBullet's EGL plugin is the fallback
                b._want_gl = True
                return b
            except GLUnavailable as e:
                if want == "gl":
                    raise RuntimeError(f"renderer 'gl' requested but {e}; use renderer = 'auto', 'pybullet' or "
                                       f"'tiny'") from None
        if render and want in ("auto", "pybullet"):
            b._open_egl(want)
        return b

    def _open_egl(self, want: str) -> None:
        global _egl_owner
        other = _egl_owner() if _egl_owner is not None else None
        if other is not None and other is not self:
            # PyBullet's EGL plugin keeps global state: with two EGL clients in a process,
            # closing one crashes the other (measured). One World at a time gets EGL.
            if want == "pybullet":
                raise RuntimeError("another World in this process already renders with PyBullet's EGL plugin; "
                                   "close it first (world.close() or a with-block) or use renderer='gl' or "
                                   "'tiny'")
            # stacklevel: the caller of World.reset (this, open, reset)
            warnings.warn("another World in this process renders with EGL: this one uses TinyRenderer "
                          "(close the other World first to get EGL)", stacklevel=4)
        elif load_egl(p, self.client):
            self.name = "pybullet"
            _egl_owner = weakref.ref(self)
        elif want == "pybullet":
            raise RuntimeError("renderer 'pybullet' requested but PyBullet's EGL plugin did not load "
                               "(is Mesa's libEGL installed?); use renderer = 'auto' or 'tiny'")

    def attach(self, want: str) -> None:
        """Make the gl renderer over the bodies now in the client, when it was chosen; a scene it cannot draw
        falls back to TinyRenderer with a warning (an error when "gl" was asked for by name)."""
        if not self._want_gl:
            return
        try:
            self.gl = GLRenderer(p, self.client, self.intrinsics)
        except GLUnsupportedScene as e:
            if want == "gl":
                raise RuntimeError(f"renderer 'gl': {e}") from None
            # stacklevel: the caller of World.reset (this, attach, reset)
            warnings.warn(f"the gl renderer cannot draw this scene ({e}): using TinyRenderer", stacklevel=3)
            return
        self.name = "gl"

    def render(self, T_world_camera: np.ndarray, color: bool, segmentation: bool, light_direction=None):
        """The renderer's raw buffers at a camera pose: RGBA, depth buffer, body ids or None (sim.camera)."""
        t0 = time.perf_counter()  # benchmark bookkeeping only: no result depends on it
        if self.gl is not None:
            out = self.gl.render(T_world_camera, color=color, segmentation=segmentation,
                                 light_direction=light_direction)
        else:
            out = render_buffers(p, self.client, self.intrinsics, T_world_camera, self.name, segmentation,
                                 light_direction=light_direction)
        self._wall_time += time.perf_counter() - t0
        return out

    @property
    def wall_time(self) -> float:
        """Seconds spent inside the renderer (benchmarks only), in this process or the render process."""
        rp = self.process
        return self._wall_time + (rp.render_wall_time if rp is not None else 0.0)

    def close(self) -> None:
        """Release the GL scene, end the render process and give up EGL; the client itself is the world's."""
        global _egl_owner
        if _egl_owner is not None and _egl_owner() is self:
            _egl_owner = None
        if self.gl is not None:
            self.gl.release()
            self.gl = None
        if self.process is not None:
            self.process.close()
            self.process = None
