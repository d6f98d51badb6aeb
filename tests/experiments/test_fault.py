"""Collisions classed by fault (experiments.fault): the rule on crafted states, and on crafted
episodes flown in the simulator (a walker walking into a hovering drone, a drone flying into a
standing person, a drone backing into a person behind it, a fast walker catching up with it)."""
import math

import numpy as np
import pytest

from conftest import make_scenario
from experiments.episode_metrics import summarize
from experiments.fault import classify
from sim import World
from sim.controller import Reference


@pytest.mark.parametrize("kind", ["static", "structure"])
def test_touching_structure_is_always_at_fault(kind):
    assert classify(kind, [0, 0, 1], [0, 0, 0], [0.3, 0, 1]) == "structure"


def test_the_rule_on_crafted_states():
    p = [0.0, 0.0, 1.2]
    assert classify("person", p, [0.05, 0.05, 0.0], [0.4, 0.0, 1.2]) == "drone_at_rest"
    assert classify("person", p, [1.0, 0.0, 0.0], [0.4, 0.0, 1.2]) == "drone_at_fault"  # ahead
    assert classify("person", p, [1.0, 0.0, 0.0], [0.0, 0.4, 1.2]) == "drone_at_fault"  # beside: 90 deg
    assert classify("person", p, [1.0, 0.0, 0.0], [-0.4, 0.0, 1.2]) == "hit_from_behind"  # 180 deg
    a = math.radians(125)
    assert classify("person", p, [1.0, 0.0, 0.0], [0.4 * math.cos(a), 0.4 * math.sin(a), 1.2]) == "hit_from_behind"
    a = math.radians(115)
    assert classify("person", p, [1.0, 0.0, 0.0], [0.4 * math.cos(a), 0.4 * math.sin(a), 1.2]) == "drone_at_fault"
    assert classify("person", p, [-1.0, 0.0, 0.0], [-0.4, 0.0, 1.2]) == "drone_at_fault"  # backing into someone
    assert classify("person", p, [float("nan")] * 3, [0.4, 0.0, 1.2]) == "drone_at_fault"  # unknown: the drone's


def _fly(person: str, start, ref, seconds: float, base_drone="start = [2.0, 0.0, 1.2]") -> World:
    sc = make_scenario(person, base=f"""
name = "fault"
duration = 20.0
[corridor]
length = 12.0
width = 4.0
height = 3.0
[drone]
{base_drone}
goal = [11.0, 0.0, 1.2]
""")
    w = World(sc, seed=0, camera=False)
    while w.time < seconds and not w.collisions:
        w.step(ref(w.time))
    assert w.collisions, "the crafted episode must end in a collision"
    return w


def _classes(w: World) -> list[str]:
    return [classify(c.other_kind, c.position, c.drone_velocity, c.contact_point) for c in w.collisions]


def test_a_walker_walking_into_a_hovering_drone_is_not_at_fault():
    w = _fly('[[people]]\nbehaviour = "crossing"\nspeed = 1.2\nwaypoints = [[8.0, 0.0], [1.0, 0.0]]\n', None,
             lambda t: Reference.hover([2.0, 0.0, 1.2]), 10.0)
    assert _classes(w)[0] == "drone_at_rest"


def test_a_drone_flying_into_a_standing_person_is_at_fault():
    w = _fly('[[people]]\nbehaviour = "crossing"\nspeed = 1.0\nstart_delay = 100.0\n'
             'waypoints = [[6.0, 0.0], [9.0, 0.0]]\n', None,
             lambda t: Reference(position=np.array([2.0 + 1.0 * t, 0.0, 1.2]), velocity=np.array([1.0, 0.0, 0.0])),
             8.0)
    assert _classes(w)[0] == "drone_at_fault"
    assert np.hypot(*w.collisions[0].drone_velocity[:2]) > 0.5


def test_a_drone_backing_into_a_person_it_cannot_see_is_at_fault():
    # The camera looks along +x (yaw 0) while the drone flies backward into a person standing behind it.
    w = _fly('[[people]]\nbehaviour = "crossing"\nspeed = 1.0\nstart_delay = 100.0\n'
             'waypoints = [[3.0, 0.0], [2.0, 0.0]]\n', None,
             lambda t: Reference(position=np.array([7.0 - 0.8 * t, 0.0, 1.2]), velocity=np.array([-0.8, 0.0, 0.0]),
                                 yaw=0.0), 8.0, base_drone="start = [7.0, 0.0, 1.2]")
    assert _classes(w)[0] == "drone_at_fault"


def test_a_fast_walker_catching_up_from_behind_is_not_the_drones_fault():
    w = _fly('[[people]]\nbehaviour = "crossing"\nspeed = 1.6\nwaypoints = [[0.5, 0.0], [11.0, 0.0]]\n', None,
             lambda t: Reference(position=np.array([2.0 + 0.4 * t, 0.0, 1.2]), velocity=np.array([0.4, 0.0, 0.0])),
             10.0)
    assert _classes(w)[0] == "hit_from_behind"


def test_episode_summaries_count_collisions_by_fault():
    def rec(t, kind, v, point):
        return {"k": "collision", "t": t, "kind": kind, "other_id": 5, "position": [1.0, 0.0, 1.2], "v": v,
                "point": point, "other_v": [0.0, 0.0, 0.0]}

    head = {"k": "header", "scenario": "x", "seed": 1, "perception": "oracle"}
    end = {"k": "end", "t": 10.0, "reason": "goal", "reached_goal": True, "time_to_goal": 10.0}
    hit = summarize([head, rec(2.0, "person", [0.0, 0.0, 0.0], [1.3, 0.0, 1.2]), end])
    assert hit["collisions"][0]["fault"] == "drone_at_rest" and not hit["at_fault"] and hit["not_at_fault_only"]
    assert not hit["success"] and hit["failure_reason"] == "collision"
    both = summarize([head, rec(2.0, "person", [0.0, 0.0, 0.0], [1.3, 0.0, 1.2]),
                      rec(3.0, "static", [1.0, 0.0, 0.0], [1.3, 0.0, 1.2]), end])
    assert both["at_fault"] and both["at_fault_count"] == 1 and not both["not_at_fault_only"]
    assert both["failure_reason"] == "at_fault_collision"
    assert both["collisions"][1]["drone_speed"] == pytest.approx(1.0)
