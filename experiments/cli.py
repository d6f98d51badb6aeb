"""`dodt-nav`: the project's command line.

User mistakes (a bad scenario, a missing file, a bad option) print one line naming what is
wrong and exit with status 2, never a traceback. Options are checked when they are parsed, and
files a command will write are checked before it starts its work.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import threading
from pathlib import Path

from dodt.config import LearnedConfig
from dodt.learned.model import ModelError
from experiments.sequences import SequenceError
from sim.scenario import RENDERER_CHOICES, ScenarioError, load_scenario, shipped_scenarios


class UserError(Exception):
    """A mistake of the user's: reported in one line, exit status 2."""


# --------------------------------------------------------------------------- option checks
#
# Every numeric option is parsed by one of these: a value out of its bounds (NaN, infinities,
# negative counts, ...) is refused by argparse as "argument --name: reason", before any work.

SEED_MAX = 2**63 - 1  # seeds are whole numbers from 0 to what a scenario file's TOML integer holds
MAX_SECONDS = 3600.0  # s, a time limit: the longest a scenario may last (sim.scenario.MAX_DURATION)
MAX_JOBS = 256  # parallel episodes
MAX_FRAME_LATENCY = 100  # camera periods: each delayed frame is held in memory until it is delivered


def _whole(lo: int, hi: int | None = None, what: str = "a whole number"):
    """A whole number in [lo, hi]; ``what`` names it in the messages."""
    bounds = f">= {lo}" + (f" and <= {hi}" if hi is not None else "")

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {what} {bounds}, got {text!r}") from None
        if v < lo or (hi is not None and v > hi):
            raise argparse.ArgumentTypeError(f"must be {bounds}, got {v}" if what == "a whole number"
                                             else f"must be {what} {bounds}, got {v}")
        return v
    return parse


def _real(lo: float, hi: float, lo_open: bool = False, hi_open: bool = False, what: str = ""):
    """A finite number in [lo, hi] (open ends as given); ``what`` replaces the bounds in the message."""
    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not math.isfinite(v) or (v <= lo if lo_open else v < lo) or (v >= hi if hi_open else v > hi):
            bounds = what or (f"must be a number {'>' if lo_open else '>='} {lo:g} and {'<' if hi_open else '<='} "
                              f"{hi:g}")
            raise argparse.ArgumentTypeError(f"{bounds}, got {text!r}")
        return v
    return parse


_seed = _whole(0, SEED_MAX, "a seed, a whole number")
_seconds = _real(0.0, MAX_SECONDS, lo_open=True, what=f"must be a number of seconds > 0 and <= {MAX_SECONDS:g}")
_jobs = _whole(1, MAX_JOBS)
_fraction = _real(0.0, 1.0, what="must be a fraction between 0 and 1")
_frame_latency = _whole(0, MAX_FRAME_LATENCY, "a whole number of camera periods")


def _writable_file(path: str, option: str) -> None:
    """Refuse now a file the command writes at its end (a sweep's JUnit XML): found unwritable after the
    work, the work would be lost. The file is created and removed when it did not exist."""
    p = Path(path)
    if p.is_dir():
        raise UserError(f"{option}: {path} is a folder, not a file")
    existed = p.exists()
    try:
        with open(p, "a"):
            pass
    except OSError as e:
        raise UserError(f"{option}: cannot write {path}: {e.strerror or e}") from None
    if not existed:
        p.unlink()


def _output_folder(path: str, option: str = "--out") -> Path:
    """The output folder, created now (a file in the way or no permission: refused before the work)."""
    p = Path(path)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise UserError(f"{option}: cannot create the folder {path}: {e.strerror or e}") from None
    if not os.access(p, os.W_OK | os.X_OK):
        raise UserError(f"{option}: cannot write into the folder {path}")
    return p


def _cmd_simulate(args) -> int:
    from experiments.simulate import simulate

    load_scenario(args.scenario)  # refused before the output folder is made
    _output_folder(args.out)
    s = simulate(args.scenario, args.seed, Path(args.out), duration=args.duration, save_every=args.save_every,
                 renderer=args.renderer, segmentation=not args.no_segmentation, fmt=args.format)
    print(f"{s['scenario']} seed {s['seed']}: {s['sim_time']:.2f} s simulated in {s['wall_time_s']:.1f} s "
          f"({s['renderer']} renderer), {s['frames_saved']} frames written to {args.out}")
    print(f"collisions: {s['collision_count']}, min clearance [m]: " +
          ", ".join(f"{k} {v:.2f}" for k, v in s["min_clearance"].items()) +
          f", final position {s['final_position']}")
    return 0


