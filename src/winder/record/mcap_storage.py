"""The .mcap file of a winder bag, written without copying the messages, and
readable by every MCAP reader at every moment, whenever its writer stops.

rosbags' own MCAP storage copies every message three times on its way into a
chunk (a record buffer, the chunk buffer, the chunk's bytes) and compresses
the chunk as one block: for step chunks of 330 kB that is as much work as the
compression itself. :class:`StreamingMcapStorage` keeps a chunk as a list of
pieces (record headers and the payloads as they were handed over) and feeds
them straight to a streaming zstd or lz4 compressor, or to the file when the
bag is uncompressed. Small messages are packed into one buffer, so a /clock message
costs one struct.pack and two appends.

It is a storage plugin of ``rosbags.rosbag2.Writer`` (which writes
metadata.yaml and keeps the connections); the file layout is the one
rosbags writes, MCAP version 0 with chunks, message indexes and a summary
(https://mcap.dev/spec): schemas and channels at the head of the first chunk
and again in the summary, a ``rosbag2`` metadata record, statistics and
summary offsets. Unlike rosbags' files every chunk is checked, so a reader
can tell a damaged chunk from a good one (winder.record.raw does): an
uncompressed chunk carries its ``uncompressed_crc``; a compressed one carries
its codec's own checksums instead (lz4 frame block checksums, the zstd frame's
content checksum), which every decompressor verifies, and its CRC field is 0
("not computed", as the spec allows): the CRC-32 of every uncompressed byte cost
half as much as the lz4 compression itself. The summary's CRC is in the footer.
The data section's CRC is left 0 too: every message is inside a checked chunk.

The open end
------------
While the bag is open the file always ends as a complete MCAP file without
a summary: ``<chunks...><pad><Data End><Footer><magic>``, where the footer's
``summary_start`` is 0 (no index: every reader then reads the data section
from the start, as ``mcap recover`` expects) and ``pad`` is a record of
winder's own opcode (:data:`OP_OPEN_END`; MCAP keeps 0x80-0xFF for
application records, which every reader skips) whose body is the room the
next chunk is written into. A chunk is written into that body first, where
no reader looks, then made part of the file by one write of its record's
9-byte head over the pad's head, inside one page (a kill never cuts a write
within a page in two). So whenever the writer stops - SIGKILL, a crash, a
full disk, a file size limit - the file on disk holds every chunk it
completed and reads with the mcap library and rosbags (the tests: every
state between two writes), and with ``ros2 bag`` and Foxglove (their MCAP
readers' sources read a file without a summary from its start); what was
not yet in a completed chunk is lost (the chunk being filled, up to
:data:`CHUNK_BYTES`, and what waited in memory for it). Growing the file (the
trailer moved further out, then the pad's head) and the close (the summary
written into the pad, then made part of the file, then the file cut after
it) take a few writes of a few bytes each; between them the footer names
the last good trailer (or the new summary) as its summary, so that the
readers that take ``summary_start`` at its word (the mcap library, rosbags)
read the same chunks in every state, and those that fall back to reading
the data section (``ros2 bag``'s C++ reader) stop at its first Data End.
A write that fails (ENOSPC, EFBIG) leaves the file as it was (a trailer
the file could not take is cut off again): the chunk is then written in
halves, as far as they fit, so a full disk keeps every message that fits
in it, and the error is raised for the rest.
"""

from __future__ import annotations

import contextlib
import io
import mmap
import os
import struct
import zlib
from collections import defaultdict
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, cast

import lz4.frame

if TYPE_CHECKING:  # rosbags' writer is not imported by a reader (winder.record.raw reads OP_OPEN_END)
    from rosbags.interfaces import Connection, ConnectionExtRosbag2
    from rosbags.rosbag2 import CompressionMode

try:
    from compression import zstd
except ImportError:  # Python < 3.14
    from backports import zstd

__all__ = ["MAGIC", "OP_OPEN_END", "StreamingMcapStorage"]

MAGIC = b"\x89MCAP0\r\n"
#: A chunk is closed once its records pass this many bytes (rosbags: 1 MiB).
CHUNK_BYTES = 1 << 20
#: Payloads below this size are copied into the chunk's small-record buffer;
#: bigger ones are kept as they are, one piece each.
SMALL = 16 << 10
ZSTD_LEVEL = 1

