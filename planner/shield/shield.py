"""Passive safety as a constraint on any planner's plans (docs/planner.md).

``PassiveSafetyShield`` wraps a planner (by default the maneuver + MPC planner of planner.nominal.navigator)
and checks every plan it makes before the drone flies it. What the drone commits to is the plan flown
for ``commit_time`` and then a stop: replanned every 0.1 s, the commitment is extended as long as it
stays safe, and if a replan fails the stop is what is left (FASTER's back-up trajectory). The check
(planner.shield.safety): the commitment keeps clear of static structure, of every place a tracked or
remembered person could get to, unless the drone is at rest or moving away from the threat. When the plan's commitment is not safe, the shield flies the
safe motion (a target velocity, then a stop) nearest to what the planner wanted; when none is safe,
the last safe commitment from now on; when that no longer is, the least unsafe motion.

A person who stops being reported is remembered on the last prediction for ``memory`` seconds, the
disc growing as a person's reach does, until the camera sees its place free again.
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass

import numpy as np

from dodt.context import EpisodeContext, reset_with_context
from planner.fallback import brake_and_hold, braking_1d, invalid_input_stop, valid_input
from planner.map.clearance import static_clearance
from planner.map.distance import opencv_distance
from planner.shield.candidates import Candidates, backups, roll, target_velocities
from planner.shield.safety import check, in_the_way
from planner.types import ObstaclePrediction, PlannerInput, Trajectory, usable_obstacles


# Why the shield stops remembering a person no longer reported: ``memory`` ran out; reported for under
# ``memory_min_age`` (``young``); another report within ``memory_merge`` of its prediction (``merged``: that
# one again); the camera saw its predicted place free since its last report (``seen_free``)
FORGET_REASONS = ("memory", "young", "merged", "seen_free")


@dataclass(frozen=True)
class ShieldConfig:
    dt: float = 0.1  # s, the commitment's step
    commit_time: float = 0.2  # s a plan is followed before the committed stop begins
    a_brake: float = 3.5  # m/s^2, the stop
    a_emergency: float = 5.0  # m/s^2, the stop when nothing is safe (the controller tilts up to 35 deg: 6.9)
    a_max: float = 2.5  # m/s^2, the alternatives' speeding up and turning
    v_max: float = 2.0  # m/s
    speeds: tuple[float, ...] = (0.3, 0.6, 1.0, 1.5)  # m/s, the alternatives' target speeds ...
    directions: int = 24  # ... in this many directions
    drone_radius: float = 0.43  # m: the collision box's horizontal circumradius (sim vehicle 0.51 x 0.70 m)
    static_margin: float = 0.1  # m kept from structure beyond the radius
    person_margin: float = 0.0  # m added to every person's disc
    person_body: float = 0.3  # m: an unseen person's radius
    person_accel: float = 0.0  # m/s^2 a person may change velocity by (a walker's speeding up and slowing)
    person_speed: float = 1.6  # m/s a person walks at most
    sigmas: float = 1.0  # position and velocity errors covered by the discs, in standard deviations
    at_rest: float = 0.05  # m/s: a plan this slow is at rest (the fault rule's 0.1, less the hover's drift)
    away_angle: float = math.radians(120.0)  # a threat this far off the motion is left behind
    lag: float = 0.1  # s the drone follows its plan late by
    memory: float = 2.0  # s a moving obstacle no longer reported is remembered
    memory_min_age: float = 0.5  # s: only obstacles reported this long are remembered
    memory_merge: float = 1.0  # m: an obstacle reported this near a remembered one is that one again
    band: float = 0.5  # m: structure within this of the flight altitude counts
    # choosing an alternative: the one nearest the planner's velocity, plus w_way per metre its resting
    # place lies in a walker's way over the way_look seconds after (planner.shield.safety.in_the_way)
    w_way: float = 3.0
    way_look: float = 2.0
    hold_speed: float = 0.3  # m/s: stopping from slower than this holds a fixed point
    hold_reanchor: float = 0.3  # m: a hold point farther than this from the drone is set anew
    # columns with a voxel the map never observed within unobserved_band of the flight altitude count as
    # structure: the commitment keeps clear of space no sensor has looked at (the back of a box); ours. The
    # band is the body's (0.12 m tall) and its altitude error, not the structure band: the camera cannot
    # see the whole of that near the drone, and a box lower than its top is seen over
    unobserved_is_blocked: bool = True
    unobserved_band: float = 0.1  # m


class PassiveSafetyShield:
    """Implements planner.types.Planner around another planner (module docstring)."""

    def __init__(self, planner, cfg: ShieldConfig = ShieldConfig()):
        self.planner = planner
        self.cfg = cfg
        self.reset()

    def reset(self, context: EpisodeContext | None = None) -> None:
        """Before an episode: the wrapped planner is reset with the same context."""
        reset_with_context(self.planner, context)
        self._fields = None
        self._committed: Candidates | None = None  # the last safe commitment, as one motion
        self._committed_t0 = 0.0
        self._tracks: dict[int, tuple[float, float, ObstaclePrediction]] = {}  # id -> first, last stamp, last
        self.interventions = 0
        self._anchor = None  # (2,) where the current hold began
        self.threats = None  # (M, 3) x, y, radius of the people's discs at the last plan (for the episode log)
        self.forgotten = []  # (x, y, reason) of the people it stopped remembering at the last plan (FORGET_REASONS)
        self.dropped_obstacles = 0  # obstacles with non-finite fields dropped at the boundary this episode

    @property
    def path(self):
        return getattr(self.planner, "path", None)

    @property
    def brake_accel(self) -> float:
        """m/s^2: the deceleration the shield stops with (its committed stop, and the stop on invalid input
        or an error): ShieldConfig.a_brake."""
        return self.cfg.a_brake

    def telemetry(self) -> dict:
        """What the latest plan saw, for a log: ``path``, the wrapped planner's global path (K, 2) in world
        x, y, or None; ``threats``, the people's reach discs the plan was checked against, (M, 3) x, y,
        radius (None when that plan checked none: no map, or its input was invalid); ``forgotten``, where
        the people it stopped remembering at that plan were predicted and why, [(x, y, reason)] with
        reasons from FORGET_REASONS; ``brake_accel``, the deceleration it stops with."""
        return {"path": self.path, "threats": self.threats, "forgotten": list(self.forgotten),
                "brake_accel": self.brake_accel}

    # ------------------------------------------------------------------ what could be where

    def _clearance(self, inp: PlannerInput) -> dict:
        """Metres to static structure on the map's column grid at the flight altitude (cached on the column grid)."""
        c, occ = self.cfg, inp.occupancy
        z = float(inp.goal[2])
        raw = occ.column_blocked(z - c.band, z + c.band, inflate=False)
        if c.unobserved_is_blocked and hasattr(occ, "column_unobserved"):
            raw = raw | occ.column_unobserved(z - c.unobserved_band, z + c.unobserved_band)
        fence = None if inp.geofence is None else tuple(np.r_[np.asarray(inp.geofence[0], float).ravel(),
                                                             np.asarray(inp.geofence[1], float).ravel()])
        key = (z, fence, occ.xy_origin.tobytes(), occ.cfg.resolution)  # and the grid itself, below
        f = self._fields
        if f is not None and f["key"] == key and np.array_equal(f["raw"], raw):
            return f  # the map changed elsewhere than in this band
        res = occ.cfg.resolution
        clear = static_clearance(raw, res, occ.xy_origin, inp.geofence, distance=opencv_distance)
        self._fields = {"key": key, "raw": raw, "clear": np.ascontiguousarray(clear), "origin": occ.xy_origin,
                        "res": res}
        return self._fields

    def _people(self, inp: PlannerInput):
        """Reach discs of the reported and the remembered moving obstacles: C0, Vp (M, 2), R0, G (M,)."""
        c, now = self.cfg, inp.stamp
        current = {}
        for o in inp.obstacles:
            if np.all(np.isfinite(o.center)) and np.all(np.isfinite(o.velocity)):
                self._tracks[o.id] = (self._tracks.get(o.id, (now,))[0], now, o)
                current[o.id] = o
        rows = [self._disc(o, 0.0) for o in current.values()]
        seen = inp.seen
        for oid, (first, last, o) in list(self._tracks.items()):
            if oid in current:
                continue
            age = now - last
            ghost = self._disc(o, age)
            why = self._forget(ghost, first, last, age, current, seen)
            if why is not None:
                del self._tracks[oid]
                self.forgotten.append((float(ghost[0]), float(ghost[1]), why))
            else:
                rows.append(ghost)
        if not rows:
            z = np.zeros((0, 2))
            return z, z.copy(), np.zeros(0), np.zeros(0)
        a = np.array(rows)
        return (np.ascontiguousarray(a[:, :2]), np.ascontiguousarray(a[:, 2:4]), np.ascontiguousarray(a[:, 4]),
                np.ascontiguousarray(a[:, 5]))

    def _forget(self, ghost, first: float, last: float, age: float, current: dict, seen) -> str | None:
        """Why a person no longer reported is not remembered (FORGET_REASONS), or None: still remembered."""
        c = self.cfg
        if age > c.memory:
            return "memory"
        if last - first < c.memory_min_age:
            return "young"
        if any(np.hypot(*(np.asarray(q.center[:2]) - ghost[:2])) < c.memory_merge for q in current.values()):
            return "merged"
        if seen is not None:  # its predicted place seen free since it was last reported
            i, j = np.floor((np.asarray(ghost[:2]) - seen.origin) / seen.res).astype(int)
            if 0 <= i < seen.shape[0] and 0 <= j < seen.shape[1] and seen.last[i, j] > last:
                return "seen_free"
        return None

    def _disc(self, o: ObstaclePrediction, age: float) -> list[float]:
        """[cx, cy, vx, vy, r0, g] of an obstacle's reach disc ``age`` s after its report."""
        c = self.cfg
        v = np.asarray(o.velocity, float)[:2]
        sp = float(np.hypot(*v))
        if sp > c.person_speed:
            v = v * (c.person_speed / sp)
        size = np.asarray(o.size, float)
        body = 0.5 * float(np.hypot(size[0], size[1])) if np.all(np.isfinite(size[:2])) else c.person_body
        r0 = min(body, 1.0) + c.sigmas * float(o.position_std) + c.person_margin
        g = c.sigmas * float(o.std_growth)
        centre = np.asarray(o.center, float)[:2] + v * age
        return [centre[0], centre[1], v[0], v[1], r0 + g * age + 0.5 * c.person_accel * age * age,
                g + c.person_accel * age]

    # ------------------------------------------------------------------ planning

    def plan(self, inp: PlannerInput) -> Trajectory:
        t0 = time.perf_counter()
        inp, dropped = usable_obstacles(inp)
        if dropped:
            if not self.dropped_obstacles:
                warnings.warn(f"planner: an obstacle with non-finite fields was dropped at t = {inp.stamp} s; later "
                              "ones are counted (dropped_obstacles)", RuntimeWarning, stacklevel=2)
            self.dropped_obstacles += dropped
        try:
            tr = self._plan(inp)
        except Exception as e:  # noqa: BLE001 - a planner never raises: it stops instead, saying why
            self.reset()  # the error may have left its state half updated
            tr = invalid_input_stop(inp, self.cfg.a_brake)
            tr = Trajectory(tr.t0, tr.dt, tr.positions, tr.velocities, tr.accelerations, f"error:{type(e).__name__}")
        return Trajectory(tr.t0, tr.dt, tr.positions, tr.velocities, tr.accelerations, tr.status,
                          (time.perf_counter() - t0) * 1e3, tr.yaw)

    def _plan(self, inp: PlannerInput) -> Trajectory:
        c = self.cfg
        self.threats = None
        self.forgotten = []
        if not valid_input(inp):
            return invalid_input_stop(inp, c.a_brake)
        if inp.occupancy is None:
            return self.planner.plan(inp)
        fields = self._clearance(inp)
        C0, Vp, R0, G = self._people(inp)
        self.threats = np.column_stack([C0, R0])
        o, res = fields["origin"], fields["res"]
        p0, v0 = np.asarray(inp.position, float), np.asarray(inp.velocity, float)
        i, j = np.clip(np.floor((p0[:2] - o) / res).astype(int), 0, np.array(fields["clear"].shape) - 1)
        need = min(c.drone_radius + c.static_margin, float(fields["clear"][i, j]) - 0.05)  # inside: no closer

        def checked(motion: Candidates):
            return check(motion.P, motion.V, c.dt, fields["clear"], o[0], o[1], res, C0, Vp, R0, G,
                         c.person_accel, c.person_speed, need, c.drone_radius, c.at_rest, math.cos(c.away_angle),
                         c.lag)

        nominal = self.planner.plan(inp)
        planned = self._sampled(nominal, inp, p0, v0)
        commit = backups(planned.P, planned.V, c.commit_time, c.dt, c.a_brake, c.v_max)
        ok, _ = checked(commit)
        if ok[0]:
            self._commit(commit, inp.stamp)
            self._anchor = None
            return nominal
        # the plan's commitment is not safe: the safe motion nearest to it
        self.interventions += 1
        targets = target_velocities(0.0, c.speeds, c.directions)
        alt = roll(p0, v0, targets, c.commit_time, c.dt, c.a_max, c.a_brake, c.v_max)
        safe, violation = checked(alt)
        want = planned.V[0, min(2, planned.V.shape[1] - 1)]
        if safe.any():
            way = in_the_way(alt.P, c.dt, C0, Vp, R0 + c.drone_radius, c.way_look)
            cost = np.hypot(*(targets - want).T) + c.w_way * way
            k = int(np.argmin(np.where(safe, cost, np.inf)))
            if k == 0 and float(np.hypot(*v0[:2])) < c.hold_speed:
                return self._hold(inp, nominal)
            return self._fly(alt, k, inp, nominal, "shield:alternative", still=k == 0)
        prev = self._previous(inp)
        if prev is not None and checked(prev)[0][0]:
            return self._fly(prev, 0, inp, nominal, "shield:committed stop")
        # nothing is safe: stop as hard as the drone can, to be at rest, or as slow as it can be, at contact
        stop = brake_and_hold(inp.stamp, p0, v0, a_max=c.a_emergency, dt=c.dt)
        motion = Candidates(stop.positions[None, :, :2], stop.velocities[None, :, :2], stop.accelerations[None, :, :2],
                            np.zeros((1, 2)), np.zeros(1, np.int64))
        return self._fly(motion, 0, inp, nominal, "shield:emergency stop", still=True)

    def _sampled(self, tr: Trajectory, inp: PlannerInput, p0, v0) -> Candidates:
        """The planned trajectory from now on, on the commitment's grid, as one motion (2D)."""
        c = self.cfg
        n = int(math.ceil(max(tr.duration, c.commit_time) / c.dt))
        P, V = np.empty((1, n + 1, 2)), np.empty((1, n + 1, 2))
        P[0, 0], V[0, 0] = p0[:2], v0[:2]
        p, v, _ = tr.sample_many(inp.stamp + np.arange(1, n + 1) * c.dt)
        P[0, 1:], V[0, 1:] = p[:, :2], v[:, :2]
        return Candidates(P, V, np.zeros((1, n, 2)), np.zeros((1, 2)), np.zeros(1, np.int64))

    def _commit(self, motion: Candidates, stamp: float) -> None:
        self._committed = Candidates(motion.P[:1].copy(), motion.V[:1].copy(), motion.A[:1].copy(),
                                     np.zeros((1, 2)), motion.commit[:1].copy())
        self._committed_t0 = float(stamp)

    def _previous(self, inp: PlannerInput) -> Candidates | None:
        """The last safe commitment from now on (resting at its end), or None."""
        m, c = self._committed, self.cfg
        if m is None:
            return None
        s = int(round((inp.stamp - self._committed_t0) / c.dt))
        if s < 0 or s >= m.P.shape[1]:
            return None
        P = np.concatenate([m.P[:, s:], np.repeat(m.P[:, -1:], s, axis=1)], axis=1)
        V = np.concatenate([m.V[:, s:], np.zeros((1, s, 2))], axis=1)
        A = np.concatenate([m.A[:, s:], np.zeros((1, s, 2))], axis=1)
        return Candidates(P, V, A, m.targets, m.commit)

    def _hold(self, inp: PlannerInput, nominal: Trajectory) -> Trajectory:
        """Stay where the hold began (a fixed point: re-based on every plan, a hover drifts with the drone)."""
        c = self.cfg
        p0 = np.asarray(inp.position, float)
        if self._anchor is None or float(np.hypot(*(self._anchor - p0[:2]))) > c.hold_reanchor:
            self._anchor = p0[:2].copy()
        n = int(round(c.commit_time / c.dt)) + 1
        motion = Candidates(np.repeat(self._anchor[None, None], n + 1, axis=1), np.zeros((1, n + 1, 2)),
                            np.zeros((1, n, 2)), np.zeros((1, 2)), np.zeros(1, np.int64))
        return self._fly(motion, 0, inp, nominal, "shield:hold", still=True)

    def _fly(self, motion: Candidates, k: int, inp: PlannerInput, nominal: Trajectory, status: str,
             still: bool = False) -> Trajectory:
        """Motion k as the trajectory, with the heading of the planner's plan and its altitude; ``still`` (a
        stop or a hold): the altitude's rate braked to zero at a_brake instead, so that at rest the drone
        is at rest in all three axes."""
        c = self.cfg
        P, V, A = motion.P[k], motion.V[k], motion.A[k]
        n = A.shape[0]
        if still:
            z, vz = braking_1d(float(inp.position[2]), float(inp.velocity[2]), c.a_brake, c.dt, n)
        else:
            z = np.array([nominal.sample(inp.stamp + q * c.dt)[0][2] for q in range(n + 1)])
            vz = np.array([nominal.sample(inp.stamp + q * c.dt)[1][2] for q in range(n + 1)])
        az = np.diff(vz) / c.dt
        self._committed = Candidates(motion.P[k:k + 1].copy(), motion.V[k:k + 1].copy(), motion.A[k:k + 1].copy(),
                                     np.zeros((1, 2)), motion.commit[k:k + 1].copy())
        self._committed_t0 = float(inp.stamp)
        return Trajectory(t0=float(inp.stamp), dt=c.dt, positions=np.column_stack([P, z]),
                          velocities=np.column_stack([V, vz]), accelerations=np.column_stack([A, az]), status=status,
                          yaw=nominal.yaw)
