"""The DODT pipeline on bad input: invalid pixels, bad poses and timestamps, malformed frames.

Bad data is skipped and counted; malformed frames (a programming or configuration error)
raise a ValueError that names the problem (dodt.pipeline module docstring).
"""
from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dodt.frames import CameraIntrinsics, SensorFrame
from dodt.pipeline import DODT
from dodt.presets import preset

K = CameraIntrinsics()  # 640 x 480 D435i
R_LOOK_X = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # optical z -> world +x
CAM_HEIGHT = 1.2
FPS = 30.0


def pose(R=R_LOOK_X, t=(0.0, 0.0, CAM_HEIGHT)) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


T0 = pose()


def wall(depth: float = 3.0, K: CameraIntrinsics = K) -> np.ndarray:
    """A flat wall facing the camera: float32 metres."""
    return np.full((K.height, K.width), depth, np.float32)


def scene(cyl_xy=(2.0, 0.0), radius=0.25, height=1.8, wall_depth=3.0) -> np.ndarray:
    """A wall at 3 m and an upright cylinder (a person-sized pillar), rendered by ray casting
    for a camera at (0, 0, 1.2) looking along +x: float32 planar depth in metres."""
    v, u = np.mgrid[0:K.height, 0:K.width].astype(np.float64)
    xn, yn = (u - K.cx) / K.fx, (v - K.cy) / K.fy
    # a pixel's point at planar depth z is (z, -xn z, 1.2 - yn z) in the world
    a, b = cyl_xy
    A = 1.0 + xn**2
    B = -2.0 * a + 2.0 * xn * b
    C = a * a + b * b - radius**2
    disc = B * B - 4 * A * C
    hit = disc >= 0
    z = np.where(hit, (-B - np.sqrt(np.where(hit, disc, 0.0))) / (2 * A), np.inf)
    Zw = CAM_HEIGHT - yn * z
    hit &= (Zw >= 0.0) & (Zw <= height) & (z < wall_depth)
    depth = np.full(u.shape, wall_depth)
    depth[hit] = z[hit]
    return depth.astype(np.float32)


def frame(depth, stamp, T=None, color=None, intrinsics=K, seq=0) -> SensorFrame:
    return SensorFrame(depth=depth, color=color, intrinsics=intrinsics, T_world_camera=T0 if T is None else T,
                       stamp=stamp, seq=seq)


def assert_finite(result) -> None:
    for o in result.obstacles:
        for name in ("center", "size", "velocity", "acceleration"):
            a = getattr(o, name)
            assert a.shape == (3,) and np.all(np.isfinite(a)), (name, a)
        assert np.all(np.isfinite(o.history))
        assert math.isfinite(o.position_std) and math.isfinite(o.age)
    assert all(math.isfinite(v) for v in result.timings_ms.values())


def walk(p: DODT, n: int, t0: float = 0.0, y0: float = -0.5, speed: float = 0.9):
    """n frames of the cylinder walking along +y at 30 Hz; the results."""
    out = []
    for k in range(n):
        t = t0 + k / FPS
        out.append(p.process(frame(scene((2.0, y0 + speed * (t - t0))), t, seq=k)))
    return out


def pillar(result):
    """The tracked obstacle nearest the pillar's place (about x = 2 m)."""
    obs = [o for o in result.obstacles if abs(o.center[0] - 2.0) < 0.4]
    assert len(obs) == 1, [(o.id, o.center) for o in result.obstacles]
    return obs[0]


@pytest.fixture(scope="module")
def clean_results():
    """The walking-pillar sequence without bad pixels, for comparison."""
    return walk(DODT(), 10)


def test_clean_scene_tracks_the_pillar(clean_results):
    """Sanity check of the synthetic scene: the pillar is tracked with one id and moves."""
    ids = {pillar(r).id for r in clean_results}
    assert len(ids) == 1
    last = pillar(clean_results[-1])
    assert last.velocity[1] > 0.5
    assert all(r.bad_pixels == 0 and r.skipped is None for r in clean_results)


