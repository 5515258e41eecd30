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

A command is answered as soon as what it needs has come, not after a fixed
time: a service call goes out the moment the service shows on the graph
(looked at every :data:`GRAPH_POLL` s: discovery changes the graph without
waking the executor), its clients made before discovery ends, so that the
cell's nodes learn of them in the same exchange; a state query ends when
each node the graph shows in the cell has been heard. Only the verdict that
something is not there waits for the graph to settle: a newcomer learns of
the cell's processes within a few DDS announcement periods
(:data:`winder.ros.dds.ANNOUNCEMENT`).
"""

from __future__ import annotations

import contextlib
import os
import re
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

from winder.contract.states import asks_again
from winder.contract.topics import ACTION_WIND
from winder.errors import BadInputError, RefusedError, UnavailableError
from winder.ros.dds import ANNOUNCEMENT

__all__ = [
    "CellView",
    "NoSuchNodeError",
    "NodeStatus",
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
#: s between two looks at the graph while a wait depends on it (a service
#: matching, a node's name): a look reads rmw's graph cache, nothing is sent
GRAPH_POLL = 0.01
#: s after which a request that only reads (a parameter, a lifecycle state) is
#: sent again when no reply came: rmw_fastrtps drops a reply whose client's
#: reply reader the server has not matched 100 ms after it answers, which a
#: loaded machine can take longer to do. A request that changes the cell is
#: never sent twice.
RESEND = 1.0


class UnansweredError(UnavailableError):
    """Nothing came in time; the message names what was waited for."""


class NoSuchNodeError(UnavailableError):
    """The node named is not on the graph; the message names the nodes that are."""


# RefusedError (winder.errors): the node refused the request; the message is its reason, in one line


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
        self.clients: dict[str, Any] = {}
        self.actions: dict[str, Any] = {}

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        import rclpy

        self.executor.shutdown(timeout_sec=1.0)
        for client in self.actions.values():  # an action client holds the node's handle: it goes first
            client.destroy()
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
        """Spin until ``cond()`` (looked at after every callback, and every
        :data:`GRAPH_POLL` s); :class:`UnansweredError` naming ``what`` (and
        the ``hint`` after it) at the deadline."""
        while not cond():
            left = self.deadline - time.monotonic()
            if left <= 0:
                raise UnansweredError(f"no {what} within {self.timeout:g} s{hint}")
            self.spin(min(left, GRAPH_POLL))

    def action_client(self, action_type: Any, action: str) -> Any:
        """The session's client of the action ``action`` (made once, as :meth:`client`)."""
        if action not in self.actions:
            from rclpy.action.client import ActionClient

            self.actions[action] = ActionClient(self.node, action_type, action)
        return self.actions[action]

    def client(self, srv_type: Any, service: str) -> Any:
        """The session's client of ``service`` (made once: make it early, and
        discovery matches it while the session waits for other things)."""
        if service not in self.clients:
            self.clients[service] = self.node.create_client(srv_type, service)
        return self.clients[service]

    # -- the graph -------------------------------------------------------------------
    def nodes(self) -> list[str]:
        """The fully qualified names of the nodes this process sees, itself left out."""
        from winder.ros.graph import fully_qualified

        me = self.node.get_fully_qualified_name()
        seen = {fully_qualified(n, ns) for n, ns in self.node.get_node_names_and_namespaces()}
        return sorted(seen - {me})

    def shows(self, fq: str) -> bool:
        """Whether the graph shows the node ``fq``: its name, or a service of
        it that a client of this session sees served (an endpoint can come
        before the name: either is enough to call it)."""
        if fq in self.nodes():
            return True
        prefix = fq.rstrip("/") + "/"
        return any(c.service_is_ready() for name, c in self.clients.items() if name.startswith(prefix))

    def find_node(self, fq: str) -> None:
        """Wait until the graph shows the node ``fq`` (:meth:`shows`).
        :class:`NoSuchNodeError` when it shows other nodes but not this one
        and has not changed for :data:`DISCOVERY` s (or at the deadline);
        :class:`UnansweredError` when it shows none at all. A new process
        learns a cell's node names one participant at a time, on a busy
        machine seconds apart: a verdict 2 s after the start called the
        interp node unknown while the graph was still filling (``nodes
        seen: /winder_cell``). Only that verdict waits for the graph to
        settle; a node that is there is taken the moment it shows."""
        last: list[str] = []
        changed = self.started
        while True:
            if self.shows(fq):
                return
            seen = self.nodes()
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
            self.spin(GRAPH_POLL)

    def call(self, srv_type: Any, service: str, request: Any, *, reads: bool = False) -> Any:
        """One call of ``service``, made the moment the service shows; the
        reply, or :class:`UnansweredError` naming the service (not on the
        graph) or the reply (not come) at the deadline. A request that only
        ``reads`` is sent again when its reply has not come in :data:`RESEND` s
        (the first reply to come is taken)."""
        client = self.client(srv_type, service)
        self.until(client.service_is_ready, f"service {service}", f" ({graph_words()})")
        futures = [client.call_async(request)]
        sent = time.monotonic()

        def answered() -> bool:
            nonlocal sent
            if reads and time.monotonic() - sent > RESEND:
                futures.append(client.call_async(request))
                sent = time.monotonic()
            return any(f.done() for f in futures)

        self.until(answered, f"reply from {service}")
        reply = next(f for f in futures if f.done()).result()
        for f in futures:
            if not f.done():
                client.remove_pending_request(f)
        return reply


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
        raise BadInputError(f"{name}={text!r} is invalid: must be {must}{range_words(descriptor)} ({node})")
    return value


