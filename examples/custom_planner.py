"""A planner of your own: fly straight at the goal, brake when something is close ahead.

It implements planner.types.Planner: ``reset(context)`` once per episode, with the episode's
dodt.context.EpisodeContext, and ``plan(PlannerInput) -> Trajectory`` at the planning rate. From the
context it reads the vehicle's radius, the forward camera's field of view and the static map (a live,
read-only view); its own settings are a dataclass (``config_class``), set from the command line as
``--set planner.<field>=value``. Try it:

    dodt-nav run corridor --planner examples/custom_planner.py:StraightLine --perception oracle --map truth --out runs/straight
    dodt-nav run corridor --planner examples/custom_planner.py:StraightLine --set planner.cruise_speed=0.6 --shield --out runs/s
    dodt-nav sweep corridor --seeds 0:4 --planner examples/custom_planner.py:StraightLine --out runs/straight_sweep
"""
import math
from dataclasses import dataclass, field

import numpy as np

from dodt.context import EpisodeContext
from planner.types import PlannerInput, Trajectory


@dataclass(frozen=True)
class StraightLineConfig:
    cruise_speed: float = field(default=1.0, metadata={"range": (0.1, 3.0)})  # m/s
    accel: float = field(default=2.0, metadata={"range": (0.2, 10.0)})  # m/s^2, the most the plan speeds up or brakes by
    stop_distance: float = field(default=1.2, metadata={"range": (0.2, 5.0)})  # m beyond the drone's radius
    dt: float = field(default=0.1, metadata={"range": (0.02, 0.5)})  # s per plan step
    steps: int = field(default=20, metadata={"range": (2, 100)})


class StraightLine:
    config_class = StraightLineConfig

    def __init__(self, cfg: StraightLineConfig = StraightLineConfig()):
        self.cfg = cfg
        self.context: EpisodeContext | None = None

    def reset(self, context: EpisodeContext) -> None:
        self.context = context  # nothing else is kept between plans

    def plan(self, inp: PlannerInput) -> Trajectory:
        c = self.cfg
        to_goal = inp.goal - inp.position
        distance = float(np.linalg.norm(to_goal))
        direction = to_goal / max(distance, 1e-6)
        # slow down toward the goal (v <= sqrt(2 a d)), and stop for anything in the way
        speed = min(c.cruise_speed, math.sqrt(2 * c.accel * distance))
        if self._blocked(inp, direction):
            speed = 0.0
        v_want = direction * speed
        p, v = inp.position.astype(float), inp.velocity.astype(float)
        P, V, A = [p], [v], []
        for _ in range(c.steps):  # reach v_want as fast as the acceleration limit allows
            a = (v_want - v) / c.dt
            a *= min(1.0, c.accel / max(float(np.linalg.norm(a)), 1e-9))
            p, v = p + v * c.dt + 0.5 * a * c.dt ** 2, v + a * c.dt
            P.append(p)
            V.append(v)
            A.append(a)
        yaw = math.atan2(direction[1], direction[0])  # the camera looks where the drone flies
        return Trajectory(t0=inp.stamp, dt=c.dt, positions=np.array(P), velocities=np.array(V),
                          accelerations=np.array(A), status="straight" if speed > 0 else "braking", yaw=yaw)

    def _blocked(self, inp: PlannerInput, direction: np.ndarray) -> bool:
        """A moving obstacle inside the camera's view cone about the flight direction, or an occupied voxel
        of the static map on the line ahead, within the stop distance."""
        ctx = self.context
        reach = self.cfg.stop_distance + (ctx.vehicle.radius if ctx else 0.3)
        cos_view = math.cos(ctx.camera.half_view) if ctx else 0.0
        for o in inp.obstacles:
            d = o.center[:2] - inp.position[:2]
            dist = float(np.linalg.norm(d))
            if dist < reach and d @ direction[:2] >= cos_view * dist:
                return True
        smap = ctx.static_map if ctx else inp.occupancy
        if smap is None:
            return False
        ahead = inp.position + np.arange(0.3, reach, 0.5 * smap.res)[:, None] * direction  # half-voxel steps
        return bool(smap.is_occupied(ahead).any())


if __name__ == "__main__":  # python examples/custom_planner.py: one short episode
    from experiments.episode import run_episode
    from experiments.episode_config import EpisodeConfig

    s = run_episode("corridor", seed=0, perception="oracle", planner=StraightLine(),
                    cfg=EpisodeConfig(static_map="truth", duration=10.0))
    print(f"{s['planner']}: success {s['success']}, {s['failure_reason']}, path {s['path_length']:.1f} m")
