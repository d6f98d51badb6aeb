"""The maneuver layer (planner.nominal.maneuvers) and the cost-to-go field it scores progress with."""
import math

import numpy as np
import pytest

from planner.map.clearance import static_clearance
from planner.mpc.config import MPCConfig
from planner.mpc.solver import MPC
from planner.nominal.global_path import cost_to_go
from planner.nominal.maneuvers import ManeuverConfig, ManeuverSelector, hypotheses
from planner.types import ObstaclePrediction

RES = 0.1
ORIGIN = np.array([-0.5, -2.5])
FENCE = (np.array([0.0, -2.0]), np.array([16.0, 2.0]))
GOAL = np.array([15.5, 0.0])
R_ROBOT = 0.437


def _fields(occupied=None):
    occ = np.zeros((170, 50), bool) if occupied is None else occupied
    clear = static_clearance(occ, RES, ORIGIN, geofence=FENCE)
    return clear, cost_to_go(occ, ORIGIN, RES, GOAL)


def _person(x, y, vx, vy, oid=1):
    return ObstaclePrediction(id=oid, center=np.array([x, y, 0.9]), size=np.array([0.5, 0.6, 1.8]),
                              velocity=np.array([vx, vy, 0.0]))


def _choose(sel, p, v, obstacles, occupied=None, t0=0.0, goal=GOAL):
    clear, field = _fields(occupied)
    return sel.choose(t0, p, v, goal - np.asarray(p), obstacles, clear, field, ORIGIN, RES, goal)


def _roll_person(ob, t):
    return ob.predict(np.asarray(t))[:, :2]


# --- cost to go -------------------------------------------------------------------------------------

def test_cost_to_go_is_the_path_length_around_obstacles():
    free = np.zeros((170, 50), bool)
    g = cost_to_go(free, ORIGIN, RES, GOAL)
    assert g[10, 25] == pytest.approx(15.0, abs=0.01)  # straight along the grid: 150 cells
    assert g[150, 25] == pytest.approx(1.0, abs=0.01)
    wall = free.copy()
    wall[80:83, 0:40] = True  # a wall across most of the corridor at x = 7.5-7.8, a gap at the top
    gw = cost_to_go(wall, ORIGIN, RES, GOAL)
    assert gw[10, 25] > g[10, 25] + 1.0  # the detour through the gap
    assert np.isfinite(gw).all()
    inside = gw[81, 20]  # a blocked cell: finite, higher than the free cells beside the wall
    assert np.isfinite(inside) and inside > min(gw[79, 20], gw[84, 20])


def test_cost_to_go_of_a_sealed_goal_is_all_inf_and_of_a_cut_off_region_leads_out():
    free = np.zeros((60, 30), bool)
    free[30, :] = True  # a wall from side to side: the left part is cut off from the goal
    g = cost_to_go(free, (0.0, 0.0), RES, (5.0, 1.5))
    assert np.isfinite(g).all()
    assert g[10, 15] > g[29, 15] > g[31, 15]  # cut-off cells fall toward the wall, beyond which is the goal
    sealed = np.ones((20, 20), bool)
    assert np.isinf(cost_to_go(sealed, (0.0, 0.0), RES, (1.0, 1.0))).all()


# --- futures of moving obstacles --------------------------------------------------------------------

def test_hypotheses_keep_the_prediction_turn_at_walking_rates_and_stop():
    cfg = ManeuverConfig()
    t = 0.1 * np.arange(1, 26)
    ob = _person(5.0, 0.0, -1.0, 0.0)
    paths, w = hypotheses(ob, t, cfg)
    assert paths.shape == (9, 25, 2) and w.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(paths[0], _roll_person(ob, t))  # its own prediction first
    stop = paths[1]
    assert stop[-1, 0] == pytest.approx(5.0 - 1.0 / (2 * cfg.stop_decel), abs=1e-9)  # braked to a stand
    heading_end = [math.atan2(*(p[-1] - p[-2])[::-1]) for p in paths[2:]]
    turned = np.degrees(np.abs([(h - math.pi + math.pi) % (2 * math.pi) - math.pi for h in heading_end]))
    np.testing.assert_allclose(np.sort(turned), [45, 45, 90, 90, 135, 135, 180], atol=1e-6)
    steps = np.linalg.norm(np.diff(paths[2:], axis=1), axis=2) / 0.1
    assert steps.max() <= 1.0 + 1e-9  # no hypothesis walks faster than the person does
    standing, ws = hypotheses(_person(5.0, 0.0, 0.0, 0.0), t, cfg)
    assert standing.shape[0] == 10 and ws.sum() == pytest.approx(1.0)  # keep, stop, 8 directions
    ends = standing[2:, -1] - np.array([5.0, 0.0])
    assert np.allclose(np.linalg.norm(ends, axis=1), np.linalg.norm(ends[0]))  # the same reach every way


