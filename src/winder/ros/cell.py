"""Run the whole winding cell: the three node executables as separate processes
(what ``ros2 launch winder_sim winder.launch.py`` does on a ROS install), a
progress callback while the job runs, and the final report at the end.

Used by ``winder run``; the nodes' logs go to a directory that is kept and
named when the run fails, removed after a clean run. The steps, in order:
:func:`cell_environment` (domain, discovery), :class:`NodeProcesses` (spawn,
stop), :class:`CellWatch` (listen to /diagnostics, ask the interp node to
start) and :func:`run_cell`, which strings them together.
"""

from __future__ import annotations

import os
import random
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.srv import SetParametersAtomically
from rclpy.action.client import ActionClient
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from rclpy.task import Future
from std_srvs.srv import Trigger

from winder.contract.jobfile import ros_text
from winder.contract.run import JobReport
from winder.contract.states import FINAL_JOB_STATES, JobState
from winder.contract.topics import (
    ACTION_WIND,
    ROLES,
    TASK_JOB,
    TOPIC_DIAGNOSTICS,
    in_namespace,
)
from winder.contract.trust import without_senders
from winder.errors import BadInputError
from winder.interrupts import Interrupts
from winder.procs import Children
from winder.ros.dds import PROFILE_KEYS, use_profile
from winder.ros.diagnostics import ERROR
from winder.ros.early import CELL_CLASSES, CONTAINER, EarlyContainer, find_executable
from winder.ros.graph import Who, consumers, fully_qualified, profile_nodes
from winder.ros.managed import LEFT_CELL
from winder.ros.peers import Peers
from winder.ros.sender import SenderExecutor, attributed
from winder.ros.terminal import KeyReader
from winder_interfaces.action import Wind

#: the executable ``winder run`` starts for each part of the cell
NODES = {"interp": "interp_node", "profile": "profile_node", "sim": "sim_node"}
#: the role (winder.contract.topics.ROLES) of each part, by which it is found
#: on the graph and in /diagnostics whatever its node name
NODE_ROLES = {"interp": "interp", "profile": "profile", "sim": "consumer"}
#: Start order: the sim node first; the others wait for their readers, so the
#: job starts only when the whole chain is connected.
START_ORDER = ("sim", "profile", "interp")
#: Seconds before an unanswered start request is asked again.
START_RETRY = 5.0
#: s between two looks at the graph while the job is not started, for its
#: first START_POLL_FOR s (a cell on this host starts within ~1 s); 0.1 s after
START_POLL = 0.01
START_POLL_FOR = 3.0
#: s between two start requests the cell answered 'not ready' (its nodes say ready within ~0.05 s)
NOT_READY_RETRY = 0.02
#: s a cell runner listens to /diagnostics before its first start call: every
#: node reports once a second, so another cell's in the same namespace is heard
OCCUPIED_WAIT = 1.2


@dataclass
class CellResult:
    ok: bool
    summary: dict[str, str] = field(default_factory=dict)
    message: str = ""
    log_dir: Path | None = None
    errors: list[str] = field(default_factory=list)  #: every ERROR a node of the cell reported
    #: messages on the cell's topics from nodes that are not the cell's (who, how many), "" if none
    intruders: str = ""
    occupied: bool = False  #: refused: another cell's node plays a part in the namespace
    refused: bool = False  #: the job was refused before it started (a node refused a setting or the start)
    node_died: bool = False  #: the run ended because a node of the cell exited (killed, crashed)


class NodeExit(str):
    """The reason a run ended when a node of the cell exited: a ``str``, so
    every caller keeps it as the failure text, and :func:`_result` tells it
    apart from the other failures (``winder`` exits with its own code)."""


def ros_args(params: dict[str, Any], namespace: str) -> list[str]:
    """``--ros-args`` for a node: the namespace remap and one ``-p`` per parameter."""
    args = ["--ros-args"]
    if namespace:
        args += ["-r", f"__ns:={namespace}"]
    for k, v in params.items():  # each read back by ROS as the value checked here (a text stays one)
        args += ["-p", f"{k}:={ros_text(v)}"]
    return args


