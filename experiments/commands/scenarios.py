"""Scenario files: `scenarios` (list the shipped ones), `validate` (check files before flying them) and
`ceiling` (what a drone that knew the people's future could do in them)."""
from __future__ import annotations

import json
import statistics

from sim.scenario import load_scenario, shipped_scenarios

from experiments.commands.common import UserError, add_command, examples, real, whole, writable_file


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

    c = add_command(
        sub, "ceiling", help="the clairvoyant ceiling: could any drone have got through, knowing the future?",
        description="For each scenario and seed, search space and time for the earliest collision-free way to the "
                    "goal of a drone that knows where every person will walk (people who do not see the drone "
                    "walk the same whatever it does), at most --v-max fast and never within --clearance of a "
                    "person's centre. An upper bound on any planner's success and time to goal "
                    "(experiments.ceiling): it tells a scenario that leaves no way through from a planner that "
                    "did not find one. Prints, per scenario, the share of seeds with a way through (95 %% Wilson "
                    "interval) and the median clairvoyant time to goal.",
        epilog=examples("dodt-nav ceiling corridor corridor4 --split test --seeds 50",
                        "dodt-nav ceiling corridor4 --seeds 20 --clearance 0.6 --json ceiling.json"),
        func=cmd_ceiling)
    c.add_argument("scenarios", nargs="+", help="shipped scenario names or files")
    c.add_argument("--split", choices=("dev", "test"), default="dev",
                   help="dev: seeds 0..N-1 (the default); test: 1000..1000+N-1, the benchmark's split")
    c.add_argument("--seeds", type=whole(1, 1000), default=20, help="seeds per scenario (default 20)")
    c.add_argument("--clearance", type=real(0.0, 5.0, lo_open=True), default=0.75,
                   help="metres between the drone's and a person's centres (default 0.75: more than the "
                        "simulator's contacts begin at)")
    c.add_argument("--v-max", type=real(0.0, 20.0, lo_open=True), default=2.0,
                   help="the drone's top horizontal speed in m/s (default 2, the planners')")
    c.add_argument("--static-margin", type=real(0.0, 2.0), default=0.0,
                   help="metres kept from structure beyond the drone's radius (default 0; the shield keeps 0.1)")
    c.add_argument("--json", metavar="FILE", help="also write every seed's result to FILE")


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


def cmd_ceiling(args) -> int:
    from experiments.benchmark import SPLITS
    from experiments.ceiling import CeilingConfig, clairvoyant_ceiling
    from experiments.sweep import wilson
    from sim.crowd_future import SeesDrone

    if args.json:
        writable_file(args.json, "--json")
    try:
        cfg = CeilingConfig(clearance=args.clearance, v_max=args.v_max, static_margin=args.static_margin)
    except ValueError as e:
        raise UserError(str(e)) from None
    seeds = range(SPLITS[args.split], SPLITS[args.split] + args.seeds)
    for name in args.scenarios:
        load_scenario(name)  # a bad name or file is refused before any work
    print(f"clairvoyant ceiling, {args.split} seeds {seeds.start}-{seeds.stop - 1}, clearance {cfg.clearance:g} m, "
          f"v_max {cfg.v_max:g} m/s, static margin {cfg.static_margin:g} m")
    print(f"{'scenario':<18}{'seeds':>6}   {'way through [95 %]':<22} {'median time [s]':>8}", flush=True)
    results = {}
    for name in args.scenarios:  # each row as soon as its seeds are done
        out = []
        for s in seeds:
            try:
                out.append(clairvoyant_ceiling(load_scenario(name, s), s, cfg))
            except SeesDrone as e:
                raise UserError(str(e)) from None
        results[name] = [{"seed": r.seed, "reachable": r.reachable, "time_to_goal": r.time_to_goal} for r in out]
        k = sum(r.reachable for r in out)
        lo, hi = wilson(k, len(out))
        times = [r.time_to_goal for r in out if r.reachable]
        median = f"{statistics.median(times):.1f}" if times else "-"
        print(f"{name:<18}{len(out):>6}   {100 * k / len(out):5.1f} [{100 * lo:5.1f}, {100 * hi:5.1f}]   {median:>8}",
              flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"split": args.split, "clearance": cfg.clearance, "v_max": cfg.v_max,
                       "static_margin": cfg.static_margin, "scenarios": results},
                      f, indent=1)
    return 0
