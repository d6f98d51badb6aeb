"""Loading your own classes: ``--planner module:Class`` and ``--perception module:Class``.

``module`` is an importable dotted module (``mypackage.planners``) or the path of a Python file
(``examples/custom_planner.py``, relative to the working directory). The class is built once per episode,
in the process that runs the episode (a sweep's workers receive the spec string and load the class
themselves): with no arguments, or, when it declares a configuration dataclass as ``config_class``, with
that configuration (its defaults with the ``[planner]`` / ``[perception]`` overrides applied).

What the classes implement: ``planner.types.Planner`` and ``dodt.protocol.PerceptionModule``
(docs/interfaces.md). Which names are built in, and how a spec becomes a component:
experiments.registry.
"""
from __future__ import annotations

import dataclasses
import importlib
import importlib.util
import sys
import zlib
from pathlib import Path

class PluginError(ValueError):
    """A spec that does not name a usable class; the message has no option name (the CLI adds it)."""


def _failure(e: BaseException) -> str:
    """A plug-in's exception in words; ``sys.exit`` and exceptions outside the Exception family count as
    failures of the plug-in too (only a keyboard interrupt is passed on, by the callers)."""
    return f"{type(e).__name__}: {e}"[:500]


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
        except KeyboardInterrupt:
            del sys.modules[key]
            raise
        except BaseException as e:  # noqa: BLE001 - the user's file (sys.exit too): report it in one line
            del sys.modules[key]
            raise PluginError(f"importing {name} failed: {_failure(e)}") from None
        return module
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as e:
        if e.name and (name == e.name or name.startswith(e.name + ".")):
            raise PluginError(f"no such module {name!r} (not importable; a file path ends in .py)") from None
        raise PluginError(f"importing {name} failed: {_failure(e)}") from None
    except KeyboardInterrupt:
        raise
    except BaseException as e:  # noqa: BLE001
        raise PluginError(f"importing {name} failed: {_failure(e)}") from None


def load_class(spec: str) -> type:
    """The class a ``module:Class`` spec names (``Class`` may be dotted: ``Outer.Inner``)."""
    module_name, _, attr = spec.rpartition(":")
    if not module_name or not attr:
        raise PluginError(f"{spec!r}: expected module:Class (a dotted module or a .py file, a colon, a class name)")
    obj = _load_module(module_name)
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except KeyboardInterrupt:
            raise
        except AttributeError:
            raise PluginError(f"{module_name} has no class {attr[:200]!r}") from None
        except BaseException as e:  # noqa: BLE001 - a module's own __getattr__
            raise PluginError(f"{module_name}: looking up {attr[:200]!r} failed: {_failure(e)}") from None
    if not isinstance(obj, type):
        raise PluginError(f"{spec}: {attr!r} is not a class")
    return obj


def config_class(spec: str) -> type | None:
    """The configuration dataclass a plug-in class declares as ``config_class``, or None."""
    cls = load_class(spec)
    own = _attribute(cls, "config_class")
    if own is None:
        return None
    if not (isinstance(own, type) and dataclasses.is_dataclass(own)):
        raise PluginError(f"{spec}: its config_class must be a dataclass, not {own!r}")
    try:
        own()
    except KeyboardInterrupt:
        raise
    except BaseException as e:  # noqa: BLE001 - the user's class
        raise PluginError(f"{spec}: {own.__name__}() (its defaults) failed: {_failure(e)}") from None
    return own


def _attribute(obj, name: str):
    """``getattr(obj, name, None)``, also None when the object's own ``__getattr__`` fails otherwise."""
    try:
        return getattr(obj, name, None)
    except KeyboardInterrupt:
        raise
    except BaseException:  # noqa: BLE001 - the user's class: a method it cannot give is one it lacks
        return None


def load_plugin(spec: str, methods: tuple[str, ...], protocol: str, where: str, config=None):
    """An instance of the class ``spec`` names, built as ``Class(config)`` when it declares a
    ``config_class`` (``config`` None: its defaults) and as ``Class()`` otherwise; PluginError when it
    cannot be built or lacks one of ``methods``."""
    cls = load_class(spec)
    own = type(config) if config is not None else config_class(spec)
    if own is not None and config is None:
        config = own()
    try:
        obj = cls() if own is None else cls(config)
    except KeyboardInterrupt:
        raise
    except BaseException as e:  # noqa: BLE001
        how = "() (no arguments)" if own is None else f"({own.__name__})"
        raise PluginError(f"{spec}: {cls.__name__}{how} failed: {_failure(e)}") from None
    missing = [m for m in methods if not callable(_attribute(obj, m))]
    if missing:
        raise PluginError(f"{spec}: {cls.__name__} does not implement the {protocol} protocol ({where}): no "
                          + " or ".join(f"{m}()" for m in missing) + " method")
    return obj
