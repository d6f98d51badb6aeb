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

This module steps the world and hands out its frames; the parts it composes each have a module:
sim.scene (building the bodies), sim.rotors (rotor dynamics and forces), sim.contacts (collision
events and clearances), sim.odometry (the pose a frame carries), sim.render_backend (which renderer,
and its resources), sim.frame_capture (depth noise, sensor units, delivery after a latency),
sim.camera_paths (scripted camera paths), sim.lidar (an optional 3D LiDAR: ``lidar_scan``, never called by
the world itself).
"""
from __future__ import annotations

import math

import numpy as np
import pybullet_data

from sim.camera import quiet_stdout

with quiet_stdout():  # PyBullet prints its build time on import
    import pybullet as p

from dodt.frames import CameraIntrinsics, LidarScan, SensorFrame
from sim.camera import renderer_name
from sim.camera_paths import make_camera_path
from sim.contacts import CLEARANCE_CAP, CLEARANCE_LOG_LEN, ContactMonitor
from sim.controller import CascadedController, DroneState, Reference
from sim.crowd import Crowd
from sim.depth_noise import DepthNoiseModel
from sim.extra_cameras import ExtraCameras, in_first_camera
from sim.frame_capture import Capture, FrameQueue, ImageFinisher
from sim.gl_renderer import GLUnavailable
from sim.ground_truth import GroundTruth, ObstacleTruth
from sim.lidar import LidarModel, simulate_scan, top_mount
from sim.lidar_panorama import PanoramaCaster
from sim.odometry import OdometryNoise
from sim.render_backend import RenderBackend
from sim.rotors import Rotors
from sim.scenario import Scenario
from sim.scene import build_scene
from sim.vehicle import GRAVITY, load_vehicle

__all__ = ["CLEARANCE_CAP", "CLEARANCE_LOG_LEN", "LIDAR_SEED_TAG", "World", "episode_generators"]

# The LiDAR's random streams come from SeedSequence([seed, LIDAR_SEED_TAG]), apart from the world's own
# (SeedSequence(seed)): taking scans changes none of the numbers the rest of the world draws.
LIDAR_SEED_TAG = 0x11DA2


def episode_generators(seed: int) -> tuple[np.random.Generator, ...]:
    """The generators of one episode, in this order: the people's routes, looks (colours, heights),
    depth noise and odometry noise. Anything that redraws the routes of an episode uses the first."""
    return tuple(np.random.default_rng(s) for s in np.random.SeedSequence(int(seed)).spawn(4))


def _rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    return np.array(p.getMatrixFromQuaternion(p.getQuaternionFromEuler([roll, pitch, yaw]))).reshape(3, 3)


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
        for planning against ground-truth perception at a fraction of the cost. light_direction (world frame,
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
        self._backend: RenderBackend | None = None
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
        self._lidar_panorama = None  # (model, sim.lidar_panorama.PanoramaCaster) once a panorama scan was asked for
        self._extra_cameras = None  # sim.extra_cameras.ExtraCameras once add_cameras was called
        # ... or, when the render process draws them: (how many add_cameras calls, their yaws), and their poses
        self._extra_request, self._extra_poses, self._extra_calls = (), (), 0
        self._lidar_without_gl = False  # a panorama scan found no OpenGL: "auto" casts rays
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
        rng_paths, rng_looks, rng_noise, rng_odom = episode_generators(self.seed)
        sc = self.scenario

        with quiet_stdout():
            self._client = p.connect(p.DIRECT)
            self._query_client = p.connect(p.DIRECT)
        c = self._client
        want = self.requested_renderer
        self._backend = RenderBackend.open(
            c, self.intrinsics, want, self.render_on, self.render_process,
            (sc, self.seed, want, self.segmentation_on, self.light_direction, self.color_on))
        p.setAdditionalSearchPath(pybullet_data.getDataPath(), physicsClientId=c)
        p.setAdditionalSearchPath(pybullet_data.getDataPath(), physicsClientId=self._query_client)
        p.setPhysicsEngineParameter(fixedTimeStep=self.dt, numSubSteps=0, deterministicOverlappingPairs=1,
                                    physicsClientId=c)
        p.setGravity(0, 0, -GRAVITY, physicsClientId=c)

        self._scene = scene = build_scene(sc, c, self._query_client, rng_paths, rng_looks)
        self.static_bodies, self.walkers, self.person_ids = scene.static_bodies, scene.walkers, scene.person_ids
        self.drone = scene.drone
        h = self.vehicle.collision_size / 2
        self.crowd = Crowd(self.walkers, sc, drone_radius=float(math.hypot(h[0], h[1])))
        self._backend.attach(want)

        seg_lut = scene.segmentation_lut()
        self.controller = CascadedController(self.vehicle)
        self._finish_images = ImageFinisher(sc.camera, DepthNoiseModel(sc.noise, sc.camera.fx), rng_noise, seg_lut,
                                            self.color_on)
        self._odometry = OdometryNoise(sc.noise, rng_odom)
        rng_lidar, rng_lidar_odom = (np.random.default_rng(s)
                                     for s in np.random.SeedSequence([self.seed, LIDAR_SEED_TAG]).spawn(2))
        self._lidar_rng = rng_lidar
        self._lidar_odometry = OdometryNoise(sc.noise, rng_lidar_odom)
        self._lidar_scans = 0
        self._frames = FrameQueue(self.frame_latency, self.intrinsics)
        self._contacts = ContactMonitor(scene, sc, self.vehicle, self.crowd, seg_lut)
        self._rotors = Rotors(self.vehicle)
        self.time = 0.0
        self.step_count = 0
        self._last_reference: Reference | None = None
        self._camera_path = make_camera_path(sc, self.walkers, self.crowd)
        if self._camera_path is not None:
            pos, vel, yaw = self._camera_path(0.0)
            self._set_body_pose(pos, vel, yaw)
        self._pose_people()
        p.performCollisionDetection(physicsClientId=self._client)
        self._contacts.update_clearance(self.time)
        self._contacts.check_contacts(self.time)
        self._capture()
        return self._frames.frame

    def close(self) -> None:
        if self._backend is not None:
            self._backend.close()
        if getattr(self, "_lidar_panorama", None) is not None:
            self._lidar_panorama[1].release()
            self._lidar_panorama = None
        if getattr(self, "_extra_cameras", None) is not None:
            self._extra_cameras.release()
            self._extra_cameras = None
        self._extra_request, self._extra_poses = (), ()
        for cid in (self._client, self._query_client):
            if cid is not None:
                try:
                    with quiet_stdout():
                        p.disconnect(physicsClientId=cid)
                except p.error:
                    pass
        self._client = self._query_client = None

    @property
    def renderer(self) -> str:
        """The renderer in use: "gl", "pybullet", "tiny", "none" (render=False), or "<name> (render process)"."""
        return self._backend.name

    @property
    def render_wall_time(self) -> float:
        """Seconds spent inside the renderer (benchmarks only), in this process or the render process."""
        return self._backend.wall_time

    @property
    def _gl(self):
        """The gl renderer (sim.gl_renderer.GLRenderer) when the renderer is "gl", else None."""
        return self._backend.gl if self._backend is not None else None

    @property
    def _render_proc(self):
        """The render process (sim.render_process.RenderProcess) when rendering in one, else None."""
        return self._backend.process if self._backend is not None else None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass

    # ------------------------------------------------------------------ state

    def state(self) -> DroneState:
        c = self._client
        pos, quat = p.getBasePositionAndOrientation(self.drone, physicsClientId=c)
        lin, ang = p.getBaseVelocity(self.drone, physicsClientId=c)
        R = np.array(p.getMatrixFromQuaternion(quat)).reshape(3, 3)
        return DroneState(position=np.array(pos), velocity=np.array(lin), R=R, omega=R.T @ np.array(ang))

    def T_world_body(self) -> np.ndarray:
        return self._T_from_pose(*self._drone_pose())

    def _drone_pose(self):
        return p.getBasePositionAndOrientation(self.drone, physicsClientId=self._client)

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

    @property
    def collisions(self) -> list:
        """Every collision event so far (sim.ground_truth.CollisionEvent), in order."""
        return self._contacts.collisions

    @property
    def min_clearance(self) -> dict[str, float]:
        """The least clearance so far to "static" obstacles, "person"s and "structure", capped at CLEARANCE_CAP."""
        return self._contacts.min_clearance

    @property
    def clearance_log(self):
        """(t, static, person, structure) clearances of the last CLEARANCE_LOG_LEN control periods."""
        return self._contacts.clearance_log

    @property
    def collided(self) -> bool:
        return bool(self._contacts.collisions)

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
            self._rotors.thrust_cmd = self.controller(self.state(), reference, self.dt * self.steps_per_control)
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

    def _physics_step(self) -> None:
        self._rotors.step(self._client, self.drone, self.dt)
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
            self._contacts.update_clearance(self.time)
        self._contacts.check_contacts(self.time)

    # ------------------------------------------------------------------ camera

    def people_poses(self) -> list:
        """Every person's pose now (sim.people.WalkerPose), as the renderer draws them."""
        return self.crowd.poses()

    def _pose_people(self) -> None:
        for w, pose in zip(self.walkers, self.crowd.poses()):
            w.apply_pose(p, pose)

    def _render_buffers(self, T_true: np.ndarray):
        return self._backend.render(T_true, self.color_on, self.segmentation_on, self.light_direction)

    @property
    def last_images(self):
        """(depth mm, colour, segmentation) of the last frame rendered in this process, or None."""
        return self._finish_images.last_images

    def render_at(self, pos, quat, people) -> tuple:
        """Pose the drone at (pos, quat) and the people at their ``people_poses`` and render: the
        renderer's raw buffers (nothing is stepped, no noise is drawn)."""
        self._pose_at(pos, quat, people)
        return self._render_buffers(self._T_from_pose(pos, quat) @ self.T_body_camera)

    def _pose_at(self, pos, quat, people) -> None:
        """Place the drone at (pos, quat) and the people at their ``people_poses`` (nothing is stepped)."""
        p.resetBasePositionAndOrientation(self.drone, list(pos), list(quat), physicsClientId=self._client)
        for w, pose in zip(self.walkers, people):
            w.apply_pose(p, pose)

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
        rp = self._render_proc
        if rp is not None:
            rp.submit(seq, self.time, pos, quat, self.people_poses(), self.light_direction, self._extra_request)
            images = None  # asked of the render process at delivery
        elif self.render_on:
            images = self._finish_images(*self._render_buffers(T_true))
        else:  # render=False: the camera's clock and pose only
            images = (self._no_returns, None, None)
        if self._extra_cameras is not None:
            extra = self._extra_cameras.render(T_body)
        else:  # drawn by the render process (their images come with the first camera's), or none
            extra = tuple((None, T_rel) for T_rel in self._extra_poses)
        capture = Capture(seq, self.time, images, self._odometry(T_true), T_true, T_body, self.state(),
                          self.obstacle_truth(), extra)
        return self._frames.add(capture, None if rp is None else rp.result)

    # ------------------------------------------------------------------ more cameras

    def add_cameras(self, yaws) -> None:
        """Give the drone more cameras like the first, turned about the body's z axis by ``yaws`` [deg]
        (sim.extra_cameras: depth only, drawn with the gl renderer, by the render process when it renders
        with it, else in this process; GLUnavailable without OpenGL). From the next capture on, each frame
        delivered has theirs in ``latest_extra_frames``, taken at its instant, the same images wherever
        they were drawn. The first camera's frames, and everything else, are as without them."""
        if self._extra_cameras is not None:
            self._extra_cameras.release()
            self._extra_cameras = None
        self._extra_request, self._extra_poses = (), ()
        self._extra_calls += 1
        rp = self._render_proc
        if len(yaws) and rp is not None and rp.renderer == "gl":
            # the child builds them as below in its copy of this world (the same noise streams)
            self._extra_request = (self._extra_calls, tuple(float(y) for y in yaws))
            self._extra_poses = tuple(in_first_camera(self.T_body_camera, yaws))
        elif len(yaws):
            sc = self.scenario
            self._extra_cameras = ExtraCameras(p, self._client, self.intrinsics, sc.camera,
                                               DepthNoiseModel(sc.noise, sc.camera.fx), self.seed, yaws,
                                               self.T_body_camera)

    def extra_images_at(self, pos, quat, people) -> tuple[np.ndarray, ...]:
        """The other cameras' depth images (``add_cameras``; uint16 mm with their noise) with the drone at
        (pos, quat) and the people at their ``people_poses``: the render process's entry, as ``images_at``."""
        self._pose_at(pos, quat, people)
        return tuple(d for d, _ in self._extra_cameras.render(self._T_from_pose(pos, quat)))

    def latest_extra_frames(self) -> tuple[SensorFrame, ...]:
        """The other cameras' frames (``add_cameras``) of the capture ``latest_frame`` comes from."""
        return self._frames.extra

    # ------------------------------------------------------------------ lidar

    def lidar_scan(self, model: LidarModel | None = None, T_body_sensor: np.ndarray | None = None,
                   method: str = "rays") -> LidarScan:
        """A scan of a 3D LiDAR on the drone, taken now (sim.lidar.simulate_scan): ``model`` (default
        ``LidarModel()``, Mid-360-like) mounted at ``T_body_sensor`` (default ``top_mount()``, on top of the
        body). It sees what the camera sees, all as it stands now. ``method`` "rays": rays cast against
        collision shapes, the static world and the drone in the main client, the walkers' collidable copies
        in the query client. "panorama": looked up in depth images of the main client's visual shapes drawn
        around the sensor by the gl renderer (sim.lidar_panorama: faster; GLUnavailable without OpenGL).
        "auto": the panorama, or the rays from the first scan that found no OpenGL on.
        The scan's pose is the true one with the scenario's odometry noise; its stamp the world's time; its
        seq (and pattern index) counts the scans since ``reset``.

        Nothing calls this but its user: a world that never scans runs exactly as before, and one that does
        draws the same numbers everywhere else (the LiDAR's noise, dropouts and odometry come from their own
        streams, LIDAR_SEED_TAG) and steps identically."""
        if method not in ("rays", "panorama", "auto"):
            raise ValueError(f"method: expected 'rays', 'panorama' or 'auto', got {method!r}")
        auto = method == "auto"
        if auto:
            method = "rays" if self._lidar_without_gl else "panorama"
        model = LidarModel() if model is None else model
        T_bs = top_mount() if T_body_sensor is None else np.asarray(T_body_sensor, dtype=np.float64)
        pos, quat = self._drone_pose()
        T_true = self._T_from_pose(pos, quat) @ T_bs
        caster = None
        if method == "panorama":
            if self._lidar_panorama is None or self._lidar_panorama[0] != model:
                if self._lidar_panorama is not None:
                    self._lidar_panorama[1].release()
                    self._lidar_panorama = None
                try:
                    self._lidar_panorama = (model, PanoramaCaster(p, self._client, model))
                except GLUnavailable:
                    if not auto:
                        raise
                    self._lidar_without_gl = True
                    return self.lidar_scan(model, T_bs, "rays")
            caster = self._lidar_panorama[1]
        else:
            # the drone's copy in the query client stands where the drone is, as the contact monitor poses it
            # before each of its own queries, so that rays there meet the drone where it is
            p.resetBasePositionAndOrientation(self._scene.drone_proxy, pos, quat, physicsClientId=self._query_client)
        seq = self._lidar_scans
        self._lidar_scans += 1
        return simulate_scan((self._client, self._query_client), T_true, model, self._lidar_rng, seq,
                             stamp=self.time, T_world_sensor_reported=self._lidar_odometry(T_true), caster=caster)

    def obstacle_truth(self) -> tuple[ObstacleTruth, ...]:
        """Every obstacle's truth now (static ones and the people as posed at ``time``)."""
        return self._scene.obstacle_truth(self.scenario, self.crowd.velocity3)

    def latest_frame(self) -> SensorFrame:
        return self._frames.frame

    def ground_truth(self) -> GroundTruth:
        """Truth at the time of ``latest_frame()``."""
        return self._frames.truth
