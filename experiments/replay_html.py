"""A self-contained HTML replay of an episode, built afterwards from its log alone (no simulator,
no server): the scene of the live viewer (experiments.live_viewer) animated, as one HTML page with
meshcat's viewer inlined, so that it opens offline. A player bar at the bottom of the page
(play/pause, a time slider, the episode time; the space bar plays and pauses) drives meshcat's
animator, whose own controls sit in its collapsed GUI.

It draws with experiments.meshcat_scene onto a ``meshcat.Visualizer`` whose window records the
packed commands instead of sending them; the page replays them in order.
"""
from __future__ import annotations

import base64
import html
import math
import os
from pathlib import Path

import meshcat
import meshcat.geometry as g
import numpy as np
import umsgpack
from meshcat.animation import Animation
from scipy.spatial.transform import Rotation

from experiments.episode_log import map_snapshots, read_log
from experiments.meshcat_scene import (ARROW, DYNAMIC, EXECUTED, GLOBAL_PATH, PERSON, PLANNED, STATIC, TRAIL_S,
                                       UNIT_ARROW, UNIT_BOX, draw_drone, draw_line, draw_points,
                                       draw_static_scene, height_colors, voxel_centers)


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
    draw_line(vis["executed"], states[::4], EXECUTED)
    paths = [r["path"] for r in records if r["k"] == "plan" and r.get("path")]
    if paths:
        path = np.asarray(paths[-1], float)
        draw_line(vis["global_path"], np.c_[path[:, :2], np.full(len(path), 0.05)], GLOBAL_PATH)
    scans = [r["pts"] for r in records if r["k"] == "lidar" and r["pts"]]
    if scans:  # the LiDAR's last recorded scan (a still: meshcat animates poses, not clouds)
        pts = np.asarray(scans[-1], float)
        draw_points(vis["lidar"], pts, height_colors(pts[:, 2], corridor["height"]), 0.03)
    snaps = map_snapshots(records)
    if snaps and len(snaps[-1][1]):
        res = float(header["map_resolution"])
        c = voxel_centers(snaps[-1][1], header["map_origin"], res, corridor)
        draw_points(vis["voxels"], c, height_colors(c[:, 2], corridor["height"]), 0.7 * res)


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
                    draw_line(vis[node]["box"], UNIT_BOX, DYNAMIC if kind == "dynamic" else STATIC, segments=True)
                    if kind == "dynamic":
                        draw_line(vis[node]["arrow"], UNIT_ARROW, ARROW, segments=True)
                    if k > 0:
                        visible(node, False, 0)
                visible(node, True, k)
                key(node, "position", "vector3", _r3(tr["center"]), k)
                key(f"{node}/box", "scale", "vector3", _r3(np.maximum(tr["size"], 1e-3)), k)
                if kind == "dynamic":
                    v = np.asarray(tr["velocity"], float)
                    yaw, speed = math.atan2(v[1], v[0]), max(float(np.hypot(v[0], v[1])), 1e-3)
                    heading = Rotation.from_euler("z", yaw).as_quat().tolist()  # [x, y, z, w], as three.js
                    key(f"{node}/arrow", "quaternion", "quaternion", heading, k)
                    key(f"{node}/arrow", "scale", "vector3", [round(speed, 3), 1, 1], k)
            for slot in set(range(pool.n)) - set(slots.values()):
                visible(f"tracks/{kind}/{slot}", False, k)
    return anim


def _r3(v) -> list[float]:
    return [round(float(x), 3) for x in np.ravel(v)[:3]]
