"""One closed-loop episode: sim -> sensor frame -> perception -> voxel map -> planner -> controller.

Rates, all in sim time: physics and the controller as the scenario says (240 / 120 Hz), camera
frames at the camera rate (30 Hz) each go through perception, every ``map_every``-th frame updates
the voxel map (with the perception's dynamic boxes cleared), the planner runs at ``plan_rate``
(10 Hz) and the controller tracks the latest plan at every control period. Moving obstacles
reach the planner extrapolated from their perception stamp to the planning time.

Before the episode every module gets the episode's context (dodt.context.EpisodeContext: the vehicle,
the camera's model and mount, the rates, the geofence, read-only views of the static map and the seen
space) through ``reset(context)``. Nothing in the loop raises on a planner or perception failure
(experiments.guards): a planner that raises or returns a malformed trajectory gets a brake-and-hold
trajectory (status ``error:<what>``), a perception update that fails is a skipped frame; both are counted,
and the first error's traceback is printed, written to ``errors.txt`` and kept in the summary. Numba's
compilation time (its on-disk cache makes it small after a process's first run) and the simulator's
start-up are timed apart from the loop, whose real-time factor the summary reports.
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from dodt.context import CameraSensor, EpisodeContext, LidarSensor, Rates, VehicleLimits
from dodt.lidar_views import scan_depth_views
from experiments.compile_time import CompileTimer
from experiments.config import Settings
from experiments.environment import environment
from experiments.episode_config import EpisodeConfig
from experiments.episode_log import EpisodeLog
from experiments.episode_metrics import summarize_log
from experiments.episode_recorder import EpisodeRecorder
from experiments.follower import TrajectoryFollower
from experiments.guards import PerceptionGuard, PlannerGuard, planner_telemetry
from experiments.plugins import is_spec
from experiments.provenance import source
from experiments.registry import (DEFAULT_PLANNER, behind_shield, configured, make_perception, make_planner,
                                  perception_sections, planner_label, planner_sections, plugin_sections)
from planner.map.visibility import SeenSpace
from planner.map.voxel_map import MapConfig, VoxelMap
from planner.types import ObstaclePrediction, Planner, PlannerInput
from sim import World, load_scenario
from sim.rig import SensorMount, camera_mount, cameras, frames_per_scan, rig_of
from sim.static_grid import static_occupancy

GOAL_TOLERANCE = 0.4  # m: the episode succeeds when the drone is this close to the goal
CRASH_ALTITUDE = 0.1  # m: below this the drone is on the floor


def map_config_for(scenario, robot_radius: float) -> MapConfig:
    """Map bounds: the corridor (the flight area is a known geofence) with a margin; the robot size
    for the path search's inflation: the drone's horizontal circumscribed circle."""
    co = scenario.corridor
    margin = 0.5
    return MapConfig(origin=(-margin, -co.width / 2 - margin, -0.1),
                     size=(co.length + 2 * margin, co.width + 2 * margin, co.height + 0.2),
                     robot_size=(2 * robot_radius, 2 * robot_radius, 0.3))


def _extrapolate(obstacles, stamp: float, now: float) -> tuple[ObstaclePrediction, ...]:
    lag = max(now - stamp, 0.0)
    if lag == 0.0:
        return tuple(obstacles)
    return tuple(o.advanced(lag) for o in obstacles)


def sensor_yaw(sensor) -> float:
    """The heading [rad] of a sensor's forward axis on the body: a camera's optical axis, a LiDAR's x axis."""
    axis = sensor.T_body_sensor[:3, 2] if isinstance(sensor, CameraSensor) else sensor.T_body_sensor[:3, 0]
    return math.atan2(axis[1], axis[0])


def rig_sensors(sc, world: World, mounts: tuple[SensorMount, ...]) -> tuple:
    """The context's sensors of a rig (sim.rig): each camera the scenario's camera model turned by its yaw,
    each LiDAR sim.lidar's model on top."""
    out = []
    for m in mounts:
        if m.kind == "camera":
            T = camera_mount(world.T_body_camera, m.yaw)
            out.append(CameraSensor(name=m.name, intrinsics=world.intrinsics, T_body_sensor=T,
                                    rate=float(sc.rates.camera), max_depth=float(sc.camera.max_range)))
        else:
            model = m.lidar_model()
            out.append(LidarSensor(name=m.name, model=model, T_body_sensor=m.T_body_lidar(), rate=model.scan_rate))
    return tuple(out)


