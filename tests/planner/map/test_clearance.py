"""Static clearance on the column grid (planner.map.clearance)."""
import numpy as np

from planner.map.clearance import outside_geofence, static_clearance
from planner.map.distance import exact_distance, opencv_distance

RES = 0.1
ORIGIN = np.array([-0.5, -2.5])


def test_outside_the_geofence_is_every_cell_whose_centre_lies_beyond_it():
    shape, fence = (40, 50), (np.array([0.0, -2.0]), np.array([3.0, 2.0]))
    out = outside_geofence(shape, ORIGIN, RES, fence)
    i, j = np.indices(shape)
    cx, cy = ORIGIN[0] + (i + 0.5) * RES, ORIGIN[1] + (j + 0.5) * RES
    want = (cx < fence[0][0]) | (cx > fence[1][0]) | (cy < fence[0][1]) | (cy > fence[1][1])
    np.testing.assert_array_equal(out, want)
    assert out.any() and not out.all()


def test_clearance_is_the_distance_to_the_nearest_blocked_edge_the_fence_counting_as_blocked():
    blocked = np.zeros((40, 50), bool)
    blocked[20, 25] = True
    fence = (np.array([0.0, -2.0]), np.array([3.0, 2.0]))
    clear = static_clearance(blocked, RES, ORIGIN, fence)
    solid = blocked | outside_geofence(blocked.shape, ORIGIN, RES, fence)
    np.testing.assert_array_equal(clear, exact_distance(solid) * RES - 0.5 * RES)
    assert clear[20, 25] == -0.5 * RES and clear[21, 25] == 0.5 * RES
    np.testing.assert_array_equal(static_clearance(blocked, RES), exact_distance(blocked) * RES - 0.5 * RES)


def test_nothing_blocked_gives_a_kilometre_everywhere_with_either_transform():
    free = np.zeros((6, 7), bool)
    for distance in (exact_distance, opencv_distance):
        np.testing.assert_array_equal(static_clearance(free, RES, distance=distance), np.full(free.shape, 1e3))


def test_the_shields_transform_gives_its_own_floats():
    rng = np.random.default_rng(0)
    blocked = rng.random((60, 40)) < 0.05
    got = static_clearance(blocked, RES, distance=opencv_distance)
    np.testing.assert_array_equal(got, opencv_distance(blocked) * RES - 0.5 * RES)
    np.testing.assert_allclose(got, static_clearance(blocked, RES), rtol=0, atol=1e-6)
