"""Reading the messages of a rosbag2 recording undecoded, ROS-free: the bag's
files found, each MCAP file walked record by record, and a cut-short
recording written out again closed.

A recording is what the sim node writes (:mod:`winder.record.bag`): a rosbag2
directory ``<job_id>_<UTC stamp>/`` with ``metadata.yaml`` and one MCAP file.
:func:`read_raw` returns a :class:`RawBag`: the channels and the messages as
CDR bytes, in file order; :mod:`winder.record.reader` decodes them.

Cut-short recordings
--------------------
When the sim node dies mid-job (SIGKILL, a crash) or its disk fills up, its
bag's metadata.yaml still says ``winder_bag: recording`` and its MCAP file
ends in the open end winder's writer keeps (:mod:`winder.record.mcap_storage`):
every chunk completed before, then a footer without a summary, which every
MCAP reader opens as it is. Such a file is read here up to that footer, like
the other readers. A file cut anywhere else (by another writer, by a copy,
by power loss) is read record by record with the ``mcap`` library's record
parsers: every record that reached the file whole is kept, and reading stops
cleanly at the first incomplete one; inside the last, incomplete chunk
(rosbags writes uncompressed chunks of about 1 MiB by default) the messages
that are whole are recovered too. Either bag is ``recovered`` and never
``closed``; :func:`recover` writes it out again as a closed rosbag2 directory.
"""

from __future__ import annotations

import contextlib
import io
import mmap
import re
import struct
import zlib
from collections.abc import Callable, Collection, Generator, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Message, Schema

from winder.contract.files import new_directory
from winder.errors import BadBagError
from winder.record.mcap_storage import OP_OPEN_END

__all__ = ["BagError", "Connection", "RawBag", "read_raw", "recover"]

MAGIC = b"\x89MCAP0\r\n"
#: metadata.yaml larger than this is refused (rosbag2 writes a few kB per topic)
METADATA_BYTES = 16 << 20


class BagError(BadBagError):
    """A recording cannot be read; the message says which file and why, in one line."""


# -- raw MCAP -------------------------------------------------------------------


@dataclass(frozen=True)
class Connection:
    """One MCAP channel: topic, ROS type and the type's definition text."""

    id: int
    topic: str
    msgtype: str
    encoding: str  #: message encoding, "cdr" for ROS 2
    schema_encoding: str  #: "ros2msg" or "ros2idl"
    schema: str  #: message definition text
    #: the channel's metadata as rosbag2 writes it (``offered_qos_profiles``: YAML, ``topic_type_hash``)
    metadata: dict[str, str] = field(default_factory=dict)


#: one message as :meth:`RawBag.stream` gives it: (topic, log time ns, CDR bytes)
TopicMessage = tuple[str, int, bytes]


@dataclass
class RawBag:
    """The messages of a recording, undecoded, in file order.

    ``messages`` holds the messages of the topics :func:`read_raw` was told to
    keep (all, by default); every message is counted in ``counts`` whether
    kept or not, and :meth:`stream` reads the file(s) again for the topics
    that were not kept, a batch at a time, so that a recording much larger
    than memory can be read.

    ``closed``: every file was closed by its writer (it ends with its MCAP
    footer, after its summary or another writer's data). ``recovered``: some
    file was cut short (its writer stopped without closing it, or damaged)
    and was read as far as it is whole.
    """

    path: Path
    files: list[Path]
    connections: dict[int, Connection]
    messages: list[tuple[int, int, bytes]]  #: (connection id, log time ns, CDR bytes)
    closed: bool
    recovered: bool
    metadata: bool = False  #: metadata.yaml present
    notes: list[str] = field(default_factory=list)
    #: chunks skipped because their CRC or their compression showed damage, one line each
    damaged: list[str] = field(default_factory=list)
    #: messages read per connection id, kept or not
    counts: dict[int, int] = field(default_factory=dict)
    #: chunks read per chunk compression ("none", "lz4", "zstd"), as the chunk headers say
    compressions: dict[str, int] = field(default_factory=dict)

    def topics(self) -> dict[str, int]:
        """Message count per topic."""
        counts = {c.topic: 0 for c in self.connections.values()}
        for cid, n in self.counts.items():
            topic = self.connections[cid].topic
            counts[topic] = counts.get(topic, 0) + n
        return counts

    def stream(self, topics: Collection[str]) -> Iterator[list[TopicMessage]]:
        """The messages on ``topics``, read from the file(s) again: in file
        order, one batch per top-level record (an MCAP chunk), the same
        messages a full read keeps (damaged chunks skipped, a cut-short end
        read as far as it is whole)."""
        wanted = frozenset(topics)
        if self.files and self.files[0].suffix == ".db3":
            yield from _stream_sqlite(self.path, wanted)
            return
        scratch = RawBag(self.path, self.files, {}, [], closed=True, recovered=False)
        for f in self.files:
            sink = _Sink(scratch, keep=lambda topic: topic in wanted)
            for _ in _read_mcap(f, sink):
                if scratch.messages:
                    conns = scratch.connections
                    yield [(conns[cid].topic, t, data) for cid, t, data in scratch.messages]
                    scratch.messages = []


