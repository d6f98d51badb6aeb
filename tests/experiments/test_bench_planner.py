"""The planner replay benchmark (experiments.bench_planner): recorded inputs replay to the same plans."""
from dataclasses import replace

import numpy as np

from experiments import bench_planner


def test_replayed_plans_equal_the_closed_loops():
    snaps, context = bench_planner.record("crossing", 2, perception="oracle", duration=4.0, static_map="depth")
    assert context.camera.half_view > 0 and len(snaps) >= 30 and any(s.inp.obstacles for s in snaps)
    assert len({s.map_version for s in snaps}) > 5  # the map changed under the planner
    out = bench_planner.replay(snaps, context, repeats=2)
    assert out["same"] == out["n"] == 2 * len(snaps)  # deterministic, and the snapshot holds all it reads
    m = bench_planner._map(snaps[-1])  # the rebuilt map keeps what was never observed (the shield reads it)
    unknown = m.log_odds <= m.l_unknown
    assert np.array_equal(np.packbits(unknown), snaps[-1].unknown) and 0 < np.count_nonzero(unknown) < unknown.size
    assert np.array_equal(np.packbits(m.log_odds >= m.l_occ), snaps[-1].occupied)
    assert out["ms"].shape == (2, len(snaps)) and np.all(out["ms"] > 0)


def test_a_changed_input_changes_the_replayed_plan():
    snaps, context = bench_planner.record("corridor", 0, perception="oracle", duration=2.0, static_map="depth")
    s = snaps[5]
    moved = bench_planner._Snapshot(replace(s.inp, goal=s.inp.goal + np.array([0.0, 1.0, 0.0])),
                                    s.occupied, s.unknown, s.map_cfg, s.map_version, s.plan)
    out = bench_planner.replay(snaps[:5] + [moved], context, repeats=1)
    assert out["same"] == 5  # the comparison sees a different plan
