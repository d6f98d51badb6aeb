"""The parts sim.World is made of, on their own: rotors, odometry noise, frame delivery, camera paths."""
import math
from types import SimpleNamespace

import numpy as np
import pytest

from dodt.frames import CameraIntrinsics
from sim.camera_paths import make_camera_path
from sim.controller import DroneState
from sim.frame_capture import Capture, FrameQueue
from sim.odometry import OdometryNoise
from sim.rotors import Rotors
from sim.scenario import CameraPath, Noise
from sim.vehicle import GRAVITY, load_vehicle


def test_rotors_hold_hover_and_spin_up_with_their_time_constant():
    v = load_vehicle()
    r = Rotors(v)
    hover = r.speed.copy()
    np.testing.assert_allclose(r.update(1 / 240).sum(), v.mass * GRAVITY)
    np.testing.assert_allclose(r.speed, hover, rtol=1e-12)
    r.thrust_cmd = np.full(4, 1.5 * v.mass * GRAVITY / 4)  # 1.5 times the hover thrust, below the rotors' limit
    target = math.sqrt(1.5 * v.mass * GRAVITY / 4 / v.kf)
    r.update(v.tau_up)
    np.testing.assert_allclose(r.speed, target + (hover - target) * math.exp(-1.0))


def test_odometry_is_the_truth_without_noise_and_a_rigid_repeatable_error_with_it():
    T = np.eye(4)
    T[:3, 3] = [1.0, 2.0, 1.2]
    exact = OdometryNoise(Noise(), np.random.default_rng(0))(T)
    assert exact is not T and np.array_equal(exact, T)
    noise = Noise(odom_position_std=0.01, odom_rotation_std=0.01)
    a, b = (OdometryNoise(noise, np.random.default_rng(5))(T) for _ in range(2))
    np.testing.assert_array_equal(a, b)
    assert 0 < np.linalg.norm(a[:3, 3] - T[:3, 3]) < 0.1
    np.testing.assert_allclose(a[:3, :3] @ a[:3, :3].T, np.eye(3), atol=1e-12)
    assert np.array_equal(OdometryNoise(Noise(enabled=False, odom_position_std=0.01), None)(T), T)


def _capture(seq, images=None):
    state = DroneState(position=np.zeros(3), velocity=np.zeros(3), R=np.eye(3), omega=np.zeros(3))
    return Capture(seq, seq / 30, images, np.eye(4), np.eye(4), np.eye(4), state, ())


@pytest.mark.parametrize("latency", [0, 2])
def test_frames_are_delivered_latency_periods_after_capture(latency):
    q = FrameQueue(latency, CameraIntrinsics())
    depth = np.zeros((480, 640), np.uint16)
    fetched = []
    delivered = [q.add(_capture(k, None if k % 2 else (depth, None, None)),
                       lambda seq: fetched.append(seq) or (depth, None, None)) for k in range(5)]
    assert [None if f is None else f.seq for f in delivered] == [k - latency if k >= latency else None
                                                                 for k in range(5)]
    assert q.frame.seq == q.truth.seq == 4 - latency and q.frame.stamp == q.truth.stamp
    assert fetched == [k for k in range(5 - latency) if k % 2]  # images left with the render process


def test_keyframe_camera_path_interpolates_position_velocity_and_unwrapped_yaw():
    cp = CameraPath(mode="carried", keyframes=((0.0, 0.0, 0.0, 1.0, 3.0), (2.0, 2.0, 0.0, 1.0, -3.0)))
    path = make_camera_path(SimpleNamespace(camera_path=cp), [], None)
    pos, vel, yaw = path(1.0)
    np.testing.assert_allclose(pos, [1.0, 0.0, 1.0])
    np.testing.assert_allclose(vel, [1.0, 0.0, 0.0])
    assert yaw == pytest.approx(3.0 + (2 * math.pi - 6.0) / 2)  # the short way round, through pi
    assert np.array_equal(path(5.0)[1], np.zeros(3))
    assert make_camera_path(SimpleNamespace(camera_path=None), [], None) is None
