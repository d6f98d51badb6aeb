"""Configuration from TOML files and the command line: ``--config FILE.toml`` and ``--set key=value``.

Generic: it knows no section. The sections (``episode``, ``shield``, ``navigator``, ``map``, ``dodt``,
``oracle``, and ``planner`` / ``perception`` for a plug-in that declares a
configuration dataclass) and the dataclass each one overrides are wired in experiments.registry, which
passes them here as ``{name: default configuration}``.

A file holds TOML tables of these sections (``[navigator.mpc]`` then ``horizon = 30``); ``--set`` takes
``section.field=value`` with the value a TOML literal (``2.5``, ``true``, ``[3, 5]``, ``"depth"``; a bare
word is taken as a string); ``none`` sets an optional field to None. ``--set`` options apply after the file,
in the order given; the last value of a key wins. Unknown keys, values of the wrong type, numbers that are
not finite and values outside a key's range (the ``check`` hook: experiments.config_limits for the built-in
sections, a field's ``metadata["range"]`` for a plug-in's) are errors naming the key. Each summary records
``config``: the overrides and the full effective values of every section the episode used.
"""
from __future__ import annotations

import dataclasses
import math
import tomllib
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sim.toml_keys import longest_key

MAX_CONFIG_BYTES = 1 << 20  # a --config file larger than this is refused before it is parsed
MAX_KEY_DEPTH = 8  # dotted parts in a key: deeper tables are refused

Check = Callable[[str, Any], None]  # (full dotted key, value) -> None; ValueError naming what is wrong


class ConfigError(ValueError):
    """A bad configuration file, key or value; the message names it."""


Items = tuple[tuple[str, Any], ...]


@dataclass(frozen=True)
class Settings:
    """Overrides by section: ``((section, ((dotted field path, value), ...)), ...)`` in the order they
    apply. Frozen and made of plain values: picklable, and equal when the overrides are."""

    sections: tuple[tuple[str, Items], ...] = ()

    def __bool__(self) -> bool:
        return any(items for _, items in self.sections)

    def section(self, name: str) -> Items:
        """The overrides of one section (empty when it has none)."""
        return next((items for s, items in self.sections if s == name), ())

    def names(self) -> tuple[str, ...]:
        """The sections with overrides."""
        return tuple(s for s, items in self.sections if items)

    def assignments(self) -> dict[str, Any]:
        """{"section.field": value} of every override (JSON-ready: tuples as lists)."""
        return {f"{s}.{k}": _jsonable(v) for s, items in self.sections for k, v in items}

    def apply(self, section: str, cfg, check: Check | None = None):
        """``cfg`` (the section's dataclass) with the section's overrides applied, each value checked by
        ``check``; ``cfg`` itself without any."""
        items = self.section(section)
        return _apply(cfg, items, section, check) if items else cfg

    def record(self, used: Mapping[str, Any]) -> dict:
        """The ``config`` entry of a summary: ``set`` (every override) and the full values of every section
        in ``used`` (section -> the dataclass it ended as), whether overridden or not."""
        out: dict[str, Any] = {"set": self.assignments()}
        for name, v in used.items():
            out[name] = _jsonable(dataclasses.asdict(v)) if dataclasses.is_dataclass(v) else _jsonable(v)
        return out