def _inside(root: Path, path: Path, what: str) -> Path:
    """``path`` if it stays inside the bag's directory ``root`` (symlinks
    followed), else a BagError naming it: a bag never makes the reader open a
    file elsewhere."""
    try:
        real = path.resolve()
    except (OSError, RuntimeError) as exc:  # a symlink loop
        raise BagError(f"{path}: {what} cannot be resolved: {exc}") from None
    if not real.is_relative_to(root):
        raise BagError(f"{path}: {what} leads outside the bag's directory {root} (to {real}): refused")
    return path


def _listed_files(meta: Path, text: str) -> list[str]:
    """The file names metadata.yaml lists (``relative_file_paths`` and ``files[].path``)."""
    from ruamel.yaml import YAML

    try:
        doc = YAML(typ="safe").load(text)
        info = doc.get("rosbag2_bagfile_information", {}) if isinstance(doc, dict) else {}
        names = list(info.get("relative_file_paths") or [])
        names += [f.get("path") for f in info.get("files") or [] if isinstance(f, dict)]
    except Exception:  # not YAML rosbag2 would write: the names it seems to list are checked all the same
        names = re.findall(r"^\s*(?:-\s*)?(?:path:\s*)?(\S+\.(?:mcap|db3)\S*)\s*$", text, flags=re.M)
    out: list[str] = []
    for name in names:
        if not isinstance(name, str) or not name:
            raise BagError(f"{meta}: a listed file name {name!r} is not a file name")
        if name not in out:
            out.append(name)
    return out


def _bag_files(path: Path) -> tuple[Path, list[Path], bool]:
    """(bag directory or file, the MCAP files to read, metadata.yaml present).
    Every file read from a directory is inside it (see :func:`_inside`)."""
    if not path.exists():
        raise BagError(f"{path}: no such file or directory")
    if path.is_file():
        if path.name == "metadata.yaml":
            return _bag_files(path.parent)
        return path, [path], (path.parent / "metadata.yaml").exists()
    if not path.is_dir():
        raise BagError(f"{path}: not a directory or a regular file")
    root = path.resolve()
    meta = path / "metadata.yaml"
    files: list[Path] = []
    if meta.exists():
        _inside(root, meta, "metadata.yaml")
        if meta.stat().st_size > METADATA_BYTES:
            raise BagError(f"{meta}: {meta.stat().st_size} bytes, more than a rosbag2 metadata file holds")
        text = meta.read_text(errors="replace")
        listed = _listed_files(meta, text)
        for name in listed:
            if Path(name).is_absolute() or ".." in Path(name).parts:
                raise BagError(
                    f"{meta}: listed file {name!r} is outside the bag's directory: refused "
                    "(only names relative to the bag, without '..', are read)"
                )
            _inside(root, path / name, f"listed file {name!r}")
        if re.search(r"storage_identifier:\s*sqlite3", text):
            db3 = sorted(_inside(root, p, "file") for p in path.glob("*.db3"))
            if not db3:
                raise BagError(f"{path}: metadata.yaml names an sqlite3 recording, but there is no .db3 file")
            return path, db3, True
        files = [path / name for name in listed if name.endswith(".mcap") and (path / name).exists()]
    if not files:
        files = sorted(_inside(root, p, "file") for p in path.glob("*.mcap") if p.is_file())
    if not files:
        entries = [p.name for p in path.iterdir()]
        if not entries:
            raise BagError(f"{path}: empty directory, not a rosbag2 recording (no metadata.yaml, no .mcap)")
        if meta.exists():
            raise BagError(f"{path}: metadata.yaml lists no MCAP file that exists here")
        raise BagError(f"{path}: not a rosbag2 recording (no metadata.yaml and no .mcap file)")
    return path, files, meta.exists()