def episode_context(sc, seed: int, world: World, cfg: EpisodeConfig, duration: float, vmap: VoxelMap,
                    seen: SeenSpace, mounts: tuple[SensorMount, ...]) -> EpisodeContext:
    """The context every module of this episode is reset with; ``mounts``: its rig (sim.rig.rig_of)."""
    v = world.vehicle
    co = sc.corridor  # its walls are known: the planner keeps inside them (the map sees them only at a glance)
    control = 1.0 / (world.dt * world.steps_per_control)
    return EpisodeContext(
        scenario=sc.name, seed=seed, duration=duration,
        vehicle=VehicleLimits.from_thrust(v.radius, v.collision_size, v.mass, v.thrust_to_weight),
        sensors=rig_sensors(sc, world, mounts),
        rates=Rates(control=control, plan=cfg.plan_rate, map=sc.rates.camera / cfg.map_every),
        start=np.asarray(sc.drone.start, float), goal=np.asarray(sc.drone.goal, float),
        geofence=(np.array([0.0, -co.width / 2]), np.array([co.length, co.width / 2])),
        static_map=vmap, seen=seen)


def run_episode(scenario, seed: int | None = None, perception="dodt", planner: str | Planner | None = None,
                out: Path | None = None, cfg: EpisodeConfig = EpisodeConfig(), renderer: str | None = None,
                on_frame=None, settings: Settings | None = None, shield: bool = False) -> dict:
    """Fly one episode; returns the summary (and writes summary.json and log.jsonl.gz to ``out``).

    scenario: a Scenario or a shipped scenario name / TOML path. perception: a mode name
    (dodt, oracle, static-only, any DODT preset), a plug-in's ``module:Class`` (experiments.registry) or a
    perception module. planner: any object with ``reset(context)`` and ``plan(PlannerInput) -> Trajectory``,
    a plug-in's ``module:Class``, or None / "default": the maneuver + MPC planner behind the shield;
    ``shield``: put a plug-in planner (spec or object) behind the same shield.
    settings: overrides by section (experiments.config.Settings; its episode section is applied to
    ``cfg``); the summary's ``config`` records them and the full values of every section used.
    on_frame(view): optional callback per camera frame (live viewers); view is a dict with t, frame
    (SensorFrame), truth (GroundTruth), perception (PerceptionOutput), map (VoxelMap), trajectory
    (the current plan or None), T_world_body (4x4), path (the planner's global path or None), lidar (the
    latest LiDAR scan's returns in the world frame, (N, 3), or None).
    renderer: overrides ``cfg.renderer``. Frames carry colour only when the perception module reads it
    (its ``uses_color``) or ``on_frame`` is given.
    """
    timer = CompileTimer()
    with timer:
        return _run(scenario, seed, perception, planner, out, cfg, renderer, on_frame, settings or Settings(),
                    shield, timer)


