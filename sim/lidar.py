"""A simulated 3D LiDAR of the Livox Mid-360 class, cast with PyBullet's ray batches.

The sensor (Livox Mid-360 specification): 360 deg horizontal by -7 to +52 deg vertical, about 200,000
points per second (20,000 per scan at 10 Hz), a 0.1 m blind zone, about 40 m of range at 10 %
reflectivity, range precision (1 sigma) about 2 cm. Sensor frame x forward, y left, z up.

How a scan is made (``simulate_scan``): every ray of the scan's pattern is cast from the sensor's true
pose with ``rayTestBatch`` against the collision shapes of the given PyBullet clients, each ray keeping
its nearest hit over all of them (or its hit is looked up by a caster passed in: sim.lidar_panorama's
depth panoramas, several times faster); then, drawn from the generator passed in (the same number of
draws every scan, whatever was hit):

- range noise: normal, ``range_std``, along the ray;
- dropout at grazing incidence: a return whose incidence angle theta (between the ray and the surface
  normal) exceeds ``grazing_start`` is dropped with probability (theta - grazing_start) /
  (grazing_full - grazing_start), every one from ``grazing_full`` on (ours: a matte surface returns
  power in proportion to cos theta, which near 90 deg falls below what the receiver detects);
- limits: a hit nearer than ``min_range`` (the blind zone) gives no return but still hides what is
  behind it; a return whose true or measured range lies outside [min_range, max_range] is dropped.

The scan pattern (approximated, ``scan_directions``): the Mid-360 scans a non-repetitive pattern whose
rays, scan after scan, fill its field of view instead of retracing the same lines. Here ``channels``
beams spin ``spins_per_scan`` turns per scan, evenly spaced in azimuth, each zig-zagging (a triangle
wave, uniform in elevation angle) across the vertical field ``zigzags_per_spin`` times per turn. That
number is not whole: its fractional part (the golden ratio's) shifts the zig-zags from one scan to the
next, so no two scans repeat and their union covers the field ever more densely. The pattern is a
function of the scan index alone, the same in every run. It is not Livox's measured pattern: the
point density is uniform in azimuth and elevation angle, and the timing of points within a scan is not
modelled.

What is ignored: motion during a scan (every ray is cast from one pose against the scene at one
instant, as if the whole scan took no time), intensity and reflectivity (every surface has the same
range limit), multiple returns (each ray gives its nearest hit only), beam divergence (a ray is a
line), and the difference between what the camera draws and what rays hit: rays hit collision shapes
(PyBullet's humanoid walkers have capsule and sphere collision shapes close to their visual meshes;
the quadrotor's collision box, which encloses its propellers, is larger than what is drawn of it).
"""
from __future__ import annotations

import math
from itertools import chain
from operator import itemgetter

import numpy as np
from numba import njit

from sim.camera import quiet_stdout

with quiet_stdout():  # PyBullet prints its build time on import
    import pybullet as p

from dodt.frames import LidarScan
from sim.lidar_model import LidarModel, top_mount  # noqa: F401 (re-exported)

# rayTestBatch takes fewer rays than MAX_RAY_INTERSECTION_BATCH_SIZE in one call: with exactly that many,
# PyBullet 3.2.7 returns one result less (from Python lists) or none (from numpy arrays).
RAY_BATCH = p.MAX_RAY_INTERSECTION_BATCH_SIZE - 1


def scan_directions(model: LidarModel, scan_index: int) -> tuple[np.ndarray, np.ndarray]:
    """(azimuth, elevation), each (points_per_scan,) float64 radians, of the rays of scan ``scan_index``:
    the approximated non-repetitive pattern of the module's docstring. Azimuth in [-fov/2, fov/2) about
    the x axis, elevation in [elevation_min, elevation_max]."""
    return _scan_rays(model, scan_index)[:2]