def _cmd_bench(args) -> int:
    if args.json is not None:
        _writable_file(args.json, "--json")
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
        _output_folder(args.out)
        duration = args.duration if args.duration else (6.0 if args.quick else None)
        rates = _parse_rates(args.rates) if args.rates else None
        bench_perception.run(Path(args.out), list(range(args.seeds)), scenarios, configs, duration, rates=rates)
        return 0
    if args.what == "planner":
        from planner.mpc import bench_mpc
        from planner.voxel_map import bench_update

        bench_update()
        for seed in range(3):
            bench_mpc(seed=seed)
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


def _parse_rates(text: str) -> list[float]:
    """--rates: a comma list of frame rates in Hz, each above 0 and at most the camera's 30 Hz."""
    try:
        rates = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise UserError(f"--rates: expected a comma list of frame rates in Hz, got {text!r}") from None
    bad = [r for r in rates if not 0 < r <= 30]
    if not rates or bad:
        raise UserError(f"--rates: each rate must be above 0 and at most the camera's 30 Hz, got {text!r}")
    return rates


def _check_perception(mode: str) -> None:
    """A built-in mode or a plug-in's module:Class that loads and implements the protocol."""
    from experiments.plugins import PluginError, check_perception

    try:
        check_perception(mode)
    except PluginError as e:
        raise UserError(f"--perception: {e}") from None


def _check_planner(spec: str) -> str | None:
    """The --planner spec for the episodes: None for the built-in default."""
    from experiments.plugins import DEFAULT_PLANNER, PluginError, check_planner

    try:
        check_planner(spec)
    except PluginError as e:
        raise UserError(f"--planner: {e}") from None
    return None if spec == DEFAULT_PLANNER else spec


def _settings(args):
    """The overrides of --config and --set (experiments.config), checked now."""
    from experiments.config import ConfigError, build

    try:
        return build(args.config, args.set or ())
    except ConfigError as e:
        raise UserError(str(e)) from None


# episode options and the episode.* keys they stand for: giving both is refused (which one would win?)
_EPISODE_OPTIONS = {"static_map": "--map", "frame_latency": "--frame-latency", "renderer": "--renderer",
                    "duration": "--duration"}


def _episode_config(args, settings, **given):
    """The episodes' EpisodeConfig: the episode options (and ``given``, values a command decided), then the
    settings' episode section; an option given on the command line and also set as a key is refused."""
    from experiments.episode import EpisodeConfig

    keys = {k for k, _ in settings.episode}
    values = {}
    for field, option in _EPISODE_OPTIONS.items():
        v = given.get(field, getattr(args, option[2:].replace("-", "_"), None))
        if v is None:
            continue
        if field in keys:
            raise UserError(f"{option} and episode.{field} (--config/--set) both given; use one")
        values[field] = v
    return settings.episode_config(EpisodeConfig(**values))


def _cmd_run(args) -> int:
    from experiments.episode import run_episode

    sc = load_scenario(args.scenario)
    _check_perception(args.perception)
    planner = _check_planner(args.planner)
    settings = _settings(args)
    cfg = _episode_config(args, settings)
    out = _output_folder(args.out)
    viewer = None
    if args.viz == "live":
        from experiments.viz import LiveViewer

        viewer = LiveViewer(corridor=sc.corridor, goal=sc.drone.goal)
    try:
        s = run_episode(sc, seed=args.seed, perception=args.perception, planner=planner, out=out, cfg=cfg,
                        on_frame=viewer, settings=settings)
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
          f"{s['sim_time']:.1f} s simulated in {tm['wall_s']:.1f} s ({tm['real_time_factor']}x real time)")
    print(f"wrote {args.out}/summary.json and {args.out}/log.jsonl.gz")
    if args.viz == "html":
        from experiments.viz import build_replay_html

        html = build_replay_html(out / "log.jsonl.gz", out / "replay.html")
        print(f"wrote {html} ({html.stat().st_size / 1e6:.1f} MB; opens offline in a browser)")
    if args.plots:
        from experiments.plots import plot_episode

        files = plot_episode(out / "log.jsonl.gz", out)
        print("wrote " + ", ".join(str(f) for f in files))
    return 0


