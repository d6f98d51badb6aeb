"""experiments.what_if: DODT's reports completed or corrected by the truth, on hand-made truth with DODT's
reports stubbed."""
from types import SimpleNamespace

import numpy as np
import pytest

from dodt.frames import CameraIntrinsics
from dodt.protocol import PerceptionOutput
from experiments import what_if
from experiments.registry import make_perception
from planner.types import ObstaclePrediction
from sim.ground_truth import ObstacleTruth

AHEAD, BEHIND, SIDE = (3.0, 0.0), (-2.0, 0.0), (0.0, 2.0)
K = CameraIntrinsics()


def _truth(stamp, people_xy):
    """A camera at (0, 0, 1.2) looking along +x (optical z forward) and people walking at people_xy."""
    T = np.eye(4)
    T[:3, :3] = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # optical -> world
    T[:3, 3] = [0.0, 0.0, 1.2]
    people = tuple(ObstacleTruth(id=i + 1, kind="person", label="person", aabb_min=np.array([x - 0.25, y - 0.25, 0.0]),
                                 aabb_max=np.array([x + 0.25, y + 0.25, 1.7]), velocity=np.array([0.5, 0.1, 0.0]))
                   for i, (x, y) in enumerate(people_xy))
    return SimpleNamespace(T_world_camera=T, obstacles=people, stamp=stamp)


def _frame(stamp=0.0, depth=2.75):
    image = np.full((K.height, K.width), depth, np.float32)
    return SimpleNamespace(intrinsics=K, stamp=stamp, depth_m=lambda: image)


class _Reports:
    """Stands in for DODT: reports the given obstacles at every frame."""

    def __init__(self, *reports):
        self.reports = reports

    def reset(self, context=None):
        pass

    def update(self, frame, truth=None):
        return PerceptionOutput(stamp=frame.stamp, obstacles=self.reports)


def _report(oid, xy):
    return ObstaclePrediction(id=oid, center=np.array([*xy, 0.85]), size=np.array([0.4, 0.4, 1.6]),
                              velocity=np.array([1.0, 0.0, 0.0]))


def _with(cls, *reports):
    p = cls()
    p.dodt = _Reports(*reports)
    return p


def _ids(p, stamp, people_xy, **frame):
    return [o.id for o in p.update(_frame(stamp, **frame), _truth(stamp, people_xy)).obstacles]


def test_recently_left_adds_a_person_for_a_second_after_they_leave_the_view():
    p = _with(what_if.RecentlyLeft)
    added = what_if.ADDED_ID + 1
    assert _ids(p, 0.0, [AHEAD]) == []  # in view: DODT's to report
    assert _ids(p, 0.5, [BEHIND]) == [added] and _ids(p, 1.0, [BEHIND]) == [added]
    assert _ids(p, 1.1, [BEHIND]) == []  # more than a second since
    assert _ids(p, 1.2, [AHEAD]) == [] and _ids(p, 1.7, [SIDE]) == [added]  # seen again, left again
    p.reset()
    assert _ids(p, 0.0, [BEHIND]) == []  # never in view since the reset


def test_an_added_person_is_exact_and_a_reported_one_is_not_added_again():
    p = _with(what_if.ViewCompleted)
    (o,) = p.update(_frame(), _truth(0.0, [AHEAD])).obstacles
    np.testing.assert_array_equal(o.center, [3.0, 0.0, 0.85])
    np.testing.assert_array_equal(o.size, [0.5, 0.5, 1.7])
    np.testing.assert_array_equal(o.velocity, [0.5, 0.1, 0.0])
    np.testing.assert_array_equal(o.acceleration, np.zeros(3))
    assert _ids(_with(what_if.ViewCompleted, _report(7, (3.5, 0.0))), 0.0, [AHEAD]) == [7]  # within 0.6 m
    assert _ids(_with(what_if.ViewCompleted, _report(7, (3.7, 0.0))), 0.0, [AHEAD]) == [7, what_if.ADDED_ID + 1]


