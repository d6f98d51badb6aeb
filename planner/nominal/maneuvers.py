"""Maneuver selection: a few thousand short candidate motions scored against the static map, the goal
and several futures of every moving obstacle; the best one guides the MPC.

Why: the linear MPC (planner.mpc.solver) linearises each obstacle at its previous plan, so whether it passes
a person left or right, waits, backs off or goes on is inherited from that plan and a tie-break rule,
and the plan can switch sides from one replan to the next. That choice is combinatorial, and a sampled
set of whole motions, each scored over the horizon, makes it well (sampling-based local planners and
Intent-MPC's one solve per intent do the same).

Candidates: from the current state, a target velocity u1 held until t_switch, then a second target u2
until the horizon's end; each target is reached as fast as the MPC's per-axis acceleration limit allows,
so a candidate is a piecewise-constant-acceleration trajectory the MPC can fly. Targets lie on a grid in
the frame of the guiding direction (along the global path toward the goal, and left of it). Besides
them: the previous choice flown again, and, within approach_range of the point where the cost-to-go
is least (the goal, or the reachable cell nearest it), an approach that flies straight there and stops.
The grid's targets move at least 0.5 m/s for a second, so without the approach a drone stopped a
fraction of a metre short of a goal near a wall would have no candidate that ends nearer.

Futures of a moving obstacle (hypotheses h, prior weights pi_h): the prediction it came with (constant
acceleration, then constant velocity), stopping, or turning toward one of 7 other headings 45 degrees
apart at a walker's turn rate (a standing one starting to walk in 8 directions). People here turn at
random waypoints and never give way, so every turn must be survivable, not only the likely one.

Cost of a candidate with positions p_k (k = 1..N, t_k = k dt):
  J = w_goal (g(p_N) + mean_k g(p_k)) / 2                         g: metres to the goal on the map's grid
    + sum_k [w_hit 1(c(p_k) < r) + w_static max(0, r + m_s - c(p_k))^2]          c: static clearance
    + w_hit 1(c(stop) < r)                 the point where braking from p_N at a_brake ends
    + sum_o [sum_h pi_h C_oh + lam max_h C_oh]
        C_oh = sum_k gamma_k [w_hit 1(e_k < 0) + w_near max(0, m_d - e_k)^2],
        e_k = |p_k - o_hk| - R_o - r - sigma_k,  gamma_k = 1 up to t_full, then exp(-(t_k - t_full)/t_fade)
    + w_keep mean_{k <= K_keep} |p_k - q_k|^2       q: the previous choice, shifted to now (commitment)
    + w_acc mean_k |a_k|^2
R_o: half the obstacle's longest horizontal side; r: the robot's horizontal circumscribed radius;
sigma_k: the prediction's standard deviation. All sums are evaluated by one compiled kernel.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from planner.types import ObstaclePrediction


@dataclass(frozen=True)
class ManeuverConfig:
    along: tuple[float, ...] = (-1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0)  # m/s target speeds along the guide
    across: tuple[float, ...] = (-1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5)  # m/s target speeds to its left
    t_switch: float = 1.0  # s: the first target is held this long, the second after
    # futures of a moving obstacle
    p_keep: float = 0.55  # prior of its own prediction
    p_stop: float = 0.05  # of stopping
    p_turn: float = 0.40  # shared by the 7 other headings
    turn_rate: float = 2.0  # rad/s at walking speed (a walker's 2 m/s^2 of lateral acceleration at 1 m/s)
    walk_speed: tuple[float, float] = (0.6, 1.6)  # m/s: the speed of a turning hypothesis, its own clipped to this
    start_accel: float = 1.0  # m/s^2: a standing obstacle's hypotheses speed up at this
    stop_decel: float = 1.5  # m/s^2
    standing: float = 0.3  # m/s: slower than this an obstacle has no heading: 8 absolute directions
    worst_case: float = 0.3  # lam: weight of the worst hypothesis beside the expectation
    # cost weights (units: metres of path to the goal)
    w_goal: float = 1.0
    w_hit: float = 30.0  # per step of contact (per hypothesis, weighted as above)
    w_near: float = 20.0  # per step and m^2 inside the dynamic margin
    dynamic_margin: float = 0.3  # m_d; the MPC's dynamic_margin
    w_static: float = 60.0  # per step and m^2 inside the static margin
    static_margin: float = 0.15  # m_s beyond the robot radius
    brake: float = 2.5  # m/s^2 for the stopping point
    t_full: float = 1.2  # s of full weight on an obstacle's own prediction ...
    t_fade: float = 0.8  # ... fading after with this time constant (later steps are replanned anyway)
    # its other futures are answered by replanning once they show: from react_delay on the drone can accelerate
    # away at evade_accel, so under them the separation needed shrinks by evade_accel (t - react_delay)^2 / 2
    react_delay: float = 0.3  # s: a turn shows in the velocity and reaches a new plan (perception, 10 Hz plans)
    evade_accel: float = 2.0  # m/s^2, within the MPC's limit
    t_full_alt: float = 1.2  # s of full weight on the other futures...
    t_fade_alt: float = 0.8  # ...then fading like the prediction's
    max_extent: float = 0.7  # m: an obstacle's radius is half its longest horizontal side, at most half this (a
    # walker's box grows with the stride and the swinging arms, beyond the body that can be hit)
    w_keep: float = 2.0  # per m^2, commitment to the previous choice
    keep_steps: int = 10  # over the first steps
    w_acc: float = 0.01  # per (m/s^2)^2
    band_half_height: float = 0.45  # m: static columns count within the flight altitude +- this
    near_goal: float = 1.0  # m: within this of the goal the static thresholds are no stricter than the goal allows
    # m: the approach candidate (straight to where the cost-to-go is least, stopping there) is offered within
    # this of that point only; farther out the grid's candidates, which score the people's futures, lead
    approach_range: float = 2.0

    def __post_init__(self):
        # the maneuver choice's branch and bound needs every cost term >= 0 (_best)
        for name in ("p_keep", "p_stop", "p_turn", "worst_case", "w_goal", "w_hit", "w_near", "w_static", "w_keep",
                     "w_acc", "t_fade", "t_fade_alt"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"ManeuverConfig.{name}: must be a finite number >= 0, got {v!r}")


@dataclass(frozen=True, eq=False)
class Maneuver:
    positions: np.ndarray  # (N+1, 2) from the current position
    velocities: np.ndarray  # (N+1, 2)
    accelerations: np.ndarray  # (N, 2)
    cost: float
    parts: dict  # the cost's terms for the chosen candidate
    candidates: int


@njit(cache=True, nogil=True, inline="always")
def _track(P, V, A, c, k0, k1, px, vx, py, vy, tx, ty, dt, amax, k_v):
    """Steps k0 <= k < k1 of row c of P, V, A from (px, vx, py, vy): every step the acceleration that reaches
    the target velocity (tx, ty), clipped to +-amax per axis, both axes in one loop so that the row is
    written in memory order (V from step k_v on only). Returns the state after the last step."""
    for k in range(k0, k1):
        ax = min(max((tx - vx) / dt, -amax), amax)
        px += vx * dt + 0.5 * ax * dt * dt
        vx += ax * dt
        ay = min(max((ty - vy) / dt, -amax), amax)
        py += vy * dt + 0.5 * ay * dt * dt
        vy += ay * dt
        P[c, k, 0], A[c, k, 0] = px, ax
        P[c, k, 1], A[c, k, 1] = py, ay
        if k >= k_v:
            V[c, k, 0], V[c, k, 1] = vx, vy
    return px, vx, py, vy


@njit(cache=True, nogil=True)
def _two_phase(P, V, A, p0, v0, targets, ks, dt, amax, full):
    """Fills rows a * T + b of P, V, A (C, N, 2) (positions, velocities, accelerations) with every pair of
    targets (a held for ks steps, then b), each reached by bang-bang velocity tracking: every step the
    acceleration that reaches the target velocity, clipped to +-amax per axis. The first phase, the same
    for every b, is computed once per a. Rows from T * T on are left to the caller.
    Not ``full``: only what _best and the stopping points read is written: the first phase in row a * T
    alone (the other rows of the group from step ks on, and their last step), V at the last step alone
    (_velocities gives a row's V from its A)."""
    T, N = targets.shape[0], P.shape[1]
    k1 = max(min(ks, N), 0)
    k_v = 0 if full else N - 1
    k_copy = 0 if full else (N - 1 if k1 == N else k1)
    st = np.empty((4, 4))  # px, vx, py, vy of the rows stepped together
    for a in range(T):
        c0 = a * T
        px, vx, py, vy = _track(P, V, A, c0, 0, k1, p0[0], v0[0], p0[1], v0[1], targets[a, 0], targets[a, 1], dt,
                                amax, k_v)
        for b in range(1, T):
            c = c0 + b
            for k in range(k_copy, k1):
                P[c, k, 0], A[c, k, 0] = P[c0, k, 0], A[c0, k, 0]
                P[c, k, 1], A[c, k, 1] = P[c0, k, 1], A[c0, k, 1]
                if k >= k_v:
                    V[c, k, 0], V[c, k, 1] = V[c0, k, 0], V[c0, k, 1]
        # the second phases, four rows stepped side by side: each step waits on the one before (a division
        # in the loop), so independent rows interleaved keep the processor busy
        for b in range(0, T, 4):
            nb = min(4, T - b)
            for q in range(nb):
                st[q, 0], st[q, 1], st[q, 2], st[q, 3] = px, vx, py, vy
            for k in range(k1, N):
                for q in range(nb):
                    st[q, 0], st[q, 1], st[q, 2], st[q, 3] = _track(
                        P, V, A, c0 + b + q, k, k + 1, st[q, 0], st[q, 1], st[q, 2], st[q, 3], targets[b + q, 0],
                        targets[b + q, 1], dt, amax, k_v)


@njit(cache=True, nogil=True)
def _velocities(A, v0, dt):
    """(N, 2): the velocities of a row's accelerations A (N, 2) from v0, summed as _track sums them."""
    N = A.shape[0]
    V = np.empty((N, 2))
    vx, vy = v0[0], v0[1]
    for k in range(N):
        vx += A[k, 0] * dt
        vy += A[k, 1] * dt
        V[k, 0], V[k, 1] = vx, vy
    return V


@njit(cache=True, nogil=True)
def _approach(p0, v0, q, N, dt, amax, vcap, adec):
    """Positions, velocities, accelerations (N, 2) of flying straight to q and stopping there: every step
    the target velocity points at q with speed min(vcap, sqrt(2 adec d), d / dt) at distance d, reached
    under +-amax per axis as in _two_phase."""
    P, V, A = np.empty((N, 2)), np.empty((N, 2)), np.empty((N, 2))
    p, v = p0.copy(), v0.copy()
    for k in range(N):
        dx, dy = q[0] - p[0], q[1] - p[1]
        d = math.sqrt(dx * dx + dy * dy)
        sp = min(vcap, math.sqrt(2.0 * adec * d), d / dt)
        tv0, tv1 = (dx / d * sp, dy / d * sp) if d > 1e-9 else (0.0, 0.0)
        for ax in range(2):
            tv = tv0 if ax == 0 else tv1
            acc = min(max((tv - v[ax]) / dt, -amax), amax)
            p[ax] += v[ax] * dt + 0.5 * acc * dt * dt
            v[ax] += acc * dt
            P[k, ax], V[k, ax], A[k, ax] = p[ax], v[ax], acc
    return P, V, A


_TURNS = np.radians([45, -45, 90, -90, 135, -135, 180])  # a walking obstacle's turns (hypotheses)
_TURN_SIZE = np.abs(_TURNS)[:, None]  # (7, 1)
_TURN_SIGN = np.sign(_TURNS)[:, None]
_TURN_PACE = np.array([max(math.cos(a / 2), 0.3) for a in np.abs(_TURNS)])[:, None]  # speed factor while turning
_START_HEADINGS = np.array([[math.cos(h), math.sin(h)] for h in np.arange(8) * (math.pi / 4)])  # (8, 2)


def hypotheses(ob: ObstaclePrediction, times: np.ndarray, cfg: ManeuverConfig):
    """Futures of one moving obstacle: centres (H, K, 2) at ``times`` and prior weights (H,)."""
    paths, w, _ = futures([ob], times, cfg)
    return paths, w


def futures(obstacles, times: np.ndarray, cfg: ManeuverConfig, predicted: np.ndarray | None = None):
    """The futures (module docstring) of several moving obstacles at once: centres (H, K, 2) at ``times``,
    prior weights (H,), and how many of them each obstacle has (n,), obstacle after obstacle. Each value
    is computed as for the obstacle alone, element by element (the same floats). predicted (n, K, 2): their
    own predictions at ``times`` (x, y of ob.predict), when the caller has them already."""
    t = np.asarray(times, dtype=float)
    K, n = len(t), len(obstacles)
    dt = np.diff(np.r_[0.0, t])
    lo, hi = cfg.walk_speed
    c = np.empty((n, 2))
    v = np.empty((n, 2))
    keep = np.empty((n, K, 2))
    for i, ob in enumerate(obstacles):
        c[i], v[i] = np.asarray(ob.center, float)[:2], np.asarray(ob.velocity, float)[:2]
        keep[i] = ob.predict(t)[:, :2] if predicted is None else predicted[i]
    speed = np.hypot(v[:, 0], v[:, 1])
    standing = speed < cfg.standing
    count = np.where(standing, 2 + len(_START_HEADINGS), 2 + len(_TURNS))
    first = np.r_[0, np.cumsum(count)[:-1]].astype(np.int64)
    paths = np.empty((int(count.sum()), K, 2))
    paths[first] = keep
    # stopping: decelerate along the current velocity
    ts = speed / cfg.stop_decel  # standing from then on
    s_stop = np.where(t[None] < ts[:, None], speed[:, None] * t - 0.5 * cfg.stop_decel * t * t,
                      (speed * ts - 0.5 * cfg.stop_decel * ts * ts)[:, None])
    moving = speed > 1e-6
    u = np.zeros((n, 2))
    u[moving] = v[moving] / speed[moving, None]
    paths[first + 1] = c[:, None, :] + s_stop[:, :, None] * u[:, None, :]
    st = np.flatnonzero(standing)
    if len(st):  # no heading: start walking in 8 directions
        sp = np.minimum(speed[st, None] + cfg.start_accel * t, lo)
        walked = np.cumsum(sp * dt, axis=1)  # the same distance along every heading
        rows = first[st, None] + 2 + np.arange(len(_START_HEADINGS))
        paths[rows] = c[st, None, None, :] + walked[:, None, :, None] * _START_HEADINGS[None, :, None, :]
    wk = np.flatnonzero(~standing)
    if len(wk):
        th0 = np.array([math.atan2(v[i, 1], v[i, 0]) for i in wk])
        s = np.clip(speed[wk], lo, hi)
        with np.errstate(divide="ignore"):
            inv = 1.0 / s
        rate = np.where(s > 0, cfg.turn_rate * np.where(inv < 1.0, inv, 1.0), cfg.turn_rate)  # min(1, 1 / s)
        turned = (rate[:, None] * t)[:, None, :]  # (w, 1, K)
        th = th0[:, None, None] + _TURN_SIGN[None] * np.minimum(turned, _TURN_SIZE[None])  # (w, 7, K)
        ds = (s[:, None, None] * np.where(turned < _TURN_SIZE[None], _TURN_PACE[None], 1.0)) * dt  # slower turning
        rows = first[wk, None] + 2 + np.arange(len(_TURNS))
        paths[rows, :, 0] = c[wk, 0, None, None] + np.cumsum(np.cos(th) * ds, axis=2)
        paths[rows, :, 1] = c[wk, 1, None, None] + np.cumsum(np.sin(th) * ds, axis=2)
    w = np.repeat(cfg.p_turn / (count - 2), count)
    w[first], w[first + 1] = cfg.p_keep, cfg.p_stop
    return paths, w, count


@njit(cache=True, nogil=True)
def _stopping_points(P, V, decel2):
    """(C, 2): where each candidate of P, V (C, K, 2) comes to rest braking from its last state
    (decel2: twice the braking deceleration)."""
    C, K = P.shape[0], P.shape[1]
    out = np.empty((C, 2))
    for c in range(C):
        vx, vy = V[c, K - 1, 0], V[c, K - 1, 1]
        f = math.sqrt(vx * vx + vy * vy) / decel2
        out[c, 0] = P[c, K - 1, 0] + vx * f
        out[c, 1] = P[c, K - 1, 1] + vy * f
    return out


@njit(cache=True, nogil=True)
def _static_terms(P, stop, clear, goal, ox, oy, res, r_robot, m_s, w_hit, w_static, gx, gy, near_goal, r_goal,
                  m_goal, c, k0, k1, st, g_sum, g_end):
    """_best's static and goal sums of candidate c over steps k0 <= k < k1 (step K: the stopping point),
    added to st, g_sum (g_end: the goal field at step K - 1); returns (st, g_sum, g_end)."""
    K = P.shape[1]
    nx, ny = clear.shape
    for k in range(k0, k1):
        if k < K:
            x, y = P[c, k, 0], P[c, k, 1]
        else:
            x, y = stop[c, 0], stop[c, 1]
        i = int(math.floor((x - ox) / res))
        j = int(math.floor((y - oy) / res))
        i = min(max(i, 0), nx - 1)
        j = min(max(j, 0), ny - 1)
        d = clear[i, j]
        rr, mm = r_robot, m_s
        if (x - gx) * (x - gx) + (y - gy) * (y - gy) < near_goal * near_goal:
            rr, mm = r_goal, m_goal
        if d < rr:
            st += w_hit
        if k < K:
            e = rr + mm - d
            if e > 0.0:
                st += w_static * e * e
            g_sum += goal[i, j]
            if k == K - 1:
                g_end = goal[i, j]
    return st, g_sum, g_end


_BLOCK = 8  # rows outside the groups of _best are culled by reach in blocks of this many


@njit(cache=True, nogil=True)
def _block_reach(P, O, far, r0, r1, c0, ks, lo, hi):
    """The steps at which each hypothesis may be within reach of a block of candidates: rows r0 <= c < r1 of
    P (C, K, 2), steps below ks read in row c0 alone (shared steps, as _best reads them). Writes lo, hi (H,):
    hypothesis h of O (H, K, 2) is farther than sqrt(far[h, k]) from every row of the block at every step
    outside lo[h] <= k < hi[h] (lo = hi: at all). The distance is to the block's bounding box at step k,
    which is no farther than any row's point in floating point too (subtraction rounds monotonically), so
    the steps left out are ones _best's own test would skip. A NaN anywhere counts as within reach."""
    K, H = P.shape[1], O.shape[0]
    box = np.empty((K, 4))  # x min, x max, y min, y max
    for k in range(K):
        if k < ks:
            x, y = P[c0, k, 0], P[c0, k, 1]
            box[k, 0], box[k, 1], box[k, 2], box[k, 3] = x, x, y, y
            continue
        x0, x1, y0, y1 = math.inf, -math.inf, math.inf, -math.inf
        for c in range(r0, r1):
            x, y = P[c, k, 0], P[c, k, 1]
            if x != x or y != y:
                continue  # a NaN row adds no term at any distance
            x0, x1, y0, y1 = min(x0, x), max(x1, x), min(y0, y), max(y1, y)
        box[k, 0], box[k, 1], box[k, 2], box[k, 3] = x0, x1, y0, y1
    for h in range(H):
        first, last = K, 0
        for k in range(K):
            ox, oy = O[h, k, 0], O[h, k, 1]
            dx, dy = 0.0, 0.0
            if box[k, 0] - ox > dx:
                dx = box[k, 0] - ox
            if ox - box[k, 1] > dx:
                dx = ox - box[k, 1]
            if box[k, 2] - oy > dy:
                dy = box[k, 2] - oy
            if oy - box[k, 3] > dy:
                dy = oy - box[k, 3]
            if dx * dx + dy * dy > far[h, k]:
                continue
            if k < first:
                first = k
            last = k + 1
        lo[h], hi[h] = (first, last) if first < last else (0, 0)


@njit(cache=True, nogil=True, inline="always")
def _dyn_term(P, O, R, gamma, far, m_d, w_near, w_hit, row, h, k, s):
    """s plus the dynamic term of hypothesis h at step k for row ``row`` (module docstring's C_oh)."""
    dx = P[row, k, 0] - O[h, k, 0]
    dy = P[row, k, 1] - O[h, k, 1]
    d2 = dx * dx + dy * dy
    if d2 > far[h, k]:
        return s  # farther than R + m_d: no term
    e = math.sqrt(d2) - R[h, k]
    if e < m_d:
        v = w_near * (m_d - e) * (m_d - e)
        if e < 0.0:
            v += w_hit
        s += gamma[h, k] * v
    return s


@njit(cache=True, nogil=True)
def _best(P, A, stop, clear, goal, ox, oy, res, O, R, owner, prior, n_obst, gamma, keep, r_robot, m_s, m_d,
          w_goal, w_hit, w_static, w_near, worst, w_keep, w_acc, gx, gy, near_goal, r_goal, m_goal, first, group,
          shared, parts):
    """The candidate of P (C, K, 2) with the least cost J (module docstring), the first of equals: returns
    its index and cost, and writes its terms (goal, static, dynamic, keep, effort) into parts (5,).
    Within near_goal of the goal (gx, gy) the static thresholds are r_goal and m_goal (what the goal
    allows). Branch and bound: candidate ``first`` (-1: none) is costed first; every term is >= 0, so
    a candidate whose terms so far already exceed the least cost found cannot be the least and is left
    (the same choice, bit for bit, as costing every candidate, the weights, priors and gamma being >= 0;
    a NaN cost counts as infinite). owner (H,): the obstacle of each hypothesis, in ascending order.
    group, shared: rows a * group to a * group + group - 1 (a < group) start with the same ``shared`` steps
    (P, A and so stop's prefix as _two_phase writes them), which are read in the group's first row only
    (the others' may be left unwritten): the terms of those steps are summed once per group and each row
    goes on from there, the same sums in the same order (group 0: none shared).
    Cull by reach: the rows come in blocks (a group, or _BLOCK rows outside the groups); per block and
    hypothesis only the steps _block_reach finds within reach are summed, and an obstacle none of whose
    hypotheses comes within reach of the block is passed over. The steps and obstacles left out add no
    term, so every sum is the same float, added in the same order."""
    C, K = P.shape[0], P.shape[1]
    H = O.shape[0]
    start = np.zeros(n_obst + 1, np.int64)  # the hypotheses of obstacle o: start[o]:start[o + 1]
    for h in range(H):
        if owner[h] < 0 or owner[h] >= n_obst or (h > 0 and owner[h] < owner[h - 1]):
            raise ValueError("_best: owner must be ascending obstacle indices below n_obst")
        start[owner[h] + 1] = h + 1
    for o in range(n_obst):
        start[o + 1] = max(start[o + 1], start[o])
    nk = min(keep.shape[0], K)
    ks = min(max(shared, 0), K) if 0 < group and group * group <= C else 0
    n_group = group if ks > 0 else 0
    pre = np.zeros((n_group, 5))  # per group: static, goal sum, goal at the end, keep, effort over ks steps
    for a in range(n_group):
        c = a * group
        pre[a, 0], pre[a, 1], pre[a, 2] = _static_terms(P, stop, clear, goal, ox, oy, res, r_robot, m_s, w_hit,
                                                        w_static, gx, gy, near_goal, r_goal, m_goal, c, 0, ks,
                                                        0.0, 0.0, 0.0)
        for k in range(min(nk, ks)):
            dx = P[c, k, 0] - keep[k, 0]
            dy = P[c, k, 1] - keep[k, 1]
            pre[a, 3] += dx * dx + dy * dy
        for k in range(ks):
            pre[a, 4] += A[c, k, 0] * A[c, k, 0] + A[c, k, 1] * A[c, k, 1]
    # squared distances beyond which a hypothesis adds nothing (e >= m_d), a little beyond R + m_d so that
    # rounding cannot skip a term the sum would count; -1 where R + m_d <= 0 (never within reach)
    far = np.empty((H, K))
    for h in range(H):
        for k in range(K):
            lim = R[h, k] + m_d
            far[h, k] = (lim * (1.0 + 1e-9)) ** 2 if lim > 0.0 else -1.0
    # blocks: the groups, then the other rows _BLOCK at a time; each culled by reach when first needed
    n_rest = C - n_group * group
    n_block = n_group + (n_rest + _BLOCK - 1) // _BLOCK
    ready = np.zeros(n_block, np.bool_)
    lo = np.zeros((n_block, H), np.int64)
    hi = np.zeros((n_block, H), np.int64)
    dyn_pre = np.zeros((n_block, H))  # per group and hypothesis: the sum over its shared steps
    near = np.zeros((n_block, n_obst), np.bool_)  # obstacle o has a hypothesis within reach of the block
    best_j, best_c = math.inf, -1
    for n in range(C + 1):
        if n == 0:
            if first < 0:
                continue
            c = first
        else:
            c = n - 1
            if c == first:
                continue
        k0, st, g_sum, g_end, kp, ef = 0, 0.0, 0.0, 0.0, 0.0, 0.0
        c0 = c
        if c < n_group * group:
            a = c // group
            c0 = a * group
            k0, st, g_sum, g_end, kp, ef = ks, pre[a, 0], pre[a, 1], pre[a, 2], pre[a, 3], pre[a, 4]
            blk = a
        else:
            blk = n_group + (c - n_group * group) // _BLOCK
        st, g_sum, g_end = _static_terms(P, stop, clear, goal, ox, oy, res, r_robot, m_s, w_hit, w_static, gx, gy,
                                         near_goal, r_goal, m_goal, c, k0, K + 1, st, g_sum, g_end)
        jg = w_goal * 0.5 * (g_end + g_sum / K)
        for k in range(min(k0, nk), nk):
            dx = P[c, k, 0] - keep[k, 0]
            dy = P[c, k, 1] - keep[k, 1]
            kp += dx * dx + dy * dy
        kp = w_keep * kp / nk if nk > 0 else 0.0
        for k in range(k0, K):
            ef += A[c, k, 0] * A[c, k, 0] + A[c, k, 1] * A[c, k, 1]
        ef = w_acc * ef / K
        if jg + st + 0.0 + kp + ef > best_j:
            continue
        if not ready[blk]:
            if blk < n_group:
                r0, r1 = blk * group, blk * group + group
            else:
                r0 = n_group * group + (blk - n_group) * _BLOCK
                r1 = min(r0 + _BLOCK, C)
            _block_reach(P, O, far, r0, r1, c0, k0, lo[blk], hi[blk])
            for h in range(H):
                s = 0.0
                for k in range(lo[blk, h], min(hi[blk, h], k0)):
                    s = _dyn_term(P, O, R, gamma, far, m_d, w_near, w_hit, c0, h, k, s)
                dyn_pre[blk, h] = s
                if hi[blk, h] > lo[blk, h]:
                    near[blk, owner[h]] = True
            ready[blk] = True
        dyn = 0.0
        cut = False
        for o in range(n_obst):
            if not near[blk, o]:
                continue  # every term of its hypotheses is 0: the sum is unchanged
            exp, mx = 0.0, 0.0
            for h in range(start[o], start[o + 1]):
                s = dyn_pre[blk, h]  # the shared steps (below k0), read in the group's first row
                for k in range(max(lo[blk, h], k0), hi[blk, h]):
                    s = _dyn_term(P, O, R, gamma, far, m_d, w_near, w_hit, c, h, k, s)
                exp += prior[h] * s
                mx = max(mx, s)
            dyn += exp + worst * mx
            if jg + st + dyn + kp + ef > best_j:
                cut = True
                break
        if cut:
            continue
        J = jg + st + dyn + kp + ef
        if J != J:
            J = math.inf
        if J < best_j or (J == best_j and c < best_c) or best_c < 0:
            best_j, best_c = J, c
            parts[0], parts[1], parts[2], parts[3], parts[4] = jg, st, dyn, kp, ef
    return best_c, best_j


class ManeuverSelector:
    """Chooses the maneuver that guides the MPC (module docstring). ``choose`` is called once per plan."""

    def __init__(self, cfg: ManeuverConfig = ManeuverConfig(), horizon: int = 25, dt: float = 0.1,
                 a_max: float = 2.5, v_max: float = 2.0, robot_radius: float = 0.437):
        self.cfg, self.N, self.dt = cfg, horizon, dt
        self.a_max, self.v_max, self.r = a_max, v_max, robot_radius
        self.t = dt * np.arange(1, horizon + 1)
        self.k_switch = int(round(cfg.t_switch / dt))
        g = np.array([(a, b) for a in cfg.along for b in cfg.across], dtype=float)
        self._grid = g  # (T, 2) targets in the guide's frame
        fade = lambda full, tau: np.where(self.t <= full, 1.0, np.exp(-(self.t - full) / tau))  # noqa: E731
        self.gamma = fade(cfg.t_full, cfg.t_fade)  # (N,) for an obstacle's own prediction
        self.gamma_alt = fade(cfg.t_full_alt, cfg.t_fade_alt)  # (N,) for its other futures
        self.evade = 0.5 * cfg.evade_accel * np.maximum(self.t - cfg.react_delay, 0.0) ** 2  # (N,) m
        self.reset()

    def reset(self) -> None:
        self._buffers: dict = {}  # the candidates' arrays, reused from plan to plan
        self._prev: tuple[float, np.ndarray, np.ndarray] | None = None  # (t0, positions (N+1, 2), accelerations)

    def candidates(self, p0, v0, guide_dir, previous_acc=None, approach=None, out: dict | None = None,
                   full: bool = True):
        """Positions (C, N, 2), velocities, accelerations of every two-phase candidate, plus, when
        approach (2,) is given, flying straight to that point and stopping there (_approach), and, when
        previous_acc (N, 2) is given, the previous choice's accelerations flown again from now (last).
        out: a dict whose arrays are reused from call to call (new arrays when None): the arrays returned
        are then that dict's, overwritten by the next call. Not ``full``: the two-phase rows hold only what
        _best reads (_two_phase); _completed gives one whole."""
        e = np.asarray(guide_dir, float)[:2]
        e = e / max(np.linalg.norm(e), 1e-9)
        n = np.array([-e[1], e[0]])
        T = self._grid @ np.stack([e, n])  # world targets (T, 2)
        vb = self.v_max - 0.01
        T = np.clip(T, -vb, vb)
        acc = previous_acc
        p0, v0 = np.asarray(p0, float), np.asarray(v0, float)
        extra = int(acc is not None) + int(approach is not None)
        shape = (len(T) * len(T) + extra, self.N, 2)
        if out is None:
            P, V, A = np.empty(shape), np.empty(shape), np.empty(shape)
        else:
            if out.get("shape") != shape:
                out.update(shape=shape, P=np.empty(shape), V=np.empty(shape), A=np.empty(shape))
            P, V, A = out["P"], out["V"], out["A"]
        _two_phase(P, V, A, p0, v0, np.ascontiguousarray(T), self.k_switch, self.dt, self.a_max, full)
        if approach is not None:
            r = len(P) - extra
            P[r], V[r], A[r] = _approach(p0, v0, np.asarray(approach, float)[:2], self.N, self.dt, self.a_max,
                                         min(max(self.cfg.along), vb), 0.5 * self.a_max)
        if acc is not None:
            vel = np.clip(np.vstack([v0, v0 + self.dt * np.cumsum(acc, axis=0)]), -vb, vb)
            acc = np.diff(vel, axis=0) / self.dt
            P[-1] = p0 + np.cumsum(self.dt * vel[:-1] + 0.5 * self.dt * self.dt * acc, axis=0)
            V[-1], A[-1] = vel[1:], acc
        return P, V, A

    def choose(self, t0: float, p0, v0, guide_dir, obstacles, clear: np.ndarray, goal_field: np.ndarray,
               origin_xy, resolution: float, goal_xy) -> Maneuver:
        """The best candidate from (p0, v0) at time t0; goal_field: metres to goal_xy per column cell,
        clear: static clearance per cell (planner.map.clearance), both on the grid at origin_xy, resolution."""
        cfg = self.cfg
        gi = np.clip(np.floor((np.asarray(goal_xy, float)[:2] - origin_xy) / resolution).astype(int), 0,
                     np.array(clear.shape) - 1)
        c_goal = float(clear[gi[0], gi[1]])  # a goal near a wall: the static thresholds relax around it
        r_goal = min(self.r, max(c_goal - 0.05, 0.0))
        m_goal = min(cfg.static_margin, max(c_goal - r_goal, 0.0))
        p0, v0 = np.asarray(p0, float)[:2], np.asarray(v0, float)[:2]
        prev_pos, prev_acc = self._shift_previous(t0)
        q = self._least_cost_point(goal_field, origin_xy, resolution, goal_xy)
        if q is not None and np.hypot(*(q - p0)) > cfg.approach_range:
            q = None
        P, V, A = self.candidates(p0, v0, guide_dir, prev_acc, q, out=self._buffers, full=False)
        stop = _stopping_points(P, V, 2 * cfg.brake)
        O, R, G, owner, prior = self._obstacle_terms(obstacles, p0, v0)
        keep = prev_pos[1:cfg.keep_steps + 1] if prev_pos is not None else np.zeros((0, 2))
        parts = np.empty(5)
        b, cost = _best(P, A, stop, clear, goal_field, float(origin_xy[0]), float(origin_xy[1]), float(resolution),
                        O, R, owner, prior, owner[-1] + 1 if len(owner) else 0, G, np.ascontiguousarray(keep),
                        self.r, cfg.static_margin, cfg.dynamic_margin, cfg.w_goal, cfg.w_hit, cfg.w_static,
                        cfg.w_near, cfg.worst_case, cfg.w_keep, cfg.w_acc, float(goal_xy[0]), float(goal_xy[1]),
                        cfg.near_goal, r_goal, m_goal, len(P) - 1 if prev_acc is not None else -1,
                        len(self._grid), self.k_switch, parts)
        names = ["goal", "static", "dynamic", "keep", "effort"]
        pb, vb, ab = self._completed(P, V, A, b, v0)
        pos, vel = np.vstack([p0, pb]), np.vstack([v0, vb])
        self._prev = (float(t0), pos, ab)
        return Maneuver(pos, vel, ab.copy(), float(cost), dict(zip(names, parts.round(4).tolist())), len(P))

    def _obstacle_terms(self, obstacles, p0, v0):
        """_best's obstacle arrays: the futures' centres O (H, N, 2), radii R (H, N), weights over the horizon G
        (H, N), owner (H,) and priors (H,) of the obstacles within reach (_within_reach), renumbered 0, 1, ..."""
        cfg, N = self.cfg, self.N
        n = len(obstacles)
        centre = np.empty((n, 2))
        speed = np.empty(n)
        keep = np.empty((n, N, 2))
        rad = np.empty((n, N))
        for i, ob in enumerate(obstacles):
            centre[i] = np.asarray(ob.center, float)[:2]
            speed[i] = np.hypot(*np.asarray(ob.velocity, float)[:2])
            keep[i] = ob.predict(self.t)[:, :2]
            size = np.asarray(ob.size, float)
            rad[i] = 0.5 * min(max(size[0], size[1]), cfg.max_extent) + self.r + ob.std_at(self.t)
        near = np.flatnonzero(self._within_reach(p0, v0, centre, speed, keep, rad))
        if not len(near):
            return np.zeros((0, N, 2)), np.zeros((0, N)), np.zeros((0, N)), np.zeros(0, np.int64), np.zeros(0)
        O, prior, count = futures([obstacles[i] for i in near], self.t, cfg, keep[near])
        first = np.r_[0, np.cumsum(count)[:-1]]
        owner = np.repeat(np.arange(len(near), dtype=np.int64), count)
        R = rad[near][owner] - self.evade  # the other futures: the drone evades once they show
        R[first] = rad[near]
        G = np.repeat(self.gamma_alt[None], len(owner), axis=0)
        G[first] = self.gamma
        return np.ascontiguousarray(O), np.ascontiguousarray(R), G, owner, prior

    def _within_reach(self, p0, v0, centre, speed, keep, rad) -> np.ndarray:
        """(n,) bool: which obstacles may come within reach of some candidate: a cull by reach, not by count.
        The drone's candidates move at most max(|v0|, v_max) per axis (each target velocity is clipped to v_max
        and approached monotonically), so at step k they lie in the box p0 +- that times t_k. An obstacle's
        futures move at most its own prediction's distance (keep (n, N, 2)) or, the others, at most the
        largest of its speed and the walking speeds times t_k (stopping is slower, a turn walks at a walking
        speed at most, one standing speeds up to the lower walking speed), with a radius at most rad (n, N)
        (evasion shrinks it). One that stays farther than the sum plus the dynamic margin (and a rounding
        allowance) at every step adds no term to any candidate's cost (_best), so leaving it out changes no
        choice. NaN: kept."""
        cfg, t = self.cfg, self.t
        if len(centre) == 0 or not (cfg.stop_decel > 0 and cfg.start_accel >= 0):
            return np.ones(len(centre), bool)  # the bounds below assume these (the configuration's limits)
        vd = np.maximum(np.abs(np.asarray(v0, float)[:2]), abs(self.v_max - 0.01))  # per axis
        gap = np.maximum(np.abs(centre[:, None, :] - np.asarray(p0, float)[:2]) - vd * t[:, None], 0.0)  # (n, N, 2)
        gap = np.hypot(gap[..., 0], gap[..., 1])
        lo, hi = cfg.walk_speed
        walk = np.maximum(speed, max(abs(lo), abs(hi)))[:, None] * t
        moved = np.maximum(np.hypot(*(keep - centre[:, None, :]).transpose(2, 0, 1)), walk)
        reach = (moved + np.maximum(rad, rad - self.evade) + cfg.dynamic_margin) * (1 + 1e-6) + 1e-6
        return ~np.all(gap > reach, axis=1)

    def _completed(self, P, V, A, b: int, v0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Row b of candidates(full=False) as full=True gives it: positions, velocities, accelerations (N, 2)."""
        T = len(self._grid)
        if b >= T * T:  # the approach and the previous choice are written whole
            return P[b].copy(), V[b].copy(), A[b].copy()
        k1, first = max(min(self.k_switch, self.N), 0), b - b % T
        pb, ab = P[b].copy(), A[b].copy()
        pb[:k1], ab[:k1] = P[first, :k1], A[first, :k1]
        return pb, _velocities(ab, v0, self.dt), ab

    @staticmethod
    def _least_cost_point(goal_field: np.ndarray, origin_xy, resolution: float, goal_xy) -> np.ndarray | None:
        """Where the cost-to-go is least: the goal itself when its cell is reachable (0 there), else the
        centre of the cell with the least value (the reachable cell nearest the goal); None if none is finite."""
        nx, ny = goal_field.shape
        g = np.asarray(goal_xy, float)[:2]
        gi = np.floor((g - np.asarray(origin_xy, float)) / resolution).astype(int)
        if 0 <= gi[0] < nx and 0 <= gi[1] < ny and goal_field[gi[0], gi[1]] <= 0.0:
            return g
        b = int(np.argmin(goal_field))
        if not np.isfinite(goal_field.flat[b]):
            return None
        i, j = divmod(b, ny)
        return np.asarray(origin_xy, float) + (np.array([i, j]) + 0.5) * resolution

    def _shift_previous(self, t0: float) -> tuple[np.ndarray | None, np.ndarray | None]:
        """The previous choice as seen from t0: positions (N+1, 2) and accelerations (N, 2), shifted by the
        elapsed steps and held (zero acceleration) at the end; (None, None) when there is none or it is stale."""
        if self._prev is None:
            return None, None
        s = int(round((t0 - self._prev[0]) / self.dt))
        if not 0 <= s <= self.N:
            self._prev = None
            return None, None
        pos, acc = self._prev[1], self._prev[2]
        end_v = (pos[-1] - pos[-2]) / self.dt
        pos = np.vstack([pos[s:], pos[-1] + end_v * self.dt * np.arange(1, s + 1)[:, None]])
        acc = np.vstack([acc[s:], np.zeros((s, 2))])
        return pos, acc
