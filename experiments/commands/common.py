"""What every command of `dodt-nav` shares: the user-error type, the option parsers that check values
when they are parsed, the checks of files and folders a command writes, the episode and configuration
options, and the help layout (a description paragraph, example command lines, lists of names).

A command module registers its subcommands with :func:`add_command` and reports user mistakes by raising
:class:`UserError` (experiments.cli prints it on one line and exits with status 2).
"""
from __future__ import annotations

import argparse
import math
import os
import re
from pathlib import Path
from typing import Callable, Iterable

from experiments.config_limits import RIG_NAMES
from sim.scenario import RENDERER_CHOICES


class UserError(Exception):
    """A mistake of the user's: reported in one line, exit status 2."""


# --------------------------------------------------------------------------- option checks
#
# Every numeric option is parsed by one of these: a value out of its bounds (NaN, infinities,
# negative counts, ...) is refused by argparse as "argument --name: reason", before any work.

SEED_MAX = 2**63 - 1  # seeds are whole numbers from 0 to what a scenario file's TOML integer holds
MAX_SECONDS = 3600.0  # s, a time limit: the longest a scenario may last (sim.scenario.MAX_DURATION)
MAX_JOBS = 256  # parallel episodes
MAX_FRAME_LATENCY = 100  # camera periods: each delayed frame is held in memory until it is delivered


def whole(lo: int, hi: int | None = None, what: str = "a whole number"):
    """A whole number in [lo, hi]; ``what`` names it in the messages."""
    bounds = f">= {lo}" + (f" and <= {hi}" if hi is not None else "")

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {what} {bounds}, got {text!r}") from None
        if v < lo or (hi is not None and v > hi):
            raise argparse.ArgumentTypeError(f"must be {bounds}, got {v}" if what == "a whole number"
                                             else f"must be {what} {bounds}, got {v}")
        return v
    return parse


def real(lo: float, hi: float, lo_open: bool = False, hi_open: bool = False, what: str = ""):
    """A finite number in [lo, hi] (open ends as given); ``what`` replaces the bounds in the message."""
    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not math.isfinite(v) or (v <= lo if lo_open else v < lo) or (v >= hi if hi_open else v > hi):
            bounds = what or (f"must be a number {'>' if lo_open else '>='} {lo:g} and {'<' if hi_open else '<='} "
                              f"{hi:g}")
            raise argparse.ArgumentTypeError(f"{bounds}, got {text!r}")
        return v
    return parse


seed = whole(0, SEED_MAX, "a seed, a whole number")
seconds = real(0.0, MAX_SECONDS, lo_open=True, what=f"must be a number of seconds > 0 and <= {MAX_SECONDS:g}")
jobs = whole(1, MAX_JOBS)
fraction = real(0.0, 1.0, what="must be a fraction between 0 and 1")
frame_latency = whole(0, MAX_FRAME_LATENCY, "a whole number of camera periods")


def default_jobs() -> int:
    """Parallel episodes when --jobs is not given: one per CPU."""
    return max(1, os.cpu_count() or 1)


# --------------------------------------------------------------------------- files and folders


def writable_file(path: str, option: str) -> None:
    """Refuse now a file the command writes at its end (a sweep's JUnit XML): found unwritable after the
    work, the work would be lost. The file is created and removed when it did not exist."""
    p = Path(path)
    if p.is_dir():
        raise UserError(f"{option}: {path} is a folder, not a file")
    existed = p.exists()
    try:
        with open(p, "a"):
            pass
    except OSError as e:
        raise UserError(f"{option}: cannot write {path}: {e.strerror or e}") from None
    if not existed:
        p.unlink()


def nonempty_path(path: str, option: str = "--out") -> None:
    """An empty path would mean the current folder: refused."""
    if not str(path).strip():
        raise UserError(f"{option}: an empty path; name the output folder")


def output_folder(path: str, option: str = "--out") -> Path:
    """The output folder, created now (a file in the way or no permission: refused before the work)."""
    nonempty_path(path, option)
    p = Path(path)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise UserError(f"{option}: cannot create the folder {path}: {e.strerror or e}") from None
    if not os.access(p, os.W_OK | os.X_OK):
        raise UserError(f"{option}: cannot write into the folder {path}")
    return p


# --------------------------------------------------------------------------- plug-ins and configuration