@pytest.mark.parametrize("cls, added", [(what_if.SideCompleted, {2}), (what_if.ViewCompleted, {1}),
                                        (what_if.RecentlyLeft, set()), (what_if.TrueStates, set())])
def test_each_completion_adds_the_people_it_names(cls, added):
    # AHEAD in view, SIDE at 90 deg, BEHIND at 180 deg
    assert set(_ids(_with(cls), 0.0, [AHEAD, SIDE, BEHIND])) == {what_if.ADDED_ID + i for i in added}


def test_visible_completed_adds_only_a_person_the_depth_frame_shows():
    p = _with(what_if.VisibleCompleted)
    assert _ids(p, 0.0, [AHEAD], depth=2.75) == [what_if.ADDED_ID + 1]  # the body's near side at 2.75 m
    assert _ids(p, 0.0, [AHEAD], depth=1.0) == []  # something at 1 m hides them
    assert _ids(p, 0.0, [AHEAD], depth=0.0) == []  # no depth there
    assert _ids(p, 0.0, [BEHIND, SIDE], depth=2.75) == []  # outside the image


def test_true_states_corrects_reports_of_people_and_no_phantoms_drops_the_others():
    near, phantom = _report(7, (3.3, 0.2)), _report(8, (6.0, 1.0))
    truth = _truth(0.0, [AHEAD])
    fixed = _with(what_if.TrueStates, near, phantom).update(_frame(), truth).obstacles
    assert [o.id for o in fixed] == [7, 8]
    np.testing.assert_array_equal(fixed[0].center, truth.obstacles[0].center)
    np.testing.assert_array_equal(fixed[0].velocity, [0.5, 0.1, 0.0])
    assert fixed[1] is phantom
    kept = _with(what_if.NoPhantoms, near, phantom).update(_frame(), truth).obstacles
    assert kept == (near,)


def test_combined_completes_the_view_and_the_recently_left_and_corrects_the_reports():
    p = _with(what_if.Combined, _report(7, (3.3, 0.2)))
    out = p.update(_frame(0.0), _truth(0.0, [AHEAD, SIDE])).obstacles
    assert [o.id for o in out] == [7]  # AHEAD reported by DODT (corrected), SIDE never in view
    np.testing.assert_array_equal(out[0].center, [3.0, 0.0, 0.85])
    p.dodt = _Reports()
    assert _ids(p, 0.1, [AHEAD, SIDE]) == [what_if.ADDED_ID + 1]  # in view, no longer reported
    assert _ids(p, 0.6, [SIDE, SIDE]) == [what_if.ADDED_ID + 1]  # left the view 0.5 s ago


def test_what_if_modes_need_the_truth_and_plug_in_by_name():
    p = make_perception("experiments.what_if:ViewCompleted")
    assert isinstance(p, what_if.ViewCompleted) and p.uses_ground_truth and p.name == "dodt+ViewCompleted"
    ctx = _context_with_map()
    p.reset(ctx)  # the episode context's static map and geofence reach DODT's motion label
    assert p.dodt.dodt.motion.structure_test == ctx.static_map.established_fraction
    np.testing.assert_array_equal(p.dodt.dodt.motion.geofence[1], ctx.geofence[1])
    with pytest.raises(ValueError, match="ViewCompleted needs the simulator's ground truth"):
        p.update(_frame(), None)


def _context_with_map():
    from dataclasses import replace as _replace

    from context_factory import example_context
    from planner.map.voxel_map import VoxelMap

    return _replace(example_context(), static_map=VoxelMap())


