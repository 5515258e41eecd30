"""``winder ctl echo``: a topic's messages printed as ``ros2 topic echo``
prints them, on the pip install that has no ``ros2`` command.

Each message is a block of ``field: value`` lines (YAML, the fields in the
order of the message's definition, nested messages indented, strings and
arrays longer than :data:`TRUNCATE` cut with ``...`` unless asked for in
full), and ``---`` after it: what rosidl_runtime_py's ``message_to_yaml``
writes, which ``ros2 topic echo`` prints and which the pip install lacks.

Its type is the one the graph shows for the topic (as ``ros2 topic echo``
finds it). Its QoS is the cell's own for a topic of the cell (winder's
table, :data:`winder.contract.qos.TOPIC_QOS`), so a latched topic
(``winder/report``, ``winder/state``, ``winder/job``) gives a late reader
what its writer keeps; for any other topic it is made from its publishers'
as the graph shows them, as ``ros2 topic echo`` does: reliable when every
publisher is, transient-local when every publisher is.
"""

from __future__ import annotations

import array
import sys
from collections import OrderedDict
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from winder.errors import BadInputError

if TYPE_CHECKING:  # winder.ros.ctl at run time only: the command line's parser reads TRUNCATE
    from winder.ros.ctl import Session

__all__ = ["ECHO_DEPTH", "TRUNCATE", "echo", "message_yaml", "reader_qos", "topic_name"]

#: characters of a string, items of an array, shown before ``...`` (``ros2 topic echo``'s default)
TRUNCATE = 128
#: the reader's depth where its topic keeps the last few (``ros2 topic echo``'s
#: default): a latched topic with several writers (``winder/ready``: the
#: consumer's and the profile node's) keeps each one's last for a late reader,
#: and a reader of depth 1 would drop all but one of them
ECHO_DEPTH = 10
#: s of one spin while echo follows a topic
ECHO_SPIN = 0.1


def _value(value: Any, truncate: int | None) -> Any:
    """A field's value as YAML is to show it (rosidl_runtime_py's conversion)."""
    if isinstance(value, bytes):  # a byte field, or a byte array: its bytes as characters
        text = "".join(chr(c) for c in value[: truncate if truncate is not None else len(value)])
        return text + ("..." if truncate is not None and len(value) > truncate else "")
    if isinstance(value, str):
        return value[:truncate] + "..." if truncate is not None and len(value) > truncate else value
    if isinstance(value, (list, tuple, array.array, np.ndarray)):
        items = [_value(v, truncate) for v in list(value)[: truncate if truncate is not None else len(value)]]
        return items + (["..."] if truncate is not None and len(value) > truncate else [])
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (bool, int, float)):
        return value
    return _fields(value, truncate)  # a nested message


def _fields(msg: Any, truncate: int | None) -> OrderedDict[str, Any]:
    return OrderedDict(
        (name, _value(getattr(msg, name), truncate)) for name in msg.get_fields_and_field_types()
    )


def message_yaml(msg: Any, truncate: int | None = TRUNCATE) -> str:
    """``msg`` as ``ros2 topic echo`` shows it: ``field: value`` lines (a
    nested message's indented below its name), strings and arrays longer
    than ``truncate`` cut (None: in full). Ends with a newline."""
    import io

    from ruamel.yaml import YAML

    out = io.StringIO()
    dumper = YAML(typ="safe", pure=True)  # block style, every value on its field's line
    dumper.default_flow_style = False
    dumper.allow_unicode = True
    dumper.width = sys.maxsize
    dumper.representer.add_representer(
        OrderedDict, lambda r, data: r.represent_mapping("tag:yaml.org,2002:map", data.items())
    )
    dumper.dump(_fields(msg, truncate), out)
    return out.getvalue()


