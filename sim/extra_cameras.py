"""A rig's cameras beyond the first (sim.rig): depth frames drawn beside the first camera's.

The first camera is the world's (its renderer, render process, colour and segmentation); the others are
drawn where it is (in the render process when the world has one that renders with the gl renderer, else
in the world's own process) with the gl renderer (sim.gl_renderer, depth only, one pass per camera from
one read of the scene's poses) at the same capture instants, from the same body pose, each turned about
the body's z axis by its yaw. Each camera draws its depth noise (sim.depth_noise, the scenario's model)
from its own stream, so the first camera's frames are the same whatever else the rig holds. They carry
no colour and no segmentation: DODT's depth detectors read depth alone.
"""
from __future__ import annotations

import numpy as np

from dodt.frames import CameraIntrinsics
from sim.frame_capture import ImageFinisher
from sim.gl_renderer import GLRenderer
from sim.rig import camera_mount

EXTRA_CAMERA_SEED_TAG = 0x43414D  # "CAM": the extra cameras' noise streams, apart from every other


def in_first_camera(T_body_camera: np.ndarray, yaws) -> list[np.ndarray]:
    """Each other camera (turned by its yaw [deg] about the body's z axis) in the first camera's frame: the
    pose its frames carry is the first's times this."""
    T_camera_body = np.linalg.inv(np.asarray(T_body_camera, dtype=np.float64))
    return [T_camera_body @ camera_mount(T_body_camera, float(y)) for y in yaws]


class ExtraCameras:
    """Depth images of the rig's other cameras. ``yaws`` [deg] of each camera's optical axis from the first
    camera's, about the body's z axis; ``T_body_camera``: the first camera's mount. Build it after the last
    body was created (the gl renderer's rule); ``release`` frees its GL objects."""

    def __init__(self, p, client: int, K: CameraIntrinsics, camera, noise, seed: int, yaws, T_body_camera):
        self.K = K
        self.yaws = tuple(float(y) for y in yaws)
        self.T_body_cameras = [camera_mount(T_body_camera, y) for y in self.yaws]
        self.T_first_cameras = in_first_camera(T_body_camera, self.yaws)
        streams = np.random.SeedSequence([int(seed), EXTRA_CAMERA_SEED_TAG]).spawn(len(self.yaws))
        no_segmentation = np.full(1, -1, np.int64)
        self._finish = [ImageFinisher(camera, noise, np.random.default_rng(s), no_segmentation, False)
                        for s in streams]
        self._renderer = GLRenderer(p, client, K)

    def release(self) -> None:
        self._renderer.release()

    def render(self, T_world_body: np.ndarray) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
        """Each camera's (depth (uint16 mm, with its noise), its pose in the first camera's frame) with the
        body at ``T_world_body``, as posed now."""
        T = np.asarray(T_world_body, dtype=np.float64)
        zbufs = self._renderer.render_depth_views([T @ Tbc for Tbc in self.T_body_cameras])
        return tuple((f(None, z, None)[0], T_rel) for f, z, T_rel in zip(self._finish, zbufs, self.T_first_cameras))
