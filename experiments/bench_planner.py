"""The planner's time per plan on the inputs of closed-loop episodes (``dodt-nav bench planner``).

An episode is flown once with a recorder around the default planner: every PlannerInput is kept, its
voxel map reduced to the occupied and the never-observed sets (all the planner reads of it) and its
seen-space copied. The inputs are then replayed, in order, through a fresh default planner, ``repeats``
times, timing each ``plan`` call alone: the figure is the planner's, not the loop's, and its inputs are
those of a real flight. Each replay rebuilds the maps (untimed) as the loop had them: one map object
while the loop's map did not change, a new one when it did, so the map's caches serve the planner as
they did in the loop. The replayed plans must equal the recorded ones (the planner is deterministic);
the count of those that do, in every replay, is printed beside the times.
"""
from __future__ import annotations

import copy
import time
from dataclasses import dataclass, replace

import numpy as np

from dodt.context import CameraSensor, EpisodeContext, Rates, VehicleLimits, reset_with_context
from dodt.frames import CameraIntrinsics
from experiments.episode import run_episode
from experiments.episode_config import EpisodeConfig
from experiments.guards import planner_telemetry
from experiments.registry import DEFAULT_PLANNER, make_planner
from planner.map.voxel_map import VoxelMap
from planner.types import ObstaclePrediction, PlannerInput, Trajectory
from sim.vehicle import load_vehicle


@dataclass(frozen=True)
class _Snapshot:
    inp: PlannerInput  # occupancy None; the map is rebuilt from the fields below
    occupied: np.ndarray | None  # packbits of log_odds >= l_occ
    unknown: np.ndarray | None  # packbits of the voxels never observed (log_odds at l_unknown)
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
                         None if occ is None else np.packbits(occ.log_odds <= occ.l_unknown),
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
    m.log_odds[np.unpackbits(s.unknown, count=m.log_odds.size).reshape(m.log_odds.shape).astype(bool)] = m.l_unknown
    m.version += 1
    return m


def _same(a: Trajectory, b: Trajectory | None) -> bool:
    return (b is not None and a.status == b.status and a.yaw == b.yaw and np.array_equal(a.positions, b.positions)
            and np.array_equal(a.velocities, b.velocities) and np.array_equal(a.accelerations, b.accelerations))


def record(scenario: str, seed: int, perception: str = "dodt", planner: str = DEFAULT_PLANNER,
           **episode) -> tuple[list[_Snapshot], EpisodeContext]:
    """The planner inputs and plans of one closed-loop episode with a built-in planner (``episode``:
    experiments.episode_config.EpisodeConfig fields), and the episode's context."""
    rec = _Recorder(make_planner(planner, load_vehicle().radius))
    run_episode(scenario, seed=seed, perception=perception, planner=rec, cfg=EpisodeConfig(**episode))
    return rec.snapshots, replace(rec.context, static_map=None, seen=None)


def replay(snapshots: list[_Snapshot], context: EpisodeContext, repeats: int = 3, planner: str = DEFAULT_PLANNER) -> dict:
    """Times (ms) of every plan call of the built-in ``planner`` (the one recorded) over ``repeats`` replays,
    and how many replayed plans (of all replays) equal the loop's."""
    spec, times, same = planner, [], 0
    for _ in range(repeats):
        planner = make_planner(spec, context.vehicle.radius)
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


def run(scenario: str = "corridor", seeds=(0, 1), perception: str = "dodt", repeats: int = 3,
        planner: str = DEFAULT_PLANNER) -> dict:
    """Records and replays ``seeds`` of ``scenario`` with a built-in planner; prints and returns the figures."""
    per_rep, same, n = [], 0, 0
    for seed in seeds:
        r = replay(*record(scenario, seed, perception, planner), repeats=repeats, planner=planner)
        per_rep.append(r["ms"])
        same, n = same + r["same"], n + r["n"]
    ms = np.concatenate(per_rep, axis=1)  # (repeats, plans)
    stats = {q: float(np.median([np.percentile(row, p) for row in ms])) for q, p in
             (("median_ms", 50), ("p95_ms", 95), ("p99_ms", 99))}
    out = dict(stats, plans=n // repeats, repeats=repeats, same_as_loop=same, compared=n, max_ms=float(ms.max()),
               planner=planner)
    print(f"planner {planner} replay, {scenario} seeds {','.join(map(str, seeds))}, perception {perception}: {n // repeats} "
          f"plans x {repeats} replays; per plan median {stats['median_ms']:.2f} ms, p95 {stats['p95_ms']:.2f} ms, "
          f"p99 {stats['p99_ms']:.2f} ms (medians over the replays); replayed plans equal to the loop's: {same}/{n}")
    return out


