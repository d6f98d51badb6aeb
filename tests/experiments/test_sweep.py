"""Navigation sweeps: seed lists, Wilson intervals, resume after kill -9, sequential / process pool /
Dask agree seed by seed, the CLI's collision gate, JUnit XML and the summaries.

Episodes are real closed-loop PyBullet episodes on a short corridor (4 m to the goal, a few seconds
of sim time, a 320x240 camera) with the cheapest perception (oracle). Outcome fields are deterministic
for a scenario and seed; only ``timing`` depends on the wall clock, so comparisons leave it out.
"""
import json
import os
import shutil
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from experiments.episode import EpisodeConfig
import experiments.sweep as sweep_module
from experiments.sweep import RESULTS, SweepError, junit, parse_seeds, read_results, run_sweep, wilson

# A 320x240 camera with the D435i's field of view (intrinsics scaled from 640x480) keeps episodes cheap.
CAMERA = """
[camera]
width = 320
height = 240
fx = 193.58
fy = 193.58
"""

HEAD = """
seed = 0
[corridor]
length = 6.0
width = 4.0
height = 3.0
[drone]
start = [0.5, 0.0, 1.2]
goal = [4.5, 0.0, 1.2]
"""

# One person walking randomly around the goal: seeds differ (some reach the goal, some time out).
SHORT = 'name = "short"\nduration = 4.0\n' + HEAD + CAMERA + """
[[people]]
behaviour = "random_walk"
speed = 0.8
region = [2.0, -1.6, 5.5, 1.6]
start = [3.5, 0.8]
"""

# A person walks straight at the drone along its path at 1.6 m/s. In static-only mode the person
# is just map voxels that keep moving into the drone: a collision on every seed tried (0-2).
HEAD_ON = 'name = "head_on"\nduration = 3.0\n' + HEAD + CAMERA + """
[[people]]
behaviour = "crossing"
speed = 1.6
waypoints = [[5.0, 0.0], [0.3, 0.0]]
"""

# Nobody and nothing in the corridor: nothing to collide with.
EMPTY = 'name = "empty"\nduration = 4.0\n' + HEAD + CAMERA

SEEDS = list(range(6))


def _cmd(*args):
    return [sys.executable, "-m", "experiments.cli", *args]


def _cli(*args, cwd=None):
    return subprocess.run(_cmd(*args), capture_output=True, text=True, cwd=cwd, timeout=600)


def _outcomes(results: dict) -> dict:
    """Seed -> summary without the wall-clock figures and without where the camera rendered (a second
    process in a sequential sweep, the episode's own in a pool: the same frames either way)."""
    out = {}
    for seed, s in results.items():
        s = {k: v for k, v in s.items() if k != "timing"}
        episode = {k: v for k, v in s["config"]["episode"].items() if k != "render_process"}
        out[seed] = {**s, "config": {**s["config"], "episode": episode}}
    return out


def _lines(path):
    return path.read_text(encoding="utf-8").splitlines() if path.exists() else []


@pytest.fixture(scope="module")
def scenarios(tmp_path_factory):
    d = tmp_path_factory.mktemp("scenarios")
    files = {}
    for name, text in (("short", SHORT), ("head_on", HEAD_ON), ("empty", EMPTY)):
        files[name] = d / f"{name}.toml"
        files[name].write_text(text)
    r = _cli("validate", *map(str, files.values()))
    assert r.returncode == 0, r.stderr
    return files


@pytest.fixture(scope="module")
def reference(scenarios, tmp_path_factory):
    """An uninterrupted sequential sweep of the short scenario, seeds 0-5: (folder, aggregate, results)."""
    out = tmp_path_factory.mktemp("reference")
    agg = run_sweep(str(scenarios["short"]), SEEDS, "oracle", out, jobs=1, progress=False)
    results = read_results(out / RESULTS)
    assert sorted(results) == SEEDS
    return out, agg, results


# --- seeds and intervals ------------------------------------------------------------------------

