"""The meshcat server of `dodt-nav run --viz live` ends with the run, however the run ends: killed with
SIGKILL or SIGTERM while the episode runs, or failing to start its server; its ports are free then."""
from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys

import pytest

from experiments.meshcat_server import start_meshcat_server
from processes import alive, children, descendants, kill_group, wait_for

pytestmark = pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="reads the process table from /proc")


def _port_free(port: int) -> bool:
    """Nothing listens on 127.0.0.1:port: a server could bind it (as meshcat's does, reusing the address)."""
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def _server_ports(pid: int) -> set[int]:
    """The TCP ports process ``pid`` listens on (its socket inodes matched against /proc/net/tcp)."""
    inodes = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            m = re.fullmatch(r"socket:\[(\d+)\]", os.readlink(f"/proc/{pid}/fd/{fd}"))
        except OSError:
            continue
        if m:
            inodes.add(m.group(1))
    ports = set()
    for line in open("/proc/net/tcp").read().splitlines()[1:]:
        f = line.split()
        if f[3] == "0A" and f[9] in inodes:  # LISTEN
            ports.add(int(f[1].split(":")[1], 16))
    return ports


@pytest.mark.parametrize("how", [signal.SIGKILL, pytest.param(signal.SIGTERM, marks=pytest.mark.slow)])
def test_the_live_viewer_server_ends_with_a_killed_run_and_frees_its_ports(tmp_path, how):
    run = subprocess.Popen([sys.executable, "-m", "experiments.cli", "run", "corridor", "--perception", "oracle",
                            "--map", "truth", "--duration", "600", "--viz", "live", "--no-wait",
                            "--out", str(tmp_path / "run")],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, start_new_session=True)
    try:
        line = run.stdout.readline()  # printed once the server answers
        assert line.startswith("meshcat viewer: http://127.0.0.1:"), line
        (server,) = children(run.pid, b"meshcat")
        assert wait_for(lambda: len(_server_ports(server)) >= 2, timeout=30)  # its zmq and web sockets
        ports = _server_ports(server)
        assert int(re.search(r":(\d+)/", line).group(1)) in ports
        below = descendants(run.pid)
        os.kill(run.pid, how)  # the run alone, not its group
        run.wait(timeout=60)
        assert wait_for(lambda: not any(alive(p) for p in below), timeout=10), \
            f"{[p for p in below if alive(p)]} outlived the run by 10 s"
        assert wait_for(lambda: all(_port_free(p) for p in ports), timeout=10), ports
    finally:
        kill_group(run)


def test_a_server_that_does_not_start_in_time_is_stopped(monkeypatch):
    before = set(children(os.getpid(), b"meshcat"))
    with pytest.raises(RuntimeError, match="did not start"):
        start_meshcat_server(timeout=0.01)
    assert wait_for(lambda: not set(children(os.getpid(), b"meshcat")) - before, timeout=10)