def _parse_chunk_partial(body: bytes | memoryview) -> tuple[str, bytes] | None:
    """Compression and the records of a chunk record cut short (its body up to
    the cut): as much of the chunk's record data as can be had, or None."""
    if len(body) < 8 + 8 + 8 + 4 + 4:
        return None
    clen = int.from_bytes(body[28:32], "little")
    start = 32 + clen + 8
    if len(body) < start:
        return None
    compression = bytes(body[32 : 32 + clen]).decode("utf-8", "replace")
    data = bytes(body[start:])
    if compression == "":
        return compression, data
    if compression == "zstd":
        try:
            import zstandard

            return compression, zstandard.ZstdDecompressor().decompressobj().decompress(data)
        except Exception:  # a cut inside a frame: nothing usable
            return None
    return None  # lz4 frames cannot be read before their end


_MSG_HEAD = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time


def _record_spans(data: bytes | memoryview, pos: int) -> Iterator[tuple[int, int, int]]:
    """(opcode, body start, body end) of the whole MCAP records in ``data`` from
    byte ``pos`` on, in order; stops at the first incomplete record."""
    n = len(data)
    while pos + 9 <= n:
        op = data[pos]
        length = int.from_bytes(data[pos + 1 : pos + 9], "little")
        end = pos + 9 + length
        if end > n:
            return
        yield op, pos + 9, end
        pos = end


def _inner_records(data: bytes | memoryview) -> Iterator[Schema | Channel | tuple[int, int, bytes]]:
    """The whole records inside (part of) a chunk's record data, in order:
    Schema and Channel records (parsed by ``mcap``), messages as (channel id,
    log time, bytes). Stops at the first incomplete record."""
    for op, start, end in _record_spans(data, 0):
        if op == Opcode.MESSAGE:
            cid, _, log_time, _ = _MSG_HEAD.unpack_from(data, start)
            yield cid, log_time, bytes(data[start + _MSG_HEAD.size : end])
        elif op == Opcode.SCHEMA:
            yield Schema.read(ReadDataStream(io.BytesIO(data[start:end])))
        elif op == Opcode.CHANNEL:
            yield Channel.read(ReadDataStream(io.BytesIO(data[start:end])))


class DamagedChunk(Exception):  # noqa: N818 - a finding, not a failure of the reader
    """A chunk whose bytes are not what was written: it is skipped, named, counted."""


def _checked_chunk_data(chunk: Chunk) -> bytes:
    """The chunk's records, decompressed and checked against its CRC (when it
    has one: 0 means not computed, as in rosbags' files)."""
    try:
        data = _chunk_data(chunk)
    except Exception as exc:
        raise DamagedChunk(
            f"its {chunk.compression} data cannot be decompressed ({type(exc).__name__})"
        ) from None
    if len(data) != chunk.uncompressed_size:
        raise DamagedChunk(f"{len(data)} bytes where its header says {chunk.uncompressed_size}")
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise DamagedChunk("CRC mismatch")
    return data


def _chunk_data(chunk: Chunk) -> bytes:
    if chunk.compression == "":
        return chunk.data
    if chunk.compression == "zstd":
        import zstandard

        return zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=chunk.uncompressed_size)
    if chunk.compression == "lz4":
        import lz4.frame

        return lz4.frame.decompress(chunk.data)  # type: ignore[no-any-return]
    raise BagError(f"unsupported chunk compression {chunk.compression!r}")


