"""Property: the built-in planners (whatever ``experiments.registry.make_planner`` returns) never raise
and always return a finite trajectory, whatever their input: positions, velocities, stamps and goals that
are NaN, infinite or huge, obstacles with such values, occupancy maps of any content, inverted or
missing geofences, and such inputs arriving after valid plans (its state carried from one call to the
next). A planner that replaces it must pass the same tests."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from experiments.registry import DEFAULT_PLANNER, make_planner
from planner.map.voxel_map import MapConfig, VoxelMap
from planner.types import ObstaclePrediction, PlannerInput, Trajectory

ROBOT_RADIUS = 0.437  # the drone's (sim/assets/quadrotor.urdf), as the closed loop sizes the planner
GOAL = np.array([15.5, 0.0, 1.2])
FENCE = (np.array([0.0, -2.0]), np.array([16.0, 2.0]))
SETTINGS = settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                             HealthCheck.data_too_large])

# Values that break arithmetic: NaN, infinities, the largest floats, and values just far enough to
# overflow an index or an allocation.
NASTY = st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -1e308, 1.7976931348623157e308, 1e8, -1e8,
                         1e-320, -0.0])
IN_CORRIDOR = st.tuples(st.floats(-1.0, 17.0), st.floats(-2.5, 2.5), st.floats(0.0, 3.0))
SMALL = st.tuples(st.floats(-3.0, 3.0), st.floats(-3.0, 3.0), st.floats(-1.0, 1.0))


def _vec(usual):
    """A (3,) vector: mostly a usual value, sometimes with nasty components, sometimes any float at all."""
    nasty = st.tuples(st.one_of(st.floats(-20, 20), NASTY), st.one_of(st.floats(-20, 20), NASTY),
                      st.one_of(st.floats(-3, 3), NASTY))
    return st.one_of(usual, usual, nasty, st.tuples(st.floats(), st.floats(), st.floats())).map(np.array)


SCALAR = st.one_of(st.floats(0.0, 100.0), NASTY, st.floats())


@st.composite
def obstacles(draw):
    out = []
    for i in range(draw(st.integers(0, 4))):
        out.append(ObstaclePrediction(
            id=draw(st.integers(-5, 2**31)), center=draw(_vec(IN_CORRIDOR)),
            size=draw(st.one_of(st.just((0.5, 0.6, 1.8)), SMALL, NASTY.map(lambda x: (x, x, x))).map(np.array)),
            velocity=draw(_vec(SMALL)), acceleration=draw(_vec(SMALL)),
            position_std=draw(st.one_of(st.floats(0.0, 1.0), NASTY)), std_growth=draw(st.one_of(st.floats(0, 1), NASTY)),
            accel_horizon=draw(st.one_of(st.floats(0.0, 3.0), NASTY)), max_speed=draw(st.one_of(st.floats(0, 5), NASTY))))
    return tuple(out)


def _corridor_map() -> VoxelMap:
    return VoxelMap(MapConfig(origin=(-0.5, -2.5, -0.1), size=(17.0, 5.0, 3.2),
                              robot_size=(2 * ROBOT_RADIUS, 2 * ROBOT_RADIUS, 0.3)))


@st.composite
def occupancy(draw):
    """None, an empty map, or the corridor's map with random voxels occupied (sparse to full)."""
    kind = draw(st.sampled_from(["none", "empty", "random", "walls"]))
    if kind == "none":
        return None
    m = _corridor_map()
    if kind != "empty":
        rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
        occ = rng.random(tuple(m.dims)) < draw(st.sampled_from([0.001, 0.02, 0.2, 1.0]))
        if kind == "walls":
            occ[:, :5, :] = occ[:, -5:, :] = True
        m.set_known(occ)
    return m


