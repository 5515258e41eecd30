"""The topic contract shared by the three winder nodes: names, QoS, message
packing, diagnostics and safe parameter declaration.

Topic names are relative (``winder/steps``) so that a node namespace
(``--ros-args -r __ns:=/cell1``) moves the whole cell; ``/clock`` and
``/diagnostics`` stay global, as ROS tools expect them.

QoS, on purpose:

* job description and path: reliable, transient-local, depth 1 - a late
  joiner (a recorder, Foxglove) still gets the current job;
* steps and step times: reliable, keep-all - every step matters, a slow reader
  holds the writer's history instead of losing samples;
* joint states / commands: reliable, depth 100;
* ``/clock``: best-effort, depth 1 (what rclpy's time source subscribes with);
* ``/diagnostics``: reliable, depth 10 (as diagnostic_updater).
"""

from __future__ import annotations

import array
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
)
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Int32MultiArray, Int64MultiArray, MultiArrayDimension

from winder.stream import STEP_COLUMNS, TIMED_COLUMNS

TOPIC_JOB = "winder/job"
TOPIC_PATH = "winder/path"
TOPIC_STEPS = "winder/steps"
TOPIC_STEP_TIMES = "winder/step_times"
TOPIC_JOINT_STATES = "winder/joint_states"
TOPIC_JOINT_COMMANDS = "winder/joint_commands"
TOPIC_SIM_CONFIG = "winder/sim_config"
TOPIC_CLOCK = "/clock"
TOPIC_DIAGNOSTICS = "/diagnostics"

QOS_LATCHED = QoSProfile(
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
    history=HistoryPolicy.KEEP_LAST,
)
QOS_STREAM = QoSProfile(
    depth=1000, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_ALL
)
QOS_STATE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
QOS_CLOCK = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
QOS_DIAGNOSTICS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


def _layout(msg: Int32MultiArray | Int64MultiArray, rows: int, columns: Sequence[str]) -> None:
    cols = len(columns)
    msg.layout.dim = [
        MultiArrayDimension(label="steps", size=rows, stride=rows * cols),
        MultiArrayDimension(label=",".join(columns), size=cols, stride=cols),
    ]
    msg.layout.data_offset = 0


def pack_steps(rows: npt.NDArray[np.integer[Any]]) -> Int32MultiArray:
    """(n, 4) [segment, feed, fork, pole] -> Int32MultiArray with a 2-D layout."""
    msg = Int32MultiArray()
    _layout(msg, rows.shape[0], STEP_COLUMNS)
    msg.data = array.array("i", np.ascontiguousarray(rows, dtype=np.int32).tobytes())
    return msg


def pack_timed(rows: npt.NDArray[np.integer[Any]]) -> Int64MultiArray:
    """(n, 5) [t_ns, segment, feed, fork, pole] -> Int64MultiArray."""
    msg = Int64MultiArray()
    _layout(msg, rows.shape[0], TIMED_COLUMNS)
    msg.data = array.array("q", np.ascontiguousarray(rows, dtype=np.int64).tobytes())
    return msg


def unpack(msg: Int32MultiArray | Int64MultiArray, columns: Sequence[str]) -> npt.NDArray[Any]:
    """Rows of a packed chunk; ValueError if its layout is not ``columns``."""
    dims = msg.layout.dim
    cols = len(columns)
    if len(dims) != 2 or dims[1].size != cols or dims[1].label != ",".join(columns):
        raise ValueError(
            f"chunk layout {[(d.label, d.size) for d in dims]} is not (steps, {','.join(columns)})"
        )
    dtype = np.int32 if isinstance(msg, Int32MultiArray) else np.int64
    data = np.frombuffer(msg.data, dtype=dtype)
    if data.size != dims[0].size * cols:
        raise ValueError(f"chunk holds {data.size} values, layout says {dims[0].size} x {cols}")
    return data.reshape(dims[0].size, cols)


