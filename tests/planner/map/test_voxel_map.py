"""planner.map.voxel_map: insertion, free-space carving, dynamic clearing, bad depth, queries, determinism."""
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "dodt"))  # tests/dodt/synthetic.py

from dodt.frames import CameraIntrinsics  # noqa: E402
from planner.map.voxel_map import MapConfig, VoxelMap  # noqa: E402
from synthetic import camera_pose, render_depth  # noqa: E402

K = CameraIntrinsics()
T = camera_pose()  # at (0, 0, 1.2), looking along +x
SMALL = MapConfig(origin=(-2.0, -4.0, -0.1), size=(10.0, 8.0, 3.0))
# Off the 0.1 m grid, so that no face lies on a voxel boundary.
WALL = (np.array([3.03, -3.97, 0.0]), np.array([3.33, 3.97, 2.6]))


def _pts(xs, ys, zs):
    return np.array([(x, y, z) for x in xs for y in ys for z in zs], float)


def _feed(m, boxes, n, **kw):
    d = render_depth(K, T, boxes)
    for _ in range(n):
        out = m.update(d, K, T, **kw)
    return out


def test_wall_is_inserted_space_before_it_carved_and_behind_it_unknown():
    m = VoxelMap(SMALL)
    out = _feed(m, [WALL], 5)
    assert out["rays"] > 50000 and out["hits"] > 40000 and out["bad_pixels"] == 0
    surface = _pts([3.08], np.linspace(-1.0, 1.0, 9), np.linspace(0.5, 2.0, 7))
    assert m.is_occupied(surface).all()
    between = _pts(np.linspace(0.6, 2.9, 12), np.linspace(-0.3, 0.3, 3), [1.0, 1.2, 1.5])
    assert m.is_free(between).all() and not m.is_occupied(between).any()
    behind = _pts([3.2, 3.6, 4.5], np.linspace(-1.0, 1.0, 5), [0.5, 1.2, 2.0])
    assert m.is_unknown(behind).all()
    # One frame is not yet enough (a single hit on an unknown voxel leaves it below p_occ).
    m1 = VoxelMap(SMALL)
    _feed(m1, [WALL], 1)
    assert not m1.is_occupied(surface).any()


class _Pixel:
    """Duck-typed intrinsics of a 1x1 image whose only pixel looks along (a, b, 1) in the optical frame."""

    def __init__(self, a, b):
        self.fx = self.fy = 100.0
        self.cx, self.cy = -100.0 * a, -100.0 * b
        self.width = self.height = 1


@pytest.mark.parametrize("seed", range(5))
def test_one_ray_carves_exactly_the_voxels_it_crosses(seed):
    rng = np.random.default_rng(seed)
    m = VoxelMap(MapConfig(origin=(-5.0, -5.0, -0.1), size=(10.0, 10.0, 3.0), skip_pixel=1, margin=0))
    a, b = rng.uniform(-0.8, 0.8), rng.uniform(-0.3, 0.3)  # the end stays inside the map
    Tc = camera_pose(x=rng.uniform(-0.5, 0.5), y=rng.uniform(-0.5, 0.5), z=rng.uniform(1.0, 1.4),
                     yaw=rng.uniform(-np.pi, np.pi))
    depth = np.array([[rng.uniform(1.0, 2.5)]], np.float32)
    out = m.update(depth, _Pixel(a, b), Tc)
    assert out["rays"] == 1 and out["hits"] == 1
    end = Tc[:3, :3] @ (np.array([a, b, 1.0]) * float(depth[0, 0])) + Tc[:3, 3]
    s = np.linspace(0.0, 1.0, 400001)[:, None]
    crossed = {tuple(v) for v in np.floor((Tc[:3, 3] + s * (end - Tc[:3, 3]) - m.origin) / m.res).astype(int)}
    touched = {tuple(v) for v in np.argwhere(m.log_odds > m.l_unknown)}
    assert touched == crossed
    i, j, k = np.floor((end - m.origin) / m.res).astype(int)
    assert m.log_odds[i, j, k] == np.float32(m.l_unknown + m.l_hit)  # the end: one hit
    others = [v for v in touched if v != (i, j, k)]
    assert all(m.log_odds[v] == np.float32(m.l_min) for v in others)  # the rest: seen free


