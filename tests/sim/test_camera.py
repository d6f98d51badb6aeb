"""Rendering: intrinsics, metric planar depth, faces, EGL and TinyRenderer agreement, mounting."""
import math

import numpy as np
import pytest

from conftest import RENDERERS, make_scenario
from dodt.frames import CameraIntrinsics
from sim import World
from sim.camera import projection_matrix, view_matrix

NO_NOISE = "[noise]\nenabled = false\n"

# A box straight ahead of a hand-held, level camera; the camera is carried along a fixed pose.
BOX_SCENE = NO_NOISE + """
[[obstacles]]
kind = "box"
center = [4.0, 0.3]
size = [0.6, 0.8, 1.5]
yaw_deg = 25.0
[camera_path]
mode = "carried"
keyframes = [[0.0, 1.0, 0.0, 1.0, 0.0]]
"""


def _box_world(renderer):
    return World(make_scenario(BOX_SCENE), seed=0, renderer=renderer)


def test_projection_reproduces_intrinsics_with_off_centre_principal_point():
    K = CameraIntrinsics()
    P = np.array(projection_matrix(K)).reshape(4, 4).T
    T = np.eye(4)
    T[:3, :3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]  # optical frame looking along world x
    V = np.array(view_matrix(T)).reshape(4, 4).T
    pts_opt = np.array([[0.3, -0.2, 2.0], [-1.0, 0.5, 4.0], [0.0, 0.0, 1.0]])
    pts_world = pts_opt @ T[:3, :3].T
    for po, pw in zip(pts_opt, pts_world):
        clip = P @ V @ np.append(pw, 1.0)
        ndc = clip[:3] / clip[3]
        # OpenGL window coordinates with row 0 at the top, pixel centres at integers.
        u = (ndc[0] + 1) / 2 * K.width - 0.5
        v = (1 - ndc[1]) / 2 * K.height - 0.5
        assert u == pytest.approx(K.fx * po[0] / po[2] + K.cx, abs=1e-6)
        assert v == pytest.approx(K.fy * po[1] / po[2] + K.cy, abs=1e-6)


def _ray_box_depth(T_world_camera, K, u, v, obstacle):
    """Planar depth where each pixel's ray first hits an oriented box (slab method); nan on a miss."""
    rays = K.backproject(u, v, np.ones_like(u, dtype=float))  # optical frame, z = 1
    R, t = T_world_camera[:3, :3], T_world_camera[:3, 3]
    c, s = math.cos(obstacle.yaw), math.sin(obstacle.yaw)
    Rb = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])  # box frame -> world
    centre = np.array([obstacle.center[0], obstacle.center[1], obstacle.size[2] / 2])
    o = Rb.T @ (t - centre)
    d = rays @ (Rb.T @ R).T
    half = np.array(obstacle.size) / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (-half - o) / d, (half - o) / d
    t_near = np.max(np.minimum(t1, t2), axis=1)
    t_far = np.min(np.maximum(t1, t2), axis=1)
    return np.where(t_near <= t_far, t_near, np.nan)  # rays have z = 1, so t is planar depth


@pytest.mark.parametrize("renderer", RENDERERS)
def test_box_depth_within_1mm_and_backprojected_pixels_on_its_faces(renderer):
    w = _box_world(renderer)
    frame, truth = w.latest_frame(), w.ground_truth()
    o = w.scenario.obstacles[0]
    mask = truth.segmentation == truth.obstacles[0].id
    # Interior pixels: the whole 3x3 neighbourhood sees the box (silhouette pixels are
    # partial coverage by nature).
    interior = mask.copy()
    for dv in (-1, 0, 1):
        for du in (-1, 0, 1):
            interior &= np.roll(np.roll(mask, dv, axis=0), du, axis=1)
    assert interior.sum() > 5000
    v, u = np.nonzero(interior)
    z = frame.depth_m()[v, u]
    z_true = _ray_box_depth(frame.T_world_camera, frame.intrinsics, u, v, o)
    assert not np.any(np.isnan(z_true))
    assert np.max(np.abs(z - z_true)) <= 0.001 + 1e-6  # 1 mm, the sensor's quantisation included
    # Back-projected, every pixel lies on a face of the box.
    pts = frame.intrinsics.backproject(u, v, z)
    T = frame.T_world_camera
    pw = pts @ T[:3, :3].T + T[:3, 3]
    c, s = math.cos(o.yaw), math.sin(o.yaw)
    d = pw - np.array([o.center[0], o.center[1], o.size[2] / 2])
    local = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)
    surface_dist = np.max(np.abs(local) - np.array(o.size) / 2, axis=1)  # 0 on a face
    assert np.max(np.abs(surface_dist)) <= 0.001
    w.close()


