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
    (5) Occupied voxels (centres q): greedy separating planes per step, from c_k:
        n = (c_k - q)/|c_k - q| for the nearest q, n.p_k + ss_k >= n.q + robot_radius + voxel/2 + margin,
        points behind the plane through q are dropped, repeat up to K_s times. Where c_k is closer than
        that to a voxel (the previous plan runs through it), c_k is first slid sideways to the nearest
        clear spot: planes from a clear point are consistent (it satisfies them all) and lead around. In a
        gap narrower than twice that clearance no clear spot lies near, and c_k stays: its planes ask
        only the room the gap lacks, on slack, instead of facing a spot beyond the gap's sides.
    (6) Optional geofence (the known walls of the flight area): g (p_k,xy - lo - r) + ss_k >= 0 and
        g (hi - r - p_k,xy) + ss_k >= 0, r = geofence_margin, g = geofence_scale: the side walls, which a
        forward camera sees only at a grazing angle; a violation costs g times the static slack.
P and the sparsity pattern of A are fixed at construction (room for max_dynamic + K_s rows per
step); every call only updates q, l, u and the values of A, warm-started from the previous
solution shifted in time. Obstacle predictions are taken to start at the planning time t0.

Modules: planner.mpc.config (MPCConfig), planner.mpc.qp (the QP's fixed structure), planner.mpc.rows
(the obstacle half-spaces (4), (5)), this one (the solve); its benchmark is experiments.bench_mpc.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import osqp

from planner.fallback import brake_and_hold, braking_1d
from planner.mpc.config import MPCConfig
from planner.mpc.qp import QPLayout, rollout
from planner.mpc.rows import dynamic_candidates, dynamic_rows, finite_rows, static_rows
from planner.types import Trajectory, finite_obstacle

__all__ = ["MPC", "MPCResult"]

_OK = {osqp.SolverStatus.OSQP_SOLVED, osqp.SolverStatus.OSQP_SOLVED_INACCURATE}


@dataclass(frozen=True, eq=False)
class MPCResult:
    trajectory: Trajectory
    status: str  # 'solved' | 'fallback:<why>'
    iterations: int  # OSQP iterations (summed over linearisation rounds)
    max_slack_dynamic: float  # m; largest violation of a dynamic half-space by the plan
    max_slack_static: float  # m
    solve_ms: float  # wall time of the whole call (updates + OSQP), measured only
    ignored_obstacles: int = 0  # obstacles skipped for non-finite data


def altitude_band(cfg: MPCConfig, p0, v0) -> tuple[np.ndarray, np.ndarray]:
    """(3)'s altitude bounds (N,) each on p_1..p_N: the band less the backoff, widened to the vertical
    braking path from a start outside it or heading out of it."""
    zb = braking_1d(p0[2], v0[2], cfg.a_max_z, cfg.dt, cfg.horizon)[0][1:]
    return np.minimum(cfg.z_min + cfg.backoff, zb), np.maximum(cfg.z_max - cfg.backoff, zb)


def finite_geofence(geofence) -> tuple[np.ndarray, np.ndarray] | None:
    """The geofence's (lo, hi) x, y (2,) each, or None when there is none or a bound is not finite."""
    if geofence is None:
        return None
    lo, hi = (np.asarray(x, dtype=float).reshape(-1)[:2] for x in geofence)
    return (lo, hi) if np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) else None


def brake_result(t0, p0, v0, amax, dt, horizon, why, tic, iters=0, ignored=0) -> MPCResult:
    """A solver's fallback: brake-and-hold at the largest deceleration along -v within the per-axis limits
    ``amax`` (3,), status ``fallback:<why>``; solve_ms from ``tic`` (perf_counter)."""
    v = np.where(np.isfinite(v0), v0, 0.0)
    sp_ = np.linalg.norm(v)
    d = np.abs(v) / sp_ if sp_ > 1e-9 else np.ones(3)
    a = float(np.min(amax / np.maximum(d, 1e-12)))
    ms = (time.perf_counter() - tic) * 1e3
    tr = brake_and_hold(t0, p0, v, a_max=a, dt=dt, horizon=horizon, status=f"fallback:{why}")
    tr = Trajectory(tr.t0, tr.dt, tr.positions, tr.velocities, tr.accelerations, status=tr.status, solve_ms=ms)
    return MPCResult(tr, tr.status, iters, 0.0, 0.0, ms, ignored)


