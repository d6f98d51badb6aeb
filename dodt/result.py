"""What perception returns for each frame."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True, eq=False)
class TrackedObstacle:
    id: int
    center: np.ndarray  # (3,) world [m]; x, y filtered, z from the latest detection
    size: np.ndarray  # (3,) [m]
    # (3,) [m/s], z = 0: the filter's velocity (at most track.max_speed), whatever the label
    velocity: np.ndarray
    acceleration: np.ndarray  # (3,) [m/s^2], z = 0: the filter's acceleration, whatever the label
    dynamic: bool
    coasting: bool  # no detection this frame: the state is the Kalman prediction
    age: float  # s since the track was born
    history: np.ndarray  # (K, 4) recent [t, x, y, z] centres, oldest first
    is_person: bool = False
    position_std: float = 0.0  # m, predicted horizontal position uncertainty
    # (3,) [m/s] and [m/s^2], z = 0: the tracking filter's velocity and acceleration whatever the
    # label (DODT reports them as ``velocity`` and ``acceleration`` too; another module may report a
    # static track still); None: as ``velocity``, ``acceleration``
    filter_velocity: np.ndarray | None = None
    filter_acceleration: np.ndarray | None = None
    # what labelled it dynamic: "voting" (speed and point voting, paper Sec. III-D), "person" (the learned
    # detector's label), "motion" (neither: a tall box tracked at walking speed, dodt.motion_label);
    # "" when static
    evidence: str = ""
    # the sensor of its latest detection: "" the first camera, another camera's name, "lidar"
    sensor: str = ""


@dataclass(frozen=True, eq=False)
class PerceptionResult:
    stamp: float
    seq: int
    obstacles: tuple[TrackedObstacle, ...]
    timings_ms: dict[str, float]  # per module, wall time of this frame
    detections: dict[str, list] = field(default_factory=dict)  # per detector: list of (center, size)
    skipped: str | None = None  # why this frame was not processed, if it was not
    bad_pixels: int = 0  # NaN, inf or negative depth pixels in this frame (treated as invalid)

    @property
    def dynamic(self) -> tuple[TrackedObstacle, ...]:
        return tuple(o for o in self.obstacles if o.dynamic)
