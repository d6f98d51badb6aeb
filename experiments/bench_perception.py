"""`dodt-nav bench perception` and `dodt-nav bench runtime`: the paper's Tables I and II.

Perception: every configuration (dodt.presets) runs on the same simulated frames of the
perception scenarios (camera carried along scripted paths, or mounted on the flying drone, D435i
noise on) and is scored against ground truth (experiments.perception_metrics states the
matching rule). Writes table.md, table.csv (laid out like Table I, the paper's numbers beside
ours), per-scenario tables, recall against distance (recall_by_distance.md/.csv and a plot), and
plots.

Runtime: the full pipeline (with the learned module where the configuration has it) on recorded
640x480 frames, one thread; per-module median and p95 milliseconds per frame, laid out like
Table II.
"""
from __future__ import annotations

import csv
import json
import math
import time
from pathlib import Path

import numpy as np

from dodt.config import DepthConfig
from dodt.pipeline import DODT, MODULES
from dodt.presets import PRESETS, preset
from experiments.perception_metrics import RECALL_BINS, PerceptionMetrics, bin_labels
from experiments.figures import new_figure
from sim import World, load_scenario
from sim.rig import cameras, frames_per_scan, lidars, rig
from sim.trajectories import scenario_reference

SCENARIOS = ("circles", "follow_person", "wall_pass", "partial_obstacle", "static_only", "corridor", "far_people")

# Table I of the paper (real-world, D435i): position error [m], velocity error [m/s], FP rate [%].
PAPER_TABLE_I = {
    "method-1-umap": ("Method I", 0.28, 0.47, None),
    "method-2-cluster": ("Method II", 0.18, 0.29, 16.4),
    "method-3-udepth-velocity": ("Method III", 0.19, 0.21, 19.6),
    "dodt-no-ensemble": ("DODT w/o Ens", 0.17, 0.30, 18.6),
    "dodt-no-fat": ("DODT w/o FAT", 0.14, 0.29, 6.5),
    "dodt": ("DODT", 0.11, 0.23, 3.7),
}
# Table II of the paper, Intel NUC [ms].
PAPER_TABLE_II = {"udepth": 3.4, "dbscan": 1.3, "learned": 14.3, "association": 0.03, "kalman": 0.07,
                  "identification": 0.12}
PAPER_TOTAL_MS = 19.12  # with YOLO-MAD; without it 19.12 - 14.3


def result_key(config: str, rate: float | None) -> str:
    """The name a configuration's results go under: the configuration's, or with ``rate`` (frames
    processed per second, the camera's decimated) ``config@RATEHz``."""
    return config if rate is None else f"{config}@{rate:g}Hz"


def rigged_world(sc, seed: int, rig_name: str, segmentation: bool):
    """(a World carrying the rig's cameras, scan(k): the rig's LiDAR scan taken now when camera frame k is
    one the loop scans at (every sim.rig.frames_per_scan frames), else None)."""
    world = World(sc, seed=seed, segmentation=segmentation)
    mounts = rig(rig_name)
    if cameras(mounts)[1:]:
        world.add_cameras([m.yaw for m in cameras(mounts)[1:]])
    lidar = next(iter(lidars(mounts)), None)
    if lidar is None:
        return world, lambda k: None
    model, T_body = lidar.lidar_model(), lidar.T_body_lidar()
    every = frames_per_scan(sc.rates.camera, model)
    return world, lambda k: None if k % every else world.lidar_scan(model, T_body, method="auto")


def rigged_dodt(config: str, sc, rig_name: str) -> DODT:
    """DODT of a configuration, told the scene as the closed loop's context tells it: the corridor as the
    geofence, and the rig's LiDAR's lowest and highest rays."""
    co = sc.corridor
    model = next((m.lidar_model() for m in lidars(rig(rig_name))), None)
    pipe = DODT(preset(config))
    pipe.set_scene(geofence=(np.array([0.0, -co.width / 2]), np.array([co.length, co.width / 2])),
                   lidar_elevation_min=None if model is None else model.elevation_min,
                   lidar_elevation_max=None if model is None else model.elevation_max)
    return pipe


