"""meshcat's server as a subprocess bound to 127.0.0.1, ended with the process that started it,
and a check that a server answers at a zmq url before meshcat's client blocks on it."""
from __future__ import annotations

import atexit
import os
import subprocess
import sys
import tempfile
import time

import zmq

# The server ends itself when the process that started it is gone (killed with SIGKILL: nothing there can
# stop it): sim.parent_watch, given that process's pid as the first argument.
_SERVER = """
import sys
from sim.parent_watch import exit_with_parent
exit_with_parent(int(sys.argv.pop(1)))
import tornado.web
_listen = tornado.web.Application.listen
tornado.web.Application.listen = lambda self, port, address="127.0.0.1", **kw: _listen(self, port, address, **kw)
from meshcat.servers.zmqserver import main
sys.argv[0] = "meshcat-server"
main()
"""


def start_meshcat_server(timeout: float = 20.0) -> tuple[subprocess.Popen, str, str]:
    """meshcat's server as a subprocess with both its zmq and web sockets on 127.0.0.1 (meshcat's
    own listens for browsers on every interface). Returns (process, zmq_url, web_url)."""
    log = tempfile.TemporaryFile()
    # Its own session: Ctrl-C in the terminal reaches this process alone, which then stops the server itself.
    proc = subprocess.Popen([sys.executable, "-u", "-c", _SERVER, str(os.getpid())], stdout=log,
                            stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL, start_new_session=True)
    deadline = time.monotonic() + timeout
    urls: dict[str, str] = {}
    try:
        while len(urls) < 2:
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"the meshcat server did not start (exit status {proc.poll()})")
            time.sleep(0.05)
            log.seek(0)
            for line in log.read().decode("utf-8", "replace").splitlines():
                key, _, value = line.partition("=")
                if key in ("zmq_url", "web_url"):
                    urls[key] = value.strip()
    except BaseException:  # not started in time, or interrupted while waiting: it must not stay behind
        stop_meshcat_server(proc)
        raise
    finally:
        log.close()
    atexit.register(stop_meshcat_server, proc)
    return proc, urls["zmq_url"], urls["web_url"]


def stop_meshcat_server(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def check_server(zmq_url: str, timeout_ms: int = 5000) -> None:
    """meshcat's client blocks for ever on a url nobody answers: ask first, with a deadline."""
    sock = zmq.Context.instance().socket(zmq.REQ)
    sock.setsockopt(zmq.LINGER, 0)
    sock.setsockopt(zmq.RCVTIMEO, timeout_ms)
    try:
        sock.connect(zmq_url)
        sock.send(b"url")
        sock.recv()
    except zmq.ZMQError as e:
        raise ConnectionError(f"no meshcat server answers at {zmq_url} ({e})") from None
    finally:
        sock.close()
