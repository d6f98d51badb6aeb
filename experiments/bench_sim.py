"""`dodt-nav bench sim`: render, physics, LiDAR scan and real-time figures of the simulator.

Prints medians; every figure is wall-clock time on this machine, single process. The renderers are
measured side by side on the same view: ours (gl), PyBullet's EGL plugin (pybullet) and PyBullet's
TinyRenderer (tiny); a render call is the renderer's buffers decoded into metric depth and RGB, as a
frame gets them (depth-only: gl's pass without colour). The LiDAR (sim.lidar, Mid-360-like) is timed
as ``World.lidar_scan``, the hits found by each method (rays cast with PyBullet's rayTestBatch; looked up
in depth panoramas drawn by the gl renderer), then noise, dropouts and the scan message.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from sim import World, load_scenario
from sim.camera import RENDERERS, decode_render, quiet_stdout, render
from sim.gl_renderer import GLUnavailable
from sim.lidar import LidarModel

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
    for renderer in RENDERERS:
        try:
            w = World(load_scenario(scenario), seed=0, renderer=renderer)
        except RuntimeError as e:
            out[renderer] = {"error": str(e)}
            continue
        T = w.ground_truth().T_world_camera
        if renderer == "gl":
            gl = w._gl
            out[renderer] = {
                "depth_color_ms": _median_ms(lambda: decode_render(*gl.render(T)), frames),
                "depth_color_seg_ms": _median_ms(lambda: decode_render(*gl.render(T, segmentation=True)), frames),
                "depth_only_ms": _median_ms(lambda: decode_render(*gl.render(T, color=False)), frames),
                "triangles": gl.n_triangles}
        else:
            out[renderer] = {
                "depth_color_ms": _median_ms(lambda: render(p, w._client, w.intrinsics, T, renderer, False), frames),
                "depth_color_seg_ms": _median_ms(lambda: render(p, w._client, w.intrinsics, T, renderer, True),
                                                 frames),
                "depth_only_ms": None}
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


def bench_lidar(scenario: str, scans: int) -> dict:
    """Median wall time of one LiDAR scan from the drone's start pose (each scan its own pattern), by method."""
    w = World(load_scenario(scenario), seed=0, render=False)
    model = LidarModel()
    out = {"model": model.name, "rays_per_scan": model.points_per_scan, "scan_rate_hz": model.scan_rate}
    for method in ("rays", "panorama"):
        returns = []
        try:
            ms = _median_ms(lambda: returns.append(len(w.lidar_scan(model, method=method))), scans)
        except GLUnavailable as e:
            out[method] = {"error": str(e)}
            continue
        out[method] = {"scan_ms_median": ms, "returns_median": int(np.median(returns))}
    w.close()
    return out


def bench_realtime(scenario: str, seconds: float, segmentation: bool, renderer: str = "auto") -> dict:
    sc = load_scenario(scenario)
    w = World(sc, seed=0, segmentation=segmentation, renderer=renderer)
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
           "lidar": bench_lidar(scenario, frames)}
    loops = [("gl", False), ("gl", True), ("pybullet", False)]
    res["realtime"] = [bench_realtime(scenario, seconds, seg, r) for r, seg in loops
                       if "error" not in res["render"].get(r, {"error": ""})]
    from sim.gl_renderer import context_info

    res["gl_context"] = context_info()
    print(f"Simulator benchmark: {scenario}, {cam.width}x{cam.height} @ {sc.rates.camera} Hz, "
          f"physics {sc.rates.physics} Hz, control {sc.rates.control} Hz")
    print("\nrender call, median ms/frame (the scenario's camera at the start pose)")
    print(f"  {'renderer':<10}{'depth+color':>14}{'+segmentation':>16}{'depth only':>13}")
    for r, v in res["render"].items():
        if "error" in v:
            print(f"  {r:<10}  unavailable: {v['error']}")
        else:
            only = "-" if v["depth_only_ms"] is None else f"{v['depth_only_ms']:.2f}"
            print(f"  {r:<10}{v['depth_color_ms']:>14.2f}{v['depth_color_seg_ms']:>16.2f}{only:>13}")
    gi = res["gl_context"]
    if gi:
        print(f"  gl: {res['render']['gl'].get('triangles')} triangles; {gi['renderer']}, OpenGL {gi['version']}, "
              f"LP_NUM_THREADS={gi['threads'] if gi['threads'] is not None else 'unset'}")
    ph = res["physics"]
    print(f"\nphysics step (rotor forces, stepSimulation, people at control rate, contacts): "
          f"median {ph['physics_step_us_median']:.1f} us, p95 {ph['physics_step_us_p95']:.1f} us")
    li = res["lidar"]
    print(f"\nlidar scan ({li['model']}, {li['rays_per_scan']} rays, noise, dropouts), median ms/scan by method")
    for method, what in (("rays", "PyBullet rayTestBatch"), ("panorama", "gl depth panorama")):
        v = li[method]
        if "error" in v:
            print(f"  {method:<10}  unavailable: {v['error']}")
        else:
            print(f"  {method:<10}{v['scan_ms_median']:>8.1f} ms ({what}), {v['returns_median']} returns; "
                  f"{v['scan_ms_median'] * li['scan_rate_hz'] / 10:.1f} % of one core at {li['scan_rate_hz']:g} Hz")
    print(f"\nclosed simulation loop flying the straight reference for {seconds:g} s:")
    for r in res["realtime"]:
        print(f"  segmentation {'on ' if r['segmentation'] else 'off'} ({r['renderer']}): real-time factor "
              f"{r['real_time_factor']:.2f}x, render {r['render_share'] * 100:.1f} % of wall time "
              f"({r['render_ms_per_frame']:.1f} ms/frame), everything else "
              f"{(1 - r['render_share']) * 100:.1f} % ({r['non_render_ms_per_sim_second']:.0f} ms per sim second)")
    if json_out:
        Path(json_out).write_text(json.dumps(res, indent=1))
    return res