def parameter_clients(session: Session, node: str) -> None:
    """Make the session's clients of ``node``'s parameter services now, so
    that discovery matches them all while the command waits for the node."""
    from rcl_interfaces.srv import DescribeParameters, GetParameters, ListParameters, SetParametersAtomically

    for srv_type, name in (
        (DescribeParameters, "describe_parameters"),
        (GetParameters, "get_parameters"),
        (ListParameters, "list_parameters"),
        (SetParametersAtomically, "set_parameters_atomically"),
    ):
        session.client(srv_type, f"{node}/{name}")


def describe(session: Session, node: str, names: list[str]) -> list[Any]:
    """The descriptors of ``names`` on ``node``; ValueError naming the first
    the node does not have."""
    from rcl_interfaces.srv import DescribeParameters, ListParameters

    reply = session.call(
        DescribeParameters, f"{node}/describe_parameters", DescribeParameters.Request(names=names), reads=True
    )
    if len(reply.descriptors) == len(names):
        return list(reply.descriptors)
    listed = session.call(ListParameters, f"{node}/list_parameters", ListParameters.Request(), reads=True)
    have = set(listed.result.names)
    missing = next((n for n in names if n not in have), names[0])
    raise BadInputError(f"{node} has no parameter {missing!r} (winder ctl param list {node} names them)")


def get_parameter(session: Session, node: str, name: str) -> str:
    """The value of ``node``'s parameter ``name``, as text."""
    from rcl_interfaces.srv import GetParameters

    describe(session, node, [name])
    request = GetParameters.Request(names=[name])
    reply = session.call(GetParameters, f"{node}/get_parameters", request, reads=True)
    return parameter_text(reply.values[0])


def list_parameters(session: Session, node: str) -> list[tuple[str, str]]:
    """Every parameter of ``node``, sorted by name, with its value as text."""
    from rcl_interfaces.srv import GetParameters, ListParameters

    listed = session.call(ListParameters, f"{node}/list_parameters", ListParameters.Request(), reads=True)
    names = sorted(listed.result.names)
    request = GetParameters.Request(names=names)
    reply = session.call(GetParameters, f"{node}/get_parameters", request, reads=True)
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


def lifecycle_clients(session: Session, node: str) -> None:
    """Make the session's clients of ``node``'s lifecycle services now (see
    :func:`parameter_clients`)."""
    from lifecycle_msgs.srv import ChangeState, GetAvailableTransitions, GetState

    session.client(GetState, f"{node}/get_state")
    session.client(GetAvailableTransitions, f"{node}/get_available_transitions")
    session.client(ChangeState, f"{node}/change_state")


def lifecycle_state(session: Session, node: str) -> str:
    from lifecycle_msgs.srv import GetState

    reply = session.call(GetState, f"{node}/get_state", GetState.Request(), reads=True)
    return str(reply.current_state.label)


