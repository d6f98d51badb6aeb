"""Behaviour of the CasADi NMPC (planner/mpc/nmpc.py): bounds, the terminal stop, exact clearance to people,
structure and the geofence, fallbacks, determinism, and its place among the built-in planners."""
import numpy as np
import pytest

from planner.mpc.config import MPCConfig, NMPCConfig
from planner.mpc.nmpc import NMPC
from planner.types import ObstaclePrediction
from tests.planner.mpc.test_mpc import PERSON, TOL, assert_clear_of_people, line_ref, person

CFG = MPCConfig()
VMAX = np.array([CFG.v_max_xy, CFG.v_max_xy, CFG.v_max_z])
AMAX = np.array([CFG.a_max_xy, CFG.a_max_xy, CFG.a_max_z])


def assert_feasible(tr, zband=(CFG.z_min, CFG.z_max)):
    """Within the limits, and at rest at the end (the terminal stop)."""
    assert np.all(np.abs(tr.velocities[1:]) <= VMAX + TOL)
    assert np.all(np.abs(tr.accelerations) <= AMAX + 1e-9)
    assert np.all(tr.positions[1:, 2] >= zband[0] - TOL) and np.all(tr.positions[1:, 2] <= zband[1] + TOL)
    assert np.allclose(tr.velocities[-1], 0.0, atol=TOL)


def closed_loop(nm, p, goal, people, steps):
    """Receding horizon every 0.1 s (the NMPC's plans are 0.2 s a step): solve, fly 0.1 s of the plan exactly.
    Returns the results and the flown path sampled 5 times a step, with its times."""
    v, a = np.zeros(3), np.zeros(3)
    results, samples, times = [], [], []
    for k in range(steps):
        t = k * CFG.dt
        obs = [person(i, c0, vel, t) for i, (c0, vel) in enumerate(people)]
        r = nm.solve(t, p, v, a, *line_ref(p, goal), obstacles=obs)
        results.append(r)
        for j in range(5):
            samples.append(r.trajectory.sample(t + j * CFG.dt / 5)[0])
            times.append(t + j * CFG.dt / 5)
        p, v, a = r.trajectory.sample(t + CFG.dt)
    return results, np.array(samples), np.array(times)


def test_free_space_tracks_the_reference_on_its_coarser_grid_and_ends_at_rest():
    nm = NMPC()
    assert nm.N == CFG.horizon // 2 and nm.cfg.dt == pytest.approx(2 * CFG.dt)
    p, goal = np.array([0.0, 0.0, 1.2]), np.array([30.0, 0.0, 1.2])
    p_ref, v_ref = line_ref(p, goal)
    r = nm.solve(0.0, p, np.array([1.5, 0.0, 0.0]), np.zeros(3), p_ref, v_ref)
    assert r.status == "solved"
    tr = r.trajectory
    assert tr.dt == pytest.approx(0.2) and tr.positions.shape == (nm.N + 1, 3)
    assert_feasible(tr)
    assert np.all(np.abs(tr.positions[:, 1]) < 0.01) and np.all(np.abs(tr.positions[:, 2] - 1.2) < 0.01)
    assert tr.velocities[1, 0] > 1.3  # keeps going now, stops only at the horizon's end
    # the same problem on the MPC's own grid
    fine = NMPC(ncfg=NMPCConfig(stride=1)).solve(0.0, p, np.array([1.5, 0.0, 0.0]), np.zeros(3), p_ref, v_ref)
    assert fine.status == "solved" and fine.trajectory.dt == pytest.approx(CFG.dt)
    assert_feasible(fine.trajectory)


def test_without_people_the_qp_gives_ipopts_optimum():
    """With no moving obstacle the problem is a convex QP, solved by OSQP (qpsol): the same plan as IPOPT's on
    the same problem (the one-person bucket, its rows left inactive), beside a wall and from a turn."""
    p, goal = np.array([0.0, 0.3, 1.1]), np.array([6.0, 1.5, 1.4])
    p_ref, v_ref = line_ref(p, goal)
    wall = np.array([[x, 1.2, z] for x in np.arange(1.0, 4.0, 0.1) for z in np.arange(0.8, 1.8, 0.1)])
    args = (0.0, p, np.array([1.0, -0.8, 0.2]), np.array([0.5, 0.0, 0.0]), p_ref, v_ref)
    fence = (np.array([-1.0, -2.0]), np.array([20.0, 2.0]))
    qp, nlp = NMPC(), NMPC()
    nlp._problems[0] = nlp._problems[1]
    a = qp.solve(*args, static_points=wall, geofence=fence)
    b = nlp.solve(*args, static_points=wall, geofence=fence)
    assert a.status == b.status == "solved" and b.iterations > 0
    free = qp.solve(*args, geofence=fence)
    assert np.abs(free.trajectory.positions - a.trajectory.positions).max() > 0.2  # the wall's planes bind
    np.testing.assert_allclose(a.trajectory.accelerations, b.trajectory.accelerations, atol=2e-3)
    np.testing.assert_allclose(a.trajectory.positions, b.trajectory.positions, atol=1e-3)


def test_head_on_walker_is_passed_outside_the_exact_ellipse():
    """Exactly head-on, without a guide: the tie-break of the initial guess picks a side."""
    people = [((6.0, 0.0, 0.9), (-1.0, 0.0, 0.0))]
    results, samples, times = closed_loop(NMPC(), np.array([0.0, 0.0, 1.2]), np.array([12.0, 0.0, 1.2]), people,
                                          steps=60)
    assert all(r.status == "solved" for r in results)
    for r in results:
        assert_feasible(r.trajectory)
    assert_clear_of_people(samples, times, people)
    assert samples[-1, 0] > 7.0  # past the walker, not retreating


