"""The frame clock that turns the pipeline's windows of time into frames.

The pipeline's history windows are spans of seconds, not counts of frames (dodt.config), so one
configuration serves any frame rate. Each frame, a span is turned into the number of frame
intervals it covers at the frame period the pipeline sees (the median of the last intervals):
at the reference code's 30 Hz a span given as n frames' worth (n - 1 intervals, say 2 / 30 s for
its 3 consecutive candidates) is those n frames again, at 5 Hz it is two. Frames a track was not
detected in still count as intervals where the reference code counts them (the cloud voted
against, the frames coasted); entries a track records only when detected (its observations,
candidates, person votes, dynamic labels) are counted as the reference code counts them. A track a
LiDAR measures counts its force-dynamic window at the LiDAR's scan period (DODT keeps a second clock).

Two ways to count: ``intervals`` (back to the newest frame at least the span old: two frames at
any rate, for evidence that must recur, such as a person box or the frames a dynamic track must
miss before it is released) and ``frames_within`` (the frames inside the span: one at a rate
whose frame interval is longer than the span, for the consistency of candidates, where one frame
at 10 Hz already carries a vote over 0.2 s and a speed over 0.4 s).
"""
from __future__ import annotations

import math
from collections import deque


class FrameClock:
    """The frame period as the pipeline sees it.

    ``period``: the median of the last frame intervals (the reference period until one is seen).
    ``intervals(span)``: how many frame intervals a span of seconds covers at that period.
    ``steps(dt)``: dt in frames of the reference rate, the factor per-frame constants are scaled
    by, with the float rounding of a stamp difference taken off (a step of 1/30 s is exactly 1 at
    30 Hz)."""

    def __init__(self, reference_rate: float = 30.0):
        self.reference_rate = float(reference_rate)
        self._intervals: deque[float] = deque(maxlen=9)
        self.period = 1.0 / self.reference_rate

    def observe(self, dt: float) -> None:
        """Note the interval between two processed frames [s]."""
        if math.isfinite(dt) and dt > 0:
            self._intervals.append(dt)
            self.period = _median(self._intervals)

    def steps(self, dt: float) -> float:
        x = dt * self.reference_rate
        r = round(x)
        return float(r) if r >= 1 and abs(x - r) <= 1e-6 * r else x

    def intervals(self, span: float | None) -> int:
        """Frame intervals within ``span`` seconds at the current period: rounded up once the span
        exceeds a whole number of periods by a quarter period (stamp jitter and rounding move
        nothing), and at least one for any span above 0 (a window of time holds two frames at
        any rate). 0 for a span of 0 or None."""
        if span is None or not span > 0:
            return 0
        x = span / self.period
        if not x < 1e9:  # an infinite span, or frames far closer than any camera gives them
            return 1 << 30
        return max(1, math.ceil(x - 0.25))


    def frames_within(self, span: float | None) -> int:
        """How many frames lie within the last ``span`` seconds at the current period, the newest
        included (a quarter period of slack): 3 for 2 / 30 s at 30 Hz, 1 at 10 Hz and below,
        where one frame interval is longer than the span."""
        if span is None or not span > 0:
            return 1
        x = span / self.period
        if not x < 1e9:
            return 1 << 30
        return int(math.floor(x + 0.25)) + 1


def _median(values) -> float:
    """np.median of a few finite floats: the middle one, or the mean of the middle two."""
    v = sorted(values)
    m = len(v) // 2
    return float(v[m]) if len(v) % 2 else float((v[m - 1] + v[m]) / 2)


def blend(weight: float, steps: float) -> float:
    """The weight of a new value in exponential smoothing that gives ``weight`` per reference
    frame, for ``steps`` reference frames."""
    return weight if steps == 1.0 else 1.0 - (1.0 - weight) ** max(steps, 0.0)


def keep_last(entries: deque, n: int) -> None:
    """Drop all but the last ``n`` (at least 1) entries."""
    while len(entries) > max(n, 1):
        entries.popleft()
