"""Non-linear MPC in CasADi: the OSQP MPC's problem (planner.mpc.solver) with exact clearance to people
and a terminal stop, solved by IPOPT.

Grid: N = horizon // stride steps of dt * stride (NMPCConfig.stride MPC steps each); the references and
the guide are taken at those knots. Variables w = [u_0..u_{N-1}, sd_1..sd_N, ss_1..ss_N, x_1..x_N]:
the accelerations, one dynamic and one static slack per step (metres, >= 0), and the states
x_k = (p_k, v_k), tied by the double integrator's equality rows (multiple shooting: sparse derivatives
for IPOPT's linear solver, and the limits become bounds on w).
    Cost: the OSQP MPC's (2), the same weights (MPCConfig).
    Bounds: |u_k| <= a_max; |v_k| <= v_max - backoff, v_N = 0: the plan ends at rest (passive safety:
        what the drone commits to always contains a stop); z_min <= p_k,z <= z_max widened to the
        vertical braking path, as the OSQP MPC's (3); x, y within the geofence less geofence_margin,
        widened to the horizontal braking path (inside the margin: no closer).
    Moving obstacle j, step k (exact, not linearised): with f = sum_i ((p_k,i - o_i) / a_i)^2 the
        OSQP MPC's ellipsoid (4) (semi-axes growing with the prediction's standard deviation; an
        ellipsoid spanning the altitude band becomes its elliptic cylinder),
            min_i(a_i) (sqrt(f) - 1) + sd_k >= 0,
        about the metres by which p_k keeps out of it; non-convex, so the solution is a local one near
        the initial guess: the guide (the maneuver layer's chosen motion) moved radially out of every
        ellipse, so the guide picks the passing side as its linearisation does for the QP.
    Static structure: the OSQP MPC's separating planes (5) at the guide (linear rows), on ss_k.
One ``nlpsol`` (SX expressions) per bucket of obstacle counts, all built at construction; every call only
passes parameters, bounds and the initial guess (the guide's, else the previous solution shifted). With no
moving obstacle the problem is a convex QP (quadratic cost, rows linear in w), and its bucket is a ``qpsol``
(CasADi's OSQP interface, polished) instead: the same optimum, found several times faster than by IPOPT.

The solver is a drop-in for planner.mpc.solver.MPC (same ``solve`` and result); the navigator uses it
when built with ``solver="nmpc"`` (``--planner nmpc``).
"""
from __future__ import annotations

import math
import time
from dataclasses import replace

import casadi as ca
import numpy as np

from planner.mpc.config import MPCConfig, NMPCConfig
from planner.mpc.qp import rollout
from planner.mpc.rows import dynamic_candidates, finite_rows, static_rows
from planner.mpc.solver import MPCResult, altitude_band, brake_result, finite_geofence
from planner.types import Trajectory, finite_obstacle

__all__ = ["NMPC", "NMPCConfig"]

_OK = ("Solve_Succeeded", "Solved_To_Acceptable_Level")


def _buckets(cfg: MPCConfig) -> tuple[int, ...]:
    """The numbers of moving obstacles a problem is built for: powers of two below max_dynamic, and it."""
    out, j = [0], 1
    while j < cfg.max_dynamic:
        out.append(j)
        j *= 2
    return tuple(out) + (cfg.max_dynamic,)