def check_perception(mode: str, flag: str = "--perception") -> None:
    """A built-in mode or a plug-in's module:Class that loads and implements the protocol; the error names
    ``flag``, the option that gave it."""
    from experiments.plugins import PluginError
    from experiments.registry import check_perception as check

    try:
        check(mode)
    except PluginError as e:
        raise UserError(f"{flag}: {e}") from None


def check_planner(spec: str) -> str | None:
    """The --planner spec for the episodes: None for the built-in default."""
    from experiments.plugins import PluginError
    from experiments.registry import DEFAULT_PLANNER, check_planner as check

    try:
        check(spec)
    except PluginError as e:
        raise UserError(f"--planner: {e}") from None
    return None if spec == DEFAULT_PLANNER else spec


def settings(args, perceptions=None):
    """The overrides of --config and --set (experiments.config), checked now against the sections of the
    built-in components and of the plug-ins named by --planner and ``perceptions`` (default --perception)."""
    from experiments.config import ConfigError
    from experiments.plugins import PluginError
    from experiments.registry import settings_for

    specs = perceptions if perceptions is not None else [getattr(args, "perception", "dodt")]
    try:
        out = None
        for spec in specs or ["dodt"]:
            out = settings_for(args.config, args.set or (), perception=spec, planner=args.planner)
        return out
    except (ConfigError, PluginError) as e:
        raise UserError(str(e)) from None


# episode options and the episode.* keys they stand for: giving both is refused (which one would win?)
EPISODE_OPTIONS = {"rig": "--rig", "static_map": "--map", "frame_latency": "--frame-latency", "renderer": "--renderer",
                   "duration": "--duration"}


def episode_config(args, settings, **given):
    """The episodes' EpisodeConfig: the episode options (and ``given``, values a command decided), then the
    settings' episode section; an option given on the command line and also set as a key is refused."""
    from experiments.episode_config import EpisodeConfig
    from experiments.registry import configured

    keys = {k for k, _ in settings.section("episode")}
    values = {}
    for field, option in EPISODE_OPTIONS.items():
        v = given.get(field, getattr(args, option[2:].replace("-", "_"), None))
        if v is None:
            continue
        if field in keys:
            raise UserError(f"{option} and episode.{field} (--config/--set) both given; use one")
        values[field] = v
    try:
        return configured(settings, "episode", EpisodeConfig(**values))
    except ValueError as e:
        raise UserError(str(e)) from None


# --------------------------------------------------------------------------- shared options

SCENARIO_HELP = "a scenario file, or the name of a shipped one (see `dodt-nav scenarios`)"
PERCEPTION_HELP = ("dodt (default), oracle, oracle-360, oracle-noisy, static-only, a DODT preset, or your own "
                   "perception class: module:Class with module a dotted module or a .py file; built with no arguments")
RENDERER_HELP = ("the camera's renderer: gl (ours, OpenGL), pybullet (PyBullet's EGL plugin; egl is its older "
                 "name), tiny (PyBullet's TinyRenderer), auto (the first that works, in that order); default: the "
                 "scenario's")


def add_episode_options(parser: argparse.ArgumentParser) -> None:
    """--map, --frame-latency and --renderer for run, sweep and benchmark nav (experiments.episode.STATIC_MAPS and
    EpisodeConfig; not imported here: it loads the simulator), with --planner, --config and --set. Their
    defaults are None: an option given is told apart from one left out (episode_config)."""
    parser.add_argument("--renderer", choices=RENDERER_CHOICES, default=None, help=RENDERER_HELP)
    add_rig_option(parser)
    parser.add_argument("--map", choices=("depth", "truth"), default=None,
                        help="static map: depth (built from the camera, default) or truth (the scenario's geometry "
                             "known from the start; with the oracles or static-only nothing is rendered: a "
                             "fast planner test)")
    parser.add_argument("--frame-latency", type=frame_latency, default=None, metavar="N",
                        help="camera periods between a frame's capture and its perception (default 1: the next "
                             "frame renders in a second process meanwhile; 0: at once, as before)")
    add_config_options(parser)


def add_rig_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--rig", choices=RIG_NAMES, default=None,
                        help="the drone's sensors: front (the paper's forward RGB-D camera, default), front_back, "
                             "surround4 (four cameras 90 deg apart), lidar (a Mid-360-like LiDAR on top and the "
                             "forward camera), lidar_below (that LiDAR upside down under the body and the forward "
                             "camera)")