def run_scenario(name: str, seed: int, configs: list[str], duration: float | None = None,
                 record_tracks: bool = False, rates: list[float] | None = None, rig_name: str = "front"):
    """Simulate one scenario once and score every configuration on its frames.

    ``rates`` (Hz): each configuration also runs on the frames decimated to each rate (a frame is
    kept when its stamp reaches the next multiple of 1 / rate after the first), and is scored on
    those frames only; the results are keyed by ``result_key``. None: every frame, keyed by the
    configuration's name. ``rig_name`` (sim.rig): the sensors; with another rig than ``front`` each
    configuration also reads the rig's other cameras and its LiDAR (scanned at its rate, as in the closed
    loop), and recall counts the people within range in any direction, in view or not."""
    sc = load_scenario(name)
    world, scan = rigged_world(sc, seed, rig_name, segmentation=True)
    ref = scenario_reference(sc)
    runs = [(c, r) for c in configs for r in (rates or [None])]
    pipes = {result_key(c, r): rigged_dodt(c, sc, rig_name) for c, r in runs}
    metrics = {k: PerceptionMetrics(all_round=rig_name != "front") for k in pipes}
    tracks = {k: [] for k in pipes}
    slots: dict = {}  # per decimated run: (the first frame's stamp, the index of the next 1 / rate slot)
    truth_log = []
    frame = world.latest_frame()
    n = int(round((duration or sc.duration) * sc.rates.control))
    n_frames = 0
    for k in range(n + 1):
        if frame is not None:
            truth = world.ground_truth()
            extra = world.latest_extra_frames()
            taken = scan(n_frames)
            n_frames += 1
            for c, rate in runs:
                key = result_key(c, rate)
                if rate is not None:
                    t0, slot = slots.get(key, (frame.stamp, 0))
                    if frame.stamp < t0 + slot / rate - 1e-6:
                        continue
                    slots[key] = (t0, int(math.floor((frame.stamp - t0) * rate + 1e-6)) + 1)
                if extra:
                    pipes[key].observe_cameras(extra)
                if taken is not None:
                    pipes[key].observe_lidar(taken)
                r = pipes[key].process(frame)
                metrics[key].add(r, truth, frame.intrinsics)
                if record_tracks:
                    tracks[key].append([(o.id, float(o.center[0]), float(o.center[1]), o.dynamic) for o in r.obstacles])
            if record_tracks:
                truth_log.append([(o.id, float(o.center[0]), float(o.center[1])) for o in truth.obstacles
                                  if o.kind == "person"])
        if k == n:
            break
        frame = world.step(ref(world.time))
    world.close()
    return metrics, tracks, truth_log


def _pct(x):
    return None if x is None else 100 * x


def _fmt(x, nd=3):
    return "n/a" if x is None or (isinstance(x, float) and np.isnan(x)) else f"{x:.{nd}f}"


