"""`dodt-nav`: the project's command line.

User mistakes (a bad scenario, a missing file, a bad option) print one line naming what is
wrong and exit with status 2, never a traceback. Options are checked when they are parsed, and
files a command will write are checked before it starts its work.

This module builds the parser and runs a command; the commands themselves (their options, help and
handlers) live in experiments.commands, one module per group, and what they share in
experiments.commands.common.
"""
from __future__ import annotations

import argparse
import importlib.metadata
import signal
import sys
import threading

from dodt.learned.model import ModelError
from experiments.commands import add_parsers
from experiments.commands.common import HelpFormatter, LazyText, UserError, examples
from experiments.sequences import SequenceError
from sim.scenario import ScenarioError

DESCRIPTION = ("Closed-loop drone navigation among walking people with DODT (onboard dynamic-object detection and "
               "tracking, Xu et al.): "
               "fly a quadrotor through simulated scenarios with DODT or another perception module and a planner, "
               "check every run for collisions, measure it against ground truth, watch it, and run sweeps and "
               "benchmarks over many seeds. Each command has its own --help with a description and examples.")

EPILOG = examples(
    "dodt-nav scenarios",
    "dodt-nav run corridor --out runs/first --viz html",
    "dodt-nav sweep corridor --seeds 0:20 --out runs/sweep",
    "dodt-nav run --help",
)


class _Parser(argparse.ArgumentParser):
    """argparse with its refusals on one line (its own print the usage first), exit status 2, and help text
    made when it is shown (common.LazyText)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")

    def format_help(self) -> str:
        if isinstance(self.epilog, LazyText):
            self.epilog = self.epilog.make()
        return super().format_help()


DISTRIBUTION = "dodt-nav"  # the package's name in pyproject.toml


def version() -> str:
    """The installed package's version (its metadata), or a note when it is run from a source tree that was
    never installed."""
    try:
        return importlib.metadata.version(DISTRIBUTION)
    except importlib.metadata.PackageNotFoundError:
        return "unknown (not installed)"


def build_parser() -> argparse.ArgumentParser:
    ap = _Parser(prog="dodt-nav", description=DESCRIPTION, epilog=EPILOG, formatter_class=HelpFormatter)
    ap.add_argument("--version", action="version", version=f"%(prog)s {version()}",
                    help="print the version and exit")
    sub = ap.add_subparsers(dest="command", required=True)
    add_parsers(sub)
    return ap


def _terminated(signum, frame):
    raise SystemExit(128 + signum)


def main(argv: list[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as e:  # argparse's refusals (status 2, one line) and --help (0): returned like the rest
        return e.code if isinstance(e.code, int) else 2
    # SIGTERM (kill, a job scheduler) ends the command as Ctrl-C does: through its finally blocks, which
    # close what it started (a render process, a viewer's server, a sweep's workers). Those also end on
    # their own when this process is gone (SIGKILL): sim.parent_watch.
    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, _terminated)
    try:
        return args.func(args)
    except (ScenarioError, UserError, ModelError, SequenceError) as e:
        print(f"dodt-nav: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        where = f"{e.filename}: " if e.filename else ""
        print(f"dodt-nav: error: {where}{e.strerror or e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("dodt-nav: interrupted", file=sys.stderr)
        return 130
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())


__all__ = ["main", "build_parser", "UserError"]
