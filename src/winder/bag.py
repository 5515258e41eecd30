"""Recording winder runs as rosbag2 directories (metadata.yaml + one .mcap).

ROS-free: messages arrive already serialized (CDR bytes, as rclpy hands them
over with ``raw=True`` or ``serialize_message``) and are written with the
``rosbags`` library, with the message definitions of ROS 2 Jazzy embedded so
that Foxglove, ``ros2 bag`` and rosbags open the bag without winder installed.
"""

from __future__ import annotations

import contextlib
import re
import shutil
import signal
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

__all__ = ["BagRecorder", "cdr_exact", "new_bag_path", "signals_held"]


@contextlib.contextmanager
def signals_held() -> Iterator[None]:
    """Defer SIGINT/SIGTERM (main thread only; elsewhere a no-op)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held = {signal.SIGINT, signal.SIGTERM}
    old = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


_TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


def new_bag_path(directory: Path, job_id: str) -> Path:
    """A fresh directory name under ``directory``: ``<job_id>_<UTC stamp>``,
    with ``_2``, ``_3``... if that exists (rosbags never writes into an
    existing directory, and neither do we)."""
    if not re.match(r"^[A-Za-z0-9_\-]+$", job_id):
        raise ValueError(f"job_id={job_id!r} cannot name a bag")
    stamp = time.strftime("%Y%m%d_%H%M%S", time.gmtime())
    base = directory / f"{job_id}_{stamp}"
    path, n = base, 1
    while path.exists():
        n += 1
        path = base.with_name(f"{base.name}_{n}")
    return path


#: Types whose serialized form can end in alignment padding: the last field is
#: a sequence of 8-byte values that may be empty (Fast CDR aligns it anyway).
#: Strings, Clock, DiagnosticArray and JointTrajectory cannot.
PADDABLE = frozenset(
    {
        "sensor_msgs/msg/JointState",
        "std_msgs/msg/Int64MultiArray",
        "std_msgs/msg/Float64MultiArray",
        "std_msgs/msg/UInt64MultiArray",
    }
)


def cdr_exact(data: bytes | memoryview, msgtype: str) -> bytes | memoryview:
    """``data`` without bytes past the message's end beyond CDR's 4-byte padding.

    Fast CDR (rclpy's serializer) ends a message whose last field is an empty
    float64 sequence (JointState.effort) with 4 bytes of alignment for the
    elements that are not there; strict readers (rosbags) reject that. The
    message is parsed once to find its end; the payload is otherwise untouched.
    """
    msgdef = _TYPESTORE.get_msgdef(msgtype)
    little = bytes(data[1:2]) == b"\x01"
    func = msgdef.deserialize_cdr_le if little else msgdef.deserialize_cdr_be
    _, pos = func(bytes(data[4:]), 0, msgdef.cls, _TYPESTORE)
    end = 4 + ((pos + 3) & ~3)
    return data[:end] if len(data) > end else data


class BagRecorder:
    """Writes serialized messages to a new rosbag2/MCAP directory.

    ``topics`` maps each topic name to its ROS type (``"std_msgs/msg/String"``).
    Timestamps are integer nanoseconds of *simulated* time. :meth:`close` writes
    metadata.yaml; :meth:`discard` removes the directory (a job that never ran
    leaves nothing behind).
    """

    def __init__(self, path: Path, topics: dict[str, str]) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._writer: Writer | None = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        self._writer.open()
        self._conns: dict[str, Any] = {}
        self._types: dict[str, str] = {}
        self.messages = 0
        self.bytes = 0
        self.last_t = 0
        try:
            for topic, msgtype in topics.items():
                self._conns[topic] = self._writer.add_connection(topic, msgtype, typestore=_TYPESTORE)
                self._types[topic] = msgtype
        except Exception:
            self.discard()
            raise

    @property
    def is_open(self) -> bool:
        return self._writer is not None

    def write(self, topic: str, t_ns: int, data: bytes | memoryview, *, exact: bool = False) -> None:
        """Record one serialized message. ``exact``: the payload is known to
        end where the message ends (winder.cdr), so it needs no trimming."""
        if self._writer is None:
            raise RuntimeError(f"bag {self.path} is closed")
        t = max(int(t_ns), self.last_t)  # log time never goes backwards
        # (only small payloads: a trailing empty sequence means a short message,
        # and big step chunks end on their 8-byte data)
        if not exact and self._types[topic] in PADDABLE and len(data) < 65536:
            data = cdr_exact(data, self._types[topic])
        self._writer.write(self._conns[topic], t, data)
        self.last_t = t
        self.messages += 1
        self.bytes += len(data)

    def close(self) -> None:
        """Finish the .mcap and write metadata.yaml. SIGINT and SIGTERM are held
        back meanwhile: a Ctrl-C that lands here must not leave half a bag."""
        if self._writer is not None:
            writer, self._writer = self._writer, None
            with signals_held():
                writer.close()

    def discard(self) -> None:
        if self._writer is not None:
            writer, self._writer = self._writer, None
            with contextlib.suppress(Exception):  # the directory goes anyway
                writer.close()
        shutil.rmtree(self.path, ignore_errors=True)
