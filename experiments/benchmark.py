"""`dodt-nav benchmark nav`: the navigation benchmark over scenario families, perception modes, people who
do or do not see the drone, and a named seed split.

Seeds come in two disjoint splits: ``dev`` (seeds from 0) for tuning and choosing, and ``test`` (seeds
from 1000) for the figures that are reported, run once per change that is kept. Every cell (family,
people setting, perception mode) is a sweep folder (experiments.sweep) under ``OUT/<family>/<people>/
<perception>/``, appended to as episodes end, so a killed benchmark resumes where it stopped; all cells'
episodes share one pool of workers. ``report.json`` and ``report.md`` hold, per cell: success, at-fault,
not-at-fault-only and timeout rates with 95 % Wilson intervals, median time to goal, the distribution of
the closest approach to a person, the drone's speed at each contact; ``plots/<family>.png`` one figure
per family. Collisions are classed by experiments.fault.
"""
from __future__ import annotations

import json
import re
import subprocess
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from experiments.config import Settings
from experiments.environment import distinct
from experiments.episode_config import EpisodeConfig
from experiments.figures import new_figure, save_figure
from experiments.registry import configured, planner_label
from experiments.sweep import (RESULTS, SweepError, _append, _dist, _end_with_newline, _Progress, aggregate,
                               check_same_setup, describe_environment, read_results, run_tasks)
from sim import load_scenario

FAMILIES = ("corridor", "corridor4", "crossing", "head_on", "step_out", "overtaking", "static_clutter")
MODES = ("dodt", "oracle", "static-only")
PEOPLE = {"blind": False, "aware": True}  # people who do not see the drone (the paper's), and who do
SPLITS = {"dev": 0, "test": 1000}  # first seed of each split; a split holds SPLIT_SIZE seeds
SPLIT_SIZE = 1000
REPORTED = ("success", "at_fault", "not_at_fault_only", "timeout")


@dataclass(frozen=True)
class Cell:
    family: str
    people: str  # a key of PEOPLE
    perception: str

    @property
    def folder(self) -> str:
        # a plug-in's module:Class spec becomes a name a folder may have
        return f"{self.family}/{self.people}/{re.sub(r'[^A-Za-z0-9_.+-]', '_', self.perception)}"


def split_seeds(split: str, count: int | str) -> list[int]:
    """The seeds of a split: ``count`` the first N (an int or its text), or ``"start:stop"`` seeds start to
    stop - 1, which must lie in the split (fresh seeds of ``dev`` that no earlier choice has seen)."""
    if split not in SPLITS:
        raise SweepError(f"--split: {split!r} is not one of {', '.join(SPLITS)}")
    first, last = SPLITS[split], SPLITS[split] + SPLIT_SIZE - 1
    text = str(count).strip()
    try:
        numbers = [int(v) for v in text.split(":", 1)]
    except ValueError:
        raise SweepError(f"--seeds: {text!r} is not N or start:stop (whole numbers)") from None
    if len(numbers) == 2:
        lo, hi = numbers
        if not first <= lo < hi <= last + 1:
            raise SweepError(f"--seeds: {text!r} must be a non-empty range within the {split} split's seeds "
                             f"{first}-{last} (stop excluded)")
        return list(range(lo, hi))
    n = numbers[0]
    if not 1 <= n <= SPLIT_SIZE:
        raise SweepError(f"--seeds: must be between 1 and {SPLIT_SIZE}, got {n}")
    return list(range(first, first + n))


def _scenario(family: str, people: str):
    sc = load_scenario(family)
    return sc.with_values({"crowd.sees_drone": PEOPLE[people]}) if sc.people else sc


