"""The simulated LiDAR (sim.lidar): geometry against known bodies, limits, dropouts, determinism, and the
world's scans (walkers included; scanning leaves the world's run unchanged)."""
import math

import numpy as np
import pytest

from conftest import gl_available, make_scenario
from dodt.context import LidarSensor
from sim import World
from sim.camera import quiet_stdout
from sim.controller import Reference
from sim.lidar import (LidarModel, cast_rays, dropout_probability, ray_directions, scan_directions, simulate_scan,
                       top_mount)
from sim.lidar_panorama import PanoramaCaster
from sim.rig import rig

with quiet_stdout():
    import pybullet as p

MODEL = LidarModel()
METHODS = ["rays", pytest.param("panorama", marks=pytest.mark.skipif(not gl_available(), reason="no OpenGL here"))]


@pytest.fixture
def client():
    with quiet_stdout():
        c = p.connect(p.DIRECT)
    yield c
    p.disconnect(physicsClientId=c)


def add_box(client, centre, half_extents, yaw=0.0):
    """A static box, collision and visual shape alike (rays hit the one, the gl renderer draws the other)."""
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=list(half_extents), physicsClientId=client)
    look = p.createVisualShape(p.GEOM_BOX, halfExtents=list(half_extents), physicsClientId=client)
    return p.createMultiBody(0, shape, look, basePosition=list(centre),
                             baseOrientation=p.getQuaternionFromEuler([0.0, 0.0, yaw]), physicsClientId=client)


def room(client, half):
    """Six walls 0.1 m thick, their inner faces ``half`` m from the origin, overlapping at the edges."""
    for axis in range(3):
        for side in (-1.0, 1.0):
            centre, size = [0.0, 0.0, 0.0], [half + 0.1] * 3
            centre[axis], size[axis] = side * (half + 0.05), 0.05
            add_box(client, centre, size)


def pose(xyz=(0.0, 0.0, 0.0), yaw=0.0):
    T = np.eye(4)
    c, s = math.cos(yaw), math.sin(yaw)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = xyz
    return T


def scan(client, T=None, model=MODEL, seed=0, index=0):
    return simulate_scan(client, pose() if T is None else T, model, np.random.default_rng(seed), index)


def test_a_wall_at_a_known_distance_gives_ranges_within_the_noise(client):
    add_box(client, [5.05, 0.0, 0.0], [0.05, 20.0, 20.0])  # its face at x = 5, seen from the origin
    s = scan(client, pose(yaw=0.3))  # the sensor turned: the points are in its frame, the wall in the world's
    world = s.points_world()
    d = ray_directions(s.azimuth.astype(np.float64), s.elevation.astype(np.float64)) @ pose(yaw=0.3)[:3, :3].T
    assert len(s) > 5000 and np.all(d[:, 0] > 0)
    residual = s.ranges - 5.0 / d[:, 0]  # measured minus true range along each ray
    assert abs(residual.mean()) < 0.002 and 0.018 < residual.std() < 0.022
    assert np.abs(world[:, 0] - 5.0).max() < 6 * MODEL.range_std
    np.testing.assert_allclose(np.linalg.norm(s.points, axis=1), s.ranges, rtol=1e-6)


def test_the_floor_lies_where_it_is_and_nothing_comes_from_the_open_sky(client):
    add_box(client, [0.0, 0.0, -0.05], [60.0, 60.0, 0.05])  # floor top at z = 0
    T = pose((0.0, 0.0, 1.3))
    s = scan(client, T)
    z = s.points_world()[:, 2]
    assert len(s) > 500 and np.all(s.elevation < 0)  # only rays below the horizon return
    assert np.abs(z).max() < 6 * MODEL.range_std * math.sin(-MODEL.elevation_min)
    # every ray below the horizon meets the floor within range; the misses are the grazing dropouts
    below = scan_directions(MODEL, 0)[1] < -math.asin(1.3 / MODEL.max_range)
    assert len(s) <= below.sum()