def test_a_known_future_predicts_the_walk_from_its_stamp_and_advances_with_the_clock():
    from dataclasses import replace as _replace

    walk_t = np.array([0.0, 1.0, 2.0, 3.0])
    walk_xy = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [1.0, 2.0]])
    f = what_if.KnownFuture(id=1, center=np.array([0.55, 0.05, 0.9]), size=np.array([0.5, 0.5, 1.7]),
                            velocity=np.array([1.0, 0.0, 0.0]), std_growth=0.0, stamp=0.5, walk_t=walk_t,
                            walk_xy=walk_xy)
    # the walk from 0.5 s on, moved by the centre's 5 cm offset from it, at the centre's height
    np.testing.assert_allclose(f.predict(np.array([0.0, 1.0, 2.0, 9.0])),
                               [[0.55, 0.05, 0.9], [1.05, 0.55, 0.9], [1.05, 1.55, 0.9], [1.05, 2.05, 0.9]])
    g = f.advanced(1.0)
    assert isinstance(g, what_if.KnownFuture) and g.stamp == 1.5
    np.testing.assert_allclose(g.center, [1.05, 0.55, 0.9])
    np.testing.assert_allclose(g.velocity[:2], [0.0, 1.0])  # walking along the walk's second leg
    np.testing.assert_allclose(g.predict(np.array([0.5, 1.0])), f.predict(np.array([1.5, 2.0])))
    np.testing.assert_array_equal(f.std_at(np.array([0.0, 2.0])), [0.0, 0.0])
    # known for 0.25 s only: then on at the velocity it had then (the first leg's 1 m/s along x)
    h = _replace(f, known_for=0.25)
    np.testing.assert_allclose(h.predict(np.array([0.25, 1.25])), [[0.8, 0.05, 0.9], [1.8, 0.05, 0.9]], atol=1e-9)


def test_future_known_reports_everyone_near_with_their_true_walk():
    from dataclasses import replace as _replace

    from context_factory import example_context
    from sim import load_scenario
    from sim.crowd_future import blind_walk

    sc = load_scenario("corridor4", 3)
    times, walk = blind_walk(sc, 3, 6.0)
    p = make_perception("experiments.what_if:FutureKnown")
    p.reset(_replace(example_context(), scenario="corridor4", seed=3, duration=sc.duration))
    k = 240  # 2 s
    first = len(sc.obstacles) + 1
    people = tuple(ObstacleTruth(id=first + i, kind="person", label="person",
                                 aabb_min=np.array([x - 0.25, y - 0.25, 0.0]), aabb_max=np.array([x + 0.25, y + 0.25, 1.7]),
                                 velocity=np.zeros(3)) for i, (x, y) in enumerate(walk[k]))
    T = np.eye(4)
    T[:3, 3] = [float(walk[k, 0, 0]) - 1.0, float(walk[k, 0, 1]), 1.2]
    out = p.update(_frame(stamp=times[k]), SimpleNamespace(T_world_camera=T, obstacles=people, stamp=times[k]))
    assert out.obstacles  # everyone within 5 m, in any direction
    for o in out.obstacles:
        i = o.id - first
        np.testing.assert_allclose(o.predict(np.array([1.5]))[0, :2], walk[k + 180, i], atol=1e-9)
    # another episode under the same name: its people are not where the walk drawn again puts them
    moved = tuple(_replace(o, aabb_min=o.aabb_min + [0.5, 0.0, 0.0], aabb_max=o.aabb_max + [0.5, 0.0, 0.0])
                  for o in people)
    with pytest.raises(ValueError, match="not where the walk"):
        p.update(_frame(stamp=times[k]), SimpleNamespace(T_world_camera=T, obstacles=moved, stamp=times[k]))


@pytest.mark.parametrize("cls", [what_if.TrueStates, what_if.RecentlyLeft, what_if.NoPhantoms, what_if.Combined])
def test_what_if_modes_pass_a_rigs_scans_and_frames_to_dodt(cls):
    """On a rig, DODT under a what-if gets the LiDAR's scans and the other cameras' frames, as the dodt
    mode does (the closed loop hands them to a module that has observe_lidar / observe_cameras)."""
    seen = []
    p = cls()
    p.dodt = SimpleNamespace(observe_lidar=lambda scan: seen.append(("lidar", scan)),
                             observe_cameras=lambda frames: seen.append(("cameras", frames)))
    p.observe_lidar("scan-1")
    p.observe_cameras(("back",))
    assert seen == [("lidar", "scan-1"), ("cameras", ("back",))]
