"""Camera rendering in a second process, so that it runs beside the rest of a closed loop: the parent's side.

The child builds its own copy of the world from the same scenario and seed (same bodies, same
colours, the same depth-noise stream) and renders nothing but what it is asked: for each captured
frame the parent sends the drone's pose and the people's poses, the child poses its bodies so,
renders, adds the depth noise and sends the frame's images back over a socket (depth in mm,
colour, obstacle ids). Requests are answered in order, so the child draws the noise frame after
frame in capture order, as the parent would: the frames are bit-identical to rendering in the
parent (tested), and the parent spends no time on noise.
At most one request is on the socket at a time: the parent keeps the later ones (one per frame of
latency) and sends the next once the child has answered the last. The child sends its answer before it
reads its next request; with many requests sent ahead, they and its answer would fill the socket's
buffers both ways and both sides would wait for good on sending. Every wait on the socket is bounded
(``_REPLY_TIMEOUT_S``): a child that stops answering is an error, not a hang.
The child runs sim.render_child, which this module does not import: the parent's side does not
depend on sim.world.

It pays off only when the parent has something to do while the child renders: the World asks for
this with ``frame_latency >= 1`` (a frame is delivered one or more camera periods after its
capture), and the parent runs perception and planning on the previous frame meanwhile.

A child outlives its world: when the world closes, the child closes its copy and waits, and the next
world of the same process (the next episode of a loop or of a sweep's worker) has it build the new
one, without a new interpreter, imports, compiled code or GL context (about a second per episode).
Every world starts from its scenario and seed alone, so its frames are those a fresh child gives
(tested).
"""
from __future__ import annotations

import os
import pickle
import socket
import struct
import subprocess
import sys
from multiprocessing.connection import Connection

import numpy as np

_START_TIMEOUT_S = 120.0  # building the child's world: a few seconds at most when the machine is idle
_REPLY_TIMEOUT_S = 120.0  # one frame: tens of milliseconds; also any one read or write stalled on the socket


class RenderProcessError(RuntimeError):
    """The render process failed or stopped answering."""


_IDLE: list[tuple[subprocess.Popen, Connection]] = []  # released children of this process, ready for a world
_MAX_IDLE = 1  # kept per process: a loop or a sweep worker flies one episode at a time


def _idle_child() -> tuple[subprocess.Popen, Connection] | None:
    """A released child that is still running, or None."""
    while _IDLE:
        proc, conn = _IDLE.pop()
        if proc.poll() is None:
            return proc, conn
        conn.close()
    return None


def _spawn() -> tuple[subprocess.Popen, Connection]:
    """A fresh interpreter (no PyBullet/EGL or thread state copied from us, and, unlike multiprocessing's
    spawn, no re-import of the user's main script) on one end of a socket pair."""
    ours, theirs = socket.socketpair()
    # Our end's reads and writes give up (BlockingIOError) after this long without progress (the kernel's
    # SO_RCVTIMEO/SO_SNDTIMEO, a struct timeval): a child that stops reading or stops mid-answer is an error.
    whole = int(_REPLY_TIMEOUT_S)
    timeval = struct.pack("@ll", whole, int((_REPLY_TIMEOUT_S - whole) * 1e6))
    ours.setsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO, timeval)
    ours.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, timeval)
    env = dict(os.environ)
    # Mesa's llvmpipe rasterises on extra threads by default; beside a busy parent on two cores they only
    # contend. A user's setting wins.
    env.setdefault("LP_NUM_THREADS", "0")
    # (the child ends itself when this process is gone: sim.parent_watch)
    proc = subprocess.Popen([sys.executable, "-m", "sim.render_child", str(theirs.fileno()), str(os.getpid())],
                            pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL, env=env)
    theirs.close()
    conn = Connection(os.dup(ours.fileno()))
    ours.close()
    return proc, conn


