"""The MPC's QP structure (planner.mpc.solver's module docstring): where each variable and row lives, the cost
matrix P, the sparsity pattern of A with its constant values, the constant bounds, and an OSQP instance
set up on them. Every call then changes only q, l, u and the values of A.
"""
from __future__ import annotations

import numpy as np
import osqp
import scipy.sparse as sp

from planner.mpc.config import MPCConfig


def rollout(p0, v0, acc, dt):
    """Exact knots of (1) under piecewise-constant acceleration: (N+1, 3) positions, velocities."""
    vel = np.vstack([v0, v0 + dt * np.cumsum(acc, axis=0)])
    pos = np.vstack([p0, p0 + np.cumsum(dt * vel[:-1] + 0.5 * dt * dt * acc, axis=0)])
    return pos, vel


class QPLayout:
    """Columns: x_k (6 per step from 0), u_k (3 per step from iu), sd_k from isd, ss_k from iss.
    Rows: dynamics (6 per step from 0); bounds (9 per step from 6 N: v, p_z, u, sd, ss); moving obstacles
    (max_dynamic per step from rd); voxels (static_per_step per step from rs); geofence (4 per step from
    rg: x >= lo, -x >= -hi, y >= lo, -y >= -hi, scaled by geofence_scale)."""

    def __init__(self, cfg: MPCConfig):
        self.cfg = c = cfg
        N, Md, Ks, dt = c.horizon, c.max_dynamic, c.static_per_step, c.dt
        self.N, self.n = N, 11 * N
        self.iu, self.isd, self.iss = 6 * N, 9 * N, 10 * N
        self.rd, self.rs = 15 * N, 15 * N + Md * N  # first dynamic / static obstacle row
        self.rg = self.rs + Ks * N  # first geofence row
        self.m = self.rg + 4 * N
        ix = 6 * np.arange(N)  # column of p_k (k = 1..N)
        iu = self.iu + 3 * np.arange(N)  # column of u_k (k = 0..N-1)
        # P: 1/2 z'Pz + q'z with P = 2 W (upper triangle)
        d = np.zeros(self.n)
        d[:6 * N].reshape(N, 6)[:, :3] = 2 * c.w_pos
        d[6 * (N - 1):6 * (N - 1) + 3] = 2 * c.w_terminal
        d[:6 * N].reshape(N, 6)[:, 3:] = 2 * c.w_vel
        d[self.iu:self.isd].reshape(N, 3)[:] = (2 * c.w_acc + 2 * c.w_jerk * (1 + (np.arange(N) < N - 1)))[:, None]
        d[self.isd:self.iss] = 2 * c.w_slack_quad
        d[self.iss:] = 2 * c.w_slack_quad * c.static_slack_scale
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
        add(rb + 7, self.isd + k, 1.0)
        add(rb + 8, self.iss + k, 1.0)
        kk = np.arange(N)[:, None, None]
        rd = self.rd + Md * kk + np.arange(Md)[None, :, None]
        dyn = add(rd + 0 * i[None], ix[:, None, None] + i[None], 0.0)
        add(rd[..., 0], self.isd + kk[..., 0] + 0 * np.arange(Md), 1.0)
        rs = self.rs + Ks * kk + np.arange(Ks)[None, :, None]
        sta = add(rs + 0 * i[None], ix[:, None, None] + i[None], 0.0)
        add(rs[..., 0], self.iss + kk[..., 0] + 0 * np.arange(Ks), 1.0)
        rg = self.rg + 4 * kk[..., 0] + np.arange(4)  # (N, 4)
        add(rg, ix[:, None] + np.array([0, 0, 1, 1]), c.geofence_scale * np.array([1.0, -1.0, 1.0, -1.0]))
        add(rg, self.iss + kk[..., 0] + 0 * np.arange(4), 1.0)
        R, C, V = np.concatenate(R), np.concatenate(C), np.concatenate(V)
        A = sp.csc_matrix((np.arange(1, len(R) + 1, dtype=float), (R, C)), (self.m, self.n))
        A.sort_indices()
        order = A.data.astype(np.int64) - 1  # CSC slot j holds COO entry order[j]
        pos = np.argsort(order)  # COO entry -> CSC slot
        A.data = V[order]  # explicit zeros stay in the pattern
        self.A = A
        # A's constant values, and the slots of A.data the obstacle rows' normals go to: (N, Md, 3), (N, Ks, 3)
        self.Ax0, self.dyn_pos, self.sta_pos = A.data.copy(), pos[dyn], pos[sta]
        self.vmax = vmax = np.array([c.v_max_xy, c.v_max_xy, c.v_max_z])
        self.amax = amax = np.array([c.a_max_xy, c.a_max_xy, c.a_max_z])
        vb = vmax - c.backoff
        lb = np.tile(np.r_[-vb, c.z_min + c.backoff, -amax, 0.0, 0.0], N)
        ub = np.tile(np.r_[vb, c.z_max - c.backoff, amax, np.inf, np.inf], N)
        self.l0 = np.r_[np.zeros(6 * N), lb, np.full(self.m - 15 * N, -np.inf)]
        self.u0 = np.r_[np.zeros(6 * N), ub, np.full(self.m - 15 * N, np.inf)]
        # per-step blocks (offset, width) of z and of the duals y, for shifting a solution in time
        self.xblocks = [(0, 6), (self.iu, 3), (self.isd, 1), (self.iss, 1)]
        self.yblocks = [(0, 6), (6 * N, 9), (self.rd, Md), (self.rs, Ks), (self.rg, 4)]
        self._shifts: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # s -> shift()'s gather indices of z, y

    def new_solver(self) -> osqp.OSQP:
        """An OSQP instance set up on this structure (q = 0, constant bounds) with the config's settings."""
        c, s = self.cfg, osqp.OSQP()
        s.setup(self.P, np.zeros(self.n), self.A, self.l0, self.u0, eps_abs=c.eps_abs, eps_rel=c.eps_rel,
                max_iter=c.max_iter, polishing=False, warm_starting=True, verbose=False, rho=c.rho,
                adaptive_rho=1, check_termination=25)
        return s

    def shift(self, z, y, s: int):
        """A primal-dual solution (z, y) moved s steps earlier in time, each block's last step repeated."""
        iz, iy = self._shifts.get(s) or self._shifts.setdefault(
            s, (self._shift_index(self.n, self.xblocks, s), self._shift_index(self.m, self.yblocks, s)))
        return np.asarray(z)[iz], np.asarray(y)[iy]

    def _shift_index(self, size: int, blocks, s: int) -> np.ndarray:
        """(size,) where each entry of a shifted vector comes from: per block of N steps of width w, step k
        from step min(k + s, N - 1); entries outside the blocks stay."""
        idx = np.arange(size)
        step = np.minimum(np.arange(self.N) + s, self.N - 1)
        for off, w in blocks:
            idx[off:off + self.N * w] = (off + step[:, None] * w + np.arange(w)).ravel()
        return idx
