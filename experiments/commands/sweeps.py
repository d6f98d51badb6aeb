"""Many episodes: `sweep` (seeds of one scenario), `benchmark nav` (families x perception x people on a seed
split), `compare` (two sweeps seed by seed) and `reproduce` (the paper's tables and the corridor sweeps)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sim.scenario import ScenarioError, load_scenario

from experiments.commands.common import (PERCEPTION_HELP, LazyText, UserError, add_command,
                                         add_config_options, add_episode_options, builtin_names, check_perception,
                                         check_planner, default_jobs, episode_config, examples, fraction, jobs,
                                         nonempty_path, output_folder, real, settings, writable_file)

SWEEP_EXAMPLES = examples(
    "dodt-nav sweep corridor --seeds 0:100 --out runs/sweep",
    "dodt-nav sweep head_on --perception oracle --map truth --max-at-fault-rate 0.05 --junit junit.xml --out runs/ci",
    "dodt-nav sweep corridor --planner examples/custom_planner.py:StraightLine --out runs/mine",
)


def add_parser(sub) -> None:
    w = add_command(
        sub, "sweep", help="run many seeds in parallel; resumable; rates with Wilson intervals; CI gate",
        description="Fly one scenario over many seeds in parallel (--jobs processes, or a Dask cluster) with one "
                    "perception mode and planner. Each episode's summary is appended to OUT/results.jsonl as it "
                    "ends, so rerunning the same command resumes where a killed sweep stopped; failed episodes "
                    "keep their logs. Prints and writes (summary.json, summary.md) the success, at-fault "
                    "collision, not-at-fault-only and timeout rates with 95 % Wilson intervals; as a CI gate, "
                    "exits with status 1 when a --max-*-rate is exceeded.",
        epilog=LazyText(lambda: SWEEP_EXAMPLES + "\n\n" + builtin_names()), func=cmd_sweep)
    w.add_argument("scenario", help="a scenario file, or the name of a shipped one")
    w.add_argument("--seeds", default="0:20", help="start:stop, a number, or a comma list (default 0:20)")
    w.add_argument("--perception", default="dodt", help=PERCEPTION_HELP)
    _add_run_options(w)
    w.add_argument("--max-collision-rate", type=fraction, default=None,
                   help="exit with status 1 when the rate of episodes with any collision exceeds this fraction")
    w.add_argument("--max-at-fault-rate", type=fraction, default=None,
                   help="exit with status 1 when the rate of episodes with an at-fault collision exceeds this fraction")
    w.add_argument("--junit", default=None, help="write JUnit XML, one test case per seed")
    w.add_argument("--keep-logs", action="store_true", help="keep the episode logs of successful episodes too")
    add_episode_options(w)

    bm = add_command(
        sub, "benchmark", help="the navigation benchmark: scenario families x perception modes x people who do or "
                               "do not see the drone, on a named seed split; report.md",
        description="The closed-loop navigation benchmark: every shipped scenario family, flown with each "
                    "perception mode, among people who do not see the drone (blind) and who do (aware), on the "
                    "first --seeds seeds of a named split: dev (seeds 0-999) for tuning and choosing, test (seeds "
                    "1000-1999) for reported figures. Each cell is a resumable sweep under OUT/; OUT/report.md and "
                    "report.json give per cell the success, at-fault, not-at-fault-only and timeout rates with "
                    "95 % Wilson intervals, and OUT/plots/ one figure per family.",
        epilog=LazyText(lambda: examples(
            "dodt-nav benchmark nav --quick --out runs/bench_smoke",
            "dodt-nav benchmark nav --split test --seeds 100 --out runs/bench_test",
            "dodt-nav benchmark nav --families corridor,crossing --perception dodt,examples/custom_perception.py:NearDODT "
            "--people blind --out runs/mine",
        ) + "\n\n" + _families() + "\n\n" + builtin_names()),
        func=cmd_benchmark)
    bm.add_argument("what", choices=("nav",), help="nav: the closed-loop navigation benchmark")
    bm.add_argument("--split", choices=("dev", "test"), default="dev",
                    help="dev: seeds 0-999, for tuning and choosing; test: seeds 1000-1999, for reported figures")
    bm.add_argument("--seeds", type=seed_span, default="100",
                    help="N: the split's first N seeds (default 100); start:stop: seeds start to stop-1, inside the "
                         "split (fresh dev seeds for a choice, e.g. 200:360)")
    bm.add_argument("--families", default=None, help="comma list (default: all shipped families)")
    bm.add_argument("--perception", default=None, help="comma list of modes or module:Class plug-ins "
                                                        "(default: dodt,oracle,static-only)")
    bm.add_argument("--people", default="blind,aware",
                    help="blind (people do not see the drone), aware (they do), or both (default)")
    _add_run_options(bm)
    bm.add_argument("--quick", action="store_true",
                    help="smoke-sized: 2 seeds, corridor and head_on, oracle on the known map (unless given)")
    add_episode_options(bm)

    cp = add_command(
        sub, "compare", help="pair two sweeps seed by seed: seeds turned each way, exact sign test; "
                             "CI gate on a significant regression",
        description="Compare two sweeps of the same scenario and seeds (a baseline and a change) seed by seed: "
                    "which seeds turned from success to failure and which the other way, and the exact two-sided "
                    "sign test (McNemar's) on those; seeds with the same outcome in both say nothing about the "
                    "change. Every outcome class (at-fault collision, timeout, ...) gets the same test and a 95 % "
                    "interval of the change in its rate. Two success rates alone cannot tell a real gain from the "
                    "churn of small changes; the paired test can. As a CI gate, --fail-if-worse exits with status 1 "
                    "on a significant regression.",
        epilog=examples("dodt-nav compare runs/base runs/new",
                        "dodt-nav compare runs/base/results.jsonl runs/new/results.jsonl --fail-if-worse 0.05"),
        func=cmd_compare)
    cp.add_argument("base", help="the baseline's sweep folder (or its results.jsonl)")
    cp.add_argument("new", help="the change's sweep folder (or its results.jsonl)")
    cp.add_argument("--fail-if-worse", type=real(0.0, 1.0, lo_open=True, what="must be a significance level in (0, 1]"),
                    default=None, metavar="ALPHA",
                    help="exit with status 1 when more seeds turned to failure than to success and the sign "
                         "test's p is below ALPHA (e.g. 0.05)")

    rep = add_command(
        sub, "reproduce", help="Table I, Table II and the corridor sweeps in one report.md",
        description="Reproduce the paper's results in one go: the perception benchmark (Table I), the runtime "
                    "benchmark (Table II) and the corridor navigation sweeps (dodt, oracle, static-only), written "
                    "to OUT/report.md with the figures embedded and the paper's numbers beside ours. Rerunning "
                    "with the same folder resumes the sweeps. --quick shrinks every part to finish in minutes; "
                    "its figures are a smoke test, not results.",
        epilog=examples("dodt-nav reproduce --quick --out runs/reproduce_quick",
                        "dodt-nav reproduce --out runs/reproduce_brake3 --set shield.a_brake=3.0",
                        "dodt-nav reproduce --quick --out runs/reproduce_near "
                        "--perception examples/custom_perception.py:NearDODT"),
        func=cmd_reproduce)
    rep.add_argument("--out", required=True, help="output folder (rerun to resume the sweeps)")
    rep.add_argument("--quick", action="store_true", help="a small version that finishes in minutes")
    rep.add_argument("--jobs", type=jobs, default=default_jobs(), help="parallel episodes")
    rep.add_argument("--perception", action="append", default=[], metavar="module:Class",
                     help="your own perception class, flown in one more navigation sweep beside dodt, oracle "
                          "and static-only (as many seeds as dodt); repeatable")
    add_config_options(rep)


def seed_span(text: str) -> str:
    """--seeds of `benchmark nav`: N or start:stop (whole numbers); whether they lie in the split is the
    benchmark's check (experiments.benchmark.split_seeds)."""
    parts = text.strip().split(":")
    if len(parts) > 2 or not all(p.strip().isdigit() for p in parts):
        raise argparse.ArgumentTypeError(f"must be N or start:stop (whole numbers), got {text!r}")
    return text.strip()


