"""A walker leaving the camera's view at the side: its cut boxes must not turn its track's velocity
(dodt.tracker's update_cut, TrackConfig.edge_cut_px)."""
from dataclasses import replace

import numpy as np

from dodt.config import DODTConfig, TrackConfig
from dodt.frames import CameraIntrinsics, SensorFrame
from dodt.pipeline import DODT
from tests.dodt.synthetic import camera_pose, render_depth

K = CameraIntrinsics()
SIZE = np.array([0.4, 0.5, 1.7])


def _run(cfg: DODTConfig, y0: float = -1.2, vy: float = -1.0, frames: int = 85):
    """A box walking along -y at 3.5 m in front of a fixed camera, from the view's middle out of its right
    edge. Returns, per frame, the track's velocity nearest the box (or None) and the box's true centre."""
    p = DODT(cfg)
    T = camera_pose()
    out = []
    for k in range(frames):
        t = k / 30
        c = np.array([3.5, y0 + vy * t, SIZE[2] / 2])
        depth = render_depth(K, T, [(c - SIZE / 2, c + SIZE / 2)])
        r = p.process(SensorFrame(depth=depth, color=None, intrinsics=K, T_world_camera=T, stamp=t, seq=k))
        near = [o for o in r.obstacles if np.hypot(*(o.center[:2] - c[:2])) < 0.8]
        out.append((near[0].velocity[:2].copy() if near else None, c))
    return out


def test_a_walker_leaving_the_view_keeps_its_velocity():
    """The right edge of a 640 px D435 view 3.5 m out lies 3.3 m to the side, less the depth margin: the box
    (0.5 m wide) is cut from about y = -2.6 on. While it is cut and after, the track keeps heading -y at
    walking speed; with whole updates (edge_cut_px = 0) the visible part's shrinking turns the velocity
    toward the middle of the view (measured: 0.64 m/s across the walk)."""
    cfg = DODTConfig()
    kept = _run(cfg)
    plain = _run(replace(cfg, track=replace(cfg.track, edge_cut_px=0)))
    last = [v for v, c in kept if v is not None and c[1] < -2.5]
    last0 = [v for v, c in plain if v is not None and c[1] < -2.5]
    assert last and last0  # tracked while cut, both ways
    err = max(np.linalg.norm(v - np.array([0.0, -1.0])) for v in last)
    err0 = max(np.linalg.norm(v - np.array([0.0, -1.0])) for v in last0)
    assert err < 0.3 and err0 > 0.45
    whole = [v for v, c in kept if v is not None and -2.3 < c[1] < -1.5]
    assert all(np.linalg.norm(v - np.array([0.0, -1.0])) < 0.25 for v in whole)  # measured well before


def test_a_walker_entering_the_view_is_measured_from_its_cut_boxes():
    """Entering at the side, a young track has no velocity to keep: its cut boxes update it whole and it
    reaches walking speed before the walker is wholly in view."""
    out = _run(DODTConfig(), y0=-3.6, vy=1.0, frames=25)
    v = [v for v, c in out if v is not None and c[1] < -2.9]
    assert v and v[-1][1] > 0.5
