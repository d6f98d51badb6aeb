"""The MPC's half-space rows (planner.mpc.rows: static_rows, dynamic_rows) against their definitions."""
import numpy as np
import pytest

from planner.mpc.config import MPCConfig
from planner.mpc.rows import static_rows


def _planes_by_definition(cfg, c, pts, side, p0):
    """For each c_k, static_per_step times: the nearest point within static_radius not yet behind a plane
    gives a plane through it facing c_k (from the drone's side when the segment drone -> c_k passes
    through its voxel and c_k lies beyond it), moved out by the clearance."""
    req = cfg.robot_radius + cfg.voxel_size / 2 + cfg.static_margin
    N, Ks = cfg.horizon, cfg.static_per_step
    n_out, b_out = np.zeros((N, Ks, 3)), np.full((N, Ks), -np.inf)
    for k in range(N):
        alive = np.linalg.norm(pts - c[k], axis=1) <= cfg.static_radius
        for j in range(Ks):
            if not alive.any():
                break
            d = np.where(alive, np.linalg.norm(pts - c[k], axis=1), np.inf)
            q = pts[int(np.argmin(d))]
            nv = c[k] - q
            seg = c[k] - p0
            w = np.clip(np.dot(q - p0, seg) / max(np.dot(seg, seg), 1e-12), 0.0, 1.0)
            if np.linalg.norm(p0 + w * seg - q) < cfg.voxel_size and np.dot(nv, p0 - q) < 0:
                nv = p0 - q
            n = nv / np.linalg.norm(nv) if np.linalg.norm(nv) >= 1e-9 else side
            n_out[k, j], b_out[k, j] = n, n @ q + req
            alive &= pts @ n > n @ q + 1e-9
    return n_out, b_out


@pytest.mark.parametrize("seed", range(8))
def test_static_rows_are_the_greedy_separating_planes(seed):
    rng = np.random.default_rng(seed)
    cfg = MPCConfig()
    walls = np.array([(x, y, z) for x in np.arange(0.05, 8, 0.1) for y in (-1.95, 1.95)
                      for z in np.arange(0.45, 2.0, 0.1)])
    clutter = rng.uniform([0, -2, 0.4], [8, 2, 2], (int(rng.integers(1, 400)), 3)).round(1) + 0.05
    pts = np.vstack([walls, clutter[np.abs(clutter[:, 1]) > 0.9]])
    c = np.column_stack([np.linspace(rng.uniform(0, 4), rng.uniform(3, 8), cfg.horizon),
                         rng.uniform(-0.2, 0.2, cfg.horizon), rng.uniform(1.1, 1.3, cfg.horizon)])  # no ties
    c = c[np.argsort(c[:, 0])]
    p0 = c[0] - [0.3, 0.0, 0.0]
    # linearisation points already clear of every point: static_rows leaves them where they are
    keep = np.min(np.linalg.norm(pts[None] - c[:, None], axis=2), axis=1) >= 0.56
    c, side = c[keep], np.array([0.0, 1.0, 0.0])
    if len(c) == 0:
        pytest.skip("no clear linearisation point drawn")
    cfg = MPCConfig(horizon=len(c))
    n, b = static_rows(cfg, c, pts, side, p0)
    n_ref, b_ref = _planes_by_definition(cfg, c, pts, side, p0)
    np.testing.assert_allclose(n, n_ref, atol=1e-12)
    np.testing.assert_allclose(b, b_ref, atol=1e-12)
    assert np.isfinite(b).sum() > 0


def _shifts_by_arrays(along, perp2, h, req):
    """slide_clear's shifts as whole-array steps (all rows at once, stopping when none is blocked)."""
    out = []
    for sgn in (1.0, -1.0):
        lo = np.where(perp2 < req * req, sgn * along - h, np.inf)
        hi = np.where(perp2 < req * req, sgn * along + h, -np.inf)
        d = np.zeros(len(along))
        for _ in range(20):
            cover = (lo < d[:, None]) & (hi > d[:, None])
            if not cover.any():
                break
            d = np.where(cover.any(axis=1), np.max(np.where(cover, hi, -np.inf), axis=1) + 1e-6, d)
        out.append(np.where(cover.any(axis=1), np.inf, d))
    return np.array(out)