def _jsonable(v):
    if isinstance(v, dict):
        return {k: _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    return v


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
        if not math.isfinite(float(value)):
            raise ConfigError(f"{key}: expected a finite number, got {value!r}")
        return float(value)
    if hint is str:
        if not isinstance(value, str):
            raise ConfigError(f"{key}: expected a string, got {value!r}")
        return value
    return value


def _apply(cfg, items, section: str, check: Check | None = None):
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
    return _replace(cfg, tree, check)


def _keys(tree: dict) -> list[str]:
    """The full keys of every value set in a tree of _apply, in order."""
    return [k for sub in tree.values() for k in (_keys(sub) if isinstance(sub, dict) else [sub[0]])]


def _replace(obj, tree: dict, check: Check | None):
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
            changes[name] = _replace(current, sub, check)
        else:
            if dataclasses.is_dataclass(current):
                fields_of = ", ".join(f.name for f in dataclasses.fields(current))
                raise ConfigError(f"{key}: is a section; set its fields ({fields_of})")
            value = _coerce(sub[1], typing.get_type_hints(type(obj))[name], key)
            _field_range(obj, name, key, value)
            if check is not None:
                try:
                    check(key, value)
                except ValueError as e:
                    raise ConfigError(str(e)) from None
            changes[name] = value
    try:
        return dataclasses.replace(obj, **changes)
    except (ValueError, TypeError) as e:
        raise ConfigError(f"{', '.join(_keys(tree))}: {e}") from None


# ---------------------------------------------------------------- reading

def parse_value(text: str):
    """A ``--set`` value: a TOML literal, or the text itself when it is none (a bare word). One line only:
    a newline would let the text carry further TOML keys, which would be dropped unseen."""
    if any(c in text for c in "\n\r\x00"):
        raise ConfigError(f"--set value {text[:40]!r}: holds a line break or a NUL; give one value per --set")
    try:
        data = tomllib.loads(f"v = {text}")
    except tomllib.TOMLDecodeError:
        return text.strip()
    except ValueError as e:  # an integer of more digits than Python converts (sys.get_int_max_str_digits)
        raise ConfigError(f"--set value {text[:40]!r}...: {e}") from None
    return data["v"]


def _flatten(table: dict, prefix: str = "") -> list[tuple[str, Any]]:
    out = []
    for k, v in table.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out += _flatten(v, key + ".")
        else:
            out.append((key, v))
    return out


def _field_range(obj, name: str, key: str, value) -> None:
    """A plug-in's own range: ``field(metadata={"range": (lo, hi)})`` bounds a number (or each number of a
    list) to [lo, hi]."""
    rng = next(f for f in dataclasses.fields(obj) if f.name == name).metadata.get("range")
    if rng is None or value is None:
        return
    lo, hi = rng
    for v in (value if isinstance(value, tuple) else (value,)):
        if isinstance(v, (int, float)) and not lo <= v <= hi:
            raise ConfigError(f"{key}: {v!r} is outside [{lo:g}, {hi:g}]")


def _depth(v, limit: int, depth: int = 0) -> int:
    """How deep tables and lists nest in ``v``, counting no further than ``limit`` + 1."""
    if depth > limit:
        return depth
    children = v.values() if isinstance(v, dict) else v if isinstance(v, list) else ()
    return max((_depth(c, limit, depth + 1) for c in children), default=depth)


class TextFileError(ValueError):
    """A text file that cannot be used; the message starts with its path."""


def read_text(path: str | Path, limit: int, kind: str) -> str:
    """The text of a small UTF-8 file, read no further than ``limit`` bytes (a device such as /dev/zero never
    ends); TextFileError naming the file when it is missing, not a regular file, larger, or not UTF-8.
    ``kind`` names what the file should be, for the messages."""
    p = Path(path)
    try:
        if not p.exists():
            raise TextFileError(f"no such file {str(path)!r}")
        if p.is_dir():
            raise TextFileError(f"{path} is a folder, not {kind}")
        if not p.is_file():
            raise TextFileError(f"{path} is not a regular file")
        with open(p, "rb") as fh:
            raw = fh.read(limit + 1)
    except OSError as e:
        raise TextFileError(f"cannot read {path}: {e.strerror or e}") from None
    if len(raw) > limit:
        raise TextFileError(f"{path}: larger than {limit / (1 << 20):g} MiB; not {kind}")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise TextFileError(f"{path}: not a UTF-8 text file (byte 0x{raw[e.start]:02x} at offset {e.start})") from None
    if "\x00" in text:
        raise TextFileError(f"{path}: holds NUL bytes; not {kind}")
    return text


def read_file(path: str | Path) -> list[tuple[str, Any]]:
    """The (dotted key, value) pairs of a TOML configuration file (at most MAX_CONFIG_BYTES, UTF-8, tables
    at most MAX_KEY_DEPTH deep); a ConfigError naming the file when it cannot be used."""
    if not str(path):
        raise ConfigError("--config: an empty file name")
    try:
        text = read_text(path, MAX_CONFIG_BYTES, "a configuration file")
    except TextFileError as e:
        raise ConfigError(f"--config: {e}") from None
    parts = longest_key(text)  # before parsing: the parser's work grows with the square of a key's parts
    if parts > MAX_KEY_DEPTH:
        raise ConfigError(f"--config: {path}: a key of {parts} dotted parts: tables nested more than {MAX_KEY_DEPTH} "
                          f"deep")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"--config: {path}: not valid TOML ({e})") from None
    except RecursionError:
        raise ConfigError(f"--config: {path}: nested too deep") from None
    except ValueError as e:  # an integer of more digits than Python converts (sys.get_int_max_str_digits)
        raise ConfigError(f"--config: {path}: {e}") from None
    if _depth(data, MAX_KEY_DEPTH) > MAX_KEY_DEPTH:
        raise ConfigError(f"--config: {path}: tables or lists nested more than {MAX_KEY_DEPTH} deep")
    return _flatten(data)