def lifecycle_transition(session: Session, node: str, action: str) -> tuple[str, str]:
    """Take ``node`` through the transition ``action`` (its label; any of
    the shutdown transitions for ``shutdown``); (state before, state after).
    ValueError if the node's state has no such transition (the node is
    untouched); :class:`RefusedError` if the node refused it."""
    from lifecycle_msgs.srv import ChangeState, GetAvailableTransitions

    before = lifecycle_state(session, node)
    reply = session.call(
        GetAvailableTransitions,
        f"{node}/get_available_transitions",
        GetAvailableTransitions.Request(),
        reads=True,
    )
    available = [t.transition for t in reply.available_transitions]
    labels = [t.label for t in available]
    match = [
        t for t in available if t.label == action or (action == "shutdown" and t.label.endswith("shutdown"))
    ]
    if not match:
        can = ", ".join(dict.fromkeys(labels)) or "none"
        raise BadInputError(
            f"{node} cannot {action} from its state {before!r} (transitions from there: {can})"
        )
    request = ChangeState.Request()
    request.transition.id = match[0].id
    done = session.call(ChangeState, f"{node}/change_state", request)
    after = lifecycle_state(session, node)
    if not done.success:
        raise RefusedError(f"{node} refused {action}: it stays {after!r} (the node's log says why)")
    return before, after


# -- starting a run --------------------------------------------------------------------


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


#: s after a "not ready" reply before a start is asked again, when no
#: ``winder/ready`` message came meanwhile (one that comes asks again at once)
NOT_READY_RETRY = 0.5
#: s a canceled goal's end is waited for, past the deadline: its reason
CANCEL_WAIT = 3.0


def wind_action(interp: str) -> str:
    """The Wind action of the cell whose interp node is ``interp`` (fully qualified)."""
    namespace = interp.rsplit("/", 1)[0]
    return f"{namespace}/{ACTION_WIND}"


def start_clients(session: Session, interp: str) -> None:
    """Make the session's client of ``interp``'s cell's Wind action now (see
    :func:`parameter_clients`); the stock name's before the graph has said
    which node is the interp node."""
    from winder_interfaces.action import Wind

    session.action_client(Wind, wind_action(interp))


def goal_text(value: Any) -> str:
    """A setting as a Wind goal's ``KEY=VALUE`` override says it (the node parses it by its type)."""
    return ("true" if value else "false") if isinstance(value, bool) else str(value)


def _one_goal(session: Session, client: Any, action: str, goal: Any) -> tuple[str, str]:
    """Send one Wind goal: (the start reply, "") once its run started, or
    ("", the cell's reason) if it ended first. At the deadline the goal, still
    waiting for the cell, is canceled and its reason raised (RefusedError)."""
    started: list[Any] = []
    sent = client.send_goal_async(goal, feedback_callback=lambda m: started.append(m.feedback))
    session.until(sent.done, f"reply from {action} to the goal")
    handle = sent.result()
    if not handle.accepted:
        raise RefusedError(f"{action}: goal rejected")
    result = handle.get_result_async()
    try:
        session.until(lambda: result.done() or any(f.run_id for f in started), "start of the goal's run")
    except UnansweredError:
        handle.cancel_goal_async()  # still waiting for the cell: it stops waiting
        with contextlib.suppress(UnansweredError):
            session.renew(CANCEL_WAIT)
            session.until(result.done, "end of the canceled goal")
        reason = one_line(result.result().result.message) if result.done() else ""
        if reason:
            raise RefusedError(f"{reason} (still, after {session.timeout:g} s)") from None
        raise
    first = next((f for f in started if f.run_id), None)
    if first is not None:
        return f"run {first.run_id} started: {first.steps_total} steps", ""
    ended = result.result().result
    if ended.run_id:  # the run started and ended before its first feedback came (as fast as possible)
        return f"run {ended.run_id} started: {ended.report.steps_total} steps", ""
    return "", one_line(ended.message)


def start_run(session: Session, interp: str, values: dict[str, Any], view: CellView | None = None) -> str:
    """Send ``interp``'s cell a Wind goal with ``values`` as its overrides
    (typed already; none: the run with the settings as they are), again
    while the cell says it is not ready (at the next ``winder/ready``
    message ``view`` hears, or after :data:`NOT_READY_RETRY` s), until the
    deadline; the start reply (``run <id> started: ...``) once the goal's
    run started (its first feedback). The goal goes on when the session
    ends: the run is the cell's. :class:`RefusedError` with the cell's
    reason otherwise; a goal still waiting for the cell at the deadline is
    canceled."""
    from winder_interfaces.action import Wind

    action = wind_action(interp)
    client = session.action_client(Wind, action)
    session.until(client.server_is_ready, f"action server {action}", f" ({graph_words()})")
    goal = Wind.Goal(overrides=[f"{k}={goal_text(v)}" for k, v in values.items()])
    while True:
        reply, reason = _one_goal(session, client, action, goal)
        if reply:
            return reply
        if not asks_again(reason):
            raise RefusedError(reason or "start refused (no reason given)")
        if time.monotonic() + 0.1 > session.deadline:
            raise RefusedError(f"{reason} (still, after {session.timeout:g} s)")
        asked = time.monotonic()
        said = dict(view.ready_ns) if view is not None else {}
        while time.monotonic() - asked < NOT_READY_RETRY and time.monotonic() < session.deadline:
            if view is not None and view.ready_ns != said:
                break  # a role said something new: ask again now
            session.spin(GRAPH_POLL)


