"""The render process's child (sim.render_process starts it): ``python -m sim.render_child FD PARENT_PID``.

It builds its own copy of each world the parent asks for and answers the parent's frames over the socket
FD (with the rig's other cameras' depth images when the parent asks for them); it ends itself when the
process PARENT_PID is gone (sim.parent_watch). Nothing imports this module: only the child runs it, so
the parent's side does not depend on sim.world.
"""
from __future__ import annotations

import os
import signal
import sys
import traceback
from multiprocessing.connection import Connection

import numpy as np

from sim.parent_watch import exit_with_parent
from sim.world import World


def serve(conn) -> None:
    """The child's life: worlds one after another, each built from the parent's settings and served until
    the parent releases it (None); the interpreter, its imports and compiled code, and the GL context
    serve them all. Ends when the parent closes its end or a world fails."""
    while True:
        try:
            args = conn.recv()
        except (EOFError, OSError, KeyboardInterrupt):
            return
        if args is None or not serve_world(conn, *args):
            return


def serve_world(conn, scenario, seed, renderer, segmentation, light_direction, color) -> bool:
    """Build one world and answer its frames until the parent releases it: True, ready for another;
    False when the parent is gone or something failed (reported to the parent)."""
    try:
        world = World(scenario, seed=seed, renderer=renderer, segmentation=segmentation,
                      light_direction=light_direction, color=color)
    except Exception as e:  # noqa: BLE001 - reported to the parent, which raises it
        try:
            conn.send(("error", f"{type(e).__name__}: {e}"))
        except OSError:  # the parent gave up on this child while it built the world
            pass
        return False
    # The frame reset() rendered (t = 0, the start pose) answers frame 0: the EGL renderer's first frames are
    # not all alike (the same pose's colour differed between a first and a later render), so the child renders
    # exactly the frames the parent would, in the same order.
    first = world.last_images
    cameras = ()  # the other cameras drawn here: (the parent's World.add_cameras call, their yaws)
    try:
        conn.send(("ready", world.renderer))  # (the parent may have ended this child meanwhile: OSError)
        while True:
            msg = conn.recv()
            if msg is None:
                return True
            seq, t, pos, quat, people, light, wanted = msg
            r0 = world.render_wall_time  # the renderer's share (benchmarks), without the noise
            if seq == 0 and first is not None:
                images, first = first, None
            else:
                world.light_direction = light
                images = world.images_at(pos, quat, people)
            if wanted != cameras:  # the rig's other cameras, built as the parent's world would build them
                world.add_cameras(wanted[1] if wanted else ())
                cameras = wanted
            if wanted:
                images = (*images, *world.extra_images_at(pos, quat, people))
            render_s = world.render_wall_time - r0
            conn.send(("frame", seq, render_s, [None if a is None else (a.dtype.str, a.shape) for a in images]))
            for a in images:
                if a is not None:
                    conn.send_bytes(memoryview(np.ascontiguousarray(a)).cast("B"))
    except (EOFError, OSError, KeyboardInterrupt):  # the parent closed its end
        return False
    except Exception:  # noqa: BLE001
        try:
            conn.send(("error", traceback.format_exc(limit=5)))
        except (BrokenPipeError, OSError):
            pass
        return False
    finally:
        world.close()


if __name__ == "__main__":  # python -m sim.render_child FD PARENT_PID
    exit_with_parent(int(sys.argv[2]))
    # Ctrl-C in a terminal signals the whole process group: the parent handles it and ends this child by
    # closing its end of the socket; a KeyboardInterrupt here (building a world) would only print a traceback.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    serve(Connection(int(sys.argv[1])))
    # Leave without the interpreter's teardown: with llvmpipe's threads it can hang after EGL was used.
    os._exit(0)
