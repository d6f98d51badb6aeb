"""Viewers: the HTML replay built from a real episode log (checked offline and, where Chromium is
installed, rendered headless, looked at and played with its player bar), and the live viewer against a
real meshcat server."""
import base64
import gzip
import re
import shutil

import numpy as np
import pytest
import umsgpack
from PIL import Image

from dodt.frames import CameraIntrinsics, SensorFrame
from experiments.episode import EpisodeConfig, run_episode
from experiments.episode_log import read_log
from experiments.live_viewer import LiveViewer
from experiments.meshcat_scene import DRONE_RGB, FLOOR_RGB
from experiments.meshcat_server import start_meshcat_server, stop_meshcat_server
from experiments.replay_html import build_replay_html
from sim import load_scenario

from headless_chromium import QUIET_FLAGS, _Pipe, screenshot

VIEWER_JS_BYTES = 900_000  # meshcat's main.min.js, inlined in every page


def _commands(html: str) -> list[dict]:
    """The meshcat commands a page replays: base64 msgpack strings after the viewer is created
    (our replay's list, or meshcat's static_html fetch("data:...;base64,...") calls)."""
    tail = html[html.rindex("new MeshCat.Viewer("):]
    out = []
    for s in re.findall(r'(?:"|base64,)([A-Za-z0-9+/]{8,}={0,2})"', tail):
        out.append(umsgpack.unpackb(base64.b64decode(s)))
    return out


def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="module")
def episode_log(tmp_path_factory):
    out = tmp_path_factory.mktemp("episode")
    run_episode("corridor", seed=0, perception="oracle", out=out, cfg=EpisodeConfig(duration=3.0))
    return out / "log.jsonl.gz"


@pytest.fixture(scope="module")
def replay(episode_log, tmp_path_factory):
    return build_replay_html(episode_log, tmp_path_factory.mktemp("replay") / "replay.html")


def test_replay_is_one_offline_page_with_the_animated_scene(replay):
    html = replay.read_text(encoding="utf-8")
    assert not re.search(r"""(src|href)\s*=\s*["']?\s*(https?:)?//""", html, re.I)  # nothing fetched from outside
    assert "<script src" not in html and "import(" not in html.split("new MeshCat.Viewer(")[1]
    # A 3 s episode: the viewer plus < 0.5 MB per episode second keeps 20 s well under 20 MB.
    assert replay.stat().st_size < VIEWER_JS_BYTES + 3 * 500_000
    cmds = _commands(html)
    paths = {c["path"] for c in cmds}
    assert {"/meshcat/drone", "/meshcat/scene/floor", "/meshcat/executed", "/meshcat/people/5"} <= paths
    assert "/meshcat/voxels" in paths  # the map, rebuilt from the log's map records
    assert any(p.startswith("/meshcat/scene/obstacles/") for p in paths)
    anims = [c for c in cmds if c["type"] == "set_animation"]
    assert len(anims) == 1
    clips = {a["path"]: a["clip"] for a in anims[0]["animations"]}
    drone = clips["/meshcat/drone"]
    assert drone["fps"] == 15 and {t["name"] for t in drone["tracks"]} == {".position", ".quaternion"}
    xs = [k["value"][0] for t in drone["tracks"] if t["name"] == ".position" for k in t["keys"]]
    # frames reach perception one camera period after capture: the last one logged is stamped 2.967 s
    assert len(xs) == 3 * 15 and xs[-1] > xs[0] + 1.0  # the drone flies down the corridor
    assert any(p.startswith("/meshcat/tracks/dynamic/") for p in clips)  # the oracle reports people
    cam = [c for c in cmds if c["path"] == "/Cameras/default/rotated/<object>"]
    assert cam and cam[0]["property"] == "position"


def _screenshot(chromium: str, page, png, profile) -> np.ndarray:
    """What headless Chromium (software WebGL) shows of ``page`` (a file path or a URL) at 800x600."""
    url = page if isinstance(page, str) else page.resolve().as_uri()
    screenshot(chromium, url, png, profile, width=800, height=600, frames=60)
    return np.asarray(Image.open(png).convert("RGB")).astype(int)


