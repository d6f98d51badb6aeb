"""Numba's compilation time, measured apart from the work it delays.

The hot loops of perception, the map and the planner are compiled by numba on their first call in a
process, and cached on disk (``cache=True``), so that a later process loads them instead. ``CompileTimer``
listens to numba's compile events while it is entered and adds up the outermost ones (a compilation that
triggers others counts once): the episode reports that time on its own and leaves it out of its timings.
"""
from __future__ import annotations

import time

from numba.core import event


class CompileTimer(event.Listener):
    def __init__(self):
        self.seconds = 0.0  # total time in outermost compilations (cache loads included)
        self._depth = 0
        self._start = 0.0
        self._spans: list[tuple[float, float]] = []  # (start, duration) of each outermost compilation
        self._installed = None

    def on_start(self, ev) -> None:
        if self._depth == 0:
            self._start = time.perf_counter()
        self._depth += 1

    def on_end(self, ev) -> None:
        self._depth -= 1
        if self._depth == 0:
            d = time.perf_counter() - self._start
            self.seconds += d
            self._spans.append((self._start, d))

    def seconds_after(self, t0: float) -> float:
        """Compilation time that began at ``time.perf_counter()`` t0 or later."""
        return sum(d for s, d in self._spans if s >= t0)

    def __enter__(self) -> "CompileTimer":
        event.register("numba:compile", self)
        return self

    def __exit__(self, *exc) -> None:
        event.unregister("numba:compile", self)
