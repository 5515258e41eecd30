"""winder.record.mcap_storage, the .mcap writer behind BagRecorder, against the
reference readers: the mcap library (indexed and record by record), rosbags,
and winder's own reader. Messages of random sizes (packed small ones, big ones
kept as pieces, some bigger than a chunk), random log times and every chunk
compression; every figure is compared with a count made in the test."""

from __future__ import annotations

import struct
from collections import Counter
from pathlib import Path

import lz4.frame
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.records import Chunk, Message, MessageIndex, Statistics
from mcap.stream_reader import StreamReader
from rosbags.highlevel import AnyReader
from ruamel.yaml import YAML

from winder.record.bag import COMPRESSIONS, BagRecorder
from winder.record.mcap_storage import CHUNK_BYTES, SMALL
from winder.record.reader import read_raw

try:
    from compression import zstd
except ImportError:
    from backports import zstd

TOPICS = {
    "/a": "std_msgs/msg/String",
    "/b": "std_msgs/msg/UInt8MultiArray",
    "/c": "std_msgs/msg/Int64MultiArray",
}


def string_msg(text: str) -> bytes:
    data = text.encode() + b"\x00"
    return b"\x00\x01\x00\x00" + struct.pack("<I", len(data)) + data


def bytes_msg(n: int, seed: int) -> bytes:
    """A UInt8MultiArray of n data bytes (empty layout)."""
    body = np.random.default_rng(seed).integers(0, 4, n, dtype=np.uint8).tobytes()
    return b"\x00\x01\x00\x00" + struct.pack("<II", 0, 0) + struct.pack("<I", n) + body


def int64_msg(values: np.ndarray) -> memoryview:
    """An Int64MultiArray whose payload is handed over as a memoryview of int64 (not bytes)."""
    head = b"\x00\x01\x00\x00" + struct.pack("<II", 0, 0) + struct.pack("<I", values.size)
    buf = np.frombuffer(head + values.astype("<i8").tobytes(), dtype=np.uint8)
    return memoryview(buf.view(np.int64) if len(buf) % 8 == 0 else buf)