def _drone_pixels(im) -> int:
    r, gr, b = im[..., 0], im[..., 1], im[..., 2]  # magenta, also seen through a translucent wall
    return int(np.count_nonzero((r > 150) & (b > 150) & (gr < 0.6 * np.minimum(r, b))))


def _floor_pixels(im) -> int:
    r, gr, b = im[..., 0], im[..., 1], im[..., 2]  # sand: red >= green >= blue + 30, unlike anything else
    return int(np.count_nonzero((r > 150) & (b > 60) & (r >= gr) & (gr >= b + 30) & (r - b >= 45)))


@pytest.mark.skipif(_chromium() is None, reason="no chromium binary (CI: apt-get install -y chromium)")
def test_replay_screenshot_in_headless_chromium_shows_corridor_and_drone(replay, tmp_path):
    im = _screenshot(_chromium(), replay, tmp_path / "replay.png", tmp_path / "profile")
    assert im.shape == (600, 800, 3)
    assert len(np.unique(im.reshape(-1, 3), axis=0)) > 1500  # the background alone is one gradient
    assert DRONE_RGB == (255, 0, 255) and FLOOR_RGB == (200, 180, 120)  # what the classifiers look for
    assert _drone_pixels(im) >= 30
    assert _floor_pixels(im) >= 5000
    # The same page with no scene drawn fails all three checks: they test the drawing.
    html = replay.read_text(encoding="utf-8")
    head, tail = html.split("new MeshCat.Viewer(")
    empty = tmp_path / "empty.html"
    empty.write_text(head + "new MeshCat.Viewer(" + re.sub(r'"[A-Za-z0-9+/=]{8,}"', '""', tail), encoding="utf-8")
    blank = _screenshot(_chromium(), empty, tmp_path / "empty.png", tmp_path / "profile")
    assert len(np.unique(blank.reshape(-1, 3), axis=0)) <= 1500
    assert _drone_pixels(blank) < 30 and _floor_pixels(blank) < 500  # (a few from the legend's text)


def _evaluate(chromium: str, page, profile, expression: str, width: int = 800, height: int = 600, timeout=60.0):
    """Loads ``page`` in headless Chromium as ``screenshot`` does and returns the value of the JavaScript
    ``expression`` (awaited when it is a promise; JSON-like values only)."""
    args = ["--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader", "--hide-scrollbars",
            f"--window-size={width},{height}", f"--user-data-dir={profile}", *QUIET_FLAGS, "about:blank"]
    pipe = _Pipe(chromium, args)
    try:
        pages = [t for t in pipe.call("Target.getTargets", timeout=timeout)["targetInfos"] if t["type"] == "page"]
        session = pipe.call("Target.attachToTarget", {"targetId": pages[0]["targetId"], "flatten": True})["sessionId"]
        pipe.call("Page.enable", session=session)
        pipe.call("Emulation.setDeviceMetricsOverride", {"width": width, "height": height, "deviceScaleFactor": 1,
                                                         "mobile": False}, session=session)
        pipe.call("Page.navigate", {"url": page.resolve().as_uri()}, session=session, timeout=timeout)
        pipe.wait_event("Page.loadEventFired", session, timeout)
        out = pipe.call("Runtime.evaluate", {"expression": expression, "awaitPromise": True, "returnByValue": True},
                        session=session, timeout=timeout)
        assert "exceptionDetails" not in out, out["exceptionDetails"]
        return out["result"].get("value")
    finally:
        pipe.close()


