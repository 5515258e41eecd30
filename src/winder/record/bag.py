"""Recording winder runs as rosbag2 directories (metadata.yaml + one .mcap).

ROS-free: messages arrive already serialized (CDR bytes, as rclpy hands them
over with ``raw=True`` or ``serialize_message``) and are written with the
``rosbags`` library, with the message definitions of ROS 2 Jazzy embedded so
that Foxglove, ``ros2 bag`` and rosbags open the bag without winder installed.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import queue
import re
import shutil
import signal
import threading
import time
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from rosbags.interfaces import Qos as BagQos
from rosbags.interfaces import QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

from winder import __version__
from winder.contract.files import fsync_path
from winder.contract.params import BAG_COMPRESSIONS
from winder.contract.qos import Qos, qos_of
from winder.errors import BadInputError
from winder.record.mcap_storage import StreamingMcapStorage
from winder.record.msgtypes import typestore_for

__all__ = [
    "STATE_KEY",
    "VERSION_KEY",
    "BagRecorder",
    "bag_qos",
    "bags_in",
    "being_written",
    "cdr_exact",
    "new_bag_path",
    "remove_stale_staging",
    "signals_held",
    "unclosed",
    "unclosed_bags",
    "unclosed_line",
]


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


def new_bag_path(directory: Path, job_id: str) -> Path:
    """A fresh directory name under ``directory``: ``<job_id>_<UTC stamp>``,
    with ``_2``, ``_3``... if that exists (rosbags never writes into an
    existing directory, and neither do we)."""
    if not re.match(r"^[A-Za-z0-9_\-]+$", job_id):
        raise BadInputError(f"job_id={job_id!r} cannot name a bag")
    stamp = time.strftime("%Y%m%d_%H%M%S", time.gmtime())
    base = directory / f"{job_id}_{stamp}"
    path, n = base, 1
    while path.exists():
        n += 1
        path = base.with_name(f"{base.name}_{n}")
    return path


def run_bag_path(directory: Path, run_id: str) -> Path:
    """The directory of a run's bag: ``<directory>/<run id>`` (``_2``... if
    that exists: a run id is unique, but a directory may be copied in)."""
    if not re.match(r"^[A-Za-z0-9_\-]+$", run_id):
        raise BadInputError(f"run_id={run_id!r} cannot name a bag")
    path, n = directory / run_id, 1
    while path.exists():
        n += 1
        path = directory / f"{run_id}_{n}"
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
    store = typestore_for((msgtype,))
    msgdef = store.get_msgdef(msgtype)
    little = bytes(data[1:2]) == b"\x01"
    func = msgdef.deserialize_cdr_le if little else msgdef.deserialize_cdr_be
    _, pos = func(bytes(data[4:]), 0, msgdef.cls, store)
    end = 4 + ((pos + 3) & ~3)
    return data[:end] if len(data) > end else data


#: rmw's "infinite" duration, as rosbag2 writes it for the policies winder leaves at their default
_INFINITE = QosTime(9223372036, 854775807)


def bag_qos(q: Qos) -> BagQos:
    """A topic's QoS as rosbag2 records it in ``offered_qos_profiles``
    (metadata.yaml and the MCAP channel): the policies winder sets, the
    others at rmw's defaults (no deadline, lifespan or lease; automatic liveliness)."""
    return BagQos(
        history=QosHistory.KEEP_ALL if q.keep_all else QosHistory.KEEP_LAST,
        depth=q.depth,
        reliability=QosReliability.RELIABLE if q.reliable else QosReliability.BEST_EFFORT,
        durability=QosDurability.TRANSIENT_LOCAL if q.transient_local else QosDurability.VOLATILE,
        deadline=_INFINITE,
        lifespan=_INFINITE,
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=_INFINITE,
        avoid_ros_namespace_conventions=False,
    )


#: Chunk compression of the MCAP file: lz4 (~2 GB/s here, a third of the size
#: of step chunks), zstd (level 1, ~0.7 GB/s, a tenth) or none. Compressed
#: chunks are part of the MCAP format: Foxglove, ros2 bag
#: (rosbag2_storage_mcap) and rosbags read them.
COMPRESSIONS = BAG_COMPRESSIONS


