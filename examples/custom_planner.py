"""A planner of your own: fly straight at the goal, brake when something is close ahead.

It implements planner.types.Planner (``reset()`` and ``plan(PlannerInput) -> Trajectory``) and is
built with no arguments. Try it:

    dodt-nav run corridor --planner examples/custom_planner.py:StraightLine --perception oracle --map truth --out runs/straight
    dodt-nav sweep corridor --seeds 0:4 --planner examples/custom_planner.py:StraightLine --out runs/straight_sweep
"""
import numpy as np

from planner.types import PlannerInput, Trajectory


class StraightLine:
    cruise_speed = 1.0  # m/s
    accel = 2.0  # m/s^2, the most the plan speeds up or brakes by
    stop_distance = 1.5  # m: a person or occupied map voxel this close ahead stops the drone
    dt, steps = 0.1, 20  # the plan: 20 steps of 0.1 s

    def reset(self) -> None:
        pass  # nothing is kept between plans

    def plan(self, inp: PlannerInput) -> Trajectory:
        to_goal = inp.goal - inp.position
        distance = float(np.linalg.norm(to_goal))
        direction = to_goal / max(distance, 1e-6)
        # slow down toward the goal (v <= sqrt(2 a d)), and stop for anything in the way
        speed = min(self.cruise_speed, np.sqrt(2 * self.accel * distance))
        if self._blocked(inp, direction):
            speed = 0.0
        v_want = direction * speed
        p, v = inp.position.astype(float), inp.velocity.astype(float)
        P, V, A = [p], [v], []
        for _ in range(self.steps):  # reach v_want as fast as the acceleration limit allows
            a = (v_want - v) / self.dt
            a *= min(1.0, self.accel / max(float(np.linalg.norm(a)), 1e-9))
            p, v = p + v * self.dt + 0.5 * a * self.dt ** 2, v + a * self.dt
            P.append(p)
            V.append(v)
            A.append(a)
        return Trajectory(t0=inp.stamp, dt=self.dt, positions=np.array(P), velocities=np.array(V),
                          accelerations=np.array(A), status="straight" if speed > 0 else "braking")

    def _blocked(self, inp: PlannerInput, direction: np.ndarray) -> bool:
        """A moving obstacle, or an occupied voxel of the static map, within stop_distance ahead."""
        for o in inp.obstacles:
            d = o.center[:2] - inp.position[:2]
            if np.linalg.norm(d) < self.stop_distance and d @ direction[:2] > 0:
                return True
        if inp.occupancy is None:
            return False
        ahead = inp.position + np.linspace(0.3, self.stop_distance, 8)[:, None] * direction
        return bool(inp.occupancy.is_occupied(ahead).any())


if __name__ == "__main__":  # python examples/custom_planner.py: one short episode
    from experiments.episode import EpisodeConfig, run_episode

    s = run_episode("corridor", seed=0, perception="oracle", planner=StraightLine(),
                    cfg=EpisodeConfig(static_map="truth", duration=10.0))
    print(f"{s['planner']}: success {s['success']}, {s['failure_reason']}, path {s['path_length']:.1f} m")
