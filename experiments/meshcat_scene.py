"""Drawing an episode's scene onto a ``meshcat.Visualizer``: the colours, the corridor, its static
obstacles and goal, the drone, and the line, point and box primitives the live viewer
(experiments.live_viewer) and the HTML replay (experiments.replay_html) both draw with."""
from __future__ import annotations

import meshcat.geometry as g
import numpy as np

DRONE_SIZE = (0.51, 0.70, 0.12)  # m, the collision box of sim/assets/quadrotor.urdf
CAMERA_OFFSET = (-0.35, -0.4, 0.6)  # the viewpoint from mid-corridor, in corridor lengths
TRAIL_S = 3.0  # s of people's track drawn behind them (the paper's figures)
# Flat (unlit) colours for the drone and the floor, so a screenshot can be checked for them.
DRONE_RGB, FLOOR_RGB = (255, 0, 255), (200, 180, 120)
# People orange, far from the goal's green; their velocity arrows take the dynamic tracks' red.
WALL, OBSTACLE, PERSON, GOAL = 0xD9D2C0, 0x8C7B6B, 0xFF8C00, 0x30FF30
DYNAMIC, STATIC = 0xE02020, 0x5A78A0
ARROW = DYNAMIC
EXECUTED, PLANNED, GLOBAL_PATH, CLOUD = 0xFFD700, 0x00C8FF, 0xFFFFFF, 0xB0C4FF


def _hex(rgb) -> int:
    return (rgb[0] << 16) | (rgb[1] << 8) | rgb[2]


def unit_rgb(color: int) -> np.ndarray:
    return np.array([(color >> 16) & 255, (color >> 8) & 255, color & 255], dtype=np.float32) / 255


def translation(p, scale=(1.0, 1.0, 1.0)) -> np.ndarray:
    T = np.diag([*map(float, scale), 1.0])
    T[:3, 3] = p
    return T


def height_colors(z: np.ndarray, top: float) -> np.ndarray:
    """(3, N) float32 colours ramping blue -> green -> yellow with height (voxels)."""
    stops = np.array([[0.23, 0.30, 0.75], [0.13, 0.66, 0.45], [0.99, 0.85, 0.15]])
    s = np.clip(z / max(top, 1e-6), 0, 1) * 2
    i = np.minimum(s.astype(int), 1)
    c = stops[i] + (stops[i + 1] - stops[i]) * (s - i)[:, None]
    return c.T.astype(np.float32)


def voxel_centers(idx, origin, res: float, corridor) -> np.ndarray:
    """World centres of occupied voxels above the floor, without those of the corridor's walls
    (drawn as walls already)."""
    c = np.asarray(origin, float) + (np.asarray(idx, float).reshape(-1, 3) + 0.5) * res
    keep = c[:, 2] >= 0.1
    if corridor is not None:
        L, W, _ = corridor_dims(corridor)
        keep &= (c[:, 0] > res) & (c[:, 0] < L - res) & (np.abs(c[:, 1]) < W / 2 - res)
    return c[keep]


def draw_points(vis, pts: np.ndarray, colors: np.ndarray, size: float) -> None:
    vis.set_object(g.PointCloud(np.asarray(pts, np.float32).T, colors, size=size))


def draw_line(vis, pts: np.ndarray, color: int, segments: bool = False, colors: np.ndarray | None = None) -> None:
    pts = np.asarray(pts, dtype=np.float32).reshape(-1, 3)
    if len(pts) < 2:
        pts = np.zeros((2, 3), np.float32)  # nothing to draw: a degenerate line
        colors = None
    kind = g.LineSegments if segments else g.Line
    geometry = g.PointsGeometry(pts.T, None if colors is None else np.asarray(colors, np.float32).T)
    vis.set_object(kind(geometry, g.LineBasicMaterial(color=color, vertexColors=colors is not None)))


_CUBE_EDGES = np.array([[a, b] for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1])
_CUBE = np.array([[(i >> 0) & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=float) - 0.5
UNIT_ARROW = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 0], [0.8, 0.1, 0], [1, 0, 0], [0.8, -0.1, 0]], dtype=float)
UNIT_BOX = _CUBE[_CUBE_EDGES.ravel()]  # (24, 3) segment ends of a unit wireframe cube


def box_edges(center, size) -> np.ndarray:
    """(24, 3) segment end points of a wireframe box."""
    return np.asarray(center, float) + UNIT_BOX * np.asarray(size, float)


def corridor_dims(corridor) -> tuple[float, float, float]:
    get = corridor.get if isinstance(corridor, dict) else lambda k: getattr(corridor, k)
    return float(get("length")), float(get("width")), float(get("height"))


def draw_static_scene(vis, corridor, static_boxes, goal=None) -> None:
    """Floor, semi-transparent corridor walls, static obstacles (list of (lo, hi)), the goal, and
    a camera looking down the corridor from behind and above its right side."""
    L, W, H = corridor_dims(corridor)
    vis["/Grid"].set_property("visible", False)
    s = vis["scene"]
    s["floor"].set_object(g.Box([L, W, 0.02]), g.MeshBasicMaterial(color=_hex(FLOOR_RGB)))
    s["floor"].set_transform(translation([L / 2, 0, -0.011]))
    walls = {"left": ([L / 2, W / 2 + 0.05, H / 2], [L, 0.1, H]), "start": ([-0.05, 0, H / 2], [0.1, W, H]),
             "right": ([L / 2, -W / 2 - 0.05, H / 2], [L, 0.1, H]), "end": ([L + 0.05, 0, H / 2], [0.1, W, H])}
    for name, (c, size) in walls.items():
        s["walls"][name].set_object(g.Box(size), g.MeshLambertMaterial(color=WALL, opacity=0.25))
        s["walls"][name].set_transform(translation(c))
    for i, (lo, hi) in enumerate(static_boxes):
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        s["obstacles"][str(i)].set_object(g.Box((hi - lo).tolist()), g.MeshLambertMaterial(color=OBSTACLE))
        s["obstacles"][str(i)].set_transform(translation((lo + hi) / 2))
    if goal is not None:
        s["goal"].set_object(g.Sphere(0.15), g.MeshLambertMaterial(color=GOAL, opacity=0.7))
        s["goal"].set_transform(translation(goal))
    # The viewer's camera orbits the viewer's origin: shift the scene so that it is mid-corridor.
    # The camera rig is Y-up under /Cameras/default/rotated: offset (x, y, z) is (x, z, -y) there.
    vis["/meshcat"].set_transform(translation([-L / 2, 0.0, 0.0]))
    vis["/Axes"].set_property("visible", False)
    offset = np.array(CAMERA_OFFSET) * L
    vis["/Cameras/default/rotated/<object>"].set_property("position", [offset[0], offset[2], -offset[1]])


def draw_drone(vis) -> None:
    vis["drone"].set_object(g.Box(list(DRONE_SIZE)), g.MeshBasicMaterial(color=_hex(DRONE_RGB)))
