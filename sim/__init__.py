"""PyBullet world: quadrotor, RGB-D camera, corridor, walking people, ground truth.

The only package of the project that imports PyBullet. Entry points::

    from sim import World, load_scenario
    world = World(load_scenario("corridor"), seed=0)
"""
from sim.scenario import Scenario, ScenarioError, load_scenario, scenario_path

__all__ = ["Scenario", "ScenarioError", "World", "load_scenario", "scenario_path"]


def __getattr__(name):
    # World pulls in PyBullet (about a second); scenario validation alone should not. Start-up only: no
    # module of sim imports the package itself, so this hides no import cycle.
    if name == "World":
        from sim.world import World

        return World
    raise AttributeError(name)
