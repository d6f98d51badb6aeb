"""Declarative scenarios: TOML files validated on load into frozen dataclasses.

Every user mistake (unknown key, wrong type, value out of range, a person walking out
of the corridor or starting inside an obstacle) raises ``ScenarioError`` with one
message that names the file, the key and the reason. The format is documented in the
README ("Scenario format").

This module is the public face: ``Scenario``, ``load_scenario``, ``parse_scenario``, and the names of
the modules it is made of, which import nothing from it:

- sim.scenario_bounds: the bounds a scenario must keep (MAX_*) and ScenarioError;
- sim.scenario_parts: the parts of a scenario (Corridor, Obstacle, Person, ..., Crowd);
- sim.scenario_checks: the geometry checks of the parts;
- sim.scenario_toml: finding a file, reading its TOML tables into the parts;
- sim.scenario_ranges: values written as ranges, drawn anew for every seed.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from sim.scenario_bounds import (MAX_ANGLE_DEG, MAX_CHECK_POINTS, MAX_CHOICES, MAX_COORDINATE, MAX_DURATION,
                                 MAX_FILE_BYTES, MAX_MOUNT_OFFSET, MAX_NAME_CHARS, MAX_OBSTACLE_SIZE, MAX_OBSTACLES,
                                 MAX_PEOPLE, MAX_POINTS, SEED_MAX, ScenarioError, short_repr)
from sim.scenario_parts import (BEHAVIOURS, OBSTACLE_KINDS, PERSON_HEIGHT_RANGE, PERSON_RADIUS, PERSON_SPEED_RANGE,
                                RENDERER_CHOICES, RENDERERS, Camera, CameraPath, Corridor, Crowd, Drone, Noise,
                                Obstacle, Person, Rates, circle_waypoints)
from sim.scenario_ranges import (MAX_DRAWS, check_ranges, draw, extreme_pick, has_ranges, longest_choice,
                                 ranged_nodes, seeded_pick)
from sim.scenario_toml import SCENARIO_DIR, read_fields, read_text, read_toml, scenario_path, shipped_scenarios

__all__ = [
    "BEHAVIOURS", "MAX_ANGLE_DEG", "MAX_CHOICES", "MAX_COORDINATE", "MAX_DURATION", "MAX_FILE_BYTES",
    "MAX_MOUNT_OFFSET", "MAX_NAME_CHARS", "MAX_OBSTACLES", "MAX_OBSTACLE_SIZE", "MAX_PEOPLE", "MAX_POINTS",
    "OBSTACLE_KINDS", "PERSON_HEIGHT_RANGE", "PERSON_RADIUS", "PERSON_SPEED_RANGE", "RENDERERS",
    "RENDERER_CHOICES", "SCENARIO_DIR", "SEED_MAX", "Camera", "CameraPath", "Corridor", "Crowd", "Drone",
    "Noise", "Obstacle", "Person", "Rates", "Scenario", "ScenarioError", "circle_waypoints", "load_scenario",
    "parse_scenario", "scenario_path", "shipped_scenarios",
]


@dataclass(frozen=True)
class Scenario:
    name: str
    source: str  # file the scenario came from
    seed: int = 0
    duration: float = 20.0  # s
    description: str = ""
    corridor: Corridor = field(default_factory=Corridor)
    obstacles: tuple[Obstacle, ...] = ()
    people: tuple[Person, ...] = ()
    drone: Drone = field(default_factory=Drone)
    camera: Camera = field(default_factory=Camera)
    noise: Noise = field(default_factory=Noise)
    rates: Rates = field(default_factory=Rates)
    camera_path: CameraPath | None = None
    segmentation: bool = True  # render the ground-truth segmentation image every frame
    crowd: Crowd = field(default_factory=Crowd)
    sensors: tuple = ()  # the drone's rig as declared ([[sensors]], sim.rig.SensorMount); empty: --rig decides
    # the file's tables as read (ranges included): for_seed draws them again, with_values changes them
    tables: dict | None = field(default=None, compare=False, repr=False)
    drawn_seed: int | None = field(default=None, compare=False)  # the seed its ranges were drawn for

    @property
    def randomized(self) -> bool:
        """Whether some of its values are ranges, drawn anew for each seed."""
        return self.tables is not None and has_ranges(self.tables)

    def for_seed(self, seed: int) -> "Scenario":
        """The scenario with its ranges drawn for ``seed`` (itself when it has none, or when they were
        drawn for that seed)."""
        if not self.randomized or int(seed) == self.drawn_seed:
            return self
        if _from_tables(self.tables, self.source, self.drawn_seed) != self:
            raise ScenarioError(f"{self.source}: this scenario's values are drawn by the seed, and some were changed "
                                f"after it was read (dataclasses.replace?): another seed's draw would lose them; "
                                f"change it with Scenario.with_values instead")
        return _from_tables(self.tables, self.source, int(seed))

    def with_values(self, values: dict[str, Any]) -> "Scenario":
        """The scenario with the given keys set, as if the file said so: {"crowd.sees_drone": True,
        "duration": 30.0}. Keys are dotted paths of the file's tables; arrays of tables take an index
        ("people.0.speed"). Checked like the file (ScenarioError naming the key)."""
        if self.tables is None:
            raise ScenarioError(f"{self.source}: this scenario was not read from a file; its values cannot be set")
        tables = copy.deepcopy(self.tables)
        for key, value in values.items():
            node, parts = tables, key.split(".")
            for i, part in enumerate(parts[:-1]):
                if isinstance(node, list):
                    if not part.isdigit() or int(part) >= len(node):
                        raise ScenarioError(f"{self.source}: {key}: {'.'.join(parts[:i])} has no item "
                                            f"{short_repr(part)}")
                    node = node[int(part)]
                else:
                    node = node.setdefault(part, {})
                if not isinstance(node, (dict, list)):
                    raise ScenarioError(f"{self.source}: {key}: {'.'.join(parts[:i + 1])} is a value, not a table")
            if isinstance(node, list):
                raise ScenarioError(f"{self.source}: {key}: give an index into {'.'.join(parts[:-1])}")
            node[parts[-1]] = value
        return _from_tables(tables, self.source, None)


def load_scenario(name_or_path: str | Path, seed: int | None = None) -> Scenario:
    """Read and validate a scenario file (or a shipped scenario by name). Values given as ranges
    are drawn for ``seed`` (default: the file's own seed); ``Scenario.for_seed`` draws another."""
    path = scenario_path(name_or_path)
    return parse_scenario(read_text(path), source=str(path), seed=seed)


def parse_scenario(text: str, source: str = "<string>", seed: int | None = None) -> Scenario:
    data = read_toml(text, source)
    try:
        return _from_tables(data, source, seed)
    except RecursionError:
        raise ScenarioError(f"{source}: arrays or tables nested too deeply") from None


def _from_tables(data: dict, source: str, seed: int | None) -> Scenario:
    if not has_ranges(data):
        return replace(_build(data, source), tables=data)
    check_ranges(data, source)
    # Every value a range can give must pass the checks of its key: build with the ranges at both ends
    # of every uniform range and at every value of every choice.
    ranged, memo = ranged_nodes(data), {}  # the draws share the parts holding no range, read once
    for i in range(max(2, longest_choice(data))):
        try:
            _build(draw(data, extreme_pick(i), source, ranged), source, geometry=False, memo=memo)
        except ScenarioError as e:
            raise ScenarioError(f"{e} (a value one of the scenario's ranges can take)") from None
    if seed is None:
        seed = data.get("seed", 0)
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            seed = 0  # _build below reports the bad seed by name
    pick = seeded_pick(seed)

    error, work, tries = None, [0], 0
    # drawn again while a draw fails, up to MAX_DRAWS times, and no more once the draws' geometry checks have
    # sampled MAX_CHECK_POINTS path points (a scenario of many long paths: bounded time)
    while tries < MAX_DRAWS and (tries == 0 or work[0] <= MAX_CHECK_POINTS):
        tries += 1
        try:
            sc = _build(draw(data, pick, source, ranged), source, memo=memo, work=work)
        except ScenarioError as e:
            error = e
            continue
        return replace(sc, tables=data, drawn_seed=int(seed))
    why = "" if tries == MAX_DRAWS else f", all that a scenario of paths this long gets ({work[0]} path points checked)"
    raise ScenarioError(f"{error} (seed {seed}: no draw of the scenario's ranges passed the checks in {tries} "
                        f"{'try' if tries == 1 else 'tries'}{why})")


def _build(data: dict, source: str, geometry: bool = True, memo: dict | None = None,
           work: list[int] | None = None) -> Scenario:
    return Scenario(**read_fields(data, source, geometry, memo, work))
