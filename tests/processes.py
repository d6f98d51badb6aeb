"""The process table from /proc, for tests that check that child processes end with their parent."""
from __future__ import annotations

import os
import signal
import time


def parent_of(pid: int) -> int | None:
    try:
        stat = open(f"/proc/{pid}/stat").read()
    except OSError:
        return None
    return int(stat.rsplit(")", 1)[1].split()[1])


def cmdline(pid: int) -> bytes:
    try:
        return open(f"/proc/{pid}/cmdline", "rb").read()
    except OSError:
        return b""


def alive(pid: int) -> bool:
    """Running (a zombie waiting for its parent to reap it has ended)."""
    try:
        state = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def children(parent: int, marker: bytes = b"") -> list[int]:
    """The living processes whose parent is ``parent`` and whose command line holds ``marker``."""
    out = []
    for d in os.listdir("/proc"):
        if d.isdigit() and parent_of(int(d)) == parent and marker in cmdline(int(d)) and alive(int(d)):
            out.append(int(d))
    return out


def descendants(root: int) -> list[int]:
    """Every living process below ``root``."""
    found, frontier = [], [root]
    while frontier:
        kids = children(frontier.pop())
        found += kids
        frontier += kids
    return found


def wait_for(predicate, timeout: float, period: float = 0.05) -> bool:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(period)
    return True


def kill_group(p) -> None:
    """SIGKILL to whatever is left of the process group that subprocess ``p`` leads (started with
    ``start_new_session=True``), then reaps ``p``."""
    try:
        os.killpg(p.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    p.wait(timeout=30)