#: metadata.yaml's ``custom_data`` key that says how far the bag got: ``recording``
#: from its open on (what a bag whose writer was killed keeps), ``closed`` at its close
STATE_KEY = "winder_bag"
#: the version of the winder that wrote a bag (``winder.__version__``): its key in
#: metadata.yaml's ``custom_data``, and in a consumer's final report (``extra``) too
VERSION_KEY = "winder_version"
#: the staging directory of a bag being opened: ``.<bag name>.opening-<pid>``
_STAGING = re.compile(r"^\.(?P<name>.+)\.opening-(?P<pid>[0-9]+)$")


class _MetadataOnly:
    """A storage stand-in that lets rosbags' ``Writer.close`` write metadata.yaml
    (temp file + rename) while the real storage stays open: how the bag's
    metadata is there from its open on, in the format rosbags writes at close."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def add_msgtype(self, connection: Any) -> None:  # pragma: no cover - never called
        raise NotImplementedError

    def add_connection(self, connection: Any, offered_qos_profiles: str) -> None:  # pragma: no cover
        raise NotImplementedError

    def write(self, connection: Any, timestamp: int, data: bytes | memoryview) -> None:  # pragma: no cover
        raise NotImplementedError

    def close(self, version: int, metadata: str) -> None:
        del version, metadata  # the .mcap stays open; only metadata.yaml is written

    def abort(self) -> None:  # pragma: no cover - never called
        pass


class _Writer(Writer):
    """rosbags' rosbag2 writer (metadata.yaml, connections) with winder's
    .mcap storage, which does not copy the messages (winder.record.mcap_storage).
    The directory is created under a staging name and the .mcap named after
    the bag's final name (``name``)."""

    def __init__(self, path: Path, name: str) -> None:
        super().__init__(path, version=9, storage_plugin=StoragePlugin.MCAP)
        self.name = name

    def open(self) -> None:
        self.path.mkdir(mode=0o755)  # FileExistsError: never into an existing directory
        self.storage = StreamingMcapStorage(self.path, self.compression_mode, self.name)

    def write_metadata(self, state: str) -> None:
        """metadata.yaml as it stands (counts as synced), atomically, saying ``state``."""
        real, self.storage = self.storage, _MetadataOnly(self._storage().path)
        self.set_custom_data(STATE_KEY, state)
        try:
            Writer.close(self)
        finally:
            self.storage = real

    def _storage(self) -> StreamingMcapStorage:
        assert isinstance(self.storage, StreamingMcapStorage)
        return self.storage

    def moved(self, path: Path) -> None:
        """The directory was renamed to ``path`` (the open file goes with it)."""
        self.path, self.metapath = path, path / "metadata.yaml"
        storage = self._storage()
        storage.path = path / storage.path.name


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def remove_stale_staging(directory: Path) -> list[Path]:
    """Remove the staging directories under ``directory`` whose process is
    gone (a writer SIGKILLed while it opened its bag); return them."""
    removed = []
    with contextlib.suppress(OSError):
        for entry in directory.iterdir():
            m = _STAGING.match(entry.name)
            if m and entry.is_dir() and not entry.is_symlink() and not _alive(int(m["pid"])):
                shutil.rmtree(entry, ignore_errors=True)
                removed.append(entry)
    return removed


# -- bags a writer left unclosed ------------------------------------------------------
#
# A bag's .mcap is locked (flock, exclusive) by its writer from the bag's open
# to its close: the lock goes with the writer's process, however it ends. A bag
# whose metadata.yaml still says ``winder_bag: recording`` while nobody holds
# that lock, and whose .mcap has no summary, was left unclosed: its writer was
# SIGKILLed (or crashed), or its disk filled up. Every reader opens it as it
# is (the writer keeps the file a complete MCAP file without a summary at every
# moment: winder.record.mcap_storage): every chunk completed before the end,
# read from the start, without an index; metadata.yaml's counts are those of
# its last refresh (:data:`METADATA_SECONDS`). ``winder bag recover`` writes a
# closed copy, with its index and true counts.

