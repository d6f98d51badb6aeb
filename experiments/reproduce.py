"""`dodt-nav reproduce`: the paper's tables and our navigation figures in one report.

Runs the perception benchmark (Table I), the runtime benchmark (Table II) and the corridor
navigation sweeps (dodt, oracle, static-only), then writes ``report.md`` with the figures embedded
and the paper's numbers beside ours. ``--quick`` shrinks every part (fewer configurations, shorter
scenarios, fewer seeds) to finish in minutes; its figures are a smoke test, not results.
"""
from __future__ import annotations

import json
import time
import re
from dataclasses import dataclass, replace
from pathlib import Path

from dodt.pipeline import MODULES
from dodt.presets import preset
from experiments import bench_perception, sweep
from experiments.environment import distinct
from experiments.runtime_plots import plot_runtime_table
from experiments.sweep_plots import plot_sweep


@dataclass(frozen=True)
class Plan:
    perception_configs: tuple[str, ...]
    perception_scenarios: tuple[str, ...]
    perception_duration: float | None
    runtime_seconds: float
    nav_seeds: dict[str, int]  # perception mode -> number of seeds (0..N-1)


FULL = Plan(perception_configs=("method-1-umap", "method-2-cluster", "method-3-udepth-velocity", "dodt-no-ensemble",
                                "dodt-no-fat", "dodt"),
            perception_scenarios=bench_perception.SCENARIOS, perception_duration=None, runtime_seconds=6.0,
            nav_seeds={"dodt": 100, "oracle": 100, "static-only": 40})
QUICK = Plan(perception_configs=("dodt-no-ensemble", "dodt-no-fat", "dodt"),
             perception_scenarios=("circles", "wall_pass", "corridor"), perception_duration=6.0, runtime_seconds=3.0,
             nav_seeds={"dodt": 6, "oracle": 4, "static-only": 2})

RUNTIME_CONFIG = "dodt"  # the configuration Table II times

DIFFERENCES = """\
## What differs between the paper's setup and ours

- **Sensor.** The paper used a real RealSense D435i. We render depth with our own OpenGL renderer
  (`sim/gl_renderer.py`: moderngl on Mesa's EGL, software rendering on a CPU); where it cannot start,
  PyBullet's EGL plugin or its TinyRenderer stands in, with the same image geometry (the Environment
  line above names the renderer that ran). We add the Intel RMS stereo noise model (subpixel 0.08,
  baseline 50 mm), edge holes, flying pixels and dropouts. Real stereo artefacts (textureless surfaces,
  IR interference, motion blur) are not modelled.
- **People.** The paper filmed real people. Ours are the DeepMimic humanoid posed kinematically from a
  walking clip, its limbs thin capsules. They walk their routes under the social force model of
  Helbing & Molnar (`sim/crowd.py`): they avoid each other, and the drone only where a scenario says
  they see it (`crowd.sees_drone`, off in every shipped scenario). Several detector thresholds are
  lower than the reference code's because the limbs are thin (each one is stated in `dodt/config.py`).
- **Ground truth.** The paper took ground truth from motion capture; ours comes from the simulator's
  exact boxes. Matching rules are stated in the benchmark output.
- **Compute.** The paper ran C++ on an Intel NUC or Jetson. We run Python (numba for the hot loops) on
  the CPU the Environment line names, one thread for the perception timings.
- **Navigation.** The paper reports a 15 m flight among two walking people. It does not report a
  collision rate over seeds, and it does not say which of the authors' planners flew. Our planner is a
  linear MPC on OSQP along an A* path (Intent-MPC style). Collision, at-fault and success rates here
  are our own measure of the closed loop, not a number taken from the paper; a collision is at fault
  when the drone caused it (`experiments/fault.py` states the rule).
"""


def _folder(mode: str) -> str:
    """The navigation sweep's folder of a perception mode (a plug-in's module:Class made a file name)."""
    return "nav_" + re.sub(r"[^A-Za-z0-9_.-]+", "_", mode)


NAV_HEADER = ("| perception | episodes | success | collision | at fault | timeout | median time to goal [s] "
              "| median mean speed [m/s] |")


def _md_rates(agg: dict) -> str:
    """A navigation sweep's row under NAV_HEADER (experiments.sweep.aggregate's rates, 95 % intervals)."""
    r = agg["rates"]
    f = lambda k: f"{100 * r[k]['rate']:.1f} % [{100 * r[k]['ci95'][0]:.1f}, {100 * r[k]['ci95'][1]:.1f}]"  # noqa: E731
    ttg = agg["time_to_goal"]
    spd = agg["mean_speed"]
    return (f"| {agg['perception']} | {agg['episodes']} | {f('success')} | {f('collision')} | {f('at_fault')} | "
            f"{f('timeout')} | {ttg.get('median', '-')} | {spd.get('median', '-')} |")


def runtime_rows(rt: dict, config: str) -> list[tuple]:
    """Table II's rows from ``bench_perception.run_runtime(config)``: (module, median_ms, p95_ms, paper_ms),
    one per pipeline module and the total; a module the configuration does not run (the learned detector
    without ``learned.enabled``) has None for its times, not the 0 ms the pipeline records for it."""
    learned_on = preset(config).learned.enabled
    rows = []
    for m in MODULES + ("total",):
        ran = m != "learned" or learned_on
        v = rt[m]
        rows.append((m, v["median_ms"] if ran else None, v["p95_ms"] if ran else None,
                     bench_perception.PAPER_TABLE_II.get(m)))
    return rows