STATIC = (np.array([3.53, 0.83, 0.0]), np.array([3.93, 1.23, 1.0]))
FAR_WALL = (np.array([4.53, -3.97, 0.0]), np.array([4.83, 3.97, 2.6]))
WALKER_SIZE = np.array([0.5, 0.5, 1.7])


def _walk(with_boxes, frames=24):
    m = VoxelMap(SMALL)
    for f in range(frames):
        c = np.array([2.53, -1.2 + 2.4 * f / (frames - 1), 0.85])
        d = render_depth(K, T, [(c - WALKER_SIZE / 2, c + WALKER_SIZE / 2), STATIC, FAR_WALL])
        out = m.update(d, K, T, dynamic_boxes=[(c, WALKER_SIZE)] if with_boxes else ())
    band = m.occupied_centers([2.2, -1.5, 0.15], [2.85, 1.0, 1.8])  # past positions, not the last one
    return m, band, out


@pytest.mark.slow
def test_dynamic_clearing_leaves_no_trail_but_keeps_static_obstacles():
    m, band, out = _walk(with_boxes=True)
    assert len(band) == 0
    assert out["skipped_in_dynamic"] > 1000
    assert m.is_occupied([[3.58, 1.03, 0.5], [3.58, 0.93, 0.2]]).all()  # the static box's face
    assert m.is_occupied(_pts([4.58], [-1.0, 0.0, 1.0], [1.5, 2.0])).all()  # the wall (within 5 m)
    m0, band0, out0 = _walk(with_boxes=False)
    assert len(band0) > 20  # without the boxes the walker leaves a trail
    assert out0["skipped_in_dynamic"] == 0
    assert m0.is_occupied([[3.58, 1.03, 0.5]]).all()


def _walk_past_static(static_after, seen_before=20, frames=12, protect_before=3):
    """A walker brushing the static box's front face after the box was seen for ``seen_before`` updates."""
    m = VoxelMap(MapConfig(origin=SMALL.origin, size=SMALL.size, static_after=static_after,
                           protect_before=protect_before))
    _feed(m, [STATIC, FAR_WALL], seen_before)
    for f in range(frames):  # along the face at x = 3.53, its box (+ margin) reaching 0.2 m into the box
        c = np.array([3.08, 0.2 + 1.4 * f / (frames - 1), 0.85])
        d = render_depth(K, T, [(c - WALKER_SIZE / 2, c + WALKER_SIZE / 2), STATIC, FAR_WALL])
        m.update(d, K, T, dynamic_boxes=[(c, WALKER_SIZE)])
    return m


def test_a_walker_passing_a_long_seen_obstacle_does_not_erase_it():
    face = _pts([3.58], [0.93, 1.03, 1.13], [0.3, 0.6, 0.9])  # the face's voxels inside the walker's region
    assert np.all(_walk_past_static(15).is_occupied(face))
    assert not np.any(_walk_past_static(0, protect_before=0).is_occupied(face))  # the reference rule frees them
    # occupied (after its first five updates' hits) a few updates before the walker came, younger than
    # static_after: kept all the same, since it was there before the walker's region reached it (without
    # that rule, freed)
    assert np.all(_walk_past_static(15, seen_before=9).is_occupied(face))
    assert not np.any(_walk_past_static(15, seen_before=9, protect_before=0).is_occupied(face))


