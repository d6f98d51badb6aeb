"""`dodt-nav run` and `dodt-nav sweep` stopped by SIGINT (Ctrl-C: the terminal signals the whole process
group) or SIGTERM (kill PID, a job scheduler: the command's own process alone) while they run: each ends
within seconds with one line and a non-zero status (130 and 143, 128 plus the signal), no traceback, and
leaves no process behind (the render process, the sweep's pool workers); a second Ctrl-C during the
shutdown does not leave any either, and a sweep stopped so resumes where it stopped.

The commands run as their own process group, with SIGINT's default action (a shell starts a background
job with SIGINT ignored, and the command keeps that, as commands do)."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from processes import alive, children, descendants, kill_group, wait_for

pytestmark = pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="reads the process table from /proc")

ROOT = Path(__file__).resolve().parents[2]
END_S = 15.0  # from the signal to the command's end: a few seconds on an idle machine
START_S = 300.0  # from the start to the first sign of the episode (numba compiles on a first run)



def _corridor(name: str, duration: float, length: float) -> str:
    """A scenario: an empty corridor flown from one end to the other, a 320x240 camera."""
    return f"""
name = "{name}"
duration = {duration}
seed = 0
[corridor]
length = {length}
width = 4.0
height = 3.0
[drone]
start = [0.5, 0.0, 1.2]
goal = [{length - 1.0}, 0.0, 1.2]
[camera]
width = 320
height = 240
fx = 193.58
fy = 193.58
"""


LONG = _corridor("long", 600.0, 150.0)  # an episode that is still flying when the signal comes
SHORT = _corridor("short", 3.0, 6.0)  # a few seconds of sim time: a sweep records episodes one after another

INTERRUPTED = {signal.SIGINT: (130, "dodt-nav: interrupted"), signal.SIGTERM: (143, "dodt-nav: terminated")}


class Command:
    """A `dodt-nav` command started as its own process group; its output in files (nothing to drain)."""

    def __init__(self, tmp: Path, *args: str):
        self.stdout, self.stderr = tmp / "stdout.txt", tmp / "stderr.txt"
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
        with open(self.stdout, "w") as out, open(self.stderr, "w") as err:
            self.p = subprocess.Popen([sys.executable, "-m", "experiments.cli", *args], stdout=out, stderr=err,
                                      stdin=subprocess.DEVNULL, env=env, cwd=tmp, start_new_session=True,
                                      preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        self.below: set[int] = set()

    def running_until(self, predicate, what: str) -> None:
        """Waits until ``predicate()``; the command must still be running then."""
        deadline = time.monotonic() + START_S
        while not predicate():
            assert self.p.poll() is None, f"the command ended (status {self.p.returncode}) before {what}: " \
                                          f"{self.stderr.read_text()[-2000:]}"
            assert time.monotonic() < deadline, f"no {what} within {START_S:.0f} s"
            time.sleep(0.05)
        assert self.p.poll() is None, f"the command ended before the signal ({what})"

    def watch(self) -> None:
        """Notes the processes below the command now (they must be gone once it is)."""
        self.below |= set(descendants(self.p.pid))

    def signal(self, how: int) -> None:
        """SIGINT as a terminal sends it, to the whole group; SIGTERM to the command's process alone."""
        self.watch()
        if how == signal.SIGINT:
            os.killpg(self.p.pid, how)
        else:
            os.kill(self.p.pid, how)

    def ended(self) -> int:
        """The command's exit status once it ended; its processes are gone."""
        try:
            status = self.p.wait(timeout=END_S)
        except subprocess.TimeoutExpired:
            pytest.fail(f"still running {END_S:.0f} s after the signal: {self.stderr.read_text()[-2000:]}")
        assert wait_for(lambda: not any(alive(p) for p in self.below), timeout=10), \
            f"{[p for p in self.below if alive(p)]} outlived the command by 10 s"
        return status

    def kill(self) -> None:
        kill_group(self.p)


@pytest.fixture
def command(tmp_path):
    started = []

    def start(*args: str) -> Command:
        started.append(Command(tmp_path, *args))
        return started[-1]

    yield start
    for c in started:
        c.kill()


def _stopped(c: Command, how: int) -> None:
    """The command ended as a stopped command does: its status, one line on stderr, no traceback."""
    status, line = INTERRUPTED[how]
    assert c.ended() == status
    err = c.stderr.read_text()
    assert "Traceback" not in err, err
    assert err.strip().splitlines()[-1] == line, err
    assert err.count(line) == 1, err


@pytest.fixture
def scenarios(tmp_path):
    (tmp_path / "long.toml").write_text(LONG)
    (tmp_path / "short.toml").write_text(SHORT)
    return tmp_path


@pytest.mark.slow
@pytest.mark.parametrize("how", [signal.SIGINT, signal.SIGTERM])
def test_a_run_without_a_render_process_ends_on_a_signal(command, scenarios, how):
    out = scenarios / "run"
    c = command("run", "long.toml", "--perception", "oracle", "--map", "truth", "--out", str(out))
    c.running_until(lambda: (out / "log.jsonl.gz").exists(), "the episode's log")
    time.sleep(3.0)  # flying (or compiling on a first run): either must end
    c.signal(how)
    _stopped(c, how)