def _scan_rays(model: LidarModel, scan_index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(azimuth, elevation, unit directions (N, 3) in the sensor frame) of the rays of scan ``scan_index``."""
    return _pattern(int(scan_index), model.points_per_scan, model.channels, float(model.spins_per_scan),
                    float(model.zigzags_per_spin), float(model.horizontal_fov), float(model.elevation_min),
                    float(model.elevation_max))


@njit(cache=True, nogil=True)
def _pattern(scan_index, n, c, spins, zigzags, fov, el_min, el_max):
    azimuth, elevation, dirs = np.empty(n), np.empty(n), np.empty((n, 3))
    for k in range(n):
        g = scan_index * n + k  # the ray's index since scan 0
        channel = g % c
        # turns done by the channel's beam, counted from scan 0, plus the channel's offset in azimuth
        turns = (g // c) * (c * spins / n) + channel / c
        az = fov * (turns % 1.0 - 0.5)
        sweep = (zigzags * turns + channel / (2 * c)) % 1.0
        el = el_min + (el_max - el_min) * (1.0 - abs(2.0 * sweep - 1.0))
        azimuth[k], elevation[k] = az, el
        ce = math.cos(el)
        dirs[k, 0], dirs[k, 1], dirs[k, 2] = ce * math.cos(az), ce * math.sin(az), math.sin(el)
    return azimuth, elevation, dirs


def ray_directions(azimuth: np.ndarray, elevation: np.ndarray) -> np.ndarray:
    """(N, 3) unit vectors in the sensor frame of rays at (azimuth, elevation)."""
    ce = np.cos(elevation)
    return np.stack([ce * np.cos(azimuth), ce * np.sin(azimuth), np.sin(elevation)], axis=1)


def dropout_probability(model: LidarModel, incidence: np.ndarray) -> np.ndarray:
    """Probability that a return at incidence angle ``incidence`` [rad] (0: the ray meets the surface
    head on) is dropped: 0 up to grazing_start, rising linearly to 1 at grazing_full."""
    return np.clip((np.asarray(incidence, dtype=np.float64) - model.grazing_start)
                   / (model.grazing_full - model.grazing_start), 0.0, 1.0)


def _body_boxes(client: int) -> np.ndarray:
    """(B, 2, 3) the world-frame AABB (lower, upper corner) of each body in ``client``, its links included."""
    boxes = []
    for i in range(p.getNumBodies(physicsClientId=client)):
        uid = p.getBodyUniqueId(i, physicsClientId=client)
        lo, hi = (np.array(v) for v in p.getAABB(uid, -1, physicsClientId=client))
        for link in range(p.getNumJoints(uid, physicsClientId=client)):
            a, b = p.getAABB(uid, link, physicsClientId=client)
            lo, hi = np.minimum(lo, a), np.maximum(hi, b)
        boxes.append((lo, hi))
    return np.array(boxes, dtype=np.float64).reshape(-1, 2, 3)


def _rays_meeting_boxes(origin: np.ndarray, dirs: np.ndarray, reach: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """(N,) bool: the rays from ``origin`` along unit ``dirs`` that may enter one of ``boxes`` (B, 2, 3) within
    ``reach`` (N,) (conservative: every ray that does is True).

    A box's bounding sphere decides when the origin lies outside it (one matrix product for all boxes); the
    slab test decides for the boxes whose sphere holds the origin (the sensor's own body, a floor, a wall)."""
    centres = boxes.mean(axis=1)
    radii = 0.5 * np.linalg.norm(boxes[:, 1] - boxes[:, 0], axis=1)
    v = centres - origin  # (B, 3)
    dist2 = np.einsum("ij,ij->i", v, v)
    outside = dist2 > radii * radii
    meets = np.zeros(len(dirs), dtype=bool)
    if outside.any():
        vo, ro = v[outside], radii[outside]
        t = dirs @ vo.T  # (N, B): where along each ray it passes nearest to each centre
        meets |= ((dist2[outside] - t * t <= ro * ro) & (t >= 0.0) & (t - ro <= reach[:, None])).any(axis=1)
    inside = np.flatnonzero(~outside)
    if len(inside):
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / dirs.T  # (3, N); +-inf along a zero component: the slab then bounds nothing or everything
            for lo, hi in boxes[inside]:
                t1, t2 = (lo - origin)[:, None] * inv, (hi - origin)[:, None] * inv
                near, far = np.fmin(t1, t2), np.fmax(t1, t2)  # fmin, fmax: a nan (0 * inf) gives way
                t_in = np.maximum(np.maximum(near[0], near[1]), near[2])
                t_out = np.minimum(np.minimum(far[0], far[1]), far[2])
                meets |= (t_out >= 0.0) & (t_in <= t_out) & (t_in <= reach)
    return meets


def cast_rays(clients, origin: np.ndarray, dirs: np.ndarray, reach: float) -> tuple[np.ndarray, np.ndarray]:
    """Cast rays from ``origin`` (3,) along unit ``dirs`` (N, 3), world frame, up to ``reach`` m, against every
    body of each PyBullet client in ``clients``. Returns (range (N,) m, inf where nothing was hit; the unit
    surface normal at the hit (N, 3), zero where nothing was hit), the nearest hit over all clients.

    A ray is cast in a client only when it may enter the bounding box of one of its bodies nearer than the
    nearest hit so far, and only that far."""
    n = len(dirs)
    nearest = np.full(n, float(reach))
    normal = np.zeros((n, 3))
    hit = np.zeros(n, dtype=bool)
    for client in clients:
        idx = np.flatnonzero(_rays_meeting_boxes(origin, dirs, nearest, _body_boxes(client)))
        for s in range(0, len(idx), RAY_BATCH):
            k = idx[s:s + RAY_BATCH]
            length = nearest[k]
            to = origin + dirs[k] * length[:, None]
            frm = np.broadcast_to(origin, to.shape).copy()
            res = p.rayTestBatch(frm, to, numThreads=0, physicsClientId=client)
            m = len(res)
            # each result: (body id or -1, link, hit fraction, hit position, hit normal), world frame
            got = np.fromiter(map(itemgetter(0), res), np.int64, m) >= 0
            r = np.fromiter(map(itemgetter(2), res), np.float64, m) * length
            nrm = np.fromiter(chain.from_iterable(map(itemgetter(4), res)), np.float64, 3 * m).reshape(m, 3)
            closer = got & (r < length)
            kk = k[closer]
            nearest[kk] = r[closer]
            normal[kk] = nrm[closer]
            hit[kk] = True
    return np.where(hit, nearest, np.inf), normal


def simulate_scan(client, T_world_sensor: np.ndarray, model: LidarModel, rng: np.random.Generator,
                  scan_index: int, *, stamp: float = 0.0, T_world_sensor_reported: np.ndarray | None = None,
                  seq: int | None = None, caster=None) -> LidarScan:
    """One scan of ``model`` from the true sensor pose ``T_world_sensor`` (4, 4) in the PyBullet client
    ``client`` (or several clients, each ray keeping its nearest hit over all of them), the rays of
    pattern ``scan_index``, the noise and dropouts drawn from ``rng`` (see the module's docstring).

    ``caster``, when given, finds the hits instead of rayTestBatch (``client`` is then not used): a callable
    (T_world_sensor, ray directions (N, 3) in the sensor frame, reach) -> (range (N,) m, inf where nothing
    was hit; unit surface normal (N, 3), world frame), as ``sim.lidar_panorama.PanoramaCaster``.

    The scan carries ``T_world_sensor_reported`` (the pose from odometry; default: the true pose), ``stamp``
    and ``seq`` (default: the scan index). The same generator state gives a bit-identical scan."""
    T = np.asarray(T_world_sensor, dtype=np.float64)
    azimuth, elevation, d_sensor = _scan_rays(model, scan_index)
    d_world = d_sensor @ T[:3, :3].T
    n = len(azimuth)
    noise = rng.standard_normal(n) * model.range_std
    draw = rng.random(n)
    if caster is None:
        clients = (client,) if isinstance(client, (int, np.integer)) else tuple(client)
        true_range, normal = cast_rays(clients, T[:3, 3].copy(), d_world, model.max_range)
    else:
        true_range, normal = caster(T, d_sensor, model.max_range)
    points, ranges, az, el = _returns(true_range, normal, d_world, d_sensor, azimuth, elevation, noise, draw,
                                      float(model.min_range), float(model.max_range), float(model.grazing_start),
                                      float(model.grazing_full))
    reported = T if T_world_sensor_reported is None else np.asarray(T_world_sensor_reported, dtype=np.float64)
    return LidarScan(points=points, ranges=ranges, azimuth=az, elevation=el, stamp=float(stamp),
                     T_world_sensor=reported.copy(), seq=int(scan_index if seq is None else seq), n_rays=n)


@njit(cache=True, nogil=True)
def _returns(true_range, normal, d_world, d_sensor, azimuth, elevation, noise, draw, r_min, r_max, g_start, g_full):
    """The rays that return (a hit within the limits, not dropped at grazing incidence: dropout_probability's
    rule) and their float32 (points, ranges, azimuth, elevation), in ray order."""
    n = true_range.shape[0]
    keep = np.zeros(n, np.bool_)
    count = 0
    for i in range(n):
        t = true_range[i]
        if not (t >= r_min and t <= r_max):  # also false for inf and NaN
            continue
        c = abs(d_world[i, 0] * normal[i, 0] + d_world[i, 1] * normal[i, 1] + d_world[i, 2] * normal[i, 2])
        p_drop = min(max((math.acos(min(c, 1.0)) - g_start) / (g_full - g_start), 0.0), 1.0)
        m = t + noise[i]
        if draw[i] < p_drop or not (m >= r_min and m <= r_max):
            continue
        keep[i] = True
        count += 1
    points = np.empty((count, 3), np.float32)
    ranges = np.empty(count, np.float32)
    az = np.empty(count, np.float32)
    el = np.empty(count, np.float32)
    j = 0
    for i in range(n):
        if keep[i]:
            m = true_range[i] + noise[i]
            for a in range(3):
                points[j, a] = d_sensor[i, a] * m
            ranges[j], az[j], el[j] = m, azimuth[i], elevation[i]
            j += 1
    return points, ranges, az, el
