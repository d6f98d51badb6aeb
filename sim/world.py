"""The simulated world: corridor, obstacles, walking people, a quadrotor with an RGB-D camera.

Usage::

    world = World(load_scenario("corridor"), seed=3)
    while world.time < 5.0:
        frame = world.step(Reference.hover([1.0, 0.0, 1.2]))  # one control period
        if frame is not None:
            truth = world.ground_truth()  # truth of that same frame

Two PyBullet clients are used. The main one steps the physics (240 Hz: the drone's rotor
forces, contacts with the static world) and renders the camera. People are posed there
kinematically as massless, non-colliding bodies (so they cost nothing in the solver); a
second, never-stepped client holds collidable copies of the people and of the drone, and
answers the drone-person distance and collision queries at every physics step.
"""
from __future__ import annotations

import math
import time
import warnings
import weakref
from collections import deque
from dataclasses import dataclass

import numpy as np
import pybullet_data

from sim.camera import quiet_stdout

with quiet_stdout():  # PyBullet prints its build time on import
    import pybullet as p

from dodt.frames import CameraIntrinsics, SensorFrame
from sim.camera import decode_render, load_egl, render_buffers, renderer_name
from sim.controller import CascadedController, DroneState, Reference
from sim.crowd import Crowd
from sim.depth_noise import DepthNoiseModel
from sim.ground_truth import STRUCTURE_ID, CollisionEvent, GroundTruth, ObstacleTruth
from sim.people import HUMANOID_URDF, Walker, person_height, plan_path
from sim.scenario import Obstacle, Scenario
from sim.vehicle import GRAVITY, QUADROTOR_URDF, load_vehicle

_GROUP_DRONE, _GROUP_STATIC = 1, 4
_egl_owner = None  # weakref to the one World that renders with EGL (see reset)
CLEARANCE_CAP = 1.0  # m: clearances are exact below this, reported as this value above
CLEARANCE_LOG_LEN = 4096  # control periods of clearance history kept (34 s at 120 Hz)
_PERSON_REACH = 0.6  # bounding-sphere radius of a person around the root, per metre of height


def _rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    return np.array(p.getMatrixFromQuaternion(p.getQuaternionFromEuler([roll, pitch, yaw]))).reshape(3, 3)


def _quat_from_matrix(R: np.ndarray) -> list[float]:
    """Rotation matrix -> PyBullet quaternion (x, y, z, w)."""
    w = math.sqrt(max(0.0, 1.0 + R[0, 0] + R[1, 1] + R[2, 2])) / 2
    x = math.copysign(math.sqrt(max(0.0, 1.0 + R[0, 0] - R[1, 1] - R[2, 2])) / 2, R[2, 1] - R[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1.0 - R[0, 0] + R[1, 1] - R[2, 2])) / 2, R[0, 2] - R[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1.0 - R[0, 0] - R[1, 1] + R[2, 2])) / 2, R[1, 0] - R[0, 1])
    return [x, y, z, w]


@dataclass
class _StaticBody:
    uid: int
    obstacle_id: int  # STRUCTURE_ID for floor/walls/ceiling
    aabb_min: np.ndarray
    aabb_max: np.ndarray


@dataclass
class _Capture:
    """A frame captured and not yet delivered (World.frame_latency)."""
    seq: int
    stamp: float
    images: tuple | None  # (depth mm, colour, segmentation); None: still with the render process
    T_odom: np.ndarray  # the pose the frame carries (odometry)
    T_true: np.ndarray  # the camera's true pose
    T_body: np.ndarray  # the drone's true pose
    state: DroneState
    obstacles: tuple[ObstacleTruth, ...]


