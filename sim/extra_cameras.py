"""A rig's cameras beyond the first (sim.rig): depth frames drawn in the world's own process.

The first camera is the world's (its renderer, render process, colour and segmentation); the others are
drawn here with the gl renderer (sim.gl_renderer, depth only, one pass per camera from one read of the
scene's poses) at the same capture instants, from the same body pose, each turned about the body's z
axis by its yaw. Each camera draws its depth noise (sim.depth_noise, the scenario's model) from its own
stream, so the first camera's frames are the same whatever else the rig holds. They carry no colour and
no segmentation: DODT's depth detectors read depth alone.
"""
from __future__ import annotations

import numpy as np

from dodt.frames import CameraIntrinsics
from sim.frame_capture import ImageFinisher
from sim.gl_renderer import GLRenderer
from sim.rig import yaw_matrix

EXTRA_CAMERA_SEED_TAG = 0x43414D  # "CAM": the extra cameras' noise streams, apart from every other


class ExtraCameras:
    """Depth images of the rig's other cameras. ``yaws`` [deg] of each camera's optical axis from the first
    camera's, about the body's z axis; ``T_body_camera``: the first camera's mount. Build it after the last
    body was created (the gl renderer's rule); ``release`` frees its GL objects."""

    def __init__(self, p, client: int, K: CameraIntrinsics, camera, noise, seed: int, yaws, T_body_camera):
        self.K = K
        self.yaws = tuple(float(y) for y in yaws)
        T_bc = np.asarray(T_body_camera, dtype=np.float64)
        self.T_body_cameras = []
        for y in self.yaws:
            T = np.eye(4)
            R = yaw_matrix(y)
            T[:3, :3] = R @ T_bc[:3, :3]
            T[:3, 3] = R @ T_bc[:3, 3]
            self.T_body_cameras.append(T)
        streams = np.random.SeedSequence([int(seed), EXTRA_CAMERA_SEED_TAG]).spawn(len(self.yaws))
        no_segmentation = np.full(1, -1, np.int64)
        self._finish = [ImageFinisher(camera, noise, np.random.default_rng(s), no_segmentation, False)
                        for s in streams]
        self._renderer = GLRenderer(p, client, K)

    def release(self) -> None:
        self._renderer.release()

    def render(self, T_world_body: np.ndarray) -> tuple[np.ndarray, ...]:
        """Each camera's depth (uint16 mm, with its noise) with the body at ``T_world_body``, as posed now."""
        T = np.asarray(T_world_body, dtype=np.float64)
        zbufs = self._renderer.render_depth_views([T @ Tbc for Tbc in self.T_body_cameras])
        return tuple(f(None, z, None)[0] for f, z in zip(self._finish, zbufs))
