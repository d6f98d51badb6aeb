"""The camera's pose from the floor it sees: for a fixed camera that has no odometry.

DODT works in a world frame with z up and the floor at z = 0 (its ground and ceiling filters are
heights). A camera mounted on a wall or a tripod gives no pose; the floor plane in its depth image
gives the three numbers that matter, its height above the floor and its pitch and roll, and with
them a z-up world frame: x along the optical axis projected on the floor, the camera above the
origin. The yaw and the position on the floor are free: tracks come out in that frame.

The plane is found by RANSAC on the back-projected depth (a seeded generator: the same image
gives the same fit), among planes facing the camera from below within ``max_tilt`` of the
image's up direction; a parallel plane below the best one that holds a third as many points is
taken instead (a table top is not the floor), and the plane is refined by least squares on its
inliers.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dodt.frames import CameraIntrinsics


@dataclass(frozen=True)
class FloorFit:
    normal: np.ndarray  # (3,) the floor's up direction in the camera's optical frame (unit)
    height: float  # m, the camera above the floor
    inliers: int  # depth points on the plane
    points: int  # depth points considered
    residual: float  # m, RMS distance of the inliers to the plane

    @property
    def pitch_deg(self) -> float:
        """How far the optical axis points below the horizon [deg] (negative: above)."""
        return math.degrees(-math.asin(float(np.clip(self.normal[2], -1.0, 1.0))))

    @property
    def roll_deg(self) -> float:
        """Rotation of the image about the optical axis [deg]: positive when the floor's up
        direction leans toward the image's right side."""
        return math.degrees(math.atan2(float(self.normal[0]), float(-self.normal[1])))

    def T_world_camera(self) -> np.ndarray:
        """(4, 4) pose of the optical frame in the z-up world the floor defines (floor z = 0, the
        camera above the origin, x along the optical axis projected on the floor)."""
        up = self.normal / np.linalg.norm(self.normal)
        fwd = np.array([0.0, 0.0, 1.0]) - up[2] * up
        if np.linalg.norm(fwd) < 1e-6:  # looking straight down: the image's up direction instead
            fwd = np.array([0.0, -1.0, 0.0]) - (-up[1]) * up
        x = fwd / np.linalg.norm(fwd)
        y = np.cross(up, x)
        T = np.eye(4)
        T[:3, :3] = np.stack([x, y, up])  # rows: the world's axes in camera coordinates
        T[2, 3] = self.height
        return T

    def to_json(self) -> dict:
        return {"height_m": round(self.height, 4), "pitch_deg": round(self.pitch_deg, 3),
                "roll_deg": round(self.roll_deg, 3), "normal_camera": [round(float(v), 6) for v in self.normal],
                "inliers": self.inliers, "points": self.points, "residual_m": round(self.residual, 4)}


