"""One closed-loop episode: sim -> sensor frame -> perception -> voxel map -> planner -> controller.

Rates, all in sim time: physics and the controller as the scenario says (240 / 120 Hz), camera
frames at the camera rate (30 Hz) each go through perception, every ``map_every``-th frame updates
the voxel map (with the perception's dynamic boxes cleared), the planner runs at ``plan_rate``
(10 Hz) and the controller tracks the latest plan at every control period. Moving obstacles
reach the planner extrapolated from their perception stamp to the planning time.

Nothing in the loop raises on a planner or perception failure: a planner exception becomes a
brake-and-hold trajectory (status ``error:<type>``), a frame perception skips is counted.
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from dodt.geometry import wrap_angle
from experiments.environment import environment
from experiments.episode_log import EpisodeLog, MapChanges, r4
from experiments.config import Settings
from experiments.perception_modes import PerceptionModule, config_sections, make_perception
from experiments.plugins import DEFAULT_PLANNER, is_spec, make_planner
from planner.fallback import brake_and_hold
from planner.map.visibility import SeenSpace
from planner.map.voxel_map import MapConfig, VoxelMap
from planner.mpc.config import MPCConfig
from planner.nominal.navigator import MPCPlanner, NavigatorConfig
from planner.shield.shield import PassiveSafetyShield, ShieldConfig
from planner.types import ObstaclePrediction, Planner, PlannerInput, Trajectory
from sim import World, load_scenario
from sim.controller import Reference
from sim.scenario import MAX_DURATION
from sim.static_grid import static_occupancy

STATIC_MAPS = ("depth", "truth")
GOAL_TOLERANCE = 0.4  # m: the episode succeeds when the drone is this close to the goal
CRASH_ALTITUDE = 0.1  # m: below this the drone is on the floor


@dataclass(frozen=True)
class EpisodeConfig:
    plan_rate: float = 10.0  # Hz; reference planners replan at 10-20 Hz. 20 Hz was measured (dodt, corridor seeds
    # 0-18, with the geofence): 8 of 19 successes against 10 of 19 at 10 Hz; no gain, so 10
    map_every: int = 2  # camera frames per map update: 15 Hz at 30 Hz (reference map timer: 20 Hz)
    max_yaw_rate: float = 1.2  # rad/s, heading changes toward the planner's yaw
    map_snapshot_period: float = 1.0  # s between occupied-voxel snapshots in the log
    duration: float | None = None  # s; None: the scenario's duration
    # "depth": the static map is built from the camera's depth frames (the paper's setup); "truth": it holds
    # the scenario's static geometry from the start and depth is not used (sim.static_grid), which isolates
    # a planner from the mapping; with a perception mode that needs no images (the oracles, static-only)
    # nothing is rendered then, and an episode runs several times faster
    static_map: str = "depth"
    # camera periods between a frame's capture and its arrival at perception (stamps, poses and truth stay the
    # capture's; moving obstacles are extrapolated to the planning time). 1: the camera and perception pipeline's
    # delay, and with render_process the next frame renders in a second process while this one is perceived and
    # planned on (results bit-identical to rendering in one process with the same latency)
    frame_latency: int = 1
    render_process: bool = True
    seen_band: tuple[float, float] = (0.8, 1.6)  # m, world z: a ray crossing a floor cell at these heights saw
    # nobody there (planner.map.visibility.SeenSpace; a person's torso)
    launch_radius: float = 2.0  # m around the start that counts as seen free when the episode begins
    # the camera's renderer (sim.camera: auto, gl, pybullet, tiny); None: the scenario's. Changes the images
    # (gl and pybullet draw the same geometry, shaded differently), so outcomes are compared per renderer
    renderer: str | None = None


def map_config_for(scenario, robot_radius: float) -> MapConfig:
    """Map bounds: the corridor (the flight area is a known geofence) with a margin; the robot size
    for the path search's inflation: the drone's horizontal circumscribed circle."""
    co = scenario.corridor
    margin = 0.5
    return MapConfig(origin=(-margin, -co.width / 2 - margin, -0.1),
                     size=(co.length + 2 * margin, co.width + 2 * margin, co.height + 0.2),
                     robot_size=(2 * robot_radius, 2 * robot_radius, 0.3))


def default_planner(robot_radius: float, settings: Settings | None = None) -> PassiveSafetyShield:
    """The maneuver + MPC planner behind the passive-safety shield, sized for the drone (its collision box's
    horizontal circumscribed radius); ``settings``' navigator and shield sections applied on top."""
    nav = NavigatorConfig(mpc=MPCConfig(robot_radius=robot_radius))
    shield = ShieldConfig(drone_radius=robot_radius)
    if settings:
        nav, shield = settings.navigator_config(nav), settings.shield_config(shield)
    return PassiveSafetyShield(MPCPlanner(nav), shield)


