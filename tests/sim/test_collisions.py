"""Collision checking of the drone against obstacles, walls and people; clearance."""
import numpy as np
import pytest

from conftest import make_scenario
from sim import World
from sim.controller import Reference

BOX = '[[obstacles]]\nkind = "box"\ncenter = [4.0, 0.0]\nsize = [0.6, 0.6, 2.0]\n'


def test_flying_into_a_box_is_a_collision_with_that_box():
    w = World(make_scenario(BOX), seed=0, camera=False)
    w.advance(4.0, Reference.hover([6.0, 0.0, 1.2]))  # straight through the box
    assert w.collided
    first = w.collisions[0]
    assert (first.other_id, first.other_kind) == (1, "static")
    # the drone's front (0.255 m ahead of its centre) met the box face at x = 3.7
    assert first.position[0] == pytest.approx(3.7 - 0.255, abs=0.05)
    assert w.min_clearance["static"] == 0.0


def test_hitting_a_wall_is_a_structure_collision():
    w = World(make_scenario(""), seed=0, camera=False)
    w.advance(3.0, Reference.hover([1.0, 3.0, 1.2]))  # the wall is at y = 2
    assert [c.other_kind for c in w.collisions][:1] == ["structure"]
    assert w.min_clearance["structure"] == 0.0


def test_a_person_walking_into_a_hovering_drone_is_a_person_collision():
    w = World(make_scenario('[[people]]\nbehaviour = "crossing"\nspeed = 1.0\nheight = 1.8\n'
                            'waypoints = [[6.0, 0.1], [0.5, 0.1]]\n'), seed=0, camera=False)
    w.advance(6.0, Reference.hover(w.scenario.drone.start))  # hover at x = 1
    person = [c for c in w.collisions if c.other_kind == "person"]
    assert person and person[0].other_id == 1
    # the drone box's front is at x = 1.255; the walker's front (arms, chest) is 0.1-0.35 m
    # ahead of its root, which left x = 6 at 1 m/s
    assert 6.0 - 1.255 - 0.35 < person[0].time < 6.0 - 1.255 - 0.05
    assert w.min_clearance["person"] == 0.0


def test_passing_at_a_distance_is_no_collision_and_clearance_is_measured():
    w = World(make_scenario(BOX + '[[people]]\nbehaviour = "crossing"\nspeed = 1.0\n'
                            'waypoints = [[2.0, -1.2], [8.0, -1.2]]\n'), seed=0, camera=False)
    w.advance(6.0, Reference.hover([2.5, 1.0, 1.2]))
    assert not w.collided
    # person at y = -1.2 walks past the drone at y = 1.0: about 2.2 m apart minus half-widths
    assert w.min_clearance["person"] > 0.5
    # the box (x 3.7-4.3, y -0.3-0.3) is about 0.8 m from the drone box (x <= 2.755, y >= 0.65)
    assert w.min_clearance["static"] == pytest.approx(np.hypot(3.7 - 2.755, 0.65 - 0.3), abs=0.03)
    t, s, pers, struct = w.clearance_log[-1]
    assert t == pytest.approx(w.time) and struct == pytest.approx(2.0 - 1.0 - 0.35, abs=0.02)


def test_carried_camera_paths_are_checked_too():
    sc = make_scenario(BOX + "[camera_path]\nmode = \"carried\"\n"
                       "keyframes = [[0.0, 1.0, 0.6, 1.2, 0.0], [3.0, 7.0, 0.6, 1.2, 0.0]]\n")
    w = World(sc, seed=0, camera=False)
    w.advance(3.0)
    # the path passes 0.6 m beside the box centre: the 0.7 m wide drone box (0.35 m each side)
    # overlaps the box's side (y <= 0.3) by 5 cm
    assert [c.other_id for c in w.collisions] == [1]