def cell_network(environ: dict[str, str] | None = None) -> tuple[int, str, str]:
    """The ROS domain and discovery range a cell runs on, and where they come
    from: ``ROS_DOMAIN_ID`` and ``ROS_AUTOMATIC_DISCOVERY_RANGE`` when set,
    else a random domain in 100-199 (a private graph) and LOCALHOST."""
    env = os.environ if environ is None else environ
    text = env.get("ROS_DOMAIN_ID", "")
    if text.isdigit():
        domain, source = int(text), "ROS_DOMAIN_ID"
    else:
        domain, source = random.randint(100, 199), "random in 100-199; set ROS_DOMAIN_ID to choose"
    return domain, env.get("ROS_AUTOMATIC_DISCOVERY_RANGE") or "LOCALHOST", source


@contextmanager
def cell_environment(domain: int | None) -> Iterator[dict[str, str]]:
    """The environment of the cell's processes (this one's included while it
    lasts): the domain given, else :func:`cell_network`'s, its discovery
    range and winder's DDS profile (:mod:`winder.ros.dds`)."""
    env = dict(os.environ)
    chosen, discovery, _ = cell_network(env)
    env["ROS_DOMAIN_ID"] = str(chosen if domain is None else domain)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = discovery
    env["PYTHONUNBUFFERED"] = "1"
    use_profile(env)
    keys = ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", *PROFILE_KEYS)
    saved = {k: os.environ.get(k) for k in keys}
    os.environ.update({k: env[k] for k in keys if k in env})
    try:
        yield env
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


class NodeProcesses:
    """The node executables as child processes, output to ``log_dir/<name>.log``
    (:class:`winder.procs.Children`); :meth:`stop` sends SIGINT (the nodes
    close their bags) and kills what is still running after ``grace`` seconds.
    The children get SIGINT when this process dies, however it dies."""

    def __init__(self, env: dict[str, str], log_dir: Path, early: EarlyContainer | None = None) -> None:
        self.env = env
        self.log_dir = log_dir
        self.children = early.children if early is not None else Children(log_dir, env)
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self.early = early

    def start(self, name: str, args: list[str]) -> subprocess.Popen[bytes]:
        p = self.children.start([find_executable(name), *args], name)
        self.procs[name] = p
        return p

    def left_cell(self) -> str:
        """Why a child left its cell at start (it exited with
        :data:`winder.ros.managed.LEFT_CELL`: another node already plays its
        part in the namespace), from the ERROR line of its log; "" if none did."""
        for name, p in self.procs.items():
            if p.poll() == LEFT_CELL:
                try:
                    lines = (self.log_dir / f"{name}.log").read_text(errors="replace").splitlines()
                except OSError:
                    lines = []
                said = [line.split("]: ", 1)[-1] for line in lines if "already runs in" in line]
                if said:  # else status 2 for another reason (a usage error): dead() reports it
                    return said[-1]
        return ""

    def dead(self) -> str | None:
        """``"<name> exited with status N"`` for the first child that ended, else None."""
        for name, p in self.procs.items():
            if p.poll() is not None:
                return NodeExit(f"{name} exited with status {p.returncode}")
        return None

    def stop(self, grace: float = 15.0) -> bool:
        """Stop them all: True if each ended by itself, status 0."""
        if self.early is not None:
            self.early.close()  # if it never had its arguments, it leaves at once
        killed = self.children.stop_all(signal.SIGINT, grace)
        return not killed and all(p.returncode == 0 for p, _, _ in self.children.started)


#: what each role is called in messages
ROLE_WORDS = {"consumer": "the step consumer", "profile": "the profile node"}
#: Seconds between two looks at the graph for the consumer's node name.
GRAPH_POLL = 0.5


