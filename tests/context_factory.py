"""An episode context for tests of modules that read one (the simulated drone's forward D435 camera)."""
import numpy as np

from dodt.context import CameraSensor, EpisodeContext, Rates, VehicleLimits
from dodt.frames import CameraIntrinsics

# the body (FLU) -> optical frame (x right, y down, z forward) rotation of a forward camera
R_FLU_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def example_context(width: float = 4.0, length: float = 15.0, intrinsics: CameraIntrinsics = CameraIntrinsics(),
                    static_map=None, seen=None) -> EpisodeContext:
    T = np.eye(4)
    T[:3, :3] = R_FLU_OPTICAL
    T[:3, 3] = (0.065, 0.01, 0.12)
    return EpisodeContext(
        scenario="test", seed=0, duration=30.0,
        vehicle=VehicleLimits.from_thrust(0.3, (0.4, 0.4, 0.15), 1.0, 2.0),
        sensors=(CameraSensor("front", intrinsics, T, rate=30.0, max_depth=10.0),),
        rates=Rates(control=120.0, plan=10.0, map=15.0), start=np.array([0.5, 0.0, 1.2]),
        goal=np.array([length + 0.5, 0.0, 1.2]),
        geofence=(np.array([0.0, -width / 2]), np.array([length, width / 2])), static_map=static_map, seen=seen)
