"""Walking people: path following at the set speed, heading, gait locked to speed, size,
collision geometry that follows the animated body, seeded paths."""
import math

import numpy as np
import pybullet as p
import pytest

from conftest import make_scenario
from sim import World
from sim.people import TURN_SPEED_STEP, WALK_ACCELERATION, load_walk_clip, plan_path
from sim.scenario import PERSON_HEIGHT_RANGE


def _walker_world(extra_person: str, **kw):
    return World(make_scenario("[[people]]\n" + extra_person), seed=kw.pop("seed", 0), camera=False, **kw)


def _base_xy(w, i=0):
    cid, body = w.walkers[i].bodies[0]
    return np.array(p.getBasePositionAndOrientation(body, physicsClientId=cid)[0][:2])


@pytest.mark.parametrize("speed", [0.5, 1.0, 1.6])
def test_people_follow_their_path_at_their_set_speed(speed):
    w = _walker_world(f'behaviour = "crossing"\nspeed = {speed}\nheight = 1.7\n'
                      'waypoints = [[1.0, -1.0], [9.5, -1.0]]\n')
    path = w.walkers[0].path
    w.advance(1.0)
    a, ta = _base_xy(w), w.time
    w.advance(4.0)
    b, tb = _base_xy(w), w.time
    measured = np.linalg.norm(b - a) / (tb - ta)  # the animated body, not the path
    assert measured == pytest.approx(speed, rel=0.05)
    # and the body stays on the path (the root sways a few centimetres with the gait), near where its
    # schedule would have it: the crowd model steers along the route, relaxing toward its speed
    assert abs(b[1] - (-1.0)) < 0.08
    assert np.linalg.norm(b - path.position(tb)) < 0.15


def test_crossing_stops_at_the_end_and_start_delay_holds():
    w = _walker_world('behaviour = "crossing"\nspeed = 1.0\nstart_delay = 1.0\nwaypoints = [[2.0, 0.0], [4.0, 0.0]]\n')
    start = _base_xy(w)
    w.advance(0.9)
    assert np.linalg.norm(_base_xy(w) - start) < 0.05  # still standing
    w.advance(6.0)
    assert np.linalg.norm(_base_xy(w) - [4.0, 0.0]) < 0.08
    np.testing.assert_allclose(w.crowd.vel[0], [0.0, 0.0], atol=0.02)


def test_people_face_where_they_walk():
    # Feet point forward in the humanoid: the foot boxes lie ahead of the ankle joints.
    w = _walker_world('behaviour = "waypoint_loop"\nspeed = 1.0\n'
                      'waypoints = [[2.0, -1.0], [8.0, -1.0], [8.0, 1.0], [2.0, 1.0]]\n')
    cid, body = w.walkers[0].bodies[0]
    qc, qbody = w.walkers[0].bodies[1]
    ahead = []
    for _ in range(40):
        w.advance(0.4)
        v = w.crowd.vel[0]
        d = v / np.linalg.norm(v)
        for ankle in (11, 14):
            joint = np.array(p.getLinkState(body, ankle, physicsClientId=cid)[4][:2])
            lo, hi = p.getAABB(qbody, ankle, physicsClientId=qc)
            foot = (np.array(lo[:2]) + np.array(hi[:2])) / 2
            ahead.append((foot - joint) @ d)
    assert np.mean(np.array(ahead) > 0) > 0.85  # a foot lifted mid-swing may point down


