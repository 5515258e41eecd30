"""``winder view`` and ``winder run --foxglove``: a live cell's topics served
to Foxglove (:mod:`winder.record.foxglove` serves; here one rclpy node listens).

The node ``winder_view`` (in the cell's namespace) only subscribes, with
``raw=True``: each message's CDR bytes go to its Foxglove channel as DDS
delivered them, logged at the wall-clock time they arrived (a bag's log time
is the wall clock too). It publishes nothing and reads neither
``winder/steps`` nor ``winder/step_times``, so it plays no part in the cell
(:data:`winder.contract.trust.SIGNS`): the interp node's start gate, the
profile node's stream connection and the one-node-per-role check all see it
as the echo it is. Reading the keep-all step stream would also let a slow
viewer hold the profile node back; the layout's progress panel, which counts
step times, is therefore empty on a live cell (``winder/progress`` and the
job status's ``progress`` say it instead).

What it shows is the cell's own (docs/SECURITY.md): while a node of the cell
plays a part in the namespace, a message is served only when its publisher,
as the graph names it, is the cell's node that owns the topic
(:data:`winder.contract.trust.SHOWN`), and a ``/diagnostics`` array only when
it comes from the node its statuses name; anything else is counted and
reported once per sender as a WARN, as the cell's nodes do. With no cell in
the namespace, what is published there is shown as it comes: a recording
played by ``winder play`` (which refuses to play into a live cell's
namespace unless forced, and is then foreign to the view as to the cell).

The fast topics (joint states and commands, progress receipts, clock) are
read best-effort: a viewer that falls behind loses samples, never slows the
cell. The latched ones and the events are read as the cell offers them
(reliable, transient-local), so a viewer started during a run still gets the
run's job, path, configs, state and events; ``/diagnostics`` reliably, only
the statuses of the cell's own namespace (what its bag records).
"""

from __future__ import annotations

import contextlib
import threading
import time
from dataclasses import dataclass
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.serialization import deserialize_message

from winder.contract import qos as table
from winder.contract.topic_table import TOPICS
from winder.contract.topics import (
    TOPIC_DIAGNOSTICS,
    in_namespace,
)
from winder.contract.trust import SHOWN, SIGNS
from winder.record.foxglove import Channels
from winder.ros.graph import fully_qualified
from winder.ros.peers import Peers
from winder.ros.player import message_class
from winder.ros.qos import profile
from winder.ros.sender import SenderExecutor, attributed
from winder.ros.timers import steady_timer

__all__ = ["VIEW_TOPICS", "LiveView", "ViewTopic"]

#: s between the view's looks at the graph for a cell in its namespace
CELL_LOOK = 0.5
#: s a look that found no cell stays good: a message that comes later makes
#: the view look again before serving it (a cell that has just come, and a
#: forger who answers its first message at once, are not missed)
NO_CELL_FRESH = 0.005


@dataclass(frozen=True)
class ViewTopic:
    name: str  #: relative to the cell's namespace, as in winder.contract.topics
    msgtype: str
    qos: table.Qos  #: what the view subscribes with

    @property
    def keep(self) -> int:
        """Messages sent again to a client that subscribes: a latched topic's depth."""
        return self.qos.depth if self.qos.transient_local else 0


def _lossy(q: table.Qos) -> table.Qos:
    return table.Qos(reliable=False, transient_local=False, keep_all=False, depth=q.depth)


#: what the view serves, and how it reads each topic
VIEW_TOPICS = tuple(
    ViewTopic(t.name, t.type, _lossy(table.PROFILES[t.qos]) if t.qos == "state" else table.PROFILES[t.qos])
    for t in TOPICS
    if t.shown
)


def _full(name: str, namespace: str) -> str:
    """A topic's full name in the cell's namespace (a global one as it is)."""
    return name if name.startswith("/") else fully_qualified(name, namespace)