class RemoteSettings:
    """Settings for a node of the cell that runs elsewhere on the graph
    (``winder run --external``), found by its role (:mod:`winder.ros.graph`)
    and set through its standard ``set_parameters_atomically`` service, all
    or none, before the job starts. :meth:`step` moves it on; ``done`` once
    set; a refusal (the node refused a value, a read-only or undeclared
    parameter) is returned as a one-line reason naming the settings. While
    the graph shows no node, or two, in the role, it waits (``waiting`` says
    for what; a node killed outright stays on the graph for a while)."""

    def __init__(self, node: Node, namespace: str, role: str, values: dict[str, Any]) -> None:
        self.node = node
        self.namespace = namespace
        self.role = role
        self.values = dict(values)
        self.what = ROLE_WORDS[role]
        self.target = ""  #: the node's fully qualified name, once found
        self.client: Any = None
        self.future: Future | None = None
        self.asked = 0.0
        self.done = not self.values
        self.waiting = f"{self.what} on the graph, to set {', '.join(self.values)}"

    def step(self) -> str | None:
        if self.done:
            return None
        if self.client is None:
            find = consumers if self.role == "consumer" else profile_nodes
            found = find(self.node, self.namespace)
            if not found:
                return None
            if len(found) > 1:  # two consumers, or one that died and is not off the graph yet: wait
                names = ", ".join(fully_qualified(*f) for f in found)
                self.waiting = (
                    f"one node as {self.what}, to set {', '.join(self.values)} on it: the graph shows "
                    f"{len(found)} in this cell ({names})"
                )
                return None
            self.target = fully_qualified(*found[0])
            service = f"{self.target}/set_parameters_atomically"
            self.client = self.node.create_client(SetParametersAtomically, service)
            self.waiting = f"{service}, to set {', '.join(self.values)}"
        if self.future is None or (not self.future.done() and time.monotonic() - self.asked > START_RETRY):
            if not self.client.service_is_ready():
                return None
            if self.future is not None:  # the reply was lost while the service matched: ask again
                self.client.remove_pending_request(self.future)
            request = SetParametersAtomically.Request(
                parameters=[Parameter(k, value=v).to_parameter_msg() for k, v in self.values.items()]
            )
            self.future, self.asked = self.client.call_async(request), time.monotonic()
            return None
        if not self.future.done():
            return None
        reply = self.future.result()
        result = reply.result if reply is not None else None
        if result is not None and result.successful:
            self.done = True
            return None
        why = (result.reason if result is not None else "") or "no reason given"
        why = why.splitlines()[0] if why.strip() else "no reason given"
        named = [k for k in self.values if re.search(rf"(?<![\w.]){re.escape(k)}(?![\w.])", why)]
        names = "" if named else f" ({', '.join(self.values)})"
        return f"job not started: {self.what} {self.target} refused the settings of this run{names}: {why}"


