"""Trajectory sampling."""
import numpy as np

from planner.types import Trajectory


def test_sample_many_equals_sample_bit_for_bit():
    rng = np.random.default_rng(0)
    for n in (0, 1, 7, 25):
        for dt in (0.05, 0.1, 0.3):
            tr = Trajectory(float(rng.normal() * 50), dt, rng.normal(size=(n + 1, 3)), rng.normal(size=(n + 1, 3)),
                            rng.normal(size=(n, 3)))
            t = np.concatenate([tr.t0 + rng.uniform(-1, n * dt + 1, 30), tr.t0 + np.arange(-1, n + 3) * dt])
            P, V, A = tr.sample_many(t)
            for i, ti in enumerate(t):
                p, v, a = tr.sample(float(ti))
                assert np.array_equal(p, P[i]) and np.array_equal(v, V[i]) and np.array_equal(a, A[i])
