"""ObstaclePrediction.predict: its compiled loop gives the floats of the prediction's definition in numpy."""
import numpy as np
import pytest

from planner.types import ObstaclePrediction


def _by_definition(ob: ObstaclePrediction, times) -> np.ndarray:
    """Constant acceleration for accel_horizon, then the velocity reached, its speed capped at max_speed."""
    t = np.asarray(times, dtype=float)[:, None]
    ta = np.minimum(t, ob.accel_horizon)
    v_end = ob.velocity + ob.acceleration * ta
    speed = np.linalg.norm(v_end, axis=1, keepdims=True)
    cruise = v_end * np.where(speed > ob.max_speed, ob.max_speed / np.maximum(speed, 1e-9), 1.0)
    return ob.center + ((ob.velocity * ta + 0.5 * ob.acceleration * ta * ta) + cruise * (t - ta))


@pytest.mark.parametrize("seed", range(3))
def test_predict_gives_the_definitions_floats(seed):
    rng = np.random.default_rng(seed)
    for i in range(2000):
        ob = ObstaclePrediction(id=1, center=rng.normal(0, 5, 3), size=np.ones(3),
                                velocity=rng.normal(0, 1.5, 3) * rng.choice([0, 1, 3]),
                                acceleration=rng.normal(0, 1, 3) * rng.choice([0, 1]),
                                accel_horizon=float(rng.choice([0.0, 0.5, 1.0, np.inf])),
                                max_speed=float(rng.choice([0.0, 1.0, 2.5])))
        t = [0.1 * np.arange(1, 26), np.sort(rng.uniform(0, 5, rng.integers(0, 30))), np.array([0.0, 2.0, 1.0])][i % 3]
        got, want = ob.predict(t), _by_definition(ob, t)
        assert got.shape == want.shape and got.tobytes() == want.tobytes()


def test_predict_names_a_centre_of_the_wrong_size():
    with pytest.raises(ValueError, match="3 values"):
        ObstaclePrediction(id=1, center=np.zeros(2), size=np.ones(3)).predict(np.array([0.1]))
