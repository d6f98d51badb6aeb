"""What every detector returns: an axis-aligned world box, with the obstacle's points."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from dodt.view_edge import ViewSides


@dataclass(eq=False)
class Detection:
    center: np.ndarray  # (3,) world [m]
    size: np.ndarray  # (3,) [m]
    source: str  # udepth | dbscan | ensemble | learned
    points: np.ndarray = field(default_factory=lambda: np.empty((0, 3), np.float32))  # (M, 3) world
    is_person: bool = False  # set by a learned detector that recognises people
    cut: bool = False  # its box crosses the image's left or right edge (set by the pipeline)
    sides: "ViewSides | None" = None  # its sides and the image edges that cut it (dodt.view_edge; the pipeline)
    sensor: str = ""  # the rig's sensor that found it ("": the first camera, whose frames DODT.process takes)

    @property
    def lower(self) -> np.ndarray:
        return self.center - self.size / 2

    @property
    def upper(self) -> np.ndarray:
        return self.center + self.size / 2

    @staticmethod
    def from_bounds(lo, hi, source: str, points=None) -> "Detection":
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        pts = np.empty((0, 3), np.float32) if points is None else points
        return Detection(center=(lo + hi) / 2, size=hi - lo, source=source, points=pts)
