"""Passing sides for the MPC (planner.mpc's module docstring, (4')): which side of its line of relative
motion each of the nearest moving obstacles is forced to, one QP per combination."""
from __future__ import annotations

import itertools

import numpy as np

from planner.mpc_config import MPCConfig


def side_combinations(cfg: MPCConfig, c, cand, obstacles, sides: dict):
    """Passing sides to try: a list of forced-side arrays (J,) for planner.mpc_rows.dynamic_rows, the
    one to keep first, and [(j, obstacle id)] of the enumerated candidates. The homotopy_obstacles nearest
    candidates (planner.mpc_rows.dynamic_candidates) within homotopy_range of the plan get both sides each
    (2^M combinations); the first combination is the side each was passed on by the last plan (``sides``:
    obstacle id -> +-1), else the side c_k lies on, as the tie-break puts it."""
    M = [j for j, e in enumerate(cand) if e[0] <= cfg.homotopy_range][:cfg.homotopy_obstacles]
    if not M:
        return [None], []
    ids = [(j, getattr(obstacles[cand[j][1]], "id", None)) for j in M]
    first = np.zeros(len(cand))
    for j, k in ids:
        e = cand[j]
        kk = int(np.argmin(np.linalg.norm(c - e[2], axis=1)))
        lat = float((c[kk] - e[2][kk]) @ e[4])
        first[j] = sides.get(k, -1.0 if lat < 0 else 1.0)  # (ids of None are never kept)
    combos = [first]
    for signs in itertools.product((1.0, -1.0), repeat=len(M)):
        f = np.zeros(len(cand))
        f[M] = signs
        if not np.array_equal(f, first):
            combos.append(f)
    return combos, ids
