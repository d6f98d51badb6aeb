"""`dodt-nav perceive` on recorded sequences (experiments.perceive, experiments.sequences): a tiny
TUM RGB-D sequence built here (a fixed camera 2 m up, tilted down 27 degrees, a box of furniture
and a person-sized box walking across the room, 10 Hz), read with poses, with a fitted floor,
with a given fixed pose; its mistakes refused by name; and a simulated run written in the TUM
format read back to the benchmark's figures."""
from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from dodt.floor import camera_pose
from dodt.frames import CameraIntrinsics, SensorFrame
from experiments.cli import main
from experiments.perceive import perceive
from experiments.sequences import (PoseTrack, SequenceError, TumWriter, matrix_to_quaternion, open_sequence,
                                   quaternion_to_matrix)
from tests.dodt.synthetic import render_depth

K = CameraIntrinsics()
RATE = 10.0
FRAMES = 24
HEIGHT, PITCH = 2.0, 27.0
FURNITURE = ((2.4, 1.6, 0.0), (3.0, 2.2, 1.0))


def walker(t: float):
    y = -1.6 + 1.2 * t  # 1.2 m/s across the view, 3.5 m ahead
    return (3.3, y - 0.2, 0.0), (3.7, y + 0.2, 1.7)


def make_tum(root: Path, poses: bool = True, world: np.ndarray | None = None, intrinsics: str = "text",
             frames: int = FRAMES) -> Path:
    """The tiny TUM sequence; ``world``: a transform of the pose file's world (a mocap frame that
    is not z-up); intrinsics as a text line, JSON, or not written ("none")."""
    (root / "rgb").mkdir(parents=True, exist_ok=True)
    (root / "depth").mkdir(exist_ok=True)
    T = camera_pose(HEIGHT, PITCH)
    depth_lines, rgb_lines, pose_lines = ["# depth maps", "# timestamp filename"], ["# color images"], ["# gt"]
    for k in range(frames):
        t = 1305031102.0 + k / RATE
        d = render_depth(K, T, [FURNITURE, walker(k / RATE)])
        units = np.round(d.astype(np.float64) * 5000)
        units = np.where(units <= 65535, units, 0).astype(np.uint16)  # beyond 13.1 m: no depth, as a sensor gives
        cv2.imwrite(str(root / "depth" / f"{t:.6f}.png"), units)
        depth_lines.append(f"{t:.6f} depth/{t:.6f}.png")
        color = np.full((K.height, K.width, 3), 90, np.uint8)
        tc = t + 0.004  # the colour camera's stamps are a little off
        cv2.imwrite(str(root / "rgb" / f"{tc:.6f}.png"), color)
        rgb_lines.append(f"{tc:.6f} rgb/{tc:.6f}.png")
    if poses:
        Tw = T if world is None else world @ T
        q = matrix_to_quaternion(Tw[:3, :3])
        for j in range(-1, 2 * frames + 2):  # a motion-capture rate of 20 Hz
            t = 1305031102.0 + j * 0.05
            pose_lines.append(f"{t:.6f} " + " ".join(f"{v:.9f}" for v in (*Tw[:3, 3], *q)))
        (root / "groundtruth.txt").write_text("\n".join(pose_lines) + "\n")
    (root / "depth.txt").write_text("\n".join(depth_lines) + "\n")
    (root / "rgb.txt").write_text("\n".join(rgb_lines) + "\n")
    if intrinsics == "text":
        (root / "camera.txt").write_text(f"{K.fx} {K.fy} {K.cx} {K.cy}\n")
    elif intrinsics == "json":
        (root / "intrinsics.json").write_text(json.dumps({"fx": K.fx, "fy": K.fy, "cx": K.cx, "cy": K.cy}))
    return root


@pytest.fixture(scope="module")
def tum(tmp_path_factory) -> Path:
    return make_tum(tmp_path_factory.mktemp("tum") / "seq")


def tracks(out: Path) -> list[dict]:
    return [json.loads(line) for line in open(out / "tracks.jsonl")]


