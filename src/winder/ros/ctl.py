"""Commands to a running cell from outside it (``winder ctl``), on the graph
of this process' ROS_DOMAIN_ID: the standard services every ROS 2 tool uses
(parameters, lifecycle, the interp node's ``~/start_run``) and the cell's
topics (``winder/state``, ``winder/ready``, ``/diagnostics``), so that the
pip install needs no ``ros2`` command. What it reads of the cell it takes
from the cell's own nodes only, each message's sender as the graph names it
(:meth:`Session.peers`, docs/SECURITY.md).

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
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

from winder.contract.jobfile import goal_sha256
from winder.contract.states import asks_again
from winder.contract.topics import ACTION_WIND
from winder.errors import BadInputError, RefusedError, UnavailableError
from winder.ros.dds import ANNOUNCEMENT

__all__ = [
    "CellView",
    "Goal",
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
    A Ctrl-C while it waits is a KeyboardInterrupt. Its executor takes the
    messages of an :func:`winder.ros.sender.attributed` subscription with
    their publishers (:meth:`peers` judges them)."""

    def __init__(self, timeout: float) -> None:
        import rclpy
        from rclpy.context import Context

        from winder.ros.dds import use_profile
        from winder.ros.sender import SenderExecutor

        use_profile()
        self.timeout = timeout
        self.context = Context()
        rclpy.init(args=[], context=self.context)
        self.node = rclpy.create_node(f"winder_ctl_{os.getpid()}", context=self.context)
        self.executor = SenderExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.started = time.monotonic()
        self.deadline = self.started + timeout
        self.clients: dict[str, Any] = {}
        self.actions: dict[str, Any] = {}
        self._peers: dict[str, Any] = {}
        #: the Wind goals' feedback from the cell's interp node, by goal id (:func:`start_clients`)
        self.feedback: dict[bytes, list[Any]] = {}

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

    def peers(self, namespace: str) -> Any:
        """The verdict on the senders of the cell in ``namespace``
        (:class:`winder.ros.peers.Peers`; one per namespace and session, so
        that the nodes it pinned stay pinned). Only the cell's own nodes are
        believed; what others send is counted (its ``intruders``), said
        once by the command (``ignored, foreign``), never logged."""
        key = namespace.strip("/")
        if key not in self._peers:
            from winder.ros.peers import Peers

            self._peers[key] = Peers(self.node, key, lambda _text: None, what="are believed by winder ctl")
            self._peers[key].see_parts()
        return self._peers[key]

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
    which node is the interp node. Its goals' feedback is taken here as well,
    with its sender: only the cell's interp node's counts
    (``session.feedback``; rclpy's action client does not say who sent a
    feedback, and anyone on the domain can publish one for a goal whose id
    the action's status topic shows)."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from winder.ros.sender import attributed
    from winder_interfaces.action import Wind

    action = wind_action(interp)
    if action in session.actions:
        return
    session.action_client(Wind, action)
    peers = session.peers(interp.rsplit("/", 1)[0])
    topic = f"{action}/_action/feedback"  # rcl_action's name for it; its QoS: rmw's default
    feedback_type = Wind.Impl.FeedbackMessage

    def take(raw: bytes, gid: bytes) -> None:
        def act(_raw: bytes) -> None:
            try:
                msg = deserialize(raw, feedback_type)
            except Exception:  # not a Wind feedback: nothing to take
                return
            session.feedback.setdefault(bytes(msg.goal_id.uuid), []).append(msg.feedback)

        peers.deliver(topic, gid, raw, act, "interp")

    attributed(
        session.node, feedback_type, topic, take, QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    )


def deserialize(raw: bytes, msg_type: Any) -> Any:
    """``raw`` (CDR bytes) as a ``msg_type`` message; what is not one raises."""
    from rclpy.serialization import deserialize_message

    return deserialize_message(raw, msg_type)


def goal_text(value: Any) -> str:
    """A setting as a Wind goal's ``KEY=VALUE`` override says it (the node parses it by its type)."""
    return ("true" if value else "false") if isinstance(value, bool) else str(value)


@dataclass
class Goal:
    """A Wind goal whose run started: the start reply (``run <id> started:
    N steps``), the run, and the future of the goal's result (the action's
    answer to this client's own request, once the run has ended)."""

    reply: str
    run_id: str
    result: Any


def _one_goal(session: Session, client: Any, action: str, goal: Any) -> tuple[Goal | None, str]:
    """Send one Wind goal: (the goal, "") once its run started, or (None,
    the cell's reason) if it ended first. Its run started when the cell's
    interp node's feedback names it (:func:`start_clients`). At the
    deadline the goal, still waiting for the cell, is canceled and its
    reason raised (RefusedError)."""
    sent = client.send_goal_async(goal)
    session.until(sent.done, f"reply from {action} to the goal")
    handle = sent.result()
    if not handle.accepted:
        raise RefusedError(f"{action}: goal rejected")
    started = session.feedback.setdefault(bytes(handle.goal_id.uuid), [])
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
        return Goal(f"run {first.run_id} started: {first.steps_total} steps", first.run_id, result), ""
    ended = result.result().result
    if ended.run_id:  # the run started and ended before its first feedback came (as fast as possible)
        return Goal(f"run {ended.run_id} started: {ended.report.steps_total} steps", ended.run_id, result), ""
    return None, one_line(ended.message)


def start_run(session: Session, interp: str, values: dict[str, Any], view: CellView | None = None) -> Goal:
    """Send ``interp``'s cell a Wind goal with ``values`` as its overrides
    (typed already; none: the run with the settings as they are), again
    while the cell says it is not ready (at the next ``winder/ready``
    message ``view`` hears, or after :data:`NOT_READY_RETRY` s), until the
    deadline; the goal once its run started (its first feedback), with
    the start reply (``run <id> started: ...``). The goal goes on when the
    session ends: the run is the cell's. :class:`RefusedError` with the
    cell's reason otherwise; a goal still waiting for the cell at the
    deadline is canceled."""
    from winder_interfaces.action import Wind

    start_clients(session, interp)
    action = wind_action(interp)
    client = session.action_client(Wind, action)
    session.until(client.server_is_ready, f"action server {action}", f" ({graph_words()})")
    overrides = [f"{k}={goal_text(v)}" for k, v in values.items()]
    goal = Wind.Goal(overrides=overrides, goal_sha256=goal_sha256("", overrides))  # a cut goal is refused
    while True:
        started, reason = _one_goal(session, client, action, goal)
        if started is not None:
            return started
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


# -- the cell's state ------------------------------------------------------------------

#: s after which a message the cell repeats every second (a node's job
#: status, a role's winder/ready) is overdue: its node is silent, held up or
#: killed and not yet timed out of the graph (winder/ready's own rule: 3 s)
SILENT = 3.0
#: s a state query listens on after it first hears the cell, at most: the
#: bound for a node the graph shows that says nothing (a held-up process),
#: and for a node whose status still shows a moment before the cell's state
#: (each node sends one every second: the one after a transition comes
#: within a second of it)
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
#: s a state query goes on listening once what it heard is one picture, for
#: what has arrived meanwhile: a transition's winder/state and the consumer's
#: status come from two writers at once, one a moment after the other
CONFIRM = 0.05
#: what the consumer's job status says in each state of the cell (winder/state)
#: that does not contradict it; a state not listed agrees with its own name only
AGREES = {
    "running": ("running", "stalled"),
    "failed": ("incomplete",),
    **{state: (state, "blocked") for state in ("idle", "done", "aborted")},
}


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
        """The node that sent it: the one it names (a status is taken only from the node it names)."""
        return node_of(self.name)


@dataclass
class CellView:
    """What a cell's own nodes say of it, as heard so far: ``winder/state``
    (its consumer's), the roles' ``winder/ready`` and each role's job
    status on ``/diagnostics`` (``statuses``, by role: the part the graph
    shows its sender in, never a role its payload names), each with when it
    was sent; and what the graph shows of the cell (its node names, the
    nodes in each role), looked at with :func:`look`. What other nodes sent
    is counted by ``peers`` (:meth:`ignored`), not shown."""

    namespace: str
    state: dict[str, str] = field(default_factory=dict)
    ready: dict[str, str] = field(default_factory=dict)
    statuses: dict[str, NodeStatus] = field(default_factory=dict)  #: role -> its node's last job status
    changed: int = 0  #: counts what was heard, and each change of the graph
    state_ns: int = 0  #: when winder/state was sent
    state_by: str = ""  #: the node that sent it (as the graph names it)
    ready_ns: dict[str, int] = field(default_factory=dict)  #: when each role's winder/ready was sent
    graph: set[str] | None = None  #: the nodes the graph showed at the last look (None: not looked yet)
    holders: dict[str, set[str]] = field(default_factory=dict)  #: the nodes it showed in each role
    graph_changed: float = field(default_factory=time.monotonic)  #: when the graph last changed
    peers: Any = None  #: the verdict on the senders (winder.ros.peers.Peers), None for a view filled by hand

    def roles(self) -> dict[str, NodeStatus]:
        """The job status of each role heard (interp, profile, consumer)."""
        return dict(self.statuses)

    def heard(self) -> bool:
        return bool(self.state or self.statuses)

    def complete(self) -> bool:
        """Every role's job status, ``winder/state`` and both roles' ``winder/ready``
        heard (latched messages of two publishers come at different times)."""
        from winder.contract.topics import READY_ROLES, ROLES

        return (
            all(r in self.statuses for r in ROLES)
            and bool(self.state)
            and all(r in self.ready for r in READY_ROLES)
        )

    def ignored(self) -> str:
        """What was not believed, by sender (``/intruder (3 on /diagnostics)``), "" if nothing."""
        return str(self.peers.intruders.summary()) if self.peers is not None else ""

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
        the role's is, else the one the graph shows in it ("" if none)."""
        st = self.statuses.get(role)
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

    def behind(self, role: str) -> str:
        """Why ``role``'s job status does not show the cell as its state
        does ("" if it does, or there is nothing to compare): it was sent
        before winder/state (a moment before a transition, its node's next
        status is on its way), it speaks of another run, or, the consumer's
        (the node that sends winder/state), it says a state that contradicts
        the cell's."""
        st = self.statuses.get(role)
        if st is None or not self.state:
            return ""
        if st.sent_ns < self.state_ns:
            return "said before the cell's state"
        run, cell_run = st.values.get("run_id") or "-", self.state.get("run_id") or "-"
        if run != cell_run:
            return f"of run {run}, the cell's is {cell_run}"
        said, cell = st.values.get("state", "-"), self.state.get("state", "-")
        if role == "consumer" and said not in AGREES.get(cell, (cell,)):
            return f"says {said}, the cell {cell}"
        return ""

    def awaited(self, now_ns: int | None = None) -> list[str]:
        """What the graph shows of the cell that has not been heard yet; each
        job status older than :data:`FRESH` at ``now_ns`` (wall clock): a
        newer one is on its way (the older ones a node keeps for a reader
        that joins come first), or the node is held up; and each that does
        not show the cell as winder/state does (:meth:`behind`), of a node
        still on the graph."""
        from winder.contract.topics import READY_ROLES, ROLES

        now_ns = time.time_ns() if now_ns is None else now_ns
        out = [
            f"the job status of {', '.join(sorted(self.holders[role]))}"
            for role in ROLES
            if role not in self.statuses and self.holders.get(role)
        ]
        if not self.state and self.holders.get("consumer"):
            out.append("winder/state")
        out += [f"the {r}'s winder/ready" for r in READY_ROLES if r not in self.ready and self.holders.get(r)]
        heard = {st.node for st in self.statuses.values()} | ({self.state_by} if self.state_by else set())
        if self.graph is not None:
            out += [f"{n} on the graph" for n in sorted(heard - self.graph)]
        for role, st in self.statuses.items():
            if self.gone(st.node):
                continue
            if age_s(st.sent_ns, now_ns) > FRESH:
                out.append(f"a newer status of {st.node}")
            elif self.behind(role):
                out.append(f"a status of {st.node} that shows the cell's state ({self.behind(role)})")
        return out

    def settled(self, now: float, now_ns: int | None = None) -> bool:
        """Whether a state query has heard what there is to hear (at ``now``,
        monotonic, and ``now_ns``, wall clock): every node heard is on the
        graph (an endpoint's message can come before its node's name), its
        status fresh and showing the cell as winder/state does, and the cell
        complete; or, with a part missing, the graph has not changed for
        :data:`SETTLE` s and everything it shows of the cell has been heard."""
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


def taken(
    session: Session,
    msg_type: Any,
    topic: str,
    qos: Any,
    take: Callable[[bytes, bytes, int], None],
    **kwargs: Any,
) -> None:
    """A subscription whose ``take(raw, gid, sent)`` gets each message with
    its publisher's GID and when it was sent (its source timestamp: the
    sender's wall clock, ns; now when it has none); ``kwargs`` as
    ``create_subscription`` takes them."""
    from winder.ros.sender import attributed

    subs: list[Any] = []

    def on_raw(raw: bytes, gid: bytes) -> None:
        # the message info of the message just taken (winder.ros.sender's taker
        # keeps it until its next take, which comes after this callback)
        sent = int(subs[0].winder_taker.info.source_timestamp)
        take(raw, gid, sent if sent > 0 else time.time_ns())

    subs.append(attributed(session.node, msg_type, topic, on_raw, qos, **kwargs))


def watch_cell(session: Session, namespace: str, *, statuses: bool = True) -> CellView:
    """Subscribe to the cell's state topics; the view they fill while the
    session spins, with what the cell's own nodes send only (the session's
    :meth:`Session.peers` judges each message's sender as the graph names
    it): ``winder/state`` from the consumer, a role's ``winder/ready`` from
    the node in that role, a job status from the node in a part, for that
    part, and only the sender's own. /diagnostics is read twice:
    transient-local, for the statuses winder's nodes keep for a newcomer
    (each node's last ones, at once), and volatile, for a node that keeps
    none (a third-party consumer). Without ``statuses``, only winder/state
    and winder/ready (a start that follows nothing)."""
    from diagnostic_msgs.msg import DiagnosticArray, KeyValue
    from rclpy.event_handler import SubscriptionEventCallbacks
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from winder.contract.topics import (
        READY_ROLES,
        TASK_JOB,
        TOPIC_DIAGNOSTICS,
        TOPIC_READY,
        TOPIC_STATE,
        cell_state_values,
        in_namespace,
    )
    from winder.ros.diagnostics import QOS_DIAGNOSTICS_KEPT
    from winder.ros.graph import Who, fully_qualified
    from winder.ros.qos import QOS_DIAGNOSTICS
    from winder_interfaces.msg import CellState

    peers = session.peers(namespace)
    view = CellView(namespace, peers=peers)
    latched = QoSProfile(
        depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )

    def on_state(raw: bytes, gid: bytes, sent: int) -> None:
        def act(_raw: bytes) -> None:
            try:
                msg = deserialize(raw, CellState)
            except Exception:  # not a CellState: nothing to show
                return
            if sent < view.state_ns:
                return  # an older one (a latched topic keeps a few for a newcomer)
            who = peers.sender(TOPIC_STATE, gid)
            view.state = cell_state_values(msg)
            view.state_ns = sent
            view.state_by = who.fq if who is not None else ""
            view.changed += 1

        peers.deliver(TOPIC_STATE, gid, raw, act, "consumer")

    def on_ready(raw: bytes, gid: bytes, sent: int) -> None:
        try:
            msg = deserialize(raw, KeyValue)
        except Exception:  # not a KeyValue
            return
        if msg.key not in READY_ROLES:
            return

        def act(_raw: bytes) -> None:
            if sent >= view.ready_ns.get(msg.key, 0):
                view.ready[msg.key] = msg.value
                view.ready_ns[msg.key] = sent
                view.changed += 1

        peers.deliver(TOPIC_READY, gid, raw, act, msg.key)

    def on_diagnostics(raw: bytes, gid: bytes, sent: int) -> None:
        try:
            msg = deserialize(raw, DiagnosticArray)
        except Exception:  # not a DiagnosticArray
            return
        if not any(
            st.name.endswith(f": {TASK_JOB}") and in_namespace(st.name, namespace) for st in msg.status
        ):
            return  # no job status of this cell's (another cell's, another tool's)

        def act(role: str, who: Who) -> None:
            for st in msg.status:
                if not st.name.endswith(f": {TASK_JOB}") or node_of(st.name) != who.fq:
                    continue  # only its own job status: a node speaks for no other
                known = view.statuses.get(role)
                if known is not None and known.node == who.fq and known.sent_ns >= sent:
                    continue  # the other reader's copy, or an older one kept for newcomers
                values = {kv.key: kv.value for kv in st.values}
                view.statuses[role] = NodeStatus(st.name, values, st.message, sent)
                view.changed += 1

        peers.deliver_by_part(TOPIC_DIAGNOSTICS, gid, raw, act)

    taken(session, CellState, fully_qualified(TOPIC_STATE, namespace), latched, on_state)
    taken(session, KeyValue, fully_qualified(TOPIC_READY, namespace), latched, on_ready)
    if statuses:
        # a publisher that keeps nothing (a third-party node's, a stranger's) cannot match the
        # kept reader: the volatile one takes its statuses, and the command's output stays its own
        quiet = SubscriptionEventCallbacks(incompatible_qos=lambda _event: None)
        taken(
            session,
            DiagnosticArray,
            TOPIC_DIAGNOSTICS,
            QOS_DIAGNOSTICS_KEPT,
            on_diagnostics,
            event_callbacks=quiet,
        )
        taken(session, DiagnosticArray, TOPIC_DIAGNOSTICS, QOS_DIAGNOSTICS, on_diagnostics)
    return view


def cell_state(session: Session, namespace: str) -> CellView:
    """The cell's state, as soon as it is one picture (:meth:`CellView.settled`):
    every role's status, ``winder/state`` and the ready messages of the
    nodes the graph shows in the cell, each node named on the graph, each
    status sent after the state it is shown with; then :data:`CONFIRM` s
    more for what is on its way already. Bounded: the session's deadline
    (``--timeout``) to hear the cell at all, then at most :data:`LISTEN` s;
    what is still not one picture then is shown saying so
    (:meth:`CellView.behind`)."""
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
            seen = view.changed
            confirm = min(end, time.monotonic() + CONFIRM)
            while time.monotonic() < confirm:
                session.spin(confirm - time.monotonic())
            look(session, view)
            if view.changed == seen or view.settled(time.monotonic()):
                break
            continue
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


def estop(session: Session, namespace: str) -> tuple[bool, str]:
    """An emergency stop: the ``~/estop`` of the cell's consumer (found by its
    role, whatever its name: a driver node's, beside the profile node's
    ``~/abort``); (success, the node's words or why it was not called)."""
    try:
        consumer = find_role(session, namespace, "consumer", "the step consumer")
    except UnansweredError as exc:
        return False, str(exc)
    ok, message = trigger(f"{consumer}/estop", session=session)
    if not ok and message.endswith("is the cell running there?"):
        message = f"{message} ({consumer} offers no ~/estop: only a driver node does, sim_node does not)"
    return ok, message


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
