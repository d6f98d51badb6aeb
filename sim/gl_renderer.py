"""Our own OpenGL camera (moderngl on an EGL context; Mesa's llvmpipe without a GPU).

It draws the visual shapes a PyBullet client holds (boxes, spheres, capsules, cylinders: what the
corridor, the obstacles, the DeepMimic humanoid and the quadrotor are made of) as the same meshes
PyBullet's renderers draw for them, at the poses PyBullet holds when ``render`` is called, with the
same projection as ``sim.camera`` (``projection_matrix``:
the intrinsics exactly, pixel centres sampled, row 0 at the top) and hands back the same raw buffers
as PyBullet's ``getCameraImage`` path: RGBA (H, W, 4) uint8, the depth buffer (H, W) float32 in
[0, 1] (1 where nothing was hit; ``sim.camera.linearize_depth`` makes it metric planar depth) and
PyBullet body ids (H, W) int32 with -1 for the background. So the depth noise, the segmentation
lookup and the render process work unchanged on either renderer.

How it is drawn: every visual shape becomes a mesh once (see "meshes" below), in its link's frame, in
one vertex buffer; each vertex names its link (a "part"). Per frame the link poses are read from
PyBullet, each part's model-view-projection matrix is composed in float64 and uploaded with the light direction in the part's frame as one small float
texture, and the whole scene is one indexed draw call. Colour is Lambert shading per vertex with an
ambient term (not PyBullet's shading: colours differ from PyBullet's images, depth and body ids do not).

Depth precision: PyBullet's EGL plugin renders into a 16-bit depth buffer (its depth values step by
exactly 2^-16: 1 mm at 4.6 m, far below the sensor noise). The depth read back here (24 bits) is
rounded onto that grid (``depth_bits=16``, the default), because DODT's output turns on it: at 24
bits a wall fragment of the static_only scenario can be reported moving where PyBullet's grid, as
PyBullet's renderer, gives none.

The GL context is created once per process and kept (``shared_context``): successive worlds in one
process (a sweep worker's episodes) reuse it; a renderer frees only its own buffers.
"""
from __future__ import annotations

import math
import os
import threading
from functools import lru_cache

import numpy as np

from dodt.frames import CameraIntrinsics
from sim.camera import FAR_PLANE, NEAR_PLANE, projection_matrix, view_matrix

BACKGROUND = (0.7, 0.7, 0.8)  # RGB where nothing is hit: PyBullet's EGL background (measured on its images)
# Shading: a surface shows its colour times AMBIENT + (1 - AMBIENT) max(0, n . l), l the unit direction
# towards the light. The default light comes from above and behind a camera flying along +x, so that,
# as in PyBullet's images, walls facing the camera are the brightest surfaces and the floor is lit.
AMBIENT = 0.6
DEFAULT_LIGHT = (-0.8, 0.2, 0.55)  # direction towards the light, world frame, when none is given

# PyBullet geometry types (pybullet.GEOM_*), here so that this module's geometry code needs no PyBullet
GEOM_SPHERE, GEOM_BOX, GEOM_CYLINDER, GEOM_MESH, GEOM_PLANE, GEOM_CAPSULE = 2, 3, 4, 5, 6, 7
_GEOM_NAMES = {GEOM_SPHERE: "sphere", GEOM_BOX: "box", GEOM_CYLINDER: "cylinder", GEOM_MESH: "mesh",
               GEOM_PLANE: "plane", GEOM_CAPSULE: "capsule"}


class GLUnavailable(RuntimeError):
    """No OpenGL context could be made (moderngl missing, or no EGL)."""


class GLUnsupportedScene(RuntimeError):
    """The scene holds a shape this renderer does not draw (a mesh file or a plane)."""


# --------------------------------------------------------------------------- the context

_ctx = None
_ctx_error: str | None = None
_ctx_lock = threading.Lock()
_EGL_DRAW, _EGL_READ = 0x3059, 0x305A