#: the steps of a walk: it pauses after every top-level record it has added to
#: its sink, saying the byte offset it has read up to
Steps = Generator[int, None, None]
#: the walk hands the pages it has read back to the kernel every this many bytes
#: (mapped pages of the file would otherwise count in the process' memory)
RELEASE_BYTES = 4 << 20


def _read_mcap(path: Path, sink: _Sink) -> Steps:
    """Add the records of one MCAP file to ``sink``, stopping cleanly at the
    first incomplete or damaged record; pauses after every top-level record."""
    size = path.stat().st_size
    if size == 0:
        raise BagError(f"{path}: empty file (0 bytes)")
    with path.open("rb") as f:
        mm = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
        data = memoryview(mm)
        released = 0
        try:
            for pos in _scan(path, data, sink):
                if pos - released >= RELEASE_BYTES:
                    upto = pos - pos % mmap.PAGESIZE
                    mm.madvise(mmap.MADV_DONTNEED, released, upto - released)
                    released = upto
                yield pos
        finally:
            # a walk left early (an exception, a Ctrl-C) may still hold a slice in its
            # traceback: the mapping then goes with the slice, not here
            with contextlib.suppress(BufferError):
                data.release()
                mm.close()


def _scan(path: Path, data: memoryview, sink: _Sink) -> Steps:
    """Add the records of one mapped MCAP file to ``sink``: the whole records
    in order, then what can be had of a cut-short end."""
    _check_magic(path, data)
    _channels_from_summary(data, sink)
    walk = yield from _walk(data, sink)
    _finish(path, data, sink.raw, sink, walk)
    yield len(data)


_FOOTER = struct.Struct("<BQQQI")  # opcode, length 20, summary start, summary offsets start, summary CRC


def _channels_from_summary(data: memoryview, sink: _Sink) -> None:
    """The schemas and channels of a closed file's summary, before its chunks:
    a damaged first chunk (where they come first) then costs only its own
    messages. Used only when the summary's CRC (in the footer) vouches for it."""
    n = len(data)
    at = n - 8 - _FOOTER.size
    if at < 8 or bytes(data[n - 8 :]) != MAGIC or data[at] != Opcode.FOOTER:
        return
    _, length, start, _, crc = _FOOTER.unpack_from(data, at)
    if length != 20 or crc == 0 or not 8 <= start <= at:
        return
    if zlib.crc32(data[start : n - 8 - 4]) != crc:
        return
    try:
        for op, s, e in _record_spans(data[:at], start):
            if op in (Opcode.SCHEMA, Opcode.CHANNEL):
                _read_record(op, data[s:e], e - s, sink)
    except Exception:  # a summary that vouched for itself and still does not parse: the chunks tell
        return


#: an MCAP file's footer record and closing magic
FOOTER_BYTES = _FOOTER.size + 8


def footer_summary_start(tail: bytes | memoryview) -> int:
    """The ``summary_start`` of the footer an MCAP file's last :data:`FOOTER_BYTES`
    bytes hold (0: none, or no footer there)."""
    if len(tail) != FOOTER_BYTES or bytes(tail[-8:]) != MAGIC or tail[0] != Opcode.FOOTER:
        return 0
    _, length, start, _, _ = _FOOTER.unpack_from(tail, 0)
    return int(start) if length == 20 else 0


def opens_summary(op: int) -> bool:
    """Whether a footer's ``summary_start`` pointing at a record of opcode ``op``
    names a summary: not at a Data End, where winder's writer points it for a
    moment while the file grows (it points at the summary it is writing while
    it closes: :mod:`winder.record.mcap_storage`). A file closed by its writer
    ends with a footer naming its summary; one left open does not."""
    return op != Opcode.DATA_END


def names_summary(data: bytes | memoryview) -> bool:
    """Whether the MCAP file ``data`` ends with a footer naming a summary (:func:`opens_summary`)."""
    n = len(data)
    start = footer_summary_start(data[n - FOOTER_BYTES :]) if n >= 8 + FOOTER_BYTES else 0
    return 8 <= start < n - FOOTER_BYTES and opens_summary(data[start])