# --------------------------------------------------------------------------- invalid pixels


BAD_VALUES = {"nan": np.nan, "+inf": np.inf, "-inf": -np.inf, "negative": -1.5}


@pytest.mark.parametrize("kind", list(BAD_VALUES))
def test_invalid_depth_pixels_are_counted_and_ignored(kind, clean_results):
    rng = np.random.default_rng(1)
    p = DODT()
    total = 0
    results = []
    for k in range(10):
        t = k / FPS
        d = scene((2.0, -0.5 + 0.9 * t))
        n_bad = 500 + 37 * k
        idx = rng.choice(d.size, n_bad, replace=False)
        d.flat[idx] = BAD_VALUES[kind]
        f = frame(d, t, seq=k)
        r = p.process(f)
        total += n_bad
        assert r.skipped is None
        assert r.bad_pixels == n_bad
        assert p.counters["bad_pixels"] == total
        assert p.counters["frames_with_bad_pixels"] == k + 1
        assert_finite(r)
        # the caller's image is left as it was
        assert np.sum(~np.isfinite(f.depth) | (f.depth < 0)) == n_bad
        results.append(r)
    # scattered invalid pixels hardly change what is seen
    assert len(results[-1].obstacles) == len(clean_results[-1].obstacles)
    np.testing.assert_allclose(pillar(results[-1]).center, pillar(clean_results[-1]).center, atol=0.1)
    assert len({pillar(r).id for r in results}) == 1


def test_a_frame_of_mixed_invalid_pixels_counts_each_kind():
    d = wall()
    d[0:10, :] = np.nan  # 6400
    d[10:12, :] = np.inf  # 1280
    d[12:13, :] = -np.inf  # 640
    d[13:14, :100] = -0.01  # 100
    d[14:15, :50] = 0.0  # zero is "no depth", not a bad pixel
    p = DODT()
    r = p.process(frame(d, 0.0))
    assert r.bad_pixels == 6400 + 1280 + 640 + 100
    assert p.counters["bad_pixels"] == r.bad_pixels
    assert_finite(r)


@pytest.mark.filterwarnings("ignore:overflow encountered in cast:RuntimeWarning")
def test_float64_depth_with_invalid_pixels():
    d = scene().astype(np.float64)
    d[100:110, 200:210] = np.nan
    d[300, 300] = -np.inf
    d[301, 300] = 1e300  # beyond float32: becomes inf, counted as invalid
    p = DODT()
    r = p.process(frame(d, 0.0))
    assert r.bad_pixels == 102
    assert_finite(r)
    assert len(r.obstacles) >= 1


def test_uint16_millimetre_depth_matches_float_metres():
    p_mm, p_m = DODT(), DODT()
    for k in range(3):
        d = scene((2.0, -0.5 + 0.03 * k))
        mm = np.round(d * 1000).astype(np.uint16)
        r_mm = p_mm.process(frame(mm, k / FPS))
        r_m = p_m.process(frame(mm.astype(np.float32) / 1000, k / FPS))
        assert r_mm.bad_pixels == 0
        assert len(r_mm.obstacles) == len(r_m.obstacles) >= 1
        for a, b in zip(r_mm.obstacles, r_m.obstacles):
            # 1 mm depth quantisation moves the points, and so their median, by about 1 mm
            np.testing.assert_allclose(a.center, b.center, atol=2e-3)


@pytest.mark.parametrize("dtype", [np.float32, np.uint16])
def test_all_zero_depth_gives_no_obstacles(dtype):
    p = DODT()
    for k in range(5):
        r = p.process(frame(np.zeros((K.height, K.width), dtype), k / FPS))
        assert r.skipped is None and r.obstacles == () and r.bad_pixels == 0
        assert all(len(v) == 0 for v in r.detections.values())
    assert p.counters["frames"] == 5