RUN_ID = re.compile(r"run (\S+) started")


# -- the cell's state ------------------------------------------------------------------

#: s after which a message the cell repeats every second (a node's job
#: status, a role's winder/ready) is overdue: its node is silent, held up or
#: killed and not yet timed out of the graph (winder/ready's own rule: 3 s)
SILENT = 3.0
#: s a state query listens on after it first hears the cell, at most: the
#: bound for a node the graph shows that says nothing (a held-up process)
LISTEN = 2.5
#: s a node's job status is young enough to be its last: the nodes send one
#: every second, so an older one has a newer one coming (a node keeps its
#: last ten for a reader that joins, and they come oldest first)
FRESH = 1.5
#: s the graph must stay unchanged before a part of the cell it does not show
#: is taken as not there: a newcomer learns of every process within one of
#: their announcement periods (:data:`winder.ros.dds.ANNOUNCEMENT`); the rest
#: is margin for a loaded machine. Only a cell with a part missing waits for it.
SETTLE = 4 * ANNOUNCEMENT


def sent_ns(info: Any) -> int:
    """When a message was sent: its source timestamp (the sender's wall
    clock, ns) from rclpy's message info; now when it has none."""
    try:
        t = int(info["source_timestamp"])
    except (KeyError, TypeError, ValueError):
        t = 0
    return t if t > 0 else time.time_ns()


def node_of(status_name: str) -> str:
    """The fully qualified node a status name speaks for: ``/cell1/sim_node``
    for ``cell1/sim_node: job``."""
    return "/" + status_name.split(":", 1)[0].strip("/")


def age_s(sent: int, now_ns: int) -> float:
    """Seconds since ``sent`` (wall-clock ns), never below 0 (a sender's clock a little ahead)."""
    return max(0.0, (now_ns - sent) / 1e9)


@dataclass
class NodeStatus:
    name: str  #: the status name, ``cell1/sim_node: job``
    values: dict[str, str]
    message: str
    sent_ns: int = 0  #: when its node sent it (the sender's wall clock, ns; 0 not known)

    @property
    def node(self) -> str:
        return node_of(self.name)


