"""Linear MPC on a double-integrator point mass, OSQP QPs (Intent-MPC style).

State x = [p, v] in R^6, input u = a in R^3, step dt:
    (1) p_{k+1} = p_k + dt v_k + dt^2/2 a_k,   v_{k+1} = v_k + dt a_k          (x_0 given)
Decision vector z = [x_1..x_N, u_0..u_{N-1}, sd_1..sd_N, ss_1..ss_N] (11 N): one dynamic and one static
slack per step, both >= 0 and in metres.
    (2) J = sum_{k<N} Qp|p_k - p^_k|^2 + Qf|p_N - p^_N|^2 + sum_k Qv|v_k - v^_k|^2
          + sum_k R|u_k|^2 + Rd|u_k - u_{k-1}|^2   (u_{-1}: the current commanded acceleration)
          + sum_k w1 (sd_k + s ss_k) + w2 (sd_k^2 + s ss_k^2)   (s: static_slack_scale)
    (3) |v_k| <= v_max (k >= 1), |u_k| <= a_max, z_min <= p_k,z <= z_max.
    (4) Moving obstacle j, step k: outside the ellipsoid f(p) = sum_i ((p_i - o_i)/a_i)^2 >= 1,
        o = predicted centre at t_k = k dt, a = size/2 + robot_radius + margin (+ z_std std(t_k) in x, y);
        one that spans the whole altitude band is replaced by its (enclosing) elliptic cylinder.
        f is convex, so any tangent plane is a conservative half-space. We take the tangent plane at
        c~ = o + (c - o)/sqrt(f(c)), the radial projection onto the surface of the previous plan's
        point c_k: n.p_k + sd_k >= n.c~, n = grad f(c~)/|grad f(c~)|. This equals linearising at c_k
        when c_k is on the surface and is never more conservative elsewhere ((1 + f)/2 >= sqrt f).
        Where c_k lies within side_bias of the obstacle's line of relative motion, it is first moved
        side_bias off that line, toward the obstacle's back: near head-on, from behind or crossing, the
        plane then asks the drone to step aside or pass behind rather than to outrun the obstacle.
    (4') Passing sides: the homotopy_obstacles nearest obstacles may be forced to either side of their
        line of relative motion (c_k mirrored across it before linearising). The side kept from the
        last call is solved first; when it needs more than homotopy_trigger of dynamic slack,
        every other side combination is solved too, each by its own OSQP instance warm-started from its
        own last solution, and the cheapest J wins (with hysteresis toward the side kept).
    (5) Occupied voxels (centres q): greedy separating planes per step, from c_k:
        n = (c_k - q)/|c_k - q| for the nearest q, n.p_k + ss_k >= n.q + robot_radius + voxel/2 + margin,
        points behind the plane through q are dropped, repeat up to K_s times. Where c_k is closer than
        that to a voxel (the previous plan runs through it), c_k is first slid sideways to the nearest
        clear spot: planes from a clear point are consistent (it satisfies them all) and lead around.
    (6) Optional geofence (the known walls of the flight area): g (p_k,xy - lo - r) + ss_k >= 0 and
        g (hi - r - p_k,xy) + ss_k >= 0, r = geofence_margin, g = geofence_scale: the side walls, which a
        forward camera sees only at a grazing angle; a violation costs g times the static slack.
P and the sparsity pattern of A are fixed at construction (room for max_dynamic + K_s rows per
step); every call only updates q, l, u and the values of A, warm-started from the previous
solution shifted in time. Obstacle predictions are taken to start at the planning time t0.
"""
from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass

import numpy as np
import osqp
import scipy.sparse as sp

from planner.fallback import brake_and_hold
from planner.types import ObstaclePrediction, Trajectory

_OK = {osqp.SolverStatus.OSQP_SOLVED, osqp.SolverStatus.OSQP_SOLVED_INACCURATE}


