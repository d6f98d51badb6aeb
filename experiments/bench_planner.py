"""The planner's time per plan on the inputs of closed-loop episodes (``dodt-nav bench planner``).

An episode is flown once with a recorder around the default planner: every PlannerInput is kept, its
voxel map reduced to the occupied set (all the planner reads of it) and its seen-space copied. The
inputs are then replayed, in order, through a fresh default planner, ``repeats`` times, timing each
``plan`` call alone: the figure is the planner's, not the loop's, and its inputs are those of a real
flight. Each replay rebuilds the maps (untimed) as the loop had them: one map object while the loop's
map did not change, a new one when it did, so the map's caches serve the planner as they did in the
loop. The replayed plans must equal the recorded ones (the planner is deterministic); the count of
those that do, in every replay, is printed beside the times.
"""
from __future__ import annotations

import copy
import time
from dataclasses import dataclass, replace

import numpy as np

from dodt.context import EpisodeContext, reset_with_context
from experiments.episode import run_episode
from experiments.episode_config import EpisodeConfig
from experiments.guards import planner_telemetry
from experiments.registry import DEFAULT_PLANNER, make_planner
from planner.map.voxel_map import VoxelMap
from planner.types import PlannerInput, Trajectory
from sim.vehicle import load_vehicle


@dataclass(frozen=True)
class _Snapshot:
    inp: PlannerInput  # occupancy None; the map is rebuilt from the fields below
    occupied: np.ndarray | None  # packbits of log_odds >= l_occ
    map_cfg: object
    map_version: int | None  # the loop's map version: equal versions share one rebuilt map
    plan: Trajectory | None  # None: the planner raised


class _Recorder:
    """A planner that records what it is asked and what the wrapped planner answers."""

    def __init__(self, planner):
        self.planner, self.snapshots, self.context = planner, [], None

    def reset(self, context: EpisodeContext | None = None) -> None:
        self.context = context
        reset_with_context(self.planner, context)

    def plan(self, inp: PlannerInput) -> Trajectory:
        occ = inp.occupancy  # the input as the planner gets it, before the call (kept if the call raises)
        snap = _Snapshot(replace(inp, occupancy=None, seen=copy.deepcopy(inp.seen)),
                         None if occ is None else np.packbits(occ.log_odds >= occ.l_occ),
                         None if occ is None else occ.cfg, None if occ is None else occ.version, None)
        self.snapshots.append(snap)
        out = self.planner.plan(inp)
        self.snapshots[-1] = replace(snap, plan=out)
        return out

    def telemetry(self) -> dict:
        return planner_telemetry(self.planner)


def _map(s: _Snapshot) -> VoxelMap:
    m = VoxelMap(s.map_cfg)
    m.set_known(np.unpackbits(s.occupied, count=m.log_odds.size).reshape(m.log_odds.shape).astype(bool))
    return m


def _same(a: Trajectory, b: Trajectory | None) -> bool:
    return (b is not None and a.status == b.status and a.yaw == b.yaw and np.array_equal(a.positions, b.positions)
            and np.array_equal(a.velocities, b.velocities) and np.array_equal(a.accelerations, b.accelerations))


def record(scenario: str, seed: int, perception: str = "dodt", **episode) -> tuple[list[_Snapshot], EpisodeContext]:
    """The planner inputs and plans of one closed-loop episode with the default planner (``episode``:
    experiments.episode_config.EpisodeConfig fields), and the episode's context."""
    rec = _Recorder(make_planner(DEFAULT_PLANNER, load_vehicle().radius))
    run_episode(scenario, seed=seed, perception=perception, planner=rec, cfg=EpisodeConfig(**episode))
    return rec.snapshots, replace(rec.context, static_map=None, seen=None)


def replay(snapshots: list[_Snapshot], context: EpisodeContext, repeats: int = 3) -> dict:
    """Times (ms) of every plan call over ``repeats`` replays, and how many replayed plans (of all replays)
    equal the loop's."""
    times, same = [], 0
    for _ in range(repeats):
        planner = make_planner(DEFAULT_PLANNER, context.vehicle.radius)
        planner.reset(context)
        run, version, m = [], None, None
        for s in snapshots:
            inp = s.inp
            if s.occupied is not None:
                if m is None or s.map_version != version:
                    m, version = _map(s), s.map_version  # untimed, as the loop's map update was
                inp = replace(s.inp, occupancy=m)
            t = time.perf_counter()
            out = planner.plan(inp)
            run.append((time.perf_counter() - t) * 1e3)
            same += _same(out, s.plan)
        times.append(run)
    return {"ms": np.array(times), "same": same, "n": len(snapshots) * repeats}


def run(scenario: str = "corridor", seeds=(0, 1), perception: str = "dodt", repeats: int = 3) -> dict:
    """Records and replays ``seeds`` of ``scenario``; prints and returns the figures."""
    per_rep, same, n = [], 0, 0
    for seed in seeds:
        r = replay(*record(scenario, seed, perception), repeats=repeats)
        per_rep.append(r["ms"])
        same, n = same + r["same"], n + r["n"]
    ms = np.concatenate(per_rep, axis=1)  # (repeats, plans)
    stats = {q: float(np.median([np.percentile(row, p) for row in ms])) for q, p in
             (("median_ms", 50), ("p95_ms", 95), ("p99_ms", 99))}
    out = dict(stats, plans=n // repeats, repeats=repeats, same_as_loop=same, compared=n, max_ms=float(ms.max()))
    print(f"planner replay, {scenario} seeds {','.join(map(str, seeds))}, perception {perception}: {n // repeats} "
          f"plans x {repeats} replays; per plan median {stats['median_ms']:.2f} ms, p95 {stats['p95_ms']:.2f} ms, "
          f"p99 {stats['p99_ms']:.2f} ms (medians over the replays); replayed plans equal to the loop's: {same}/{n}")
    return out
