"""Perception metrics against simulator ground truth, computed per frame and summed.

Matching rule: in every frame, the tracks reported dynamic are matched one-to-one to the people
of the ground truth (Hungarian assignment on the horizontal distance between box centres),
a pair counting only within ``match_distance`` (0.5 m).
- position error: mean horizontal distance of matched pairs [m] (the filter estimates x, y;
  the 3D centre error is reported beside it), people within ``table_range`` (5 m, the range of
  the geometric detectors) of the camera, so that every configuration is scored on the same
  people; pairs farther away are scored apart (``pos_err_beyond``, ``vel_err_beyond``);
- velocity error: mean norm of the horizontal velocity difference of matched pairs [m/s], same
  range;
- false-positive rate (the paper's definition, static obstacles reported dynamic over all
  detections): dynamic reports farther than ``match_distance`` from every person, over all
  dynamic reports; a second dynamic track on a person (a duplicate) is counted apart;
- recall: people walking (> 0.1 m/s) within 0.5-5 m of the camera and visible (at least
  ``min_visible_px`` pixels in the segmentation, or, without segmentation, centre in view)
  that are matched by a dynamic track, over all such people;
- recall by distance: the same, counted in bins of camera distance out to 10 m (the paper's
  Fig. 10: the learned module's range extension); people beyond 5 m count when they show at
  least ``min_visible_px`` pixels (without segmentation: centre in view within 10 m);
- the filter's position std against its error (``std_scale``): the median, over matched pairs within
  ``table_range``, of the error over the track's reported ``position_std``, divided by sqrt(2 ln 2) (the
  median distance of an isotropic Gaussian error with one standard deviation per axis): 1 when the
  reported std is calibrated, below 1 when it overstates the error;
- prediction error (``pred_err_cv``, ``pred_err_ca``): for every matched pair within ``table_range``,
  where the track's state puts the person ``horizon`` (1 s) later, against where the person then is
  (mean horizontal distance): at constant velocity, and with the track's acceleration held (constant
  acceleration, the filter's own model). What a planner reading the tracks is told of the next second.
  The person's place is read at the first frame at or after that time (none within ``max_lag``: the pair
  is not scored; nor when the person has left the ground truth);
- id switches: a person matched by a different track id than the last time it was matched;
- speed of static tracks: the reported horizontal speed of every track labelled static, in every
  frame (``static_speed_p95``), and of every track, whatever its label, lying farther than
  ``still_distance`` (1 m) from every person (``still_speed_p95``): what a planner that reads every
  obstacle's velocity gets from obstacles that do not move.
"""
from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from dodt.frames import CameraIntrinsics
from dodt.geometry import in_field_of_view

# the median distance from the mean of an isotropic 2D Gaussian, in standard deviations per axis
MEDIAN_PER_SIGMA = float(np.sqrt(2.0 * np.log(2.0)))
RECALL_BINS = (0.5, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 10.0)  # m, camera distance


def bin_labels() -> list[str]:
    return [f"{a:g}-{b:g}" for a, b in zip(RECALL_BINS[:-1], RECALL_BINS[1:])]