_STATE_LINE = re.compile(rf"^\s*{STATE_KEY}:\s*['\"]?(?P<state>[A-Za-z_-]+)['\"]?\s*$", re.M)
_RECOVERED_FROM = re.compile(r"^\s*winder_recovered_from:\s*['\"]?(?P<name>[^'\"\s]+)['\"]?\s*$", re.M)
#: metadata.yaml larger than this is not looked into (rosbag2 writes a few kB per topic)
_METADATA_BYTES = 1 << 20


def _metadata_text(bag: Path) -> str:
    meta = bag / "metadata.yaml"
    try:
        if meta.is_symlink() or meta.stat().st_size > _METADATA_BYTES:
            return ""
        return meta.read_text(errors="replace")
    except OSError:
        return ""


def _mcap_files(bag: Path) -> list[Path]:
    """The .mcap files of a bag (its directory, its metadata.yaml or the file itself)."""
    try:
        if bag.is_file():
            return [bag] if bag.suffix == ".mcap" else _mcap_files(bag.parent)
        return sorted(p for p in bag.glob("*.mcap") if p.is_file() and not p.is_symlink())
    except OSError:
        return []


def being_written(bag: Path) -> bool:
    """Whether a writer holds the bag's .mcap now (it is being recorded)."""
    for f in _mcap_files(Path(bag)):
        try:
            fd = os.open(f, os.O_RDONLY | os.O_NOFOLLOW)
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return True
        except OSError:  # a file system without locks: nobody is known to hold it
            continue
        finally:
            os.close(fd)  # (and its shared lock with it)
    return False


def _has_summary(f: Path) -> bool:
    """Whether the MCAP file ``f`` ends with a footer that names its summary
    (:func:`winder.record.raw.names_summary`, read without reading the file)."""
    from winder.record.raw import FOOTER_BYTES, footer_summary_start, opens_summary

    try:
        with f.open("rb") as fh:
            size = fh.seek(0, os.SEEK_END)
            if size < 8 + FOOTER_BYTES:
                return False
            fh.seek(size - FOOTER_BYTES)
            start = footer_summary_start(fh.read(FOOTER_BYTES))
            if not 8 <= start < size - FOOTER_BYTES:
                return False
            fh.seek(start)
            return opens_summary(fh.read(1)[0])
    except OSError:
        return False


def unclosed(bag: Path) -> bool:
    """Whether ``bag`` (a winder bag directory) was left unclosed by its
    writer: its metadata.yaml says ``recording``, no writer holds it, and its
    .mcap has no summary (see above). ``winder bag recover`` writes it out closed."""
    bag = Path(bag)
    m = _STATE_LINE.search(_metadata_text(bag))
    if m is None or m["state"] != "recording":
        return False
    files = _mcap_files(bag)
    if not files or all(_has_summary(f) for f in files):
        return False  # killed between the file's close and metadata.yaml's: the file is whole
    return not being_written(bag)


def bags_in(directory: Path | str) -> list[Path]:
    """The bags directly under ``directory`` (a ``bag_dir``), sorted by name:
    its subdirectories but the hidden ones (a bag being opened is staged as
    ``.<name>.opening-<pid>``, then renamed). A file there is no bag: the part
    index (``parts.sqlite`` and SQLite's ``-wal`` and ``-shm`` beside it,
    docs/PARTS.md), or whatever else was put there. The one answer to "which
    bags are in this directory" for every command, benchmark and test: none
    if the directory does not exist."""
    try:
        return sorted(p for p in Path(directory).iterdir() if p.is_dir() and not p.name.startswith("."))
    except FileNotFoundError:
        return []


def unclosed_bags(directory: Path) -> list[Path]:
    """The bags directly under ``directory`` that a writer left unclosed
    (:func:`unclosed`), sorted; a bag a recovered copy beside it comes from
    (``winder bag recover``'s ``<bag>_recovered``) is not counted again."""
    try:
        entries = bags_in(directory)
    except OSError:
        return []
    recovered = set()
    for entry in entries:
        m = _RECOVERED_FROM.search(_metadata_text(entry)) if entry.name.endswith("_recovered") else None
        if m is not None:
            recovered.add(m["name"])
    return [e for e in entries if e.name not in recovered and unclosed(e)]


