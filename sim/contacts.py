"""The drone's contacts and clearances: collision events, and its distance to structure, obstacles and people.

Contacts with the static world come from the main client's physics contacts; contacts with people, and
the distance to them, from the query client, where collidable copies of the people and of the drone
live (sim.scene). Clearances are exact below ``CLEARANCE_CAP`` and reported as the cap above it.
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np

from sim.camera import quiet_stdout

with quiet_stdout():  # PyBullet prints its build time on import
    import pybullet as p

from sim.crowd import Crowd
from sim.ground_truth import STRUCTURE_ID, CollisionEvent
from sim.scenario import Scenario
from sim.scene import Scene
from sim.vehicle import VehicleParams

CLEARANCE_CAP = 1.0  # m: clearances are exact below this, reported as this value above
CLEARANCE_LOG_LEN = 4096  # control periods of clearance history kept (34 s at 120 Hz)
PERSON_REACH = 0.6  # bounding-sphere radius of a person around the root, per metre of height
PERSON_CONTACT_RANGE = 0.3  # m: people are checked for contact while the nearest is closer than this


class ContactMonitor:
    """Collision events and clearances of one world's drone, from the state its clients hold now."""

    def __init__(self, scene: Scene, scenario: Scenario, vehicle: VehicleParams, crowd: Crowd,
                 seg_lut: np.ndarray):
        self.scene, self.scenario, self.vehicle, self.crowd = scene, scenario, vehicle, crowd
        self._seg_lut = seg_lut  # body uid + 1 -> obstacle id
        self.collisions: list[CollisionEvent] = []
        self._in_contact: set[int] = set()
        self.min_clearance = {"static": CLEARANCE_CAP, "person": CLEARANCE_CAP, "structure": CLEARANCE_CAP}
        # t, static, person, structure of the last CLEARANCE_LOG_LEN control periods (bounded: an episode of an
        # hour keeps its whole history in its log file, not in memory)
        self.clearance_log: deque[tuple[float, float, float, float]] = deque(maxlen=CLEARANCE_LOG_LEN)
        self._corners = vehicle.corners
        obstacles = scene.obstacles
        self._obstacle_uids = [b.uid for b in obstacles]
        self._obstacle_lo = np.array([b.aabb_min for b in obstacles]).reshape(-1, 3)
        self._obstacle_hi = np.array([b.aabb_max for b in obstacles]).reshape(-1, 3)
        self._person_clearance = CLEARANCE_CAP

    def _drone_pose(self):
        return p.getBasePositionAndOrientation(self.scene.drone, physicsClientId=self.scene.client)

    def check_contacts(self, t: float) -> None:
        """Record the contacts begun since the last check as collision events at time ``t``. Static world from
        the physics contacts, people from the query client whenever the drone is close to one. Each event keeps
        the drone's velocity, the point of the other body nearest the drone and that body's velocity
        (experiments.fault)."""
        sc = self.scene
        points: dict[int, tuple] = {}
        for cp_ in p.getContactPoints(bodyA=sc.drone, physicsClientId=sc.client):
            points.setdefault(cp_[2], cp_[6])  # positionOnB
        if self._person_clearance < PERSON_CONTACT_RANGE:
            pos, quat = self._drone_pose()
            p.resetBasePositionAndOrientation(sc.drone_proxy, pos, quat, physicsClientId=sc.query_client)
            for w, oid in zip(sc.walkers, sc.person_ids):
                hits = p.getClosestPoints(sc.drone_proxy, w.bodies[1][1], 0.0, physicsClientId=sc.query_client)
                if hits:
                    points[-oid] = min(hits, key=lambda h: h[8])[6]  # negative: person ids, apart from uids
        touching = set(points)
        new = touching - self._in_contact
        if new:
            pos = tuple(self._drone_pose()[0])
            lin, _ = p.getBaseVelocity(sc.drone, physicsClientId=sc.client)
            for uid in sorted(new):
                other_v = (0.0, 0.0, 0.0)
                if uid < 0:
                    oid, kind = -uid, "person"
                    other_v = tuple(self.crowd.velocity3(sc.person_ids.index(oid)))
                else:
                    oid = int(self._seg_lut[uid + 1]) if uid + 1 < len(self._seg_lut) else STRUCTURE_ID
                    kind = "structure" if oid == STRUCTURE_ID else "static"
                self.collisions.append(CollisionEvent(t, oid, kind, pos, tuple(lin), tuple(points[uid]), other_v))
        self._in_contact = touching

    def update_clearance(self, t: float) -> None:
        """Distance from the drone's collision box to the structure (exact, box against the corridor's planes),
        to static obstacles and to people (PyBullet closest points, exact below CLEARANCE_CAP), logged at ``t``."""
        sc = self.scene
        c, q = sc.client, sc.query_client
        pos, quat = self._drone_pose()
        pos_a = np.array(pos)
        R = np.array(p.getMatrixFromQuaternion(quat)).reshape(3, 3)
        corners = self._corners @ R.T + pos_a
        co = self.scenario.corridor
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        gaps = [lo[2], co.width / 2 - hi[1], co.width / 2 + lo[1], lo[0], co.length - hi[0]]
        if co.ceiling:
            gaps.append(co.height - hi[2])
        clear = {"structure": min(max(min(gaps), 0.0), CLEARANCE_CAP), "static": CLEARANCE_CAP,
                 "person": CLEARANCE_CAP}
        if self._obstacle_uids:
            gap = np.linalg.norm(np.maximum(0.0, np.maximum(self._obstacle_lo - hi, lo - self._obstacle_hi)), axis=1)
            for k in np.flatnonzero(gap < CLEARANCE_CAP):
                pts = p.getClosestPoints(sc.drone, self._obstacle_uids[k], CLEARANCE_CAP, physicsClientId=c)
                if pts:
                    clear["static"] = min(clear["static"], max(min(x[8] for x in pts), 0.0))
        proxy_posed = False
        reach = self.vehicle.radius + CLEARANCE_CAP
        for i, w in enumerate(sc.walkers):
            root = self.crowd.pos[i]
            if math.hypot(root[0] - pos[0], root[1] - pos[1]) - PERSON_REACH * w.height > reach:
                continue
            if not proxy_posed:
                p.resetBasePositionAndOrientation(sc.drone_proxy, pos, quat, physicsClientId=q)
                proxy_posed = True
            pts = p.getClosestPoints(sc.drone_proxy, w.bodies[1][1], CLEARANCE_CAP, physicsClientId=q)
            if pts:
                clear["person"] = min(clear["person"], max(min(x[8] for x in pts), 0.0))
        self._person_clearance = clear["person"]
        for k, d in clear.items():
            self.min_clearance[k] = min(self.min_clearance[k], d)
        self.clearance_log.append((t, clear["static"], clear["person"], clear["structure"]))