def _cmd_replay(args) -> int:
    from experiments.viz import build_replay_html

    out = Path(args.out) if args.out else Path(args.log).with_name("replay.html")
    _writable_file(out, "--out")
    try:
        html = build_replay_html(Path(args.log), out)
    except ValueError as e:
        raise UserError(str(e)) from None
    print(f"wrote {html} ({html.stat().st_size / 1e6:.1f} MB; opens offline in a browser)")
    return 0


def _cmd_collisions(args) -> int:
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


def _cmd_plot(args) -> int:
    from experiments.plots import plot_episode, plot_sweep

    src = Path(args.source)
    out = Path(args.out or (src if src.is_dir() else src.parent))
    plot = plot_sweep if (src / "results.jsonl").exists() or src.name == "results.jsonl" else plot_episode
    try:
        files = plot(src, out)
    except ValueError as e:
        raise UserError(str(e)) from None
    print("wrote " + ", ".join(str(f) for f in files))
    return 0


def _cmd_sweep(args) -> int:
    from experiments import sweep

    load_scenario(args.scenario)  # validate before starting workers
    _check_perception(args.perception)
    planner = _check_planner(args.planner)
    settings = _settings(args)
    cfg = _episode_config(args, settings)
    if args.junit:
        _writable_file(args.junit, "--junit")
    try:
        seeds = sweep.parse_seeds(args.seeds)
        agg = sweep.run_sweep(args.scenario, seeds, args.perception, Path(args.out), jobs=args.jobs,
                              dask_address=args.dask, keep_logs=args.keep_logs, progress=not args.quiet, cfg=cfg,
                              settings=settings, planner=planner)
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
        Path(args.junit).write_text(sweep.junit(agg, by_seed))
        print(f"wrote {args.junit}")
    status = 0
    for key, limit in (("collision", args.max_collision_rate), ("at_fault", args.max_at_fault_rate)):
        if limit is not None and r[key]["rate"] > limit:
            what = "at-fault collision" if key == "at_fault" else "collision"
            print(f"{what} rate {r[key]['rate']:.4f} exceeds --max-{key.replace('_', '-')}-rate {limit}",
                  file=sys.stderr)
            status = 1
    return status


def _cmd_benchmark(args) -> int:
    from experiments import benchmark
    from experiments.sweep import SweepError

    def names(text, known, option):
        out = [x.strip() for x in text.split(",") if x.strip()]
        bad = [repr(x) for x in out if known is not None and x not in known]
        if not out or bad:
            raise UserError(f"--{option}: {bad[0] if bad else repr(text)} is not one of {', '.join(known)}"
                            if known else f"--{option}: {text!r} names nothing")
        return tuple(out)

    families = names(args.families, None, "families") if args.families else benchmark.FAMILIES
    for f in families:
        try:
            load_scenario(f)  # validate before starting workers
        except ScenarioError as e:
            raise UserError(f"--families: {e}") from None
    modes = names(args.perception, None, "perception") if args.perception else benchmark.MODES
    for m in modes:
        _check_perception(m)
    people = names(args.people, tuple(benchmark.PEOPLE), "people")
    planner = _check_planner(args.planner)
    settings = _settings(args)
    count, given = args.seeds, {}
    if args.quick:  # a smoke-sized run: two families, the oracle on the known map (unless given), two seeds
        families = families if args.families else ("corridor", "head_on")
        modes = modes if args.perception else ("oracle",)
        count = min(count, 2)
        if args.map is None and "static_map" not in dict(settings.episode):
            given["static_map"] = "truth"
    cfg = _episode_config(args, settings, **given)
    try:
        report = benchmark.run_benchmark(Path(args.out), args.split, count, families, modes, people, jobs=args.jobs,
                                         dask_address=args.dask, cfg=cfg, progress=not args.quiet,
                                         settings=settings, planner=planner)
    except SweepError as e:
        raise UserError(str(e)) from None
    print(benchmark.markdown(report))
    print(f"wrote {args.out}/report.md, {args.out}/report.json and {args.out}/plots/")
    return 0