def _build(cfg: MPCConfig, ncfg: NMPCConfig, J: int):
    """The NLP (module docstring) with rows for J moving obstacles, as one ``nlpsol`` (a ``qpsol`` for J = 0);
    returns (solver, parameter offsets, row offsets). Variables w = [u (3 N), sd (N), ss (N), x (6 N)]: the
    states x_k = (p_k, v_k), k = 1..N, are variables tied by the dynamics' equality rows (sparse derivatives,
    which IPOPT's linear solver factorises fast), so the speed and altitude limits are bounds on w, not rows."""
    N, Ks, dt = cfg.horizon, cfg.static_per_step, cfg.dt
    u, sd, ss, x = ca.SX.sym("u", 3, N), ca.SX.sym("sd", N), ca.SX.sym("ss", N), ca.SX.sym("x", 6, N)
    p0, v0, a0 = ca.SX.sym("p0", 3), ca.SX.sym("v0", 3), ca.SX.sym("a0", 3)
    pref, vref = ca.SX.sym("pref", 3, N), ca.SX.sym("vref", 3, N)
    obs_o = ca.SX.sym("o", 3, N * J)  # predicted centres, column k * J + j
    obs_ia = ca.SX.sym("ia", 3, N * J)  # inverse semi-axes (0 in z: a cylinder)
    obs_am = ca.SX.sym("am", N * J)  # smallest semi-axis
    st_n = ca.SX.sym("sn", 3, N * Ks)  # static planes' normals, column k * Ks + i
    params = ca.vertcat(p0, v0, a0, ca.vec(pref), ca.vec(vref), ca.vec(obs_o), ca.vec(obs_ia), obs_am, ca.vec(st_n))
    cost = 0
    p, v, prev_u = p0, v0, a0
    g_eq, g_dyn, g_sta = [], [], []
    for k in range(N):
        uk = u[:, k]
        g_eq += [x[:3, k] - (p + dt * v + 0.5 * dt * dt * uk), x[3:, k] - (v + dt * uk)]
        p, v = x[:3, k], x[3:, k]
        w_p = cfg.w_terminal if k == N - 1 else cfg.w_pos
        cost += w_p * ca.sumsqr(p - pref[:, k]) + cfg.w_vel * ca.sumsqr(v - vref[:, k])
        cost += cfg.w_acc * ca.sumsqr(uk) + cfg.w_jerk * ca.sumsqr(uk - prev_u)
        cost += cfg.w_slack_lin * (sd[k] + cfg.static_slack_scale * ss[k])
        cost += cfg.w_slack_quad * (sd[k] ** 2 + cfg.static_slack_scale * ss[k] ** 2)
        prev_u = uk
        for j in range(J):
            c = k * J + j
            q = (p - obs_o[:, c]) * obs_ia[:, c]
            g_dyn.append(obs_am[c] * (ca.sqrt(ca.sumsqr(q) + 1e-9) - 1.0) + sd[k])
        g_sta += [ca.dot(st_n[:, k * Ks + i], p) + ss[k] for i in range(Ks)]
    g = ca.vertcat(*g_eq, *g_dyn, *g_sta)
    w = ca.vertcat(ca.vec(u), sd, ss, ca.vec(x))
    rows = {"dyn": 6 * N, "sta": 6 * N + J * N, "m": 6 * N + J * N + Ks * N}
    lay = {"pref": 9, "vref": 9 + 3 * N, "o": 9 + 6 * N, "ia": 9 + 6 * N + 3 * N * J, "am": 9 + 6 * N + 6 * N * J,
           "sn": 9 + 6 * N + 7 * N * J, "np": int(params.numel())}
    # fast_step_computation: no residual check of each search direction (MUMPS solves these small systems
    # accurately; the iterates agree to rounding)
    opts = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "ipopt.max_iter": ncfg.max_iter,
            "ipopt.tol": ncfg.tol, "ipopt.nlp_scaling_method": "gradient-based", "ipopt.fast_step_computation": "yes",
            "error_on_fail": False}
    nlp = {"x": w, "p": params, "f": cost, "g": g}
    if J == 0:  # a convex QP: OSQP, to well inside IPOPT's tolerance, then polished on the active set
        qp_opts = {"error_on_fail": False, "osqp": {"verbose": False, "eps_abs": 1e-5, "eps_rel": 1e-5,
                                                    "polish": True, "max_iter": cfg.max_iter}}
        return ca.qpsol("nmpc0", "osqp", nlp, qp_opts), lay, rows
    return ca.nlpsol(f"nmpc{J}", "ipopt", nlp, opts), lay, rows


