"""Commands to a running cell from outside it (``winder ctl``), on the graph
of this process' ROS_DOMAIN_ID: the standard services every ROS 2 tool uses
(parameters, lifecycle, the interp node's ``~/start_run``) and the cell's
topics (``winder/state``, ``winder/ready``, ``/diagnostics``), so that the
pip install needs no ``ros2`` command.

Every wait is bounded: a :class:`Session` has a deadline, and what it did not
get in time raises :class:`UnansweredError` naming what it waited for. A node that
is not on the graph raises :class:`NoSuchNodeError` (with the nodes the graph
does show); a node that says no raises :class:`RefusedError` with its reason, in
one line. The command line (:mod:`winder.cli.ctl`) maps each to its exit
status.
"""

from __future__ import annotations

import os
import re
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

__all__ = [
    "CellView",
    "NoSuchNodeError",
    "RefusedError",
    "Session",
    "UnansweredError",
    "parameter_text",
    "set_parameter",
    "trigger",
]

#: s without a change of the graph after which a node it does not show, while
#: it shows others, is taken as not there (a mistyped name), before the timeout
DISCOVERY = 3.0


class UnansweredError(Exception):
    """Nothing came in time; the message names what was waited for."""


class NoSuchNodeError(Exception):
    """The node named is not on the graph; the message names the nodes that are."""


class RefusedError(Exception):
    """The node refused the request; the message is its reason, in one line."""


def one_line(text: str) -> str:
    lines = [s.strip() for s in str(text).splitlines() if s.strip()]
    return lines[0] if lines else ""


def node_name(name: str, namespace: str) -> str:
    """A node's fully qualified name: ``name`` as given when absolute, else in ``namespace``."""
    from winder.ros.graph import fully_qualified

    if name.startswith("/"):
        return "/" + name.strip("/")
    return fully_qualified(name.strip("/"), namespace)


class Session:
    """One rclpy context and node (``winder_ctl_<pid>``) for one command,
    with a deadline ``timeout`` s from now that every wait respects.
    A Ctrl-C while it waits is a KeyboardInterrupt."""

    def __init__(self, timeout: float) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor

        from winder.ros.dds import use_profile

        use_profile()
        self.timeout = timeout
        self.context = Context()
        rclpy.init(args=[], context=self.context)
        self.node = rclpy.create_node(f"winder_ctl_{os.getpid()}", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.started = time.monotonic()
        self.deadline = self.started + timeout

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        import rclpy

        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)

    def renew(self, timeout: float | None = None) -> None:
        """A new deadline, ``timeout`` (default: the session's) s from now."""
        self.deadline = time.monotonic() + (self.timeout if timeout is None else timeout)

    def spin(self, seconds: float) -> None:
        """Serve callbacks for up to ``seconds``; a Ctrl-C (rclpy shut the context down) raises."""
        from rclpy.executors import ExternalShutdownException

        try:
            self.executor.spin_once(timeout_sec=max(seconds, 0.0))
        except ExternalShutdownException:
            raise KeyboardInterrupt from None
        if not self.context.ok():
            raise KeyboardInterrupt

    def until(self, cond: Callable[[], bool], what: str, hint: str = "") -> None:
        """Spin until ``cond()``; :class:`UnansweredError` naming ``what`` (and
        the ``hint`` after it) at the deadline."""
        while not cond():
            left = self.deadline - time.monotonic()
            if left <= 0:
                raise UnansweredError(f"no {what} within {self.timeout:g} s{hint}")
            self.spin(min(left, 0.05))

    # -- the graph -------------------------------------------------------------------
    def nodes(self) -> list[str]:
        """The fully qualified names of the nodes this process sees, itself left out."""
        from winder.ros.graph import fully_qualified

        me = self.node.get_fully_qualified_name()
        seen = {fully_qualified(n, ns) for n, ns in self.node.get_node_names_and_namespaces()}
        return sorted(seen - {me})

    def find_node(self, fq: str) -> None:
        """Wait until the graph shows the node ``fq``. :class:`NoSuchNodeError` when
        it shows other nodes but not this one and has not changed for
        :data:`DISCOVERY` s (or at the deadline); :class:`UnansweredError` when
        it shows none at all. A new process learns a cell's node names one
        participant at a time, on a busy machine seconds apart: a verdict 2 s
        after the start called the interp node unknown while the
        graph was still filling (``nodes seen: /winder_cell``)."""
        last: list[str] = []
        changed = self.started
        while True:
            seen = self.nodes()
            if fq in seen:
                return
            now = time.monotonic()
            if seen != last:
                last, changed = seen, now
            if now > self.deadline or (seen and now - changed > DISCOVERY):
                if not seen:
                    raise UnansweredError(
                        f"no node {fq} within {self.timeout:g} s: the graph shows no node at all "
                        f"({graph_words()}): is the cell running there?"
                    )
                raise NoSuchNodeError(
                    f"no node {fq} on the graph ({graph_words()}); nodes seen: {', '.join(seen)}"
                )
            self.spin(0.05)

    def call(self, srv_type: Any, service: str, request: Any) -> Any:
        """One call of ``service``; the reply, or :class:`UnansweredError` naming
        the service (not on the graph) or the reply (not come) at the deadline."""
        client = self.node.create_client(srv_type, service)
        try:
            self.until(client.service_is_ready, f"service {service}", f" ({graph_words()})")
            future = client.call_async(request)
            self.until(future.done, f"reply from {service}")
            return future.result()
        finally:
            self.node.destroy_client(client)