# Run in the page: whether each player control is on screen and on top (what a click there reaches),
# then pause, seek to either end and play with them, reading meshcat's animator and the drone it moves.
_PLAYER_CHECK = """(async () => {
  const frames = n => new Promise(done => { const step = () => (--n > 0) ? requestAnimationFrame(step)
                                                                          : done(); requestAnimationFrame(step); });
  const out = {controls: {}}, anim = viewer.animator;
  const button = document.getElementById("play-pause"), slider = document.getElementById("time-slider");
  // the playing state first, and paused at once: on a loaded machine a few frames can outlast the 3 s
  // animation, which then stops by itself
  await frames(2);
  out.playing_on_load = anim.playing; out.label_on_load = button.textContent;
  button.click(); await frames(3);
  out.paused = !anim.playing; out.label_paused = button.textContent;
  const t = anim.time; await frames(10); out.time_held = anim.time === t;
  for (const id of ["play-pause", "time-slider", "time-label"]) {
    const el = document.getElementById(id), r = el.getBoundingClientRect(), st = getComputedStyle(el);
    const top = document.elementFromPoint(r.left + r.width / 2, r.top + r.height / 2);
    out.controls[id] = {w: r.width, h: r.height, inside: r.left >= 0 && r.top >= 0 && r.right <= innerWidth
      && r.bottom <= innerHeight, shown: st.visibility === "visible" && st.display !== "none"
      && parseFloat(st.opacity) > 0.5, on_top: top === el || el.contains(top)};
  }
  const drone = () => viewer.scene_tree.find(["meshcat", "drone"]).object.position.x;
  out.duration = anim.duration; out.slider_max = parseFloat(slider.max);
  const seek = v => { slider.value = v; slider.dispatchEvent(new Event("input")); };
  seek(0); await frames(2); out.x_start = drone(); out.text_start = document.getElementById("time-label").textContent;
  seek(slider.max); await frames(2); out.x_end = drone(); out.time_end = anim.time;
  seek(0); button.click(); await frames(3); out.playing_again = anim.playing;
  const mat = path => viewer.scene_tree.find(path.concat(["<object>"])).object.material.color.getHexString();
  out.person_color = mat(["meshcat", "people", "5"]); out.goal_color = mat(["meshcat", "scene", "goal"]);
  return out;
})()"""


def _rgb(hex_string: str) -> np.ndarray:
    return np.array([int(hex_string[i:i + 2], 16) for i in (0, 2, 4)], float)


def test_replay_people_are_not_coloured_like_the_goal(replay):
    mats = {c["path"]: c["object"]["materials"][0]["color"] for c in _commands(replay.read_text(encoding="utf-8"))
            if c["type"] == "set_object" and c["path"] in ("/meshcat/people/5", "/meshcat/scene/goal")}
    person, goal = (_rgb(f"{mats[p]:06x}") for p in ("/meshcat/people/5", "/meshcat/scene/goal"))
    assert np.abs(person - goal).max() >= 150  # orange against green: red differs by over half its range
    legend = replay.read_text(encoding="utf-8").split('<div id="legend">')[1].split("</div>")[0]
    assert "people orange" in legend and "goal green" in legend


@pytest.mark.skipif(_chromium() is None, reason="no chromium binary (CI: apt-get install -y chromium)")
def test_replay_player_controls_are_visible_and_drive_the_animation(replay, tmp_path):
    out = _evaluate(_chromium(), replay, tmp_path / "profile", _PLAYER_CHECK)
    for name, c in out["controls"].items():  # on screen at 800x600 when the page opens, not under the canvas
        assert c["inside"] and c["shown"] and c["on_top"] and c["w"] >= 20 and c["h"] >= 10, (name, c)
    assert out["playing_on_load"] and out["label_on_load"] == "Pause"
    assert out["duration"] == pytest.approx(3 - 1 / 15, abs=0.01)  # 45 frames at 15 fps
    assert out["slider_max"] == pytest.approx(out["duration"], abs=1e-3)
    assert out["paused"] and out["label_paused"] == "Play" and out["time_held"]
    assert out["time_end"] == pytest.approx(out["duration"], abs=1e-3)
    assert out["x_end"] > out["x_start"] + 1.0  # seeking moves the drone down the corridor
    assert re.fullmatch(r"t = 0\.\d\d / 2\.\d\d s", out["text_start"]), out["text_start"]
    assert out["playing_again"]
    # what the browser draws the people and the goal with
    assert np.abs(_rgb(out["person_color"]) - _rgb(out["goal_color"])).max() >= 150, out


def test_replay_bad_input_names_the_file(tmp_path):
    missing = tmp_path / "nope.jsonl.gz"
    with pytest.raises(FileNotFoundError, match="nope.jsonl.gz"):
        build_replay_html(missing, tmp_path / "a.html")
    text = tmp_path / "notes.txt"
    text.write_text("hello\n")
    with pytest.raises(ValueError, match="notes.txt"):
        build_replay_html(text, tmp_path / "a.html")
    header_only = tmp_path / "short.jsonl.gz"
    with gzip.open(header_only, "wt") as fh:
        fh.write('{"k": "header", "corridor": {"length": 5, "width": 2, "height": 2}}\n')
    with pytest.raises(ValueError, match="short.jsonl.gz.*no camera frame"):
        build_replay_html(header_only, tmp_path / "a.html")
    assert not (tmp_path / "a.html").exists()


