"""Frame latency and rendering in a second process (sim.render_process)."""
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from sim import World, load_scenario
from sim.controller import Reference
from sim.render_process import RenderProcessError

REF = Reference.hover([3.0, 0.3, 1.2])  # the drone climbs and moves: every frame has its own pose


def _frames(steps: int, **kw) -> list:
    """(world time when delivered, frame, truth) for each frame ``step`` returned."""
    out = []
    with World(load_scenario("corridor"), seed=3, **kw) as w:
        for _ in range(steps):
            f = w.step(REF)
            if f is not None:
                out.append((w.time, f, w.ground_truth()))
    return out


def _same(a, b) -> bool:
    (_, fa, ta), (_, fb, tb) = a, b
    return (fa.seq == fb.seq and fa.stamp == fb.stamp and np.array_equal(fa.depth, fb.depth)
            and np.array_equal(fa.color, fb.color) and np.array_equal(fa.T_world_camera, fb.T_world_camera)
            and np.array_equal(ta.T_world_camera, tb.T_world_camera) and np.array_equal(ta.T_world_body, tb.T_world_body)
            and ta.stamp == fa.stamp and [o.to_json() for o in ta.obstacles] == [o.to_json() for o in tb.obstacles])


def test_a_late_frame_is_the_frame_captured_then_delivered_one_period_later():
    now = _frames(40, frame_latency=0)
    late = _frames(40, frame_latency=1)
    period = 1.0 / 30
    assert [f.seq for _, f, _ in late] == list(range(len(late))) and len(late) == 10
    by_seq = {f.seq: (t, f, tr) for t, f, tr in now}
    for t, f, tr in late:
        assert t == pytest.approx(f.stamp + period)  # arrives one camera period after its capture
        if f.seq in by_seq:  # frame 0 is the one reset() captures, which step() never returns
            assert _same(by_seq[f.seq], (t, f, tr))  # the same images, poses and truth as without latency
    assert not _same(late[2], late[3])  # the test can tell frames apart


def test_the_render_process_gives_bit_identical_frames():
    here = _frames(40, frame_latency=1)
    beside = _frames(40, frame_latency=1, render_process=True)
    assert len(here) == len(beside) == 10
    assert all(_same(a, b) for a, b in zip(here, beside))
    assert here[-1][1].depth.any() and here[-1][1].color.any()


def test_render_process_settings_are_checked():
    sc = load_scenario("corridor")
    with pytest.raises(ValueError, match="frame_latency >= 1"):
        World(sc, seed=0, render_process=True)
    with pytest.raises(ValueError, match="frame_latency: must be a whole number"):
        World(sc, seed=0, frame_latency=-1)
    with pytest.raises(ValueError, match="render_process: needs render=True"):
        World(sc, seed=0, frame_latency=1, render=False, render_process=True)


def test_a_dead_render_process_is_a_clear_error():
    with World(load_scenario("corridor"), seed=0, frame_latency=1, render_process=True) as w:
        w.step(REF)
        w._render_proc._proc.kill()
        w._render_proc._proc.wait()
        with pytest.raises(RenderProcessError, match="render process"):
            for _ in range(8):
                w.step(REF)


def test_a_released_render_process_builds_the_next_world_with_the_same_frames():
    from sim import render_process

    here = _frames(40, frame_latency=1)
    with World(load_scenario("corridor"), seed=0, frame_latency=1, render_process=True) as w:
        for _ in range(12):
            w.step(REF)  # frames of another world, one still in flight when it closes
        first = w._render_proc._proc.pid
    assert [proc.pid for proc, _ in render_process._IDLE] == [first]  # released, not ended
    with World(load_scenario("corridor"), seed=3, frame_latency=1, render_process=True) as w:
        assert w._render_proc._proc.pid == first and not render_process._IDLE  # built by the same child
    beside = _frames(40, frame_latency=1, render_process=True)
    assert len(here) == len(beside) == 10
    assert all(_same(a, b) for a, b in zip(here, beside))


