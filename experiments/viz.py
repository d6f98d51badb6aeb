"""Watching an episode in meshcat: a live view streamed while it runs, and a self-contained HTML
replay built afterwards from its log.

- ``LiveViewer``: starts a meshcat server bound to 127.0.0.1 (or connects to one given its zmq
  url), prints the viewer's address and, passed as ``run_episode(on_frame=...)``, draws each
  camera frame: the drone, its executed and planned trajectories, the global path, perception's
  boxes (red: dynamic, with velocity arrows; blue-grey: static), the people (orange) with their
  last 3 s of track, the goal (green), the depth point cloud and the occupied voxels. Heavy
  updates are throttled in sim time.
- ``build_replay_html(log, out_html)``: the same scene animated from an episode log alone (no
  simulator, no server), as one HTML page with meshcat's viewer inlined: it opens offline. A
  player bar at the bottom of the page (play/pause, a time slider, the episode time; the space
  bar plays and pauses) drives meshcat's animator, whose own controls sit in its collapsed GUI.

Both draw through the same functions onto a ``meshcat.Visualizer``; the replay's visualizer
records the packed commands instead of sending them, and the page replays them in order.
"""
from __future__ import annotations

import atexit
import base64
import contextlib
import html
import io
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import meshcat
import meshcat.geometry as g
import numpy as np
import umsgpack
import zmq
from meshcat.animation import Animation

from experiments.episode_log import map_snapshots, read_log

DRONE_SIZE = (0.51, 0.70, 0.12)  # m, the collision box of sim/assets/quadrotor.urdf
CAMERA_OFFSET = (-0.35, -0.4, 0.6)  # the viewpoint from mid-corridor, in corridor lengths
TRAIL_S = 3.0  # s of people's track drawn behind them (the paper's figures)
# Flat (unlit) colours for the drone and the floor, so a screenshot can be checked for them.
DRONE_RGB, FLOOR_RGB = (255, 0, 255), (200, 180, 120)
# People orange, far from the goal's green; their velocity arrows take the dynamic tracks' red.
WALL, OBSTACLE, PERSON, GOAL = 0xD9D2C0, 0x8C7B6B, 0xFF8C00, 0x30FF30
DYNAMIC, STATIC = 0xE02020, 0x5A78A0
ARROW = DYNAMIC
EXECUTED, PLANNED, GLOBAL_PATH, CLOUD = 0xFFD700, 0x00C8FF, 0xFFFFFF, 0xB0C4FF


def _hex(rgb) -> int:
    return (rgb[0] << 16) | (rgb[1] << 8) | rgb[2]


def _rgb(color: int) -> np.ndarray:
    return np.array([(color >> 16) & 255, (color >> 8) & 255, color & 255], dtype=np.float32) / 255


def _translation(p, scale=(1.0, 1.0, 1.0)) -> np.ndarray:
    T = np.diag([*map(float, scale), 1.0])
    T[:3, 3] = p
    return T


def _height_colors(z: np.ndarray, top: float) -> np.ndarray:
    """(3, N) float32 colours ramping blue -> green -> yellow with height (voxels)."""
    stops = np.array([[0.23, 0.30, 0.75], [0.13, 0.66, 0.45], [0.99, 0.85, 0.15]])
    s = np.clip(z / max(top, 1e-6), 0, 1) * 2
    i = np.minimum(s.astype(int), 1)
    c = stops[i] + (stops[i + 1] - stops[i]) * (s - i)[:, None]
    return c.T.astype(np.float32)


def _voxel_centers(idx, origin, res: float, corridor) -> np.ndarray:
    """World centres of occupied voxels above the floor, without those of the corridor's walls
    (drawn as walls already)."""
    c = np.asarray(origin, float) + (np.asarray(idx, float).reshape(-1, 3) + 0.5) * res
    keep = c[:, 2] >= 0.1
    if corridor is not None:
        L, W, _ = _corridor_dims(corridor)
        keep &= (c[:, 0] > res) & (c[:, 0] < L - res) & (np.abs(c[:, 1]) < W / 2 - res)
    return c[keep]


def _points(vis, pts: np.ndarray, colors: np.ndarray, size: float) -> None:
    vis.set_object(g.PointCloud(np.asarray(pts, np.float32).T, colors, size=size))


