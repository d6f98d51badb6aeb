"""The clairvoyant ceiling of a scenario: could any drone reach the goal without touching anyone, had it
known where every person will walk?

For people who do not see the drone the whole walk is fixed by the seed (sim.crowd_future). A drone
that knows it needs no prediction and no caution; the earliest it can reach the goal is a search in
space and time. On a grid over the floor at the flight altitude, the cells the drone can be in at step
k are those within ``v_max * step`` of a cell it could be in at step k - 1, clear of structure by the
drone's circumscribed radius (plus ``static_margin``), and farther than ``clearance`` from every
person's centre at both steps. The first step at which that set meets the goal region is the clairvoyant time to goal; a set that
empties, or the time limit, means no drone of that speed could have made it.

This is an upper bound on what a planner can do, not a planner: the speed is bounded, the acceleration
is not (a drone that turns on the spot at full speed), and the drone's yaw is free. Its use is to tell a
scenario that leaves no way through from a planner that did not find the way: the gap between a
planner's success and the ceiling is the planner's and its predictions'. ``clearance`` is centre to
centre; the simulator's contacts between the drone's box and a walking body begin 0.42-0.75 m apart
(the arms swing, the box turns), so the default 0.75 leaves room at any yaw.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy import ndimage

from experiments.episode import GOAL_TOLERANCE
from sim.crowd_future import blind_walk
from sim.scenario import Scenario
from sim.static_grid import static_occupancy
from sim.vehicle import load_vehicle

@dataclass(frozen=True)
class CeilingConfig:
    clearance: float = 0.75  # m between the drone's and a person's centres
    v_max: float = 2.0  # m/s: the planners' horizontal speed limit (navigator.mpc.v_max_xy)
    resolution: float = 0.05  # m per grid cell
    step: float = 0.05  # s per step (rounded to whole control periods)
    altitude_band: float = 0.1  # m: structure within this of the flight altitude counts
    # m kept from structure beyond the drone's circumscribed radius (the shield keeps shield.static_margin,
    # 0.1): a gap the drone fits through but its margins do not is a way only at 0
    static_margin: float = 0.0

    def __post_init__(self):
        for name in ("clearance", "v_max", "resolution", "step", "altitude_band"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"CeilingConfig.{name}: must be a number > 0, got {v!r}")
        m = self.static_margin
        if not (isinstance(m, (int, float)) and math.isfinite(m) and m >= 0):
            raise ValueError(f"CeilingConfig.static_margin: must be a number >= 0, got {m!r}")
        if self.v_max * self.step < self.resolution:
            raise ValueError(f"CeilingConfig: v_max * step ({self.v_max * self.step:g} m) is below the resolution "
                             f"({self.resolution:g} m): the drone could never leave its cell")


@dataclass(frozen=True)
class Ceiling:
    seed: int
    reachable: bool
    time_to_goal: float | None  # s, None when not reachable


def earliest_arrival(free: Callable[[int], np.ndarray], start: tuple[int, int], goal: np.ndarray,
                     reach: np.ndarray, steps: int) -> int | None:
    """The first step k <= steps at which a cell of ``goal`` can be occupied, moving from ``start`` at
    step 0 by at most the footprint ``reach`` (a boolean structuring element centred on the cell) per
    step through cells with ``free(k)`` and ``free(k - 1)`` both True; None if none. ``free(k)`` is a
    boolean grid of goal's shape."""
    here = np.zeros(goal.shape, bool)
    before = free(0)
    if not before[start]:
        return None
    here[start] = True
    if goal[start]:
        return 0
    for k in range(1, steps + 1):
        now = free(k)
        here = ndimage.binary_dilation(here, reach) & now & before
        if (here & goal).any():
            return k
        if not here.any():
            return None
        before = now
    return None


def clairvoyant_ceiling(scenario: Scenario, seed: int, cfg: CeilingConfig = CeilingConfig()) -> Ceiling:
    """The scenario's ceiling for one seed (``scenario`` already drawn for it: ``load_scenario(name, seed)``)."""
    sc = scenario
    ctrl = sc.rates.control
    stride = max(1, int(round(cfg.step * ctrl)))
    step = stride / ctrl
    steps = int(math.floor(sc.duration / step))
    _, walk = blind_walk(sc, seed, steps * step)
    walk = walk[::stride]
    L, W, res = sc.corridor.length, sc.corridor.width, cfg.resolution
    nx, ny = int(math.ceil(L / res)), int(math.ceil(W / res))
    z = sc.drone.start[2]
    nz = max(1, int(math.ceil(2 * cfg.altitude_band / res)))
    occupied = static_occupancy(sc, (0.0, -W / 2, z - cfg.altitude_band), (nx, ny, nz), res).any(axis=2)
    half = load_vehicle().collision_size[:2] / 2
    body = float(math.hypot(*half))
    radius = body + cfg.static_margin
    xs = (np.arange(nx) + 0.5) * res
    ys = -W / 2 + (np.arange(ny) + 0.5) * res
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    clear = ndimage.distance_transform_edt(~occupied) * res > radius
    # the end walls by the body alone: the drone starts and ends within the margin of them
    clear &= (np.abs(Y) < W / 2 - radius) & (X > body) & (X < L - body)
    gx, gy = sc.drone.goal[0], sc.drone.goal[1]
    goal = (X - gx) ** 2 + (Y - gy) ** 2 < GOAL_TOLERANCE ** 2
    sx, sy = sc.drone.start[0], sc.drone.start[1]
    start = (min(max(int(sx / res), 0), nx - 1), min(max(int((sy + W / 2) / res), 0), ny - 1))
    c2 = cfg.clearance ** 2

    def free(k: int) -> np.ndarray:
        f = clear.copy()
        for px, py in walk[k]:
            f &= (X - px) ** 2 + (Y - py) ** 2 > c2
        return f

    n = int(math.floor(cfg.v_max * step / res))
    dy, dx = np.mgrid[-n:n + 1, -n:n + 1]
    reach = (dx * dx + dy * dy) * res * res <= (cfg.v_max * step) ** 2 + 1e-12
    k = earliest_arrival(free, start, goal, reach, steps)
    return Ceiling(int(seed), k is not None, None if k is None else round(k * step, 6))
