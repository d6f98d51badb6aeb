"""Navigation sweeps: many seeds of one scenario and perception mode, resumable, gated.

Each finished episode's summary is appended to ``results.jsonl`` (flushed and fsynced) the moment
it completes, so a sweep killed at any point (even ``kill -9``) loses at most the episodes that
were running; rerunning the same command skips every seed already in the file. Logs are kept for
failed episodes (``episodes/seed_NNNN/``), for all with ``keep_logs``.

Aggregates: success, collision and timeout rates with 95 % Wilson score intervals, time to goal
and minimum clearance distributions, per-seed outcomes (``summary.json``, ``summary.md``),
optionally JUnit XML with one test case per seed.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import sys
import time
import xml.etree.ElementTree as ET
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import replace
from pathlib import Path

import numpy as np

from experiments.environment import distinct
from sim import load_scenario
from experiments.config import Settings
from experiments.episode import EpisodeConfig, run_episode
from experiments.registry import DEFAULT_PLANNER_LABEL, configured, planner_label

RESULTS = "results.jsonl"
SEED_MAX = 2**63 - 1  # what a scenario file's seed (a TOML integer) holds


class SweepError(ValueError):
    """A user mistake in a sweep request (reported in one line by the CLI)."""


MAX_SEEDS = 1_000_000  # episodes one command may start


def parse_seeds(text: str) -> list[int]:
    """'0:200' (start:stop), '3', or '1,4,9' -> sorted unique seeds."""
    out: set[int] = set()
    try:
        for part in text.split(","):
            part = part.strip()
            if ":" in part:
                a, b = part.split(":", 1)
                lo, hi = int(a), int(b)
                if hi <= lo:
                    raise SweepError(f"--seeds: empty range {part!r} (stop must be greater than start)")
                if hi - lo > MAX_SEEDS:
                    raise SweepError(f"--seeds: range {part!r} is longer than {MAX_SEEDS} seeds")
                out.update(range(lo, hi))
                if len(out) > MAX_SEEDS:
                    raise SweepError(f"--seeds: {text!r} names more than {MAX_SEEDS} seeds in all")
            elif part:
                out.add(int(part))
    except ValueError as e:
        if isinstance(e, SweepError):
            raise
        raise SweepError(f"--seeds: {text!r} is not a seed list (examples: 0:200, 5, 1,4,9)") from None
    if not out or min(out) < 0 or max(out) > SEED_MAX:
        raise SweepError(f"--seeds: {text!r}: seeds must be non-negative whole numbers, at most {SEED_MAX}")
    return sorted(out)




def wilson(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval of a proportion k/n (scipy.stats.binomtest); no trials: (0, 1)."""
    if n == 0:
        return (0.0, 1.0)
    from scipy.stats import binomtest

    ci = binomtest(int(k), int(n)).proportion_ci(confidence_level=confidence, method="wilson")
    return (max(0.0, float(ci.low)), min(1.0, float(ci.high)))


def run_one(scenario, seed: int, perception: str, episodes_dir: str, keep_log: bool,
            cfg: EpisodeConfig = EpisodeConfig(), settings: Settings | None = None, planner: str | None = None,
            shield: bool = False) -> dict:
    """One episode in a worker (module-level so process pools and Dask can ship it). perception and planner
    are names or ``module:Class`` specs, resolved here (experiments.registry); settings: the overrides
    (experiments.config); shield: a plug-in planner behind the passive-safety shield."""
    out = Path(episodes_dir) / f"seed_{seed:04d}"
    s = run_episode(scenario, seed=seed, perception=perception, planner=planner, out=out, cfg=cfg, settings=settings,
                    shield=shield)
    if s["success"] and not keep_log:
        shutil.rmtree(out, ignore_errors=True)
    return s


RESULT_KEYS = ("seed",)  # what every results row (an episode summary, a JSON object) holds at least


MAX_RESULT_LINE = 4 << 20  # bytes of one results row (an episode summary is some kilobytes)
MAX_RESULTS_BYTES = 1 << 30  # bytes of a results file: some hundred thousand episodes


