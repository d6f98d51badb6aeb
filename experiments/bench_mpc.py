"""The MPC's receding-horizon benchmark (``python3 -m experiments.bench_mpc``; the CLI's ``bench planner``)."""
from __future__ import annotations

import numpy as np

from planner.mpc.config import MPCConfig
from planner.mpc.nmpc import NMPC
from planner.mpc.solver import MPC
from planner.types import ObstaclePrediction


def bench_mpc(n: int = 300, seed: int = 0, cfg: MPCConfig = MPCConfig(), verbose: bool = True,
              solver: str = "default") -> dict:
    """Receding-horizon benchmark: the drone shuttles along y = 0 between x = 0.5 and 14.5 at 1.5 m/s
    beside a wall of voxels (y = 1.3, 637 points) while 4 people (0.5 x 0.5 x 1.8 m, 1 m/s) cross its
    path at 45-180 degrees, bouncing off y = -1.6, y = 0.9 and the corridor ends. Prediction: constant
    velocity (the truth between bounces). Each plan's first 0.1 s (cfg.dt) is flown exactly. solve_ms figures.
    solver: the MPC of the built-in planner of that name (default: the OSQP MPC; nmpc: the CasADi NMPC)."""
    rng = np.random.default_rng(seed)
    size = np.array([0.5, 0.5, 1.8])
    wx, wz = np.meshgrid(np.arange(3.0, 12.0 + 1e-9, 0.1), np.arange(0.6, 1.8 + 1e-9, 0.2))
    wall = np.column_stack([wx.ravel(), np.full(wx.size, 1.3), wz.ravel()])
    ang = np.radians([90.0, 45.0, 135.0, 180.0]) + rng.uniform(-0.1, 0.1, 4)
    pc = np.column_stack([[4.0, 7.0, 9.0, 13.0], [-1.5, -1.4, 0.8, 0.2], np.full(4, 0.9)])
    pv = np.column_stack([np.cos(ang), np.sin(ang), np.zeros(4)])
    mpc, dt, N = (MPC(cfg) if solver == "default" else NMPC(cfg)), cfg.dt, cfg.horizon
    p, v, a, goal, flown = np.array([0.5, 0.0, 1.2]), np.zeros(3), np.zeros(3), 14.5, 0.0
    ms, fallbacks, slack, clear_p, clear_w = [], 0, 0.0, np.inf, np.inf
    for k in range(n):
        goal = 15.0 - goal if abs(goal - p[0]) < 0.3 else goal
        sk = p[0] + np.sign(goal - p[0]) * np.minimum(1.5 * dt * np.arange(1, N + 1), abs(goal - p[0]))
        p_ref = np.column_stack([sk, np.zeros(N), np.full(N, 1.2)])
        v_ref = np.column_stack([np.sign(goal - sk) * 1.5, np.zeros((N, 2))])
        obs = [ObstaclePrediction(id=j, center=pc[j].copy(), size=size, velocity=pv[j].copy()) for j in range(4)]
        r = mpc.solve(k * dt, p, v, a, p_ref, v_ref, obstacles=obs, static_points=wall)
        ms.append(r.solve_ms)
        fallbacks += r.status != "solved"
        slack = max(slack, r.max_slack_dynamic, r.max_slack_static)
        tr = r.trajectory
        before = p
        if tr.dt == dt:
            p, v, a = tr.positions[1].copy(), tr.velocities[1].copy(), tr.accelerations[0].copy()
        else:  # the NMPC's coarser grid
            p, v, a = tr.sample(k * dt + dt)
        flown += float(np.linalg.norm(p - before))
        pc += pv * dt
        pv[:, 1] *= np.where((pc[:, 1] < -1.6) | (pc[:, 1] > 0.9), -1.0, 1.0)
        pv[:, 0] *= np.where((pc[:, 0] < 0.0) | (pc[:, 0] > 15.0), -1.0, 1.0)
        clear_p = min(clear_p, float(np.min(np.linalg.norm(pc[:, :2] - p[:2], axis=1))) - size[0] / 2)
        clear_w = min(clear_w, float(np.min(np.linalg.norm(wall - p, axis=1))))
    ms = np.array(ms)
    out = {"n": n, "median_ms": float(np.median(ms)), "p95_ms": float(np.percentile(ms, 95)),
           "p99_ms": float(np.percentile(ms, 99)), "max_ms": float(ms.max()),
           "fallbacks": int(fallbacks),
           "max_slack_m": slack, "flown_m": flown, "min_clearance_people_m": clear_p, "min_clearance_wall_m": clear_w}
    if verbose:
        print(f"MPC bench ({solver}): " + ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in out.items()))
    return out


if __name__ == "__main__":
    bench_mpc()
