"""Physical constants of the quadrotor, read from its URDF (the one place they live)."""
from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

QUADROTOR_URDF = Path(__file__).resolve().parent / "assets" / "quadrotor.urdf"
GRAVITY = 9.81  # m/s^2


@dataclass(frozen=True)
class VehicleParams:
    mass: float  # kg
    inertia: np.ndarray  # (3,) principal moments [kg m^2]
    rotor_positions: np.ndarray  # (4, 3) in the body frame (FLU) [m]
    rotor_spin: np.ndarray  # (4,) sign of each rotor's reaction yaw moment on the body (+1: +z, the rotor turns clockwise seen from above)
    kf: float  # thrust coefficient [N / (rad/s)^2]
    km: float  # yaw-moment-to-thrust ratio [m]
    max_rotor_speed: float  # rad/s
    tau_up: float  # rotor speed time constant, spinning up [s]
    tau_down: float  # rotor speed time constant, spinning down [s]
    drag: np.ndarray  # (3,) linear drag in the body frame [N s / m]
    collision_size: np.ndarray  # (3,) collision box [m]
    prop_radius: float

    @property
    def max_rotor_thrust(self) -> float:
        return self.kf * self.max_rotor_speed**2

    @property
    def thrust_to_weight(self) -> float:
        return 4 * self.max_rotor_thrust / (self.mass * GRAVITY)

    @property
    def allocation(self) -> np.ndarray:
        """(4, 4) map from rotor thrusts to [collective thrust, Mx, My, Mz] (body frame)."""
        r = self.rotor_positions
        return np.vstack([np.ones(4), r[:, 1], -r[:, 0], self.km * self.rotor_spin])

    @property
    def corners(self) -> np.ndarray:
        """(8, 3) corners of the collision box in the body frame."""
        h = self.collision_size / 2
        return np.array([[sx * h[0], sy * h[1], sz * h[2]] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])

    @property
    def radius(self) -> float:
        """Radius of the sphere around the body centre that contains the collision box."""
        return float(np.linalg.norm(self.collision_size) / 2)


@lru_cache(maxsize=None)
def load_vehicle(urdf: str | Path = QUADROTOR_URDF) -> VehicleParams:
    root = ET.parse(urdf).getroot()
    p = root.find("properties")
    if p is None:
        raise ValueError(f"{urdf}: no <properties> element with the vehicle constants")
    a = {k: v for k, v in p.attrib.items()}
    rx, ry = float(a["rotor_x"]), float(a["rotor_y"])
    # X configuration: front-left and rear-right turn clockwise (reaction moment +z), the
    # other diagonal counter-clockwise.
    rotors = np.array([[rx, ry, 0.0], [-rx, -ry, 0.0], [rx, -ry, 0.0], [-rx, ry, 0.0]])
    return VehicleParams(
        mass=float(a["mass"]),
        inertia=np.array([float(a["ixx"]), float(a["iyy"]), float(a["izz"])]),
        rotor_positions=rotors,
        rotor_spin=np.array([1.0, 1.0, -1.0, -1.0]),
        kf=float(a["kf"]), km=float(a["km"]), max_rotor_speed=float(a["max_rotor_speed"]),
        tau_up=float(a["tau_up"]), tau_down=float(a["tau_down"]),
        drag=np.array([float(a["drag_xy"]), float(a["drag_xy"]), float(a["drag_z"])]),
        collision_size=np.array([float(x) for x in a["collision_size"].split()]),
        prop_radius=float(a["prop_radius"]),
    )
