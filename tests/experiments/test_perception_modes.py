"""experiments.perception_modes: the oracle modes' view rules, on hand-made ground truth."""
import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from dodt.context import CameraSensor, LidarSensor
from dodt.frames import CameraIntrinsics
from experiments.perception_modes import OracleConfig, OraclePerception
from experiments.registry import known_modes, make_perception
from sim.ground_truth import ObstacleTruth
from sim.lidar import LidarModel, top_mount
from sim.rig import yaw_matrix
from tests.context_factory import example_context


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


@pytest.mark.parametrize("half_view, seen", [(None, {1}), (30.0, set()), (100.0, {1, 3}), (180.0, {1, 2, 3})])
def test_oracle_sees_people_in_the_view_it_is_given(half_view, seen):
    # person 1 at 38.7 deg (its body reaches 33.4 deg), BEHIND at 180 deg, SIDE at 90 deg
    p = OraclePerception(OracleConfig(half_view=half_view))
    assert {o.id for o in p.update(FRAME, _truth(0.0, [(3.0, 2.4), BEHIND, SIDE])).obstacles} == seen


def test_oracle_reports_a_person_coming_into_view_once_confirmed():
    p = OraclePerception(OracleConfig(memory=1.0, confirm_time=0.3))
    ids = lambda t, where: [o.id for o in p.update(FRAME, _truth(t, [where])).obstacles]
    assert ids(0.0, AHEAD) == [] and ids(0.2, AHEAD) == []  # in view for under 0.3 s
    assert ids(0.3, AHEAD) == [1] and ids(1.2, BEHIND) == [1]  # confirmed, then remembered out of view
    assert ids(1.5, BEHIND) == [] and ids(2.0, AHEAD) == []  # lost: a new sighting is confirmed again
    assert ids(2.3, AHEAD) == [1]
    with pytest.raises(ValueError, match="confirm_time must be >= 0"):
        OracleConfig(confirm_time=-0.1)


@pytest.mark.parametrize("bad", [0.0, -10.0, 181.0, math.nan])
def test_oracle_refuses_a_view_outside_0_to_180_degrees(bad):
    with pytest.raises(ValueError, match="half_view must be in"):
        OracleConfig(half_view=bad)


def test_oracle_remembers_a_person_for_its_memory_only():
    p = OraclePerception(OracleConfig(memory=1.0))
    p.update(FRAME, _truth(0.0, [AHEAD]))
    assert [o.id for o in p.update(FRAME, _truth(0.9, [BEHIND])).obstacles] == [1]  # left the view 0.9 s ago
    assert p.update(FRAME, _truth(1.1, [BEHIND])).obstacles == ()


def test_oracle_modes_are_known_and_need_the_truth():
    assert {"oracle", "oracle-360"} <= set(known_modes())
    with pytest.raises(ValueError, match="ground truth"):
        make_perception("oracle-360").update(FRAME, None)


def test_dodt_mode_passes_dodts_dynamic_tracks_and_clears_the_map_under_voted_ones_only():
    """The loop avoids every track DODT labels dynamic, with the filter's velocity; the map is freed under a
    voted one, not under one dynamic by its motion alone, nor under a slow learned person box."""
    from dodt.result import PerceptionResult, TrackedObstacle
    from experiments.perception_modes import DODTPerception

    def track(i, dynamic, evidence, speed=1.0, person=False):
        v = np.array([speed, 0.0, 0.0])
        return TrackedObstacle(id=i, center=np.array([3.0, float(i), 0.85]), size=np.array([0.5, 0.5, 1.7]),
                               velocity=v, acceleration=np.zeros(3), dynamic=dynamic, coasting=False, age=2.0,
                               history=np.zeros((0, 4)), is_person=person, filter_velocity=v, evidence=evidence)

    tracks = (track(1, True, "voting"), track(2, True, "motion", 0.2), track(3, False, ""),
              track(4, True, "person", 0.2, person=True), track(5, True, "person", 1.0, person=True))
    p = DODTPerception("dodt")
    p.dodt = SimpleNamespace(process=lambda f: PerceptionResult(stamp=0.0, seq=0, obstacles=tracks, timings_ms={}))
    out = p.update(None)
    assert [o.id for o in out.obstacles] == [1, 2, 4, 5]
    assert out.obstacles[1].velocity[0] == pytest.approx(0.2)
    assert [float(c[1]) for c, _ in out.clear_boxes] == [1.0, 5.0]


