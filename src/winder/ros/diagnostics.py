"""Diagnostics the diagnostic_updater way: one DiagnosticStatus per task,
named ``"<node>: <task>"``, with a hardware id and key/value pairs."""

from __future__ import annotations

import os
import socket
import time
from collections.abc import Callable

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile

from winder.contract.topics import PROCESS_KEYS, TOPIC_DIAGNOSTICS
from winder.ros.qos import QOS_DIAGNOSTICS

#: The statuses' writer: /diagnostics' QoS (winder.contract.qos), but
#: transient-local, so that a reader that asks for it (``winder ctl state``)
#: has each node's last statuses the moment it matches, not at the node's
#: next one (up to 1 s). A volatile reader, the default, gets only new ones,
#: as before.
QOS_DIAGNOSTICS_KEPT = QoSProfile(
    depth=QOS_DIAGNOSTICS.depth,
    reliability=QOS_DIAGNOSTICS.reliability,
    history=QOS_DIAGNOSTICS.history,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)


class Diagnostics:
    """Publishes one node's DiagnosticStatus entries the diagnostic_updater way:
    names ``"<node>: <task>"``, a hardware id, key/value pairs. The node name
    includes its namespace (``cell1/sim_node: job``): /diagnostics is global,
    and two cells on one graph must stay tellable apart. Every status ends
    with the process that sent it (:data:`winder.contract.topics.PROCESS_KEYS`:
    pid, host, start time), so that two nodes of one name or role are told
    apart (:class:`winder.ros.peers.Solo`)."""

    def __init__(self, node: Node, hardware_id: str) -> None:
        self.node = node
        self.hardware_id = hardware_id
        started = (str(os.getpid()), socket.gethostname(), str(time.time_ns()))
        self.process = dict(zip(PROCESS_KEYS, started, strict=True))
        #: what the node refused from foreign senders, in words ("" if nothing): its statuses say it
        self.foreign: Callable[[], str] | None = None
        self.pub = node.create_publisher(DiagnosticArray, TOPIC_DIAGNOSTICS, QOS_DIAGNOSTICS_KEPT)

    def publish(self, task: str, level: int, message: str, values: dict[str, object]) -> None:
        self.pub.publish(self.status(task, level, message, values))

    def foreign_keys(self, values: dict[str, object]) -> dict[str, object]:
        said = self.foreign() if self.foreign is not None and "intruders" not in values else ""
        return {"intruders": said} if said else {}

    def status(self, task: str, level: int, message: str, values: dict[str, object]) -> DiagnosticArray:
        """The DiagnosticArray that :meth:`publish` would send."""
        status = DiagnosticStatus(
            level=bytes([level]),
            name=f"{self.node.get_fully_qualified_name().lstrip('/')}: {task}",
            message=message,
            hardware_id=self.hardware_id,
            values=[
                KeyValue(key=k, value=str(v))
                for k, v in {**values, **self.foreign_keys(values), **self.process}.items()
            ],
        )
        arr = DiagnosticArray(status=[status])
        arr.header.stamp = self.node.get_clock().now().to_msg()
        return arr


OK = int.from_bytes(DiagnosticStatus.OK, "little")
WARN = int.from_bytes(DiagnosticStatus.WARN, "little")
ERROR = int.from_bytes(DiagnosticStatus.ERROR, "little")