def test_gait_is_timed_to_speed_so_feet_do_not_slide():
    # The foot on the ground (the lower one) stays put while the person walks: the gait phase
    # follows the distance walked, whatever the speed. Measured over each stance (a run of
    # control steps with the same foot lowest), from where it lands to where it lifts.
    for speed in (0.6, 1.5):
        w = _walker_world(f'behaviour = "crossing"\nspeed = {speed}\nwaypoints = [[1.0, 0.0], [9.5, 0.0]]\n')
        cid, body = w.walkers[0].bodies[0]
        lowest, feet = [], []
        for _ in range(360):
            w.step()
            f = [p.getLinkState(body, k, physicsClientId=cid)[4] for k in (11, 14)]
            lowest.append(0 if f[0][2] < f[1][2] else 1)
            feet.append(f)
        slips = []
        start = 0
        for i in range(1, len(lowest) + 1):
            if i == len(lowest) or lowest[i] != lowest[start]:
                if i - start >= 12:  # a stance of at least 0.1 s
                    a, b = feet[start][lowest[start]], feet[i - 1][lowest[start]]
                    slips.append(np.hypot(b[0] - a[0], b[1] - a[1]) / ((i - 1 - start) / 120))
                start = i
        assert len(slips) >= 3
        assert np.median(slips) < 0.25 * speed, (speed, slips)


def test_people_are_scaled_to_their_height():
    clip = load_walk_clip()
    assert clip.stride == pytest.approx(1.2386, abs=1e-3)
    for h in (1.6, 1.85):
        w = World(make_scenario(f'[[people]]\nbehaviour = "crossing"\nspeed = 1.0\nheight = {h}\n'
                                'waypoints = [[2.0, 0.0], [8.0, 0.0]]\n'), seed=0, renderer="tiny")
        heights = []
        for _ in range(60):
            if w.step() is not None:
                heights.append(w.ground_truth().obstacles[0].size[2])
        assert np.mean(heights) == pytest.approx(h, rel=0.04)
        w.close()


def test_unset_heights_are_drawn_in_range_from_the_seed():
    sc = make_scenario('[[people]]\nbehaviour = "crossing"\nspeed = 1.0\nwaypoints = [[2.0, 0.0], [8.0, 0.0]]\n'
                       '[[people]]\nbehaviour = "crossing"\nspeed = 1.0\nwaypoints = [[2.0, 1.0], [8.0, 1.0]]\n')
    hs = {s: [wk.height for wk in World(sc, seed=s, camera=False).walkers] for s in (0, 1)}
    assert all(PERSON_HEIGHT_RANGE[0] <= h <= PERSON_HEIGHT_RANGE[1] for v in hs.values() for h in v)
    assert hs[0] != hs[1]
    assert hs[0] == [wk.height for wk in World(sc, seed=0, camera=False).walkers]


def test_collision_geometry_follows_the_animated_body():
    w = _walker_world('behaviour = "crossing"\nspeed = 1.2\nwaypoints = [[1.0, 0.0], [9.0, 0.0]]\n')
    (c0, b0), (c1, b1) = w.walkers[0].bodies
    for _ in range(5):
        w.advance(0.5)
        for link in range(p.getNumJoints(b0, physicsClientId=c0)):
            a = p.getLinkState(b0, link, physicsClientId=c0)[4]
            b = p.getLinkState(b1, link, physicsClientId=c1)[4]
            np.testing.assert_allclose(a, b, atol=1e-9)  # rendered body == collidable body
        lo, hi = p.getAABB(b1, 10, physicsClientId=c1)  # a knee moves with the walk
        assert abs((lo[0] + hi[0]) / 2 - w.crowd.pos[0, 0]) < 0.6


def test_random_walk_stays_in_its_region_avoids_obstacles_and_is_seeded():
    sc = make_scenario('[[obstacles]]\nkind = "box"\ncenter = [5.0, 0.0]\nsize = [1.0, 1.0, 1.0]\n'
                       '[[people]]\nbehaviour = "random_walk"\nspeed = 1.0\nregion = [2.0, -1.5, 8.0, 1.5]\n')
    paths = {}
    for seed in (0, 0, 1):
        rng = np.random.default_rng(seed)
        paths.setdefault(seed, []).append(plan_path(sc.people[0], sc, rng, horizon=60.0))
    a, b, c = paths[0][0], paths[0][1], paths[1][0]
    np.testing.assert_array_equal(a.points, b.points)
    assert not np.array_equal(a.points, c.points)
    assert a.length >= 60.0
    ts = np.linspace(0, 60, 3000)
    pts = np.array([a.position(t) for t in ts])
    assert np.all((pts[:, 0] >= 2.0 - 1e-9) & (pts[:, 0] <= 8.0 + 1e-9) & (np.abs(pts[:, 1]) <= 1.5 + 1e-9))
    assert not np.any(sc.obstacles[0].footprint_contains(pts, 0.2))


