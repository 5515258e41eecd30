"""The .mcap file of a winder bag, written without copying the messages.

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
"""

from __future__ import annotations

import struct
import zlib
from collections import defaultdict
from collections.abc import Iterable
from pathlib import Path
from typing import BinaryIO, cast

import lz4.frame
from rosbags.interfaces import Connection, ConnectionExtRosbag2
from rosbags.rosbag2 import CompressionMode

try:
    from compression import zstd
except ImportError:  # Python < 3.14
    from backports import zstd

__all__ = ["MAGIC", "StreamingMcapStorage"]

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

#: opcode, record length, channel id, sequence, log time, publish time
_MESSAGE_HEAD = struct.Struct("<BQHIQQ")
_MESSAGE_FIELDS = _MESSAGE_HEAD.size - 9  # the record's bytes before its data


def _string(s: str | bytes) -> bytes:
    b = s.encode() if isinstance(s, str) else s
    return struct.pack("<I", len(b)) + b


def _record(op: int, *parts: bytes) -> bytes:
    body = b"".join(parts)
    return struct.pack("<BQ", op, len(body)) + body


class StreamingMcapStorage:
    """rosbags storage writer (``Writer.STORAGE_PLUGINS``) for one .mcap.

    ``compression`` is rosbags' CompressionMode: STORAGE means compressed
    chunks, anything else uncompressed ones. rosbags names no format, so the
    attribute :attr:`compression` ("zstd", the default, "lz4" or "") may be
    set before the first message. Payloads handed to :meth:`write` are kept
    until their chunk is closed and must not change meanwhile.
    """

    def __init__(self, path: Path, compression: CompressionMode | None, name: str = "") -> None:
        # ``name``: the file's stem, when the directory is opened under another
        # name than the bag's (winder.record.bag stages it, then renames it)
        self.path = path / f"{name or path.name}.mcap"
        self.compression = "zstd" if compression == CompressionMode.STORAGE else ""
        self.bio: BinaryIO = self.path.open("xb")
        self._crc = 0  # CRC-32 of the summary section, as it is written (see close())
        self.bio.write(MAGIC)
        self.bio.write(_record(_OP_HEADER, _string("ros2"), _string("winder")))
        self.schemas: dict[str, tuple[int, bytes]] = {}  # type name -> (id, record)
        self.channels: list[bytes] = []
        self.chunk_indexes: list[bytes] = []
        self.counts: dict[int, int] = {}  # messages per channel id
        self.first_t = 2**63 - 1  # log times of the first and last message
        self.last_t = 0
        self._new_chunk()

    def _out(self, data: bytes | memoryview) -> None:
        """Write a summary record to the file, keeping its CRC for the footer."""
        self.bio.write(data)
        self._crc = zlib.crc32(data, self._crc)

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
            _string(cast(ConnectionExtRosbag2, connection.ext).serialization_format),
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
        self.counts[cid] += 1
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
        """Write the pending chunk, its message indexes, and remember its index record."""
        pieces = self._chunk_pieces()
        size = self._size
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
        if self._index:
            t0, t1 = self._t0, self._t1
            self.first_t, self.last_t = min(self.first_t, t0), max(self.last_t, t1)
        else:  # only schema and channel records
            t0 = t1 = 0
        head = struct.pack("<QQQI", t0, t1, size, crc) + _string(self.compression)
        head += struct.pack("<Q", stored)
        bio = self.bio
        chunk_start = bio.tell()
        bio.write(struct.pack("<BQ", _OP_CHUNK, len(head) + stored))
        bio.write(head)
        for p in out:
            bio.write(p)
        chunk_end = bio.tell()
        offsets = []
        for cid, idx in self._index.items():
            offsets.append(struct.pack("<HQ", cid, bio.tell()))
            entries = struct.pack(f"<{len(idx)}Q", *idx)
            bio.write(_record(_OP_MESSAGE_INDEX, struct.pack("<HI", cid, len(entries)), entries))
        self.chunk_indexes.append(
            _record(
                _OP_CHUNK_INDEX,
                struct.pack("<QQQQ", t0, t1, chunk_start, chunk_end - chunk_start),
                _string(b"".join(offsets)),
                struct.pack("<Q", bio.tell() - chunk_end),
                _string(self.compression),
                struct.pack("<QQ", stored, size),
            )
        )
        self._new_chunk()

    def flush(self) -> None:
        """Close the pending chunk, if it holds anything."""
        if self._size:
            self.close_chunk()

    def close(self, version: int, metadata: str) -> None:
        """Last chunk, the rosbag2 metadata record, data end, summary, footer."""
        del version  # the rosbag2 version is inside ``metadata``
        self.flush()
        bio = self.bio
        meta_start = bio.tell()
        bio.write(
            _record(
                _OP_METADATA,
                _string("rosbag2"),
                _string(_string("serialized_metadata") + _string(metadata)),
            )
        )
        meta_end = bio.tell()
        # the data section's CRC is left 0 ("not computed"): every message lives in a
        # chunk with a CRC of its own, and a second pass over the whole file would
        # cost as much as the chunks' CRCs again
        bio.write(_record(_OP_DATA_END, struct.pack("<I", 0)))
        summary_start = bio.tell()
        groups: list[tuple[int, int, int]] = []

        def group(op: int, records: Iterable[bytes]) -> None:
            start = bio.tell()
            for rec in records:
                self._out(rec)
            if bio.tell() > start:
                groups.append((op, start, bio.tell() - start))

        group(_OP_SCHEMA, [rec for _, rec in self.schemas.values()])
        group(_OP_CHANNEL, self.channels)
        group(_OP_CHUNK_INDEX, self.chunk_indexes)
        meta_where = struct.pack("<QQ", meta_start, meta_end - meta_start)
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
        offsets_start = bio.tell()
        for op, start, length in groups:
            self._out(_record(_OP_SUMMARY_OFFSET, struct.pack("<BQQ", op, start, length)))
        footer = struct.pack("<BQQQ", _OP_FOOTER, 20, summary_start, offsets_start)
        self._out(footer)
        bio.write(struct.pack("<I", self._crc))
        bio.write(MAGIC)
        bio.close()

    def abort(self) -> None:
        """Stop without a summary: the chunks written so far stay in the file,
        which winder.record.raw reads and ``winder bag recover`` writes out
        closed; no other reader opens it without its summary."""
        self.bio.close()