# --- candidates -------------------------------------------------------------------------------------

def test_candidates_are_trajectories_the_mpc_can_fly():
    sel = ManeuverSelector()
    P, V, A = sel.candidates(np.array([2.0, 0.3]), np.array([1.8, -0.7]), np.array([1.0, 0.2]))
    assert P.shape == ((len(sel.cfg.along) * len(sel.cfg.across)) ** 2, 25, 2)  # every pair of targets
    assert np.abs(A).max() <= sel.a_max + 1e-9 and np.abs(V).max() <= sel.v_max
    dt, p, v = sel.dt, np.array([2.0, 0.3]), np.array([1.8, -0.7])
    for k in range(25):  # the double integrator under piecewise-constant acceleration, exactly
        p = p + v * dt + 0.5 * A[:, k] * dt * dt
        v = v + A[:, k] * dt
        np.testing.assert_allclose(P[:, k], p, atol=1e-9)
        np.testing.assert_allclose(V[:, k], v, atol=1e-9)


# --- choices ----------------------------------------------------------------------------------------

def _min_gap(man, ob, t):
    """Smallest centre distance minus the contact radius the selector uses, over the horizon."""
    rad = 0.5 * min(max(ob.size[0], ob.size[1]), ManeuverConfig().max_extent) + R_ROBOT
    return float(np.min(np.linalg.norm(man.positions[1:] - _roll_person(ob, t), axis=1)) - rad)


@pytest.mark.parametrize("y_person", [-0.3, 0.3])
def test_a_head_on_walker_is_passed_on_the_side_with_room(y_person):
    sel = ManeuverSelector()
    ob = _person(6.0, y_person, -1.0, 0.0)
    man = _choose(sel, (2.0, 0.0), (1.5, 0.0), [ob])
    t = sel.t
    assert _min_gap(man, ob, t) > 0.1  # clear of the walker all along its prediction
    lateral = man.positions[1:, 1] - _roll_person(ob, t)[:, 1]
    closest = np.argmin(np.linalg.norm(man.positions[1:] - _roll_person(ob, t), axis=1))
    assert np.sign(lateral[closest]) == -np.sign(y_person)  # the side away from the walker's offset
    assert np.all(np.abs(man.positions[:, 1]) < 2.0 - R_ROBOT)  # inside the walls


def test_a_crossing_walker_is_passed_with_the_full_margin():
    """A walker crossing from the right, 2.5 m ahead: whether the drone passes behind it or well ahead of
    it, it keeps the contact distance plus the dynamic margin from the walker's prediction."""
    sel = ManeuverSelector()
    ob = _person(4.5, -1.6, 0.0, 1.0)
    man = _choose(sel, (2.0, 0.0), (1.5, 0.0), [ob])
    assert _min_gap(man, ob, sel.t) >= sel.cfg.dynamic_margin - 0.02
    assert man.positions[-1, 0] > 5.5  # and it goes on


def test_static_obstacles_and_walls_are_kept_clear_and_a_goal_near_a_wall_is_reached():
    occ = np.zeros((170, 50), bool)
    occ[55:62, 20:30] = True  # a 0.7 x 1.0 m block at x = 5.0-5.7, y = -0.5-0.5 on the flight line
    clear, _ = _fields(occ)
    sel = ManeuverSelector()
    man = _choose(sel, (3.0, 0.0), (1.5, 0.0), [], occupied=occ)
    i = np.floor((man.positions[:, 0] - ORIGIN[0]) / RES).astype(int)
    j = np.floor((man.positions[:, 1] - ORIGIN[1]) / RES).astype(int)
    assert clear[i, j].min() >= R_ROBOT  # around the block
    assert man.positions[-1, 0] > 6.0  # and on toward the goal
    near = ManeuverSelector()  # the goal lies 0.5 m from the end wall, inside the usual static margin
    for k in range(30):
        m = _choose(near, (14.5, 0.0), (0.0, 0.0), [], t0=0.1 * k)
    assert np.linalg.norm(m.positions[-1] - GOAL) < 0.3