def topic_name(topic: str, namespace: str) -> str:
    """``topic``'s full name: as given when absolute, else in ``namespace``
    (``winder/report`` in ``/cell1`` is ``/cell1/winder/report``), checked
    as rcl checks a topic's name; one line naming what is wrong otherwise."""
    from rclpy.exceptions import InvalidTopicNameException
    from rclpy.validate_full_topic_name import validate_full_topic_name

    if not topic.strip("/"):
        raise BadInputError(f"TOPIC={topic!r} is invalid: must be a topic name, name[/name...] or /name...")
    ns = namespace.strip("/")
    full = topic if topic.startswith("/") else (f"/{ns}/{topic}" if ns else f"/{topic}")
    try:
        validate_full_topic_name(full)
    except InvalidTopicNameException as exc:
        why = str(exc).splitlines()[0].split(": ", 1)[-1]
        raise BadInputError(f"TOPIC={topic!r} is invalid: {full!r}: {why}") from None
    return full


def reader_qos(full: str, publishers: list[Any]) -> tuple[Any, str]:
    """The QoS to read ``full`` with, and where it came from: the cell's
    table for a topic of the cell; else from its ``publishers`` (the graph's
    endpoint infos) as ``ros2 topic echo`` chooses it; rmw's default
    (reliable, volatile) when none shows."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    from winder.contract.qos import qos_of
    from winder.ros.qos import profile

    known = qos_of(full)
    if known is not None:
        qos = profile(known)
        if qos.history == HistoryPolicy.KEEP_LAST:
            qos.depth = max(qos.depth, ECHO_DEPTH)
        return qos, "winder's topic table"
    infos = [p.qos_profile for p in publishers]
    reliable = bool(infos) and all(q.reliability == ReliabilityPolicy.RELIABLE for q in infos)
    latched = bool(infos) and all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in infos)
    qos = QoSProfile(
        depth=ECHO_DEPTH,
        reliability=ReliabilityPolicy.RELIABLE if reliable or not infos else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )
    return qos, "its publishers'" if infos else "the default (no publisher on the graph)"


def _on_graph(session: Session, full: str) -> tuple[str, list[Any]]:
    """Wait until the graph shows ``full`` with one type (and, for a topic
    that is not the cell's, a publisher, whose QoS the reader takes); the
    type and the publishers. :class:`UnansweredError` at the deadline when
    the graph does not show the topic at all."""
    from winder.contract.qos import qos_of
    from winder.ros.ctl import UnansweredError, graph_words

    me = session.node.get_fully_qualified_name()
    types: list[str] = []
    pubs: list[Any] = []

    def found() -> bool:
        nonlocal types, pubs
        types = next((list(t) for name, t in session.node.get_topic_names_and_types() if name == full), [])
        pubs = [
            p
            for p in session.node.get_publishers_info_by_topic(full)
            if f"{p.node_namespace.rstrip('/')}/{p.node_name}" != me
        ]
        return bool(types) and (bool(pubs) or qos_of(full) is not None)

    try:
        session.until(found, f"topic {full} on the graph", f" ({graph_words()}): is it published there?")
    except UnansweredError:
        if not types:
            raise
    if len(types) > 1:
        raise UnansweredError(f"{full} has {len(types)} types on the graph ({', '.join(types)}): which one?")
    return types[0], pubs


def echo(
    session: Session,
    full: str,
    *,
    once: bool,
    truncate: int | None,
    write: Callable[[str], None],
) -> int:
    """Print the messages of ``full`` with ``write`` (each a block and
    ``---``): the first only with ``once`` (:class:`UnansweredError` when
    none came within the session's timeout of the subscription), else every
    one until Ctrl-C. The number printed."""
    from winder.ros.ctl import UnansweredError, graph_words
    from winder.ros.player import message_class

    msgtype, pubs = _on_graph(session, full)
    try:
        cls = message_class(msgtype)
    except Exception:  # not installed here: its package is not in this Python
        raise UnansweredError(
            f"{full} is a {msgtype}, which is not installed here: it cannot be read"
        ) from None
    qos, _ = reader_qos(full, pubs)
    count = 0

    def take(msg: Any) -> None:
        nonlocal count
        if once and count:
            return
        write(message_yaml(msg, truncate) + "---\n")
        count += 1

    session.node.create_subscription(cls, full, take, qos)
    if once:
        session.renew()
        session.until(lambda: count > 0, f"message on {full}", f" ({graph_words()})")
        return count
    while True:  # Ctrl-C (a KeyboardInterrupt from the spin) ends it
        session.spin(ECHO_SPIN)
