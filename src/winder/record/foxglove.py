"""A cell's messages served to Foxglove over its WebSocket protocol, ROS-free
(``foxglove-sdk``, import name ``foxglove``).

Every ROS topic is one channel with a ``ros2msg`` schema (the message
definition and its dependencies, as rosbag2 records it) and ``cdr`` message
encoding: the bytes rclpy takes from DDS (``raw=True``) or a bag holds are
sent as they are, never decoded and encoded again, and Foxglove decodes them
as it decodes a bag, so ``layouts/winder_foxglove.json`` works on either.

* :class:`Channels`: the channels of a server, and the last messages of its
  latched topics, sent again whenever a client subscribes to one (what a
  transient-local subscription gives a late joiner on the ROS graph; a
  WebSocket client that connects during a run would otherwise never get the
  run's ``winder/job`` or ``winder/path``). The SDK's Python API cannot
  address one client (``Client.id`` is not the sink id ``Channel.log``
  takes), so the other subscribers of that channel get the message again.
* :func:`start_server`: a server on a port checked first, a port in use as
  one line naming the option.
* :class:`BagPlayback`: a recording (:class:`winder.record.replay.PlayPlan`)
  served with Foxglove's playback controls (play, pause, seek, speed): the
  SDK's ``PlaybackControl`` capability (foxglove-sdk 0.30), with the
  ``Time`` capability for the playback clock.

The live side (rclpy subscriptions feeding :class:`Channels`) is
:mod:`winder.ros.view`.
"""

from __future__ import annotations

import dataclasses
import functools
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from typing import Any

from winder.record.replay import PlayPlan, PlayTopic
from winder.spec import Spec, SpecError

__all__ = [
    "DEFAULT_PORT",
    "BagPlayback",
    "Channels",
    "port_spec",
    "ros2msg_schema",
    "start_server",
]

DEFAULT_PORT = 8765
#: the WebSocket subprotocol foxglove-sdk 0.30 speaks (the Foxglove app offers it)
SUBPROTOCOL = "foxglove.sdk.v1"


def port_spec(option: str) -> Spec:
    """The TCP port of ``option`` (``--foxglove``, ``--port``): 0 is any free port."""
    return Spec(
        option,
        int,
        DEFAULT_PORT,
        "TCP port of the Foxglove WebSocket server (0: any free port)",
        "",
        0,
        65535,
    )


def _sdk() -> Any:
    try:
        import foxglove
    except ImportError as exc:
        raise SpecError(
            f"the Foxglove SDK is not installed ({exc}); run 'make venv' (pip package foxglove-sdk)"
        ) from None
    return foxglove


def start_server(
    *,
    name: str,
    host: str,
    port: int,
    option: str,
    listener: Any = None,
    playback_range: tuple[int, int] | None = None,
) -> Any:
    """A running foxglove WebSocket server on ``host``:``port``; a port that
    cannot be bound (in use, not allowed) or a host that cannot be resolved is
    a :class:`SpecError` naming ``option`` and the value."""
    foxglove = _sdk()
    from foxglove.websocket import Capability

    capabilities = [] if playback_range is None else [Capability.PlaybackControl, Capability.Time]
    try:
        return foxglove.start_server(
            name=name,
            host=host,
            port=port,
            capabilities=capabilities,
            server_listener=listener,
            playback_time_range=playback_range,
        )
    except SystemError as exc:
        # a Ctrl-C (or SIGTERM) while the server starts, raised in the Python code
        # it calls (its logging) and reported as a SystemError: the command is interrupted
        if isinstance(exc.__cause__, KeyboardInterrupt):
            raise KeyboardInterrupt from None
        raise
    except (RuntimeError, OverflowError) as exc:
        why = str(exc).removeprefix("FoxgloveError: ")
        raise SpecError(
            f"{option}={port} is invalid: cannot listen on {host}:{port} ({why}); must be a free TCP "
            f"port in [0, 65535] (0: any free port)"
        ) from None


@functools.cache
def _typestore() -> Any:
    from winder.record.msgtypes import jazzy_store

    return jazzy_store()