class _EGLCurrent:
    """Which EGL context is current on this thread, and putting one back.

    PyBullet's EGL plugin makes its own context current once (with its pbuffer surface) and renders
    into whatever is current after that: a World with renderer "pybullet" in the same process as
    ours (a comparison, a test) crashed once our context had been made current. So our context is
    made current only while we draw, and the one that was current before comes back with its
    surfaces afterwards (moderngl's own context switch restores it without them)."""

    def __init__(self):
        import ctypes
        import ctypes.util

        name = ctypes.util.find_library("EGL") or "libEGL.so.1"
        lib = ctypes.CDLL(name)
        vp = ctypes.c_void_p
        for fn, args in (("eglGetCurrentDisplay", []), ("eglGetCurrentContext", []),
                         ("eglGetCurrentSurface", [ctypes.c_int32])):
            getattr(lib, fn).restype = vp
            getattr(lib, fn).argtypes = args
        lib.eglMakeCurrent.restype = ctypes.c_uint32
        lib.eglMakeCurrent.argtypes = [vp, vp, vp, vp]
        self.lib = lib

    def get(self) -> tuple:
        lib = self.lib
        return (lib.eglGetCurrentDisplay(), lib.eglGetCurrentSurface(_EGL_DRAW), lib.eglGetCurrentSurface(_EGL_READ),
                lib.eglGetCurrentContext())

    def restore(self, state: tuple) -> None:
        if state[3]:  # nothing was current before: ours may stay
            self.lib.eglMakeCurrent(*state)


_egl: _EGLCurrent | None = None
_ours = None  # our EGLContext handle


def shared_context():
    """This process's one OpenGL context (made on first use, then kept); GLUnavailable when none can be made."""
    global _ctx, _ctx_error, _egl, _ours
    with _ctx_lock:
        if _ctx is not None:
            return _ctx
        if _ctx_error is not None:
            raise GLUnavailable(_ctx_error)
        try:
            import moderngl
        except ImportError as e:
            _ctx_error = f"the gl renderer needs the moderngl package ({e})"
            raise GLUnavailable(_ctx_error) from None
        try:
            egl = _EGLCurrent()
            before = egl.get()
            ctx = moderngl.create_standalone_context(backend="egl")  # leaves it current
            _ours = egl.get()[3]
            egl.restore(before)
        except Exception as e:  # noqa: BLE001 - any failure means: no GL here
            _ctx_error = f"no OpenGL context through EGL ({type(e).__name__}: {e}); is Mesa's libEGL installed?"
            raise GLUnavailable(_ctx_error) from None
        _ctx, _egl = ctx, egl
        return _ctx


class _Current:
    """``with _Current():`` our context is current inside, and what was current before comes back after."""

    def __enter__(self):
        self.before = _egl.get()
        if self.before[3] != _ours:
            _ctx.mglo.__enter__()
        return self

    def __exit__(self, *exc):
        if self.before[3] != _ours:
            _egl.restore(self.before)


def gl_available() -> bool:
    try:
        shared_context()
    except GLUnavailable:
        return False
    return True


def context_info() -> dict:
    """The GL renderer and version strings of the shared context ({} when there is none)."""
    if not gl_available():
        return {}
    with _Current():
        info = _ctx.info
    return {"renderer": info.get("GL_RENDERER"), "version": info.get("GL_VERSION"),
            "threads": os.environ.get("LP_NUM_THREADS")}


# --------------------------------------------------------------------------- meshes
#
# The meshes PyBullet's renderers draw for its primitive shapes (measured against its EGL plugin's images:
# the same pixels, depth within hundredths of a millimetre; tests/sim/test_gl_renderer.py). A box is drawn
# as it is. A sphere, capsule or cylinder is drawn as a convex polyhedron: the hull of the shape's support
# points along 42 fixed directions (the vertices of an icosahedron with two vertices on the z axis, and the
# midpoints of its edges, pushed out onto the unit sphere). The support points are those of a sphere for a
# sphere; for a cylinder, of its two rims as 32-gons (vertex i at (r sin a, r cos a), a = 2 pi i / 32) with a
# 1 mm margin around them; a capsule adds its two poles. Where two points tie, the first in that order wins
# (upper rim before lower). People therefore look as faceted as in PyBullet's images, a little inside their
# collision shapes.

PYBULLET_HULL_MARGIN = 0.001  # m, around the rim polygons of a cylinder or capsule
_RIM_VERTICES = 32