def test_structure_beside_a_person_from_the_start_stays_unknown_until_seen():
    """A walker stands by the static box's front face from the first frame, so the face inside the walker's
    region was never seen: it stays unknown (neither occupied nor seen free, so the shield's unobserved rule
    keeps the drone out of it) while the walker stands there, and is inserted once the walker has left."""
    m = VoxelMap(SMALL)
    c = np.array([3.08, 0.45, 0.85])  # beside the face, not hiding it: its region reaches y = 1.0
    walker = (c - WALKER_SIZE / 2, c + WALKER_SIZE / 2)
    face = _pts([3.58], [0.88, 0.93], [0.3, 0.6, 0.9])  # inside the walker's region (its box + 0.3 m)
    rng = np.random.default_rng(0)
    for _ in range(10):  # with depth noise: points behind the face, whose rays cross it, are in the region too
        d = render_depth(K, T, [walker, STATIC, FAR_WALL])
        d = np.where(d > 0, d + rng.normal(0.0, 0.03, d.shape), 0.0).astype(np.float32)
        out = m.update(d, K, T, dynamic_boxes=[(c, WALKER_SIZE)])
    assert out["skipped_in_dynamic"] > 0
    assert m.is_unknown(face).all()
    assert m.is_occupied(_pts([3.58], [1.13], [0.3, 0.6, 0.9])).all()  # the face outside the region
    for _ in range(m.cfg.dynamic_history + 5):  # the walker has gone
        m.update(render_depth(K, T, [STATIC, FAR_WALL]), K, T)
    assert m.is_occupied(face).all()


@pytest.mark.parametrize("window", [0, 2])
def test_a_hole_beside_returns_is_free_only_up_to_them(window):
    """Pixels without a return (0) in the middle of the wall's image: with map.hole_window they carve free
    space only up to a voxel short of the wall, and what lies behind the wall stays unknown; with 0 (the
    reference) each is a free ray of raycast_max through the wall."""
    m = VoxelMap(MapConfig(origin=SMALL.origin, size=SMALL.size, hole_window=window))
    d = render_depth(K, T, [WALL])
    holes = [(240, 320), (200, 300), (280, 360)]  # even pixels: sampled with skip_pixel 2
    for v, u in holes:
        d[v, u] = 0.0
    for _ in range(5):
        m.update(d, K, T)
    behind = []
    for v, u in holes:
        ray = T[:3, :3] @ np.array([(u - K.cx) / K.fx, (v - K.cy) / K.fy, 1.0])
        ray /= np.linalg.norm(ray)
        behind.append(T[:3, 3] + ray * (3.6 - T[0, 3]) / ray[0])  # 0.27 m behind the wall's back
    assert m.is_occupied(_pts([3.08], [-0.5, 0.0, 0.5], [1.0, 1.2, 1.4])).all()  # the wall itself either way
    assert m.is_unknown(behind).all() if window else m.is_free(behind).all()


def test_history_blocks_insertion_for_a_few_frames_only():
    box = (np.array([2.03, -0.27, 0.0]), np.array([2.43, 0.23, 1.5]))
    center, size = (box[0] + box[1]) / 2, box[1] - box[0]
    m = VoxelMap(SMALL)
    _feed(m, [box], 1, dynamic_boxes=[(center, size)])
    face = _pts([2.08], [-0.1, 0.1], [0.5, 1.0])
    for _ in range(m.cfg.dynamic_history - 1):  # the region is still in the history
        out = m.update(render_depth(K, T, [box]), K, T)
        assert out["skipped_in_dynamic"] > 0
    assert not m.is_occupied(face).any()
    out = _feed(m, [box], 5)  # history expired: the (now static) box is inserted
    assert out["skipped_in_dynamic"] == 0
    assert m.is_occupied(face).all()


N_SAMPLED = len(range(2, 478, 2)) * len(range(2, 638, 2))


@pytest.mark.parametrize("value, bad", [(0.0, False), (7.0, False), (np.nan, True), (np.inf, True),
                                        (-np.inf, True), (-1.0, True)])
