"""``winder play``: a recording's messages back onto a ROS graph.

:func:`winder.record.replay.plan_play` chooses what is played; here one node,
``winder_player`` (in the cell's namespace), publishes it: each topic with
the QoS it was recorded with (latched ones latched), every message in
log-time order at ``rate`` times the recorded pace. Nothing is dropped by
the player: the writers of the volatile topics are reliable and keep-all, so
a slow reliable keep-all subscriber holds the player back instead of losing
messages (a publish finds the writer's history full of messages that reader
has not acknowledged: it is tried again, and the recording's time goes on
from where it was held), one that takes nothing for :data:`STALL_S` s stops
the replay in one line, and before the node goes the player waits until
every subscriber has acknowledged every message. What a subscriber's own
history drops is its own: a keep-last reader whose depth is below a topic's
count loses the oldest messages it has not taken yet when it falls behind,
which no writer can see (nor the depth, which the graph does not show);
the player names the best-effort readers, which may lose any message, in
one line before it plays.

While it plays, the node offers ``~/pause``, ``~/resume``, ``~/toggle_paused``
and ``~/play_next`` (std_srvs/Trigger; play_next publishes the next message
while paused) and the parameter ``rate``; on a terminal the space bar pauses
and resumes, ``n`` plays the next message, ``+`` and ``-`` double and halve
the rate. A pause stops the recording's time: after the resume it goes on
from where it stopped, it does not catch up.
"""

from __future__ import annotations

import contextlib
import importlib
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import rclpy
from rcl_interfaces.msg import SetParametersResult
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from std_srvs.srv import Trigger

from winder.contract.topics import TOPIC_JOB
from winder.contract.trust import SIGNS
from winder.errors import BadBagError, BadInputError
from winder.interrupts import Interrupts
from winder.record.replay import PlayPlan, PlayTopic
from winder.ros.qos import profile

__all__ = ["PlayResult", "Player", "message_class"]

#: seconds the player waits, at the end, for its subscribers to acknowledge everything
#: (and longer after slow readers held it back: BACKLOG_FACTOR)
ACK_TIMEOUT = 10.0
#: seconds of discovery before the player trusts the graph's list of readers:
#: a newcomer learns of a participant at its next announcement, once a second
#: in winder's profile (0.06-1.07 s measured on a quiet machine, more under
#: load: at 1.0 s a reader already there missed the first messages in a
#: loaded CI run); only ``--force`` reaches it sooner than LIVE_LOOK
SETTLE = 2.5
#: seconds the player gives a matched reader to match it in turn before the first message
MATCH_GRACE = 0.1
#: seconds a publish may wait for room in its writer's history (a reliable keep-all
#: reader has not acknowledged what came before) before the replay stops: below the
#: 10 s lease of winder's DDS profile, so that a reader that stopped taking (a hung or
#: SIGSTOPped process) stops the replay before DDS drops it and the replay goes on without it
STALL_S = 5.0
#: a publish that took longer than this (s) waited for room in its writer's history
HELD_S = 0.01
#: the end's wait adds this many times as long as readers held the replay back: DDS tells
#: only whether every message is acknowledged, not how many are left, and a reader that
#: held the replay back still has what the writers' and its own histories hold to take
#: (thousands of messages a topic), at the pace that held it back (measured: a keep-all
#: reader taking 190 messages/s held a default job's replay at x10 back 63 s and needed
#: 105 s more for the rest)
BACKLOG_FACTOR = 2.0


def message_class(msgtype: str) -> Any:
    """The Python class of a ROS message type name (``sensor_msgs/msg/JointState``)."""
    pkg, kind, name = msgtype.split("/")
    try:
        return getattr(importlib.import_module(f"{pkg}.{kind}"), name)
    except (ImportError, AttributeError):
        raise BadBagError(f"message type {msgtype} is not installed here; it cannot be published") from None


@dataclass
class PlayResult:
    published: dict[str, int] = field(default_factory=dict)  #: by played name
    loops: int = 0
    wall_s: float = 0.0
    unacked: list[str] = field(default_factory=list)  #: topics whose readers did not acknowledge all
    held_s: float = 0.0  #: seconds slow reliable readers held the replay back (behind the rate)
    stalled: str = ""  #: why the replay stopped before its end (a reader took nothing), one line


