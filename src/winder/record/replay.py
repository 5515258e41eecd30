"""What ``winder play`` puts back on a graph, ROS-free: which topics, under
which names, with which QoS, from which message on.

:func:`plan_play` reads a recording once without keeping its messages (the
counts, the channels and whether log time ever goes back), refuses a
recording that cannot be replayed whole (:class:`~winder.record.raw.BagError`,
one line, the same checks as ``winder analyze``: cut short or with damaged
chunks, and whatever ``winder analyze`` refuses, in its words) and returns
a :class:`PlayPlan`; :meth:`PlayPlan.messages` then
yields the messages to publish, in log-time order, with the latched topics'
last message before ``--start-offset`` first (what ``ros2 bag play
--start-offset`` loses). The rclpy side is :mod:`winder.ros.player`.
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from winder.contract.qos import Qos, qos_of
from winder.contract.topics import TOPIC_DIAGNOSTICS, TOPIC_JOB, check_namespace
from winder.errors import BadInputError
from winder.record.raw import BagError, Connection, RawBag, read_raw

__all__ = ["PlayPlan", "PlayTopic", "offered_qos", "plan_play", "play_qos"]

CLOCK_TYPE = "rosgraph_msgs/msg/Clock"

_HISTORY = {"keep_last": False, "keep_all": True, "1": False, "2": True}
_RELIABLE = {"reliable": True, "best_effort": False, "1": True, "2": False}
_TRANSIENT = {"transient_local": True, "volatile": False, "1": True, "2": False}


def offered_qos(conn: Connection) -> Qos | None:
    """The QoS the recording says its publishers offered (the channel's
    ``offered_qos_profiles``, rosbag2's YAML, by name or by number), merged
    over the profiles as ``ros2 bag play`` does: reliable and transient-local
    only if every publisher was; None if the recording does not say."""
    text = conn.metadata.get("offered_qos_profiles", "").strip()
    if not text or text == "[]":
        return None
    from ruamel.yaml import YAML

    try:
        profiles = YAML(typ="safe").load(text)
    except Exception:
        return None
    if not isinstance(profiles, list) or not profiles or not all(isinstance(p, dict) for p in profiles):
        return None
    try:
        reliable = all(_RELIABLE[str(p.get("reliability")).lower()] for p in profiles)
        transient = all(_TRANSIENT[str(p.get("durability")).lower()] for p in profiles)
        keep_all = any(_HISTORY[str(p.get("history")).lower()] for p in profiles)
        depth = max(int(p.get("depth", 0)) for p in profiles)
    except (KeyError, ValueError, TypeError):
        return None
    return Qos(reliable=reliable, transient_local=transient, keep_all=keep_all, depth=max(depth, 1))


def play_qos(recorded: Qos) -> Qos:
    """The QoS the player offers for a topic recorded with ``recorded``: its
    durability and depth (a latched topic stays latched, with the history a
    late joiner is owed), always reliable, and keep-all for the volatile
    topics, so that the writer drops no message for a subscriber that asks
    for reliability, whatever the rate (a slow reader holds the player back;
    what a keep-last reader's own history drops is its own: winder.ros.player).
    A best-effort subscriber (rclpy's /clock) still matches a reliable writer."""
    if recorded.transient_local:
        return Qos(reliable=True, transient_local=True, keep_all=False, depth=recorded.depth)
    return Qos(reliable=True, transient_local=False, keep_all=True, depth=max(recorded.depth, 1000))


@dataclass(frozen=True)
class PlayTopic:
    """One topic of the recording as it is played."""

    recorded: str  #: the name in the recording
    name: str  #: the name it is published under (``--namespace`` applied)
    msgtype: str
    count: int  #: messages recorded
    recorded_qos: Qos  #: from the recording, else the cell's table, else reliable, volatile, depth 100
    qos_source: str  #: "recording", "winder table" or "default"

    @property
    def qos(self) -> Qos:
        return play_qos(self.recorded_qos)

    @property
    def latched(self) -> bool:
        return self.recorded_qos.transient_local


@dataclass
class PlayPlan:
    raw: RawBag
    topics: dict[str, PlayTopic]  #: by recorded name, only those played
    namespace: str  #: the recorded cell's namespace ("" = root)
    first_ns: int  #: log time of the recording's first message
    last_ns: int  #: and of its last
    start_ns: int  #: log time playback starts from (first_ns + start offset)
    in_order: bool  #: file order is log-time order (winder's bags always)
    skipped: dict[str, str] = field(default_factory=dict)  #: recorded topics not played, and why

    @property
    def count(self) -> int:
        """Messages to publish once through (the latched ones before the start included)."""
        return sum(t.count for t in self.topics.values())

    def messages(self) -> Iterator[tuple[PlayTopic, int, bytes]]:
        """The messages to publish, in log-time order: first, for each latched
        topic, the last message before the start (the state a subscriber that
        joins at the start is owed), then every message from the start on."""
        wanted = list(self.topics)
        if self.start_ns > self.first_ns:
            last: dict[str, tuple[int, bytes]] = {}
            latched = [name for name, t in self.topics.items() if t.latched]
            for batch in self._batches(latched):
                for topic, t, data in batch:
                    if t < self.start_ns:
                        last[topic] = (t, data)
            for topic, (t, data) in sorted(last.items(), key=lambda kv: kv[1][0]):
                yield self.topics[topic], t, data
        for batch in self._batches(wanted):
            for topic, t, data in batch:
                if t >= self.start_ns:
                    yield self.topics[topic], t, data

    def _batches(self, topics: Sequence[str]) -> Iterator[list[tuple[str, int, bytes]]]:
        if self.in_order:
            yield from self.raw.stream(topics)
            return
        # not winder's: the whole recording sorted by log time (stable: file order on ties)
        every = [m for batch in self.raw.stream(topics) for m in batch]
        every.sort(key=lambda m: m[1])
        yield every


def _cell_namespace(topics: Sequence[str]) -> str:
    jobs = sorted(t[: -len(TOPIC_JOB)].rstrip("/") for t in topics if t.endswith("/" + TOPIC_JOB))
    return jobs[0] if len(jobs) == 1 else ""


def _renamed(topic: str, recorded_ns: str, namespace: str) -> str:
    """``topic`` moved from the recorded cell's namespace into ``namespace``;
    /diagnostics and topics outside the cell keep their names."""
    if topic == TOPIC_DIAGNOSTICS:
        return topic
    if recorded_ns and topic.startswith(recorded_ns + "/"):
        return namespace + topic[len(recorded_ns) :]
    if not recorded_ns and namespace and (topic.startswith("/winder/") or topic == "/clock"):
        return namespace + topic
    return topic


def _matches(topic: str, patterns: Sequence[str]) -> bool:
    return any(topic == p or re.fullmatch(p, topic) for p in patterns)


def plan_play(
    path: str | Path,
    *,
    start_offset: float = 0.0,
    clock: bool = False,
    topics: Sequence[str] = (),
    exclude: Sequence[str] = (),
    namespace: str | None = None,
) -> PlayPlan:
    """Check a recording for replay and choose what to play (see the module).
    ``topics``/``exclude``: recorded topic names or regular expressions;
    ``namespace``: where the recorded cell's topics go (None: where they were);
    ``clock``: the recorded simulated clock is published too (it is left out
    otherwise: a replay does not drive a graph's time unless asked)."""
    if not (start_offset >= 0 and start_offset < 1e7):
        raise BadInputError(f"start_offset={start_offset!r} is invalid: must be a number of seconds >= 0")
    for p in (*topics, *exclude):
        try:
            re.compile(p)
        except re.error as exc:
            raise BadInputError(f"topic pattern {p!r} is invalid: {exc}") from None
    raw = read_raw(path, keep=lambda _t: False)
    _check_as_analyze(path, raw.topics())  # first: what analyze refuses is refused in its words
    if raw.recovered or not raw.closed:
        raise BagError(
            f"{raw.path}: the recording was cut short ({'; '.join(raw.notes) or 'no footer'}); "
            f"`winder bag recover {raw.path}` writes its whole messages as a complete bag, which plays"
        )
    if raw.damaged:
        raise BagError(
            f"{raw.path}: damaged recording: {len(raw.damaged)} chunk(s) skipped (first: {raw.damaged[0]}); "
            "a replay would leave a gap in every stream, so nothing is played"
        )
    counts = raw.topics()
    recorded_ns = _cell_namespace([t for t, n in counts.items() if n])
    target = recorded_ns if namespace is None else check_namespace(namespace)
    unknown = [p for p in topics if not any(_matches(t, [p]) for t in counts)]
    if unknown:
        raise BadInputError(
            f"topics={unknown[0]!r} is invalid: no topic of the recording matches it "
            f"(it has {', '.join(sorted(counts))})"
        )
    chosen: dict[str, PlayTopic] = {}
    skipped: dict[str, str] = {}
    seen: dict[str, Connection] = {}
    for conn in raw.connections.values():
        seen.setdefault(conn.topic, conn)
    for topic, conn in sorted(seen.items()):
        if counts.get(topic, 0) == 0:
            skipped[topic] = "no messages"
        elif topics and not _matches(topic, topics):
            skipped[topic] = "not in --topics"
        elif _matches(topic, exclude):
            skipped[topic] = "excluded"
        elif conn.msgtype == CLOCK_TYPE and not clock:
            skipped[topic] = "the recorded clock: played with --clock"
        elif conn.encoding != "cdr":
            skipped[topic] = f"{conn.encoding} messages, not CDR"
        else:
            recorded = offered_qos(conn)
            source = "recording"
            if recorded is None:
                recorded, source = qos_of(topic[len(recorded_ns) :] if recorded_ns else topic), "winder table"
            if recorded is None:
                recorded = Qos(reliable=True, transient_local=False, keep_all=False, depth=100)
                source = "default"
            chosen[topic] = PlayTopic(
                topic, _renamed(topic, recorded_ns, target), conn.msgtype, counts[topic], recorded, source
            )
    if not chosen:
        raise BadInputError(f"{raw.path}: nothing to play: every topic is left out ({skipped})")
    first, last, in_order = _span(raw, list(chosen))
    start = first + round(start_offset * 1e9)
    if start > last:
        raise BadInputError(
            f"start_offset={start_offset:g} is invalid: the recording lasts {(last - first) / 1e9:.3f} s"
        )
    return PlayPlan(raw, chosen, recorded_ns, first, last, start, in_order, skipped)


def _check_as_analyze(path: str | Path, counts: dict[str, int]) -> None:
    """Refuse what ``winder analyze`` refuses, in its words: a bag that is not
    a winder recording, or whose cell's messages do not decode (a job
    description, configuration, joint state or step chunk that is not what
    the nodes write). Each cell of a bag with several is checked."""
    from winder.record.reader import job_namespaces, read_run

    spaces: list[str | None] = [*job_namespaces({t for t, n in counts.items() if n})]
    for ns in spaces or [None]:  # none: read_run says why it is not a winder bag
        read_run(path, ns)


def _span(raw: RawBag, topics: list[str]) -> tuple[int, int, bool]:
    """First and last log time of the recording's messages on ``topics``, and
    whether the file has them in log-time order (one pass, nothing kept)."""
    first, last, prev, in_order = -1, -1, -1, True
    for batch in raw.stream(topics):
        for _, t, _ in batch:
            if first < 0:
                first = t
            if t < prev:
                in_order = False
            prev = t
            first, last = min(first, t), max(last, t)
    return first, last, in_order