class CellWatch:
    """What this process hears of the cell on /diagnostics, and its start call.

    A status is taken only from the cell's own nodes, each for the part the
    graph shows it in (:meth:`winder.ros.peers.Peers.deliver_by_part`), and
    only the sender's own: the consumer (the node that executes the steps:
    the sim node, or a hardware driver in its place) is the node that reads
    ``winder/step_times`` and writes ``winder/progress``, whatever its name
    and whatever a status says of its role. A stranger's status, named like
    the consumer's or saying ``role: consumer``, ends no run.

    ``heard_consumer``: the consumer's job status can reach us (so no report
    can be missed once the job starts); ``job_seen``: the interp node reports
    the job sending; ``summary``: the consumer's final job report (``done``,
    ``aborted`` or ``incomplete``); ``errors``: ERROR statuses of the cell's
    nodes. ``remote``: settings for nodes that run elsewhere (role -> values),
    set before the job starts (:class:`RemoteSettings`).
    """

    def __init__(
        self,
        node: Node,
        namespace: str,
        remote: dict[str, dict[str, Any]] | None = None,
        own: Callable[[], set[str]] | None = None,
    ) -> None:
        self.node = node
        #: the pids of the nodes this process started (None: it started none, they run elsewhere)
        self.own = own
        self.started: set[str] = set()  #: names of the nodes this process started (set by run_cell)
        self.consumer_here = True  #: the consumer is a process this one started (set by run_cell)
        self.consumer_blocked = ""  #: why the consumer is blocked (its job status), if it is
        #: an external consumer on the graph: when it was last looked for, and last seen (monotonic s)
        self.consumer_look = self.consumer_seen = 0.0
        self.occupied = ""  #: another cell's node heard in this namespace, in words
        self.refused = ""  #: why the job was refused before it started (a setting, the start call)
        self.foreign: dict[str, str] = {}  #: node -> what it refused from foreign senders
        self.since = time.monotonic()
        self.namespace = namespace
        self.ns = namespace.strip("/")
        self.consumer_nodes: set[str] = set()  #: node names the graph shows as the cell's consumer
        self._looked = 0.0
        self.heard_consumer = False
        self.job_seen = False
        self.progress = 0.0
        self.sim_time = "0"
        self.summary: dict[str, str] | None = None
        self.message = ""
        self.run_id = ""  #: the run started (from the start reply or the interp node's status)
        self.errors: list[str] = []
        self.remote = [RemoteSettings(node, namespace, role, v) for role, v in (remote or {}).items() if v]
        self.external = set(remote or {})  #: roles whose nodes run elsewhere (not started here)
        # a status counts only from the cell's node in a part, for that part
        # (winder.ros.peers): a stranger's status named like ours fools nobody
        self.peers = Peers(node, namespace)
        self.peers.see_parts()
        attributed(
            node,
            DiagnosticArray,
            TOPIC_DIAGNOSTICS,
            self._on_raw,
            QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE),
        )
        # the run starts as a goal of the cell's Wind action (the job as the nodes have it)
        self.wind = ActionClient(node, Wind, f"{namespace.rstrip('/')}/{ACTION_WIND}")
        self._request: Future | None = None  # the goal sent, its acceptance
        self._result: Future | None = None  # its result, once accepted
        self._goal_run = ""  # the run its feedback names
        self._asked = 0.0
        self.accepted = False
        self.not_ready = ""  #: the last 'not ready' reply to a start request

    def close(self) -> None:
        """The action client goes before the node: it holds the node's handle."""
        self.wind.destroy()

    def waiting_for(self) -> str:
        """What the start of the job still waits for, in words (when it never came)."""
        if not self.heard_consumer:  # the likelier of the two to be missing, and the one to name
            return (
                "the step consumer (sim_node or a hardware driver), which is not on this graph: is it "
                "running, on the same ROS_DOMAIN_ID, discovery range (and static peers) as this host?"
            )
        if not self.wind.server_is_ready():
            return f"the interp node's {ACTION_WIND} action server"
        pending = next((r for r in self.remote if not r.done), None)
        if pending is not None:
            return pending.waiting
        blocked = f": {self.consumer_blocked}" if self.consumer_blocked else ""
        return f"the cell to be ready ({self.not_ready or 'no answer to the goal yet'}){blocked}"

    def _look(self, force: bool = False) -> None:
        """The consumer's node name(s) from the graph (at most every GRAPH_POLL s)."""
        now = time.monotonic()
        if force or now - self._looked >= GRAPH_POLL:
            self._looked = now
            self.consumer_nodes |= {name for name, _ in consumers(self.node, self.namespace)}

    def _on_raw(self, raw: bytes, gid: bytes) -> None:
        try:
            msg = deserialize_message(raw, DiagnosticArray)
        except Exception:  # not a DiagnosticArray: nothing to read
            return
        if not any(in_namespace(st.name, self.ns) for st in msg.status):
            return  # another cell's (or nobody's): not this run's
        # taken for the part its sender plays on the graph, never for a name or
        # role in its payload; held while the graph does not name or place its
        # sender yet (a node's first status may come before)
        take = lambda role, who: self._on_diagnostics(msg, role, who)  # noqa: E731 - the message already parsed
        self.peers.deliver_by_part(TOPIC_DIAGNOSTICS, gid, raw, take)

    def _on_diagnostics(self, msg: DiagnosticArray, role: str, who: Who) -> None:
        """The statuses of the cell's node ``who``, which plays ``role`` (its own only)."""
        for st in msg.status:
            if "/" + st.name.split(":", 1)[0].strip("/") != who.fq:
                continue  # a status it sends for another node: not its to give
            values = {kv.key: kv.value for kv in st.values}
            if self._stranger(st.name, values, role):
                continue
            if values.get("intruders"):  # what this node refused from foreign senders
                self.foreign[st.name.split(":", 1)[0]] = values["intruders"]
            job = st.name.endswith(f": {TASK_JOB}")
            consumer = job and role == "consumer"
            if consumer:
                self.heard_consumer = True
                # a consumer blocked by its settings says why in its job status: named when the start waits
                self.consumer_blocked = st.message if values.get("state") == JobState.BLOCKED else ""
            asked = self._request is not None  # a run the interp node had before we asked is not ours
            if asked and job and role == "interp" and values.get("run_id"):
                self.job_seen = True  # the start request got through
                self.run_id = self.run_id or values["run_id"]
            if consumer and values.get("run_id") and values["run_id"] == self.run_id:
                self.progress = float(values.get("progress", 0.0))
                self.sim_time = values.get("sim_time_s", "0")
                if values.get("state") in FINAL_JOB_STATES:
                    self.summary = values
                    self.message = st.message
            elif values.get("run_id") and values["run_id"] != self.run_id:
                # another run's: the consumer keeps telling how the last run ended (a failed
                # run's final report, at ERROR) until the next one starts; not this run's error
                continue
            elif st.level == bytes([ERROR]):
                report = f"{st.name}: {st.message}"
                if report not in self.errors:  # a status repeats every second while it lasts
                    self.errors.append(report)

    def _stranger(self, name: str, values: dict[str, str], role: str) -> bool:
        """A status of the node in ``role`` that this process did not start
        (another cell's, pinned in the namespace before ours showed): noted,
        never taken as ours."""
        if self.own is None or "pid" not in values:
            return False
        if values.get("host") == socket.gethostname() and values["pid"] in self.own():
            return False
        node = name.split(":", 1)[0].rsplit("/", 1)[-1]
        if role in self.external:
            # a node of a part that runs elsewhere is another process' by design; one
            # named like a node this process started is a stranger's all the same
            return node in self.started
        self.occupied = self.occupied or (
            f"another cell runs in namespace /{self.ns}: {name.split(':', 1)[0]} "
            f"(pid {values['pid']} on {values.get('host', '?')}); start this one with --namespace "
            "or another ROS_DOMAIN_ID"
        )
        return True

    def _alone(self) -> bool:
        """The graph shows this namespace holding only the nodes this process
        started, each once, each in its part: no other cell here, known
        without waiting for statuses."""
        ns = "/" + self.ns if self.ns else "/"
        names = self.node.get_node_names_and_namespaces()
        if any(names.count((name, ns)) != 1 for name in self.started):
            return False
        for role in ROLES:
            if role in self.external:
                continue
            holders = self.peers.holders(role)
            if len(holders) != 1 or next(iter(holders))[0] not in self.started:
                return False
        return True

    def _consumer_reports_here(self) -> bool:
        """The consumer's /diagnostics writer is matched with this process'
        reader (the graph shows it), so its job reports reach us: no need to
        wait for its first 1 Hz status to know."""
        self._look(force=True)
        ns = "/" + self.ns if self.ns else "/"
        return any(
            info.node_name in self.consumer_nodes and info.node_namespace == ns
            for info in self.node.get_publishers_info_by_topic(TOPIC_DIAGNOSTICS)
        )

    def ask_to_start(self) -> str | None:
        """One step of starting the job: set the remote nodes' settings, send
        the Wind goal once the cell is listening, send it again if its
        acceptance is lost, and return the reason if the job was refused
        (None while starting or once started)."""
        self.accepted = self.accepted or self.job_seen
        if self.accepted:
            return None
        ready = self.wind.server_is_ready()
        if not self.heard_consumer and ready:
            self.heard_consumer = self._consumer_reports_here()
        for remote in self.remote:
            refused = remote.step()
            if refused:
                return refused
        if not (ready and self.heard_consumer):
            return None
        if self.own is not None and time.monotonic() - self.since < OCCUPIED_WAIT and not self._alone():
            return None  # every node of the namespace has said who it is (1 Hz) before we start
        if self.occupied:
            return f"job not started: {self.occupied}"
        if not all(r.done for r in self.remote):
            return None
        req = self._request
        if req is None and time.monotonic() - self._asked < NOT_READY_RETRY:
            return None  # the last answer said "not ready" a moment ago
        if req is None or (not req.done() and time.monotonic() - self._asked > START_RETRY):
            # a goal's acceptance can be lost while the action's services are still matching:
            # send it again (a run already started by the first refuses it "is running": ours)
            self._request, self._result = self.wind.send_goal_async(Wind.Goal(), self._on_feedback), None
            self._asked = time.monotonic()
            return None
        if not req.done():
            return None
        handle = req.result()
        if handle is None or not handle.accepted:
            return "job refused: the interp node rejected the goal"
        if self._result is None:
            self._result = handle.get_result_async()
        if self._goal_run:
            self.accepted = True
            self.run_id = self.run_id or self._goal_run
        elif self._result.done():
            answer = self._result.result()
            message = answer.result.message if answer is not None else ""
            if answer is not None and (answer.result.run_id or "is running" in message):
                self.accepted = True  # ended already (or a second goal refused: the first's run is ours)
                said = re.search(r"\brun (\S+) is running", message)
                self.run_id = self.run_id or answer.result.run_id or (said.group(1) if said else "")
            elif "not ready" in message:
                self.not_ready = message
                self._request = None  # the consumer or the profile node is still coming up: ask again
            else:
                return f"job refused: {message or 'no reason given'}"
        return None

    def _on_feedback(self, msg: Any) -> None:
        self._goal_run = self._goal_run or msg.feedback.run_id


