"""Looking at saved results: `replay` (an HTML replay of an episode log), `plot` (PNG figures of an episode
or a sweep) and `collisions` (one table row per collision)."""
from __future__ import annotations

from pathlib import Path

from experiments.commands.common import UserError, add_command, examples, seconds, writable_file


def add_parser(sub) -> None:
    rp = add_command(
        sub, "replay", help="build the self-contained HTML replay of a saved episode log",
        description="Build a self-contained HTML replay of a saved episode (OUT/log.jsonl.gz of `dodt-nav run`, or "
                    "the log a sweep keeps of a failed episode): the corridor, the drone with its executed and "
                    "planned trajectories, the people with their recent tracks, perception's boxes (dynamic ones "
                    "red, with velocity arrows), the depth points and the occupied voxels, animated in 3D with "
                    "meshcat's viewer inlined. The page opens offline in a browser; no simulator or server needed.",
        epilog=examples("dodt-nav replay runs/first/log.jsonl.gz",
                        "dodt-nav replay runs/sweep/episodes/seed_0007/log.jsonl.gz --out seed7.html"),
        func=cmd_replay)
    rp.add_argument("log", help="an episode's log.jsonl.gz")
    rp.add_argument("--out", default=None, help="HTML file (default: replay.html beside the log)")

    pl = add_command(
        sub, "plot", help="PNG figures of an episode (run folder or log) or a sweep (sweep folder)",
        description="Draw PNG figures of saved results. Given an episode (a `dodt-nav run` folder or its "
                    "log.jsonl.gz): topdown.png (the drone's path among the people and obstacles, collisions "
                    "marked), clearance.png, perception_error.png and runtime.png. Given a sweep (a `dodt-nav "
                    "sweep` folder or its results.jsonl): the outcome rates with 95 % Wilson intervals, times to "
                    "goal, closest approaches and outcomes per seed. The figures are drawn from the files alone.",
        epilog=examples("dodt-nav plot runs/first", "dodt-nav plot runs/sweep --out figures/"),
        func=cmd_plot)
    pl.add_argument("source", help="an episode folder / log.jsonl.gz, or a sweep folder / results.jsonl")
    pl.add_argument("--out", default=None, help="folder for the PNGs (default: beside the source)")

    co = add_command(
        sub, "collisions", help="one row per collision of saved episodes: who closed in, was the person in view, "
                                "tracked, reported moving",
        description="Print one table row per collision found in saved episode logs (single logs, run folders, or "
                    "sweep and benchmark folders, searched for logs): seed, time, what was hit, the fault class, "
                    "the drone's speed, the angle of its motion off the camera's heading (off_heading: over 43.5 it "
                    "flew where the camera did not look; empty at rest), who closed the gap (drone and person), the "
                    "person's lowest speed in the --window seconds before it (a walker that stood or turned), and "
                    "the fraction of camera frames in that window in which the person was in the camera's view, "
                    "tracked by perception, and reported moving. A person hit from outside the view was never "
                    "seen coming; one seen and reported moving points at the planner. With the default "
                    "planner's logs: the fraction of plans at which it knew the person (planner_knew), for how "
                    "long before the contact without a break (known_for), and why it last stopped remembering "
                    "someone where the person was (forgot: memory, young, merged, seen_free) and how long before "
                    "(forgot_s). Prints 'no collisions' when there are none.",
        epilog=examples("dodt-nav collisions runs/first",
                        "dodt-nav collisions runs/sweep runs/benchmark --window 3"),
        func=cmd_collisions)
    co.add_argument("source", nargs="+", help="episode logs, run folders or sweep folders")
    co.add_argument("--window", type=seconds, default=2.0, help="seconds before each collision looked at (default 2)")


def cmd_replay(args) -> int:
    from experiments.replay_html import build_replay_html

    out = Path(args.out) if args.out else Path(args.log).with_name("replay.html")
    writable_file(out, "--out")
    try:
        html = build_replay_html(Path(args.log), out)
    except ValueError as e:
        raise UserError(str(e)) from None
    print(f"wrote {html} ({html.stat().st_size / 1e6:.1f} MB; opens offline in a browser)")
    return 0


def cmd_collisions(args) -> int:
    from experiments.collision_report import collision_rows, format_table, logs_under
    from experiments.episode_log import read_log

    rows = []
    try:
        for path in args.source:
            for log in logs_under(Path(path)):
                rows += collision_rows(read_log(log), window=args.window)
    except ValueError as e:
        raise UserError(str(e)) from None
    print(format_table(rows) if rows else "no collisions")
    return 0


def cmd_plot(args) -> int:
    from experiments.episode_plots import plot_episode
    from experiments.sweep_plots import plot_sweep

    src = Path(args.source)
    out = Path(args.out or (src if src.is_dir() else src.parent))
    plot = plot_sweep if (src / "results.jsonl").exists() or src.name == "results.jsonl" else plot_episode
    try:
        files = plot(src, out)
    except ValueError as e:
        raise UserError(str(e)) from None
    print("wrote " + ", ".join(str(f) for f in files))
    return 0
