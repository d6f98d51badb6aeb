"""PNG figures of one episode, drawn from its log (experiments.episode_log) after the run.

``plot_episode(log, out_dir)`` writes ``topdown.png`` (corridor, static obstacles, the drone's path,
people's true paths with time marks, perception's dynamic tracks, collisions, start and goal),
``clearance.png`` (distance to the nearest person, static obstacle and structure over time,
collisions marked, the periods near the start and goal shaded), ``perception_error.png``
(position and velocity error of dynamic tracks matched to people, per person) and ``runtime.png`` (perception, map update and planner solve milliseconds,
laid out like the paper's Table II). File names are fixed; the same input gives the same PNG.

The perception-error matching here is a viewer's rule, looser than the benchmark's
(experiments.perception_metrics: one-to-one within 0.5 m): in every camera frame each person is
paired with the nearest dynamic track centre within ``match_distance`` (1.0 m) horizontally.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from experiments.episode_log import read_log
from experiments.episode_metrics import END_ZONE_RADIUS, end_zones, in_end_zone, timing_stats
from experiments.figures import COLLISION_COLOR, new_figure, save_figure, show_message
from experiments.runtime_plots import plot_runtime_table

# One colour per person; pure red is kept for collisions, black for the drone.
PERSON_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:pink", "tab:olive",
                 "tab:cyan")
TRACK_COLOR = "0.45"
STRUCTURE_COLOR = "tab:brown"  # the corridor's walls, floor and ceiling in clearance.png

EPISODE_FILES = ("topdown.png", "clearance.png", "perception_error.png", "runtime.png")


def _load_records(log) -> list[dict]:
    """Records from a log path (or a run folder holding log.jsonl.gz) or a list of records."""
    if isinstance(log, (str, Path)):
        p = Path(log)
        if p.is_dir():
            if not (p / "log.jsonl.gz").is_file():
                raise FileNotFoundError(f"{p}: no log.jsonl.gz in this folder (not an episode output folder)")
            p = p / "log.jsonl.gz"
        return read_log(p)  # FileNotFoundError / ValueError naming the file
    records = list(log)
    if not records or not isinstance(records[0], dict) or records[0].get("k") != "header":
        raise ValueError("episode records: the first record must be the header (k = 'header')")
    return records


def _title(h: dict) -> str:
    return f"{h.get('scenario', '?')} seed {h.get('seed', '?')}, perception {h.get('perception', '?')}"


def _person_colors(records: list[dict]) -> dict:
    ids = [p["id"] for p in records[0].get("people", [])]
    for r in records:
        if r["k"] == "f":
            ids += [p["id"] for p in r.get("people", [])]
    ids = sorted(set(ids))
    return {pid: PERSON_COLORS[i % len(PERSON_COLORS)] for i, pid in enumerate(ids)}


def _time_marks(t: np.ndarray, every: float) -> np.ndarray:
    """Indices of the first samples at or after each multiple of ``every`` within t's span."""
    if len(t) == 0 or every <= 0:
        return np.zeros(0, dtype=int)
    marks = np.arange(math.ceil(t[0] / every - 1e-9) * every, t[-1] + 1e-9, every)
    idx = np.searchsorted(t, marks - 1e-6)
    return np.unique(idx[idx < len(t)])


def _people_paths(frames: list[dict]) -> dict:
    """Person id -> (t (n,), centre xy (n, 2), velocity xy (n, 2)) from the frame records' truth boxes."""
    out: dict = {}
    for f in frames:
        for p in f.get("people", []):
            c = 0.5 * (np.asarray(p["lo"][:2], float) + np.asarray(p["hi"][:2], float))
            out.setdefault(p["id"], []).append((f["t"], c, np.asarray(p.get("v", (np.nan, np.nan))[:2], float)))
    return {pid: (np.array([a[0] for a in v]), np.array([a[1] for a in v]), np.array([a[2] for a in v]))
            for pid, v in out.items()}


def plot_episode(log, out_dir, *, mark_every: float = 2.0, match_distance: float = 1.0) -> list[Path]:
    """Write the episode figures (EPISODE_FILES) to ``out_dir``; returns their paths in that order.

    log: the path of a ``log.jsonl.gz`` (or the run folder holding it), or its records as
    ``experiments.episode_log.read_log`` returns them. mark_every: seconds between the time marks on
    the top-down paths. match_distance: horizontal gate [m] pairing a person with a dynamic track.
    """
    records = _load_records(log)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return [
        plot_topdown(records, out / EPISODE_FILES[0], mark_every=mark_every),
        plot_clearance(records, out / EPISODE_FILES[1]),
        plot_perception_error(records, out / EPISODE_FILES[2], match_distance=match_distance),
        plot_episode_runtime(records, out / EPISODE_FILES[3]),
    ]