#: keys of `winder run` on a terminal: the profile node's service each calls
KEYS = {" ": "pause/resume", "p": "pause", "r": "resume", "a": "abort"}


class Keys:
    """Single keys from a terminal on stdin, read without waiting (cbreak
    mode, restored at :meth:`close`); does nothing when stdin is not a
    terminal (a script, CI). Each key calls the profile node's ``~/pause``,
    ``~/resume`` or ``~/abort``; the space bar pauses a running cell and
    resumes a paused one. Replies are written to stderr."""

    def __init__(self, node: Node, namespace: str) -> None:
        self.terminal = KeyReader()
        self.enabled = self.terminal.enabled
        self.paused = False
        self.pending: list[tuple[str, Future]] = []
        base = f"{namespace.rstrip('/')}/profile_node"
        self.clients = {k: node.create_client(Trigger, f"{base}/{k}") for k in ("pause", "resume", "abort")}
        if self.enabled:
            sys.stderr.write("keys: space pause/resume, p pause, r resume, a abort\n")

    def poll(self) -> None:
        """Act on the keys typed since the last call, report the replies that came."""
        for key in self.terminal.read():
            action = KEYS.get(key)
            if action == "pause/resume":
                action = "resume" if self.paused else "pause"
            if action is not None:
                # the toggle follows what was asked, at once (a key typed before
                # the reply toggles back); a refusal below puts it right
                self.paused = {"pause": True, "resume": False}.get(action, self.paused)
                self.pending.append((action, self.clients[action].call_async(Trigger.Request())))
        for item in [p for p in self.pending if p[1].done()]:
            self.pending.remove(item)
            action, future = item
            reply = future.result()
            if reply is not None and not reply.success and action in ("pause", "resume"):
                self.paused = "already paused" in reply.message or (action == "resume" and self.paused)
            text = reply.message if reply is not None else "no reply"
            sys.stderr.write(f"\n{action}: {text}\n")

    def close(self) -> None:
        self.terminal.close()


