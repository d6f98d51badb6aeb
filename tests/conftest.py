import numpy as np
import pytest

from sim.scenario import parse_scenario

BASE = """
name = "test"
duration = 10.0
[corridor]
length = 10.0
width = 4.0
height = 3.0
[drone]
start = [1.0, 0.0, 1.2]
goal = [9.0, 0.0, 1.2]
"""


def make_scenario(extra: str = "", base: str = BASE):
    """A small test scenario: the base corridor plus extra TOML (tables appended)."""
    return parse_scenario(base + "\n" + extra, source="test.toml")


@pytest.fixture
def scenario_factory():
    return make_scenario


def egl_available() -> bool:
    import pybullet as p

    from sim.camera import load_egl, quiet_stdout

    with quiet_stdout():
        c = p.connect(p.DIRECT)
    try:
        return load_egl(p, c)
    finally:
        with quiet_stdout():
            p.disconnect(c)


def gl_available() -> bool:
    from sim.gl_renderer import gl_available as available

    return available()


RENDERERS = ["tiny"] + (["pybullet"] if egl_available() else []) + (["gl"] if gl_available() else [])


def rng(seed=0):
    return np.random.default_rng(seed)
