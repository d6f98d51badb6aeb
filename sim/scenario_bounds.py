"""What a scenario may ask of the machine, and the error that refuses a scenario file.

Every user mistake in a scenario (sim.scenario) raises ``ScenarioError`` with one message that names
the file, the key and the reason; the helpers here are shared by the modules that write such messages.
"""
from __future__ import annotations

import math
from typing import Any


# Bounds on what a scenario may ask of the machine (README, "Scenario format", bounds). Beyond them a run
# would not fit in memory or time (a waypoint 1e8 m away: a path sampled every 5 cm; 1,000 people: minutes
# before the first frame), so they are refused on load like any other mistake.
MAX_FILE_BYTES = 1 << 20  # a scenario file: 1 MiB
MAX_DURATION = 3600.0  # s, duration, start_delay and keyframe times
MAX_COORDINATE = 1000.0  # m, |x|, |y|, |z| of every position given (the corridor itself is at most 200 m long)
MAX_OBSTACLE_SIZE = 200.0  # m, each dimension of an obstacle
MAX_MOUNT_OFFSET = 1.0  # m, |x|, |y|, |z| of the camera in the body frame
MAX_ANGLE_DEG = 360.0  # |angle| in degrees
MAX_OBSTACLES = 200
MAX_PEOPLE = 100
MAX_SENSORS = 8  # the sensors of a rig ([[sensors]])
MAX_POINTS = 100  # waypoints of a person, keyframes of a camera path
MAX_CHOICES = 100  # values of one {choice = [...]}
MAX_NAME_CHARS = 200
MAX_CHECK_POINTS = 10_000_000  # path points the geometry checks of one scenario's draws sample, all together
MAX_KEY_PARTS = 16  # dotted parts of one key or table name (the format's deepest key has 3)
SEED_MAX = 2**63 - 1  # the largest TOML integer


class ScenarioError(ValueError):
    """A scenario file is wrong: the message names the file, the key and the reason."""


def finite_number(x: Any) -> bool:
    """A number (not a boolean) that is finite as a float (an integer too large for one is not)."""
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return False
    try:
        return math.isfinite(x)
    except OverflowError:
        return False


def short_repr(v: Any, limit: int = 80) -> str:
    """repr(v) cut to ``limit`` characters: a message quotes what it refuses, on one line of bounded length."""
    r = repr(v)
    return r if len(r) <= limit else r[:limit] + "..."
