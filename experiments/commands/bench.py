"""`bench`: the benchmarks that print figures (the simulator, perception's Table I, runtime's Table II, the
planner, the closed loop's real-time factor)."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from sim.scenario import RENDERER_CHOICES, load_scenario

from experiments.config_limits import PLANNER_NAMES, RIG_NAMES
from experiments.commands.common import (RENDERER_HELP, LazyText, UserError, add_command, check_perception,
                                         dodt_presets, examples, output_folder, seconds, whole, writable_file)


BENCHES = ("sim", "perception", "runtime", "planner", "loop")
# The benches each option applies to: given to another bench, it is refused (cmd_bench).
APPLIES_TO = {
    "--scenario": ("sim", "runtime", "planner", "loop"),
    "--seconds": ("sim", "runtime", "loop"),
    "--out": ("perception",),
    "--seeds": ("perception", "planner"),
    "--split": ("perception",),
    "--scenarios": ("perception",),
    "--configs": ("perception",),
    "--duration": ("perception",),
    "--quick": ("perception",),
    "--rates": ("perception",),
    "--config": ("runtime", "planner", "loop"),
    "--frames": ("sim",),
    "--json": ("sim", "runtime", "planner"),
    "--renderer": ("loop",),
    "--people": ("planner",),
    "--rig": ("perception", "runtime", "loop"),
    "--planner": ("planner", "loop"),
}
# The value of an option that was not given, where it has one (the rest: None, --quick False).
DEFAULTS = {"--scenario": "corridor", "--seconds": 10.0, "--out": "runs/bench_perception", "--config": "dodt",
            "--frames": 30}


def add_parser(sub) -> None:
    b = add_command(
        sub, "bench", help="benchmarks that print figures",
        description="Measure and print figures; nothing here is a pass/fail test. sim: render, physics, LiDAR "
                    "scan and real-time figures of the simulator, renderer by renderer. perception: every DODT "
                    "configuration on the same simulated frames, scored against ground truth, laid out like the "
                    "paper's Table I (written to --out). runtime: per-module milliseconds per frame of one "
                    "configuration, like Table II. planner: voxel map update and MPC solve times, and the whole "
                    "planner's time per plan replaying the inputs of closed-loop episodes. loop: the "
                    "real-time factor of a closed-loop episode (the median of three runs). Figures are wall-clock "
                    "times on this machine.",
        epilog=LazyText(lambda: examples(
            "dodt-nav bench sim --scenario corridor --frames 60",
            "dodt-nav bench perception --quick --configs dodt,dodt-no-ensemble --out runs/table1",
            "dodt-nav bench loop --config oracle --seconds 5",
        ) + "\n\n" + dodt_presets()),
        func=cmd_bench)
    b.add_argument("what", choices=BENCHES,
                   help="sim: render/physics/LiDAR/real-time; perception: Table I; runtime: Table II; planner: "
                        "voxel map update, MPC and whole-planner times; loop: real-time factor of a closed-loop episode")
    # Every option but "what" is None (--quick: False) unless given, so that cmd_bench can refuse one given to a
    # bench it does not apply to (APPLIES_TO); DEFAULTS holds the values of those that have one.
    def opt(flag: str, help: str, **kw) -> None:
        b.add_argument(flag, help=f"{', '.join(APPLIES_TO[flag])}: {help}", **{"default": None, **kw})

    opt("--scenario", "the scenario (default corridor)")
    opt("--seconds", "simulated seconds (sim: of the real-time figure; runtime: of the frames timed; loop: the "
                     "episode's length); default 10", type=seconds)
    opt("--out", "output folder (default runs/bench_perception)")
    opt("--seeds", "seeds 0..N-1 (perception: per scenario, default 1; planner: the episodes replayed, default 2)",
        type=whole(1, 10_000))
    opt("--split", "the seeds' split: dev (seeds 0..N-1, the default) to choose on, test (1000..1000+N-1) "
                   "to report", choices=("dev", "test"))
    opt("--scenarios", "comma-separated scenarios")
    opt("--configs", "comma-separated configurations")
    opt("--duration", "seconds per scenario", type=seconds)
    opt("--quick", "6 s per scenario", action="store_true", default=False)
    opt("--rates", "also score each configuration on the frames decimated to these rates (e.g. 30,15,10,5), "
                   "rows named config@RATEHz", metavar="HZ,...")
    opt("--config", "the DODT configuration (runtime) or the perception mode (planner, loop); default dodt")
    opt("--frames", "frames for the render medians (default 30)", type=whole(1, 100_000))
    opt("--json", "also write the figures as JSON", type=Path)
    opt("--renderer", RENDERER_HELP, choices=RENDERER_CHOICES)
    opt("--people", "only the time per plan against these numbers of people in range (comma list, "
                    "e.g. 10,50,200)", type=_counts, metavar="N,...")
    opt("--rig", "perception, runtime, loop: the drone's sensors (front, the default; front_back, surround4, lidar, "
                 "lidar_below): "
                 "every configuration reads them all (perception: recall counts the people all round, in view or "
                 "not; runtime: the other cameras' and the LiDAR's modules are timed too)",
        choices=RIG_NAMES)
    opt("--planner", "a built-in planner: default (the OSQP MPC) or nmpc (the CasADi NMPC)",
        choices=PLANNER_NAMES)


def _counts(text: str) -> tuple[int, ...]:
    """--people: a comma list of whole numbers of people, 1 to 2000 each."""
    try:
        counts = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a comma list of whole numbers, got {text!r}") from None
    if not counts or len(counts) > 20 or not all(1 <= n <= 2000 for n in counts):
        raise argparse.ArgumentTypeError(f"expected 1 to 20 numbers of people in [1, 2000], got {text!r}")
    return counts


def check_applies(args) -> None:
    """Refuse an option given to a bench it does not apply to (UserError naming it and its benches), and
    set the defaults of those not given."""
    for flag, benches in APPLIES_TO.items():
        dest = flag[2:]
        given = getattr(args, dest) not in (None, False)
        if given and args.what not in benches:
            raise UserError(f"bench {args.what}: {flag} applies only to bench {', '.join(benches)}")
        if not given and flag in DEFAULTS:
            setattr(args, dest, DEFAULTS[flag])


def parse_rates(text: str) -> list[float]:
    """--rates: a comma list of frame rates in Hz, each above 0 and at most the camera's 30 Hz."""
    try:
        rates = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise UserError(f"--rates: expected a comma list of frame rates in Hz, got {text!r}") from None
    bad = [r for r in rates if not 0 < r <= 30]
    if not rates or bad:
        raise UserError(f"--rates: each rate must be above 0 and at most the camera's 30 Hz, got {text!r}")
    return rates