def _check_magic(path: Path, data: memoryview) -> None:
    n = len(data)
    if bytes(data[:8]) != MAGIC:
        if bytes(data[:8]) == MAGIC[: min(8, n)] and n < 8:
            raise BagError(f"{path}: MCAP file cut short inside its header, damaged beyond recovery")
        if bytes(data[:16]) == b"SQLite format 3\x00":  # a bag directory's part index, globbed with its bags
            raise BagError(
                f"{path}: an SQLite file (the part index?), not a bag: `winder parts --db {path}` reads it"
            )
        raise BagError(f"{path}: not an MCAP file (it does not start with the MCAP magic bytes)")


class _Sink:
    """Adds the records of one MCAP file to a RawBag: schemas kept for the
    channels that name them, channel ids of a later split file following on
    from the earlier files', messages of unknown channels dropped."""

    def __init__(self, raw: RawBag, keep: Callable[[str], bool] | None = None) -> None:
        self.raw = raw
        self.schemas: dict[int, Schema] = {}
        self.offset = max(raw.connections, default=0)
        self.ids: dict[int, int] = {}  #: channel id in the file -> connection id in the RawBag
        self.kept: dict[int, bool] = {}  #: channel id in the file -> its messages are kept
        self.keep = keep
        self.crcs = False  #: the file's chunks carry CRCs (winder's uncompressed ones do, rosbags' do not)

    def add(self, rec: Schema | Channel | Message | tuple[int, int, bytes]) -> None:
        if isinstance(rec, tuple):  # a message inside a chunk, the most frequent case
            self._message(rec[0], rec[1], rec[2])
        elif isinstance(rec, Schema):
            self.schemas[rec.id] = rec
        elif isinstance(rec, Channel):
            self._channel(rec)
        else:
            self._message(rec.channel_id, rec.log_time, rec.data)

    def _message(self, channel: int, log_time: int, data: bytes) -> None:
        cid = self.ids.get(channel)
        if cid is None:
            return
        counts = self.raw.counts
        counts[cid] = counts.get(cid, 0) + 1
        if self.kept[channel]:
            self.raw.messages.append((cid, log_time, data))

    def _channel(self, rec: Channel) -> None:
        if rec.id in self.ids:
            return
        sch = self.schemas.get(rec.schema_id)
        cid = self.offset + rec.id
        self.ids[rec.id] = cid
        self.kept[rec.id] = self.keep is None or self.keep(rec.topic)
        self.raw.connections[cid] = Connection(
            cid,
            rec.topic,
            sch.name if sch else "",
            rec.message_encoding,
            sch.encoding if sch else "",
            bytes(sch.data).decode("utf-8", "replace") if sch else "",
            dict(rec.metadata),
        )


@dataclass(frozen=True)
class _Walk:
    """Where the walk over a file's top-level records stopped."""

    pos: int  #: byte after the last whole record read (after the footer, if found)
    footer: bool = False
    damaged: str = ""  #: why a whole record could not be read, "" if none
    #: the data ended in the open end of a writer that never closed the file
    #: (winder's room for the next chunk, :data:`~winder.record.mcap_storage.OP_OPEN_END`)
    open_end: bool = False


def _walk(data: memoryview, sink: _Sink) -> Generator[int, None, _Walk]:
    """Add the whole top-level records after the magic to ``sink``, up to the
    footer, the first incomplete record or the first damaged one."""
    pos = 8
    last = before_end = 0  # opcodes of the last record, and of the one before the Data End
    for op, start, end in _record_spans(data, pos):
        if op == Opcode.FOOTER:
            return _Walk(end, footer=True, open_end=before_end == OP_OPEN_END)
        if op == Opcode.DATA_END:
            before_end = last
        last = op
        try:
            _read_record(op, data[start:end], end - start, sink)
        except DamagedChunk as exc:  # its length was whole: skip it, read on
            sink.raw.damaged.append(f"chunk at byte {pos} skipped: {exc}")
        except Exception as exc:  # a damaged record: keep what came before it
            return _Walk(pos, damaged=f"damaged record at byte {pos} ({type(exc).__name__})")
        pos = end
        yield pos
    return _Walk(pos)


