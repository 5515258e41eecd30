"""The end every stand-in node of test/consumers has: spin until Ctrl-C or
an external shutdown, then destroy the node and shut rclpy down. (A
sibling module: each script runs as ``python test/consumers/<name>.py``,
its directory first on sys.path.)"""

from __future__ import annotations

from typing import Any

import rclpy
from rclpy.executors import ExternalShutdownException


def spin_until_stopped(node: Any) -> None:
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