def _threats(planner) -> dict:
    """A plan record's ``threats``: the people's discs the planner kept its plan from, where it says (the
    shield's ``threats``, (M, 3) x, y, radius), and ``forgot``: where the people it stopped remembering at
    this plan were predicted, and why (the shield's ``forgotten``); nothing for a planner that does not."""
    th = getattr(planner, "threats", None)
    if th is None:
        return {}
    th = np.asarray(th, dtype=float)
    if th.ndim != 2 or th.shape[1] != 3:  # a plug-in's own attribute of that name: not ours to log
        return {}
    out = {"threats": np.round(th[np.all(np.isfinite(th), axis=1)], 2).tolist()}
    try:
        gone = [[round(float(x), 2), round(float(y), 2), str(why)] for x, y, why in getattr(planner, "forgotten", ())]
    except (TypeError, ValueError):  # a plug-in's own attribute of that name
        gone = []
    gone = [g for g in gone if math.isfinite(g[0]) and math.isfinite(g[1])]
    if gone:
        out["forgot"] = gone
    return out


def _extrapolate(obstacles, stamp: float, now: float) -> tuple[ObstaclePrediction, ...]:
    lag = max(now - stamp, 0.0)
    if lag == 0.0:
        return tuple(obstacles)
    out = []
    for o in obstacles:
        c = o.predict(np.array([lag]))[0]
        v = o.velocity + o.acceleration * min(lag, o.accel_horizon)
        out.append(replace(o, center=c, velocity=v, position_std=float(o.std_at(np.array([lag]))[0])))
    return tuple(out)


def _finite_trajectory(traj) -> bool:
    return isinstance(traj, Trajectory) and all(np.all(np.isfinite(a)) for a in
                                                (traj.positions, traj.velocities, traj.accelerations))


