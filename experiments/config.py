"""Configuration from TOML files and the command line: ``--config FILE.toml`` and ``--set key=value``.

Sections and the configuration each one overrides:

- ``episode``: experiments.episode.EpisodeConfig (``episode.plan_rate``, ``episode.duration``, ...);
- ``shield``: planner.shield.shield.ShieldConfig of the default planner (``shield.a_brake``);
- ``navigator``: planner.nominal.navigator.NavigatorConfig of the default planner, with its nested sections
  (``navigator.cruise_speed``, ``navigator.mpc.horizon``, ``navigator.maneuvers.<field>``);
- ``map``: planner.map.voxel_map.MapConfig of the episode's static map, after the episode sizes it to the
  scenario (``map.p_hit``);
- ``dodt``: dodt.config.DODTConfig of the DODT perception modes, on top of the mode's preset
  (``dodt.kalman.q_pos``; dodt.config.override);
- ``moving_rule``: experiments.perception_modes.MovingTrackRule of the DODT perception modes, which tracks
  besides DODT's dynamic ones the planner avoids (``moving_rule.min_speed``);
- ``oracle``: experiments.perception_modes.OracleConfig of the oracle perception modes, on top of the mode's
  own (``oracle.max_range``; oracle-noisy starts from its velocity noise).

A file holds TOML tables of these sections (``[navigator.mpc]`` then ``horizon = 30``); ``--set`` takes
``section.field=value`` with the value a TOML literal (``2.5``, ``true``, ``[3, 5]``, ``"depth"``; a bare
word is taken as a string); ``none`` sets an optional field to None. ``--set`` options apply after the file,
in the order given; the last value of a key wins. Unknown keys and values of the wrong type are errors
naming the key. Each summary records ``config``: ``set`` (the overrides, by dotted key) and the full
values of every overridden section; with no overrides nothing is added and results are bit-identical
to a run without these options.

The shield and navigator sections configure the default planner only; a plug-in planner
(experiments.plugins) is built with no arguments. The dodt and moving_rule sections configure the DODT
modes only, the oracle section the oracle modes only; a plug-in perception module reads none.
"""
from __future__ import annotations

import dataclasses
import tomllib
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any

SECTIONS = ("episode", "shield", "navigator", "map", "dodt", "moving_rule", "oracle")


class ConfigError(ValueError):
    """A bad configuration file, key or value; the message names it."""


def _section_classes() -> dict[str, type]:
    from dodt.config import DODTConfig
    from experiments.episode import EpisodeConfig
    from experiments.perception_modes import MovingTrackRule, OracleConfig
    from planner.map.voxel_map import MapConfig
    from planner.nominal.navigator import NavigatorConfig
    from planner.shield.shield import ShieldConfig

    return {"episode": EpisodeConfig, "shield": ShieldConfig, "navigator": NavigatorConfig, "map": MapConfig,
            "dodt": DODTConfig, "moving_rule": MovingTrackRule, "oracle": OracleConfig}


@dataclass(frozen=True)
class Settings:
    """Overrides by section, each a tuple of (dotted field path within the section, value) in the order they
    apply. Frozen and made of plain values: picklable, and equal when the overrides are."""

    episode: tuple[tuple[str, Any], ...] = ()
    shield: tuple[tuple[str, Any], ...] = ()
    navigator: tuple[tuple[str, Any], ...] = ()
    map: tuple[tuple[str, Any], ...] = ()
    dodt: tuple[tuple[str, Any], ...] = ()
    moving_rule: tuple[tuple[str, Any], ...] = ()
    oracle: tuple[tuple[str, Any], ...] = ()

    def __bool__(self) -> bool:
        return any(getattr(self, s) for s in SECTIONS)

    def assignments(self) -> dict[str, Any]:
        """{"section.field": value} of every override (JSON-ready: tuples as lists)."""
        return {f"{s}.{k}": _jsonable(v) for s in SECTIONS for k, v in getattr(self, s)}

    # ------------------------------------------------------------ applying
    def apply(self, section: str, cfg):
        """``cfg`` (the section's dataclass) with the section's overrides applied; ``cfg`` itself without any."""
        items = getattr(self, section)
        return _apply(cfg, items, section) if items else cfg

    def episode_config(self, cfg):
        return self.apply("episode", cfg)

    def shield_config(self, cfg):
        return self.apply("shield", cfg)

    def navigator_config(self, cfg):
        return self.apply("navigator", cfg)

    def map_config(self, cfg):
        return self.apply("map", cfg)

    def moving_rule_config(self, cfg):
        return self.apply("moving_rule", cfg)

    def oracle_config(self, cfg):
        return self.apply("oracle", cfg)

    def dodt_assignments(self) -> tuple[str, ...]:
        """The dodt section as dodt.config.override's ``section.field=value`` strings."""
        return tuple(f"{k}={_override_text(v)}" for k, v in self.dodt)

    def dodt_config(self, cfg):
        if not self.dodt:
            return cfg
        from dodt.config import override

        try:
            return override(cfg, self.dodt_assignments())
        except ValueError as e:
            msg = str(e)
            raise ConfigError("dodt." + (msg[len("--set "):] if msg.startswith("--set ") else msg)) from None

    def record(self, sections: dict[str, Any]) -> dict:
        """The ``config`` entry of a summary: ``set`` (every override) and, for each overridden section, its
        full values from ``sections`` (section -> the dataclass it ended as, or a note when not used)."""
        out: dict[str, Any] = {"set": self.assignments()}
        for s in SECTIONS:
            if getattr(self, s) and s in sections:
                v = sections[s]
                out[s] = _jsonable(dataclasses.asdict(v)) if dataclasses.is_dataclass(v) else v
        return out