@pytest.mark.parametrize("fill", [10.0, np.nan, 0.3])
def test_empty_scene_gives_no_obstacles(fill):
    """Nothing in range: everything beyond depth_max, all invalid, or all nearer than depth_min."""
    p = DODT()
    for k in range(5):
        r = p.process(frame(np.full((K.height, K.width), fill, np.float32), k / FPS))
        assert r.skipped is None and r.obstacles == ()
        assert r.bad_pixels == (K.width * K.height if np.isnan(fill) else 0)


def test_pillar_disappearing_into_nan_coasts_then_goes():
    """A frame whose depth turns all invalid: the pillar's track coasts, then is dropped."""
    p = DODT()
    r = walk(p, 10)[-1]
    pid = pillar(r).id
    nan = np.full((K.height, K.width), np.nan, np.float32)
    t = 10 / FPS
    r = p.process(frame(nan, t))
    assert any(o.id == pid and o.coasting for o in r.obstacles)
    assert_finite(r)
    for k in range(1, 40):
        r = p.process(frame(nan, t + k / FPS))
        assert_finite(r)
    assert r.obstacles == ()


# --------------------------------------------------------------------------- bad poses and timestamps


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_pose_skips_the_frame(bad):
    p = DODT()
    before = walk(p, 5)[-1]
    T = pose()
    T[1, 3] = bad
    r = p.process(frame(scene(), 5 / FPS, T=T, seq=99))
    assert r.skipped == "skipped_bad_pose"
    assert p.counters["skipped_bad_pose"] == 1
    assert p.counters["frames"] == 6
    assert r.seq == 99
    # the tracks are reported as they were, at the last processed time
    assert r.stamp == pytest.approx(4 / FPS)
    assert [o.id for o in r.obstacles] == [o.id for o in before.obstacles]
    assert_finite(r)
    # the next good frame goes on with the same tracks
    r = p.process(frame(scene((2.0, -0.5 + 0.9 * 6 / FPS)), 6 / FPS))
    assert r.skipped is None
    assert pillar(r).id == pillar(before).id


def test_nan_in_the_rotation_skips_the_frame():
    p = DODT()
    T = pose()
    T[0, 0] = np.nan
    r = p.process(frame(wall(), 0.0, T=T))
    assert r.skipped == "skipped_bad_pose" and r.obstacles == ()
    assert p.counters["skipped_bad_pose"] == 1


def test_bad_pose_frame_still_counts_its_bad_pixels():
    p = DODT()
    T = pose()
    T[0, 3] = np.nan
    d = wall()
    d[:2, :] = np.nan
    r = p.process(frame(d, 0.0, T=T))
    assert r.skipped == "skipped_bad_pose"
    assert r.bad_pixels == 2 * K.width
    assert p.counters["bad_pixels"] == 2 * K.width


@pytest.mark.parametrize("stamp_offset", [0.0, -1 / FPS, -10.0])
def test_repeated_or_backwards_timestamp_skips_the_frame(stamp_offset):
    p = DODT()
    before = walk(p, 5)[-1]
    r = p.process(frame(scene(), before.stamp + stamp_offset))
    assert r.skipped == "skipped_time"
    assert p.counters["skipped_time"] == 1
    assert [o.id for o in r.obstacles] == [o.id for o in before.obstacles]
    assert r.stamp == before.stamp
    # time moves on: processed again
    r = p.process(frame(scene((2.0, -0.5 + 0.9 * 5 / FPS)), before.stamp + 1 / FPS))
    assert r.skipped is None
    assert pillar(r).id == pillar(before).id
    assert p.counters["skipped_time"] == 1


@pytest.mark.parametrize("stamp", [np.nan, np.inf])
def test_non_finite_timestamp_skips_the_frame(stamp):
    p = DODT()
    r = p.process(frame(wall(), stamp))
    assert r.skipped == "skipped_time"
    assert p.counters["skipped_time"] == 1
    r = p.process(frame(wall(), 0.0))  # the first good stamp is accepted
    assert r.skipped is None


