"""Topic names of the cell and the names of its status reports (ROS-free).

Names are relative (``winder/steps``) so that a node namespace
(``--ros-args -r __ns:=/cell1``) moves the whole cell. The simulated clock is
relative too (``clock``): ``/clock`` for a cell in the root namespace, as ROS
tools expect it, and ``/cell1/clock`` for a cell in ``/cell1``, so that two
cells on one graph never drive one time base back and forth (a node that
should follow cell1's time remaps ``/clock:=/cell1/clock``). ``/diagnostics``
stays global, as diagnostic tools expect it; status names carry the namespace. Their QoS is in
:mod:`winder.ros.qos`; their types and contents in docs/CONTRACT.md (the topic table: docs/INTEGRATING.md).
"""

from __future__ import annotations

import re
from collections.abc import Collection, Mapping, Sequence
from typing import Any

from winder.contract.states import CellState, JobState, ReadyState
from winder.errors import BadInputError
from winder.spec import shorten

#: a run's description (winder_interfaces/JobDescription, latched; a std_msgs/String of
#: JSON in older bags), sent by the interp node as the run starts
TOPIC_JOB = "winder/job"
TOPIC_PATH = "winder/path"
TOPIC_STEPS = "winder/steps"
TOPIC_STEP_TIMES = "winder/step_times"
TOPIC_JOINT_STATES = "winder/joint_states"
#: the wire's tension (geometry_msgs/WrenchStamped, force.x in N), as a load cell reads it
#: the cell's Wind action (winder_interfaces/action/Wind), served by the interp node
ACTION_WIND = "winder/wind"
TOPIC_TENSION = "winder/tension"
TOPIC_JOINT_COMMANDS = "winder/joint_commands"
TOPIC_SIM_CONFIG = "winder/sim_config"
TOPIC_PROGRESS = "winder/progress"
TOPIC_PROFILE_CONFIG = "winder/profile_config"
TOPIC_CLOCK = "clock"
#: The cell's state (winder_interfaces/CellState, latched; a DiagnosticStatus with
#: the values :data:`CELL_STATE_KEYS` in older bags): one message per transition
TOPIC_STATE = "winder/state"
#: idle, running, pausing (braking for a pause), paused (at rest: a pause or a
#: programmed stop), aborting (braking for an abort), done, aborted (ended at
#: rest by an abort), failed (ended incomplete otherwise)
CELL_STATES = tuple(CellState)
CELL_STATE_KEYS = ("state", "job_id", "run_id", "coil", "layer", "turn", "sim_time_s")
TOPIC_DIAGNOSTICS = "/diagnostics"
#: Operator commands as they take effect (winder_interfaces/ControlEvent; a
#: std_msgs/String of JSON in older bags; reliable,
#: transient-local, depth 100): the profile node publishes one event per
#: pause, resume, abort or override of a run - when it takes effect in
#: simulated time, where the axes come to rest - and the sim node records and
#: announces them; the interp node stops sending an aborted run.
TOPIC_CONTROL = "winder/control"
#: The consumer's final report of each run (winder_interfaces/JobReport, latched),
#: as its run ends: the same account as its last ``"<node>: job"`` status, typed
TOPIC_REPORT = "winder/report"

#: The diagnostic task every node reports its job under (``"<node>: job"``).
TASK_JOB = "job"


def status_name(node: str, task: str = TASK_JOB, namespace: str = "") -> str:
    """The DiagnosticStatus name of ``node``'s ``task`` in ``namespace``, as
    diagnostic_updater forms it from the node's fully qualified name:
    ``"sim_node: job"``, ``"cell1/sim_node: job"``."""
    ns = namespace.strip("/")
    return f"{ns}/{node}: {task}" if ns else f"{node}: {task}"


def in_namespace(name: str, namespace: str) -> bool:
    """A status name (``"cell1/sim_node: job"``) of a node in ``namespace``
    itself, not in a deeper one: what a cell's bag records and reports."""
    node = name.split(":", 1)[0]
    ns = namespace.strip("/")
    if not ns:
        return "/" not in node
    return node.startswith(ns + "/") and "/" not in node[len(ns) + 1 :]


_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")

