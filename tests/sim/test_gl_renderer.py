"""Our OpenGL renderer (sim.gl_renderer): its meshes, its agreement with PyBullet's renderer, determinism,
depth-only frames, and living beside PyBullet's EGL plugin in one process.

The known-box and back-projection tests of tests/sim/test_camera.py run on it too (RENDERERS)."""
import math

import numpy as np
import pytest

from conftest import BASE, RENDERERS, make_scenario
from sim import World
from sim import gl_renderer as glr

pytestmark = pytest.mark.skipif("gl" not in RENDERERS, reason="no OpenGL context through EGL here")

NO_NOISE = "[noise]\nenabled = false\n"

# Two people walking across in front of a drone that hovers at (3, 0, 1.2); an outside camera sees all three.
PEOPLE = NO_NOISE + """
[[people]]
behaviour = "crossing"
speed = 1.0
waypoints = [[4.5, 1.5], [4.5, -1.5]]
[[people]]
behaviour = "crossing"
speed = 0.8
waypoints = [[6.0, -1.5], [6.0, 1.5]]
start_delay = 0.5
"""
PEOPLE_BASE = BASE.replace("start = [1.0, 0.0, 1.2]", "start = [3.0, 0.0, 1.2]")


def _look_at(eye, target) -> np.ndarray:
    """Optical-frame camera pose at ``eye`` looking at ``target`` (image rows downwards)."""
    z = np.asarray(target, float) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, np.cross(z, x), z, eye
    return T


# name: (mesh, its shape's volume, its smallest radius of curvature (None: flat faces only))
MESHES = {
    "box": (lambda: glr.box_mesh([0.3, 0.2, 0.5]), 8 * 0.3 * 0.2 * 0.5, None),
    "sphere": (lambda: glr.sphere_mesh(0.11), 4 / 3 * math.pi * 0.11 ** 3, 0.11),
    "small sphere": (lambda: glr.sphere_mesh(0.04), 4 / 3 * math.pi * 0.04 ** 3, 0.04),
    "capsule": (lambda: glr.capsule_mesh(0.055, 0.3), math.pi * 0.055 ** 2 * 0.3 + 4 / 3 * math.pi * 0.055 ** 3,
                0.055),
    "cylinder": (lambda: glr.cylinder_mesh(0.25, 3.0), math.pi * 0.25 ** 2 * 3.0, 0.25),
}


@pytest.mark.parametrize("name", MESHES)
def test_meshes_are_closed_outward_and_within_the_chord_tolerance(name):
    make, volume, r_min = MESHES[name]
    v, n, t = make()
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    cross = np.cross(b - a, c - a)
    # Closed and counter-clockwise seen from outside: the divergence theorem gives the volume, positive; an
    # inscribed tessellation holds a little less than the shape (its faces lie at most about two chord
    # tolerances inside a round surface: one along each direction of the grid).
    mesh_volume = np.sum(np.einsum("ij,ij->i", a, cross)) / 6
    if r_min is None:
        assert mesh_volume == pytest.approx(volume, rel=1e-12)
    else:
        assert volume * (1 - 2 * glr.CHORD_TOLERANCE / r_min) ** 3 <= mesh_volume <= volume
    # Every face looks away from the centre (all these shapes are convex and centred at the origin).
    big = np.linalg.norm(cross, axis=1) > 1e-12
    assert np.all(np.einsum("ij,ij->i", cross[big], (a + b + c)[big]) > 0)
    # Unit normals pointing outwards.
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-9)
    if name in ("sphere", "small sphere"):
        r = 0.11 if name == "sphere" else 0.04
        np.testing.assert_allclose(np.linalg.norm(v, axis=1), r, atol=1e-12)  # vertices on the surface
        gaps = np.concatenate([r - np.linalg.norm((p + q) / 2, axis=1) for p, q in ((a, b), (b, c), (c, a))])
        # the grid's edges within the tolerance, the diagonals of its cells within twice that
        assert np.max(gaps) <= 2 * glr.CHORD_TOLERANCE
        assert np.mean(gaps <= glr.CHORD_TOLERANCE + 1e-12) >= 2 / 3


def test_segments_keep_the_chord_within_tolerance():
    for r in (0.02, 0.055, 0.11, 0.25, 1.0):
        n = glr.segments_for(r)
        assert glr.MIN_SEGMENTS <= n <= glr.MAX_SEGMENTS
        if glr.MIN_SEGMENTS < n < glr.MAX_SEGMENTS:
            assert r * (1 - math.cos(math.pi / n)) <= glr.CHORD_TOLERANCE


def _people_worlds():
    sc = make_scenario(PEOPLE, PEOPLE_BASE)
    return World(sc, seed=0, renderer="gl", segmentation=True), World(sc, seed=0, renderer="pybullet",
                                                                       segmentation=True)


