"""Hostile recorded sequences and options for `dodt-nav perceive`: list files, intrinsics, sensor.json and
ground truth that are not UTF-8, not JSON, lack stamps, ids, fx or width, or hold the wrong types; broken
or missing PNGs; options out of range (--depth-factor 0, --roll inf, --pitch nan, --camera-height 1e308).
Each ends non-zero with one line naming the file or option, never a traceback.

A tiny valid TUM sequence (three 64x48 frames) and a tiny simulate-style sequence are written per test and
broken one way each.
"""
from __future__ import annotations

import copy
import json

import cv2
import numpy as np
import pytest
from hostile_cli import assert_refused, cli

W, H = 64, 48
INTRINSICS = {"fx": 50.0, "fy": 50.0, "cx": 32.0, "cy": 24.0, "width": W, "height": H}


def _depth(k: int) -> np.ndarray:
    d = np.full((H, W), 2000 + 10 * k, np.uint16)  # 2 m wall (millimetres)
    d[H // 2:, :] = 1500
    return d


def tum(root, depth_txt=None, rgb_txt=None, intrinsics=None, poses=None, images=True):
    """A TUM folder; each argument replaces one file's content (text or bytes), None keeps the valid one."""
    (root / "depth").mkdir(parents=True)
    (root / "rgb").mkdir()
    lines_d, lines_c = [], []
    for k in range(3):
        t = 1.0 + k / 30
        if images:
            cv2.imwrite(str(root / "depth" / f"{k}.png"), (_depth(k).astype(np.uint32) * 5).astype(np.uint16))
            cv2.imwrite(str(root / "rgb" / f"{k}.png"), np.full((H, W, 3), 120, np.uint8))
        lines_d.append(f"{t:.6f} depth/{k}.png")
        lines_c.append(f"{t:.6f} rgb/{k}.png")
    for name, value, default in (("depth.txt", depth_txt, "\n".join(lines_d) + "\n"),
                                 ("rgb.txt", rgb_txt, "\n".join(lines_c) + "\n"),
                                 ("intrinsics.json", intrinsics, json.dumps(INTRINSICS)),
                                 ("groundtruth.txt", poses, "".join(f"{1.0 + k / 30:.6f} 0 0 1 0 0 0 1\n"
                                                                    for k in range(3)))):
        data = default if value is None else value
        (root / name).write_bytes(data if isinstance(data, bytes) else data.encode())
    return root


SENSOR = {"intrinsics": dict(INTRINSICS), "depth_scale": 0.001,
          "frames": [{"seq": k, "stamp": 1.0 + k / 30, "depth": f"depth/{k}.png", "color": f"color/{k}.png",
                      "T_world_camera": np.eye(4).tolist()} for k in range(3)]}


def sim(root, sensor):
    (root / "depth").mkdir(parents=True)
    (root / "color").mkdir()
    for k in range(3):
        cv2.imwrite(str(root / "depth" / f"{k}.png"), _depth(k))
        cv2.imwrite(str(root / "color" / f"{k}.png"), np.full((H, W, 3), 120, np.uint8))
    (root / "sensor.json").write_bytes(sensor if isinstance(sensor, bytes) else json.dumps(sensor).encode())
    return root


def _sensor(path: list, value=None, delete=False):
    s = copy.deepcopy(SENSOR)
    node = s
    for p in path[:-1]:
        node = node[p]
    if delete:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return s


NAN, INF = float("nan"), float("inf")

# (id, how the TUM folder is broken: keyword arguments of tum(), extra options, the file or option named)
TUM_CASES = [
    ("depth.txt latin-1", {"depth_txt": "# caf\u00e9\n1.0 depth/0.png\n".encode("latin-1")}, [], "depth.txt"),
    ("depth.txt binary", {"depth_txt": bytes(range(256)) * 4}, [], "depth.txt"),
    ("depth.txt utf-16", {"depth_txt": "1.0 depth/0.png\n".encode("utf-16")}, [], "depth.txt"),
    ("depth.txt empty", {"depth_txt": ""}, [], "depth.txt"),
    ("depth.txt comments only", {"depth_txt": "# nothing\n"}, [], "depth.txt"),
    ("depth.txt no stamp", {"depth_txt": "depth/0.png\n"}, [], "depth.txt"),
    ("depth.txt stamp nan", {"depth_txt": "nan depth/0.png\n"}, [], "depth.txt"),
    ("depth.txt stamp inf", {"depth_txt": "inf depth/0.png\n"}, [], "depth.txt"),
    ("depth.txt stamp 1e400", {"depth_txt": "1e400 depth/0.png\n"}, [], "depth.txt"),
    ("depth.txt no path", {"depth_txt": "1.0\n2.0\n"}, [], "depth"),
    ("depth.txt missing files", {"depth_txt": "1.0 depth/none.png\n"}, [], "depth"),
    ("depth.txt absolute path", {"depth_txt": "1.0 /etc/passwd\n"}, [], "depth"),
    ("depth.txt folder", {"depth_txt": "1.0 depth\n"}, [], "depth"),
    ("depth.txt huge", {"depth_txt": "1.0 depth/0.png\n" + "# x\n" * (4 << 20) + "# x\n"}, [], "depth.txt"),
    ("depth.txt NUL", {"depth_txt": b"1.0 depth/0.png\x00\n"}, [], "depth"),
    ("rgb.txt latin-1", {"rgb_txt": "1.0 caf\u00e9.png\n".encode("latin-1")}, [], "rgb.txt"),
    ("rgb.txt stamp text", {"rgb_txt": "one rgb/0.png\n"}, [], "rgb.txt"),
    ("intrinsics latin-1", {"intrinsics": '{"fx": 50, "note": "caf\u00e9"}'.encode("latin-1")}, [], "intrinsics.json"),
    ("intrinsics binary", {"intrinsics": bytes(range(256))}, [], "intrinsics.json"),
    ("intrinsics list", {"intrinsics": "[1, 2, 3]"}, [], "intrinsics.json"),
    ("intrinsics no fx", {"intrinsics": json.dumps({k: v for k, v in INTRINSICS.items() if k != "fx"})}, [], "fx"),
    ("intrinsics fx string", {"intrinsics": json.dumps({**INTRINSICS, "fx": "fast"})}, [], "fx"),
    ("intrinsics fx 0", {"intrinsics": json.dumps({**INTRINSICS, "fx": 0})}, [], "fx"),
    ("intrinsics fx negative", {"intrinsics": json.dumps({**INTRINSICS, "fy": -50})}, [], "fy"),
    ("intrinsics fx NaN", {"intrinsics": json.dumps({**INTRINSICS, "fx": NAN})}, [], "fx"),
    ("intrinsics fx 1e400", {"intrinsics": '{"fx": 1e400, "fy": 50, "cx": 32, "cy": 24}'}, [], "fx"),
    ("intrinsics fx huge", {"intrinsics": json.dumps({**INTRINSICS, "fx": 1e300})}, [], "fx"),
    ("intrinsics cx nan", {"intrinsics": json.dumps({**INTRINSICS, "cx": NAN})}, [], "cx"),
    ("intrinsics cx huge", {"intrinsics": json.dumps({**INTRINSICS, "cx": 1e300})}, [], "cx"),
    ("intrinsics width wrong", {"intrinsics": json.dumps({**INTRINSICS, "width": 640})}, [], "640"),
    ("intrinsics width string", {"intrinsics": json.dumps({**INTRINSICS, "width": "wide"})}, [], "width"),
    ("intrinsics width inf", {"intrinsics": json.dumps({**INTRINSICS, "width": INF})}, [], "width"),
    ("intrinsics width 1e30", {"intrinsics": json.dumps({**INTRINSICS, "width": 1e30})}, [], "width"),
    ("intrinsics depth factor 0", {"intrinsics": json.dumps({**INTRINSICS, "depth_factor": 0})}, [], "depth_factor"),
    ("intrinsics depth factor -1", {"intrinsics": json.dumps({**INTRINSICS, "depth_factor": -1})}, [],
     "depth_factor"),
    ("intrinsics deep", {"intrinsics": "[" * 100000 + "]" * 100000}, [], "intrinsics.json"),
    ("intrinsics text line short", {"intrinsics": "50 50 32\n"}, [], "intrinsics.json"),
    ("intrinsics huge", {"intrinsics": json.dumps(INTRINSICS) + " " * (2 << 20)}, [], "intrinsics.json"),
    ("poses latin-1", {"poses": "1.0 0 0 1 0 0 0 1 caf\u00e9\n".encode("latin-1")}, [], "groundtruth.txt"),
    ("poses short line", {"poses": "1.0 0 0 1\n"}, [], "groundtruth.txt"),
    ("poses nan", {"poses": "1.0 nan 0 1 0 0 0 1\n"}, [], "groundtruth.txt"),
    ("poses zero quaternion", {"poses": "1.0 0 0 1 0 0 0 0\n"}, [], "groundtruth.txt"),
    ("poses empty", {"poses": ""}, [], "groundtruth.txt"),
    ("poses far in time", {"poses": "100.0 0 0 1 0 0 0 1\n"}, [], "pose"),
    ("no images", {"images": False}, [], "depth"),
]


def _option_cases():
    ok = ["--poses", "none", "--camera-height", "1.0", "--pitch", "0"]
    fixed = ["--poses", "none"]
    bad = {
        "--depth-factor": ["0", "-1", "nan", "inf", "1e308", "abc", "-0"],
        "--roll": ["inf", "nan", "-inf", "1e308", "abc", "1000"],
        "--pitch": ["nan", "inf", "1e308", "-1000", "abc"],
        "--camera-height": ["1e308", "nan", "inf", "0", "-1", "abc", "1e6"],
        "--fx": ["0", "-5", "nan", "inf", "1e308", "abc"], "--fy": ["0", "nan"], "--cx": ["nan", "inf", "-1e308"],
        "--cy": ["nan", "1e308"], "--rate": ["0", "-1", "nan", "inf", "abc"], "--max-frames": ["0", "-1", "abc", "1.5"],
        "--person-class": ["-1", "abc", "1e9"], "--detector-input": ["abc", "0x0", "-5x5", "99999x99999", "1x"],
        "--detector": ["NOWHERE/model.onnx", "TMP"], "--config": ["nonexistent", ""],
        "--set": ["kalman.q_pos=nan", "kalman.q_pos=abc", "warp.speed=1", "kalman", "=", "kalman.q_pos=1e400",
                  "kalman.q_pos=inf", "voxel.resolution=0", "voxel.resolution=-1", "association.method=telepathy"],
        "--intrinsics": ["NOWHERE/i.json", "TMP", "/dev/zero"],
        "--poses": ["NOWHERE/p.txt", "/dev/zero"],
        "--out": ["", "/proc/version/out"],
    }
    cases = []
    for option, values in bad.items():
        for v in values:
            base = fixed if option in ("--camera-height", "--pitch", "--roll") else ok
            if option == "--poses":
                base = []
            if option == "--camera-height":
                extra = ["--pitch", "0", option, v]
            elif option == "--pitch":
                extra = ["--camera-height", "1.0", option, v]
            elif option == "--roll":
                extra = ["--camera-height", "1.0", "--pitch", "0", option, v]
            else:
                extra = base + [option, v]
            cases.append((f"{option} {v!r}", extra, option))
    cases += [("--camera-height without --pitch", fixed + ["--camera-height", "1"], "--pitch"),
              ("--fit-floor and a fixed pose", ok + ["--fit-floor"], "--fit-floor"),
              ("no poses at all", ["--poses", "none"], "poses"),
              ("fit-floor on a wall", ["--poses", "none", "--fit-floor"], "--fit-floor")]
    return cases


OPTION_CASES = _option_cases()

SIM_CASES = [
    ("sensor latin-1", '{"intrinsics": "caf\u00e9"}'.encode("latin-1")),
    ("sensor binary", bytes(range(256)) * 4), ("sensor not json", b"{intrinsics"), ("sensor list", b"[]"),
    ("sensor deep", b"[" * 100000 + b"]" * 100000), ("sensor huge", b" " * (16 << 20) + b"{}"),
    ("no intrinsics", _sensor(["intrinsics"], delete=True)), ("no frames", _sensor(["frames"], delete=True)),
    ("frames 5", _sensor(["frames"], 5)), ("frames empty", _sensor(["frames"], [])),
    ("frames strings", _sensor(["frames"], ["a", "b"])), ("intrinsics string", _sensor(["intrinsics"], "K")),
    ("no fx", _sensor(["intrinsics", "fx"], delete=True)), ("no width", _sensor(["intrinsics", "width"], delete=True)),
    ("fx string", _sensor(["intrinsics", "fx"], "f")), ("fx 0", _sensor(["intrinsics", "fx"], 0)),
    ("fx nan", _sensor(["intrinsics", "fx"], NAN)), ("fx null", _sensor(["intrinsics", "fx"], None)),
    ("width string", _sensor(["intrinsics", "width"], "w")), ("width 0", _sensor(["intrinsics", "width"], 0)),
    ("width 1.5", _sensor(["intrinsics", "width"], 1.5)), ("width huge", _sensor(["intrinsics", "width"], 1e30)),
    ("width wrong", _sensor(["intrinsics", "width"], 640)), ("height -1", _sensor(["intrinsics", "height"], -1)),
    ("depth scale 0", _sensor(["depth_scale"], 0)), ("depth scale nan", _sensor(["depth_scale"], NAN)),
    ("depth scale string", _sensor(["depth_scale"], "mm")), ("depth scale -1", _sensor(["depth_scale"], -1)),
    ("no stamp", _sensor(["frames", 0, "stamp"], delete=True)), ("stamp string", _sensor(["frames", 0, "stamp"], "t")),
    ("stamp nan", _sensor(["frames", 1, "stamp"], NAN)), ("stamp inf", _sensor(["frames", 1, "stamp"], INF)),
    ("no seq", _sensor(["frames", 0, "seq"], delete=True)), ("seq string", _sensor(["frames", 0, "seq"], "s")),
    ("seq 1.5", _sensor(["frames", 0, "seq"], 1.5)), ("seq huge", _sensor(["frames", 0, "seq"], 1e300)),
    ("no depth", _sensor(["frames", 0, "depth"], delete=True)), ("depth int", _sensor(["frames", 0, "depth"], 5)),
    ("depth null", _sensor(["frames", 0, "depth"], None)), ("color int", _sensor(["frames", 0, "color"], 5)),
    ("no pose", _sensor(["frames", 0, "T_world_camera"], delete=True)),
    ("pose 3x3", _sensor(["frames", 0, "T_world_camera"], np.eye(3).tolist())),
    ("pose nan", _sensor(["frames", 0, "T_world_camera"], [[NAN] * 4] * 4)),
    ("pose string", _sensor(["frames", 0, "T_world_camera"], "identity")),
    ("pose ragged", _sensor(["frames", 0, "T_world_camera"], [[1, 0], [0, 1, 0, 0]])),
    ("frame null", _sensor(["frames", 1], None)),
]

PNG_CASES = [
    ("truncated PNG", lambda p: p.write_bytes(p.read_bytes()[:60])),
    ("garbage PNG", lambda p: p.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 4)),
    ("empty PNG", lambda p: p.write_bytes(b"")), ("text PNG", lambda p: p.write_text("not an image")),
    ("8-bit depth", lambda p: cv2.imwrite(str(p), np.full((H, W), 7, np.uint8))),
    ("colour depth", lambda p: cv2.imwrite(str(p), np.full((H, W, 3), 7, np.uint16))),
    ("wrong size", lambda p: cv2.imwrite(str(p), np.full((H * 2, W), 2000, np.uint16))),
    ("folder", lambda p: (p.unlink(), p.mkdir())), ("missing", lambda p: p.unlink()),
    ("corrupt CRC", lambda p: p.write_bytes(p.read_bytes()[:40] + b"\xff\xff\xff\xff" + p.read_bytes()[44:])),
]


