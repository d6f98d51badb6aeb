"""The default planner (planner.nominal.navigator): path, maneuver choice, MPC and heading, through plan()."""
import math

import numpy as np
import pytest

from planner.map.voxel_map import MapConfig, VoxelMap
from planner.mpc.config import MPCConfig
from planner.nominal.navigator import MPCPlanner, NavigatorConfig
from planner.types import ObstaclePrediction, PlannerInput

R_ROBOT = 0.437
GOAL = np.array([15.5, 0.0, 1.2])
FENCE = (np.array([0.0, -2.0]), np.array([16.0, 2.0]))


def _corridor_map(end_wall: int = 165):
    """The corridor's walls, known (16 x 4 m, as the closed loop's map bounds); the end wall's face at
    x = -0.5 + 0.1 * end_wall (165: x = 16)."""
    m = VoxelMap(MapConfig(origin=(-0.5, -2.5, -0.1), size=(17.0, 5.0, 3.2)))
    occ = np.zeros(tuple(m.dims), bool)
    occ[:, :5, :] = occ[:, 45:, :] = True  # y < -2, y > 2
    occ[:5, :, :] = occ[end_wall:, :, :] = True  # x < 0, x > the end wall
    m.set_known(occ)
    return m


def _planner(**kw):
    return MPCPlanner(NavigatorConfig(mpc=MPCConfig(robot_radius=R_ROBOT), **kw))


def _input(t, p, v, obstacles=(), yaw=0.0, occupancy=None):
    return PlannerInput(stamp=t, position=np.array([p[0], p[1], 1.2]), velocity=np.array([v[0], v[1], 0.0]),
                        acceleration=np.zeros(3), goal=GOAL, obstacles=tuple(obstacles),
                        occupancy=occupancy if occupancy is not None else _corridor_map(), yaw=yaw, geofence=FENCE)


def _bearing_off(yaw, p, q):
    b = math.atan2(q[1] - p[1], q[0] - p[0])
    return abs((b - yaw + math.pi) % (2 * math.pi) - math.pi)


def test_open_corridor_heads_for_the_goal():
    pl = _planner()
    tr = pl.plan(_input(0.0, (2.0, 0.0), (1.0, 0.0)))
    assert tr.status == "solved" and abs(tr.yaw) < math.radians(6)
    assert tr.positions[-1, 0] > 5.0  # on its way at cruise
    assert pl.last_maneuver is not None and tr.solve_ms > 0


def test_a_person_close_beside_the_drone_is_kept_in_view_while_it_gives_way():
    """A person 1.1 m off, 63 degrees to the right of the path ahead, walks at the hovering drone: the drone
    gives way, and its heading turns to keep the person inside the camera's view (facing the path or the
    evasive motion would lose them)."""
    pl = _planner()
    occ = _corridor_map()
    person = ObstaclePrediction(id=1, center=np.array([5.5, -1.0, 0.9]), size=np.array([0.5, 0.6, 1.8]),
                                velocity=np.array([-0.6, 0.6, 0.0]))
    p = np.array([5.0, 0.0])
    tr = pl.plan(_input(0.0, p, (0.0, 0.0), [person], occupancy=occ))
    assert _bearing_off(tr.yaw, p, person.center) < pl.half_fov  # the person stays in view
    moved = pl.last_maneuver.positions[10] - p
    assert np.hypot(*moved) > 0.3  # it does give way
    gap = np.linalg.norm(pl.last_maneuver.positions[1:] - person.predict(0.1 * np.arange(1, 26))[:, :2], axis=1)
    assert gap.min() > 0.3 + R_ROBOT


def test_without_a_map_the_mpc_follows_the_straight_path():
    pl = _planner()
    inp = PlannerInput(stamp=0.0, position=np.array([2.0, 0.0, 1.2]), velocity=np.array([1.0, 0.0, 0.0]),
                       acceleration=np.zeros(3), goal=GOAL, obstacles=(), occupancy=None, yaw=0.0, geofence=FENCE)
    tr = pl.plan(inp)
    assert tr.status == "solved" and pl.last_maneuver is None
    assert tr.positions[-1, 0] > 4.0 and abs(tr.positions[-1, 1]) < 0.1


@pytest.mark.parametrize("side", [-1.0, 1.0])
def test_a_head_on_person_is_passed_without_switching_sides(side):
    """Receding horizon, a walker coming head-on slightly off the centre line: the drone passes on one side
    and keeps its margin all along (the MPC follows the maneuver; the next plans keep the side)."""
    pl = _planner()
    occ = _corridor_map()
    p, v = np.array([2.0, 0.0]), np.array([1.5, 0.0])
    q = np.array([7.0, 0.2 * side])
    lateral = []
    for k in range(40):
        person = ObstaclePrediction(id=1, center=np.array([q[0], q[1], 0.9]), size=np.array([0.5, 0.6, 1.8]),
                                    velocity=np.array([-1.0, 0.0, 0.0]))
        tr = pl.plan(_input(0.1 * k, p, v, [person], occupancy=occ))
        p, v = tr.positions[1, :2], tr.velocities[1, :2]  # fly the first step exactly
        q = q + np.array([-0.1, 0.0])
        assert np.hypot(*(p - q)) > R_ROBOT + 0.3  # never within the contact distance
        if abs(p[0] - q[0]) < 1.0:
            lateral.append(np.sign(p[1] - q[1]))
    assert lateral and len(set(lateral)) == 1 and lateral[0] == -side  # one side, the roomier one
    assert p[0] > q[0] + 1.0  # passed