class MPC:
    """One OSQP problem set up once; ``solve`` re-linearises the obstacles and re-solves (module docstring)."""

    def __init__(self, cfg: MPCConfig = MPCConfig()):
        self.cfg = cfg
        self.qp = QPLayout(cfg)
        self.N = cfg.horizon
        self.solver = self.qp.new_solver()
        self.reset()

    def reset(self) -> None:
        """Forget the previous solution: the next call starts cold."""
        self._prev = None  # (t0, z, y, positions (N+1, 3), velocities, accelerations)

    def _fallback(self, t0, p0, v0, why, tic, iters=0, ignored=0):
        self._prev = None
        return brake_result(t0, p0, v0, self.qp.amax, self.cfg.dt, self.N, why, tic, iters, ignored)

    def _rejected(self, res) -> str:
        """Why an OSQP result cannot be used ('' when it can): solved (or out of iterations with a primal
        residual below max_prim_res) and finite."""
        st = osqp.SolverStatus(res.info.status_val)
        ok = st in _OK or (st == osqp.SolverStatus.OSQP_MAX_ITER_REACHED and res.info.prim_res < self.cfg.max_prim_res)
        if not ok:
            return st.name.removeprefix("OSQP_").lower()
        return "" if np.all(np.isfinite(res.x)) else "nonfinite_solution"

    def _start(self, t0, p0, p_ref):
        """Linearisation points c (N, 3) and warm start (z, y): the previous plan shifted by the elapsed
        steps, else the straight line to the reference's end and zeros."""
        cfg, N, qp = self.cfg, self.N, self.qp
        s = None if self._prev is None else round((t0 - self._prev[0]) / cfg.dt)
        zw, yw = np.zeros(qp.n), np.zeros(qp.m)
        if s is not None and 0 <= s <= N:
            c = self._prev[3][np.minimum(np.arange(1, N + 1) + s, N)]
            if cfg.warm_start:
                zw, yw = qp.shift(self._prev[1], self._prev[2], s)
        else:
            c = p0 + np.arange(1, N + 1)[:, None] / N * (p_ref[-1] - p0)
        return c, zw, yw

    def _linear_cost(self, p_ref, v_ref, a0):
        """q of (2)."""
        cfg, N, qp = self.cfg, self.N, self.qp
        q = np.zeros(qp.n)
        qx = q[:6 * N].reshape(N, 6)
        qx[:, :3] = -2 * cfg.w_pos * p_ref
        qx[-1, :3] = -2 * cfg.w_terminal * p_ref[-1]
        qx[:, 3:] = -2 * cfg.w_vel * v_ref
        q[qp.iu:qp.iu + 3] = -2 * cfg.w_jerk * a0
        q[qp.isd:qp.iss] = cfg.w_slack_lin
        q[qp.iss:] = cfg.w_slack_lin * cfg.static_slack_scale
        return q

    def _bounds(self, p0, v0, geofence):
        """l, u for the initial state (1), the altitude band (3) and the geofence (6); and the fence the
        positions must keep inside ((lo, hi) (2,) each, margin included), or None."""
        cfg, N, dt, qp = self.cfg, self.N, self.cfg.dt, self.qp
        l, u = qp.l0.copy(), qp.u0.copy()
        l[:3] = u[:3] = p0 + dt * v0
        l[3:6] = u[3:6] = v0
        rz = slice(6 * N + 3, 15 * N, 9)
        l[rz], u[rz] = altitude_band(cfg, p0, v0)
        fence, g = None, finite_geofence(geofence)
        if g is not None:
            lo, hi = g
            req = cfg.geofence_margin
            fence = (lo + req, hi - req)
            l[qp.rg:qp.rg + 4 * N] = cfg.geofence_scale * np.tile([lo[0] + req, req - hi[0], lo[1] + req, req - hi[1]], N)
        return l, u, fence

    def _solve_qp(self, c, cand, p0, guided, q, l, u, Ax0, zw, yw):
        """The QP with the moving obstacles' rows (4) linearised at c, solved from the warm start (zw, yw).
        Returns (z, y, OSQP iterations, normals (N, J, 3), right-hand sides (N, J), why the result cannot be
        used: '' when it can)."""
        N, qp = self.N, self.qp
        nd, bd = dynamic_rows(self.cfg, c, cand, p0, 0.0 if guided else None)
        if guided:  # never ask for more room than the guide keeps: the half-space holds the guide itself
            bd = np.minimum(bd, np.einsum("kjd,kd->kj", nd, c))
        nd[~np.isfinite(bd)], bd[~np.isfinite(bd)] = 0.0, -np.inf
        J = nd.shape[1]
        Ax = Ax0.copy()
        Ax[qp.dyn_pos[:, :J]] = nd
        l[qp.rd:qp.rs].reshape(N, -1)[:, :J] = bd
        self.solver.update(q=q, l=l, u=u, Ax=Ax)
        self.solver.warm_start(x=zw, y=yw)
        res = self.solver.solve(raise_error=False)
        return np.array(res.x), np.array(res.y), int(res.info.iter), nd, bd, self._rejected(res)

    def solve(self, t0, position, velocity, acceleration, p_ref, v_ref, obstacles=(), static_points=None,
              geofence=None, guide=None) -> MPCResult:
        """One receding-horizon plan from (position, velocity) at time t0; see the module docstring.
        geofence: (lo (2,), hi (2,)) the known walls of the flight area in x, y (a corridor's), or None;
        every planned position keeps geofence_margin inside it, on the static slack (6).
        guide: (N, 3) positions of a motion chosen beforehand (planner.nominal.maneuvers), or None: the obstacles
        are linearised at it instead of at the previous plan, and the passing sides are the guide's (no
        tie-break offset), and no half-space asks for more room than the guide
        keeps (its right-hand side is capped at the guide's own value): the decision is the guide's, the MPC
        refines it."""
        tic = time.perf_counter()
        cfg, N, dt, qp = self.cfg, self.N, self.cfg.dt, self.qp
        p0, v0, a0 = (np.asarray(x, dtype=float).reshape(3) for x in (position, velocity, acceleration))
        p_ref, v_ref = np.asarray(p_ref, dtype=float).reshape(N, 3), np.asarray(v_ref, dtype=float).reshape(N, 3)
        if not (math.isfinite(t0) and all(np.all(np.isfinite(x)) for x in (p0, v0, a0, p_ref, v_ref))):
            if self._prev is not None and not np.all(np.isfinite(p0)) and math.isfinite(t0):
                prev = self._prev  # hold where the previous plan puts us now
                p0 = Trajectory(prev[0], dt, prev[3], prev[4], prev[5]).sample(t0)[0]
            return self._fallback(t0, p0, v0, "nonfinite_input", tic)
        if np.any(np.abs(v0) > qp.vmax - cfg.backoff + qp.amax * dt):  # step-1 velocity bound unreachable
            return self._fallback(t0, p0, v0, "infeasible_start", tic)
        obs = [ob for ob in obstacles if finite_obstacle(ob)]
        ignored = len(obstacles) - len(obs)
        pts = np.zeros((0, 3)) if static_points is None else np.asarray(static_points, dtype=float).reshape(-1, 3)
        pts = finite_rows(pts)
        c, zw, yw = self._start(t0, p0, p_ref)
        guided = guide is not None and np.all(np.isfinite(np.asarray(guide, dtype=float)))
        if guided:
            c = np.asarray(guide, dtype=float).reshape(N, 3)
        fwd = (p_ref[-1] - p0)[:2]
        fwd = fwd / np.linalg.norm(fwd) if np.linalg.norm(fwd) > 1e-6 else np.array([1.0, 0.0])
        side = np.array([-fwd[1], fwd[0], 0.0])  # left of the direction of travel
        q = self._linear_cost(p_ref, v_ref, a0)
        l, u, fence = self._bounds(p0, v0, geofence)
        v_plan = (p_ref[-1] - p0) / (N * dt)
        iters = 0
        for _ in range(max(1, cfg.iterations)):
            cand = dynamic_candidates(cfg, c, obs, side, v_plan)
            ns, bs = static_rows(cfg, c, pts, side, p0)
            ns[~np.isfinite(bs)], bs[~np.isfinite(bs)] = 0.0, -np.inf  # overflow from absurd inputs: row unused
            Ax0 = qp.Ax0.copy()
            Ax0[qp.sta_pos] = ns
            l[qp.rs:qp.rg] = bs.ravel()
            zw, yw, it, nd, bd, why = self._solve_qp(c, cand, p0, guided, q, l, u, Ax0, zw, yw)
            iters += it
            if why:
                return self._fallback(t0, p0, v0, why, tic, iters, ignored)
            acc = np.clip(zw[qp.iu:qp.isd].reshape(N, 3), -qp.amax, qp.amax)
            pos, vel = rollout(p0, v0, acc, dt)
            c = pos[1:]
        slack_d = float(np.max(bd - np.einsum("kjd,kd->kj", nd, c), initial=0.0))  # -inf rows: no violation
        slack_s = float(np.max(bs - np.einsum("kjd,kd->kj", ns, c), initial=0.0))
        if fence is not None:  # metres beyond the geofence's margin
            slack_s = max(slack_s, float(np.max(np.r_[fence[0] - c[:, :2], c[:, :2] - fence[1]].ravel(), initial=0.0)))
        self._prev = (float(t0), zw, yw, pos, vel, acc)
        ms = (time.perf_counter() - tic) * 1e3
        traj = Trajectory(float(t0), dt, pos, vel, acc, status="solved", solve_ms=ms)
        return MPCResult(traj, "solved", iters, slack_d, slack_s, ms, ignored)