class _Stalled(Exception):  # noqa: N818 - the replay's end, not a failure of the player
    """A reader took nothing for :data:`STALL_S` s: the replay stops (the message says where)."""


class Player:
    """Plays a :class:`PlayPlan` from the calling thread; services and the
    ``rate`` parameter are served by an executor thread meanwhile."""

    def __init__(
        self, plan: PlayPlan, *, rate: float = 1.0, node_namespace: str = "", start_paused: bool = False
    ) -> None:
        self.plan = plan
        self.node = rclpy.create_node("winder_player", namespace=node_namespace or "/")
        self.created = time.monotonic()
        self.cond = threading.Condition()
        self.rate = rate
        self.paused = start_paused
        self.steps = 0  # play_next requests not served yet
        self.stopped = False
        self.position_ns = plan.start_ns  # log time of the last message published
        self.anchor_wall = 0.0  # wall time at which log time anchor_log was due
        self.anchor_log = plan.start_ns
        self.held_s = 0.0  # how far slow readers held the replay behind the recording's time
        self.pubs: dict[str, Any] = {}
        for topic in plan.topics.values():
            cls = message_class(topic.msgtype)
            self.pubs[topic.recorded] = self.node.create_publisher(cls, topic.name, profile(topic.qos))
        self.node.declare_parameter("rate", rate)
        self.node.add_on_set_parameters_callback(self._on_parameters)
        for name, handler in (
            ("pause", self._pause),
            ("resume", self._resume),
            ("toggle_paused", self._toggle),
            ("play_next", self._play_next),
        ):
            self.node.create_service(Trigger, f"~/{name}", handler)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self._spin, name="player-services", daemon=True)
        self.thread.start()

    def _spin(self) -> None:
        with contextlib.suppress(Exception):  # the context was shut down under it: the player is ending
            self.executor.spin()

    # -- control (executor thread, or keys from the playing thread) -------------------
    def _reanchor(self) -> None:
        self.anchor_wall, self.anchor_log = time.monotonic(), self.position_ns

    def set_paused(self, paused: bool) -> str:
        with self.cond:
            if paused == self.paused:
                return "already paused" if paused else "not paused"
            self.paused = paused
            if not paused:
                self._reanchor()  # the recording's time goes on from where it stopped
            self.cond.notify_all()
        at = (self.position_ns - self.plan.first_ns) / 1e9
        return f"{'paused' if paused else 'resumed'} at {at:.3f} s of the recording"

    def _pause(self, _req: Trigger.Request, res: Trigger.Response) -> Trigger.Response:
        res.message = self.set_paused(True)
        res.success = res.message.startswith("paused")
        return res

    def _resume(self, _req: Trigger.Request, res: Trigger.Response) -> Trigger.Response:
        res.message = self.set_paused(False)
        res.success = res.message.startswith("resumed")
        return res

    def _toggle(self, _req: Trigger.Request, res: Trigger.Response) -> Trigger.Response:
        res.message = self.set_paused(not self.paused)
        res.success = True
        return res

    def play_next(self) -> str:
        with self.cond:
            if not self.paused:
                return "not paused: play_next steps through a paused replay"
            self.steps += 1
            self.cond.notify_all()
        return "the next message is published"

    def _play_next(self, _req: Trigger.Request, res: Trigger.Response) -> Trigger.Response:
        res.message = self.play_next()
        res.success = res.message.startswith("the next")
        return res

    def set_rate(self, rate: float) -> None:
        with self.cond:
            self.rate = rate
            self._reanchor()
            self.cond.notify_all()

    def _on_parameters(self, params: list[Parameter]) -> SetParametersResult:
        for p in params:
            if p.name == "rate":
                value = p.value
                if not isinstance(value, (int, float)) or isinstance(value, bool) or not 1e-3 <= value <= 1e6:
                    return SetParametersResult(
                        successful=False, reason=f"rate={value!r} is invalid: must be in [0.001, 1e6]"
                    )
                self.set_rate(float(value))
        return SetParametersResult(successful=True)

    # -- playing (the calling thread) -------------------------------------------------
    def wait_for_subscribers(self, timeout: float, *, first_reader: bool = False) -> str:
        """Wait until every subscriber the graph shows on a played topic is
        matched by the player's publisher, so that a reader already on the
        graph hears the first message (rosbag2 #109): at least
        :data:`SETTLE` s after the node was made, so that discovery has shown
        the readers there are (a graph with none: nothing to wait for), and
        with ``first_reader`` until at least one reader is matched (a reader
        started after the player). Bounded by ``timeout`` s; "" when matched,
        else the topics still unmatched (or that no reader came)."""
        deadline = time.monotonic() + timeout
        while True:
            missing = [
                t.name
                for t in self.plan.topics.values()
                if self.pubs[t.recorded].get_subscription_count() < self.node.count_subscribers(t.name)
            ]
            any_reader = any(p.get_subscription_count() for p in self.pubs.values())
            settled = time.monotonic() - self.created >= SETTLE
            if not missing and settled and (any_reader or not first_reader):
                if any_reader:  # the reader's side matches the player a moment after the player's side
                    time.sleep(MATCH_GRACE)
                return ""
            if time.monotonic() > deadline:
                return ", ".join(missing) if missing or any_reader else "no subscriber on any played topic"
            time.sleep(0.05)

    def _wait_until_due(self, t_ns: int, poll: Callable[[], None] | None) -> bool:
        """Block until the message of log time ``t_ns`` is due (or a step is
        asked for while paused); False if the player was stopped."""
        while True:
            if poll is not None:
                poll()
            with self.cond:
                if self.stopped:
                    return False
                if self.paused:
                    if self.steps:
                        self.steps -= 1
                        return True
                    self.cond.wait(0.05)
                    continue
                wait = self._due(t_ns) - time.monotonic()
                if wait <= 0:
                    return True
                self.cond.wait(min(wait, 0.05))

    def play(
        self,
        *,
        loop: bool = False,
        progress: Callable[[float, str], None] | None = None,
        poll: Callable[[], None] | None = None,
    ) -> PlayResult:
        """Publish the plan (again and again with ``loop``, until stopped)."""
        result = PlayResult({t.name: 0 for t in self.plan.topics.values()})
        wall0 = time.monotonic()
        span = max(self.plan.last_ns - self.plan.start_ns, 1)
        last_report = 0.0
        while not self.stopped:
            with self.cond:
                self.position_ns = self.anchor_log = self.plan.start_ns
                self.anchor_wall = time.monotonic()
            late = 0.0
            for topic, t, data in self.plan.messages():
                if not self._wait_until_due(t, poll):
                    break
                try:
                    if not self._publish(topic, t, data):
                        break  # stopped while a reader held it back
                except _Stalled as exc:
                    result.stalled = str(exc)
                    break
                result.published[topic.name] += 1
                self.position_ns = max(self.position_ns, t)
                now = time.monotonic()
                late = now - self._due(t)  # behind the recording's time (readers slower than the rate)
                if progress is not None and now - last_report > 0.1:
                    last_report = now
                    progress(
                        (self.position_ns - self.plan.start_ns) / span,
                        f"{(self.position_ns - self.plan.first_ns) / 1e9:8.3f} s  x{self.rate:g}"
                        + ("  paused" if self.paused else ""),
                    )
            else:
                if self.held_s and not self.paused:  # readers held it back: as late as the pass ended
                    self.held_s += max(late, 0.0)
                result.loops += 1
                if progress is not None:
                    progress(1.0, f"{(self.plan.last_ns - self.plan.first_ns) / 1e9:8.3f} s")
                if loop:
                    continue
            break
        if not result.stalled:  # a reader that held the replay back has its backlog still to take
            result.unacked = self.wait_for_acks(ACK_TIMEOUT + BACKLOG_FACTOR * self.held_s)
        result.held_s = self.held_s
        result.wall_s = time.monotonic() - wall0
        return result

    def _publish(self, topic: PlayTopic, t_ns: int, data: bytes) -> bool:
        """Publish one message (False: the player was stopped first). A
        reliable keep-all reader slower than the replay fills the writer's
        history with messages it has not acknowledged; a publish then waits
        for room, up to the writer's blocking time (Fast DDS' 100 ms), and
        fails after it (rmw: "cannot publish data"): it is tried again until
        the reader has made room. The replay is held back meanwhile (counted
        in :attr:`held_s`), and its time goes on from here, not catching up in
        a burst. :class:`_Stalled` after :data:`STALL_S` s without room."""
        from rclpy._rclpy_pybind11 import RCLError

        pub = self.pubs[topic.recorded]
        start = time.monotonic()
        while True:
            try:
                pub.publish(data)  # waits up to the writer's blocking time for room
                break
            except RCLError as exc:
                if self.stopped:
                    return False
                if time.monotonic() - start > STALL_S:
                    at = (t_ns - self.plan.first_ns) / 1e9
                    why = (str(exc).splitlines() or [type(exc).__name__])[0].split(", at ")[0]
                    raise _Stalled(
                        f"stopped at {at:.3f} s of the recording: a reliable reader of {topic.name} took no "
                        f"message for {STALL_S:g} s ({pub.get_subscription_count()} matched; the writer: "
                        f"{why}); nothing was dropped: the messages after it were not published"
                    ) from None
        if time.monotonic() - start > HELD_S:
            with self.cond:
                now = time.monotonic()
                self.held_s += max(now - self._due(t_ns), 0.0)
                # the recording's time goes on from this message, where the reader held it
                self.anchor_wall, self.anchor_log = now, max(self.position_ns, t_ns)
        return True

    def _due(self, t_ns: int) -> float:
        """The monotonic time the message of log time ``t_ns`` is due at, as the replay stands."""
        return self.anchor_wall + (t_ns - self.anchor_log) / 1e9 / self.rate

    def best_effort_readers(self) -> str:
        """The best-effort readers on the graph of a volatile played topic, in
        one line ("" if none): they may lose any message, and no writer
        learns of it. (A reader's history, keep-last or keep-all, and its
        depth are not announced on the graph: the player cannot name those.)"""
        from rclpy.qos import ReliabilityPolicy

        found = []
        for t in played_topics(self.plan):
            if t.latched:
                continue
            for info in self.node.get_subscriptions_info_by_topic(t.name):
                if info.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT:
                    found.append(f"{t.name}: {info.node_namespace.rstrip('/')}/{info.node_name}")
        if not found:
            return ""
        return f"best-effort readers may lose messages, unseen by the player: {'; '.join(found)}"

    def wait_for_acks(self, timeout: float) -> list[str]:
        """Wait until every reliable subscriber has acknowledged every message;
        the topics where some did not within ``timeout`` s."""
        from rclpy.duration import Duration

        deadline = time.monotonic() + timeout
        late = []
        for topic, pub in self.pubs.items():
            left = max(deadline - time.monotonic(), 0.0)
            if not pub.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9))):
                late.append(self.plan.topics[topic].name)
        return late

    def stop(self) -> None:
        with self.cond:
            self.stopped = True
            self.cond.notify_all()

    def close(self) -> None:
        """Stop the service thread, then destroy the node. A node destroyed
        while that thread still waits on it crashes the process (seen once,
        SIGSEGV, at a Ctrl-C mid-replay): if the thread has not ended, the
        node is left for the process' exit."""
        self.stop()
        self.executor.shutdown(timeout_sec=5.0)
        self.thread.join(timeout=5.0)
        if not self.thread.is_alive():
            self.node.destroy_node()


