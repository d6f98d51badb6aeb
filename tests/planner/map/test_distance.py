"""The distance transforms (planner.map.distance) against scipy's."""
import numpy as np
from scipy.ndimage import distance_transform_edt

from planner.map.distance import exact_distance, opencv_distance


def _random_grids(n):
    rng = np.random.default_rng(1)
    for _ in range(n):
        nx, ny = rng.integers(1, 50, 2)
        f = rng.random((nx, ny)) < rng.random() ** 3
        f[rng.integers(0, nx), rng.integers(0, ny)] = True
        yield f


def test_equals_scipy_bit_for_bit_on_random_grids():
    for f in _random_grids(300):
        assert np.array_equal(exact_distance(f), distance_transform_edt(~f))


def test_single_feature_gives_the_euclidean_distance():
    f = np.zeros((7, 5), bool)
    f[2, 1] = True
    i, j = np.indices(f.shape)
    np.testing.assert_array_equal(exact_distance(f), np.sqrt((i - 2.0) ** 2 + (j - 1.0) ** 2))


def test_opencv_distance_is_within_float32_rounding_of_the_exact_one():
    for f in _random_grids(100):
        exact = exact_distance(f)
        np.testing.assert_allclose(opencv_distance(f), exact, rtol=1e-6, atol=0)