def near(obstacles, xy, d=0.6):
    return [o for o in obstacles if math.hypot(o["center"][0] - xy[0], o["center"][1] - xy[1]) < d]


def check_scene(out: Path, summary: dict, xy_of=lambda x, y: (x, y)) -> None:
    """The walker is dynamic in most frames once seen for a few, the furniture never; every track
    reports its filter's velocity, no faster than a person (track.max_speed), and no track
    labelled static moves more than 0.3 m between frames."""
    lines = tracks(out)
    assert len(lines) == summary["frames_read"] == FRAMES and summary["frames_processed"] == FRAMES
    walking = []
    last_static = {}  # id -> centre of a track labelled static in the frame before
    for k, line in enumerate(lines):
        for o in line["obstacles"]:
            assert o["velocity"] == o["filter_velocity"] and math.hypot(*o["velocity"][:2]) <= 2.5 + 1e-3
            if not o["dynamic"] and o["id"] in last_static:
                assert math.dist(o["center"][:2], last_static[o["id"]]) <= 0.3, (k, o)
        last_static = {o["id"]: o["center"][:2] for o in line["obstacles"] if not o["dynamic"]}
        assert line["skipped"] is None
        lo, hi = walker(k / RATE)
        w = near(line["obstacles"], xy_of((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2))
        walking.append(any(o["dynamic"] for o in w))
        for o in near(line["obstacles"], xy_of(2.7, 1.9), 0.4):
            assert not o["dynamic"], (k, o)
    assert sum(walking[4:]) >= 0.8 * len(walking[4:]), walking
    assert summary["timings_ms"]["total"]["median"] > 0
    rows = list(open(out / "timings.csv"))
    assert len(rows) == FRAMES + 1 and rows[0].startswith("seq,stamp,point_cloud")


def test_a_tum_sequence_with_poses(tum, tmp_path):
    s = perceive(tum, tmp_path / "out", intrinsics=str(tum / "camera.txt"), images=True)
    assert s["format"] == "tum" and s["poses"].endswith("groundtruth.txt")
    assert s["depth_scale_m"] == pytest.approx(1 / 5000) and s["frame_rate_hz"] == pytest.approx(RATE)
    assert s["sequence_counters"] == {"unreadable": 0, "no_pose": 0, "no_color": 0}
    check_scene(tmp_path / "out", s)
    assert len(list((tmp_path / "out" / "annotated").glob("*.png"))) == FRAMES
    assert s["config"]["identification"]["vote_span"] == pytest.approx(5 / 30)


def test_a_fixed_camera_without_poses_from_the_floor(tmp_path):
    seq = make_tum(tmp_path / "seq", poses=False, intrinsics="json")
    with pytest.raises(SequenceError, match="no camera poses: give --poses FILE, --fit-floor"):
        perceive(seq, tmp_path / "x")
    s = perceive(seq, tmp_path / "out", fit_floor=True)
    f = s["floor_fit"]
    assert f["height_m"] == pytest.approx(HEIGHT, abs=0.02) and f["pitch_deg"] == pytest.approx(PITCH, abs=0.5)
    assert abs(f["roll_deg"]) < 0.5
    check_scene(tmp_path / "out", s)  # the floor's world: x along the view, the camera above the origin
    s2 = perceive(seq, tmp_path / "out2", camera_height=HEIGHT, pitch=PITCH)
    assert s2["poses"].startswith("fixed: height 2.0 m")
    check_scene(tmp_path / "out2", s2)


@pytest.mark.slow
def test_poses_in_a_world_that_is_not_z_up_are_turned_to_the_floor(tmp_path):
    """A motion-capture world with y up and an offset: without the floor fit the ground filter
    throws the scene away; with it, the world is turned so that the floor is at z = 0."""
    world = np.array([[1.0, 0, 0, 0.5], [0, 0, -1.0, 2.0], [0, 1.0, 0, -1.0], [0, 0, 0, 1.0]])  # z-up -> y-up
    seq = make_tum(tmp_path / "seq", world=world)
    s = perceive(seq, tmp_path / "out", intrinsics=str(seq / "camera.txt"), fit_floor=True)
    assert s["poses"].endswith("groundtruth.txt, turned to the floor fit")
    assert s["floor_fit"]["height_m"] == pytest.approx(HEIGHT, abs=0.02)
    # in the turned world the camera is 2 m up, the walker's box about 0.85 m up
    lines = tracks(tmp_path / "out")
    centers = [o["center"] for line in lines[8:] for o in line["obstacles"] if o["dynamic"]]
    assert centers and all(abs(c[2] - 0.85) < 0.2 for c in centers)


def test_decimated_frames_and_a_missing_image(tmp_path):
    seq = make_tum(tmp_path / "seq")
    (seq / "depth.txt").write_text((seq / "depth.txt").read_text() + "1305031110.000000 depth/missing.png\n")
    s = perceive(seq, tmp_path / "out", intrinsics=str(seq / "camera.txt"), rate=5.0)
    assert s["frames_read"] == FRAMES // 2 + 1 and s["frames_processed"] == FRAMES // 2
    assert s["sequence_counters"]["unreadable"] == 1  # skipped and counted, no crash
    s = perceive(seq, tmp_path / "out3", intrinsics=str(seq / "camera.txt"), max_frames=3)
    assert s["frames_read"] == 3


def test_poses_are_interpolated_and_a_frame_without_one_is_counted():
    q0 = matrix_to_quaternion(np.eye(3))
    R = quaternion_to_matrix([0.0, 0.0, math.sin(0.5), math.cos(0.5)])  # 1 rad about z
    q1 = matrix_to_quaternion(R)
    track = PoseTrack(np.array([0.0, 0.1, 1.0]), np.array([[0, 0, 0, *q0], [1, 2, 0, *q1], [5, 5, 5, *q1]]),
                      max_gap=0.2)
    T = track.at(0.05)
    np.testing.assert_allclose(T[:3, 3], [0.5, 1.0, 0.0])
    assert math.atan2(T[1, 0], T[0, 0]) == pytest.approx(0.5)
    assert track.at(0.5) is None and track.at(-1.0) is None and track.at(2.0) is None  # a gap, outside
    np.testing.assert_allclose(track.at(1.0)[:3, 3], [5, 5, 5])
    for R in (np.eye(3), quaternion_to_matrix([1.0, 2.0, -0.5, 0.1]), np.diag([1.0, -1.0, -1.0])):
        np.testing.assert_allclose(quaternion_to_matrix(matrix_to_quaternion(R)), R, atol=1e-12)


def test_quaternion_conversions_agree_with_rodrigues_formula():
    """TUM's (qx, qy, qz, qw) against axis-angle rotations made by OpenCV's Rodrigues formula, to 1e-12:
    the matrix of any scaled quaternion, and the quaternion (w >= 0) of the matrix."""
    rng = np.random.default_rng(0)
    axes = rng.normal(size=(500, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.concatenate([rng.uniform(0.0, math.pi - 1e-6, 496), [0.0, 1e-9, 1.0, math.pi - 1e-6]])
    for n, th in zip(axes, angles):
        R, _ = cv2.Rodrigues(n * th)
        q = np.array([*(math.sin(th / 2) * n), math.cos(th / 2)])
        assert np.allclose(quaternion_to_matrix(q * rng.uniform(0.1, 10.0)), R, rtol=0, atol=1e-12)
        assert np.allclose(matrix_to_quaternion(R), q, rtol=0, atol=1e-12)
    for R in (np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0])):  # half turns
        q = matrix_to_quaternion(R)
        assert q[3] == 0 and np.array_equal(np.abs(q[:3]), (np.diag(R) == 1).astype(float))  # about that axis
        assert np.allclose(quaternion_to_matrix(q), R, rtol=0, atol=1e-12)


def test_the_tum_writer_round_trip(tmp_path):
    """Frames written by TumWriter read back with the same stamps, poses and depth (5000 per metre
    on disk, read back as the millimetres it was written from), the colour registered by stamp;
    depth that is no whole number of millimetres is read at 5000 per metre."""
    rng = np.random.default_rng(0)
    frames = []
    for k in range(3):
        depth = rng.integers(0, 9000, (K.height, K.width)).astype(np.uint16)
        color = rng.integers(0, 255, (K.height, K.width, 3)).astype(np.uint8)
        T = camera_pose(1.3 + 0.1 * k, 5.0 * k, 1.0)
        frames.append(SensorFrame(depth=depth, color=color, intrinsics=K, T_world_camera=T, stamp=k / 30, seq=k))
    w = TumWriter(tmp_path, K)
    for f in frames:
        w.add(f, f.T_world_camera)
    w.close()
    seq = open_sequence(tmp_path)
    got = [f for _, f in seq.frames()]
    assert [f.stamp for f in got] == [f.stamp for f in frames]
    for a, b in zip(frames, got):
        np.testing.assert_array_equal(b.depth, a.depth)
        assert b.depth_scale == 0.001
        np.testing.assert_array_equal(b.depth_m(), a.depth_m())
        on_disk = cv2.imread(str(tmp_path / "depth" / f"{a.stamp!r}.png"), cv2.IMREAD_UNCHANGED)
        np.testing.assert_array_equal(on_disk, np.where(a.depth.astype(np.uint32) * 5 <= 65535, a.depth * 5, 0))
        np.testing.assert_allclose(b.T_world_camera, a.T_world_camera, atol=1e-12)
        np.testing.assert_array_equal(b.color, a.color)
    assert seq.intrinsics == K
    # a frame in tenths of millimetres is read at 5000 per metre
    odd = cv2.imread(str(tmp_path / "depth" / f"{frames[0].stamp!r}.png"), cv2.IMREAD_UNCHANGED)
    odd[0, 0] = 12343
    cv2.imwrite(str(tmp_path / "depth" / f"{frames[0].stamp!r}.png"), odd)
    first = next(open_sequence(tmp_path).frames())[1]
    assert first.depth_scale == pytest.approx(1 / 5000) and first.depth[0, 0] == 12343


@pytest.mark.parametrize("setup, kwargs, match", [
    ("none", {}, r"no camera intrinsics \(fx, fy, cx, cy missing\): give --intrinsics FILE"),
    ("text", {"intrinsics": "nothing.txt"}, r"--intrinsics: nothing.txt: no such file"),
    ("badfile", {}, r"camera.txt: expected JSON with fx, fy, cx, cy"),
    ("text", {"fx": -1.0}, r"intrinsics fx must be above 0"),
    ("text", {"camera_height": 2.0}, r"--camera-height and --pitch go together"),
    ("text", {"camera_height": 2.0, "pitch": 10.0, "fit_floor": True}, r"not with --fit-floor"),
    ("text", {"rate": 0.0}, r"--rate: must be a frame rate above 0"),
    ("text", {"config": "dodt-fast"}, r"--config: unknown configuration 'dodt-fast'"),
    ("text", {"assignments": ["kalman.q_pos=fast"]}, r"--set kalman.q_pos=fast: expected a number"),
    ("text", {"detector": "none.onnx"}, r"--detector: none.onnx: no such model file"),
    ("text", {"poses": "nothing.txt"}, r"--poses: .*nothing.txt: no such file"),
    ("badline", {}, r"depth.txt, line 3: expected 'timestamp \.\.\.'"),
    ("size", {}, r"the intrinsics are for 320x240 but the depth images are 640x480"),
])
def test_mistakes_are_refused_by_name(tmp_path, setup, kwargs, match):
    seq = make_tum(tmp_path / "seq", intrinsics="none" if setup != "size" else "none", frames=2)
    if setup in ("text", "badfile"):
        (seq / "camera.txt").write_text("not numbers" if setup == "badfile" else f"{K.fx} {K.fy} {K.cx} {K.cy}")
        kwargs = {"intrinsics": str(seq / "camera.txt")} | kwargs
    if setup == "badline":
        (seq / "camera.txt").write_text(f"{K.fx} {K.fy} {K.cx} {K.cy}")
        (seq / "depth.txt").write_text("# x\n# y\nsoon depth/a.png\n")
        kwargs = {"intrinsics": str(seq / "camera.txt")}
    if setup == "size":
        (seq / "intrinsics.json").write_text(json.dumps({"fx": 1, "fy": 1, "cx": 1, "cy": 1, "width": 320,
                                                         "height": 240}))
    with pytest.raises(SequenceError, match=match):
        perceive(seq, tmp_path / "out", **kwargs)


def test_cli_runs_and_refuses_in_one_line(tum, tmp_path, capsys):
    out = tmp_path / "cli"
    assert main(["perceive", str(tum), "--out", str(out), "--intrinsics", str(tum / "camera.txt"), "--video",
                 "--set", "track.coast_time=0.8"]) == 0
    text = capsys.readouterr().out
    assert f"{FRAMES} frames read, {FRAMES} processed" in text and "wrote" in text
    assert (out / "annotated.mp4").stat().st_size > 1000
    assert json.loads((out / "summary.json").read_text())["config"]["track"]["coast_time"] == 0.8
    assert main(["perceive", str(tmp_path / "nowhere"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "nowhere: no such sequence folder" in err
    assert main(["perceive", str(tum), "--out", str(out), "--set", "kalman.nope=1"]) == 2
    assert "KalmanConfig has no field 'nope'" in capsys.readouterr().err


@pytest.mark.slow
def test_a_simulated_run_in_the_tum_format_gives_the_benchmarks_figures(tmp_path):
    """`simulate --format tum` and `perceive` on it give the perception benchmark's figures of the
    same run, scored against the truth written beside it: the same depth in metres (5000 units
    per metre or millimetres), stamps and truth at full precision, the poses through quaternions."""
    from experiments.bench_perception import run_scenario

    assert main(["simulate", "circles", "--seed", "1", "--duration", "3", "--format", "tum",
                 "--out", str(tmp_path / "tum")]) == 0
    for name in ("rgb.txt", "depth.txt", "groundtruth.txt", "odometry.txt", "intrinsics.json", "ground_truth.json"):
        assert (tmp_path / "tum" / name).is_file()
    s = perceive(tmp_path / "tum", tmp_path / "out")
    bench = run_scenario("circles", 1, ["dodt"], duration=3.0)[0]["dodt"].summary()
    got = s["metrics"]
    assert got["frames"] == bench["frames"] == s["frames_processed"]
    for k in ("visible_people", "dynamic_reports", "false_dynamic", "duplicates", "id_switches", "matched",
              "recall", "fp_rate"):
        assert got[k] == bench[k], k
    for k in ("pos_err", "vel_err", "static_speed_p95", "still_speed_p95"):
        assert got[k] == pytest.approx(bench[k], rel=1e-9, abs=1e-12), k


@pytest.mark.slow
def test_a_simulate_output_in_its_own_format_is_read_too(tmp_path):
    """The project's own `simulate` output (sensor.json, millimetre depth, poses rounded to 1e-6)
    is a sequence too, scored against its truth."""
    assert main(["simulate", "wall_pass", "--seed", "0", "--duration", "1", "--out", str(tmp_path / "sim")]) == 0
    s = perceive(tmp_path / "sim", tmp_path / "out", images=True)
    assert s["format"] == "dodt-sim" and s["poses"].endswith("sensor.json")
    saved = json.loads((tmp_path / "sim" / "summary.json").read_text())["frames_saved"]
    assert s["frames_processed"] == saved == s["metrics"]["frames"]
    assert s["depth_scale_m"] == 0.001 and s["sequence_counters"]["unreadable"] == 0


def make_folder(root: Path, stamps_as_names: bool, frames: int = FRAMES) -> Path:
    """The tiny scene as a plain folder of frames: depth/ and rgb/ PNGs of the same names (timestamps,
    or frame numbers without zero padding), intrinsics.json, no list files."""
    (root / "depth").mkdir(parents=True)
    (root / "rgb").mkdir()
    T = camera_pose(HEIGHT, PITCH)
    for k in range(frames):
        name = f"{1305031102.0 + k / RATE:.6f}.png" if stamps_as_names else f"{k}.png"
        d = render_depth(K, T, [FURNITURE, walker(k / RATE)])
        units = np.round(d.astype(np.float64) * 5000)
        cv2.imwrite(str(root / "depth" / name), np.where(units <= 65535, units, 0).astype(np.uint16))
        cv2.imwrite(str(root / "rgb" / name), np.full((K.height, K.width, 3), 90, np.uint8))
    (root / "intrinsics.json").write_text(json.dumps({"fx": K.fx, "fy": K.fy, "cx": K.cx, "cy": K.cy}))
    return root


def test_a_folder_of_frames_without_timestamps_needs_the_rate(tmp_path):
    """Frames named 0.png .. 23.png: refused without --rate; with it, stamped frame / rate in numerical
    order (10.png after 9.png), which the walker's track shows."""
    seq = make_folder(tmp_path / "seq", stamps_as_names=False)
    with pytest.raises(SequenceError, match=r"no timestamps \(file names such as 0.png\): give .* --rate HZ"):
        perceive(seq, tmp_path / "x", camera_height=HEIGHT, pitch=PITCH)
    s = perceive(seq, tmp_path / "out", camera_height=HEIGHT, pitch=PITCH, rate=RATE)
    assert s["format"] == "folder" and s["stamps"] == "--rate 10 Hz"
    assert s["frame_rate_hz"] == pytest.approx(RATE) and s["sequence_counters"]["no_color"] == 0
    assert [line["stamp"] for line in tracks(tmp_path / "out")] == pytest.approx([k / RATE for k in range(FRAMES)])
    check_scene(tmp_path / "out", s)


def test_a_folder_of_frames_named_by_timestamp_keeps_them(tmp_path):
    """Frames named by their timestamps are timed by them; --rate then decimates."""
    seq = make_folder(tmp_path / "seq", stamps_as_names=True)
    s = perceive(seq, tmp_path / "out", camera_height=HEIGHT, pitch=PITCH)
    assert s["stamps"] == "per-frame" and s["frame_rate_hz"] == pytest.approx(RATE)
    assert tracks(tmp_path / "out")[1]["stamp"] == pytest.approx(1305031102.1)
    check_scene(tmp_path / "out", s)
    s = perceive(seq, tmp_path / "out2", camera_height=HEIGHT, pitch=PITCH, rate=5.0)
    assert s["frames_read"] == FRAMES // 2 and s["frame_rate_hz"] == pytest.approx(5.0)


def test_a_wrong_depth_scale_is_warned_of(tmp_path, capsys):
    """Millimetre depth images read at TUM's 5000 units per metre: the floor fit puts the camera 0.4 m
    up, which is warned of in one line on stderr and in the summary, naming --depth-factor 1000;
    read at 1000, no warning."""
    seq = make_folder(tmp_path / "seq", stamps_as_names=True, frames=4)
    for png in (seq / "depth").iterdir():  # the same scene in millimetres
        units = cv2.imread(str(png), cv2.IMREAD_UNCHANGED).astype(np.float64)
        cv2.imwrite(str(png), np.round(units / 5).astype(np.uint16))
    s = perceive(seq, tmp_path / "wrong", fit_floor=True)
    assert s["floor_fit"]["height_m"] == pytest.approx(HEIGHT / 5, abs=0.02)
    assert len(s["warnings"]) == 1
    assert "camera 0.40 m above the floor" in s["warnings"][0]
    assert "--depth-factor 1000 would put it 2.00 m up" in s["warnings"][0]
    s = perceive(seq, tmp_path / "right", fit_floor=True, depth_factor=1000.0)
    assert s["floor_fit"]["height_m"] == pytest.approx(HEIGHT, abs=0.02) and s["warnings"] == []
    capsys.readouterr()
    assert main(["perceive", str(seq), "--out", str(tmp_path / "cli"), "--fit-floor"]) == 0
    warnings = [line for line in capsys.readouterr().err.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1 and "--depth-factor 1000" in warnings[0]
