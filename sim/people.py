"""Walking people: paths from behaviours, and the DeepMimic humanoid animated from mocap.

A person's path is planned once, at world build, from its behaviour and the seed: a long
polyline walked at the set speed, slowing down for tight corners and U-turns and speeding up
again at a walker's acceleration (WalkPath). Position and velocity at any time follow from it
exactly, which is what ground truth reports: the velocity is the position's rate of change.
The body is pybullet_data's DeepMimic humanoid (``humanoid/humanoid.urdf``, Y-up, 1.62 m at
globalScaling 0.25) posed kinematically from the walking clip
(``data/motions/humanoid3d_walk.txt``: 38 intervals of 1/30 s per gait cycle, the root
advancing 1.2386 m). The gait phase follows the distance
walked, so the feet do not slide whatever the speed, and the body is scaled to the person's
height (stride scales with it).
"""
from __future__ import annotations

import bisect
import json
import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from sim.scenario import Scenario
from sim.scenario_parts import PERSON_HEIGHT_RANGE, PERSON_RADIUS, Person, circle_waypoints

HUMANOID_URDF = "humanoid/humanoid.urdf"
WALK_CLIP = "data/motions/humanoid3d_walk.txt"
HUMANOID_BASE_SCALE = 0.25  # globalScaling that gives the nominal height
HUMANOID_NOMINAL_HEIGHT = 1.62  # m at HUMANOID_BASE_SCALE (foot sole to head top)

# Clip column layout after [duration, root position (3), root quaternion (4)]:
# (urdf joint index, first column, number of values); quaternions are (w, x, y, z).
_CLIP_JOINTS = (
    (1, 8, 4),  # chest
    (2, 12, 4),  # neck
    (9, 16, 4),  # right hip
    (10, 20, 1),  # right knee
    (11, 21, 4),  # right ankle
    (3, 25, 4),  # right shoulder
    (4, 29, 1),  # right elbow
    (12, 30, 4),  # left hip
    (13, 34, 1),  # left knee
    (14, 35, 4),  # left ankle
    (6, 39, 4),  # left shoulder
    (7, 43, 1),  # left elbow
)
_SPHERICAL = [j for j, _, n in _CLIP_JOINTS if n == 4]
_REVOLUTE = [j for j, _, n in _CLIP_JOINTS if n == 1]
_Q_X90 = Rotation.from_euler("x", math.pi / 2).as_quat()  # (x, y, z, w): +90 deg about x


# --------------------------------------------------------------------------- quaternions (x, y, z, w)


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz])


