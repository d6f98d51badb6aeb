"""planner.shield.shield: a plan is flown as it is while its commitment (followed for commit_time, then a stop) is
safe; otherwise the shield flies a safe motion, the committed stop, or the hardest stop; it remembers
people who leave the view, and never raises."""
import math
from dataclasses import replace

import numpy as np
import pytest

from planner.map.visibility import SeenSpace
from planner.map.voxel_map import MapConfig, VoxelMap
from planner.shield.shield import PassiveSafetyShield, ShieldConfig
from planner.types import ObstaclePrediction, PlannerInput, Trajectory

GOAL = np.array([14.0, 0.0, 1.2])
FENCE = (np.array([0.0, -2.0]), np.array([15.0, 2.0]))
CFG = ShieldConfig()


class Straight:
    """A stand-in planner: flies at ``velocity`` (m/s, x and y) from wherever the drone is."""

    def __init__(self, velocity):
        self.velocity = np.array([velocity[0], velocity[1], 0.0])
        self.calls = 0

    def reset(self):
        self.calls = 0

    def plan(self, inp):
        self.calls += 1
        n, dt = 25, 0.1
        t = dt * np.arange(n + 1)[:, None]
        p = inp.position + self.velocity * t
        return Trajectory(inp.stamp, dt, p, np.repeat(self.velocity[None], n + 1, axis=0), np.zeros((n, 3)),
                          status="solved", yaw=0.0)


def _map():
    m = VoxelMap(MapConfig(origin=(-0.5, -2.5, -0.1), size=(16.0, 5.0, 3.2)))
    m.set_known(np.zeros(m.log_odds.shape, bool))
    return m


def _person(oid, xy, v=(0.0, 0.0)):
    return ObstaclePrediction(id=oid, center=np.array([xy[0], xy[1], 0.9]), size=np.array([0.5, 0.5, 1.8]),
                              velocity=np.array([v[0], v[1], 0.0]), position_std=0.05)


def _input(t, p, v, obstacles=(), occ=None, yaw=0.0, seen=None):
    return PlannerInput(stamp=t, position=np.array([p[0], p[1], 1.2]), velocity=np.array([v[0], v[1], 0.0]),
                        acceleration=np.zeros(3), goal=GOAL, obstacles=tuple(obstacles), occupancy=occ or _map(),
                        yaw=yaw, geofence=FENCE, seen=seen)


def test_a_safe_plan_is_flown_as_planned():
    nominal = Straight((1.5, 0.0))
    shield = PassiveSafetyShield(nominal, CFG)
    inp = _input(0.0, (2.0, 0.0), (1.5, 0.0), [_person(1, (9.0, 1.5))])
    tr = shield.plan(inp)
    assert tr.status == "solved" and shield.interventions == 0
    np.testing.assert_allclose(tr.positions, Straight((1.5, 0.0)).plan(inp).positions)


def test_the_shield_says_which_discs_it_kept_the_plan_from():
    shield = PassiveSafetyShield(Straight((1.5, 0.0)), CFG)
    shield.plan(_input(0.0, (2.0, 0.0), (1.5, 0.0), [_person(1, (9.0, 1.5)), _person(2, (6.0, -1.0))]))
    assert shield.threats.shape == (2, 3)
    np.testing.assert_allclose(shield.threats[:, :2], [[9.0, 1.5], [6.0, -1.0]])
    assert np.all(shield.threats[:, 2] >= 0.5 * math.hypot(0.5, 0.5))  # the body at least
    shield.plan(_input(0.1, (2.15, 0.0), (1.5, 0.0), []))
    assert shield.threats.shape == (0, 3)  # reported once only: not remembered


def test_flying_into_a_standing_person_is_refused():
    shield = PassiveSafetyShield(Straight((1.5, 0.0)), CFG)
    person = _person(1, (3.3, 0.0))
    tr = shield.plan(_input(0.0, (2.0, 0.0), (1.5, 0.0), [person]))
    assert tr.status.startswith("shield:") and shield.interventions == 1
    # whatever it flies instead stops short of the person's reach, or moves away from them
    gap = np.hypot(*(tr.positions[:, :2] - person.center[:2]).T)
    closing = (tr.velocities[:, :2] @ (person.center[:2] - tr.positions[:, :2]).T).diagonal() > 0
    assert np.all(gap[closing] > CFG.drone_radius + 0.25) and np.hypot(*tr.velocities[-1, :2]) < 1e-6


def test_moving_away_from_a_walker_who_follows_is_allowed():
    """A walker coming up from behind faster than the drone: contact would be a hit from behind."""
    shield = PassiveSafetyShield(Straight((1.0, 0.0)), CFG)
    tr = shield.plan(_input(0.0, (5.0, 0.0), (1.0, 0.0), [_person(1, (4.0, 0.0), (1.6, 0.0))]))
    assert tr.status == "solved"


