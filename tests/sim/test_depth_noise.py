"""Depth noise: the measured sigma matches the model; every component is switchable."""
import dataclasses

import numpy as np
import pytest

from conftest import make_scenario
from sim import World
from sim.depth_noise import DepthNoiseModel, apply_depth_noise, axial_sigma
from sim.scenario import Noise

FX = 387.1537


@pytest.mark.parametrize("distance", [1.0, 2.0, 3.0])
def test_measured_sigma_on_a_wall_matches_the_intel_rms_model(distance):
    # The camera faces the corridor's end wall (x = 10) from `distance` away; the full
    # pipeline runs: render, noise (defaults), range limits, 1 mm quantisation to uint16.
    body_x = 10.0 - distance - 0.065
    sc = make_scenario(f"[camera_path]\nkeyframes = [[0.0, {body_x}, 0.0, 1.5, 0.0]]\n")
    w = World(sc, seed=3, renderer="tiny")
    z = w.latest_frame().depth_m()[140:340, 220:420]  # centre of the image: all end wall
    valid = z > 0
    err = z[valid] - distance
    model = axial_sigma(np.float32(distance), w.scenario.noise, FX)
    assert abs(np.std(err) / model - 1.0) < 0.10
    assert abs(np.mean(err)) < 0.1 * model + 0.0005  # unbiased
    # the default dropout leaves a small fraction of invalid pixels
    assert 0.001 < 1 - valid.mean() < 0.02
    w.close()


def test_sigma_grows_with_the_square_of_distance():
    n = Noise()
    s1, s2, s3 = (float(axial_sigma(np.float32(z), n, FX)) for z in (1.0, 2.0, 3.0))
    assert s2 / s1 == pytest.approx(4.0, rel=1e-5) and s3 / s1 == pytest.approx(9.0, rel=1e-5)
    assert s1 == pytest.approx(0.08 / (FX * 0.05), rel=1e-5)  # about 4.1 mm at 1 m


def _step_image():
    z = np.full((120, 160), 2.0, np.float32)
    z[:, 80:] = 4.0  # a depth edge between columns 79 and 80
    z[:10] = 0.0  # invalid band: makes no edge by itself
    return z


def test_edges_get_holes_and_flying_pixels_only_at_the_edge():
    n = Noise(axial_model="none", dropout=0.0, edge_hole_prob=0.5, flying_pixel_prob=0.5)
    out = apply_depth_noise(_step_image(), n, FX, np.random.default_rng(0))
    edge_cols = out[10:, 79:81]
    assert np.mean(edge_cols == 0) == pytest.approx(0.5, abs=0.1)
    mixed = edge_cols[(edge_cols > 2.0) & (edge_cols < 4.0)]
    assert mixed.size > 0.3 * edge_cols.size  # flying pixels between the two surfaces
    untouched = np.ones(out.shape, bool)
    untouched[:, 79:81] = False
    untouched[:11] = False  # rows next to the invalid band are not edges either, but stay exact
    np.testing.assert_array_equal(out[untouched], _step_image()[untouched])
    np.testing.assert_array_equal(out[10:, :79], 2.0)


def test_dropout_fraction():
    n = Noise(axial_model="none", edge_hole_prob=0.0, flying_pixel_prob=0.0, dropout=0.05)
    z = np.full((480, 640), 3.0, np.float32)
    out = apply_depth_noise(z, n, FX, np.random.default_rng(1))
    assert np.mean(out == 0) == pytest.approx(0.05 * (1 - 0.05 / 2), abs=0.004)  # with repeats


def test_disabled_noise_is_exact_and_every_component_switches_off():
    z = _step_image()
    np.testing.assert_array_equal(apply_depth_noise(z, Noise(enabled=False), FX, np.random.default_rng(0)), z)
    off = Noise(axial_model="none", edge_hole_prob=0.0, flying_pixel_prob=0.0, dropout=0.0)
    np.testing.assert_array_equal(apply_depth_noise(z, off, FX, np.random.default_rng(0)), z)
    only_axial = dataclasses.replace(off, axial_model="intel_rms")
    out = apply_depth_noise(z, only_axial, FX, np.random.default_rng(0))
    assert np.all(out[z == 0] == 0) and np.all(out[z > 0] != z[z > 0])


