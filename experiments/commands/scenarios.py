"""Scenario files: `scenarios` (list the shipped ones) and `validate` (check files before flying them)."""
from __future__ import annotations

from sim.scenario import load_scenario, shipped_scenarios

from experiments.commands.common import add_command, examples


def add_parser(sub) -> None:
    add_command(
        sub, "scenarios", help="list the shipped scenarios",
        description="List the scenarios shipped with the project, one line each: the name that every command "
                    "takes in place of a scenario file, and what the scenario is. Copy a shipped TOML file "
                    "(sim/scenarios/) to start one of your own.",
        epilog=examples("dodt-nav scenarios", "dodt-nav run corridor4 --out runs/corridor4"),
        func=cmd_scenarios)

    v = add_command(
        sub, "validate", help="check scenario files and report the first problem of each",
        description="Check scenario files without flying them: each is loaded as the other commands load it, and "
                    "either reported ok (with its obstacles, people and duration) or refused with its first "
                    "problem, naming the file, the key and the reason (exit status 2).",
        epilog=examples("dodt-nav validate my_scenario.toml sim/scenarios/corridor.toml"),
        func=cmd_validate)
    v.add_argument("files", nargs="+")


def cmd_scenarios(args) -> int:
    for name in shipped_scenarios():
        sc = load_scenario(name)
        print(f"{name:<22}{sc.description}")
    return 0


def cmd_validate(args) -> int:
    for f in args.files:
        sc = load_scenario(f)
        print(f"{f}: ok ({len(sc.obstacles)} obstacles, {len(sc.people)} people, {sc.duration:g} s)")
    return 0