def _hull_directions() -> np.ndarray:
    """The 42 unit directions: an icosahedron with vertices at the poles, its lower ring at azimuths 36 + 72 k
    degrees and its upper ring at 72 k degrees, then its 30 edge midpoints normalised."""
    ring_z = 1.0 / math.sqrt(5.0)
    ring_r = 2.0 * ring_z
    verts = [(0.0, 0.0, -1.0)]
    verts += [(ring_r * math.cos(math.radians(36 + 72 * k)), ring_r * math.sin(math.radians(36 + 72 * k)), -ring_z)
              for k in range(5)]
    verts += [(ring_r * math.cos(math.radians(72 * k)), ring_r * math.sin(math.radians(72 * k)), ring_z)
              for k in range(5)]
    verts.append((0.0, 0.0, 1.0))
    v = np.array(verts)
    dist = np.linalg.norm(v[:, None] - v[None], axis=2)
    edge = dist[dist > 1e-9].min()
    mids = [(v[i] + v[j]) / 2 for i in range(12) for j in range(i + 1, 12) if abs(dist[i, j] - edge) < 1e-9]
    mids = [m / np.linalg.norm(m) for m in mids]
    return np.vstack([v, np.array(mids)])


HULL_DIRECTIONS = _hull_directions()


def _support_hull(points: np.ndarray, margin: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flat-shaded mesh of the convex hull of the support points of ``points`` (with ``margin`` around them)
    along HULL_DIRECTIONS: (positions (3T, 3), face normals per vertex, triangles (T, 3)), outward and
    counter-clockwise."""
    from scipy.spatial import ConvexHull

    d = HULL_DIRECTIONS
    support = points[np.argmax(d @ points.T, axis=1)] + margin * d  # argmax: the first of tied points
    pts = np.unique(support, axis=0)
    tri = ConvexHull(pts).simplices
    a, b, c = pts[tri[:, 0]], pts[tri[:, 1]], pts[tri[:, 2]]
    n = np.cross(b - a, c - a)
    inward = np.einsum("ij,ij->i", n, a - pts.mean(axis=0)) < 0
    tri[inward] = tri[inward][:, ::-1]
    n[inward] *= -1.0
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return pts[tri].reshape(-1, 3), np.repeat(n, 3, axis=0), np.arange(3 * len(tri)).reshape(-1, 3)


def _rims(radius: float, length: float) -> np.ndarray:
    """The upper and lower rim polygons of a cylinder along z, vertex by vertex (upper first)."""
    a = 2.0 * np.pi * np.arange(_RIM_VERTICES) / _RIM_VERTICES
    x, y = radius * np.sin(a), radius * np.cos(a)
    h = np.full_like(a, length / 2)
    return np.stack([np.stack([x, y, h], -1), np.stack([x, y, -h], -1)], axis=1).reshape(-1, 3)


def sphere_mesh(radius: float):
    return _support_hull(np.zeros((1, 3)), radius)


def capsule_mesh(radius: float, length: float):
    """A capsule along z: a cylinder of ``length`` between two hemispheres (Bullet's and URDF's convention)."""
    poles = np.array([[0.0, 0.0, length / 2 + radius], [0.0, 0.0, -length / 2 - radius]])
    return _support_hull(np.vstack([_rims(radius, length), poles]), PYBULLET_HULL_MARGIN)


def cylinder_mesh(radius: float, length: float):
    return _support_hull(_rims(radius, length), PYBULLET_HULL_MARGIN)


def box_mesh(half_extents):
    """An axis-aligned box: 6 faces with their own normals, 12 outward counter-clockwise triangles."""
    hx, hy, hz = (float(x) for x in half_extents)
    pos, nrm, tri = [], [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            n = np.zeros(3)
            n[axis] = sign
            u, v = np.zeros(3), np.zeros(3)
            u[(axis + 1) % 3], v[(axis + 2) % 3] = 1.0, 1.0
            if sign < 0:
                u, v = v, u  # keep u x v = n, so the corners below run counter-clockwise seen from outside
            h = np.array([hx, hy, hz])
            centre = n * h
            k = len(pos)
            for du, dv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                pos.append(centre + du * u * h + dv * v * h)
                nrm.append(n)
            tri += [(k, k + 1, k + 2), (k, k + 2, k + 3)]
    return np.array(pos), np.array(nrm), np.array(tri)


@lru_cache(maxsize=512)
def shape_mesh(geom: int, dims: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The mesh PyBullet draws for one visual shape, from ``getVisualShapeData``'s type and dimensions (box:
    full extents; sphere: radius first; capsule and cylinder: length, then radius). Cached: read-only."""
    if geom == GEOM_BOX:
        mesh = box_mesh(np.asarray(dims[:3], dtype=float) / 2)
    elif geom == GEOM_SPHERE:
        mesh = sphere_mesh(float(dims[0]))
    elif geom == GEOM_CAPSULE:
        mesh = capsule_mesh(float(dims[1]), float(dims[0]))
    elif geom == GEOM_CYLINDER:
        mesh = cylinder_mesh(float(dims[1]), float(dims[0]))
    else:
        raise GLUnsupportedScene(f"a {_GEOM_NAMES.get(geom, f'type {geom}')} shape")
    for a in mesh:
        a.setflags(write=False)
    return mesh


# --------------------------------------------------------------------------- poses


def _matrix(pos, quat) -> np.ndarray:
    """4x4 transform from a position and a PyBullet quaternion (x, y, z, w)."""
    x, y, z, w = quat
    T = np.eye(4)
    T[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                 [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                 [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    T[:3, 3] = pos
    return T


# --------------------------------------------------------------------------- the renderer

_VERTEX_SHADER = """
#version 330
uniform sampler2D parts;  // per part: 4 texels of its MVP's columns, then (light in its frame, body id)
uniform float ambient;
uniform int row0;  // the first part's row: several views' parts are stacked in one texture
in vec3 in_pos;
in vec3 in_normal;
in vec4 in_color;
in int in_part;
out vec3 v_color;
flat out int v_body;
void main() {
    mat4 mvp = mat4(texelFetch(parts, ivec2(0, in_part + row0), 0), texelFetch(parts, ivec2(1, in_part + row0), 0),
                    texelFetch(parts, ivec2(2, in_part + row0), 0), texelFetch(parts, ivec2(3, in_part + row0), 0));
    vec4 light = texelFetch(parts, ivec2(4, in_part + row0), 0);
    gl_Position = mvp * vec4(in_pos, 1.0);
    v_color = in_color.rgb * (ambient + (1.0 - ambient) * max(dot(in_normal, light.xyz), 0.0));
    v_body = int(light.w);
}
"""

_FRAGMENT_SHADERS = {
    "color_seg": """
#version 330
in vec3 v_color;
flat in int v_body;
layout(location = 0) out vec4 out_color;
layout(location = 1) out int out_body;
void main() { out_color = vec4(v_color, 1.0); out_body = v_body + 1; }
""",
    "color": """
#version 330
in vec3 v_color;
layout(location = 0) out vec4 out_color;
void main() { out_color = vec4(v_color, 1.0); }
""",
    "seg": """
#version 330
flat in int v_body;
layout(location = 1) out int out_body;
void main() { out_body = v_body + 1; }
""",
    "depth": """
#version 330
void main() {}
""",
}


class _Part:
    """One rigid set of shapes: a body's base or one of its links."""

    __slots__ = ("body", "link", "T_base_urdf")

    def __init__(self, body: int, link: int, T_base_urdf: np.ndarray | None):
        self.body, self.link, self.T_base_urdf = body, link, T_base_urdf


class GLRenderer:
    """Renders a PyBullet client's visual shapes; build it after the last body was created.

    ``render`` reads every link's pose from the client when called, so it draws the scene as posed
    then (kinematically posed people included). Free its GL objects with ``release`` (the world's close)."""

    def __init__(self, p, client: int, K: CameraIntrinsics, near: float = NEAR_PLANE, far: float = FAR_PLANE,
                 depth_bits: int = 16):
        if depth_bits not in (16, 24):
            raise ValueError(f"depth_bits: expected 16 (PyBullet's depth precision) or 24, got {depth_bits!r}")
        self.depth_bits = depth_bits
        self.p, self.client, self.K = p, client, K
        self.near, self.far = near, far
        self._P = np.array(projection_matrix(K, near, far)).reshape(4, 4).T
        self._P[1, :] *= -1.0  # draw upside down, so that the rows read back run from the top as PyBullet's do
        ctx = shared_context()
        self.ctx = ctx
        self._objects = []
        self._build_geometry()
        with _Current():  # current while in use: PyBullet's EGL plugin may hold another context in this process
            self._build_pipeline()

    # ---------------------------------------------------------------- building

    def _build_geometry(self) -> None:
        p, c = self.p, self.client
        parts: dict[tuple[int, int], int] = {}
        self.parts: list[_Part] = []
        pos_l, nrm_l, col_l, part_l, tri_l = [], [], [], [], []
        n_vert = 0
        bodies = [p.getBodyUniqueId(i, physicsClientId=c) for i in range(p.getNumBodies(physicsClientId=c))]
        self._multi_link: dict[int, list[int]] = {}  # body -> its links with shapes (for getLinkStates)
        for body in bodies:
            for shape in p.getVisualShapeData(body, physicsClientId=c):
                _, link, geom, dims, mesh_file, local_pos, local_orn, rgba = shape[:8]
                if rgba[3] <= 0.0:
                    continue  # invisible (any other alpha is drawn opaque: the scenes hold no transparency)
                try:
                    v, nv, t = shape_mesh(geom, tuple(dims))
                except GLUnsupportedScene as e:
                    name = p.getBodyInfo(body, physicsClientId=c)[1].decode("utf-8", "replace")
                    extra = f" ({mesh_file.decode('utf-8', 'replace')})" if mesh_file else ""
                    raise GLUnsupportedScene(f"body {body} ({name!r}) link {link} has {e}{extra}, which the gl "
                                             f"renderer does not draw; use renderer 'pybullet' or 'tiny'") from None
                key = (body, link)
                if key not in parts:
                    parts[key] = len(self.parts)
                    T_base_urdf = None
                    if link < 0:
                        # the base's pose is its centre of mass; the shapes are placed from its URDF frame
                        info = p.getDynamicsInfo(body, -1, physicsClientId=c)
                        T_base_urdf = np.linalg.inv(_matrix(info[3], info[4]))
                    else:
                        self._multi_link.setdefault(body, []).append(link)
                    self.parts.append(_Part(body, link, T_base_urdf))
                L = _matrix(local_pos, local_orn)
                pos_l.append(v @ L[:3, :3].T + L[:3, 3])
                nrm_l.append(nv @ L[:3, :3].T)
                col_l.append(np.tile(np.round(np.clip(rgba[:3], 0.0, 1.0) * 255.0), (len(v), 1)))
                part_l.append(np.full(len(v), parts[key]))
                tri_l.append(t + n_vert)
                n_vert += len(v)
        if not self.parts:
            raise GLUnsupportedScene("the client holds no visual shape to draw")
        self.n_triangles = int(sum(len(t) for t in tri_l))
        self.n_vertices = n_vert
        verts = np.zeros(n_vert, dtype=[("pos", "<f4", 3), ("normal", "<f4", 3), ("color", "u1", 4),
                                         ("part", "<i4")])
        verts["pos"] = np.concatenate(pos_l)
        verts["normal"] = np.concatenate(nrm_l)
        verts["color"][:, :3] = np.concatenate(col_l)
        verts["color"][:, 3] = 255
        verts["part"] = np.concatenate(part_l)
        self._verts = verts
        self._tris = np.concatenate(tri_l).astype("<i4")
        self._part_data = np.zeros((len(self.parts), 5, 4), dtype="<f4")
        self._part_data[:, 4, 3] = [pt.body for pt in self.parts]

    def _track(self, obj):
        self._objects.append(obj)
        return obj

    def _build_pipeline(self) -> None:
        ctx, K = self.ctx, self.K
        size = (K.width, K.height)
        self._vbo = self._track(ctx.buffer(self._verts.tobytes()))
        self._ibo = self._track(ctx.buffer(self._tris.tobytes()))
        self._tex = self._track(ctx.texture((5, len(self.parts)), 4, dtype="f4"))
        self._tex.filter = (ctx.NEAREST, ctx.NEAREST)
        self._color_rb = self._track(ctx.renderbuffer(size, 4))
        self._seg_rb = self._track(ctx.renderbuffer(size, 1, dtype="i4"))
        self._depth_rb = self._track(ctx.depth_renderbuffer(size))
        attachments = {"color_seg": [self._color_rb, self._seg_rb], "color": [self._color_rb],
                       "seg": [self._color_rb, self._seg_rb], "depth": []}
        # Clearing sets every attachment of a framebuffer to the same four numbers, read as floats: the
        # background colour and the body ids (stored as id + 1, 0 = nothing) are cleared each through its own.
        self._clear_color = self._track(ctx.framebuffer([self._color_rb], self._depth_rb))
        self._clear_seg = self._track(ctx.framebuffer([self._seg_rb]))
        self._passes = {}
        self._views_targets = {}  # views -> (their parts' texture, one depth framebuffer side by side): lazily
        for name, fs in _FRAGMENT_SHADERS.items():
            prog = self._track(ctx.program(vertex_shader=_VERTEX_SHADER, fragment_shader=fs))
            prog["parts"].value = 0
            if "ambient" in prog:
                prog["ambient"].value = AMBIENT
            names = [a for a in ("in_pos", "in_normal", "in_color", "in_part") if a in prog]
            fmt = " ".join(f if a in names else x for a, f, x in
                           (("in_pos", "3f", "12x"), ("in_normal", "3f", "12x"), ("in_color", "4f1", "4x"),
                            ("in_part", "1i", "4x")))
            vao = self._track(ctx.vertex_array(prog, [(self._vbo, fmt, *names)], index_buffer=self._ibo,
                                               index_element_size=4))
            fbo = self._track(ctx.framebuffer(attachments[name], self._depth_rb))
            self._passes[name] = (vao, fbo)

    def release(self) -> None:
        """Free this renderer's GL objects (the shared context stays)."""
        if not self._objects:
            return
        with _Current():
            for obj in reversed(self._objects):
                obj.release()
        self._objects = []
        self._passes = {}

    # ---------------------------------------------------------------- rendering

    def _part_poses(self) -> list[np.ndarray]:
        """World pose of each part's URDF link frame, from the client now."""
        p, c = self.p, self.client
        out: list[np.ndarray | None] = [None] * len(self.parts)
        links_state = {}
        for body, links in self._multi_link.items():
            states = p.getLinkStates(body, links, computeForwardKinematics=1, physicsClientId=c)
            for link, st in zip(links, states):
                links_state[(body, link)] = st
        base_pose = {}
        for i, pt in enumerate(self.parts):
            if pt.link < 0:
                if pt.body not in base_pose:
                    pos, quat = p.getBasePositionAndOrientation(pt.body, physicsClientId=c)
                    base_pose[pt.body] = _matrix(pos, quat)
                out[i] = base_pose[pt.body] @ pt.T_base_urdf
            else:
                st = links_state[(pt.body, pt.link)]
                out[i] = _matrix(st[4], st[5])  # the link's URDF frame, which visual frames are relative to
        return out

    def render(self, T_world_camera: np.ndarray, color: bool = True, segmentation: bool = False,
               light_direction=None) -> tuple[np.ndarray | None, np.ndarray, np.ndarray | None]:
        """(RGBA (H, W, 4) uint8 or None, depth buffer (H, W) float32 in [0, 1], body ids (H, W) int32 or
        None) seen from an optical-frame camera pose. color=False skips shading and reading colour back."""
        if not self._passes:
            raise RuntimeError("this GL renderer was released")
        PV = self._P @ np.array(view_matrix(T_world_camera)).reshape(4, 4).T
        light = np.asarray(DEFAULT_LIGHT if light_direction is None else light_direction, dtype=float)
        norm = float(np.linalg.norm(light))
        if not (math.isfinite(norm) and norm > 0.0):
            raise ValueError(f"light_direction: expected a non-zero finite 3-vector, got {light_direction!r}")
        light = light / norm
        data = self._part_data
        for i, T in enumerate(self._part_poses()):
            data[i, :4, :] = (PV @ T).T  # columns of the MVP
            data[i, 4, :3] = T[:3, :3].T @ light
        name = ("color_seg" if segmentation else "color") if color else ("seg" if segmentation else "depth")
        with _Current():
            return self._draw(data, name, color, segmentation)

    def render_depth_views(self, T_world_cameras) -> np.ndarray:
        """Depth buffers (V, H, W) float32 in [0, 1] seen from V optical-frame camera poses, the scene's poses
        read from the client once: what ``render(T, color=False)`` gives for each pose, at less cost. The views
        are drawn side by side into one framebuffer and read back at once; where the rasteriser rounds a view's
        offset differently, a few pixels differ from ``render``'s by a step of the depth buffer."""
        if not self._passes:
            raise RuntimeError("this GL renderer was released")
        V, H, W = len(T_world_cameras), self.K.height, self.K.width
        poses = self._part_poses()
        data = np.zeros((V, len(self.parts), 5, 4), dtype="<f4")  # view k's parts from row k * parts
        for k, T_world_camera in enumerate(T_world_cameras):
            PV = self._P @ np.array(view_matrix(T_world_camera)).reshape(4, 4).T
            for i, T in enumerate(poses):
                data[k, i, :4, :] = (PV @ T).T  # columns of the MVP, as ``render`` computes them
        zbuf = np.empty((H, V * W), dtype=np.float32)
        with _Current():
            # every view drawn into its own part of one framebuffer, then read back at once: one wait for the
            # rasteriser instead of one per view
            if V not in self._views_targets:
                tex = self._track(self.ctx.texture((5, V * len(self.parts)), 4, dtype="f4"))
                tex.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
                fbo = self._track(self.ctx.framebuffer([], self._track(self.ctx.depth_renderbuffer((V * W, H)))))
                self._views_targets[V] = (tex, fbo)
            tex, fbo = self._views_targets[V]
            tex.write(data.tobytes())
            vao, _ = self._passes["depth"]
            self._draw_state()
            fbo.use()
            fbo.viewport = (0, 0, V * W, H)
            fbo.clear(depth=1.0)
            tex.use(location=0)
            row0 = vao.program["row0"]
            for k in range(V):
                fbo.viewport = (k * W, 0, W, H)
                row0.value = k * len(self.parts)
                vao.render()
            row0.value = 0
            fbo.read_into(zbuf, components=1, attachment=-1, dtype="f4", viewport=(0, 0, V * W, H))
        self._to_depth_grid(zbuf)
        return np.ascontiguousarray(zbuf.reshape(H, V, W).transpose(1, 0, 2))

    def _draw_state(self) -> None:
        """Depth test on; back faces culled (counter-clockwise outward faces, drawn upside down)."""
        ctx = self.ctx
        ctx.enable_only(ctx.DEPTH_TEST | ctx.CULL_FACE)
        ctx.front_face = "cw"
        ctx.cull_face = "back"

    def _to_depth_grid(self, zbuf: np.ndarray) -> None:
        """With 16 depth bits, ``zbuf`` (read back as float32) rounded in place onto PyBullet's grid k / 65535."""
        if self.depth_bits == 16:
            zbuf *= np.float32(65535.0)
            np.rint(zbuf, out=zbuf)
            zbuf *= np.float32(1.0 / 65535.0)

    def _draw(self, data: np.ndarray, name: str, color: bool, segmentation: bool):
        self._tex.write(data.tobytes())
        vao, fbo = self._passes[name]
        K = self.K
        self._draw_state()
        if color:
            self._clear_color.clear(*BACKGROUND, 1.0, depth=1.0)
        else:
            fbo.clear(depth=1.0)
        if segmentation:
            self._clear_seg.clear(0.0, 0.0, 0.0, 0.0)
        fbo.use()
        self._tex.use(location=0)
        vao.render()
        H, W = K.height, K.width
        rgba = None
        if color:
            rgba = np.empty((H, W, 4), dtype=np.uint8)
            fbo.read_into(rgba, components=4, attachment=0)
        zbuf = np.empty((H, W), dtype=np.float32)
        fbo.read_into(zbuf, components=1, attachment=-1, dtype="f4")
        self._to_depth_grid(zbuf)
        seg = None
        if segmentation:
            seg = np.empty((H, W), dtype=np.int32)
            fbo.read_into(seg, components=1, attachment=1, dtype="i4")
            seg -= 1
        return rgba, zbuf, seg
