"""PNG figures of episodes and sweeps, drawn from the recorded files after the run.

- ``plot_episode(log, out_dir)``: from an episode log (``experiments.episode_log``) writes
  ``topdown.png`` (corridor, static obstacles, the drone's path, people's true paths with time
  marks, perception's dynamic tracks, collisions, start and goal), ``clearance.png`` (distance
  to the nearest person and static obstacle over time, collisions marked), ``perception_error.png``
  (position and velocity error of dynamic tracks matched to people, per person) and
  ``runtime.png`` (perception, map update and planner solve milliseconds, laid out like the
  paper's Table II).
- ``plot_sweep(results, out_dir)``: from a sweep's ``results.jsonl`` (experiments.sweep) or a list
  of episode summaries writes ``sweep_outcomes.png`` (counts with 95 % Wilson intervals),
  ``sweep_time_to_goal.png``, ``sweep_min_clearance.png`` and ``sweep_per_seed.png``.
- ``plot_runtime_table(rows, out_png)``: a Table-II-like horizontal bar chart of
  (module, median ms, p95 ms[, paper ms]) rows, its legend under the axes
  (``runtime_table_figure`` builds the figure without saving it).

Headless: figures are ``matplotlib.figure.Figure`` objects rendered by the Agg canvas, never
registered with pyplot (no global backend switch, nothing left open after saving). File names are
fixed; the same input gives the same PNG.

The perception-error matching here is a viewer's rule, looser than the benchmark's
(experiments.perception_metrics: one-to-one within 0.5 m): in every camera frame each person is
paired with the nearest dynamic track centre within ``match_distance`` (1.0 m) horizontally.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from experiments.episode_metrics import timing_stats

DPI = 110  # as experiments.bench_perception
# One colour per person; pure red is kept for collisions, black for the drone.
PERSON_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:pink", "tab:olive",
                 "tab:cyan")
COLLISION_COLOR = "#ff0000"
TRACK_COLOR = "0.45"
OUTCOME_COLORS = {"success": "tab:green", "collision": COLLISION_COLOR, "timeout": "tab:orange",
                  "other": "tab:purple"}

EPISODE_FILES = ("topdown.png", "clearance.png", "perception_error.png", "runtime.png")
SWEEP_FILES = ("sweep_outcomes.png", "sweep_time_to_goal.png", "sweep_min_clearance.png", "sweep_per_seed.png")


# --------------------------------------------------------------------------- helpers


def new_figure(figsize=(8, 5), nrows=1, ncols=1, **kw):
    """A pyplot-free figure (Agg canvas) and its axes."""
    try:
        from matplotlib.figure import Figure
    except ImportError:
        raise RuntimeError("matplotlib is not installed: no plots (pip install matplotlib)") from None
    fig = Figure(figsize=figsize, layout="constrained")
    ax = fig.subplots(nrows, ncols, **kw)
    return fig, ax


def _save(fig, path: Path, tight: bool = False) -> Path:
    try:
        kw = {"bbox_inches": "tight", "pad_inches": 0.1} if tight else {}
        fig.savefig(path, dpi=DPI, metadata={"Software": None}, **kw)
    finally:
        fig.clear()  # drop the artists at once; the figure is not known to pyplot
    return path


def _message(ax, text: str) -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, fontsize=11, wrap=True)
    ax.set_xticks([])
    ax.set_yticks([])


def _load_records(log) -> list[dict]:
    """Records from a log path (or a run folder holding log.jsonl.gz) or a list of records."""
    if isinstance(log, (str, Path)):
        from experiments.episode_log import read_log

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


# --------------------------------------------------------------------------- episode


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
    return _save(fig, Path(out_png), tight=True)  # equal aspect leaves margins; trim them


def plot_clearance(log, out_png) -> Path:
    """Distance to the nearest person and static obstacle over time, collisions marked."""
    records = _load_records(log)
    h = records[0]
    states = [r for r in records if r["k"] == "s"]
    collisions = [r for r in records if r["k"] == "collision"]
    fig, ax = new_figure((8, 4.5))
    if not states:
        _message(ax, "no state records in the log")
        ax.set_title(f"{_title(h)}: clearance")
        return _save(fig, Path(out_png))
    t = np.array([s["t"] for s in states])
    c = np.array([s["c"] for s in states], dtype=float)
    ax.plot(t, c[:, 1], "-", color="tab:blue", lw=1.5, label="nearest person")
    ax.plot(t, c[:, 0], "-", color="0.4", lw=1.2, label="nearest static obstacle")
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
    top = float(np.nanmax(c[:, :2]))
    if np.mean(np.isclose(c[:, :2], top)) > 0.05:
        ax.axhline(top, color="0.6", lw=0.8, ls=":", label=f"reporting cap ({top:g} m: at least this far)")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("clearance [m]")
    ax.set_ylim(min(-0.05, float(np.nanmin(c[:, :2])) - 0.05), top * 1.08 + 0.02)
    ax.set_xlim(float(t[0]), float(t[-1]))
    ax.set_title(f"{_title(h)}: distance to the nearest obstacle")
    ax.legend(fontsize=7, loc="lower left")
    return _save(fig, Path(out_png))


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
        _message(ax, reason)
        ax.set_title(title, fontsize=9)
        return _save(fig, Path(out_png))
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
    return _save(fig, Path(out_png))


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


def plot_runtime_table(rows, out_png, title: str | None = None, paper_label: str = "paper (Intel NUC)") -> Path:
    """Horizontal bars laid out like the paper's Table II: one module a row, top to bottom as given; the
    bar is the median, the whisker reaches the p95. ``rows``: [(module, median_ms, p95_ms), ...], each
    optionally with a 4th item, the paper's milliseconds (drawn as a diamond; None for none), or a dict
    {module: {"median_ms", "p95_ms"}} as ``experiments.bench_perception.run_runtime`` returns. Returns out_png."""
    return _save(runtime_table_figure(rows, title, paper_label), Path(out_png))


def runtime_table_figure(rows, title: str | None = None, paper_label: str = "paper (Intel NUC)"):
    """The figure ``plot_runtime_table`` saves (same arguments), not yet drawn. Its legend is a figure
    legend in a row of its own under the x label, outside the axes: it covers no bar, value label,
    tick label or title, however long the labels are."""
    if isinstance(rows, dict):
        rows = [(m, v["median_ms"], v["p95_ms"]) for m, v in rows.items()]
    rows = [tuple(r) for r in rows]
    if any(len(r) not in (3, 4) for r in rows):
        raise ValueError("plot_runtime_table: each row must be (module, median_ms, p95_ms[, paper_ms])")
    n = len(rows)
    if n == 0:
        fig, ax = new_figure((8, 2.2))
        _message(ax, "no runtime rows")
        ax.set_title(title or "runtime per call", fontsize=9)
        return fig
    fig, ax = new_figure((8, max(2.2, 0.45 * n + 1.4) + 0.3))  # + the legend's row
    names = [str(r[0]) for r in rows]
    med = np.array([np.nan if r[1] is None else float(r[1]) for r in rows])
    p95 = np.array([np.nan if r[2] is None else float(r[2]) for r in rows])
    y = np.arange(n)
    ok = np.isfinite(med)
    whisk = np.where(np.isfinite(p95), np.maximum(p95 - med, 0.0), 0.0)
    ax.barh(y[ok], med[ok], height=0.6, color="tab:blue", alpha=0.8, label="median")
    ax.errorbar(med[ok], y[ok], xerr=[np.zeros(ok.sum()), whisk[ok]], fmt="none", ecolor="k", capsize=4, lw=1,
                label="p95")
    paper = [(i, r[3]) for i, r in enumerate(rows) if len(r) == 4 and r[3] is not None]
    if paper:
        ax.plot([p for _, p in paper], [i for i, _ in paper], "D", color="tab:orange", ms=6, mec="k",
                label=paper_label)
    xmax = float(np.nanmax(np.concatenate([med[ok], p95[np.isfinite(p95)], [p for _, p in paper], [1e-3]])))
    for i in range(n):
        txt = "no data" if not ok[i] else (f"{med[i]:.2f} / {p95[i]:.2f} ms" if np.isfinite(p95[i])
                                           else f"{med[i]:.2f} ms")
        x = max(med[i] if ok[i] else 0.0, p95[i] if np.isfinite(p95[i]) else 0.0)
        ax.text(x + 0.02 * xmax, i, txt, va="center", fontsize=7)
    ax.set_yticks(y, names, fontsize=8)
    ax.invert_yaxis()  # first row on top, as in a table
    ax.set_xlim(0, xmax * 1.3)
    ax.set_xlabel("milliseconds per call (bar: median, whisker: p95; labels: median / p95)")
    handles, labels = ax.get_legend_handles_labels()
    order = sorted(range(len(labels)), key=lambda i: {"median": 0, "p95": 1}.get(labels[i], 2))
    fig.legend([handles[i] for i in order], [labels[i] for i in order], loc="outside lower center",
               ncol=len(handles), fontsize=7, frameon=False)
    ax.set_title(title or "runtime per call, laid out like the paper's Table II", fontsize=9)
    return fig


# --------------------------------------------------------------------------- sweep


def _load_summaries(results) -> list[dict]:
    """Summaries from a results.jsonl path (or the sweep folder holding it) or a list of summary dicts."""
    if isinstance(results, (str, Path)):
        from experiments.sweep import RESULTS, read_results

        p = Path(results)
        if p.is_dir():
            p = p / RESULTS
        if not p.is_file():
            raise FileNotFoundError(f"{p}: no such sweep results file")
        summaries = list(read_results(p).values())
        if not summaries:
            raise ValueError(f"{p}: no episode summaries in this file")
        return summaries
    summaries = list(results)
    if not summaries:
        raise ValueError("plot_sweep: no episode summaries")
    need = ("seed", "success", "collided", "timeout", "time_to_goal", "reached_goal", "min_clearance")
    for s in summaries:
        missing = [k for k in need if not isinstance(s, dict) or k not in s]
        if missing:
            raise ValueError(f"plot_sweep: an episode summary lacks {', '.join(missing)}")
    return summaries


def _outcome(row: dict) -> str:
    if row["success"]:
        return "success"
    if row["collided"]:
        return "collision"
    if row["timeout"]:
        return "timeout"
    return "other"


def _aggregate(summaries: list[dict]) -> dict:
    from experiments.sweep import aggregate

    def one(key):
        vals = sorted({str(s.get(key)) for s in summaries})
        return vals[0] if len(vals) == 1 else "+".join(vals)

    # aggregate() also reads these; default them so hand-made summaries plot too.
    full = [{"mean_speed": 0.0, "planner_stats": {"fallbacks": 0}, "collision_count": int(s["collided"]),
             "failure_reason": None, **s} for s in summaries]
    return aggregate(full, one("scenario"), one("perception"))


def plot_sweep(results, out_dir) -> list[Path]:
    """Write the sweep figures (SWEEP_FILES) to ``out_dir``; returns their paths in that order.

    results: a sweep's ``results.jsonl`` (or its folder), or a list of episode summaries
    (experiments.episode_metrics.summarize); duplicate seeds in a file keep the last line."""
    summaries = _load_summaries(results)
    agg = _aggregate(summaries)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    name = f"{agg['scenario']}, perception {agg['perception']}, {agg['episodes']} episodes"
    paths = []

    # Outcomes: counts, the Wilson interval drawn in counts.
    fig, ax = new_figure((7, 4.5))
    n = agg["episodes"]
    keys = list(agg["rates"])
    counts = [agg["rates"][k]["count"] for k in keys]
    lo = [agg["rates"][k]["ci95"][0] * n for k in keys]
    hi = [agg["rates"][k]["ci95"][1] * n for k in keys]
    other = sum(_outcome(r) == "other" for r in agg["per_seed"])
    if other:
        keys.append("other")
        counts.append(other)
        from experiments.sweep import wilson

        a, b = wilson(other, n)
        lo.append(a * n)
        hi.append(b * n)
    x = np.arange(len(keys))
    ax.bar(x, counts, color=[OUTCOME_COLORS.get(k, "tab:gray") for k in keys], alpha=0.85, width=0.6)
    ax.errorbar(x, counts, yerr=[np.subtract(counts, lo), np.subtract(hi, counts)], fmt="none", ecolor="k",
                capsize=6, lw=1.2, label="95 % Wilson interval")
    for i, c in enumerate(counts):
        ax.text(i + 0.33, c, f"{c}/{n}\n{100 * c / n:.1f} %" if n else "0", fontsize=8, va="center")
    ax.set_xticks(x, keys)
    ax.set_xlim(-0.6, len(keys) - 0.1)
    ax.set_ylim(0, max(n, 1) * 1.1)
    ax.set_ylabel("episodes")
    ax.legend(fontsize=7, loc="upper right")
    ax.set_title(f"{name}: outcomes (collision and timeout may overlap)", fontsize=9)
    paths.append(_save(fig, out / SWEEP_FILES[0]))

    # Time to goal of the episodes that reached it.
    ttg = np.array([s["time_to_goal"] for s in summaries if s.get("reached_goal") and s["time_to_goal"] is not None],
                   dtype=float)
    fig, ax = new_figure((7, 4.5))
    if len(ttg):
        ax.hist(ttg, bins=min(30, max(5, int(np.sqrt(len(ttg))) * 2)), color="tab:blue", alpha=0.8, ec="k", lw=0.5)
        d = agg["time_to_goal"]
        ax.axvline(d["median"], color="k", ls="--", lw=1, label=f"median {d['median']:.2f} s")
        ax.axvline(d["p95"], color="0.5", ls=":", lw=1, label=f"p95 {d['p95']:.2f} s")
        ax.legend(fontsize=7)
        ax.set_xlabel("time to goal [s]")
        ax.set_ylabel("episodes")
    else:
        _message(ax, "no episode reached the goal")
    ax.set_title(f"{name}: time to goal ({len(ttg)} reached it)", fontsize=9)
    paths.append(_save(fig, out / SWEEP_FILES[1]))

    # Minimum clearance: to people and overall.
    mcp = np.array([s["min_clearance"].get("person") for s in summaries
                    if s["min_clearance"].get("person") is not None], dtype=float)
    mco = np.array([s["min_clearance"].get("overall") for s in summaries
                    if s["min_clearance"].get("overall") is not None], dtype=float)
    fig, ax = new_figure((7, 4.5))
    both = np.concatenate([mcp, mco])
    if len(both):
        lo_e, hi_e = float(min(both.min(), 0.0)), float(both.max())
        bins = np.linspace(lo_e, hi_e + 1e-6 if hi_e > lo_e else lo_e + 1.0, 26)
        if len(mcp):
            ax.hist(mcp, bins=bins, color="tab:blue", alpha=0.55, ec="tab:blue", label=f"to people (n={len(mcp)})")
        if len(mco):
            ax.hist(mco, bins=bins, histtype="step", color="k", lw=1.5, label=f"overall (n={len(mco)})")
        ax.axvline(0.0, color=COLLISION_COLOR, lw=1, label="contact")
        ax.legend(fontsize=7)
        ax.set_xlabel("minimum clearance over the episode [m]")
        ax.set_ylabel("episodes")
    else:
        _message(ax, "no clearance figures in these summaries")
    ax.set_title(f"{name}: minimum clearance", fontsize=9)
    paths.append(_save(fig, out / SWEEP_FILES[2]))

    # Per-seed strip: outcome cells, minimum clearance below.
    rows = agg["per_seed"]
    seeds = np.array([r["seed"] for r in rows])
    outc = [_outcome(r) for r in rows]
    fig, ax = new_figure((max(7.0, min(16.0, 0.08 * len(rows) + 5)), 4.5), 2, 1, sharex=True,
                      gridspec_kw={"height_ratios": [1, 3]})
    pos = np.arange(len(rows))
    for k in ("success", "collision", "timeout", "other"):
        sel = [i for i, o in enumerate(outc) if o == k]
        if sel:
            ax[0].bar(pos[sel], np.ones(len(sel)), width=1.0, color=OUTCOME_COLORS[k], ec="w",
                      lw=0.3 if len(rows) < 120 else 0, label=f"{k} ({len(sel)})")
            mc = np.array([np.nan if rows[i]["min_clearance"] is None else rows[i]["min_clearance"] for i in sel])
            ax[1].plot(pos[sel], mc, "o", color=OUTCOME_COLORS[k], ms=4)
    ax[0].set_yticks([])
    ax[0].set_ylim(0, 1)
    ax[0].legend(fontsize=7, ncol=4, loc="lower center", bbox_to_anchor=(0.5, 1.0), frameon=False)
    ax[1].axhline(0.0, color="k", lw=0.8)
    ax[1].set_ylabel("min clearance [m]")
    ax[1].set_xlabel("seed")
    step = max(1, int(math.ceil(len(rows) / 20)))
    ax[1].set_xticks(pos[::step], [str(s) for s in seeds[::step]], fontsize=7)
    ax[1].set_xlim(-0.5, len(rows) - 0.5)
    fig.suptitle(f"{name}: per seed", fontsize=9)
    paths.append(_save(fig, out / SWEEP_FILES[3]))
    return paths


def _main(argv=None) -> int:
    """python -m experiments.plots episode LOG OUT | sweep RESULTS OUT (a convenience; the CLI proper is dodt-nav)."""
    import sys

    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) != 3 or args[0] not in ("episode", "sweep"):
        print("usage: python -m experiments.plots episode LOG_OR_RUN_DIR OUT_DIR | sweep RESULTS_OR_DIR OUT_DIR",
              file=sys.stderr)
        return 2
    try:
        paths = (plot_episode if args[0] == "episode" else plot_sweep)(args[1], args[2])
    except (OSError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    for p in paths:
        print(p)
    return 0


if __name__ == "__main__":
    raise SystemExit(_main())