def played_topics(plan: PlayPlan) -> list[PlayTopic]:
    return sorted(plan.topics.values(), key=lambda t: t.name)


def describe(plan: PlayPlan) -> list[str]:
    """A table of the played topics: name, messages recorded, type, QoS (and
    where the QoS comes from when the recording does not say)."""
    topics = played_topics(plan)
    wide = max(len(t.name) for t in topics)
    kind = max(len(t.msgtype) for t in topics)
    lines = [f"  {'topic':{wide}s} {'messages':>8s}  {'type':{kind}s}  QoS offered"]
    for t in topics:
        source = "" if t.qos_source == "recording" else f"  (not recorded: {t.qos_source})"
        lines.append(f"  {t.name:{wide}s} {t.count:8d}  {t.msgtype:{kind}s}  {t.qos.describe()}{source}")
    return lines


def run_player(
    plan: PlayPlan,
    *,
    rate: float,
    loop: bool,
    start_paused: bool,
    delay: float,
    wait_subscribers: float,
    progress: Callable[[float, str], None] | None,
    keys: bool,
    force: bool = False,
    first_reader: bool = False,
    interrupts: Interrupts,
) -> PlayResult:
    """Init rclpy, play, shut down. Ctrl-C or SIGTERM ends the replay
    (KeyboardInterrupt), taken by ``interrupts`` (installed by the caller;
    rclpy's own signal handlers are not used, see :mod:`winder.interrupts`).
    :class:`CellLiveError` if a live cell runs in the namespace played into (unless ``force``)."""
    from rclpy.signals import SignalHandlerOptions

    from winder.ros.dds import use_profile

    use_profile()
    player = None
    terminal = None
    try:
        with interrupts.held():  # no signal between init and a node whose thread spins
            rclpy.init(args=[], signal_handler_options=SignalHandlerOptions.NO)
            player = Player(plan, rate=rate, node_namespace=_namespace_of(plan), start_paused=start_paused)
        if not force:
            refuse_live_cell(
                player.node,
                _namespace_of(plan),
                "reads the topics this bag would publish: its run would take the recording's messages "
                "for its own",
                "play into another namespace (--namespace /replay), or give --force",
            )
        if wait_subscribers > 0:
            missing = player.wait_for_subscribers(wait_subscribers, first_reader=first_reader)
            if missing:
                sys.stderr.write(
                    f"winder play: after {wait_subscribers:g} s still unmatched (playing anyway): {missing}\n"
                )
        lossy = player.best_effort_readers()
        if lossy:
            sys.stderr.write(f"winder play: {lossy}\n")
        if delay > 0:
            time.sleep(delay)
        from winder.ros.terminal import KeyReader

        terminal = KeyReader() if keys else None
        poll = None
        if terminal is not None and terminal.enabled:
            sys.stderr.write("keys: space pause/resume, n next message, + faster, - slower\n")
            poll = lambda: _keys(player, terminal)  # noqa: E731 - a closure over both
        return player.play(loop=loop, progress=progress, poll=poll)
    finally:
        interrupts.ending()  # the thread stops before the node goes, the node before rclpy
        if terminal is not None:
            terminal.close()
        if player is not None:
            player.close()
        rclpy.try_shutdown()