def unclosed_line(bags: Sequence[Path], where: str = "") -> str:
    """One line saying that ``bags`` were left unclosed and what mends them;
    ``where``: the directory they are in, named first ("" if not said)."""
    if not bags:
        return ""
    head = f"{where} holds " if where else ""
    if len(bags) == 1:
        return (
            f"{head}a bag left unclosed (its writer was killed or its disk filled; every reader opens it as "
            f"it is, without an index, its metadata.yaml counts as last refreshed): "
            f"`winder bag recover {bags[0]}` writes a closed copy"
        )
    return (
        f"{head}{len(bags)} bags left unclosed (their writer was killed or their disk filled; every reader "
        f"opens them as they are, without an index, their metadata.yaml counts as last refreshed): "
        f"`winder bag recover BAG` writes a closed copy of each: {', '.join(map(str, bags))}"
    )


#: Payload bytes the writer thread may have queued before write() waits for it.
QUEUE_BYTES = 64 << 20
#: s between two refreshes of an open bag's metadata.yaml (counts and span), made
#: by the writer thread after a chunk reached the file: what ``ros2 bag info`` and
#: rosbags' counts show of a bag whose writer was killed (a few ms each)
METADATA_SECONDS = 2.0
#: Messages are handed to the writer thread in batches of this many bytes or messages.
BATCH_BYTES = 256 << 10
BATCH_MESSAGES = 512