def test_compiled_shifts_equal_the_array_steps_bit_for_bit():
    from planner.mpc.rows import _shifts

    rng = np.random.default_rng(0)
    for _ in range(200):
        K, M = rng.integers(1, 6), rng.integers(1, 300)
        along = rng.normal(0.0, rng.choice([0.3, 1.0, 3.0]), (K, M))
        perp2 = rng.random((K, M)) * rng.choice([0.1, 1.0, 4.0])
        req = float(rng.choice([0.2, 0.5, 1.5]))
        h = np.sqrt(np.maximum(req * req - perp2, 0.0))
        np.testing.assert_array_equal(_shifts(along, perp2, h, req), _shifts_by_arrays(along, perp2, h, req))


def test_compiled_shifts_give_inf_where_twenty_steps_do_not_clear():
    from planner.mpc.rows import _shifts

    along = np.array([0.9 * np.arange(-30, 31)])  # a chain of overlapping intervals both ways
    perp2 = np.zeros_like(along)
    h = np.full_like(along, 0.5)
    got = _shifts(along, perp2, h, 0.5)
    assert np.all(np.isinf(got))
    np.testing.assert_array_equal(got, _shifts_by_arrays(along, perp2, h, 0.5))


def test_compiled_row_filters_equal_the_boolean_masks():
    from planner.mpc.rows import _inside, finite_rows

    rng = np.random.default_rng(1)
    for _ in range(100):
        p = rng.normal(size=(int(rng.integers(0, 100)), 3)) * 3
        if len(p):
            i = rng.integers(0, len(p), len(p) // 4)
            p[i, rng.integers(0, 3, len(i))] = rng.choice([np.nan, np.inf, -np.inf], len(i))
        q = finite_rows(p)
        np.testing.assert_array_equal(q, p[np.all(np.isfinite(p), axis=1)])
        lo, hi = rng.normal(size=3) - 1, rng.normal(size=3) + 1
        np.testing.assert_array_equal(_inside(q, lo, hi), q[np.all((q >= lo) & (q <= hi), axis=1)])


def _dynamic_rows_by_definition(cfg, c, cand, p0, bias):
    """(4) in numpy: the offset from each predicted centre to c_k (horizontal for a person spanning the
    altitude band), tie-broken to at least the bias along its side, the point where
    it meets the ellipsoid, and the tangent plane there."""
    o = np.stack([e[2] for e in cand], axis=1)
    ax = np.stack([e[3] for e in cand], axis=1)
    side = np.stack([e[4] for e in cand])
    tall = ((o[..., 2] - ax[..., 2] <= cfg.z_min) & (o[..., 2] + ax[..., 2] >= cfg.z_max))[..., None]
    flat = np.where(tall, np.array([1.0, 1.0, 0.0]), 1.0)
    d = (c[:, None, :] - o) * flat
    lat = np.sum(d * side, axis=-1)
    sgn = np.where(lat < 0, -1.0, 1.0)
    d = d + (sgn * np.maximum(np.abs(lat), cfg.side_bias if bias is None else bias) - lat)[..., None] * side
    away = (p0 - o) * flat
    away = np.where(np.linalg.norm(away, axis=-1, keepdims=True) > 1e-9, away, np.array([0.0, 1.0, 0.0]))
    d = np.where(np.linalg.norm(d, axis=-1, keepdims=True) < 1e-9, away, d)
    cs = o + d / np.sqrt(np.sum((d / ax) ** 2, axis=-1, keepdims=True))
    g = (cs - o) / ax ** 2
    n = g / np.linalg.norm(g, axis=-1, keepdims=True)
    return n, np.sum(n * cs, axis=-1)


@pytest.mark.parametrize("seed", range(3))
def test_dynamic_rows_give_the_definitions_floats(seed):
    from planner.mpc.rows import dynamic_rows
    cfg, rng = MPCConfig(), np.random.default_rng(seed)
    N = cfg.horizon
    for it in range(300):
        c, p0 = rng.normal(0, 3, (N, 3)), rng.normal(0, 3, 3)
        cand = []
        for j in range(int(rng.integers(1, 5))):
            o = c.copy() if it % 7 == 0 else rng.normal(0, 3, (N, 3))  # c_k on the centre, or anywhere
            ax = np.abs(rng.normal(0.6, 0.3, (N, 3))) + 0.05
            if it % 3 == 0:
                ax[:, 2] = 5.0  # spanning the altitude band
            sd = rng.normal(0, 1, 3)
            cand.append((0.0, j, o, ax, sd / np.linalg.norm(sd)))
        bias = (None, 0.0, 0.3)[it % 3]
        got = dynamic_rows(cfg, c, cand, p0, bias)
        want = _dynamic_rows_by_definition(cfg, c, cand, p0, bias)
        for g, w in zip(got, want):
            assert g.shape == w.shape and g.tobytes() == w.tobytes()