def graph_words() -> str:
    """Which graph this process looks at, for messages."""
    domain = os.environ.get("ROS_DOMAIN_ID") or "0 (ROS_DOMAIN_ID not set)"
    return f"ROS_DOMAIN_ID={domain}"


# -- parameters ----------------------------------------------------------------------

_TYPE_WORDS = {
    1: "a bool",
    2: "an integer",
    3: "a double",
    4: "a string",
    5: "a byte array",
    6: "a bool array",
    7: "an integer array",
    8: "a double array",
    9: "a string array",
}


def parameter_text(value: Any) -> str:
    """An rcl_interfaces ParameterValue as text (as a parameters file would write it)."""
    from rclpy.parameter import parameter_value_to_python

    v = parameter_value_to_python(value)
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple)) or hasattr(v, "tolist"):
        items = v.tolist() if hasattr(v, "tolist") else list(v)
        return "[" + ", ".join(parameter_text_py(x) for x in items) + "]"
    return parameter_text_py(v)


def parameter_text_py(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    return str(v)


def range_words(descriptor: Any) -> str:
    """A descriptor's range as the winder specs write it (``[0.001, 1e+06]``), "" if none."""
    for r in (*descriptor.floating_point_range, *descriptor.integer_range):
        return f" in [{r.from_value:g}, {r.to_value:g}]"
    return ""


def parse_value(node: str, name: str, text: str, descriptor: Any) -> Any:
    """``text`` as the Python value to set for the parameter described by
    ``descriptor``: read as a ROS parameters file reads a scalar (``40`` an
    integer, ``1.5`` a double, ``true`` a bool, else a string; ``[a, b]`` a
    list), then made the declared type where that is what it stands for (an
    integer for a double, any text for a string). A value that cannot be the
    declared type is a ValueError naming the parameter, the value and the
    type and range it must have."""
    from winder.contract.jobfile import ros_scalar

    kind = int(descriptor.type)
    if kind == 4:  # a string: the text as typed
        return text
    stripped = text.strip()
    if stripped.startswith("[") and stripped.endswith("]"):
        inner = stripped[1:-1].strip()
        value: Any = [ros_scalar(part.strip()) for part in inner.split(",")] if inner else []
        if kind == 8:
            value = [float(v) if type(v) is int else v for v in value]
        if kind == 9:
            value = [str(v) for v in value]
    else:
        value = ros_scalar(stripped)
    if kind == 3 and type(value) is int:
        value = float(value)
    ok = {
        1: lambda v: type(v) is bool,
        2: lambda v: type(v) is int,
        3: lambda v: type(v) is float,
        6: lambda v: isinstance(v, list) and all(type(x) is bool for x in v),
        7: lambda v: isinstance(v, list) and all(type(x) is int for x in v),
        8: lambda v: isinstance(v, list) and all(type(x) is float for x in v),
        9: lambda v: isinstance(v, list),
    }.get(kind)
    if ok is not None and not ok(value) and not descriptor.dynamic_typing:
        must = _TYPE_WORDS.get(kind, "of its declared type")
        raise ValueError(f"{name}={text!r} is invalid: must be {must}{range_words(descriptor)} ({node})")
    return value


def describe(session: Session, node: str, names: list[str]) -> list[Any]:
    """The descriptors of ``names`` on ``node``; ValueError naming the first
    the node does not have."""
    from rcl_interfaces.srv import DescribeParameters, ListParameters

    reply = session.call(
        DescribeParameters, f"{node}/describe_parameters", DescribeParameters.Request(names=names)
    )
    if len(reply.descriptors) == len(names):
        return list(reply.descriptors)
    listed = session.call(ListParameters, f"{node}/list_parameters", ListParameters.Request())
    have = set(listed.result.names)
    missing = next((n for n in names if n not in have), names[0])
    raise ValueError(f"{node} has no parameter {missing!r} (winder ctl param list {node} names them)")


def get_parameter(session: Session, node: str, name: str) -> str:
    """The value of ``node``'s parameter ``name``, as text."""
    from rcl_interfaces.srv import GetParameters

    describe(session, node, [name])
    reply = session.call(GetParameters, f"{node}/get_parameters", GetParameters.Request(names=[name]))
    return parameter_text(reply.values[0])


def list_parameters(session: Session, node: str) -> list[tuple[str, str]]:
    """Every parameter of ``node``, sorted by name, with its value as text."""
    from rcl_interfaces.srv import GetParameters, ListParameters

    listed = session.call(ListParameters, f"{node}/list_parameters", ListParameters.Request())
    names = sorted(listed.result.names)
    reply = session.call(GetParameters, f"{node}/get_parameters", GetParameters.Request(names=names))
    return [(n, parameter_text(v)) for n, v in zip(names, reply.values, strict=False)]


def to_message(name: str, value: Any) -> Any:
    from rclpy.parameter import Parameter

    return Parameter(name, value=value).to_parameter_msg()


def set_parameters(session: Session, node: str, texts: dict[str, str]) -> dict[str, Any]:
    """Set ``node``'s parameters from the text of each value, converted to
    its declared type (:func:`parse_value`), all in one change
    (``set_parameters_atomically``); the values set. ValueError for a name the
    node does not have or a value that cannot be its type; :class:`RefusedError`
    with the node's reason."""
    from rcl_interfaces.srv import SetParametersAtomically

    names = list(texts)
    descriptors = describe(session, node, names)
    values = {n: parse_value(node, n, texts[n], d) for n, d in zip(names, descriptors, strict=True)}
    request = SetParametersAtomically.Request(parameters=[to_message(n, v) for n, v in values.items()])
    reply = session.call(SetParametersAtomically, f"{node}/set_parameters_atomically", request)
    if not reply.result.successful:
        raise RefusedError(one_line(reply.result.reason) or f"{', '.join(names)} refused (no reason given)")
    return values


# -- lifecycle -----------------------------------------------------------------------

LIFECYCLE_ACTIONS = ("configure", "activate", "deactivate", "cleanup", "shutdown")


def lifecycle_state(session: Session, node: str) -> str:
    from lifecycle_msgs.srv import GetState

    reply = session.call(GetState, f"{node}/get_state", GetState.Request())
    return str(reply.current_state.label)


def lifecycle_transition(session: Session, node: str, action: str) -> tuple[str, str]:
    """Take ``node`` through the transition ``action`` (its label; any of
    the shutdown transitions for ``shutdown``); (state before, state after).
    ValueError if the node's state has no such transition (the node is
    untouched); :class:`RefusedError` if the node refused it."""
    from lifecycle_msgs.srv import ChangeState, GetAvailableTransitions

    before = lifecycle_state(session, node)
    reply = session.call(
        GetAvailableTransitions, f"{node}/get_available_transitions", GetAvailableTransitions.Request()
    )
    available = [t.transition for t in reply.available_transitions]
    labels = [t.label for t in available]
    match = [
        t for t in available if t.label == action or (action == "shutdown" and t.label.endswith("shutdown"))
    ]
    if not match:
        can = ", ".join(dict.fromkeys(labels)) or "none"
        raise ValueError(f"{node} cannot {action} from its state {before!r} (transitions from there: {can})")
    request = ChangeState.Request()
    request.transition.id = match[0].id
    done = session.call(ChangeState, f"{node}/change_state", request)
    after = lifecycle_state(session, node)
    if not done.success:
        raise RefusedError(f"{node} refused {action}: it stays {after!r} (the node's log says why)")
    return before, after


# -- starting a run --------------------------------------------------------------------

#: the start replies that mean "ask again": a node of the cell is still connecting
NOT_READY = "job not started: not ready"
#: states on winder/ready that asking again does not change (an orchestrator's, or a setting's)
LASTING = (" inactive", " blocked")


def find_role(session: Session, namespace: str, role: str, what: str) -> str:
    """The fully qualified name of the one node in ``namespace`` that plays
    ``role`` on the graph (:mod:`winder.ros.graph`), waited for."""
    from winder.ros.graph import fully_qualified, role_holders

    me = (session.node.get_name(), session.node.get_namespace())
    found: list[tuple[str, str]] = []

    def one() -> bool:
        nonlocal found
        found = sorted({(w.name, w.namespace) for w in role_holders(session.node, namespace, role)} - {me})
        return len(found) == 1

    try:
        session.until(one, f"{what} in {namespace or '/'}")
    except UnansweredError as exc:
        if len(found) > 1:
            names = ", ".join(fully_qualified(*f) for f in found)
            raise UnansweredError(f"{exc}: the graph shows {len(found)} ({names})") from None
        raise UnansweredError(f"{exc} ({graph_words()}): is the cell running there?") from None
    return fully_qualified(*found[0])


def start_run(session: Session, interp: str, values: dict[str, Any]) -> str:
    """Call ``interp``'s ``~/start_run`` with ``values`` (typed already; none:
    its ``~/start``, the run with the settings as they are), again while the
    cell says it is not ready, until the deadline; the start reply (``run
    <id> started: ...``). :class:`RefusedError` with the reply otherwise."""
    from rcl_interfaces.srv import SetParametersAtomically
    from std_srvs.srv import Trigger

    request = SetParametersAtomically.Request(parameters=[to_message(n, v) for n, v in values.items()])
    while True:
        if values:
            reply = session.call(SetParametersAtomically, f"{interp}/start_run", request)
            ok, reason = bool(reply.result.successful), one_line(reply.result.reason)
        else:  # start_run refuses an empty change (rclpy: "parameter list cannot be empty")
            answer = session.call(Trigger, f"{interp}/start", Trigger.Request())
            ok, reason = bool(answer.success), one_line(answer.message)
        if ok:
            return reason
        lasting = any(word in reason for word in LASTING)
        if not reason.startswith(NOT_READY) or lasting or time.monotonic() + 0.5 > session.deadline:
            raise RefusedError(reason or "start refused (no reason given)")
        session.spin(0.5)


RUN_ID = re.compile(r"run (\S+) started")


# -- the cell's state ------------------------------------------------------------------


@dataclass
class NodeStatus:
    name: str  #: the status name, ``cell1/sim_node: job``
    values: dict[str, str]
    message: str


@dataclass
class CellView:
    """What a cell says of itself, as heard so far: ``winder/state``, the
    roles' ``winder/ready`` and each node's job status on ``/diagnostics``."""

    namespace: str
    state: dict[str, str] = field(default_factory=dict)
    ready: dict[str, str] = field(default_factory=dict)
    statuses: dict[str, NodeStatus] = field(default_factory=dict)
    changed: int = 0  #: counts what was heard

    def roles(self) -> dict[str, NodeStatus]:
        """The job status of each role heard (interp, profile, consumer)."""
        from winder.contract.topics import ROLES, has_role

        out = {}
        for st in self.statuses.values():
            for role in ROLES:
                if role not in out and has_role(st.name, st.values, role, self.namespace):
                    out[role] = st
        return out

    def heard(self) -> bool:
        return bool(self.state or self.statuses)

    def complete(self) -> bool:
        """Every role's job status, ``winder/state`` and both roles' ``winder/ready``
        heard (latched messages of two publishers come at different times)."""
        from winder.contract.topics import READY_ROLES

        return len(self.roles()) == 3 and bool(self.state) and all(r in self.ready for r in READY_ROLES)


def watch_cell(session: Session, namespace: str) -> CellView:
    """Subscribe to the cell's state topics; the view they fill while the session spins."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from winder.contract.topics import TASK_JOB, TOPIC_DIAGNOSTICS, TOPIC_READY, TOPIC_STATE, in_namespace
    from winder.ros.graph import fully_qualified
    from winder.ros.qos import QOS_DIAGNOSTICS

    view = CellView(namespace)
    latched = QoSProfile(
        depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )

    def on_state(msg: DiagnosticStatus) -> None:
        view.state = {kv.key: kv.value for kv in msg.values}
        view.changed += 1

    def on_ready(msg: KeyValue) -> None:
        view.ready[msg.key] = msg.value
        view.changed += 1

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for st in msg.status:
            if st.name.endswith(f": {TASK_JOB}") and in_namespace(st.name, namespace):
                values = {kv.key: kv.value for kv in st.values}
                view.statuses[st.name] = NodeStatus(st.name, values, st.message)
                view.changed += 1

    node = session.node
    node.create_subscription(DiagnosticStatus, fully_qualified(TOPIC_STATE, namespace), on_state, latched)
    node.create_subscription(KeyValue, fully_qualified(TOPIC_READY, namespace), on_ready, latched)
    node.create_subscription(DiagnosticArray, TOPIC_DIAGNOSTICS, on_diagnostics, QOS_DIAGNOSTICS)
    return view


#: s a state query listens on after it first hears the cell, for the nodes' 1 Hz statuses
LISTEN = 2.5


def cell_state(session: Session, namespace: str) -> CellView:
    """The cell's state as heard within the deadline: every role's status
    and ``winder/state``, or what came within :data:`LISTEN` s of the first."""
    view = watch_cell(session, namespace)
    from winder.contract.topics import TOPIC_STATE
    from winder.ros.graph import fully_qualified

    what = (
        f"state from the cell in {namespace or '/'} ({fully_qualified(TOPIC_STATE, namespace)}, and the "
        "nodes' job statuses on /diagnostics)"
    )
    session.until(view.heard, what, f" ({graph_words()}): is the cell running there?")
    end = min(session.deadline, time.monotonic() + LISTEN)
    while not view.complete() and time.monotonic() < end:
        session.spin(min(0.05, end - time.monotonic()))
    return view


def follow(session: Session, view: CellView) -> Iterator[int]:
    """Spin on, yielding ``view.changed`` each time something new was heard (Ctrl-C ends it)."""
    last = view.changed
    while True:
        session.spin(0.1)
        if view.changed != last:
            last = view.changed
            yield last


# -- the services winder ctl had before (pause, resume, abort, override) ----------------------


def trigger(service: str, timeout: float = 10.0) -> tuple[bool, str]:
    """Call the std_srvs/Trigger ``service``; (success, message). No service
    within ``timeout`` s is (False, why)."""
    from std_srvs.srv import Trigger

    with Session(timeout) as session:
        try:
            reply = session.call(Trigger, service, Trigger.Request())
        except UnansweredError as exc:
            return False, f"{exc}: is the cell running there?"
    return bool(reply.success), str(reply.message)


def set_parameter(node: str, name: str, value: float, timeout: float = 10.0) -> tuple[bool, str]:
    """Set the double parameter ``name`` of the node ``node`` (its fully
    qualified name) through its ``set_parameters`` service; (success, the
    node's reason or a confirmation)."""
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    value_msg = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=float(value))
    request = SetParameters.Request(parameters=[Parameter(name=name, value=value_msg)])
    with Session(timeout) as session:
        try:
            reply = session.call(SetParameters, f"{node}/set_parameters", request)
        except UnansweredError as exc:
            return False, f"{exc}: is the cell running there?"
    result = reply.results[0]
    if not result.successful:
        return False, result.reason or f"{name} refused"
    return True, f"{node}: {name} = {value:g}"
