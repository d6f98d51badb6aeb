"""The planner the closed loop flies by default: global path on the voxel map, a maneuver chosen
among sampled motions, the MPC refining it.

Every call: (1) every ``path_period`` seconds, or sooner when the current path runs into newly
occupied cells, an A* path to the goal on the map's column grid at the flight altitude, and the
cost-to-go field the maneuvers score against (both cached on the map's version);
(2) ``planner.nominal.maneuvers`` scores two-phase candidate motions against the goal, static clearance and
several hypotheses of each moving obstacle's future, and the chosen one is the MPC's reference and the
point its obstacle constraints are linearised at (without a map: a reference along the straight line
to the goal at cruise speed);
(3) the MPC over the predicted moving obstacles and the occupied voxels near the drone;
(4) a heading that keeps both where the drone goes and the nearby moving obstacles in the
camera's view (without a map: toward a point ``look_ahead`` metres further on the path).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from dodt.context import EpisodeContext
from dodt.frames import CameraIntrinsics
from dodt.geometry import half_view
from planner.fallback import brake_and_hold, invalid_input_stop, valid_input
from planner.map.clearance import static_clearance
from planner.mpc.config import MPCConfig, NMPCConfig
from planner.mpc.solver import MPC
from planner.nominal.global_path import CostToGo, PathFollower, block_discs, grid_path
from planner.nominal.maneuvers import ManeuverConfig, ManeuverSelector
from planner.nominal.view import ViewTerm
from planner.types import PlannerInput, Trajectory, usable_obstacles


@dataclass(frozen=True)
class NavigatorConfig:
    cruise_speed: float = 1.5  # m/s; reference autonomous_flight desired_velocity 1.5
    goal_decel: float = 1.0  # m/s^2, speed profile toward the goal: v <= sqrt(2 a d)
    band_half_height: float = 0.3  # m; the column grid covers goal altitude +- this (plus inflation)
    path_period: float = 0.5  # s between global path searches
    static_radius: float = 3.5  # m; occupied voxels within this horizontal box half-size reach the MPC
    static_band: float = 0.8  # m; ... and within this height of the goal altitude
    block_times: tuple[float, ...] = (0.0, 0.5, 1.0)  # s; moving obstacles block the path search here
    look_ahead: float = 2.0  # m along the path for the heading
    use_geofence: bool = True  # keep the plan inside PlannerInput.geofence (the corridor's walls) when given
    # the maneuver layer (planner.nominal.maneuvers): picks how to pass moving obstacles and the MPC refines that motion
    maneuvers: ManeuverConfig = field(default_factory=ManeuverConfig)
    guide_look_ahead: float = 1.5  # m along the path: the maneuvers' frame points at this point
    # With maneuvers the heading is chosen to keep in the camera's view both where the drone goes (the chosen
    # maneuver heading_look_time ahead, weighted by its speed) and the moving obstacles that will be within
    # watch_range of the drone at watch_times (weighted more the closer they will be): a forward camera that
    # turns away from a person it is avoiding loses that person's track. Headings every 5 degrees; cost: how
    # far each bearing lies outside the half field of view less fov_margin, times its weight, plus a small
    # pull toward the motion.
    heading_look_time: float = 1.0  # s
    # rad: the camera's half horizontal field of view; None: the episode context's camera's (39.7 degrees for
    # the simulated D435 depth stream at 640x480, fx 387; a real D435's is 43.5). Less fov_margin, the rule
    # keeps what it watches inside the view
    camera_half_fov: float | None = None
    fov_margin: float = 0.15  # rad
    watch_range: float = 3.0  # m
    # s: the obstacles are watched where they and the drone will be at these times (bearing from the drone's
    # planned position to the obstacle's predicted one, weighted by that distance): what the drone is leaving
    # behind stops pulling the camera round, away from what lies ahead
    watch_times: tuple[float, ...] = (0.5, 1.0)
    # held up: when the cost-to-go at the drone fell by less than stall_progress metres over the last
    # stall_window seconds, the maneuvers and the MPC plan with stall_radius (at most mpc.robot_radius) instead
    # of mpc.robot_radius until it makes progress again (the shield keeps the vehicle's radius). 0.35 m: the
    # larger half side of the simulated drone's collision box, whose circumradius is 0.437 (ours; measured
    # in docs/experiments.md). None: never
    stall_window: float = 2.0  # s
    stall_progress: float = 1.0  # m
    stall_radius: float | None = 0.35  # m
    mpc: MPCConfig = field(default_factory=MPCConfig)
    nmpc: NMPCConfig = field(default_factory=NMPCConfig)  # the CasADi NMPC's solver (the nmpc planner only)


def _nmpc(cfg: NavigatorConfig):
    from planner.mpc.nmpc import NMPC  # CasADi is loaded only by the runs that use it

    return NMPC(cfg.mpc, cfg.nmpc)


SOLVERS = {"osqp": lambda cfg: MPC(cfg.mpc), "nmpc": _nmpc}  # the MPC's solver by name
_HEADINGS = np.radians(np.arange(-180, 180, 5.0))  # the heading's choices


class MPCPlanner:
    """Implements planner.types.Planner."""

    def __init__(self, cfg: NavigatorConfig = NavigatorConfig(), solver: str = "osqp"):
        """solver: the MPC's, ``osqp`` (planner.mpc.solver, the QP) or ``nmpc`` (planner.mpc.nmpc, CasADi)."""
        self.cfg = cfg
        if solver not in SOLVERS:
            raise ValueError(f"MPCPlanner: unknown solver {solver!r}; known: {', '.join(SOLVERS)}")
        self.solver = solver
        self.mpc = SOLVERS[solver](cfg)
        m = cfg.mpc
        self.selector = ManeuverSelector(cfg.maneuvers, horizon=m.horizon, dt=m.dt, a_max=m.a_max_xy,
                                         v_max=m.v_max_xy, robot_radius=m.robot_radius)
        # the solver's own configuration (the NMPC's on its coarser grid), and the same held up (stall_radius,
        # never wider than its own radius; without stall_radius the same)
        own = self.mpc.cfg
        held = own if cfg.stall_radius is None else replace(own, robot_radius=min(cfg.stall_radius, own.robot_radius))
        self._mpc_cfgs = (own, held)
        self.reset()

    def reset(self, context: EpisodeContext | None = None) -> None:
        """Before an episode; the context's camera gives the half view when the configuration has none (no
        context: the default camera model's)."""
        if self.cfg.camera_half_fov is not None:
            self.half_fov = self.cfg.camera_half_fov
        else:
            self.half_fov = context.camera.half_view if context is not None else half_view(CameraIntrinsics())
        self.mpc.reset()
        self.selector.reset()
        self._fields = None  # (grid and fence key, column grid, static clearance)
        self._cost_to_go = CostToGo()
        self.last_maneuver = None
        self.follower: PathFollower | None = None
        self._path_stamp = -math.inf
        self._goal: np.ndarray | None = None
        self.path_searches = 0
        self.path_failures = 0
        self._progress: list[tuple[float, float]] = []  # (stamp, cost-to-go at the drone) over stall_window
        self._set_radius(False)

    def _set_radius(self, stalled: bool) -> None:
        """The maneuvers and the MPC plan with the held-up configuration's radius when stalled, else with
        mpc.robot_radius (_mpc_cfgs)."""
        self.mpc.cfg = self._mpc_cfgs[stalled]
        self.selector.r = self.mpc.cfg.robot_radius

    def _update_stall(self, inp: PlannerInput, goal_field: np.ndarray) -> None:
        """Record the cost-to-go at the drone and set the planning radius (config: stall_*)."""
        c = self.cfg
        if c.stall_radius is None:
            return
        occ = inp.occupancy
        ij = occ.world_to_cell(np.asarray(inp.position, float)[None, :2])[0]
        inside = 0 <= ij[0] < goal_field.shape[0] and 0 <= ij[1] < goal_field.shape[1]
        g = float(goal_field[ij[0], ij[1]]) if inside else math.inf
        if not math.isfinite(g):
            g = float(np.hypot(*(np.asarray(inp.goal, float)[:2] - np.asarray(inp.position, float)[:2])))
        h = self._progress
        if h and inp.stamp < h[-1][0]:
            h.clear()
        h.append((float(inp.stamp), g))
        while len(h) > 1 and inp.stamp - h[1][0] >= c.stall_window:
            h.pop(0)
        full = inp.stamp - h[0][0] >= c.stall_window - 1e-9
        self._set_radius(full and h[0][1] - g < c.stall_progress)

    @property
    def path(self) -> np.ndarray | None:
        """The current global path (K, 2) in world x, y."""
        return None if self.follower is None else self.follower.points

    def _blocked(self, occupancy, z: float, obstacles=()):
        """The column grid, with discs around the moving obstacles' current and near-future positions
        blocked too: the path then passes people on the side with room, and the MPC follows it."""
        b = occupancy.column_blocked(z - self.cfg.band_half_height, z + self.cfg.band_half_height, inflate=True)
        if not obstacles:
            return b
        m = self.cfg.mpc
        times = np.asarray(self.cfg.block_times)
        centres, radii = [], []
        for o in obstacles:
            r = 0.5 * float(np.hypot(o.size[0], o.size[1])) + m.robot_radius + m.dynamic_margin
            c = o.predict(times)
            ok = np.all(np.isfinite(c), axis=1)
            centres.append(c[ok, :2])
            radii.append(np.full(int(ok.sum()), r))
        b = b.copy()
        block_discs(b, np.ascontiguousarray(np.concatenate(centres)), np.concatenate(radii),
                    float(occupancy.xy_origin[0]), float(occupancy.xy_origin[1]), float(occupancy.res))
        return b

    def _path_still_free(self, blocked, occupancy, s0: float) -> bool:
        s = np.arange(s0, self.follower.length, occupancy.cfg.resolution)
        if len(s) == 0:
            return True
        pts, _ = self.follower.at(s)
        ij = occupancy.world_to_cell(pts)
        ok = (ij[:, 0] >= 0) & (ij[:, 1] >= 0) & (ij[:, 0] < blocked.shape[0]) & (ij[:, 1] < blocked.shape[1])
        ij = ij[ok]
        return not bool(blocked[ij[:, 0], ij[:, 1]].any())

    def _update_path(self, inp: PlannerInput) -> None:
        goal_changed = self._goal is None or not np.array_equal(self._goal, inp.goal)
        occ = inp.occupancy
        if occ is None:
            if goal_changed or self.follower is None:
                self.follower = PathFollower(np.array([inp.position[:2], inp.goal[:2]]))
            self._goal = np.array(inp.goal, dtype=float)
            return
        due = goal_changed or self.follower is None or inp.stamp - self._path_stamp >= self.cfg.path_period
        blocked = self._blocked(occ, float(inp.goal[2]), inp.obstacles)
        if not due:
            due = not self._path_still_free(blocked, occ, self.follower.project(inp.position[:2]))
        if not due:
            return
        self.path_searches += 1
        pts = grid_path(blocked, occ.xy_origin, occ.cfg.resolution, inp.position[:2], inp.goal[:2])
        if pts is None:
            self.path_failures += 1  # keep the previous path (or the straight line): the MPC still avoids
            if self.follower is None:
                pts = np.array([inp.position[:2], inp.goal[:2]])
            else:
                pts = None
        if pts is not None:
            self.follower = PathFollower(pts)
        self._path_stamp = inp.stamp
        self._goal = np.array(inp.goal, dtype=float)

    def _profile(self, s0: float, cruise: float) -> tuple[np.ndarray, np.ndarray]:
        c, m, f = self.cfg, self.cfg.mpc, self.follower
        s_k, v_k = np.empty(m.horizon), np.empty(m.horizon)
        s = s0
        for k in range(m.horizon):
            v = min(cruise, math.sqrt(2.0 * c.goal_decel * max(f.length - s, 0.0)))
            s = min(s + v * m.dt, f.length)
            s_k[k], v_k[k] = s, v
        return s_k, v_k

    def reference(self, inp: PlannerInput) -> tuple[np.ndarray, np.ndarray]:
        """MPC position and velocity references (N, 3) along the path at cruise speed (without a map)."""
        c, m = self.cfg, self.cfg.mpc
        f = self.follower
        s_k, v_k = self._profile(f.project(inp.position[:2]), c.cruise_speed)
        pts, tang = f.at(s_k)
        p_ref = np.column_stack([pts, np.full(m.horizon, float(inp.goal[2]))])
        v_ref = np.column_stack([tang * v_k[:, None], np.zeros(m.horizon)])
        return p_ref, v_ref

    def _static_fields(self, inp: PlannerInput):
        """Static clearance and cost-to-go grids at the flight altitude. The clearance is recomputed when its
        column grid, the grid's placement or the geofence change (most map updates leave it as it was), the
        cost-to-go when a change can reach it (global_path.CostToGo)."""
        occ, z = inp.occupancy, float(inp.goal[2])
        fence = None if inp.geofence is None or not self.cfg.use_geofence else tuple(np.asarray(g, float) for g in inp.geofence)
        h = self.cfg.maneuvers.band_half_height
        solid = occ.column_blocked(z - h, z + h, inflate=False)
        blocked = occ.column_blocked(z - self.cfg.band_half_height, z + self.cfg.band_half_height, inflate=True)
        key = (occ.xy_origin.tobytes(), occ.res, None if fence is None else tuple(np.r_[fence[0], fence[1]]))
        f = self._fields
        if f is None or f[0] != key or not np.array_equal(f[1], solid):
            self._fields = (key, solid, static_clearance(solid, occ.res, occ.xy_origin, fence))
        return self._fields[2], self._cost_to_go(blocked, occ.xy_origin, occ.res, inp.goal[:2])

    def _toward_path_ahead(self, inp: PlannerInput, distance: float) -> np.ndarray:
        """(2,) from the drone to the point ``distance`` metres further along the path than its projection."""
        f = self.follower
        ahead, _ = f.at(np.array([f.project(inp.position[:2]) + distance]))
        return ahead[0] - inp.position[:2]

    def guided_reference(self, inp: PlannerInput):
        """(p_ref, v_ref) for the MPC from the maneuver layer (also its guide: the chosen maneuver)."""
        m = self.cfg.mpc
        d = self._toward_path_ahead(inp, self.cfg.guide_look_ahead)
        if np.hypot(*d) < 0.2:
            d = inp.goal[:2] - inp.position[:2]
        if np.hypot(*d) < 1e-6:
            d = np.array([1.0, 0.0])
        clear, goal = self._static_fields(inp)
        self._update_stall(inp, goal)
        man = self.selector.choose(inp.stamp, inp.position, inp.velocity, d, inp.obstacles, clear, goal,
                                   inp.occupancy.xy_origin, inp.occupancy.res, inp.goal[:2])
        self.last_maneuver = man
        z = float(inp.goal[2])
        p_ref = np.column_stack([man.positions[1:], np.full(m.horizon, z)])
        v_ref = np.column_stack([man.velocities[1:], np.zeros(m.horizon)])
        return p_ref, v_ref

    def _view_term(self, inp: PlannerInput, path_yaw: float | None) -> ViewTerm:
        """The heading rule's bearings (config) as a view.ViewTerm over this call's obstacles."""
        c = self.cfg
        steps = lambda t, lo: min(max(int(round(t / c.mpc.dt)), lo), c.mpc.horizon)  # noqa: E731
        times = np.asarray(c.watch_times, float)
        watch = np.array([ob.predict(times)[:, :2] for ob in inp.obstacles], float).reshape(-1, len(times), 2)
        return ViewTerm(_HEADINGS, self.half_fov - c.fov_margin, steps(c.heading_look_time, 1),
                        c.heading_look_time, math.nan if path_yaw is None else path_yaw, watch,
                        np.array([steps(t, 0) for t in c.watch_times], np.int64), c.watch_range, 0.05)

    def _heading(self, inp: PlannerInput, path_yaw: float | None, view: ViewTerm) -> float | None:
        """The heading, every 5 degrees, that best keeps the maneuver's direction and nearby moving obstacles
        in view (config; view: this call's _view_term); path_yaw when there is nothing to keep in view."""
        _, arg = view.costs(self.last_maneuver.positions[None, 1:], inp.position)
        return path_yaw if arg[0] < 0 else float(view.headings[arg[0]])

    def plan(self, inp: PlannerInput) -> Trajectory:
        """The trajectory to fly from ``inp``; its solve_ms is the whole call's wall time (path search,
        maneuver choice and MPC), not the MPC's alone (bench_mpc measures that).

        Never raises and always returns a finite trajectory: a stamp, position, velocity, acceleration,
        goal or heading that is not finite, or whose size no vehicle reaches (fallback.valid_input), gives
        brake-and-hold (status ``fallback:invalid_input``) and leaves the planner as it was; an error
        inside gives brake-and-hold (``error:<type>``) and resets the planner, whose state the error may
        have left half updated."""
        tic = time.perf_counter()
        a_max = self.cfg.mpc.a_max_xy
        if not valid_input(inp):
            return invalid_input_stop(inp, a_max)
        inp, _ = usable_obstacles(inp)  # one with non-finite fields is dropped (the shield counts them)
        try:
            traj = self._plan(inp, tic)
            if not (isinstance(traj, Trajectory) and all(np.all(np.isfinite(a)) for a in (
                    traj.positions, traj.velocities, traj.accelerations)) and math.isfinite(traj.t0)
                    and (traj.yaw is None or math.isfinite(traj.yaw))):
                raise FloatingPointError("the plan is not finite")
            return traj
        except Exception as e:  # noqa: BLE001 - a planner error must not stop the vehicle's loop
            self.reset()
            return brake_and_hold(inp.stamp, inp.position, inp.velocity, a_max=a_max, status=f"error:{type(e).__name__}")

    def _plan(self, inp: PlannerInput, tic: float) -> Trajectory:
        self._update_path(inp)
        guide = None
        d = self._toward_path_ahead(inp, self.cfg.look_ahead)
        yaw = math.atan2(d[1], d[0]) if np.hypot(*d) > 0.3 else None
        if inp.occupancy is not None:
            p_ref, v_ref = self.guided_reference(inp)
            guide = p_ref
        else:
            p_ref, v_ref = self.reference(inp)
        static = None
        occ = inp.occupancy
        if occ is not None:
            r, zc, h = self.cfg.static_radius, float(inp.goal[2]), self.cfg.static_band
            lo = np.array([inp.position[0] - r, inp.position[1] - r, zc - h])
            hi = np.array([inp.position[0] + r, inp.position[1] + r, zc + h])
            static = occ.occupied_centers(lo, hi)
        res = self.mpc.solve(inp.stamp, inp.position, inp.velocity, inp.acceleration, p_ref, v_ref,
                             obstacles=inp.obstacles, static_points=static,
                             geofence=inp.geofence if self.cfg.use_geofence else None, guide=guide)
        traj = res.trajectory
        if guide is not None:
            yaw = self._heading(inp, yaw, self._view_term(inp, yaw))
        return Trajectory(traj.t0, traj.dt, traj.positions, traj.velocities, traj.accelerations,
                          status=traj.status, solve_ms=(time.perf_counter() - tic) * 1e3, yaw=yaw)