class Diagnostics:
    """Publishes one node's DiagnosticStatus entries the diagnostic_updater way:
    names ``"<node>: <task>"``, a hardware id, key/value pairs."""

    def __init__(self, node: Node, hardware_id: str) -> None:
        self.node = node
        self.hardware_id = hardware_id
        self.pub = node.create_publisher(DiagnosticArray, TOPIC_DIAGNOSTICS, QOS_DIAGNOSTICS)

    def publish(self, task: str, level: int, message: str, values: dict[str, object]) -> None:
        self.pub.publish(self.status(task, level, message, values))

    def status(self, task: str, level: int, message: str, values: dict[str, object]) -> DiagnosticArray:
        """The DiagnosticArray that :meth:`publish` would send."""
        status = DiagnosticStatus(
            level=bytes([level]),
            name=f"{self.node.get_name()}: {task}",
            message=message,
            hardware_id=self.hardware_id,
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()],
        )
        arr = DiagnosticArray(status=[status])
        arr.header.stamp = self.node.get_clock().now().to_msg()
        return arr


OK = int.from_bytes(DiagnosticStatus.OK, "little")
WARN = int.from_bytes(DiagnosticStatus.WARN, "little")
ERROR = int.from_bytes(DiagnosticStatus.ERROR, "little")


def float_param(
    description: str, low: float, high: float, *, read_only: bool = False
) -> ParameterDescriptor:
    return ParameterDescriptor(
        type=ParameterType.PARAMETER_DOUBLE,
        description=description,
        floating_point_range=[FloatingPointRange(from_value=low, to_value=high, step=0.0)],
        read_only=read_only,
    )


def int_param(description: str, low: int, high: int, *, read_only: bool = False) -> ParameterDescriptor:
    return ParameterDescriptor(
        type=ParameterType.PARAMETER_INTEGER,
        description=description,
        integer_range=[IntegerRange(from_value=low, to_value=high, step=1)],
        read_only=read_only,
    )


def plain_param(kind: int, description: str, *, read_only: bool = False) -> ParameterDescriptor:
    return ParameterDescriptor(type=kind, description=description, read_only=read_only)


def declare_all(
    node: Node,
    specs: dict[str, tuple[Any, ParameterDescriptor]],
    check: Callable[[dict[str, Any]], str | None],
) -> list[str]:
    """Declare parameters; a bad start-up override (``--ros-args -p``) is not
    fatal: it is logged with its reason, the default is kept, and the returned
    list names the parameters that were rejected. ``check`` validates the
    whole set (None if fine, else a reason) and is also installed as the
    set-parameters callback, so validation lives in one place."""
    from rclpy.exceptions import (
        InvalidParameterTypeException,
        InvalidParameterValueException,
    )

    rejected = []
    overrides = node._parameter_overrides  # noqa: SLF001 - read only, to report the bad value
    for name, (default, descriptor) in specs.items():
        try:
            node.declare_parameter(name, default, descriptor)
        except (InvalidParameterTypeException, InvalidParameterValueException, TypeError) as exc:
            bad = overrides.get(name)
            shown = bad.value if bad is not None else "?"
            reason = str(exc).splitlines()[0]
            node.get_logger().error(f"parameter {name}={shown!r} rejected at start: {reason}; keeping {default!r}")
            node.declare_parameter(name, default, descriptor, ignore_override=True)
            rejected.append(name)
    current = {name: node.get_parameter(name).value for name in specs}
    reason = check(current)
    if reason is not None:
        node.get_logger().error(f"parameters rejected at start: {reason}")
        rejected.append(reason)

    from rcl_interfaces.msg import SetParametersResult

    def on_set(params: list[Any]) -> SetParametersResult:
        merged = {name: node.get_parameter(name).value for name in specs}
        for p in params:
            merged[p.name] = p.value
        why = check(merged)
        if why is not None:
            node.get_logger().warning(f"parameter change rejected: {why}")
            return SetParametersResult(successful=False, reason=why)
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(on_set)
    return rejected