_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE = 0x01, 0x02, 0x03, 0x04, 0x05
_OP_CHUNK, _OP_MESSAGE_INDEX, _OP_CHUNK_INDEX = 0x06, 0x07, 0x08
_OP_STATISTICS, _OP_METADATA, _OP_METADATA_INDEX = 0x0B, 0x0C, 0x0D
_OP_SUMMARY_OFFSET, _OP_DATA_END = 0x0E, 0x0F
#: the record of an open file's room for its next chunk (see the module's doc)
OP_OPEN_END = 0xF0

#: opcode, record length, channel id, sequence, log time, publish time
_MESSAGE_HEAD = struct.Struct("<BQHIQQ")
_MESSAGE_FIELDS = _MESSAGE_HEAD.size - 9  # the record's bytes before its data
#: a record's opcode and length
_HEAD = struct.Struct("<BQ")
#: Data End (13 bytes), Footer (29), magic (8): how an open file ends
TRAILER = 13 + 29 + 8
#: where the footer's summary_start lies in the trailer
_SUMMARY_START_AT = 13 + 9
#: writes inside one page of the page cache are never cut in two by a kill
PAGE = mmap.PAGESIZE
#: buffers per pwritev call (IOV_MAX on Linux)
_IOV_MAX = 1024


def _string(s: str | bytes) -> bytes:
    b = s.encode() if isinstance(s, str) else s
    return struct.pack("<I", len(b)) + b


def _record(op: int, *parts: bytes) -> bytes:
    body = b"".join(parts)
    return _HEAD.pack(op, len(body)) + body


def _pad_head(body: int) -> bytes:
    return _HEAD.pack(OP_OPEN_END, body)


def _trailer(summary_start: int) -> bytes:
    """Data End, a footer naming ``summary_start`` (0: none), the magic."""
    return (
        _record(_OP_DATA_END, struct.pack("<I", 0))
        + struct.pack("<BQQQI", _OP_FOOTER, 20, summary_start, 0, 0)
        + MAGIC
    )


def _within_page(pos: int, n: int) -> bool:
    return pos // PAGE == (pos + n - 1) // PAGE


def _write_all(fd: int, pieces: Sequence[bytes | bytearray | memoryview], offset: int) -> None:
    """Every byte of ``pieces`` at ``offset`` (a short write, as at a file size
    limit, is taken up again, and then fails with its error)."""
    views = [memoryview(p).cast("B") for p in pieces if len(p)]
    while views:
        done = os.pwritev(fd, views[:_IOV_MAX], offset)
        if done == 0:
            raise OSError(f"no byte written at offset {offset}")
        offset += done
        while views and done >= len(views[0]):
            done -= len(views[0])
            views.pop(0)
        if done:
            views[0] = views[0][done:]


