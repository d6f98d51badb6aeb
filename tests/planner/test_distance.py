"""The compiled distance transform against scipy's."""
import numpy as np
from scipy.ndimage import distance_transform_edt

from planner.map.distance import distance_to


def test_equals_scipy_bit_for_bit_on_random_grids():
    rng = np.random.default_rng(1)
    for _ in range(300):
        nx, ny = rng.integers(1, 50, 2)
        f = rng.random((nx, ny)) < rng.random() ** 3
        f[rng.integers(0, nx), rng.integers(0, ny)] = True
        assert np.array_equal(distance_to(f), distance_transform_edt(~f))


def test_single_feature_gives_the_euclidean_distance():
    f = np.zeros((7, 5), bool)
    f[2, 1] = True
    i, j = np.indices(f.shape)
    np.testing.assert_array_equal(distance_to(f), np.sqrt((i - 2.0) ** 2 + (j - 1.0) ** 2))
