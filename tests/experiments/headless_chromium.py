"""A screenshot of a page in headless Chromium, driven over the DevTools protocol on a pipe.

Chromium's own ``--screenshot`` flag gives no control over when the picture is taken and, with
``--virtual-time-budget``, can wait forever (it did on a CI machine for a ``file://`` page). Here every
step has its own deadline, the picture is taken once the page has loaded and drawn a number of
animation frames in real time, and a failure says which step did not answer and what Chromium printed.
"""
from __future__ import annotations

import base64
import fcntl
import json
import os
import select
import subprocess
import tempfile
import time
from pathlib import Path

# The closed network of a CI machine refuses or never answers Chromium's own background requests.
QUIET_FLAGS = ["--disable-background-networking", "--disable-component-update", "--disable-sync",
               "--disable-quic", "--no-first-run", "--no-default-browser-check", "--disable-dev-shm-usage"]


class ChromiumError(RuntimeError):
    pass


class _Pipe:
    """The DevTools protocol over ``--remote-debugging-pipe``: JSON messages ending in NUL, commands
    on the child's fd 3, answers and events on its fd 4."""

    def __init__(self, chromium: str, args: list[str]):
        to_child_r, self._to_child = os.pipe()
        self._from_child, from_child_w = os.pipe()
        # Copies above fd 4, so that placing one at 3 or 4 in the child cannot overwrite the other.
        high_r, high_w = (fcntl.fcntl(fd, fcntl.F_DUPFD_CLOEXEC, 10) for fd in (to_child_r, from_child_w))
        os.close(to_child_r)
        os.close(from_child_w)
        self._stderr = tempfile.TemporaryFile()

        def fds():  # runs in the child before exec (and before it closes fds not in pass_fds)
            os.dup2(high_r, 3)
            os.dup2(high_w, 4)

        self.proc = subprocess.Popen([chromium, "--remote-debugging-pipe", *args], stdin=subprocess.DEVNULL,
                                     stdout=subprocess.DEVNULL, stderr=self._stderr, preexec_fn=fds,
                                     pass_fds=(3, 4))
        os.close(high_r)
        os.close(high_w)
        self._buf = b""
        self._next_id = 0
        self.events: list[dict] = []

    def stderr_tail(self, n: int = 1500) -> str:
        self._stderr.seek(0)
        return self._stderr.read().decode(errors="replace")[-n:]

    def _read_message(self, deadline: float, what: str) -> dict:
        while b"\0" not in self._buf:
            left = deadline - time.monotonic()
            if left <= 0 or self.proc.poll() is not None:
                state = "exited with status %s" % self.proc.returncode if self.proc.poll() is not None \
                    else "gave no answer in time"
                raise ChromiumError(f"chromium {state} while waiting for {what}; it printed:\n{self.stderr_tail()}")
            ready, _, _ = select.select([self._from_child], [], [], min(left, 0.5))
            if ready:
                chunk = os.read(self._from_child, 1 << 20)
                if not chunk:
                    self.proc.wait(timeout=5)
                    continue
                self._buf += chunk
        raw, self._buf = self._buf.split(b"\0", 1)
        return json.loads(raw)

    def call(self, method: str, params: dict | None = None, session: str | None = None,
             timeout: float = 30.0) -> dict:
        self._next_id += 1
        msg = {"id": self._next_id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        os.write(self._to_child, json.dumps(msg).encode() + b"\0")
        deadline = time.monotonic() + timeout
        while True:
            m = self._read_message(deadline, method)
            if m.get("id") == self._next_id:
                if "error" in m:
                    raise ChromiumError(f"{method} failed: {m['error']}")
                return m.get("result", {})
            self.events.append(m)

    def wait_event(self, method: str, session: str, timeout: float) -> dict:
        deadline = time.monotonic() + timeout
        while True:
            for i, e in enumerate(self.events):
                if e.get("method") == method and e.get("sessionId") == session:
                    return self.events.pop(i)
            self.events.append(self._read_message(deadline, method))

    def close(self) -> None:
        for fd in (self._to_child, self._from_child):
            try:
                os.close(fd)
            except OSError:
                pass
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(timeout=10)
        self._stderr.close()


def screenshot(chromium: str, url: str, png: Path, profile: Path, width: int = 800, height: int = 600,
               frames: int = 30, timeout: float = 60.0) -> Path:
    """Load ``url``, let it draw ``frames`` animation frames, write what it shows to ``png``.

    Software WebGL (SwiftShader) stands in for a GPU. Raises ChromiumError naming the step that failed.
    """
    args = ["--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader", "--hide-scrollbars",
            f"--window-size={width},{height}", f"--user-data-dir={profile}", *QUIET_FLAGS, "about:blank"]
    pipe = _Pipe(chromium, args)
    try:
        targets = pipe.call("Target.getTargets", timeout=timeout)["targetInfos"]
        pages = [t for t in targets if t["type"] == "page"]
        target = pages[0]["targetId"] if pages else pipe.call("Target.createTarget", {"url": "about:blank"})["targetId"]
        session = pipe.call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        pipe.call("Page.enable", session=session)
        pipe.call("Emulation.setDeviceMetricsOverride", {"width": width, "height": height, "deviceScaleFactor": 1,
                                                         "mobile": False}, session=session)
        pipe.call("Page.navigate", {"url": url}, session=session, timeout=timeout)
        pipe.wait_event("Page.loadEventFired", session, timeout)
        wait = ("new Promise(done => { let n = %d; const step = () => (--n > 0) ? requestAnimationFrame(step)"
                " : done(true); requestAnimationFrame(step); })" % frames)
        pipe.call("Runtime.evaluate", {"expression": wait, "awaitPromise": True}, session=session, timeout=timeout)
        shot = pipe.call("Page.captureScreenshot", {"format": "png"}, session=session, timeout=timeout)
        png.write_bytes(base64.b64decode(shot["data"]))
        pipe.call("Browser.close", timeout=10)
    finally:
        pipe.close()
    return png