def test_invalid_depth_is_counted_or_carved_free_never_raises(value, bad):
    m = VoxelMap(SMALL)
    out = m.update(np.full((480, 640), value, np.float32), K, T)
    assert m.occupied_count() == 0 and out["hits"] == 0
    ahead = _pts(np.linspace(0.5, 4.8, 10), [0.0], [1.2])
    far = _pts([5.3, 6.0], [0.0], [1.2])
    assert m.is_unknown(far).all()
    if bad:
        assert out["bad_pixels"] == N_SAMPLED and out["rays"] == 0
        assert m.is_unknown(ahead).all()
    else:  # no return / over range: a free ray of raycast_max (5 m)
        assert out["bad_pixels"] == 0 and out["rays"] == N_SAMPLED
        assert m.is_free(ahead).all()


def test_mixed_bad_pixels_and_close_pixels():
    d = render_depth(K, T, [WALL])
    d[:100] = np.nan
    d[100:150] = -0.5
    d[150:160] = np.inf
    d[200:210] = 0.1  # closer than depth_min: dropped, not bad
    m = VoxelMap(SMALL)
    out = m.update(d, K, T)
    assert out["bad_pixels"] == len(range(2, 160, 2)) * len(range(2, 638, 2))
    assert out["rays"] == N_SAMPLED - out["bad_pixels"] - len(range(200, 210, 2)) * len(range(2, 638, 2))


def test_obstacle_beyond_local_update_range_is_not_inserted():
    m = VoxelMap(MapConfig(origin=SMALL.origin, size=SMALL.size, local_update_range=(2.75, 5.0, 5.0)))
    _feed(m, [WALL], 5)
    assert not m.is_occupied(_pts([3.08], np.linspace(-1, 1, 5), [0.8, 1.2, 1.6])).any()
    assert len(m.occupied_centers([2.85, -4, 0.15], [6, 4, 3])) == 0
    assert m.is_free(_pts([1.0, 2.7], [0.0], [1.2])).all()
    assert m.is_unknown(_pts([2.85, 2.95], [0.0], [1.2])).all()  # the range ends at x = 2.8 m
    assert m.is_occupied([[2.45, 0.05, 0.05]]).all()  # the floor inside the range is inserted
    control = VoxelMap(SMALL)
    _feed(control, [WALL], 5)
    assert control.is_occupied(_pts([3.08], np.linspace(-1, 1, 5), [0.8, 1.2, 1.6])).all()


def _single(ijk=(50, 40, 12)):
    m = VoxelMap(SMALL)
    m.log_odds[ijk] = np.float32(m.l_max)
    return m, np.array(ijk)


def test_occupied_centers_in_an_aabb():
    m, ijk = _single()
    c = m.origin + (ijk + 0.5) * m.res
    m.log_odds[tuple(ijk + [5, 0, 0])] = np.float32(m.l_max)
    got = m.occupied_centers(c - 0.2, c + 0.2)
    assert got.shape == (1, 3) and got.dtype == np.float64 and np.allclose(got[0], c)
    assert len(m.occupied_centers(c - 0.2, c + 0.6)) == 2
    assert len(m.occupied_centers(c + 0.06, c + 0.4)) == 0  # centre outside the box
    assert len(m.occupied_centers([-100, -100, -100], [100, 100, 100])) == 2 == m.occupied_count()
    assert m.occupied_indices().tolist() == [list(ijk), list(ijk + [5, 0, 0])]
    walled = VoxelMap(SMALL)
    _feed(walled, [WALL], 4)
    lo, hi = np.array([2.9, -1.0, 0.5]), np.array([3.5, 1.0, 2.0])
    got = walled.occupied_centers(lo, hi)
    assert len(got) > 100 and walled.is_occupied(got).all()
    assert ((got >= lo) & (got <= hi)).all()