def _jsonable(v):
    if isinstance(v, dict):
        return {k: _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    return v


def _override_text(v) -> str:
    """A value in dodt.config.override's syntax."""
    if v is None:
        return "none"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple)):
        return ",".join(_override_text(x) for x in v)
    return str(v) if not isinstance(v, float) else repr(v)


# ---------------------------------------------------------------- typed values

def _coerce(value, hint, key: str):
    """``value`` (from TOML) as a field of type ``hint``; ConfigError naming ``key`` when it is not one."""
    args = typing.get_args(hint)
    origin = typing.get_origin(hint)
    if origin in (typing.Union, getattr(__import__("types"), "UnionType", None)):
        inner = [a for a in args if a is not type(None)]
        if type(None) in args and (value is None or (isinstance(value, str) and value.lower() == "none")):
            return None
        if len(inner) == 1:
            return _coerce(value, inner[0], key)
        for a in inner:
            try:
                return _coerce(value, a, key)
            except ConfigError:
                pass
        raise ConfigError(f"{key}: {value!r} is not a {' or '.join(getattr(a, '__name__', str(a)) for a in inner)}")
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{key}: expected a list (e.g. [1.0, 2.0]), got {value!r}")
        if args and args[-1] is Ellipsis:
            return tuple(_coerce(x, args[0], key) for x in value)
        if args and len(args) != len(value):
            raise ConfigError(f"{key}: expected a list of {len(args)} values, got {len(value)}")
        return tuple(_coerce(x, a, key) for x, a in zip(value, args)) if args else tuple(value)
    if hint is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{key}: expected true or false, got {value!r}")
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{key}: expected a whole number, got {value!r}")
        return value
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{key}: expected a number, got {value!r}")
        return float(value)
    if hint is str:
        if not isinstance(value, str):
            raise ConfigError(f"{key}: expected a string, got {value!r}")
        return value
    return value


def _apply(cfg, items, section: str):
    """``cfg`` (a dataclass) with (dotted path, value) items applied through nested dataclasses. Each
    dataclass is replaced once, with all of its changes, so that values it checks against each other (a
    minimum and a maximum) can be set in any order."""
    tree: dict = {}  # field name -> (full key, value), or a dict of the same for a nested dataclass
    for path, value in items:
        key = f"{section}.{path}"
        *heads, last = path.split(".")
        node = tree
        for h in heads:
            node = node.setdefault(h, {})
            if not isinstance(node, dict):
                raise ConfigError(f"{key}: {node[0]} is set too; a key is a value or a section, not both")
        if isinstance(node.get(last), dict):
            raise ConfigError(f"{key}: {_keys(node[last])[0]} is set too; a key is a value or a section, not both")
        node[last] = (key, value)
    return _replace(cfg, tree)


def _keys(tree: dict) -> list[str]:
    """The full keys of every value set in a tree of _apply, in order."""
    return [k for sub in tree.values() for k in (_keys(sub) if isinstance(sub, dict) else [sub[0]])]


