"""Child processes that end with the process that started them.

A child started by a command (the render process, a sweep's pool workers, the meshcat server of a
live viewer) is closed by its parent when the parent ends normally or by Ctrl-C or SIGTERM. When the
parent is killed outright (SIGKILL, a crash, an out-of-memory kill) nothing in it runs, and the
child would live on, holding its memory and ports. ``exit_with_parent`` makes the child watch for
that itself: once its parent is gone it is re-parented (its parent pid changes), and it exits.

Standard library only: it runs first thing in a child, before anything heavy is imported.
"""
from __future__ import annotations

import os
import threading
import time

WATCH_PERIOD_S = 0.2  # how often a child looks at its parent pid


def exit_with_parent(parent_pid: int, period: float = WATCH_PERIOD_S, status: int = 1) -> None:
    """End this process (``os._exit(status)``, no clean-up) as soon as ``parent_pid`` is no longer its
    parent; checked at once and then every ``period`` seconds by a daemon thread. Pass the parent's
    pid as the parent saw it (``os.getpid()`` there): a child that starts after its parent already died
    sees another parent pid from the start, and exits then."""
    if os.getppid() != parent_pid:
        os._exit(status)

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(period)
        os._exit(status)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()
