"""One episode or one sequence: `run` (a closed-loop flight), `simulate` (the sensor data of a flight, no
perception or planning) and `perceive` (DODT on a recorded RGB-D sequence; its options live in
experiments.perceive)."""
from __future__ import annotations

import sys
from pathlib import Path

from sim.scenario import RENDERER_CHOICES, load_scenario

from experiments.commands.common import (PERCEPTION_HELP, RENDERER_HELP, SCENARIO_HELP, LazyText, UserError,
                                         add_command, add_episode_options, builtin_names, check_perception,
                                         check_planner, describe, dodt_presets, episode_config, examples,
                                         output_folder, real, seconds, seed, settings, whole)
from experiments.config import ConfigError

RUN_EXAMPLES = examples(
    "dodt-nav run corridor --out runs/first --viz html",
    "dodt-nav run head_on --seed 3 --perception oracle --map truth --set shield.a_brake=3.0 --out runs/oracle",
    "dodt-nav run corridor --planner examples/custom_planner.py:StraightLine --out runs/mine",
)


def add_parser(sub) -> None:
    r = add_command(
        sub, "run", help="fly one closed-loop episode headless; write summary.json and the episode log",
        description="Fly one closed-loop episode of a scenario: the simulator renders the drone's RGB-D camera, "
                    "the perception module (DODT by default) turns the frames into tracked obstacles, the planner "
                    "flies around them, and every contact is checked and classed by fault. Prints the outcome, "
                    "time to goal, clearances and timings; writes OUT/summary.json and OUT/log.jsonl.gz, and on "
                    "request a replay (--viz html), a live meshcat view (--viz live) or PNG figures (--plots).",
        epilog=LazyText(lambda: RUN_EXAMPLES + "\n\n" + builtin_names()), func=cmd_run)
    r.add_argument("scenario", help=SCENARIO_HELP)
    r.add_argument("--seed", type=seed, default=None, help="seed (default: the scenario's)")
    r.add_argument("--perception", default="dodt", help=PERCEPTION_HELP)
    r.add_argument("--out", required=True, help="output folder")
    r.add_argument("--duration", type=seconds, default=None, help="time limit in seconds (default: the scenario's)")
    add_episode_options(r)
    r.add_argument("--viz", choices=("live", "html"), default=None,
                   help="live: stream to a meshcat server on 127.0.0.1; html: write OUT/replay.html")
    r.add_argument("--no-wait", action="store_true", help="live: close the viewer when the episode ends")
    r.add_argument("--plots", action="store_true", help="write PNG figures of the episode into OUT")

    s = add_command(
        sub, "simulate", help="fly a scenario headless; write depth/color PNGs, ground truth, summary",
        description="Fly a scenario headless along its reference path, without perception or planning, and write what "
                    "its camera sees: depth (uint16 millimetres) and color PNGs with the camera poses and "
                    "intrinsics, segmentation images, the ground truth of every obstacle, and a summary. The output "
                    "is a recorded sequence for `dodt-nav perceive` or for your own perception code; --format tum "
                    "writes a TUM RGB-D sequence instead.",
        epilog=examples("dodt-nav simulate corridor --out runs/sim --duration 5",
                        "dodt-nav simulate wall_pass --seed 1 --out runs/tum --format tum --save-every 2",
                        "dodt-nav perceive runs/sim --out runs/sim_tracks"),
        func=cmd_simulate)
    s.add_argument("scenario", help=SCENARIO_HELP)
    s.add_argument("--seed", type=seed, default=None, help="seed (default: the scenario's)")
    s.add_argument("--out", required=True, help="output folder")
    s.add_argument("--duration", type=seconds, default=None, help="seconds to simulate (default: the scenario's)")
    s.add_argument("--save-every", type=whole(1), default=1, help="write every k-th camera frame")
    s.add_argument("--renderer", choices=RENDERER_CHOICES, default=None, help=RENDERER_HELP)
    s.add_argument("--no-segmentation", action="store_true", help="skip the segmentation images (faster)")
    s.add_argument("--format", choices=("dodt", "tum"), default="dodt",
                   help="dodt (default: depth/, color/, sensor.json) or tum (a TUM RGB-D sequence: rgb/, depth/, "
                        "rgb.txt, depth.txt, groundtruth.txt, intrinsics.json), with the ground truth beside")
    s.add_argument("--lidar", action="store_true",
                   help="also a Mid-360-like LiDAR on top of the drone (the lidar rig's), scanned at 10 Hz: "
                        "lidar/NNNNNN.pcd (binary PCD, the sensor frame, the scan's pose as VIEWPOINT; PCL and Open3D "
                        "read it) and lidar.txt (stamp, pose from odometry and file of each scan)")