@pytest.mark.skipif("pybullet" not in RENDERERS, reason="PyBullet's EGL plugin not available")
def test_people_and_the_drone_render_where_pybullet_draws_them():
    """Seen from outside, the walking people (posed links) and the drone are where PyBullet's renderer
    draws them: the body ids agree on >= 99 % of the pixels, and on the bodies' own pixels depth agrees."""
    import pybullet as p

    from sim.camera import linearize_depth, render_buffers

    g, b = _people_worlds()
    try:
        for _ in range(3):  # 1.5 s: both people are walking
            for w in (g, b):
                w.advance(0.5)
        T = _look_at(np.array([1.0, -1.8, 1.7]), [5.0, 0.0, 1.0])
        _, zg, sg = g._gl.render(T, segmentation=True)
        _, zb, sb = render_buffers(p, b._client, b.intrinsics, T, "pybullet", True)
        people = [w.bodies[0][1] for w in g.walkers]
        assert people == [w.bodies[0][1] for w in b.walkers] and g.drone == b.drone
        for body in people + [g.drone]:
            assert np.sum(sb == body) > 150, f"body {body} is not in view"
            # each body's own pixels: the same pixels within its silhouette (tessellations differ at the rim)
            inter, union = np.sum((sg == body) & (sb == body)), np.sum((sg == body) | (sb == body))
            assert inter / union > 0.85
        assert np.mean(sg == sb) >= 0.99
        dg, db = linearize_depth(zg), linearize_depth(zb)
        same = (sg == sb) & (sg >= 0)
        assert np.median(np.abs(dg[same] - db[same])) < 0.002
    finally:
        g.close()
        b.close()


def test_rendering_is_deterministic_and_a_new_world_in_the_process_renders_the_same():
    sc = make_scenario(PEOPLE, PEOPLE_BASE)
    w = World(sc, seed=0, renderer="gl", segmentation=True)
    T = _look_at(np.array([1.0, -1.8, 1.7]), [5.0, 0.0, 1.0])
    first = w._gl.render(T, segmentation=True)
    ctx = glr.shared_context()
    for _ in range(3):
        again = w._gl.render(T, segmentation=True)
        for x, y in zip(first, again):
            np.testing.assert_array_equal(x, y)
    w.close()
    w2 = World(sc, seed=0, renderer="gl", segmentation=True)  # a sweep worker's next episode
    assert glr.shared_context() is ctx  # the context outlives the world that used it
    renderer = w2._gl
    for x, y in zip(first, renderer.render(T, segmentation=True)):
        np.testing.assert_array_equal(x, y)
    w2.close()
    with pytest.raises(RuntimeError, match="released"):
        renderer.render(T)


def test_depth_only_frames_have_the_same_depth():
    sc = make_scenario(PEOPLE.replace(NO_NOISE, ""), PEOPLE_BASE)  # with depth noise
    a = World(sc, seed=2, renderer="gl", segmentation=True)
    b = World(sc, seed=2, renderer="gl", segmentation=True, color=False)
    for _ in range(12):  # three frames
        fa, fb = a.step(), b.step()
        if fa is not None:
            assert fb.color is None and fa.color is not None
            np.testing.assert_array_equal(fa.depth, fb.depth)
            np.testing.assert_array_equal(a.ground_truth().segmentation, b.ground_truth().segmentation)
    a.close()
    b.close()


def test_a_shape_it_cannot_draw_is_a_clear_error():
    import pybullet as p
    import pybullet_data

    from dodt.frames import CameraIntrinsics

    c = p.connect(p.DIRECT)
    try:
        vis = p.createVisualShape(p.GEOM_MESH, fileName=f"{pybullet_data.getDataPath()}/cube.obj", physicsClientId=c)
        p.createMultiBody(0, -1, vis, physicsClientId=c)
        with pytest.raises(glr.GLUnsupportedScene, match=r"body 0 .* link -1 has a mesh shape .*cube\.obj.*'pybullet'"):
            glr.GLRenderer(p, c, CameraIntrinsics())
    finally:
        p.disconnect(c)


def test_a_bad_light_direction_is_a_clear_error():
    w = World(make_scenario(NO_NOISE), seed=0, renderer="gl")
    with pytest.raises(ValueError, match="light_direction"):
        w._gl.render(np.eye(4), light_direction=(0.0, 0.0, 0.0))
    w.close()


def test_the_light_direction_shades_faces():
    """A face turned to the light is brighter than one turned away; the default light is used without one."""
    w = World(make_scenario(NO_NOISE), seed=0, renderer="gl")
    T = w.ground_truth().T_world_camera  # looking along +x at the end wall (normal -x)
    end_wall = (200, 320)
    lit, _, _ = w._gl.render(T, light_direction=(-1.0, 0.0, 0.0))
    dark, _, _ = w._gl.render(T, light_direction=(1.0, 0.0, 0.0))
    assert lit[end_wall][:3].astype(int).sum() > dark[end_wall][:3].astype(int).sum() + 60
    default, _, _ = w._gl.render(T)
    np.testing.assert_array_equal(default, w._gl.render(T, light_direction=glr.DEFAULT_LIGHT)[0])
    w.close()
