"""Detections cut by the image's side: which edge cuts them, and a track measured from the side in view."""
from dataclasses import replace

import numpy as np
import pytest

from dodt.config import DepthConfig, DODTConfig, VoxelConfig
from dodt.frames import CameraIntrinsics, SensorFrame
from dodt.pipeline import DODT
from dodt.pointcloud import VoxelCloud
from dodt.view_edge import view_sides
from synthetic import camera_pose, render_depth

K = CameraIntrinsics()
T = camera_pose()  # at the origin, 1.2 m up, looking along +x: the image's left is +y
EDGE = (K.cx / K.fx)  # tan of the half view on the image's left


def _sides(box):
    depth = render_depth(K, T, [box])
    pts = VoxelCloud(DepthConfig(), VoxelConfig())(depth, K, T)
    lo, hi = np.asarray(box[0]), np.asarray(box[1])
    inside = pts[np.all((pts >= lo - 0.06) & (pts <= hi + 0.06), axis=1)]
    return view_sides(inside, K, T, DepthConfig().margin, VoxelConfig().resolution)


def _box(x, y, width=0.5, depth=0.3, height=1.7):
    return (np.array([x, y - width / 2, 0.0]), np.array([x + depth, y + width / 2, height]))


def test_a_box_wholly_in_view_is_not_cut_and_its_sides_span_its_width():
    s = _sides(_box(3.03, 0.21))
    assert s.cut == 0
    assert 0.3 <= s.high - s.low <= 0.5  # 0.5 m wide, less the voxels and percentiles at its sides


@pytest.mark.parametrize("sign, cut", [(1, -1), (-1, 1)])
def test_a_box_across_the_view_side_is_cut_on_that_side_and_its_inner_side_is_true(sign, cut):
    x = 3.03
    y = sign * EDGE * x  # the box's centre on the edge of the view: half of it out of view
    s = _sides(_box(x, y))
    assert s.cut == cut
    lo, hi = _box(x, y)
    lats = [s.lateral(np.array([cx, cy])) for cx in (lo[0], hi[0]) for cy in (lo[1], hi[1])]
    # the side in view is the obstacle's own silhouette (within a voxel); the side at the edge is not
    inner, outer = (max(lats), min(lats)) if cut < 0 else (min(lats), max(lats))
    assert abs((s.high if cut < 0 else s.low) - inner) < 0.1
    assert abs((s.low if cut < 0 else s.high) - outer) > 0.15


def test_a_wall_across_the_whole_view_is_cut_on_both_sides():
    s = _sides((np.array([3.03, -4.0, 0.0]), np.array([3.33, 4.0, 2.0])))
    assert s.cut == 2


def test_too_few_points_give_no_sides():
    assert view_sides(np.zeros((2, 3)), K, T, 10, 0.1) is None


def _walk(cfg, y0, vy, seconds, x=3.03, rate=30.0):
    """A 0.5 m walker at x walking along y from y0 at vy, seen by a still camera: per frame, the
    (stamp, true y, the walker's track) with the track the one nearest the walker (None if none
    within 0.8 m)."""
    pipe = DODT(cfg)
    out = []
    for i in range(int(seconds * rate)):
        t = i / rate
        y = y0 + vy * t
        depth = render_depth(K, T, [_box(x, y)])
        r = pipe.process(SensorFrame(stamp=t, seq=i, depth=depth, color=None, T_world_camera=T, intrinsics=K))
        near = [o for o in r.obstacles if np.hypot(o.center[0] - x - 0.1, o.center[1] - y) < 0.8]
        out.append((t, y, min(near, key=lambda o: abs(o.center[1] - y)) if near else None))
    return out


@pytest.mark.parametrize("vy", [1.0, pytest.param(-1.0, marks=pytest.mark.slow)])  # -1: the mirror image
def test_a_walker_leaving_the_view_sideways_is_measured_from_its_side_in_view_and_predicted_on(vy):
    # from 1.2 m inside the view to 1.2 m beyond its edge
    x = 3.03
    edge_y = np.sign(vy) * EDGE * x
    seconds = 2.4 / abs(vy)
    side = _walk(DODTConfig(), edge_y - np.sign(vy) * 1.2, vy, seconds)
    plain = _walk(DODTConfig(kalman=replace(DODTConfig().kalman, cut_half_width=0.0)), edge_y - np.sign(vy) * 1.2,
                  vy, seconds)

    def errors(run):
        """(lateral error at the last measured frame, lateral error of the coasting prediction 0.5 s on)"""
        seen = [(t, y, o) for t, y, o in run if o is not None and not o.coasting]
        t_last, y_last, o_last = seen[-1]
        after = [(t, y, o) for t, y, o in run if t >= t_last + 0.5 - 1e-9 and o is not None]
        assert after, "the track coasts on after the walker left the view"
        t, y, o = after[0]
        return abs(o_last.center[1] - y_last), abs(o.center[1] - y)

    last_side, on_side = errors(side)
    last_plain, on_plain = errors(plain)
    # the centre of the cut box's part in view slides at about half the walker's speed: the plain
    # track falls behind its walker, and stays behind as it coasts
    assert last_plain > 0.2 and on_plain > 0.25
    assert last_side < 0.05 and on_side < 0.15


def test_a_walker_coming_into_view_is_placed_from_its_side_in_view():
    x, vy = 3.03, -1.0  # from beyond the left edge (+y) into the view
    y0 = EDGE * x + 0.4
    side = _walk(DODTConfig(), y0, vy, 0.8)
    plain = _walk(DODTConfig(kalman=replace(DODTConfig().kalman, cut_half_width=0.0)), y0, vy, 0.8)

    def mean_error(run):
        """mean lateral error over the first 0.4 s of the track"""
        first = next(t for t, _, o in run if o is not None)
        return np.mean([abs(o.center[1] - y) for t, y, o in run if first <= t <= first + 0.4 and o is not None])

    assert mean_error(side) < 0.15
    assert mean_error(plain) - mean_error(side) > 0.1
