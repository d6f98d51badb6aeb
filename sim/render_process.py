"""Camera rendering in a second process, so that it runs beside the rest of a closed loop.

The child builds its own copy of the world from the same scenario and seed (same bodies, same
colours, the same depth-noise stream) and renders nothing but what it is asked: for each captured
frame the parent sends the drone's pose and the people's poses, the child poses its bodies so,
renders, adds the depth noise and sends the frame's images back over a socket (depth in mm,
colour, obstacle ids). Requests are answered in order, so the child draws the noise frame after
frame in capture order, as the parent would: the frames are bit-identical to rendering in the
parent (tested), and the parent spends no time on noise.

It pays off only when the parent has something to do while the child renders: the World asks for
this with ``frame_latency >= 1`` (a frame is delivered one or more camera periods after its
capture), and the parent runs perception and planning on the previous frame meanwhile.
"""
from __future__ import annotations

import os
import socket
import subprocess
import sys
import traceback
from multiprocessing.connection import Connection

import numpy as np

_START_TIMEOUT_S = 120.0  # building the child's world: a few seconds at most when the machine is idle
_REPLY_TIMEOUT_S = 120.0  # one frame: tens of milliseconds


class RenderProcessError(RuntimeError):
    """The render process failed or stopped answering."""


def _serve(conn, scenario, seed, renderer, segmentation, light_direction, color) -> None:
    from sim.world import World  # in the child only

    try:
        world = World(scenario, seed=seed, renderer=renderer, segmentation=segmentation,
                      light_direction=light_direction, color=color)
    except Exception as e:  # noqa: BLE001 - reported to the parent, which raises it
        conn.send(("error", f"{type(e).__name__}: {e}"))
        return
    conn.send(("ready", world.renderer))
    # The frame reset() rendered (t = 0, the start pose) answers frame 0: the EGL renderer's first frames are
    # not all alike (the same pose's colour differed between a first and a later render), so the child renders
    # exactly the frames the parent would, in the same order.
    first = world.last_images
    try:
        while True:
            msg = conn.recv()
            if msg is None:
                break
            seq, t, pos, quat, people, light = msg
            r0 = world.render_wall_time  # the renderer's share (benchmarks), without the noise
            if seq == 0 and first is not None:
                images, first = first, None
            else:
                world.light_direction = light
                images = world.images_at(pos, quat, people)
            render_s = world.render_wall_time - r0
            conn.send(("frame", seq, render_s, [None if a is None else (a.dtype.str, a.shape) for a in images]))
            for a in images:
                if a is not None:
                    conn.send_bytes(memoryview(np.ascontiguousarray(a)).cast("B"))
    except (EOFError, OSError, KeyboardInterrupt):  # the parent closed its end
        pass
    except Exception:  # noqa: BLE001
        try:
            conn.send(("error", traceback.format_exc(limit=5)))
        except (BrokenPipeError, OSError):
            pass
    finally:
        world.close()


class RenderProcess:
    """Parent side: ``submit`` frames in capture order, ``result`` them in the same order."""

    def __init__(self, scenario, seed: int, renderer: str, segmentation: bool, light_direction=None,
                 color: bool = True):
        # A fresh interpreter (no PyBullet/EGL or thread state copied from us, and, unlike
        # multiprocessing's spawn, no re-import of the user's main script) on one end of a socket pair.
        ours, theirs = socket.socketpair()
        env = dict(os.environ)
        # Mesa's llvmpipe rasterises on extra threads by default; beside a busy parent on two cores they only
        # contend (corridor closed loop: 1.18x real time with them, 1.23x without). A user's setting wins.
        env.setdefault("LP_NUM_THREADS", "0")
        # (the child ends itself when this process is gone: sim.parent_watch)
        self._proc = subprocess.Popen([sys.executable, "-m", "sim.render_process", str(theirs.fileno()),
                                       str(os.getpid())], pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL, env=env)
        theirs.close()
        self._conn = Connection(os.dup(ours.fileno()))
        ours.close()
        self._outstanding: list[int] = []
        self.render_wall_time = 0.0
        try:
            self._conn.send((scenario, seed, renderer, segmentation, light_direction, color))
            kind, value = self._recv(_START_TIMEOUT_S, "starting")
        except BaseException:  # no answer in time, the child gone, Ctrl-C: a child still building is ended now
            self._proc.kill()
            self.close()
            raise
        if kind != "ready":
            self.close()
            raise RenderProcessError(f"the render process could not build the world: {value}")
        self.renderer = value

    def _recv(self, timeout: float, doing: str):
        if not self._conn.poll(timeout):
            raise RenderProcessError(f"the render process did not answer within {timeout:.0f} s ({doing})")
        try:
            msg = self._conn.recv()
        except EOFError:
            raise RenderProcessError(f"the render process stopped ({doing}; exit code {self._proc.poll()})") \
                from None
        if msg[0] == "error":
            raise RenderProcessError(f"the render process failed ({doing}): {msg[1]}")
        return msg[0], msg[1:] if len(msg) > 2 else msg[1]

    def submit(self, seq: int, t: float, pos, quat, people, light_direction) -> None:
        """Frame ``seq`` captured at sim time t: the drone's pose and the people's (sim.people.WalkerPose)."""
        light = None if light_direction is None else [float(x) for x in light_direction]
        try:
            self._conn.send((seq, float(t), tuple(pos), tuple(quat), list(people), light))
        except (BrokenPipeError, OSError):
            raise RenderProcessError(f"the render process stopped (exit code {self._proc.poll()})") from None
        self._outstanding.append(seq)

    def result(self, seq: int) -> tuple[np.ndarray | None, ...]:
        """The images of frame ``seq`` (``World.images_at``): depth in mm with the depth noise, colour or
        None, obstacle ids or None."""
        if not self._outstanding or self._outstanding[0] != seq:
            raise RenderProcessError(f"frame {seq} asked out of order (outstanding: {self._outstanding[:3]})")
        kind, (got, render_s, layout) = self._recv(_REPLY_TIMEOUT_S, f"rendering frame {seq}")
        if got != seq:
            raise RenderProcessError(f"the render process answered frame {got} for frame {seq}")
        self._outstanding.pop(0)
        self.render_wall_time += render_s
        out = []
        for spec in layout:
            if spec is None:
                out.append(None)
                continue
            dtype, shape = spec
            a = np.empty(shape, dtype=np.dtype(dtype))
            self._conn.recv_bytes_into(memoryview(a).cast("B"))
            out.append(a)
        return tuple(out)

    def close(self) -> None:
        if self._proc is None:
            return
        try:
            self._conn.send(None)
        except (BrokenPipeError, OSError):
            pass
        # Closing our end also ends a child blocked on sending a frame nobody will read.
        self._conn.close()
        try:
            self._proc.wait(timeout=10.0)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait(timeout=5.0)
        self._proc = None


if __name__ == "__main__":  # the child: python -m sim.render_process FD PARENT_PID
    from sim.parent_watch import exit_with_parent

    exit_with_parent(int(sys.argv[2]))
    _conn = Connection(int(sys.argv[1]))
    try:
        _args = _conn.recv()
    except EOFError:
        sys.exit(0)
    _serve(_conn, *_args)
    # Leave without the interpreter's teardown: with llvmpipe's threads it can hang after EGL was used.
    os._exit(0)
