"""The camera-heading cost (planner.nominal.view)."""
import math

import numpy as np
import pytest

from planner.nominal.view import view_costs

HEADINGS = np.radians(np.arange(-180, 180, 5.0))
HALF_VIEW = 0.759 - 0.15


def _line(p0, v, n=25, dt=0.1):
    return np.asarray(p0, float) + np.outer(dt * np.arange(1, n + 1), v)


def _view(P, watch, fallback=math.nan):
    """view_costs of candidates P (C, 25, 2) from (0, 0), watching points (O, 2, 2) at 0.5 s and 1 s."""
    return view_costs(np.ascontiguousarray(P, dtype=float), np.zeros(2), 10, 1.0, fallback,
                      np.asarray(watch, float).reshape(-1, 2, 2), np.array([5, 10]), 3.0, HALF_VIEW, HEADINGS, 0.05)


def test_view_cost_is_nil_when_one_heading_sees_the_motion_and_the_walker_and_grows_when_none_can():
    ahead = [[[2.0, 0.3], [2.0, 0.3]]]  # a walker standing ahead, a little left
    behind = [[[-1.0, 0.0], [-1.0, 0.0]]]  # one standing behind the start
    fwd = _line([0, 0], [1.5, 0.0])[None]
    cost, arg = _view(fwd, ahead)
    assert cost[0] == pytest.approx(0.0) and abs(HEADINGS[arg[0]]) < HALF_VIEW
    cost_b, _ = _view(fwd, behind)  # flying on away from him: motion and walker 180 degrees apart
    slow = _line([0, 0], [0.2, 0.0])[None]  # hardly moving: the motion weighs less and he is nearer
    cost_s, _ = _view(slow, behind, fallback=0.0)
    assert cost_b[0] > 0.5 and cost_s[0] > 0.0
    none, idx = _view(fwd[:, :, :] * 0.0 + 0.01, np.zeros((0, 2, 2)))  # no motion, no fallback, nobody
    assert none[0] == 0.0 and idx[0] == -1
    far = [[[10.0, 5.0], [10.0, 5.0]]]  # beyond the watch range: only the motion counts
    cost_f, arg_f = _view(fwd, far)
    assert cost_f[0] == pytest.approx(0.0) and HEADINGS[arg_f[0]] == 0.0