@pytest.mark.parametrize("renderer", RENDERERS)
def test_planar_depth_of_a_fronto_parallel_wall_is_exact(renderer):
    # The corridor's end wall at x = 10 m faces a camera at x = 7 looking along +x: every pixel
    # on it has planar depth 3 m (ray length would grow towards the image corners).
    sc = make_scenario(NO_NOISE + "[camera_path]\nkeyframes = [[0.0, 7.0, 0.0, 1.5, 0.0]]\n")
    w = World(sc, seed=0, renderer=renderer)
    frame = w.latest_frame()
    z = frame.depth_m()
    v, u = np.nonzero(z > 0)
    pts = frame.intrinsics.backproject(u, v, z[v, u])
    T = frame.T_world_camera
    pw = pts @ T[:3, :3].T + T[:3, 3]
    # On the end wall's face and away from its edges with the floor and side walls.
    on_wall = (np.abs(pw[:, 0] - 10.0) < 0.05) & (np.abs(pw[:, 1]) < 1.95) & (pw[:, 2] > 0.05)
    assert on_wall.sum() > 0.3 * z.size
    expected = 10.0 - (7.0 + 0.065)  # the camera sits 0.065 m ahead of the body centre
    err_mm = np.abs(z[v[on_wall], u[on_wall]] - expected) * 1000
    assert np.max(err_mm) <= 1.0
    w.close()


@pytest.mark.parametrize("pair", [("pybullet", "tiny"), ("gl", "pybullet")])
def test_renderers_have_identical_semantics(pair):
    if any(r not in RENDERERS for r in pair):
        pytest.skip(f"{' or '.join(r for r in pair if r not in RENDERERS)} not available here")
    a, b = _box_world(pair[0]), _box_world(pair[1])
    da, db = a.latest_frame().depth_m(), b.latest_frame().depth_m()
    sa, sb = a.ground_truth().segmentation, b.ground_truth().segmentation
    both = (da > 0) & (db > 0)
    assert np.mean(sa == sb) > 0.99  # differences only along silhouettes
    assert np.median(np.abs(da[both] - db[both])) <= 0.001
    assert np.mean(np.abs(da[both] - db[both]) < 0.01) > 0.99
    assert a.latest_frame().color.shape == b.latest_frame().color.shape == (480, 640, 3)
    a.close()
    b.close()


def test_camera_moves_with_the_body_and_tilts_when_it_pitches():
    import pybullet as p

    w = World(make_scenario(NO_NOISE), seed=0, renderer="tiny")
    T_level = w.ground_truth().T_world_camera.copy()
    np.testing.assert_allclose(T_level, w.T_world_body() @ w.T_body_camera, atol=1e-9)
    floor_level = np.mean(w.ground_truth().segmentation[240:] == 0)
    # Pitch the body nose-down by 20 degrees and render again.
    pos, _ = p.getBasePositionAndOrientation(w.drone, physicsClientId=w._client)
    p.resetBasePositionAndOrientation(w.drone, pos, p.getQuaternionFromEuler([0, math.radians(20), 0]),
                                      physicsClientId=w._client)
    w._capture()
    T_pitch = w.ground_truth().T_world_camera
    optical_axis = T_pitch[:3, 2]
    assert math.degrees(math.asin(-optical_axis[2])) == pytest.approx(20.0, abs=1e-6)
    # Looking down, the floor (below the image centre) fills more of the image.
    lower_half = w.ground_truth().segmentation[240:]
    assert np.mean(lower_half == 0) >= floor_level
    depth_pitched = w.latest_frame().depth_m()
    w.close()
    level = World(make_scenario(NO_NOISE), seed=0, renderer="tiny")
    depth_level = level.latest_frame().depth_m()
    # The centre pixel now hits the floor much closer than the level view's corridor end.
    assert 0 < depth_pitched[240, 320] < 0.7 * depth_level[240, 320]
    level.close()


