"""The default planner: passively safe motions chosen for progress (docs/planner.md).

Each call: (1) static fields of the voxel map at the flight altitude (clearance to structure and the
cost-to-go to the goal), refreshed when the map changed; (2) the moving obstacles as reach discs, with
those no longer reported remembered for a while; (3) the distance to space the camera has not seen
recently (planner.visibility); (4) candidate motions that end at rest (planner.candidates) checked for
safety (planner.safety) and ranked by progress and soft costs; (5) the heading. When no candidate is
safe, the last committed plan is flown on if it still is; otherwise the least unsafe candidate.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import cv2
from scipy.ndimage import binary_dilation

from planner.candidates import Candidates, backups
from planner.maneuvers import ManeuverConfig, hypotheses, _score, ManeuverSelector
from planner.fallback import brake_and_hold
from planner.global_path import cost_to_go
from planner.safety import bilinear, check, guide_index, in_the_way, proximity
from planner.types import ObstaclePrediction, PlannerInput, Trajectory


@dataclass(frozen=True)
class SafePlannerConfig:
    dt: float = 0.1  # s, the plan's step
    speeds: tuple[float, ...] = (0.3, 0.6, 1.0, 1.5, 2.0)  # m/s, target speeds of the candidates
    directions: int = 24  # target directions, evenly around the direction down the cost-to-go
    # s a target velocity is held before the committed plan brakes to rest: the plan the drone flies,
    # and the one that must be safe (replanned every 0.1 s, it is extended while it stays safe)
    commit_time: float = 0.2
    a_max: float = 2.5  # m/s^2 reaching a target velocity
    a_brake: float = 2.5  # m/s^2 the stop
    v_max: float = 2.0  # m/s
    drone_radius: float = 0.43  # m: the collision box's horizontal circumradius (sim vehicle 0.51 x 0.70 m)
    static_margin: float = 0.15  # m kept from structure beyond the radius
    person_margin: float = 0.1  # m added to every person's disc
    person_body: float = 0.3  # m: a person's radius where perception gives no size (unseen space)
    person_accel: float = 1.5  # m/s^2 a person may change velocity by (discs grow by a t^2 / 2)
    person_speed: float = 1.6  # m/s a person walks at most (unseen space; remembered people's speed cap)
    sigmas: float = 2.0  # position and velocity errors covered by the discs, in standard deviations
    at_rest: float = 0.05  # m/s: a plan this slow is at rest (the fault rule's 0.1, less the drone's hover drift)
    away_angle: float = math.radians(120.0)  # a threat this far off the motion is left behind
    lag: float = 0.15  # s the drone follows its plan late by
    memory: float = 2.0  # s a moving obstacle no longer reported is remembered
    memory_min_age: float = 0.5  # s: only obstacles reported this long are remembered
    memory_merge: float = 1.0  # m: an obstacle reported this near a remembered one is that one again
    band: float = 0.5  # m: structure within this of the flight altitude counts
    field_period: float = 0.2  # s between refreshes of the static fields
    eval_time: float = 1.0  # s: progress is the cost-to-go a candidate's target held this long gains
    look_time: float = 2.0  # s: proximity to people is judged on the target held this long (then a stop)
    w_progress: float = 1.0  # per m/s of cost-to-go gained
    w_turn: float = 0.3  # per rad (m/s) moving off where the camera looks
    w_smooth: float = 0.2  # per m/s of change of the target velocity from the last plan's
    w_soft: float = 0.5  # per exp(-gap / soft_scale): how near a candidate passes to each person's expected place
    soft_scale: float = 0.3  # m
    w_way: float = 2.0  # per m a resting place lies inside a walker's way
    way_look: float = 2.0  # s after coming to rest that a walker's way is looked at
    guide_range: float = 1.5  # m: the guide direction points at the best place this far away in clear view
    heading_speed: float = 0.3  # m/s: a slower plan faces down the cost-to-go instead of along its motion
    heading_time: float = 0.5  # s ahead: the heading looks where the plan and the people will be then
    view_half_angle: float = math.radians(35.0)  # the camera's 43.5 deg less a margin
    watch_range: float = 3.0  # m: people this near are kept in view
    w_look: float = 2.0  # weight of where the drone goes
    w_watch: float = 1.0  # weight of a person watched (times how near: 1 at the drone, 0 at watch_range)


def distance_to(mask: np.ndarray, res: float) -> np.ndarray:
    """(nx, ny) metres from each cell's centre to the nearest cell of ``mask`` (exact Euclidean; OpenCV's
    transform, several times faster than scipy's here)."""
    return cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE).astype(float) * res