def test_circle_and_back_and_forth_paths():
    sc = make_scenario('[[people]]\nbehaviour = "circle"\nspeed = 1.0\ncenter = [5.0, 0.0]\nradius = 1.0\n'
                       '[[people]]\nbehaviour = "back_and_forth"\nspeed = 1.0\nwaypoints = [[2.0, 1.5], [4.0, 1.5]]\n')
    rng = np.random.default_rng(0)
    circle = plan_path(sc.people[0], sc, rng, 30.0)
    r = [np.linalg.norm(circle.position(t) - [5.0, 0.0]) for t in np.linspace(0, 30, 200)]
    assert min(r) > 0.96 and max(r) <= 1.0 + 1e-9
    bf = plan_path(sc.people[1], sc, rng, 30.0)
    xs = [bf.position(t)[0] for t in np.linspace(0, 30, 600)]
    assert min(xs) == pytest.approx(2.0, abs=0.06) and max(xs) == pytest.approx(4.0, abs=0.06)
    # each end is reached and turned at (nearly) standstill, then walked away from
    ends = [t for t in np.arange(0, 12, 0.01) if abs(bf.position(t)[0] - 4.0) < 1e-3]
    assert ends and all(np.linalg.norm(bf.velocity(t)) < 0.15 for t in ends)
    t4 = ends[0]
    assert bf.velocity(t4 + 0.5)[0] < -0.3 and bf.position(t4 + 1.0)[0] < 3.7


@pytest.mark.parametrize("behaviour", ["back_and_forth", "random_walk", "crossing"])
def test_walkers_change_velocity_as_people_do_and_velocity_is_the_rate_of_position(behaviour):
    """The ground truth velocity must be what the body does: the derivative of the position,
    with accelerations a person makes (no reversal at walking speed in one step at a U-turn,
    no jump from standing to walking speed)."""
    body = {"back_and_forth": 'waypoints = [[2.0, 1.5], [5.0, 1.5]]\n',
            "random_walk": 'region = [2.0, -1.5, 8.0, 1.5]\n',
            "crossing": 'waypoints = [[2.0, -1.0], [5.0, -1.0], [5.0, 1.5]]\nstart_delay = 0.5\n'}[behaviour]
    sc = make_scenario(f'[[people]]\nbehaviour = "{behaviour}"\nspeed = 1.2\n' + body)
    path = plan_path(sc.people[0], sc, np.random.default_rng(3), 20.0)
    dt = 1 / 120
    ts = np.arange(0.0, 20.0, dt)
    pos = np.array([path.position(t) for t in ts])
    vel = np.array([path.velocity(t) for t in ts])
    # position is the integral of velocity (trapezoid rule, to well under a centimetre)
    integrated = pos[0] + np.concatenate([[[0, 0]], np.cumsum(0.5 * (vel[1:] + vel[:-1]) * dt, axis=0)])
    assert np.max(np.linalg.norm(integrated - pos, axis=1)) < 0.01
    dv = np.linalg.norm(np.diff(vel, axis=0), axis=1)
    assert dv.max() <= TURN_SPEED_STEP + WALK_ACCELERATION * dt + 1e-9  # no jump beyond a vertex step
    # over a tenth of a second, accelerations stay within what walking people do
    acc = np.linalg.norm(vel[12:] - vel[:-12], axis=1) / (12 * dt)
    assert acc.max() < 4.0
    speed = np.linalg.norm(vel, axis=1)
    assert speed.max() <= 1.2 + 1e-9 and np.median(speed[speed > 0]) > 0.9  # mostly at the set speed
    assert (speed[0] == 0.0) == (behaviour == "crossing")  # from standing only after a start delay