def test_column_blocked_inflation_widens_a_single_column():
    m, ijk = _single()
    z = m.origin[2] + (ijk[2] + 0.5) * m.res
    plain = m.column_blocked(z - 0.3, z + 0.3, inflate=False)
    assert plain.shape == tuple(m.dims[:2]) and plain.sum() == 1 and plain[ijk[0], ijk[1]]
    infl = m.column_blocked(z - 0.3, z + 0.3)
    rx, ry, rz = m.inflation
    assert (rx, ry, rz) == (3, 3, 2)  # ceil(robot_size / (2 res)), reference
    expect = np.zeros_like(infl)
    expect[ijk[0] - rx:ijk[0] + rx + 1, ijk[1] - ry:ijk[1] + ry + 1] = True
    assert np.array_equal(infl, expect)
    # Inflation in z: a voxel 2 layers under the band blocks it, 3 layers under does not.
    assert m.column_blocked(z + 0.2, z + 0.5).sum() == expect.sum()
    assert not m.column_blocked(z + 0.3, z + 0.6).any()
    assert not m.column_blocked(z + 0.1, z + 0.5, inflate=False).any()
    cell = m.world_to_cell(m.cell_to_world([ijk[:2]]))
    assert np.array_equal(cell[0], ijk[:2])
    assert np.array_equal(m.world_to_cell(m.xy_origin + [0.05, 0.15]), [[0, 1]])
    c = m.origin + (ijk + 0.5) * m.res
    near = np.array([c + [0.3, 0.3, 0.2], c + [0.4, 0.0, 0.0], c + [0.0, 0.0, 0.3]])
    assert m.inflated_occupied(near).tolist() == [True, False, False]


def test_points_outside_the_map():
    m, ijk = _single((0, 0, 0))
    out = np.array([[-2.05, -3.95, 0.0], [100.0, 0, 1], [0, 0, -0.2], [0, 0, 2.95], [np.nan, 0, 1],
                    [np.inf, 0, 1]])
    assert not m.is_occupied(out).any() and not m.is_free(out).any()
    assert m.is_unknown(out).all()
    assert not m.inflated_occupied(out).any()
    assert m.is_occupied([[-1.95, -3.95, -0.05]]).all()


def test_same_frames_give_bit_identical_log_odds_and_reset_forgets():
    rng = np.random.default_rng(7)
    frames = []
    for f in range(6):
        c = np.array([2.53, -1.0 + 0.2 * f, 0.85])
        d = render_depth(K, T, [(c - WALKER_SIZE / 2, c + WALKER_SIZE / 2), STATIC, WALL])
        d = (d * (1 + 0.01 * rng.standard_normal(d.shape))).astype(np.float32)
        d[rng.random(d.shape) < 0.02] = np.nan
        frames.append((d, c))
    a, b = VoxelMap(SMALL), VoxelMap(SMALL)
    for m in (a, b):
        for d, c in frames:
            m.update(d, K, T, dynamic_boxes=[(c, WALKER_SIZE)])
    assert a.log_odds.dtype == np.float32 and a.log_odds.tobytes() == b.log_odds.tobytes()
    b.reset()
    assert b.occupied_count() == 0 and b.is_unknown(_pts([1.0], [0.0], [1.2])).all()
    for d, c in frames:
        b.update(d, K, T, dynamic_boxes=[(c, WALKER_SIZE)])
    assert a.log_odds.tobytes() == b.log_odds.tobytes()


def test_config_rejects_nonsense():
    with pytest.raises(ValueError, match="p_min"):
        MapConfig(p_occ=0.99)
    with pytest.raises(ValueError, match="resolution"):
        MapConfig(resolution=0.0)


def _uncarved_fraction(m):
    """Share of voxel centres in the camera frustum in front of WALL that are still unknown."""
    c = m.origin + (np.argwhere(np.ones(m.dims, bool)) + 0.5) * m.res
    pc = (c - T[:3, 3]) @ T[:3, :3]  # optical frame
    z = np.maximum(pc[:, 2], 1e-9)
    u, v = K.fx * pc[:, 0] / z + K.cx, K.fy * pc[:, 1] / z + K.cy
    ok = (pc[:, 2] > 0.3) & (c[:, 0] < 2.95) & (c[:, 2] > 0.1) & (u > 4) & (u < 635) & (v > 4) & (v < 475)
    return float(np.mean(m.is_unknown(c[ok])))