def _cmd_compare(args) -> int:
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


def _cmd_reproduce(args) -> int:
    from experiments.reproduce import reproduce

    planner = _check_planner(args.planner)
    settings = _settings(args)
    _output_folder(args.out)
    reproduce(Path(args.out), quick=args.quick, jobs=args.jobs, settings=settings, planner=planner)
    return 0


def _detector_data(args, splits: tuple[str, ...] = ("train", "val")) -> Path:
    """The dataset folder, its ``splits`` generated where missing (seeds never shared)."""
    import numpy as np

    from experiments.detector import dataset
    from experiments.sweep import SweepError, parse_seeds

    try:
        train_seeds, val_seeds = parse_seeds(args.train_seeds), parse_seeds(args.val_seeds)
        dataset.check_disjoint(train_seeds, val_seeds)
    except (SweepError, ValueError) as e:
        raise UserError(str(e).replace("--seeds", "--train-seeds/--val-seeds")) from None
    data = Path(args.data)
    for split, seeds in (("train", train_seeds), ("val", val_seeds)):
        if split not in splits:
            continue
        if (data / f"{split}.npz").is_file():
            with np.load(data / f"{split}.npz") as z:
                meta = json.loads(str(z["meta"])) if "meta" in z else {}
            if meta.get("seeds") != list(seeds) or meta.get("images_per_seed") != args.images_per_seed:
                raise UserError(f"{data / (split + '.npz')} was rendered from other seeds or images per seed than "
                                f"asked; use another --data folder or the same options")
        else:
            print(f"rendering the {split} split: {len(seeds)} seeds x {args.images_per_seed} images into {data}",
                  flush=True)
            dataset.generate(data, split, seeds, args.images_per_seed)
    return data


def _cmd_train_detector(args) -> int:
    try:
        import torch  # noqa: F401  (training only; run time uses onnxruntime)
    except ImportError:
        raise UserError("training needs PyTorch: pip install torch==2.13.0 onnx (or pip install -e '.[train]')") from None
    from experiments.detector.train import option_flags, train

    data = _detector_data(args)
    command = (f"dodt-nav train-detector --data {args.data} --train-seeds {args.train_seeds} --val-seeds "
               f"{args.val_seeds} --images-per-seed {args.images_per_seed} --epochs {args.epochs} --seed {args.seed} "
               f"--threads {args.threads}")
    command += option_flags(args.device, args.arch, args.batch_size, args.lr, args.warmup_epochs)
    try:
        record = train(data, Path(args.out), epochs=args.epochs, seed=args.seed, threads=args.threads,
                       command=command, device=args.device, arch=args.arch, batch_size=args.batch_size,
                       lr=args.lr, eval_every=args.eval_every, warmup_epochs=args.warmup_epochs)
    except ValueError as e:
        raise UserError(str(e)) from None
    print(f"wrote {args.out}/person_detector.onnx and person_detector.json; validation: "
          + json.dumps(record.get("validation", {}))[:400])
    return 0


def _cmd_pack_detector_data(args) -> int:
    from experiments.detector.packed import pack

    missing = [f for f in args.files if not Path(f).is_file()]
    if missing:
        raise UserError(f"{missing[0]}: no such dataset file")
    try:
        out = pack(args.files, args.out, quality=args.quality)
    except ValueError as e:
        raise UserError(str(e)) from None
    print(f"wrote {out} ({out.stat().st_size / 2**20:.1f} MiB)")
    return 0


def _cmd_eval_detector(args) -> int:
    from dodt.learned.model import SHIPPED_MODEL, load_record
    from dodt.learned.views import parse_views
    from experiments.detector.evaluate import average_precision

    model = Path(args.model) if args.model else SHIPPED_MODEL
    load_record(model)  # a missing or corrupt model stops here with its name
    try:
        views = parse_views(args.views)
    except ValueError as e:
        raise UserError(f"--views: {e}") from None
    data = _detector_data(args, splits=("val",))  # evaluation needs no training images
    r = average_precision(model, data / "val.npz", max_distance=args.max_distance, nms_iou=args.nms_iou,
                          min_visible_px=args.min_visible_px, views=views, soft_sigma=args.soft_nms,
                          score_threshold=args.score_floor)
    keys = ", ".join(f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}" for k, v in r.items()
                     if not isinstance(v, dict))
    print(f"{model.name} on {data / 'val.npz'}: {keys}")
    for k, v in r.items():
        if isinstance(v, dict):
            print(f"  {k}: " + ", ".join(f"{b} {x:.3f}" if isinstance(x, float) else f"{b} {x}" for b, x in v.items()))
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