@dataclass
class PerceptionMetrics:
    match_distance: float = 0.5
    min_visible_px: int = 400
    pos_err: list = field(default_factory=list)
    pos_err_3d: list = field(default_factory=list)
    vel_err: list = field(default_factory=list)
    std_ratio: list = field(default_factory=list)  # error / reported position_std, matched pairs in range
    table_range: float = 5.0
    pos_err_beyond: list = field(default_factory=list)
    vel_err_beyond: list = field(default_factory=list)
    dynamic_reports: int = 0
    false_dynamic: int = 0
    duplicates: int = 0
    visible_people: int = 0
    recalled_people: int = 0
    id_switches: int = 0
    visible_by_bin: list = field(default_factory=lambda: [0] * (len(RECALL_BINS) - 1))
    recalled_by_bin: list = field(default_factory=lambda: [0] * (len(RECALL_BINS) - 1))
    frames: int = 0
    still_distance: float = 1.0
    static_speeds: list = field(default_factory=list)
    still_speeds: list = field(default_factory=list)
    last_id: dict = field(default_factory=dict)
    series: list = field(default_factory=list)  # (t, mean pos err of the frame, mean vel err) for plots
    horizon: float = 1.0  # s, the prediction error's look-ahead
    max_lag: float = 0.1  # s, the latest frame after that time the prediction is scored at
    pred_cv: list = field(default_factory=list)  # m, constant-velocity prediction errors
    pred_ca: list = field(default_factory=list)  # m, constant-acceleration prediction errors
    pending: list = field(default_factory=list)  # (due stamp, person id, cv xy, ca xy), oldest first

    def _score_predictions(self, stamp: float, people: dict) -> None:
        """Scores the predictions due by ``stamp`` against ``people`` ({id: (2,) xy})."""
        n = 0
        for due, pid, cv, ca in self.pending:
            if due > stamp + 1e-9:
                break
            n += 1
            if stamp - due <= self.max_lag + 1e-9 and pid in people:
                self.pred_cv.append(float(np.linalg.norm(cv - people[pid])))
                self.pred_ca.append(float(np.linalg.norm(ca - people[pid])))
        del self.pending[:n]

    def add(self, result, truth, K: CameraIntrinsics) -> None:
        self.frames += 1
        people = [o for o in truth.obstacles if o.kind == "person"]
        if self.pending:
            self._score_predictions(float(truth.stamp), {p.id: p.center[:2] for p in people})
        for o in getattr(result, "obstacles", ()):
            speed = float(np.hypot(o.velocity[0], o.velocity[1]))
            if not o.dynamic:
                self.static_speeds.append(speed)
            if all(np.linalg.norm(o.center[:2] - p.center[:2]) > self.still_distance for p in people):
                self.still_speeds.append(speed)
        dyn = list(result.dynamic)
        self.dynamic_reports += len(dyn)
        pairs = []
        if dyn and people:
            a = np.array([o.center[:2] for o in dyn])
            b = np.array([p.center[:2] for p in people])
            cost = np.linalg.norm(a[:, None] - b[None], axis=2)
            r, c = linear_sum_assignment(cost)
            pairs = [(i, j) for i, j in zip(r, c) if cost[i, j] <= self.match_distance]
        for i, o in enumerate(dyn):
            if i in {a for a, _ in pairs}:
                continue
            if people and min(np.linalg.norm(o.center[:2] - p.center[:2]) for p in people) <= self.match_distance:
                self.duplicates += 1
            else:
                self.false_dynamic += 1
        fe, fv = [], []
        matched_people = {}
        for i, j in pairs:
            o, p = dyn[i], people[j]
            e = float(np.linalg.norm(o.center[:2] - p.center[:2]))
            v = float(np.linalg.norm(o.velocity[:2] - p.velocity[:2]))
            if np.linalg.norm(p.center - truth.T_world_camera[:3, 3]) > self.table_range:
                self.pos_err_beyond.append(e)
                self.vel_err_beyond.append(v)
            else:
                self.pos_err.append(e)
                self.pos_err_3d.append(float(np.linalg.norm(o.center - p.center)))
                self.vel_err.append(v)
                std = float(getattr(o, "position_std", 0.0))
                if std > 0.0:
                    self.std_ratio.append(e / std)
                h = self.horizon
                cv = o.center[:2] + h * np.asarray(o.velocity[:2], dtype=float)
                acc = np.asarray(getattr(o, "acceleration", np.zeros(3))[:2], dtype=float)
                self.pending.append((float(truth.stamp) + h, p.id, cv, cv + 0.5 * h * h * acc))
            fe.append(e)
            fv.append(v)
            matched_people[p.id] = o.id
            if p.id in self.last_id and self.last_id[p.id] != o.id:
                self.id_switches += 1
            self.last_id[p.id] = o.id
        cam = truth.T_world_camera
        for p in people:
            dist = float(np.linalg.norm(p.center - cam[:3, 3]))
            if np.linalg.norm(p.velocity[:2]) <= 0.1 or not RECALL_BINS[0] <= dist <= RECALL_BINS[-1]:
                continue
            if truth.segmentation is not None:
                visible = int(np.count_nonzero(truth.segmentation == p.id)) >= self.min_visible_px
            else:
                visible = bool(in_field_of_view(p.center[None], cam, K, RECALL_BINS[-1])[0])
            if not visible:
                continue
            b = min(int(np.searchsorted(RECALL_BINS, dist, side="right")) - 1, len(RECALL_BINS) - 2)
            self.visible_by_bin[b] += 1
            self.recalled_by_bin[b] += p.id in matched_people
            if dist <= 5.0:
                self.visible_people += 1
                self.recalled_people += p.id in matched_people
        self.series.append((truth.stamp, float(np.mean(fe)) if fe else np.nan, float(np.mean(fv)) if fv else np.nan))

    def summary(self) -> dict:
        def mean(x):
            return float(np.mean(x)) if x else float("nan")

        def p95(x):
            return float(np.percentile(x, 95)) if x else float("nan")
        return {"pos_err": mean(self.pos_err), "pos_err_3d": mean(self.pos_err_3d), "vel_err": mean(self.vel_err),
                "pos_err_beyond": mean(self.pos_err_beyond), "vel_err_beyond": mean(self.vel_err_beyond),
                "matched_beyond": len(self.pos_err_beyond),
                "fp_rate": self.false_dynamic / self.dynamic_reports if self.dynamic_reports else 0.0,
                "recall": self.recalled_people / self.visible_people if self.visible_people else float("nan"),
                "recall_by_distance": {lab: (r / v if v else float("nan")) for lab, v, r in
                                       zip(bin_labels(), self.visible_by_bin, self.recalled_by_bin)},
                "visible_by_distance": dict(zip(bin_labels(), self.visible_by_bin)),
                "recall_beyond_4m": (sum(self.recalled_by_bin[3:]) / sum(self.visible_by_bin[3:])
                                     if sum(self.visible_by_bin[3:]) else float("nan")),
                "id_switches": self.id_switches, "matched": len(self.pos_err), "dynamic_reports": self.dynamic_reports,
                "false_dynamic": self.false_dynamic, "duplicates": self.duplicates, "visible_people": self.visible_people, "frames": self.frames,
                "static_speed_p95": p95(self.static_speeds), "still_speed_p95": p95(self.still_speeds),
                "static_tracks": len(self.static_speeds),
                "std_scale": (float(np.median(self.std_ratio)) / MEDIAN_PER_SIGMA if self.std_ratio
                              else float("nan")),
                "pred_err_cv": mean(self.pred_cv), "pred_err_ca": mean(self.pred_ca), "predicted": len(self.pred_cv)}

    @staticmethod
    def combine(parts: list["PerceptionMetrics"]) -> dict:
        m = PerceptionMetrics()
        for p in parts:
            m.pos_err += p.pos_err
            m.pos_err_3d += p.pos_err_3d
            m.vel_err += p.vel_err
            m.std_ratio += p.std_ratio
            m.pred_cv += p.pred_cv
            m.pred_ca += p.pred_ca
            m.pos_err_beyond += p.pos_err_beyond
            m.vel_err_beyond += p.vel_err_beyond
            m.static_speeds += p.static_speeds
            m.still_speeds += p.still_speeds
            for k in ("dynamic_reports", "false_dynamic", "duplicates", "visible_people", "recalled_people",
                      "id_switches", "frames"):
                setattr(m, k, getattr(m, k) + getattr(p, k))
            m.visible_by_bin = [a + b for a, b in zip(m.visible_by_bin, p.visible_by_bin)]
            m.recalled_by_bin = [a + b for a, b in zip(m.recalled_by_bin, p.recalled_by_bin)]
        return m.summary()


def per_scenario(results: dict) -> dict:
    """{(scenario, config): PerceptionMetrics} -> {config: combined summary}."""
    by_cfg = defaultdict(list)
    for (_, cfg), m in results.items():
        by_cfg[cfg].append(m)
    return {cfg: PerceptionMetrics.combine(ms) for cfg, ms in by_cfg.items()}