def _nlerp(a: np.ndarray, b: np.ndarray, w: float) -> np.ndarray:
    """Normalised linear interpolation of rows of quaternions, taking the short way."""
    sign = np.where(np.sum(a * b, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    q = (1 - w) * a + w * sign * b
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


# --------------------------------------------------------------------------- the clip


@dataclass(frozen=True)
class WalkClip:
    sph: np.ndarray  # (F, 8, 4) spherical joint quaternions (x, y, z, w)
    rev: np.ndarray  # (F, 4) revolute joint angles
    root_offset: np.ndarray  # (F, 3) root position minus its linear progression, clip frame
    root_quat: np.ndarray  # (F, 4) root orientation (x, y, z, w), clip frame (Y up)
    stride: float  # m the root advances per cycle at nominal height

    @property
    def n_intervals(self) -> int:
        return self.sph.shape[0] - 1


@lru_cache(maxsize=1)
def load_walk_clip() -> WalkClip:
    import pybullet_data

    data = json.loads((Path(pybullet_data.getDataPath()) / WALK_CLIP).read_text())
    f = np.asarray(data["Frames"], dtype=float)
    n = f.shape[0] - 1  # the last frame closes the loop (same pose, one stride on)
    stride = f[n, 1] - f[0, 1]
    phase = np.arange(f.shape[0]) / n
    root = f[:, 1:4].copy()
    root[:, 0] -= phase * stride
    wxyz_to_xyzw = [1, 2, 3, 0]
    sph = np.stack([f[:, c:c + 4][:, wxyz_to_xyzw] for _, c, k in _CLIP_JOINTS if k == 4], axis=1)
    rev = np.stack([f[:, c] for _, c, k in _CLIP_JOINTS if k == 1], axis=1)
    return WalkClip(sph=sph, rev=rev, root_offset=root, root_quat=f[:, 4:8][:, wxyz_to_xyzw], stride=stride)


@dataclass(frozen=True)
class _PoseTable:
    """The gait cycle sampled finely (10 samples per clip interval, 3 mm of travel at the
    nominal stride), so that posing a person costs a lookup instead of interpolation."""

    targets: list  # per sample: joint targets for _SPHERICAL + _REVOLUTE, as PyBullet takes them
    root_offset: list  # per sample: (3,) root offset in the clip frame, nominal size
    base_quat: list  # per sample: (4,) root orientation after the Y-up -> Z-up roll


@lru_cache(maxsize=1)
def _pose_table(samples_per_interval: int = 10) -> _PoseTable:
    c = load_walk_clip()
    targets, offsets, quats = [], [], []
    for j in range(c.n_intervals * samples_per_interval):
        i, w = divmod(j, samples_per_interval)
        w /= samples_per_interval
        sph = _nlerp(c.sph[i], c.sph[i + 1], w)
        rev = (1 - w) * c.rev[i] + w * c.rev[i + 1]
        targets.append([q.tolist() for q in sph] + [[a] for a in rev.tolist()])
        offsets.append(((1 - w) * c.root_offset[i] + w * c.root_offset[i + 1]).tolist())
        quats.append(_qmul(_Q_X90, _nlerp(c.root_quat[i], c.root_quat[i + 1], w)))
    return _PoseTable(targets=targets, root_offset=offsets, base_quat=quats)


# --------------------------------------------------------------------------- paths


# How people change speed (ours; the polyline alone would have them reverse at 0.9 m/s in one
# step at the end of a back-and-forth leg, an acceleration no person makes):
WALK_ACCELERATION = 1.0  # m/s^2, speeding up from standing and slowing down to stop or turn
TURN_LATERAL_ACCELERATION = 2.0  # m/s^2 at most around a corner: tight corners are walked slower
TURN_SPEED_STEP = 0.2  # m/s, the largest velocity change at one polyline vertex (a U-turn's)
_SPEED_GRID = 0.05  # m, the speed profile's sampling along the path


class WalkPath:
    """A polyline walked from ``start_delay`` on at up to ``speed``; standing at its end.

    A walker with a start delay starts from standing (one without is walking already when the
    scenario starts); it slows down before corners (to keep the lateral acceleration at
    ``TURN_LATERAL_ACCELERATION``; at a U-turn nearly to a stop) and before the end, and
    speeds up again, all at ``acceleration``: position and velocity are continuous, as a
    person's are. The speed profile v(s) is sampled along the path with v^2
    piecewise linear in s (constant acceleration in each cell), so distance(t) and velocity(t)
    are exact for it.
    """

    def __init__(self, points: np.ndarray, speed: float, start_delay: float,
                 acceleration: float = WALK_ACCELERATION):
        self.points = np.asarray(points, dtype=float)
        self.speed = float(speed)
        self.start_delay = float(start_delay)
        seg = np.diff(self.points, axis=0)
        seg_len = np.linalg.norm(seg, axis=1)
        self._cum = [0.0] + np.cumsum(seg_len).tolist()
        self._xy = self.points.tolist()
        dirs = seg / np.maximum(seg_len, 1e-12)[:, None]
        self._dir = dirs.tolist()
        self._profile(dirs, seg_len, float(acceleration))

    def _profile(self, dirs: np.ndarray, seg_len: np.ndarray, acc: float) -> None:
        """Speed limits at the vertices, a forward (speeding up) and a backward (slowing down)
        pass over a grid in s, then the time at each grid point. The route speed (``route_speed``) is
        the same profile without the standing start."""
        s, cap = self._caps(dirs, seg_len)
        v = self._passes(s, cap, acc)
        if self.start_delay > 0:
            self._v_route = self._passes(s, np.concatenate([[self.speed], cap[1:]]), acc).tolist()
        else:
            self._v_route = v.tolist()
        v2 = v ** 2
        ds = np.diff(s)
        dt = np.where(ds > 0, 2 * ds / np.maximum(v[:-1] + v[1:], 1e-9), 0.0)
        self._s = s.tolist()
        self._v = v.tolist()
        self._t = np.concatenate([[0.0], np.cumsum(dt)]).tolist()
        self._a = np.where(ds > 0, (v2[1:] - v2[:-1]) / np.maximum(2 * ds, 1e-12), 0.0).tolist()
        self.duration = self._t[-1]  # s from the start to standing at the end

    @staticmethod
    def _passes(s: np.ndarray, cap: np.ndarray, acc: float) -> np.ndarray:
        v2 = cap ** 2
        ds = np.diff(s)
        for k in range(1, len(s)):
            v2[k] = min(v2[k], v2[k - 1] + 2 * acc * ds[k - 1])
        for k in range(len(s) - 2, -1, -1):
            v2[k] = min(v2[k], v2[k + 1] + 2 * acc * ds[k])
        return np.sqrt(v2)

    def _caps(self, dirs: np.ndarray, seg_len: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The grid in s and the speed limit at each of its points."""
        cum = np.asarray(self._cum)
        L = cum[-1]
        n_cells = np.maximum(np.ceil(seg_len / _SPEED_GRID).astype(int), 1)
        s = np.concatenate([np.linspace(cum[i], cum[i + 1], n_cells[i] + 1)[:-1] for i in range(len(seg_len))]
                           + [[L]]) if len(seg_len) else np.array([0.0])
        cap = np.full(len(s), self.speed)
        cap[-1] = 0.0  # standing at the end
        if self.start_delay > 0:
            cap[0] = 0.0  # standing until start_delay, then speeding up (without one: walking already)
        for i in range(1, len(dirs)):  # vertex i joins segments i-1 and i
            cos_turn = float(np.clip(dirs[i - 1] @ dirs[i], -1.0, 1.0))
            turn = math.acos(cos_turn)
            if turn < 1e-6:
                continue
            curvature = turn / max(0.5 * (seg_len[i - 1] + seg_len[i]), 1e-6)
            v = min(self.speed, math.sqrt(TURN_LATERAL_ACCELERATION / curvature),
                    TURN_SPEED_STEP / (2.0 * math.sin(turn / 2)))
            k = int(np.searchsorted(s, cum[i]))
            k = min(k, len(s) - 1)
            cap[k] = min(cap[k], v)
        return s, cap

    @property
    def length(self) -> float:
        return self._cum[-1]

    def _state(self, t: float) -> tuple[float, float]:
        """(arc length walked, speed) at time t."""
        tau = t - self.start_delay
        if tau < 0.0 or self.length <= 0.0:
            return 0.0, 0.0
        if tau >= self.duration:
            return self.length, 0.0
        k = min(max(bisect.bisect_right(self._t, tau) - 1, 0), len(self._t) - 2)
        d = tau - self._t[k]
        a = self._a[k]
        s = min(self._s[k] + self._v[k] * d + 0.5 * a * d * d, self._s[k + 1])
        return s, max(self._v[k] + a * d, 0.0)

    def distance(self, t: float) -> float:
        """Arc length walked by time t."""
        return self._state(t)[0]

    def _segment(self, s: float) -> int:
        return min(max(bisect.bisect_right(self._cum, s) - 1, 0), len(self._cum) - 2)

    def route_speed(self, s: float) -> float:
        """The speed the route asks for at arc length s (slower before corners and the end; a
        person who started from standing walks it at full speed once under way)."""
        if s >= self.length:
            return 0.0
        k = min(max(bisect.bisect_right(self._s, s) - 1, 0), len(self._s) - 2)
        s0, s1 = self._s[k], self._s[k + 1]
        w = (s - s0) / (s1 - s0) if s1 > s0 else 0.0
        return (1 - w) * self._v_route[k] + w * self._v_route[k + 1]

    def project(self, xy, s0: float, back: float = 0.3, ahead: float = 1.0) -> float:
        """Arc length of the route point nearest to ``xy`` within [s0 - back, s0 + ahead], never less
        than s0 (progress only grows; of nearly equal points the furthest, so that a U-turn's return
        leg, lying on its way out, is taken once reached)."""
        lo, hi = max(s0 - back, 0.0), min(s0 + ahead, self.length)
        i0, i1 = self._segment(lo), self._segment(hi)
        a = self.points[i0:i1 + 1]
        d = np.asarray(self._dir[i0:i1 + 1])
        cum = np.asarray(self._cum[i0:i1 + 1])
        seg = np.asarray(self._cum[i0 + 1:i1 + 2]) - cum
        q = np.asarray(xy, float)[:2]
        r = np.clip(np.einsum("ij,ij->i", q - a, d), 0.0, seg)
        s = np.clip(cum + r, lo, hi)
        foot = a + d * (s - cum)[:, None]
        dist = np.hypot(foot[:, 0] - q[0], foot[:, 1] - q[1])
        best = float(np.max(s[dist <= dist.min() + 0.01]))
        return max(best, s0)

    def point_at(self, s: float) -> np.ndarray:
        s = min(max(s, 0.0), self.length)
        i = self._segment(s)
        a, d = self._xy[i], self._dir[i]
        r = s - self._cum[i]
        return np.array([a[0] + r * d[0], a[1] + r * d[1]])

    def position(self, t: float) -> np.ndarray:
        return self.point_at(self.distance(t))

    def trail_point(self, s: float) -> np.ndarray:
        """Like point_at, but before the start it extends the first segment backwards."""
        if s >= 0:
            return self.point_at(s)
        a, d = self._xy[0], self._dir[0]
        return np.array([a[0] + s * d[0], a[1] + s * d[1]])

    def velocity(self, t: float) -> np.ndarray:
        s, v = self._state(t)
        if v <= 0.0:
            return np.zeros(2)
        d = self._dir[self._segment(s)]
        return np.array([v * d[0], v * d[1]])

    def heading(self, t: float, window: float = 0.3) -> float:
        """Body heading: direction of the path around the current point, smoothed over
        +-window metres so that corners are turned, not snapped."""
        s = self.distance(t)
        a, b = self.point_at(s - window), self.point_at(s + window)
        dx, dy = b[0] - a[0], b[1] - a[1]
        if dx * dx + dy * dy < 1e-12:
            d = self._dir[0]
            dx, dy = d[0], d[1]
        return math.atan2(dy, dx)


TURN_RADIUS = 0.4  # m: people turn along arcs, not on the spot (the path stays continuous in heading)


def round_corners(points: np.ndarray, radius: float = TURN_RADIUS, step_deg: float = 10.0) -> np.ndarray:
    """Replace each corner of a polyline by a circular arc tangent to both legs.

    The arc's radius is ``radius``, or less for sharp turns and short legs (the arc starts at
    most ``radius`` and half a leg before the corner), so a walker's velocity turns smoothly
    instead of jumping at waypoints.
    """
    pts = np.asarray(points, float)
    if len(pts) < 3:
        return pts
    out = [pts[0]]
    for i in range(1, len(pts) - 1):
        a, b, c = pts[i - 1], pts[i], pts[i + 1]
        u, w = b - a, c - b
        lu, lw = np.linalg.norm(u), np.linalg.norm(w)
        if lu < 1e-9 or lw < 1e-9:
            continue
        u, w = u / lu, w / lw
        turn = math.acos(max(-1.0, min(1.0, float(u @ w))))
        if turn < 1e-3 or turn > math.pi - 1e-3:
            out.append(b)
            continue
        # distance from the corner to the arc's ends: a sharp turn is made on a tighter arc, so
        # that the walker still reaches (nearly) its waypoint
        cut = min(radius * math.tan(turn / 2), radius, 0.5 * lu, 0.5 * lw)
        r = cut / math.tan(turn / 2)
        p0 = b - u * cut
        left = u[0] * w[1] - u[1] * w[0] > 0
        normal = np.array([-u[1], u[0]]) if left else np.array([u[1], -u[0]])
        centre = p0 + normal * r
        a0 = math.atan2(p0[1] - centre[1], p0[0] - centre[0])
        n = max(2, int(math.ceil(math.degrees(turn) / step_deg)) + 1)
        for k in range(n):
            ang = a0 + (turn if left else -turn) * k / (n - 1)
            out.append(centre + r * np.array([math.cos(ang), math.sin(ang)]))
    out.append(pts[-1])
    return np.array(out)


def _segment_clear(a, b, scenario: Scenario, margin: float) -> bool:
    n = max(2, int(np.linalg.norm(b - a) / 0.05) + 1)
    pts = a + np.linspace(0, 1, n)[:, None] * (b - a)
    return not any(np.any(o.footprint_contains(pts, margin)) for o in scenario.obstacles)


def plan_path(person: Person, scenario: Scenario, rng: np.random.Generator, horizon: float) -> WalkPath:
    """Expand a behaviour into the polyline walked over ``horizon`` seconds."""
    need = person.speed * max(horizon - person.start_delay, 0.0) + 1.0
    if person.behaviour in ("waypoint_loop", "circle"):
        loop = np.array(person.waypoints if person.behaviour == "waypoint_loop"
                        else circle_waypoints(person.center, person.radius, person.clockwise, n=72))
        closed = np.vstack([loop, loop[:1]])
        per = np.sum(np.linalg.norm(np.diff(closed, axis=0), axis=1))
        reps = int(math.ceil(need / per)) + 1
        pts = np.vstack([loop] * reps + [loop[:1]])
    elif person.behaviour == "back_and_forth":
        wp = np.array(person.waypoints)
        length = np.sum(np.linalg.norm(np.diff(wp, axis=0), axis=1))
        reps = int(math.ceil(need / (2 * length))) + 1
        pts = np.vstack([wp] + [np.vstack([wp[-2::-1], wp[1:]])] * reps)
    elif person.behaviour == "crossing":
        pts = np.array(person.waypoints)
    else:  # random_walk
        x0, y0, x1, y1 = person.region
        lo, hi = np.array([x0, y0]), np.array([x1, y1])

        def sample():
            for _ in range(1000):
                q = lo + rng.random(2) * (hi - lo)
                if not any(o.footprint_contains(q, PERSON_RADIUS)[0] for o in scenario.obstacles):
                    return q
            raise ValueError(f"{scenario.source}: people: no free point in the random-walk region {list(person.region)}")

        cur = np.array(person.start) if person.start is not None else sample()
        pts_list, total = [cur], 0.0
        min_leg = min(1.0, 0.5 * float(np.linalg.norm(hi - lo)))
        while total < 1.3 * need + 2.0:  # margin for the length the rounded corners cut
            for _ in range(200):
                goal = sample()
                if np.linalg.norm(goal - cur) >= min_leg and _segment_clear(cur, goal, scenario, PERSON_RADIUS):
                    break
            else:
                break  # boxed in: the person stops here
            total += float(np.linalg.norm(goal - cur))
            pts_list.append(goal)
            cur = goal
        pts = np.array(pts_list) if len(pts_list) > 1 else np.array([cur, cur + 1e-3])
    return WalkPath(points=round_corners(pts.astype(float)), speed=person.speed, start_delay=person.start_delay)


ROUTE_SLACK = 5.0  # s: routes are drawn for the scenario's duration and this much more


def walk_paths(scenario: Scenario, rng: np.random.Generator) -> list[WalkPath]:
    """Every person's route, drawn from ``rng`` in the file's order (the world draws them so)."""
    horizon = scenario.duration + ROUTE_SLACK
    return [plan_path(person, scenario, rng, horizon) for person in scenario.people]


def person_height(person: Person, rng: np.random.Generator) -> float:
    if person.height is not None:
        return person.height
    return float(rng.uniform(*PERSON_HEIGHT_RANGE))


# --------------------------------------------------------------------------- the animated body


class Walker:
    """One person: a path, a height, and humanoid bodies in one or more PyBullet clients."""

    def __init__(self, path: WalkPath, height: float):
        self.path = path
        self.height = height
        self.k = height / HUMANOID_NOMINAL_HEIGHT
        self.clip = load_walk_clip()
        self.bodies: list[tuple[int, int]] = []  # (client, body id)

    @property
    def global_scaling(self) -> float:
        return HUMANOID_BASE_SCALE * self.k

    def gait_sample(self, walked: float) -> int:
        """The gait cycle's sample shown after walking ``walked`` metres: the phase follows the distance
        walked, so the feet do not slide whatever the speed."""
        n = len(_pose_table().targets)
        return int(walked / (self.clip.stride * self.k) % 1.0 * n)

    def body_pose(self, pose: "WalkerPose"):
        """(base position, base quaternion, joint targets for _SPHERICAL + _REVOLUTE) of a WalkerPose."""
        table = _pose_table()
        off = table.root_offset[pose.k]
        cy, sy = math.cos(pose.yaw), math.sin(pose.yaw)
        # Clip frame (x forward, y up, z right-ish) -> world after the +90 deg roll: (x, -z, y).
        lx, ly = off[0] * self.k, -off[2] * self.k
        pos = [pose.x + cy * lx - sy * ly, pose.y + sy * lx + cy * ly, off[1] * self.k]
        q_yaw = Rotation.from_euler("z", pose.yaw).as_quat()  # (x, y, z, w)
        quat = _qmul(q_yaw, table.base_quat[pose.k])
        return pos, quat, table.targets[pose.k]

    def apply_pose(self, p, pose: "WalkerPose") -> None:
        """Pose the person's bodies in every client they live in."""
        pos, quat, targets = self.body_pose(pose)
        quat = quat.tolist()
        joints = _SPHERICAL + _REVOLUTE
        for client, body in self.bodies:
            p.resetBasePositionAndOrientation(body, pos, quat, physicsClientId=client)
            p.resetJointStatesMultiDof(body, joints, targets, physicsClientId=client)



@dataclass(frozen=True)
class WalkerPose:
    """A person's pose as the renderer needs it: root position on the floor, heading, gait sample."""

    x: float
    y: float
    yaw: float  # rad
    k: int  # index into the gait cycle's pose table
