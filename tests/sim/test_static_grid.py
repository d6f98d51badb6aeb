"""The scenario's static geometry as a voxel grid (sim.static_grid)."""
import numpy as np

from conftest import make_scenario
from sim.static_grid import static_occupancy

ORIGIN, RES = np.array([-0.5, -2.5, -0.1]), 0.1
OBSTACLES = """
[[obstacles]]
kind = "pillar"
center = [3.0, -1.0]
radius = 0.25
height = 3.0

[[obstacles]]
kind = "box"
center = [6.0, 1.0]
size = [0.8, 0.6, 1.0]
"""


def _grid(extra=""):
    sc = make_scenario(extra)
    co = sc.corridor
    dims = np.round(np.array([co.length + 1.0, co.width + 1.0, co.height + 0.2]) / RES).astype(int)
    return sc, static_occupancy(sc, ORIGIN, dims, RES)


def _at(occ, x, y, z):
    i, j, k = np.floor((np.array([x, y, z]) - ORIGIN) / RES).astype(int)
    return bool(occ[i, j, k])


def test_walls_and_floor_are_occupied_and_the_corridor_is_free():
    sc, occ = _grid()
    co = sc.corridor
    for z in (0.5, 1.2, 2.5):
        assert _at(occ, 5.0, co.width / 2 + 0.05, z) and _at(occ, 5.0, -co.width / 2 - 0.05, z)  # side walls
        assert _at(occ, -0.05, 0.0, z) and _at(occ, co.length + 0.05, 0.0, z)  # end walls
    assert _at(occ, 5.0, 0.0, -0.05)  # the floor slab
    inside = occ[np.ix_(np.arange(6, 6 + 95), np.arange(6, 6 + 38), np.arange(2, 30))]
    assert not inside.any()  # nothing between the walls of an empty corridor


def test_obstacles_fill_their_footprint_up_to_their_height():
    sc, occ = _grid(OBSTACLES)
    assert _at(occ, 3.0, -1.0, 1.2) and _at(occ, 3.2, -1.0, 2.9)  # pillar, up to 3 m
    assert not _at(occ, 3.45, -1.0, 1.2) and not _at(occ, 3.0, -0.62, 1.2)  # 0.2 m beyond its radius: free
    assert _at(occ, 6.35, 1.25, 0.5) and _at(occ, 5.65, 0.75, 0.95)  # box corners
    assert not _at(occ, 6.0, 1.0, 1.15)  # above the 1 m box
    assert not _at(occ, 6.6, 1.0, 0.5) and not _at(occ, 6.0, 0.55, 0.5)  # beside it
    assert not _at(occ, 1.5, 0.0, 1.2)  # the flight line away from obstacles
