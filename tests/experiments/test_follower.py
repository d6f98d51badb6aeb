"""experiments.follower: the plan sampled into the controller's references, the acceleration fed forward ahead
of time so that a stop flown by the simulated quadrotor ends at rest and stays there."""
import numpy as np
import pytest

from conftest import make_scenario
from experiments.episode_config import EpisodeConfig
from experiments.fault import AT_REST_SPEED as AT_REST
from experiments.follower import TrajectoryFollower
from planner.fallback import braking_1d
from planner.shield.candidates import roll
from planner.shield.shield import ShieldConfig
from planner.types import Trajectory
from sim import World
from sim.trajectories import straight_line

SHIELD = ShieldConfig()
CONTROL_DT = 1.0 / 120.0  # s, for the sampling test (it sets only how fast the heading turns)


def _ramp(t0=0.0):
    """A plan that speeds up along x at 1 m/s^2 for 1 s, then at 3 m/s^2 for 1 s."""
    acc = np.zeros((20, 3))
    acc[:10, 0], acc[10:, 0] = 1.0, 3.0
    vel = np.vstack([np.zeros(3), np.cumsum(acc * 0.1, axis=0)])
    pos = np.vstack([np.zeros(3), np.cumsum(vel[:-1] * 0.1 + 0.5 * acc * 0.01, axis=0)])
    return Trajectory(t0, 0.1, pos, vel, acc)


def test_the_acceleration_is_the_plans_lead_seconds_ahead_the_rest_the_plans_now():
    tr = _ramp()
    f = TrajectoryFollower(0.0, 1.2, CONTROL_DT, lead=0.08)
    f.follow(tr)
    ref = f.reference(0.95, np.zeros(3))
    p, v, a = tr.sample(0.95)
    np.testing.assert_array_equal(ref.position, p)
    np.testing.assert_array_equal(ref.velocity, v)
    np.testing.assert_array_equal(ref.acceleration, [3.0, 0.0, 0.0])  # 1.03 s: the second phase already
    np.testing.assert_array_equal(f.acceleration, a)  # the planner is told the plan's own
    late = TrajectoryFollower(0.0, 1.2, CONTROL_DT)
    late.follow(tr)
    np.testing.assert_array_equal(late.reference(0.95, np.zeros(3)).acceleration, [1.0, 0.0, 0.0])


def _speeds_after_stop(speed: float, lead: float) -> np.ndarray:
    """Cruise along x at ``speed``, then fly the shield's standing-still motion, planned anew every 0.1 s from
    the drone's state as the closed loop flies it; the drone's 3D speeds over the 3 s after the stop begins."""
    w = World(make_scenario(""), seed=0, camera=False)
    start = np.array(w.scenario.drone.start, float)
    cruise, _ = straight_line(start, start + [100.0, 0.0, 0.0], speed, accel=2.0)
    while w.time < speed / 2.0 + 1.5:  # speeding up, then 1.5 s at the speed
        w.step(cruise(w.time))
    control_dt = w.dt * w.steps_per_control
    follower, speeds = TrajectoryFollower(0.0, 1.2, control_dt, lead), []
    per_plan = int(round(SHIELD.dt / control_dt))
    for step in range(int(3.0 / control_dt)):
        s = w.state()
        if step % per_plan == 0:
            m = roll(s.position, s.velocity, np.zeros((1, 2)), SHIELD.commit_time, SHIELD.dt, SHIELD.a_max,
                     SHIELD.a_brake, SHIELD.v_max)
            z, vz = braking_1d(float(s.position[2]), float(s.velocity[2]), SHIELD.a_brake, SHIELD.dt, m.A.shape[1])
            follower.follow(Trajectory(w.time, SHIELD.dt, np.column_stack([m.P[0], z]),
                                       np.column_stack([m.V[0], vz]), np.column_stack([m.A[0], np.diff(vz) / SHIELD.dt]),
                                       yaw=0.0))
        w.step(follower.reference(w.time, s.position))
        speeds.append(float(np.linalg.norm(w.state().velocity)))
    return np.array(speeds)


def _overshoot(speeds: np.ndarray) -> float:
    """The highest speed after the drone first comes within half the at-rest speed of rest."""
    first = int(np.argmax(speeds < 0.5 * AT_REST))
    assert speeds[first] < 0.5 * AT_REST, "the drone never came to rest"
    return float(speeds[first:].max())


@pytest.mark.parametrize("speed", [0.6, 1.0, 2.0])
def test_a_stop_fed_forward_ahead_stays_at_rest_once_reached(speed):
    assert _overshoot(_speeds_after_stop(speed, EpisodeConfig().accel_lead)) < 0.7 * AT_REST


def test_a_stop_fed_forward_at_its_own_time_overshoots_into_motion():
    """Why the lead: the tilt follows the acceleration late, and the drone moves back."""
    assert _overshoot(_speeds_after_stop(1.0, 0.0)) > AT_REST