def test_clearance_rows_are_exact_at_the_knots():
    """One plan against a person standing across the way: every knot keeps outside the person's elliptic
    cylinder (robot radius and margin added), measured exactly, not on a tangent plane."""
    nm = NMPC()
    p, goal = np.array([0.0, 0.0, 1.2]), np.array([8.0, 0.0, 1.2])
    ob = ObstaclePrediction(id=0, center=np.array([2.5, 0.1, 0.9]), size=PERSON, std_growth=0.0)
    p_ref, v_ref = line_ref(p, goal)
    r = nm.solve(0.0, p, np.zeros(3), np.zeros(3), p_ref, v_ref, obstacles=[ob])
    assert r.status == "solved" and r.max_slack_dynamic < 1e-3
    a = PERSON[0] / 2 + CFG.robot_radius + CFG.dynamic_margin
    d = np.hypot(*(r.trajectory.positions[1:, :2] - ob.center[:2]).T)
    assert np.all(d >= a - 1e-3)
    assert np.min(d) < a + 0.3  # it passes close, not far around


def test_a_wall_of_voxels_and_the_geofence_hold():
    nm = NMPC()
    wx, wz = np.meshgrid(np.arange(2.0, 6.0, 0.1), np.arange(0.6, 1.8, 0.2))
    wall = np.column_stack([wx.ravel(), np.full(wx.size, 0.6), wz.ravel()])
    p, goal = np.array([0.0, 0.3, 1.2]), np.array([8.0, 1.0, 1.2])
    fence = (np.array([-1.0, -1.5]), np.array([20.0, 1.5]))
    p_ref, v_ref = line_ref(p, goal)
    r = nm.solve(0.0, p, np.array([1.0, 0.0, 0.0]), np.zeros(3), p_ref, v_ref, static_points=wall, geofence=fence)
    assert r.status == "solved"
    pos = r.trajectory.positions
    req = CFG.robot_radius + CFG.voxel_size / 2 + CFG.static_margin
    assert np.min(np.linalg.norm(pos[1:, None, :] - wall[None], axis=2)) >= req - 0.02
    assert np.all(pos[:, 1] <= fence[1][1] - CFG.geofence_margin + TOL)
    # a start inside the fence's margin may not go closer to the wall, but is not refused
    r = nm.solve(1.0, np.array([0.0, 1.2, 1.2]), np.zeros(3), np.zeros(3), *line_ref(np.array([0.0, 1.2, 1.2]),
                 np.array([8.0, 1.45, 1.2])), geofence=fence)
    assert r.status == "solved" and np.all(r.trajectory.positions[:, 1] <= 1.2 + TOL)


def test_bad_input_falls_back_and_identical_input_gives_identical_plans():
    p, goal = np.array([0.0, 0.0, 1.2]), np.array([8.0, 0.0, 1.2])
    p_ref, v_ref = line_ref(p, goal)
    nm = NMPC()
    r = nm.solve(0.0, np.array([np.nan, 0.0, 1.2]), np.zeros(3), np.zeros(3), p_ref, v_ref)
    assert r.status == "fallback:nonfinite_input" and np.all(np.isfinite(r.trajectory.positions))
    r = nm.solve(0.0, p, np.array([9.0, 0.0, 0.0]), np.zeros(3), p_ref, v_ref)
    assert r.status == "fallback:infeasible_start"
    bad = ObstaclePrediction(id=1, center=np.array([np.inf, 0.0, 0.9]), size=PERSON)
    ob = ObstaclePrediction(id=0, center=np.array([3.0, 0.0, 0.9]), size=PERSON, velocity=np.array([-0.5, 0.0, 0.0]))
    a = NMPC().solve(0.0, p, np.zeros(3), np.zeros(3), p_ref, v_ref, obstacles=[ob, bad])
    b = NMPC().solve(0.0, p, np.zeros(3), np.zeros(3), p_ref, v_ref, obstacles=[ob, bad])
    assert a.ignored_obstacles == 1 and a.status == "solved"
    assert np.array_equal(a.trajectory.positions, b.trajectory.positions)
    with pytest.raises(ValueError, match="stride"):
        NMPC(ncfg=NMPCConfig(stride=0))


def test_nmpc_is_a_built_in_planner():
    from experiments.plugins import PluginError
    from experiments.config_limits import PLANNER_NAMES
    from experiments.registry import BUILTIN_PLANNERS, check_planner, make_planner, planner_label
    from planner.mpc.nmpc import NMPC as Solver
    from planner.nominal.navigator import MPCPlanner

    assert tuple(BUILTIN_PLANNERS) == PLANNER_NAMES  # the command line's list, kept light of imports
    check_planner("nmpc")
    planner = make_planner("nmpc", 0.3)
    assert isinstance(planner.planner, MPCPlanner) and isinstance(planner.planner.mpc, Solver)
    assert planner_label("nmpc") == "PassiveSafetyShield+NMPC" and planner_label("default") == "PassiveSafetyShield"
    with pytest.raises(PluginError, match="nmpc"):
        check_planner("nmpcc")
    with pytest.raises(ValueError, match="unknown solver"):
        MPCPlanner(solver="ipopt")