def ros2msg_schema(msgtype: str, text: str = "") -> Any:
    """The foxglove ``Schema`` of a ROS 2 message type (``sensor_msgs/msg/JointState``):
    ``text``, or the ROS 2 Jazzy definition with its dependencies."""
    foxglove = _sdk()
    if not text:
        text, _ = _typestore().generate_msgdef(msgtype, ros_version=2)
    return foxglove.Schema(name=msgtype, encoding="ros2msg", data=text.encode())


class Channels:
    """The channels of one server, by topic, and the latched topics' last
    messages. ``now`` gives the log time of a latched message sent again to a
    client that subscribes (the wall clock for a live cell, the playback
    position for a recording). Also the server's listener: pass it to
    :func:`start_server`."""

    def __init__(self, now: Callable[[], int] = time.time_ns) -> None:
        self.now = now
        self.channels: dict[str, Any] = {}
        self.topics: dict[int, str] = {}  #: channel id -> topic
        self.kept: dict[str, deque[bytes]] = {}  #: latched topic -> its last messages
        self.counts: dict[str, int] = {}  #: messages logged per topic
        self.lock = threading.Lock()

    def add(self, topic: str, msgtype: str, *, keep: int = 0, schema_text: str = "") -> None:
        """A channel for ``topic``; ``keep`` > 0: its last ``keep`` messages
        go again to each client that subscribes (a latched topic's depth)."""
        foxglove = _sdk()
        channel = foxglove.Channel(topic, message_encoding="cdr", schema=ros2msg_schema(msgtype, schema_text))
        self.channels[topic] = channel
        self.topics[channel.id()] = topic
        self.counts[topic] = 0
        if keep > 0:
            self.kept[topic] = deque(maxlen=keep)

    def log(self, topic: str, data: bytes, log_time: int) -> None:
        kept = self.kept.get(topic)
        with self.lock:
            if kept is not None:
                kept.append(bytes(data))
            self.channels[topic].log(bytes(data), log_time=log_time)
            self.counts[topic] += 1

    def forget(self) -> None:
        """Drop the latched messages kept (a seek: the recording's state before it is not the one after)."""
        with self.lock:
            for kept in self.kept.values():
                kept.clear()

    # -- the server's listener (called from the SDK's threads) ------------------------
    def on_subscribe(self, client: Any, channel: Any) -> None:
        topic = self.topics.get(channel.id)
        kept = self.kept.get(topic or "")
        if topic is None or not kept:
            return
        with self.lock:
            t = self.now()
            for data in kept:
                self.channels[topic].log(data, log_time=t)

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        return None

    def close(self) -> None:
        for channel in self.channels.values():
            channel.close()


#: playback speeds a client may ask for (the Foxglove app offers 0.01 to 20)
SPEEDS = (0.01, 100.0)
#: Hz at which the playback clock is broadcast while playing
TIME_RATE = 60.0


