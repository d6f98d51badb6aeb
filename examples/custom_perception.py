"""A perception module of your own: DODT, reporting only the obstacles within 3 m of the camera.

It implements dodt.protocol.PerceptionModule (``reset()`` and
``update(frame, truth=None) -> PerceptionOutput``, with ``name`` and the ``uses_*`` flags) and is built
with no arguments. Try it:

    dodt-nav run corridor --perception examples/custom_perception.py:NearDODT --out runs/near
    dodt-nav sweep corridor --seeds 0:4 --perception examples/custom_perception.py:NearDODT --out runs/near_sweep
"""
from dataclasses import replace

import numpy as np

from experiments.perception_modes import DODTPerception


class NearDODT:
    name = "dodt-near"
    uses_ground_truth = False  # update() gets truth=None
    uses_images = True  # it reads the depth image
    uses_color = False  # ... but not the colour
    max_distance = 3.0  # m from the camera

    def __init__(self):
        self.dodt = DODTPerception("dodt")  # DODT with the closed loop's moving-track rule

    def reset(self) -> None:
        self.dodt.reset()

    def update(self, frame, truth=None):
        out = self.dodt.update(frame)
        camera = frame.T_world_camera[:3, 3]
        near = tuple(o for o in out.obstacles if np.linalg.norm(o.center - camera) <= self.max_distance)
        return replace(out, obstacles=near)


if __name__ == "__main__":  # python examples/custom_perception.py: one short episode
    from experiments.episode import EpisodeConfig, run_episode

    s = run_episode("corridor", seed=0, perception=NearDODT(), cfg=EpisodeConfig(duration=5.0))
    print(f"{s['perception']}: success {s['success']}, {s['failure_reason']}, {s['perception_stats']}")