def test_depth_cloud_is_capped_and_in_world_coordinates():
    intr = CameraIntrinsics()
    depth = np.full((intr.height, intr.width), 2000, np.uint16)
    depth[:10] = 0  # invalid pixels are left out
    T = np.eye(4)
    T[:3, 3] = [1.0, 2.0, 3.0]
    pts = LiveViewer.cloud(SensorFrame(depth=depth, color=None, intrinsics=intr, T_world_camera=T, stamp=0.0), 5000)
    assert 3000 < len(pts) <= 5000
    np.testing.assert_allclose(pts[:, 2], 5.0)


def _listen_addresses(port: int) -> set[str]:
    """Local addresses with a listening TCP socket on ``port`` (from /proc/net/tcp and tcp6)."""
    out = set()
    for name in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            lines = open(name).read().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            local, state = line.split()[1], line.split()[3]
            addr, p = local.split(":")
            if state == "0A" and int(p, 16) == port:
                out.add(addr)
    return out


def test_live_viewer_streams_an_episode_to_a_local_meshcat_server(tmp_path):
    sc = load_scenario("corridor")
    with LiveViewer(corridor=sc.corridor, goal=sc.drone.goal, quiet=True) as viewer:
        run_episode(sc, seed=0, perception="oracle", cfg=EpisodeConfig(duration=1.0), on_frame=viewer)
        assert viewer.failed is None
        m = re.match(r"http://127\.0\.0\.1:(\d+)/static/", viewer.url)
        assert m, viewer.url
        assert _listen_addresses(int(m.group(1))) <= {"0100007F"}  # browsers: loopback only
        html = viewer.vis.static_html()
        proc = viewer.proc
        if _chromium() is not None:  # a browser on the live page gets the scene over the websocket
            im = _screenshot(_chromium(), viewer.url, tmp_path / "live.png", tmp_path / "profile")
            assert _drone_pixels(im) >= 30 and _floor_pixels(im) >= 5000
    assert proc.poll() is not None  # close() stopped the server it started
    paths = {c["path"] for c in _commands(html)}
    assert {"/meshcat/drone", "/meshcat/scene/floor", "/meshcat/scene/walls/left", "/meshcat/executed",
            "/meshcat/planned", "/meshcat/tracks", "/meshcat/people_trails", "/meshcat/cloud",
            "/meshcat/voxels"} <= paths
    assert any(p.startswith("/meshcat/people/") for p in paths)
    assert any(p.startswith("/meshcat/scene/obstacles/") for p in paths)


def test_live_viewer_uses_a_running_server_and_leaves_it_running():
    proc, zmq_url, _ = start_meshcat_server()
    try:
        viewer = LiveViewer(zmq_url=zmq_url, quiet=True)
        assert viewer.proc is None
        viewer.close()
        assert proc.poll() is None
        with pytest.raises(ConnectionError, match="tcp://127.0.0.1:1"):
            LiveViewer(zmq_url="tcp://127.0.0.1:1", quiet=True, timeout=0.3)
    finally:
        stop_meshcat_server(proc)


def test_a_lidar_rigs_replay_shows_its_last_scan(tmp_path):
    run_episode("corridor", seed=0, perception="oracle", out=tmp_path, cfg=EpisodeConfig(duration=1.0, rig="lidar"))
    records = [r for r in read_log(tmp_path / "log.jsonl.gz") if r["k"] == "lidar"]
    assert len(records) == 1 and 500 < len(records[0]["pts"]) <= 1500  # one per second, decimated
    html = build_replay_html(tmp_path / "log.jsonl.gz", tmp_path / "replay.html").read_text(encoding="utf-8")
    cmds = [c for c in _commands(html) if c["path"] == "/meshcat/lidar"]
    assert cmds and cmds[0]["object"]["object"]["type"] == "Points"