def _run(scenario, seed, perception, planner, out, cfg, renderer, on_frame, settings: Settings, shield: bool,
         timer: CompileTimer) -> dict:
    t_wall = time.perf_counter()
    sc = load_scenario(scenario) if isinstance(scenario, (str, Path)) else scenario
    seed = sc.seed if seed is None else int(seed)
    sc = sc.for_seed(seed)  # a scenario with ranges: this seed's draw
    cfg = configured(settings, "episode", cfg)
    perc = make_perception(perception, settings=settings) if isinstance(perception, str) else perception
    spec = DEFAULT_PLANNER if planner is None else planner
    duration = sc.duration if cfg.duration is None else cfg.duration
    name = getattr(perc, "name", type(perc).__name__)
    labels = {"perception": perception if isinstance(perception, str) and is_spec(perception) else name,
              "perception_name": name}
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
    # streamed to the file as the episode runs (a temporary one without ``out``); the metrics are read from it
    log = EpisodeLog(None if out is None else out / "log.jsonl.gz")
    # images are needed by a depth-built map or by a perception module that looks at them (unknown ones do)
    render = cfg.static_map == "depth" or bool(getattr(perc, "uses_images", True))
    color = sc.camera.color and (bool(getattr(perc, "uses_color", True)) or on_frame is not None)
    world = None
    try:
        world = World(sc, seed=seed, renderer=renderer if renderer is not None else cfg.renderer,
                      segmentation=False, render=render, frame_latency=cfg.frame_latency, color=color,
                      render_process=cfg.render_process and render and cfg.frame_latency > 0)
        rig = rig_of(cfg.rig, sc)  # (its name, its sensors)
        others = cameras(rig[1])[1:]
        if others and render:
            world.add_cameras([m.yaw for m in others])
        if isinstance(spec, str):
            planner = make_planner(spec, world.vehicle.radius, settings, shield=shield)
            labels["planner"] = planner_label(spec, shield)
        else:
            labels["planner"] = type(planner).__name__
            if shield:
                planner = behind_shield(planner, world.vehicle.radius, settings)
                labels["planner"] = f"shield+{labels['planner']}"
        used = {"episode": cfg, **planner_sections(planner), **perception_sections(perc),
                **plugin_sections(perception, spec, settings)}
        loop = _Loop(sc, seed, world, perc, planner, log, cfg, duration, on_frame, labels, timer, rig)
        startup = time.perf_counter() - t_wall
        summary = loop.run(used, settings)
    finally:
        if world is not None:
            world.close()
        log.close()
    wall = time.perf_counter() - t_wall
    compile_s = timer.seconds
    loop_s = max(wall - startup - timer.seconds_after(loop.started), 1e-9)
    summary["timing"].update(wall_s=round(wall, 2), startup_s=round(startup, 2), compile_s=round(compile_s, 2),
                             loop_s=round(loop_s, 2),
                             real_time_factor=round(summary["sim_time"] / loop_s, 3),
                             renderer=world.renderer)
    errors = {m.errors.module: m.errors.summary() for m in (loop.planner, loop.perception) if m.errors.count}
    if errors:
        summary["module_errors"] = errors
    # what computed it: outcomes agree bit for bit within one environment, not across them (the
    # renderer, not where it ran: a render process gives the same frames)
    summary["environment"] = {**environment(), "renderer": world.renderer.split(" (")[0]}
    summary["source"] = source()
    if out is not None:
        if errors:
            (out / "errors.txt").write_text("".join(
                f"{m}: {e['count']} failures, the first at t = {e['first_time']:.2f} s:\n{e['first']}\n"
                for m, e in errors.items()))
        (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return summary


class _Loop:
    """One episode's closed loop, once its world and modules exist: ``run`` sets up the map, the seen space
    and the context, then alternates ``_perceive`` (each camera frame), ``_plan`` (each planning period)
    and a control step until the goal, a crash or the time limit."""

    def __init__(self, sc, seed: int, world: World, perc, planner, log: EpisodeLog, cfg: EpisodeConfig,
                 duration: float, on_frame, labels: dict, timer: CompileTimer, rig: tuple[str, tuple[SensorMount, ...]]):
        self.sc, self.seed, self.world, self.cfg, self.duration = sc, seed, world, cfg, duration
        self.on_frame, self.labels, self.timer = on_frame, labels, timer
        self.rig_name, self.mounts = rig  # sim.rig.rig_of: the rig's name and its sensors
        self.raw_planner = planner
        self.perception = PerceptionGuard(perc, labels["perception"])
        self.planner = PlannerGuard(planner, labels["planner"])
        self.log = log
        self.started = time.perf_counter()
        self.obstacles, self.obstacles_stamp = (), 0.0  # the latest moving obstacles perception reported
        self.n_frames = 0

    def run(self, used: dict, settings: Settings) -> dict:
        world = self.world
        ctx = self._setup(settings)
        config = settings.record({**used, "map": self.vmap.cfg})
        self._header(ctx, config)
        control_dt = world.dt * world.steps_per_control
        plan_every = max(1, int(round(1.0 / (self.cfg.plan_rate * control_dt))))
        self.follower = TrajectoryFollower(float(self.sc.drone.yaw), self.cfg.max_yaw_rate, control_dt,
                                           self.cfg.accel_lead)
        reason, time_to_goal = "timeout", None
        frame, truth = world.latest_frame(), world.ground_truth()  # None until the first frame arrives (latency)
        k = 0
        while True:
            t = world.time
            if frame is not None:
                self._perceive(t, frame, truth)
            st = world.state()
            if not (np.all(np.isfinite(st.position)) and st.position[2] > CRASH_ALTITUDE or t < 0.5):
                reason = "crashed"
                break
            if np.linalg.norm(st.position - ctx.goal) < GOAL_TOLERANCE:
                reason, time_to_goal = "goal", t
                break
            if t >= self.duration - 1e-9:
                break
            if k % plan_every == 0:
                self._plan(t, st, ctx)
            ref = self.follower.reference(t, st.position)
            frame = world.step(ref)
            truth = world.ground_truth() if frame is not None else truth
            k += 1
            self.rec.step(world, ref.position)

        self.rec.end(world.time, reason, time_to_goal)
        summary = summarize_log(self.log.finish())
        summary["map_voxels_occupied"] = int(self.vmap.occupied_count())
        summary["perception_name"] = self.labels["perception_name"]
        summary["rig"] = self.rig_name
        summary["config"] = config
        return summary

    def _setup(self, settings: Settings) -> EpisodeContext:
        """The static map (known from the start with ``static_map = truth``), the seen space, the recorder,
        and the modules reset with the episode's context."""
        sc, world, cfg = self.sc, self.world, self.cfg
        self.vmap = vmap = VoxelMap(configured(settings, "map", map_config_for(sc, world.vehicle.radius)))
        self.known_map = cfg.static_map == "truth"
        if self.known_map:
            vmap.set_known(static_occupancy(sc, vmap.origin, vmap.dims, vmap.res))
        self.seen = seen = SeenSpace(vmap.xy_origin, tuple(vmap.dims[:2]), vmap.res, band=cfg.seen_band)
        seen.reset(start_xy=np.asarray(sc.drone.start[:2], float), radius=cfg.launch_radius, stamp=0.0)
        self.seen_blocked = vmap.column_blocked(*cfg.seen_band, inflate=False) if self.known_map else None
        ctx = episode_context(sc, self.seed, world, cfg, self.duration, vmap, seen, self.mounts)
        self.perception.reset(ctx)
        self.planner.reset(ctx)
        self.truth_for_perception = bool(getattr(self.perception.perception, "uses_ground_truth", False))
        self._setup_rig(ctx)
        self.rec = EpisodeRecorder(self.log, cfg.map_snapshot_period, map_changes_stop=self.known_map)
        return ctx

    def _setup_rig(self, ctx: EpisodeContext) -> None:
        """The rig's other cameras (their frames come with the first's) and its LiDAR: scanned every
        ``lidar_every``-th camera frame when perception reads scans or the map is built from the sensors."""
        world, perc = self.world, self.perception.perception
        self.other_cameras = len(cameras(self.mounts)) > 1 and world.render_on
        self.lidar = next((s for s in ctx.sensors if isinstance(s, LidarSensor)), None)
        wants_scans = callable(getattr(perc, "observe_lidar", None)) or not self.known_map
        if self.lidar is not None and not (wants_scans and world.render_on):
            self.lidar = None  # nothing would read its scans
        self.lidar_every = 1 if self.lidar is None else frames_per_scan(self.sc.rates.camera, self.lidar.model)
        self.map_scan = None  # the latest scan not yet in the map
        self.scan_world = None  # the latest scan's returns in the world frame (for on_frame only)

    def _scan(self):
        """A LiDAR scan now: the depth panorama (sim.lidar_panorama), or cast rays without OpenGL."""
        return self.world.lidar_scan(self.lidar.model, self.lidar.T_body_sensor, method="auto")

    def _header(self, ctx: EpisodeContext, config: dict) -> None:
        sc, world, cfg, vmap = self.sc, self.world, self.cfg, self.vmap
        self.rec.header(
            scenario=sc.name, source=sc.source, seed=self.seed, perception=self.labels["perception"],
            planner=self.labels["planner"], duration=self.duration, static_map=cfg.static_map,
            rig=self.rig_name,
            sensors=[{"name": s.name, "kind": s.kind, "yaw": round(math.degrees(sensor_yaw(s)), 3)}
                     for s in ctx.sensors],
            frame_latency=cfg.frame_latency,
            rates={"control": ctx.rates.control, "camera": sc.rates.camera, "plan": cfg.plan_rate, "map": ctx.rates.map},
            corridor={"length": sc.corridor.length, "width": sc.corridor.width, "height": sc.corridor.height},
            start=list(sc.drone.start), goal=ctx.goal.tolist(), map_resolution=vmap.cfg.resolution,
            map_origin=list(vmap.cfg.origin),
            camera={k: getattr(world.intrinsics, k) for k in ("width", "height", "fx", "fy", "cx", "cy")},
            static=[o.to_json() for o in world.obstacle_truth() if o.kind == "static"],
            people=[{"id": i, "height": round(w.height, 3), "sees_drone": bool(sees)}
                    for i, w, sees in zip(world.person_ids, world.walkers, world.crowd.sees)],
            config=config)

    def _perceive(self, t: float, frame, truth) -> None:
        """One camera frame: perception (timed without numba's compilation), the map and the seen space
        every ``map_every`` frames, the log, the viewer."""
        cfg, vmap, seen = self.cfg, self.vmap, self.seen
        others = self.world.latest_extra_frames() if self.other_cameras else ()
        scan = self._scan() if self.lidar is not None and self.n_frames % self.lidar_every == 0 else None
        c0, t0 = self.timer.seconds, time.perf_counter()
        if others:
            self.perception.observe("observe_cameras", others, frame.stamp)
        if scan is not None:
            self.perception.observe("observe_lidar", scan, frame.stamp)
            self.map_scan = scan  # for the map's next update
            self.rec.lidar(scan)
            if self.on_frame is not None:
                self.scan_world = scan.points_world()
        po = self.perception.update(frame, truth if self.truth_for_perception else None)
        perc_ms = (time.perf_counter() - t0 - (self.timer.seconds - c0)) * 1e3
        if po.skipped is None:
            self.obstacles, self.obstacles_stamp = po.obstacles, po.stamp
        map_ms = None
        if self.n_frames % cfg.map_every == 0:
            if self.known_map:
                seen.observe_map(self.seen_blocked, frame.intrinsics, frame.T_world_camera, frame.stamp,
                                 occluders=[(o.center, o.size) for o in po.obstacles])
            else:
                views = [(f.depth_m_counted()[0], f.intrinsics, f.T_world_camera) for f in (frame, *others)]
                if self.map_scan is not None:  # the LiDAR's returns, as depth images around it (dodt.lidar_views)
                    li = self.lidar.model
                    views += scan_depth_views(self.map_scan, li.elevation_min, li.elevation_max)
                    self.map_scan = None
                map_ms = vmap.update_views(views, dynamic_boxes=po.clear_boxes, stamp=frame.stamp)["ms"]
                for depth_m, K, T in views:
                    seen.observe_depth(depth_m, K, T, frame.stamp)
        self.n_frames += 1
        self.rec.frame(frame.stamp, truth, po, perc_ms, map_ms)
        self.rec.map_snapshot(t, vmap)
        if self.on_frame is not None:
            self.on_frame({"t": frame.stamp, "frame": frame, "truth": truth, "perception": po, "map": vmap,
                           "trajectory": self.follower.trajectory, "T_world_body": truth.T_world_body,
                           "lidar": self.scan_world,
                           "path": planner_telemetry(self.raw_planner).get("path")})

    def _plan(self, t: float, st, ctx: EpisodeContext) -> None:
        """One plan from the drone's state and the obstacles extrapolated to now; the follower flies it."""
        inp = PlannerInput(stamp=t, position=st.position.copy(), velocity=st.velocity.copy(),
                           acceleration=self.follower.acceleration.copy(), goal=ctx.goal,
                           obstacles=_extrapolate(self.obstacles, self.obstacles_stamp, t), occupancy=self.vmap,
                           yaw=st.yaw, geofence=ctx.geofence, seen=self.seen)
        c0 = self.timer.seconds
        traj = self.planner.plan(inp)
        compile_ms = (self.timer.seconds - c0) * 1e3
        if compile_ms > 0.0:
            traj = replace(traj, solve_ms=max(traj.solve_ms - compile_ms, 0.0))
        self.follower.follow(traj)
        self.rec.plan(t, traj, len(inp.obstacles), planner_telemetry(self.raw_planner))