@dataclass(frozen=True)
class MPCConfig:
    horizon: int = 25  # steps; ours: 2.5 s ahead (Intent-MPC: 20-30 steps)
    dt: float = 0.1  # s; Intent-MPC ts 0.1 = its prediction_time_step
    v_max_xy: float = 2.0  # m/s per axis; mpc-dev solver setup |v| <= 2
    v_max_z: float = 1.0  # m/s; ours: gentle altitude changes indoors
    a_max_xy: float = 2.5  # m/s^2 per axis; ours: above the 1.5 cruise acceleration, room to dodge
    a_max_z: float = 2.0  # m/s^2; ours
    z_min: float = 0.7  # m; Intent-MPC / DODT planner height band lower bound 0.7
    z_max: float = 2.0  # m; ours: 3 m corridor ceiling minus a metre
    w_pos: float = 10.0  # position tracking; ours (Intent-MPC 1000 vs acc 10: same 100:1 ratio to w_acc)
    w_vel: float = 1.0  # velocity tracking; ours (Intent-MPC 0)
    w_terminal: float = 30.0  # terminal position; ours
    w_acc: float = 0.1  # acceleration; ours (ratio as above)
    w_jerk: float = 1.0  # (a_k - a_{k-1}); ours, smooths the commanded acceleration
    w_slack_lin: float = 500.0  # per metre; ours: an exact penalty (above the tracking multipliers)
    w_slack_quad: float = 5e3  # per metre^2; ours (Intent-MPC 100/1000 on unscaled slack); larger: more ADMM iterations
    static_slack_scale: float = 10.0  # static slack costs this many times the dynamic one: squeezed between a
    # person and a wall, the plan eats into the person's margin (which holds its uncertainty), not the wall's; ours
    robot_radius: float = 0.3  # m; our drone's collision box is ~0.55 x 0.55 m in x, y
    dynamic_margin: float = 0.3  # m; ours (Intent-MPC dynamic_safety 0.6 includes the robot)
    static_margin: float = 0.2  # m; ours
    z_std: float = 1.0  # std multiples added to the x, y semi-axes (Intent-MPC z-score 0.674)
    dynamic_range: float = 4.0  # m; obstacles farther than this from the plan at every step are ignored
    max_dynamic: int = 8  # nearest moving obstacles with rows in the QP; ours
    static_per_step: int = 4  # K_s separating planes per step; ours
    static_radius: float = 2.5  # m; voxels farther than this from c_k are ignored; ours
    voxel_size: float = 0.1  # m; map resolution (Intent-MPC map res 0.1)
    side_bias: float = 0.4  # m; near head-on, linearise as if c_k were this far aside: breaks the tie; ours
    relative_side: bool = True  # side_bias applies across each obstacle's velocity relative to the planned
    # motion (False: across the direction of travel); ours. A person walking into a waiting drone from behind
    # or head-on then gets a tangent plane that says "step aside" instead of "outrun it" (which the drone,
    # blocked or slower, cannot)
    geofence_margin: float = 0.55  # m from a known wall (6): half the diagonal of the drone's collision box
    # (0.51 x 0.70 m: 0.43) plus room for a tilt, a few cm of tracking error and slack; ours
    geofence_scale: float = 3.0  # the geofence rows are scaled by this: a metre beyond the fence costs this many
    # metres of static slack, so a squeeze from moving obstacles is not resolved by flying into a side wall; ours
    homotopy_obstacles: int = 1  # the nearest this many moving obstacles are tried on both sides (2^M QPs per
    # call, the cheapest kept); ours, in the spirit of Intent-MPC's one solve per intent. 0: one QP, the
    # side each obstacle is passed on inherited from the previous plan through its linearisation
    homotopy_range: float = 2.0  # m; only obstacles whose ellipsoid comes this close to the plan
    homotopy_trigger: float = 0.05  # m; the other sides are tried only when the side kept needs more dynamic
    # slack than this somewhere (most calls then solve one QP)
    homotopy_max_iter: int = 300  # the other sides are compared on solves this short...
    homotopy_eps: float = 1e-2  # ...and this loose; the winner is then finished at eps_abs / eps_rel
    homotopy_hysteresis: float = 0.1  # another side must cost this fraction less than the side kept...
    homotopy_hysteresis_abs: float = 1.0  # ...and this much less (cost units: w_pos m^2)
    iterations: int = 1  # linearise-and-solve rounds per call
    warm_start: bool = True  # start OSQP from the previous solution shifted in time (False: from zero)
    rho: float = 0.5  # OSQP initial ADMM step (adaptive after); ours, fewer iterations on bench_mpc than 0.1
    eps_abs: float = 1e-3  # OSQP tolerances; ours
    eps_rel: float = 1e-3
    max_iter: int = 4000
    max_prim_res: float = 1e-2  # accept a max-iterations result whose primal residual is below this
    backoff: float = 0.01  # m/s, m; v and z bounds tightened inside the QP: OSQP's residuals stay within bounds


@dataclass(frozen=True, eq=False)
class MPCResult:
    trajectory: Trajectory
    status: str  # 'solved' | 'fallback:<why>'
    iterations: int  # OSQP iterations (summed over linearisation rounds)
    max_slack_dynamic: float  # m; largest violation of a dynamic half-space by the plan
    max_slack_static: float  # m
    solve_ms: float  # wall time of the whole call (updates + OSQP), measured only
    ignored_obstacles: int = 0  # obstacles skipped for non-finite data
    qp_solves: int = 1  # QPs solved (one per passing-side combination tried, per linearisation round)


def _rollout(p0, v0, acc, dt):
    """Exact knots of (1) under piecewise-constant acceleration: (N+1, 3) positions, velocities."""
    vel = np.vstack([v0, v0 + dt * np.cumsum(acc, axis=0)])
    pos = np.vstack([p0, p0 + np.cumsum(dt * vel[:-1] + 0.5 * dt * dt * acc, axis=0)])
    return pos, vel


