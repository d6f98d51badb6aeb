"""People among people and the drone (sim.crowd): bodies never overlap, people who see the drone
give way to it and return to their routes, the others do not, ground truth's velocity is the
derivative of position, and the whole is deterministic."""
import math

import numpy as np
import pytest

from conftest import BASE, make_scenario
from sim import World
from sim.controller import Reference
from sim.crowd import _repulsion
from sim.scenario import PERSON_RADIUS

HEAD_ON = ('[[people]]\nbehaviour = "crossing"\nspeed = 1.0\nwaypoints = [[1.5, 0.0], [8.5, 0.0]]\n'
           '[[people]]\nbehaviour = "crossing"\nspeed = 1.2\nwaypoints = [[8.5, 0.02], [1.5, 0.02]]\n')


def _run(w: World, seconds: float, ref: Reference | None = None) -> list[np.ndarray]:
    out = []
    for _ in range(int(round(seconds * 120))):
        w.step(ref)
        out.append(w.crowd.pos.copy())
    return out


def test_the_repulsion_is_minus_the_gradient_of_the_elliptic_potential():
    V0, sigma = 2.1, 0.3

    def V(r, y):
        s = np.linalg.norm(r) + np.linalg.norm(r - y)
        return V0 * math.exp(-0.5 * math.sqrt(s * s - y @ y) / sigma)

    rng = np.random.default_rng(0)
    for _ in range(50):
        r, y = rng.uniform(-2, 2, 2), rng.uniform(-1.5, 1.5, 2)
        h = 1e-6
        grad = np.array([(V(r + h * e, y) - V(r - h * e, y)) / (2 * h) for e in np.eye(2)])
        np.testing.assert_allclose(_repulsion(r[0], r[1], y[0], y[1], V0, sigma), -grad, rtol=1e-5, atol=1e-8)
    # a standing other: the circular potential, pushing straight away
    fx, fy = _repulsion(0.5, 0.0, 0.0, 0.0, V0, sigma)
    assert fy == 0.0 and fx == pytest.approx(V0 / sigma * math.exp(-0.5 / sigma))


def test_people_walking_at_each_other_pass_without_overlapping_and_regain_their_routes():
    w = World(make_scenario(HEAD_ON), seed=0, camera=False)
    track = np.array(_run(w, 9.0, Reference.hover([1.0, -1.5, 1.2])))
    gaps = np.hypot(*(track[:, 0] - track[:, 1]).T)
    assert gaps.min() >= 2 * PERSON_RADIUS - 1e-9  # bodies never overlap
    assert gaps.min() < 2.0  # ... but they do meet
    assert np.abs(track[:, :, 1]).max() > 0.2  # someone stepped aside
    np.testing.assert_allclose(track[-1, 0], [8.5, 0.0], atol=0.1)  # and both reached their routes' ends
    np.testing.assert_allclose(track[-1, 1], [1.5, 0.02], atol=0.1)


@pytest.mark.parametrize("sees", [True, False])
def test_only_people_who_see_the_drone_give_way_to_it(sees):
    sc = make_scenario('[[people]]\nbehaviour = "crossing"\nspeed = 1.0\nwaypoints = [[8.5, 0.0], [1.5, 0.0]]\n'
                       f'[crowd]\nsees_drone = {str(sees).lower()}\n', base=BASE.replace("[1.0, 0.0, 1.2]", "[5.0, 0.0, 1.2]"))
    w = World(sc, seed=0, camera=False)
    hover = Reference.hover([5.0, 0.0, 1.2])
    track = np.array(_run(w, 12.0, hover))[:, 0]
    drone = np.array([5.0, 0.0])
    closest = np.hypot(*(track - drone).T).min()
    if sees:
        assert closest > 0.6 and not w.collisions  # went round the hovering drone
        np.testing.assert_allclose(track[-1], [1.5, 0.0], atol=0.1)  # and back onto its route to the end
    else:
        assert closest < 0.3 and any(c.other_kind == "person" for c in w.collisions)  # walked into it
        ev = next(c for c in w.collisions if c.other_kind == "person")
        assert np.hypot(*ev.drone_velocity[:2]) < 0.3 and np.hypot(*ev.other_velocity[:2]) > 0.5


def test_a_person_overrides_the_scenario_default():
    sc = make_scenario('[[people]]\nbehaviour = "crossing"\nspeed = 1.0\nwaypoints = [[8.5, 0.0], [1.5, 0.0]]\n'
                       'sees_drone = true\n'
                       '[[people]]\nbehaviour = "crossing"\nspeed = 1.0\nwaypoints = [[8.5, 1.0], [1.5, 1.0]]\n')
    w = World(sc, seed=0, camera=False)
    assert w.crowd.sees.tolist() == [True, False]


def test_truth_velocity_is_the_derivative_of_position_and_speed_stays_capped():
    sc = make_scenario(HEAD_ON + '[crowd]\nsees_drone = true\n')
    w = World(sc, seed=0, camera=False)
    dt = 1 / 120
    prev = w.crowd.pos.copy()
    for _ in range(int(6 / dt)):
        w.step(Reference.hover([5.0, 0.3, 1.2]))
        np.testing.assert_allclose(w.crowd.vel, (w.crowd.pos - prev) / dt, atol=1e-9)
        assert np.all(np.hypot(*w.crowd.vel.T) <= np.array([1.3, 1.56]) + 1e-9)  # 1.3 x the route speed
        prev = w.crowd.pos.copy()
    truth = {o.id: o for o in w.obstacle_truth() if o.kind == "person"}
    np.testing.assert_allclose([truth[i].velocity[:2] for i in w.person_ids], w.crowd.vel)


def test_people_keep_out_of_obstacles_and_walls_when_pushed():
    # A person walking along a box, pushed toward it by a drone it sees, stays outside the box.
    sc = make_scenario('[[obstacles]]\nkind = "box"\ncenter = [5.0, -1.2]\nsize = [2.0, 1.0, 1.0]\n'
                       '[[people]]\nbehaviour = "crossing"\nspeed = 1.0\nwaypoints = [[2.0, -0.4], [8.0, -0.4]]\n'
                       '[crowd]\nsees_drone = true\n')
    w = World(sc, seed=0, camera=False)
    track = np.array(_run(w, 7.0, Reference.hover([5.0, 0.2, 1.2])))[:, 0]
    o = w.scenario.obstacles[0]
    assert not np.any(o.footprint_contains(track, PERSON_RADIUS - 1e-6))
    assert np.all(np.abs(track[:, 1]) <= 2.0 - PERSON_RADIUS + 1e-9)


def test_the_crowd_is_deterministic():
    sc = make_scenario(HEAD_ON + '[crowd]\nsees_drone = true\n')
    a = np.array(_run(World(sc, seed=0, camera=False), 4.0, Reference.hover([5.0, 0.0, 1.2])))
    b = np.array(_run(World(sc, seed=0, camera=False), 4.0, Reference.hover([5.0, 0.0, 1.2])))
    np.testing.assert_array_equal(a, b)