@pytest.mark.parametrize("case", TUM_CASES, ids=[c[0] for c in TUM_CASES])
def test_a_broken_tum_sequence_is_one_line(case, tmp_path, capsys):
    _, broken, extra, name = case
    root = tum(tmp_path / "seq", **broken)
    code, err, _ = cli(["perceive", root, "--out", tmp_path / "out", *extra], capsys)
    assert_refused(code, err, name)


@pytest.mark.parametrize("case", OPTION_CASES, ids=[c[0] for c in OPTION_CASES])
def test_a_bad_perceive_option_is_one_line(case, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _, extra, name = case
    root = tum(tmp_path / "seq")
    extra = [a.replace("TMP", str(tmp_path)).replace("NOWHERE", str(tmp_path / "nowhere")) for a in extra]
    code, err, _ = cli(["perceive", root, "--out", tmp_path / "out", *extra], capsys)
    assert_refused(code, err, name)


@pytest.mark.parametrize("case", SIM_CASES, ids=[c[0] for c in SIM_CASES])
def test_a_broken_sensor_file_is_one_line(case, tmp_path, capsys):
    _, sensor = case
    root = sim(tmp_path / "seq", sensor)
    code, err, _ = cli(["perceive", root, "--out", tmp_path / "out"], capsys)
    assert_refused(code, err, "sensor.json")


@pytest.mark.parametrize("case", PNG_CASES, ids=[c[0] for c in PNG_CASES])
def test_every_depth_png_broken_is_one_line_without_library_warnings(case, tmp_path, capfd):
    _, breaks = case
    root = tum(tmp_path / "seq")
    for k in range(3):
        breaks(root / "depth" / f"{k}.png")
    capfd.readouterr()
    code, err, _ = cli(["perceive", root, "--out", tmp_path / "out", "--poses", "none", "--camera-height", "1",
                        "--pitch", "0"], capfd)
    assert_refused(code, err, "depth")
    assert len(err.strip().splitlines()) == 1, err  # the image library's own warnings are not shown


def test_the_valid_sequences_are_read(tmp_path, capsys):
    """The corpus breaks sequences that work: the unbroken ones run."""
    root = tum(tmp_path / "tum")
    code, err, out = cli(["perceive", root, "--out", tmp_path / "o1"], capsys)
    assert code == 0, err
    root = sim(tmp_path / "sim", SENSOR)
    code, err, out = cli(["perceive", root, "--out", tmp_path / "o2"], capsys)
    assert code == 0, err
