"""Timers on the steady clock: the nodes' own loops never wait on ROS time.

With ``use_sim_time:=true`` (what every launch file of a simulated cell sets)
a timer made with ``Node.create_timer`` runs on /clock, and /clock only moves
while steps flow through these very loops: the cell would wait for itself.
"""

from __future__ import annotations

from collections.abc import Callable

from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from rclpy.timer import Timer

_STEADY = Clock(clock_type=ClockType.STEADY_TIME)


def steady_timer(node: Node, period: float, callback: Callable[[], None]) -> Timer:
    """``node.create_timer(period, callback)`` on the steady clock."""
    return node.create_timer(period, callback, clock=_STEADY)