@pytest.mark.parametrize("start", [(14.9, -0.6), (15.11, 0.12), (14.6, -0.1)])
def test_a_drone_stopped_short_of_a_goal_near_the_end_wall_reaches_it(start):
    """The goal lies 0.4 m from the end wall's face (x = 15.9), inside the path search's inflation: from a
    hover 0.4-0.9 m short of it (where corridor episodes timed out), the plans bring the drone within the
    closed loop's 0.4 m goal tolerance and keep it clear of the wall."""
    m = _corridor_map(end_wall=164)  # x >= 15.9
    pl = _planner()
    p, v = np.array(start), np.zeros(2)
    for k in range(40):
        tr = pl.plan(_input(0.1 * k, p, v, occupancy=m))
        p, v = tr.positions[1, :2], tr.velocities[1, :2]
        assert p[0] < 15.9 - 0.3
    assert np.hypot(*(p - GOAL[:2])) < 0.35 and np.hypot(*v) < 0.1


def test_a_walker_just_passed_does_not_turn_the_camera_from_a_fast_flight():
    """Flying on at 1.9 m/s past a walker now 1 m behind to its right, the camera keeps where the drone
    goes in view: the walker is watched where it and the drone will be in 0.5 and 1 s, by then 2-3 m
    apart. Watched from where the drone is now (the earlier rule), the walker outweighs the motion and the
    camera turns back to it, as on corridor seed 126 (dodt), where the drone then flew into a person ahead."""
    p, v = np.array([5.0, 0.0]), np.array([1.9, 0.0])
    person = ObstaclePrediction(id=1, center=np.array([4.2, -0.6, 0.9]), size=np.array([0.5, 0.6, 1.8]),
                                velocity=np.array([-0.2, 0.5, 0.0]))
    off = {}
    for name, kw in (("now", {}), ("earlier", dict(watch_times=(0.0, 0.0)))):
        pl = _planner(**kw)
        tr = pl.plan(_input(0.0, p, v, [person]))
        ahead = pl.last_maneuver.positions[10]
        assert ahead[0] - p[0] > 1.2  # flying on
        off[name] = _bearing_off(tr.yaw, p, ahead)
    assert off["now"] < pl.half_fov - 0.1
    assert off["earlier"] > pl.half_fov + 0.1


def test_the_half_view_is_the_context_cameras_unless_configured():
    import math
    from dataclasses import replace

    from context_factory import example_context
    from dodt.frames import CameraIntrinsics
    from dodt.geometry import half_view

    wide = CameraIntrinsics(width=848, height=480, fx=420.0, fy=420.0, cx=424.0, cy=240.0)
    pl = _planner()
    pl.reset(example_context(intrinsics=wide))
    assert pl.half_fov == half_view(wide) == math.atan2(424.0, 420.0)
    pl.reset(example_context())
    assert pl.half_fov == half_view(CameraIntrinsics())
    pinned = _planner(camera_half_fov=0.759)
    pinned.reset(example_context(intrinsics=wide))
    assert pinned.half_fov == 0.759


def test_a_drone_held_up_plans_with_the_stall_radius_and_returns_to_its_own():
    """No progress toward the goal over stall_window: the maneuvers and the MPC plan with stall_radius; once
    the drone gains stall_progress over the window again, with the vehicle's radius; never wider than it."""
    occ = _corridor_map()
    pl = _planner()  # the defaults: 0.35 m after 2 s with less than 1 m of progress
    radii = []
    for k in range(31):  # held at x = 5 for 3 s
        pl.plan(_input(0.1 * k, (5.0, 0.0), (0.0, 0.0), occupancy=occ))
        radii.append((pl.selector.r, pl.mpc.cfg.robot_radius))
    assert radii[19] == (R_ROBOT, R_ROBOT)  # under 2 s of record: not held up yet
    assert radii[20] == radii[-1] == (0.35, 0.35)
    for k in range(31, 52):  # then 1 m/s toward the goal: 2 m over the window
        pl.plan(_input(0.1 * k, (5.0 + 0.1 * (k - 30), 0.0), (1.0, 0.0), occupancy=occ))
    assert (pl.selector.r, pl.mpc.cfg.robot_radius) == (R_ROBOT, R_ROBOT)
    for kw, r in (({"stall_radius": None}, R_ROBOT), ({"mpc": MPCConfig(robot_radius=0.3)}, 0.3)):
        other = MPCPlanner(NavigatorConfig(**{"mpc": MPCConfig(robot_radius=R_ROBOT), **kw}))
        for k in range(31):
            other.plan(_input(0.1 * k, (5.0, 0.0), (0.0, 0.0), occupancy=occ))
        assert other.selector.r == r and other.mpc.cfg.robot_radius == r