def test_oracle_acceleration_is_the_change_of_the_true_velocity():
    """A person turning from +x to +y at 1 m/s over 0.3 s: the oracle reports the velocity's change over
    its 0.1 s window; a person walking straight has none, and accel_window=None reports none."""
    def truth(stamp, vel):
        t = _truth(stamp, [AHEAD])
        (o,) = t.obstacles
        return SimpleNamespace(**{**vars(t), "obstacles": (replace(o, velocity=np.array(vel)),)})

    dt = 1.0 / 30.0
    turning = [(math.cos(a), math.sin(a), 0.0) for a in np.linspace(0.0, math.pi / 2, 10)]
    for window, expect_turn in ((0.1, True), (None, False)):
        p = OraclePerception(OracleConfig(accel_window=window))
        outs = [p.update(FRAME, truth(k * dt, v)) for k, v in enumerate(turning)]
        (ob,) = outs[-1].obstacles
        if expect_turn:
            np.testing.assert_allclose(ob.acceleration, (np.array(turning[-1]) - turning[-4]) / (3 * dt), atol=1e-9)
            assert np.hypot(*ob.acceleration[:2]) > 4.0  # turning at 5.2 rad/s at 1 m/s
        else:
            np.testing.assert_array_equal(ob.acceleration, np.zeros(3))
    p = OraclePerception()
    for k in range(6):
        (ob,) = p.update(FRAME, truth(k * dt, (0.5, 0.0, 0.0))).obstacles
    np.testing.assert_allclose(ob.acceleration, np.zeros(3), atol=1e-12)


def test_noisy_oracle_velocity_error_has_its_size_and_repeats():
    """oracle-noisy: the truth's positions and sizes, velocities off by a wandering error of about
    NOISY_ORACLE_VELOCITY_NOISE per axis; the same episode after reset() gives the same errors."""
    from experiments.perception_modes import NOISY_ORACLE_VELOCITY_NOISE
    p = make_perception("oracle-noisy")
    assert p.name == "oracle-noisy" and "oracle-noisy" in known_modes() and not p.uses_images

    def run():
        p.reset()
        errs = []
        for k in range(900):  # 30 s at 30 Hz, one person walking at +0.5 m/s in view
            (ob,) = p.update(FRAME, _truth(k / 30.0, [AHEAD])).obstacles
            np.testing.assert_allclose(ob.center, [3.0, 0.0, 0.85])
            errs.append(ob.velocity - np.array([0.5, 0.0, 0.0]))
        return np.array(errs)

    e = run()
    assert np.all(e[:, 2] == 0.0)
    assert 0.5 * NOISY_ORACLE_VELOCITY_NOISE < e[:, :2].std() < 1.5 * NOISY_ORACLE_VELOCITY_NOISE
    assert np.corrcoef(e[:-1, 0], e[1:, 0])[0, 1] > 0.85 and np.corrcoef(e[:-1, 1], e[1:, 1])[0, 1] > 0.85
    assert abs(np.corrcoef(e[:-90, 0], e[90:, 0])[0, 1]) < 0.3  # 3 s apart: unrelated
    np.testing.assert_array_equal(run(), e)
    exact = make_perception("oracle").update(FRAME, _truth(0.0, [AHEAD])).obstacles[0]
    np.testing.assert_array_equal(exact.velocity, [0.5, 0.0, 0.0])


def test_the_protocol_is_dodts_and_every_built_in_mode_implements_it():
    import dodt.protocol
    import experiments.perception_modes as pm

    assert pm.PerceptionModule is dodt.protocol.PerceptionModule
    assert pm.PerceptionOutput is dodt.protocol.PerceptionOutput
    for mode in pm.MODES:
        assert isinstance(make_perception(mode), dodt.protocol.PerceptionModule), mode


def test_the_planner_gets_the_tracks_but_not_the_filters_overstated_std(monkeypatch):
    from dodt.result import PerceptionResult, TrackedObstacle
    from experiments.perception_modes import DODTPerception
    from planner.types import ObstaclePrediction

    tracks = tuple(TrackedObstacle(id=i, center=np.array([3.0, i, 0.9]), size=np.array([0.5, 0.5, 1.8]),
                                   velocity=np.array([1.0, 0.0, 0.0]), acceleration=np.zeros(3), dynamic=True,
                                   coasting=i == 2, age=1.0, history=np.zeros((0, 4)), position_std=std)
                   for i, std in ((1, 0.12), (2, 0.8)))
    perc = DODTPerception("dodt")
    monkeypatch.setattr(perc.dodt, "process", lambda frame: PerceptionResult(0.0, 0, tracks, {}))
    out = perc.update(None)
    assert [o.id for o in out.obstacles] == [1, 2]
    assert [o.position_std for o in out.obstacles] == [0.0, 0.0]
    default = ObstaclePrediction(0, np.zeros(3), np.ones(3))
    assert [o.std_growth for o in out.obstacles] == [default.std_growth] * 2 and default.std_growth > 0


