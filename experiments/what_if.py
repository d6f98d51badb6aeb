"""What-if perception: DODT's reports completed or corrected by the simulator's truth.

Diagnostics, not sensors: each class answers "how much would the closed loop gain if DODT did not
have this one shortcoming?" by removing it with the truth and leaving everything else as DODT reports
it. They are perception plug-ins (experiments.plugins), e.g.

    dodt-nav sweep corridor --seeds 400:600 --perception experiments.what_if:ViewCompleted --out runs/view
    dodt-nav compare runs/dodt runs/view

Completed (DODT's reports, plus each person they leave out, exact):
- ``RecentlyLeft``: people who left the camera's view less than ``memory`` (1 s) ago;
- ``SideCompleted``: people out of view within ``half_view`` (90 deg) of the camera's heading: a 180 deg view;
- ``ViewCompleted``: people in the camera's view as the ``oracle`` mode sees them (the horizontal view's cone
  within 5 m, so people hidden behind structure or another person too);
- ``VisibleCompleted``: people the depth frame shows (at least ``min_points`` of 15 points on the near side
  of the body project into the image at their own depth): what a tracker could report at once.

Corrected (DODT's reports only, changed):
- ``TrueStates``: each report of a person at that person's true centre, size and velocity;
- ``NoPhantoms``: the reports of no person dropped.

``Combined``: ``ViewCompleted``, ``RecentlyLeft`` and ``TrueStates`` at once: what the ``oracle`` mode
knows, with DODT's phantoms, and the map cleared under DODT's dynamic tracks only (the oracle clears it
under every person it reports).

Foreseen (not DODT at all):
- ``FutureKnown``: the ``oracle-360`` mode's reports, each predicting the person's true walk instead of a
  constant acceleration (``KnownFuture``; sim.crowd_future, people who do not see the drone only) and no
  uncertainty. What a perfect predictor would give the planner; fly it with the maneuvers' other futures
  off (``--set navigator.maneuvers.p_keep=1 --set navigator.maneuvers.p_turn=0 --set
  navigator.maneuvers.p_stop=0 --set navigator.maneuvers.worst_case=0``). The shield's discs still
  extrapolate the velocity. ``known_for`` limits how far ahead the walk is known (constant velocity
  after).

A person is reported when one of DODT's reports lies within ``match`` (0.6 m) of them horizontally. A
person added has the truth's centre, size and velocity, no acceleration, and the id ``ADDED_ID`` + theirs.
Subclass one to change its parameters (a plug-in is built with no arguments).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from dodt.context import EpisodeContext
from dodt.protocol import PerceptionOutput
from experiments.perception_modes import DODTPerception, OraclePerception, horizontal_view, oracle_view
from planner.types import ObstaclePrediction
from sim.crowd_future import blind_walk
from sim.ground_truth import person_id
from sim.scenario import load_scenario

ADDED_ID = 100000


def _exact(person, oid: int) -> ObstaclePrediction:
    return ObstaclePrediction(id=oid, center=person.center.copy(), size=person.size.copy(),
                              velocity=person.velocity.copy(), acceleration=np.zeros(3))


def _gap(report, person) -> float:
    return float(np.hypot(*(np.asarray(report.center[:2]) - person.center[:2])))


def _true_states(reports, people, match: float) -> list:
    """Each report within ``match`` of a person as that person, exact (the nearest; the report's id kept)."""
    out = []
    for q in reports:
        near = [(g, o) for o in people if (g := _gap(q, o)) < match]
        out.append(_exact(min(near, key=lambda x: x[0])[1], q.id) if near else q)
    return out


class _DODTWithTruth:
    uses_ground_truth = True
    uses_images = True
    uses_color = False
    match = 0.6  # m: a report this near a person (horizontally) reports them
    max_range = 5.0  # m: the oracle's range (to the body's near side)

    def __init__(self):
        self.dodt = DODTPerception("dodt")
        self.reset()

    @property
    def name(self) -> str:
        return f"dodt+{type(self).__name__}"

    def reset(self, context: EpisodeContext | None = None) -> None:
        self.dodt.reset(context)  # DODT's moving-track rule reads the context's static map
        self._last_in_view: dict[int, float] = {}

    def observe_lidar(self, scan) -> None:
        """The rig's LiDAR scans go to DODT as in the ``dodt`` mode (without this, DODT on a rig would see
        the forward camera alone)."""
        self.dodt.observe_lidar(scan)

    def observe_cameras(self, frames) -> None:
        """The rig's other cameras' frames, likewise."""
        self.dodt.observe_cameras(frames)

    def update(self, frame, truth=None) -> PerceptionOutput:
        if truth is None:
            raise ValueError(f"{type(self).__name__} needs the simulator's ground truth")
        out = self.dodt.update(frame)
        people = [o for o in truth.obstacles if o.kind == "person"]
        reports = self._corrected(out.obstacles, people)
        cam, heading, half_fov = horizontal_view(truth.T_world_camera, frame.intrinsics)
        added = []
        for o in people:
            in_view, bearing, near_side = oracle_view(cam, heading, half_fov, o, self.max_range)
            if in_view:
                self._last_in_view[o.id] = truth.stamp
            if any(_gap(q, o) < self.match for q in out.obstacles):
                continue  # DODT reports them
            if self._adds(o, in_view, bearing, near_side, truth, frame):
                added.append(_exact(o, ADDED_ID + o.id))
        return replace(out, obstacles=tuple(reports) + tuple(added))

    def _corrected(self, reports, people) -> list:
        """DODT's reports as passed on (all of them, unchanged, unless a subclass says otherwise)."""
        return list(reports)

    def _adds(self, person, in_view: bool, bearing: float, near_side: float, truth, frame) -> bool:
        """Whether ``person`` is added when DODT does not report them (none, unless a subclass says)."""
        return False


class RecentlyLeft(_DODTWithTruth):
    memory = 1.0  # s since the person was last in view

    def _adds(self, person, in_view, bearing, near_side, truth, frame) -> bool:
        seen = self._last_in_view.get(person.id)
        return not in_view and seen is not None and truth.stamp - seen <= self.memory


class SideCompleted(_DODTWithTruth):
    half_view = 90.0  # deg about the camera's heading

    def _adds(self, person, in_view, bearing, near_side, truth, frame) -> bool:
        return not in_view and bearing <= math.radians(self.half_view) and near_side <= self.max_range


class ViewCompleted(_DODTWithTruth):
    def _adds(self, person, in_view, bearing, near_side, truth, frame) -> bool:
        return in_view


class VisibleCompleted(_DODTWithTruth):
    min_points = 3  # of the 15 body points the depth frame must show
    depth_tolerance = 0.35  # m between a point's depth and the frame's there
    body = 0.25  # m: the near side's points lie this far in front of the centre, and this far to each side
    range_limit = 5.5  # m from the camera to the person's centre

    def reset(self, context: EpisodeContext | None = None) -> None:
        super().reset(context)
        self._depth = (None, None)  # (frame, its depth in metres): converted once per frame, when needed

    def _adds(self, person, in_view, bearing, near_side, truth, frame) -> bool:
        T = np.asarray(truth.T_world_camera, dtype=float)
        cam = T[:3, 3]
        d = person.center[:2] - cam[:2]
        dist = float(np.hypot(*d))
        if not 1e-3 < dist <= self.range_limit:
            return False
        if self._depth[0] is not frame:
            self._depth = (frame, frame.depth_m())
        return self._shown(person, d / dist, self._depth[1], frame.intrinsics, T)

    def _shown(self, person, toward, depth, K, T) -> bool:
        """Whether the depth frame shows at least min_points of 15 points on the body's near side (3
        columns across it, 5 heights from 20 to 90 % of its height)."""
        side = np.array([-toward[1], toward[0]])
        near = person.center[:2] - toward * self.body
        bottom, top = float(person.center[2] - person.size[2] / 2), float(person.center[2] + person.size[2] / 2)
        heights = np.linspace(bottom + 0.2 * (top - bottom), bottom + 0.9 * (top - bottom), 5)
        points = np.array([[*(near + side * s * self.body), z] for s in (-1.0, 0.0, 1.0) for z in heights])
        q = (points - T[:3, 3]) @ T[:3, :3]  # optical: x right, y down, z ahead
        q = q[q[:, 2] > 0.1]
        H, W = depth.shape
        shown = 0
        for (u, v), z in zip(K.project(q), q[:, 2]):
            if not (0 <= u < W and 0 <= v < H):
                continue
            i, j = int(v), int(u)
            window = depth[max(i - 2, 0):i + 3, max(j - 2, 0):j + 3]
            window = window[np.isfinite(window) & (window > 0)]
            if window.size and abs(float(np.median(window)) - z) < self.depth_tolerance:
                shown += 1
        return shown >= self.min_points


class TrueStates(_DODTWithTruth):
    def _corrected(self, reports, people) -> list:
        return _true_states(reports, people, self.match)


class NoPhantoms(_DODTWithTruth):
    def _corrected(self, reports, people) -> list:
        return [q for q in reports if any(_gap(q, o) < self.match for o in people)]


class Combined(RecentlyLeft):
    def _corrected(self, reports, people) -> list:
        return _true_states(reports, people, self.match)

    def _adds(self, person, in_view, bearing, near_side, truth, frame) -> bool:
        return in_view or super()._adds(person, in_view, bearing, near_side, truth, frame)


def _walk_at(t: np.ndarray, walk_t: np.ndarray, walk_xy: np.ndarray) -> np.ndarray:
    """(K, 2) a walk's positions at absolute times t (K,), interpolated; held at its ends."""
    return np.column_stack([np.interp(t, walk_t, walk_xy[:, 0]), np.interp(t, walk_t, walk_xy[:, 1])])


@dataclass(frozen=True, eq=False)
class KnownFuture(ObstaclePrediction):
    """A prediction that is the person's true walk: ``walk_t`` (K,) absolute times and ``walk_xy`` (K, 2)
    positions, from ``stamp``, the absolute time of ``center``; the height of ``center`` kept. Past the
    walk's end the person stays at its last place."""

    stamp: float = 0.0
    walk_t: np.ndarray = field(default_factory=lambda: np.zeros(1))
    walk_xy: np.ndarray = field(default_factory=lambda: np.zeros((1, 2)))
    known_for: float = math.inf  # s ahead of now the walk is known; later, its velocity then goes on

    def _at(self, t: np.ndarray) -> np.ndarray:
        s = np.minimum(t, self.stamp + self.known_for)
        xy = _walk_at(s, self.walk_t, self.walk_xy)
        late = t > s
        if np.any(late):
            h = 0.05
            v = (xy[late] - _walk_at(s[late] - h, self.walk_t, self.walk_xy)) / h
            xy[late] += v * (t[late] - s[late])[:, None]
        return xy

    def predict(self, times: np.ndarray) -> np.ndarray:
        t = self.stamp + np.asarray(times, dtype=float)
        xy = self._at(t) + (np.asarray(self.center, float)[:2] - self._at(np.array([self.stamp]))[0])
        return np.column_stack([xy, np.full(len(t), float(self.center[2]))])

    def advanced(self, lag: float) -> "KnownFuture":
        c = self.predict(np.array([lag, lag + 0.01]))
        return replace(self, center=c[0], velocity=(c[1] - c[0]) / 0.01, stamp=self.stamp + lag)


class FutureKnown(OraclePerception):
    """oracle-360 whose every report predicts the person's true walk (module docstring). It draws the walk
    again from the context's scenario name and seed, so it runs on shipped scenarios; a report away from
    the walk drawn (another scenario of the same name) is an error."""

    tolerance = 0.3  # m between a report's centre and the walk drawn, at the report's stamp

    known_for = math.inf  # s ahead of each report the walk is known (KnownFuture.known_for)

    def __init__(self):
        super().__init__(all_around=True, name="future-known")
        self._walk = None

    def reset(self, context: EpisodeContext | None = None) -> None:
        super().reset(context)
        if context is None:
            self._walk = None
            return
        sc = load_scenario(context.scenario, context.seed)
        t, xy = blind_walk(sc, context.seed, context.duration + 5.0)
        self._walk = (t, xy, person_id(len(sc.obstacles), 0))

    def update(self, frame, truth=None) -> PerceptionOutput:
        out = super().update(frame, truth)
        if self._walk is None:
            raise ValueError("future-known perception: reset with the episode's context first")
        t, xy, first = self._walk
        for o in out.obstacles:
            i = o.id - first
            here = _walk_at(np.array([out.stamp]), t, xy[:, i])[0] if 0 <= i < xy.shape[1] else np.full(2, np.inf)
            if not np.hypot(*(np.asarray(o.center, float)[:2] - here)) <= self.tolerance:
                raise ValueError(f"future-known perception: person {o.id} at t = {out.stamp:g} s is not where the walk "
                                 "drawn again from the scenario's name and seed puts them (is the scenario a shipped "
                                 "one, unchanged?)")
        preds = tuple(KnownFuture(id=o.id, center=o.center, size=o.size, velocity=o.velocity, std_growth=0.0,
                                  stamp=out.stamp, walk_t=t, walk_xy=xy[:, o.id - first], known_for=self.known_for)
                      for o in out.obstacles)
        return replace(out, obstacles=preds)