def read_results(path: Path) -> dict[int, dict]:
    """Seed -> summary from a results file; a line cut short by a kill is ignored, and a file that is not a
    results file (not a regular file, larger than MAX_RESULTS_BYTES, a line longer than MAX_RESULT_LINE, not
    UTF-8 text, rows that are not episode summaries, seeds that are not whole numbers) is a SweepError naming
    the file and the line. Read line by line, no line further than its limit."""
    done: dict[int, dict] = {}
    if not path.exists():
        return done
    if not path.is_file():
        raise SweepError(f"{path}: not a regular file; not a results file")
    total = 0
    try:
        with open(path, "rb") as fh:
            for n, raw in enumerate(iter(lambda: fh.readline(MAX_RESULT_LINE + 1), b""), 1):
                total += len(raw)
                if len(raw) > MAX_RESULT_LINE:
                    raise SweepError(f"{path}, line {n}: longer than {MAX_RESULT_LINE >> 20} MiB; not a results file")
                if total > MAX_RESULTS_BYTES:
                    raise SweepError(f"{path}: larger than {MAX_RESULTS_BYTES >> 30} GiB; split the sweep into "
                                     f"several folders")
                try:
                    line = raw.decode("utf-8")
                except UnicodeDecodeError as e:
                    raise SweepError(f"{path}, line {n}: not UTF-8 text (byte {e.start} of the line); not a results "
                                     f"file") from None
                try:
                    r = json.loads(line)
                except json.JSONDecodeError:
                    continue  # the last line of a killed run
                except RecursionError:
                    raise SweepError(f"{path}, line {n}: nested too deep; not a results file") from None
                except ValueError as e:  # an integer of more digits than Python converts
                    raise SweepError(f"{path}, line {n}: {str(e)[:120]}; not a results file") from None
                seed = r.get("seed") if isinstance(r, dict) else None
                if not isinstance(r, dict) or any(k not in r for k in RESULT_KEYS):
                    raise SweepError(f"{path}, line {n}: not an episode summary (a results file holds one per "
                                     f"line, written by dodt-nav sweep)")
                if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= SEED_MAX:
                    raise SweepError(f"{path}, line {n}: seed {seed!r} is not a whole number in [0, {SEED_MAX}]")
                done[seed] = r
    except OSError as e:
        raise SweepError(f"{path}: cannot read it: {e.strerror or e}") from None
    return done


def _end_with_newline(path: Path) -> None:
    """A line cut short by a kill has no newline: end it, so the next result starts a line of its own."""
    if path.exists() and path.stat().st_size > 0:
        with open(path, "rb+") as fh:
            fh.seek(-1, os.SEEK_END)
            if fh.read(1) != b"\n":
                fh.write(b"\n")


def _append(path: Path, summary: dict) -> None:
    with open(path, "a", encoding="utf-8") as fh:
        fh.write(json.dumps(summary, separators=(",", ":")) + "\n")
        fh.flush()
        os.fsync(fh.fileno())


class _Progress:
    """The progress bar of a sweep or benchmark (tqdm): episodes done of all, failures, time left. It writes
    nothing unless ``stream`` is a terminal (a log file or a CI job gets no bar)."""

    def __init__(self, total: int, done: int, stream=None):
        from tqdm import tqdm

        stream = sys.stderr if stream is None else stream
        self.failures = 0
        self.bar = tqdm(total=total, initial=done, unit="episode", file=stream, dynamic_ncols=True,
                        disable=not (hasattr(stream, "isatty") and stream.isatty()))

    def tick(self, s: dict) -> None:
        self.failures += not s["success"]
        self.bar.set_postfix_str(f"{self.failures} failed", refresh=False)
        self.bar.update(1)

    def close(self) -> None:
        self.bar.close()