class RenderProcess:
    """Parent side: ``submit`` frames in capture order, ``result`` them in the same order."""

    def __init__(self, scenario, seed: int, renderer: str, segmentation: bool, light_direction=None,
                 color: bool = True):
        # A child released by an earlier world of this process builds this one (a second or so of start-up
        # saved per episode); a fresh one is started when there is none, or when the released one fails.
        self._outstanding: list[int] = []  # frames submitted and not yet read, in order
        self._unsent: list[bytes] = []  # the latest of them, pickled, not sent yet: at most one is on the socket
        self._on_socket = False  # a request sent and not yet answered
        self.render_wall_time = 0.0
        self._healthy = False
        config = (scenario, seed, renderer, segmentation, light_direction, color)
        reused = _idle_child()
        if reused is not None:
            self._proc, self._conn = reused
            try:
                self.renderer = self._start(config)
                return
            except RenderProcessError:
                self._end()
        self._proc, self._conn = _spawn()
        self.renderer = self._start(config)

    def _start(self, config) -> str:
        """Has the child build the world of ``config``: its renderer's name. Ends the child on failure."""
        try:
            self._conn.send(config)
            kind, value = self._recv(_START_TIMEOUT_S, "starting")
        except BaseException:  # no answer in time, the child gone, Ctrl-C: a child still building is ended now
            self._end()
            raise
        if kind != "ready":
            self._end()
            raise RenderProcessError(f"the render process could not build the world: {value}")
        self._healthy = True
        return value

    def _recv(self, timeout: float, doing: str):
        if not self._conn.poll(timeout):
            raise self._stalled(doing, timeout)
        try:
            msg = self._conn.recv()
        except BlockingIOError:
            raise self._stalled(doing) from None
        except (EOFError, OSError):
            raise self._stopped(doing) from None
        if msg[0] == "error":
            raise RenderProcessError(f"the render process failed ({doing}): {msg[1]}")
        return msg[0], msg[1:] if len(msg) > 2 else msg[1]

    def _stopped(self, doing: str) -> RenderProcessError:
        return RenderProcessError(f"the render process stopped ({doing}; exit code {self._proc.poll()})")

    @staticmethod
    def _stalled(doing: str, timeout: float | None = None) -> RenderProcessError:
        """The error for a wait on the child that ran out (by default, a read or write on the socket)."""
        timeout = _REPLY_TIMEOUT_S if timeout is None else timeout
        return RenderProcessError(f"the render process did not answer within {timeout:.0f} s ({doing})")

    def submit(self, seq: int, t: float, pos, quat, people, light_direction, cameras: tuple = ()) -> None:
        """Frame ``seq`` captured at sim time t: the drone's pose and the people's (sim.people.WalkerPose).
        cameras: () or (n, yaws): the rig's other cameras (World.add_cameras, the n-th call), drawn too, their
        depth images following the first camera's in ``result``."""
        light = None if light_direction is None else [float(x) for x in light_direction]
        # pickled now, as it stands at capture; sent when the child has answered the requests before it
        self._unsent.append(pickle.dumps((seq, float(t), tuple(pos), tuple(quat), list(people), light,
                                          tuple(cameras))))
        self._outstanding.append(seq)
        self._send_next()

    def _send_next(self) -> None:
        """Sends the oldest unsent request, unless one is on the socket already: the child, having answered
        every earlier one, reads it, so sending it never waits on the child's sending."""
        if self._on_socket or not self._unsent:
            return
        healthy, self._healthy = self._healthy, False  # until the request is whole (not cut by Ctrl-C)
        try:
            self._conn.send_bytes(self._unsent[0])
        except BlockingIOError:
            raise self._stalled("taking a request") from None
        except (BrokenPipeError, OSError):
            raise RenderProcessError(f"the render process stopped (exit code {self._proc.poll()})") from None
        self._unsent.pop(0)
        self._on_socket = True
        self._healthy = healthy

    def result(self, seq: int) -> tuple[np.ndarray | None, ...]:
        """The images of frame ``seq`` (``World.images_at``): depth in mm with the depth noise, colour or
        None, obstacle ids or None; then the other cameras' depth images when ``submit`` asked for them."""
        if not self._outstanding or self._outstanding[0] != seq:
            raise RenderProcessError(f"frame {seq} asked out of order (outstanding: {self._outstanding[:3]})")
        self._send_next()  # (sent already, unless an earlier send failed)
        # the connection is in step with the child again only once the whole frame is read: a reply cut
        # short (an error, Ctrl-C) leaves the child to be ended, not released
        healthy, self._healthy = self._healthy, False
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
            try:
                self._conn.recv_bytes_into(memoryview(a).cast("B"))
            except BlockingIOError:
                raise self._stalled(f"sending frame {seq}") from None
            except (EOFError, OSError):
                raise self._stopped(f"sending frame {seq}") from None
            out.append(a)
        self._on_socket = False
        self._healthy = healthy
        self._send_next()  # the child renders the next frame while the caller uses this one
        return tuple(out)

    def close(self) -> None:
        """Releases the child for this process's next world (its frames still in flight read and dropped),
        or ends it when it failed or enough children wait already."""
        if self._proc is None:
            return
        # requests not sent yet are dropped; the one on the socket is read
        del self._outstanding[len(self._outstanding) - len(self._unsent):]
        self._unsent.clear()
        try:
            while self._healthy and self._outstanding:
                self.result(self._outstanding[0])
        except Exception:  # noqa: BLE001 - a child that cannot answer is ended below, whatever went wrong
            pass
        if self._healthy and self._proc.poll() is None and len(_IDLE) < _MAX_IDLE:
            try:
                self._conn.send(None)  # the child closes this world and waits for the next
                _IDLE.append((self._proc, self._conn))
                self._proc = self._conn = None
                return
            except (BrokenPipeError, OSError):
                pass
        self._end()

    def _end(self) -> None:
        """Ends the child: closing our end ends it whether it waits for a message or is blocked on sending
        a frame nobody will read."""
        if self._proc is None:
            return
        try:
            self._conn.send(None)
            self._conn.send(None)  # releases a world if one is open, then ends the child
        except (BrokenPipeError, OSError):
            pass
        self._conn.close()
        try:
            self._proc.wait(timeout=10.0)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait(timeout=5.0)
        self._proc = self._conn = None
        self._healthy = False