@pytest.mark.parametrize("text, seeds", [
    ("0:5", [0, 1, 2, 3, 4]),
    ("3", [3]),
    ("1,4,9", [1, 4, 9]),
    ("9,1,4", [1, 4, 9]),
    ("0:3,7,2:4, 10", [0, 1, 2, 3, 7, 10]),  # mixed, overlapping, spaces
    ("0:2,", [0, 1]),
    ("0", [0]),
])
def test_parse_seeds(text, seeds):
    assert parse_seeds(text) == seeds


@pytest.mark.parametrize("text, fragment", [
    ("5:5", "empty range"),
    ("7:3", "empty range"),
    ("-1", "non-negative"),
    ("-3:2", "non-negative"),
    ("1,-4", "non-negative"),
    ("abc", "not a seed list"),
    ("1:2:3", "not a seed list"),
    ("1.5", "not a seed list"),
    ("0:x", "not a seed list"),
    ("", "--seeds"),
    (" , ", "--seeds"),
])
def test_parse_seeds_rejects_bad_lists_naming_the_option(text, fragment):
    with pytest.raises(SweepError) as e:
        parse_seeds(text)
    assert str(e.value).startswith("--seeds")
    assert fragment in str(e.value)
    assert isinstance(e.value, ValueError)  # SweepError is a ValueError (user mistake)


@pytest.mark.parametrize("k, n, lo, hi", [
    (0, 20, 0.0, 0.1611),
    (10, 20, 0.2993, 0.7007),
    (20, 20, 0.8389, 1.0),
    (1, 10, 0.0179, 0.4042),
    (6, 6, 0.6097, 1.0),
])
def test_wilson_interval_known_values(k, n, lo, hi):
    a, b = wilson(k, n)
    assert a == pytest.approx(lo, abs=1e-4) and b == pytest.approx(hi, abs=1e-4)
    assert 0.0 <= a <= k / n <= b <= 1.0


def test_wilson_interval_edge_cases():
    assert wilson(0, 0) == (0.0, 1.0)  # no episodes: nothing known
    assert wilson(0, 5)[0] == 0.0 and wilson(5, 5)[1] == 1.0
    a, b = wilson(3, 7)
    c, d = wilson(4, 7)
    assert (1 - b, 1 - a) == pytest.approx((c, d))  # symmetric in successes and failures
    assert wilson(50, 100)[1] - wilson(50, 100)[0] < wilson(5, 10)[1] - wilson(5, 10)[0]  # narrows with n


# --- resume, parallel back ends -------------------------------------------------------------------

def _pool_workers(parent: int) -> list[int]:
    """The process-pool workers (spawned interpreters) whose parent is ``parent``, from /proc."""
    out = []
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            stat = open(f"/proc/{d}/stat").read()
            cmd = open(f"/proc/{d}/cmdline", "rb").read()
        except OSError:
            continue
        if int(stat.rsplit(")", 1)[1].split()[1]) == parent and b"spawn_main" in cmd:
            out.append(int(d))
    return out


def _alive(pid: int) -> bool:
    try:
        state = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.slow
@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="reads the process table from /proc")
@pytest.mark.parametrize("how", [signal.SIGKILL, signal.SIGTERM])
def test_pool_workers_end_when_the_sweep_alone_is_killed(scenarios, tmp_path, how):
    """kill -9 or kill of the sweep's own process (not its group): its workers end within seconds instead
    of running the queued episodes for nobody and then sleeping for good (SIGTERM: the sweep ends them)."""
    cmd = _cmd("sweep", str(scenarios["short"]), "--seeds", "0:6", "--jobs", "2", "--perception", "oracle",
               "--out", str(tmp_path / "sweep"), "--quiet")
    p = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    workers = []
    try:
        deadline = time.monotonic() + 120
        while len(workers) < 2:
            assert p.poll() is None, f"the sweep ended (status {p.returncode}) before its workers were seen"
            assert time.monotonic() < deadline, "no two pool workers within 120 s"
            time.sleep(0.05)
            workers = _pool_workers(p.pid)
        os.kill(p.pid, how)  # the main process only
        p.wait(timeout=30)
        deadline = time.monotonic() + 20
        while any(_alive(w) for w in workers) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not any(_alive(w) for w in workers), "pool workers outlived the killed sweep by 20 s"
    finally:
        try:
            os.killpg(p.pid, signal.SIGKILL)  # whatever is left of the group
        except ProcessLookupError:
            pass