def _spawn(
    procs: NodeProcesses,
    params: dict[str, dict[str, Any]],
    namespace: str,
    external: frozenset[str],
    one_process: bool = False,
    nodes: dict[str, str] = NODES,
) -> None:
    if one_process:  # the three in one container process, each node's parameters in a section of its own
        path = procs.log_dir / "cell_params.yaml"
        path.write_text(cell_params_file(params, namespace))
        args = [*ros_args({}, namespace), "--params-file", str(path)]
        if procs.early is not None:  # started while the command read its arguments: it waits for these
            procs.procs[CONTAINER] = procs.early.proc
            procs.early.hand(procs.env, args)
        else:
            procs.start(CONTAINER, [*(CELL_CLASSES[key] for key in START_ORDER), *args])
        return
    for key in START_ORDER:
        if key in external:
            continue  # it runs elsewhere on the graph (another host)
        procs.start(nodes[key], ros_args(_node_params(params, key), namespace))


def cell_params_file(params: dict[str, dict[str, Any]], namespace: str) -> str:
    """A ROS parameters file with each node's parameters under its fully
    qualified name, for the nodes of one container. (rcl's node-prefixed
    ``-p node:name:=value`` matches a node only outside any namespace: in a
    namespaced cell every setting was dropped without a word.)"""
    ns = namespace.strip("/")
    lines = []
    for key in START_ORDER:
        values = _node_params(params, key)
        lines.append(f"{'/' + ns if ns else ''}/{NODES[key]}:")
        lines.append("  ros__parameters:" + ("" if values else " {}"))
        lines += [f"    {k}: {ros_text(v)}" for k, v in values.items()]
    return "\n".join(lines) + "\n"


def _node_params(params: dict[str, dict[str, Any]], key: str) -> dict[str, Any]:
    node_params = dict(params.get(key, {}))
    if key == "interp":
        node_params["autostart"] = False  # started by the watch, once it listens
    return node_params


