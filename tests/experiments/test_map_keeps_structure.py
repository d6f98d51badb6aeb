"""A walker grazing a pillar, seen by a hovering drone with oracle perception: the map's dynamic clearing
frees the walker's voxels but keeps the pillar's near face (planner.map.voxel_map, protect_before)."""
from dataclasses import replace

import numpy as np
import pytest

from conftest import make_scenario
from experiments.episode import map_config_for
from experiments.perception_modes import OraclePerception
from planner.map.voxel_map import VoxelMap
from sim import World
from sim.controller import Reference

SCENE = """
name = "graze"
duration = 12.0
segmentation = false
[corridor]
length = 8.0
width = 4.0
height = 3.0
[[obstacles]]
kind = "pillar"
center = [5.0, 0.5]
radius = 0.25
height = 3.0
[[people]]
behaviour = "crossing"
speed = 1.0
start_delay = 2.0
waypoints = [[4.45, -1.7], [4.45, 1.7]]
[drone]
start = [1.5, 0.0, 1.2]
goal = [7.0, 0.0, 1.2]
"""


def _face_occupancy(map_kw) -> tuple[list[float], list[float]]:
    """Per map update while the walker is near the pillar: the share of the pillar's near-face voxels
    occupied, and the share of the walker's own voxels occupied."""
    sc = make_scenario(base=SCENE)
    w = World(sc, seed=0, frame_latency=0)
    m = VoxelMap(replace(map_config_for(sc, w.vehicle.radius), **map_kw))
    oracle = OraclePerception()
    oracle.reset()
    face = np.array([(4.78, y, z) for y in np.linspace(0.42, 0.58, 3) for z in (0.6, 0.9, 1.2)])
    hover = Reference.hover([1.5, 0.0, 1.2])
    shares, walker = [], []
    n = 0
    while w.time < 7.0:
        f = w.step(hover)
        if f is None:
            continue
        truth = w.ground_truth()
        po = oracle.update(f, truth)
        n += 1
        if n % 2:
            continue
        depth, _ = f.depth_m_counted()
        m.update(depth, f.intrinsics, f.T_world_camera, dynamic_boxes=po.clear_boxes, stamp=f.stamp)
        person = next(o for o in truth.obstacles if o.kind == "person")
        if abs(person.center[1] - 0.5) < 0.8:  # the walker is beside the pillar
            shares.append(float(m.is_occupied(face).mean()))
            body = np.array([(person.center[0], person.center[1], z) for z in (0.6, 0.9, 1.2)])
            walker.append(float(m.is_occupied(body).mean()))
    w.close()
    return shares, walker


@pytest.mark.slow
def test_a_walker_grazing_a_pillar_leaves_the_pillar_in_the_map():
    kept, walker = _face_occupancy({})
    assert len(kept) >= 10
    assert min(kept) == 1.0  # the face stays occupied all the while the walker grazes it
    assert max(walker) == 0.0  # and the walker leaves no voxels behind
    erased, _ = _face_occupancy({"static_after": 0, "protect_before": 0})  # the reference's clearing
    assert min(erased) < 0.5