class LiveView:
    """The listening node and its Foxglove channels. :meth:`attach` once
    rclpy is initialised (it creates the node, in ``namespace``);
    :meth:`spin` in the calling thread, or :meth:`start` a thread of its own
    beside another node's executor (``winder run``)."""

    def __init__(self, channels: Channels, namespace: str) -> None:
        self.channels = channels
        self.namespace = namespace
        self.node: Node | None = None
        self.peers: Peers | None = None
        #: a node of the cell plays a part in the namespace (as of the last look)
        self.cell_here = False
        self.looked = 0.0  # time.monotonic() of the last look
        self.executor: SenderExecutor | None = None
        self.thread: threading.Thread | None = None
        #: relative name -> the channel's topic (full name); advertised from now on
        self.names = {t.name: _full(t.name, namespace) for t in VIEW_TOPICS}
        for topic in VIEW_TOPICS:
            self.channels.add(self.names[topic.name], topic.msgtype, keep=topic.keep)

    def attach(self) -> None:
        node = rclpy.create_node("winder_view", namespace=self.namespace or "/")
        self.node = node
        self.peers = Peers(node, self.namespace, what="show in the live view", patient=True)
        for topic in VIEW_TOPICS:
            full = self.names[topic.name]
            assert node.resolve_topic_name(topic.name) == full, (topic.name, full)
            take = self._diagnostics if topic.name == TOPIC_DIAGNOSTICS else self._forward(topic.name, full)
            attributed(node, message_class(topic.msgtype), topic.name, take, profile(topic.qos))
        self._look()
        steady_timer(node, CELL_LOOK, self._look)
        self.executor = SenderExecutor()
        self.executor.add_node(node)

    def _look(self) -> None:
        assert self.peers is not None
        self.cell_here = any(self.peers.holders(role) for role in SIGNS)
        self.looked = time.monotonic()

    def _no_cell(self) -> bool:
        """No node of a cell plays a part in the namespace, as of a fresh look."""
        if not self.cell_here and time.monotonic() - self.looked > NO_CELL_FRESH:
            self._look()
        return not self.cell_here

    def _forward(self, name: str, full: str) -> Any:
        """The callback of topic ``name``: its message served (logged at the
        time it arrived) if the cell's node owning the topic sent it, or if
        no cell is in the namespace. Either is judged only once the graph
        names the message's publisher: until then it is held
        (:meth:`winder.ros.peers.Peers.deliver`), so that neither a cell's
        node discovered after its first (latched) message nor a forger
        heard before the cell's nodes is judged on a graph that does not
        show them yet."""
        log = self.channels.log
        role = SHOWN[name]
        peers = self.peers
        assert peers is not None

        def judge(topic: str, gid: bytes) -> bool | None:
            if peers.sender(topic, gid) is None:
                return None  # held until the graph names it
            if self._no_cell():
                return True
            return peers.verdict(topic, gid, role)

        def take(raw: bytes, gid: bytes) -> None:
            stamp = time.time_ns()
            peers.deliver(name, gid, raw, lambda r: log(full, r, stamp), judge=judge)

        return take

    def _diagnostics(self, raw: bytes, gid: bytes) -> None:
        """A /diagnostics array, if any of its statuses is of the cell's
        namespace and, with a cell there, the node they name sent it; held,
        as a topic's message is (:meth:`_forward`), until the graph names its
        publisher (a node's first status may come before)."""
        peers = self.peers
        assert peers is not None
        msg = deserialize_message(raw, DiagnosticArray)
        named = {
            st.name.split(":", 1)[0].rsplit("/", 1)[-1]
            for st in msg.status
            if in_namespace(st.name, self.namespace)
        }
        if not named:
            return
        stamp = time.time_ns()

        def judge(topic: str, gid: bytes) -> bool | None:
            if peers.sender(topic, gid) is None:
                return None  # held until the graph names it
            if self._no_cell():
                return True
            return all(peers.admit_from(topic, gid, n) for n in sorted(named))

        full = self.names[TOPIC_DIAGNOSTICS]
        peers.deliver(TOPIC_DIAGNOSTICS, gid, raw, lambda r: self.channels.log(full, r, stamp), judge=judge)

    @property
    def ignored(self) -> str:
        """The messages not served because a node not the cell's sent them,
        per sender ("" if none)."""
        return self.peers.intruders.summary() if self.peers is not None else ""

    def spin(self) -> None:
        assert self.executor is not None, "attach() first"
        self.executor.spin()

    def start(self) -> None:
        """Spin in a thread of its own (ends with :meth:`close`)."""
        self.thread = threading.Thread(target=self._spin_quietly, name="winder-view", daemon=True)
        self.thread.start()

    def _spin_quietly(self) -> None:
        with contextlib.suppress(Exception):  # the context shut down under it: the view is ending
            self.spin()

    def close(self) -> None:
        """Stop spinning and destroy the node (left to the process' exit if
        its thread does not end: destroying a node under a waiting executor
        crashes, see :meth:`winder.ros.player.Player.close`)."""
        if self.executor is not None:
            self.executor.shutdown(timeout_sec=5.0)
        if self.thread is not None:
            self.thread.join(timeout=5.0)
            if self.thread.is_alive():
                return
        if self.node is not None:
            self.node.destroy_node()
            self.node = None


def run_view(view: LiveView) -> None:
    """``winder view``: init rclpy, listen until Ctrl-C (SIGINT) or SIGTERM, shut down."""
    from rclpy.executors import ExternalShutdownException

    from winder.ros.dds import use_profile

    use_profile()
    rclpy.init(args=[])
    try:
        view.attach()
        view.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass  # the way a view ends
    finally:
        view.close()
        rclpy.try_shutdown()