class BagRecorder:
    """Writes serialized messages to a new rosbag2/MCAP directory.

    ``topics`` maps each topic name to its ROS type (``"std_msgs/msg/String"``);
    ``qos`` each topic to the QoS its publishers offer (default: the cell's
    table, :func:`winder.contract.qos.qos_of`), recorded with it so that a
    player offers it again (a latched topic stays latched). The type hash of
    each topic (RIHS01) is recorded too.
    Timestamps are integer nanoseconds of *simulated* time.

    The directory appears whole: it is made under a hidden staging name
    (``.<name>.opening-<pid>``), with the connections, the messages of
    ``first`` (the run's description) in a first chunk on disk, and a
    metadata.yaml that says ``winder_bag: recording`` in its ``custom_data``,
    then renamed. :meth:`close` writes the summary and metadata.yaml again
    (temp file + rename, ``winder_bag: closed``): a bag closed so (at the
    end of a run, at SIGINT or SIGTERM) every reader opens, indexed. A
    writer that ends without its close (SIGKILL, a crash) or whose disk
    fills up leaves its bag unclosed, and every reader (rosbags, the mcap
    library, ``ros2 bag``, Foxglove) still opens it as it is: the .mcap is
    a complete MCAP file without a summary at every moment, holding every
    chunk completed before the end (:mod:`winder.record.mcap_storage`), and
    metadata.yaml names every topic from the open on, its counts and span
    refreshed at most every :data:`METADATA_SECONDS` while chunks come (a
    reader takes the messages from the file, not from those counts).
    :func:`unclosed` finds such a bag (the writer holds a lock on its .mcap
    while it is open); ``winder bag recover`` writes a closed, indexed copy.
    A staging directory left by a killed writer is removed by the next bag
    opened beside it. :meth:`discard` removes the directory (a job that
    never ran leaves nothing behind).

    The file is written by a thread of its own: :meth:`write` queues the
    payload (bytes, not to be changed afterwards) and returns, while chunk
    compression and file writes, which release the GIL, run beside the caller.
    At most :data:`QUEUE_BYTES` wait in the queue (then write() waits); an
    error of the thread (a full disk) is raised by the next write() or by
    close().
    """

    def __init__(
        self,
        path: Path,
        topics: dict[str, str],
        *,
        compression: str = "lz4",
        qos: Mapping[str, Qos] | None = None,
        first: Sequence[tuple[str, int, bytes | memoryview]] = (),
        custom: Mapping[str, str] | None = None,
    ) -> None:
        if compression not in COMPRESSIONS:
            raise BadInputError(f"compression={compression!r} is invalid: must be one of {COMPRESSIONS}")
        self.path = Path(path)
        self.compression = compression
        self._conns: dict[str, int] = {}  # topic -> channel id
        self._types: dict[str, str] = {}
        self.messages = 0
        self.bytes = 0
        self.last_t = 0
        self._queue: queue.SimpleQueue[tuple[list[tuple[int, int, bytes | memoryview]], int] | None] = (
            queue.SimpleQueue()
        )
        self._batch: list[tuple[int, int, bytes | memoryview]] = []
        self._batch_bytes = 0
        self._queued = 0  # payload bytes in the queue
        self._room = threading.Condition()
        self._error: BaseException | None = None
        self._writer: _Writer | None = None
        self._made = False  # the bag's directory is there under its name
        parent = self.path.parent
        parent.mkdir(parents=True, exist_ok=True)
        remove_stale_staging(parent)
        if self.path.exists():
            raise FileExistsError(f"{self.path}: exists already; a bag is never written into it")
        self._stage = parent / f".{self.path.name}.opening-{os.getpid()}"
        try:
            self._open(topics, qos, first, custom or {})
        except BaseException:  # a signal too: nothing half-made stays behind
            self.discard()
            raise
        self._thread = threading.Thread(target=self._drain, name="bag-writer", daemon=True)
        self._thread.start()

    def _open(
        self,
        topics: dict[str, str],
        qos: Mapping[str, Qos] | None,
        first: Sequence[tuple[str, int, bytes | memoryview]],
        custom: Mapping[str, str],
    ) -> None:
        """The bag, made whole under a staging name, then renamed: its directory
        never exists without metadata.yaml and a first chunk that holds
        ``first`` (the run's description), so a writer killed at any moment
        after leaves a bag that ``winder bag recover`` reads. ``custom``:
        metadata.yaml's custom_data besides the bag's state."""
        writer = _Writer(self._stage, self.path.name)
        for key, value in {**custom, VERSION_KEY: __version__}.items():
            writer.set_custom_data(key, value)
        if self.compression != "none":  # chunk compression inside the .mcap
            writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        self._writer = writer
        writer.open()
        storage = writer._storage()
        # held till the file is closed, or its process ends however it ends: a bag whose
        # metadata says "recording" and whom nobody holds was left unclosed (unclosed())
        with contextlib.suppress(OSError):  # a file system without locks
            fcntl.flock(storage.bio.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        if self.compression != "none":
            storage.compression = self.compression
        self._storage = storage
        store = typestore_for(topics.values())
        for topic, msgtype in topics.items():
            offered = (qos or {}).get(topic) or qos_of(topic)
            profiles = [bag_qos(offered)] if offered is not None else []
            conn = writer.add_connection(topic, msgtype, typestore=store, offered_qos_profiles=profiles)
            self._conns[topic] = conn.id
            self._types[topic] = msgtype
        for topic, t, data in first:
            storage.write_id(*self._message(topic, t, data, exact=False))
        if first:  # the head a recovery needs: schemas, channels and these messages, in a chunk
            self._sync(writer)  # (closes the chunk)
        storage.bio.flush()
        os.fsync(storage.bio.fileno())
        writer.write_metadata("recording")
        os.rename(self._stage, self.path)  # the bag appears whole, with its metadata
        self._made = True
        writer.moved(self.path)
        fsync_path(self.path.parent)

    @property
    def is_open(self) -> bool:
        return self._writer is not None

    def write(self, topic: str, t_ns: int, data: bytes | memoryview, *, exact: bool = False) -> None:
        """Record one serialized message. ``exact``: the payload is known to
        end where the message ends (winder.contract.cdr), so it needs no trimming."""
        if self._writer is None:
            raise RuntimeError(f"bag {self.path} is closed")
        if self._error is not None:
            raise RuntimeError(f"bag {self.path}: writing failed: {self._error}") from self._error
        message = self._message(topic, t_ns, data, exact=exact)
        # small messages go to the thread in batches: one hand-over per batch
        self._batch.append(message)
        self._batch_bytes += len(message[2])
        if self._batch_bytes >= BATCH_BYTES or len(self._batch) >= BATCH_MESSAGES:
            self._hand_over()

    def _message(
        self, topic: str, t_ns: int, data: bytes | memoryview, *, exact: bool
    ) -> tuple[int, int, bytes | memoryview]:
        """(channel id, log time, payload) of one message, counted."""
        t = max(int(t_ns), self.last_t)  # log time never goes backwards
        # (only small payloads: a trailing empty sequence means a short message,
        # and big step chunks end on their 8-byte data)
        if not exact and self._types[topic] in PADDABLE and len(data) < 65536:
            data = cdr_exact(data, self._types[topic])
        self.last_t = t
        self.messages += 1
        self.bytes += len(data)
        return self._conns[topic], t, data

    def _hand_over(self) -> None:
        """Queue the batch for the writer thread (waits while the queue is full)."""
        if not self._batch:
            return
        with self._room:
            while self._queued > QUEUE_BYTES and self._error is None:
                self._room.wait(0.1)
            self._queued += self._batch_bytes
        self._queue.put((self._batch, self._batch_bytes))
        self._batch, self._batch_bytes = [], 0

    def _drain(self) -> None:
        """The writer thread: queued messages into the file, in order; the
        open bag's metadata.yaml refreshed now and then (:meth:`_refresh`)."""
        storage, writer = self._storage, self._writer
        write = storage.write_id  # past rosbags' Writer.write: counts are synced in close()
        refreshed, chunks = time.monotonic(), len(storage.chunk_indexes)
        while True:
            item = self._queue.get()
            if item is None:
                return
            batch, size = item
            try:
                if self._error is None:
                    for cid, t, data in batch:
                        write(cid, t, data)
            except BaseException as exc:  # reported by write() / close()
                self._error = exc
            with self._room:
                self._queued -= size
                self._room.notify()
            now = time.monotonic()
            if (
                writer is not None
                and len(storage.chunk_indexes) > chunks
                and now - refreshed >= METADATA_SECONDS
            ):
                refreshed, chunks = now, len(storage.chunk_indexes)
                self._refresh(writer)

    def _refresh(self, writer: _Writer) -> None:
        """metadata.yaml of the open bag with the counts and span of the chunks in
        its file, still saying ``recording`` (the writer thread, between chunks).
        One that cannot be written (a full disk) leaves the one before."""
        self._counted(writer)
        with contextlib.suppress(OSError):
            writer.write_metadata("recording")

    def _stop(self) -> None:
        self._hand_over()
        if self._thread.is_alive():
            self._queue.put(None)
            self._thread.join()

    def close(self) -> None:
        """Finish the .mcap and write metadata.yaml. SIGINT and SIGTERM are held
        back meanwhile: a Ctrl-C that lands here must not leave half a bag."""
        if self._writer is not None:
            writer, self._writer = self._writer, None
            with signals_held():
                try:
                    self._stop()  # everything queued is in the file
                    if self._error is None:
                        self._sync(writer)
                        writer.set_custom_data(STATE_KEY, "closed")
                        writer.close()  # the .mcap's summary, then metadata.yaml (temp file + rename)
                    else:  # the summary (if the disk takes it); metadata.yaml keeps saying "recording"
                        self._counted(writer)
                        with contextlib.suppress(Exception):
                            writer.close()
                finally:
                    # the file closed (its lock let go) even when its close failed: the bag
                    # is then one its writer left unclosed (unclosed(), winder bag recover)
                    with contextlib.suppress(Exception):
                        self._storage.bio.close()
            if self._error is not None:
                raise RuntimeError(f"bag {self.path}: writing failed: {self._error}") from self._error

    def _sync(self, writer: Writer) -> None:
        """The pending chunk into the file, then :meth:`_counted`."""
        self._storage.flush()
        self._counted(writer)

    def _counted(self, writer: Writer) -> None:
        """Message counts and time span for metadata.yaml, those of the chunks
        in the file (the thread wrote past Writer.write, which would have kept them)."""
        storage = self._storage
        writer.counts.update(storage.counts)
        if any(storage.counts.values()):
            writer.min_timestamp, writer.max_timestamp = storage.first_t, storage.last_t

    def discard(self) -> None:
        """Remove the bag (or what of it was made while it opened)."""
        if self._writer is not None:
            writer, self._writer = self._writer, None
            if hasattr(self, "_thread"):
                self._stop()
            with contextlib.suppress(Exception):  # the directory goes anyway
                writer.abort()
        if self._made:
            shutil.rmtree(self.path, ignore_errors=True)
        shutil.rmtree(self._stage, ignore_errors=True)