def run_benchmark(out: Path, split: str, count: int | str, families=FAMILIES, modes=MODES, people=tuple(PEOPLE),
                  jobs: int = 1, dask_address: str | None = None, cfg=None, progress: bool = True,
                  settings=None, planner: str | None = None, shield: bool = False) -> dict:
    """Run what is missing of the benchmark into ``out``; write and return the report. count: the split's
    seeds (split_seeds: N, or "start:stop"). settings: configuration
    overrides (experiments.config); planner: a ``module:Class`` spec, None for the default planner; shield:
    the plug-in planner behind the passive-safety shield."""
    settings = settings or Settings()
    cfg = configured(settings, "episode", cfg or EpisodeConfig())
    seeds = split_seeds(split, count)
    out = Path(out)
    cells, scenarios = [], {}
    for family in families:
        for p in people:
            if p not in PEOPLE:
                raise SweepError(f"--people: {p!r} is not one of {', '.join(PEOPLE)}")
            sc = _scenario(family, p)
            if not sc.people and p != people[0]:
                continue  # nobody to see the drone: one setting says it all
            scenarios[(family, p)] = sc
            cells += [Cell(family, p, m) for m in modes]
    done: dict[Cell, dict[int, dict]] = {}
    for c in cells:
        folder = out / c.folder
        folder.mkdir(parents=True, exist_ok=True)
        _end_with_newline(folder / RESULTS)
        done[c] = read_results(folder / RESULTS)
        wrong = [s for s in done[c].values() if s.get("perception") != c.perception
                 or s.get("static_map", "depth") != cfg.static_map or s.get("frame_latency") != cfg.frame_latency]
        if wrong:
            raise SweepError(f"{folder}: holds results of another configuration (perception, static map or frame "
                             f"latency); use another --out folder")
        check_same_setup(folder / RESULTS, done[c].values(), settings, planner_label(planner, shield))
    if jobs > 1 or dask_address:
        cfg = replace(cfg, render_process=False)  # the cores are busy with episodes already
    tasks = [(c, (scenarios[(c.family, c.people)], seed, c.perception, str(out / c.folder / "episodes"), False, cfg,
                  settings, planner, shield))
             for seed in seeds for c in cells if seed not in done[c]]
    total = len(seeds) * len(cells)
    bar = _Progress(total, total - len(tasks)) if progress and tasks else None

    def finished(cell: Cell, summary: dict) -> None:
        _append(out / cell.folder / RESULTS, summary)
        done[cell][int(summary["seed"])] = summary
        if bar:
            bar.tick(summary)

    t0 = time.perf_counter()
    run_tasks(tasks, jobs, dask_address, finished)
    if bar:
        bar.close()
    report = build_report(out, split, seeds, cells, done)
    if planner is not None:
        report["planner"] = planner_label(planner, shield)
    if settings:
        report["config"] = {"set": settings.assignments()}
    report["wall_s_this_run"] = round(time.perf_counter() - t0, 1)
    (out / "report.json").write_text(json.dumps(report, indent=1))
    (out / "report.md").write_text(markdown(report))
    plot_families(report, out / "plots")
    return report