def _line(vis, pts: np.ndarray, color: int, segments: bool = False, colors: np.ndarray | None = None) -> None:
    pts = np.asarray(pts, dtype=np.float32).reshape(-1, 3)
    if len(pts) < 2:
        pts = np.zeros((2, 3), np.float32)  # nothing to draw: a degenerate line
        colors = None
    kind = g.LineSegments if segments else g.Line
    geometry = g.PointsGeometry(pts.T, None if colors is None else np.asarray(colors, np.float32).T)
    vis.set_object(kind(geometry, g.LineBasicMaterial(color=color, vertexColors=colors is not None)))


_CUBE_EDGES = np.array([[a, b] for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1])
_CUBE = np.array([[(i >> 0) & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=float) - 0.5
_ARROW = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 0], [0.8, 0.1, 0], [1, 0, 0], [0.8, -0.1, 0]], dtype=float)
_UNIT_BOX = _CUBE[_CUBE_EDGES.ravel()]  # (24, 3) segment ends of a unit wireframe cube


def _box_edges(center, size) -> np.ndarray:
    """(24, 3) segment end points of a wireframe box."""
    return np.asarray(center, float) + _UNIT_BOX * np.asarray(size, float)


def _corridor_dims(corridor) -> tuple[float, float, float]:
    get = corridor.get if isinstance(corridor, dict) else lambda k: getattr(corridor, k)
    return float(get("length")), float(get("width")), float(get("height"))


def draw_static_scene(vis, corridor, static_boxes, goal=None) -> None:
    """Floor, semi-transparent corridor walls, static obstacles (list of (lo, hi)), the goal, and
    a camera looking down the corridor from behind and above its right side."""
    L, W, H = _corridor_dims(corridor)
    vis["/Grid"].set_property("visible", False)
    s = vis["scene"]
    s["floor"].set_object(g.Box([L, W, 0.02]), g.MeshBasicMaterial(color=_hex(FLOOR_RGB)))
    s["floor"].set_transform(_translation([L / 2, 0, -0.011]))
    walls = {"left": ([L / 2, W / 2 + 0.05, H / 2], [L, 0.1, H]), "start": ([-0.05, 0, H / 2], [0.1, W, H]),
             "right": ([L / 2, -W / 2 - 0.05, H / 2], [L, 0.1, H]), "end": ([L + 0.05, 0, H / 2], [0.1, W, H])}
    for name, (c, size) in walls.items():
        s["walls"][name].set_object(g.Box(size), g.MeshLambertMaterial(color=WALL, opacity=0.25))
        s["walls"][name].set_transform(_translation(c))
    for i, (lo, hi) in enumerate(static_boxes):
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        s["obstacles"][str(i)].set_object(g.Box((hi - lo).tolist()), g.MeshLambertMaterial(color=OBSTACLE))
        s["obstacles"][str(i)].set_transform(_translation((lo + hi) / 2))
    if goal is not None:
        s["goal"].set_object(g.Sphere(0.15), g.MeshLambertMaterial(color=GOAL, opacity=0.7))
        s["goal"].set_transform(_translation(goal))
    # The viewer's camera orbits the viewer's origin: shift the scene so that it is mid-corridor.
    # The camera rig is Y-up under /Cameras/default/rotated: offset (x, y, z) is (x, z, -y) there.
    vis["/meshcat"].set_transform(_translation([-L / 2, 0.0, 0.0]))
    vis["/Axes"].set_property("visible", False)
    offset = np.array(CAMERA_OFFSET) * L
    vis["/Cameras/default/rotated/<object>"].set_property("position", [offset[0], offset[2], -offset[1]])


def draw_drone(vis) -> None:
    vis["drone"].set_object(g.Box(list(DRONE_SIZE)), g.MeshBasicMaterial(color=_hex(DRONE_RGB)))


# --------------------------------------------------------------------------------------- live


# The server ends itself when the process that started it is gone (killed with SIGKILL: nothing there can
# stop it): sim.parent_watch, given that process's pid as the first argument.
_SERVER = """
import sys
from sim.parent_watch import exit_with_parent
exit_with_parent(int(sys.argv.pop(1)))
import tornado.web
_listen = tornado.web.Application.listen
tornado.web.Application.listen = lambda self, port, address="127.0.0.1", **kw: _listen(self, port, address, **kw)
from meshcat.servers.zmqserver import main
sys.argv[0] = "meshcat-server"
main()
"""


