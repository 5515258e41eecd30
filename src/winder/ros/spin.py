"""``main`` of every winder node."""

from __future__ import annotations

import contextlib
from collections.abc import Callable

from rclpy.node import Node


def spin(factory: Callable[[], Node], args: list[str] | None = None) -> None:
    """``main`` of every winder node: init, spin, and on Ctrl-C / SIGTERM /
    external shutdown run the node's ``shutdown()`` hook (close the bag) with
    further signals ignored, then destroy the node."""
    import signal

    import rclpy
    from rclpy._rclpy_pybind11 import RCLError
    from rclpy.executors import ExternalShutdownException

    from winder.ros.dds import use_profile

    use_profile()
    rclpy.init(args=args)
    node = None
    try:
        node = factory()
        rclpy.spin(node)
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
