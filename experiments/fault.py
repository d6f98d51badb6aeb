"""Collisions classed by fault: nuPlan's rule (no_ego_at_fault_collisions) adapted to a drone.

A collision is judged from the states at the contact (sim.ground_truth.CollisionEvent), in order:
- ``structure``: the drone touched a wall, the floor or a static obstacle. Always at fault.
- ``drone_at_rest``: the drone's speed was at most AT_REST_SPEED (0.1 m/s; nuPlan's stopped ego is
  0.05 m/s, the CARLA leaderboard ignores collisions below 0.1 m/s). Not at fault: passive motion
  safety (Bouraine, Fraichard & Salhi 2012) asks only that the robot be at rest when hit.
- ``hit_from_behind``: the person came from more than BEHIND_ANGLE (120 deg; nuPlan's rear sector
  starts at 150 deg) off the drone's direction of motion, and the drone was not closing on them
  (its velocity's component toward the contact not positive). Not at fault: it was moving away.
- ``drone_at_fault``: every other contact with a person.
"Where the person came from" is the bearing, in the horizontal plane, of the contact point on the
person's body as seen from the drone's centre.
"""
from __future__ import annotations

import math

import numpy as np

AT_REST_SPEED = 0.1  # m/s
BEHIND_ANGLE = math.radians(120.0)
CLASSES = ("drone_at_rest", "hit_from_behind", "drone_at_fault", "structure")
AT_FAULT = frozenset({"drone_at_fault", "structure"})


def classify(kind: str, drone_position, drone_velocity, contact_point=None) -> str:
    """The fault class of one collision (see the module docstring). kind: person | static | structure."""
    if kind != "person":
        return "structure"
    v = np.asarray(drone_velocity, dtype=float)
    if not np.all(np.isfinite(v)):
        return "drone_at_fault"
    if float(np.linalg.norm(v)) <= AT_REST_SPEED:
        return "drone_at_rest"
    if contact_point is None:
        return "drone_at_fault"
    b = np.asarray(contact_point, dtype=float)[:2] - np.asarray(drone_position, dtype=float)[:2]
    vh = v[:2]
    nb, nv = float(np.linalg.norm(b)), float(np.linalg.norm(vh))
    if nb < 1e-9 or nv < 1e-9:  # touched at the centre, or moving straight up or down into someone
        return "drone_at_fault"
    closing = float(vh @ b) > 0.0
    off_motion = math.acos(max(-1.0, min(1.0, float(vh @ b) / (nb * nv))))
    return "hit_from_behind" if off_motion > BEHIND_ANGLE and not closing else "drone_at_fault"


def at_fault(cls: str) -> bool:
    return cls in AT_FAULT
