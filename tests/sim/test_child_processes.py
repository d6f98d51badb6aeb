"""Child processes end with their parent: sim.parent_watch, and the render process (sim.render_process,
its child running sim.render_child) when its start fails and when the process that started it is killed."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

import pytest

from conftest import BASE
from processes import alive, children, wait_for
from sim import render_process
from sim.render_process import RenderProcess, RenderProcessError
from sim.scenario import parse_scenario

pytestmark = pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="reads the process table from /proc")


def _python(code: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", textwrap.dedent(code)], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True, start_new_session=True)


def _kill_group(p: subprocess.Popen) -> None:
    try:
        os.killpg(p.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    p.wait(timeout=30)


@pytest.mark.parametrize("how", [signal.SIGKILL, signal.SIGTERM])
def test_a_watching_child_ends_when_its_parent_is_killed(how):
    """A parent starts a child that calls exit_with_parent and would otherwise sleep for a minute."""
    parent = _python("""
        import os, subprocess, sys, time
        child = subprocess.Popen([sys.executable, "-c", "import sys, time; from sim.parent_watch import "
                                  "exit_with_parent; exit_with_parent(int(sys.argv[1])); print('ready', flush=True); "
                                  "time.sleep(60)", str(os.getpid())], stdout=subprocess.PIPE, text=True)
        assert child.stdout.readline() == "ready\\n"
        print(child.pid, flush=True)
        time.sleep(60)
    """)
    try:
        child = int(parent.stdout.readline())
        assert alive(child)
        os.kill(parent.pid, how)  # the parent alone, not its group
        parent.wait(timeout=30)
        assert wait_for(lambda: not alive(child), timeout=10), "the child outlived its parent by 10 s"
    finally:
        _kill_group(parent)


def test_a_child_whose_parent_died_before_it_watched_exits_at_once():
    r = subprocess.run([sys.executable, "-c", "from sim.parent_watch import exit_with_parent; "
                        "exit_with_parent(1, status=7); print('still here')"], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 7 and "still here" not in r.stdout


def test_a_render_process_that_does_not_start_in_time_is_ended(monkeypatch):
    """The audit's 1,000 people: the render process did not answer within its start time, the error was
    raised and the child went on building (1.6 GB). Now it is ended with the error."""
    monkeypatch.setattr(render_process, "_START_TIMEOUT_S", 0.01)
    before = set(children(os.getpid(), b"sim.render_child"))
    with pytest.raises(RenderProcessError, match="did not answer within"):
        RenderProcess(parse_scenario(BASE, "test.toml"), 0, "tiny", False)
    assert wait_for(lambda: not set(children(os.getpid(), b"sim.render_child")) - before, timeout=10)


@pytest.mark.parametrize("how", [signal.SIGKILL, pytest.param(signal.SIGTERM, marks=pytest.mark.slow)])
def test_the_render_process_ends_when_the_process_that_started_it_is_killed(how):
    """Killed while the child builds its world (it reads nothing from its socket then) or later."""
    parent = _python("""
        import os
        from conftest import BASE
        from sim.render_process import RenderProcess
        from sim.scenario import parse_scenario
        print(os.getpid(), flush=True)
        rp = RenderProcess(parse_scenario(BASE, "test.toml"), 0, "tiny", False)
        print("ready", flush=True)
        import time
        time.sleep(60)
    """.replace("from conftest", "import sys; sys.path.insert(0, %r); from conftest" % os.path.dirname(
        os.path.dirname(__file__))))
    try:
        assert int(parent.stdout.readline()) == parent.pid
        assert wait_for(lambda: children(parent.pid, b"sim.render_child"), timeout=60), "no render process"
        (child,) = children(parent.pid, b"sim.render_child")
        os.kill(parent.pid, how)
        parent.wait(timeout=30)
        assert wait_for(lambda: not alive(child), timeout=10), "the render process outlived its parent by 10 s"
    finally:
        _kill_group(parent)