@pytest.mark.parametrize("absurd", [1e300, 1e9, 50.0, -1e300])
def test_one_absurd_timestamp_is_skipped_and_the_rest_go_on(absurd):
    """A single stamp far ahead of (or behind) the others does not become the clock: the frame is
    skipped and counted, and the next frames are processed with the same tracks."""
    p = DODT()
    before = walk(p, 5)[-1]
    r = p.process(frame(scene(), absurd))
    assert r.skipped == "skipped_time" and p.counters["skipped_time"] == 1
    assert r.stamp == before.stamp
    after = walk(p, 5, t0=5 / FPS, y0=-0.5 + 0.9 * 5 / FPS)
    assert all(x.skipped is None for x in after)
    assert {pillar(x).id for x in after} == {pillar(before).id}
    assert p.counters["skipped_time"] == 1 and p.counters["restarted_after_gap"] == 0
    assert pillar(after[-1]).velocity[1] > 0.5


@pytest.mark.parametrize("new_clock", [1000.0, -500.0])
def test_a_clock_that_jumps_for_good_is_followed_after_a_few_frames(new_clock):
    """A clock that really jumps (ahead, or back to an earlier time) is taken once
    depth.confirm_jump_frames frames in a row run on from the jump: those before are skipped and
    counted, then the tracks restart on the new time."""
    p = DODT()
    walk(p, 5)
    n = p.cfg.depth.confirm_jump_frames
    assert n == 3
    results = walk(p, 6, t0=new_clock)
    assert [r.skipped for r in results] == ["skipped_time"] * (n - 1) + [None] * (6 - n + 1)
    assert p.counters["skipped_time"] == n - 1 and p.counters["restarted_after_gap"] == 1
    assert results[-1].stamp == pytest.approx(new_clock + 5 / FPS)
    assert len(results[-1].obstacles) >= 1
    assert_finite(results[-1])


def test_an_absurd_first_stamp_is_left_behind():
    """The first frame's stamp is taken as it is; when it was absurd the frames after it are a
    clock jump, taken after depth.confirm_jump_frames of them."""
    p = DODT()
    assert p.process(frame(scene(), 1e300)).skipped is None
    results = walk(p, 6)
    assert [r.skipped for r in results][:3] == ["skipped_time", "skipped_time", None]
    assert all(r.skipped is None for r in results[2:])
    assert p.counters["restarted_after_gap"] == 1


def test_a_stuck_clock_is_never_taken_for_a_jump():
    """Frames repeating one old stamp are skipped, however many come."""
    p = DODT()
    before = walk(p, 5)[-1]
    for _ in range(10):
        assert p.process(frame(scene(), 0.0)).skipped == "skipped_time"
    assert p.counters["restarted_after_gap"] == 0
    assert p.process(frame(scene(), before.stamp + 1 / FPS)).skipped is None


def test_gap_longer_than_the_coast_time_restarts_the_tracks():
    p = DODT()
    assert p.cfg.track.coast_time == 1.0
    before = walk(p, 10)
    old_ids = {o.id for o in before[-1].obstacles}
    assert p.counters["restarted_after_gap"] == 0
    t = before[-1].stamp + 1.5
    r = p.process(frame(scene((2.0, 0.4)), t))
    assert r.skipped is None
    assert p.counters["restarted_after_gap"] == 1
    new_ids = {o.id for o in r.obstacles}
    assert new_ids and not (new_ids & old_ids)
    assert all(np.all(o.velocity == 0) and o.age == 0 for o in r.obstacles)
    # a gap shorter than the coast time keeps them
    r2 = p.process(frame(scene((2.0, 0.4)), t + 0.9))
    assert p.counters["restarted_after_gap"] == 1
    assert {o.id for o in r2.obstacles} == new_ids


