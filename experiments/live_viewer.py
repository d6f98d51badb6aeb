"""The live meshcat view of a running episode.

``LiveViewer`` starts a meshcat server bound to 127.0.0.1 (or connects to one given its zmq url),
prints the viewer's address and, passed as ``run_episode(on_frame=...)``, draws each camera frame:
the drone, its executed and planned trajectories, the global path, perception's boxes (red: dynamic,
with velocity arrows; blue-grey: static), the people (orange) with their last 3 s of track, the
goal (green), the depth point cloud and the occupied voxels. Heavy updates are throttled in sim
time. It draws with experiments.meshcat_scene, as the HTML replay (experiments.replay_html) does.
"""
from __future__ import annotations

import contextlib
import io
import math
import sys

import meshcat
import meshcat.geometry as g
import numpy as np
import zmq

from experiments.meshcat_scene import (ARROW, CLOUD, DYNAMIC, EXECUTED, GLOBAL_PATH, PERSON, PLANNED, STATIC,
                                       TRAIL_S, UNIT_ARROW, box_edges, corridor_dims, draw_drone, draw_line,
                                       draw_points, draw_static_scene, height_colors, translation, unit_rgb,
                                       voxel_centers)
from experiments.meshcat_server import check_server, start_meshcat_server, stop_meshcat_server


