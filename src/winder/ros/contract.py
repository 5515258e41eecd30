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
* progress (diagnostic_msgs/KeyValue: job id, steps consumed), reliable depth
  100: the sim node's receipt that lets the interp node keep at most
  ``max_in_flight`` steps in the pipeline (memory stays bounded);
* ``/clock``: best-effort, depth 1 (what rclpy's time source subscribes with);
* ``/diagnostics``: reliable, depth 10 (as diagnostic_updater).
"""

from __future__ import annotations

import array
import contextlib
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.exceptions import InvalidHandle, InvalidParameterTypeException, InvalidParameterValueException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription
from std_msgs.msg import Int32MultiArray, Int64MultiArray, MultiArrayDimension

from winder.contract.cdr import MultiArrayCodec
from winder.contract.stream import STEP_COLUMNS, TIMED_COLUMNS
from winder.spec import Spec, SpecError

TOPIC_JOB = "winder/job"
TOPIC_PATH = "winder/path"
TOPIC_STEPS = "winder/steps"
TOPIC_STEP_TIMES = "winder/step_times"
TOPIC_JOINT_STATES = "winder/joint_states"
TOPIC_JOINT_COMMANDS = "winder/joint_commands"
TOPIC_SIM_CONFIG = "winder/sim_config"
TOPIC_PROGRESS = "winder/progress"
TOPIC_PROFILE_CONFIG = "winder/profile_config"
TOPIC_CLOCK = "/clock"
TOPIC_DIAGNOSTICS = "/diagnostics"

QOS_LATCHED = QoSProfile(
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
    history=HistoryPolicy.KEEP_LAST,
)
QOS_STREAM = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_ALL)
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


#: The chunks of winder/steps and winder/step_times as serialized payloads:
#: the nodes publish and take these bytes directly (no message objects).
#: Messages a stream callback takes from its subscription's queue by itself.
WAITING_LIMIT = 16


def waiting(sub: Subscription[Any], limit: int = WAITING_LIMIT) -> Iterator[Any]:
    """Messages already queued on ``sub`` (up to ``limit``), taken the way the
    executor takes them. A stream callback that handles them in one go spares
    the executor a round per chunk: rclpy rebuilds its wait set in Python for
    every message it hands out, ~0.1 ms with a node's dozen entities."""
    handle = sub.handle
    take = getattr(handle, "take_message", None)
    if take is None:  # an rclpy without it: the executor hands them out
        return
    for _ in range(limit):
        try:
            with handle:
                got = take(sub.msg_type, sub.raw)
        except InvalidHandle:  # destroyed meanwhile (shutdown)
            return
        if got is None:
            return
        yield got[0]


STEPS_CDR = MultiArrayCodec(STEP_COLUMNS, np.int32)
TIMED_CDR = MultiArrayCodec(TIMED_COLUMNS, np.int64)


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
    names ``"<node>: <task>"``, a hardware id, key/value pairs. The node name
    includes its namespace (``cell1/sim_node: job``): /diagnostics is global,
    and two cells on one graph must stay tellable apart."""

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
            name=f"{self.node.get_fully_qualified_name().lstrip('/')}: {task}",
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


def descriptor(spec: Spec) -> ParameterDescriptor:
    """The ROS parameter descriptor of a winder setting. Typing is dynamic so
    that ``v_max:=3000`` (an integer) is accepted for a double; the checks in
    the set-parameters callback convert and validate every value."""
    kind = {
        bool: ParameterType.PARAMETER_BOOL,
        int: ParameterType.PARAMETER_INTEGER,
        float: ParameterType.PARAMETER_DOUBLE,
        str: ParameterType.PARAMETER_STRING,
    }[spec.kind]
    d = ParameterDescriptor(type=kind, description=spec.help(), dynamic_typing=True)
    if spec.low is not None and spec.high is not None:
        if spec.kind is float:
            d.floating_point_range = [
                FloatingPointRange(from_value=float(spec.low), to_value=float(spec.high), step=0.0)
            ]
        elif spec.kind is int:
            d.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high), step=1)]
    if spec.choices:
        d.additional_constraints = "one of: " + ", ".join(spec.choices)
    return d


class Settings:
    """A node's settings declared as ROS parameters from a winder spec table.

    A bad start-up override (``--ros-args -p name:=value``) is not fatal: it is
    logged with its reason and the default is kept, and :attr:`rejected` lists
    it; run-time changes go through the same checks and are refused with the
    reason. :meth:`values` returns the current values converted to their types.
    """

    def __init__(
        self,
        node: Node,
        specs: dict[str, Spec],
        check: Callable[[dict[str, Any]], None],
    ) -> None:
        self.node = node
        self.specs = specs
        self.check = check
        self.rejected: list[str] = []
        self._values: dict[str, Any] | None = None
        log = node.get_logger()
        for name, spec in specs.items():
            try:
                node.declare_parameter(name, spec.default, descriptor(spec))
            except (InvalidParameterValueException, InvalidParameterTypeException) as exc:
                log.error(f"{self._reason_for_override(name, exc)}; keeping the default {spec.default!r}")
                node.declare_parameter(name, spec.default, descriptor(spec), ignore_override=True)
                self.rejected.append(name)
                continue
            try:
                spec.check(node.get_parameter(name).value)
            except SpecError as exc:
                log.error(f"{exc}; keeping the default {spec.default!r}")
                node.set_parameters([Parameter(name, value=spec.default)])
                self.rejected.append(name)
        try:
            check(self.values())
        except SpecError as exc:
            log.error(f"settings rejected at start: {exc}")
            self.rejected.append(str(exc))
        node.add_on_set_parameters_callback(self._on_set)

    def _reason_for_override(self, name: str, exc: Exception) -> str:
        override = self.node._parameter_overrides.get(name)
        if override is not None:
            try:
                self.specs[name].check(override.value)
            except SpecError as err:
                return str(err)
        return f"{name}: {str(exc).splitlines()[0]}"

    def values(self) -> dict[str, Any]:
        """Current values, typed; cached until a parameter change is accepted."""
        if self._values is None:
            self._values = {n: s.check(self.node.get_parameter(n).value) for n, s in self.specs.items()}
        return self._values

    def _on_set(self, params: list[Parameter]) -> SetParametersResult:
        merged = {n: self.node.get_parameter(n).value for n in self.specs}
        try:
            for p in params:
                if p.name in self.specs:
                    merged[p.name] = self.specs[p.name].check(p.value)
            self.check({n: self.specs[n].check(v) for n, v in merged.items()})
        except SpecError as exc:
            self.node.get_logger().warning(f"parameter change rejected: {exc}")
            return SetParametersResult(successful=False, reason=str(exc))
        self._values = None  # the new values are in place once this returns
        # a start-up rejection is resolved once that parameter is set validly
        names = {p.name for p in params}
        self.rejected = [r for r in self.rejected if r in self.specs and r not in names]
        return SetParametersResult(successful=True)

    def blocked(self) -> str | None:
        """Why the node must not run a job: start-up values it had to refuse."""
        if self.rejected:
            return (
                f"settings rejected at start: {', '.join(self.rejected)}; "
                "set valid values (ros2 param set) to proceed"
            )
        return None


def spin(factory: Callable[[], Node], args: list[str] | None = None) -> None:
    """``main`` of every winder node: init, spin, and on Ctrl-C / SIGTERM /
    external shutdown run the node's ``shutdown()`` hook (close the bag) with
    further signals ignored, then destroy the node."""
    import signal

    import rclpy
    from rclpy._rclpy_pybind11 import RCLError
    from rclpy.executors import ExternalShutdownException

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
