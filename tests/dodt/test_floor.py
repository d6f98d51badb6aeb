"""The camera's height, pitch and roll from the floor in its depth image (dodt.floor)."""
import numpy as np
import pytest

from dodt.floor import camera_pose, fit_floor, fit_floor_frames
from dodt.frames import CameraIntrinsics
from tests.dodt.synthetic import render_depth

K = CameraIntrinsics()


@pytest.mark.parametrize("height, pitch, roll", [(2.0, 27.0, 0.0), (1.2, 0.0, 0.0), (2.5, 45.0, -4.0),
                                                 (0.8, 10.0, 6.0)])
def test_the_floor_gives_the_cameras_height_pitch_and_roll(height, pitch, roll):
    T = camera_pose(height, pitch, roll)
    assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3)) and np.linalg.det(T[:3, :3]) == pytest.approx(1.0)
    assert T[2, 3] == height
    # a room: a person-sized box, a table and a wall far ahead, depth with 1 cm noise
    boxes = [((3.0, -0.3, 0.0), (3.4, 0.1, 1.8)), ((2.0, 0.8, 0.7), (2.8, 1.6, 0.75)),
             ((7.0, -5.0, 0.0), (7.2, 5.0, 3.0))]
    clean = render_depth(K, T, boxes)
    floor_px = (clean > 0) & (render_depth(K, T, []) == clean)
    depth = clean + np.where(clean > 0, np.random.default_rng(0).normal(0, 0.01, clean.shape), 0).astype(np.float32)
    fit = fit_floor(depth, K)
    assert fit is not None
    assert fit.height == pytest.approx(height, abs=0.02)
    assert fit.pitch_deg == pytest.approx(pitch, abs=0.5)
    assert fit.roll_deg == pytest.approx(roll, abs=0.5)
    # the world it builds has the floor at z = 0 and the camera above the origin, looking along x
    Tw = fit.T_world_camera()
    v, u = np.nonzero(floor_px)
    pts = K.backproject(u[::50], v[::50], depth[v[::50], u[::50]]) @ Tw[:3, :3].T + Tw[:3, 3]
    assert np.abs(pts[:, 2]).mean() < 0.02
    np.testing.assert_allclose(Tw[:3, 3], [0.0, 0.0, fit.height])
    assert Tw[1, 2] == pytest.approx(0.0, abs=1e-9) and Tw[0, 2] > 0  # the optical axis in the x-z plane


def test_a_table_top_is_not_the_floor():
    """A wide table 0.75 m high fills most of the view, the floor around it shows fewer points
    than the table but more than a third as many: the lower plane is the floor."""
    T = camera_pose(1.6, 40.0)
    for table in (((0.5, -1.0, 0.0), (1.5, 1.0, 0.75)), ((0.3, -1.2, 0.0), (1.5, 1.2, 0.75))):
        depth = render_depth(K, T, [table])
        on_table = depth != render_depth(K, T, [])
        assert np.count_nonzero(on_table) > np.count_nonzero(~on_table & (depth > 0) & (depth < 8))
        fit = fit_floor(depth, K)
        assert fit.height == pytest.approx(1.6, abs=0.02) and fit.pitch_deg == pytest.approx(40.0, abs=0.5)


def test_no_floor_in_view_gives_none():
    T = camera_pose(1.5, 0.0)  # level, a wall ahead and no floor
    assert fit_floor(render_depth(K, T, [((6.0, -5, 0), (6.2, 5, 4))], floor=False), K) is None
    assert fit_floor(np.zeros((K.height, K.width), np.float32), K) is None
    assert fit_floor(np.full((K.height, K.width), np.nan, np.float32), K) is None


def test_the_fit_is_deterministic_and_several_frames_take_the_best():
    T = camera_pose(2.2, 20.0, 2.0)
    d = render_depth(K, T, [((3.0, -0.3, 0.0), (3.4, 0.1, 1.8))])
    a, b = fit_floor(d, K), fit_floor(d.copy(), K)
    assert np.array_equal(a.normal, b.normal) and a.height == b.height
    blocked = d.copy()
    blocked[200:] = 0.0  # a frame whose lower part has no depth
    best = fit_floor_frames([blocked, d], K)
    assert best.inliers == a.inliers
    assert fit_floor_frames([np.zeros_like(d)], K) is None
