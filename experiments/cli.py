"""`dodt-nav`: the project's command line.

User mistakes (a bad scenario, a missing file, a bad option) print one line naming what is
wrong and exit with status 2, never a traceback.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sim.scenario import ScenarioError, load_scenario, shipped_scenarios


class UserError(Exception):
    """A mistake of the user's: reported in one line, exit status 2."""


def _cmd_simulate(args) -> int:
    from experiments.simulate import simulate

    if args.save_every < 1:
        raise UserError("--save-every: must be >= 1")
    if args.duration is not None and args.duration <= 0:
        raise UserError("--duration: must be > 0")
    s = simulate(args.scenario, args.seed, Path(args.out), duration=args.duration, save_every=args.save_every,
                 renderer=args.renderer, segmentation=not args.no_segmentation)
    print(f"{s['scenario']} seed {s['seed']}: {s['sim_time']:.2f} s simulated in {s['wall_time_s']:.1f} s "
          f"({s['renderer']} renderer), {s['frames_saved']} frames written to {args.out}")
    print(f"collisions: {s['collision_count']}, min clearance [m]: " +
          ", ".join(f"{k} {v:.2f}" for k, v in s["min_clearance"].items()) +
          f", final position {s['final_position']}")
    return 0


def _cmd_bench(args) -> int:
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
        if args.seeds < 1:
            raise UserError("--seeds: must be >= 1")
        duration = args.duration if args.duration else (6.0 if args.quick else None)
        bench_perception.run(Path(args.out), list(range(args.seeds)), scenarios, configs, duration)
        return 0
    from experiments import bench_perception

    load_scenario(args.scenario or "corridor")
    bench_perception.run_runtime(args.config, args.scenario or "corridor", seconds=args.seconds if args.seconds else 6.0,
                                 json_out=args.json)
    return 0


def _cmd_scenarios(args) -> int:
    for name in shipped_scenarios():
        sc = load_scenario(name)
        print(f"{name:<22}{sc.description}")
    return 0


def _cmd_validate(args) -> int:
    for f in args.files:
        sc = load_scenario(f)
        print(f"{f}: ok ({len(sc.obstacles)} obstacles, {len(sc.people)} people, {sc.duration:g} s)")
    return 0


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="dodt-nav", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="command", required=True)

    s = sub.add_parser("simulate", help="fly a scenario headless; write depth/color PNGs, ground truth, summary")
    s.add_argument("scenario", help="a scenario file, or the name of a shipped one (see `dodt-nav scenarios`)")
    s.add_argument("--seed", type=int, default=None, help="seed (default: the scenario's)")
    s.add_argument("--out", required=True, help="output folder")
    s.add_argument("--duration", type=float, default=None, help="seconds to simulate (default: the scenario's)")
    s.add_argument("--save-every", type=int, default=1, help="write every k-th camera frame")
    s.add_argument("--renderer", choices=("auto", "egl", "tiny"), default=None)
    s.add_argument("--no-segmentation", action="store_true", help="skip the segmentation images (faster)")
    s.set_defaults(func=_cmd_simulate)

    b = sub.add_parser("bench", help="benchmarks that print figures")
    b.add_argument("what", choices=("sim", "perception", "runtime"),
                   help="sim: render/physics/real-time; perception: Table I; runtime: Table II")
    b.add_argument("--scenario", default=None, help="sim, runtime: the scenario (default corridor)")
    b.add_argument("--seconds", type=float, default=10.0, help="simulated seconds (sim: real-time figure; runtime: frames)")
    b.add_argument("--out", default="runs/bench_perception", help="perception: output folder")
    b.add_argument("--seeds", type=int, default=1, help="perception: seeds 0..N-1 per scenario")
    b.add_argument("--scenarios", default=None, help="perception: comma-separated scenarios")
    b.add_argument("--configs", default=None, help="perception: comma-separated configurations")
    b.add_argument("--duration", type=float, default=None, help="perception: seconds per scenario")
    b.add_argument("--quick", action="store_true", help="perception: 6 s per scenario")
    b.add_argument("--config", default="dodt", help="runtime: the configuration")
    b.add_argument("--frames", type=int, default=30, help="frames for the render medians")
    b.add_argument("--json", type=Path, default=None, help="also write the figures as JSON")
    b.set_defaults(func=_cmd_bench)

    sc = sub.add_parser("scenarios", help="list the shipped scenarios")
    sc.set_defaults(func=_cmd_scenarios)

    v = sub.add_parser("validate", help="check scenario files and report the first problem of each")
    v.add_argument("files", nargs="+")
    v.set_defaults(func=_cmd_validate)
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (ScenarioError, UserError) as e:
        print(f"dodt-nav: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        print(f"dodt-nav: error: {e.filename or ''}: {e.strerror}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("dodt-nav: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())


__all__ = ["main", "build_parser"]