def test_sensor_frame_carries_only_what_a_robot_has():
    w = World(make_scenario(""), seed=0, renderer="tiny")
    f = w.latest_frame()
    assert f.depth.dtype == np.uint16 and f.depth.shape == (480, 640)
    assert f.color.dtype == np.uint8 and f.color.shape == (480, 640, 3)
    assert f.intrinsics.fx == pytest.approx(387.1537)
    assert not hasattr(f, "segmentation") and not hasattr(f, "obstacles")
    w.close()


@pytest.mark.skipif("pybullet" not in RENDERERS, reason="PyBullet's EGL plugin not available")
def test_one_world_at_a_time_renders_with_pybullets_egl_plugin_and_closing_it_is_safe(monkeypatch):
    a = World(make_scenario(BOX_SCENE), seed=0, renderer="pybullet")
    assert a.renderer == "pybullet"
    with pytest.raises(RuntimeError, match="already renders with PyBullet's EGL plugin"):
        World(make_scenario(BOX_SCENE), seed=0, renderer="egl")  # the older name of the same renderer
    # auto without our gl renderer: PyBullet's plugin is taken, so a second world falls back to TinyRenderer
    import sim.gl_renderer as gl

    def no_gl():
        raise gl.GLUnavailable("no GL in this test")
    monkeypatch.setattr(gl, "shared_context", no_gl)
    with pytest.warns(UserWarning, match="renders with EGL"):
        b = World(make_scenario(BOX_SCENE), seed=0, renderer="auto")
    assert b.renderer == "tiny"
    a.close()  # with two EGL clients this crashed the other one
    for _ in range(5):
        b.step()
    assert b.latest_frame().depth.max() > 0
    b.close()
    c = World(make_scenario(BOX_SCENE), seed=0, renderer="auto")  # the plugin is free again
    assert c.renderer == "pybullet"
    c.close()


def test_render_off_keeps_the_camera_clock_and_the_ground_truth():
    """World(render=False): a frame every camera period with the pose and no returns, truth still moving."""
    sc = make_scenario('[[people]]\nbehaviour = "crossing"\nspeed = 1.0\nwaypoints = [[5.0, 1.5], [5.0, -1.5]]\n')
    with World(sc, seed=0, render=False) as w:
        assert w.renderer == "none"
        frames, truths = [], []
        for _ in range(60):  # 0.5 s at the 120 Hz control rate
            f = w.step()
            if f is not None:
                frames.append(f)
                truths.append(w.ground_truth())
        assert len(frames) == 15  # 30 Hz
        assert all(not f.depth.any() and f.color is None and f.depth.shape == (sc.camera.height, sc.camera.width)
                   for f in frames)
        assert [f.stamp for f in frames] == [t.stamp for t in truths]
        np.testing.assert_allclose(frames[-1].T_world_camera, truths[-1].T_world_camera)
        centres = np.array([[o for o in t.obstacles if o.kind == "person"][0].center[:2] for t in truths])
        path = np.array([w.walkers[0].path.position(t.stamp) for t in truths])[:, :2]
        assert np.max(np.linalg.norm(centres - path, axis=1)) < 0.25  # the body's box follows the walk (gait sway)
        assert path[0, 1] - path[-1, 1] == pytest.approx(14 / 30, abs=0.02)  # 1 m/s over 14 frame periods
        assert truths[-1].segmentation is None