def test_ray_bundles_carve_the_whole_frustum_where_the_reference_stop_rule_leaves_holes():
    ours, ref = VoxelMap(SMALL), VoxelMap(MapConfig(origin=SMALL.origin, size=SMALL.size, ray_bundle_px=0))
    _feed(ours, [WALL], 5)
    _feed(ref, [WALL], 5)
    assert _uncarved_fraction(ours) == 0.0
    assert _uncarved_fraction(ref) > 0.3  # a static camera sees the same holes every frame
    # Nearly the same occupied voxels: ours loses a few floor voxels seen at grazing angles.
    assert abs(ours.occupied_count() - ref.occupied_count()) < 0.03 * ref.occupied_count()
    surface = _pts([3.08], np.linspace(-1.0, 1.0, 9), np.linspace(0.5, 2.0, 7))
    assert ours.is_occupied(surface).all() and ref.is_occupied(surface).all()


def test_camera_outside_the_map_or_a_bad_pose_casts_nothing():
    d = render_depth(K, T, [WALL])
    d[:10] = np.nan
    m = VoxelMap(SMALL)
    for pose in (camera_pose(x=-5.0), np.full((4, 4), np.nan)):
        out = m.update(d, K, pose, dynamic_boxes=[(np.full(3, np.nan), np.ones(3))])
        assert out["rays"] == 0 and out["bad_pixels"] == len(range(2, 10, 2)) * len(range(2, 638, 2))
    assert not m.is_free(_pts(np.linspace(0.5, 2.9, 5), [0.0], [1.2])).any()
    assert m.update(d, K, T)["rays"] > 0  # and the next good frame is cast as usual


def test_established_fraction_counts_long_held_columns_only():
    box = (np.array([2.03, -0.27, 0.0]), np.array([2.43, 0.23, 1.5]))
    m = VoxelMap(SMALL)
    _feed(m, [box], 3)
    on_face = (np.array([2.1, 0.0, 0.8]), np.array([0.2, 0.4, 1.0]))  # straddles the seen face
    assert m.established_fraction(*on_face) == 0.0  # occupied, but for 3 updates only
    _feed(m, [box], m.cfg.static_after + 5)  # (a voxel turns occupied after a few hits)
    share = m.established_fraction(*on_face)
    assert 0.2 <= share <= 0.8  # the face column row, not the free space in front of it
    assert m.established_fraction(np.array([1.0, 0.0, 0.8]), np.array([0.4, 0.4, 1.0])) == 0.0  # free space
    assert m.established_fraction(np.array([np.nan, 0.0, 0.8]), np.array([0.4, 0.4, 1.0])) == 0.0


def test_known_geometry_replaces_the_map_and_is_never_cleared():
    m = VoxelMap(MapConfig(origin=(0.0, 0.0, 0.0), size=(2.0, 2.0, 1.0)))
    occ = np.zeros(tuple(m.dims), bool)
    occ[5:8, 5:8, 0:6] = True
    m.set_known(occ)
    assert m.occupied_count() == occ.sum()
    assert m.is_occupied(np.array([[0.65, 0.65, 0.3]]))[0] and m.is_free(np.array([[1.5, 1.5, 0.3]]))[0]
    assert not m.is_unknown(np.array([[1.5, 1.5, 0.3]]))[0]
    # known voxels count as established: a dynamic box over them frees nothing
    m.update(np.zeros((16, 16), np.float32), CameraIntrinsics(16, 16, 8.0, 8.0, 8.0, 8.0),
             np.eye(4), dynamic_boxes=[(np.array([0.65, 0.65, 0.3]), np.array([0.4, 0.4, 0.6]))])
    assert m.is_occupied(np.array([[0.65, 0.65, 0.3]]))[0]
    assert m.established_fraction(np.array([0.65, 0.65, 0.3]), np.array([0.3, 0.3, 0.6])) == 1.0
    with pytest.raises(ValueError, match="set_known"):
        m.set_known(np.zeros((3, 3, 3), bool))