def _rig_context(*sensors):
    return replace(example_context(), sensors=example_context().sensors + tuple(sensors))


def test_the_oracle_sees_whom_some_sensor_of_the_rig_could_see():
    front = _rig_context().camera
    T_back = front.T_body_sensor.copy()
    T_back[:3, :3] = yaw_matrix(180.0) @ T_back[:3, :3]
    back = CameraSensor("back", front.intrinsics, T_back, rate=30.0, max_depth=10.0)
    people = [AHEAD, BEHIND, SIDE, FAR]
    for ctx, seen in ((_rig_context(), {1}), (_rig_context(back), {1, 2}),
                      (_rig_context(LidarSensor("top", LidarModel(), top_mount(), 10.0)), {1, 2, 3})):
        p = make_perception("oracle")
        p.reset(ctx)
        assert {o.id for o in p.update(FRAME, _truth(0.0, people)).obstacles} == seen


def _with_box(truth, lo, hi):
    box = ObstacleTruth(id=99, kind="static", label="box", aabb_min=np.array(lo, float), aabb_max=np.array(hi, float),
                        velocity=np.zeros(3))
    return SimpleNamespace(T_world_camera=truth.T_world_camera, obstacles=truth.obstacles + (box,), stamp=truth.stamp)


def test_the_line_of_sight_oracle_does_not_see_through_a_column():
    # a 0.8 m wide column 1.5 m ahead hides the person 3 m ahead, not the one beside it nor one behind the drone
    truth = _with_box(_truth(0.0, [AHEAD, (3.0, 1.5), BEHIND]), [1.3, -0.4, 0.0], [1.7, 0.4, 3.0])
    through = OraclePerception(OracleConfig(), all_around=True)
    assert {o.id for o in through.update(FRAME, truth).obstacles} == {1, 2, 3}
    sight = OraclePerception(OracleConfig(line_of_sight=True), all_around=True)
    assert {o.id for o in sight.update(FRAME, truth).obstacles} == {2, 3}
    # a low box (below the camera's 1.2 m and the person's body height it looks at) hides nobody
    low = _with_box(_truth(0.0, [AHEAD]), [1.3, -0.4, 0.0], [1.7, 0.4, 0.8])
    assert {o.id for o in OraclePerception(OracleConfig(line_of_sight=True)).update(FRAME, low).obstacles} == {1}
    # half hidden: one side of the body in sight is enough
    edge = _with_box(_truth(0.0, [AHEAD]), [1.3, -0.4, 0.0], [1.7, 0.05, 3.0])
    assert {o.id for o in OraclePerception(OracleConfig(line_of_sight=True)).update(FRAME, edge).obstacles} == {1}


def test_the_line_of_sight_oracle_remembers_a_person_who_went_behind_a_column_for_its_memory():
    column = ([1.3, -0.4, 0.0], [1.7, 0.4, 3.0])
    p = OraclePerception(OracleConfig(line_of_sight=True, memory=1.0), all_around=True)
    assert [o.id for o in p.update(FRAME, _with_box(_truth(0.0, [(3.0, 1.5)]), *column)).obstacles] == [1]
    hidden = lambda t: [o.id for o in p.update(FRAME, _with_box(_truth(t, [AHEAD]), *column)).obstacles]  # noqa: E731
    assert hidden(0.9) == [1] and hidden(1.1) == []


def test_segment_blocked_is_the_slab_test():
    from experiments.perception_modes import segment_blocked
    lo, hi = np.array([[1.0, -1.0, 0.0]]), np.array([[2.0, 1.0, 1.0]])
    p0 = np.array([0.0, 0.0, 0.5])
    assert segment_blocked(p0, np.array([3.0, 0.0, 0.5]), lo, hi)  # through it
    assert not segment_blocked(p0, np.array([0.9, 0.0, 0.5]), lo, hi)  # ends before it
    assert segment_blocked(p0, np.array([3.0, 0.0, 1.5]), lo, hi)  # rising through its top half
    assert not segment_blocked(np.array([0.0, 0.0, 1.5]), np.array([3.0, 0.0, 1.5]), lo, hi)  # above it, flat in z
    assert not segment_blocked(np.array([0.0, 2.0, 0.5]), np.array([3.0, 2.0, 0.5]), lo, hi)  # beside it, flat in y
    assert segment_blocked(np.array([1.5, 0.0, 0.5]), np.array([5.0, 0.0, 0.5]), lo, hi)  # starts inside
    assert not segment_blocked(p0, np.array([3.0, 0.0, 0.5]), np.zeros((0, 3)), np.zeros((0, 3)))