def test_the_choice_is_kept_when_the_walker_wavers():
    """A head-on walker straight on the flight line, its heading wavering by a few degrees from plan to plan:
    the side chosen first is kept."""
    sel = ManeuverSelector()
    rng = np.random.default_rng(0)
    p, v = np.array([2.0, 0.0]), np.array([1.5, 0.0])
    sides = []
    for k in range(8):
        a = math.pi + rng.normal(0.0, math.radians(4))
        ob = _person(6.5 - 0.1 * k, 0.0, math.cos(a), math.sin(a))
        man = _choose(sel, p, v, [ob], t0=0.1 * k)
        sides.append(np.sign(man.positions[10, 1]))
        p, v = man.positions[1], man.velocities[1]
    assert len(set(sides)) == 1 and sides[0] != 0


def test_the_mpc_follows_the_guides_side():
    """Guided, the MPC passes a head-on walker on the guide's side, whichever side its tie-break would take."""
    mpc_cfg = MPCConfig(robot_radius=R_ROBOT)
    t = 0.1 * np.arange(1, 26)
    ob = _person(5.0, 0.0, -1.0, 0.0)
    for side in (-1.0, 1.0):
        mpc = MPC(mpc_cfg)
        guide = np.column_stack([2.0 + 1.5 * t, side * np.minimum(1.2, 1.5 * t), np.full(25, 1.2)])
        v_ref = np.column_stack([np.full(25, 1.5), np.where(1.5 * t < 1.2, side * 1.5, 0.0), np.zeros(25)])
        r = mpc.solve(0.0, [2.0, 0.0, 1.2], [1.5, 0.0, 0.0], [0.0, 0.0, 0.0], guide, v_ref, obstacles=[ob],
                      guide=guide)
        assert r.status == "solved"
        person = ob.predict(t)
        k = int(np.argmin(np.linalg.norm(r.trajectory.positions[1:, :2] - person[:, :2], axis=1)))
        assert np.sign(r.trajectory.positions[k + 1, 1] - person[k, 1]) == side


# --- view term ----------------------------------------------------------------------------------------

# --- the cost and its branch and bound -----------------------------------------------------------------

def _costs_by_definition(P, A, stop, clear, goal, O, R, owner, prior, gamma, keep, cfg, r, goal_xy, r_goal, m_goal):
    """Every candidate's cost terms (C, 5), from the module docstring's formula, candidate by candidate."""
    out = []
    for c in range(len(P)):
        pts = np.vstack([P[c], stop[c][None]])
        ij = np.clip(np.floor((pts - ORIGIN) / RES).astype(int), 0, np.array(clear.shape) - 1)
        d = clear[ij[:, 0], ij[:, 1]]
        near = np.sum((pts - goal_xy) ** 2, axis=1) < cfg.near_goal ** 2
        rr, mm = np.where(near, r_goal, r), np.where(near, m_goal, cfg.static_margin)
        st = cfg.w_hit * np.sum(d < rr) + cfg.w_static * np.sum(np.maximum(rr + mm - d, 0.0)[:-1] ** 2)
        g = goal[ij[:-1, 0], ij[:-1, 1]]
        jg = cfg.w_goal * 0.5 * (g[-1] + g.mean())
        e = np.linalg.norm(P[c][None] - O, axis=2) - R  # (H, K)
        ch = np.sum(gamma * np.where(e < cfg.dynamic_margin, cfg.w_near * (cfg.dynamic_margin - e) ** 2
                                     + cfg.w_hit * (e < 0), 0.0), axis=1)
        dyn = sum(np.sum(prior[owner == o] * ch[owner == o]) + cfg.worst_case * ch[owner == o].max()
                  for o in np.unique(owner))
        kp = cfg.w_keep * np.mean(np.sum((P[c, :len(keep)] - keep) ** 2, axis=1)) if len(keep) else 0.0
        ef = cfg.w_acc * np.mean(np.sum(A[c] ** 2, axis=1))
        out.append([jg, st, dyn, kp, ef])
    return np.array(out)