_GUIDE_ANGLES = np.radians(np.arange(0.0, 360.0, 5.0))
_GUIDE_RADII = np.array([0.2, 0.5, 1.0])  # times guide_range
_HEADINGS = np.radians(np.arange(-180.0, 180.0, 5.0))


class SafePlanner:
    """Implements planner.types.Planner."""

    def __init__(self, cfg: SafePlannerConfig = SafePlannerConfig()):
        self.cfg = cfg
        self._selector = ManeuverSelector(ManeuverConfig(), horizon=25, dt=cfg.dt, a_max=cfg.a_max, v_max=cfg.v_max,
                                          robot_radius=cfg.drone_radius)
        self.reset()

    def reset(self) -> None:
        self._fields = None  # (map version, goal, stamp) and the fields
        self._committed: Trajectory | None = None
        self._chosen = None  # (stamp, accelerations) of the last chosen candidate
        self._tracks: dict[int, tuple[float, float, ObstaclePrediction]] = {}  # id -> first, last stamp, last
        self.path = None  # no global path polyline (the cost-to-go field guides)

    # ------------------------------------------------------------------ inputs

    def _static(self, inp: PlannerInput) -> dict:
        """Clearance (m), cost-to-go (m) and walkable cells on the map's column grid at the flight altitude."""
        c, occ, z = self.cfg, inp.occupancy, float(inp.goal[2])
        key = (getattr(occ, "version", None), tuple(np.round(inp.goal, 3)))
        if self._fields is not None and self._fields["key"] == key:
            return self._fields
        if self._fields is not None and self._fields["key"][1] == key[1] and \
                inp.stamp - self._fields["stamp"] < c.field_period:
            return self._fields
        col = occ.column_blocked(z - c.band, z + c.band, inflate=False)
        res, origin = occ.cfg.resolution, occ.xy_origin
        centres = occ.cell_to_world(np.argwhere(np.ones(col.shape, bool))).reshape(col.shape + (2,))
        outside = np.zeros(col.shape, bool)
        if inp.geofence is not None:
            lo, hi = np.asarray(inp.geofence[0], float), np.asarray(inp.geofence[1], float)
            outside = ((centres[..., 0] < lo[0]) | (centres[..., 0] > hi[0]) | (centres[..., 1] < lo[1])
                       | (centres[..., 1] > hi[1]))
        solid = col | outside
        clear = distance_to(solid, res) - 0.5 * res if solid.any() else np.full(col.shape, 1e3)
        r = int(math.ceil((c.drone_radius + c.static_margin) / res))
        disk = np.hypot(*np.mgrid[-r:r + 1, -r:r + 1]) <= r
        ctg = cost_to_go(binary_dilation(solid, disk), origin, res, inp.goal[:2])
        if not np.all(np.isfinite(ctg)):
            ctg = np.where(np.isfinite(ctg), ctg, 1e3)
        self._fields = {"key": key, "stamp": inp.stamp, "clear": np.ascontiguousarray(clear),
                        "ctg": np.ascontiguousarray(ctg), "walkable": ~solid, "origin": origin, "res": res}
        return self._fields

    def _people(self, inp: PlannerInput):
        """Reach discs of the reported and the remembered moving obstacles: C0, Vp (M, 2), R0, G (M,)."""
        c, now = self.cfg, inp.stamp
        current = {}
        for o in inp.obstacles:
            if not (np.all(np.isfinite(o.center)) and np.all(np.isfinite(o.velocity))):
                continue
            first = self._tracks.get(o.id, (now, now, o))[0]
            self._tracks[o.id] = (first, now, o)
            current[o.id] = o
        rows = []
        for o in current.values():
            rows.append(self._disc(o, 0.0))
        seen = inp.seen
        for oid, (first, last, o) in list(self._tracks.items()):
            if oid in current:
                continue
            age = now - last
            ghost = self._disc(o, age)
            centre = ghost[:2]
            lost = (age > c.memory or last - first < c.memory_min_age
                    or any(np.hypot(*(np.asarray(q.center[:2]) - centre)) < c.memory_merge for q in current.values()))
            if not lost and seen is not None:
                i, j = np.floor((centre - seen.origin) / seen.res).astype(int)
                lost = 0 <= i < seen.shape[0] and 0 <= j < seen.shape[1] and seen.last[i, j] > last
            if lost:
                del self._tracks[oid]
                continue
            rows.append(ghost)
        if not rows:
            z = np.zeros((0, 2))
            return z, z.copy(), np.zeros(0), np.zeros(0)
        a = np.array(rows)
        return (np.ascontiguousarray(a[:, :2]), np.ascontiguousarray(a[:, 2:4]), np.ascontiguousarray(a[:, 4]),
                np.ascontiguousarray(a[:, 5]))

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

    def _hidden(self, inp: PlannerInput, fields: dict):
        """(m an unseen person still has to walk to each cell, the nearest cell where one may be now) on the
        map's column grid (planner.visibility); nobody anywhere without one."""
        seen, shape = inp.seen, fields["clear"].shape
        if seen is None or seen.shape != shape:
            return np.full(shape, np.inf), np.full(shape, -1, np.int64)
        left, near = seen.reach(inp.stamp)
        return np.ascontiguousarray(left), np.ascontiguousarray(near)

    # ------------------------------------------------------------------ planning

    def plan(self, inp: PlannerInput) -> Trajectory:
        t0 = time.perf_counter()
        try:
            traj = self._plan(inp)
        except Exception as e:  # noqa: BLE001 - a planner never raises: it stops instead, saying why
            traj = self._hold(inp, f"error:{type(e).__name__}")
        return Trajectory(traj.t0, traj.dt, traj.positions, traj.velocities, traj.accelerations, traj.status,
                          (time.perf_counter() - t0) * 1e3, traj.yaw)

    def _hold(self, inp: PlannerInput, status: str) -> Trajectory:
        c = self.cfg
        stamp = float(inp.stamp) if np.isfinite(inp.stamp) else 0.0
        tr = brake_and_hold(stamp, inp.position, inp.velocity, a_max=c.a_brake, dt=c.dt, status=status)
        self._committed = tr
        return tr

    def _plan(self, inp: PlannerInput) -> Trajectory:
        c = self.cfg
        bad = [name for name, v in (("stamp", inp.stamp), ("position", inp.position), ("velocity", inp.velocity))
               if not np.all(np.isfinite(v))]
        if bad:
            return self._hold(inp, f"invalid:{bad[0]}")
        if inp.occupancy is None:
            return self._hold(inp, "invalid:no map")
        goal = np.asarray(inp.goal, dtype=float)
        if not np.all(np.isfinite(goal)):
            return self._hold(inp, "invalid:goal")
        fields = self._static(inp)
        C0, Vp, R0, G = self._people(inp)
        hidden, hidden_near = self._hidden(inp, fields)
        p0, v0 = np.asarray(inp.position, float), np.asarray(inp.velocity, float)
        origin, res = fields["origin"], fields["res"]
        need = c.drone_radius + c.static_margin
        here = bilinear(fields["clear"], origin[0], origin[1], res, p0[0], p0[1])
        need = min(need, here - 0.05)  # inside the margin already: at least no closer
        guide = self._guide(fields, p0, need)
        ranked, rank_cost = self._rank(inp, fields, p0, v0, guide)
        flown = backups(ranked.P, ranked.V, c.commit_time, c.dt, c.a_brake, c.v_max)
        targets = ranked.targets
        nobody = np.full_like(hidden, np.inf)

        def checked(cand, hidden_field=hidden):
            return check(cand.P, cand.V, c.dt, fields["clear"], hidden_field, hidden_near, origin[0], origin[1], res,
                         C0, Vp, R0, G, c.person_accel, c.person_speed, need, c.drone_radius,
                         c.drone_radius + c.person_body + c.person_margin, c.person_speed, c.at_rest,
                         math.cos(c.away_angle), c.lag)

        # candidates sharing their first commit_time share their committed motion: check each motion once
        _, first, inverse = np.unique(np.round(flown.P[:, :int(round(c.commit_time / c.dt)) + 1], 6).reshape(len(flown), -1),
                                      axis=0, return_index=True, return_inverse=True)
        unique = Candidates(flown.P[first], flown.V[first], flown.A[first], flown.targets[first], flown.commit[first])
        safe_u, violation_u = checked(unique)
        safe, violation = safe_u[inverse.ravel()], violation_u[inverse.ravel()]
        cost = rank_cost + self._view_cost(ranked, inp.yaw)
        # where it would go if it had seen everything: the camera turns there first
        wish_safe = checked(unique, nobody)[0][inverse.ravel()]
        wish = int(np.argmin(np.where(wish_safe, cost, np.inf))) if wish_safe.any() else -1
        look = self._look(flown, wish, hidden, hidden_near, fields) if wish >= 0 and not safe[wish] else None
        if safe.any():
            k = int(np.argmin(np.where(safe, cost, np.inf)))
            status = "solved"
        else:
            prev = self._previous(inp)
            if prev is not None and checked(prev)[0][0]:
                return self._trajectory(inp, prev.P[0], prev.V[0], prev.A[0], "fallback:previous", guide, look,
                                        prev.P[0])
            k = int(np.argmin(violation))
            status = "unsafe"
        self._chosen = (float(inp.stamp), ranked.A[k].copy())
        return self._trajectory(inp, flown.P[k], flown.V[k], flown.A[k], status, guide, look, ranked.P[k])

    def _guide(self, fields: dict, p0: np.ndarray, need: float) -> float:
        """Direction (rad) in which the cost-to-go falls most steeply, judged over points up to ``guide_range``
        away that the drone can fly to in a straight line (the field's own gradient is bent by its
        8-connected grid)."""
        ang = np.tile(_GUIDE_ANGLES, len(_GUIDE_RADII))
        r = np.repeat(_GUIDE_RADII, len(_GUIDE_ANGLES)) * self.cfg.guide_range
        pts = p0[:2] + r[:, None] * np.stack([np.cos(ang), np.sin(ang)], axis=1)
        k = guide_index(fields["ctg"], fields["clear"], fields["origin"][0], fields["origin"][1], fields["res"],
                        p0[0], p0[1], pts, need)
        return float(ang[k])

    def _rank(self, inp, fields, p0, v0, guide):
        """Two-phase candidates and their scenario costs (planner.maneuvers' scoring)."""
        c = self.cfg
        sel = self._selector
        o, res = fields["origin"], fields["res"]
        gdir = np.array([math.cos(guide), math.sin(guide)])
        prev_acc = None
        if self._chosen is not None:
            s = int(round((inp.stamp - self._chosen[0]) / c.dt))
            if 0 <= s < len(self._chosen[1]):
                prev_acc = np.vstack([self._chosen[1][s:], np.zeros((s, 2))])
        goal = np.asarray(inp.goal, float)[:2]
        q = sel._least_cost_point(fields["ctg"], o, res, goal)
        if q is not None and np.hypot(*(q - p0[:2])) > sel.cfg.approach_range:
            q = None
        P, V, A = sel.candidates(p0[:2], v0[:2], gdir, prev_acc, q)
        cfg, N = sel.cfg, sel.N
        sp = np.linalg.norm(V[:, -1], axis=1)
        stop = P[:, -1] + V[:, -1] * (sp / (2 * cfg.brake))[:, None]
        O, R, G, owner, prior = [], [], [], [], []
        for j, ob in enumerate(inp.obstacles):
            paths, w = hypotheses(ob, sel.t, cfg)
            size = np.asarray(ob.size, float)
            rad = 0.5 * min(max(size[0], size[1]), cfg.max_extent) + sel.r + ob.std_at(sel.t)
            O.append(paths)
            R.append(np.vstack([rad[None], np.repeat((rad - sel.evade)[None], len(w) - 1, axis=0)]))
            G.append(np.vstack([sel.gamma[None], np.repeat(sel.gamma_alt[None], len(w) - 1, axis=0)]))
            owner.append(np.full(len(w), j))
            prior.append(w)
        if O:
            O, R, G = np.concatenate(O), np.ascontiguousarray(np.concatenate(R)), np.concatenate(G)
            owner, prior = np.concatenate(owner).astype(np.int64), np.concatenate(prior)
        else:
            O, R, G = np.zeros((0, N, 2)), np.zeros((0, N)), np.zeros((0, N))
            owner, prior = np.zeros(0, np.int64), np.zeros(0)
        keep = np.zeros((0, 2))
        if prev_acc is not None:
            keep = P[-1, :cfg.keep_steps]
        gi = np.clip(np.floor((goal - o) / res).astype(int), 0, np.array(fields["clear"].shape) - 1)
        c_goal = float(fields["clear"][gi[0], gi[1]])
        r_goal = min(sel.r, max(c_goal - 0.05, 0.0))
        m_goal = min(cfg.static_margin, max(c_goal - r_goal, 0.0))
        parts = np.empty((len(P), 5))
        J = _score(np.ascontiguousarray(P), np.ascontiguousarray(A), stop, fields["clear"], fields["ctg"],
                   float(o[0]), float(o[1]), float(res), np.ascontiguousarray(O), R, owner, prior,
                   len(inp.obstacles), G, np.ascontiguousarray(keep), sel.r, cfg.static_margin, cfg.dynamic_margin,
                   cfg.w_goal, cfg.w_hit, cfg.w_static, cfg.w_near, cfg.worst_case, cfg.w_keep, cfg.w_acc,
                   float(goal[0]), float(goal[1]), cfg.near_goal, r_goal, m_goal, parts)
        Pf = np.concatenate([np.repeat(p0[None, None, :2], len(P), axis=0), P], axis=1)
        Vf = np.concatenate([np.repeat(v0[None, None, :2], len(P), axis=0), V], axis=1)
        return Candidates(Pf, Vf, A, V[:, min(sel.k_switch, N) - 1], np.zeros(len(P), np.int64)), J

    def _look(self, flown: Candidates, k: int, hidden, hidden_near, fields) -> float | None:
        """Where to look for the motion k would make, were it not for people unseen: toward the cell where
        one may be nearest to the sample of its committed motion that they could reach first."""
        c = self.cfg
        o, res = fields["origin"], fields["res"]
        ij = np.floor((flown.P[k, 1:] - o) / res).astype(int)
        ij = np.clip(ij, 0, np.array(hidden.shape) - 1)
        t = c.dt * np.arange(1, flown.P.shape[1])
        gap = hidden[ij[:, 0], ij[:, 1]] - c.person_speed * t
        m = int(np.argmin(gap))
        q = hidden_near[ij[m, 0], ij[m, 1]]
        if q < 0:
            return None
        target = o + (np.array([q // hidden.shape[1], q % hidden.shape[1]]) + 0.5) * res
        d = target - flown.P[k, 0]
        return math.atan2(d[1], d[0]) if np.hypot(*d) > 1e-6 else None

    def _view_cost(self, cand: Candidates, yaw) -> np.ndarray:
        """Moving off where the camera looks costs: w_turn per rad and m/s, over the first second."""
        c = self.cfg
        if yaw is None or not np.isfinite(yaw):
            return np.zeros(len(cand))
        k = min(int(round(1.0 / c.dt)), cand.P.shape[1] - 1)
        d = cand.P[:, k] - cand.P[:, 0]
        speed = np.hypot(d[:, 0], d[:, 1])
        off = np.abs((np.arctan2(d[:, 1], d[:, 0]) - yaw + np.pi) % (2 * np.pi) - np.pi)
        return c.w_turn * off * speed

    def _costs(self, cand: Candidates, fields: dict, p0, yaw, soft, way) -> np.ndarray:
        c = self.cfg
        ctg, o, res = fields["ctg"], fields["origin"], fields["res"]
        k = min(int(round(c.eval_time / c.dt)), cand.P.shape[1] - 1)
        here = bilinear(ctg, o[0], o[1], res, p0[0], p0[1])
        there = np.array([bilinear(ctg, o[0], o[1], res, x, y) for x, y in cand.P[:, k]])
        progress = (here - there) / c.eval_time
        speed = np.hypot(cand.targets[:, 0], cand.targets[:, 1])
        if yaw is not None and np.isfinite(yaw):
            heading = np.arctan2(cand.targets[:, 1], cand.targets[:, 0])
            off = np.abs((heading - yaw + np.pi) % (2 * np.pi) - np.pi)
        else:
            off = np.zeros(len(cand))
        change = np.hypot(*(cand.targets - self._target).T)
        return (-c.w_progress * progress + c.w_turn * off * speed + c.w_smooth * change + c.w_soft * soft
                + c.w_way * way)

    def _previous(self, inp: PlannerInput) -> Candidates | None:
        """The last committed plan from now on, as one candidate, or None."""
        tr, c = self._committed, self.cfg
        if tr is None:
            return None
        n = len(tr.accelerations)
        P, V, A = np.empty((1, n + 1, 2)), np.empty((1, n + 1, 2)), np.empty((1, n, 2))
        for k in range(n + 1):
            p, v, _ = tr.sample(inp.stamp + k * c.dt)
            P[0, k], V[0, k] = p[:2], v[:2]
            if k < n:
                A[0, k] = tr.sample(inp.stamp + (k + 0.5) * c.dt)[2][:2]
        return Candidates(P, V, A, np.zeros((1, 2)), np.zeros(1, dtype=np.int64))

    def _heading(self, inp: PlannerInput, motion, guide: float, look: float | None) -> float:
        """The heading that best keeps in the camera's view (its half field of view less a margin): where the
        drone goes in the next ``heading_time`` s (``motion``: (2,) displacement; weighted by its speed),
        where it would rather go but has not seen (``look``), else the guide; and the people within
        ``watch_range`` (weighted the more the nearer)."""
        c = self.cfg
        dirs, weights = [], []
        d = np.asarray(motion, float)
        speed = float(np.hypot(*d)) / c.heading_time
        if look is not None:
            dirs.append(look)
            weights.append(c.w_look)
        if speed > c.heading_speed:
            dirs.append(math.atan2(d[1], d[0]))
            weights.append(c.w_look * (1.0 + speed))
        elif look is None:
            dirs.append(guide)
            weights.append(c.w_look)
        p = np.asarray(inp.position, float)[:2] + d
        ahead = dirs[-1]
        for o in inp.obstacles:
            r = np.asarray(o.center, float)[:2] + np.asarray(o.velocity, float)[:2] * c.heading_time - p
            dist = float(np.hypot(*r))
            if not (0.2 < dist < c.watch_range and np.all(np.isfinite(r))):
                continue
            bearing = math.atan2(r[1], r[0])
            if abs((bearing - ahead + math.pi) % (2 * math.pi) - math.pi) < math.pi / 2:  # the way ahead only
                dirs.append(bearing)
                weights.append(c.w_watch * (c.watch_range - dist) / c.watch_range)
        dirs, weights = np.asarray(dirs), np.asarray(weights)
        off = np.abs((_HEADINGS[:, None] - dirs[None, :] + np.pi) % (2 * np.pi) - np.pi)
        cost = (np.maximum(off - c.view_half_angle, 0.0) * weights).sum(axis=1)
        yaw0 = inp.yaw if inp.yaw is not None and np.isfinite(inp.yaw) else guide
        turn = np.abs((_HEADINGS - yaw0 + np.pi) % (2 * np.pi) - np.pi)
        return float(_HEADINGS[int(np.argmin(cost + 0.01 * turn))])

    def _trajectory(self, inp: PlannerInput, P, V, A, status: str, guide: float, look: float | None,
                    intended: np.ndarray) -> Trajectory:
        """The chosen planar motion with the altitude held toward the goal's, and the heading: ``look`` when
        given (where the drone would rather go, unseen yet), else along the motion, else the guide."""
        c = self.cfg
        n = A.shape[0]
        z, vz = float(inp.position[2]), float(inp.velocity[2])
        zg = float(inp.goal[2])
        Z, VZ, AZ = [z], [vz], []
        for _ in range(n):
            target = min(max((zg - z) / 0.8, -0.5), 0.5)
            az = min(max((target - vz) / c.dt, -1.0), 1.0)
            z += vz * c.dt + 0.5 * az * c.dt * c.dt
            vz += az * c.dt
            Z.append(z)
            VZ.append(vz)
            AZ.append(az)
        k = min(int(round(c.heading_time / c.dt)), len(intended) - 1)
        ranked_motion = intended[k] - intended[0]
        positions = np.column_stack([P, Z])
        velocities = np.column_stack([V, VZ])
        accelerations = np.column_stack([A, AZ])
        yaw = self._heading(inp, ranked_motion, guide, look)
        tr = Trajectory(t0=float(inp.stamp), dt=c.dt, positions=positions, velocities=velocities,
                        accelerations=accelerations, status=status, yaw=yaw)
        self._committed = tr
        return tr
