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
  ``min_visible_px`` pixels in the segmentation, or, without segmentation, centre in view; with
  ``all_round``, a rig's, in any direction) that are matched by a dynamic track, over all such people;
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
- time to moving (``moving_latency_*``): for each stretch in which a walking person is visible within
  ``table_range`` (the recall's test; a stretch ends after ``stretch_gap`` s not visible), the time from
  its first visible frame to the first in which a dynamic track is matched to the person (0 when one
  already is); the median and 90th percentile over stretches, and how many stretches saw no such report
  (``moving_latency_unreported``). DODT's dynamic label, the one the closed loop avoids;
- speed of static tracks: the reported horizontal speed of every track labelled static, in every
  frame (``static_speed_p95``), and of every track, whatever its label, lying farther than
  ``still_distance`` (1 m) from every person (``still_speed_p95``): what a planner that reads every
  obstacle's velocity gets from obstacles that do not move;
- track life (``TrackLife``, the same figures in the closed-loop summary, read from the episode log):
  continuity, phantom- and drifted-moving reports per minute, the largest reported speed, and identity switches
  over every track, whatever its label.
"""
from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from dodt.frames import CameraIntrinsics
from dodt.geometry import in_field_of_view

# the median distance from the mean of an isotropic 2D Gaussian, in standard deviations per axis
MEDIAN_PER_SIGMA = float(np.sqrt(2.0 * np.log(2.0)))
RECALL_BINS = (0.5, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 10.0)  # m, camera distance
WALKING_SPEED = 0.1  # m/s: a person faster than this walks (recall and time to moving count only walkers)


def match_pairs(tracks_xy: np.ndarray, people_xy: np.ndarray, gate: float) -> list[tuple[int, int]]:
    """One-to-one (track, person) index pairs nearest overall (Hungarian assignment on the horizontal
    distance between centres) among the pairs within ``gate`` metres: the pairs beyond it cost the same
    large amount, so that no far pair (dropped after) draws a track from a near one."""
    if not len(tracks_xy) or not len(people_xy):
        return []
    dist = np.linalg.norm(tracks_xy[:, None] - people_xy[None], axis=2)
    r, c = linear_sum_assignment(np.where(dist <= gate, dist, 1e6))
    return [(i, j) for i, j in zip(r, c) if dist[i, j] <= gate]


@dataclass
class MovingLatency:
    """Time to moving: for each stretch in which a walking person is in view and within reach (a stretch
    ends after ``stretch_gap`` s not so), the time from its first such frame to the first in which a track
    labelled dynamic is matched to the person (0 when one already is). ``add`` once per frame and person
    in view."""

    stretch_gap: float = 0.5  # s a person may go unseen within one stretch
    stretches: dict = field(default_factory=dict)  # person id -> [first visible, last visible, reported]
    latencies: list = field(default_factory=list)  # s, one per stretch reported moving
    unreported: int = 0  # closed stretches without a dynamic report

    def add(self, stamp: float, pid, reported: bool) -> None:
        st = self.stretches.get(pid)
        if st is not None and stamp - st[1] > self.stretch_gap:  # a new stretch: the last one ended
            self.unreported += not st[2]
            st = None
        if st is None:
            st = self.stretches[pid] = [stamp, stamp, False]
        st[1] = stamp
        if reported and not st[2]:
            st[2] = True
            self.latencies.append(stamp - st[0])

    def all_unreported(self) -> int:
        """Stretches without a dynamic report: the closed ones and those still open."""
        return self.unreported + sum(not st[2] for st in self.stretches.values())

    def summary(self) -> dict:
        x = self.latencies
        return {"moving_latency_median": float(np.median(x)) if x else float("nan"),
                "moving_latency_p90": float(np.percentile(x, 90)) if x else float("nan"),
                "moving_latency_n": len(x), "moving_latency_unreported": self.all_unreported()}

    @staticmethod
    def combine(parts: list["MovingLatency"]) -> "MovingLatency":
        m = MovingLatency()
        for p in parts:
            m.latencies += p.latencies
            m.unreported += p.all_unreported()
        return m


@dataclass
class TrackLife:
    """How well the tracks keep the people and how much motion they invent, frame by frame (``add``):

    - continuity: of the frames in which a person is within ``reach`` (5 m) of the sensor, in view or
      not, the share in which a track, whatever its label, is matched to the person (one-to-one,
      nearest, within ``match_distance``); pooled over people, so each person weighs by the time
      spent within reach. ``continuity_moving``: the share in which a track labelled dynamic lies
      within ``match_distance`` of the person;
    - phantom-moving reports: a track labelled dynamic farther than ``match_distance`` from every
      person that has never been matched to a person (motion invented on structure or noise), counted
      once per stretch of frames in a row it stays so, per minute of frames (``phantom_moving_s``: the
      track-seconds of such reports);
    - drifted-moving reports (``drifted_moving*``): the same for a track that has been matched to a
      person before (its prediction left the person it followed: a person lost, not one invented);
    - the largest reported horizontal speed of any track, whatever its label;
    - identity switches (``track_id_switches``): a person matched to another track id than the
      last time it was matched (the matching of continuity).

    The time is the sum of the gaps between consecutive frames, each at most ``max_gap`` seconds.
    """

    match_distance: float = 0.5  # m
    reach: float = 5.0  # m
    max_gap: float = 1.0  # s
    last_id: dict = field(default_factory=dict)  # person id -> the track id last matched
    person_frames: int = 0  # frames x people within reach
    reported: int = 0  # of those, matched by a track
    reported_moving: int = 0  # of those, with a dynamic track within match_distance
    phantoms: set = field(default_factory=set)  # the track ids phantom-moving in the latest frame
    drifts: set = field(default_factory=set)  # the track ids drifted-moving in the latest frame
    on_person: set = field(default_factory=set)  # the track ids ever matched to a person
    drifted_reports: int = 0
    drifted_s: float = 0.0  # track-seconds
    track_id_switches: int = 0
    phantom_reports: int = 0
    phantom_s: float = 0.0  # track-seconds
    last_t: float | None = None  # s, the latest frame's stamp
    max_speed: float = 0.0  # m/s
    seconds: float = 0.0

    def add(self, stamp: float, sensor, tracks, people) -> None:
        """One frame: ``sensor`` (3,) its position; ``tracks``: (id, centre (3,), velocity (3,), dynamic)
        per reported track; ``people``: (id, centre (3,)) per person of the ground truth."""
        dt = 0.0 if self.last_t is None else min(max(stamp - self.last_t, 0.0), self.max_gap)
        self.last_t = stamp
        self.seconds += dt
        sensor = np.asarray(sensor, dtype=float)
        t_xy = np.array([np.asarray(c, dtype=float)[:2] for _, c, _, _ in tracks]).reshape(-1, 2)
        p_xyz = np.array([np.asarray(c, dtype=float)[:3] for _, c in people]).reshape(-1, 3)
        for _, _, v, _ in tracks:
            self.max_speed = max(self.max_speed, float(math.hypot(v[0], v[1])))
        matched = {j: tracks[i][0] for i, j in match_pairs(t_xy, p_xyz[:, :2], self.match_distance)}
        self.on_person.update(matched.values())
        for j, tid in matched.items():
            pid = people[j][0]
            if pid in self.last_id and self.last_id[pid] != tid:
                self.track_id_switches += 1
            self.last_id[pid] = tid
        dyn = np.array([bool(d) for *_, d in tracks], dtype=bool)
        dist = (np.linalg.norm(t_xy[:, None] - p_xyz[None, :, :2], axis=2) if len(people)
                else np.full((len(tracks), 0), np.inf))
        for j in range(len(people)):
            if np.linalg.norm(p_xyz[j] - sensor) <= self.reach:
                self.person_frames += 1
                self.reported += j in matched
                self.reported_moving += bool(np.any(dyn & (dist[:, j] <= self.match_distance)))
        far = dist.min(axis=1) > self.match_distance if len(people) else np.ones(len(tracks), dtype=bool)
        off = {tracks[i][0] for i in np.flatnonzero(dyn & far)}
        now, drifts = off - self.on_person, off & self.on_person
        self.phantom_reports += len(now - self.phantoms)
        self.phantom_s += dt * len(now & self.phantoms)
        self.phantoms = now
        self.drifted_reports += len(drifts - self.drifts)
        self.drifted_s += dt * len(drifts & self.drifts)
        self.drifts = drifts

    def summary(self) -> dict:
        """The figures (None where nothing was counted)."""
        minutes = self.seconds / 60.0
        return {"continuity": self.reported / self.person_frames if self.person_frames else None,
                "continuity_moving": self.reported_moving / self.person_frames if self.person_frames else None,
                "continuity_frames": self.person_frames,
                "phantom_moving_per_min": self.phantom_reports / minutes if minutes > 0 else None,
                "phantom_moving": self.phantom_reports, "phantom_moving_s": round(self.phantom_s, 4),
                "drifted_moving_per_min": self.drifted_reports / minutes if minutes > 0 else None,
                "drifted_moving": self.drifted_reports, "drifted_moving_s": round(self.drifted_s, 4),
                "max_reported_speed": round(self.max_speed, 4), "track_id_switches": self.track_id_switches,
                "track_life_s": round(self.seconds, 4)}

    @staticmethod
    def combine(parts: list["TrackLife"]) -> "TrackLife":
        """The counts of several runs summed (the largest speed the largest)."""
        m = TrackLife()
        for p in parts:
            for k in ("person_frames", "reported", "reported_moving", "track_id_switches", "phantom_reports",
                      "phantom_s", "drifted_reports", "drifted_s", "seconds"):
                setattr(m, k, getattr(m, k) + getattr(p, k))
            m.max_speed = max(m.max_speed, p.max_speed)
        return m


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
    life: TrackLife = field(default_factory=TrackLife)
    # recall of the people all round the sensors (a rig's), not only of those in the first camera's view
    all_round: bool = False
    latency: MovingLatency = field(default_factory=MovingLatency)

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
        self.life.add(float(truth.stamp), truth.T_world_camera[:3, 3],
                      [(o.id, o.center, o.velocity, o.dynamic) for o in getattr(result, "obstacles", ())],
                      [(p.id, p.center) for p in people])
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
            if np.linalg.norm(p.velocity[:2]) <= WALKING_SPEED or not RECALL_BINS[0] <= dist <= RECALL_BINS[-1]:
                continue
            if self.all_round:
                visible = True
            elif truth.segmentation is not None:
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
            if dist <= self.table_range:
                self.latency.add(float(truth.stamp), p.id, p.id in matched_people)
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
                "pred_err_cv": mean(self.pred_cv), "pred_err_ca": mean(self.pred_ca), "predicted": len(self.pred_cv),
                **self.latency.summary(), **self.life.summary()}

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
        m.life = TrackLife.combine([p.life for p in parts])
        m.latency = MovingLatency.combine([p.latency for p in parts])
        return m.summary()


def per_scenario(results: dict) -> dict:
    """{(scenario, config): PerceptionMetrics} -> {config: combined summary}."""
    by_cfg = defaultdict(list)
    for (_, cfg), m in results.items():
        by_cfg[cfg].append(m)
    return {cfg: PerceptionMetrics.combine(ms) for cfg, ms in by_cfg.items()}