def start_meshcat_server(timeout: float = 20.0) -> tuple[subprocess.Popen, str, str]:
    """meshcat's server as a subprocess with both its zmq and web sockets on 127.0.0.1 (meshcat's
    own listens for browsers on every interface). Returns (process, zmq_url, web_url)."""
    log = tempfile.TemporaryFile()
    # Its own session: Ctrl-C in the terminal reaches this process alone, which then stops the server itself.
    proc = subprocess.Popen([sys.executable, "-u", "-c", _SERVER, str(os.getpid())], stdout=log,
                            stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL, start_new_session=True)
    deadline = time.monotonic() + timeout
    urls: dict[str, str] = {}
    try:
        while len(urls) < 2:
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"the meshcat server did not start (exit status {proc.poll()})")
            time.sleep(0.05)
            log.seek(0)
            for line in log.read().decode("utf-8", "replace").splitlines():
                key, _, value = line.partition("=")
                if key in ("zmq_url", "web_url"):
                    urls[key] = value.strip()
    except BaseException:  # not started in time, or interrupted while waiting: it must not stay behind
        stop_meshcat_server(proc)
        raise
    finally:
        log.close()
    atexit.register(stop_meshcat_server, proc)
    return proc, urls["zmq_url"], urls["web_url"]


def stop_meshcat_server(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def _check_server(zmq_url: str, timeout_ms: int = 5000) -> None:
    """meshcat's client blocks for ever on a url nobody answers: ask first, with a deadline."""
    sock = zmq.Context.instance().socket(zmq.REQ)
    sock.setsockopt(zmq.LINGER, 0)
    sock.setsockopt(zmq.RCVTIMEO, timeout_ms)
    try:
        sock.connect(zmq_url)
        sock.send(b"url")
        sock.recv()
    except zmq.ZMQError as e:
        raise ConnectionError(f"no meshcat server answers at {zmq_url} ({e})") from None
    finally:
        sock.close()


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
            _check_server(zmq_url, int(timeout * 1000))
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
        self.period = {"lines": 1.0 / lines_hz, "cloud": 1.0 / cloud_hz, "map": 1.0 / map_hz}
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
            _line(vis["executed"], np.array(self._executed), EXECUTED)
            traj = view.get("trajectory")
            _line(vis["planned"], traj.positions if traj is not None else [], PLANNED)
            path = view.get("path")
            if path is not None and len(path) >= 2:
                path = np.asarray(path, float)
                _line(vis["global_path"], np.c_[path[:, :2], np.full(len(path), 0.05)], GLOBAL_PATH)
            self._draw_trails(t)
        if view.get("frame") is not None and self._due("cloud", t):
            pts = self.cloud(view["frame"], self.max_points)
            _points(vis["cloud"], pts, np.tile(_rgb(CLOUD)[:, None], (1, len(pts))), 0.03)
        if view.get("map") is not None and self._due("map", t):
            vmap = view["map"]
            res = float(vmap.cfg.resolution)
            c = _voxel_centers(vmap.occupied_indices(), vmap.cfg.origin, res, self.corridor)
            top = _corridor_dims(self.corridor)[2] if self.corridor is not None else 3.0
            _points(vis["voxels"], c, _height_colors(c[:, 2], top), 0.7 * res)

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
            segs = [_box_edges(c, tr["size"])]
            v = np.asarray(tr.get("velocity", (0, 0, 0)), float)
            if tr.get("dynamic") and np.linalg.norm(v[:2]) > 0.05:
                side = np.array([-v[1], v[0], 0]) / np.linalg.norm(v[:2])
                segs.append(c + _ARROW[:, :1] * v + _ARROW[:, 1:2] * side)
                color_arrow = np.tile(_rgb(ARROW), (len(_ARROW), 1))
            else:
                color_arrow = np.zeros((0, 3))
            pts += segs
            cols += [np.tile(_rgb(color), (24, 1)), color_arrow]
        _line(self.vis["tracks"], np.vstack(pts), 0xFFFFFF, segments=True, colors=np.vstack(cols))

    def _draw_people(self, truth, t: float) -> None:
        for o in truth.obstacles:
            if o.kind != "person":
                continue
            node = self.vis["people"][str(o.id)]
            if o.id not in self._people:
                node.set_object(g.Box([1, 1, 1]), g.MeshLambertMaterial(color=PERSON, opacity=0.7))
                self._people.add(o.id)
            node.set_transform(_translation(o.center, np.maximum(o.size, 1e-3)))
            trail = self._trails.setdefault(o.id, [])
            trail.append((t, np.array([o.center[0], o.center[1], 0.03])))
            while trail and trail[0][0] < t - TRAIL_S:
                trail.pop(0)

    def _draw_trails(self, t: float) -> None:
        segs = [np.repeat([p for _, p in tr], 2, axis=0)[1:-1] for tr in self._trails.values() if len(tr) > 1]
        _line(self.vis["people_trails"], np.vstack(segs) if segs else [], PERSON, segments=True)

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


# ------------------------------------------------------------------------------------- replay


class _Recorder:
    """Stands in for meshcat's ViewerWindow: keeps each command, packed, instead of sending it."""

    def __init__(self):
        self.commands: list[bytes] = []

    def send(self, command) -> None:
        self.commands.append(umsgpack.packb(command.lower(), force_float_precision="single"))


_VIEWER_JS = Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js"
_PAGE = """<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>{title}</title>
<style>body {{ margin: 0; }} #meshcat-pane {{ width: 100vw; height: 100vh; overflow: hidden; }}
#hud {{ position: absolute; left: 8px; right: 8px; bottom: 8px; display: flex; flex-direction: column;
  align-items: flex-start; gap: 4px; font: 12px sans-serif; color: #fff; pointer-events: none; }}
#hud > div {{ background: rgba(0, 0, 0, 0.55); padding: 4px 8px; border-radius: 4px; box-sizing: border-box; }}
#player {{ display: flex; align-items: center; gap: 8px; width: 100%; max-width: 720px; pointer-events: auto; }}
#player button {{ width: 5em; font: 12px sans-serif; cursor: pointer; }}
#player input {{ flex: 1; min-width: 80px; margin: 0; cursor: pointer; }}
#player span {{ font-variant-numeric: tabular-nums; white-space: nowrap; }}</style>
</head><body><div id="meshcat-pane"></div>
<div id="hud"><div id="player"><button id="play-pause" type="button">Play</button>
<input id="time-slider" type="range" min="0" max="0" step="0.001" value="0" aria-label="episode time">
<span id="time-label">t = 0.00 s</span></div><div id="legend">{legend}</div></div>
<script>{viewer_js}</script>
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
function unpack(s) {{ var b = atob(s), a = new Uint8Array(b.length);
  for (var i = 0; i < b.length; i++) a[i] = b.charCodeAt(i); return a; }}
[{commands}].forEach(function (c) {{ viewer.handle_command_bytearray(unpack(c)); }});
</script>
<script>
(function () {{  // the player bar, wired to meshcat's animator (play, pause, seek, time, duration)
  var anim = viewer.animator, t0 = {t0}, button = document.getElementById("play-pause"),
      slider = document.getElementById("time-slider"), label = document.getElementById("time-label");
  function toggle() {{
    if (anim.playing) {{ anim.pause(); return; }}
    if (anim.time >= anim.duration - 1e-6) {{ anim.reset(); }}
    anim.play();
  }}
  button.addEventListener("click", toggle);
  slider.addEventListener("input", function () {{
    var t = parseFloat(slider.value); anim.seek(t); anim.display_progress(t); }});
  document.addEventListener("keydown", function (e) {{
    if (e.key === " " && e.target.tagName !== "INPUT" && e.target.tagName !== "BUTTON") {{
      e.preventDefault(); toggle(); }} }});
  function show() {{
    slider.max = anim.duration.toFixed(3);
    slider.value = anim.time;
    button.textContent = anim.playing ? "Pause" : "Play";
    label.textContent = "t = " + (t0 + anim.time).toFixed(2) + " / " + (t0 + anim.duration).toFixed(2) + " s";
    requestAnimationFrame(show);
  }}
  show();
}})();
</script></body></html>
"""


class _Pool:
    """Animated slots for boxes that come and go: an id keeps its slot while it is reported."""

    def __init__(self, cap: int):
        self.cap, self.slot_of, self.n = cap, {}, 0

    def assign(self, ids: list[int]) -> dict[int, int]:
        self.slot_of = {i: s for i, s in self.slot_of.items() if i in ids}
        free = sorted(set(range(self.cap)) - set(self.slot_of.values()))
        for i in ids:
            if i not in self.slot_of and free:
                self.slot_of[i] = free.pop(0)
                self.n = max(self.n, self.slot_of[i] + 1)
        return self.slot_of


def build_replay_html(log_path, out_html, fps: float = 15.0, max_tracks: int = 16) -> Path:
    """Writes one self-contained animated HTML replay of the episode log ``log_path``; returns its path.

    Raises FileNotFoundError / ValueError naming the file when it is missing or not an episode
    log with camera frames. Perception boxes beyond ``max_tracks`` per kind at once are left out.
    """
    records = read_log(log_path)
    frames = [r for r in records if r["k"] == "f"]
    if not frames:
        raise ValueError(f"{log_path}: no camera frame records: nothing to replay")
    vis = meshcat.Visualizer(window=_Recorder())
    try:
        _replay_scene(vis, records, frames)
        vis.set_animation(_replay_animation(vis, records, frames, fps, max_tracks), play=True, repetitions=1)
    except (KeyError, TypeError, ValueError, IndexError) as e:
        raise ValueError(f"{log_path}: malformed episode log ({type(e).__name__}: {e})") from None
    header, end = records[0], next((r for r in reversed(records) if r["k"] == "end"), None)
    legend = html.escape(f"{header.get('scenario')} seed {header.get('seed')}, perception {header.get('perception')}"
                         f"{'' if end is None else ', ' + str(end.get('reason'))}")
    legend += (" &middot; drone magenta, executed yellow, plan cyan, global path white, people orange, "
               "goal green, tracks red (dynamic) / blue (static), voxels by height")
    js = _VIEWER_JS.read_text(encoding="utf-8").replace("</script", "<\\/script")
    commands = ",".join(f'"{base64.b64encode(c).decode("ascii")}"' for c in vis.window.commands)
    out_html = Path(out_html)
    out_html.parent.mkdir(parents=True, exist_ok=True)
    tmp = out_html.with_name(out_html.name + ".part")
    tmp.write_text(_PAGE.format(title=html.escape(f"dodt-nav replay: {header.get('scenario')}"), legend=legend,
                                viewer_js=js, commands=commands, t0=f"{float(frames[0]['t']):.3f}"),
                   encoding="utf-8")
    os.replace(tmp, out_html)
    return out_html


def _replay_scene(vis, records: list[dict], frames: list[dict]) -> None:
    """The still part: corridor, obstacles, drone, the whole executed path, the last global path
    and the last map snapshot."""
    header = records[0]
    corridor = header["corridor"]
    draw_static_scene(vis, corridor, [(o["aabb_min"], o["aabb_max"]) for o in header.get("static", [])],
                      header.get("goal"))
    draw_drone(vis)
    states = np.array([r["p"] for r in records if r["k"] == "s"] or [frames[0]["p"]], dtype=float)
    _line(vis["executed"], states[::4], EXECUTED)
    paths = [r["path"] for r in records if r["k"] == "plan" and r.get("path")]
    if paths:
        path = np.asarray(paths[-1], float)
        _line(vis["global_path"], np.c_[path[:, :2], np.full(len(path), 0.05)], GLOBAL_PATH)
    snaps = map_snapshots(records)
    if snaps and len(snaps[-1][1]):
        res = float(header["map_resolution"])
        c = _voxel_centers(snaps[-1][1], header["map_origin"], res, corridor)
        _points(vis["voxels"], c, _height_colors(c[:, 2], corridor["height"]), 0.7 * res)


def _replay_animation(vis, records: list[dict], frames: list[dict], fps: float, max_tracks: int) -> Animation:
    """Keyframes at ``fps`` from the frame records: drone pose, people boxes with dots along their
    last 3 s, dots along the current plan, perception boxes in slots shown and hidden."""
    n_plan_dots, n_trail_dots = 12, 10
    for pid in sorted({p["id"] for f in frames for p in f["people"]}):
        vis["people"][str(pid)].set_object(g.Box([1, 1, 1]), g.MeshLambertMaterial(color=PERSON, opacity=0.7))
        for j in range(n_trail_dots):
            vis["people_trails"][f"{pid}_{j}"].set_object(g.Sphere(0.04), g.MeshBasicMaterial(color=PERSON))
    for j in range(n_plan_dots):
        vis["planned"][str(j)].set_object(g.Sphere(0.04), g.MeshBasicMaterial(color=PLANNED))
    plans = [r for r in records if r["k"] == "plan"]
    ft, pt = np.array([f["t"] for f in frames]), np.array([p["t"] for p in plans])
    anim = Animation(default_framerate=fps)
    pools = {"dynamic": _Pool(max_tracks), "static": _Pool(max_tracks)}
    shown: dict[str, bool] = {}

    def key(node: str, prop: str, jstype: str, value, k: int) -> None:
        anim.at_frame(vis, k)[node].set_property(prop, jstype, value)

    def visible(node: str, on: bool, k: int) -> None:
        if shown.get(node) != on:
            key(node, "visible", "boolean", on, k)
            shown[node] = on

    def frame_at(t: float) -> dict:
        return frames[max(int(np.searchsorted(ft, t + 1e-9)) - 1, 0)]

    for k in range(int(math.floor((ft[-1] - ft[0]) * fps)) + 1):
        t = ft[0] + k / fps
        f = frame_at(t)
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = np.reshape(f["R"], (3, 3)), f["p"]
        anim.at_frame(vis, k)["drone"].set_transform(T)
        if k == 0:
            vis["drone"].set_transform(T)
        for p in f["people"]:
            lo, hi = np.asarray(p["lo"], float), np.asarray(p["hi"], float)
            key(f"people/{p['id']}", "position", "vector3", _r3((lo + hi) / 2), k)
            key(f"people/{p['id']}", "scale", "vector3", _r3(np.maximum(hi - lo, 1e-3)), k)
            for j in range(n_trail_dots):
                back = frame_at(t - (j + 1) * TRAIL_S / n_trail_dots)
                q = next((b for b in back["people"] if b["id"] == p["id"]), p)
                c = (np.asarray(q["lo"], float) + np.asarray(q["hi"], float)) / 2
                key(f"people_trails/{p['id']}_{j}", "position", "vector3", _r3([c[0], c[1], 0.03]), k)
        i_plan = int(np.searchsorted(pt, t + 1e-9)) - 1
        pos = np.asarray(plans[i_plan]["pos"], float) if i_plan >= 0 else np.asarray([f["p"]], float)
        for j, idx in enumerate(np.linspace(0, len(pos) - 1, n_plan_dots).round().astype(int)):
            key(f"planned/{j}", "position", "vector3", _r3(pos[idx]), k)
        for kind, pool in pools.items():
            tracks = {tr["id"]: tr for tr in f["tracks"] if bool(tr.get("dynamic")) == (kind == "dynamic")}
            slots = pool.assign(list(tracks))
            for tid, slot in slots.items():
                tr, node = tracks[tid], f"tracks/{kind}/{slot}"
                if node not in shown:  # a new slot: hidden until now
                    _line(vis[node]["box"], _UNIT_BOX, DYNAMIC if kind == "dynamic" else STATIC, segments=True)
                    if kind == "dynamic":
                        _line(vis[node]["arrow"], _ARROW, ARROW, segments=True)
                    if k > 0:
                        visible(node, False, 0)
                visible(node, True, k)
                key(node, "position", "vector3", _r3(tr["center"]), k)
                key(f"{node}/box", "scale", "vector3", _r3(np.maximum(tr["size"], 1e-3)), k)
                if kind == "dynamic":
                    v = np.asarray(tr["velocity"], float)
                    yaw, speed = math.atan2(v[1], v[0]), max(float(np.hypot(v[0], v[1])), 1e-3)
                    key(f"{node}/arrow", "quaternion", "quaternion", [0, 0, math.sin(yaw / 2), math.cos(yaw / 2)], k)
                    key(f"{node}/arrow", "scale", "vector3", [round(speed, 3), 1, 1], k)
            for slot in set(range(pool.n)) - set(slots.values()):
                visible(f"tracks/{kind}/{slot}", False, k)
    return anim


def _r3(v) -> list[float]:
    return [round(float(x), 3) for x in np.ravel(v)[:3]]