class CellLiveError(BadInputError):
    """``winder play`` would publish onto a namespace where a live cell runs."""


#: s the player looks at the graph for a live cell in its namespace before it
#: plays. A running cell's participants announce themselves once a second
#: (winder's DDS profile) and a newcomer learns of them at their next
#: announcement: measured 0.06-1.07 s to the first node of a live cell, so
#: 1.0 s missed one at times (and the player published into it)
LIVE_LOOK = 2.5


def live_cell(node: Any, namespace: str, look: float = LIVE_LOOK) -> list[str]:
    """The nodes of a live cell in ``namespace`` (the interp, profile and
    consumer parts as the graph shows them; :data:`winder.contract.trust.SIGNS`),
    looked for up to ``look`` s while discovery goes on; [] if none."""
    from winder.ros.graph import fully_qualified
    from winder.ros.peers import Peers

    peers = Peers(node, namespace)
    deadline = time.monotonic() + look
    while True:
        me = (node.get_name(), node.get_namespace())
        found = sorted({who[:2] for role in SIGNS for who in peers.holders(role)} - {me})  # not the player
        if found or time.monotonic() > deadline:
            return [fully_qualified(*who) for who in found]
        time.sleep(0.05)


def refuse_live_cell(node: Any, namespace: str, harm: str, instead: str) -> None:
    """:class:`CellLiveError`, one line, if a live cell runs in ``namespace``
    (:func:`live_cell`): what the command would do to it (``harm``) and what
    to do instead. ``winder play`` and ``winder resim`` refuse so."""
    live = live_cell(node, namespace)
    if live:
        raise CellLiveError(
            f"a live cell runs in {namespace or '/'} ({', '.join(live)}) and {harm}; {instead}"
        )


def _namespace_of(plan: PlayPlan) -> str:
    """The namespace the player node lives in: the played cell's."""
    job = "/" + TOPIC_JOB
    for t in plan.topics.values():
        if t.recorded.endswith(job):
            return t.name[: -len(job)]
    return ""


def _keys(player: Player | None, terminal: Any) -> None:
    if player is None:
        return
    for key in terminal.read():
        if key == " ":
            sys.stderr.write(f"\n{player.set_paused(not player.paused)}\n")
        elif key == "n":
            player.play_next()
        elif key in "+-":
            player.set_rate(min(max(player.rate * (2.0 if key == "+" else 0.5), 1e-3), 1e6))
            sys.stderr.write(f"\nrate x{player.rate:g}\n")