def test_no_coast_preset_tracks_at_30_hz():
    p = DODT(preset("dodt-no-coast"))
    results = walk(p, 10)
    assert p.counters["restarted_after_gap"] == 0
    assert len({pillar(r).id for r in results}) == 1


# --------------------------------------------------------------------------- malformed frames


def scaled(depth_scale) -> SensorFrame:
    """A uint16 frame of the wall with the given depth scale."""
    return SensorFrame(depth=np.full((K.height, K.width), 3000, np.uint16), color=None, intrinsics=K,
                       T_world_camera=T0, stamp=0.0, depth_scale=depth_scale)


@pytest.mark.parametrize("make, match", [
    (lambda: frame(np.zeros((240, 320), np.float32), 0.0), r"320x240 but the intrinsics are for 640x480"),
    (lambda: frame(np.zeros((480, 640), np.int32), 0.0), r"dtype int32"),
    (lambda: frame(np.zeros((480, 640), np.float16), 0.0), r"dtype float16"),
    (lambda: frame(np.zeros((480, 640, 1), np.float32), 0.0), r"2-D.*\(480, 640, 1\)"),
    (lambda: frame(np.zeros(480 * 640, np.float32), 0.0), r"2-D"),
    (lambda: frame(np.zeros((480, 640)).tolist(), 0.0), r"2-D array, got list"),
    (lambda: frame(wall(), 0.0, color=np.zeros((240, 320, 3), np.uint8)), r"color .*\(480, 640, 3\).*\(240, 320, 3\)"),
    (lambda: frame(wall(), 0.0, color=np.zeros((480, 640), np.uint8)), r"color"),
    (lambda: frame(wall(), 0.0, color=np.zeros((480, 640, 3), np.float32)), r"color .*uint8.*float32"),
    (lambda: frame(wall(), 0.0, T=np.eye(3)), r"T_world_camera must be 4x4, got shape \(3, 3\)"),
    (lambda: frame(wall(), 0.0, T=np.eye(4)[:3]), r"T_world_camera must be 4x4, got shape \(3, 4\)"),
    (lambda: frame(wall(), 0.0, T=np.eye(4)[:, :3]), r"T_world_camera must be 4x4, got shape \(4, 3\)"),
    (lambda: frame(wall(), 0.0, intrinsics=CameraIntrinsics(fx=0.0)), r"fx, fy must be finite and positive"),
    (lambda: frame(wall(), 0.0, intrinsics=CameraIntrinsics(fy=np.nan)), r"fx, fy must be finite and positive"),
    (lambda: scaled(np.nan), r"depth_scale .* must be a finite number above 0, got nan"),
    (lambda: scaled(0.0), r"depth_scale .* must be a finite number above 0, got 0.0"),
    (lambda: scaled(-0.001), r"depth_scale .* must be a finite number above 0, got -0.001"),
    (lambda: scaled("0.001"), r"depth_scale .* must be a finite number above 0, got '0.001'"),
    (lambda: frame(wall(), 0.0, T=pose(R_LOOK_X @ np.diag([1.0, -1.0, 1.0]))), r"determinant -1: a reflection"),
], ids=["shape-vs-intrinsics", "int32", "float16", "3-D", "1-D", "list", "color-shape", "color-2-D",
        "color-dtype", "pose-3x3", "pose-3x4", "pose-4x3", "fx-zero", "fy-nan", "scale-nan", "scale-zero",
        "scale-negative", "scale-string", "mirrored-pose"])
def test_malformed_frame_raises_a_value_error_naming_the_problem(make, match):
    p = DODT()
    with pytest.raises(ValueError, match=match):
        p.process(make())
    assert p.counters["frames"] == 0  # nothing was counted or processed
    assert p.last_stamp is None
    # the pipeline still works afterwards
    assert p.process(frame(wall(), 0.0)).skipped is None