#: rcl's bounds on names (rmw: validate_full_topic_name.h, validate_namespace.h):
#: a fully qualified topic or service name is at most ``255 - 8`` characters
#: (DDS prefixes and suffixes take the rest), a namespace at most 2 fewer
MAX_NAME_LENGTH = 255 - 8
MAX_NAMESPACE_LENGTH = MAX_NAME_LENGTH - 2
#: the nodes winder runs in a cell's namespace: the cell's and the command-line
#: tools' (``winder run``, ``view``, ``play``, ``resim``); the bridge's helper
#: node ``bridge_node_io`` has no parameter services
NODE_NAMES = (
    "interp_node", "profile_node", "sim_node", "bridge_node", "winder_cell", "winder_view",
    "winder_player", "winder_resim",
)  # fmt: skip
#: the services of those nodes: rclpy's parameter and type description
#: services, a managed node's lifecycle services, winder's own (``~/start_run``...)
NODE_SERVICES = (
    "describe_parameters", "get_parameter_types", "get_parameters", "list_parameters", "set_parameters",
    "set_parameters_atomically", "get_type_description", "change_state", "get_state",
    "get_available_states", "get_available_transitions", "get_transition_graph", "transition_event",
    "start", "start_run", "pause", "resume", "abort", "toggle_paused", "play_next",
)  # fmt: skip
#: the longest name a cell forms under its namespace (a topic, or a node's service)
LONGEST_NAME = max(
    (
        TOPIC_JOB, TOPIC_PATH, TOPIC_STEPS, TOPIC_STEP_TIMES, TOPIC_JOINT_STATES, TOPIC_JOINT_COMMANDS,
        TOPIC_SIM_CONFIG, TOPIC_PROGRESS, TOPIC_PROFILE_CONFIG, TOPIC_CLOCK, TOPIC_STATE, TOPIC_CONTROL,
        TOPIC_REPORT, *(f"{node}/{service}" for node in NODE_NAMES for service in NODE_SERVICES),
        "bridge_node_io/get_type_description",
    ),
    key=len,
)  # fmt: skip


def check_namespace(namespace: str, option: str = "namespace", longest: str = LONGEST_NAME) -> str:
    """A cell's namespace as ROS 2 accepts it, with the leading ``/`` added:
    ``""`` or ``"/"`` (the root), else ``/name[/name...]``, each name of
    letters, digits and ``_``, not starting with a digit, and short enough
    that every name the cell forms under it (``longest``: a topic, a node's
    service) stays within ROS's bound on a name (:data:`MAX_NAME_LENGTH`).
    ValueError (one line) naming ``option``, the value (shortened) and the
    rule otherwise, before anything reaches rcl (whose refusal is a traceback)."""
    if not isinstance(namespace, str):
        raise BadInputError(f"{option}={namespace!r} is invalid: must be a text, /name[/name...]")
    if namespace in ("", "/"):
        return ""
    body = namespace[1:] if namespace.startswith("/") else namespace
    tokens = body.split("/")
    bad = next((t for t in tokens if not _TOKEN.fullmatch(t)), None)
    if bad is not None:
        why = "an empty name ('//' or a trailing '/')" if bad == "" else f"the name {shorten(bad)}"
        raise BadInputError(
            f"{option}={shorten(namespace)} is invalid: it has {why}; a namespace is /name[/name...], "
            "each name letters, digits and '_', not starting with a digit"
        )
    most = min(MAX_NAMESPACE_LENGTH, MAX_NAME_LENGTH - 1 - len(longest))
    if 1 + len(body) > most:
        raise BadInputError(
            f"{option}={shorten(namespace)} is invalid: {1 + len(body)} characters, at most {most}: ROS "
            f"bounds a name to {MAX_NAME_LENGTH} characters, and the longest the cell forms under its "
            f"namespace is /{longest}"
        )
    return "/" + body


def check_node_name(name: str, namespace: str = "", option: str = "node") -> str:
    """A node named on a command line (``winder ctl param NODE``: its name
    in ``namespace``, or its full name ``/ns/name``) fully qualified, as ROS
    takes it: each name letters, digits and ``_``, not starting with a digit,
    and its services (``<node>/set_parameters_atomically``, the longest of
    :data:`NODE_SERVICES`) within :data:`MAX_NAME_LENGTH`. ValueError (one
    line: ``option``, the value shortened, the rule) otherwise."""
    text = name.strip("/") if isinstance(name, str) else ""
    if not text:
        raise BadInputError(f"{option}={name!r} is invalid: must be a node name, or its full name /ns/name")
    ns = namespace.strip("/")
    full = "/" + text if name.startswith("/") else (f"/{ns}/{text}" if ns else f"/{text}")
    bad = next((t for t in full[1:].split("/") if not _TOKEN.fullmatch(t)), None)
    if bad is not None:
        why = "an empty name ('//')" if bad == "" else f"the name {shorten(bad)}"
        raise BadInputError(
            f"{option}={shorten(name)} is invalid: it has {why}; a node is NAME or /NS/NAME, each name "
            "letters, digits and '_', not starting with a digit"
        )
    service = max(NODE_SERVICES, key=len)
    if len(full) + 1 + len(service) > MAX_NAME_LENGTH:
        raise BadInputError(
            f"{option}={shorten(name)} is invalid: its service {shorten(full + '/' + service)} would be "
            f"longer than the {MAX_NAME_LENGTH} characters ROS allows a name (the node's full name: at most "
            f"{MAX_NAME_LENGTH - 1 - len(service)})"
        )
    return full