@dataclass
class CellView:
    """What a cell says of itself, as heard so far: ``winder/state``, the
    roles' ``winder/ready`` and each node's job status on ``/diagnostics``,
    each with when it was sent; and what the graph shows of the cell (its
    node names, the node in each role), looked at with :func:`look`."""

    namespace: str
    state: dict[str, str] = field(default_factory=dict)
    ready: dict[str, str] = field(default_factory=dict)
    statuses: dict[str, NodeStatus] = field(default_factory=dict)
    changed: int = 0  #: counts what was heard, and each change of the graph
    state_ns: int = 0  #: when winder/state was sent
    state_by: str = ""  #: the node that sent it (its status name says)
    ready_ns: dict[str, int] = field(default_factory=dict)  #: when each role's winder/ready was sent
    graph: set[str] | None = None  #: the nodes the graph showed at the last look (None: not looked yet)
    holders: dict[str, set[str]] = field(default_factory=dict)  #: the nodes it showed in each role
    graph_changed: float = field(default_factory=time.monotonic)  #: when the graph last changed

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

    def gone(self, node: str) -> bool:
        """Whether the node ``node``, heard from, is no longer on the graph:
        its process ended, or was killed and its DDS lease ran out."""
        return bool(node) and self.graph is not None and node not in self.graph

    @staticmethod
    def age(sent: int, now_ns: int) -> float:
        """Seconds since ``sent`` (:func:`age_s`)."""
        return age_s(sent, now_ns)

    def silent(self, sent: int, now_ns: int) -> bool:
        """Whether a message the cell repeats every second, sent at ``sent``, is overdue (:data:`SILENT`)."""
        return age_s(sent, now_ns) > SILENT

    def ready_by(self, role: str) -> str:
        """The node that says ``role``'s winder/ready: the one whose job status
        names the role, else the one the graph shows in it ("" if none)."""
        st = self.roles().get(role)
        if st is not None:
            return st.node
        held = sorted(self.holders.get(role, ()))
        return held[0] if len(held) == 1 else ""

    def ready_gone(self, role: str) -> bool:
        """Whether the node that said ``role``'s winder/ready has left the graph."""
        by = self.ready_by(role)
        if by:
            return self.gone(by)
        return self.graph is not None and not self.holders.get(role)

    def awaited(self, now_ns: int | None = None) -> list[str]:
        """What the graph shows of the cell that has not been heard yet; and
        each job status older than :data:`FRESH` at ``now_ns`` (wall clock):
        a newer one is on its way (the older ones a node keeps for a reader
        that joins come first), or the node is held up."""
        from winder.contract.topics import READY_ROLES, ROLES

        now_ns = time.time_ns() if now_ns is None else now_ns

        roles = self.roles()
        out = [
            f"the job status of {', '.join(sorted(self.holders[role]))}"
            for role in ROLES
            if role not in roles and self.holders.get(role)
        ]
        if not self.state and self.holders.get("consumer"):
            out.append("winder/state")
        out += [f"the {r}'s winder/ready" for r in READY_ROLES if r not in self.ready and self.holders.get(r)]
        heard = {st.node for st in self.statuses.values()} | ({self.state_by} if self.state_by else set())
        if self.graph is not None:
            out += [f"{n} on the graph" for n in sorted(heard - self.graph)]
        out += [
            f"a newer status of {st.node}"
            for st in self.statuses.values()
            if age_s(st.sent_ns, now_ns) > FRESH and not self.gone(st.node)
        ]
        return out

    def settled(self, now: float, now_ns: int | None = None) -> bool:
        """Whether a state query has heard what there is to hear (at ``now``,
        monotonic, and ``now_ns``, wall clock): every node heard is on the
        graph (an endpoint's message can come before its node's name), its
        status fresh, and the cell complete; or, with a part missing, the
        graph has not changed for :data:`SETTLE` s and everything it shows of
        the cell has been heard."""
        if self.graph is None or self.awaited(now_ns):
            return False
        return self.complete() or now - self.graph_changed >= SETTLE


def look(session: Session, view: CellView) -> None:
    """Update what ``view`` knows of the graph: its nodes, and the cell's node in each role."""
    from winder.contract.topics import ROLES
    from winder.ros.graph import role_holders

    me = session.node.get_fully_qualified_name()
    nodes = set(session.nodes())
    holders = {r: {w.fq for w in role_holders(session.node, view.namespace, r)} - {me} for r in ROLES}
    if nodes != view.graph or holders != view.holders:
        view.graph, view.holders = nodes, holders
        view.graph_changed = time.monotonic()
        view.changed += 1


def watch_cell(session: Session, namespace: str, *, statuses: bool = True) -> CellView:
    """Subscribe to the cell's state topics; the view they fill while the
    session spins. /diagnostics is read twice: transient-local, for the
    statuses winder's nodes keep for a newcomer (each node's last ones, at
    once), and volatile, for a node that keeps none (a third-party consumer).
    Without ``statuses``, only winder/state and winder/ready (a start that
    follows nothing)."""
    from diagnostic_msgs.msg import DiagnosticArray, KeyValue
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from winder.contract.topics import (
        TASK_JOB,
        TOPIC_DIAGNOSTICS,
        TOPIC_READY,
        TOPIC_STATE,
        cell_state_values,
        in_namespace,
    )
    from winder.ros.diagnostics import QOS_DIAGNOSTICS_KEPT
    from winder.ros.graph import fully_qualified
    from winder.ros.qos import QOS_DIAGNOSTICS
    from winder_interfaces.msg import CellState

    view = CellView(namespace)
    latched = QoSProfile(
        depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )

    def on_state(msg: CellState, info: Any) -> None:
        view.state = cell_state_values(msg)
        view.state_ns = sent_ns(info)
        view.state_by = node_of(msg.node) if msg.node else ""
        view.changed += 1

    def on_ready(msg: KeyValue, info: Any) -> None:
        view.ready[msg.key] = msg.value
        view.ready_ns[msg.key] = sent_ns(info)
        view.changed += 1

    def on_diagnostics(msg: DiagnosticArray, info: Any) -> None:
        t = sent_ns(info)
        for st in msg.status:
            if st.name.endswith(f": {TASK_JOB}") and in_namespace(st.name, namespace):
                known = view.statuses.get(st.name)
                if known is not None and known.sent_ns >= t:
                    continue  # the other reader's copy, or an older one kept for newcomers
                values = {kv.key: kv.value for kv in st.values}
                view.statuses[st.name] = NodeStatus(st.name, values, st.message, t)
                view.changed += 1

    # rclpy hands a callback of two arguments the message's info too (its
    # source timestamp: when it was sent); its type hints know only one
    subscribe: Any = session.node.create_subscription
    subscribe(CellState, fully_qualified(TOPIC_STATE, namespace), on_state, latched)
    subscribe(KeyValue, fully_qualified(TOPIC_READY, namespace), on_ready, latched)
    if statuses:
        subscribe(DiagnosticArray, TOPIC_DIAGNOSTICS, on_diagnostics, QOS_DIAGNOSTICS_KEPT)
        subscribe(DiagnosticArray, TOPIC_DIAGNOSTICS, on_diagnostics, QOS_DIAGNOSTICS)
    return view