def test_column_blocked_follows_the_map_and_is_shared_read_only():
    m, ijk = _single()
    z = m.origin[2] + (ijk[2] + 0.5) * m.res
    first = m.column_blocked(z - 0.3, z + 0.3)
    assert m.column_blocked(z - 0.3, z + 0.3) is first  # the same map: computed once
    with pytest.raises(ValueError):
        first[0, 0] = True  # shared by every caller: not to be edited
    m.set_known(np.zeros(m.log_odds.shape, bool))  # the map changes: so does the answer
    assert not m.column_blocked(z - 0.3, z + 0.3).any() and first.any()


@pytest.mark.parametrize("history", [1, 6])
def test_dynamic_regions_free_and_hold_voxels_as_the_whole_grid_rule_says(history):
    """The region bookkeeping, worked out inside the regions' box, against the rule applied to the whole
    grid: boxes that move, vanish and come back over voxels occupied for different lengths of time."""
    cfg = MapConfig(size=(6.0, 6.0, 2.0), origin=(-3.0, -3.0, -0.1), static_after=8, protect_before=3,
                    dynamic_history=history)
    m = VoxelMap(cfg)
    rng = np.random.default_rng(4)
    occupied = rng.random(m.log_odds.shape) < 0.2
    m.log_odds[occupied] = np.float32(m.l_max)
    m.log_odds[~occupied & (rng.random(m.log_odds.shape) < 0.5)] = np.float32(m.l_min)  # seen free; the rest unknown
    m._since[...] = rng.integers(0, 12, m.log_odds.shape)
    m._updates = 10
    log_odds, held, covered = m.log_odds.copy(), np.zeros_like(occupied), np.zeros_like(occupied)
    bad_pose = np.full((4, 4), np.nan)  # nothing is cast: only the regions act
    K = CameraIntrinsics(8, 6, 5.0, 5.0, 4.0, 3.0)
    for step in range(14):
        boxes = [((rng.uniform(-3.5, 3.5), rng.uniform(-3.5, 3.5), 0.9), (0.5, 0.5, 1.8))
                 for _ in range(rng.integers(0, 3))]
        if step == 6:
            boxes.append(((np.nan, 0.0, 0.9), (0.5, 0.5, 1.8)))  # a bad box: no region
        m.update(np.zeros((6, 8), np.float32), K, bad_pose, boxes)
        cover = np.zeros_like(occupied)
        for c, s in boxes:
            r = m._region(c, s)
            cover[r[0]:r[3] + 1, r[1]:r[4] + 1, r[2]:r[5] + 1] = True
        occ = log_odds >= m.l_occ
        first = cover & ~covered
        held[first] = occ[first] & (m._updates - m._since[first] >= cfg.protect_before)
        held &= cover
        covered = cover
        established = (occ & (m._updates - m._since >= cfg.static_after)) | held
        log_odds[cover & ~established & (log_odds > m.l_unknown)] = np.float32(m.l_min)  # unknown stays unknown
        np.testing.assert_array_equal(m.log_odds, log_odds)
        np.testing.assert_array_equal(m._held, held)
        np.testing.assert_array_equal(m._covered, covered)
        assert not m._protection.any()
    assert np.any(held) and np.any(occupied & (log_odds == m.l_min))  # both rules were exercised
    assert np.any(~occupied & (log_odds == m.l_unknown))  # unknown voxels under regions among them