def check_relative_name(option: str, value: str, namespace: str = "", suffixes: Sequence[str] = ("",)) -> str:
    """A relative topic name a setting gives (``controller``: its topics
    ``<controller>/commands`` and ``<controller>/joint_trajectory``) as ROS
    accepts it in ``namespace``: names of letters, digits and ``_``, not
    starting with a digit, separated by ``/``, and the longest topic it
    names (``namespace/value`` + one of ``suffixes``) within
    :data:`MAX_NAME_LENGTH`. ValueError (one line: the setting, the value
    shortened, the rule) otherwise; the value as given."""
    if not isinstance(value, str) or not value:
        raise BadInputError(f"{option}={value!r} is invalid: must be a name (letters, digits, '_' and '/')")
    bad = next((t for t in value.split("/") if not _TOKEN.fullmatch(t)), None)
    if bad is not None:
        why = "an empty name ('//', or a '/' at an end)" if bad == "" else f"the name {shorten(bad)}"
        raise BadInputError(
            f"{option}={shorten(value)} is invalid: it has {why}; a relative topic name is name[/name...], "
            "each name letters, digits and '_', not starting with a digit"
        )
    base = namespace.rstrip("/")
    tail = max(suffixes, key=len, default="")
    full = f"{base}/{value}{tail}"
    if len(full) > MAX_NAME_LENGTH:
        most = MAX_NAME_LENGTH - len(base) - 1 - len(tail)
        raise BadInputError(
            f"{option}={shorten(value)} is invalid: it names the topic {shorten(full)}, longer than the "
            f"{MAX_NAME_LENGTH} characters ROS allows a name; in the namespace {base or '/'} it may have "
            f"at most {max(most, 0)} characters"
        )
    return value


def check_service_name(option: str, value: str, namespace: str = "") -> str:
    """A service a setting names (the bridge's ``homing_service``), as rcl
    takes it when a client of it is made: relative to ``namespace``
    (``name[/name...]``) or fully qualified (``/name[/name...]``), names of
    letters, digits and ``_``, not starting with a digit, and its full name
    within :data:`MAX_NAME_LENGTH` (rcl refuses a longer one with a raw
    error when the call is made, long after the setting was taken).
    ValueError (one line: the setting, the value shortened, the rule)
    otherwise; the value as given."""
    if not isinstance(value, str) or value.strip("/") == "":
        raise BadInputError(
            f"{option}={value!r} is invalid: must be a service name, name[/name...] or /name..."
        )
    absolute = value.startswith("/")
    body = value[1:] if absolute else value
    bad = next((t for t in body.split("/") if not _TOKEN.fullmatch(t)), None)
    if bad is not None:
        why = "an empty name ('//', or a '/' at its end)" if bad == "" else f"the name {shorten(bad)}"
        raise BadInputError(
            f"{option}={shorten(value)} is invalid: it has {why}; a service name is name[/name...] (in the "
            "node's namespace) or /name[/name...], each name letters, digits and '_', not starting with a "
            "digit"
        )
    base = "" if absolute else namespace.rstrip("/")
    full = f"{base}/{body}"
    if len(full) > MAX_NAME_LENGTH:
        where = "" if absolute else f" in the namespace {base or '/'}"
        raise BadInputError(
            f"{option}={shorten(value)} is invalid: its full name {shorten(full)} is longer than the "
            f"{MAX_NAME_LENGTH} characters ROS allows a name{where}; it may have at most "
            f"{max(MAX_NAME_LENGTH - len(base) - (0 if absolute else 1), 0)} characters"
        )
    return value


#: The start handshake (diagnostic_msgs/KeyValue, latched): the step stream's
#: consumer (``key="consumer"``: the sim node, or a hardware driver) and the
#: profile node (``key="profile"``) say whether they can take a job now
#: (``value`` one of :data:`READY_STATES`: "waiting" = its stream is not
#: connected yet, "busy" = running a job, "blocked" = settings refused). The
#: interp node starts a job only when both say "ready" ("inactive": a managed
#: node not activated yet, see winder.ros.managed); readers of any other
#: topic change nothing. Each repeats its state every second; one not heard
#: for 3 s no longer counts (its node is gone).
TOPIC_READY = "winder/ready"
READY_ROLES = ("consumer", "profile")
READY_STATES = tuple(ReadyState)


