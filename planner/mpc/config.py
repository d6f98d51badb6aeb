"""Settings of the linear MPC (planner.mpc.solver); symbols as in that module's docstring."""
from __future__ import annotations

from dataclasses import dataclass


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
    iterations: int = 1  # linearise-and-solve rounds per call
    warm_start: bool = True  # start OSQP from the previous solution shifted in time (False: from zero)
    rho: float = 0.5  # OSQP initial ADMM step (adaptive after); ours (docs/experiments.md)
    eps_abs: float = 1e-3  # OSQP tolerances; ours
    eps_rel: float = 1e-3
    max_iter: int = 4000
    max_prim_res: float = 1e-2  # accept a max-iterations result whose primal residual is below this
    backoff: float = 0.01  # m/s, m; v and z bounds tightened inside the QP: OSQP's residuals stay within bounds


@dataclass(frozen=True)
class NMPCConfig:
    """Settings of the CasADi NMPC (planner.mpc.nmpc) beyond MPCConfig's, whose problem it solves."""

    stride: int = 2  # the NMPC's step is this many MPCConfig.dt (its horizon as long, in fewer steps): IPOPT's
    # time grows with the problem's size; ours
    max_iter: int = 60  # IPOPT iterations; a plan not converged by then is refused (the shield's stop); ours
    tol: float = 1e-4  # IPOPT's tolerance; ours