PERCEPTION_HELP = ("dodt (default), oracle, oracle-360, oracle-noisy, static-only, a DODT preset, or your own "
                   "perception class: module:Class with module a dotted module or a .py file; built with no arguments")
RENDERER_HELP = ("the camera's renderer: gl (ours, OpenGL), pybullet (PyBullet's EGL plugin; egl is its older "
                 "name), tiny (PyBullet's TinyRenderer), auto (the first that works, in that order); default: the "
                 "scenario's")


def _add_episode_options(parser: argparse.ArgumentParser) -> None:
    """--map, --frame-latency and --renderer for run, sweep and benchmark nav (experiments.episode.STATIC_MAPS and
    EpisodeConfig; not imported here: it loads the simulator), with --planner, --config and --set. Their
    defaults are None: an option given is told apart from one left out (_episode_config)."""
    parser.add_argument("--renderer", choices=RENDERER_CHOICES, default=None, help=RENDERER_HELP)
    parser.add_argument("--map", choices=("depth", "truth"), default=None,
                        help="static map: depth (built from the camera, default) or truth (the scenario's geometry "
                             "known from the start; with the oracles or static-only nothing is rendered: a "
                             "fast planner test)")
    parser.add_argument("--frame-latency", type=_frame_latency, default=None, metavar="N",
                        help="camera periods between a frame's capture and its perception (default 1: the next "
                             "frame renders in a second process meanwhile; 0: at once, as before)")
    _add_config_options(parser)


def _add_config_options(parser: argparse.ArgumentParser, perception: bool = False) -> None:
    """--planner, --config and --set (experiments.plugins, experiments.config)."""
    if perception:
        parser.add_argument("--perception", default="dodt", help=PERCEPTION_HELP)
    parser.add_argument("--planner", default="default", metavar="NAME|module:Class",
                        help="default (the MPC planner behind the passive-safety shield) or your own planner class: "
                             "module:Class with module a dotted module or a .py file; built with no arguments")
    parser.add_argument("--config", default=None, metavar="FILE.toml",
                        help="configuration overrides: TOML tables episode, shield, navigator (navigator.mpc, "
                             "navigator.maneuvers), map, dodt (experiments.config)")
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                        help="one override, the value a TOML literal (e.g. shield.a_brake=3.0, "
                             "navigator.mpc.horizon=30); repeatable, applied after --config")


