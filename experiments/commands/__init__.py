"""The subcommands of `dodt-nav`, one module per group; experiments.cli builds the parser from them.

Each module's ``add_parser(sub)`` registers its subcommands on argparse's subparsers, each with its options,
a description and examples (experiments.commands.common.add_command), and its handler as ``func``: a
function of the parsed arguments returning the exit status, raising common.UserError for a user's mistake.
"""
from __future__ import annotations

from experiments.commands import bench, detector, episode, scenarios, sweeps, viewers


def add_parsers(sub) -> None:
    """Every subcommand, in the order `dodt-nav --help` lists them: from one episode to many, then the
    benchmarks, scenario files and the learned detector."""
    episode.add_parser(sub)  # run, simulate
    episode.add_perceive_parser(sub)  # perceive
    viewers.add_parser(sub)  # replay, plot, collisions
    sweeps.add_parser(sub)  # sweep, benchmark, compare, reproduce
    bench.add_parser(sub)  # bench
    scenarios.add_parser(sub)  # scenarios, validate, ceiling
    detector.add_parser(sub)  # train-detector, eval-detector, pack-detector-data


__all__ = ["add_parsers"]
