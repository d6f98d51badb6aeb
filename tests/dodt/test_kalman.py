"""The Kalman filters of paper Sec. III-C: constant acceleration (DODT) and constant velocity.

The convergence tests feed the filter the same kind of measurement the tracker does:
position, plus velocity and acceleration as finite-difference pseudo-measurements over up to
``averaging_time`` (10 frames at 30 Hz) of (noisy) detected positions (dodt.tracker.Track.update). A test
checks that the helper below builds exactly what the tracker builds.
"""
from __future__ import annotations

import numpy as np
import pytest

from dodt.config import DODTConfig, KalmanConfig
from dodt.detection import Detection
from dodt.kalman import KalmanFilter
from dodt.tracker import Track

FPS = 30.0
DURATION = 6.0
NOISE = 0.03  # m, standard deviation of the detected position
SEEDS = range(5)
ACC = np.array([0.4, -0.2])


def trajectory(t: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact constant acceleration: x = 1 + 0.5 t + 0.5 * 0.4 t^2, y = -2 + 0.3 t - 0.5 * 0.2 t^2."""
    p = np.array([1.0 + 0.5 * t + 0.5 * ACC[0] * t * t, -2.0 + 0.3 * t + 0.5 * ACC[1] * t * t])
    v = np.array([0.5 + ACC[0] * t, 0.3 + ACC[1] * t])
    return p, v


class PseudoMeasurements:
    """[x, y, vx, vy, ax, ay] as dodt.tracker.Track.update builds them.

    v = (p_now - p_prev) / dt with p_prev the observation up to ``averaging_frames`` back (at a
    steady frame rate, the oldest within the tracker's averaging_time);
    a = (v - v_prev) / dt with v_prev the pseudo-velocity stored with that observation; the
    first observation has none, and then a is the filter's own acceleration estimate (no
    innovation).
    """

    def __init__(self, averaging_frames: int):
        self.n = averaging_frames
        self.obs: list[tuple[float, np.ndarray, np.ndarray]] = []  # (stamp, position, velocity)

    def first(self, stamp: float, p: np.ndarray) -> None:
        self.obs = [(stamp, np.asarray(p, float), None)]

    def __call__(self, stamp: float, p: np.ndarray, a_filter=(0.0, 0.0)) -> np.ndarray:
        p = np.asarray(p, float)
        prev = self.obs[max(0, len(self.obs) - self.n)]
        dt = stamp - prev[0]
        v = (p - prev[1]) / dt
        a = (v - prev[2]) / dt if prev[2] is not None else np.asarray(a_filter, float)
        self.obs.append((stamp, p, v))
        self.obs = self.obs[-(self.n + 1):]
        return np.concatenate([p, v, a])


# The reference code's noise values; our defaults trust the velocity pseudo-measurement more
# (p0 4, r_vel 0.1: a new track's speed passes T_vel sooner), which on this synthetic target
# raises the steady-state velocity error (CA, seeds 0-4: 0.116 -> 0.131 m/s RMS).
REF_NOISE = dict(p0=0.25, r_vel=0.3)


def run_filter(model: str, seed: int, noise: float = NOISE, **cfg_overrides):
    """Filter the trajectory at 30 Hz for 6 s; per-frame position / velocity errors and the
    raw measurement error, plus the filters' states."""
    cfg = KalmanConfig(model=model, **(REF_NOISE | cfg_overrides))
    rng = np.random.default_rng(seed)
    times = np.arange(0.0, DURATION + 1e-9, 1.0 / FPS)
    meas = PseudoMeasurements(round(cfg.averaging_time * FPS))
    kf = None
    pos_err, vel_err, raw_err, states = [], [], [], []
    for k, t in enumerate(times):
        p, v = trajectory(t)
        z = p + rng.normal(0.0, noise, 2)
        if kf is None:
            kf = KalmanFilter(cfg, z)
            meas.first(t, z)
        else:
            kf.predict(t - times[k - 1])
            kf.update(meas(t, z, kf.acceleration.copy()))
        pos_err.append(np.linalg.norm(kf.position - p))
        vel_err.append(np.linalg.norm(kf.velocity - v))
        raw_err.append(np.linalg.norm(z - p))
        states.append(kf.x.copy())
    return np.array(pos_err), np.array(vel_err), np.array(raw_err), kf, states


FIRST = slice(0, int(FPS))  # the first second
LAST = slice(-int(FPS), None)  # the last second


@pytest.fixture(scope="module")
def runs():
    return {m: [run_filter(m, s) for s in SEEDS] for m in ("ca", "cv")}


# --------------------------------------------------------------------------- model matrices


def test_ca_transition_matrix_is_the_papers_for_dt_0_1():
    kf = KalmanFilter(KalmanConfig(model="ca"), np.zeros(2))
    dt = 0.1
    expected = np.array([
        [1, 0, dt, 0, 0.5 * dt * dt, 0],
        [0, 1, 0, dt, 0, 0.5 * dt * dt],
        [0, 0, 1, 0, dt, 0],
        [0, 0, 0, 1, 0, dt],
        [0, 0, 0, 0, 1, 0],
        [0, 0, 0, 0, 0, 1],
    ])
    F = kf.F(dt)
    assert F.shape == (6, 6)
    np.testing.assert_allclose(F, expected, atol=1e-15)
    assert F[0, 4] == pytest.approx(0.005) and F[1, 5] == pytest.approx(0.005)
    assert F[0, 2] == pytest.approx(0.1) and F[2, 4] == pytest.approx(0.1)


def test_cv_transition_matrix():
    kf = KalmanFilter(KalmanConfig(model="cv"), np.zeros(2))
    np.testing.assert_allclose(kf.F(0.1), [[1, 0, 0.1, 0], [0, 1, 0, 0.1], [0, 0, 1, 0], [0, 0, 0, 1]])
    assert kf.x.shape == (4,)
    np.testing.assert_array_equal(kf.acceleration, [0.0, 0.0])


def test_initial_state_and_covariance():
    cfg = KalmanConfig(model="ca")
    kf = KalmanFilter(cfg, np.array([1.5, -2.0, 0.9]))
    np.testing.assert_array_equal(kf.x, [1.5, -2.0, 0, 0, 0, 0])
    np.testing.assert_array_equal(kf.P, np.eye(6) * cfg.p0)
    np.testing.assert_array_equal(np.diag(kf.Q), [cfg.q_pos] * 2 + [cfg.q_vel] * 2 + [cfg.q_acc] * 2)
    np.testing.assert_array_equal(np.diag(kf.R), [cfg.r_pos] * 2 + [cfg.r_vel] * 2 + [cfg.r_acc] * 2)
    assert kf.position_variance == pytest.approx(cfg.p0)


def test_predict_propagates_the_state_exactly():
    kf = KalmanFilter(KalmanConfig(model="ca"), np.zeros(2))
    kf.x = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    kf.predict(0.1)
    np.testing.assert_allclose(kf.x, [1 + 0.3 + 0.025, 2 + 0.4 + 0.03, 3.5, 4.6, 5.0, 6.0])
    cv = KalmanFilter(KalmanConfig(model="cv"), np.zeros(2))
    cv.x = np.array([1.0, 2.0, 3.0, 4.0])
    cv.predict(0.1)
    np.testing.assert_allclose(cv.x, [1.3, 2.4, 3.0, 4.0])


def test_first_update_by_hand():
    """H = I and diagonal P, R: the gain is P / (P + R) per component."""
    cfg = KalmanConfig(model="ca")
    kf = KalmanFilter(cfg, np.zeros(2))
    z = np.array([0.2, -0.1, 1.0, 0.5, 0.3, -0.3])
    kf.update(z)
    r = np.array([cfg.r_pos] * 2 + [cfg.r_vel] * 2 + [cfg.r_acc] * 2)
    gain = cfg.p0 / (cfg.p0 + r)
    np.testing.assert_allclose(kf.x, gain * z)
    np.testing.assert_allclose(kf.P, np.diag(cfg.p0 * r / (cfg.p0 + r)))


def test_weak_axis_update_by_hand():
    """A weak axis multiplies R along it by weak_factor: rotated to that axis, the gain is
    P / (P + factor r) along it and P / (P + r) across it, per quantity."""
    cfg = KalmanConfig(model="ca")
    axis = np.array([np.cos(0.5), np.sin(0.5)])
    across = np.array([-axis[1], axis[0]])
    z = np.array([0.2, -0.1, 1.0, 0.5, 0.3, -0.3])
    kf = KalmanFilter(cfg, np.zeros(2))
    kf.update(z, weak_axis=axis, weak_factor=100.0)
    for i, r in ((0, cfg.r_pos), (2, cfg.r_vel), (4, cfg.r_acc)):
        along, side = kf.x[i:i + 2] @ axis, kf.x[i:i + 2] @ across
        assert along == pytest.approx(cfg.p0 / (cfg.p0 + 100.0 * r) * (z[i:i + 2] @ axis))
        assert side == pytest.approx(cfg.p0 / (cfg.p0 + r) * (z[i:i + 2] @ across))
    plain = KalmanFilter(cfg, np.zeros(2))
    plain.update(z, weak_axis=axis, weak_factor=1.0)
    ref = KalmanFilter(cfg, np.zeros(2))
    ref.update(z)
    np.testing.assert_array_equal(plain.x, ref.x)


def test_cv_filter_ignores_the_acceleration_measurement():
    a = KalmanFilter(KalmanConfig(model="cv"), np.zeros(2))
    b = KalmanFilter(KalmanConfig(model="cv"), np.zeros(2))
    a.update([0.2, -0.1, 1.0, 0.5, 10.0, -10.0])
    b.update([0.2, -0.1, 1.0, 0.5])
    np.testing.assert_array_equal(a.x, b.x)


@pytest.mark.parametrize("model", ["ca", "cv"])
def test_predict_grows_and_update_shrinks_the_covariance(model):
    kf = KalmanFilter(KalmanConfig(model=model, **REF_NOISE), np.zeros(2))
    rng = np.random.default_rng(3)
    for _ in range(50):
        P0 = kf.P.copy()
        kf.predict(1 / 30)
        P1 = kf.P.copy()
        # F P F^T + Q - P is positive semi-definite here (measured: smallest eigenvalue 0.0086)
        assert np.trace(P1) > np.trace(P0)
        assert np.min(np.linalg.eigvalsh(P1 - P0)) > -1e-12
        kf.update(np.concatenate([rng.normal(0, 0.1, 2), rng.normal(0, 0.5, 2), rng.normal(0, 1, 2)])[: kf.n])
        P2 = kf.P.copy()
        assert np.trace(P2) < np.trace(P1)
        assert np.min(np.linalg.eigvalsh(P1 - (P2 + P2.T) / 2)) > -1e-12
        assert np.min(np.linalg.eigvalsh((P2 + P2.T) / 2)) > 0
        np.testing.assert_allclose(P2, P2.T, atol=1e-12)


@pytest.mark.parametrize("model", ["ca", "cv"])
def test_covariance_converges_to_a_steady_state(model):
    kf = KalmanFilter(KalmanConfig(model=model), np.zeros(2))
    z = np.zeros(kf.n)
    traces = []
    for _ in range(300):
        kf.predict(1 / 30)
        kf.update(z)
        traces.append(np.trace(kf.P))
    assert abs(traces[-1] - traces[-2]) < 1e-9
    assert 0 < traces[-1] < np.trace(np.eye(kf.n) * KalmanConfig().p0)


# --------------------------------------------------------------------------- pseudo-measurements


def test_pseudo_measurements_match_the_tracker():
    """The helper builds the same [x, y, vx, vy, ax, ay] as dodt.tracker.Track.update (the
    paper's pseudo-measurements: turn compensation off)."""
    cfg = DODTConfig(kalman=KalmanConfig(turn_window=0.0))
    rng = np.random.default_rng(11)
    times = np.arange(0.0, 1.5, 1.0 / FPS)

    def det(t):
        p, _ = trajectory(t)
        c = np.array([p[0], p[1], 0.9]) + np.r_[rng.normal(0, NOISE, 2), 0.0]
        return Detection(center=c, size=np.array([0.5, 0.5, 1.7]), source="dbscan")

    d0 = det(times[0])
    track = Track(1, d0, 0, times[0], cfg)
    fed = []
    real_update = track.kf.update
    track.kf.update = lambda z, **kw: (fed.append(np.array(z, float)), real_update(z, **kw))
    meas = PseudoMeasurements(round(cfg.kalman.averaging_time * FPS))
    meas.first(times[0], d0.center[:2])
    built = []
    for k, t in enumerate(times[1:], start=1):
        d = det(t)
        track.kf.predict(t - times[k - 1])
        a_filter = track.kf.acceleration.copy()
        track.update(d, k, t)
        built.append(meas(t, d.center[:2], a_filter))
    assert len(fed) == len(built) == len(times) - 1
    np.testing.assert_allclose(np.array(fed), np.array(built), rtol=1e-12, atol=1e-12)


# --------------------------------------------------------------------------- convergence


def test_ca_filter_converges_on_a_constant_acceleration_trajectory(runs):
    pos_first = np.mean([r[0][FIRST].mean() for r in runs["ca"]])
    pos_last = np.mean([r[0][LAST].mean() for r in runs["ca"]])
    vel_first = np.mean([r[1][FIRST].mean() for r in runs["ca"]])
    vel_last = np.mean([r[1][LAST].mean() for r in runs["ca"]])
    raw_last = np.mean([r[2][LAST].mean() for r in runs["ca"]])
    # measured (5 seeds, averaging_frames 15): position 2.4 cm -> 1.8 cm, raw measurement error
    # 3.6 cm; velocity 0.27 m/s -> 0.107 m/s
    assert vel_last < 0.5 * vel_first
    assert vel_last < 0.13
    assert pos_last < pos_first
    assert pos_last < 0.03
    assert pos_last < 0.7 * raw_last  # the filter beats the raw detections


@pytest.mark.parametrize("seed", SEEDS)
def test_ca_filter_error_bounds_per_seed(runs, seed):
    pos, vel, raw, kf, states = runs["ca"][seed]
    # measured over seeds 0-4 (averaging_frames 15): last-second mean velocity error
    # <= 0.123 m/s, max <= 0.21 m/s; last-second mean position error <= 2.1 cm, max <= 4.3 cm
    assert vel[LAST].mean() < 0.15
    assert vel[LAST].max() < 0.35
    assert pos[LAST].mean() < 0.03
    assert pos[LAST].max() < 0.065
    # the acceleration state finds the true acceleration (measured: within 0.05 m/s^2 on the
    # last-second mean)
    acc_last = np.array([s[4:6] for s in states[LAST]]).mean(axis=0)
    assert np.linalg.norm(acc_last - ACC) < 0.2
    assert all(np.all(np.isfinite(s)) for s in states)
    assert np.all(np.isfinite(kf.P))


def test_ca_beats_cv_on_velocity_for_an_accelerating_target(runs):
    """RMS velocity error after the first second: CA lower than CV (measured 0.124 vs 0.148 m/s
    on average over the seeds, lower for every seed)."""
    after = slice(int(FPS), None)
    rms = {m: np.array([np.sqrt(np.mean(r[1][after] ** 2)) for r in runs[m]]) for m in runs}
    assert rms["ca"].mean() < 0.95 * rms["cv"].mean()
    assert np.all(rms["ca"] < rms["cv"])
    # with our default noise values the margin shrinks (measured 0.131 vs 0.135) but CA stays ahead
    d = {m: np.array([np.sqrt(np.mean(run_filter(m, s, p0=KalmanConfig().p0, r_vel=KalmanConfig().r_vel)[1][after] ** 2))
                      for s in SEEDS]) for m in ("ca", "cv")}
    assert np.all(d["ca"] < d["cv"])


def test_ca_beats_cv_without_noise():
    """Noise-free: the CV filter lags an accelerating target more than the CA filter.

    Neither reaches zero: the finite-difference velocity over the window is the mean velocity
    of the window, i.e. the velocity half a window ago, fed as the current one; so its floor is
    |a| * averaging_time / 2 (0.112 m/s for 15 frames at 30 Hz). Measured with 15 frames:
    last-second velocity error 0.110 m/s for CA, 0.140 m/s for CV."""
    ca = run_filter("ca", 0, noise=0.0)
    cv = run_filter("cv", 0, noise=0.0)
    lag = np.linalg.norm(ACC) * KalmanConfig().averaging_time / 2
    assert ca[1][LAST].mean() < 0.9 * cv[1][LAST].mean()
    assert ca[1][LAST].mean() < 1.1 * lag
    assert ca[0][LAST].mean() < 0.01


@pytest.mark.parametrize("model", ["ca", "cv"])
def test_state_stays_finite_through_long_predictions(model):
    kf = KalmanFilter(KalmanConfig(model=model), np.array([1.0, 2.0]))
    kf.update(np.array([1.0, 2.0, 1.0, -1.0, 0.5, 0.5])[: kf.n])
    for dt in (1 / 30, 0.5, 5.0, 60.0):
        kf.predict(dt)
        assert np.all(np.isfinite(kf.x)) and np.all(np.isfinite(kf.P))
    kf.update(np.array([100.0, -50.0, 0.0, 0.0, 0.0, 0.0])[: kf.n])
    assert np.all(np.isfinite(kf.x)) and np.all(np.isfinite(kf.P))
    # after a long prediction the filter trusts the new position almost entirely
    np.testing.assert_allclose(kf.position, [100.0, -50.0], atol=0.5)


def test_position_only_measurement_option_tracks_a_constant_velocity_target():
    # measurement = "position": only x, y are measured; the white-jerk model carries velocity
    cfg = KalmanConfig(model="ca", measurement="position", q_white=1.0, r_pos=0.01)
    kf = KalmanFilter(cfg, np.array([0.0, 0.0]))
    rng = np.random.default_rng(0)
    dt = 1 / 30
    for k in range(1, 181):
        kf.predict(dt)
        t = k * dt
        kf.update(np.array([1.0 * t, -0.5 * t]) + rng.normal(0, 0.03, 2))
    np.testing.assert_allclose(kf.velocity, [1.0, -0.5], atol=0.15)
    assert kf.Q_for(dt)[0, 0] == pytest.approx(1.0 * dt**5 / 20)


# --------------------------------------------------------------------------- turn compensation


def _track_walker(path, turn_window: float, seconds: float = 8.0, seed: int = 0) -> float:
    """Mean velocity error of a track fed noisy detections of a walker after 2 s."""
    cfg = DODTConfig(kalman=KalmanConfig(turn_window=turn_window))
    rng = np.random.default_rng(seed)
    times = np.arange(0.0, seconds, 1.0 / FPS)

    def det(t):
        p, _ = path(t)
        c = np.array([p[0], p[1], 0.9]) + np.r_[rng.normal(0, NOISE, 2), 0.0]
        return Detection(center=c, size=np.array([0.5, 0.5, 1.7]), source="dbscan")

    track = Track(1, det(0.0), 0, 0.0, cfg)
    errors = []
    for k, t in enumerate(times[1:], start=1):
        track.kf.predict(t - times[k - 1])
        track.update(det(t), k, t)
        if t >= 2.0:
            errors.append(np.linalg.norm(track.kf.velocity - path(t)[1]))
    return float(np.mean(errors))


def _circle(t, r=1.0, speed=1.0):
    w = speed / r
    return (np.array([r * np.cos(w * t), r * np.sin(w * t)]),
            np.array([-speed * np.sin(w * t), speed * np.cos(w * t)]))


def _swaying_line(t, speed=1.0, sway=0.03, period=1.1):
    """Straight walk with the body swaying sideways at the gait period."""
    w = 2 * np.pi / period
    return (np.array([speed * t, sway * np.sin(w * t)]), np.array([speed, sway * w * np.cos(w * t)]))


@pytest.mark.parametrize("seed", range(3))
def test_turn_compensation_removes_the_lag_on_a_circle_and_leaves_straight_walks_alone(seed):
    """On a circle (1 m radius at 1 m/s, as in the circles scenario) the 10-frame difference
    points 1/6 rad behind; rotated forward by the sustained turn rate, the filtered velocity
    error falls by a quarter or more (0.18-0.19 -> 0.10-0.12 m/s here). On a straight walk with
    gait sway it stays within 5 % (1-3 % worse here)."""
    lagging, compensated = _track_walker(_circle, 0.0, seed=seed), _track_walker(_circle, 1.0, seed=seed)
    assert compensated < 0.75 * lagging, (lagging, compensated)
    straight, straight_comp = _track_walker(_swaying_line, 0.0, seed=seed), _track_walker(_swaying_line, 1.0, seed=seed)
    assert straight_comp < 1.05 * straight, (straight, straight_comp)