SIZES = st.one_of(
    st.integers(0, 200),  # packed into the small-record buffer
    st.integers(SMALL - 16, SMALL + 16),  # either side of the threshold
    st.integers(SMALL, 3 * CHUNK_BYTES // 2),  # big: own pieces, up to more than a chunk
)


@st.composite
def recordings(draw: st.DrawFn) -> list[tuple[str, int, bytes | memoryview]]:
    n = draw(st.integers(0, 40))
    t = draw(st.integers(0, 2**40))
    out: list[tuple[str, int, bytes | memoryview]] = []
    for i in range(n):
        t += draw(st.integers(0, 10**9))  # equal log times too
        kind = draw(st.sampled_from(sorted(TOPICS)))
        if kind == "/a":
            out.append((kind, t, string_msg(f"m{i}" * draw(st.integers(0, 50)))))
        elif kind == "/b":
            out.append((kind, t, bytes_msg(draw(SIZES), i)))
        else:
            out.append((kind, t, int64_msg(np.arange(draw(st.integers(0, 3000))) * (i + 1))))
    return out


def write(path: Path, sent: list[tuple[str, int, bytes | memoryview]], compression: str) -> Path:
    rec = BagRecorder(path, TOPICS, compression=compression)
    for topic, t, data in sent:
        rec.write(topic, t, data, exact=True)
    rec.close()
    return next(path.glob("*.mcap"))


def decompress(chunk: Chunk) -> bytes:
    if chunk.compression == "zstd":
        return zstd.decompress(chunk.data)
    if chunk.compression == "lz4":
        return lz4.frame.decompress(chunk.data)
    assert chunk.compression == ""
    return chunk.data


@pytest.mark.parametrize("compression", COMPRESSIONS)
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(sent=recordings())
def test_the_reference_readers_get_back_every_message(
    tmp_path_factory: pytest.TempPathFactory,
    compression: str,
    sent: list[tuple[str, int, bytes | memoryview]],
) -> None:
    bag = tmp_path_factory.mktemp("bag") / "b"
    mcap = write(bag, sent, compression)
    expected = [(topic, t, bytes(data)) for topic, t, data in sent]
    counts = Counter(topic for topic, _, _ in sent)
    times = [t for _, t, _ in sent]

    # mcap, indexed: summary, chunk indexes, statistics
    with mcap.open("rb") as f:
        reader = make_reader(f)
        got = [(ch.topic, m.log_time, m.data) for _, ch, m in reader.iter_messages(log_time_order=False)]
        summary = reader.get_summary()
    assert got == expected
    assert summary is not None
    stats = summary.statistics
    assert stats is not None
    assert stats.message_count == len(sent)
    topic_of = {cid: ch.topic for cid, ch in summary.channels.items()}
    assert {topic_of[cid]: n for cid, n in stats.channel_message_counts.items() if n} == dict(counts)
    span = (min(times), max(times)) if sent else (0, 0)
    assert (stats.message_start_time, stats.message_end_time) == span
    assert {c.compression for c in summary.chunk_indexes} <= {"" if compression == "none" else compression}
    assert stats.chunk_count == len(summary.chunk_indexes)
    assert {s.name for s in summary.schemas.values()} == set(TOPICS.values())

    # mcap, record by record: every message index entry points at its message
    records = list(StreamReader(mcap.open("rb"), emit_chunks=True).records)
    chunks = [r for r in records if isinstance(r, Chunk)]
    indexed = 0
    for r in records:
        if isinstance(r, Chunk):
            body = decompress(r)
            assert len(body) == r.uncompressed_size
        elif isinstance(r, MessageIndex):
            for t, offset in r.records:
                op, _length, cid, _seq, log_time = struct.unpack_from("<BQHIQ", body, offset)
                assert (op, cid, log_time) == (0x05, r.channel_id, t)
                indexed += 1
    assert indexed == len(sent)
    assert len(chunks) == stats.chunk_count
    assert not any(isinstance(r, Message) for r in records)  # all inside chunks
    assert sum(isinstance(r, Statistics) for r in records) == 1

    # rosbags and metadata.yaml
    meta = YAML(typ="safe").load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == len(sent)
    assert {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]} == {
        topic: counts.get(topic, 0) for topic in TOPICS
    }
    if sent:
        assert meta["starting_time"]["nanoseconds_since_epoch"] == min(times)
        assert meta["duration"]["nanoseconds"] == max(times) - min(times)
    with AnyReader([bag]) as reader:
        assert [(c.topic, t, bytes(d)) for c, t, d in reader.messages()] == expected

    # winder's own reader
    if sent:
        raw = read_raw(bag)
        assert raw.closed and not raw.recovered
        assert [(raw.connections[cid].topic, t, bytes(d)) for cid, t, d in raw.messages] == expected


@pytest.mark.parametrize("compression", COMPRESSIONS)
def test_chunks_are_compressed_as_named(tmp_path: Path, compression: str) -> None:
    rows = np.cumsum(np.random.default_rng(1).integers(0, 3, size=(200_000, 5)), axis=0)
    sent = [("/c", 1000 * i, int64_msg(rows[i * 20_000 : (i + 1) * 20_000])) for i in range(10)]
    mcap = write(tmp_path / "b", sent, compression)
    raw_size = sum(memoryview(d).nbytes for _, _, d in sent)
    size = mcap.stat().st_size
    with mcap.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    if compression == "none":
        assert size > raw_size
        assert {c.compression for c in summary.chunk_indexes} == {""}
    else:  # small steps of a running count: both compress it at least 2x
        assert size < raw_size / 2
        assert {c.compression for c in summary.chunk_indexes} == {compression}


def test_a_payload_that_is_not_a_buffer_is_refused_before_anything_is_written(tmp_path: Path) -> None:
    from winder.record.mcap_storage import StreamingMcapStorage

    bag = tmp_path / "b"
    bag.mkdir()
    storage = StreamingMcapStorage(bag, None)
    with pytest.raises(TypeError):
        storage.write_id(1, 0, "text")  # type: ignore[arg-type]
    assert storage._size == 0 and not storage._index
