"""The bodies of a world: corridor, static obstacles, people and the drone, built in PyBullet clients.

The main client holds what is stepped and rendered: the static bodies, the drone, and the people as
massless, non-colliding bodies posed kinematically. The query client (never stepped) holds collidable
copies of the people and of the drone for distance and contact queries (sim.contacts).

Colours and people's routes and heights are drawn from the generators passed in, in a fixed order
(corridor, obstacles in scenario order, then each person's route, height and colours): the same seed
gives the same scene.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.camera import quiet_stdout

with quiet_stdout():  # PyBullet prints its build time on import
    import pybullet as p

from sim.ground_truth import STRUCTURE_ID, ObstacleTruth, person_id
from sim.people import HUMANOID_URDF, Walker, person_height, walk_paths
from sim.scenario import Scenario
from sim.scenario_parts import Obstacle
from sim.vehicle import QUADROTOR_URDF

GROUP_DRONE, GROUP_STATIC = 1, 4  # collision filter groups: the drone collides with static bodies only
WALL_THICKNESS = 0.1  # m, of the floor, walls and ceiling


@dataclass
class StaticBody:
    uid: int
    obstacle_id: int  # STRUCTURE_ID for floor/walls/ceiling
    aabb_min: np.ndarray
    aabb_max: np.ndarray


@dataclass
class Scene:
    """What ``build_scene`` made: body ids in the main client (``client``) and the query client."""

    client: int
    query_client: int
    static_bodies: list[StaticBody]
    walkers: list[Walker]  # each with its bodies: (client, uid) in the main client, then the query client
    person_ids: list[int]  # obstacle id of each walker
    drone: int  # the flying body, main client
    drone_proxy: int  # its fixed copy in the query client

    @property
    def obstacles(self) -> list[StaticBody]:
        """The static bodies that are obstacles (not the corridor's structure)."""
        return [b for b in self.static_bodies if b.obstacle_id != STRUCTURE_ID]

    def segmentation_lut(self) -> np.ndarray:
        """PyBullet body uid + 1 -> obstacle id (-1: none), for the renderer's segmentation buffer."""
        n = max([b.uid for b in self.static_bodies] + [c for w in self.walkers for _, c in w.bodies[:1]]
                + [self.drone]) + 2
        lut = np.full(n, -1, dtype=np.int32)
        for b in self.static_bodies:
            lut[b.uid + 1] = b.obstacle_id
        for w, oid in zip(self.walkers, self.person_ids):
            lut[w.bodies[0][1] + 1] = oid
        return lut

    def obstacle_truth(self, scenario: Scenario, person_velocities) -> tuple[ObstacleTruth, ...]:
        """Every obstacle's truth: static ones, and the people as posed now (their boxes from the query
        client's collidable copies), person i moving at ``person_velocities(i)``."""
        out = []
        labels = {i + 1: o.kind for i, o in enumerate(scenario.obstacles)}
        for b in self.static_bodies:
            if b.obstacle_id != STRUCTURE_ID:
                out.append(ObstacleTruth(b.obstacle_id, "static", labels[b.obstacle_id], b.aabb_min.copy(),
                                         b.aabb_max.copy(), np.zeros(3)))
        for i, (w, oid) in enumerate(zip(self.walkers, self.person_ids)):
            cid, body = w.bodies[1]
            lo, hi = np.array(p.getAABB(body, -1, physicsClientId=cid))
            for link in range(p.getNumJoints(body, physicsClientId=cid)):
                a, b = p.getAABB(body, link, physicsClientId=cid)
                lo, hi = np.minimum(lo, a), np.maximum(hi, b)
            lo[2] = max(lo[2], 0.0)
            out.append(ObstacleTruth(oid, "person", "person", lo, hi, person_velocities(i)))
        return tuple(out)


def build_scene(scenario: Scenario, client: int, query_client: int, rng_paths: np.random.Generator,
                rng_looks: np.random.Generator) -> Scene:
    """Build the scenario's bodies; people's routes from ``rng_paths``, colours and heights from ``rng_looks``."""
    sc = scenario
    static: list[StaticBody] = []
    _build_corridor(sc, client, static, rng_looks)
    for i, o in enumerate(sc.obstacles):
        _build_obstacle(o, i + 1, client, static, rng_looks)
    walkers, person_ids = [], []
    for i, (person, path) in enumerate(zip(sc.people, walk_paths(sc, rng_paths))):
        w = Walker(path, person_height(person, rng_looks))
        _build_person(w, person, client, query_client, rng_looks)
        walkers.append(w)
        person_ids.append(person_id(len(sc.obstacles), i))
    drone, proxy = _build_drone(sc, client, query_client)
    return Scene(client, query_client, static, walkers, person_ids, drone, proxy)


def _add_static(client: int, static: list[StaticBody], shapes, obstacle_id: int, color, base_pos,
                base_yaw: float = 0.0) -> None:
    """shapes: list of (geom, dims, local offset) -> one static body in the main client."""
    c = client
    geoms, dims_he, dims_r, dims_l, offsets = [], [], [], [], []
    for geom, dims, off in shapes:
        geoms.append(geom)
        offsets.append(off)
        if geom == p.GEOM_BOX:
            dims_he.append(dims)
            dims_r.append(0.0)
            dims_l.append(0.0)
        else:
            dims_he.append([0, 0, 0])
            dims_r.append(dims[0])
            dims_l.append(dims[1])
    kw = dict(shapeTypes=geoms, halfExtents=dims_he, radii=dims_r, lengths=dims_l,
              collisionFramePositions=offsets, physicsClientId=c) if len(shapes) > 1 else None
    if kw:
        col = p.createCollisionShapeArray(**kw)
        vkw = dict(kw)
        vkw["visualFramePositions"] = vkw.pop("collisionFramePositions")
        vis = p.createVisualShapeArray(rgbaColors=[list(color) + [1.0]] * len(shapes), **vkw)
    else:
        geom, dims, off = shapes[0]
        if geom == p.GEOM_BOX:
            col = p.createCollisionShape(geom, halfExtents=dims, collisionFramePosition=off, physicsClientId=c)
            vis = p.createVisualShape(geom, halfExtents=dims, visualFramePosition=off,
                                      rgbaColor=list(color) + [1.0], physicsClientId=c)
        else:
            col = p.createCollisionShape(geom, radius=dims[0], height=dims[1], collisionFramePosition=off,
                                         physicsClientId=c)
            vis = p.createVisualShape(geom, radius=dims[0], length=dims[1], visualFramePosition=off,
                                      rgbaColor=list(color) + [1.0], physicsClientId=c)
    uid = p.createMultiBody(0, col, vis, basePosition=base_pos,
                            baseOrientation=p.getQuaternionFromEuler([0, 0, base_yaw]), physicsClientId=c)
    p.setCollisionFilterGroupMask(uid, -1, GROUP_STATIC, GROUP_DRONE, physicsClientId=c)
    lo, hi = p.getAABB(uid, physicsClientId=c)
    static.append(StaticBody(uid, obstacle_id, np.array(lo), np.array(hi)))


def _build_corridor(sc: Scenario, client: int, static: list[StaticBody], rng) -> None:
    co = sc.corridor
    L, W, H, t = co.length, co.width, co.height, WALL_THICKNESS
    floor = (0.55, 0.55, 0.55) if co.floor_color is None else tuple(co.floor_color)
    wall = tuple(np.clip(np.array([0.85, 0.82, 0.75]) + rng.uniform(-0.05, 0.05, 3), 0, 1))  # always drawn
    if co.wall_color is not None:
        wall = tuple(co.wall_color)
    box = p.GEOM_BOX
    _add_static(client, static, [(box, [L / 2 + t, W / 2 + t, t / 2], [0, 0, 0])], STRUCTURE_ID, floor,
                [L / 2, 0, -t / 2])
    for side in (-1, 1):
        _add_static(client, static, [(box, [L / 2 + t, t / 2, H / 2], [0, 0, 0])], STRUCTURE_ID, wall,
                    [L / 2, side * (W / 2 + t / 2), H / 2])
    for x in (-t / 2, L + t / 2):
        _add_static(client, static, [(box, [t / 2, W / 2, H / 2], [0, 0, 0])], STRUCTURE_ID, wall, [x, 0, H / 2])
    if co.ceiling:
        _add_static(client, static, [(box, [L / 2 + t, W / 2 + t, t / 2], [0, 0, 0])], STRUCTURE_ID, floor,
                    [L / 2, 0, H + t / 2])


def _build_obstacle(o: Obstacle, oid: int, client: int, static: list[StaticBody], rng) -> None:
    color = o.color if o.color is not None else tuple(rng.uniform(0.15, 0.9, 3))
    sx, sy, sz = o.size
    base = [o.center[0], o.center[1], 0.0]
    if o.kind == "pillar":
        shapes = [(p.GEOM_CYLINDER, [sx / 2, sz], [0, 0, sz / 2])]
    elif o.kind == "shelf":
        post, board = 0.03, 0.025
        shapes = [(p.GEOM_BOX, [post, post, sz / 2], [dx * (sx / 2 - post), dy * (sy / 2 - post), sz / 2])
                  for dx in (-1, 1) for dy in (-1, 1)]
        for k in range(4):
            z = board + k * (sz - 2 * board) / 3
            shapes.append((p.GEOM_BOX, [sx / 2, sy / 2, board], [0, 0, z]))
    else:  # box, wall
        shapes = [(p.GEOM_BOX, [sx / 2, sy / 2, sz / 2], [0, 0, sz / 2])]
    _add_static(client, static, shapes, oid, color, base, o.yaw)


def _build_person(w: Walker, person, client: int, query_client: int, rng) -> None:
    """The person's humanoid in both clients: coloured and inert in the main one, collidable in the query one."""
    shirt = person.color if person.color is not None else tuple(rng.uniform(0.05, 0.95, 3))
    trousers = tuple(rng.uniform(0.05, 0.6, 3))
    skin = tuple(np.array([0.93, 0.75, 0.6]) * rng.uniform(0.45, 1.0))
    part_color = {0: trousers, 1: shirt, 2: skin, 3: shirt, 4: shirt, 5: skin, 6: shirt, 7: shirt, 8: skin,
                  9: trousers, 10: trousers, 11: (0.1, 0.1, 0.1), 12: trousers, 13: trousers, 14: (0.1, 0.1, 0.1)}
    for cid in (client, query_client):
        with quiet_stdout():
            body = p.loadURDF(HUMANOID_URDF, [0, 0, 0], globalScaling=w.global_scaling, useFixedBase=True,
                              physicsClientId=cid)
        n = p.getNumJoints(body, physicsClientId=cid)
        if cid == client:
            for link in range(-1, n):
                p.setCollisionFilterGroupMask(body, link, 0, 0, physicsClientId=cid)
                p.changeDynamics(body, link, mass=0.0, physicsClientId=cid)
                p.changeVisualShape(body, link, rgbaColor=list(part_color.get(link, shirt)) + [1.0],
                                    physicsClientId=cid)
        w.bodies.append((cid, body))


def _build_drone(sc: Scenario, client: int, query_client: int) -> tuple[int, int]:
    quat = p.getQuaternionFromEuler([0, 0, sc.drone.yaw])
    drone = p.loadURDF(str(QUADROTOR_URDF), sc.drone.start, quat, flags=p.URDF_USE_INERTIA_FROM_FILE,
                       physicsClientId=client)
    p.changeDynamics(drone, -1, linearDamping=0.0, angularDamping=0.0, physicsClientId=client)
    p.setCollisionFilterGroupMask(drone, -1, GROUP_DRONE, GROUP_STATIC, physicsClientId=client)
    proxy = p.loadURDF(str(QUADROTOR_URDF), sc.drone.start, quat, useFixedBase=True, physicsClientId=query_client)
    return drone, proxy

