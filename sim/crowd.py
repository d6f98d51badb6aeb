"""People walking their routes among each other, the walls, the obstacles and (if they see it) the drone.

Each person has a route (sim.people.WalkPath: the polyline its behaviour gives, with the speed it
walks along it) and moves by the social force model of Helbing & Molnar (Phys. Rev. E 51, 4282, 1995):

    dv/dt = (v0 e - v) / tau + sum_b w(e, d_b) f_b,        f_b = -grad V(b_ab),  V(b) = V0 exp(-b / sigma)

- v0 e, the desired velocity: toward a point ``CARROT`` metres further along the route than the person
  is, at the route's speed there (slower before tight corners and U-turns, zero at its end);
- f_b, the repulsion of another person (and of the drone, for people who see it): the potential's
  equipotentials are ellipses around the other, stretched along its next step v_b dt_step,
  2 b = sqrt((|r| + |r - v_b dt_step|)^2 - |v_b dt_step|^2) with r the vector from the other to
  this person;
- w = 1 for what lies within the view angle phi of the person's desired direction, c behind.
Parameters (sim.scenario.Crowd): tau 0.5 s, V0 2.1 m^2/s^2, sigma 0.3 m, 2 phi 200 deg, c 0.5, the
paper's values; the speed is capped at 1.3 times the route speed (the paper's maximal speed factor)
and at 1.6 m/s. dt_step is 1 s (ours, as PySocialForce's step width): the ellipse's long axis is the
other's next step, and with 2 s a faster walker coming head-on pushed a slower one backward at its
full speed.

Ours, beyond the paper's point model:
- b is measured from the bodies' surfaces (b minus the sum of the two radii, as Helbing, Farkas &
  Vicsek 2000 measure their repulsion): a person is a disc of PERSON_RADIUS, the drone a disc of its
  collision box's horizontal circumradius. With the paper's point model a person stops 0.4 m from
  the centre of what stands in its way, inside the drone's rotors.
- Choosing a side: the repulsion of what lies ahead (within SIDE_ANGLE of the desired direction)
  gets a component SIDE_GAIN times its size across that direction, toward the side the person is
  already on (the right when dead ahead). A point model facing an obstacle head-on has no reason to
  turn either way and stops in front of it; people pick a side.
- Bodies never overlap: an overlap left by a step is pushed apart, and people are kept out of walls
  and obstacles as hard boundaries instead of the paper's wall potential (the routes already keep the
  body radius clear of walls and obstacles; a wall potential would only push people off them).
A person's velocity is the displacement of its last step over the step, so ground truth's velocity is
the derivative of its position.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from sim.people import WalkerPose, Walker
from sim.scenario import Scenario
from sim.scenario_parts import PERSON_RADIUS, PERSON_SPEED_RANGE

CARROT = 1.0  # m along the route ahead of the person: where it heads
TURN_RATE = 2 * math.pi  # rad/s: the body turns toward its motion at most this fast
_MIN_TURN_SPEED = 0.1  # m/s: slower than this, the body keeps its heading
_RETARGET_EVERY = 4  # control steps between updates of the route progress and the carrot
_ARRIVED = 0.05  # m: this close to the point it heads for (its route's end), a person stops
SIDE_ANGLE = math.radians(45.0)  # what lies within this of a person's desired direction makes it pick a side
SIDE_GAIN = 1.0


@njit(cache=True, nogil=True)
def _repulsion(rx, ry, yx, yy, V0, sigma, reach=0.0):
    """-grad of V(b - reach) at r (from the other to this person), the other's step y: (fx, fy).
    reach: the two bodies' radii, so that b counts from their surfaces."""
    nr = math.sqrt(rx * rx + ry * ry)
    qx, qy = rx - yx, ry - yy
    nq = math.sqrt(qx * qx + qy * qy)
    ny = math.sqrt(yx * yx + yy * yy)
    s = nr + nq
    b = 0.5 * math.sqrt(max(s * s - ny * ny, 1e-12))
    b = max(b, 1e-3)
    if nr < 1e-9 or nq < 1e-9:
        return 0.0, 0.0
    g = s / (4.0 * b)
    mag = V0 / sigma * math.exp(-max(b - reach, 0.0) / sigma)
    return mag * g * (rx / nr + qx / nq), mag * g * (ry / nr + qy / nq)