def _wait_for_job(
    node: Node,
    watch: CellWatch,
    procs: NodeProcesses,
    timeouts: tuple[float, float],
    progress: Callable[[float, str], None] | None,
    keys: Keys | None,
    interrupts: Interrupts,
) -> str:
    """Spin until the consumer's final report; the reason if it never came
    (the job not started within ``timeouts[0]`` s, or not done within ``timeouts[1]``).
    A signal taken by ``interrupts`` ends it between two rounds, never inside
    one (a KeyboardInterrupt raised in Python code that rclpy's C++ runs can be lost)."""
    start_timeout, timeout = timeouts
    executor = SenderExecutor()  # the watch takes /diagnostics with each sender (winder.ros.sender)
    executor.add_node(node)
    t0 = time.monotonic()
    waited = min(start_timeout, timeout)
    t_start, t_end = t0 + waited, t0 + timeout
    while watch.summary is None:
        with interrupts.held():
            refused = watch.ask_to_start()
            if refused:
                watch.refused = refused
                return refused
            # what the start waits for (the graph: the nodes' services and
            # endpoints) wakes no executor: look often until the job has started
            fast = not watch.accepted and time.monotonic() - t0 < START_POLL_FOR
            executor.spin_once(timeout_sec=START_POLL if fast else 0.1)
            if keys is not None:
                keys.poll()
            if progress is not None:
                progress(watch.progress, watch.sim_time)
            left = procs.left_cell()
            if left:  # a node of ours found another cell's node in its part and did not join
                watch.occupied = watch.occupied or left
                return f"job not started: {watch.occupied}"
            dead = procs.dead()
            if dead:
                return dead
            now = time.monotonic()
            gone = _consumer_gone(node, watch, now)
            if gone:
                return gone
            if not watch.accepted and now > t_start:
                return f"the job did not start within {waited:g} s: waiting for {watch.waiting_for()}"
            if now > t_end:
                return f"job did not finish within {timeout:g} s"
    return ""


#: s an external consumer may be missing from the graph mid-run before the run is given up
CONSUMER_GONE_S = 3.0


def _consumer_gone(node: Node, watch: CellWatch, now: float) -> str:
    """A consumer this process did not start (``--external sim``) that left
    the graph while the run goes on (stopped, killed: its participant gone
    or its lease out) ends the wait, named, after CONSUMER_GONE_S s: before,
    ``winder run`` waited for a final report that could not come until its
    ``--timeout`` (an hour). One look at the graph a second."""
    if not watch.accepted or watch.consumer_here:
        return ""  # a consumer started here is watched as a process (procs.dead)
    if now - watch.consumer_look < 1.0:
        return ""
    watch.consumer_look = now
    if consumers(node, watch.ns):
        watch.consumer_seen = now
        return ""
    if not watch.consumer_seen or now - watch.consumer_seen < CONSUMER_GONE_S:
        return ""  # (never seen on this node's graph: nothing it could tell went)
    where = watch.ns or "/"
    return f"the step consumer left the graph mid-run (none in {where} for {now - watch.consumer_seen:.0f} s)"


def _foreign(watch: CellWatch) -> str:
    """What the cell's nodes and this process refused from foreign senders
    (``ignored, foreign`` in the summary): ``<refuser>: <sender> (n on
    <topic>)...``, each refuser's in one entry. Never the cell's own nodes: a
    node that heard one of them before its graph showed it in its part
    (a discovery race) may have refused and counted it."""
    ns = watch.ns
    own = {fully_qualified(name, ns) for name in watch.started}
    own |= {r.target for r in watch.remote if r.target}  # the --external nodes found in their part
    refused = {**watch.foreign, "winder run": watch.peers.intruders.summary()}
    kept = {who: without_senders(what, own) for who, what in refused.items()}
    return "; ".join(f"{who}: {what}" for who, what in kept.items() if what)


def _result(watch: CellWatch, failure: str, log_dir: Path) -> CellResult:
    result = CellResult(False, message=failure, log_dir=log_dir, node_died=isinstance(failure, NodeExit))
    if watch.summary is not None:
        result.summary = watch.summary
        result.ok = watch.summary.get("state") == JobState.DONE
        result.message = watch.message
    result.errors = list(watch.errors)
    result.occupied = bool(watch.occupied) and watch.summary is None
    result.refused = bool(watch.refused) and watch.summary is None
    result.intruders = _foreign(watch)
    if watch.errors and not result.message:
        result.message = watch.errors[0]
    if result.ok and not watch.errors and not JobReport.from_values(result.summary).errors:
        # a clean run's logs say nothing the summary does not: leave no litter in /tmp
        shutil.rmtree(log_dir, ignore_errors=True)
        result.log_dir = None
    return result


