"""Geometry checks of a scenario's parts: everything inside the corridor, nobody walking through an obstacle.

A person is a disc of PERSON_RADIUS; paths are sampled every 5 cm between their waypoints.
"""
from __future__ import annotations

from typing import Callable, NoReturn

import numpy as np

from sim.scenario_parts import PERSON_RADIUS, CameraPath, Corridor, Drone, Obstacle, Person, circle_waypoints


def _inside_corridor(c: Corridor, xy: np.ndarray, margin: float) -> np.ndarray:
    xy = np.atleast_2d(xy)
    return ((xy[:, 0] >= margin) & (xy[:, 0] <= c.length - margin)
            & (np.abs(xy[:, 1]) <= c.width / 2 - margin))


def _sample_segments(points: np.ndarray, closed: bool, step: float = 0.05) -> np.ndarray:
    """The path through ``points`` (closed: back to the first) sampled at most ``step`` apart: the first
    point, then each segment a -> b at a + linspace(0, 1, n)[1:] (b - a), n = max(2, ceil(|b - a| / step) + 1)."""
    pts = np.asarray(points, dtype=float)
    if closed:
        pts = np.vstack([pts, pts[:1]])
    a, b = pts[:-1], pts[1:]
    n = np.maximum(2, np.ceil(np.linalg.norm(b - a, axis=1) / step).astype(np.int64) + 1)  # samples per segment
    seg = np.repeat(np.arange(len(a)), n - 1)
    k = np.arange(len(seg)) - np.repeat(np.cumsum(n - 1) - (n - 1), n - 1) + 1  # 1 .. n - 1 in each segment
    t = k * (1.0 / (n - 1))[seg]  # as linspace steps
    t[k == (n - 1)[seg]] = 1.0  # each segment ends on its end point, as linspace does
    return np.vstack([pts[:1], a[seg] + t[:, None] * (b - a)[seg]])


