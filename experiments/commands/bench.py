"""`bench`: the benchmarks that print figures (the simulator, perception's Table I, runtime's Table II, the
planner, the closed loop's real-time factor)."""
from __future__ import annotations

import json
from pathlib import Path

from sim.scenario import RENDERER_CHOICES, load_scenario

from experiments.commands.common import (RENDERER_HELP, LazyText, UserError, add_command, dodt_presets, examples,
                                         output_folder, seconds, whole, writable_file)


def add_parser(sub) -> None:
    b = add_command(
        sub, "bench", help="benchmarks that print figures",
        description="Measure and print figures; nothing here is a pass/fail test. sim: render, physics and "
                    "real-time figures of the simulator, renderer by renderer. perception: every DODT "
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
    b.add_argument("what", choices=("sim", "perception", "runtime", "planner", "loop"),
                   help="sim: render/physics/real-time; perception: Table I; runtime: Table II; planner: voxel map "
                        "update, MPC and whole-planner times; loop: real-time factor of a closed-loop episode")
    b.add_argument("--scenario", default=None, help="sim, runtime, planner: the scenario (default corridor)")
    b.add_argument("--seconds", type=seconds, default=10.0, help="simulated seconds (sim: real-time figure; runtime: frames)")
    b.add_argument("--out", default="runs/bench_perception", help="perception: output folder")
    b.add_argument("--seeds", type=whole(1, 10_000), default=None, help="perception: seeds 0..N-1 per scenario; planner: episodes "
                                                                        "replayed (seeds 0..N-1, default 2)")
    b.add_argument("--scenarios", default=None, help="perception: comma-separated scenarios")
    b.add_argument("--configs", default=None, help="perception: comma-separated configurations")
    b.add_argument("--duration", type=seconds, default=None, help="perception: seconds per scenario")
    b.add_argument("--quick", action="store_true", help="perception: 6 s per scenario")
    b.add_argument("--rates", default=None, metavar="HZ,...",
                   help="perception: also score each configuration on the frames decimated to these rates "
                        "(e.g. 30,15,10,5), rows named config@RATEHz")
    b.add_argument("--config", default="dodt", help="runtime: the configuration; loop, planner: the perception mode")
    b.add_argument("--frames", type=whole(1, 100_000), default=30, help="frames for the render medians")
    b.add_argument("--json", type=Path, default=None, help="also write the figures as JSON")
    b.add_argument("--renderer", choices=RENDERER_CHOICES, default=None, help="loop: " + RENDERER_HELP)


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
    if args.json is not None:
        writable_file(args.json, "--json")
    if args.what == "sim":
        from experiments.bench_sim import run

        load_scenario(args.scenario or "corridor")  # validate before anything heavy
        run(args.scenario or "corridor", seconds=args.seconds, frames=args.frames, json_out=args.json)
        return 0
    if args.what == "perception":
        from dodt.presets import PRESETS
        from experiments import bench_perception

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
        bench_perception.run(Path(args.out), list(range(args.seeds or 1)), scenarios, configs, duration, rates=rates)
        return 0
    if args.what == "planner":
        from experiments import bench_planner
        from experiments.bench_map import bench_update
        from experiments.bench_mpc import bench_mpc

        bench_update()
        for seed in range(3):
            bench_mpc(seed=seed)
        out = bench_planner.run(args.scenario or "corridor", range(args.seeds or 2), perception=args.config)
        if args.json:
            args.json.write_text(json.dumps(out, indent=1) + "\n")
        return 0
    if args.what == "loop":
        from experiments.episode import EpisodeConfig, run_episode

        sc = load_scenario(args.scenario or "corridor")
        runs = []
        for _ in range(3):  # the same episode three times: the median real-time factor is quoted
            runs.append(run_episode(sc, seed=0, perception=args.config, cfg=EpisodeConfig(duration=args.seconds),
                                    renderer=args.renderer))
        rtf = [s["timing"]["real_time_factor"] for s in runs]
        s = sorted(runs, key=lambda r: r["timing"]["real_time_factor"])[1]
        tm = s["timing"]
        print(f"closed loop, {sc.name} seed 0, perception {args.config}, frame latency {s['frame_latency']}: "
              f"{s['sim_time']:.1f} s simulated; real-time factor median {tm['real_time_factor']}x of "
              f"{', '.join(f'{x}x' for x in rtf)} ({tm['renderer']} renderer)")
        for k in ("perception_ms", "map_update_ms", "planner_solve_ms"):
            print(f"  {k}: median {tm[k].get('median')} ms, p95 {tm[k].get('p95')} ms, p99 {tm[k].get('p99')} ms")
        return 0
    from experiments import bench_perception

    load_scenario(args.scenario or "corridor")
    bench_perception.run_runtime(args.config, args.scenario or "corridor", seconds=args.seconds if args.seconds else 6.0,
                                 json_out=args.json)
    return 0
