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
import os
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


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where it arrives as Ctrl-C's KeyboardInterrupt is, so that it goes where Ctrl-C goes: past
    the guards around plug-ins and modules (which contain everything else a module raises, SystemExit too)
    and through the finally blocks that close what the command started."""


class _Stop:
    """The handler of SIGINT and SIGTERM while a command runs. The first signal stops the command in order:
    KeyboardInterrupt (SIGINT) or Terminated (SIGTERM) is raised where it arrives. A second signal, while
    the command closes what it started (or when something swallowed the first), ends the process at once
    with 128 + the signal's number; its children end themselves then (sim.parent_watch)."""

    def __init__(self):
        self.signum = None

    def __call__(self, signum, frame):
        if self.signum is not None:
            os.write(2, b"dodt-nav: interrupted again; stopped at once\n")
            os._exit(128 + signum)
        self.signum = signum
        raise KeyboardInterrupt if signum == signal.SIGINT else Terminated


def _handle_signals(stop: _Stop) -> dict:
    """Installs ``stop`` for SIGTERM, and for SIGINT unless the process was started with SIGINT ignored (a
    shell's background job: Ctrl-C is not meant for it); the handlers it replaced."""
    previous = {signal.SIGTERM: signal.signal(signal.SIGTERM, stop)}
    if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:
        previous[signal.SIGINT] = signal.signal(signal.SIGINT, stop)
    return previous


def main(argv: list[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as e:  # argparse's refusals (status 2, one line) and --help (0): returned like the rest
        return e.code if isinstance(e.code, int) else 2
    # SIGTERM (kill, a job scheduler) ends the command as Ctrl-C does: through its finally blocks, which
    # close what it started (a render process, a viewer's server, a sweep's workers). Those also end on
    # their own when this process is gone (SIGKILL, a second signal): sim.parent_watch.
    stop = _Stop()
    previous = {}
    if threading.current_thread() is threading.main_thread():
        previous = _handle_signals(stop)
    try:
        return args.func(args)
    except (ScenarioError, UserError, ModelError, SequenceError) as e:
        print(f"dodt-nav: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        where = f"{e.filename}: " if e.filename else ""
        print(f"dodt-nav: error: {where}{e.strerror or e}", file=sys.stderr)
        return 2
    except Terminated:
        print("dodt-nav: terminated", file=sys.stderr)
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:
        print("dodt-nav: interrupted", file=sys.stderr)
        return 128 + signal.SIGINT
    finally:
        # After a signal its handler stays: a second one while the interpreter ends (joining a pool's threads,
        # closing children) ends the process at once instead of printing a traceback from that clean-up.
        if stop.signum is None:
            for signum, handler in previous.items():
                signal.signal(signum, handler)


if __name__ == "__main__":
    sys.exit(main())


__all__ = ["main", "build_parser", "UserError", "Terminated"]