def cell_state(session: Session, namespace: str) -> CellView:
    """The cell's state, as soon as it is all heard (:meth:`CellView.settled`):
    every role's status, ``winder/state`` and the ready messages of the
    nodes the graph shows in the cell, and each of those nodes named on the
    graph; at most :data:`LISTEN` s after the cell was first heard."""
    view = watch_cell(session, namespace)
    from winder.contract.topics import TOPIC_STATE
    from winder.ros.graph import fully_qualified

    what = (
        f"state from the cell in {namespace or '/'} ({fully_qualified(TOPIC_STATE, namespace)}, and the "
        "nodes' job statuses on /diagnostics)"
    )

    def heard() -> bool:
        look(session, view)
        return view.heard()

    session.until(heard, what, f" ({graph_words()}): is the cell running there?")
    end = min(session.deadline, time.monotonic() + LISTEN)
    while time.monotonic() < end:
        look(session, view)
        if view.settled(time.monotonic()):
            break
        session.spin(min(GRAPH_POLL, end - time.monotonic()))
    look(session, view)
    return view


#: s between two looks at the graph while ``winder ctl state --watch`` follows the cell
WATCH_LOOK = 0.25


def follow(session: Session, view: CellView) -> Iterator[int]:
    """Spin on, looking at the graph every :data:`WATCH_LOOK` s; yields
    ``view.changed`` after each look and each new message (Ctrl-C ends it),
    so that the caller also sees a node fall silent or leave the graph."""
    looked = time.monotonic()
    while True:
        session.spin(WATCH_LOOK)
        now = time.monotonic()
        if now - looked >= WATCH_LOOK:
            looked = now
            look(session, view)
        yield view.changed


# -- the operator commands (pause, resume, abort, override) ---------------------------------
# Each is one call, sent the moment the profile node's service shows: nothing
# else is waited for (not the node's name, not the cell's state).


def trigger(service: str, timeout: float = 10.0, session: Session | None = None) -> tuple[bool, str]:
    """Call the std_srvs/Trigger ``service`` (in ``session``, else in a
    session of its own); (success, message). No service within ``timeout``
    s is (False, why)."""
    from std_srvs.srv import Trigger

    with contextlib.nullcontext(session) if session is not None else Session(timeout) as s:
        try:
            reply = s.call(Trigger, service, Trigger.Request())
        except UnansweredError as exc:
            return False, f"{exc}: is the cell running there?"
    return bool(reply.success), str(reply.message)


def set_parameter(
    node: str, name: str, value: float, timeout: float = 10.0, session: Session | None = None
) -> tuple[bool, str]:
    """Set the double parameter ``name`` of the node ``node`` (its fully
    qualified name) through its ``set_parameters`` service (in ``session``,
    else in a session of its own); (success, the node's reason or a confirmation)."""
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    value_msg = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=float(value))
    request = SetParameters.Request(parameters=[Parameter(name=name, value=value_msg)])
    with contextlib.nullcontext(session) if session is not None else Session(timeout) as s:
        try:
            reply = s.call(SetParameters, f"{node}/set_parameters", request)
        except UnansweredError as exc:
            return False, f"{exc}: is the cell running there?"
    result = reply.results[0]
    if not result.successful:
        return False, result.reason or f"{name} refused"
    return True, f"{node}: {name} = {value:g}"