@st.composite
def planner_inputs(draw):
    fence = draw(st.sampled_from(["corridor", "none", "inverted", "nasty"]))
    geofence = {"corridor": FENCE, "none": None, "inverted": (FENCE[1], FENCE[0]),
                "nasty": (np.array([math.nan, -math.inf]), np.array([math.inf, 1e308]))}[fence]
    return PlannerInput(stamp=draw(SCALAR), position=draw(_vec(IN_CORRIDOR)), velocity=draw(_vec(SMALL)),
                        acceleration=draw(_vec(SMALL)), goal=draw(st.one_of(st.just(tuple(GOAL)), IN_CORRIDOR).map(np.array)
                                                                  if draw(st.booleans()) else _vec(IN_CORRIDOR)),
                        obstacles=draw(obstacles()), occupancy=draw(occupancy()),
                        yaw=draw(st.one_of(st.none(), st.floats(-4, 4), NASTY)), geofence=geofence)


def _valid(t: float, position=(2.0, 0.0, 1.2)) -> PlannerInput:
    return PlannerInput(stamp=t, position=np.array(position), velocity=np.array([0.5, 0.0, 0.0]),
                        acceleration=np.zeros(3), goal=GOAL, obstacles=(), occupancy=_corridor_map(), yaw=0.0,
                        geofence=FENCE)


def assert_finite_trajectory(tr) -> None:
    assert isinstance(tr, Trajectory)
    n = len(tr.accelerations)
    assert tr.positions.shape == (n + 1, 3) and tr.velocities.shape == (n + 1, 3) and tr.accelerations.shape == (n, 3)
    for a in (tr.positions, tr.velocities, tr.accelerations):
        assert np.all(np.isfinite(a))
    assert math.isfinite(tr.t0) and math.isfinite(tr.dt) and tr.dt > 0
    assert tr.yaw is None or math.isfinite(tr.yaw)
    for t in (tr.t0, tr.t0 + tr.duration / 2, tr.t0 + tr.duration + 1.0):  # and it samples finite references
        assert all(np.all(np.isfinite(x)) for x in tr.sample(t))


@pytest.fixture(scope="module", params=[DEFAULT_PLANNER, pytest.param("nmpc", marks=pytest.mark.slow)])
def planner(request):
    pl = make_planner(request.param, ROBOT_RADIUS)
    pl.plan(_valid(0.0))  # compile what it compiles once, outside the examples
    return pl


@SETTINGS
@given(inp=planner_inputs())
def test_any_input_gives_a_finite_trajectory_and_never_raises(planner, inp):
    planner.reset()
    assert_finite_trajectory(planner.plan(inp))


@SETTINGS
@given(inp=planner_inputs(), before=st.integers(1, 3))
def test_any_input_after_valid_plans_then_valid_plans_again(planner, inp, before):
    """The audit's failures came after valid plans (a NaN position or stamp then): the state they left
    must not turn a bad input into an exception, and the bad input must not break the plans after it."""
    planner.reset()
    for k in range(before):
        assert_finite_trajectory(planner.plan(_valid(0.1 * k, (2.0 + 0.05 * k, 0.0, 1.2))))
    assert_finite_trajectory(planner.plan(inp))
    after = planner.plan(_valid(0.1 * before + 0.1, (2.2, 0.0, 1.2)))
    assert_finite_trajectory(after)
    assert not after.status.startswith("error")


@pytest.mark.parametrize("change, brakes", [
    ({"position": np.array([math.nan, 0.0, 1.2])}, True),
    ({"stamp": math.nan}, True),
    ({"goal": np.array([15.5, 0.0, math.inf])}, True),
    ({"yaw": math.inf}, True),
    ({"velocity": np.array([1e308, 0.0, 0.0])}, True),  # finite, but no vehicle's
    ({"position": np.array([1e308, -1e308, 1.2])}, True),
    ({"position": np.array([0.0, 1e308, 0.0]), "yaw": None}, True),  # found by the property below
    ({"position": np.array([1e4, -50.0, 1.2])}, False),  # far off the map: planned or braked, finite
])
def test_the_audited_inputs_give_a_finite_trajectory(planner, change, brakes):
    import dataclasses

    planner.reset()
    assert planner.plan(_valid(0.0)).status == "solved"
    tr = planner.plan(dataclasses.replace(_valid(0.1), **change))
    assert_finite_trajectory(tr)
    if brakes:  # what is not finite is not planned on: brake and hold
        assert tr.status == "fallback:invalid_input"
        assert np.allclose(tr.velocities[-1], 0.0)