def run_sweep(scenario: str, seeds: list[int], perception: str, out: Path, jobs: int = 1,
              dask_address: str | None = None, keep_logs: bool = False, progress: bool = True,
              cfg: EpisodeConfig = EpisodeConfig(), settings: Settings | None = None,
              planner: str | None = None, shield: bool = False) -> dict:
    """Run the seeds not yet in ``out/results.jsonl``; return the aggregate over all requested seeds.
    cfg: every episode's settings (experiments.episode.EpisodeConfig); a folder holds results of one
    static map and one frame latency only. Episodes render in a second process only when they run one
    at a time here: with several at once the cores are busy already (the results are the same).
    settings: configuration overrides (experiments.config); planner: a ``module:Class`` spec or None for the
    default (experiments.plugins). A folder holds results of one planner and one set of overrides only."""
    settings = settings or Settings()
    cfg = configured(settings, "episode", cfg)
    if jobs > 1 or dask_address:
        cfg = replace(cfg, render_process=False)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    res_path = out / RESULTS
    done = read_results(res_path)
    _end_with_newline(res_path)
    clash = [s for s in done.values() if s.get("perception") != perception]
    if clash:
        raise SweepError(f"{res_path}: holds results of perception {clash[0].get('perception')!r}, not "
                         f"{perception!r}; use another --out folder")
    for key, what, old_default in (("static_map", "static map", "depth"), ("frame_latency", "frame latency", 0)):
        want = getattr(cfg, key)
        clash = [s for s in done.values() if s.get(key, old_default) != want]
        if clash:
            raise SweepError(f"{res_path}: holds results with the {what} {clash[0].get(key, old_default)!r}, not "
                             f"{want!r}; use another --out folder")
    check_same_setup(res_path, done.values(), settings, planner_label(planner, shield))

    name = load_scenario(scenario).name
    other = [s for s in done.values() if s.get("scenario") != name]
    if other:
        raise SweepError(f"{res_path}: holds results of scenario {other[0].get('scenario')!r}, not {name!r}; "
                         f"use another --out folder")
    todo = [s for s in seeds if s not in done]
    episodes_dir = str(out / "episodes")
    bar = _Progress(len(seeds), len(seeds) - len(todo)) if progress and todo else None
    t0 = time.perf_counter()

    def finished(s: dict) -> None:
        _append(res_path, s)
        done[int(s["seed"])] = s
        if bar:
            bar.tick(s)

    run_tasks([(None, (scenario, seed, perception, episodes_dir, keep_logs, cfg, settings, planner, shield))
               for seed in todo],
              jobs, dask_address, lambda _key, s: finished(s))
    if bar:
        bar.close()
    try:
        agg = aggregate([done[s] for s in seeds], name, perception, planner=planner_label(planner, shield),
                        settings=settings)
    except (KeyError, TypeError, ValueError, AttributeError) as e:  # rows read from the file lack a field
        raise SweepError(f"{res_path}: holds rows that are not whole episode summaries ({type(e).__name__}: "
                         f"{str(e)[:100]}); use another --out folder") from None
    agg["wall_s_this_run"] = round(time.perf_counter() - t0, 1)
    (out / "summary.json").write_text(json.dumps(agg, indent=1))
    (out / "summary.md").write_text(markdown(agg))
    return agg


def check_same_setup(res_path: Path, done, settings: Settings, want_planner: str) -> None:
    """Refuse a results file of another planner (``want_planner``: its label) or other configuration
    overrides (a row without the entries: the default planner, no overrides)."""
    want_set = settings.assignments()
    for s in done:
        if s.get("planner", DEFAULT_PLANNER_LABEL) != want_planner:
            raise SweepError(f"{res_path}: holds results of planner {s.get('planner')!r}, not {want_planner!r}; "
                             f"use another --out folder")
        if (s.get("config") or {}).get("set", {}) != want_set:
            raise SweepError(f"{res_path}: holds results of other configuration overrides "
                             f"({(s.get('config') or {}).get('set', {})} against {want_set}); use another --out folder")


