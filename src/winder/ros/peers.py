"""Only the cell acts on the cell: the verdict on a message's sender.

ROS 2 without DDS Security authenticates nobody: any node on the domain may
publish on a cell's topics. A winder node therefore acts on a message only
when its publisher (the GID :mod:`winder.ros.sender` takes it with, looked
up on the graph) is the cell's own node that owns the topic
(:data:`winder.contract.trust.OWNERS`); anything else is counted, reported
once per foreign node as a WARN naming it, and never acted on (docs/SECURITY.md).

The cell's nodes are found by their part (:data:`winder.contract.trust.SIGNS`:
the topics they publish and read in the cell's namespace), never by their
names. The first node seen in a role is *pinned*: a second node that shows
up in the role later (another cell started in the same namespace, an
impersonator) is foreign while the pinned one is on the graph. A node that
restarts under its own name and namespace is the same node.
"""

from __future__ import annotations

import os
import socket
import time
from collections import Counter, deque
from collections.abc import Callable, Collection
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message
from rclpy.subscription import Subscription

from winder.contract.topics import PROCESS_KEYS, ROLE_KEY, TOPIC_DIAGNOSTICS, in_namespace
from winder.contract.trust import OTHER_PROCESS, OWNERS, ROLE_NAMES, SIGNS, Intruders
from winder.ros.dds import DISCOVERY_SERVER_KEY
from winder.ros.graph import Who, fully_qualified, publishers_by_gid, role_holders
from winder.ros.qos import QOS_DIAGNOSTICS
from winder.ros.sender import attributed
from winder.ros.timers import steady_timer

__all__ = ["Peers", "Solo"]

#: s a message is held for the graph to name its publisher (:meth:`Peers.deliver`),
#: counted in the node's own time: a stretch in which the node did not run at
#: all (its process held up, a host starved) does not count, as the graph
#: could not be looked at meanwhile. Only a publisher that never gets named (a
#: DDS writer of no ROS node) reaches it.
HOLD = 2.0
#: s between two looks at the held messages
RETRY = 0.01
#: a gap longer than this (s) between two looks is time the node did not run
STALLED = 0.1

#: a verdict on a message's sender: True act, False refused, None not known yet
Judge = Callable[[str, bytes], bool | None]
#: what settles a message held for :data:`HOLD` s without a verdict (None: refused as unnamed)
Expire = Callable[[str, bytes], None] | None
#: a held message: when (node's own time), its publisher's GID, payload, what acts on it, its
#: judge, what settles it at the end of its hold
Held = tuple[float, bytes, bytes, Callable[[bytes], None], Judge, Expire]