def _random_case(seed):
    rng = np.random.default_rng(seed)
    cfg, C, K = ManeuverConfig(), 300, 25
    P = np.cumsum(rng.normal(0.0, 0.15, (C, K, 2)), axis=1) + np.array([3.0, 0.0])
    A = rng.normal(0.0, 1.0, (C, K, 2))
    stop = P[:, -1] + rng.normal(0.0, 0.2, (C, 2))
    occ = rng.random((170, 50)) < 0.02
    clear, goal = static_clearance(occ, RES, ORIGIN, geofence=FENCE), cost_to_go(occ, ORIGIN, RES, GOAL)
    n_obst = 3
    owner = np.repeat(np.arange(n_obst), 9).astype(np.int64)
    O = np.array([3.0, 0.0]) + np.cumsum(rng.normal(0.0, 0.1, (len(owner), K, 2)), axis=1)
    R = np.full((len(owner), K), 0.7)
    prior = rng.random(len(owner))
    gamma = rng.random((len(owner), K))
    keep = P[7, :10] + rng.normal(0.0, 0.05, (10, 2))
    goal_xy = np.array([4.0, 0.5])  # near the candidates: the goal's own static thresholds are used
    return dict(P=P, A=A, stop=stop, clear=clear, goal=goal, O=O, R=R, owner=owner, prior=prior, gamma=gamma,
                keep=keep, goal_xy=goal_xy, cfg=cfg)


def _run_best(k, first, group=0, shared=0):
    from planner.nominal.maneuvers import _best
    cfg, parts = k["cfg"], np.empty(5)
    b, cost = _best(k["P"], k["A"], k["stop"], k["clear"], k["goal"], ORIGIN[0], ORIGIN[1], RES, k["O"], k["R"],
                    k["owner"], k["prior"], 3, k["gamma"], k["keep"], R_ROBOT, cfg.static_margin, cfg.dynamic_margin,
                    cfg.w_goal, cfg.w_hit, cfg.w_static, cfg.w_near, cfg.worst_case, cfg.w_keep, cfg.w_acc,
                    k["goal_xy"][0], k["goal_xy"][1], cfg.near_goal, 0.3, 0.05, first, group, shared,
                    parts)
    return b, cost, parts


def _reference(k):
    return _costs_by_definition(k["P"], k["A"], k["stop"], k["clear"], k["goal"], k["O"], k["R"], k["owner"],
                                k["prior"], k["gamma"], k["keep"], k["cfg"], R_ROBOT, k["goal_xy"], 0.3, 0.05)