def _spans_band(cfg: MPCConfig, o, ax) -> np.ndarray:
    """(N,) bool: steps at which the ellipsoid (centres o, semi-axes ax (N, 3)) spans the whole altitude band,
    and counts as its elliptic cylinder (planner.mpc.rows' rule)."""
    return (o[:, 2] - ax[:, 2] <= cfg.z_min) & (o[:, 2] + ax[:, 2] >= cfg.z_max)


def _outside(c, cand, bands, bias: float) -> np.ndarray:
    """The initial guess's positions c (N, 3) moved out of every candidate's ellipse (dynamic_candidates;
    bands: _spans_band of each), radially from its centre: the side it is passed on is the guess's. Where
    c_k lies within ``bias`` of the obstacle's line of relative motion (a symmetric head-on start, whose
    gradient cannot pick a side), the offset is first raised to ``bias`` along the candidate's tie-break
    side (planner.mpc.rows.dynamic_rows)."""
    c = np.array(c, dtype=float)
    for (_, _, o, ax, side), band in zip(cand, bands):
        d = c - o
        d[band, 2] = 0.0  # an elliptic cylinder: horizontal offsets
        lat = d @ side
        lift = np.where(np.abs(lat) < bias, np.where(lat < 0, -bias, bias) - lat, 0.0)
        d += lift[:, None] * side
        f = np.sqrt(np.sum((d / ax) ** 2, axis=1))
        inside = f < 1.0
        d[inside] /= np.maximum(f[inside, None], 1e-9) / 1.01
        moved = inside | (lift != 0)
        c[moved] = o[moved] + d[moved] + np.where(band[moved, None], [0.0, 0.0, 1.0], 0.0) * (c[moved] - o[moved])
    return c