def _exit_with_parent(parent_pid: int) -> None:
    """Pool worker initializer: the worker ends at once when the sweep that started it is gone
    (sim.parent_watch). A sweep killed alone (kill PID, a job scheduler's SIGTERM or SIGKILL to the main
    process) otherwise leaves its workers running: each finishes its episode and the ones queued behind it,
    results nobody writes, then sleeps for good holding its memory (seen: orphans alive 50 minutes after
    their sweep, 0.6 GB each). Ctrl-C, which a terminal sends to every process of the sweep, is ignored
    here: the sweep ends its workers then (a KeyboardInterrupt in each would print a traceback)."""
    from sim.parent_watch import exit_with_parent

    exit_with_parent(parent_pid)
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def run_tasks(tasks: list[tuple], jobs: int, dask_address: str | None, finished) -> None:
    """Run episodes: tasks are (key, run_one's arguments); finished(key, summary) is called in this process
    as each ends (in the order they end). One at a time here, in a pool of ``jobs`` processes, or on a Dask
    scheduler."""
    if not tasks:
        return
    if dask_address:
        _run_dask(dask_address, tasks, finished)
    elif jobs <= 1:
        for key, args in tasks:
            finished(key, run_one(*args))
    else:
        _run_pool(jobs, tasks, finished)


def _run_pool(jobs, tasks, finished) -> None:
    import multiprocessing as mp

    # spawn: every worker starts clean (PyBullet's EGL plugin and numba do not like forked parents).
    before = set(mp.active_children())
    ex = ProcessPoolExecutor(max_workers=jobs, mp_context=mp.get_context("spawn"), initializer=_exit_with_parent,
                             initargs=(os.getpid(),))
    done = False
    try:
        pending = {ex.submit(run_one, *args): key for key, args in tasks}
        while pending:
            ready, _ = wait(pending, return_when=FIRST_COMPLETED)
            for f in ready:
                finished(pending.pop(f), f.result())
        done = True
    finally:
        if not done:
            # An error, Ctrl-C or SIGTERM: the queued episodes are not run, and the running ones, whose results
            # nobody would write, are ended now instead of being waited for.
            for worker in set(mp.active_children()) - before:
                worker.terminate()
        ex.shutdown(wait=True, cancel_futures=True)


def _run_dask(address, tasks, finished) -> None:
    try:
        from dask.distributed import Client, as_completed
    except ImportError:
        raise SweepError("--dask needs the cluster extra: pip install -e '.[cluster]'") from None
    try:
        client = Client(address, timeout="10s")
    except (ValueError, OSError, TimeoutError) as e:
        raise SweepError(f"--dask: cannot connect to {address!r}: {e}") from None
    with client:
        # pure=False: every task gets a unique key, so sweeps sharing a scheduler never share results
        futures = {client.submit(run_one, *args, pure=False): key for key, args in tasks}
        for f in as_completed(list(futures)):
            finished(futures[f], f.result())


def _dist(values) -> dict:
    a = np.asarray([v for v in values if v is not None], dtype=float)
    if a.size == 0:
        return {"n": 0}
    q = np.percentile(a, [5, 25, 50, 75, 95])
    return {"n": int(a.size), "mean": round(float(a.mean()), 3), "min": round(float(a.min()), 3),
            "p5": round(float(q[0]), 3), "p25": round(float(q[1]), 3), "median": round(float(q[2]), 3),
            "p75": round(float(q[3]), 3), "p95": round(float(q[4]), 3), "max": round(float(a.max()), 3)}


def describe_environment(env: dict) -> str:
    """One line naming an episode's environment (experiments.environment) for a report."""
    pk = ", ".join(f"{k} {v}" for k, v in (env.get("packages") or {}).items() if v)
    over = ", ".join(f"{k}={v}" for k, v in (env.get("overrides") or {}).items())
    simd = "/".join(env.get("numpy_simd") or []) or "baseline"
    return (f"Python {env.get('python')}, {pk}; processor {env.get('cpu_model')} (compiled for {env.get('cpu')}, "
            f"NumPy SIMD {simd}, OpenBLAS {env.get('blas_core')}); renderer {env.get('renderer')}"
            + (f" (Mesa {env['mesa']})" if env.get("mesa") else "") + (f"; set: {over}" if over else ""))