def _add_run_options(parser) -> None:
    """--jobs, --dask, --out and --quiet of the commands that fly many resumable episodes (sweep, benchmark)."""
    parser.add_argument("--jobs", type=jobs, default=default_jobs(), help="parallel episodes (default: CPUs)")
    parser.add_argument("--dask", default=None, metavar="ADDRESS", help="run on a Dask distributed scheduler")
    parser.add_argument("--out", required=True, help="output folder (rerun with the same folder to resume)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def _families() -> str:
    from experiments.benchmark import FAMILIES
    from experiments.commands.common import name_list

    return name_list("scenario families (--families; default all)", FAMILIES)


def cmd_sweep(args) -> int:
    from experiments import sweep

    load_scenario(args.scenario)  # validate before starting workers
    nonempty_path(args.out)
    check_perception(args.perception)
    planner = check_planner(args.planner)
    config = settings(args)
    cfg = episode_config(args, config)
    if args.junit:
        writable_file(args.junit, "--junit")
    try:
        seeds = sweep.parse_seeds(args.seeds)
        agg = sweep.run_sweep(args.scenario, seeds, args.perception, Path(args.out), jobs=args.jobs,
                              dask_address=args.dask, keep_logs=args.keep_logs, progress=not args.quiet, cfg=cfg,
                              settings=config, planner=planner, shield=args.shield)
    except sweep.SweepError as e:
        raise UserError(str(e)) from None
    r = agg["rates"]

    def rate(k):
        return f"{100 * r[k]['rate']:.1f} % [{100 * r[k]['ci95'][0]:.1f}, {100 * r[k]['ci95'][1]:.1f}]"

    print(f"{agg['scenario']} / {agg['perception']}" + (f" / {agg['planner']}" if planner else "")
          + f": {agg['episodes']} episodes; success {rate('success')}, "
          f"at-fault collision {rate('at_fault')}, only not-at-fault collisions {rate('not_at_fault_only')}, "
          f"timeout {rate('timeout')}")
    print(f"wrote {args.out}/summary.json, {args.out}/summary.md")
    if args.junit:
        by_seed = sweep.read_results(Path(args.out) / sweep.RESULTS)
        try:
            Path(args.junit).write_text(sweep.junit(agg, by_seed))
        except OSError as e:  # a full disk (/dev/full) fails on the write, whose error names no file
            raise UserError(f"--junit: cannot write {args.junit}: {e.strerror or e}") from None
        print(f"wrote {args.junit}")
    status = 0
    errs = agg.get("module_errors") or []
    if errs:
        print(f"error: the planner or perception failed in {len(errs)} episodes (seeds "
              + ", ".join(str(e["seed"]) for e in errs) + f"); see {args.out}/episodes/seed_NNNN/errors.txt",
              file=sys.stderr)
        status = 1
    for key, limit in (("collision", args.max_collision_rate), ("at_fault", args.max_at_fault_rate)):
        if limit is not None and r[key]["rate"] > limit:
            what = "at-fault collision" if key == "at_fault" else "collision"
            print(f"{what} rate {r[key]['rate']:.4f} exceeds --max-{key.replace('_', '-')}-rate {limit}",
                  file=sys.stderr)
            status = 1
    return status


def cmd_benchmark(args) -> int:
    from experiments import benchmark
    from experiments.sweep import SweepError

    def names(text, known, option):
        out = [x.strip() for x in text.split(",") if x.strip()]
        bad = [repr(x) for x in out if known is not None and x not in known]
        if not out or bad:
            raise UserError(f"--{option}: {bad[0] if bad else repr(text)} is not one of {', '.join(known)}"
                            if known else f"--{option}: {text!r} names nothing")
        return tuple(out)

    nonempty_path(args.out)
    families = names(args.families, None, "families") if args.families else benchmark.FAMILIES
    for f in families:
        try:
            load_scenario(f)  # validate before starting workers
        except ScenarioError as e:
            raise UserError(f"--families: {e}") from None
    modes = names(args.perception, None, "perception") if args.perception else benchmark.MODES
    for m in modes:
        check_perception(m)
    people = names(args.people, tuple(benchmark.PEOPLE), "people")
    planner = check_planner(args.planner)
    config = settings(args, modes)
    count, given = args.seeds, {}
    if args.quick:  # a smoke-sized run: two families, the oracle on the known map (unless given), two seeds
        families = families if args.families else ("corridor", "head_on")
        modes = modes if args.perception else ("oracle",)
        try:
            seeds = benchmark.split_seeds(args.split, count)
        except SweepError as e:
            raise UserError(str(e)) from None
        count = f"{seeds[0]}:{seeds[0] + min(len(seeds), 2)}"
        if args.map is None and "static_map" not in dict(config.section("episode")):
            given["static_map"] = "truth"
    cfg = episode_config(args, config, **given)
    try:
        report = benchmark.run_benchmark(Path(args.out), args.split, count, families, modes, people, jobs=args.jobs,
                                         dask_address=args.dask, cfg=cfg, progress=not args.quiet,
                                         settings=config, planner=planner, shield=args.shield)
    except SweepError as e:
        raise UserError(str(e)) from None
    print(benchmark.markdown(report))
    print(f"wrote {args.out}/report.md, {args.out}/report.json and {args.out}/plots/")
    failed = sum(len(r.get("module_errors") or []) for r in report["cells"])
    if failed:
        print(f"error: the planner or perception failed in {failed} episodes (listed in {args.out}/report.md)",
              file=sys.stderr)
        return 1
    return 0


def cmd_compare(args) -> int:
    from experiments.compare_sweeps import CompareError, compare_sweeps, format_comparison

    try:
        c = compare_sweeps(args.base, args.new)
    except CompareError as e:
        raise UserError(str(e)) from None
    print(format_comparison(c))
    worse = len(c.to_failure) > len(c.to_success)
    if args.fail_if_worse is not None and worse and c.p_value < args.fail_if_worse:
        print(f"the change is worse than the baseline: p = {c.p_value:.3g} < --fail-if-worse {args.fail_if_worse}",
              file=sys.stderr)
        return 1
    return 0


def cmd_reproduce(args) -> int:
    from experiments.plugins import is_spec
    from experiments.reproduce import reproduce

    planner = check_planner(args.planner)
    for spec in args.perception:
        if not is_spec(spec):
            raise UserError(f"--perception: {spec!r} is not module:Class; the built-in modes are flown already")
        check_perception(spec)
    config = settings(args, list(args.perception) or ["dodt"])
    output_folder(args.out)
    reproduce(Path(args.out), quick=args.quick, jobs=args.jobs, settings=config, planner=planner,
              perception=tuple(args.perception), shield=args.shield)
    return 0
