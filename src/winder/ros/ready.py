"""The start handshake on ``winder/ready`` (see :data:`winder.contract.topics.TOPIC_READY`).

A node that must be ready before a job starts announces its state with
:class:`Announcer` (latched, so a late-starting interp node hears it); the
interp node follows every announcement with :class:`Readiness`. Standard
messages only: a third-party consumer publishes ``KeyValue(key="consumer",
value="ready")`` on ``winder/ready`` with a reliable, transient-local QoS.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Collection
from typing import Any

from diagnostic_msgs.msg import KeyValue
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.serialization import deserialize_message

from winder.contract.states import ReadyState
from winder.contract.topics import READY_ROLES, READY_STATES, TOPIC_READY
from winder.ros.peers import Peers
from winder.ros.qos import QOS_LATCHED, QOS_LATCHED_READER
from winder.ros.sender import attributed
from winder.ros.timers import steady_timer

#: s between two looks at the graph while a node says "waiting" (see :class:`Announcer`)
RECHECK = 0.05
#: after waiting this long (s), it looks every :data:`RECHECK_SLOW` s only
FAST_WAIT = 3.0
RECHECK_SLOW = 0.5


class Announcer:
    """Publishes one node's readiness: each change at once (latched), and
    again on :meth:`repeat` (the node's 1 Hz report), so that a listener that
    forgot it (see :class:`Readiness`) hears it again.

    ``recheck`` (the node's own announce) is called every :data:`RECHECK` s
    while the node says "waiting": what it waits for is on the graph (its
    publishers matched, the cell's other nodes discovered), which tells no
    one when it changes; looked at only with the 1 Hz report, a cell's start
    waited up to a second, and a node started 1.2 s before it said ready.
    After :data:`FAST_WAIT` s of waiting (a cell part or the hardware is not
    there) it looks every :data:`RECHECK_SLOW` s: each look queries the
    graph, and 20 a second kept an idle bridge_node at 2-3 % of a core."""

    def __init__(self, node: Node, role: str, recheck: Callable[[], None] | None = None) -> None:
        assert role in READY_ROLES
        self.role = role
        self.log = node.get_logger()
        self.said = ""  # why it waits, as last said in the log
        self.pub = node.create_publisher(KeyValue, TOPIC_READY, QOS_LATCHED)
        self.state: ReadyState | None = None
        self.timer = self.slow_timer = None
        self.waiting_since = 0.0
        if recheck is not None:
            self.recheck = recheck
            self.timer = steady_timer(node, RECHECK, self._fast)
            self.timer.cancel()  # runs while "waiting"
            self.slow_timer = steady_timer(node, RECHECK_SLOW, recheck)
            self.slow_timer.cancel()  # after FAST_WAIT s of it

    def _fast(self) -> None:
        if time.monotonic() - self.waiting_since > FAST_WAIT and self.timer is not None:
            self.timer.cancel()
            if self.slow_timer is not None:
                self.slow_timer.reset()
        self.recheck()

    def announce(self, state: ReadyState | str, why: str = "") -> None:
        """``state``; ``why``: what a node that says "waiting" waits for,
        said in its log once it has waited :data:`FAST_WAIT` s (a cell part
        missing, or a graph that does not name it: what an operator asks
        of a cell that refuses "not ready"), and again when it changes."""
        assert state in READY_STATES
        state = ReadyState(state)
        if state is ReadyState.WAITING and why and self.state is ReadyState.WAITING:
            if why != self.said and time.monotonic() - self.waiting_since > FAST_WAIT:
                self.said = why
                self.log.info(f"not ready for a run: {why}")
        elif state is not ReadyState.WAITING and self.said:
            self.said = ""
            self.log.info(f"ready for a run ({state})")
        if state != self.state:
            if state is ReadyState.WAITING:
                self.waiting_since = time.monotonic()
            self.state = state
            self.pub.publish(KeyValue(key=self.role, value=state))
        if self.timer is None or self.slow_timer is None:
            return
        looking = not (self.timer.is_canceled() and self.slow_timer.is_canceled())
        if state is ReadyState.WAITING and not looking:
            self.timer.reset()
        elif state is not ReadyState.WAITING and looking:
            self.timer.cancel()
            self.slow_timer.cancel()

    def repeat(self) -> None:
        if self.state is not None:
            self.pub.publish(KeyValue(key=self.role, value=self.state))


#: an announcement older than this (s) no longer counts: the announcers repeat
#: theirs every second, so silence means the node is gone (a node killed
#: outright stays in the DDS graph, its latched "ready" with it, for ~20 s)
FRESH = 3.0


class Readiness:
    """What the cell's other nodes last said on ``winder/ready``, and when;
    anything that is not a known role and state is ignored (it cannot start a
    job), and so is an announcement that has not been repeated for
    :data:`FRESH` seconds."""

    def __init__(
        self, node: Node, on_change: Callable[[], None] | None = None, peers: Peers | None = None
    ) -> None:
        self.node = node
        self.states: dict[str, ReadyState] = {}
        self.heard: dict[str, float] = {}  # role -> monotonic time of its last announcement
        self.on_change = on_change
        # an announcement counts only from the cell's node in the role it names
        self.peers = peers or Peers(node)
        attributed(
            node,
            KeyValue,
            TOPIC_READY,
            self._on_raw,
            QOS_LATCHED_READER,  # deep: one role's announcement must not replace another's not taken yet
            event_callbacks=SubscriptionEventCallbacks(matched=self._on_matched),
        )

    def _on_raw(self, raw: bytes, gid: bytes) -> None:
        try:
            msg = deserialize_message(raw, KeyValue)
        except Exception:  # not a KeyValue: nothing to act on
            return
        if msg.key in READY_ROLES and msg.value in READY_STATES:
            self.peers.deliver(TOPIC_READY, gid, raw, lambda _raw: self._on_ready(msg), msg.key)

    def _on_matched(self, info: Any) -> None:
        """An announcer left (its node died or stopped): its last word, kept
        by the latched topic, no longer holds. Everything heard is forgotten;
        the announcers still there say their state again within a second."""
        if info.current_count_change < 0:
            self.states.clear()

    def _on_ready(self, msg: KeyValue) -> None:
        if msg.key not in READY_ROLES or msg.value not in READY_STATES:
            return
        fresh = time.monotonic() - self.heard.get(msg.key, -math.inf) <= FRESH
        self.heard[msg.key] = time.monotonic()
        if self.states.get(msg.key) != msg.value or not fresh:
            self.states[msg.key] = ReadyState(msg.value)
            if self.on_change is not None:
                self.on_change()

    def missing(self, excused: Collection[str] = ()) -> str:
        """Why a job cannot start now ("" if every role said ready). A role in
        ``excused`` that says ``busy`` does not hold a start (the interp node's
        verdict on a consumer still busy on a run it aborted)."""
        now = time.monotonic()
        waiting = []
        for r in READY_ROLES:
            silent = now - self.heard.get(r, -math.inf)
            if r not in self.states:
                waiting.append(f"{r} not heard from")
            elif silent > FRESH:
                waiting.append(f"{r} silent for {silent:.1f} s")
            elif self.states[r] is not ReadyState.READY and not (
                r in excused and self.states[r] is ReadyState.BUSY
            ):
                waiting.append(f"{r} {self.states[r]}")
            else:
                # a node killed and started again: until the dead process's endpoints leave the
                # graph (its lease) the cell's node in the part is the dead one, whose last
                # "ready" is still fresh; a start then went to it and stalled (make flakes)
                holders = self.peers.holders(r)
                if len(holders) > 1:
                    names = ", ".join(sorted(w.fq for w in holders))
                    waiting.append(
                        f"{r}: {len(holders)} nodes in the part ({names}) until one leaves the graph"
                    )
        return f"not ready: {', '.join(waiting)} (winder/ready)" if waiting else ""