@pytest.mark.slow
def test_resume_after_kill_9_runs_each_seed_once_with_the_same_results(scenarios, reference, tmp_path):
    ref_out, _, ref_results = reference
    out = tmp_path / "sweep"
    cmd = _cmd("sweep", str(scenarios["short"]), "--seeds", "0:6", "--jobs", "1", "--perception", "oracle",
               "--out", str(out), "--quiet")
    res = out / RESULTS
    p = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 300
        while len(_lines(res)) < 2:
            assert p.poll() is None, f"the sweep ended (status {p.returncode}) before two episodes were written"
            assert time.monotonic() < deadline, "no two episodes written within 300 s"
            time.sleep(0.05)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)  # the whole group: pool workers too
        p.wait(timeout=60)
    assert p.returncode == -signal.SIGKILL, "the sweep finished before it could be killed"
    before = _lines(res)
    assert 2 <= len(before) < 6
    # A line cut short by the kill: half a summary and no newline.
    with open(res, "a", encoding="utf-8") as fh:
        fh.write(before[0][: len(before[0]) // 2])

    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    after = _lines(res)
    assert after[: len(before)] == before  # episodes written before the kill are kept as they were
    valid, broken = [], 0
    for line in after:
        try:
            valid.append(json.loads(line))
        except json.JSONDecodeError:
            broken += 1
    seeds = [s["seed"] for s in valid]
    assert sorted(seeds) == SEEDS, f"each seed exactly once in {res}; got {seeds} and {broken} broken line(s)"
    assert broken <= 1  # at most the line cut short (a repair may also drop it)
    results = read_results(res)
    assert sorted(results) == SEEDS
    assert _outcomes(results) == _outcomes(ref_results)
    summary = json.loads((out / "summary.json").read_text())
    ref_summary = json.loads((ref_out / "summary.json").read_text())
    assert summary["episodes"] == 6
    assert [row["seed"] for row in summary["per_seed"]] == SEEDS
    for key in ("rates", "per_seed", "time_to_goal", "min_clearance_overall", "planner_fallbacks"):
        assert summary[key] == ref_summary[key], key


@pytest.mark.slow
def test_process_pool_gives_the_same_results_as_sequential(scenarios, reference, tmp_path):
    ref_out, ref_agg, ref_results = reference
    out = tmp_path / "pool"
    agg = run_sweep(str(scenarios["short"]), SEEDS, "oracle", out, jobs=2, keep_logs=True, progress=False)
    results = read_results(out / RESULTS)
    assert len(_lines(out / RESULTS)) == 6
    assert _outcomes(results) == _outcomes(ref_results)
    assert agg["per_seed"] == ref_agg["per_seed"] and agg["rates"] == ref_agg["rates"]
    # Logs: kept for every episode with keep_logs; without, only for the failed ones.
    kept = {p.name for p in (out / "episodes").iterdir()}
    assert kept == {f"seed_{s:04d}" for s in SEEDS}
    assert all((out / "episodes" / k / "log.jsonl.gz").exists() for k in kept)
    ref_kept = {p.name for p in (ref_out / "episodes").iterdir()} if (ref_out / "episodes").exists() else set()
    assert ref_kept == {f"seed_{s:04d}" for s, r in ref_results.items() if not r["success"]}


@pytest.fixture(scope="module")
def dask_cluster():
    try:
        from dask.distributed import LocalCluster
    except ImportError:
        pytest.skip("dask.distributed is not installed (pip install -e '.[cluster]')")
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        yield cluster


@pytest.mark.slow
def test_dask_cluster_gives_the_same_results_as_local(scenarios, reference, dask_cluster, tmp_path):
    _, ref_agg, ref_results = reference
    out = tmp_path / "dask"
    agg = run_sweep(str(scenarios["short"]), SEEDS, "oracle", out, dask_address=dask_cluster.scheduler_address,
                    progress=False)
    results = read_results(out / RESULTS)
    assert len(_lines(out / RESULTS)) == 6
    assert _outcomes(results) == _outcomes(ref_results)
    assert agg["per_seed"] == ref_agg["per_seed"] and agg["rates"] == ref_agg["rates"]


@pytest.mark.slow
def test_concurrent_dask_sweeps_of_different_scenarios_keep_their_own_results(scenarios, dask_cluster, tmp_path):
    """Two CI jobs sharing one scheduler, same perception and seed, different scenarios."""
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(2) as ex:
        futures = {name: ex.submit(run_sweep, str(scenarios[name]), [0], "oracle", tmp_path / name,
                                   dask_address=dask_cluster.scheduler_address, progress=False)
                   for name in ("short", "empty")}
        for f in futures.values():
            f.result(timeout=300)
    for name in futures:
        (s,) = read_results(tmp_path / name / RESULTS).values()
        assert s["scenario"] == name, f"the {name} sweep got the result of a {s['scenario']} episode"


@pytest.mark.slow
def test_rerun_of_finished_seeds_runs_nothing_and_aggregates_only_the_requested_ones(reference, scenarios, tmp_path):
    ref_out, _, ref_results = reference
    out = tmp_path / "copy"
    shutil.copytree(ref_out, out)
    before = (out / RESULTS).read_bytes()
    agg = run_sweep(str(scenarios["short"]), [1, 3], "oracle", out, jobs=1, progress=False)
    assert (out / RESULTS).read_bytes() == before
    assert agg["episodes"] == 2 and [row["seed"] for row in agg["per_seed"]] == [1, 3]
    assert agg["rates"]["success"]["count"] == sum(ref_results[s]["success"] for s in (1, 3))


# --- CLI: gate, JUnit, summaries, mistakes ------------------------------------------------------------

def _junit_cases(path):
    suite = ET.parse(path).getroot()
    assert suite.tag == "testsuite"
    return suite, suite.findall("testcase")


def test_junit_escapes_names_and_messages():
    """Scenario and perception names (a file path, a plug-in's module:Class) and failure details are text,
    whatever they hold: the XML parses back to them."""
    name, mode = 'a<b & "c" \'d\'', "x&y.py:Near<DODT>"
    agg = {"scenario": name, "perception": mode, "per_seed": [
        {"seed": 0, "success": True, "collisions": 0, "failure_reason": None, "faults": []},
        {"seed": 3, "success": False, "collisions": 1, "failure_reason": "collision", "faults": ["<&\">"]}]}
    detail = {"collisions": [{"with": "wall & <door>"}], "min_clearance": None, "time_to_goal": None, "sim_time": 1.5}
    text = junit(agg, {0: {"sim_time": 4.0}, 3: detail})
    assert text.startswith('<?xml version="1.0" encoding="UTF-8"?>\n')
    suite = ET.fromstring(text.encode())
    assert (suite.get("name"), suite.get("tests"), suite.get("failures"), suite.get("errors")) == (
        f"dodt-nav sweep {name} {mode}", "2", "1", "0")
    cases = suite.findall("testcase")
    assert [(c.get("classname"), c.get("name"), c.get("time")) for c in cases] == [
        (f"{name}.{mode}", "seed_0000", "4.0"), (f"{name}.{mode}", "seed_0003", "1.5")]
    assert cases[0].find("failure") is None
    failure = cases[1].find("failure")
    assert failure.get("message") == 'collision: 1 collision(s) (<&">)' and json.loads(failure.text) == detail


@pytest.mark.slow
def test_collision_gate_fails_the_run_and_junit_marks_the_seed(scenarios, tmp_path):
    out, xml = tmp_path / "head_on", tmp_path / "head_on.xml"
    args = ("sweep", str(scenarios["head_on"]), "--seeds", "0", "--perception", "static-only", "--jobs", "1",
            "--out", str(out), "--quiet", "--junit", str(xml))
    r = _cli(*args, "--max-collision-rate", "0")
    s = read_results(out / RESULTS)[0]
    assert s["collided"], f"the head-on scenario no longer collides in static-only mode: {s['min_clearance']}"
    assert r.returncode == 1, r.stderr
    assert "exceeds --max-collision-rate" in r.stderr and "Traceback" not in r.stderr
    suite, cases = _junit_cases(xml)
    assert suite.get("tests") == "1" and suite.get("failures") == "1"
    assert [c.get("name") for c in cases] == ["seed_0000"]
    assert cases[0].find("failure") is not None
    # The same folder (nothing left to run) under a gate the rate does not exceed passes.
    r = _cli(*args, "--max-collision-rate", "1")
    assert r.returncode == 0, r.stderr
    assert len(_lines(out / RESULTS)) == 1


@pytest.mark.slow
def test_collision_gate_passes_without_collisions(scenarios, tmp_path):
    out, xml = tmp_path / "empty", tmp_path / "empty.xml"
    r = _cli("sweep", str(scenarios["empty"]), "--seeds", "0", "--perception", "oracle", "--jobs", "1",
             "--out", str(out), "--quiet", "--junit", str(xml), "--max-collision-rate", "0")
    s = read_results(out / RESULTS)[0]
    assert not s["collided"], s["collisions"]
    assert r.returncode == 0, r.stderr
    suite, cases = _junit_cases(xml)
    assert suite.get("tests") == "1" and suite.get("failures") == str(int(not s["success"]))
    assert (cases[0].find("failure") is None) == s["success"]


@pytest.mark.slow
def test_junit_and_gate_over_a_finished_sweep(scenarios, reference, tmp_path):
    ref_out, _, ref_results = reference
    xml = tmp_path / "junit.xml"
    r = _cli("sweep", str(scenarios["short"]), "--seeds", "0:6", "--perception", "oracle", "--jobs", "1",
             "--out", str(ref_out), "--quiet", "--junit", str(xml), "--max-collision-rate", "0")
    collided = any(s["collided"] for s in ref_results.values())
    assert r.returncode == (1 if collided else 0), r.stderr
    assert "Traceback" not in r.stderr
    suite, cases = _junit_cases(xml)
    assert suite.get("tests") == "6" and suite.get("errors") == "0"
    assert [c.get("name") for c in cases] == [f"seed_{s:04d}" for s in SEEDS]
    failed = {int(c.get("name")[5:]) for c in cases if c.find("failure") is not None}
    assert failed == {s for s, res in ref_results.items() if not res["success"]}
    assert failed >= {s for s, res in ref_results.items() if res["collided"] or res["timeout"]}
    assert suite.get("failures") == str(len(failed))
    for c in cases:
        assert float(c.get("time")) == ref_results[int(c.get("name")[5:])]["sim_time"]
        assert c.get("classname").endswith(".oracle")


@pytest.mark.slow
def test_summary_files_hold_the_rates_table_and_one_row_per_seed(reference):
    ref_out, agg, results = reference
    summary = json.loads((ref_out / "summary.json").read_text())
    assert summary["episodes"] == 6 and summary["perception"] == "oracle"
    for key, field in (("success", "success"), ("collision", "collided"), ("timeout", "timeout"),
                       ("at_fault", "at_fault"), ("not_at_fault_only", "not_at_fault_only")):
        count = sum(s[field] for s in results.values())
        rate = summary["rates"][key]
        assert rate["count"] == count and rate["rate"] == pytest.approx(count / 6, abs=1e-4)
        assert rate["ci95"] == pytest.approx(list(wilson(count, 6)), abs=1e-4)
    md = (ref_out / "summary.md").read_text()
    lines = md.splitlines()
    assert "| outcome | count | rate | 95 % Wilson interval |" in lines
    for key in ("success", "collision", "timeout"):
        assert sum(line.startswith(f"| {key} | {summary['rates'][key]['count']} |") for line in lines) == 1, key
    assert "| seed | outcome | collisions (fault) | time to goal [s] | min clearance [m] |" in lines
    for seed, s in results.items():
        rows = [line for line in lines if line.startswith(f"| {seed} | ")]
        assert len(rows) == 1, (seed, rows)
        cells = [c.strip() for c in rows[0].strip("|").split("|")]
        assert cells[1] == ("success" if s["success"] else s["failure_reason"])
        faults = ", ".join(c["fault"] for c in s["collisions"])
        assert cells[2] == str(s["collision_count"]) + (f" ({faults})" if faults else "")
        assert cells[3] == ("-" if s["time_to_goal"] is None else f"{s['time_to_goal']:.2f}")
    # one machine and installation ran them all: one environment, named in both files
    assert summary["environments"] == [results[SEEDS[0]]["environment"]]
    env_lines = [line for line in lines if line.startswith("Environment: ")]
    assert len(env_lines) == 1 and f"numpy {np.__version__}" in env_lines[0]


@pytest.mark.parametrize("args, fragment", [
    (["--seeds", "5:5"], "--seeds: empty range"),
    (["--seeds", "banana"], "--seeds: 'banana' is not a seed list"),
    (["--seeds=-2"], "--seeds"),
    (["--perception", "telepathy"], "--perception: unknown mode 'telepathy'"),
    (["--jobs", "0"], "--jobs: must be >= 1"),
    (["--max-collision-rate", "2"], "--max-collision-rate: must be a fraction between 0 and 1"),
    (["--max-collision-rate", "-0.1"], "--max-collision-rate"),
    (["--dask", "not-an-address"], "--dask"),
    (["--frame-latency", "-1"], "--frame-latency: must be a whole number of camera periods >= 0"),
])
def test_sweep_mistakes_exit_2_with_one_line_and_no_traceback(scenarios, tmp_path, args, fragment):
    out = tmp_path / "out"
    r = _cli("sweep", str(scenarios["short"]), "--perception", "oracle", "--seeds", "0:2", "--jobs", "1",
             "--out", str(out), "--quiet", *args)
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert fragment in r.stderr
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (out / RESULTS).exists()  # nothing ran


def _folder_holding(tmp_path, perception: str) -> tuple:
    """A sweep folder with one result line of seed 0 written before the newer options: (folder, line)."""
    out = tmp_path / "out"
    out.mkdir()
    line = json.dumps({"scenario": "short", "seed": 0, "perception": perception, "success": True})
    (out / RESULTS).write_text(line + "\n")
    return out, line


def test_results_of_another_perception_mode_are_refused(scenarios, tmp_path):
    out, line = _folder_holding(tmp_path, "dodt")
    r = _cli("sweep", str(scenarios["short"]), "--perception", "oracle", "--seeds", "0:2", "--jobs", "1",
             "--out", str(out), "--quiet")
    assert r.returncode == 2, r.stderr
    assert "holds results of perception 'dodt', not 'oracle'" in r.stderr
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert (out / RESULTS).read_text() == line + "\n"  # untouched
    with pytest.raises(SweepError, match="another --out folder"):
        run_sweep(str(scenarios["short"]), [0], "oracle", out, progress=False)


@pytest.mark.slow
def test_results_with_another_static_map_are_refused(scenarios, tmp_path):
    """A sweep folder of depth-map episodes is not extended with known-map ones (or back), and a known-map
    sweep records its map in every result (a line from before the option counts as depth)."""
    out, line = _folder_holding(tmp_path, "oracle")
    r = _cli("sweep", str(scenarios["short"]), "--perception", "oracle", "--seeds", "0:2", "--jobs", "1",
             "--map", "truth", "--out", str(out), "--quiet")
    assert r.returncode == 2, r.stderr
    assert "holds results with the static map 'depth', not 'truth'" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and (out / RESULTS).read_text() == line + "\n"
    known = tmp_path / "known"
    run_sweep(str(scenarios["short"]), [0, 1], "oracle", known, progress=False, cfg=EpisodeConfig(static_map="truth"))
    assert all(s["static_map"] == "truth" for s in read_results(known / RESULTS).values())
    with pytest.raises(SweepError, match="static map"):
        run_sweep(str(scenarios["short"]), [2], "oracle", known, progress=False)


@pytest.mark.slow
def test_results_with_another_frame_latency_are_refused(scenarios, tmp_path):
    """Frame latency changes every result: a folder holds one; a line from before the option counts as 0."""
    out, line = _folder_holding(tmp_path, "oracle")
    r = _cli("sweep", str(scenarios["short"]), "--perception", "oracle", "--seeds", "0:2", "--jobs", "1",
             "--out", str(out), "--quiet")
    assert r.returncode == 2, r.stderr
    assert "holds results with the frame latency 0, not 1" in r.stderr
    assert (out / RESULTS).read_text() == line + "\n"
    r = _cli("sweep", str(scenarios["short"]), "--perception", "oracle", "--seeds", "1:2", "--jobs", "1",
             "--frame-latency", "0", "--out", str(out), "--quiet")
    assert r.returncode == 0, r.stderr
    assert read_results(out / RESULTS)[1]["frame_latency"] == 0


def test_bad_scenario_file_exits_2(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[corridor]\nwidth = 0.5\n")
    r = _cli("sweep", str(bad), "--perception", "oracle", "--seeds", "0", "--out", str(tmp_path / "out"))
    assert r.returncode == 2
    assert "corridor.width" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "out").exists()


def test_progress_bar_writes_nothing_unless_a_terminal():
    import io

    from experiments.sweep import _Progress

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    for stream, shown in ((io.StringIO(), False), (Terminal(), True)):
        bar = _Progress(3, 1, stream)
        bar.tick({"success": False})
        bar.close()
        text = stream.getvalue()
        assert bool(text) is shown and (not shown or ("2/3" in text and "1 failed" in text))


@pytest.mark.parametrize("rows, fragment", [
    ('["seed", 3]\n', "line 1: not an episode summary"),
    (None, "line 1: seed 'abc' is not a whole number"),
    (None, "line 1: seed None is not a whole number"),
    (None, "line 1: seed 1e+400"),
])
def test_a_broken_results_file_is_one_line_for_sweep_and_compare(tmp_path, capsys, rows, fragment):
    from experiments.cli import main
    from experiments.sweep import RESULT_KEYS

    seed = {"line 1: seed 'abc' is not a whole number": '"abc"', "line 1: seed None is not a whole number": "null",
            "line 1: seed 1e+400": "1e400"}.get(fragment)
    if rows is None:
        rows = "{" + ", ".join(f'"{k}": {seed if k == "seed" else "null"}' for k in RESULT_KEYS) + "}\n"
    folder = tmp_path / "s"
    folder.mkdir()
    (folder / "results.jsonl").write_text(rows)
    for argv in (["compare", str(folder), str(folder)],
                 ["sweep", "corridor", "--seeds", "0:1", "--quiet", "--out", str(folder)]):
        rc = main(argv)
        err = capsys.readouterr().err
        assert rc == 2 and fragment.replace("1e+400", "inf") in err.replace("1e+400", "inf") \
            and err.count("\n") == 1, (argv, err)


def test_a_results_file_that_is_not_utf8_and_too_many_seeds_are_one_line(tmp_path, capsys):
    from experiments.cli import main

    folder = tmp_path / "s"
    folder.mkdir()
    (folder / "results.jsonl").write_bytes(b"\xff\xfe\x00garbage\n")
    assert main(["compare", str(folder), str(folder)]) == 2
    err = capsys.readouterr().err
    assert "not UTF-8 text" in err and err.count("\n") == 1
    assert main(["sweep", "corridor", "--seeds", "0:1000000,2000000:3000000", "--out", str(tmp_path / "t")]) == 2
    err = capsys.readouterr().err
    assert "more than 1000000 seeds in all" in err and err.count("\n") == 1
    assert main(["run", "corridor", "--out", ""]) == 2
    assert "--out: an empty path" in capsys.readouterr().err


@pytest.mark.parametrize("name, data, fragment", [
    ("long line", b'{"seed": 1, "x": "' + b"a" * (5 << 20) + b'"}\n', "line 1: longer than 4 MiB"),
    ("no newline", b"0" * (5 << 20), "line 1: longer than 4 MiB"),
    ("huge integer", b'{"seed": ' + b"1" * 5000 + b"}\n", "line 1: Exceeds the limit"),
    ("latin-1 row", b'{"seed": 0}\n{"seed": 1, "x": "\xe9"}\n', "line 2: not UTF-8 text"),
])
def test_results_files_are_read_no_further_than_their_limits(tmp_path, name, data, fragment):
    path = tmp_path / RESULTS
    path.write_bytes(data)
    with pytest.raises(SweepError, match=fragment):
        read_results(path)


def test_a_results_file_that_is_a_device_or_too_large_is_refused(tmp_path, monkeypatch):
    with pytest.raises(SweepError, match="/dev/zero: not a regular file"):
        read_results(Path("/dev/zero"))
    path = tmp_path / RESULTS
    path.write_text("".join(f'{{"seed": {i}}}\n' for i in range(100)))
    assert sorted(read_results(path)) == list(range(100))
    monkeypatch.setattr(sweep_module, "MAX_RESULTS_BYTES", 500)  # the limit itself, small enough to reach here
    with pytest.raises(SweepError, match="larger than"):
        read_results(path)


_FINISHED_ROW = {"seed": 0, "scenario": "corridor", "perception": "oracle", "static_map": "depth", "frame_latency": 1,
                 "success": True, "reached_goal": True, "collided": False, "collision_count": 0, "at_fault": False,
                 "not_at_fault_only": False, "timeout": False, "failure_reason": None, "time_to_goal": 14.7,
                 "mean_speed": 1.2, "min_clearance": {"static": 0.3, "person": 0.5, "structure": 0.3, "overall": 0.3},
                 "sim_time": 14.7, "planner_stats": {"fallbacks": 0}}


def test_junit_to_a_full_disk_names_the_file_and_a_partial_row_is_one_line(tmp_path, capsys):
    """A finished sweep (no episode left to run): --junit /dev/full fails on the write, and the one line says
    which file; a results row without the fields the aggregate reads is one line too, not a traceback."""
    from experiments.cli import main

    out = tmp_path / "s"
    out.mkdir()
    (out / RESULTS).write_text(json.dumps(_FINISHED_ROW) + "\n")
    argv = ["sweep", "corridor", "--seeds", "0", "--perception", "oracle", "--out", str(out), "--quiet"]
    assert main(argv + ["--junit", "/dev/full"]) == 2
    err = capsys.readouterr().err
    assert "--junit: cannot write /dev/full" in err and err.count("\n") == 1
    assert main(argv + ["--junit", str(tmp_path / "j.xml")]) == 0 and (tmp_path / "j.xml").exists()
    capsys.readouterr()
    partial = {k: v for k, v in _FINISHED_ROW.items() if k != "time_to_goal"}
    (out / RESULTS).write_text(json.dumps(partial) + "\n")
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "not whole episode summaries (KeyError: 'time_to_goal')" in err and err.count("\n") == 1