class StreamingMcapStorage:
    """rosbags storage writer (``Writer.STORAGE_PLUGINS``) for one .mcap.

    ``compression`` is rosbags' CompressionMode: STORAGE means compressed
    chunks, anything else uncompressed ones. rosbags names no format, so the
    attribute :attr:`compression` ("zstd", the default, "lz4" or "") may be
    set before the first message. Payloads handed to :meth:`write` are kept
    until their chunk is closed and must not change meanwhile. ``counts``,
    ``first_t`` and ``last_t`` are those of the chunks in the file.
    """

    def __init__(self, path: Path, compression: CompressionMode | None, name: str = "") -> None:
        # ``name``: the file's stem, when the directory is opened under another
        # name than the bag's (winder.record.bag stages it, then renames it)
        self.path = path / f"{name or path.name}.mcap"
        self.compression = "zstd" if compression is not None and compression.name == "STORAGE" else ""
        self.bio: io.FileIO = self.path.open("xb", buffering=0)
        self._fd = self.bio.fileno()
        head = MAGIC + _record(_OP_HEADER, _string("ros2"), _string("winder"))
        self._end = len(head)  #: where the open end's pad begins: the file's whole records end here
        self._tail = self._end + 9  #: where the trailer begins
        self._file_size = self._tail + TRAILER
        _write_all(self._fd, [head, _pad_head(0), _trailer(0)], 0)
        self.schemas: dict[str, tuple[int, bytes]] = {}  # type name -> (id, record)
        self.channels: list[bytes] = []
        self.chunk_indexes: list[bytes] = []
        self.counts: dict[int, int] = {}  # messages per channel id, in the file
        self.first_t = 2**63 - 1  # log times of the first and last message in the file
        self.last_t = 0
        self._new_chunk()

    # -- the pending chunk -------------------------------------------------
    def _new_chunk(self) -> None:
        self._pieces: list[bytes | memoryview] = []
        self._small = bytearray()
        self._size = 0  # bytes of records in the chunk
        self._index: defaultdict[int, list[int]] = defaultdict(list)  # cid -> t, offset, t, offset...
        self._t0 = 2**63 - 1
        self._t1 = 0

    def _add(self, data: bytes | memoryview) -> None:
        """Records (schema, channel) that go into the chunk as they are."""
        self._small += data
        self._size += len(data)

    def add_msgtype(self, connection: Connection) -> None:
        fmt = "ros2idl" if connection.msgdef.format.name == "IDL" else "ros2msg"
        sid = len(self.schemas) + 1
        rec = _record(
            _OP_SCHEMA,
            struct.pack("<H", sid),
            _string(connection.msgtype),
            _string(fmt),
            _string(connection.msgdef.data),
        )
        self.schemas[connection.msgtype] = (sid, rec)
        self._add(rec)

    def add_connection(self, connection: Connection, offered_qos_profiles: str) -> None:
        # the channel's metadata as rosbag2_storage_mcap writes it: the QoS its
        # publishers offered and the type's hash, so a player can offer it again
        meta = _string("offered_qos_profiles") + _string(offered_qos_profiles)
        if connection.digest.startswith("RIHS01_"):
            meta += _string("topic_type_hash") + _string(connection.digest)
        rec = _record(
            _OP_CHANNEL,
            struct.pack("<HH", connection.id, self.schemas[connection.msgtype][0]),
            _string(connection.topic),
            _string(cast("ConnectionExtRosbag2", connection.ext).serialization_format),
            _string(meta),
        )
        self.channels.append(rec)
        self.counts[connection.id] = 0
        self._add(rec)

    def write(self, connection: Connection, timestamp: int, data: bytes | memoryview) -> None:
        self.write_id(connection.id, timestamp, data)

    def write_id(self, cid: int, t: int, data: bytes | memoryview) -> None:
        """:meth:`write` by channel id (what the bag recorder's thread calls)."""
        data = memoryview(data).cast("B")  # a TypeError here, before anything changed
        n = len(data)
        head = _MESSAGE_HEAD.pack(_OP_MESSAGE, _MESSAGE_FIELDS + n, cid, 0, t, t)
        idx = self._index[cid]
        idx.append(t)
        idx.append(self._size)
        self._small += head
        if n < SMALL:
            self._small += data
        else:
            self._pieces.append(bytes(self._small))
            self._pieces.append(data)
            self._small.clear()
        self._size += len(head) + n
        if t < self._t0:
            self._t0 = t
        if t > self._t1:
            self._t1 = t
        if self._size > CHUNK_BYTES:
            self.close_chunk()

    def _chunk_pieces(self) -> list[bytes | memoryview]:
        if self._small:
            self._pieces.append(bytes(self._small))
            self._small.clear()
        return self._pieces

    def close_chunk(self) -> None:
        """Write the pending chunk and its message indexes into the file. If
        the file cannot take it (a full disk, a file size limit), its
        messages are written in halves, in order, as far as they fit; the
        error is raised for the rest, which are dropped (the file stays as
        it was after the last whole part)."""
        pieces = self._chunk_pieces()
        size, index, t0, t1 = self._size, self._index, self._t0, self._t1
        self._new_chunk()
        try:
            self._put_chunk(pieces, size, index, t0, t1)
        except OSError:
            data = b"".join(pieces)
            starts = sorted(
                (index[cid][i + 1], cid, index[cid][i]) for cid in index for i in range(0, len(index[cid]), 2)
            )
            if len(starts) < 2:
                raise
            self._put_split(data, starts, 0, len(starts))

    def _put_split(self, data: bytes, starts: list[tuple[int, int, int]], lo: int, hi: int) -> None:
        """The messages ``starts[lo:hi]`` (offset, channel id, log time) of the
        chunk ``data`` as one chunk, else as two halves; the records before
        the first message (schemas, channels) go with it."""
        begin = 0 if lo == 0 else starts[lo][0]
        end = starts[hi][0] if hi < len(starts) else len(data)
        index: defaultdict[int, list[int]] = defaultdict(list)
        for offset, cid, t in starts[lo:hi]:
            index[cid] += (t, offset - begin)
        times = [t for _, _, t in starts[lo:hi]]
        try:
            self._put_chunk([data[begin:end]], end - begin, index, min(times), max(times))
        except OSError:
            if hi - lo < 2:
                raise
            mid = (lo + hi) // 2
            self._put_split(data, starts, lo, mid)
            self._put_split(data, starts, mid, hi)

    def _put_chunk(
        self, pieces: list[bytes | memoryview], size: int, index: dict[int, list[int]], t0: int, t1: int
    ) -> None:
        """One chunk of ``size`` bytes of records, its message indexes, into the file."""
        out: list[bytes | memoryview]
        if self.compression == "zstd":
            options = {zstd.CompressionParameter.compression_level: ZSTD_LEVEL}
            options[zstd.CompressionParameter.checksum_flag] = 1  # verified by the decompressor
            comp = zstd.ZstdCompressor(options=options)
            comp.set_pledged_input_size(size)
            out = [comp.compress(p) for p in pieces]
            out.append(comp.flush())
        elif self.compression == "lz4":
            # independent blocks: a quarter faster on step chunks, the same size
            # and a checksum of each compressed block, verified by the decompressor
            lz = lz4.frame.LZ4FrameCompressor(content_checksum=False, block_linked=False, block_checksum=True)
            out = [lz.begin(size)]
            out += [lz.compress(p) for p in pieces]
            out.append(lz.flush())
        else:
            out = pieces
        stored = sum(len(p) for p in out)
        crc = 0  # a compressed chunk: its frame's checksums check it (see the module's doc)
        if not self.compression:
            for p in pieces:
                crc = zlib.crc32(p, crc)
        if not index:  # only schema and channel records
            t0 = t1 = 0
        head = struct.pack("<QQQI", t0, t1, size, crc) + _string(self.compression)
        head += struct.pack("<Q", stored)
        start = self._end
        chunk_length = 9 + len(head) + stored
        at = start + chunk_length
        offsets, indexes = [], []
        for cid, idx in index.items():
            offsets.append(struct.pack("<HQ", cid, at))
            entries = struct.pack(f"<{len(idx)}Q", *idx)
            rec = _record(_OP_MESSAGE_INDEX, struct.pack("<HI", cid, len(entries)), entries)
            indexes.append(rec)
            at += len(rec)
        self._commit(_HEAD.pack(_OP_CHUNK, len(head) + stored), [head, *out, *indexes])
        # in the file: counted, and indexed in the summary
        self.chunk_indexes.append(
            _record(
                _OP_CHUNK_INDEX,
                struct.pack("<QQQQ", t0, t1, start, chunk_length),
                _string(b"".join(offsets)),
                struct.pack("<Q", at - start - chunk_length),
                _string(self.compression),
                struct.pack("<QQ", stored, size),
            )
        )
        for cid, idx in index.items():
            self.counts[cid] = self.counts.get(cid, 0) + len(idx) // 2
        if index:
            self.first_t, self.last_t = min(self.first_t, t0), max(self.last_t, t1)

    # -- the open end ------------------------------------------------------
    def _commit(self, head: bytes, rest: Sequence[bytes | memoryview]) -> None:
        """Records (``head``, the first one's opcode and length, then the rest
        of their bytes) into the pad's room, then made part of the file by
        writing ``head`` over the pad's head (see the module's doc)."""
        start = self._end
        end = start + len(head) + sum(len(r) for r in rest)
        filler: list[bytes] = []
        if not _within_page(end, 9):  # the next commit's head must not straddle a page
            filler.append(_pad_head(0))
            end += 9
        self._make_room(end - start + 9)  # the records, then the next pad's head
        _write_all(self._fd, [*rest, *filler, _pad_head(self._tail - end - 9)], start + len(head))
        _write_all(self._fd, [head], start)  # the one write that makes them part of the file
        self._end = end

    def _make_room(self, n: int) -> None:
        """At least ``n`` bytes between the end of the whole records and the
        trailer: the trailer is written further out (its footer naming the
        old trailer as the summary: readers stop there meanwhile), then the
        pad's head covers the room, then the footer names no summary again.
        A trailer the file cannot take is cut off again."""
        if self._tail - self._end >= n:
            return
        tail = max(self._end + n, self._file_size)
        while not _within_page(tail, TRAILER):
            tail += 1
        size = self._file_size
        try:
            _write_all(self._fd, [_trailer(self._tail)], tail)
        except OSError:
            with contextlib.suppress(OSError):
                os.ftruncate(self._fd, size)
            raise
        self._file_size = tail + TRAILER
        _write_all(self._fd, [_pad_head(tail - self._end - 9)], self._end)
        _write_all(self._fd, [struct.pack("<Q", 0)], tail + _SUMMARY_START_AT)
        self._tail = tail

    def flush(self) -> None:
        """Close the pending chunk, if it holds anything."""
        if self._size:
            self.close_chunk()

    def close(self, version: int, metadata: str) -> None:
        """Last chunk, the rosbag2 metadata record, data end, summary, footer:
        written into the open end's room, made part of the file, the file cut after it."""
        del version  # the rosbag2 version is inside ``metadata``
        self.flush()
        start = self._end
        meta = _record(
            _OP_METADATA,
            _string("rosbag2"),
            _string(_string("serialized_metadata") + _string(metadata)),
        )
        # the data section's CRC is left 0 ("not computed"): every message lives in a
        # chunk with a CRC of its own, and a second pass over the whole file would
        # cost as much as the chunks' CRCs again
        data_end = _record(_OP_DATA_END, struct.pack("<I", 0))
        summary_start = start + len(meta) + len(data_end)
        summary = bytearray()
        groups: list[tuple[int, int, int]] = []

        def group(op: int, records: Iterable[bytes]) -> None:
            at = len(summary)
            for rec in records:
                summary.extend(rec)
            if len(summary) > at:
                groups.append((op, summary_start + at, len(summary) - at))

        group(_OP_SCHEMA, [rec for _, rec in self.schemas.values()])
        group(_OP_CHANNEL, self.channels)
        group(_OP_CHUNK_INDEX, self.chunk_indexes)
        meta_where = struct.pack("<QQ", start, len(meta))
        group(_OP_METADATA_INDEX, [_record(_OP_METADATA_INDEX, meta_where, _string("rosbag2"))])
        counts = b"".join(struct.pack("<HQ", cid, n) for cid, n in sorted(self.counts.items()))
        total = sum(self.counts.values())
        group(
            _OP_STATISTICS,
            [
                _record(
                    _OP_STATISTICS,
                    struct.pack(
                        "<QHIIIIQQ",
                        total,
                        len(self.schemas),
                        len(self.channels),
                        0,  # attachments
                        1,  # metadata records
                        len(self.chunk_indexes),
                        self.first_t if total else 0,
                        self.last_t,
                    ),
                    _string(counts),
                )
            ],
        )
        offsets_start = summary_start + len(summary)
        for op, at, length in groups:
            summary.extend(_record(_OP_SUMMARY_OFFSET, struct.pack("<BQQ", op, at, length)))
        summary.extend(struct.pack("<BQQQ", _OP_FOOTER, 20, summary_start, offsets_start))
        closing = meta + data_end + bytes(summary) + struct.pack("<I", zlib.crc32(summary)) + MAGIC
        self._make_room(len(closing))
        _write_all(self._fd, [memoryview(closing)[9:]], start + 9)
        # the open end's footer names the summary meanwhile: a reader that takes it at its word reads it
        _write_all(self._fd, [struct.pack("<Q", summary_start)], self._tail + _SUMMARY_START_AT)
        _write_all(self._fd, [closing[:9]], start)
        os.ftruncate(self._fd, start + len(closing))
        self._end = self._file_size = start + len(closing)
        self.bio.close()

    def abort(self) -> None:
        """Stop without a summary: the file keeps every chunk written so far,
        and every MCAP reader reads it as it is (see the module's doc)."""
        self.bio.close()
