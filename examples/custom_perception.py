"""A perception module of your own: DODT, reporting only the obstacles near the camera and in its view.

It implements dodt.protocol.PerceptionModule: ``reset(context)`` once per episode, with the episode's
dodt.context.EpisodeContext, and ``update(frame, truth=None) -> PerceptionOutput`` on every frame, with
``name`` and the ``uses_*`` flags. It reads the camera's model and range from the context; its own setting
is a dataclass (``config_class``), set from the command line as ``--set perception.max_distance=2.5``.
Try it:

    dodt-nav run corridor --perception examples/custom_perception.py:NearDODT --out runs/near
    dodt-nav sweep corridor --seeds 0:4 --perception examples/custom_perception.py:NearDODT \
        --set perception.max_distance=2.5 --out runs/near_sweep
"""
import math
from dataclasses import dataclass, field, replace

import numpy as np

from dodt.context import EpisodeContext
from experiments.perception_modes import DODTPerception


@dataclass(frozen=True)
class NearConfig:
    max_distance: float = field(default=3.0, metadata={"range": (0.2, 20.0)})  # m from the camera
    view_margin: float = field(default=0.1, metadata={"range": (0.0, 0.5)})  # rad narrower than the camera's view


class NearDODT:
    name = "dodt-near"
    uses_ground_truth = False  # update() gets truth=None
    uses_images = True  # it reads the depth image
    uses_color = False  # ... but not the colour
    config_class = NearConfig

    def __init__(self, cfg: NearConfig = NearConfig()):
        self.cfg = cfg
        self.dodt = DODTPerception("dodt")  # DODT with the closed loop's moving-track rule
        self.reach, self.half_view = cfg.max_distance, math.pi

    def reset(self, context: EpisodeContext) -> None:
        self.dodt.reset(context)  # DODT's moving-track rule reads the context's static map
        camera = context.camera  # the rig's forward camera: intrinsics, mount, rate, depth range
        self.reach = min(self.cfg.max_distance, camera.max_depth)
        self.half_view = max(camera.half_view - self.cfg.view_margin, 0.0)

    def update(self, frame, truth=None):
        out = self.dodt.update(frame)
        T = frame.T_world_camera
        camera, forward = T[:3, 3], T[:3, 2]
        heading = math.atan2(forward[1], forward[0])

        def near(o) -> bool:
            d = o.center[:2] - camera[:2]
            off = abs(math.remainder(math.atan2(d[1], d[0]) - heading, math.tau))
            return float(np.linalg.norm(d)) <= self.reach and off <= self.half_view

        return replace(out, obstacles=tuple(o for o in out.obstacles if near(o)))


if __name__ == "__main__":  # python examples/custom_perception.py: one short episode
    from experiments.episode import run_episode
    from experiments.episode_config import EpisodeConfig

    s = run_episode("corridor", seed=0, perception=NearDODT(), cfg=EpisodeConfig(duration=5.0))
    print(f"{s['perception']}: success {s['success']}, {s['failure_reason']}, {s['perception_stats']}")