def _commit() -> str | None:
    try:
        r = subprocess.run(["git", "-C", str(Path(__file__).resolve().parent), "describe", "--always", "--dirty"],
                           capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return r.stdout.strip() or None if r.returncode == 0 else None


def build_report(out: Path, split: str, seeds: list[int], cells: list[Cell], done: dict) -> dict:
    rows, envs = [], []
    for c in cells:
        summaries = [done[c][s] for s in seeds if s in done[c]]
        if not summaries:
            continue
        agg = aggregate(summaries, c.family, c.perception)
        person = [s["min_clearance"]["person"] for s in summaries if s["min_clearance"]["person"] is not None]
        rigs = sorted({str(s.get("rig", "front")) for s in summaries})
        # time to moving, pooled over the cell's stretches (experiments.episode_metrics)
        lat = [x for s in summaries for x in (s.get("track_life") or {}).get("moving_latencies", ())]
        unreported = sum((s.get("track_life") or {}).get("moving_latency_unreported") or 0 for s in summaries)
        rows.append({"family": c.family, "people": c.people, "perception": c.perception, "rig": ", ".join(rigs),
                     "episodes": agg["episodes"], "rates": agg["rates"],
                     "time_to_goal_median": agg["time_to_goal"].get("median"),
                     "min_person_clearance": _dist(person), "contact_speeds": agg["contact_speeds"],
                     "failed_seeds": [r["seed"] for r in agg["per_seed"] if not r["success"]],
                     "module_errors": agg["module_errors"],
                     "moving_latency": {"n": len(lat), "unreported": unreported,
                                        "median": float(np.median(lat)) if lat else None,
                                        "p90": float(np.percentile(lat, 90)) if lat else None}})
        envs += agg["environments"]
    return {"split": split, "seeds": [seeds[0], seeds[-1]], "seeds_per_cell": len(seeds), "commit": _commit(),
            "environments": distinct(envs), "cells": rows}


def _pct(r: dict) -> str:
    return f"{100 * r['rate']:.1f} [{100 * r['ci95'][0]:.1f}, {100 * r['ci95'][1]:.1f}]"


def markdown(report: dict) -> str:
    a, b = report["seeds"]
    L = [f"# Navigation benchmark, {report['split']} split (seeds {a}-{b})", "",
         f"Commit {report.get('commit') or 'unknown'}. Rates in % of episodes with 95 % Wilson intervals; "
         "collisions classed by fault (experiments.fault): at fault = the drone moved into a person or touched "
         "structure; not at fault only = hit while at rest or from behind while moving away. "
         "People: blind = they do not see the drone, aware = they see it and give way."
         + (f" Planner: {report['planner']}." if report.get("planner") else "")
         + (" Configuration overrides: " + ", ".join(f"{k}={v}" for k, v in report["config"]["set"].items()) + "."
            if report.get("config") else ""), "",
         "| family | people | perception | rig | n | success | at-fault collision | only not-at-fault collisions | "
         "timeout | median time to goal [s] | closest to a person, p5 / median [m] |",
         "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in report["cells"]:
        cl = r["min_person_clearance"]
        close = f"{cl['p5']:.2f} / {cl['median']:.2f}" if cl.get("n") else "-"
        ttg = "-" if r["time_to_goal_median"] is None else f"{r['time_to_goal_median']:.1f}"
        L.append(f"| {r['family']} | {r['people']} | {r['perception']} | {r.get('rig', 'front')} | {r['episodes']} | "
                 + " | ".join(_pct(r["rates"][k]) for k in REPORTED) + f" | {ttg} | {close} |")
    speeds = [(r, k, v) for r in report["cells"] for k, v in r["contact_speeds"].items()]
    if speeds:
        L += ["", "Drone speed at each contact [m/s], by fault class:", ""]
        for r, k, v in speeds:
            L.append(f"- {r['family']} / {r['people']} / {r['perception']}, {k}: " + ", ".join(f"{x:.2f}" for x in v))
    lat = [r for r in report["cells"] if (r.get("moving_latency") or {}).get("n")]
    if lat:
        L += ["", "Time to moving: from a walking person's first frame 0.5-5 m away in the rig's horizontal view to "
              "the first frame a track labelled dynamic lies on the person, median / 90th percentile [s] (stretches "
              "reported; never reported):", ""]
        for r in lat:
            m = r["moving_latency"]
            L.append(f"- {r['family']} / {r['people']} / {r['perception']}: {m['median']:.2f} / {m['p90']:.2f} "
                     f"({m['n']}; {m['unreported']})")
    errs = [(r, e["seed"]) for r in report["cells"] for e in r.get("module_errors") or []]
    if errs:
        L += ["", f"Episodes in which the planner or perception failed ({len(errs)}; each episode folder's "
              "errors.txt has the first traceback): "
              + "; ".join(f"{r['family']} / {r['people']} / {r['perception']} seed {seed}" for r, seed in errs)]
    envs = report.get("environments") or []
    if envs:
        L += ["", "Machine and installation: " + "; ".join(describe_environment(e) for e in envs)]
    return "\n".join(L) + "\n"


def plot_families(report: dict, out: Path) -> list[Path]:
    """One figure per family: the reported rates of every (people, perception) cell, with intervals."""
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    colors = {"success": "tab:green", "at_fault": "tab:red", "not_at_fault_only": "tab:orange",
              "timeout": "tab:gray"}
    for family in dict.fromkeys(r["family"] for r in report["cells"]):
        rows = [r for r in report["cells"] if r["family"] == family]
        fig, ax = new_figure((max(6.0, 1.6 * len(rows) + 2), 4.5))
        x = np.arange(len(rows))
        w = 0.8 / len(REPORTED)
        for i, k in enumerate(REPORTED):
            v = np.array([100 * r["rates"][k]["rate"] for r in rows])
            lo = v - np.array([100 * r["rates"][k]["ci95"][0] for r in rows])
            hi = np.array([100 * r["rates"][k]["ci95"][1] for r in rows]) - v
            ax.bar(x + (i - 1.5) * w, v, w, color=colors[k], label=k.replace("_", " "))
            ax.errorbar(x + (i - 1.5) * w, v, yerr=[lo, hi], fmt="none", ecolor="k", capsize=2, lw=0.8)
        ax.set_xticks(x, [f"{r['perception']}\n{r['people']}" for r in rows], fontsize=8)
        ax.set_ylim(0, 105)
        ax.set_ylabel("% of episodes (95 % Wilson interval)")
        ax.set_title(f"{family}: {report['split']} split, {rows[0]['episodes']} seeds per cell", fontsize=9)
        ax.legend(fontsize=7, ncol=4, loc="upper center", bbox_to_anchor=(0.5, -0.18))
        paths.append(save_figure(fig, out / f"{family}.png", tight=True))
    return paths