def parse_set(text: str) -> tuple[str, Any]:
    key, sep, raw = text.partition("=")
    key, raw = key.strip(), raw.strip()
    if not sep or not key or not raw:
        raise ConfigError(f"--set {text[:80]!r}: expected section.key=value, e.g. shield.a_brake=3.0")
    if not key.isprintable():
        raise ConfigError(f"--set {key[:80]!r}: a key of printable characters on one line, as shield.a_brake")
    return key, parse_value(raw)


def build(sections: Mapping[str, Any], config_file: str | Path | None = None, sets: typing.Iterable[str] = (),
          check: Check | None = None, absent: Mapping[str, str] | None = None) -> Settings:
    """Settings from a TOML file and ``--set`` assignments (after the file, in order), each key and value
    checked now against its section's default configuration in ``sections`` (name -> dataclass instance)
    and by ``check``: a ConfigError naming the key (and the file, for a key the file set). ``absent``: why
    a known section is not available in this run (name -> reason), for its error message."""
    pairs = [(k, v, config_file) for k, v in read_file(config_file)] if config_file is not None else []
    pairs += [(*parse_set(s), None) for s in sets]
    by_section: dict[str, dict[str, Any]] = {s: {} for s in sections}
    origin: dict[str, Any] = {}
    for key, value, where in pairs:
        section, _, rest = key.partition(".")
        prefix = f"{where}: " if where else ""
        if not key.isprintable():
            raise ConfigError(f"{prefix}{key[:80]!r}: a key of printable characters on one line")
        if section not in by_section:
            why = (absent or {}).get(section)
            raise ConfigError(f"{prefix}{key}: {why}" if why else
                              f"{prefix}{key}: unknown section {section!r}; sections: {', '.join(sections)}")
        if not rest or rest.count(".") >= MAX_KEY_DEPTH:
            raise ConfigError(f"{prefix}{key}: expected {section}.<field>")
        d = by_section[section]
        d.pop(rest, None)  # the last value wins, in the order of its last assignment
        d[rest] = tuple(value) if isinstance(value, list) else value
        origin[key] = where
    settings = Settings(tuple((s, tuple(d.items())) for s, d in by_section.items() if d))
    for name in settings.names():
        try:
            settings.apply(name, sections[name], check)
        except ConfigError as e:
            keys = str(e).split(":", 1)[0].split(", ")  # the message names the keys it is about
            where = next((origin[k] for k in keys if origin.get(k)), None)
            raise ConfigError(f"{where}: {e}" if where else str(e)) from None
    return settings