def test_a_person_who_left_the_view_is_remembered_until_their_place_is_seen_free():
    shield = PassiveSafetyShield(Straight((1.5, 0.0)), CFG)
    occ = _map()
    seen = SeenSpace(occ.xy_origin, tuple(occ.dims[:2]), occ.res)
    for k in range(8):  # reported for 0.7 s, standing ahead
        shield.plan(_input(0.1 * k, (1.0, 0.0), (0.0, 0.0), [_person(4, (3.6, 0.0))], occ=occ, seen=seen))
    tr = shield.plan(_input(0.8, (2.4, 0.0), (1.5, 0.0), [], occ=occ, seen=seen))  # not reported any more
    assert tr.status.startswith("shield:")  # still there as far as the shield knows
    # the camera sees the place free: forgotten, and the plan is flown
    K = type("K", (), dict(fx=387.15, fy=387.15, cx=321.3, cy=233.5, width=640, height=480))()
    T = np.eye(4)
    T[:3, :3] = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    T[:3, 3] = [2.4, 0.0, 1.2]
    seen.observe_map(occ.column_blocked(0.8, 1.6, inflate=False), K, T, 0.85)
    tr = shield.plan(_input(0.9, (2.4, 0.0), (1.5, 0.0), [], occ=occ, seen=seen))
    assert tr.status == "solved"
    assert [why for _, _, why in shield.forgotten] == ["seen_free"]


def test_the_shield_says_why_it_stopped_remembering_someone():
    shield = PassiveSafetyShield(Straight((0.0, 0.0)), CFG)
    occ = _map()
    for k in range(8):  # 4 reported for 0.7 s, 5 for 0.2 s
        people = [_person(4, (3.6, 1.0))] + [_person(5, (3.0, -1.0))] * (k >= 6)
        shield.plan(_input(0.1 * k, (1.0, 0.0), (0.0, 0.0), people, occ=occ))
    shield.plan(_input(0.8, (1.0, 0.0), (0.0, 0.0), [], occ=occ))
    assert [w for _, _, w in shield.forgotten] == ["young"] and shield.threats.shape == (1, 3)
    shield.plan(_input(0.9, (1.0, 0.0), (0.0, 0.0), [_person(6, (3.7, 1.2))], occ=occ))
    assert [w for _, _, w in shield.forgotten] == ["merged"]
    shield.plan(_input(0.9 + CFG.memory + 0.1, (1.0, 0.0), (0.0, 0.0), [], occ=occ))
    assert [(x, y, w) for x, y, w in shield.forgotten] == [(3.7, 1.2, "memory")]
    shield.plan(_input(5.0, (1.0, 0.0), (0.0, 0.0), [], occ=occ))
    assert shield.forgotten == []


def test_telemetry_gives_the_latest_plans_path_threats_and_forgotten():
    class WithPath(Straight):
        path = np.array([[2.0, 0.0], [14.0, 0.0]])

    shield = PassiveSafetyShield(WithPath((1.5, 0.0)), CFG)
    assert shield.brake_accel == CFG.a_brake
    shield.plan(_input(0.0, (2.0, 0.0), (1.5, 0.0), [_person(1, (9.0, 1.5))]))
    t = shield.telemetry()
    assert set(t) == {"path", "threats", "forgotten", "brake_accel"} and t["brake_accel"] == CFG.a_brake
    np.testing.assert_array_equal(t["path"], WithPath.path)
    np.testing.assert_array_equal(t["threats"], shield.threats)
    assert t["threats"].shape == (1, 3) and t["forgotten"] == []
    shield.plan(replace(_input(0.1, (2.0, 0.0), (1.5, 0.0)), stamp=math.nan))
    assert shield.telemetry()["threats"] is None  # an invalid input: no discs were checked
    assert PassiveSafetyShield(Straight((0.0, 0.0)), CFG).telemetry()["path"] is None


def test_when_nothing_is_safe_the_drone_stops_as_hard_as_it_can():
    shield = PassiveSafetyShield(Straight((2.0, 0.0)), CFG)
    tr = shield.plan(_input(0.0, (2.0, 0.0), (2.0, 0.0), [_person(1, (2.9, 0.0), (-1.5, 0.0)),
                                                           _person(2, (2.0, 1.0), (0.0, -1.0)),
                                                           _person(3, (2.0, -1.0), (0.0, 1.0))]))
    assert tr.status in ("shield:emergency stop", "shield:alternative")
    assert np.all(np.isfinite(tr.positions))
    if tr.status == "shield:emergency stop":
        assert np.linalg.norm(tr.accelerations[0, :2]) == pytest.approx(CFG.a_emergency)


