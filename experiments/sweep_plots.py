"""PNG figures of a sweep, drawn from its ``results.jsonl`` (experiments.sweep) or a list of episode
summaries after the run.

``plot_sweep(results, out_dir)`` writes ``sweep_outcomes.png`` (counts with 95 % Wilson intervals),
``sweep_time_to_goal.png``, ``sweep_min_clearance.png`` and ``sweep_per_seed.png``. File names
are fixed; the same input gives the same PNG.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from experiments.figures import COLLISION_COLOR, new_figure, save_figure, show_message
from experiments.sweep import RESULTS, aggregate, read_results, wilson

OUTCOME_COLORS = {"success": "tab:green", "collision": COLLISION_COLOR, "timeout": "tab:orange",
                  "other": "tab:purple"}

SWEEP_FILES = ("sweep_outcomes.png", "sweep_time_to_goal.png", "sweep_min_clearance.png", "sweep_per_seed.png")


def _load_summaries(results) -> list[dict]:
    """Summaries from a results.jsonl path (or the sweep folder holding it) or a list of summary dicts."""
    if isinstance(results, (str, Path)):
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
    def one(key):
        vals = sorted({str(s.get(key)) for s in summaries})
        return vals[0] if len(vals) == 1 else "+".join(vals)

    # aggregate() also reads these; default them so hand-made summaries plot too.
    full = [{"mean_speed": 0.0, "planner_stats": {"fallbacks": 0}, "collision_count": int(s["collided"]),
             "failure_reason": None, **s} for s in summaries]
    return aggregate(full, one("scenario"), one("perception"))


def _label_histogram(ax, xlabel: str) -> None:
    """Legend and axis labels of a histogram of episodes."""
    ax.legend(fontsize=7)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("episodes")


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
    paths.append(save_figure(fig, out / SWEEP_FILES[0]))

    # Time to goal of the episodes that reached it.
    ttg = np.array([s["time_to_goal"] for s in summaries if s.get("reached_goal") and s["time_to_goal"] is not None],
                   dtype=float)
    fig, ax = new_figure((7, 4.5))
    if len(ttg):
        ax.hist(ttg, bins=min(30, max(5, int(np.sqrt(len(ttg))) * 2)), color="tab:blue", alpha=0.8, ec="k", lw=0.5)
        d = agg["time_to_goal"]
        ax.axvline(d["median"], color="k", ls="--", lw=1, label=f"median {d['median']:.2f} s")
        ax.axvline(d["p95"], color="0.5", ls=":", lw=1, label=f"p95 {d['p95']:.2f} s")
        _label_histogram(ax, "time to goal [s]")
    else:
        show_message(ax, "no episode reached the goal")
    ax.set_title(f"{name}: time to goal ({len(ttg)} reached it)", fontsize=9)
    paths.append(save_figure(fig, out / SWEEP_FILES[1]))

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
        _label_histogram(ax, "minimum clearance over the episode [m]")
    else:
        show_message(ax, "no clearance figures in these summaries")
    ax.set_title(f"{name}: minimum clearance", fontsize=9)
    paths.append(save_figure(fig, out / SWEEP_FILES[2]))

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
    paths.append(save_figure(fig, out / SWEEP_FILES[3]))
    return paths