def _replace(obj, tree: dict):
    fields = {f.name for f in dataclasses.fields(obj)}
    changes = {}
    for name, sub in tree.items():
        key = _keys(sub)[0] if isinstance(sub, dict) else sub[0]
        if name not in fields:
            raise ConfigError(f"{key}: unknown key; {type(obj).__name__} has no field {name!r} "
                              f"(fields: {', '.join(sorted(fields))})")
        current = getattr(obj, name)
        if isinstance(sub, dict):
            if not dataclasses.is_dataclass(current):
                raise ConfigError(f"{key}: unknown key; {type(obj).__name__}.{name} is a value, not a section")
            changes[name] = _replace(current, sub)
        else:
            if dataclasses.is_dataclass(current):
                fields_of = ", ".join(f.name for f in dataclasses.fields(current))
                raise ConfigError(f"{key}: is a section; set its fields ({fields_of})")
            changes[name] = _coerce(sub[1], typing.get_type_hints(type(obj))[name], key)
    try:
        return dataclasses.replace(obj, **changes)
    except (ValueError, TypeError) as e:
        raise ConfigError(f"{', '.join(_keys(tree))}: {e}") from None


# ---------------------------------------------------------------- reading

def parse_value(text: str):
    """A ``--set`` value: a TOML literal, or the text itself when it is none (a bare word)."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text.strip()


def _flatten(table: dict, prefix: str = "") -> list[tuple[str, Any]]:
    out = []
    for k, v in table.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out += _flatten(v, key + ".")
        else:
            out.append((key, v))
    return out


def read_file(path: str | Path) -> list[tuple[str, Any]]:
    """The (dotted key, value) pairs of a TOML configuration file."""
    p = Path(path)
    try:
        with open(p, "rb") as fh:
            data = tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"--config: no such file {str(path)!r}") from None
    except IsADirectoryError:
        raise ConfigError(f"--config: {path} is a folder, not a TOML file") from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"--config: {path}: not valid TOML ({e})") from None
    except OSError as e:
        raise ConfigError(f"--config: cannot read {path}: {e.strerror or e}") from None
    return [(k, v) for k, v in _flatten(data)]


def parse_set(text: str) -> tuple[str, Any]:
    key, sep, raw = text.partition("=")
    key, raw = key.strip(), raw.strip()
    if not sep or not key or not raw:
        raise ConfigError(f"--set {text!r}: expected section.key=value, e.g. shield.a_brake=3.0")
    return key, parse_value(raw)


def build(config_file: str | Path | None = None, sets: typing.Iterable[str] = ()) -> Settings:
    """Settings from a TOML file and ``--set`` assignments (after the file, in order), each key and value
    checked against its section's dataclass now (ConfigError naming the key when wrong)."""
    pairs = read_file(config_file) if config_file else []
    pairs += [parse_set(s) for s in sets]
    by_section: dict[str, dict[str, Any]] = {s: {} for s in SECTIONS}
    for key, value in pairs:
        section, _, rest = key.partition(".")
        if section not in by_section:
            raise ConfigError(f"{key}: unknown section {section!r}; sections: {', '.join(SECTIONS)}")
        if not rest:
            raise ConfigError(f"{key}: expected {section}.<field>")
        d = by_section[section]
        d.pop(rest, None)  # the last value wins, in the order of its last assignment
        d[rest] = tuple(value) if isinstance(value, list) else value
    settings = Settings(**{s: tuple(d.items()) for s, d in by_section.items()})
    check(settings)
    return settings


def check(settings: Settings) -> None:
    """Apply every section to its default configuration: an unknown key or a bad value raises now."""
    if not settings:
        return
    classes = _section_classes()
    from dodt.presets import preset

    settings.episode_config(classes["episode"]())
    settings.shield_config(classes["shield"]())
    settings.navigator_config(classes["navigator"]())
    settings.map_config(classes["map"]())
    settings.dodt_config(preset("dodt"))
    settings.moving_rule_config(classes["moving_rule"]())
    settings.oracle_config(classes["oracle"]())
    if settings.episode:
        from experiments.episode import STATIC_MAPS

        e = settings.episode_config(classes["episode"]())
        if e.static_map not in STATIC_MAPS:
            raise ConfigError(f"episode.static_map: {e.static_map!r} is not one of {', '.join(STATIC_MAPS)}")
        if e.duration is not None and not 0 < e.duration <= 3600:
            raise ConfigError(f"episode.duration: expected seconds > 0 and <= 3600, got {e.duration!r}")
        if e.frame_latency < 0 or e.map_every < 1 or not e.plan_rate > 0:
            raise ConfigError("episode: frame_latency must be >= 0, map_every >= 1 and plan_rate > 0")