def run_cell(
    params: dict[str, dict[str, Any]],
    *,
    namespace: str = "",
    domain: int | None = None,
    timeout: float = 3600.0,
    progress: Callable[[float, str], None] | None = None,
    external: frozenset[str] = frozenset(),
    start_timeout: float = 60.0,
    view: Any = None,
    interrupts: Interrupts | None = None,
    one_process: bool = False,
    early: EarlyContainer | None = None,
    consumer: str = NODES["sim"],
) -> CellResult:
    """Start the three nodes with ``params[node]`` parameters (but those in
    ``external``, which run elsewhere on the graph: their ``params`` are set
    on them through their parameter services before the job starts, and a
    refusal ends the run unstarted), wait for the consumer to report the job
    done, stop them with SIGINT, return the summary; give up after
    ``timeout`` s, or ``start_timeout`` s if the job never started. The
    nodes' output goes to ``result.log_dir``, removed after a clean run.
    ``view``: a :class:`winder.ros.view.LiveView` (``--foxglove``), listening
    on the graph from before the nodes start until they are stopped.

    Ctrl-C or SIGTERM ends it (KeyboardInterrupt, the nodes stopped), taken
    by ``interrupts`` (installed by the caller, else here): rclpy's own
    handlers are not used (:mod:`winder.interrupts`). They shut the context
    down from a thread of their own, under the view's spinning thread, in
    the middle of creating the node or the view's subscriptions (a
    traceback), and a Ctrl-C while the cell started was lost at times: the
    job ran to its end (10 of 40 signals under load, ``--foxglove``).

    ``one_process``: the three nodes run in one ``winder_container`` process
    (none may be external): they find each other without discovery between
    processes, so the job starts sooner, but share one core. ``early``: that
    container, started already (:func:`winder.ros.early.prestart`): it gets
    its arguments when the cell starts, and is stopped with the cell in any case.
    ``consumer``: the consumer's executable, started in the place of ``sim_node``
    with ``params["sim"]`` (``cia402_node`` for ``winder run --drives``; not
    in one process)."""
    from rclpy.signals import SignalHandlerOptions

    if (one_process or early is not None) and external:
        if early is not None:
            early.cancel()
        raise BadInputError(
            f"one_process with external={sorted(external)} is invalid: one process holds the whole cell"
        )
    one_process = one_process or early is not None
    if one_process and consumer != NODES["sim"]:
        if early is not None:
            early.cancel()
        raise BadInputError(
            f"one_process with consumer={consumer!r} is invalid: it runs as a process of its own"
        )
    nodes = {**NODES, "sim": consumer}
    own = interrupts is None
    if interrupts is None:
        interrupts = Interrupts().install()
    log_dir = early.log_dir if early is not None else Path(tempfile.mkdtemp(prefix="winder-cell-"))
    clean, adopted = False, False
    errors: list[str] = []  # the watch's, once it is there
    try:
        with cell_environment(domain) as env:
            procs = NodeProcesses(env, log_dir, early)
            adopted = True
            node: Node | None = None
            keys: Keys | None = None
            watch: CellWatch | None = None
            try:
                with interrupts.held():  # no signal between init and the nodes, the view's thread spinning
                    rclpy.init(args=[], signal_handler_options=SignalHandlerOptions.NO)
                    node = rclpy.create_node("winder_cell", namespace=namespace or "/")
                    keys = Keys(node, namespace)
                    if view is not None:
                        view.attach()
                        view.start()
                    remote = {NODE_ROLES[key]: dict(params.get(key, {})) for key in external}
                    own_pids = lambda: {str(p.pid) for p in procs.procs.values()}  # noqa: E731
                    watch = CellWatch(node, namespace, remote, own=own_pids)
                    errors = watch.errors
                    watch.started = {nodes[key] for key in NODE_ROLES if key not in external}
                    watch.consumer_here = "sim" not in external
                    _spawn(procs, params, namespace, external, one_process, nodes)
                failure = _wait_for_job(
                    node, watch, procs, (start_timeout, timeout), progress, keys, interrupts
                )
            finally:
                interrupts.ending()  # the view's thread stops before its node goes, the nodes before rclpy
                if keys is not None:
                    keys.close()
                if watch is not None:
                    watch.close()
                clean = procs.stop()
                if view is not None:
                    view.close()
                if node is not None:
                    node.destroy_node()
                rclpy.try_shutdown()
    except KeyboardInterrupt:
        if clean and not errors:  # stopped as asked, every node in order, nothing reported: no litter
            shutil.rmtree(log_dir, ignore_errors=True)
        raise
    finally:
        if early is not None and not adopted:  # ended before the cell had it (a signal)
            early.cancel()
        if own:
            interrupts.restore()
    result = _result(watch, failure, log_dir)
    if view is not None and view.ignored:  # what the live view did not show: not the cell's
        shown = f"live view: {view.ignored}"
        result.intruders = f"{result.intruders}; {shown}" if result.intruders else shown
    return result