class NMPC:
    """CasADi NLPs built once (one per bucket of moving-obstacle counts); ``solve`` fills the
    parameters and bounds and runs IPOPT (module docstring). Same interface as planner.mpc.solver.MPC."""

    def __init__(self, cfg: MPCConfig = MPCConfig(), ncfg: NMPCConfig = NMPCConfig()):
        """cfg: the problem (horizon and dt: the references' grid); ncfg: the solver, whose step is
        ``ncfg.stride`` of cfg's (the returned trajectory's dt)."""
        if not (isinstance(ncfg.stride, int) and 1 <= ncfg.stride <= cfg.horizon):
            raise ValueError(f"NMPCConfig.stride must be a whole number in [1, horizon = {cfg.horizon}], "
                             f"not {ncfg.stride!r}")
        self.fine, self.ncfg = cfg, ncfg
        self.cfg = cfg = replace(cfg, horizon=cfg.horizon // ncfg.stride, dt=cfg.dt * ncfg.stride)
        self.N = cfg.horizon
        self._take = ncfg.stride * np.arange(1, self.N + 1) - 1  # the references' knots on the NMPC's grid
        self.buckets = _buckets(cfg)
        # every bucket's problem built now (some 50 ms each), not on a plan's time
        self._problems = {J: (J, *_build(cfg, ncfg, J)) for J in self.buckets}
        self.amax = np.array([cfg.a_max_xy, cfg.a_max_xy, cfg.a_max_z])
        self.vmax = np.array([cfg.v_max_xy, cfg.v_max_xy, cfg.v_max_z])
        self.reset()

    def problem(self, n: int):
        """(solver, parameter offsets, row offsets) of the smallest problem with rows for n moving obstacles."""
        return self._problems[next(b for b in self.buckets if b >= min(n, self.cfg.max_dynamic))]

    def reset(self) -> None:
        """Forget the previous solution: the next call starts from the guide or a straight line."""
        self._prev = None  # (t0, accelerations (N, 3))

    def _fallback(self, t0, p0, v0, why, tic, iters=0, ignored=0):
        self._prev = None
        return brake_result(t0, p0, v0, self.amax, self.cfg.dt, self.N, why, tic, iters, ignored)

    def _fence(self, geofence, p0, v0) -> tuple[np.ndarray, np.ndarray]:
        """The planned positions' x, y bounds (2,) each from the geofence (the known walls): geofence_margin
        inside it, widened to what the drone cannot avoid from (p0, v0) (its braking path at a_max_xy per
        axis): inside the margin, no closer. Unbounded without a finite geofence."""
        g = finite_geofence(geofence)
        if g is None:
            return np.full(2, -np.inf), np.full(2, np.inf)
        g_lo, g_hi = g
        v = v0[:2]
        reach = p0[:2] + v * np.abs(v) / (2 * self.cfg.a_max_xy) + np.sign(v) * self.cfg.backoff
        r = self.cfg.geofence_margin
        return np.minimum(g_lo + r, np.minimum(p0[:2], reach)), np.maximum(g_hi - r, np.maximum(p0[:2], reach))

    def _initial(self, t0, p0, v0, guide, p_ref) -> np.ndarray:
        """Initial guess of the accelerations (N, 3): the motion through the guide's knots, else the previous
        solution shifted by the elapsed steps, else one step toward the reference's end."""
        N, dt = self.N, self.cfg.dt
        s = None if self._prev is None else round((t0 - self._prev[0]) / dt)
        if guide is not None:
            vel = np.vstack([v0, np.diff(np.vstack([p0, guide]), axis=0) / dt])
            acc = np.diff(vel, axis=0) / dt
        elif s is not None and 0 <= s <= N:
            acc = np.vstack([self._prev[1][s:], np.zeros((s, 3))])
        else:
            acc = np.zeros((N, 3))
            acc[0] = (p_ref[-1] - p0) / (N * dt) - v0
        return np.clip(acc, -self.amax, self.amax)

    def solve(self, t0, position, velocity, acceleration, p_ref, v_ref, obstacles=(), static_points=None,
              geofence=None, guide=None) -> MPCResult:
        """One receding-horizon plan from (position, velocity) at time t0, as planner.mpc.solver.MPC.solve
        (the same arguments; guide: the initial guess and the static planes' linearisation points)."""
        tic = time.perf_counter()
        cfg, N, dt, Nf = self.cfg, self.N, self.cfg.dt, self.fine.horizon
        p0, v0, a0 = (np.asarray(x, dtype=float).reshape(3) for x in (position, velocity, acceleration))
        p_ref = np.asarray(p_ref, dtype=float).reshape(Nf, 3)[self._take]
        v_ref = np.asarray(v_ref, dtype=float).reshape(Nf, 3)[self._take]
        if not (math.isfinite(t0) and all(np.all(np.isfinite(x)) for x in (p0, v0, a0, p_ref, v_ref))):
            return self._fallback(t0, p0, v0, "nonfinite_input", tic)
        if np.any(np.abs(v0) > self.vmax - cfg.backoff + self.amax * dt):
            return self._fallback(t0, p0, v0, "infeasible_start", tic)
        obs = [ob for ob in obstacles if finite_obstacle(ob)]
        ignored = len(obstacles) - len(obs)
        pts = np.zeros((0, 3)) if static_points is None else np.asarray(static_points, dtype=float).reshape(-1, 3)
        pts = finite_rows(pts)
        guided = guide is not None and np.all(np.isfinite(np.asarray(guide, dtype=float)))
        guide = np.asarray(guide, dtype=float).reshape(Nf, 3)[self._take] if guided else None
        acc0 = self._initial(t0, p0, v0, guide, p_ref)
        pos0, vel0 = rollout(p0, v0, acc0, dt)
        c = guide if guided else pos0[1:]
        fwd = (p_ref[-1] - p0)[:2]
        fwd = fwd / np.linalg.norm(fwd) if np.linalg.norm(fwd) > 1e-6 else np.array([1.0, 0.0])
        side = np.array([-fwd[1], fwd[0], 0.0])
        cand = dynamic_candidates(cfg, c, obs, side, (p_ref[-1] - p0) / (N * dt))
        J, solver, lay, rows = self.problem(len(cand))
        bands = [_spans_band(cfg, oc, ax) for _, _, oc, ax, _ in cand]
        pos0[1:] = _outside(pos0[1:] if not guided else guide, cand, bands, 0.0 if guided else cfg.side_bias)
        P = np.zeros(lay["np"])
        P[0:3], P[3:6], P[6:9] = p0, v0, a0
        P[lay["pref"]:lay["vref"]] = p_ref.ravel()
        P[lay["vref"]:lay["o"]] = v_ref.ravel()
        lbg, ubg = np.full(rows["m"], -np.inf), np.full(rows["m"], np.inf)
        lbg[:rows["dyn"]] = ubg[:rows["dyn"]] = 0.0  # the dynamics
        # moving obstacles: the nearest max_dynamic, exact
        o, ia, am, live = np.zeros((N, J, 3)), np.zeros((N, J, 3)), np.ones((N, J)), np.zeros((N, J), bool)
        for j, ((_, _, oc, ax, _), band) in enumerate(zip(cand, bands)):
            o[:, j], ia[:, j], am[:, j], live[:, j] = oc, 1.0 / ax, ax.min(axis=1), True
            ia[band, j, 2] = 0.0  # spans the altitude band: its elliptic cylinder
            am[band, j] = ax[band, :2].min(axis=1)
        P[lay["o"]:lay["ia"]] = o.ravel()
        P[lay["ia"]:lay["am"]] = ia.ravel()
        P[lay["am"]:lay["sn"]] = am.ravel()
        lbg[rows["dyn"]:rows["sta"]] = np.where(live, 0.0, -np.inf).ravel()
        # static structure: the OSQP MPC's planes at c
        ns, bs = static_rows(cfg, c, pts, side, p0)
        ok = np.isfinite(bs)
        ns[~ok] = 0.0
        P[lay["sn"]:] = ns.ravel()
        lbg[rows["sta"]:] = np.where(ok, bs, -np.inf).ravel()
        # bounds on w: accelerations, slacks >= 0, speeds (zero at the end: the terminal stop), altitude band,
        # geofence
        vb = np.tile(self.vmax - cfg.backoff, (N, 1))
        vb[-1] = 0.0
        zlo, zhi = altitude_band(cfg, p0, v0)
        flo, fhi = self._fence(geofence, p0, v0)
        xlo = np.column_stack([np.tile(flo, (N, 1)), zlo, -vb])
        xhi = np.column_stack([np.tile(fhi, (N, 1)), zhi, vb])
        lbx = np.r_[-np.tile(self.amax, N), np.zeros(2 * N), xlo.ravel()]
        ubx = np.r_[np.tile(self.amax, N), np.full(2 * N, np.inf), xhi.ravel()]
        w0 = np.r_[acc0.ravel(), np.zeros(2 * N), np.hstack([pos0[1:], vel0[1:]]).ravel()]  # x_k need not follow u_k
        sol = solver(x0=w0, p=P, lbg=lbg, ubg=ubg, lbx=lbx, ubx=ubx)
        st = solver.stats()
        iters = max(int(st.get("iter_count", 0)), 0)  # the QP interface reports none (-1)
        w = np.array(sol["x"]).ravel()
        if not (st.get("success") if J == 0 else st.get("return_status") in _OK):
            return self._fallback(t0, p0, v0, str(st.get("return_status", "failed")).lower(), tic, iters, ignored)
        if not np.all(np.isfinite(w)):
            return self._fallback(t0, p0, v0, "nonfinite_solution", tic, iters, ignored)
        acc = np.clip(w[:3 * N].reshape(N, 3), -self.amax, self.amax)
        pos, vel = rollout(p0, v0, acc, dt)
        slack_d = float(np.max(w[3 * N:4 * N], initial=0.0))
        slack_s = float(np.max(w[4 * N:5 * N], initial=0.0))
        self._prev = (float(t0), acc)
        ms = (time.perf_counter() - tic) * 1e3
        traj = Trajectory(float(t0), dt, pos, vel, acc, status="solved", solve_ms=ms)
        return MPCResult(traj, "solved", iters, slack_d, slack_s, ms, ignored)