def test_matching_colour_image_is_accepted():
    p = DODT()
    r = p.process(frame(wall(), 0.0, color=np.zeros((480, 640, 3), np.uint8)))
    assert r.skipped is None


@pytest.mark.parametrize("h, w", [(3, 64), (64, 1)])
def test_tiny_images_raise_value_error_or_work(h, w):
    Kt = CameraIntrinsics(width=w, height=h, fx=50.0, fy=50.0, cx=w / 2, cy=h / 2)
    p = DODT()
    try:
        r = p.process(frame(np.full((h, w), 2.0, np.float32), 0.0, intrinsics=Kt))
    except ValueError:
        return
    assert r.obstacles == ()


# --------------------------------------------------------------------------- property-based


SPECIAL = [np.nan, np.inf, -np.inf, 0.0, -1.0, -1e-3, 1e-3, 0.5, 5.0, 1e6]


@st.composite
def depth_frames(draw):
    """A random small depth image (structured or noise, float32 / float64 / uint16) with its
    matching intrinsics and the number of invalid pixels it holds."""
    h = draw(st.integers(16, 96))  # smaller images are refused: see test_tiny_images_raise_value_error_or_work
    w = draw(st.integers(16, 128))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    kind = draw(st.sampled_from(["structured", "noise", "uint16"]))
    if kind == "uint16":
        d = rng.integers(0, 8000, (h, w)).astype(np.uint16)
        if draw(st.booleans()):
            d[:] = draw(st.integers(0, 65535))
        n_bad = 0
    else:
        if kind == "structured":
            d = np.full((h, w), draw(st.floats(0.0, 8.0)))
            for _ in range(draw(st.integers(0, 3))):  # blocks at other depths
                v0, u0 = rng.integers(0, h), rng.integers(0, w)
                d[v0:v0 + rng.integers(1, h + 1), u0:u0 + rng.integers(1, w + 1)] = rng.uniform(0.3, 6.0)
            d += rng.normal(0.0, draw(st.sampled_from([0.0, 0.01, 0.1])), d.shape)
        else:
            d = rng.uniform(-1.0, 8.0, (h, w))
        n_special = draw(st.integers(0, h * w))
        idx = rng.choice(h * w, n_special, replace=False)
        d.flat[idx] = rng.choice(SPECIAL, n_special)
        dtype = draw(st.sampled_from([np.float32, np.float64]))
        d = d.astype(dtype)
        d32 = d.astype(np.float32)
        n_bad = int(np.sum(~np.isfinite(d32) | (d32 < 0)))
    f = draw(st.floats(0.3, 3.0)) * w
    K_ = CameraIntrinsics(width=w, height=h, fx=f, fy=f * draw(st.floats(0.8, 1.25)),
                          cx=draw(st.floats(0.0, w - 1.0)), cy=draw(st.floats(0.0, h - 1.0)))
    return d, K_, n_bad


@st.composite
def poses(draw):
    q = np.array(draw(st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4)))
    n = np.linalg.norm(q)
    if n < 1e-3:
        q, n = np.array([1.0, 0.0, 0.0, 0.0]), 1.0
    w, x, y, z = q / n
    R = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])
    t = draw(st.lists(st.floats(-50.0, 50.0), min_size=3, max_size=3))
    return pose(R, t)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(depth_frames(), poses(), st.floats(1e-3, 2.0))
def test_random_depth_and_pose_never_raise_and_stay_finite(fd, T, dt):
    d, K_, n_bad = fd
    np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-9)
    p = DODT()
    stamp = 0.0
    for k in range(3):
        # the camera moves a little between frames
        Tk = T.copy()
        Tk[:3, 3] += k * 0.05
        r = p.process(SensorFrame(depth=d, color=None, intrinsics=K_, T_world_camera=Tk, stamp=stamp, seq=k))
        assert r.skipped is None
        assert r.bad_pixels == n_bad
        assert_finite(r)
        stamp += dt
    assert p.counters["bad_pixels"] == 3 * n_bad


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(poses(), st.integers(0, 3))
def test_random_pose_on_the_pillar_scene_stays_finite(T, n_frames_nan):
    """A full-size frame with an obstacle, seen from random poses, with NaN frames mixed in."""
    p = DODT()
    for k in range(4):
        d = scene((2.0, -0.5 + 0.03 * k))
        if k < n_frames_nan:
            d[::7, ::5] = np.nan
        Tk = T.copy()
        Tk[:3, 3] += (0.02 * k, 0.0, 0.0)
        r = p.process(frame(d, k / FPS, T=Tk))
        assert r.skipped is None
        assert_finite(r)


