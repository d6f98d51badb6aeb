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


# name: (mesh, the shape's volume, the largest distance of a vertex outside the shape)
MESHES = {
    "box": (lambda: glr.box_mesh([0.3, 0.2, 0.5]), 8 * 0.3 * 0.2 * 0.5, 0.0),
    "sphere": (lambda: glr.sphere_mesh(0.11), 4 / 3 * math.pi * 0.11 ** 3, 0.0),
    "capsule": (lambda: glr.capsule_mesh(0.055, 0.3), math.pi * 0.055 ** 2 * 0.3 + 4 / 3 * math.pi * 0.055 ** 3,
                glr.PYBULLET_HULL_MARGIN),
    "cylinder": (lambda: glr.cylinder_mesh(0.25, 3.0), math.pi * 0.25 ** 2 * 3.0, glr.PYBULLET_HULL_MARGIN),
}


@pytest.mark.parametrize("name", MESHES)
def test_meshes_are_closed_outward_polyhedra_on_their_shapes(name):
    make, volume, outside = MESHES[name]
    v, n, t = make()
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    cross = np.cross(b - a, c - a)
    # Closed and counter-clockwise seen from outside: the divergence theorem gives the volume, positive. Round
    # shapes are drawn as PyBullet draws them, coarse polyhedra a little inside the shape (80 faces).
    mesh_volume = np.sum(np.einsum("ij,ij->i", a, cross)) / 6
    if name == "box":
        assert mesh_volume == pytest.approx(volume, rel=1e-12) and len(t) == 12
    else:
        assert 0.7 * volume <= mesh_volume <= volume and len(t) == 80
    # Every face looks away from the centre (all these shapes are convex and centred at the origin), and its
    # normal is the face's.
    assert np.all(np.einsum("ij,ij->i", cross, a + b + c) > 0)
    np.testing.assert_allclose(n[t[:, 0]], cross / np.linalg.norm(cross, axis=1, keepdims=True), atol=1e-9)
    if name == "sphere":
        np.testing.assert_allclose(np.linalg.norm(v, axis=1), 0.11, atol=1e-12)  # vertices on the surface
    if name == "capsule":  # within the margin of the capsule's surface
        d = np.linalg.norm(v - np.clip(v * [0, 0, 1], -0.15, 0.15), axis=1)  # distance to the axis segment
        assert np.all(d <= 0.055 + outside + 1e-12) and np.max(d) > 0.055


@pytest.mark.skipif("pybullet" not in RENDERERS, reason="PyBullet's EGL plugin not available")
def test_round_shapes_are_the_meshes_pybullet_draws():
    """A sphere, a capsule, a cylinder and the humanoid, close up: the same pixels and depth as PyBullet's
    EGL plugin draws (the facets included)."""
    import pybullet as p
    import pybullet_data

    from dodt.frames import CameraIntrinsics
    from sim.camera import linearize_depth, load_egl, quiet_stdout, render_buffers

    K = CameraIntrinsics()
    with quiet_stdout():
        c = p.connect(p.DIRECT)
    try:
        assert load_egl(p, c)
        shapes = [p.createVisualShape(p.GEOM_SPHERE, radius=0.1, physicsClientId=c),
                  p.createVisualShape(p.GEOM_CAPSULE, radius=0.045, length=0.18, physicsClientId=c),
                  p.createVisualShape(p.GEOM_CYLINDER, radius=0.25, length=1.0, physicsClientId=c)]
        for i, s in enumerate(shapes):
            p.createMultiBody(0, -1, s, basePosition=[0, 0.8 * i, 0],
                              baseOrientation=p.getQuaternionFromEuler([0.3 * i, 0.2, 0.1 * i]), physicsClientId=c)
        with quiet_stdout():
            p.loadURDF(f"{pybullet_data.getDataPath()}/humanoid/humanoid.urdf", [0, 3.0, -0.2], globalScaling=0.25,
                       useFixedBase=True, physicsClientId=c)
        g = glr.GLRenderer(p, c, K)
        for target in ([0, 0, 0], [0, 0.8, 0], [0, 1.6, 0], [0, 3.0, 0.2]):
            T = _look_at(np.array(target) + [0.6, -0.1, 0.2], target)
            _, zg, sg = g.render(T, segmentation=True)
            _, zb, sb = render_buffers(p, c, K, T, "pybullet", True)
            drawn, both = (sg >= 0) | (sb >= 0), (sg >= 0) & (sb >= 0)
            assert drawn.sum() > 5000
            assert np.mean((sg == sb)[drawn]) >= 0.999
            dz = np.abs(linearize_depth(zg) - linearize_depth(zb))[both]
            assert np.median(dz) < 1e-4 and np.percentile(dz, 99) < 2e-3
        g.release()
    finally:
        with quiet_stdout():
            p.disconnect(c)