def plot_topdown(log, out_png, *, mark_every: float = 2.0) -> Path:
    """Top-down view: corridor, static boxes, drone path, people's paths (time-marked), dynamic tracks,
    collisions (big red X), start and goal."""
    from matplotlib.patches import Rectangle

    records = _load_records(log)
    h = records[0]
    states = [r for r in records if r["k"] == "s"]
    frames = [r for r in records if r["k"] == "f"]
    collisions = [r for r in records if r["k"] == "collision"]
    colors = _person_colors(records)
    co = h.get("corridor") or {}
    L, W = float(co.get("length", 0.0)), float(co.get("width", 0.0))
    figw = 11.0
    figh = float(np.clip(figw * (W + 1.0) / max(L + 1.0, 1.0) + 1.6, 3.5, 9.0)) if L > 0 else 6.0
    fig, ax = new_figure((figw, figh))
    if L > 0 and W > 0:
        ax.add_patch(Rectangle((0.0, -W / 2), L, W, fill=False, ec="k", lw=1.5, zorder=1))
    for i, o in enumerate(h.get("static", [])):
        lo, hi = o["aabb_min"], o["aabb_max"]
        ax.add_patch(Rectangle((lo[0], lo[1]), hi[0] - lo[0], hi[1] - lo[1], fc="0.78", ec="0.35", lw=1, zorder=2,
                               label="static obstacle" if i == 0 else None))
        ax.text(0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), o.get("label", ""), fontsize=6, ha="center",
                va="center", color="0.25", zorder=3)

    # Perception's dynamic tracks (centres), below the true paths.
    tr = np.array([t["center"][:2] for f in frames for t in f.get("tracks", []) if t.get("dynamic")]).reshape(-1, 2)
    if len(tr):
        ax.plot(tr[:, 0], tr[:, 1], ".", color=TRACK_COLOR, ms=2.5, zorder=3,
                label=f"dynamic tracks, {h.get('perception', '?')} ({len(tr)} reports)")

    # People's true paths, with time marks.
    for pid, (t, xy, _) in sorted(_people_paths(frames).items()):
        c = colors.get(pid, "tab:gray")
        ax.plot(xy[:, 0], xy[:, 1], "-", color=c, lw=2, alpha=0.75, zorder=4, label=f"person {pid} (truth)")
        for j in _time_marks(t, mark_every):
            ax.plot(xy[j, 0], xy[j, 1], "o", color=c, ms=5, mec="k", mew=0.5, zorder=5)
            ax.annotate(f"{t[j]:g}", (xy[j, 0], xy[j, 1]), xytext=(3, 3), textcoords="offset points", fontsize=6,
                        color=c, zorder=6)

    # The drone's executed path, time-marked the same way.
    if states:
        t = np.array([s["t"] for s in states])
        p = np.array([s["p"][:2] for s in states])
        ax.plot(p[:, 0], p[:, 1], "-", color="k", lw=1.5, zorder=6, label="drone (executed)")
        for j in _time_marks(t, mark_every):
            ax.plot(p[j, 0], p[j, 1], "s", color="k", ms=4, zorder=7)
            ax.annotate(f"{t[j]:g}", (p[j, 0], p[j, 1]), xytext=(3, -8), textcoords="offset points", fontsize=6,
                        color="k", zorder=7)
    if h.get("start") is not None:
        ax.plot(h["start"][0], h["start"][1], "^", color="tab:green", ms=11, mec="k", zorder=8, label="start")
    if h.get("goal") is not None:
        ax.plot(h["goal"][0], h["goal"][1], "*", color="gold", ms=16, mec="k", zorder=8, label="goal")
    for i, c in enumerate(collisions):
        pos = c.get("position")
        if pos is None:
            continue
        ax.plot(pos[0], pos[1], "X", color=COLLISION_COLOR, ms=18, mec=COLLISION_COLOR, zorder=9,
                label="collision" if i == 0 else None)
        ax.annotate(f"{c['t']:.2f} s, {c.get('kind', '?')}", (pos[0], pos[1]), xytext=(8, 8),
                    textcoords="offset points", fontsize=7, color="k", zorder=9)
    ax.set_aspect("equal")
    if L > 0 and W > 0:
        ax.set_xlim(-0.5, L + 0.5)
        ax.set_ylim(-W / 2 - 0.5, W / 2 + 0.5)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    n_col = len(collisions)
    ax.set_title(f"{_title(h)}: top-down, numbers are times [s]"
                 + (f", {n_col} collision{'s' if n_col != 1 else ''}" if n_col else ""))
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7, ncol=4, loc="upper center", bbox_to_anchor=(0.5, -0.12 * 5 / figh), frameon=False)
    return save_figure(fig, Path(out_png), tight=True)  # equal aspect leaves margins; trim them