def test_the_blind_zone_hides_what_is_behind_it_and_nothing_beyond_max_range_returns(client):
    add_box(client, [0.10, 0.0, 0.0], [0.05, 0.05, 0.05])  # its face 5 cm ahead: inside the blind zone
    add_box(client, [5.05, 0.0, 0.0], [0.05, 20.0, 20.0])  # a wall behind it
    add_box(client, [-45.05, 0.0, 0.0], [0.05, 60.0, 60.0])  # a wall beyond range, behind the sensor
    add_box(client, [0.0, 39.55, 0.0], [60.0, 0.05, 60.0])  # a wall just inside range, to the left
    s = scan(client)
    assert len(s) > 1000
    assert s.ranges.min() >= MODEL.min_range and s.ranges.max() <= MODEL.max_range
    ahead = s.points[:, 0] > 0
    # the near box (x from 0.05 m, +-0.05 m across) hides the wall within 45 deg of the x axis
    hidden = ahead & (np.abs(s.points[:, 1]) < 0.9 * s.points[:, 0]) & (np.abs(s.points[:, 2]) < 0.9 * s.points[:, 0])
    assert not hidden.any()
    assert np.all(s.points[:, 0] > -40.0)  # nothing from the far wall
    assert (s.points[:, 1] > 39.0).any()  # the wall at 39.5 m returns


