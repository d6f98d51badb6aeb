"""experiments.perception_modes: the oracle modes' view rules, on hand-made ground truth."""
from types import SimpleNamespace

import numpy as np
import pytest

from dodt.frames import CameraIntrinsics
from experiments.perception_modes import OraclePerception, known_modes, make_perception
from sim.ground_truth import ObstacleTruth


def _truth(stamp, people_xy):
    """A camera at (0, 0, 1.2) looking along +x (optical z forward) and people standing at people_xy."""
    T = np.eye(4)
    T[:3, :3] = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # optical -> world
    T[:3, 3] = [0.0, 0.0, 1.2]
    obstacles = tuple(ObstacleTruth(id=i + 1, kind="person", label="person",
                                    aabb_min=np.array([x - 0.25, y - 0.25, 0.0]),
                                    aabb_max=np.array([x + 0.25, y + 0.25, 1.7]), velocity=np.array([0.5, 0, 0]))
                      for i, (x, y) in enumerate(people_xy))
    return SimpleNamespace(T_world_camera=T, obstacles=obstacles, stamp=stamp)


FRAME = SimpleNamespace(intrinsics=CameraIntrinsics(), stamp=0.0)
AHEAD, BEHIND, SIDE, FAR = (3.0, 0.0), (-2.0, 0.0), (0.0, 2.0), (8.0, 0.0)


@pytest.mark.parametrize("mode, seen", [("oracle", {1}), ("oracle-360", {1, 2, 3})])
def test_oracle_sees_its_view_and_the_all_around_oracle_everything_in_range(mode, seen):
    p = make_perception(mode)
    assert p.name == mode and p.uses_ground_truth
    out = p.update(FRAME, _truth(0.0, [AHEAD, BEHIND, SIDE, FAR]))
    assert {o.id for o in out.obstacles} == seen  # the person 8 m away is out of range for both
    assert sorted(tuple(c) for c, _ in out.clear_boxes) == sorted(tuple(o.center) for o in out.obstacles)
    np.testing.assert_allclose(next(o for o in out.obstacles if o.id == 1).velocity, [0.5, 0, 0])


def test_oracle_remembers_a_person_for_its_memory_only():
    p = OraclePerception(memory=1.0)
    p.update(FRAME, _truth(0.0, [AHEAD]))
    assert [o.id for o in p.update(FRAME, _truth(0.9, [BEHIND])).obstacles] == [1]  # left the view 0.9 s ago
    assert p.update(FRAME, _truth(1.1, [BEHIND])).obstacles == ()


def test_oracle_modes_are_known_and_need_the_truth():
    assert {"oracle", "oracle-360"} <= set(known_modes())
    with pytest.raises(ValueError, match="ground truth"):
        make_perception("oracle-360").update(FRAME, None)


def _track(coasting, speed=0.8, dynamic=False, size=(0.5, 0.5, 1.7)):
    from dodt.result import TrackedObstacle
    return TrackedObstacle(id=7, center=np.array([3.0, 0.0, 0.85]), size=np.array(size),
                           velocity=np.array([speed, 0.0, 0.0]), acceleration=np.zeros(3), dynamic=dynamic,
                           coasting=coasting, age=1.0, history=np.zeros((0, 4)))


def _rule_only(rule):
    from experiments.perception_modes import DODTPerception
    p = DODTPerception.__new__(DODTPerception)  # the rule only: no DODT pipeline needed
    p.moving_rule, p.structure_test, p._on_structure = rule, None, set()
    return p


def test_moving_track_rule_passes_person_like_tracks_at_walking_speed():
    """A person-sized track at walking speed reaches the planner though DODT labels it static (coasting
    too, unless `measured`); a wall-sized or slow one does not."""
    from experiments.perception_modes import MovingTrackRule
    p = _rule_only(MovingTrackRule(measured=False))
    assert p._moving(_track(coasting=False)) and p._moving(_track(coasting=True))
    assert not p._moving(_track(coasting=False, speed=0.2))
    assert not p._moving(_track(coasting=False, size=(2.5, 0.3, 1.7)))
    p = _rule_only(MovingTrackRule(measured=True))
    assert p._moving(_track(coasting=False)) and not p._moving(_track(coasting=True))


def test_moving_track_rule_drops_a_track_once_seen_on_long_held_structure():
    from experiments.perception_modes import MovingTrackRule
    p = _rule_only(MovingTrackRule(measured=False, on_structure=0.2))
    share = {"v": 0.0}
    p.structure_test = lambda c, s: share["v"]
    assert p._moving(_track(coasting=False))
    share["v"] = 0.5  # measured on a static obstacle's edge: dropped, and for good
    assert not p._moving(_track(coasting=False))
    share["v"] = 0.0
    assert not p._moving(_track(coasting=True)) and not p._moving(_track(coasting=False))