def _near_box(o: Obstacle, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """An axis-aligned (x, y) box holding the footprint grown by ``margin`` (a rotated box grows its
    corners by up to margin * sqrt(2) along the axes)."""
    lo, hi = o.aabb()
    g = margin * 1.5 + 1e-9
    return lo[:2] - g, hi[:2] + g


def _first_hit(obstacles, points: np.ndarray, margin: float) -> tuple[int, int] | None:
    """(j, i): the first obstacle, in order, whose footprint grown by margin holds one of the (N, 2) points,
    and the first such point; None when there is none. Each obstacle is tested only against the points
    in its box (points sorted by x, its range found by bisection): a path of many points past many
    obstacles costs about what its points near obstacles cost."""
    if not obstacles or not len(points):
        return None
    order = np.argsort(points[:, 0], kind="stable")
    xs = points[order, 0]
    for j, o in enumerate(obstacles):
        lo, hi = _near_box(o, margin)
        near = order[np.searchsorted(xs, lo[0], "left"):np.searchsorted(xs, hi[0], "right")]
        near = near[(points[near, 1] >= lo[1]) & (points[near, 1] <= hi[1])]
        hit = near[o.footprint_contains(points[near], margin)] if len(near) else near
        if len(hit):
            return j, int(hit.min())
    return None


def _region_covered(obstacles, region, margin: float, most: int = 256) -> bool:
    """Whether the obstacles' footprints grown by margin cover every point of a grid over the region
    [x0, y0, x1, y1]: every 0.1 m, or coarser on a side longer than ``most`` points (25.6 m). Each
    obstacle is tested against the grid points in its box only."""
    x0, y0, x1, y1 = region
    xs = np.arange(x0, x1 + 1e-9, max(0.1, (x1 - x0) / most))
    ys = np.arange(y0, y1 + 1e-9, max(0.1, (y1 - y0) / most))
    covered = np.zeros((len(ys), len(xs)), bool)
    for o in obstacles:
        lo, hi = _near_box(o, margin)
        ix = slice(np.searchsorted(xs, lo[0], "left"), np.searchsorted(xs, hi[0], "right"))
        iy = slice(np.searchsorted(ys, lo[1], "left"), np.searchsorted(ys, hi[1], "right"))
        gx, gy = np.meshgrid(xs[ix], ys[iy])
        if gx.size:
            inside = o.footprint_contains(np.stack([gx.ravel(), gy.ravel()], axis=1), margin)
            covered[iy, ix] |= inside.reshape(gx.shape)
    return bool(covered.all())


def check_geometry(corridor: Corridor, obstacles: tuple[Obstacle, ...], people: tuple[Person, ...], drone: Drone,
                   camera_path: CameraPath | None, fail: Callable[[str, str], NoReturn],
                   work: list[int] | None = None) -> None:
    """Calls ``fail(key, reason)`` (which raises) for the first part that does not fit: an obstacle sticking out
    of the corridor, a person's path leaving it or walking through an obstacle, the drone's start or goal, or
    the camera path, outside the corridor or inside an obstacle. work: a one-item
    list counting the path points sampled (a person's path every 5 cm), added to as they are sampled."""
    c = corridor
    for i, o in enumerate(obstacles):
        lo, hi = o.aabb()
        if lo[0] < 0 or hi[0] > c.length or lo[1] < -c.width / 2 or hi[1] > c.width / 2:
            fail(f"obstacles[{i}].center", f"the {o.kind} at {list(o.center)} sticks out of the corridor")
        if hi[2] > c.height + 1e-9 and c.ceiling:
            fail(f"obstacles[{i}].size", f"taller than the corridor ({c.height} m)")

    def in_obstacle(xy, margin):
        for j, o in enumerate(obstacles):
            if np.any(o.footprint_contains(xy, margin)):
                return j
        return None

    for i, p in enumerate(people):
        key = f"people[{i}]"
        if p.behaviour == "random_walk":
            x0, y0, x1, y1 = p.region
            corners = np.array([[x0, y0], [x1, y1]])
            if not np.all(_inside_corridor(c, corners, PERSON_RADIUS)):
                fail(f"{key}.region", f"region {list(p.region)} leaves the corridor "
                         f"(x in [0, {c.length}], |y| <= {c.width / 2}, minus {PERSON_RADIUS} m body radius)")
            if _region_covered(obstacles, p.region, PERSON_RADIUS):
                fail(f"{key}.region", f"no free space in the region {list(p.region)}: obstacles cover all of it")
            if p.start is not None:
                if not (x0 <= p.start[0] <= x1 and y0 <= p.start[1] <= y1):
                    fail(f"{key}.start", f"start {list(p.start)} is outside the region {list(p.region)}")
                j = in_obstacle(np.array(p.start), PERSON_RADIUS)
                if j is not None:
                    fail(f"{key}.start", f"starts inside obstacles[{j}] ({obstacles[j].kind})")
            continue
        if p.behaviour == "circle":
            wps = np.array(circle_waypoints(p.center, p.radius, p.clockwise))
            path_key = f"{key}.center"
        else:
            wps = np.array(p.waypoints)
            path_key = f"{key}.waypoints"
        j = in_obstacle(wps[0], PERSON_RADIUS)
        if j is not None:
            fail(path_key, f"the person starts inside obstacles[{j}] ({obstacles[j].kind})")
        # the waypoints first, then the path between them sampled every 5 cm (inside the corridor: bounded)
        samples = wps
        outside = ~_inside_corridor(c, wps, PERSON_RADIUS)
        if not np.any(outside):
            samples = _sample_segments(wps, closed=p.behaviour in ("waypoint_loop", "circle"))
            if work is not None:
                work[0] += len(samples)
            outside = ~_inside_corridor(c, samples, PERSON_RADIUS)
        if np.any(outside):
            q = samples[np.argmax(outside)]
            fail(path_key, f"the path leaves the corridor near ({q[0]:.2f}, {q[1]:.2f}) "
                     f"(x in [0, {c.length}], |y| <= {c.width / 2}, minus {PERSON_RADIUS} m body radius)")
        hit = _first_hit(obstacles, samples, PERSON_RADIUS)
        if hit is not None:
            j, q = hit[0], samples[hit[1]]
            fail(path_key, f"the path walks through obstacles[{j}] ({obstacles[j].kind}) near "
                     f"({q[0]:.2f}, {q[1]:.2f}) (the body is {PERSON_RADIUS} m wide each side)")

    for name in ("start", "goal"):
        pos = getattr(drone, name)
        if not _inside_corridor(c, np.array(pos[:2]), 0.3)[0] or not 0.2 <= pos[2] <= c.height - 0.2:
            fail(f"drone.{name}", f"{list(pos)} is not inside the corridor with 0.3 m to the walls and 0.2 m to floor and top")
        j = in_obstacle(np.array(pos[:2]), 0.3)
        if j is not None and pos[2] <= obstacles[j].size[2] + 0.3:
            fail(f"drone.{name}", f"{list(pos)} is inside obstacles[{j}] ({obstacles[j].kind})")

    cp = camera_path
    if cp is not None:
        if cp.follow_person is not None and cp.follow_person >= len(people):
            fail("camera_path.follow_person", f"there is no people[{cp.follow_person}] ({len(people)} people)")
        for k, (t, x, y, z, _) in enumerate(cp.keyframes):
            if not _inside_corridor(c, np.array([x, y]), 0.1)[0] or not 0.1 <= z <= c.height:
                fail(f"camera_path.keyframes[{k}]", f"({x}, {y}, {z}) is outside the corridor")
        if cp.keyframes:
            pts = np.array([kf[1:4] for kf in cp.keyframes])
            for k in range(len(pts)):
                seg = pts[k:k + 2]
                n = max(2, int(np.linalg.norm(seg[-1] - seg[0]) / 0.05) + 1)
                samples = seg[0] + np.linspace(0, 1, n)[:, None] * (seg[-1] - seg[0])
                for j, o in enumerate(obstacles):
                    lo, hi = o.aabb()
                    inside = np.all((samples >= lo - 0.1) & (samples <= hi + 0.1), axis=1)
                    if np.any(inside):
                        q = samples[np.argmax(inside)]
                        fail(f"camera_path.keyframes[{k}]", f"the camera path passes through obstacles[{j}] "
                                 f"({o.kind}) near ({q[0]:.2f}, {q[1]:.2f}, {q[2]:.2f})")