def _people_worlds():
    sc = make_scenario(PEOPLE, PEOPLE_BASE)
    return World(sc, seed=0, renderer="gl", segmentation=True), World(sc, seed=0, renderer="pybullet",
                                                                       segmentation=True)


@pytest.mark.skipif("pybullet" not in RENDERERS, reason="PyBullet's EGL plugin not available")
def test_people_and_the_drone_render_where_pybullet_draws_them():
    """Seen from outside, the walking people (posed links) and the drone are where PyBullet's renderer
    draws them, drawn as the same meshes: the body ids agree on >= 99.9 % of the pixels (99.999 % measured),
    each body covers the same pixels, and depth agrees."""
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
            inter, union = np.sum((sg == body) & (sb == body)), np.sum((sg == body) | (sb == body))
            assert inter / union > 0.99
        assert np.mean(sg == sb) >= 0.999
        dg, db = linearize_depth(zg), linearize_depth(zb)
        same = (sg == sb) & (sg >= 0)
        assert np.median(np.abs(dg[same] - db[same])) < 0.001
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


def test_several_depth_views_at_once_are_the_views_one_by_one():
    w = World(make_scenario(PEOPLE, PEOPLE_BASE), seed=0, renderer="gl")
    poses = [_look_at(np.array([1.0, -1.8, 1.7]), [5.0, 0.0, 1.0]), _look_at(np.array([6.0, 1.5, 1.2]), [3.0, 0.0, 1.0])]
    views = w._gl.render_depth_views(poses)
    assert views.shape == (2, w.intrinsics.height, w.intrinsics.width)
    for T, view in zip(poses, views):
        # drawn side by side in one framebuffer: the rasteriser's rounding of a view's offset may move a
        # few pixels by a step of the depth buffer, no more
        one = w._gl.render(T, color=False)[1]
        np.testing.assert_allclose(view, one, rtol=0, atol=5e-5)
        assert np.mean(view == one) >= 0.99
    assert not np.array_equal(views[0], views[1])
    w.close()


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


def test_depth_lies_on_pybullets_16_bit_grid_and_24_bits_are_finer():
    w = World(make_scenario(NO_NOISE), seed=0, renderer="gl")
    T = w.ground_truth().T_world_camera
    _, z16, _ = w._gl.render(T)
    k = z16.astype(np.float64) * 65535
    np.testing.assert_allclose(k, np.rint(k), atol=1e-3)  # k / 65535, as PyBullet's EGL plugin gives
    fine = glr.GLRenderer(w._gl.p, w._client, w.intrinsics, depth_bits=24)
    _, z24, _ = fine.render(T)
    steps = np.diff(np.unique(z24[z24 < 1.0]))
    assert steps.min() < 1e-6 < 1.5e-5 < np.diff(np.unique(z16[z16 < 1.0])).min()
    assert np.max(np.abs(z24 - z16)) <= 0.5 / 65535 + 1e-7
    fine.release()
    with pytest.raises(ValueError, match="depth_bits"):
        glr.GLRenderer(w._gl.p, w._client, w.intrinsics, depth_bits=32)
    w.close()


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