class Peers:
    """The cell's own nodes as ``node`` sees them on the graph, and the
    verdict on each message's sender (see the module doc). ``namespace``:
    the cell's (the node's own by default)."""

    def __init__(
        self,
        node: Node,
        namespace: str | None = None,
        warn: Callable[[str], None] | None = None,
        *,
        what: str = "change a run",
        patient: bool = False,
    ) -> None:
        self.node = node
        ns = (node.get_namespace() if namespace is None else namespace).strip("/")
        self.ns = "/" + ns if ns else "/"
        self.namespace = ns
        self.pinned: dict[str, Who] = {}
        self.gids: dict[bytes, Who] = {}  # publisher GID -> its node, as the graph reported it
        self.intruders = Intruders()  # over the node's life: each sender reported once
        self.run = Intruders()  # of the current run (the owner resets it): for its report
        self.unnamed = 0  # messages from endpoints the graph did not name yet: not acted on
        #: messages held while the graph does not name their publisher yet, per topic
        #: (in arrival order; each publisher's in its own order)
        self.held: dict[str, deque[Held]] = {}
        self._held_from: Counter[tuple[str, bytes]] = Counter()  # (topic, GID) -> messages held
        self._retry_timer: Any = None
        self._looked = 0.0  # time.monotonic() of the last look at the held messages
        self._stalled = 0.0  # s the node did not run while messages were held (not counted in HOLD)
        #: called when a new foreign sender is refused (the node says so in its status at once)
        self.on_new: Callable[[], None] | None = None
        #: called after held messages were acted on (from the retry timer, not
        #: the subscription's callback: work a node does after its callback must
        #: be woken, as the consumer's pump)
        self.on_late: Callable[[], None] | None = None
        self.warn = warn or (lambda text: node.get_logger().warning(text))
        #: what only the cell's own nodes may do here, in the warning ("show in the live view")
        self.what = what
        #: a message whose sender no node's part has shown by the end of its hold is
        #: refused unnamed, not in the sender's name (the live view, which has no cell to
        #: wait for: :meth:`verdict`)
        self.patient = patient

    # -- the graph ----------------------------------------------------------------
    def topic(self, name: str) -> str:
        return name if name.startswith("/") else fully_qualified(name, self.namespace)

    def sender(self, topic: str, gid: bytes) -> Who | None:
        """The node that owns the publisher ``gid`` on ``topic``, or None
        while the graph does not show it."""
        who = self.gids.get(gid)
        if who is None:
            self.gids.update(publishers_by_gid(self.node, self.topic(topic)))
            who = self.gids.get(gid)
        return who

    def holders(self, role: str) -> set[Who]:
        """The nodes in the cell's namespace that play ``role`` by their
        endpoints (normally one; this node itself included)."""
        return role_holders(self.node, self.namespace, role)

    def owner(self, role: str) -> Who | None:
        """The cell's node in ``role``: the pinned one while the graph shows
        it, else the only one the graph shows (pinned from now), else None."""
        pinned = self.pinned.get(role)
        holders = self.holders(role)
        if pinned is not None and pinned in holders:
            return pinned
        self.pinned.pop(role, None)
        if len(holders) == 1:
            self.pinned[role] = next(iter(holders))
            return self.pinned[role]
        return None

    def knows(self, *roles: str) -> str:
        """Why the cell's nodes in ``roles`` are not known yet ("" once each
        shows up on the graph alone or pinned): a node is ready only when it
        can tell its cell's messages from others'."""
        missing = []
        for role in roles:
            if self.owner(role) is None:
                holders = sorted(self.holders(role))
                if holders:
                    names = ", ".join(h.fq for h in holders)
                    missing.append(f"{len(holders)} nodes play the {ROLE_NAMES[role]} in {self.ns} ({names})")
                else:
                    missing.append(f"no {ROLE_NAMES[role]} in {self.ns} on the graph")
        return "; ".join(missing)

    def subscribe(
        self,
        msg_type: Any,
        topic: str,
        callback: Callable[[Any], None],
        qos: QoSProfile,
        role: str | None = None,
        **kwargs: Any,
    ) -> Subscription:
        """A subscription of this node whose ``callback`` gets only the
        messages of the cell's node that owns ``topic`` (:data:`OWNERS`; or
        plays ``role``), deserialized; what does not deserialize is dropped."""

        def act(raw: bytes) -> None:
            try:
                msg = deserialize_message(raw, msg_type)
            except Exception:  # not of the topic's type: nothing to act on
                return
            callback(msg)

        def take(raw: bytes, gid: bytes) -> None:
            self.deliver(topic, gid, raw, act, role)

        return attributed(self.node, msg_type, topic, take, qos, **kwargs)

    def see_parts(self) -> None:
        """Behind a discovery server (``ROS_DISCOVERY_SERVER``) a process
        learns only the endpoints of the topics it uses itself, so one that
        reads none of the parts' topics (``winder run``'s watch, ``winder
        ctl``) could tell no node's part, and so believe none. It reads one
        light topic of each part here (the interp node's ``winder/job``, the
        profile node's ``winder/control``, the consumer's
        ``winder/progress``), taking nothing from them. Elsewhere the graph
        shows every endpoint: nothing is made."""
        if not os.environ.get(DISCOVERY_SERVER_KEY):
            return
        from diagnostic_msgs.msg import KeyValue

        from winder.contract.topics import TOPIC_CONTROL, TOPIC_JOB, TOPIC_PROGRESS
        from winder.ros.qos import QOS_EVENTS, QOS_LATCHED_READER, QOS_STATE
        from winder_interfaces.msg import ControlEvent, JobDescription

        for msg_type, topic, qos in (
            (JobDescription, TOPIC_JOB, QOS_LATCHED_READER),
            (ControlEvent, TOPIC_CONTROL, QOS_EVENTS),
            (KeyValue, TOPIC_PROGRESS, QOS_STATE),
        ):
            self.node.create_subscription(msg_type, self.topic(topic), lambda _raw: None, qos, raw=True)

    # -- the verdict --------------------------------------------------------------
    def verdict(self, topic: str, gid: bytes, role: str | None = None) -> bool | None:
        """True: the message comes from the cell's node owning ``topic``
        (``role``, by default the owner in :data:`OWNERS`); False: from
        another node (counted, reported once per sender); None: the graph
        does not name its publisher yet, or shows no node in the role yet.

        The latter is a discovery race, not a stranger: the graph learns a
        node's endpoints one by one, so the cell's own node's first message
        (its latched "waiting" on ``winder/ready``) can come before the graph
        shows the endpoints that give it its part. Refused then, that node
        was counted, warned about and listed by ``winder run`` as foreign;
        held (:meth:`deliver`), it is judged again once its part shows, and
        a sender in whose role no node has shown by the end of the hold is
        refused then, in its name (:meth:`_expired`)."""
        role = role or OWNERS[topic]
        who = self.sender(topic, gid)
        if who is None:
            return None
        if who == self.pinned.get(role) or who == self.owner(role):
            return True
        if not self.holders(role):
            return None  # nobody plays the part yet, as far as the graph shows: judged again
        self.refuse(topic, who, gid, f"not the cell's {ROLE_NAMES[role]}")
        return False

    def _expired(self, topic: str, gid: bytes, role: str | None) -> None:
        """A message held by :meth:`verdict` for :data:`HOLD` s: refused in its
        sender's name if the graph names it (no node showed in the role
        meanwhile), else as unnamed."""
        role = role or OWNERS[topic]
        who = None if self.patient else self.sender(topic, gid)
        if who is None:
            self._unnamed(topic)
            return
        self.refuse(topic, who, gid, f"not the cell's {ROLE_NAMES[role]}: no node plays that part here")

    def _unnamed(self, topic: str) -> None:
        self.unnamed += 1
        if self.unnamed == 1:
            self.warn(
                f"{self.topic(topic)}: a message from a publisher the graph did not name "
                f"within {HOLD:g} s ignored (docs/SECURITY.md)"
            )

    def deliver(
        self,
        topic: str,
        gid: bytes,
        raw: bytes,
        act: Callable[[bytes], None],
        role: str | None = None,
        *,
        judge: Judge | None = None,
        expire: Expire = None,
    ) -> None:
        """``act(raw)`` if the message comes from the cell's node owning
        ``topic`` (see :meth:`verdict`; or as ``judge(topic, gid)`` says). A
        message whose publisher the graph does not name yet (its node's
        discovery info is a little behind its data), or, judged by
        :meth:`verdict`, one in whose role the graph shows no node yet, is
        held, with every later one of that publisher behind it so that their
        order stays, and judged again every 10 ms, for up to :data:`HOLD` s
        of the node's own time; then it is refused (:meth:`_expired`, or as
        ``expire(topic, gid)`` says, or as unnamed). Another publisher's
        messages on the topic do not wait behind it."""
        if judge is None:
            judge = lambda t, g: self.verdict(t, g, role)  # noqa: E731 - the default judge
            expire = lambda t, g: self._expired(t, g, role)  # noqa: E731 - and its end of a hold
        if self._held_from[topic, gid]:
            self._hold(topic, gid, raw, act, judge, expire)
            return
        verdict = judge(topic, gid)
        if verdict:
            act(raw)
        elif verdict is None:
            self._hold(topic, gid, raw, act, judge, expire)

    def deliver_from(
        self, topic: str, gid: bytes, raw: bytes, act: Callable[[bytes], None], names: Collection[str]
    ) -> None:
        """``act(raw)`` if the message speaks for the nodes ``names`` of this
        cell (the statuses of a ``/diagnostics`` array) and that very node
        sent it (:meth:`admit_from`), held as :meth:`deliver` holds one while
        the graph does not name its publisher yet."""

        def judge(t: str, g: bytes) -> bool | None:
            if self.sender(t, g) is None:
                return None
            return all(self.admit_from(t, g, n) for n in sorted(names))

        self.deliver(topic, gid, raw, act, judge=judge)

    def part(self, who: Who) -> str | None:
        """The role ``who`` plays in the cell: the node pinned in it, or the
        only one the graph shows there (:meth:`owner`); None if it plays none
        (a stranger, or a second node in a part)."""
        for role in SIGNS:
            if who == self.pinned.get(role) or who == self.owner(role):
                return role
        return None

    def deliver_by_part(self, topic: str, gid: bytes, raw: bytes, act: Callable[[str, Who], None]) -> None:
        """``act(role, sender)`` for a message that speaks for its sender as
        the cell's node in ``role`` (a ``/diagnostics`` array of job
        statuses): the role is the part the graph shows its publisher in
        (:meth:`part`), never one its payload names. Held as :meth:`deliver`
        holds one while the graph does not name the publisher, shows it as a
        second node in a part, or does not show every part yet (its own may be
        the one missing); refused, in its name, when it plays no part while
        every part shows, or still none at the end of the hold."""

        def judge(t: str, g: bytes) -> bool | None:
            who = self.sender(t, g)
            if who is None:
                return None
            if self.part(who) is not None:
                return True
            if any(who in held or not held for held in map(self.holders, SIGNS)):
                return None  # its part may show yet, or its twin leave the graph: judged again
            self.refuse(t, who, g, "it plays no part in the cell")
            return False

        def expire(t: str, g: bytes) -> None:
            who = self.sender(t, g)
            if who is None:
                self._unnamed(t)
            else:
                self.refuse(t, who, g, "it plays no part in the cell alone")

        def take(_raw: bytes) -> None:
            who = self.sender(topic, gid)
            role = None if who is None else self.part(who)
            if who is not None and role is not None:
                act(role, who)

        self.deliver(topic, gid, raw, take, judge=judge, expire=expire)

    def _own_time(self) -> float:
        """time.monotonic(), less the stretches in which the node did not run
        while messages were held (see :data:`HOLD`)."""
        return time.monotonic() - self._stalled

    def _hold(
        self, topic: str, gid: bytes, raw: bytes, act: Callable[[bytes], None], judge: Judge, expire: Expire
    ) -> None:
        if not self.held:
            self._looked = time.monotonic()  # the gap since the last look is no stall: nothing was held
        self.held.setdefault(topic, deque()).append((self._own_time(), gid, raw, act, judge, expire))
        self._held_from[topic, gid] += 1
        if self._retry_timer is None:
            self._retry_timer = steady_timer(self.node, RETRY, self._retry)
        elif self._retry_timer.is_canceled():
            self._retry_timer.reset()

    def _retry(self) -> None:
        now = time.monotonic()
        gap = now - self._looked
        self._looked = now
        if gap > STALLED:  # the node did not run (held up, starved): the graph was not looked at either
            self._stalled += gap - RETRY
        acted = False
        for topic in list(self.held):
            # taken out while judged: what is acted on may deliver more (held behind these)
            held = self.held.pop(topic)
            waiting: set[bytes] = set()  # publishers whose earlier message is still held
            kept: deque[Held] = deque()
            for item in held:
                since, gid, raw, act, judge, expire = item
                if gid in waiting:
                    kept.append(item)
                    continue
                verdict = judge(topic, gid)
                if verdict is None and self._own_time() - since < HOLD:
                    waiting.add(gid)
                    kept.append(item)
                    continue
                self._held_from[topic, gid] -= 1
                if not self._held_from[topic, gid]:
                    del self._held_from[topic, gid]
                if verdict:
                    act(raw)
                    acted = True
                elif verdict is None and expire is not None:
                    expire(topic, gid)
                elif verdict is None:
                    self._unnamed(topic)
            kept.extend(self.held.pop(topic, ()))  # held meanwhile, behind them
            if kept:
                self.held[topic] = kept
        if not self.held and self._retry_timer is not None:
            self._retry_timer.cancel()
        if acted and self.on_late is not None:
            self.on_late()

    def admit_from(self, topic: str, gid: bytes, name: str) -> bool:
        """Whether a message on ``topic`` that speaks for the node ``name``
        of this cell (a ``<node>: job`` status) comes from that very node, as
        the graph names its publisher. (Not whether that node plays a part:
        a process that uses no topic of the cell but /diagnostics, as
        ``winder run``, may not see the parts' endpoints behind a discovery
        server. A stranger named like the cell's node is told apart by the
        process its statuses name: :class:`Solo`, ``winder run``.)"""
        who = self.sender(topic, gid)
        if who is not None and who.name == name and who.namespace == self.ns:
            return True
        self.refuse(topic, who, gid, f"it speaks for {fully_qualified(name, self.namespace)}")
        return False

    def refuse(self, topic: str, who: Who | None, gid: bytes, why: str) -> None:
        if who is None:
            # an endpoint the graph does not name yet (its node's discovery info
            # is on its way): not acted on, and not blamed on anyone; the
            # messages that matter before a run are repeated (readiness, 1 Hz)
            self.unnamed += 1
            return
        sender = who.fq
        if any(who.participant != w.participant and who[:2] == w[:2] for w in self.pinned.values()):
            sender += OTHER_PROCESS
        self.run.count(sender, self.topic(topic))
        if self.intruders.count(sender, self.topic(topic)):
            self.warn(
                f"{self.topic(topic)}: messages from {sender} ignored ({why}); "
                f"only the cell's own nodes {self.what} (docs/SECURITY.md)"
            )
            if self.on_new is not None:
                self.on_new()