@pytest.mark.parametrize("field,value", [("position", math.nan), ("velocity", math.inf), ("goal", math.inf),
                                         ("stamp", math.nan)])
def test_bad_input_gives_a_finite_stop_saying_why(field, value):
    shield = PassiveSafetyShield(Straight((1.0, 0.0)), CFG)
    kw = dict(stamp=0.0, position=np.array([2.0, 0.0, 1.2]), velocity=np.zeros(3), acceleration=np.zeros(3),
              goal=GOAL.copy(), obstacles=(), occupancy=_map(), yaw=0.0, geofence=FENCE)
    if field == "stamp":
        kw["stamp"] = value
    else:
        kw[field] = kw[field].copy()
        kw[field][0] = value
    tr = shield.plan(PlannerInput(**kw))
    assert tr.status == "fallback:invalid_input"
    assert all(np.all(np.isfinite(a)) for a in (tr.positions, tr.velocities, tr.accelerations))


class Climbing(Straight):
    """A stand-in planner that flies at ``velocity`` and climbs at 0.5 m/s."""

    def plan(self, inp):
        tr = super().plan(inp)
        t = tr.dt * np.arange(len(tr.positions))
        p, v = tr.positions.copy(), tr.velocities.copy()
        p[:, 2] += 0.5 * t
        v[:, 2] = 0.5
        return Trajectory(tr.t0, tr.dt, p, v, tr.accelerations, status="solved", yaw=0.0)


def test_a_hold_is_at_rest_in_all_three_axes():
    """The planner climbs toward a person standing just ahead; the shield's hold brakes the drone's vertical
    rate as well and stays at a fixed altitude, not where the plan's altitude goes."""
    shield = PassiveSafetyShield(Climbing((1.5, 0.0)), CFG)
    inp = _input(0.0, (2.0, 0.0), (0.05, 0.0), [_person(1, (2.85, 0.0))])
    tr = shield.plan(replace(inp, velocity=np.array([0.05, 0.0, 0.2])))
    assert tr.status == "shield:hold"
    assert tr.velocities[0, 2] == 0.2 and np.all(tr.velocities[1:] == 0.0)
    assert np.all(tr.positions[1:, 2] == tr.positions[1, 2]) and tr.positions[1, 2] < 1.2 + 0.2 * CFG.dt
    p, v, _ = tr.sample(tr.t0 + 5.0)
    assert np.all(v == 0.0) and p[2] == tr.positions[-1, 2]


def test_space_the_map_never_observed_counts_as_structure():
    """A box 1.4 m tall whose front face was seen and whose back never was (unknown voxels behind the face,
    reaching wider than the face, up to the box's top; seen free over it): a plan whose commitment passes
    within the drone's radius of that unseen space, but clear of the face, is not flown; with the rule off,
    it is. Moving away from unseen space stays allowed."""
    m = _map()
    face = m.world_to_cell(np.array([[4.0, -0.5], [4.0, 0.5]]))
    back = m.world_to_cell(np.array([[4.1, -0.5], [5.5, 0.9]]))
    top = int(np.floor((1.4 - m.origin[2]) / m.res))
    m.log_odds[face[0, 0], face[0, 1]:face[1, 1] + 1, :top] = m.l_max
    m.log_odds[back[0, 0]:back[1, 0] + 1, back[0, 1]:back[1, 1] + 1, :top] = m.l_unknown
    m.version += 1
    unseen = m.column_unobserved(1.1, 1.3)[back[0, 0]:back[1, 0] + 1, back[0, 1]:back[1, 1] + 1]
    assert np.all(unseen) and not np.any(m.column_unobserved(1.5, 1.7))  # over the box: seen
    inp = _input(0.0, (3.0, 1.25), (1.5, 0.0), occ=m)  # 0.75 m beside the face, 0.35 m beside the unseen space
    off = replace(CFG, unobserved_is_blocked=False)
    assert PassiveSafetyShield(Straight((1.5, 0.0)), off).plan(inp).status == "solved"
    assert PassiveSafetyShield(Straight((1.5, 0.0)), CFG).plan(inp).status.startswith("shield:")
    assert PassiveSafetyShield(Straight((1.5, 0.0)), CFG).plan(replace(inp, position=np.array([3.0, 1.5, 1.2]))
                                                              ).status == "solved"  # 0.6 m beside it
    away = PassiveSafetyShield(Straight((0.0, 1.0)), CFG).plan(replace(inp, position=np.array([4.8, 1.25, 1.2]),
                                                                         velocity=np.zeros(3)))
    assert away.status == "solved"