class _Parser(argparse.ArgumentParser):
    """argparse with its refusals on one line (its own print the usage first), exit status 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    ap = _Parser(prog="dodt-nav", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="command", required=True)

    s = sub.add_parser("simulate", help="fly a scenario headless; write depth/color PNGs, ground truth, summary")
    s.add_argument("scenario", help="a scenario file, or the name of a shipped one (see `dodt-nav scenarios`)")
    s.add_argument("--seed", type=_seed, default=None, help="seed (default: the scenario's)")
    s.add_argument("--out", required=True, help="output folder")
    s.add_argument("--duration", type=_seconds, default=None, help="seconds to simulate (default: the scenario's)")
    s.add_argument("--save-every", type=_whole(1), default=1, help="write every k-th camera frame")
    s.add_argument("--renderer", choices=RENDERER_CHOICES, default=None, help=RENDERER_HELP)
    s.add_argument("--no-segmentation", action="store_true", help="skip the segmentation images (faster)")
    s.add_argument("--format", choices=("dodt", "tum"), default="dodt",
                   help="dodt (default: depth/, color/, sensor.json) or tum (a TUM RGB-D sequence: rgb/, depth/, "
                        "rgb.txt, depth.txt, groundtruth.txt, intrinsics.json), with the ground truth beside")
    s.set_defaults(func=_cmd_simulate)

    b = sub.add_parser("bench", help="benchmarks that print figures")
    b.add_argument("what", choices=("sim", "perception", "runtime", "planner", "loop"),
                   help="sim: render/physics/real-time; perception: Table I; runtime: Table II; planner: voxel map "
                        "update and MPC solve times; loop: real-time factor of a closed-loop episode")
    b.add_argument("--scenario", default=None, help="sim, runtime: the scenario (default corridor)")
    b.add_argument("--seconds", type=_seconds, default=10.0, help="simulated seconds (sim: real-time figure; runtime: frames)")
    b.add_argument("--out", default="runs/bench_perception", help="perception: output folder")
    b.add_argument("--seeds", type=_whole(1, 10_000), default=1, help="perception: seeds 0..N-1 per scenario")
    b.add_argument("--scenarios", default=None, help="perception: comma-separated scenarios")
    b.add_argument("--configs", default=None, help="perception: comma-separated configurations")
    b.add_argument("--duration", type=_seconds, default=None, help="perception: seconds per scenario")
    b.add_argument("--quick", action="store_true", help="perception: 6 s per scenario")
    b.add_argument("--rates", default=None, metavar="HZ,...",
                   help="perception: also score each configuration on the frames decimated to these rates "
                        "(e.g. 30,15,10,5), rows named config@RATEHz")
    b.add_argument("--config", default="dodt", help="runtime: the configuration; loop: the perception mode")
    b.add_argument("--frames", type=_whole(1, 100_000), default=30, help="frames for the render medians")
    b.add_argument("--json", type=Path, default=None, help="also write the figures as JSON")
    b.add_argument("--renderer", choices=RENDERER_CHOICES, default=None, help="loop: " + RENDERER_HELP)
    b.set_defaults(func=_cmd_bench)

    r = sub.add_parser("run", help="fly one closed-loop episode headless; write summary.json and the episode log")
    r.add_argument("scenario", help="a scenario file, or the name of a shipped one (see `dodt-nav scenarios`)")
    r.add_argument("--seed", type=_seed, default=None, help="seed (default: the scenario's)")
    r.add_argument("--perception", default="dodt", help=PERCEPTION_HELP)
    r.add_argument("--out", required=True, help="output folder")
    r.add_argument("--duration", type=_seconds, default=None, help="time limit in seconds (default: the scenario's)")
    _add_episode_options(r)
    r.add_argument("--viz", choices=("live", "html"), default=None,
                   help="live: stream to a meshcat server on 127.0.0.1; html: write OUT/replay.html")
    r.add_argument("--no-wait", action="store_true", help="live: close the viewer when the episode ends")
    r.add_argument("--plots", action="store_true", help="write PNG figures of the episode into OUT")
    r.set_defaults(func=_cmd_run)

    rp = sub.add_parser("replay", help="build the self-contained HTML replay of a saved episode log")
    rp.add_argument("log", help="an episode's log.jsonl.gz")
    rp.add_argument("--out", default=None, help="HTML file (default: replay.html beside the log)")
    rp.set_defaults(func=_cmd_replay)

    co = sub.add_parser("collisions", help="one row per collision of saved episodes: who closed in, was the person "
                                           "in view, tracked, reported moving")
    co.add_argument("source", nargs="+", help="episode logs, run folders or sweep folders")
    co.add_argument("--window", type=_seconds, default=2.0, help="seconds before each collision looked at (default 2)")
    co.set_defaults(func=_cmd_collisions)

    pl = sub.add_parser("plot", help="PNG figures of an episode (run folder or log) or a sweep (sweep folder)")
    pl.add_argument("source", help="an episode folder / log.jsonl.gz, or a sweep folder / results.jsonl")
    pl.add_argument("--out", default=None, help="folder for the PNGs (default: beside the source)")
    pl.set_defaults(func=_cmd_plot)

    w = sub.add_parser("sweep", help="run many seeds in parallel; resumable; rates with Wilson intervals; CI gate")
    w.add_argument("scenario", help="a scenario file, or the name of a shipped one")
    w.add_argument("--seeds", default="0:20", help="start:stop, a number, or a comma list (default 0:20)")
    w.add_argument("--perception", default="dodt", help=PERCEPTION_HELP)
    w.add_argument("--jobs", type=_jobs, default=max(1, os.cpu_count() or 1), help="parallel episodes (default: CPUs)")
    w.add_argument("--out", required=True, help="output folder (rerun with the same folder to resume)")
    w.add_argument("--max-collision-rate", type=_fraction, default=None,
                   help="exit with status 1 when the rate of episodes with any collision exceeds this fraction")
    w.add_argument("--max-at-fault-rate", type=_fraction, default=None,
                   help="exit with status 1 when the rate of episodes with an at-fault collision exceeds this fraction")
    w.add_argument("--junit", default=None, help="write JUnit XML, one test case per seed")
    w.add_argument("--dask", default=None, metavar="ADDRESS", help="run on a Dask distributed scheduler")
    w.add_argument("--keep-logs", action="store_true", help="keep the episode logs of successful episodes too")
    w.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_episode_options(w)
    w.set_defaults(func=_cmd_sweep)

    bm = sub.add_parser("benchmark", help="the navigation benchmark: scenario families x perception modes x people "
                                          "who do or do not see the drone, on a named seed split; report.md")
    bm.add_argument("what", choices=("nav",), help="nav: the closed-loop navigation benchmark")
    bm.add_argument("--split", choices=("dev", "test"), default="dev",
                    help="dev: seeds 0-999, for tuning and choosing; test: seeds 1000-1999, for reported figures")
    bm.add_argument("--seeds", type=_whole(1, 1000), default=100, help="seeds per cell, the first of the split (default 100)")
    bm.add_argument("--families", default=None, help="comma list (default: all shipped families)")
    bm.add_argument("--perception", default=None, help="comma list of modes or module:Class plug-ins "
                                                        "(default: dodt,oracle,static-only)")
    bm.add_argument("--people", default="blind,aware",
                    help="blind (people do not see the drone), aware (they do), or both (default)")
    bm.add_argument("--jobs", type=_jobs, default=max(1, os.cpu_count() or 1), help="parallel episodes (default: CPUs)")
    bm.add_argument("--dask", default=None, metavar="ADDRESS", help="run on a Dask distributed scheduler")
    bm.add_argument("--out", required=True, help="output folder (rerun with the same folder to resume)")
    bm.add_argument("--quick", action="store_true",
                    help="smoke-sized: 2 seeds, corridor and head_on, oracle on the known map (unless given)")
    bm.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_episode_options(bm)
    bm.set_defaults(func=_cmd_benchmark)

    cp = sub.add_parser("compare", help="pair two sweeps seed by seed: seeds turned each way, exact sign test; "
                                        "CI gate on a significant regression")
    cp.add_argument("base", help="the baseline's sweep folder (or its results.jsonl)")
    cp.add_argument("new", help="the change's sweep folder (or its results.jsonl)")
    cp.add_argument("--fail-if-worse", type=_real(0.0, 1.0, lo_open=True, what="must be a significance level in (0, 1]"),
                    default=None, metavar="ALPHA",
                    help="exit with status 1 when more seeds turned to failure than to success and the sign "
                         "test's p is below ALPHA (e.g. 0.05)")
    cp.set_defaults(func=_cmd_compare)

    rep = sub.add_parser("reproduce", help="Table I, Table II and the corridor sweeps in one report.md")
    rep.add_argument("--out", required=True, help="output folder (rerun to resume the sweeps)")
    rep.add_argument("--quick", action="store_true", help="a small version that finishes in minutes")
    rep.add_argument("--jobs", type=_jobs, default=max(1, os.cpu_count() or 1), help="parallel episodes")
    _add_config_options(rep)
    rep.set_defaults(func=_cmd_reproduce)

    for name, func, text in (("train-detector", _cmd_train_detector,
                              "render the person dataset (where missing) and train the learned detector (PyTorch)"),
                             ("eval-detector", _cmd_eval_detector,
                              "validation AP@0.5 of a person detector model through onnxruntime")):
        d = sub.add_parser(name, help=text)
        d.add_argument("--data", default="runs/detector_data", help="dataset folder (train.npz, val.npz)")
        d.add_argument("--train-seeds", default="0:200", help="scene seeds of the training split")
        d.add_argument("--val-seeds", default="1000:1040", help="scene seeds of the validation split")
        d.add_argument("--images-per-seed", type=_whole(1, 100_000), default=20, help="images rendered per scene")
        if name == "train-detector":
            d.add_argument("--epochs", type=_whole(1, 100_000), default=60)
            d.add_argument("--seed", type=_seed, default=0, help="training seed (weights, data order, augmentation)")
            d.add_argument("--threads", type=_whole(1, 1024), default=2, help="PyTorch threads (the result depends on it)")
            d.add_argument("--device", default="cpu", help="cpu, or a CUDA device (cuda, cuda:1)")
            d.add_argument("--arch", default="base", help="network size: base (FastestDet's shape), wide, or wide8 (wide with a stride-8 head)")
            d.add_argument("--batch-size", type=_whole(2, 100_000, "a whole number (BatchNorm needs 2)"), default=32)
            d.add_argument("--lr", type=_real(0.0, 10.0, lo_open=True), default=3e-3, help="AdamW's peak learning rate")
            d.add_argument("--warmup-epochs", type=_real(0.0, 100_000.0), default=1.0, help="linear warm-up before the cosine decay")
            d.add_argument("--eval-every", type=_whole(0), default=5, help="validate every N epochs (0: at the end only)")
            d.add_argument("--out", default="runs/detector", help="folder for person_detector.onnx and .json")
        else:
            d.add_argument("--model", default=None, help="an ONNX model with its .json (default: the shipped one)")
            d.add_argument("--max-distance", type=_real(0.0, 1000.0, lo_open=True), default=10.0, help="people within this distance count")
            d.add_argument("--nms-iou", type=_real(0.0, 1.0, lo_open=True), default=0.45, help="non-maximum suppression IoU (FastestDet's 0.45)")
            d.add_argument("--score-floor", type=_real(0.0, 1.0, lo_open=True, hi_open=True), default=0.05,
                           help="detections scoring less are left out of the AP (default %(default)s; "
                                "YOLO evaluations use 0.001, which counts more of the curve's tail)")
            d.add_argument("--soft-nms", type=_real(0.0, 100.0), default=LearnedConfig().soft_nms_sigma, metavar="SIGMA",
                           help="Gaussian soft-NMS with this sigma, as at run time (default %(default)s); "
                                "0: NMS at --nms-iou")
            d.add_argument("--min-visible-px", type=_whole(0), default=0,
                           help="ignore people showing fewer pixels at 640x480 (the perception metrics use 400)")
            d.add_argument("--views", default="full",
                           help="views fused at run time, a comma list of full, flip, center, center-flip")
        d.set_defaults(func=func)

    pk = sub.add_parser("pack-detector-data", help="a person dataset file (or shards of one split) with its "
                        "images as WebP, some 60 times smaller, for copying to a training machine")
    pk.add_argument("files", nargs="+", help="train.npz / val.npz files of one split, as rendered")
    pk.add_argument("--out", required=True, help="the packed file to write")
    pk.add_argument("--quality", type=_whole(1, 101), default=90, help="WebP quality 1-100, or 101 for lossless")
    pk.set_defaults(func=_cmd_pack_detector_data)

    from experiments.perceive import add_parser as add_perceive

    add_perceive(sub)

    sc = sub.add_parser("scenarios", help="list the shipped scenarios")
    sc.set_defaults(func=_cmd_scenarios)

    v = sub.add_parser("validate", help="check scenario files and report the first problem of each")
    v.add_argument("files", nargs="+")
    v.set_defaults(func=_cmd_validate)
    return ap


def _terminated(signum, frame):
    raise SystemExit(128 + signum)


def main(argv: list[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as e:  # argparse's refusals (status 2, one line) and --help (0): returned like the rest
        return e.code if isinstance(e.code, int) else 2
    # SIGTERM (kill, a job scheduler) ends the command as Ctrl-C does: through its finally blocks, which
    # close what it started (a render process, a viewer's server, a sweep's workers). Those also end on
    # their own when this process is gone (SIGKILL): sim.parent_watch.
    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, _terminated)
    try:
        return args.func(args)
    except (ScenarioError, UserError, ModelError, SequenceError) as e:
        print(f"dodt-nav: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        where = f"{e.filename}: " if e.filename else ""
        print(f"dodt-nav: error: {where}{e.strerror or e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("dodt-nav: interrupted", file=sys.stderr)
        return 130
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())


__all__ = ["main", "build_parser"]
