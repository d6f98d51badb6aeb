"""Quadrotor and cascaded controller: hover, steps, figure-eight, actuator limits, yaw."""
import math

import numpy as np
import pytest

from conftest import make_scenario
from sim import World
from sim.controller import CascadedController, DroneState, Reference
from sim.trajectories import figure_eight, straight_line
from sim.vehicle import GRAVITY, load_vehicle


def _world():
    return World(make_scenario(""), seed=0, camera=False)


def _fly(w, ref_at, seconds):
    pos = []
    for _ in range(int(round(seconds * 120))):
        w.step(ref_at(w.time))
        pos.append(w.state().position.copy())
    return np.array(pos)


def test_vehicle_constants_come_from_the_urdf():
    v = load_vehicle()
    assert v.mass == pytest.approx(1.5)
    assert v.thrust_to_weight == pytest.approx(4 * 5.84e-6 * 1100**2 / (1.5 * GRAVITY))
    assert 1.8 < v.thrust_to_weight < 2.2
    np.testing.assert_allclose(v.inertia, [0.029125, 0.029125, 0.055225])


def test_hover_holds_within_2cm():
    w = _world()
    start = np.array(w.scenario.drone.start)
    # Begin 0.3 m below and 0.2 m beside the hover point, converge, then hold.
    import pybullet as p

    p.resetBasePositionAndOrientation(w.drone, (start + [0.0, 0.2, -0.3]).tolist(), [0, 0, 0, 1],
                                      physicsClientId=w._client)
    pos = _fly(w, lambda t: Reference.hover(start), 10.0)
    hold = pos[int(3 * 120):]
    assert np.max(np.linalg.norm(hold - start, axis=1)) < 0.02
    assert not w.collided


@pytest.mark.parametrize("target", [[2.0, 0.0, 1.2], [1.0, 1.0, 1.2], [1.0, 0.0, 2.2]])
def test_one_metre_step_settles_fast_without_overshoot(target):
    w = _world()
    start, target = np.array(w.scenario.drone.start), np.array(target)
    pos = _fly(w, lambda t: Reference.hover(target), 5.0)
    axis = (target - start) / np.linalg.norm(target - start)
    progress = (pos - start) @ axis
    assert progress.max() - 1.0 < 0.05  # overshoot under 5 %
    err = np.linalg.norm(pos - target, axis=1)
    assert np.all(err[int(2.5 * 120):] < 0.05)  # within 5 cm after 2.5 s
    assert err[-1] < 0.02


def test_figure_eight_is_tracked():
    w = _world()
    f8 = figure_eight([5.0, 0.0, 1.2], radius=1.5, period=8.0)  # up to 1.2 m/s, 2.3 m/s^2
    _fly(w, lambda t: Reference.hover(f8(0.0).position), 6.0)  # fly to the figure's start, settle
    t0 = w.time
    err = []
    for _ in range(16 * 120):
        w.step(f8(w.time - t0))
        err.append(np.linalg.norm(w.state().position - f8(w.time - t0).position))
    err = np.array(err)
    print(f"figure-eight error: first lap max {err[:960].max():.3f} m, second lap max {err[960:].max():.3f} m, "
          f"rms {np.sqrt(np.mean(err[960:]**2)):.3f} m")
    # The reference starts at full speed from hover: a transient on the first lap; the second
    # lap is the steady state.
    assert np.max(err[:960]) < 0.5
    assert np.max(err[960:]) < 0.10
    assert np.sqrt(np.mean(err[960:] ** 2)) < 0.06


def test_straight_reference_reaches_the_goal_at_cruise_speed():
    w = _world()
    ref_at, T = straight_line(w.scenario.drone.start, [8.0, 0.0, 1.2], speed=1.5, accel=1.0)
    pos = _fly(w, ref_at, T + 2.0)
    assert np.linalg.norm(pos[-1] - [8.0, 0.0, 1.2]) < 0.05
    speeds = np.linalg.norm(np.diff(pos, axis=0), axis=1) * 120
    assert np.max(speeds) == pytest.approx(1.5, abs=0.1)


def test_yaw_is_tracked():
    w = _world()
    start = np.array(w.scenario.drone.start)
    _fly(w, lambda t: Reference(position=start, yaw=math.radians(90)), 4.0)
    assert math.degrees(w.state().yaw) == pytest.approx(90.0, abs=2.0)
    assert np.linalg.norm(w.state().position - start) < 0.05


def test_rotor_thrusts_stay_within_actuator_limits():
    v = load_vehicle()
    ctrl = CascadedController(v)
    state = DroneState(position=np.zeros(3), velocity=np.zeros(3), R=np.eye(3), omega=np.zeros(3))
    # A huge demand: 10 m away and upwards at once.
    f = ctrl(state, Reference.hover([10.0, -10.0, 10.0]), 1 / 120)
    assert np.all(f >= 0) and np.all(f <= v.max_rotor_thrust + 1e-12)
    # A pure yaw demand that cannot be met keeps thrust and gives up yaw moment first.
    f = ctrl.mix(v.mass * GRAVITY, np.array([0.0, 0.0, 50.0]))
    assert np.all(f >= 0) and np.all(f <= v.max_rotor_thrust + 1e-12)
    assert f.sum() == pytest.approx(v.mass * GRAVITY)
    yaw = v.allocation[3] @ f
    assert 0 < yaw < 50.0  # as much yaw moment as fits, in the right direction


def test_the_image_tilts_when_the_drone_accelerates():
    # Flying forward fast needs the nose down: the camera's optical axis points below horizon.
    w = World(make_scenario(""), seed=0, renderer="tiny")
    ref_at, _ = straight_line(w.scenario.drone.start, [8.0, 0.0, 1.2], speed=2.0, accel=2.0)
    pitches = []
    for _ in range(120):
        if w.step(ref_at(w.time)) is not None:
            axis = w.ground_truth().T_world_camera[:3, 2]
            pitches.append(math.degrees(math.asin(-axis[2])))
    assert max(pitches) > 5.0  # nose down while accelerating
    w.close()