class BagPlayback:
    """A recording served with Foxglove's playback controls.

    The messages of ``plan`` (its topics, names as played, from its start)
    are logged in log-time order, each with its log time, paced at the speed
    the client asks for; a seek starts the recording again at the time asked
    for, the latched topics' last messages before it first (what a
    subscriber joining there is owed: :meth:`PlayPlan.messages`). It starts
    paused at the plan's start, as the Foxglove app expects; the app's play
    button, speed menu and time slider drive it (``PlaybackControlRequest``);
    every change is answered with a ``PlaybackState``.
    """

    def __init__(self, plan: PlayPlan, *, speed: float = 1.0) -> None:
        self.plan = plan
        self.cond = threading.Condition()
        self.speed = min(max(speed, SPEEDS[0]), SPEEDS[1])
        self.playing = False
        self.ended = False
        self.stopped = False
        self.position = plan.start_ns  # log time of the playback
        self.anchor_wall = time.monotonic()
        self.anchor_log = plan.start_ns
        self.seeks = 0
        self.channels = Channels(now=lambda: self.position)
        for topic in sorted(plan.topics.values(), key=lambda t: t.name):
            self.channels.add(
                topic.name,
                topic.msgtype,
                keep=topic.recorded_qos.depth if topic.latched else 0,
                schema_text=self._schema_text(topic),
            )
        self.server: Any = None
        self._messages: Iterator[tuple[PlayTopic, int, bytes]] = plan.messages()

    def _schema_text(self, topic: PlayTopic) -> str:
        for conn in self.plan.raw.connections.values():
            if conn.topic == topic.recorded and conn.schema_encoding == "ros2msg":
                return conn.schema
        return ""

    @property
    def time_range(self) -> tuple[int, int]:
        return self.plan.start_ns, self.plan.last_ns

    # -- the client's requests (SDK thread) ---------------------------------------------
    def state(self, request_id: str | None, did_seek: bool = False) -> Any:
        from foxglove.websocket import PlaybackState, PlaybackStatus

        if self.ended:
            status = PlaybackStatus.Ended
        else:
            status = PlaybackStatus.Playing if self.playing else PlaybackStatus.Paused
        return PlaybackState(
            status=status,
            current_time=self.position,
            playback_speed=self.speed,
            did_seek=did_seek,
            request_id=request_id,
        )

    def on_playback_control_request(self, request: Any) -> Any:
        from foxglove.websocket import PlaybackCommand

        with self.cond:
            did_seek = request.seek_time is not None
            if did_seek:
                self._seek(int(request.seek_time))
            if request.playback_speed and request.playback_speed > 0:
                self.speed = min(max(float(request.playback_speed), SPEEDS[0]), SPEEDS[1])
            self.playing = request.playback_command == PlaybackCommand.Play and not self.ended
            self._reanchor()
            self.cond.notify_all()
            return self.state(request.request_id, did_seek)

    def on_subscribe(self, client: Any, channel: Any) -> None:
        self.channels.on_subscribe(client, channel)

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        return None

    def _seek(self, t_ns: int) -> None:
        start = min(max(t_ns, self.plan.start_ns), self.plan.last_ns)
        self._messages = dataclasses.replace(self.plan, start_ns=start).messages()
        self.position = start
        self.ended = False
        self.seeks += 1
        self.channels.forget()

    def _reanchor(self) -> None:
        self.anchor_wall, self.anchor_log = time.monotonic(), self.position

    # -- playing (the calling thread) ---------------------------------------------------
    def serve(self, server: Any, progress: Callable[[float, str], None] | None = None) -> None:
        """Play on ``server`` (started with this object as its listener and
        :attr:`time_range`) until :meth:`stop`; the end of the recording
        waits for a seek."""
        self.server = server
        last_time = 0.0
        span = max(self.plan.last_ns - self.plan.start_ns, 1)
        while True:
            with self.cond:
                while not self.stopped and (not self.playing or self.ended):
                    self.cond.wait(0.1)
                if self.stopped:
                    return
                item = next(self._messages, None)
                if item is None:
                    self.ended, self.playing = True, False
                    self.position = self.plan.last_ns
                    server.broadcast_playback_state(self.state(None))
                    continue
                topic, t, data = item
                generation = self.seeks
                while not self.stopped and self.seeks == generation:
                    if self.playing:
                        due = self.anchor_wall + max(t - self.anchor_log, 0) / 1e9 / self.speed
                        wait = due - time.monotonic()
                        if wait <= 0:
                            break
                    else:
                        wait = 0.1
                    self.cond.wait(min(wait, 0.1))
                if self.stopped:
                    return
                if self.seeks != generation:
                    continue  # a seek meanwhile: this message is not the next one any more
                self.position = max(self.position, t)
                self.channels.log(topic.name, data, t)
            now = time.monotonic()
            if now - last_time >= 1.0 / TIME_RATE:
                last_time = now
                server.broadcast_time(self.position)
                if progress is not None:
                    progress(
                        (self.position - self.plan.start_ns) / span,
                        f"{(self.position - self.plan.first_ns) / 1e9:8.3f} s  x{self.speed:g}",
                    )

    def stop(self) -> None:
        with self.cond:
            self.stopped = True
            self.cond.notify_all()