def write_tables(out: Path, overall: dict, per_scn: dict, per_seed: dict | None = None) -> str:
    """table.md / table.csv; ``per_seed`` ({seed: {config: summary}}, two seeds or more) adds the
    overall figures of each seed, so that the spread between draws is in the table too."""
    rows = []
    for cfg, s in overall.items():
        paper = PAPER_TABLE_I.get(cfg.split("@")[0], (None, None, None, None))
        rows.append({"configuration": cfg, "paper_row": paper[0] or "",
                     "pos_err_m": s["pos_err"], "vel_err_mps": s["vel_err"], "fp_rate_pct": 100 * s["fp_rate"],
                     "recall_pct": 100 * s["recall"], "id_switches": s["id_switches"], "pos_err_3d_m": s["pos_err_3d"],
                     "paper_pos_err_m": paper[1], "paper_vel_err_mps": paper[2], "paper_fp_rate_pct": paper[3],
                     "matched": s["matched"], "dynamic_reports": s["dynamic_reports"],
                     "duplicate_pct": 100 * s["duplicates"] / max(s["dynamic_reports"], 1),
                     "static_speed_p95_mps": s["static_speed_p95"], "still_speed_p95_mps": s["still_speed_p95"],
                     "std_scale": s.get("std_scale", float("nan")),
                     "pred_err_cv_m": s.get("pred_err_cv", float("nan")),
                     "pred_err_ca_m": s.get("pred_err_ca", float("nan")),
                     # track life (experiments.perception_metrics.TrackLife)
                     "continuity_pct": _pct(s.get("continuity")), "continuity_moving_pct": _pct(s.get("continuity_moving")),
                     "phantom_moving_per_min": s.get("phantom_moving_per_min"),
                     "drifted_moving_per_min": s.get("drifted_moving_per_min"),
                     "max_reported_speed_mps": s.get("max_reported_speed"),
                     "track_id_switches": s.get("track_id_switches"),
                     # time to moving (experiments.perception_metrics.MovingLatency)
                     "moving_latency_median_s": s.get("moving_latency_median", float("nan")),
                     "moving_latency_p90_s": s.get("moving_latency_p90", float("nan")),
                     "moving_latency_n": s.get("moving_latency_n"),
                     "moving_latency_unreported": s.get("moving_latency_unreported")})
    with open(out / "table.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: (round(v, 4) if isinstance(v, float) else v) for k, v in r.items()})
    lines = ["| Method | Pos. Err. (m) | Vel. Err. (m/s) | FP Rate (%) | Recall 0.5-5 m (%) | ID switches | "
             "Duplicates (%) | Static speed p95 (m/s) | Continuity 5 m (%) | Phantom moving (/min) | "
             "Drifted moving (/min) | Max speed (m/s) | Track ID switches | paper Pos. Err. | paper Vel. Err. | paper FP (%) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        name = r["configuration"] + (f" ({r['paper_row']})" if r["paper_row"] else "")
        lines.append(f"| {name} | {_fmt(r['pos_err_m'])} | {_fmt(r['vel_err_mps'])} | {_fmt(r['fp_rate_pct'], 1)} | "
                     f"{_fmt(r['recall_pct'], 1)} | {r['id_switches']} | {_fmt(r['duplicate_pct'], 1)} | "
                     f"{_fmt(r['static_speed_p95_mps'], 2)} | {_fmt(r['continuity_pct'], 1)} | "
                     f"{_fmt(r['phantom_moving_per_min'], 2)} | {_fmt(r['drifted_moving_per_min'], 2)} | "
                     f"{_fmt(r['max_reported_speed_mps'], 2)} | "
                     f"{'n/a' if r['track_id_switches'] is None else r['track_id_switches']} | "
                     f"{_fmt(r['paper_pos_err_m'], 2)} | "
                     f"{_fmt(r['paper_vel_err_mps'], 2)} | {_fmt(r['paper_fp_rate_pct'], 1)} |")
    lines += ["", "The tracks' reported position std against their error (std_scale: 1 when calibrated, below 1 "
              "when the std overstates the error): " + ", ".join(f"{r['configuration']} {_fmt(r['std_scale'], 2)}"
                                                                   for r in rows) + "."]
    lines += ["", "Track life: continuity is the share of the frames in which a person within 5 m of the camera, in "
              "view or not, is matched by a track of any label (by a dynamic track: " + ", ".join(
                  f"{r['configuration']} {_fmt(r['continuity_moving_pct'], 1)} %" for r in rows) + "); phantom "
              "moving counts a dynamic track farther than 0.5 m from every person, never matched to one before, once per "
              "stretch; drifted moving the same for a track once matched to a person (its prediction left them); the speed is the "
              "largest any track reported; track ID switches match people to tracks of any label."]
    lines += ["", "Time to moving, from a walking person's first visible frame within 5 m to the first frame a "
              "dynamic track is matched to it (DODT's label; without a static map, the motion label is off), median / 90th percentile s (stretches reported; "
              "never reported): " + ", ".join(
                  f"{r['configuration']} {_fmt(r['moving_latency_median_s'], 2)} / "
                  f"{_fmt(r['moving_latency_p90_s'], 2)} ({r['moving_latency_n']}; {r['moving_latency_unreported']})"
                  for r in rows) + "."]
    lines += ["", "Where the tracks put a person 1 s later, mean error (m) at constant velocity / with the filter's "
              "acceleration held: " + ", ".join(f"{r['configuration']} {_fmt(r['pred_err_cv_m'], 2)} / "
                                                f"{_fmt(r['pred_err_ca_m'], 2)}" for r in rows) + "."]
    lines += ["", "Per scenario (pos. err. m / vel. err. m/s / FP % / recall % / id switches / static speed p95 m/s):", "",
              "| Method | " + " | ".join(per_scn) + " |", "|---|" + "---|" * len(per_scn)]
    for cfg in overall:
        cells = []
        for scn in per_scn:
            s = per_scn[scn][cfg]
            cells.append(f"{_fmt(s['pos_err'], 2)} / {_fmt(s['vel_err'], 2)} / {_fmt(100 * s['fp_rate'], 1)} / "
                         f"{_fmt(100 * s['recall'], 0)} / {s['id_switches']} / {_fmt(s['static_speed_p95'], 2)}")
        lines.append(f"| {cfg} | " + " | ".join(cells) + " |")
    if per_seed and len(per_seed) > 1:
        lines += ["", "Per seed, all scenarios (pos. err. m / vel. err. m/s / FP % / recall %):", "",
                  "| Method | " + " | ".join(f"seed {k}" for k in per_seed) + " |", "|---|" + "---|" * len(per_seed)]
        for cfg in overall:
            cells = [f"{_fmt(d[cfg]['pos_err'])} / {_fmt(d[cfg]['vel_err'])} / {_fmt(100 * d[cfg]['fp_rate'], 1)} / "
                     f"{_fmt(100 * d[cfg]['recall'], 1)}" for d in per_seed.values()]
            lines.append(f"| {cfg} | " + " | ".join(cells) + " |")
    text = "\n".join(lines) + "\n"
    (out / "table.md").write_text(text)
    return text


def write_recall_by_distance(out: Path, overall: dict) -> str:
    """Recall of walking people against camera distance (the paper's Fig. 10), a table and a plot."""
    labels = bin_labels()
    lines = ["| Method | " + " | ".join(f"{b} m" for b in labels) + " | beyond 4 m | pos. / vel. err. beyond 5 m |",
             "|---|" + "---|" * (len(labels) + 2)]
    lines.append("| (people visible, frames) | " + " | ".join(
        str(next(iter(overall.values()))["visible_by_distance"][b]) for b in labels) + " | | |")
    for cfg, s in overall.items():
        lines.append(f"| {cfg} | " + " | ".join(_fmt(100 * s["recall_by_distance"][b], 0) for b in labels)
                     + f" | {_fmt(100 * s['recall_beyond_4m'], 1)} | {_fmt(s['pos_err_beyond'], 2)} / "
                     f"{_fmt(s['vel_err_beyond'], 2)} ({s['matched_beyond']} pairs) |")
    text = ("Recall (%) of walking people by camera distance (Table I's errors count people within 5 m; "
            "matches farther away are scored in the last column):\n\n" + "\n".join(lines) + "\n")
    (out / "recall_by_distance.md").write_text(text)
    with open(out / "recall_by_distance.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["configuration"] + labels + ["beyond_4m"])
        for cfg, s in overall.items():
            w.writerow([cfg] + [round(s["recall_by_distance"][b], 4) for b in labels] + [round(s["recall_beyond_4m"], 4)])
    mids = [(a + b) / 2 for a, b in zip(RECALL_BINS[:-1], RECALL_BINS[1:])]
    fig, ax = new_figure(figsize=(7, 4))
    for cfg, s in overall.items():
        main = cfg in ("dodt", "dodt+yolo")
        ax.plot(mids, [100 * s["recall_by_distance"][b] for b in labels], "o-" if main else "-",
                lw=2.5 if main else 0.8, alpha=1.0 if main else 0.5, label=cfg)
    depth_max = DepthConfig().depth_max
    ax.axvline(depth_max, color="grey", ls=":", lw=1)
    ax.text(depth_max + 0.05, 3, f"geometric detectors' depth range {depth_max:g} m", fontsize=7, color="grey")
    ax.set_xlabel("camera distance of the person [m]")
    ax.set_ylabel("recall of walking people [%]")
    ax.set_ylim(0, 103)
    ax.legend(fontsize=7, ncol=2)
    ax.set_title("Recall against distance (paper Fig. 10: the learned module's range)")
    fig.savefig(out / "recall_vs_distance.png", dpi=110)
    return text


def plot(out: Path, scenario: str, metrics: dict, tracks: dict, truth_log: list) -> None:
    fig, ax = new_figure(figsize=(8, 6), nrows=2, sharex=True)
    for cfg, m in metrics.items():
        s = np.array(m.series)
        if len(s):
            ax[0].plot(s[:, 0], s[:, 1], label=cfg, lw=1)
            ax[1].plot(s[:, 0], s[:, 2], lw=1)
    ax[0].set_ylabel("position error [m]")
    ax[1].set_ylabel("velocity error [m/s]")
    ax[1].set_xlabel("time [s]")
    ax[0].legend(fontsize=7, ncol=2)
    ax[0].set_title(f"{scenario}: errors of dynamic tracks matched to people")
    fig.savefig(out / f"errors_{scenario}.png", dpi=110)
    fig, ax = new_figure(figsize=(8, 5))
    for pid in {p[0] for frame in truth_log for p in frame}:
        xy = np.array([(x, y) for frame in truth_log for i, x, y in frame if i == pid])
        ax.plot(xy[:, 0], xy[:, 1], "k-", lw=3, alpha=0.3)
    main = next((k for k in tracks if k.split("@")[0] == "dodt"), None)  # dodt, or dodt at its first rate
    if main is not None:
        by_id: dict = {}
        for frame in tracks[main]:
            for tid, x, y, dyn in frame:
                if dyn:
                    by_id.setdefault(tid, []).append((x, y))
        for tid, xy in by_id.items():
            xy = np.array(xy)
            ax.plot(xy[:, 0], xy[:, 1], ".", ms=2, label=f"track {tid}" if len(by_id) <= 12 else None)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"{scenario}: people (grey) and dodt's dynamic tracks, top-down")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7, ncol=3)
    fig.savefig(out / f"topdown_{scenario}.png", dpi=110)


def run(out: Path, seeds: list[int], scenarios=SCENARIOS, configs=None, duration: float | None = None,
        rates: list[float] | None = None, rig_name: str = "front") -> dict:
    """``rates`` (Hz): score every configuration at each of these frame rates (run_scenario), its
    rows named ``config@RATEHz``; None: at the camera's rate, rows named by configuration."""
    configs = list(configs or PRESETS)
    keys = [result_key(c, r) for c in configs for r in (rates or [None])]
    out.mkdir(parents=True, exist_ok=True)
    per_scn_metrics: dict = {s: {k: [] for k in keys} for s in scenarios}
    t0 = time.perf_counter()
    for scn in scenarios:
        for i, seed in enumerate(seeds):
            m, tracks, truth = run_scenario(scn, seed, configs, duration, record_tracks=(i == 0), rates=rates,
                                            rig_name=rig_name)
            for k in keys:
                per_scn_metrics[scn][k].append(m[k])
            if i == 0:
                plot(out, scn, m, tracks, truth)
            s = m[keys[0]].summary()
            print(f"  {scn} seed {seed}: {keys[0]} recall {s['recall']:.3f} FP {s['fp_rate']:.4f} vel {s['vel_err']:.3f} "
                  f"static speed p95 {s['static_speed_p95']:.3f}", flush=True)
    per_scn = {s: {c: PerceptionMetrics.combine(v) for c, v in d.items()} for s, d in per_scn_metrics.items()}
    overall = {k: PerceptionMetrics.combine([m for s in scenarios for m in per_scn_metrics[s][k]]) for k in keys}
    per_seed = {seed: {k: PerceptionMetrics.combine([per_scn_metrics[s][k][i] for s in scenarios]) for k in keys}
                for i, seed in enumerate(seeds)}
    text = write_tables(out, overall, per_scn, per_seed) + "\n" + write_recall_by_distance(out, overall)
    (out / "results.json").write_text(json.dumps({"rig": rig_name, "seeds": seeds, "scenarios": list(scenarios),
                                                  "overall": overall,
                                                  "per_scenario": per_scn, "per_seed": per_seed}, indent=1))
    print(text)
    print(f"wrote {out}/table.md, table.csv, recall_by_distance.md/.csv, results.json and plots in "
          f"{time.perf_counter() - t0:.0f} s")
    return overall


# --------------------------------------------------------------------------- runtime (Table II)


def record_frames(scenario: str = "corridor", seconds: float = 6.0, seed: int = 0, rig_name: str = "front") -> list:
    """The first camera's frames of a flight along the scenario's reference; with another rig than ``front``,
    each as (frame, the other cameras' frames, the LiDAR's scan taken with it or None)."""
    sc = load_scenario(scenario)
    world, scan = rigged_world(sc, seed, rig_name, segmentation=False)
    ref = scenario_reference(sc)
    frames = []
    f = world.latest_frame()
    while True:
        if rig_name == "front":
            frames.append(f)
        else:
            frames.append((f, world.latest_extra_frames(), scan(len(frames))))
        if world.time >= seconds:
            break
        f = None
        while f is None:
            f = world.step(ref(world.time))
    world.close()
    return frames


def run_runtime(config: str = "dodt", scenario: str = "corridor", seconds: float = 6.0, repeats: int = 3,
                json_out: Path | None = None, rig_name: str = "front") -> dict:
    """Per-module times of one configuration; with another rig than ``front``, on the rig's sensors (the
    ``lidar`` module's figures over the frames a scan joined)."""
    import cv2

    cv2.setNumThreads(1)  # single-threaded, as the paper's table
    recorded = record_frames(scenario, seconds, rig_name=rig_name)
    rigged = rig_name != "front"
    frames = [r[0] for r in recorded] if rigged else recorded
    per = {m: [] for m in MODULES + ("total",)}
    sc = load_scenario(scenario)
    for rep in range(repeats + 1):
        pipe = rigged_dodt(config, sc, rig_name)
        for item in recorded:
            f = item
            if rigged:
                f, extra, scan = item
                if extra:
                    pipe.observe_cameras(extra)
                if scan is not None:
                    pipe.observe_lidar(scan)
            r = pipe.process(f)
            if rep > 0:  # the first pass compiles and warms up
                for m in per:
                    if m != "lidar" or not rigged or item[2] is not None:
                        per[m].append(r.timings_ms[m])
    res = {m: {"median_ms": float(np.median(v)), "p95_ms": float(np.percentile(v, 95))} for m, v in per.items()}
    K = frames[0].intrinsics
    print(f"Runtime of '{config}' per frame, {K.width}x{K.height}, one thread, {len(frames)} frames of {scenario} "
          f"x {repeats} passes, rig {rig_name}")
    print(f"| {'module':<22} | {'median (ms)':>11} | {'p95 (ms)':>8} | {'paper, Intel NUC (ms)':>21} |")
    print(f"|{'-' * 24}|{'-' * 13}|{'-' * 10}|{'-' * 23}|")
    names = {"point_cloud": "point cloud + voxel", "udepth": "U-depth detection", "dbscan": "DBSCAN detection",
             "ensemble": "ensemble fusion", "association": "data association", "kalman": "Kalman filter tracking",
             "learned": "YOLO-MAD detection", "identification": "dynamic obstacle id.", "total": "total",
             "other_cameras": "other cameras' detectors", "lidar": "LiDAR detection, fusion"}
    uses = {"other_cameras": bool(cameras(rig(rig_name))[1:]), "lidar": bool(lidars(rig(rig_name)))}
    learned_on = preset(config).learned.enabled
    for m in MODULES + ("total",):
        if (m == "learned" and not learned_on) or not uses.get(m, True):
            continue
        paper = PAPER_TABLE_II.get(m)
        if m == "total":
            paper = PAPER_TOTAL_MS if learned_on else PAPER_TOTAL_MS - PAPER_TABLE_II["learned"]
        print(f"| {names[m]:<22} | {res[m]['median_ms']:>11.2f} | {res[m]['p95_ms']:>8.2f} | "
              f"{(f'{paper:.2f}' if paper is not None else '-'):>21} |")
    if learned_on:
        det = sum(res[m]["median_ms"] for m in ("udepth", "dbscan", "learned"))
        share = 100 * res["learned"]["median_ms"] / det if det else float("nan")
        paper_share = 100 * PAPER_TABLE_II["learned"] / sum(PAPER_TABLE_II[m] for m in ("udepth", "dbscan", "learned"))
        print(f"YOLO-MAD share of the detectors' median time: {share:.1f} % (paper, Intel NUC: {paper_share:.1f} %)")
        res["learned_share_of_detectors_pct"] = share
    if json_out:
        Path(json_out).write_text(json.dumps(res, indent=1))
    return res
