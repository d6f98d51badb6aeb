"""A* on the column grid and the path follower."""
import numpy as np
import pytest

from planner.nominal.global_path import PathFollower, grid_path


def _grid(nx=60, ny=30):
    return np.zeros((nx, ny), dtype=bool)


def _cells_of(path, origin, res, n=400):
    f = PathFollower(path)
    pts, _ = f.at(np.linspace(0, f.length, n))
    return np.floor((pts - origin) / res).astype(int)


def test_free_grid_gives_the_straight_line():
    path = grid_path(_grid(), (0.0, -1.5), 0.1, (0.5, 0.0), (5.5, 0.0))
    assert path is not None
    assert len(path) == 2  # shortcut to one segment
    np.testing.assert_allclose(path[0], (0.5, 0.0))
    np.testing.assert_allclose(path[-1], (5.5, 0.0))


def test_path_goes_around_a_wall_through_the_gap_and_never_crosses_blocked_cells():
    g = _grid()
    g[30, :] = True
    g[30, 24:27] = False  # a gap near y = +0.9
    origin = np.array([0.0, -1.5])
    path = grid_path(g, origin, 0.1, (0.5, 0.0), (5.5, 0.0))
    assert path is not None
    cells = _cells_of(path, origin, 0.1)
    assert not g[cells[:, 0], cells[:, 1]].any()
    crossing = cells[cells[:, 0] == 30]
    assert np.all((crossing[:, 1] >= 24) & (crossing[:, 1] <= 26))
    # Shortest: about the two legs through the gap, far shorter than a detour.
    L = PathFollower(path).length
    direct = np.hypot(2.5, 0.95) + np.hypot(2.5, 0.95)
    assert direct - 0.2 < L < direct + 0.4


def test_no_path_returns_none():
    g = _grid()
    g[30, :] = True
    assert grid_path(g, (0.0, -1.5), 0.1, (0.5, 0.0), (5.5, 0.0)) is None


def test_start_inside_a_blocked_cell_moves_to_the_nearest_free_cell():
    g = _grid()
    g[3:8, 13:18] = True  # the drone sits inside an inflation margin
    path = grid_path(g, (0.0, -1.5), 0.1, (0.55, 0.05), (5.5, 0.0))
    assert path is not None
    np.testing.assert_allclose(path[0], (0.55, 0.05))


def test_no_corner_cutting_between_diagonal_blocked_cells():
    g2 = np.zeros((2, 2), dtype=bool)
    g2[1, 0] = g2[0, 1] = True
    assert grid_path(g2, (0.0, 0.0), 1.0, (0.5, 0.5), (1.5, 1.5)) is None


def test_follower_projection_and_sampling():
    f = PathFollower(np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]]))
    assert f.length == pytest.approx(4.0)
    assert f.project((1.0, 0.3)) == pytest.approx(1.0)
    assert f.project((2.4, 1.0)) == pytest.approx(3.0)
    pts, tang = f.at(np.array([0.5, 3.0, 10.0]))
    np.testing.assert_allclose(pts, [[0.5, 0.0], [2.0, 1.0], [2.0, 2.0]])
    np.testing.assert_allclose(tang[0], [1.0, 0.0])
    np.testing.assert_allclose(tang[1], [0.0, 1.0])


def test_bucketed_field_equals_the_heap_search_bit_for_bit():
    from planner.nominal.global_path import _field, _search

    rng = np.random.default_rng(0)
    for _ in range(200):
        nx, ny = rng.integers(1, 50, 2)
        b = rng.random((nx, ny)) < rng.random() * 0.5
        si, sj = rng.integers(0, nx), rng.integers(0, ny)
        b[si, sj] = False
        assert np.array_equal(_field(b, si, sj), _search(b, si, sj, -1, -1)[0])


def test_cost_to_go_cache_gives_the_fresh_field_as_cells_change():
    from planner.nominal.global_path import CostToGo, cost_to_go

    rng = np.random.default_rng(2)
    b = _grid(40, 20)
    b[20, 3:] = True  # a wall with a gap at the bottom
    b[:, 0] = True
    cached = CostToGo()
    for _ in range(60):
        b = b.copy()
        i, j = rng.integers(0, 40), rng.integers(0, 20)
        b[i, j] = not b[i, j]
        np.testing.assert_array_equal(cached(b, (0.0, 0.0), 0.1, (3.5, 1.5)), cost_to_go(b, (0.0, 0.0), 0.1, (3.5, 1.5)))