def plot_clearance(log, out_png) -> Path:
    """Distance to the nearest person, static obstacle and structure over time, collisions marked."""
    return save_figure(clearance_figure(_load_records(log)), Path(out_png))


def clearance_figure(records: list[dict]):
    """The figure ``plot_clearance`` saves, not yet drawn: the clearances of the state records over time,
    with the periods near the start or the goal, which the summary's structure clearance leaves out
    (experiments.episode_metrics.END_ZONE_RADIUS), shaded."""
    h = records[0]
    states = [r for r in records if r["k"] == "s"]
    collisions = [r for r in records if r["k"] == "collision"]
    fig, ax = new_figure((8, 4.5))
    if not states:
        show_message(ax, "no state records in the log")
        ax.set_title(f"{_title(h)}: clearance")
        return fig
    t = np.array([s["t"] for s in states])
    c = np.array([s["c"] for s in states], dtype=float)
    zones = end_zones(h)
    near = np.array([in_end_zone(s["p"], zones) for s in states])
    edges = np.flatnonzero(np.diff(np.r_[0, near.astype(int), 0]))  # each run of periods near an end: [i0, i1)
    for n, (i0, i1) in enumerate(zip(edges[::2], edges[1::2])):
        ax.axvspan(t[i0], t[min(i1, len(t) - 1)], color="0.9", lw=0, zorder=0,
                   label=f"within {END_ZONE_RADIUS:g} m of start or goal: structure not in the summary"
                   if n == 0 else None)
    ax.plot(t, c[:, 1], "-", color="tab:blue", lw=1.5, label="nearest person")
    ax.plot(t, c[:, 0], "-", color="0.4", lw=1.2, label="nearest static obstacle")
    ax.plot(t, c[:, 2], "-", color=STRUCTURE_COLOR, lw=1.2, label="nearest wall, floor or ceiling")
    ax.axhline(0.0, color="k", lw=0.8)
    for i, col in enumerate(collisions):
        ax.axvline(col["t"], color=COLLISION_COLOR, lw=1.5, ls="--",
                   label="collision" if i == 0 else None)
        ax.annotate(col.get("kind", "?"), (col["t"], 0.0), xytext=(3, 5), textcoords="offset points", fontsize=7,
                    color=COLLISION_COLOR, rotation=90, va="bottom")
    j = int(np.argmin(c[:, 1]))
    ax.plot(t[j], c[j, 1], "o", color="tab:blue", ms=5)
    ax.annotate(f"min {c[j, 1]:.2f} m at {t[j]:.1f} s", (t[j], c[j, 1]), xytext=(5, -12),
                textcoords="offset points", fontsize=7, color="tab:blue")
    # The simulator reports clearances only up to a cap (sim.world.CLEARANCE_CAP): a plateau at the
    # top is "at least this far", say so.
    top = float(np.nanmax(c[:, :3]))
    if np.mean(np.isclose(c[:, :3], top)) > 0.05:
        ax.axhline(top, color="0.6", lw=0.8, ls=":", label=f"reporting cap ({top:g} m: at least this far)")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("clearance [m]")
    ax.set_ylim(min(-0.05, float(np.nanmin(c[:, :3])) - 0.05), top * 1.08 + 0.02)
    ax.set_xlim(float(t[0]), float(t[-1]))
    ax.set_title(f"{_title(h)}: distance to the nearest obstacle")
    fig.legend(fontsize=7, loc="outside lower center", ncol=2, frameon=False)  # under the axes: hides no line
    return fig