def run_episode(scenario, seed: int | None = None, perception: str | PerceptionModule = "dodt",
                planner: str | Planner | None = None, out: Path | None = None, cfg: EpisodeConfig = EpisodeConfig(),
                renderer: str | None = None, on_frame=None, settings: Settings | None = None) -> dict:
    """Fly one episode; returns the summary (and writes summary.json and log.jsonl.gz to ``out``).

    scenario: a Scenario or a shipped scenario name / TOML path. perception: a mode name
    (dodt, oracle, static-only, any DODT preset), a plug-in's ``module:Class`` (experiments.plugins) or a
    PerceptionModule. planner: any object with ``reset()`` and ``plan(PlannerInput) -> Trajectory``, a
    plug-in's ``module:Class``, or None / "default": the maneuver + MPC planner behind the shield.
    settings: overrides by section (experiments.config.Settings; its episode section is applied to
    ``cfg``); the effective values of the overridden sections are recorded as the summary's ``config``.
    on_frame(view): optional callback per camera frame (live viewers); view is a dict with t, frame
    (SensorFrame), truth (GroundTruth), perception (PerceptionOutput), map (VoxelMap), trajectory
    (the current plan or None), T_world_body (4x4), path (the planner's global path or None).
    renderer: overrides ``cfg.renderer``. Frames carry colour only when the perception module reads it
    (its ``uses_color``) or ``on_frame`` is given.
    """
    sc = load_scenario(scenario) if isinstance(scenario, (str, Path)) else scenario
    seed = sc.seed if seed is None else int(seed)
    sc = sc.for_seed(seed)  # a scenario with ranges: this seed's draw
    settings = settings or Settings()
    cfg = settings.episode_config(cfg)
    perc = make_perception(perception, settings=settings) if isinstance(perception, str) else perception
    perception_label = perception if isinstance(perception, str) and is_spec(perception) else None
    planner_label = planner if isinstance(planner, str) and planner != DEFAULT_PLANNER else None
    planner = make_planner(planner) if isinstance(planner, str) else planner
    if cfg.static_map not in STATIC_MAPS:
        raise ValueError(f"static_map: {cfg.static_map!r} is not one of {', '.join(STATIC_MAPS)}")
    duration = sc.duration if cfg.duration is None else cfg.duration
    if not 0 < duration <= MAX_DURATION:  # (NaN too: it would run without a time limit)
        raise ValueError(f"duration: expected seconds > 0 and <= {MAX_DURATION:g}, got {duration!r}")
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
    # streamed to the file as the episode runs (a temporary one without ``out``); the metrics are read from it
    log = EpisodeLog(None if out is None else out / "log.jsonl.gz")
    t_wall = time.perf_counter()
    # images are needed by a depth-built map or by a perception module that looks at them (unknown ones do)
    render = cfg.static_map == "depth" or bool(getattr(perc, "uses_images", True))
    world = None
    color = sc.camera.color and (bool(getattr(perc, "uses_color", True)) or on_frame is not None)
    try:
        world = World(sc, seed=seed, renderer=renderer if renderer is not None else cfg.renderer,
                      segmentation=False, render=render, frame_latency=cfg.frame_latency, color=color,
                      render_process=cfg.render_process and render and cfg.frame_latency > 0)
        used = {"episode": cfg}
        if planner is None:
            planner = default_planner(world.vehicle.radius, settings)
            used.update(shield=planner.cfg, navigator=planner.planner.cfg)
        used.update(config_sections(perc))
        labels = {"perception": perception_label or getattr(perc, "name", type(perc).__name__),
                  "planner": planner_label or type(planner).__name__}
        summary = _loop(sc, seed, world, perc, planner, log, cfg, duration, on_frame, settings, used, labels)
    finally:
        if world is not None:
            world.close()
        log.close()
    wall = time.perf_counter() - t_wall
    summary["timing"]["wall_s"] = round(wall, 2)
    summary["timing"]["real_time_factor"] = round(summary["sim_time"] / wall, 3) if wall > 0 else None
    summary["timing"]["renderer"] = world.renderer
    # what computed it: outcomes agree bit for bit within one environment, not across them (the
    # renderer, not where it ran: a render process gives the same frames)
    summary["environment"] = {**environment(), "renderer": world.renderer.split(" (")[0]}
    if out is not None:
        (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return summary


def _loop(sc, seed, world: World, perc, planner, log: EpisodeLog, cfg: EpisodeConfig, duration, on_frame,
          settings: Settings, used: dict, labels: dict) -> dict:
    perc.reset()
    planner.reset()
    vmap = VoxelMap(settings.map_config(map_config_for(sc, world.vehicle.radius)))
    used["map"] = vmap.cfg
    config = settings.record(used) if settings else None
    known_map = cfg.static_map == "truth"
    if known_map:
        vmap.set_known(static_occupancy(sc, vmap.origin, vmap.dims, vmap.res))
    seen = SeenSpace(vmap.xy_origin, tuple(vmap.dims[:2]), vmap.res, band=cfg.seen_band)
    seen.reset(start_xy=np.asarray(sc.drone.start[:2], float), radius=cfg.launch_radius, stamp=0.0)
    seen_blocked = vmap.column_blocked(*cfg.seen_band, inflate=False) if known_map else None
    if hasattr(perc, "structure_test"):  # DODT's moving-track rule checks boxes against the static map
        perc.structure_test = vmap.established_fraction
    goal = np.asarray(sc.drone.goal, dtype=float)
    control_dt = world.dt * world.steps_per_control
    plan_every = max(1, int(round(1.0 / (cfg.plan_rate * control_dt))))
    log.add({"k": "header", "scenario": sc.name, "source": sc.source, "seed": seed, "perception": labels["perception"],
             "planner": labels["planner"], "duration": duration, "static_map": cfg.static_map,
             "frame_latency": cfg.frame_latency,
             "rates": {"control": 1.0 / control_dt, "camera": sc.rates.camera, "plan": cfg.plan_rate,
                       "map": sc.rates.camera / cfg.map_every},
             "corridor": {"length": sc.corridor.length, "width": sc.corridor.width, "height": sc.corridor.height},
             "start": list(sc.drone.start), "goal": goal.tolist(), "map_resolution": vmap.cfg.resolution,
             "map_origin": list(vmap.cfg.origin),
             "camera": {k: getattr(world.intrinsics, k) for k in ("width", "height", "fx", "fy", "cx", "cy")},
             "static": [o.to_json() for o in world.obstacle_truth() if o.kind == "static"],
             "people": [{"id": i, "height": round(w.height, 3), "sees_drone": bool(sees)}
                        for i, w, sees in zip(world.person_ids, world.walkers, world.crowd.sees)],
             **({"config": config} if config else {})})

    co = sc.corridor  # its walls are known: the planner keeps inside them (the map sees them only at a glance)
    geofence = (np.array([0.0, -co.width / 2]), np.array([co.length, co.width / 2]))
    obstacles, obstacles_stamp = (), 0.0
    traj: Trajectory | None = None
    yaw = float(sc.drone.yaw)
    accel_cmd = np.zeros(3)
    n_frames = 0
    next_snapshot = 0.0
    map_changes = MapChanges()
    n_collisions = 0
    reason, time_to_goal = "timeout", None
    frame, truth = world.latest_frame(), world.ground_truth()  # None until the first frame arrives (latency)
    k = 0
    while True:
        t = world.time
        if frame is not None:
            t0 = time.perf_counter()
            po = perc.update(frame, truth if getattr(perc, "uses_ground_truth", False) else None)
            perc_ms = (time.perf_counter() - t0) * 1e3
            if po.skipped is None:
                obstacles, obstacles_stamp = po.obstacles, po.stamp
            map_ms = None
            if not known_map and n_frames % cfg.map_every == 0:
                depth_m, _ = frame.depth_m_counted()
                m = vmap.update(depth_m, frame.intrinsics, frame.T_world_camera, dynamic_boxes=po.clear_boxes,
                                stamp=frame.stamp)
                seen.observe_depth(depth_m, frame.intrinsics, frame.T_world_camera, frame.stamp)
                map_ms = m.get("ms")
            elif known_map and n_frames % cfg.map_every == 0:
                seen.observe_map(seen_blocked, frame.intrinsics, frame.T_world_camera, frame.stamp,
                                 occluders=[(o.center, o.size) for o in po.obstacles])
            n_frames += 1
            q = truth.T_world_body  # the drone at the frame's capture, as its truth and tracks
            people = [o for o in truth.obstacles if o.kind == "person"]
            log.add({"k": "f", "t": round(frame.stamp, 4), "p": r4(q[:3, 3]), "R": r4(q[:3, :3]), "tracks": po.tracks,
                     "people": [{"id": o.id, "lo": r4(o.aabb_min), "hi": r4(o.aabb_max), "v": r4(o.velocity[:2])}
                                for o in people],
                     "perc_ms": round(perc_ms, 3), "map_ms": None if map_ms is None else round(map_ms, 3),
                     "skipped": po.skipped})
            if t >= next_snapshot:
                idx = vmap.occupied_indices()
                above_floor = idx[:, 2] * vmap.cfg.resolution + vmap.cfg.origin[2] >= 0.1
                log.add(map_changes.record(round(t, 4), idx[above_floor]))
                next_snapshot = math.inf if known_map else t + cfg.map_snapshot_period  # a known map never changes
            if on_frame is not None:
                on_frame({"t": frame.stamp, "frame": frame, "truth": truth, "perception": po, "map": vmap, "trajectory": traj,
                          "T_world_body": q, "path": getattr(planner, "path", None)})

        st = world.state()
        if not (np.all(np.isfinite(st.position)) and st.position[2] > CRASH_ALTITUDE or t < 0.5):
            reason = "crashed"
            break
        if np.linalg.norm(st.position - goal) < GOAL_TOLERANCE:
            reason, time_to_goal = "goal", t
            break
        if t >= duration - 1e-9:
            break

        if k % plan_every == 0:
            inp = PlannerInput(stamp=t, position=st.position.copy(), velocity=st.velocity.copy(),
                               acceleration=accel_cmd.copy(), goal=goal,
                               obstacles=_extrapolate(obstacles, obstacles_stamp, t), occupancy=vmap,
                               yaw=st.yaw, geofence=geofence, seen=seen)
            try:
                traj = planner.plan(inp)
                if not _finite_trajectory(traj):
                    raise ValueError("planner returned a non-finite trajectory")
            except Exception as e:  # noqa: BLE001 - the loop must go on: brake and hold instead
                traj = brake_and_hold(t, st.position, st.velocity, a_max=planner_accel_limit(planner),
                                      status=f"error:{type(e).__name__}")
            log.add({"k": "plan", "t": round(t, 4), "status": traj.status, "ms": round(traj.solve_ms, 3),
                     "pos": np.round(traj.positions[::2], 3).tolist(),
                     "path": None if getattr(planner, "path", None) is None else np.round(planner.path, 2).tolist(),
                     "n_obst": len(inp.obstacles),
                     **_threats(planner)})

        p_ref, v_ref, a_ref = traj.sample(t)
        accel_cmd = a_ref
        want = traj.yaw
        if want is None:
            d = traj.sample(t + 1.0)[0][:2] - st.position[:2]
            want = math.atan2(d[1], d[0]) if np.hypot(*d) > 0.3 else yaw
        err = wrap_angle(want - yaw)
        step = cfg.max_yaw_rate * control_dt
        yaw_rate = float(np.clip(err, -step, step)) / control_dt
        yaw = yaw + yaw_rate * control_dt
        ref = Reference(position=p_ref, velocity=v_ref, acceleration=a_ref, yaw=yaw, yaw_rate=yaw_rate)

        frame = world.step(ref)
        truth = world.ground_truth() if frame is not None else truth
        k += 1
        cl = world.clearance_log[-1]
        after = world.state()
        log.add({"k": "s", "t": round(world.time, 5), "p": r4(after.position), "v": r4(after.velocity),
                 "r": r4(p_ref), "c": [round(min(x, 9.0), 4) for x in cl[1:]]})
        for ev in world.collisions[n_collisions:]:
            log.add({"k": "collision", "t": round(ev.time, 5), "kind": ev.other_kind, "other_id": ev.other_id,
                     "position": r4(ev.position), "v": r4(ev.drone_velocity),
                     "point": None if ev.contact_point is None else r4(ev.contact_point),
                     "other_v": r4(ev.other_velocity)})
        n_collisions = len(world.collisions)

    log.add({"k": "end", "t": round(world.time, 5), "reason": reason, "reached_goal": reason == "goal",
             "time_to_goal": None if time_to_goal is None else round(time_to_goal, 5)})
    summary = log.summarize()
    summary["map_voxels_occupied"] = int(vmap.occupied_count())
    if config:
        summary["config"] = config
    return summary


def planner_accel_limit(planner) -> float:
    """The deceleration of the brake-and-hold fallback: the planner's own limit if it has one."""
    cfg = getattr(getattr(planner, "mpc", None), "cfg", None)
    return float(getattr(cfg, "a_max_xy", 2.0))