def test_a_render_process_whose_reply_was_cut_short_is_ended_not_released():
    from sim import render_process

    with World(load_scenario("corridor"), seed=0, frame_latency=1, render_process=True) as w:
        for _ in range(8):
            w.step(REF)
        rp = w._render_proc
        proc = rp._proc
        rp.submit(99, w.time, *w._drone_pose(), w.people_poses(), w.light_direction)
        seq = rp._outstanding[0]

        def cut(*_):
            raise KeyboardInterrupt  # Ctrl-C between a frame's header and its images

        rp._conn.recv_bytes_into = cut
        with pytest.raises(KeyboardInterrupt):
            rp.result(seq)
    assert proc.wait(timeout=20) is not None  # ended with its world
    assert all(p is not proc for p, _ in render_process._IDLE)


@pytest.mark.slow
def test_the_longest_latency_with_a_crowd_does_not_hang():
    """frame_latency 100 (the most a run takes) with 30 walkers: a hundred requests in flight, each with
    30 poses, and the child's answers, whole images, once filled the socket both ways and both processes
    waited for good. In a subprocess, so that a hang fails the test instead of stopping the suite."""
    code = textwrap.dedent("""
        from sim import World
        from sim.controller import Reference
        from sim.scenario import parse_scenario, scenario_path
        text = scenario_path("corridor4").read_text()
        walker = "[[people]]" + text.split("[[people]]")[1].split("[drone]")[0]
        crowd = parse_scenario(text + walker * 26)
        assert len(crowd.people) == 30
        seqs = []
        with World(crowd, seed=0, frame_latency=100, render_process=True) as w:
            while len(seqs) < 3:
                f = w.step(Reference.hover([3.0, 0.3, 1.2]))
                if f is not None:
                    seqs.append(f.seq)
        print(seqs)
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().splitlines()[-1] == "[0, 1, 2]"


@pytest.mark.timeout(60)  # a wait without a bound fails here instead of stopping the suite
def test_a_render_process_stalled_mid_answer_is_a_clear_error(monkeypatch):
    from sim import render_process

    monkeypatch.setattr(render_process, "_REPLY_TIMEOUT_S", 1.0)  # read by the socket of a fresh child
    monkeypatch.setattr(render_process, "_IDLE", [])
    with World(load_scenario("corridor"), seed=0, frame_latency=1, render_process=True) as w:
        rp = w._render_proc
        assert rp._conn.poll(30)  # frame 0's answer has begun; its images, larger than the socket's buffer, wait
        time.sleep(0.5)
        os.kill(rp._proc.pid, signal.SIGSTOP)  # the child stops in the middle of sending them
        try:
            with pytest.raises(RenderProcessError, match=r"did not answer within 1 s \(sending frame 0\)"):
                for _ in range(8):
                    w.step(REF)
        finally:
            os.kill(rp._proc.pid, signal.SIGCONT)


def _rig_frames(steps: int, **kw) -> tuple[list, bool]:
    """(frame, the other cameras' frames) for each frame ``step`` returned, cameras looking back and left;
    and whether the render process drew the other cameras (none were drawn in this process)."""
    out = []
    with World(load_scenario("crossing"), seed=3, frame_latency=1, renderer="gl", **kw) as w:
        w.add_cameras([180.0, 90.0])
        drawn_beside = w._extra_cameras is None
        for _ in range(steps):
            f = w.step(REF)
            if f is not None:
                out.append((f, w.latest_extra_frames()))
    return out, drawn_beside


def test_the_render_process_draws_the_other_cameras_bit_identically():
    here, in_child = _rig_frames(48, render_process=False)
    assert not in_child
    beside, in_child = _rig_frames(48, render_process=True)
    assert in_child
    assert len(here) == len(beside) == 12
    assert here[0][1] == () and beside[0][1] == ()  # frame 0 was captured before the cameras were added
    for (fa, ea), (fb, eb) in zip(here[1:], beside[1:]):
        assert np.array_equal(fa.depth, fb.depth) and len(ea) == len(eb) == 2
        for a, b in zip(ea, eb):
            assert a.seq == b.seq == fa.seq and a.stamp == b.stamp
            assert np.array_equal(a.depth, b.depth) and np.array_equal(a.T_world_camera, b.T_world_camera)
    back, left = here[-1][1]
    assert back.depth.any() and not np.array_equal(back.depth, left.depth)
