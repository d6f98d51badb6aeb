"""The camera-heading cost: how well a heading keeps in a forward camera's view where a candidate motion
goes and the moving obstacles to watch (the navigator's heading rule, NavigatorConfig)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit


@dataclass(frozen=True, eq=False)
class ViewTerm:
    """What the camera should keep in view (view_costs takes these): the heading rule's inputs."""
    headings: np.ndarray  # (H,) rad
    half_view: float  # rad: the camera's half field of view less a margin
    look_step: int  # the motion is p0 to the position at this step...
    look_time: float  # ... this many seconds ahead
    fallback: float  # rad: the motion's bearing when a candidate moves less than 0.3 m (nan: none)
    watch: np.ndarray  # (O, J, 2): each obstacle's predicted centre at the watch steps
    watch_steps: np.ndarray  # (J,) int
    watch_range: float  # m
    pull: float  # per rad between the heading and the motion

    def costs(self, P: np.ndarray, p0) -> tuple[np.ndarray, np.ndarray]:
        """view_costs of candidates P (C, N, 2) from p0: the least view cost (C,) and its heading index (C,)."""
        return view_costs(np.ascontiguousarray(P, dtype=float), np.asarray(p0, float)[:2], self.look_step,
                          self.look_time, self.fallback,
                          np.ascontiguousarray(self.watch, dtype=float).reshape(-1, len(self.watch_steps), 2),
                          np.asarray(self.watch_steps, np.int64), self.watch_range, self.half_view,
                          np.asarray(self.headings, float), self.pull)


@njit(cache=True, nogil=True)
def view_costs(P, p0, k_look, look_time, fallback, watch, k_watch, watch_range, half_view, headings, pull):
    """How well a camera can keep in view where each candidate goes and the obstacles to watch.

    For each candidate c (positions P (C, N, 2), P[c, k - 1] at step k, p0 at step 0), bearings with weights:
    the motion, from p0 to the position at step k_look, weighted by its mean speed (at least 0.5) when it is
    longer than 0.3 m, else ``fallback`` (a bearing; nan for none) weighted 0.5; and each watched point
    watch[o, j] (O, J, 2) seen from the candidate's position at step k_watch[j] when 0.05 < distance <
    watch_range, weighted 2 (1 - distance / watch_range). Returns, per candidate, the least over ``headings``
    of sum_b w_b max(|b - h| - half_view, 0) + pull |motion - h| and the index of the heading attaining it
    (cost 0 and index -1 when there is no bearing)."""
    C = P.shape[0]
    O, Jn = watch.shape[0], watch.shape[1]
    NH = headings.shape[0]
    best = np.zeros(C)
    arg = np.full(C, -1, np.int64)
    b = np.empty(1 + O * Jn)
    w = np.empty(1 + O * Jn)
    for c in range(C):
        x = P[c, k_look - 1, 0] - p0[0] if k_look > 0 else 0.0
        y = P[c, k_look - 1, 1] - p0[1] if k_look > 0 else 0.0
        n = 0
        motion = fallback
        if math.hypot(x, y) > 0.3:
            motion = math.atan2(y, x)
        if not math.isnan(motion):
            b[0], w[0] = motion, max(math.hypot(x, y) / look_time, 0.5)
            n = 1
        for o in range(O):
            for j in range(Jn):
                k = k_watch[j]
                dx, dy = (P[c, k - 1, 0], P[c, k - 1, 1]) if k > 0 else (p0[0], p0[1])
                qx, qy = watch[o, j, 0] - dx, watch[o, j, 1] - dy
                dist = math.hypot(qx, qy)
                if 0.05 < dist < watch_range:
                    b[n], w[n] = math.atan2(qy, qx), 2.0 * (1.0 - dist / watch_range)
                    n += 1
        if n == 0:
            continue
        lo, li = math.inf, -1
        for i in range(NH):
            h = headings[i]
            s = 0.0
            for m in range(n):
                off = abs((b[m] - h + math.pi) % (2 * math.pi) - math.pi)
                s += max(off - half_view, 0.0) * w[m]
            if not math.isnan(motion):
                s += pull * abs((motion - h + math.pi) % (2 * math.pi) - math.pi)
            if s < lo:
                lo, li = s, i
        best[c], arg[c] = lo, li
    return best, arg
