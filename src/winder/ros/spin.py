"""``main`` of every winder node."""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import os
import signal
from collections.abc import Callable
from types import FrameType

from rclpy.node import Node

#: glibc's mallopt parameters, and the values a node runs with: blocks up to
#: 32 MiB (glibc's limit) come from the heap, and up to 64 MiB of freed heap
#: stay with the process.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
HEAP_BLOCKS = 32 << 20
HEAP_KEPT = 64 << 20


def keep_freed_memory() -> bool:
    """Let the allocator reuse freed memory for numpy's temporaries (glibc;
    elsewhere nothing changes). A node's arrays of a few hundred kB (a chunk
    of steps, its columns, the tracker's terms) would otherwise each be a
    fresh mmap, zeroed page by page by the kernel and unmapped when freed:
    at 10**7 steps that was a tenth of the sim node's time. True if set."""
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name) if name else None
        mallopt = getattr(libc, "mallopt", None)
    except OSError:
        return False
    if mallopt is None:
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, HEAP_BLOCKS)) and bool(mallopt(_M_TRIM_THRESHOLD, HEAP_KEPT))


#: a signal came (one entry each): one before ``rclpy.init`` installs its handlers ends the node too
_signalled: list[bool] = []


def _stop_quietly(signum: int, frame: FrameType | None) -> None:
    """The Python side of SIGINT and SIGTERM in a node: nothing. rclpy's own
    handler (which calls this one after it) shuts the context down, and spin
    returns once the callback that runs has ended. Python's default, a
    KeyboardInterrupt raised wherever the main thread happens to be, could
    land between a bag's creation and the line that keeps it (which once left a
    0-byte .mcap and no metadata.yaml)."""
    del signum, frame
    _signalled.append(True)


def _hangup(signum: int, frame: FrameType | None) -> None:
    """SIGHUP (the terminal went away) ends the node as SIGTERM does, which
    rclpy handles; by default it would kill the node outright, its bag open."""
    del signum, frame
    os.kill(os.getpid(), signal.SIGTERM)


def install_signal_handlers() -> None:
    """Signals that end a node let it finish its callback and close its bag
    (see :func:`_stop_quietly`); installed before ``rclpy.init``, which chains
    its handlers to these."""
    signal.signal(signal.SIGINT, _stop_quietly)
    signal.signal(signal.SIGTERM, _stop_quietly)
    signal.signal(signal.SIGHUP, _hangup)


def spin(factory: Callable[[], Node], args: list[str] | None = None) -> None:
    """``main`` of every winder node: init, spin, and on Ctrl-C / SIGTERM /
    SIGHUP / external shutdown run the node's ``shutdown()`` hook (close the
    bag) with further signals ignored, then destroy the node."""
    import rclpy
    from rclpy._rclpy_pybind11 import RCLError
    from rclpy.executors import ExternalShutdownException

    from winder.ros.dds import use_profile
    from winder.ros.sender import SenderExecutor

    use_profile()
    keep_freed_memory()
    install_signal_handlers()
    rclpy.init(args=args)
    node = None
    try:
        if _signalled:  # before rclpy's handlers were there to shut the context down
            return
        node = factory()
        executor = SenderExecutor()  # takes attributed subscriptions with their publisher (winder.ros.sender)
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        # a signal shut the context down while a callback was using it (an
        # RCLError from a publish, an invalid handle): the shutdown's doing
        if rclpy.ok():
            raise
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        signal.signal(signal.SIGHUP, signal.SIG_IGN)
        if node is not None:
            hook = getattr(node, "shutdown", None)
            if callable(hook):
                hook()
            node.destroy_node()
        # the signal handler may shut the context down at this very moment
        with contextlib.suppress(RCLError):
            rclpy.try_shutdown()
    code = getattr(node, "exit_code", 0)
    if code:
        raise SystemExit(code)