@pytest.mark.parametrize("height", [3.0, 6.4, 7.0])
def test_column_bands_and_occupied_centres_equal_the_direct_computations(height):
    """Bands from the columns' bits (up to 64 voxels high) or scanned (higher), and the compiled centres,
    against the plain numpy definitions."""
    import cv2

    from planner.map.voxel_map import _column_any

    rng = np.random.default_rng(0)
    m = VoxelMap(MapConfig(origin=(-1, -1, -0.1), size=(2.0, 1.5, height)))
    m.set_known(rng.random(m.log_odds.shape) < 0.05)
    nz = int(m.dims[2])
    for k0 in range(-1, nz + 1, 3):
        for k1 in range(k0 - 1, nz + 2, 2):
            for inflate in (False, True):
                r = m.inflation if inflate else np.zeros(3, int)
                a, b = max(k0 - r[2], 0), min(k1 + r[2], nz - 1)
                want = _column_any(m.log_odds, m.l_occ, a, b) if b >= a else np.zeros(m.log_odds.shape[:2], bool)
                if inflate and b >= a:
                    want = cv2.dilate(want.view(np.uint8), np.ones((2 * r[0] + 1, 2 * r[1] + 1), np.uint8)).view(bool)
                got = m.column_blocked(-0.05 + 0.1 * k0, -0.05 + 0.1 * k1, inflate=inflate)
                np.testing.assert_array_equal(got, want)
    for _ in range(30):
        lo = rng.uniform(-2, 2, 3)
        hi = lo + rng.uniform(-0.5, 3, 3)
        a, b = m._centre_range(lo, hi)
        want = np.zeros((0, 3)) if np.any(b <= a) else \
            m.origin + (np.argwhere(m.log_odds[a[0]:b[0], a[1]:b[1], a[2]:b[2]] >= m.l_occ) + a + 0.5) * m.res
        np.testing.assert_array_equal(m.occupied_centers(lo, hi), want)


def test_column_unobserved_equals_the_direct_computation():
    """The compiled scan of never-observed voxels against the plain numpy definition, every band."""
    rng = np.random.default_rng(1)
    m = VoxelMap(MapConfig(origin=(-1, -1, -0.1), size=(2.0, 1.5, 3.0)))
    m.set_known(rng.random(m.log_odds.shape) < 0.05)
    m.log_odds[rng.random(m.log_odds.shape) < 0.3] = m.l_unknown
    m.version += 1
    nz = int(m.dims[2])
    checked = 0
    for k0 in range(-2, nz + 2):
        for k1 in range(k0 - 1, nz + 2, 3):
            a, b = max(k0, 0), min(k1, nz - 1)
            want = np.any(m.log_odds[:, :, a:b + 1] <= m.l_unknown, axis=2) if b >= a else np.zeros(
                m.log_odds.shape[:2], bool)
            got = m.column_unobserved(-0.05 + 0.1 * k0, -0.05 + 0.1 * k1)
            np.testing.assert_array_equal(got, want)
            checked += bool(want.any()) and not want.all()
    assert checked > 10  # bands with some columns unobserved and some not


def test_several_views_are_one_update_each_view_cast_in_turn():
    back = camera_pose(yaw=np.pi)
    behind = (np.array([-1.83, -3.97, 0.0]), np.array([-1.53, 3.97, 2.6]))  # off the grid, as WALL
    d_front, d_back = render_depth(K, T, [WALL]), render_depth(K, back, [behind])
    one, views = VoxelMap(SMALL), VoxelMap(SMALL)
    for _ in range(3):
        a = one.update(d_front, K, T)
        b = views.update_views([(d_front, K, T)])
    assert np.array_equal(one.log_odds, views.log_odds) and a.keys() == b.keys()
    for _ in range(6):
        out = views.update_views([(d_front, K, T), (d_back, K, back)])
    assert views._updates == 9  # one update for both views
    assert out["hits"] > a["hits"]
    assert views.is_occupied(np.array([[3.1, 0.05, 1.0], [-1.58, 0.05, 1.0]])).all()
    assert views.is_free(np.array([[-1.0, 0.05, 1.0], [2.0, 0.05, 1.0]])).all()