class World:
    """Build from a scenario and a seed; ``step`` with references; read frames and truth."""

    def __init__(self, scenario: Scenario, seed: int | None = None, renderer: str | None = None,
                 segmentation: bool | None = None, camera: bool = True,
                 light_direction: tuple[float, float, float] | None = None, render: bool = True,
                 frame_latency: int = 0, render_process: bool = False, color: bool | None = None):
        """camera=False skips rendering (frames and truth stay at their initial values); for
        control and planning experiments that need no images. render=False keeps the camera's
        clock but draws nothing: every camera period still gives a frame (pose, intrinsics, stamp,
        with a depth image of no returns and no colour) and its ground truth (segmentation None),
        for planning against ground-truth perception at a fraction of the cost (an oracle episode of
        corridor.toml ran 7.5 times faster: 1.8 s against 13.6 s). light_direction (world frame,
        settable between frames as ``world.light_direction``) is passed to the renderer; None
        keeps PyBullet's default light.

        frame_latency: camera periods between a frame's capture and its delivery (``step``
        returns it, ``latest_frame`` holds it; its stamp, pose and truth stay those of the
        capture). 0: delivered at once. render_process (needs frame_latency >= 1 and render):
        render in a second process (sim.render_process) while this one goes on; frames and
        truth are bit-identical to rendering here with the same latency.

        renderer: "auto" (default: the scenario's), "gl", "pybullet" ("egl") or "tiny" (sim.camera).
        color: whether frames carry a colour image (default: the scenario's ``camera.color``); without
        one the gl renderer draws depth only."""
        if int(frame_latency) != frame_latency or frame_latency < 0:
            raise ValueError(f"frame_latency: must be a whole number of camera periods >= 0, got {frame_latency!r}")
        if render_process and not (render and camera and frame_latency >= 1):
            raise ValueError("render_process: needs render=True, camera=True and frame_latency >= 1 (the render "
                             "of one frame overlaps the processing of the frame before it)")
        self.frame_latency = int(frame_latency)
        self.render_process = bool(render_process)
        self._render_proc = None
        self._gl = None  # sim.gl_renderer.GLRenderer when renderer is "gl"
        self.light_direction = light_direction
        self.camera_on = camera
        self.render_on = bool(render)
        self.seed = scenario.seed if seed is None else int(seed)
        self._template = scenario  # a scenario with ranges is drawn anew for every seed (Scenario.for_seed)
        self.scenario = scenario = scenario.for_seed(self.seed)
        self.requested_renderer = renderer_name(renderer or scenario.camera.renderer)
        self.color_on = scenario.camera.color if color is None else bool(color)
        self.segmentation_on = scenario.segmentation if segmentation is None else segmentation
        self.vehicle = load_vehicle()
        cam = scenario.camera
        self.intrinsics = CameraIntrinsics(cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy)
        self._no_returns = None if self.render_on else np.zeros((cam.height, cam.width), np.uint16)
        if self._no_returns is not None:
            self._no_returns.flags.writeable = False  # one shared image for every frame: read-only
        R_mount = _rpy_matrix(*cam.mount_rpy)
        # Body FLU -> optical (x right, y down, z forward) for a forward-looking camera.
        R_flu_optical = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
        self.T_body_camera = np.eye(4)
        self.T_body_camera[:3, :3] = R_mount @ R_flu_optical
        self.T_body_camera[:3, 3] = cam.mount_xyz
        r = scenario.rates
        self.dt = 1.0 / r.physics
        self.steps_per_control = r.physics // r.control
        self.steps_per_frame = r.physics // r.camera
        self._client = self._query_client = None
        try:
            self.reset()
        except BaseException:  # a world that fails to build closes what it started (the render process)
            self.close()
            raise

    # ------------------------------------------------------------------ building

    def reset(self, seed: int | None = None) -> SensorFrame:
        """Rebuild the world from scratch (bit-identical for the same scenario and seed)."""
        if seed is not None:
            self.seed = int(seed)
            self.scenario = self._template.for_seed(self.seed)
        self.close()
        ss = np.random.SeedSequence(self.seed)
        rng_paths, rng_looks, self._rng_noise, self._rng_odom = (np.random.default_rng(s) for s in ss.spawn(4))
        sc = self.scenario

        with quiet_stdout():
            self._client = p.connect(p.DIRECT)
            self._query_client = p.connect(p.DIRECT)
        c = self._client
        self.renderer = "tiny" if self.render_on else "none"
        want = self.requested_renderer
        use_gl = False
        if self.render_process:
            from sim.render_process import RenderProcess

            self._render_proc = RenderProcess(sc, self.seed, want, self.segmentation_on, self.light_direction,
                                              self.color_on)
            self.renderer = f"{self._render_proc.renderer} (render process)"
        elif self.render_on and want in ("auto", "gl"):
            from sim.gl_renderer import GLUnavailable, shared_context

            try:
                shared_context()  # made once per process, before any body: PyBullet's EGL plugin is the fallback
                use_gl = True
            except GLUnavailable as e:
                if want == "gl":
                    raise RuntimeError(f"renderer 'gl' requested but {e}; use renderer = 'auto', 'pybullet' or "
                                       f"'tiny'") from None
        if not use_gl and not self.render_process and self.render_on and want in ("auto", "pybullet"):
            global _egl_owner
            other = _egl_owner() if _egl_owner is not None else None
            if other is not None and other is not self:
                # PyBullet's EGL plugin keeps global state: with two EGL clients in a process,
                # closing one crashes the other (measured). One World at a time gets EGL.
                if want == "pybullet":
                    raise RuntimeError("another World in this process already renders with PyBullet's EGL plugin; "
                                       "close it first (world.close() or a with-block) or use renderer='gl' or "
                                       "'tiny'")
                warnings.warn("another World in this process renders with EGL: this one uses TinyRenderer "
                              "(close the other World first to get EGL)", stacklevel=2)
            elif load_egl(p, c):
                self.renderer = "pybullet"
                _egl_owner = weakref.ref(self)
            elif want == "pybullet":
                raise RuntimeError("renderer 'pybullet' requested but PyBullet's EGL plugin did not load "
                                   "(is Mesa's libEGL installed?); use renderer = 'auto' or 'tiny'")
        p.setAdditionalSearchPath(pybullet_data.getDataPath(), physicsClientId=c)
        p.setAdditionalSearchPath(pybullet_data.getDataPath(), physicsClientId=self._query_client)
        p.setPhysicsEngineParameter(fixedTimeStep=self.dt, numSubSteps=0, deterministicOverlappingPairs=1,
                                    physicsClientId=c)
        p.setGravity(0, 0, -GRAVITY, physicsClientId=c)

        self.static_bodies: list[_StaticBody] = []
        self._build_corridor(rng_looks)
        for i, o in enumerate(sc.obstacles):
            self._build_obstacle(o, i + 1, rng_looks)
        horizon = sc.duration + 5.0
        self.walkers: list[Walker] = []
        self.person_ids: list[int] = []
        for i, person in enumerate(sc.people):
            w = Walker(plan_path(person, sc, rng_paths, horizon), person_height(person, rng_looks))
            self._build_person(w, person, rng_looks)
            self.walkers.append(w)
            self.person_ids.append(len(sc.obstacles) + 1 + i)
        h = self.vehicle.collision_size / 2
        self.crowd = Crowd(self.walkers, sc, drone_radius=float(math.hypot(h[0], h[1])))
        self._build_drone()
        if use_gl:
            self._make_gl_renderer(want)

        # Segmentation: PyBullet body uid -> obstacle id.
        n = max([b.uid for b in self.static_bodies] + [c for w in self.walkers for _, c in w.bodies[:1]]
                + [self.drone]) + 2
        self._seg_lut = np.full(n, -1, dtype=np.int32)
        for b in self.static_bodies:
            self._seg_lut[b.uid + 1] = b.obstacle_id
        for w, oid in zip(self.walkers, self.person_ids):
            self._seg_lut[w.bodies[0][1] + 1] = oid

        self.controller = CascadedController(self.vehicle)
        self._noise_model = DepthNoiseModel(sc.noise, sc.camera.fx)
        self.time = 0.0
        self.step_count = 0
        self.collisions: list[CollisionEvent] = []
        self._in_contact: set[int] = set()
        self.min_clearance = {"static": CLEARANCE_CAP, "person": CLEARANCE_CAP, "structure": CLEARANCE_CAP}
        # t, static, person, structure of the last CLEARANCE_LOG_LEN control periods (bounded: an episode of an
        # hour keeps its whole history in its log file, not in memory)
        self.clearance_log: deque[tuple[float, float, float, float]] = deque(maxlen=CLEARANCE_LOG_LEN)
        self._frame: SensorFrame | None = None
        self._render_wall_time = 0.0  # s spent inside the renderer (for benchmarks)
        self._truth: GroundTruth | None = None
        self._pending: list[_Capture] = []  # captured frames not yet delivered (frame_latency)
        self.last_images = None  # (depth mm, colour, segmentation) of the last frame rendered in this process
        self._last_reference: Reference | None = None
        self._camera_path = self._make_camera_path()
        self._rotor_speed = np.full(4, math.sqrt(self.vehicle.mass * GRAVITY / (4 * self.vehicle.kf)))
        self._thrust_cmd = np.full(4, self.vehicle.mass * GRAVITY / 4)
        self._rotor_pos = [r.tolist() for r in self.vehicle.rotor_positions]
        self._yaw_row = self.vehicle.allocation[3]
        self._corners = self.vehicle.corners
        obstacles = [b for b in self.static_bodies if b.obstacle_id != STRUCTURE_ID]
        self._obstacle_uids = [b.uid for b in obstacles]
        self._obstacle_lo = np.array([b.aabb_min for b in obstacles]).reshape(-1, 3)
        self._obstacle_hi = np.array([b.aabb_max for b in obstacles]).reshape(-1, 3)
        self._person_clearance = CLEARANCE_CAP
        if self._camera_path is not None:
            pos, vel, yaw = self._camera_path(0.0)
            self._set_body_pose(pos, vel, yaw)
        self._pose_people()
        p.performCollisionDetection(physicsClientId=self._client)
        self._update_clearance()
        self._check_contacts()
        self._capture()
        return self._frame

    def _make_gl_renderer(self, want: str) -> None:
        """Our OpenGL renderer over the bodies just built (sim.gl_renderer)."""
        from sim.gl_renderer import GLRenderer, GLUnsupportedScene

        try:
            self._gl = GLRenderer(p, self._client, self.intrinsics)
        except GLUnsupportedScene as e:
            if want == "gl":
                raise RuntimeError(f"renderer 'gl': {e}") from None
            warnings.warn(f"the gl renderer cannot draw this scene ({e}): using TinyRenderer", stacklevel=3)
            return
        self.renderer = "gl"

    def close(self) -> None:
        global _egl_owner
        if _egl_owner is not None and _egl_owner() is self:
            _egl_owner = None
        gl = getattr(self, "_gl", None)
        if gl is not None:
            gl.release()
            self._gl = None
        for cid in (self._client, self._query_client):
            if cid is not None:
                try:
                    with quiet_stdout():
                        p.disconnect(physicsClientId=cid)
                except p.error:
                    pass
        self._client = self._query_client = None
        if self._render_proc is not None:
            self._render_proc.close()
            self._render_proc = None

    @property
    def render_wall_time(self) -> float:
        """Seconds spent inside the renderer (benchmarks only), in this process or the render process."""
        rp = self._render_proc
        return self._render_wall_time + (rp.render_wall_time if rp is not None else 0.0)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass

    def _add_static(self, shapes, obstacle_id: int, color, base_pos, base_yaw: float = 0.0) -> _StaticBody:
        """shapes: list of (geom, dims, local offset) -> one static body in the main client."""
        c = self._client
        geoms, dims_he, dims_r, dims_l, offsets = [], [], [], [], []
        for geom, dims, off in shapes:
            geoms.append(geom)
            offsets.append(off)
            if geom == p.GEOM_BOX:
                dims_he.append(dims)
                dims_r.append(0.0)
                dims_l.append(0.0)
            else:
                dims_he.append([0, 0, 0])
                dims_r.append(dims[0])
                dims_l.append(dims[1])
        kw = dict(shapeTypes=geoms, halfExtents=dims_he, radii=dims_r, lengths=dims_l,
                  collisionFramePositions=offsets, physicsClientId=c) if len(shapes) > 1 else None
        if kw:
            col = p.createCollisionShapeArray(**kw)
            vkw = dict(kw)
            vkw["visualFramePositions"] = vkw.pop("collisionFramePositions")
            vis = p.createVisualShapeArray(rgbaColors=[list(color) + [1.0]] * len(shapes), **vkw)
        else:
            geom, dims, off = shapes[0]
            if geom == p.GEOM_BOX:
                col = p.createCollisionShape(geom, halfExtents=dims, collisionFramePosition=off, physicsClientId=c)
                vis = p.createVisualShape(geom, halfExtents=dims, visualFramePosition=off,
                                          rgbaColor=list(color) + [1.0], physicsClientId=c)
            else:
                col = p.createCollisionShape(geom, radius=dims[0], height=dims[1], collisionFramePosition=off,
                                             physicsClientId=c)
                vis = p.createVisualShape(geom, radius=dims[0], length=dims[1], visualFramePosition=off,
                                          rgbaColor=list(color) + [1.0], physicsClientId=c)
        uid = p.createMultiBody(0, col, vis, basePosition=base_pos,
                                baseOrientation=p.getQuaternionFromEuler([0, 0, base_yaw]), physicsClientId=c)
        p.setCollisionFilterGroupMask(uid, -1, _GROUP_STATIC, _GROUP_DRONE, physicsClientId=c)
        lo, hi = p.getAABB(uid, physicsClientId=c)
        body = _StaticBody(uid, obstacle_id, np.array(lo), np.array(hi))
        self.static_bodies.append(body)
        return body

    def _build_corridor(self, rng) -> None:
        co = self.scenario.corridor
        L, W, H, t = co.length, co.width, co.height, 0.1
        floor = (0.55, 0.55, 0.55) if co.floor_color is None else tuple(co.floor_color)
        wall = tuple(np.clip(np.array([0.85, 0.82, 0.75]) + rng.uniform(-0.05, 0.05, 3), 0, 1))  # always drawn
        if co.wall_color is not None:
            wall = tuple(co.wall_color)
        box = p.GEOM_BOX
        self._add_static([(box, [L / 2 + t, W / 2 + t, t / 2], [0, 0, 0])], STRUCTURE_ID, floor, [L / 2, 0, -t / 2])
        for side in (-1, 1):
            self._add_static([(box, [L / 2 + t, t / 2, H / 2], [0, 0, 0])], STRUCTURE_ID, wall,
                             [L / 2, side * (W / 2 + t / 2), H / 2])
        for x in (-t / 2, L + t / 2):
            self._add_static([(box, [t / 2, W / 2, H / 2], [0, 0, 0])], STRUCTURE_ID, wall, [x, 0, H / 2])
        if co.ceiling:
            self._add_static([(box, [L / 2 + t, W / 2 + t, t / 2], [0, 0, 0])], STRUCTURE_ID, floor,
                             [L / 2, 0, H + t / 2])

    def _build_obstacle(self, o: Obstacle, oid: int, rng) -> None:
        color = o.color if o.color is not None else tuple(rng.uniform(0.15, 0.9, 3))
        sx, sy, sz = o.size
        base = [o.center[0], o.center[1], 0.0]
        if o.kind == "pillar":
            shapes = [(p.GEOM_CYLINDER, [sx / 2, sz], [0, 0, sz / 2])]
        elif o.kind == "shelf":
            post, board = 0.03, 0.025
            shapes = [(p.GEOM_BOX, [post, post, sz / 2], [dx * (sx / 2 - post), dy * (sy / 2 - post), sz / 2])
                      for dx in (-1, 1) for dy in (-1, 1)]
            for k in range(4):
                z = board + k * (sz - 2 * board) / 3
                shapes.append((p.GEOM_BOX, [sx / 2, sy / 2, board], [0, 0, z]))
        else:  # box, wall
            shapes = [(p.GEOM_BOX, [sx / 2, sy / 2, sz / 2], [0, 0, sz / 2])]
        self._add_static(shapes, oid, color, base, o.yaw)

    def _build_person(self, w: Walker, person, rng) -> None:
        shirt = person.color if person.color is not None else tuple(rng.uniform(0.05, 0.95, 3))
        trousers = tuple(rng.uniform(0.05, 0.6, 3))
        skin = tuple(np.array([0.93, 0.75, 0.6]) * rng.uniform(0.45, 1.0))
        part_color = {0: trousers, 1: shirt, 2: skin, 3: shirt, 4: shirt, 5: skin, 6: shirt, 7: shirt, 8: skin,
                      9: trousers, 10: trousers, 11: (0.1, 0.1, 0.1), 12: trousers, 13: trousers, 14: (0.1, 0.1, 0.1)}
        for cid in (self._client, self._query_client):
            with quiet_stdout():
                body = p.loadURDF(HUMANOID_URDF, [0, 0, 0], globalScaling=w.global_scaling, useFixedBase=True,
                                  physicsClientId=cid)
            n = p.getNumJoints(body, physicsClientId=cid)
            if cid == self._client:
                for link in range(-1, n):
                    p.setCollisionFilterGroupMask(body, link, 0, 0, physicsClientId=cid)
                    p.changeDynamics(body, link, mass=0.0, physicsClientId=cid)
                    p.changeVisualShape(body, link, rgbaColor=list(part_color.get(link, shirt)) + [1.0],
                                        physicsClientId=cid)
            w.bodies.append((cid, body))

    def _build_drone(self) -> None:
        sc = self.scenario
        quat = p.getQuaternionFromEuler([0, 0, sc.drone.yaw])
        self.drone = p.loadURDF(str(QUADROTOR_URDF), sc.drone.start, quat, flags=p.URDF_USE_INERTIA_FROM_FILE,
                                physicsClientId=self._client)
        p.changeDynamics(self.drone, -1, linearDamping=0.0, angularDamping=0.0, physicsClientId=self._client)
        p.setCollisionFilterGroupMask(self.drone, -1, _GROUP_DRONE, _GROUP_STATIC, physicsClientId=self._client)
        self._drone_proxy = p.loadURDF(str(QUADROTOR_URDF), sc.drone.start, quat, useFixedBase=True,
                                       physicsClientId=self._query_client)

    # ------------------------------------------------------------------ scripted camera paths

    def _make_camera_path(self):
        cp = self.scenario.camera_path
        if cp is None:
            return None
        if cp.keyframes:
            kf = np.array(cp.keyframes)
            t_k = kf[:, 0]
            yaw_k = np.unwrap(kf[:, 4])

            def at(t):
                pos = np.array([np.interp(t, t_k, kf[:, i]) for i in (1, 2, 3)])
                if len(t_k) > 1 and t_k[0] <= t < t_k[-1]:
                    i = int(np.searchsorted(t_k, t, side="right")) - 1
                    vel = (kf[i + 1, 1:4] - kf[i, 1:4]) / (t_k[i + 1] - t_k[i])
                else:
                    vel = np.zeros(3)
                return pos, vel, float(np.interp(t, t_k, yaw_k))
            return at

        i = cp.follow_person
        path = self.walkers[i].path
        crowd = self.crowd  # not self: a closure over the World would keep it (and its EGL context) alive

        def follow(t):
            # Walk the person's route, follow_distance behind the point the person has reached, looking at
            # the person (as the crowd has moved it, at the latest control period).
            s = crowd.progress[i]
            xy = path.trail_point(s - cp.follow_distance)
            target = crowd.pos[i]
            v = crowd.vel[i]
            d = target - xy
            yaw = math.atan2(d[1], d[0])
            return np.array([xy[0], xy[1], cp.follow_height]), np.array([v[0], v[1], 0.0]), yaw
        return follow

    # ------------------------------------------------------------------ state

    def state(self) -> DroneState:
        c = self._client
        pos, quat = p.getBasePositionAndOrientation(self.drone, physicsClientId=c)
        lin, ang = p.getBaseVelocity(self.drone, physicsClientId=c)
        R = np.array(p.getMatrixFromQuaternion(quat)).reshape(3, 3)
        return DroneState(position=np.array(pos), velocity=np.array(lin), R=R, omega=R.T @ np.array(ang))

    def T_world_body(self) -> np.ndarray:
        return self._T_from_pose(*self._drone_pose())

    @staticmethod
    def _T_from_pose(pos, quat) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = np.array(p.getMatrixFromQuaternion(quat)).reshape(3, 3)
        T[:3, 3] = pos
        return T

    def _set_body_pose(self, pos, vel, yaw) -> None:
        p.resetBasePositionAndOrientation(self.drone, list(pos), p.getQuaternionFromEuler([0, 0, yaw]),
                                          physicsClientId=self._client)
        p.resetBaseVelocity(self.drone, list(vel), [0, 0, 0], physicsClientId=self._client)

    def reference_for(self, t: float) -> Reference | None:
        """The scripted path as a reference (flown camera paths)."""
        if self._camera_path is None:
            return None
        pos, vel, yaw = self._camera_path(t)
        return Reference(position=pos, velocity=vel, yaw=yaw)

    # ------------------------------------------------------------------ stepping

    def step(self, reference: Reference | None = None) -> SensorFrame | None:
        """Advance one control period. Returns the sensor frame captured in it, if any.

        ``reference`` defaults to the scenario's scripted camera path, else the last
        reference, else hovering at the start. Carried camera paths ignore it.
        """
        cp = self.scenario.camera_path
        carried = cp is not None and cp.mode == "carried"
        if not carried:
            if reference is None:
                reference = self.reference_for(self.time) or self._last_reference or Reference.hover(
                    self.scenario.drone.start, self.scenario.drone.yaw)
            self._last_reference = reference
            self._thrust_cmd = self.controller(self.state(), reference, self.dt * self.steps_per_control)
        new_frame = None
        for _ in range(self.steps_per_control):
            if carried:
                self._carried_step()
            else:
                self._physics_step()
            if self.camera_on and self.step_count % self.steps_per_frame == 0:
                new_frame = self._capture() or new_frame
        return new_frame

    def advance(self, duration: float, reference: Reference | None = None) -> list[SensorFrame]:
        """Step for ``duration`` seconds with a fixed reference; return the frames captured."""
        frames = []
        n = int(round(duration / (self.dt * self.steps_per_control)))
        for _ in range(n):
            f = self.step(reference)
            if f is not None:
                frames.append(f)
        return frames

    def _rotor_update(self) -> np.ndarray:
        """First-order rotor speed response to the commanded thrusts; returns actual thrusts."""
        v = self.vehicle
        cmd = np.sqrt(np.clip(self._thrust_cmd, 0.0, v.max_rotor_thrust) / v.kf)
        tau = np.where(cmd > self._rotor_speed, v.tau_up, v.tau_down)
        self._rotor_speed = cmd + (self._rotor_speed - cmd) * np.exp(-self.dt / tau)
        return v.kf * self._rotor_speed**2

    def _physics_step(self) -> None:
        c, v = self._client, self.vehicle
        thrusts = self._rotor_update()
        pos, quat = p.getBasePositionAndOrientation(self.drone, physicsClientId=c)
        lin, _ = p.getBaseVelocity(self.drone, physicsClientId=c)
        R = np.array(p.getMatrixFromQuaternion(quat)).reshape(3, 3)
        for i in range(4):
            p.applyExternalForce(self.drone, -1, [0.0, 0.0, float(thrusts[i])], self._rotor_pos[i],
                                 p.LINK_FRAME, physicsClientId=c)
        yaw_moment = float(self._yaw_row @ thrusts)
        drag = -(R @ (v.drag * (R.T @ np.array(lin))))
        p.applyExternalTorque(self.drone, -1, (R[:, 2] * yaw_moment).tolist(), p.WORLD_FRAME, physicsClientId=c)
        p.applyExternalForce(self.drone, -1, drag.tolist(), list(pos), p.WORLD_FRAME, physicsClientId=c)
        p.stepSimulation(physicsClientId=c)
        self._after_step()

    def _carried_step(self) -> None:
        pos, vel, yaw = self._camera_path((self.step_count + 1) * self.dt)
        self._set_body_pose(pos, vel, yaw)
        p.performCollisionDetection(physicsClientId=self._client)
        self._after_step()

    def _after_step(self) -> None:
        """Advance the clock; pose people and measure clearance at the control rate; check
        contacts at every physics step."""
        self.step_count += 1
        self.time = self.step_count * self.dt
        if self.step_count % self.steps_per_control == 0:
            if len(self.crowd):
                pos, _ = self._drone_pose()
                lin, _ = p.getBaseVelocity(self.drone, physicsClientId=self._client)
                self.crowd.step(self.time, self.dt * self.steps_per_control, pos[:2], lin[:2])
                self._pose_people()
            self._update_clearance()
        self._check_contacts()

    # ------------------------------------------------------------------ collisions

    def _drone_pose(self):
        pos, quat = p.getBasePositionAndOrientation(self.drone, physicsClientId=self._client)
        return pos, quat

    def _check_contacts(self) -> None:
        """Collision events: static world from the physics contacts, people from the query
        client whenever the drone is close to one. Each event keeps the drone's velocity, the
        point of the other body nearest the drone and that body's velocity (experiments.fault)."""
        points: dict[int, tuple] = {}
        for cp_ in p.getContactPoints(bodyA=self.drone, physicsClientId=self._client):
            points.setdefault(cp_[2], cp_[6])  # positionOnB
        if self._person_clearance < 0.3:
            pos, quat = self._drone_pose()
            p.resetBasePositionAndOrientation(self._drone_proxy, pos, quat, physicsClientId=self._query_client)
            for w, oid in zip(self.walkers, self.person_ids):
                hits = p.getClosestPoints(self._drone_proxy, w.bodies[1][1], 0.0, physicsClientId=self._query_client)
                if hits:
                    points[-oid] = min(hits, key=lambda h: h[8])[6]  # negative: person ids, apart from uids
        touching = set(points)
        new = touching - self._in_contact
        if new:
            pos = tuple(self._drone_pose()[0])
            lin, _ = p.getBaseVelocity(self.drone, physicsClientId=self._client)
            for uid in sorted(new):
                other_v = (0.0, 0.0, 0.0)
                if uid < 0:
                    oid, kind = -uid, "person"
                    other_v = tuple(self.crowd.velocity3(self.person_ids.index(oid)))
                else:
                    oid = int(self._seg_lut[uid + 1]) if uid + 1 < len(self._seg_lut) else STRUCTURE_ID
                    kind = "structure" if oid == STRUCTURE_ID else "static"
                self.collisions.append(CollisionEvent(self.time, oid, kind, pos, tuple(lin),
                                                      tuple(points[uid]), other_v))
        self._in_contact = touching

    def _update_clearance(self) -> None:
        """Distance from the drone's collision box to the structure (exact, box against the
        corridor's planes), to static obstacles and to people (PyBullet closest points, exact
        below CLEARANCE_CAP)."""
        c, q = self._client, self._query_client
        pos, quat = self._drone_pose()
        pos_a = np.array(pos)
        R = np.array(p.getMatrixFromQuaternion(quat)).reshape(3, 3)
        corners = self._corners @ R.T + pos_a
        co = self.scenario.corridor
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        gaps = [lo[2], co.width / 2 - hi[1], co.width / 2 + lo[1], lo[0], co.length - hi[0]]
        if co.ceiling:
            gaps.append(co.height - hi[2])
        clear = {"structure": min(max(min(gaps), 0.0), CLEARANCE_CAP), "static": CLEARANCE_CAP,
                 "person": CLEARANCE_CAP}
        if self._obstacle_uids:
            gap = np.linalg.norm(np.maximum(0.0, np.maximum(self._obstacle_lo - hi, lo - self._obstacle_hi)), axis=1)
            for k in np.flatnonzero(gap < CLEARANCE_CAP):
                pts = p.getClosestPoints(self.drone, self._obstacle_uids[k], CLEARANCE_CAP, physicsClientId=c)
                if pts:
                    clear["static"] = min(clear["static"], max(min(x[8] for x in pts), 0.0))
        proxy_posed = False
        reach = self.vehicle.radius + CLEARANCE_CAP
        for i, w in enumerate(self.walkers):
            root = self.crowd.pos[i]
            if math.hypot(root[0] - pos[0], root[1] - pos[1]) - _PERSON_REACH * w.height > reach:
                continue
            if not proxy_posed:
                p.resetBasePositionAndOrientation(self._drone_proxy, pos, quat, physicsClientId=q)
                proxy_posed = True
            pts = p.getClosestPoints(self._drone_proxy, w.bodies[1][1], CLEARANCE_CAP, physicsClientId=q)
            if pts:
                clear["person"] = min(clear["person"], max(min(x[8] for x in pts), 0.0))
        self._person_clearance = clear["person"]
        for k, d in clear.items():
            self.min_clearance[k] = min(self.min_clearance[k], d)
        self.clearance_log.append((self.time, clear["static"], clear["person"], clear["structure"]))

    @property
    def collided(self) -> bool:
        return bool(self.collisions)

    # ------------------------------------------------------------------ camera

    def _odometry(self, T_true: np.ndarray) -> np.ndarray:
        nz = self.scenario.noise
        if not nz.enabled or (nz.odom_position_std == 0 and nz.odom_rotation_std == 0):
            return T_true.copy()
        T = T_true.copy()
        T[:3, 3] += self._rng_odom.normal(0.0, nz.odom_position_std, 3)
        rv = self._rng_odom.normal(0.0, nz.odom_rotation_std, 3)
        angle = float(np.linalg.norm(rv))
        if angle > 0:
            k = rv / angle
            Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
            T[:3, :3] = (np.eye(3) + math.sin(angle) * Kx + (1 - math.cos(angle)) * Kx @ Kx) @ T[:3, :3]
        return T

    def _render_buffers(self, T_true: np.ndarray):
        t0 = time.perf_counter()  # benchmark bookkeeping only: no result depends on it
        if self._gl is not None:
            out = self._gl.render(T_true, color=self.color_on, segmentation=self.segmentation_on,
                                  light_direction=self.light_direction)
        else:
            out = render_buffers(p, self._client, self.intrinsics, T_true, self.renderer, self.segmentation_on,
                                 light_direction=self.light_direction)
        self._render_wall_time += time.perf_counter() - t0
        return out

    def _finish_images(self, rgba: np.ndarray, zbuf: np.ndarray, seg_ids: np.ndarray | None):
        """The renderer's buffers -> (depth in mm uint16 with the depth noise, colour or None,
        segmentation as obstacle ids or None). Draws from the noise stream: call in capture order."""
        cam = self.scenario.camera
        out = decode_render(rgba, zbuf, seg_ids)
        z = self._noise_model.apply(out.depth, self._rng_noise)
        z[z < cam.min_range] = 0.0
        z[z > min(cam.max_range, 65.535)] = 0.0
        z *= np.float32(1000.0)
        z += np.float32(0.5)  # round to the nearest millimetre on the cast
        depth_mm = z.astype(np.uint16)
        color = out.color if self.color_on else None
        seg = None
        if out.segmentation is not None:
            s = out.segmentation
            s = np.where((s >= -1) & (s + 1 < len(self._seg_lut)), s, -1)
            seg = self._seg_lut[s + 1]
        self.last_images = (depth_mm, color, seg)
        return depth_mm, color, seg

    def people_poses(self) -> list:
        """Every person's pose now (sim.people.WalkerPose), as the renderer draws them."""
        return self.crowd.poses()

    def _pose_people(self) -> None:
        for w, pose in zip(self.walkers, self.crowd.poses()):
            w.apply_pose(p, pose)

    def render_at(self, pos, quat, people) -> tuple:
        """Pose the drone at (pos, quat) and the people at their ``people_poses`` and render: the
        renderer's raw buffers (nothing is stepped, no noise is drawn)."""
        p.resetBasePositionAndOrientation(self.drone, list(pos), list(quat), physicsClientId=self._client)
        for w, pose in zip(self.walkers, people):
            w.apply_pose(p, pose)
        return self._render_buffers(self._T_from_pose(pos, quat) @ self.T_body_camera)

    def images_at(self, pos, quat, people) -> tuple:
        """``render_at``, then the frame's images as a capture makes them: (depth in mm with the depth
        noise, colour or None, obstacle ids or None). The render process's entry: it draws the noise from
        its own copy of this world's noise stream, frame after frame in capture order, as one process would."""
        return self._finish_images(*self.render_at(pos, quat, people))

    def _capture(self) -> SensorFrame | None:
        """Capture a frame now; deliver (and return) the one captured ``frame_latency`` camera
        periods ago, if any."""
        seq = self.step_count // self.steps_per_frame
        pos, quat = self._drone_pose()
        T_body = self._T_from_pose(pos, quat)
        T_true = T_body @ self.T_body_camera
        if self._render_proc is not None:
            self._render_proc.submit(seq, self.time, pos, quat, self.people_poses(), self.light_direction)
            images = None  # asked of the render process at delivery
        elif self.render_on:
            images = self._finish_images(*self._render_buffers(T_true))
        else:  # render=False: the camera's clock and pose only
            images = (self._no_returns, None, None)
        self._pending.append(_Capture(seq, self.time, images, self._odometry(T_true), T_true, T_body, self.state(),
                                      self.obstacle_truth()))
        delivered = None
        while self._pending and self._pending[0].seq <= seq - self.frame_latency:
            c = self._pending.pop(0)
            images = c.images
            if images is None:  # rendered beside us, the noise drawn there (in capture order, as in one process)
                images = self._render_proc.result(c.seq)
            depth_mm, color, seg = images
            self._frame = SensorFrame(depth=depth_mm, color=color, intrinsics=self.intrinsics,
                                      T_world_camera=c.T_odom, stamp=c.stamp, seq=c.seq)
            self._truth = GroundTruth(stamp=c.stamp, seq=c.seq, obstacles=c.obstacles, T_world_camera=c.T_true,
                                      drone_position=c.state.position, drone_velocity=c.state.velocity,
                                      segmentation=seg, T_world_body=c.T_body)
            delivered = self._frame
        return delivered

    def obstacle_truth(self) -> tuple[ObstacleTruth, ...]:
        """Every obstacle's truth now (static ones and the people as posed at ``time``)."""
        out = []
        labels = {i + 1: o.kind for i, o in enumerate(self.scenario.obstacles)}
        for b in self.static_bodies:
            if b.obstacle_id != STRUCTURE_ID:
                out.append(ObstacleTruth(b.obstacle_id, "static", labels[b.obstacle_id], b.aabb_min.copy(),
                                         b.aabb_max.copy(), np.zeros(3)))
        for i, (w, oid) in enumerate(zip(self.walkers, self.person_ids)):
            cid, body = w.bodies[1]  # the query client holds the collidable, posed copy
            lo, hi = np.array(p.getAABB(body, -1, physicsClientId=cid))
            for link in range(p.getNumJoints(body, physicsClientId=cid)):
                a, b = p.getAABB(body, link, physicsClientId=cid)
                lo, hi = np.minimum(lo, a), np.maximum(hi, b)
            lo[2] = max(lo[2], 0.0)
            out.append(ObstacleTruth(oid, "person", "person", lo, hi, self.crowd.velocity3(i)))
        return tuple(out)

    def latest_frame(self) -> SensorFrame:
        return self._frame

    def ground_truth(self) -> GroundTruth:
        """Truth at the time of ``latest_frame()``."""
        return self._truth
