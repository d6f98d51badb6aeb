"""`dodt-nav bench sim`: render, physics and real-time figures of the simulator.

Prints medians; every figure is wall-clock time on this machine, single process.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from sim import World, load_scenario
from sim.camera import quiet_stdout, render

with quiet_stdout():  # PyBullet prints its build time on import
    import pybullet as p
from sim.trajectories import scenario_reference


def _median_ms(fn, n: int) -> float:
    fn()  # warm-up
    ts = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts) * 1e3)


def bench_render(scenario: str, frames: int) -> dict:
    out = {}
    for renderer in ("egl", "tiny"):
        try:
            w = World(load_scenario(scenario), seed=0, renderer=renderer)
        except RuntimeError as e:
            out[renderer] = {"error": str(e)}
            continue
        T = w.ground_truth().T_world_camera
        out[renderer] = {
            "depth_color_ms": _median_ms(lambda: render(p, w._client, w.intrinsics, T, renderer, False), frames),
            "depth_color_seg_ms": _median_ms(lambda: render(p, w._client, w.intrinsics, T, renderer, True), frames),
        }
        w.close()
    return out


def bench_physics(scenario: str, steps: int) -> dict:
    w = World(load_scenario(scenario), seed=0)
    ts = []
    for _ in range(steps):
        t0 = time.perf_counter()
        w._physics_step()
        ts.append(time.perf_counter() - t0)
    w.close()
    return {"physics_step_us_median": float(np.median(ts) * 1e6), "physics_step_us_p95": float(np.percentile(ts, 95) * 1e6)}


def bench_realtime(scenario: str, seconds: float, segmentation: bool) -> dict:
    sc = load_scenario(scenario)
    w = World(sc, seed=0, segmentation=segmentation)
    ref_at = scenario_reference(sc)
    render0 = w.render_wall_time  # the start frame's render is not part of the loop
    n = int(round(seconds * sc.rates.control))
    t0 = time.perf_counter()
    for _ in range(n):
        w.step(ref_at(w.time))
    wall = time.perf_counter() - t0
    render_s = w.render_wall_time - render0
    res = {"renderer": w.renderer, "segmentation": segmentation, "sim_seconds": round(w.time, 3),
           "wall_seconds": round(wall, 3), "real_time_factor": round(w.time / wall, 3),
           "render_share": round(render_s / wall, 3),
           "non_render_ms_per_sim_second": round((wall - render_s) / w.time * 1e3, 1),
           "render_ms_per_frame": round(render_s / (n // (sc.rates.control // sc.rates.camera)) * 1e3, 2)}
    w.close()
    return res


def run(scenario: str = "corridor", seconds: float = 10.0, frames: int = 30, json_out: Path | None = None) -> dict:
    sc = load_scenario(scenario)
    cam = sc.camera
    res = {"scenario": scenario, "resolution": [cam.width, cam.height], "camera_hz": sc.rates.camera,
           "physics_hz": sc.rates.physics, "control_hz": sc.rates.control,
           "render": bench_render(scenario, frames), "physics": bench_physics(scenario, 2400),
           "realtime": [bench_realtime(scenario, seconds, False), bench_realtime(scenario, seconds, True)]}
    print(f"Simulator benchmark: {scenario}, {cam.width}x{cam.height} @ {sc.rates.camera} Hz, "
          f"physics {sc.rates.physics} Hz, control {sc.rates.control} Hz")
    print("\nrender call, median ms/frame (the scenario's camera at the start pose)")
    print(f"  {'renderer':<10}{'depth+color':>14}{'+segmentation':>16}")
    for r, v in res["render"].items():
        if "error" in v:
            print(f"  {r:<10}  unavailable: {v['error']}")
        else:
            print(f"  {r:<10}{v['depth_color_ms']:>14.2f}{v['depth_color_seg_ms']:>16.2f}")
    ph = res["physics"]
    print(f"\nphysics step (rotor forces, stepSimulation, people at control rate, contacts): "
          f"median {ph['physics_step_us_median']:.1f} us, p95 {ph['physics_step_us_p95']:.1f} us")
    print(f"\nclosed simulation loop flying the straight reference for {seconds:g} s:")
    for r in res["realtime"]:
        print(f"  segmentation {'on ' if r['segmentation'] else 'off'} ({r['renderer']}): real-time factor "
              f"{r['real_time_factor']:.2f}x, render {r['render_share'] * 100:.1f} % of wall time "
              f"({r['render_ms_per_frame']:.1f} ms/frame), everything else "
              f"{(1 - r['render_share']) * 100:.1f} % ({r['non_render_ms_per_sim_second']:.0f} ms per sim second)")
    if json_out:
        Path(json_out).write_text(json.dumps(res, indent=1))
    return res