@pytest.mark.parametrize("seed", range(6))
def test_branch_and_bound_picks_the_least_cost_candidate(seed):
    k = _random_case(seed)
    ref = _reference(k)
    J = ref.sum(axis=1)
    for first in (-1, 7, int(np.argmax(J))):
        b, cost, parts = _run_best(k, first)
        assert b == int(np.argmin(J))
        assert cost == pytest.approx(J.min(), rel=1e-12)
        np.testing.assert_allclose(parts, ref[b], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_shared_first_steps_give_the_same_choice_bit_for_bit(seed):
    """Rows of one group sharing their first steps (as _two_phase writes them) are summed from one prefix:
    the same choice, cost and terms as summing every row from its start."""
    k = _random_case(seed)
    T, ks = 17, 10  # 289 of the 300 rows in 17 groups; the rest on their own
    for a in range(T):
        for key in ("P", "A"):
            k[key][a * T + 1:a * T + T, :ks] = k[key][a * T, :ks]
    grouped = {}
    for first in (-1, 299, 5):
        b0, c0, p0 = _run_best(k, first)
        b1, c1, p1 = _run_best(k, first, T, ks)
        assert (b0, c0) == (b1, c1)
        assert np.array_equal(p0, p1)
        grouped[first] = (b1, c1, p1)
    for a in range(T):  # the shared steps are read in each group's first row only: others' may be anything
        k["P"][a * T + 1:a * T + T, :ks] = k["O"][0, :ks]  # (here: on a walker)
        k["A"][a * T + 1:a * T + T, :ks] = 50.0
    for first in (-1, 299, 5):
        b2, c2, p2 = _run_best(k, first, T, ks)
        assert (b2, c2) == grouped[first][:2] and np.array_equal(p2, grouped[first][2])


@pytest.mark.parametrize("k_switch", [0, 3, 10, 25, 30])
def test_candidates_written_for_the_choice_complete_to_the_full_rows(k_switch):
    """candidates(full=False) leaves out what _best does not read; _completed gives every row back as
    full=True writes it, and the stopping points (last step) are written in every row."""
    sel = ManeuverSelector()
    sel.k_switch = k_switch
    args = (np.array([2.0, 0.3]), np.array([1.8, -0.7]), np.array([1.0, 0.2]), np.full((25, 2), 0.4),
            np.array([3.0, 1.0]))
    P, V, A = (x.copy() for x in sel.candidates(*args))
    Pp, Vp, Ap = sel.candidates(*args, out={}, full=False)
    assert np.array_equal(P[:, -1], Pp[:, -1]) and np.array_equal(V[:, -1], Vp[:, -1])
    for b in range(len(P)):
        pb, vb, ab = sel._completed(Pp, Vp, Ap, b, args[1])
        assert np.array_equal(pb, P[b]) and np.array_equal(vb, V[b]) and np.array_equal(ab, A[b])


def test_candidates_reuse_their_buffers_without_changing_them():
    sel = ManeuverSelector()
    args = (np.array([2.0, 0.3]), np.array([1.8, -0.7]), np.array([1.0, 0.2]))
    fresh = [x.copy() for x in sel.candidates(*args)]
    out = {}
    sel.candidates(np.array([0.0, 0.0]), np.array([-1.0, 0.5]), np.array([0.0, 1.0]), out=out)
    again = sel.candidates(*args, out=out)
    assert again[0] is out["P"]
    for x, y in zip(fresh, again):
        assert np.array_equal(x, y)


def test_branch_and_bound_breaks_ties_and_infinities_as_argmin_does():
    k = _random_case(0)
    b = int(np.argmin(_reference(k).sum(axis=1)))
    src, dup = (b, 0) if b > 0 else (0, 5)
    for name in ("P", "A", "stop"):
        k[name][dup] = k[name][src]  # an equal candidate
    first = max(src, dup)
    assert _run_best(k, first)[0] == min(src, dup)  # the first of equals, though the later was costed first
    k["goal"] = np.full_like(k["goal"], np.inf)  # no way to the goal: every cost infinite
    assert _run_best(k, 7)[0] == 0


def test_maneuver_weights_must_not_be_negative():
    with pytest.raises(ValueError, match="w_near"):
        ManeuverConfig(w_near=-1.0)


# --- culls by reach ------------------------------------------------------------------------------------

def _costs_in_kernel_order(k, cfg):
    """Every candidate's cost J summed as _best sums it without any cull (the same operations in the same
    order, in Python): what the culled kernel must reproduce bit for bit."""
    from planner.nominal.maneuvers import _static_terms
    P, A, O, R, gamma, keep = k["P"], k["A"], k["O"], k["R"], k["gamma"], k["keep"]
    C, K = P.shape[:2]
    m_d = cfg.dynamic_margin
    far = np.where(R + m_d > 0.0, ((R + m_d) * (1.0 + 1e-9)) ** 2, -1.0)
    out = []
    for c in range(C):
        st, g_sum, g_end = _static_terms(P, k["stop"], k["clear"], k["goal"], ORIGIN[0], ORIGIN[1], RES, R_ROBOT,
                                         cfg.static_margin, cfg.w_hit, cfg.w_static, k["goal_xy"][0],
                                         k["goal_xy"][1], cfg.near_goal, 0.3, 0.05, c, 0, K + 1, 0.0, 0.0, 0.0)
        jg = cfg.w_goal * 0.5 * (g_end + g_sum / K)
        kp = 0.0
        for j in range(len(keep)):
            dx, dy = P[c, j, 0] - keep[j, 0], P[c, j, 1] - keep[j, 1]
            kp += dx * dx + dy * dy
        kp = cfg.w_keep * kp / len(keep)
        ef = 0.0
        for j in range(K):
            ef += A[c, j, 0] * A[c, j, 0] + A[c, j, 1] * A[c, j, 1]
        ef = cfg.w_acc * ef / K
        dyn = 0.0
        for o in np.unique(k["owner"]):
            exp, mx = 0.0, 0.0
            for h in np.flatnonzero(k["owner"] == o):
                s = 0.0
                for j in range(K):
                    dx, dy = P[c, j, 0] - O[h, j, 0], P[c, j, 1] - O[h, j, 1]
                    d2 = dx * dx + dy * dy
                    if d2 > far[h, j]:
                        continue
                    e = math.sqrt(d2) - R[h, j]
                    if e < m_d:
                        v = cfg.w_near * (m_d - e) * (m_d - e)
                        if e < 0.0:
                            v += cfg.w_hit
                        s += gamma[h, j] * v
                exp += k["prior"][h] * s
                mx = max(mx, s)
            dyn += exp + cfg.worst_case * mx
        out.append(jg + st + dyn + kp + ef)
    return np.array(out)


@pytest.mark.parametrize("seed", range(3))
def test_the_reach_cull_leaves_every_cost_bit_for_bit(seed):
    """Obstacles near some candidates and far from others (some hypotheses culled per block, some kept):
    the choice and its cost are those of summing every term, to the last bit."""
    k = _random_case(seed)
    rng = np.random.default_rng(seed + 10)
    k["O"] = k["O"] + rng.uniform(-2.5, 2.5, (3, 1, 1, 2)).repeat(9, axis=0).reshape(27, 1, 2)  # spread out
    k["O"][9:18] += 40.0  # one obstacle beyond every candidate's reach
    J = _costs_in_kernel_order(k, k["cfg"])
    for first in (-1, 7):
        b, cost, _ = _run_best(k, first)
        assert b == int(np.argmin(J)) and cost == J.min()


def test_far_obstacles_are_culled_and_change_nothing():
    sel = ManeuverSelector()
    near = [_person(4.0, 0.5, -1.0, 0.0, 1), _person(3.0, -1.0, 0.0, 0.8, 2), _person(6.0, 0.0, 0.0, 0.0, 3)]
    far = [_person(40.0 + i, (-1) ** i * 1.5, -1.5, 0.0, 10 + i) for i in range(5)]
    p, v = np.array([2.0, 0.0]), np.array([1.0, 0.0])
    mask = sel._within_reach(p, v, np.array([[o.center[0], o.center[1]] for o in near + far]),
                             np.array([np.hypot(*o.velocity[:2]) for o in near + far]),
                             np.array([o.predict(sel.t)[:, :2] for o in near + far]),
                             np.full((8, sel.N), 1.0))
    assert mask.tolist() == [True] * 3 + [False] * 5
    a = _choose(ManeuverSelector(), p, v, near)
    b = _choose(ManeuverSelector(), p, v, near[:1] + far[:2] + near[1:] + far[2:])
    assert a.cost == b.cost and a.parts == b.parts and np.array_equal(a.positions, b.positions)


@pytest.mark.parametrize("seed", [0, pytest.param(1, marks=pytest.mark.slow), pytest.param(2, marks=pytest.mark.slow)])
def test_an_obstacle_culled_by_reach_is_out_of_reach_of_every_candidate(seed):
    """The cull's claim itself: every future of an obstacle _within_reach leaves out stays farther than its
    radius plus the dynamic margin from every candidate at every step (full candidates, every row)."""
    from planner.nominal.maneuvers import futures
    rng = np.random.default_rng(seed)
    sel, cfg = ManeuverSelector(), ManeuverConfig()
    p, v = np.array([2.0, 0.0]), rng.uniform(-2.5, 2.5, 2)
    obs = [_person(*(p + rng.uniform(-12, 12, 2)), *rng.uniform(-1.6, 1.6, 2), oid=i) for i in range(300)]
    rad = np.array([0.5 * min(0.6, cfg.max_extent) + sel.r + o.std_at(sel.t) for o in obs])
    keep = np.array([o.predict(sel.t)[:, :2] for o in obs])
    mask = sel._within_reach(p, v, np.array([[o.center[0], o.center[1]] for o in obs]),
                             np.array([np.hypot(*o.velocity[:2]) for o in obs]), keep, rad)
    assert 0 < mask.sum() < len(obs)
    P, _, _ = sel.candidates(p, v, np.array([1.0, 0.0]), np.full((sel.N, 2), 2.0), np.array([3.0, 1.0]))
    culled = [o for o, m in zip(obs, mask) if not m]
    paths, _, count = futures(culled, sel.t, cfg)
    radius = np.repeat(rad[~mask], count, axis=0)  # the largest radius any future has (evasion only shrinks it)
    gap = np.min(np.linalg.norm(P[:, None] - paths[None], axis=3), axis=0) - radius  # (H, N)
    assert gap.min() >= cfg.dynamic_margin


def test_futures_of_several_obstacles_are_each_ones_own():
    cfg = ManeuverConfig()
    t = 0.1 * np.arange(1, 26)
    obs = [_person(5.0, 0.0, -1.0, 0.0, 1), _person(2.0, 1.0, 0.1, 0.0, 2), _person(3.0, -1.0, 0.0, 2.4, 3),
           _person(1.0, 1.0, 0.0, 0.0, 4)]  # walking, standing, fast, still: 9 and 10 futures interleaved
    from planner.nominal.maneuvers import futures
    paths, w, count = futures(obs, t, cfg)
    assert count.tolist() == [9, 10, 9, 10]
    start = 0
    for ob, n in zip(obs, count):
        one, wo = hypotheses(ob, t, cfg)
        assert np.array_equal(paths[start:start + n], one) and np.array_equal(w[start:start + n], wo)
        start += n