def match_tracks_to_people(records: list[dict], match_distance: float = 1.0) -> dict:
    """Person id -> (t, position error, velocity error) arrays over every frame the person is in;
    NaN where no dynamic track centre lies within ``match_distance`` (horizontal) of the person's box
    centre. Errors are horizontal: |track centre - box centre|, |track velocity - person velocity|."""
    out: dict = {}
    for f in records:
        if f["k"] != "f":
            continue
        dyn = [t for t in f.get("tracks", []) if t.get("dynamic")]
        tc = np.array([t["center"][:2] for t in dyn], dtype=float).reshape(-1, 2)
        tv = np.array([(t.get("velocity") or [np.nan, np.nan])[:2] for t in dyn], dtype=float).reshape(-1, 2)
        for p in f.get("people", []):
            c = 0.5 * (np.asarray(p["lo"][:2], float) + np.asarray(p["hi"][:2], float))
            pe = ve = np.nan
            if len(tc):
                d = np.linalg.norm(tc - c, axis=1)
                k = int(np.argmin(d))
                if d[k] <= match_distance:
                    pe = float(d[k])
                    v = np.asarray(p.get("v", (np.nan, np.nan))[:2], float)
                    ve = float(np.linalg.norm(tv[k] - v))
            out.setdefault(p["id"], []).append((f["t"], pe, ve))
    return {pid: tuple(np.array(col, dtype=float) for col in zip(*rows)) for pid, rows in out.items()}


def plot_perception_error(log, out_png, *, match_distance: float = 1.0) -> Path:
    """Position and velocity error of dynamic tracks matched to people over time, per person; a figure
    saying why when there is nothing to score (oracle / static-only modes, no dynamic tracks, no match)."""
    records = _load_records(log)
    h = records[0]
    mode = h.get("perception")
    title = f"{_title(h)}: errors of dynamic tracks matched to people (within {match_distance:g} m)"
    matched = match_tracks_to_people(records, match_distance)
    any_dyn = any(t.get("dynamic") for r in records if r["k"] == "f" for t in r.get("tracks", []))
    reason = None
    if mode in ("oracle", "oracle-360"):
        reason = f"no dynamic tracks to score: perception '{mode}' reports the ground truth"
    elif mode == "static-only":
        reason = f"no dynamic tracks: perception '{mode}' reports none"
    elif not any_dyn:
        reason = "no dynamic tracks in this episode"
    elif not any(np.isfinite(pe).any() for _, pe, _ in matched.values()):
        reason = f"no dynamic tracks matched to a person within {match_distance:g} m"
    if reason is not None:
        fig, ax = new_figure((8, 4))
        show_message(ax, reason)
        ax.set_title(title, fontsize=9)
        return save_figure(fig, Path(out_png))
    colors = _person_colors(records)
    fig, ax = new_figure((8, 6), 2, 1, sharex=True)
    for pid in sorted(matched):
        t, pe, ve = matched[pid]
        ok = np.isfinite(pe)
        if not ok.any():
            ax[0].plot([], [], color=colors.get(pid, "tab:gray"), label=f"person {pid}: never matched")
            continue
        lab = (f"person {pid}: matched {100 * ok.mean():.0f} % of {len(t)} frames, "
               f"median {np.nanmedian(pe):.2f} m, {np.nanmedian(ve):.2f} m/s")
        c = colors.get(pid, "tab:gray")
        ax[0].plot(t, pe, ".-", color=c, lw=1, ms=3, label=lab)  # NaN (unmatched) breaks the line
        ax[1].plot(t, ve, ".-", color=c, lw=1, ms=3)
    ax[0].set_ylabel("position error [m]")
    ax[1].set_ylabel("velocity error [m/s]")
    ax[1].set_xlabel("time [s]")
    ax[0].set_ylim(bottom=0)
    ax[1].set_ylim(bottom=0)
    ax[0].legend(fontsize=7)
    ax[0].set_title(title, fontsize=9)
    return save_figure(fig, Path(out_png))


def episode_runtime_rows(records: list[dict]) -> list[tuple[str, float, float, int]]:
    """(module, median ms, p95 ms, n) for perception per frame, map update and planner solve."""
    rows = []
    mode = records[0].get("perception", "?")
    for label, values in ((f"perception ({mode}) per frame", (r.get("perc_ms") for r in records if r["k"] == "f")),
                          ("map update", (r.get("map_ms") for r in records if r["k"] == "f")),
                          ("planner solve", (r.get("ms") for r in records if r["k"] == "plan"))):
        st = timing_stats(values)
        rows.append((label, st.get("median", float("nan")), st.get("p95", float("nan")), st["n"]))
    return rows


def plot_episode_runtime(log, out_png) -> Path:
    """Per-call wall-clock milliseconds of the episode's modules (median bars, p95 whiskers)."""
    records = _load_records(log)
    rows = episode_runtime_rows(records)
    return plot_runtime_table([(f"{m} (n={n})", med, p95) for m, med, p95, n in rows], out_png,
                              title=f"{_title(records[0])}: wall-clock per call, this machine")