# Episode outcomes counted by a sweep: each an indicator of every episode (they overlap: a timeout may
# have had a collision), with its rate and 95 % Wilson interval. experiments.fault says what is at fault.
OUTCOMES = {
    "success": lambda s: s["success"],  # goal reached, no collision of any kind
    "at_fault_free": lambda s: not s.get("at_fault", s["collided"]),
    "at_fault": lambda s: s.get("at_fault", s["collided"]),  # at least one collision the drone caused
    "not_at_fault_only": lambda s: s.get("not_at_fault_only", False),  # hit, but never at fault
    "collision": lambda s: s["collided"],  # any collision
    "timeout": lambda s: s["timeout"],
}


def rates_of(summaries: list[dict]) -> dict:
    n = len(summaries)
    counts = {k: sum(bool(f(s)) for s in summaries) for k, f in OUTCOMES.items()}
    return {k: {"count": c, "rate": round(c / n, 4) if n else 0.0,
                "ci95": [round(x, 4) for x in wilson(c, n)]} for k, c in counts.items()}


def contact_speeds(summaries: list[dict]) -> dict:
    """The drone's speed at each collision, by fault class: {class: [m/s, ...]}."""
    out: dict[str, list] = {}
    for s in summaries:
        for c in s.get("collisions", []):
            if c.get("drone_speed") is not None:
                out.setdefault(c.get("fault", "unclassified"), []).append(c["drone_speed"])
    return {k: sorted(v) for k, v in sorted(out.items())}


def aggregate(summaries: list[dict], scenario: str, perception: str, planner: str | None = None,
              settings: Settings | None = None) -> dict:
    """The sweep's summary; planner (its label, experiments.plugins.planner_label) and settings (the overrides)
    are recorded when given: ``planner`` and ``config`` (the overrides, ``set``, and the full values of each
    overridden section, as the episodes recorded them)."""
    n = len(summaries)
    rates = rates_of(summaries)
    extra = {}
    if planner is not None:
        extra["planner"] = planner
    if settings is not None:
        recorded = next((s["config"] for s in summaries if s.get("config")), None)
        extra["config"] = recorded if settings else {}
    return {
        "scenario": scenario, "perception": perception,
        "rig": ", ".join(sorted({str(s.get("rig", "front")) for s in summaries})) or None, **extra,
        "episodes": n, "rates": rates,
        "contact_speeds": contact_speeds(summaries),
        "time_to_goal": _dist(s["time_to_goal"] for s in summaries),
        "mean_speed": _dist(s["mean_speed"] for s in summaries if s["reached_goal"]),
        "min_clearance_person": _dist(s["min_clearance"]["person"] for s in summaries),
        "min_clearance_overall": _dist(s["min_clearance"]["overall"] for s in summaries),
        "planner_fallbacks": int(sum(s["planner_stats"]["fallbacks"] for s in summaries)),
        # episodes in which the planner or perception raised or returned malformed output (experiments.guards)
        "module_errors": [{"seed": s["seed"], **{m: e["count"] for m, e in s["module_errors"].items()}}
                          for s in sorted(summaries, key=lambda s: s["seed"]) if s.get("module_errors")],
        # the environments the episodes ran in (one, unless a sweep was resumed elsewhere)
        "environments": distinct(s.get("environment") for s in summaries),
        "per_seed": [{"seed": s["seed"], "success": s["success"], "collided": s["collided"],
                      "collisions": s["collision_count"], "timeout": s["timeout"],
                      "at_fault": s.get("at_fault", s["collided"]),
                      "faults": [c.get("fault", "unclassified") for c in s.get("collisions", [])],
                      "failure_reason": s["failure_reason"], "time_to_goal": s["time_to_goal"],
                      "min_clearance": s["min_clearance"]["overall"]} for s in sorted(summaries, key=lambda s: s["seed"])],
    }


