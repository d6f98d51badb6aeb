"""Your own planner or perception module in every command: ``--planner module:Class`` and
``--perception module:Class``.

``module`` is an importable dotted module (``mypackage.planners``) or the path of a Python file
(``examples/custom_planner.py``, relative to the working directory). The class is instantiated with no
arguments, once per episode, in the process that runs the episode (a sweep's workers receive the spec
string and load the class themselves).

- A planner implements ``planner.types.Planner``: ``reset()`` and ``plan(PlannerInput) -> Trajectory``.
  The built-in name ``default`` is the maneuver + MPC planner behind the passive-safety shield
  (experiments.episode.default_planner).
- A perception module implements ``dodt.protocol.PerceptionModule``: ``reset()`` and
  ``update(frame, truth=None) -> PerceptionOutput``; optional attributes ``uses_ground_truth`` (default
  False: ``truth`` is None), ``uses_images`` and ``uses_color`` (default True). Built-in names: the
  perception modes and DODT presets (experiments.perception_modes.known_modes).

Results record the spec as given: ``planner`` and ``perception`` of each summary are the spec string
for a plug-in (the class name ``PassiveSafetyShield`` and the mode name for the built-ins).
"""
from __future__ import annotations

import importlib
import importlib.util
import sys
import zlib
from pathlib import Path

DEFAULT_PLANNER = "default"
DEFAULT_PLANNER_LABEL = "PassiveSafetyShield"  # what summaries have always recorded for the default planner
PLANNER_METHODS = ("reset", "plan")
PERCEPTION_METHODS = ("reset", "update")


class PluginError(ValueError):
    """A spec that does not name a usable class; the message has no option name (the CLI adds it)."""


def is_spec(text: str) -> bool:
    """A ``module:Class`` spec (built-in names hold no colon)."""
    return isinstance(text, str) and ":" in text


def _load_module(name: str):
    if name.endswith(".py") or "/" in name or "\\" in name:
        path = Path(name).expanduser().resolve()
        if not path.is_file():
            raise PluginError(f"no such file {name!r}")
        key = f"_dodt_nav_plugin_{zlib.crc32(str(path).encode()):08x}_{path.stem}"
        if key in sys.modules:
            return sys.modules[key]
        spec = importlib.util.spec_from_file_location(key, path)
        if spec is None or spec.loader is None:
            raise PluginError(f"{name!r} is not a Python file")
        module = importlib.util.module_from_spec(spec)
        sys.modules[key] = module  # dataclasses and pickling look classes up here
        try:
            spec.loader.exec_module(module)
        except Exception as e:  # noqa: BLE001 - the user's file: report it in one line
            del sys.modules[key]
            raise PluginError(f"importing {name} failed: {type(e).__name__}: {e}") from None
        return module
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as e:
        if e.name and (name == e.name or name.startswith(e.name + ".")):
            raise PluginError(f"no such module {name!r} (not importable; a file path ends in .py)") from None
        raise PluginError(f"importing {name} failed: {type(e).__name__}: {e}") from None
    except Exception as e:  # noqa: BLE001
        raise PluginError(f"importing {name} failed: {type(e).__name__}: {e}") from None


def load_class(spec: str) -> type:
    """The class a ``module:Class`` spec names (``Class`` may be dotted: ``Outer.Inner``)."""
    module_name, _, attr = spec.rpartition(":")
    if not module_name or not attr:
        raise PluginError(f"{spec!r}: expected module:Class (a dotted module or a .py file, a colon, a class name)")
    obj = _load_module(module_name)
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise PluginError(f"{module_name} has no class {attr!r}")
        obj = getattr(obj, part)
    if not isinstance(obj, type):
        raise PluginError(f"{spec}: {attr!r} is not a class")
    return obj


def _instantiate(spec: str, methods: tuple[str, ...], protocol: str, where: str):
    cls = load_class(spec)
    try:
        obj = cls()
    except Exception as e:  # noqa: BLE001
        raise PluginError(f"{spec}: {cls.__name__}() (no arguments) failed: {type(e).__name__}: {e}") from None
    missing = [m for m in methods if not callable(getattr(obj, m, None))]
    if missing:
        raise PluginError(f"{spec}: {cls.__name__} does not implement the {protocol} protocol ({where}): no "
                          + " or ".join(f"{m}()" for m in missing) + " method")
    return obj


def make_planner(spec: str | None):
    """A planner instance for a spec; None for the built-in default (built per episode, sized for the drone)."""
    if spec is None or spec == DEFAULT_PLANNER:
        return None
    if not is_spec(spec):
        raise PluginError(f"unknown planner {spec!r}; built-in: {DEFAULT_PLANNER}; or module:Class")
    return _instantiate(spec, PLANNER_METHODS, "planner", "planner.types.Planner")


def planner_label(spec: str | None) -> str:
    """What a summary records as ``planner`` for a spec."""
    return DEFAULT_PLANNER_LABEL if spec is None or spec == DEFAULT_PLANNER else spec


def make_perception_plugin(spec: str):
    """A perception module instance for a ``module:Class`` spec."""
    return _instantiate(spec, PERCEPTION_METHODS, "perception", "dodt.protocol.PerceptionModule")


def check_planner(spec: str | None) -> None:
    """Raises PluginError when the spec does not give a planner (the class is loaded and instantiated once)."""
    make_planner(spec)


def check_perception(spec: str) -> None:
    """Raises PluginError when the spec is neither a built-in mode nor a usable plug-in."""
    from experiments.perception_modes import known_modes

    if is_spec(spec):
        make_perception_plugin(spec)
    elif spec not in known_modes():
        raise PluginError(f"unknown mode {spec!r}; known: {', '.join(known_modes())}; or module:Class")