# absolute stamps, or steps from the last one: small, zero, backwards, jumps, non-finite
STAMP_EVENTS = st.one_of(
    st.tuples(st.just("step"), st.floats(1e-3, 0.4)),
    st.tuples(st.just("step"), st.sampled_from([0.0, 5e-324, 1e-9, -1e-3, -0.5, 11.0, 1e6])),
    st.tuples(st.just("at"), st.sampled_from([np.nan, np.inf, -np.inf, 1e300, -1e300, 0.0, 1e15])),
)
DEPTH_KINDS = st.sampled_from(["scene", "sprinkled", "nan", "zeros", "uint16", "inf-rows"])


def depth_of(kind: str, k: int, rng) -> tuple[np.ndarray, float]:
    d = scene((2.0, -0.5 + 0.03 * k))
    if kind == "sprinkled":
        d.flat[rng.choice(d.size, 5000, replace=False)] = rng.choice([np.nan, np.inf, -np.inf, -2.0, 1e30], 5000)
    elif kind == "nan":
        d[:] = np.nan
    elif kind == "zeros":
        d[:] = 0.0
    elif kind == "inf-rows":
        d[::3] = np.inf
    elif kind == "uint16":
        scale = float(rng.choice([0.001, 0.0002, 0.00025]))
        return np.clip(np.round(d / scale), 0, 65535).astype(np.uint16), scale
    return d, 0.001


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(STAMP_EVENTS, st.booleans(), DEPTH_KINDS), min_size=2, max_size=12), poses(),
       st.integers(0, 2**31 - 1))
def test_random_stamps_poses_and_depth_never_raise_and_recover(events, T, seed):
    """Any sequence of stamps (steps, repeats, reversals, jumps, NaN, inf, 1e300), poses (some
    non-finite) and depth images (NaN, inf, zeros, uint16 at any scale) is processed without an
    exception, every output is finite, every frame is counted once, and a camera that then runs
    on at a sane clock is processed again within depth.confirm_jump_frames frames."""
    rng = np.random.default_rng(seed)
    p = DODT()
    stamp = 0.0
    skipped = 0
    for k, ((how, value), bad_pose, kind) in enumerate(events):
        stamp = value if how == "at" else (stamp + value if math.isfinite(stamp) else value)
        Tk = T.copy()
        Tk[:3, 3] += (0.02 * k, 0.0, 0.0)
        if bad_pose:
            Tk[int(rng.integers(0, 3)), int(rng.integers(0, 4))] = rng.choice([np.nan, np.inf])
        d, scale = depth_of(kind, k, rng)
        r = p.process(SensorFrame(depth=d, color=None, intrinsics=K, T_world_camera=Tk, stamp=stamp, seq=k,
                                  depth_scale=scale))
        assert r.skipped in (None, "skipped_time", "skipped_bad_pose")
        skipped += r.skipped is not None
        assert_finite(r)
        assert math.isfinite(r.stamp)
    assert p.counters["frames"] == len(events)
    assert p.counters["skipped_time"] + p.counters["skipped_bad_pose"] == skipped
    n = p.cfg.depth.confirm_jump_frames
    for j in range(n + 1):
        r = p.process(frame(scene(), 1e7 + j / FPS, T=T))
        assert_finite(r)
    assert r.skipped is None