class MPC:
    """One OSQP problem set up once; ``solve`` re-linearises the obstacles and re-solves (module docstring)."""

    def __init__(self, cfg: MPCConfig = MPCConfig()):
        self.cfg = c = cfg
        N, Md, Ks, dt = c.horizon, c.max_dynamic, c.static_per_step, c.dt
        self.N, self.n = N, 12 * N
        self._iu, self._isd, self._iss, self._isc = 6 * N, 9 * N, 10 * N, 11 * N
        self._rd, self._rs = 15 * N, 15 * N + Md * N  # first dynamic / static obstacle row
        # inert rows and columns (2 N rows, Md N + N rows and N columns sc_k >= 0 that nothing uses), left
        # in this commit only so that OSQP's numerics stay those of the previous one; the next removes them
        self._rf = self._rs + Ks * N
        self._rc = self._rf + 2 * N
        self._rg = self._rc + Md * N + N  # first geofence row (4 per step: x >= lo, -x >= -hi, y >= lo, -y >= -hi)
        self.m = self._rg + 4 * N
        ix = 6 * np.arange(N)  # column of p_k (k = 1..N)
        iu = self._iu + 3 * np.arange(N)  # column of u_k (k = 0..N-1)
        # P: 1/2 z'Pz + q'z with P = 2 W (upper triangle)
        d = np.zeros(self.n)
        d[:6 * N].reshape(N, 6)[:, :3] = 2 * c.w_pos
        d[6 * (N - 1):6 * (N - 1) + 3] = 2 * c.w_terminal
        d[:6 * N].reshape(N, 6)[:, 3:] = 2 * c.w_vel
        d[self._iu:self._isd].reshape(N, 3)[:] = (2 * c.w_acc + 2 * c.w_jerk * (1 + (np.arange(N) < N - 1)))[:, None]
        d[self._isd:self._iss] = 2 * c.w_slack_quad
        d[self._iss:self._isc] = 2 * c.w_slack_quad * c.static_slack_scale
        d[self._isc:] = 2 * 100.0  # inert
        ju = (iu[:-1, None] + np.arange(3)).ravel()
        self.P = sp.csc_matrix((np.r_[d, np.full(len(ju), -2 * c.w_jerk)],
                                (np.r_[np.arange(self.n), ju], np.r_[np.arange(self.n), ju + 3])), (self.n, self.n))
        # A pattern: COO entries, each (row, col) once
        R, C, V = [], [], []

        def add(r, col, v):
            r, col = np.broadcast_arrays(np.asarray(r), np.asarray(col))
            R.append(r.ravel()); C.append(col.ravel()); V.append(np.broadcast_to(v, r.shape).ravel().astype(float))
            return np.arange(sum(len(x) for x in R) - r.size, sum(len(x) for x in R)).reshape(r.shape)

        k, i = np.arange(N)[:, None], np.arange(3)[None, :]
        add(6 * k + i, ix[:, None] + i, 1.0)  # p_{k+1}
        add(6 * k + 3 + i, ix[:, None] + 3 + i, 1.0)  # v_{k+1}
        add(6 * k + i, iu[:, None] + i, -0.5 * dt * dt)  # u_k
        add(6 * k + 3 + i, iu[:, None] + i, -dt)
        k1 = np.arange(1, N)[:, None]  # x_k terms for k >= 1 (x_0 goes to the bounds)
        add(6 * k1 + i, ix[:-1, None] + i, -1.0)
        add(6 * k1 + i, ix[:-1, None] + 3 + i, -dt)
        add(6 * k1 + 3 + i, ix[:-1, None] + 3 + i, -1.0)
        rb = 6 * N + 9 * k  # per step k+1: [v(3), p_z, u_k(3), sd, ss]
        add(rb + i, ix[:, None] + 3 + i, 1.0)
        add(rb + 3, ix[:, None] + 2, 1.0)
        add(rb + 4 + i, iu[:, None] + i, 1.0)
        add(rb + 7, self._isd + k, 1.0)
        add(rb + 8, self._iss + k, 1.0)
        kk = np.arange(N)[:, None, None]
        rd = self._rd + Md * kk + np.arange(Md)[None, :, None]
        dyn = add(rd + 0 * i[None], ix[:, None, None] + i[None], 0.0)
        add(rd[..., 0], self._isd + kk[..., 0] + 0 * np.arange(Md), 1.0)
        rs = self._rs + Ks * kk + np.arange(Ks)[None, :, None]
        sta = add(rs + 0 * i[None], ix[:, None, None] + i[None], 0.0)
        add(rs[..., 0], self._iss + kk[..., 0] + 0 * np.arange(Ks), 1.0)
        rf = self._rf + 2 * kk + np.arange(2)[None, :, None]
        add(rf + 0 * i[None, :, :2], ix[:, None, None] + 3 + i[None, :, :2], 0.0)
        rc = self._rc + Md * kk + np.arange(Md)[None, :, None]
        add(rc + 0 * i[None], ix[:, None, None] + i[None], 0.0)
        add(rc[..., 0], self._isc + kk[..., 0] + 0 * np.arange(Md), 1.0)
        add(self._rc + Md * N + np.arange(N), self._isc + np.arange(N), 1.0)
        rg = self._rg + 4 * kk[..., 0] + np.arange(4)  # (N, 4)
        add(rg, ix[:, None] + np.array([0, 0, 1, 1]), c.geofence_scale * np.array([1.0, -1.0, 1.0, -1.0]))
        add(rg, self._iss + kk[..., 0] + 0 * np.arange(4), 1.0)
        R, C, V = np.concatenate(R), np.concatenate(C), np.concatenate(V)
        A = sp.csc_matrix((np.arange(1, len(R) + 1, dtype=float), (R, C)), (self.m, self.n))
        A.sort_indices()
        order = A.data.astype(np.int64) - 1  # CSC slot j holds COO entry order[j]
        pos = np.argsort(order)  # COO entry -> CSC slot
        A.data = V[order]  # explicit zeros stay in the pattern
        self._Ax0, self._dyn_pos, self._sta_pos = A.data.copy(), pos[dyn], pos[sta]  # (N, Md, 3), (N, Ks, 3)
        self._vmax = vmax = np.array([c.v_max_xy, c.v_max_xy, c.v_max_z])
        self._amax = amax = np.array([c.a_max_xy, c.a_max_xy, c.a_max_z])
        vb = vmax - c.backoff
        lb = np.tile(np.r_[-vb, c.z_min + c.backoff, -amax, 0.0, 0.0], N)
        ub = np.tile(np.r_[vb, c.z_max - c.backoff, amax, np.inf, np.inf], N)
        self._l0 = np.r_[np.zeros(6 * N), lb, np.full(self._rc + Md * N - 15 * N, -np.inf), np.zeros(N),
                         np.full(4 * N, -np.inf)]
        self._u0 = np.r_[np.zeros(6 * N), ub, np.full(self.m - 15 * N, np.inf)]
        self._xblocks = [(0, 6), (self._iu, 3), (self._isd, 1), (self._iss, 1), (self._isc, 1)]
        self._yblocks = [(0, 6), (6 * N, 9), (self._rd, Md), (self._rs, Ks), (self._rf, 2), (self._rc, Md),
                         (self._rc + Md * N, 1), (self._rg, 4)]
        self._A = A
        self.solver = self._new_solver()
        self._slot_solvers = {}  # passing-side pattern -> its own OSQP instance (made when first needed)
        self.reset()

    def _new_solver(self) -> osqp.OSQP:
        c, s = self.cfg, osqp.OSQP()
        s.setup(self.P, np.zeros(self.n), self._A, self._l0, self._u0, eps_abs=c.eps_abs, eps_rel=c.eps_rel,
                max_iter=c.max_iter, polishing=False, warm_starting=True, verbose=False, rho=c.rho,
                adaptive_rho=1, check_termination=25)
        return s

    def reset(self) -> None:
        """Forget the previous solution: the next call starts cold."""
        self._prev = None  # (t0, z, y, positions (N+1, 3))
        self._sides = {}  # obstacle id -> the side (+-1) the last plan passed it on, for the enumerated ones
        self._slot_prev = {}  # passing-side pattern -> (t0, z, y) of its last solution, its own warm start

    def _shift(self, vec, blocks, s):
        out = vec.copy()
        for off, w in blocks:
            b = vec[off:off + self.N * w].reshape(self.N, w)
            out[off:off + self.N * w] = np.vstack([b[s:], np.repeat(b[-1:], s, axis=0)]).ravel()
        return out

    def _fallback(self, t0, p0, v0, why, tic, iters=0, ignored=0):
        self._prev = None
        v = np.where(np.isfinite(v0), v0, 0.0)
        sp_ = np.linalg.norm(v)
        d = np.abs(v) / sp_ if sp_ > 1e-9 else np.ones(3)
        a = float(np.min(self._amax / np.maximum(d, 1e-12)))  # the largest deceleration along -v within limits
        ms = (time.perf_counter() - tic) * 1e3
        tr = brake_and_hold(t0, p0, v, a_max=a, dt=self.cfg.dt, horizon=self.N, status=f"fallback:{why}")
        tr = Trajectory(tr.t0, tr.dt, tr.positions, tr.velocities, tr.accelerations, status=tr.status, solve_ms=ms)
        return MPCResult(tr, tr.status, iters, 0.0, 0.0, ms, ignored)

    def _tolerance(self, solver, loose: bool) -> None:
        """The normal OSQP limits, or the short, loose ones other passing sides are compared on."""
        c = self.cfg
        solver.update_settings(max_iter=c.homotopy_max_iter if loose else c.max_iter,
                               eps_abs=c.homotopy_eps if loose else c.eps_abs,
                               eps_rel=c.homotopy_eps if loose else c.eps_rel)

    def _rejected(self, res) -> str:
        """Why an OSQP result cannot be used ('' when it can): solved (or out of iterations with a primal
        residual below max_prim_res) and finite."""
        st = osqp.SolverStatus(res.info.status_val)
        ok = st in _OK or (st == osqp.SolverStatus.OSQP_MAX_ITER_REACHED and res.info.prim_res < self.cfg.max_prim_res)
        if not ok:
            return st.name.removeprefix("OSQP_").lower()
        return "" if np.all(np.isfinite(res.x)) else "nonfinite_solution"

    def _tie_break(self, d, side, forced=None, bias=None):
        """Offsets d (N, J, 3) from obstacle j to c_k whose component along side[j] is below side_bias get
        it raised to side_bias (on their side, left if 0): a symmetric head-on plan would otherwise only
        ever brake or push through on slack. Any tangent plane is conservative. `side`: left of the
        obstacle's velocity relative to the planned motion (relative_side), else left of travel.
        forced (J,) in {-1, 0, +1}: where non-zero, the offset is put on that side (mirrored across the
        line if it lies on the other), so every plane asks the plan to pass the obstacle there."""
        lat = np.sum(d * side, axis=-1)
        sgn = np.where(lat < 0, -1.0, 1.0)
        if forced is not None:
            sgn = np.where(forced != 0, forced, sgn)
        bias = self.cfg.side_bias if bias is None else bias
        return d + (sgn * np.maximum(np.abs(lat), bias) - lat)[..., None] * side

    def _dynamic_candidates(self, c, obstacles, side, v_plan=None):
        """The obstacles (4) applies to, nearest first: (distance from the plan to the ellipsoid, index in
        `obstacles`, predicted centres (N, 3), semi-axes (N, 3), tie-break side (3,)), at most max_dynamic."""
        cfg, N = self.cfg, self.N
        t = cfg.dt * np.arange(1, N + 1)
        cand = []
        for idx, ob in enumerate(obstacles):
            sd = side
            if cfg.relative_side and v_plan is not None:
                vo = np.asarray(ob.velocity, dtype=float)
                vr = (vo - v_plan)[:2]
                if np.hypot(*vr) > 0.2:
                    sd = np.array([-vr[1], vr[0], 0.0]) / np.hypot(*vr)
                    lead = float(sd @ vo)  # the tie goes behind the obstacle; left of travel if it is neither
                    sd = -sd if lead > 0.05 or (lead >= -0.05 and float(sd @ side) < 0) else sd
            o = ob.predict(t)
            half = np.asarray(ob.size, dtype=float) / 2 + cfg.robot_radius + cfg.dynamic_margin
            ax = np.repeat(half[None], N, axis=0)
            ax[:, :2] += cfg.z_std * ob.std_at(t)[:, None]
            dist = float(np.min(np.linalg.norm(c - o, axis=1) - ax.max(axis=1)))  # to the ellipsoid, roughly
            if dist <= cfg.dynamic_range:
                cand.append((dist, idx, o, ax, sd))
        return sorted(cand, key=lambda e: e[:2])[:cfg.max_dynamic]

    def _side_combinations(self, c, cand, obstacles):
        """Passing sides to try: a list of forced-side arrays (J,) for _dynamic_rows, the one to keep first,
        and [(j, obstacle id)] of the enumerated candidates. The homotopy_obstacles nearest candidates
        within homotopy_range of the plan get both sides each (2^M combinations); the first combination is
        the side each was passed on by the last plan (else the side c_k lies on, as the tie-break puts it)."""
        cfg = self.cfg
        M = [j for j, e in enumerate(cand) if e[0] <= cfg.homotopy_range][:cfg.homotopy_obstacles]
        if not M:
            return [None], []
        ids = [(j, getattr(obstacles[cand[j][1]], "id", None)) for j in M]
        first = np.zeros(len(cand))
        for j, k in ids:
            e = cand[j]
            kk = int(np.argmin(np.linalg.norm(c - e[2], axis=1)))
            lat = float((c[kk] - e[2][kk]) @ e[4])
            first[j] = self._sides.get(k, -1.0 if lat < 0 else 1.0)  # (ids of None are never kept)
        combos = [first]
        for signs in itertools.product((1.0, -1.0), repeat=len(M)):
            f = np.zeros(len(cand))
            f[M] = signs
            if not np.array_equal(f, first):
                combos.append(f)
        return combos, ids

    def _dynamic_rows(self, c, cand, p0, forced=None, bias=None):
        """(4): unit normals (N, J, 3) and right-hand sides (N, J) for the candidates (_dynamic_candidates);
        forced (J,): the side each must be passed on (0: the tie-break rule's)."""
        cfg, N = self.cfg, self.N
        if not cand:
            return np.zeros((N, 0, 3)), np.zeros((N, 0))
        o = np.stack([e[2] for e in cand], axis=1)  # (N, J, 3)
        ax = np.stack([e[3] for e in cand], axis=1)
        side = np.stack([e[4] for e in cand])  # (J, 3)
        # an ellipsoid spanning the whole altitude band (a person) is treated as its elliptic cylinder:
        # horizontal normals, so the plan goes around it rather than climbing along its shoulder
        tall = ((o[..., 2] - ax[..., 2] <= cfg.z_min) & (o[..., 2] + ax[..., 2] >= cfg.z_max))[..., None]
        flat = np.where(tall, np.array([1.0, 1.0, 0.0]), 1.0)
        d = self._tie_break((c[:, None, :] - o) * flat, side, forced, bias)
        away = (p0 - o) * flat  # c_k at the centre (only with side_bias = 0): toward the drone, else +y
        away = np.where(np.linalg.norm(away, axis=-1, keepdims=True) > 1e-9, away, np.array([0.0, 1.0, 0.0]))
        d = np.where(np.linalg.norm(d, axis=-1, keepdims=True) < 1e-9, away, d)
        cs = o + d / np.sqrt(np.sum((d / ax) ** 2, axis=-1, keepdims=True))  # on the surface
        g = (cs - o) / ax ** 2
        n = g / np.linalg.norm(g, axis=-1, keepdims=True)
        return n, np.sum(n * cs, axis=-1)

    def _slide_clear(self, c, PT, d2, req, side):
        """Move each c_k along +-side (the shorter way, left on ties) to the nearest spot at least req from
        every point; q blocks the shifts sgn*(q - c).side +- sqrt(req^2 - |q - c|_perp^2) (d2 = |q - c|^2).
        Where no spot lies within static_radius, c_k stays."""
        along = (side @ PT)[None] - (c @ side)[:, None]
        perp2 = d2 - along ** 2
        keep = np.any(perp2 < req * req, axis=0)
        along, perp2 = along[:, keep], perp2[:, keep]
        h = np.sqrt(np.maximum(req * req - perp2, 0.0))
        shift = []
        for sgn in (1.0, -1.0):
            lo = np.where(perp2 < req * req, sgn * along - h, np.inf)
            hi = np.where(perp2 < req * req, sgn * along + h, -np.inf)
            d = np.zeros(len(c))
            for _ in range(20):
                cover = (lo < d[:, None]) & (hi > d[:, None])
                if not cover.any():
                    break
                d = np.where(cover.any(axis=1), np.max(np.where(cover, hi, -np.inf), axis=1) + 1e-6, d)
            shift.append(np.where(cover.any(axis=1), np.inf, d))
        s = np.where(shift[0] <= shift[1], shift[0], -shift[1])
        return c + np.where(np.abs(s) <= self.cfg.static_radius, s, 0.0)[:, None] * side

    def _static_rows(self, c, pts, side, p0):
        """(5): greedy separating planes, normals (N, Ks, 3) (zeros where unused) and rhs (N, Ks).
        Written for numpy speed on thousands of points: matrix products against the contiguous (3, M)
        transpose, masks combined as booleans, never a masked float assignment."""
        cfg, N, Ks = self.cfg, self.N, self.cfg.static_per_step
        n_out, b_out = np.zeros((N, Ks, 3)), np.full((N, Ks), -np.inf)
        r, req = cfg.static_radius, cfg.robot_radius + cfg.voxel_size / 2 + cfg.static_margin
        pts = pts[np.all((pts >= c.min(axis=0) - r) & (pts <= c.max(axis=0) + r), axis=1)]
        if len(pts) == 0:
            return n_out, b_out
        PT = np.ascontiguousarray(pts.T)
        sq = np.sum(PT * PT, axis=0)[None]

        def sqdist(c):  # (K, M) |c_k - q|^2, in place (large temporaries cost page faults)
            d = c @ PT
            d *= -2.0
            d += sq
            d += np.sum(c * c, axis=1)[:, None]
            return d

        d2 = sqdist(c)
        pen = np.min(d2, axis=1) < req * req
        if pen.any():  # the previous plan runs through voxels there: linearise beside them instead
            c = c.copy()
            c[pen] = self._slide_clear(c[pen], PT, d2[pen], req, side)
            d2[pen] = sqdist(c[pen])
        dead = d2 > r * r
        rows, key = np.arange(N), np.empty_like(d2)
        for j in range(Ks):
            np.multiply(dead, 1e30, out=key)
            key += d2
            idx = np.argmin(key, axis=1)
            use = ~dead[rows, idx]
            if not use.any():
                break
            q = pts[idx]
            nv = c - q
            # A linearisation point beyond the voxel, seen from the drone (the previous plan went through a
            # wall on slack), would give a plane keeping the plan beyond the wall: where the straight
            # line from the drone to c_k passes within the clearance of q, orient the plane from the
            # drone's position instead, which is on the free side. (A plan through a gap passes its
            # edge voxels farther than that and keeps its planes.)
            seg = c - p0
            w = np.clip(np.sum((q - p0) * seg, axis=1) / np.maximum(np.sum(seg * seg, axis=1), 1e-12), 0.0, 1.0)
            crosses = np.linalg.norm(p0 + w[:, None] * seg - q, axis=1) < req
            behind = crosses & (np.sum(nv * (p0 - q), axis=1) < 0.0)
            nv[behind] = (p0 - q)[behind]
            nn = np.linalg.norm(nv, axis=1)
            nv[nn < 1e-9], nn[nn < 1e-9] = side, 1.0  # c_k on a voxel centre (no clear spot found): left
            n = nv / nn[:, None]
            nq = np.sum(n * q, axis=1)
            n_out[use, j], b_out[use, j] = n[use], nq[use] + req
            dead |= (n @ PT) <= nq[:, None] + 1e-9  # points behind the plane through q: covered
        return n_out, b_out

    def solve(self, t0, position, velocity, acceleration, p_ref, v_ref, obstacles=(), static_points=None,
              geofence=None, guide=None) -> MPCResult:
        """One receding-horizon plan from (position, velocity) at time t0; see the module docstring.
        geofence: (lo (2,), hi (2,)) the known walls of the flight area in x, y (a corridor's), or None;
        every planned position keeps geofence_margin inside it, on the static slack (6).
        guide: (N, 3) positions of a motion chosen beforehand (planner.maneuvers), or None: the obstacles
        are linearised at it instead of at the previous plan, and the passing sides are the guide's (no
        side enumeration (4'), no tie-break offset), and no half-space asks for more room than the guide
        keeps (its right-hand side is capped at the guide's own value): the decision is the guide's, the MPC
        refines it."""
        tic = time.perf_counter()
        cfg, N, dt = self.cfg, self.N, self.cfg.dt
        p0, v0, a0 = (np.asarray(x, dtype=float).reshape(3) for x in (position, velocity, acceleration))
        p_ref, v_ref = np.asarray(p_ref, dtype=float).reshape(N, 3), np.asarray(v_ref, dtype=float).reshape(N, 3)
        if not (math.isfinite(t0) and all(np.all(np.isfinite(x)) for x in (p0, v0, a0, p_ref, v_ref))):
            if self._prev is not None and not np.all(np.isfinite(p0)) and math.isfinite(t0):
                prev = self._prev  # hold where the previous plan puts us now
                p0 = Trajectory(prev[0], dt, prev[3], prev[4], prev[5]).sample(t0)[0]
            return self._fallback(t0, p0, v0, "nonfinite_input", tic)
        if np.any(np.abs(v0) > self._vmax - cfg.backoff + self._amax * dt):  # step-1 velocity bound unreachable
            return self._fallback(t0, p0, v0, "infeasible_start", tic)
        obs = [ob for ob in obstacles if all(np.all(np.isfinite(np.asarray(x, dtype=float))) for x in
                                             (ob.center, ob.size, ob.velocity, ob.acceleration, ob.position_std))]
        ignored = len(obstacles) - len(obs)
        pts = np.zeros((0, 3)) if static_points is None else np.asarray(static_points, dtype=float).reshape(-1, 3)
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        # linearisation points and warm start: previous plan shifted by the elapsed steps, else a line
        s = None if self._prev is None else round((t0 - self._prev[0]) / dt)
        zw, yw = np.zeros(self.n), np.zeros(self.m)
        if s is not None and 0 <= s <= N:
            c = self._prev[3][np.minimum(np.arange(1, N + 1) + s, N)]
            if cfg.warm_start:
                zw, yw = self._shift(self._prev[1], self._xblocks, s), self._shift(self._prev[2], self._yblocks, s)
        else:
            c = p0 + np.arange(1, N + 1)[:, None] / N * (p_ref[-1] - p0)
        guided = guide is not None and np.all(np.isfinite(np.asarray(guide, dtype=float)))
        if guided:
            c = np.asarray(guide, dtype=float).reshape(N, 3)
        fwd = (p_ref[-1] - p0)[:2]
        fwd = fwd / np.linalg.norm(fwd) if np.linalg.norm(fwd) > 1e-6 else np.array([1.0, 0.0])
        side = np.array([-fwd[1], fwd[0], 0.0])  # left of the direction of travel
        q = np.zeros(self.n)
        qx = q[:6 * N].reshape(N, 6)
        qx[:, :3] = -2 * cfg.w_pos * p_ref
        qx[-1, :3] = -2 * cfg.w_terminal * p_ref[-1]
        qx[:, 3:] = -2 * cfg.w_vel * v_ref
        q[self._iu:self._iu + 3] = -2 * cfg.w_jerk * a0
        q[self._isd:self._iss] = cfg.w_slack_lin
        q[self._iss:self._isc] = cfg.w_slack_lin * cfg.static_slack_scale
        q[self._isc:] = 10.0  # inert
        l, u = self._l0.copy(), self._u0.copy()
        l[:3] = u[:3] = p0 + dt * v0
        l[3:6] = u[3:6] = v0
        # altitude band, widened to the vertical braking path from a start outside it or heading out of it
        vz = np.sign(v0[2]) * np.maximum(abs(v0[2]) - cfg.a_max_z * dt * np.arange(N + 1), 0.0)
        zb = p0[2] + np.cumsum(0.5 * dt * (vz[:-1] + vz[1:]))
        rz = slice(6 * N + 3, 15 * N, 9)
        l[rz], u[rz] = np.minimum(cfg.z_min + cfg.backoff, zb), np.maximum(cfg.z_max - cfg.backoff, zb)
        fence = None
        if geofence is not None:
            lo, hi = (np.asarray(x, dtype=float).reshape(-1)[:2] for x in geofence)
            if np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)):
                req = cfg.geofence_margin
                fence = (lo + req, hi - req)
                l[self._rg:self._rg + 4 * N] = cfg.geofence_scale * np.tile(
                    [lo[0] + req, req - hi[0], lo[1] + req, req - hi[1]], N)
        # the tracking cost's constant part: cost = OSQP objective + const >= 0, comparable across homotopies
        const = (cfg.w_pos * np.sum(p_ref[:-1] ** 2) + cfg.w_terminal * np.sum(p_ref[-1] ** 2)
                 + cfg.w_vel * np.sum(v_ref ** 2) + cfg.w_jerk * np.sum(a0 ** 2))
        v_plan = (p_ref[-1] - p0) / (N * dt)
        iters, why, n_hom = 0, "", 0
        for _ in range(max(1, cfg.iterations)):
            cand = self._dynamic_candidates(c, obs, side, v_plan)
            ns, bs = self._static_rows(c, pts, side, p0)
            ns[~np.isfinite(bs)], bs[~np.isfinite(bs)] = 0.0, -np.inf  # overflow from absurd inputs: row unused
            Ax0 = self._Ax0.copy()
            Ax0[self._sta_pos] = ns
            l[self._rs:self._rf] = bs.ravel()
            combos, enum_ids = ([None], []) if guided else self._side_combinations(c, cand, obs)
            best, zw0, yw0 = None, zw, yw
            for i, forced in enumerate(combos):
                nd, bd = self._dynamic_rows(c, cand, p0, forced, 0.0 if guided else None)
                if guided:  # never ask for more room than the guide keeps: the half-space holds the guide itself
                    bd = np.minimum(bd, np.einsum("kjd,kd->kj", nd, c))
                nd[~np.isfinite(bd)], bd[~np.isfinite(bd)] = 0.0, -np.inf
                J = nd.shape[1]
                Ax = Ax0.copy()
                Ax[self._dyn_pos[:, :J]] = nd
                l[self._rd:self._rs].reshape(N, -1)[:, :J] = bd
                solver, z0, y0, key = self.solver, zw0, yw0, None
                if forced is not None:  # each passing-side pattern keeps its own solver and warm start
                    key = tuple(float(forced[j]) for j, _ in sorted(enum_ids, key=lambda e: str(e[1])))
                    if key not in self._slot_solvers:
                        self._slot_solvers[key] = self._new_solver()
                    solver, pv = self._slot_solvers[key], self._slot_prev.get(key)
                    sk = None if pv is None else round((t0 - pv[0]) / dt)
                    if cfg.warm_start and sk is not None and 0 <= sk <= N:
                        z0, y0 = self._shift(pv[1], self._xblocks, sk), self._shift(pv[2], self._yblocks, sk)
                solver.update(q=q, l=l, u=u, Ax=Ax)
                # the other sides are only compared: a looser, shorter solve; the one kept is refined below
                loose = i > 0
                self._tolerance(solver, loose)
                solver.warm_start(x=z0, y=y0)
                res = solver.solve(raise_error=False)
                if key is not None and np.all(np.isfinite(res.x)) and np.all(np.isfinite(res.y)):
                    self._slot_prev[key] = (float(t0), np.array(res.x), np.array(res.y))
                iters += int(res.info.iter)
                n_hom += 1
                why = self._rejected(res)
                if why:
                    continue
                cost = float(res.info.obj_val) + const
                if i > 0:  # hysteresis: another side must be clearly cheaper than the one kept so far
                    cost = cost * (1.0 + cfg.homotopy_hysteresis) + cfg.homotopy_hysteresis_abs
                if best is None or cost < best[0]:
                    best = (cost, np.array(res.x), np.array(res.y), nd, bd, forced, (solver, Ax, l.copy(), loose))
                if i == 0 and max(np.max(res.x[self._isd:self._iss]), np.max(res.x[self._isc:])) <= cfg.homotopy_trigger:
                    break  # the side kept costs no slack worth speaking of: the others are not tried
            if best is None:
                return self._fallback(t0, p0, v0, why, tic, iters, ignored)
            _, zw, yw, nd, bd, forced, (solver, Ax, lb, loose) = best  # (a second round starts from this solution)
            if loose:  # another side won on a loose solve: finish it to the normal tolerance from there
                solver.update(q=q, l=lb, u=u, Ax=Ax)
                self._tolerance(solver, False)
                solver.warm_start(x=zw, y=yw)
                res = solver.solve(raise_error=False)
                iters += int(res.info.iter)
                if not self._rejected(res):
                    zw, yw = np.array(res.x), np.array(res.y)
            self._sides = {} if forced is None else {k: float(forced[j]) for j, k in enum_ids if k is not None}
            acc = np.clip(zw[self._iu:self._isd].reshape(N, 3), -self._amax, self._amax)
            pos, vel = _rollout(p0, v0, acc, dt)
            c = pos[1:]
        slack_d = float(np.max(bd - np.einsum("kjd,kd->kj", nd, c), initial=0.0))  # -inf rows: no violation
        slack_s = float(np.max(bs - np.einsum("kjd,kd->kj", ns, c), initial=0.0))
        if fence is not None:  # metres beyond the geofence's margin
            slack_s = max(slack_s, float(np.max(np.r_[fence[0] - c[:, :2], c[:, :2] - fence[1]].ravel(), initial=0.0)))
        self._prev = (float(t0), zw, yw, pos, vel, acc)
        ms = (time.perf_counter() - tic) * 1e3
        traj = Trajectory(float(t0), dt, pos, vel, acc, status="solved", solve_ms=ms)
        return MPCResult(traj, "solved", iters, slack_d, slack_s, ms, ignored, n_hom)