def test_nguyen_model_option():
    n = Noise(axial_model="nguyen")
    assert float(axial_sigma(np.float32(2.0), n, FX)) == pytest.approx(0.0012 + 0.0019 * 1.6**2, rel=1e-5)
    out = DepthNoiseModel(dataclasses.replace(n, edge_hole_prob=0, flying_pixel_prob=0, dropout=0), FX).apply(
        np.zeros((10, 10), np.float32), np.random.default_rng(0))
    assert np.all(out == 0)  # invalid pixels stay invalid


def test_same_generator_state_gives_the_same_noise():
    z = _step_image()
    a = apply_depth_noise(z, Noise(), FX, np.random.default_rng(7))
    b = apply_depth_noise(z, Noise(), FX, np.random.default_rng(7))
    c = apply_depth_noise(z, Noise(), FX, np.random.default_rng(8))
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_range_limits_and_millimetre_quantisation():
    sc = make_scenario("[noise]\nenabled = false\n[camera]\nmax_range = 4.0\n"
                       "[camera_path]\nkeyframes = [[0.0, 1.0, 0.0, 1.5, 0.0]]\n")
    w = World(sc, seed=0, renderer="tiny")
    d = w.latest_frame().depth
    assert d.dtype == np.uint16
    assert d.max() <= 4000 and np.any(d == 0)  # the far end (9 m) is beyond max_range
    w.close()


def _rough_image(seed, shape=(48, 64)):
    """Patches of random depths with invalid pixels, rows and columns of them at the borders too."""
    rng = np.random.default_rng(seed)
    patches = rng.uniform(0.3, 8.0, (-(-shape[0] // 4), -(-shape[1] // 4)))
    z = np.repeat(np.repeat(patches, 4, 0), 4, 1)[:shape[0], :shape[1]].astype(np.float32)
    z += rng.normal(0, 0.02, shape).astype(np.float32)
    z[rng.random(shape) < 0.05] = 0.0
    if min(shape) > 3:  # invalid border lines (a thinner image keeps its pixels, to have edges)
        z[:, 0] = 0.0
        z[-1, :] = 0.0
    return z


@pytest.mark.parametrize("seed, shape", [(s, (48, 64)) for s in range(5)]
                         + [(5, (13, 21)), (6, (3, 9)), (7, (1, 17)), (8, (9, 1)), (9, (2, 2))])
def test_edge_pixels_are_the_valid_pixels_whose_neighbourhood_jumps(seed, shape):
    from scipy.ndimage import maximum_filter, minimum_filter

    from sim.depth_noise import _edge_pixels, _extremes_at

    z = _rough_image(seed, shape)
    far = np.where(z <= 0, z + np.float32(1e4), z)
    lo = minimum_filter(far, size=3, mode="nearest")  # the neighbourhood clipped to the image
    hi = maximum_filter(z, size=3, mode="nearest")
    jump = (hi - lo).astype(np.float64)
    want = np.flatnonzero((z > 0) & (jump - 0.05 * z.astype(np.float64) * (1 + 1e-9) > 0))
    want_loose = np.flatnonzero((z > 0) & (jump - 0.05 * z.astype(np.float64) * (1 - 1e-9) > 0))
    idx = np.empty(z.size, np.int64)
    got = idx[:_edge_pixels(z, np.float32(0.05), idx)]
    assert set(want) <= set(got) <= set(want_loose) and np.all(np.diff(got) > 0)  # row-major order
    a, b = _extremes_at(z, got)
    np.testing.assert_array_equal(a, lo.reshape(-1)[got])
    np.testing.assert_array_equal(b, hi.reshape(-1)[got])


def test_linearised_depth_and_millimetres_follow_their_formulas_in_float32():
    from sim.camera import FAR_PLANE, NEAR_PLANE, linearize_depth
    from sim.frame_capture import _millimetres

    d = np.random.default_rng(0).random((30, 40), dtype=np.float32)
    d[0, :5] = 1.0
    f = np.float32(FAR_PLANE)
    z = linearize_depth(d)
    want = np.float32(FAR_PLANE * NEAR_PLANE) / (d * np.float32(-(FAR_PLANE - NEAR_PLANE)) + f)
    want[d >= np.float32(1 - 1e-6)] = 0.0
    assert z.dtype == np.float32
    np.testing.assert_array_equal(z, want)
    mm = _millimetres(z, np.float32(0.2), np.float32(4.0))
    keep = (z >= np.float32(0.2)) & (z <= np.float32(4.0))
    assert mm.dtype == np.uint16
    np.testing.assert_array_equal(mm[~keep], 0)
    np.testing.assert_array_equal(mm[keep], np.floor(z[keep].astype(np.float64) * 1000 + 0.5).astype(np.uint16))