def test_the_same_seed_gives_the_same_scan_and_the_pattern_moves_on_with_the_scan_index(client):
    inside = pose((0.5, -0.5, 0.2))
    room(client, 5.0)
    a, b = scan(client, inside, seed=3), scan(client, inside, seed=3)
    for f in ("points", "ranges", "azimuth", "elevation", "T_world_sensor"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
    other_seed = scan(client, inside, seed=4)
    np.testing.assert_array_equal(other_seed.azimuth, a.azimuth)  # the same rays, other noise
    assert not np.array_equal(other_seed.ranges, a.ranges)
    next_scan = scan(client, inside, seed=3, index=1)
    assert not np.array_equal(next_scan.elevation, a.elevation)  # the beams sweep other lines
    # a closed room meets every ray well off grazing (at most 60 deg off the normal): every ray returns
    assert len(a) == a.n_rays == MODEL.points_per_scan == len(next_scan)


def test_the_pattern_keeps_to_the_field_of_view_and_fills_it_scan_after_scan():
    cells = set()
    for index in range(3):
        az, el = scan_directions(MODEL, index)
        assert len(az) == MODEL.points_per_scan
        assert MODEL.elevation_min <= el.min() < MODEL.elevation_min + math.radians(0.5)
        assert MODEL.elevation_max - math.radians(0.5) < el.max() <= MODEL.elevation_max
        assert -math.pi <= az.min() < -math.pi + 0.01 and math.pi - 0.01 < az.max() < math.pi
        one = set(zip(np.floor(np.degrees(az)).astype(int).tolist(), np.floor(np.degrees(el)).astype(int).tolist()))
        cells |= one
        if index == 0:
            assert 0.5 < len(one) / (360 * 59) < 0.7  # one scan leaves gaps at 1 deg ...
    assert len(cells) / (360 * 59) > 0.99  # ... that the next scans fill: the pattern does not repeat


def test_returns_lie_within_the_vertical_field_of_view(client):
    room(client, 30.0)
    s = scan(client, pose((1.0, 2.0, 0.5), yaw=1.0))
    r = np.linalg.norm(s.points.astype(np.float64), axis=1)
    el = np.arcsin(s.points[:, 2] / r)
    tol = 1e-5
    assert el.min() >= MODEL.elevation_min - tol and el.max() <= MODEL.elevation_max + tol
    assert el.min() < MODEL.elevation_min + 0.01 and el.max() > MODEL.elevation_max - 0.01
    sensor = LidarSensor(name="top", model=MODEL, T_body_sensor=top_mount(), rate=MODEL.scan_rate)
    inner = s.points * (1 - 1e-4)  # off the field's very edges, where float32 rounding decides
    assert sensor.in_view(inner[(el > MODEL.elevation_min + tol) & (el < MODEL.elevation_max - tol)]).all()
    assert not sensor.in_view([[1.0, 0.0, -0.2], [0.3, 0.0, 0.6], [0.05, 0.0, 0.0], [41.0, 0.0, 0.0]]).any()


def test_grazing_returns_drop_out_by_the_stated_rule(client):
    np.testing.assert_allclose(dropout_probability(MODEL, np.radians([0.0, 80.0, 84.5, 89.0, 90.0])),
                               [0.0, 0.0, 0.5, 1.0, 1.0])
    add_box(client, [0.0, 0.0, -0.05], [60.0, 60.0, 0.05])
    T = pose((0.0, 0.0, 1.0))
    # a sensor whose rays meet the floor at 30-60 deg of incidence: none drops out
    steep = LidarModel(elevation_min=math.radians(-60.0), elevation_max=math.radians(-30.0))
    assert len(scan(client, T, steep)) == steep.points_per_scan
    # 80-88 deg of incidence (elevation -10 to -2 deg): the kept share follows 1 - p, bin by bin
    grazing = LidarModel(elevation_min=math.radians(-10.0), elevation_max=math.radians(-2.0), points_per_scan=40_000)
    s = scan(client, T, grazing)
    _, el_all = scan_directions(grazing, 0)
    edges = np.radians([-10.0, -8.0, -6.0, -4.0, -2.0])
    for lo, hi in zip(edges[:-1], edges[1:]):
        rays = el_all[(el_all >= lo) & (el_all < hi)]
        expected = np.sum(1.0 - dropout_probability(grazing, math.pi / 2 + rays))  # incidence 90 deg - |el|
        kept = np.count_nonzero((s.elevation >= np.float32(lo)) & (s.elevation < np.float32(hi)))
        assert abs(kept - expected) < 4 * math.sqrt(len(rays) * 0.25) + 2, (math.degrees(lo), kept, expected)


@pytest.mark.skipif(not gl_available(), reason="the panorama draws with the gl renderer: no OpenGL here")
def test_the_panorama_finds_the_hits_the_rays_find(client):
    room(client, 6.0)
    add_box(client, [2.0, 1.0, -1.0], [0.5, 0.3, 1.0], yaw=0.4)  # a box turned in the room: edges, slanted faces
    T = pose((0.3, -0.2, 0.4), yaw=0.2)
    d = ray_directions(*scan_directions(MODEL, 0))
    ray_range, ray_normal = cast_rays((client,), T[:3, 3].copy(), d @ T[:3, :3].T, MODEL.max_range)
    caster = PanoramaCaster(p, client, MODEL)
    try:
        pano_range, pano_normal = caster(T, d, MODEL.max_range)
    finally:
        caster.release()
    assert np.isfinite(ray_range).all() and np.isfinite(pano_range).all()  # a closed room
    err = np.abs(pano_range - ray_range)
    # the same range to a millimetre but at the box's edges, where a pixel holds the one surface or the other
    assert np.mean(err < 1e-3) > 0.99 and np.median(err) < 1e-4
    same = err < 1e-3
    assert np.mean(np.einsum("ij,ij->i", pano_normal[same], ray_normal[same]) > 0.999) > 0.99


def test_model_values_are_checked():
    with pytest.raises(ValueError, match="min_range"):
        LidarModel(min_range=50.0)
    with pytest.raises(ValueError, match="elevation"):
        LidarModel(elevation_min=0.5, elevation_max=0.2)


# --------------------------------------------------------------------------- the world's LiDAR

def standing(height, xy):
    """A person standing at xy (a walk that starts after the test ends)."""
    return (f'[[people]]\nbehaviour = "crossing"\nspeed = 1.0\nheight = {height}\nstart_delay = 100.0\n'
            f'waypoints = [[{xy[0]}, {xy[1]}], [{xy[0] + 1.0}, {xy[1]}]]\n')


def scene():
    """The drone at x = 5 in the test corridor, one person 2 m behind it, one 1.4 m to its left."""
    return make_scenario(standing(1.8, (3.0, 0.2)) + standing(1.7, (5.3, 1.4))).with_values(
        {"drone.start": [5.0, 0.0, 1.2]})


@pytest.mark.parametrize("method", METHODS)
def test_the_worlds_scan_sees_walkers_behind_and_beside_the_drone(method):
    w = World(scene(), seed=0, camera=False, render=False)
    s = w.lidar_scan(method=method)
    assert (s.seq, s.stamp, s.n_rays) == (0, 0.0, MODEL.points_per_scan)
    np.testing.assert_allclose(s.T_world_sensor, w.T_world_body() @ top_mount())  # no odometry noise set
    pts = s.points_world()
    people = [o for o in w.obstacle_truth() if o.kind == "person"]
    assert len(people) == 2
    for o in people:  # the walker 2 m behind, and the one 1.4 m to the left
        inside = np.all((pts >= o.aabb_min - 0.05) & (pts <= o.aabb_max + 0.05), axis=1)
        assert inside.sum() > 50, (o.id, inside.sum())
    assert np.abs(pts[:, 1]).max() < 2.0 + 0.1  # the corridor's walls bound it
    assert w.lidar_scan(method=method).seq == 1
    w.close()


def _run(world, scan_every, method="rays"):
    out = []
    for k in range(36):
        f = world.step(Reference.hover([5.6, 0.6, 1.2]))
        if scan_every and k % scan_every == 0:
            out.append(world.lidar_scan(method=method).ranges)
        if f is not None:
            out.append((f.T_world_camera.tobytes(), f.stamp, [(o.id, o.aabb_min.tobytes()) for o in
                                                             world.ground_truth().obstacles]))
    st = world.state()
    return out, st.position.tobytes(), st.R.tobytes(), list(world.clearance_log), list(world.collisions)


@pytest.mark.parametrize("method", METHODS)
def test_scanning_changes_nothing_else_the_world_does(method):
    # odometry noise on, and the drone flown close to a walker, so that the query client is used for contacts
    sc = scene().with_values({"noise.odom_position_std": 0.01, "noise.odom_rotation_std": 0.002})
    plain = _run(World(sc, seed=2, camera=True, render=False), 0)
    scanned, scanned_again = (_run(World(sc, seed=2, camera=True, render=False), 3, method) for _ in range(2))
    frames = [x for x in scanned[0] if isinstance(x, tuple)]
    assert frames == plain[0] and scanned[1:] == plain[1:]
    assert plain[3] and min(r[2] for r in plain[3]) < 1.0  # a person was near enough to be measured
    scans = [x for x in scanned[0] if not isinstance(x, tuple)]
    scans_again = [x for x in scanned_again[0] if not isinstance(x, tuple)]
    assert len(scans) == 12 and all(np.array_equal(a, b) for a, b in zip(scans, scans_again))


@pytest.mark.parametrize("method", METHODS)
def test_flying_at_head_height_a_lidar_under_the_body_sees_the_person_beside_it_one_on_top_does_not(method):
    """The drone at 1.6 m, a 1.65 m person 0.8 m to its left: on top (1.72 m up, -7 deg at the lowest) the
    field passes over their head; upside down under the body (1.48 m up, -52 to +7 deg) it holds them from
    the floor up, and no ray meets the drone's own box."""
    sc = make_scenario(standing(1.65, (5.0, 0.8))).with_values({"drone.start": [5.0, 0.0, 1.6]})
    w = World(sc, seed=0, camera=False, render=False)
    person = next(o for o in w.obstacle_truth() if o.kind == "person")
    counts = {}
    for name in ("lidar", "lidar_below"):
        mount = next(m for m in rig(name) if m.kind == "lidar")
        s = w.lidar_scan(mount.lidar_model(), mount.T_body_lidar(), method=method)
        np.testing.assert_allclose(s.T_world_sensor, w.T_world_body() @ mount.T_body_lidar())
        pts = s.points_world()
        on = np.all((pts >= person.aabb_min - 0.05) & (pts <= person.aabb_max + 0.05), axis=1)
        counts[name] = int(on.sum())
        if name == "lidar_below":
            assert np.linalg.norm(pts - s.T_world_sensor[:3, 3], axis=1).min() > 0.3  # nothing of the drone
            assert pts[on, 2].min() < 0.3 and pts[:, 2].min() < 0.05  # the person's legs, and the floor
    assert counts["lidar"] < 5 and counts["lidar_below"] > 100, counts
    w.close()
