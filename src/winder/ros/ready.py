"""The start handshake on ``winder/ready`` (see :data:`winder.contract.topics.TOPIC_READY`).

A node that must be ready before a job starts announces its state with
:class:`Announcer` (latched, so a late-starting interp node hears it); the
interp node follows every announcement with :class:`Readiness`. Standard
messages only: a third-party consumer publishes ``KeyValue(key="consumer",
value="ready")`` on ``winder/ready`` with a reliable, transient-local QoS.
"""

from __future__ import annotations

from collections.abc import Callable

from diagnostic_msgs.msg import KeyValue
from rclpy.node import Node

from winder.contract.topics import READY_ROLES, READY_STATES, TOPIC_READY
from winder.ros.qos import QOS_LATCHED


class Announcer:
    """Publishes one node's readiness, each change once (latched)."""

    def __init__(self, node: Node, role: str) -> None:
        assert role in READY_ROLES
        self.role = role
        self.pub = node.create_publisher(KeyValue, TOPIC_READY, QOS_LATCHED)
        self.state = ""

    def announce(self, state: str) -> None:
        assert state in READY_STATES
        if state != self.state:
            self.state = state
            self.pub.publish(KeyValue(key=self.role, value=state))


class Readiness:
    """What the cell's other nodes last said on ``winder/ready``; anything that
    is not a known role and state is ignored (it cannot start a job)."""

    def __init__(self, node: Node, on_change: Callable[[], None] | None = None) -> None:
        self.node = node
        self.states: dict[str, str] = {}
        self.on_change = on_change
        node.create_subscription(KeyValue, TOPIC_READY, self._on_ready, QOS_LATCHED)

    def _on_ready(self, msg: KeyValue) -> None:
        if msg.key in READY_ROLES and msg.value in READY_STATES and self.states.get(msg.key) != msg.value:
            self.states[msg.key] = msg.value
            if self.on_change is not None:
                self.on_change()

    def missing(self) -> str:
        """Why a job cannot start now ("" if every role said ready)."""
        waiting = [
            f"{r} {self.states.get(r, 'not heard from')}"
            for r in READY_ROLES
            if self.states.get(r) != "ready"
        ]
        return f"not ready: {', '.join(waiting)} (winder/ready)" if waiting else ""
