"""Where the people of an episode walk when nobody reacts to the drone.

People who do not see the drone walk the same whatever it does: their routes come from the episode's
seed (sim.world.episode_generators) and their steps from the social forces among them alone. Their
whole walk can then be computed without the physics or the drone, exactly as the world steps it:
the input of a clairvoyant planner (experiments.ceiling) and of tests that need the people's future.
"""
from __future__ import annotations

import numpy as np

from sim.crowd import Crowd
from sim.people import Walker, walk_paths
from sim.scenario import Scenario
from sim.world import episode_generators

_HEIGHT = 1.75  # m: a walker's height only scales its gait, which the positions do not depend on


class SeesDrone(ValueError):
    """The scenario has people who see the drone: their walk depends on what the drone does."""


def blind_walk(scenario: Scenario, seed: int, seconds: float) -> tuple[np.ndarray, np.ndarray]:
    """The people's positions at every control period from 0 to ``seconds``: times (K + 1,) and
    positions (K + 1, n, 2), equal to ``World(scenario, seed).crowd.pos`` after each control period
    (sim.world steps the crowd once per control period, at the physics clock's time)."""
    sc = scenario
    seeing = [i for i, p in enumerate(sc.people) if (sc.crowd.sees_drone if p.sees_drone is None else p.sees_drone)]
    if seeing:
        raise SeesDrone(f"scenario {sc.name!r}: people {seeing} see the drone, so where they walk depends on it "
                        "(set [crowd] sees_drone = false)")
    rng_paths = episode_generators(seed)[0]
    crowd = Crowd([Walker(path, _HEIGHT) for path in walk_paths(sc, rng_paths)], sc)
    dt_physics = 1.0 / sc.rates.physics
    per_control = sc.rates.physics // sc.rates.control
    n_steps = int(round(float(seconds) * sc.rates.control))
    times = np.zeros(n_steps + 1)
    out = np.zeros((n_steps + 1, len(crowd), 2))
    out[0] = crowd.pos
    for k in range(1, n_steps + 1):
        t = (k * per_control) * dt_physics  # the world's clock: step_count * dt
        if len(crowd):
            crowd.step(t, dt_physics * per_control)
            out[k] = crowd.pos
        times[k] = t
    return times, out