def bench_mpc(n: int = 300, seed: int = 0, cfg: MPCConfig = MPCConfig(), verbose: bool = True) -> dict:
    """Receding-horizon benchmark: the drone shuttles along y = 0 between x = 0.5 and 14.5 at 1.5 m/s
    beside a wall of voxels (y = 1.3, 637 points) while 4 people (0.5 x 0.5 x 1.8 m, 1 m/s) cross its
    path at 45-180 degrees, bouncing off y = -1.6, y = 0.9 and the corridor ends. Prediction: constant
    velocity (the truth between bounces). Each plan's first step is flown exactly. solve_ms figures."""
    rng = np.random.default_rng(seed)
    size = np.array([0.5, 0.5, 1.8])
    wx, wz = np.meshgrid(np.arange(3.0, 12.0 + 1e-9, 0.1), np.arange(0.6, 1.8 + 1e-9, 0.2))
    wall = np.column_stack([wx.ravel(), np.full(wx.size, 1.3), wz.ravel()])
    ang = np.radians([90.0, 45.0, 135.0, 180.0]) + rng.uniform(-0.1, 0.1, 4)
    pc = np.column_stack([[4.0, 7.0, 9.0, 13.0], [-1.5, -1.4, 0.8, 0.2], np.full(4, 0.9)])
    pv = np.column_stack([np.cos(ang), np.sin(ang), np.zeros(4)])
    mpc, dt, N = MPC(cfg), cfg.dt, cfg.horizon
    p, v, a, goal, flown = np.array([0.5, 0.0, 1.2]), np.zeros(3), np.zeros(3), 14.5, 0.0
    ms, fallbacks, slack, clear_p, clear_w, qps = [], 0, 0.0, np.inf, np.inf, 0
    for k in range(n):
        goal = 15.0 - goal if abs(goal - p[0]) < 0.3 else goal
        sk = p[0] + np.sign(goal - p[0]) * np.minimum(1.5 * dt * np.arange(1, N + 1), abs(goal - p[0]))
        p_ref = np.column_stack([sk, np.zeros(N), np.full(N, 1.2)])
        v_ref = np.column_stack([np.sign(goal - sk) * 1.5, np.zeros((N, 2))])
        obs = [ObstaclePrediction(id=j, center=pc[j].copy(), size=size, velocity=pv[j].copy()) for j in range(4)]
        r = mpc.solve(k * dt, p, v, a, p_ref, v_ref, obstacles=obs, static_points=wall)
        ms.append(r.solve_ms)
        qps += r.qp_solves
        fallbacks += r.status != "solved"
        slack = max(slack, r.max_slack_dynamic, r.max_slack_static)
        tr = r.trajectory
        flown += float(np.linalg.norm(tr.positions[1] - p))
        p, v, a = tr.positions[1].copy(), tr.velocities[1].copy(), tr.accelerations[0].copy()
        pc += pv * dt
        pv[:, 1] *= np.where((pc[:, 1] < -1.6) | (pc[:, 1] > 0.9), -1.0, 1.0)
        pv[:, 0] *= np.where((pc[:, 0] < 0.0) | (pc[:, 0] > 15.0), -1.0, 1.0)
        clear_p = min(clear_p, float(np.min(np.linalg.norm(pc[:, :2] - p[:2], axis=1))) - size[0] / 2)
        clear_w = min(clear_w, float(np.min(np.linalg.norm(wall - p, axis=1))))
    ms = np.array(ms)
    out = {"n": n, "median_ms": float(np.median(ms)), "p95_ms": float(np.percentile(ms, 95)),
           "p99_ms": float(np.percentile(ms, 99)), "max_ms": float(ms.max()), "qp_per_call": qps / n,
           "fallbacks": int(fallbacks),
           "max_slack_m": slack, "flown_m": flown, "min_clearance_people_m": clear_p, "min_clearance_wall_m": clear_w}
    if verbose:
        print("MPC bench: " + ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in out.items()))
    return out


if __name__ == "__main__":
    bench_mpc()