def _read_record(op: int, body: memoryview, length: int, sink: _Sink) -> None:
    """Add one whole top-level record (its opcode and body) to ``sink``."""
    if op == Opcode.CHUNK:
        try:
            chunk = Chunk.read(ReadDataStream(io.BytesIO(body)))
        except Exception as exc:
            raise DamagedChunk(f"its header cannot be read ({type(exc).__name__})") from None
        kind = chunk.compression or "none"
        sink.raw.compressions[kind] = sink.raw.compressions.get(kind, 0) + 1
        if chunk.uncompressed_crc:
            sink.crcs = True
        elif sink.crcs and not chunk.compression:
            # a file writes CRCs for all its chunks or for none; winder's own
            # compressed chunks have none (their frames carry checksums)
            raise DamagedChunk("no CRC, in a file whose chunks carry one")
        records = list(_inner_records(_checked_chunk_data(chunk)))  # whole, or none of it
        for rec in records:
            sink.add(rec)
    elif op in (Opcode.SCHEMA, Opcode.CHANNEL):
        stream = ReadDataStream(io.BytesIO(body))
        sink.add(Schema.read(stream) if op == Opcode.SCHEMA else Channel.read(stream))
    elif op == Opcode.MESSAGE:
        sink.add(Message.read(ReadDataStream(io.BytesIO(body)), length))


def _finish(path: Path, data: memoryview, raw: RawBag, sink: _Sink, walk: _Walk) -> None:
    """Mark ``raw`` cut short unless the walk ended at the footer and the
    closing magic, and say in a note how the file ended."""
    n, pos = len(data), walk.pos
    if walk.footer and bytes(data[pos : pos + 8]) == MAGIC and (not walk.open_end or names_summary(data)):
        return  # (an open end whose last footer names the summary: killed in its close, the summary whole)
    raw.closed = False
    raw.recovered = True
    if walk.open_end:
        raw.notes.append(
            f"{path.name}: its writer stopped without closing it (killed, or its disk filled): "
            "every chunk it had completed was read; the file has no summary or index"
        )
        return
    if walk.footer:
        raw.notes.append(f"{path.name}: cut short inside its closing magic bytes; every message was read")
        return
    if walk.damaged:
        raw.notes.append(f"{path.name}: {walk.damaged}; {n - pos} bytes after it not read")
        return
    _read_cut_chunk(data, pos, sink)
    where = f"inside the record at byte {pos}" if pos < n else "after a whole record"
    raw.notes.append(
        f"{path.name}: cut short at byte {n} ({where}), without summary and footer; "
        "every whole message before the cut was read"
    )


def _read_cut_chunk(data: memoryview, pos: int, sink: _Sink) -> None:
    """The record the file was cut in, at ``pos``: a chunk may still hold whole messages."""
    if pos + 9 > len(data) or data[pos] != Opcode.CHUNK:
        return
    part = _parse_chunk_partial(data[pos + 9 :])
    if part is None:
        return
    try:
        for rec in _inner_records(part[1]):
            sink.add(rec)
    except Exception:
        pass


def _read_sqlite(path: Path, raw: RawBag, keep: Callable[[str], bool] | None) -> None:
    from rosbags.rosbag2 import Reader

    try:
        with Reader(path) as reader:
            for c in reader.connections:
                raw.connections[c.id] = Connection(
                    c.id, c.topic, c.msgtype, "cdr", "ros2msg", c.msgdef.data if c.msgdef else ""
                )
            for conn, t, data in reader.messages():
                raw.counts[conn.id] = raw.counts.get(conn.id, 0) + 1
                if keep is None or keep(conn.topic):
                    raw.messages.append((conn.id, t, bytes(data)))
    except Exception as exc:
        raise BagError(f"{path}: rosbag2 (sqlite3) recording cannot be read: {exc}") from None


def _stream_sqlite(path: Path, wanted: frozenset[str], batch: int = 4096) -> Iterator[list[TopicMessage]]:
    from rosbags.rosbag2 import Reader

    with Reader(path) as reader:
        conns = [c for c in reader.connections if c.topic in wanted]
        out: list[TopicMessage] = []
        for conn, t, data in reader.messages(connections=conns) if conns else ():
            out.append((conn.topic, t, bytes(data)))
            if len(out) >= batch:
                yield out
                out = []
        if out:
            yield out