# --------------------------------------------------------------------------- time against people in range

_FLU_TO_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # body -> camera optical


def _corridor_context(length: float = 15.0, width: float = 4.0) -> EpisodeContext:
    """An episode context of the default drone (its URDF's limits) with one forward camera in an empty
    corridor, for planning without an episode."""
    T = np.eye(4)
    T[:3, :3] = _FLU_TO_OPTICAL
    T[:3, 3] = (0.065, 0.01, 0.12)
    return EpisodeContext(
        scenario="people", seed=0, duration=60.0, vehicle=VehicleLimits.from_thrust(0.3, (0.4, 0.4, 0.15), 1.0, 2.0),
        sensors=(CameraSensor("front", CameraIntrinsics(), T, rate=30.0, max_depth=10.0),),
        rates=Rates(control=120.0, plan=10.0, map=15.0), start=np.array([0.5, 0.0, 1.2]),
        goal=np.array([length - 0.5, 0.0, 1.2]), geofence=(np.array([0.0, -width / 2]), np.array([length, width / 2])))


def people_scaling(counts=(10, 50, 200), plans: int = 20, seed: int = 0, radius: float = 6.0,
                   planner: str = DEFAULT_PLANNER) -> dict:
    """Milliseconds per plan of the default planner (shield, maneuvers and MPC) against the number of people
    in range: each plan sees ``n`` people (0.5 x 0.5 x 1.8 m, walking 0.5-1.5 m/s in random directions) placed
    uniformly within ``radius`` m of the drone, which flies down the corridor at 1 m/s over a known-free
    static map (so the shield checks every plan). The first plan of each
    count (warm-up) is left out of the median and p95."""
    rng = np.random.default_rng(seed)
    out = {}
    for n in counts:
        nav = make_planner(planner, 0.2)
        reset_with_context(nav, _corridor_context())
        free = VoxelMap()  # an empty static map, known free: the shield checks every plan against the people
        free.set_known(np.zeros(free.log_odds.shape, dtype=bool))
        ms = []
        for k in range(plans + 1):
            p = np.array([0.5 + 0.1 * k, 0.0, 1.2])
            r, a = radius * np.sqrt(rng.uniform(0.04, 1.0, n)), rng.uniform(0, 2 * np.pi, n)
            h, s = rng.uniform(0, 2 * np.pi, n), rng.uniform(0.5, 1.5, n)
            obs = tuple(ObstaclePrediction(id=i, center=np.array([p[0] + r[i] * np.cos(a[i]), p[1] + r[i] * np.sin(a[i]),
                                                                  0.9]),
                                           size=np.array([0.5, 0.5, 1.8]),
                                           velocity=s[i] * np.array([np.cos(h[i]), np.sin(h[i]), 0.0]))
                        for i in range(n))
            inp = PlannerInput(stamp=0.1 * k, position=p, velocity=np.array([1.0, 0.0, 0.0]), acceleration=np.zeros(3),
                               goal=np.array([14.5, 0.0, 1.2]), obstacles=obs, yaw=0.0, occupancy=free)
            t = time.perf_counter()
            nav.plan(inp)
            ms.append((time.perf_counter() - t) * 1e3)
        ms = np.array(ms[1:])
        out[n] = {"median_ms": float(np.median(ms)), "p95_ms": float(np.percentile(ms, 95)), "plans": plans}
        print(f"planner {planner} with {n} people within {radius:g} m: {out[n]['median_ms']:.1f} ms per plan median, "
              f"{out[n]['p95_ms']:.1f} ms p95 ({plans} plans)")
    return out