def cmd_bench(args) -> int:
    check_applies(args)
    if args.json is not None:
        writable_file(args.json, "--json")
    if args.what == "sim":
        from experiments.bench_sim import run

        load_scenario(args.scenario)  # validate before anything heavy
        run(args.scenario, seconds=args.seconds, frames=args.frames, json_out=args.json)
        return 0
    if args.what == "perception":
        from dodt.presets import PRESETS
        from experiments import bench_perception
        from experiments.benchmark import SweepError, split_seeds

        scenarios = tuple(args.scenarios.split(",")) if args.scenarios else bench_perception.SCENARIOS
        for s in scenarios:
            load_scenario(s)
        configs = args.configs.split(",") if args.configs else list(PRESETS)
        unknown = [c for c in configs if c not in PRESETS]
        if unknown:
            raise UserError(f"--configs: unknown configuration {unknown[0]!r}; known: {', '.join(PRESETS)}")
        output_folder(args.out)
        duration = args.duration if args.duration else (6.0 if args.quick else None)
        rates = parse_rates(args.rates) if args.rates else None
        try:
            seeds = split_seeds(args.split or "dev", args.seeds or 1)
        except SweepError as e:
            raise UserError(str(e)) from None
        bench_perception.run(Path(args.out), seeds, scenarios, configs, duration, rates=rates,
                             rig_name=args.rig or "front")
        return 0
    if args.what in ("planner", "loop"):  # --config names the perception mode
        check_perception(args.config, f"bench {args.what}: --config")
    if args.what == "planner":
        from experiments import bench_planner
        from experiments.bench_map import bench_update
        from experiments.bench_mpc import bench_mpc

        planner = args.planner or PLANNER_NAMES[0]
        if args.people:
            out = bench_planner.people_scaling(args.people, planner=planner)
            if args.json:
                args.json.write_text(json.dumps(out, indent=1) + "\n")
            return 0
        bench_update()
        for seed in range(3):
            bench_mpc(seed=seed, solver=planner)
        out = bench_planner.run(args.scenario, range(args.seeds or 2), perception=args.config, planner=planner)
        if args.json:
            args.json.write_text(json.dumps(out, indent=1) + "\n")
        return 0
    if args.what == "loop":
        from experiments.episode import EpisodeConfig, run_episode

        sc = load_scenario(args.scenario)
        runs = []
        for _ in range(3):  # the same episode three times: the median real-time factor is quoted
            runs.append(run_episode(sc, seed=0, perception=args.config, renderer=args.renderer,
                                    planner=args.planner or PLANNER_NAMES[0],
                                    cfg=EpisodeConfig(duration=args.seconds, rig=args.rig)))
        rtf = [s["timing"]["real_time_factor"] for s in runs]
        s = sorted(runs, key=lambda r: r["timing"]["real_time_factor"])[1]
        tm = s["timing"]
        print(f"closed loop, {sc.name} seed 0, perception {args.config}, planner {s['planner']}, rig {s['rig']}, "
              f"frame latency "
              f"{s['frame_latency']}: "
              f"{s['sim_time']:.1f} s simulated; real-time factor median {tm['real_time_factor']}x of "
              f"{', '.join(f'{x}x' for x in rtf)} ({tm['renderer']} renderer)")
        for k in ("perception_ms", "map_update_ms", "planner_solve_ms"):
            print(f"  {k}: median {tm[k].get('median')} ms, p95 {tm[k].get('p95')} ms, p99 {tm[k].get('p99')} ms")
        return 0
    from dodt.presets import PRESETS
    from experiments import bench_perception

    if args.config not in PRESETS:
        raise UserError(f"bench runtime: --config takes a DODT configuration ({', '.join(PRESETS)}), "
                        f"got {args.config!r}")
    load_scenario(args.scenario)
    bench_perception.run_runtime(args.config, args.scenario, seconds=args.seconds,
                                 json_out=args.json, rig_name=args.rig or "front")
    return 0