def markdown(agg: dict) -> str:
    L = [f"# Sweep: {agg['scenario']}, perception {agg['perception']}, {agg['episodes']} episodes", "",
         *([f"Planner: {agg['planner']}", ""] if agg.get("planner") not in (None, DEFAULT_PLANNER_LABEL) else []),
         *(["Configuration overrides: " + ", ".join(f"{k}={v}" for k, v in agg["config"]["set"].items()), ""]
           if (agg.get("config") or {}).get("set") else []),
         "| outcome | count | rate | 95 % Wilson interval |", "|---|---|---|---|"]
    for k, r in agg["rates"].items():
        L.append(f"| {k} | {r['count']} | {100 * r['rate']:.1f} % | {100 * r['ci95'][0]:.1f}–{100 * r['ci95'][1]:.1f} % |")
    L += ["", "| distribution | n | mean | p5 | median | p95 | max |", "|---|---|---|---|---|---|---|"]
    for key, label in (("time_to_goal", "time to goal [s]"), ("mean_speed", "mean speed [m/s]"),
                       ("min_clearance_person", "min clearance to people [m]"),
                       ("min_clearance_overall", "min clearance overall [m]")):
        d = agg[key]
        if d["n"]:
            L.append(f"| {label} | {d['n']} | {d['mean']} | {d['p5']} | {d['median']} | {d['p95']} | {d['max']} |")
    speeds = agg.get("contact_speeds") or {}
    if speeds:
        L += ["", "| collisions by fault | count | drone speed at contact [m/s] |", "|---|---|---|"]
        for k, v in speeds.items():
            L.append(f"| {k} | {len(v)} | {', '.join(f'{x:.2f}' for x in v)} |")
    L += ["", f"Planner fallbacks over all episodes: {agg['planner_fallbacks']}", ""]
    errs = agg.get("module_errors") or []
    if errs:
        L += [f"Episodes with planner or perception errors: {len(errs)} (seeds "
              + ", ".join(str(e["seed"]) for e in errs) + "; each episode's errors.txt has the first traceback)", ""]
    envs = agg.get("environments", [])
    if envs:
        L += [("Environment: " if len(envs) == 1 else f"Environments ({len(envs)}, outcomes may differ between them): ")
              + "; ".join(describe_environment(e) for e in envs), ""]
    L += ["| seed | outcome | collisions (fault) | time to goal [s] | min clearance [m] |", "|---|---|---|---|---|"]
    for s in agg["per_seed"]:
        outcome = "success" if s["success"] else (s["failure_reason"] or "failure")
        ttg = "-" if s["time_to_goal"] is None else f"{s['time_to_goal']:.2f}"
        mc = "-" if s["min_clearance"] is None else f"{s['min_clearance']:.2f}"
        faults = ", ".join(s.get("faults") or [])
        L.append(f"| {s['seed']} | {outcome} | {s['collisions']}{f' ({faults})' if faults else ''} | {ttg} | {mc} |")
    return "\n".join(L) + "\n"


def junit(agg: dict, summaries_by_seed: dict[int, dict]) -> str:
    """JUnit XML: one test case per seed; a collision or a timeout is a failure."""
    suite = ET.Element("testsuite", name=f"dodt-nav sweep {agg['scenario']} {agg['perception']}")
    failures = 0
    for row in agg["per_seed"]:
        s = summaries_by_seed.get(row["seed"], {})
        case = ET.SubElement(suite, "testcase", classname=f"{agg['scenario']}.{agg['perception']}",
                             name=f"seed_{row['seed']:04d}", time=str(s.get("sim_time", 0.0)))
        if not row["success"]:
            failures += 1
            faults = ", ".join(row.get("faults") or [])
            msg = (f"{row['failure_reason'] or 'failure'}: {row['collisions']} collision(s)"
                   + (f" ({faults})" if faults else ""))
            failure = ET.SubElement(case, "failure", message=msg)
            failure.text = json.dumps({k: s.get(k) for k in ("collisions", "min_clearance", "time_to_goal", "sim_time")})
    suite.set("tests", str(len(agg["per_seed"])))
    suite.set("failures", str(failures))
    suite.set("errors", "0")
    ET.indent(suite, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(suite, encoding="unicode") + "\n"