class LiveViewer:
    """Streams an episode to meshcat; pass it as ``run_episode(..., on_frame=viewer)``.

    corridor: the scenario's corridor (object or dict with length, width, height) for the floor
    and walls; None draws neither. zmq_url: an already running server (``meshcat-server``);
    None starts one on 127.0.0.1, stopped by ``close()``. timeout: seconds to wait for the server;
    one that stops answering turns the viewer off and the episode goes on. Rates are in sim time:
    the drone and boxes every frame, lines at ``lines_hz``, the depth cloud (at most
    ``max_points`` points) at ``cloud_hz``, the occupied voxels at ``map_hz``. A frame whose time
    goes back starts a new episode's drawing.
    """

    def __init__(self, corridor=None, zmq_url: str | None = None, lines_hz: float = 10.0, cloud_hz: float = 5.0,
                 map_hz: float = 2.0, max_points: int = 5000, goal=None, quiet: bool = False,
                 timeout: float = 10.0):
        self.proc = None
        if zmq_url is None:
            self.proc, zmq_url, _ = start_meshcat_server()
        else:
            check_server(zmq_url, int(timeout * 1000))
        try:
            with contextlib.redirect_stdout(io.StringIO()):  # meshcat prints its url: we print ours
                self.vis = meshcat.Visualizer(zmq_url=zmq_url)
        except BaseException:
            self.close()
            raise
        for opt, value in ((zmq.RCVTIMEO, timeout * 1000), (zmq.SNDTIMEO, timeout * 1000), (zmq.LINGER, 0)):
            self.vis.window.zmq_socket.setsockopt(opt, int(value))
        self.url = self.vis.url()
        self.zmq_url = zmq_url
        if not quiet:
            print(f"meshcat viewer: {self.url}", flush=True)
        self.corridor, self.goal, self.max_points = corridor, goal, max_points
        self.period = {"lines": 1.0 / lines_hz, "cloud": 1.0 / cloud_hz, "lidar": 1.0 / cloud_hz, "map": 1.0 / map_hz}
        self.failed: str | None = None
        self._reset()

    def _reset(self) -> None:
        self._next = {k: -math.inf for k in self.period}
        self._executed: list[np.ndarray] = []
        self._trails: dict[int, list[tuple[float, np.ndarray]]] = {}
        self._people: set[int] = set()
        self._started, self._last_t = False, -math.inf

    def __call__(self, view: dict) -> None:
        if self.failed:
            return
        try:
            self._draw(view)
        except zmq.ZMQError as e:  # the server went away: keep the episode going without a view
            self.failed = str(e)
            print(f"meshcat viewer stopped: {e}", file=sys.stderr)

    def _due(self, what: str, t: float) -> bool:
        if t < self._next[what]:
            return False
        self._next[what] = t + self.period[what]
        return True

    def _draw(self, view: dict) -> None:
        vis, t, truth = self.vis, float(view["t"]), view.get("truth")
        if t < self._last_t:
            self._reset()
        self._last_t = t
        if not self._started:
            static = [(o.aabb_min, o.aabb_max) for o in truth.obstacles if o.kind == "static"] if truth else []
            if self.corridor is not None:
                draw_static_scene(vis, self.corridor, static, self.goal)
            draw_drone(vis)
            self._started = True
        T = np.asarray(view["T_world_body"], dtype=float)
        vis["drone"].set_transform(T)
        self._executed.append(T[:3, 3].copy())
        self._draw_tracks(view["perception"].tracks if view.get("perception") is not None else [])
        if truth is not None:
            self._draw_people(truth, t)
        if self._due("lines", t):
            draw_line(vis["executed"], np.array(self._executed), EXECUTED)
            traj = view.get("trajectory")
            draw_line(vis["planned"], traj.positions if traj is not None else [], PLANNED)
            path = view.get("path")
            if path is not None and len(path) >= 2:
                path = np.asarray(path, float)
                draw_line(vis["global_path"], np.c_[path[:, :2], np.full(len(path), 0.05)], GLOBAL_PATH)
            self._draw_trails(t)
        if view.get("frame") is not None and self._due("cloud", t):
            pts = self.cloud(view["frame"], self.max_points)
            draw_points(vis["cloud"], pts, np.tile(unit_rgb(CLOUD)[:, None], (1, len(pts))), 0.03)
        if view.get("lidar") is not None and self._due("lidar", t):
            pts = np.asarray(view["lidar"])[::max(1, -(-len(view["lidar"]) // self.max_points))]
            draw_points(vis["lidar"], pts, height_colors(pts[:, 2], 3.0), 0.03)
        if view.get("map") is not None and self._due("map", t):
            vmap = view["map"]
            res = float(vmap.cfg.resolution)
            c = voxel_centers(vmap.occupied_indices(), vmap.cfg.origin, res, self.corridor)
            top = corridor_dims(self.corridor)[2] if self.corridor is not None else 3.0
            draw_points(vis["voxels"], c, height_colors(c[:, 2], top), 0.7 * res)

    @staticmethod
    def cloud(frame, max_points: int = 5000, max_range: float = 8.0) -> np.ndarray:
        """(N, 3) world points of a depth frame subsampled on a regular pixel grid, N <= max_points."""
        h, w = frame.depth.shape
        step = max(1, math.ceil(math.sqrt(h * w / max_points)))
        v, u = np.mgrid[0:h:step, 0:w:step]
        z = frame.depth[::step, ::step].astype(np.float64)
        if frame.depth.dtype == np.uint16:
            z = z * frame.depth_scale
        ok = np.isfinite(z) & (z > 0) & (z < max_range)
        p = frame.intrinsics.backproject(u[ok], v[ok], z[ok])
        T = np.asarray(frame.T_world_camera, dtype=float)
        return (p @ T[:3, :3].T + T[:3, 3])[:max_points]

    def _draw_tracks(self, tracks: list[dict]) -> None:
        pts, cols = [np.zeros((0, 3))], [np.zeros((0, 3))]
        for tr in tracks:
            c = np.asarray(tr["center"], float)
            color = DYNAMIC if tr.get("dynamic") else STATIC
            segs = [box_edges(c, tr["size"])]
            v = np.asarray(tr.get("velocity", (0, 0, 0)), float)
            if tr.get("dynamic") and np.linalg.norm(v[:2]) > 0.05:
                side = np.array([-v[1], v[0], 0]) / np.linalg.norm(v[:2])
                segs.append(c + UNIT_ARROW[:, :1] * v + UNIT_ARROW[:, 1:2] * side)
                color_arrow = np.tile(unit_rgb(ARROW), (len(UNIT_ARROW), 1))
            else:
                color_arrow = np.zeros((0, 3))
            pts += segs
            cols += [np.tile(unit_rgb(color), (24, 1)), color_arrow]
        draw_line(self.vis["tracks"], np.vstack(pts), 0xFFFFFF, segments=True, colors=np.vstack(cols))

    def _draw_people(self, truth, t: float) -> None:
        for o in truth.obstacles:
            if o.kind != "person":
                continue
            node = self.vis["people"][str(o.id)]
            if o.id not in self._people:
                node.set_object(g.Box([1, 1, 1]), g.MeshLambertMaterial(color=PERSON, opacity=0.7))
                self._people.add(o.id)
            node.set_transform(translation(o.center, np.maximum(o.size, 1e-3)))
            trail = self._trails.setdefault(o.id, [])
            trail.append((t, np.array([o.center[0], o.center[1], 0.03])))
            while trail and trail[0][0] < t - TRAIL_S:
                trail.pop(0)

    def _draw_trails(self, t: float) -> None:
        segs = [np.repeat([p for _, p in tr], 2, axis=0)[1:-1] for tr in self._trails.values() if len(tr) > 1]
        draw_line(self.vis["people_trails"], np.vstack(segs) if segs else [], PERSON, segments=True)

    def close(self) -> None:
        """Disconnects; stops the server if this viewer started it (the page then goes blank)."""
        with contextlib.suppress(Exception):  # (no socket when the constructor failed)
            self.vis.window.zmq_socket.close(linger=0)
        if self.proc is not None:
            stop_meshcat_server(self.proc)
            self.proc = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
