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
    metrics, _, _ = run_scenario("wall_pass", 0, ["dodt", "dodt-no-fat"])
    return {k: m.summary() for k, m in metrics.items()}


def test_person_passing_a_wall_keeps_its_id_and_the_wall_stays_static(wall_pass):
    s = wall_pass["dodt"]
    assert s["id_switches"] <= 1
    assert s["false_dynamic"] == 0  # the wall is never reported dynamic
    assert s["recall"] > 0.8
    assert s["pos_err"] < 0.12


def test_centre_distance_association_keeps_the_wall_static_too(wall_pass):
    # Paper Fig. 7: centre-distance association can hand the person's track to the wall. In this
    # implementation the wall still never turns dynamic (identification votes against the whole
    # cloud k frames back, where the wall's points have not moved); measured, not assumed.
    assert wall_pass["dodt-no-fat"]["false_dynamic"] == 0
    assert wall_pass["dodt-no-fat"]["id_switches"] <= 2


def test_partially_visible_static_obstacle_stays_static():
    metrics, _, _ = run_scenario("partial_obstacle", 0, ["dodt"])
    assert metrics["dodt"].summary()["dynamic_reports"] == 0


def test_static_only_scene_gives_at_most_a_blip():
    # Flying past static objects: a side wall seen at a grazing angle can blink dynamic for a
    # frame or two (measured: 2 of 421 frames); never more than 1 % of the frames
    metrics, _, _ = run_scenario("static_only", 0, ["dodt"])
    s = metrics["dodt"].summary()
    assert s["dynamic_reports"] <= 0.01 * s["frames"]


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
start_delay = 0.5
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