@pytest.mark.slow
@pytest.mark.parametrize("how", [signal.SIGINT, signal.SIGTERM])
def test_a_run_ends_on_a_signal_with_its_render_process(command, scenarios, how):
    out = scenarios / "run"
    c = command("run", "long.toml", "--perception", "dodt", "--duration", "60", "--out", str(out))
    c.running_until(lambda: children(c.p.pid, b"sim.render_child"), "a render process")
    c.running_until(lambda: (out / "log.jsonl.gz").exists(), "the episode's log")
    time.sleep(3.0)
    c.signal(how)
    _stopped(c, how)


@pytest.mark.slow
@pytest.mark.parametrize("how", [signal.SIGINT, signal.SIGTERM])
def test_a_sweep_ends_on_a_signal_with_its_workers(command, scenarios, how):
    c = command("sweep", "long.toml", "--seeds", "0:6", "--jobs", "2", "--perception", "oracle", "--map", "truth",
                "--out", str(scenarios / "sweep"), "--quiet")
    c.running_until(lambda: len(children(c.p.pid, b"spawn_main")) >= 2, "two pool workers")
    time.sleep(3.0)
    c.signal(how)
    _stopped(c, how)


@pytest.mark.slow
@pytest.mark.parametrize("what", ["run", "sweep"])
def test_a_second_ctrl_c_during_the_shutdown_leaves_nothing_behind(command, scenarios, what):
    if what == "run":
        out = scenarios / "run"
        c = command("run", "long.toml", "--perception", "dodt", "--duration", "60", "--out", str(out))
        c.running_until(lambda: children(c.p.pid, b"sim.render_child"), "a render process")
        c.running_until(lambda: (out / "log.jsonl.gz").exists(), "the episode's log")
    else:
        c = command("sweep", "long.toml", "--seeds", "0:6", "--jobs", "2", "--perception", "dodt", "--out",
                    str(scenarios / "sweep"), "--quiet")
        c.running_until(lambda: len(children(c.p.pid, b"spawn_main")) >= 2, "two pool workers")
    time.sleep(3.0)
    c.signal(signal.SIGINT)
    time.sleep(0.02)  # the first is being handled: the command is closing what it started
    if c.p.poll() is None:
        c.signal(signal.SIGINT)
    status = c.ended()
    assert status != 0
    err = c.stderr.read_text()
    assert "Traceback" not in err, err
    # the first signal's line, or the second's (a stop at once: multiprocessing's resource tracker may then
    # warn of the semaphores it cleans up for the sweep)
    assert "dodt-nav: interrupted\n" in err or "dodt-nav: interrupted again; stopped at once\n" in err, err


# A command whose clean-up does not end: its child (which ignores Ctrl-C, as the render process and the pool
# workers do) prints its pid, then the command sleeps, and sleeps again in its finally block.
STUCK = """
import argparse, os, subprocess, sys, time
from experiments import cli

def stuck(args):
    child = subprocess.Popen([sys.executable, "-c", "import signal, sys, time; from sim.parent_watch import "
                              "exit_with_parent; exit_with_parent(int(sys.argv[1])); "
                              "signal.signal(signal.SIGINT, signal.SIG_IGN); print(flush=True); time.sleep(60)",
                              str(os.getpid())], stdout=subprocess.PIPE, text=True)
    child.stdout.readline()
    try:
        print(child.pid, flush=True)
        time.sleep(60)
    finally:
        print("closing", flush=True)
        time.sleep(60)

class Parser:
    def parse_args(self, argv):
        return argparse.Namespace(func=stuck)

cli.build_parser = Parser
sys.exit(cli.main([]))
"""


def test_a_second_ctrl_c_ends_a_clean_up_that_does_not_end_and_its_children(tmp_path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    p = subprocess.Popen([sys.executable, "-c", STUCK], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         env=env, start_new_session=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        child = int(p.stdout.readline())
        os.killpg(p.pid, signal.SIGINT)
        assert p.stdout.readline() == "closing\n"
        assert p.poll() is None and alive(child)  # the first Ctrl-C: the command closes what it started
        os.killpg(p.pid, signal.SIGINT)
        assert p.wait(timeout=30) == 130
        assert wait_for(lambda: not alive(child), timeout=10), "the child outlived the command by 10 s"
        err = p.stderr.read()
        assert err == "dodt-nav: interrupted again; stopped at once\n", err
    finally:
        kill_group(p)


def _lines(path: Path) -> list[str]:
    return path.read_text(encoding="utf-8").splitlines() if path.exists() else []


@pytest.mark.slow
def test_a_sweep_stopped_by_sigterm_resumes_where_it_stopped(command, scenarios):
    out = scenarios / "sweep"
    args = ("sweep", "short.toml", "--seeds", "0:6", "--jobs", "1", "--perception", "oracle", "--map", "truth",
            "--out", str(out), "--quiet")
    results = out / "results.jsonl"
    c = command(*args)
    c.running_until(lambda: len(_lines(results)) >= 2, "two recorded episodes")
    c.signal(signal.SIGTERM)
    _stopped(c, signal.SIGTERM)
    before = _lines(results)
    assert 2 <= len(before) < 6
    seeds_before = [json.loads(line)["seed"] for line in before]

    again = command(*args)
    assert again.p.wait(timeout=600) == 0, again.stderr.read_text()
    after = _lines(results)
    assert after[:len(before)] == before  # what was recorded is kept as it was
    seeds = [json.loads(line)["seed"] for line in after]
    assert sorted(seeds) == list(range(6)), seeds  # each seed once: none run twice, none lost
    assert seeds[:len(before)] == seeds_before