def fit_floor(depth_m: np.ndarray, K: CameraIntrinsics, seed: int = 0, iterations: int = 300,
              inlier_distance: float = 0.03, max_tilt_deg: float = 70.0, min_height: float = 0.1,
              stride: int = 4, depth_range: tuple[float, float] = (0.3, 8.0),
              min_inlier_fraction: float = 0.05) -> FloorFit | None:
    """The floor plane in one depth image [m] (0: no depth), or None when no plane fits: fewer
    than ``min_inlier_fraction`` of the points (and 200) on it, or none below the camera."""
    d = np.asarray(depth_m, dtype=np.float64)[::stride, ::stride]
    v, u = np.mgrid[0:depth_m.shape[0]:stride, 0:depth_m.shape[1]:stride]
    ok = np.isfinite(d) & (d >= depth_range[0]) & (d <= depth_range[1])
    if np.count_nonzero(ok) < 200:
        return None
    pts = K.backproject(u[ok], v[ok], d[ok])
    n_pts = len(pts)
    rng = np.random.default_rng(seed)
    image_up = np.array([0.0, -1.0, 0.0])
    cos_tilt = math.cos(math.radians(max_tilt_deg))
    best = None  # (inliers, height, normal)
    for _ in range(iterations):
        a, b, c = pts[rng.choice(n_pts, 3, replace=False)]
        n = np.cross(b - a, c - a)
        norm = np.linalg.norm(n)
        if norm < 1e-9:
            continue
        n /= norm
        if n @ image_up < 0:
            n = -n  # pointing up, toward the camera's side
        h = -float(n @ a)  # plane n.p + h = 0: the camera (origin) lies h above it
        if n @ image_up < cos_tilt or h < min_height:
            continue
        count = int(np.count_nonzero(np.abs(pts @ n + h) < inlier_distance))
        if best is None or count > best[0]:
            best = (count, h, n)
    if best is None or best[0] < max(200, min_inlier_fraction * n_pts):
        return None
    count, h, n = best
    n, h = _refine(pts, n, h, inlier_distance)
    # A plane parallel to it and lower that holds at least a third as many points is the floor
    # under a table: the lowest such peak of the points' heights below the plane.
    below = pts @ n + h
    bins = np.arange(-h, -0.1 + 1e-9, 0.02)
    if len(bins) > 3:
        hist, _ = np.histogram(below, bins=bins)
        near = np.convolve(hist, np.ones(3, int), mode="same")  # points within +-3 cm of each bin
        low = np.nonzero(near >= max(200, count / 3))[0]
        if len(low):
            i = low[0]
            n, h = _refine(pts, n, h - 0.5 * (bins[i] + bins[i + 1]), inlier_distance)
    dist = pts @ n + h
    inl = np.abs(dist) < inlier_distance
    if h < min_height or not np.any(inl):
        return None
    return FloorFit(normal=n, height=h, inliers=int(inl.sum()), points=n_pts,
                    residual=float(np.sqrt(np.mean(dist[inl] ** 2))))


def _refine(pts: np.ndarray, n: np.ndarray, h: float, inlier_distance: float) -> tuple[np.ndarray, float]:
    """The plane n.p + h = 0 refitted by least squares to the points within ``inlier_distance`` of
    it, twice (the plane through their centroid, normal to their least spread), its normal kept
    pointing to the same side."""
    for _ in range(2):
        inl = pts[np.abs(pts @ n + h) < inlier_distance]
        if len(inl) < 3:
            break
        centroid = inl.mean(axis=0)
        _, _, vt = np.linalg.svd(inl - centroid, full_matrices=False)
        n_ls = vt[2] if vt[2] @ n >= 0 else -vt[2]
        n, h = n_ls, -float(n_ls @ centroid)
    return n, h


def fit_floor_frames(depths, K: CameraIntrinsics, seed: int = 0, return_index: bool = False, **kw):
    """The floor from several depth images of a fixed camera: each is fitted, and the fit with the
    most points on its plane is taken (a person walking through one frame does not decide it).
    None when no image has one; with ``return_index``, (fit, index of its image)."""
    fits = [(f, i) for i, f in enumerate(fit_floor(d, K, seed=seed, **kw) for d in depths) if f is not None]
    best = max(fits, key=lambda e: (e[0].inliers, -e[1])) if fits else (None, None)
    return best if return_index else best[0]


def camera_pose(height: float, pitch_deg: float, roll_deg: float = 0.0) -> np.ndarray:
    """(4, 4) pose of a camera's optical frame at ``height`` above the floor, its optical axis
    ``pitch_deg`` below the horizon and its image rolled by ``roll_deg`` (FloorFit's conventions),
    looking along the world's x axis."""
    p, r = math.radians(pitch_deg), math.radians(roll_deg)
    # the floor's up direction in the camera frame: level, (0, -1, 0); pitched down by p, tilted
    # toward the optical axis' back; rolled by r about the optical axis
    up = np.array([math.sin(r) * math.cos(p), -math.cos(r) * math.cos(p), -math.sin(p)])
    return FloorFit(normal=up, height=float(height), inliers=0, points=0, residual=0.0).T_world_camera()