#: The keys every node's ``"<node>: job"`` status carries, in every state, so
#: that a controller reads one schema: ``state`` (:data:`JOB_STATES`), the
#: ``job_id`` and ``run_id`` of the run it speaks of ("" before the first),
#: the node's ``steps_done`` of ``steps_total`` and their ratio ``progress``.
#: Right after them comes :data:`ROLE_KEY`; then the node's own keys (the sim
#: node: lost steps, bag...).
STATUS_KEYS = ("state", "job_id", "run_id", "steps_done", "steps_total", "progress")
#: The key after :data:`STATUS_KEYS` that names the node's part in the cell,
#: one of :data:`ROLES`: ``interp`` (the job and its steps), ``profile`` (the
#: step times) or ``consumer`` (the node that subscribes to
#: ``winder/step_times`` and executes the steps: the sim node, a ros2_control
#: bridge, a hardware driver). A controller finds a node's status by its role,
#: never by its node name, which a launch may remap (``-r __node:=axes``).
#: Statuses recorded before roles existed carry none: :func:`has_role` falls
#: back on the stock node names (:data:`LEGACY_NAMES`) for them.
ROLE_KEY = "role"
#: The keys that end every status a winder node sends: the process that sent
#: it (pid, host name, its start as wall-clock ns), so that two nodes of one
#: name or role are told apart (``winder.ros.peers.Solo``).
PROCESS_KEYS = ("pid", "host", "started_ns")
ROLES = ("interp", "profile", "consumer")
#: The node name each role had before roles existed (older bags, and a node
#: that does not name its role yet).
LEGACY_NAMES = {"interp": "interp_node", "profile": "profile_node", "consumer": "sim_node"}
#: idle: no run yet; running: a run in progress; pausing / paused: braking
#: for a pause / at rest (a pause, or a programmed stop), going on after a
#: resume; aborting: braking for an abort; stalled: running, but its step
#: stream stopped (the sim node); done: the last run ended complete; aborted:
#: it was ended by an abort, the axes at rest; incomplete: it ended short
#: otherwise (stalled for good, cut off...); blocked: the node's settings are
#: refused, it takes no run
JOB_STATES = tuple(JobState)


def status_values(
    state: str,
    job_id: str = "",
    run_id: str = "",
    done: int = 0,
    total: int = 0,
    *,
    role: str = "",
    **extra: object,
) -> dict[str, object]:
    """The key/values of a ``job`` status: :data:`STATUS_KEYS` first, then
    ``role`` (:data:`ROLE_KEY`, when given), then ``extra``."""
    if state not in JOB_STATES:
        raise ValueError(f"state={state!r} is invalid: must be one of {', '.join(JOB_STATES)}")
    if role and role not in ROLES:
        raise ValueError(f"role={role!r} is invalid: must be one of {', '.join(ROLES)}")
    values: dict[str, object] = {
        "state": state,
        "job_id": job_id,
        "run_id": run_id,
        "steps_done": done,
        "steps_total": total,
        "progress": f"{done / total:.4f}" if total else "0.0000",
    }
    if role:
        values[ROLE_KEY] = role
    values.update(extra)
    return values


def cell_state_values(msg: Any) -> dict[str, str]:
    """The :data:`CELL_STATE_KEYS` of a ``winder/state`` message as text: a
    winder_interfaces/CellState (by its fields), or the DiagnosticStatus of
    older bags (its key/values)."""
    if hasattr(msg, "values"):
        return {kv.key: kv.value for kv in msg.values}
    values = {k: str(getattr(msg, k)) for k in CELL_STATE_KEYS if k != "sim_time_s"}
    return {**values, "sim_time_s": f"{msg.sim_time_s:.6f}"}


def status_node(name: str) -> str:
    """The node of a status name, without its namespace: ``"axes"`` for
    ``"cell1/axes: job"``."""
    return name.split(":", 1)[0].rsplit("/", 1)[-1]


def has_role(
    name: str,
    values: Mapping[str, object],
    role: str,
    namespace: str,
    nodes: Collection[str] = (),
    task: str = TASK_JOB,
) -> bool:
    """Whether the status ``name`` with ``values`` is the ``task`` status of
    the node in ``namespace`` (itself, not a deeper one) that has ``role``:
    its values say so (:data:`ROLE_KEY`); a status that names no role is
    taken by its node's name, the stock one (:data:`LEGACY_NAMES`) or one of
    ``nodes`` (names known to have the role by other means: the graph, the
    bag's ``winder/state``)."""
    if not name.endswith(f": {task}") or not in_namespace(name, namespace):
        return False
    said = values.get(ROLE_KEY)
    if said:
        return said == role
    node = status_node(name)
    return node == LEGACY_NAMES.get(role) or node in nodes