#: s a node listens for another node of its role before it takes a run
JOIN_LISTEN = 1.2


class Solo:
    """One node per role in a namespace. Every winder node's statuses end
    with the process that sent them (pid, host, start time:
    :data:`winder.contract.topics.PROCESS_KEYS`); when ``node`` hears a
    status of its own role in its namespace from another process, sent by
    the node the status names (no stranger can make it leave), the one that
    started later leaves: ``leave`` is called once with one line naming the
    other (the node says so and exits). The one that stays warns once.

    ``also``, if given, is handed every status message taken (its payload,
    its sender's GID and its statuses), so that a node that wants the
    statuses too needs no second subscription: each would wake the
    executor and parse the message again."""

    def __init__(
        self,
        node: Node,
        role: str,
        peers: Peers,
        leave: Callable[[str], None],
        also: Callable[[bytes, bytes, list[Any]], None] | None = None,
    ) -> None:
        self.node = node
        self.also = also
        self.role = role
        self.peers = peers
        self.leave = leave
        self.me = (str(os.getpid()), socket.gethostname())
        self.started_ns = time.time_ns()
        self.left = False
        self.alone = False  # known to be the only node of its role here (settled())
        self.warned: set[str] = set()
        self.t0 = time.monotonic()
        attributed(node, DiagnosticArray, TOPIC_DIAGNOSTICS, self._on_raw, QOS_DIAGNOSTICS)
        self.on_settled: Callable[[], None] | None = None
        self._timer = steady_timer(node, JOIN_LISTEN, self._settle)

    def _settle(self) -> None:
        self._timer.cancel()
        if self.on_settled is not None and not self.left:
            self.on_settled()

    def settled(self) -> bool:
        """Whether this node may take a run: it is alone in its role. Known
        at once when the graph shows the cell's other parts (discovery has
        run) and no other node in this part or under this name; else (a
        node of the part on the graph, alive or the ghost of a killed one)
        after listening :data:`JOIN_LISTEN` s to the statuses, which every
        node sends once a second, without hearing an earlier one. Before, a
        job description is not acted on."""
        if self.left:
            return False
        if not self.alone:
            self.alone = time.monotonic() - self.t0 >= JOIN_LISTEN or self._alone_on_graph()
        return self.alone

    def _alone_on_graph(self) -> bool:
        me = (self.node.get_name(), self.node.get_namespace())
        if self.node.get_node_names_and_namespaces().count(me) != 1:
            return False  # another node under this very name (a second cell's, or a ghost)
        if any((w.name, w.namespace) != me for w in self.peers.holders(self.role)):
            return False
        return all(self.peers.owner(r) is not None for r in SIGNS if r != self.role)

    def _on_raw(self, raw: bytes, gid: bytes) -> None:
        try:
            statuses = deserialize_message(raw, DiagnosticArray).status
        except Exception:  # not a DiagnosticArray
            return
        if self.also is not None:
            self.also(raw, gid, statuses)
        self._judge(raw, gid, statuses)

    def _judge(self, raw: bytes, gid: bytes, statuses: list[Any]) -> None:
        if self.left:
            return
        for st in statuses:
            values = {kv.key: kv.value for kv in st.values}
            if values.get(ROLE_KEY) != self.role or not in_namespace(st.name, self.peers.namespace):
                continue
            pid, host, started = (values.get(k, "") for k in PROCESS_KEYS)
            if (pid, host) == self.me or not started.isdigit():
                continue
            name = st.name.split(":", 1)[0].rsplit("/", 1)[-1]
            who = self.peers.sender(TOPIC_DIAGNOSTICS, gid)
            if who is None:
                # the graph does not name its sender yet (its discovery info is behind its
                # first status): judged again once it does, not a second later
                named = lambda t, g: None if self.peers.sender(t, g) is None else True  # noqa: E731
                self.peers.deliver(
                    TOPIC_DIAGNOSTICS, gid, raw, lambda _raw: self._judge(raw, gid, statuses), judge=named
                )
                return
            if (who.name, who.namespace) != (name, self.peers.ns):
                continue  # a status forged by another node: it cannot make this one leave
            other = f"{fully_qualified(name, self.peers.namespace)} (pid {pid} on {host})"
            if (int(started), pid) < (self.started_ns, self.me[0]):
                self.left = True
                self.leave(
                    f"another {ROLE_NAMES[self.role]} already runs in {self.peers.ns}: {other}; "
                    "this one does not join (one cell per namespace: start it with another "
                    "namespace or ROS_DOMAIN_ID)"
                )
                return
            if other not in self.warned:
                self.warned.add(other)
                self.node.get_logger().warning(
                    f"a second {ROLE_NAMES[self.role]} started in {self.peers.ns}: {other}; it will not join"
                )