def _md_runtime_row(module: str, med, p95, paper, config: str) -> str:
    """One row of the report's Table II; a module that did not run says so."""
    ms = lambda x: "-" if x is None else f"{x:.2f}"  # noqa: E731
    if med is None:
        return (f"| {module} | not run (`{config}` has no learned detector; `dodt-nav bench runtime --config "
                f"dodt+yolo` times it) | - | {ms(paper)} |")
    return f"| {module} | {ms(med)} | {ms(p95)} | {ms(paper)} |"


def reproduce(out: Path, quick: bool = False, jobs: int = 2, plan: Plan | None = None, scenario: str = "corridor",
              settings=None, planner: str | None = None, perception: tuple[str, ...] = (), shield: bool = False) -> Path:
    """Run every part and write out/report.md; ``plan`` overrides the FULL / QUICK sizes (tests). settings
    (experiments.config) and planner (a ``module:Class`` spec, None: the default) apply to the navigation
    sweeps (``shield``: the plug-in planner behind the passive-safety shield); Tables I and II measure the DODT
    presets as they are. perception: ``module:Class`` specs of
    perception plug-ins, each flown in one more navigation sweep with as many seeds as dodt."""
    plan = plan or (QUICK if quick else FULL)
    if perception:
        n = plan.nav_seeds.get("dodt", max(plan.nav_seeds.values(), default=1))
        plan = replace(plan, nav_seeds={**plan.nav_seeds, **{p: n for p in perception}})
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    timings = {}

    t = time.perf_counter()
    print("== Table I: perception benchmark", flush=True)
    bench_perception.run(out / "perception", [0], plan.perception_scenarios, list(plan.perception_configs),
                         plan.perception_duration)
    timings["perception benchmark"] = time.perf_counter() - t

    t = time.perf_counter()
    print("== Table II: runtime", flush=True)
    rt = bench_perception.run_runtime(RUNTIME_CONFIG, scenario, seconds=plan.runtime_seconds,
                                      json_out=out / "runtime.json")
    rows = runtime_rows(rt, RUNTIME_CONFIG)
    plot_runtime_table(rows, out / "runtime.png", title="DODT per-frame runtime, 640x480, one thread")
    timings["runtime benchmark"] = time.perf_counter() - t

    nav = {}
    for mode, n in plan.nav_seeds.items():
        t = time.perf_counter()
        print(f"== navigation sweep: {scenario}, {mode}, seeds 0:{n}", flush=True)
        agg = sweep.run_sweep(scenario, list(range(n)), mode, out / _folder(mode), jobs=jobs, settings=settings,
                              planner=planner, shield=shield)
        plot_sweep(out / _folder(mode) / sweep.RESULTS, out / _folder(mode))
        nav[mode] = agg
        timings[f"navigation sweep ({mode}, {n} seeds)"] = time.perf_counter() - t

    table_i = (out / "perception" / "table.md").read_text()
    L = ["# DODT reproduction report", "",
         f"Generated by `dodt-nav reproduce{' --quick' if quick else ''}` in {time.perf_counter() - t0:.0f} s "
         f"({'quick: a smoke test, too small for conclusions' if quick else 'full run'})."
         + (f" Navigation planner: {planner}." if planner else "")
         + (" Configuration overrides of the navigation sweeps: "
            + ", ".join(f"{k}={v}" for k, v in settings.assignments().items()) + "." if settings else ""), "",
         "## Table I: detection and tracking accuracy (ours beside the paper's)", "", table_i, "",
         *[f"![errors over time and tracks against ground truth, {sn}](perception/{kind}_{sn}.png)"
           for sn in plan.perception_scenarios[-1:] for kind in ("errors", "topdown")], "",
         "## Table II: runtime per frame (ms)", "",
         "| module | median | p95 | paper, Intel NUC |", "|---|---|---|---|"]
    L += [_md_runtime_row(*row, RUNTIME_CONFIG) for row in rows]
    L += ["", "![runtime](runtime.png)", "",
          f"## Navigation: `{scenario}`" + (" (15 m corridor, two people walking randomly)" if scenario == "corridor" else ""), "",
          "Success = reached the goal with no collision before the time limit; at fault = at least one collision "
          "the drone caused (`experiments/fault.py`); rates with 95 % Wilson intervals.", "",
          NAV_HEADER, "|---|---|---|---|---|---|---|---|"]
    L += [_md_rates(a) for a in nav.values()]
    envs = distinct(e for a in nav.values() for e in a.get("environments", []))
    if envs:
        L += ["", "Environment (outcomes agree bit for bit only within one; compare sweeps run in the same): "
              + "; ".join(sweep.describe_environment(e) for e in envs)]
    for mode in nav:
        L += ["", f"### {mode}", "", f"![outcomes]({_folder(mode)}/sweep_outcomes.png)",
              f"![min clearance]({_folder(mode)}/sweep_min_clearance.png)", "",
              f"Per-seed results: `{_folder(mode)}/summary.md`; failed episodes keep their logs under "
              f"`{_folder(mode)}/episodes/` (`dodt-nav replay` turns one into an HTML replay)."]
    L += ["", DIFFERENCES, "## Wall time of each part", ""]
    L += [f"- {k}: {v:.0f} s" for k, v in timings.items()]
    report = out / "report.md"
    report.write_text("\n".join(L) + "\n")
    (out / "report.json").write_text(json.dumps({"navigation": nav, "runtime": rt, "timings_s": timings}, indent=1))
    print(f"wrote {report}")
    return report
