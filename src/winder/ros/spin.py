"""``main`` of every winder node."""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
from collections.abc import Callable

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


def spin(factory: Callable[[], Node], args: list[str] | None = None) -> None:
    """``main`` of every winder node: init, spin, and on Ctrl-C / SIGTERM /
    external shutdown run the node's ``shutdown()`` hook (close the bag) with
    further signals ignored, then destroy the node."""
    import signal

    import rclpy
    from rclpy._rclpy_pybind11 import RCLError
    from rclpy.executors import ExternalShutdownException

    from winder.ros.dds import use_profile
    from winder.ros.sender import SenderExecutor

    use_profile()
    keep_freed_memory()
    rclpy.init(args=args)
    node = None
    try:
        node = factory()
        executor = SenderExecutor()  # takes attributed subscriptions with their publisher (winder.ros.sender)
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RCLError:
        # a signal shut the context down while a callback was publishing
        if rclpy.ok():
            raise
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
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