@njit(cache=True, nogil=True)
def social_acceleration(pos, vel, desired, sees, drone, drone_vel, tau, V0, sigma, step_time, cos_view,
                        behind, radius, drone_radius, cos_side, side_gain):
    """Acceleration of every person (n, 2): relaxation toward the desired velocity plus the weighted
    repulsions of the other people and, for those with sees[a], of the drone (drone: (2,) position,
    drone_vel: (2,); a NaN drone position means no drone). See the module docstring."""
    n = pos.shape[0]
    out = np.empty((n, 2))
    for a in range(n):
        ax = (desired[a, 0] - vel[a, 0]) / tau
        ay = (desired[a, 1] - vel[a, 1]) / tau
        ex, ey = desired[a, 0], desired[a, 1]
        ne = math.sqrt(ex * ex + ey * ey)
        if ne < 1e-6:
            ex, ey = vel[a, 0], vel[a, 1]
            ne = math.sqrt(ex * ex + ey * ey)
        for b in range(n + 1):
            if b == a:
                continue
            if b < n:
                ox, oy, ovx, ovy, reach = pos[b, 0], pos[b, 1], vel[b, 0], vel[b, 1], 2.0 * radius
            else:
                if not sees[a] or math.isnan(drone[0]):
                    continue
                ox, oy, ovx, ovy, reach = drone[0], drone[1], drone_vel[0], drone_vel[1], radius + drone_radius
            rx, ry = pos[a, 0] - ox, pos[a, 1] - oy
            fx, fy = _repulsion(rx, ry, ovx * step_time, ovy * step_time, V0, sigma, reach)
            w = 1.0
            if ne >= 1e-6:  # the other lies along -r
                nr = math.sqrt(rx * rx + ry * ry)
                ahead = -(ex * rx + ey * ry)
                if ahead < nr * ne * cos_view:
                    w = behind
                elif ahead >= nr * ne * cos_side:  # ahead: step aside, to the side the person is on
                    cross = ex * ry - ey * rx  # > 0: the person is left of the other's line
                    side = 1.0 if cross > 1e-9 * nr * ne else -1.0
                    f = math.sqrt(fx * fx + fy * fy) * side_gain / ne
                    fx += -ey * f * side
                    fy += ex * f * side
            ax += w * fx
            ay += w * fy
        out[a, 0] = ax
        out[a, 1] = ay
    return out


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


