"""DODT on simulated scenarios: the paper's traps, occlusion, and the false-positive check."""
import numpy as np
import pytest

from conftest import make_scenario
from dodt.pipeline import DODT
from dodt.presets import preset
from experiments.bench_perception import run_scenario
from experiments.perception_metrics import PerceptionMetrics
from sim import World

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def wall_pass():
    metrics, tracks, truth = run_scenario("wall_pass", 0, ["dodt", "dodt-no-fat"], record_tracks=True)
    return {k: m.summary() for k, m in metrics.items()}, tracks, truth


def _ids_while_passing_the_wall(tracks, truth, x_range=(3.5, 5.5)):
    """Per pass of the wall (x = 4.5; a pass: consecutive frames with the person within x_range), the
    set of dynamic tracks within 0.5 m of the person in each frame; and how many such frames there were."""
    passes, frames, inside = [], 0, False
    for frame_tracks, people in zip(tracks, truth):
        (_, px, py), = people
        if not x_range[0] <= px <= x_range[1]:
            inside = False
            continue
        if not inside:
            passes.append([])
            inside = True
        frames += 1
        passes[-1].append({tid for tid, x, y, dyn in frame_tracks if dyn and np.hypot(x - px, y - py) <= 0.5})
    return passes, frames


def test_person_passing_a_wall_keeps_its_id_and_the_wall_stays_static(wall_pass):
    summary, tracks, truth = wall_pass
    s = summary["dodt"]
    passes, frames = _ids_while_passing_the_wall(tracks["dodt"], truth)
    assert len(passes) >= 2 and frames > 50
    # one track follows the person through each pass of the wall, in nearly every frame (the person
    # walks back and forth: a new pass after the person has left the 3.5-5.5 m range may bring a new
    # track, never a change during a pass)
    for near in passes:
        held = max(set().union(*near), key=lambda tid: sum(tid in n for n in near))
        assert sum(held in n for n in near) >= 0.9 * len(near), near
    assert s["false_dynamic"] == 0  # the wall is never reported dynamic
    assert s["recall"] > 0.8
    assert s["pos_err"] < 0.12


def test_centre_distance_association_hands_the_persons_track_to_the_wall(wall_pass):
    # Paper Fig. 7: as the person passes close to the wall, centre-distance association gives
    # the person's track to the wall, which then stays dynamic for a while (the hysteresis of
    # identification keeps the track's label); DODT's feature association does not.
    summary, _, _ = wall_pass
    assert summary["dodt"]["false_dynamic"] == 0
    assert summary["dodt-no-fat"]["false_dynamic"] > 50


def test_partially_visible_static_obstacle_stays_static():
    metrics, _, _ = run_scenario("partial_obstacle", 0, ["dodt"])
    assert metrics["dodt"].summary()["dynamic_reports"] == 0


def test_static_only_scene_gives_at_most_a_blip():
    # Flying past static objects: a side wall seen at a grazing angle can blink dynamic for a
    # frame or two (measured: 2 of 421 frames); never more than 1 % of the frames
    metrics, _, _ = run_scenario("static_only", 0, ["dodt"])
    s = metrics["dodt"].summary()
    assert s["dynamic_reports"] <= 0.01 * s["frames"]


# The person is walking already when the scenario starts. A known limit: with start_delay = 0.5
# (standing, then speeding up for 1 s) the occlusion's onset, where less and less of the person
# is seen, drags the track's coasting velocity down to 0.63 m/s, and the person comes back out
# as a new track.
OCCLUSION = '''
[[obstacles]]
kind = "box"
center = [3.0, 0.0]
size = [0.3, 0.3, 2.0]
[[people]]
behaviour = "crossing"
speed = 1.0
height = 1.75
waypoints = [[5.0, -1.7], [5.0, 1.7]]
[camera_path]
keyframes = [[0.0, 0.8, 0.0, 1.3, 0.0]]
'''


def test_a_track_coasts_through_an_occlusion_and_keeps_its_id():
    w = World(make_scenario(OCCLUSION), seed=0, segmentation=True, renderer="tiny")
    pipe = DODT(preset("dodt"))
    ids, hidden_coasting = set(), []
    for _ in range(5 * 120):
        f = w.step()
        if f is None:
            continue
        truth = w.ground_truth()
        person = [o for o in truth.obstacles if o.kind == "person"][0]
        r = pipe.process(f)
        near = [o for o in r.dynamic if np.linalg.norm(o.center[:2] - person.center[:2]) < 0.6]
        ids |= {o.id for o in near}
        if np.count_nonzero(truth.segmentation == person.id) == 0:  # fully hidden behind the box
            hidden_coasting.append(any(o.coasting for o in near))
    w.close()
    assert len(ids) == 1  # one id before, during and after the occlusion
    assert hidden_coasting and all(hidden_coasting)  # reported, on its prediction, while hidden