def add_config_options(parser: argparse.ArgumentParser) -> None:
    """--planner, --config and --set (experiments.plugins, experiments.config)."""
    parser.add_argument("--planner", default="default", metavar="NAME|module:Class",
                        help="default (the MPC planner behind the passive-safety shield), nmpc (the same with the "
                             "MPC in CasADi) or your own planner class: module:Class with module a dotted module or "
                             "a .py file; built with no arguments")
    parser.add_argument("--shield", action="store_true",
                        help="fly a plug-in --planner behind the passive-safety shield (the default planner is)")
    parser.add_argument("--config", default=None, metavar="FILE.toml",
                        help="configuration overrides: TOML tables episode, shield, navigator (navigator.mpc, "
                             "navigator.maneuvers), map, dodt (dodt.motion: the motion label), oracle, and planner / perception for a "
                             "plug-in with a config_class (experiments.registry)")
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                        help="one override, the value a TOML literal (e.g. shield.a_brake=3.0, "
                             "navigator.mpc.horizon=30); repeatable, applied after --config")


# --------------------------------------------------------------------------- help layout


class HelpFormatter(argparse.HelpFormatter):
    """argparse's layout, except for the description and the epilog: their paragraphs (separated by blank
    lines) are wrapped to the terminal's width, and a block with an indented line (a title over example
    command lines or a list) is printed as written."""

    def _fill_text(self, text, width, indent):
        blocks = re.split(r"\n\s*\n", text.strip("\n"))
        out = []
        for block in blocks:
            lines = block.splitlines()
            if any(line.startswith(" ") for line in lines):
                out.append("\n".join(indent + line.rstrip() for line in lines))
            else:
                out.append(super()._fill_text(block, width, indent))
        return "\n\n".join(out)


class LazyText:
    """Help text computed when the help is shown (it may import a module the command itself needs only
    when it runs): experiments.cli's parser resolves it in format_help."""

    def __init__(self, make: Callable[[], str]):
        self.make = make


def examples(*lines: str) -> str:
    """An epilog block: 'examples:' and the command lines, indented."""
    return "examples:\n" + "\n".join(f"  {line}" for line in lines)


def name_list(title: str, names: Iterable[str]) -> str:
    """An epilog block: a title and the names, wrapped and indented (kept as written by HelpFormatter)."""
    import textwrap

    body = textwrap.wrap(", ".join(names), width=76, break_on_hyphens=False)
    return title + ":\n" + "\n".join(f"  {line}" for line in body)


def builtin_names() -> str:
    """Epilog blocks naming the built-in perception modes, the DODT presets and the built-in planner."""
    from dodt.presets import PRESETS
    from experiments.perception_modes import MODES
    from experiments.registry import BUILTIN_PLANNERS, DEFAULT_PLANNER

    return "\n\n".join([
        name_list("perception modes (--perception)", MODES),
        name_list("DODT presets (--perception; see dodt/presets.py)", PRESETS),
        name_list("built-in planners (--planner)", [
            f"{DEFAULT_PLANNER} (the maneuver and MPC planner behind the passive-safety shield, the MPC an OSQP QP; "
            f"recorded as {BUILTIN_PLANNERS[DEFAULT_PLANNER][1]})",
            f"nmpc (the same with the MPC a CasADi NMPC solved by IPOPT; recorded as {BUILTIN_PLANNERS['nmpc'][1]})"]),
        "Your own classes plug in as --perception module:Class and --planner module:Class (examples/"
        "custom_perception.py, examples/custom_planner.py).",
    ])


def dodt_presets() -> str:
    """An epilog block naming the DODT presets."""
    from dodt.presets import PRESETS

    return name_list("DODT presets (see dodt/presets.py)", PRESETS)


def add_command(sub, name: str, help: str, description: str, epilog, func: Callable[..., int],
                **kwargs) -> argparse.ArgumentParser:
    """Register subcommand ``name``: ``help`` is its line in `dodt-nav --help`, ``description`` the paragraph
    atop its own --help, ``epilog`` (text or LazyText) what follows its options: examples, lists of names."""
    p = sub.add_parser(name, help=help, description=description, epilog=epilog, formatter_class=HelpFormatter,
                       **kwargs)
    p.set_defaults(func=func)
    return p


def describe(parser: argparse.ArgumentParser, description: str, epilog) -> None:
    """Give a parser registered elsewhere (experiments.perceive's) the description and epilog of the rest."""
    parser.description = description
    parser.epilog = epilog
    parser.formatter_class = HelpFormatter