class Crowd:
    """The people of one world: their state, advanced one control period at a time by ``step``."""

    def __init__(self, walkers: list[Walker], scenario: Scenario, drone_radius: float = 0.43):
        """drone_radius: the drone's body as the people keep clear of it (its collision box's
        horizontal circumradius)."""
        self.walkers = walkers
        self.drone_radius = float(drone_radius)
        sc = scenario
        self.params = sc.crowd
        n = len(walkers)
        self.sees = np.array([sc.crowd.sees_drone if p.sees_drone is None else p.sees_drone for p in sc.people],
                             dtype=np.bool_).reshape(n)
        self.start_delay = np.array([w.path.start_delay for w in walkers]).reshape(n)
        self.route_speed = np.array([w.path.speed for w in walkers]).reshape(n)
        self.max_speed = np.minimum(self.route_speed * sc.crowd.max_speed_factor, PERSON_SPEED_RANGE[1])
        self.pos = np.array([w.path.point_at(0.0) for w in walkers]).reshape(n, 2)
        self.vel = np.zeros((n, 2))
        for i, w in enumerate(walkers):
            if w.path.start_delay <= 0.0:  # walking already when the scenario starts
                self.vel[i] = w.path.velocity(0.0)
        self.yaw = np.array([w.path.heading(0.0) for w in walkers]).reshape(n)
        self.walked = np.zeros(n)
        self.progress = np.zeros(n)  # arc length along each route the person has reached
        self._carrot = np.array([w.path.point_at(CARROT) for w in walkers]).reshape(n, 2)
        self._carrot_speed = np.array([w.path.route_speed(0.0) for w in walkers]).reshape(n)
        self._steps = 0
        co = sc.corridor
        r = PERSON_RADIUS
        self._box = (r, co.length - r, -co.width / 2 + r, co.width / 2 - r)
        self._obstacles = sc.obstacles

    def __len__(self) -> int:
        return len(self.walkers)

    def pose(self, i: int) -> WalkerPose:
        w = self.walkers[i]
        return WalkerPose(float(self.pos[i, 0]), float(self.pos[i, 1]), float(self.yaw[i]), w.gait_sample(self.walked[i]))

    def poses(self) -> list[WalkerPose]:
        return [self.pose(i) for i in range(len(self))]

    def velocity3(self, i: int) -> np.ndarray:
        return np.array([self.vel[i, 0], self.vel[i, 1], 0.0])

    def _retarget(self) -> None:
        """Route progress (the nearest route point a little behind to a little ahead of the last one)
        and the point each person heads for."""
        for i, w in enumerate(self.walkers):
            s = w.path.project(self.pos[i], self.progress[i])
            self.progress[i] = s
            self._carrot[i] = w.path.point_at(s + CARROT)
            # the route's speed where the person will be once its velocity has relaxed (tau on):
            # slowing down for a corner or the end starts where the route's profile starts it
            ahead = math.hypot(self.vel[i, 0], self.vel[i, 1]) * self.params.relaxation_time
            self._carrot_speed[i] = w.path.route_speed(s + ahead)

    def step(self, t: float, dt: float, drone_xy=None, drone_vel=None) -> None:
        """Advance every person by dt to time t (the end of the step). drone_xy / drone_vel: the drone's
        horizontal position and velocity, seen by the people who see it (None: no drone)."""
        n = len(self)
        if n == 0:
            return
        if self._steps % _RETARGET_EVERY == 0:
            self._retarget()
        self._steps += 1
        to = self._carrot - self.pos
        dist = np.hypot(to[:, 0], to[:, 1])
        walking = (t > self.start_delay) & (dist > _ARRIVED)
        desired = np.where(walking[:, None], to / np.maximum(dist, 1e-9)[:, None] * self._carrot_speed[:, None], 0.0)
        c = self.params
        drone = np.full(2, np.nan) if drone_xy is None else np.asarray(drone_xy, float)[:2]
        dv = np.zeros(2) if drone_vel is None else np.asarray(drone_vel, float)[:2]
        acc = social_acceleration(self.pos, self.vel, desired, self.sees, drone, dv, c.relaxation_time, c.strength,
                                  c.range, c.step_time, math.cos(c.view_angle), c.behind_weight, PERSON_RADIUS,
                                  self.drone_radius, math.cos(SIDE_ANGLE), SIDE_GAIN)
        v = self.vel + acc * dt
        speed = np.hypot(v[:, 0], v[:, 1])
        v *= np.minimum(1.0, self.max_speed / np.maximum(speed, 1e-9))[:, None]
        before = self.pos.copy()
        self.pos = self._keep_apart(self.pos + v * dt)
        moved = self.pos - before
        self.vel = moved / dt
        self.walked += np.hypot(moved[:, 0], moved[:, 1])
        for i in range(n):
            sp = math.hypot(self.vel[i, 0], self.vel[i, 1])
            if sp > _MIN_TURN_SPEED:
                err = _wrap(math.atan2(self.vel[i, 1], self.vel[i, 0]) - self.yaw[i])
                self.yaw[i] = _wrap(self.yaw[i] + max(-TURN_RATE * dt, min(TURN_RATE * dt, err)))

    def _keep_apart(self, p: np.ndarray) -> np.ndarray:
        """Bodies do not overlap: people pushed apart along the line between them, then out of the
        obstacles and inside the corridor's walls."""
        r = PERSON_RADIUS
        n = len(p)
        for _ in range(2):
            for a in range(n):
                for b in range(a + 1, n):
                    d = p[a] - p[b]
                    dist = math.hypot(d[0], d[1])
                    if dist < 2 * r:
                        u = d / dist if dist > 1e-9 else np.array([0.0, 1.0 if a < b else -1.0])
                        push = 0.5 * (2 * r - dist)
                        p[a] += push * u
                        p[b] -= push * u
        for o in self._obstacles:
            for i in range(n):
                p[i] = _out_of(o, p[i], r)
        x0, x1, y0, y1 = self._box
        p[:, 0] = np.clip(p[:, 0], x0, x1)
        p[:, 1] = np.clip(p[:, 1], y0, y1)
        return p


def _out_of(o, xy: np.ndarray, margin: float) -> np.ndarray:
    """The point moved to the nearest point outside the obstacle's footprint grown by margin."""
    c = np.asarray(o.center, float)
    d = xy - c
    if o.kind == "pillar":
        R = o.size[0] / 2 + margin
        dist = math.hypot(d[0], d[1])
        if dist >= R:
            return xy
        u = d / dist if dist > 1e-9 else np.array([1.0, 0.0])
        return c + u * R
    cs, sn = math.cos(o.yaw), math.sin(o.yaw)
    lx, ly = cs * d[0] + sn * d[1], -sn * d[0] + cs * d[1]
    hx, hy = o.size[0] / 2 + margin, o.size[1] / 2 + margin
    if abs(lx) >= hx or abs(ly) >= hy:
        return xy
    if hx - abs(lx) < hy - abs(ly):
        lx = math.copysign(hx, lx if lx != 0 else 1.0)
    else:
        ly = math.copysign(hy, ly if ly != 0 else 1.0)
    return c + np.array([cs * lx - sn * ly, sn * lx + cs * ly])