def read_raw(path: str | Path, keep: Callable[[str], bool] | None = None) -> RawBag:
    """Every readable message of a recording (directory, metadata.yaml or .mcap
    file); with ``keep``, only the messages of the topics it accepts are kept
    (the others are counted; :meth:`RawBag.stream` reads them)."""
    bag, files, meta = _bag_files(Path(path))
    raw = RawBag(bag, files, {}, [], closed=True, recovered=False, metadata=meta)
    if files and files[0].suffix == ".db3":
        _read_sqlite(bag, raw, keep)
        return raw
    for f in files:
        try:
            for _ in _read_mcap(f, _Sink(raw, keep)):
                pass
        except OSError as exc:
            raise BagError(f"{f}: cannot be read: {exc.strerror or exc}") from None
    if raw.closed and bag.is_dir() and not meta:
        raw.notes.append("metadata.yaml missing (the MCAP file itself is complete)")
    if not raw.counts:
        if raw.damaged:
            raise BagError(
                f"{bag}: damaged beyond recovery: {len(raw.damaged)} chunk(s) skipped and no message "
                f"readable (first: {raw.damaged[0]})"
            )
        if raw.recovered:
            raise BagError(
                f"{bag}: damaged beyond recovery: the MCAP file is cut short before its first whole message"
            )
        raise BagError(f"{bag}: empty recording: no messages")
    return raw


def _typestore() -> Any:
    from winder.record.msgtypes import jazzy_store

    return jazzy_store()


def bag_typestore(raw: RawBag) -> Any:
    """:func:`_typestore` for the messages of ``raw``: winder's own types as
    the bag defines them, where an earlier winder recorded other fields
    (:func:`winder.record.msgtypes.store_for_schemas`)."""
    from winder.record.msgtypes import store_for_schemas

    return store_for_schemas(
        (c.msgtype, c.schema) for c in raw.connections.values() if c.schema_encoding == "ros2msg"
    )


# -- repair -------------------------------------------------------------------------


def recover(path: str | Path, out: str | Path | None = None) -> tuple[Path, int]:
    """Write the readable messages of a cut-short recording as a new, closed
    rosbag2/MCAP directory (default ``<bag>_recovered`` beside it); return the
    directory and the number of messages saved. Never writes into an existing
    directory; a failed write leaves nothing behind (the bag is made beside
    ``out`` and renamed when closed; OutputError if it cannot be written)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import get_types_from_msg

    raw = read_raw(path)
    src = raw.path
    if out is None:
        base = src if src.is_dir() else src.with_suffix("")
        out = base.with_name(base.name + "_recovered")
    out = Path(out)
    if out.exists():
        raise BagError(f"{out}: already exists; remove it or choose another name")
    store = bag_typestore(raw)
    saved = 0
    # built beside ``out`` and renamed when closed: an interrupt or a full disk leaves no half bag
    with new_directory(out, create=False) as staging:
        writer = Writer(staging, version=9, storage_plugin=StoragePlugin.MCAP)
        # the new bag says where it comes from, and that it is a recovered part (never a whole run)
        writer.set_custom_data("winder_bag", "recovered")
        writer.set_custom_data("winder_recovered_from", src.name)
        writer.open()
        conns: dict[int, Any] = {}
        by_topic: dict[tuple[str, str], Any] = {}
        for c in raw.connections.values():
            if c.encoding != "cdr" or not c.msgtype:
                continue
            if c.msgtype not in store.fielddefs and c.schema and c.schema_encoding == "ros2msg":
                try:
                    store.register(get_types_from_msg(c.schema, c.msgtype))
                except Exception:
                    continue
            if c.msgtype not in store.fielddefs:
                continue
            key = (c.topic, c.msgtype)
            if key not in by_topic:
                by_topic[key] = writer.add_connection(c.topic, c.msgtype, typestore=store)
            conns[c.id] = by_topic[key]
        for cid, t, data in raw.messages:
            conn = conns.get(cid)
            if conn is not None:
                writer.write(conn, t, data)
                saved += 1
        writer.close()
    return out, saved