def add_perceive_parser(sub) -> None:
    """`perceive`: its options and handler are experiments.perceive's; its help text is given here."""
    from experiments.perceive import add_parser as add_perceive

    add_perceive(sub, real, whole, output_folder)
    describe(
        sub.choices["perceive"],
        "Run DODT alone, open loop, on a recorded RGB-D sequence: a TUM RGB-D folder (from a real camera), "
        "the output of `dodt-nav simulate`, or a folder of depth (and colour) images. Writes the tracked "
        "obstacles of every frame (OUT/tracks.jsonl), per-stage timings (timings.csv) and a summary; with "
        "ground truth beside the sequence (a simulate output), also position and velocity errors, false "
        "positives, recall and ID switches. Without camera poses, a fixed camera is placed by --fit-floor "
        "(which warns of a camera height that points to a wrong --depth-factor) or --camera-height and --pitch. "
        "The colour image must be registered (aligned) to the depth image: the same size, pixel (u, v) of "
        "both seeing the same point, as a RealSense's colour aligned to depth or TUM RGB-D's registered "
        "images; the person detector reads the depth under its colour boxes. Frames are timed by their "
        "own timestamps; a folder of frames without timestamps needs --rate.",
        LazyText(lambda: examples(
            "dodt-nav perceive runs/sim --out runs/sim_tracks --images",
            "dodt-nav perceive rgbd_dataset_freiburg3_walking_xyz --out runs/tum --fit-floor --video",
            "dodt-nav perceive runs/sim --out runs/no_coast --config dodt-no-coast --set kalman.q_pos=0.02",
        ) + "\n\n" + dodt_presets()))


def cmd_simulate(args) -> int:
    from experiments.simulate import simulate

    load_scenario(args.scenario)  # refused before the output folder is made
    output_folder(args.out)
    s = simulate(args.scenario, args.seed, Path(args.out), duration=args.duration, save_every=args.save_every,
                 renderer=args.renderer, segmentation=not args.no_segmentation, fmt=args.format, lidar=args.lidar)
    print(f"{s['scenario']} seed {s['seed']}: {s['sim_time']:.2f} s simulated in {s['wall_time_s']:.1f} s "
          f"({s['renderer']} renderer), {s['frames_saved']} frames"
          + (f" and {s['lidar_scans_saved']} LiDAR scans (lidar/*.pcd, lidar.txt)" if args.lidar else "")
          + f" written to {args.out}")
    print(f"collisions: {s['collision_count']}, min clearance [m]: " +
          ", ".join(f"{k} {v:.2f}" for k, v in s["min_clearance"].items()) +
          f", final position {s['final_position']}")
    return 0


def cmd_run(args) -> int:
    from experiments.episode import run_episode

    sc = load_scenario(args.scenario)
    check_perception(args.perception)
    planner = check_planner(args.planner)
    config = settings(args)
    cfg = episode_config(args, config)
    out = output_folder(args.out)
    viewer = None
    if args.viz == "live":
        from experiments.live_viewer import LiveViewer

        viewer = LiveViewer(corridor=sc.corridor, goal=sc.drone.goal)
    try:
        try:
            s = run_episode(sc, seed=args.seed, perception=args.perception, planner=planner, out=out, cfg=cfg,
                            on_frame=viewer, settings=config, shield=args.shield)
        except ConfigError as e:  # a value that fits no map of this scenario (map.size, map.resolution)
            raise UserError(str(e)) from None
        if viewer is not None and not args.no_wait and sys.stdin.isatty():
            input("episode finished; press Enter to stop the meshcat viewer ")
    finally:
        if viewer is not None:
            viewer.close()
    outcome = "success" if s["success"] else f"failure ({s['failure_reason']})"
    ttg = f"{s['time_to_goal']:.2f} s" if s["time_to_goal"] is not None else "-"
    mc = s["min_clearance"]
    tm = s["timing"]
    planner_note = f" planner {s['planner']}" if planner else ""
    print(f"{s['scenario']} seed {s['seed']} perception {s['perception']}{planner_note}: {outcome}; time to goal {ttg}, "
          f"path {s['path_length']:.2f} m, mean speed {s['mean_speed']:.2f} m/s, collisions {s['collision_count']}")
    print("min clearance [m]: " + ", ".join(f"{k} {v:.2f}" for k, v in mc.items() if v is not None))
    print(f"planner solve median {tm['planner_solve_ms'].get('median', '-')} ms, p99 {tm['planner_solve_ms'].get('p99', '-')} ms, "
          f"fallbacks {s['planner_stats']['fallbacks']}; perception median {tm['perception_ms'].get('median', '-')} ms; "
          f"{s['sim_time']:.1f} s simulated in {tm['loop_s']:.1f} s ({tm['real_time_factor']}x real time; "
          f"start-up {tm['startup_s']:.1f} s and numba compilation {tm['compile_s']:.1f} s apart)")
    print(f"wrote {args.out}/summary.json and {args.out}/log.jsonl.gz")
    for module, e in (s.get("module_errors") or {}).items():
        print(f"error: the {module} failed {e['count']} times (first at t = {e['first_time']:.2f} s); the first "
              f"traceback is in {args.out}/errors.txt", file=sys.stderr)
    if args.viz == "html":
        from experiments.replay_html import build_replay_html

        html = build_replay_html(out / "log.jsonl.gz", out / "replay.html")
        print(f"wrote {html} ({html.stat().st_size / 1e6:.1f} MB; opens offline in a browser)")
    if args.plots:
        from experiments.episode_plots import plot_episode

        files = plot_episode(out / "log.jsonl.gz", out)
        print("wrote " + ", ".join(str(f) for f in files))
    return 1 if s.get("module_errors") else 0
