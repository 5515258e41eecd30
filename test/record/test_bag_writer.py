"""BagRecorder: what it writes, read back by rosbags and by the mcap library
(the reference readers), with and without chunk compression, and how its
writer thread reports a failure."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from winder.contract.cdr import MultiArrayCodec
from winder.contract.stream import TIMED_COLUMNS
from winder.record.bag import BagRecorder

TIMED = MultiArrayCodec(TIMED_COLUMNS, np.int64)
TOPICS = {"/winder/step_times": "std_msgs/msg/Int64MultiArray", "/winder/job": "std_msgs/msg/String"}


def string_payload(text: str) -> bytes:
    data = text.encode() + b"\x00"
    return b"\x00\x01\x00\x00" + len(data).to_bytes(4, "little") + data


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_every_message_reads_back_in_order(tmp_path: Path, compression: str) -> None:
    rng = np.random.default_rng(3)
    sent = [("/winder/job", 0, string_payload('{"job": "x"}'))]
    for i in range(40):  # ~13 MB: many 1 MiB chunks, written by the thread
        rows = np.cumsum(rng.integers(0, 3, size=(8192, 5)), axis=0)
        sent.append(("/winder/step_times", 1000 * i, TIMED.encode(rows)))
    rec = BagRecorder(tmp_path / "b", TOPICS, compression=compression)
    for topic, t, data in sent:
        rec.write(topic, t, data)
    rec.close()
    assert not rec.is_open and rec.messages == len(sent)
    with AnyReader([tmp_path / "b"]) as reader:
        got = [(c.topic, t, bytes(d)) for c, t, d in reader.messages()]
    assert got == sent
    with next((tmp_path / "b").glob("*.mcap")).open("rb") as f:
        summary = make_reader(f).get_summary()
        assert summary is not None
        kinds = {c.compression for c in summary.chunk_indexes}
    assert kinds == ({""} if compression == "none" else {compression})
    mcap_size = next((tmp_path / "b").glob("*.mcap")).stat().st_size
    raw_size = sum(len(d) for _, _, d in sent)
    assert (mcap_size > raw_size) if compression == "none" else (mcap_size < raw_size / 2)


def test_a_failure_of_the_writer_thread_is_raised_not_lost(tmp_path: Path) -> None:
    rec = BagRecorder(tmp_path / "b", TOPICS)
    rec.write("/winder/job", 0, "not bytes")  # type: ignore[arg-type]  # rosbags fails on it, in the thread
    with pytest.raises(RuntimeError, match=r"writing failed"):
        for _ in range(1000):  # the thread takes it up within this loop
            rec.write("/winder/job", 0, string_payload("after"))
            rec._thread.join(0.001)
    with pytest.raises(RuntimeError, match=r"writing failed"):
        rec.close()


def test_unknown_compression_is_a_one_line_error(tmp_path: Path) -> None:
    expected = r"^compression='lz5' is invalid: must be one of \('zstd', 'lz4', 'none'\)$"
    with pytest.raises(ValueError, match=expected):
        BagRecorder(tmp_path / "b", TOPICS, compression="lz5")
    assert not (tmp_path / "b").exists()


def test_a_bag_its_writer_left_unclosed_is_found_and_a_live_or_closed_one_is_not(tmp_path: Path) -> None:
    """A writer SIGKILLed mid-bag leaves it unclosed (metadata.yaml says
    ``recording``, the .mcap has no summary): :func:`unclosed_bags` finds it
    and :func:`unclosed_line` names ``winder bag recover`` for it. A bag
    being written now (its writer holds the file's lock) is not taken for
    one, nor a closed one, nor one already recovered beside it."""
    import os
    import signal
    import subprocess
    import sys

    from winder.record.bag import being_written, unclosed, unclosed_bags, unclosed_line
    from winder.record.raw import recover

    bag_dir = tmp_path / "bags"
    first = [("/winder/job", 0, string_payload('{"job": "x"}'))]
    killed = bag_dir / "killed"
    script = f"""
import os, signal
import numpy as np
from pathlib import Path
from winder.contract.cdr import MultiArrayCodec
from winder.contract.stream import TIMED_COLUMNS
from winder.record.bag import BagRecorder
rec = BagRecorder(Path({str(killed)!r}), {TOPICS!r}, first={first!r})
codec = MultiArrayCodec(TIMED_COLUMNS, np.int64)
for i in range(20):  # several chunks reach the file before the kill
    rec.write("/winder/step_times", 1000 * i, codec.encode(np.full((8192, 5), i, np.int64)))
rec._hand_over()
rec._queue.put(None)
rec._thread.join()  # all of it in the file but for the pending chunk, the summary never written
os.kill(os.getpid(), signal.SIGKILL)
"""
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert r.returncode == -signal.SIGKILL, r.stderr
    live = BagRecorder(bag_dir / "live", TOPICS, first=first)
    try:
        done = BagRecorder(bag_dir / "done", TOPICS, first=first)
        done.close()
        assert unclosed(killed) and being_written(bag_dir / "live") and not unclosed(bag_dir / "live")
        assert not being_written(killed) and not unclosed(bag_dir / "done")
        assert unclosed_bags(bag_dir) == [killed]
    finally:
        live.close()
    assert unclosed_bags(bag_dir) == [killed]  # closed now, as "done"
    line = unclosed_line(unclosed_bags(bag_dir), f"bag_dir {bag_dir}")
    assert "\n" not in line and f"`winder bag recover {killed}`" in line, line
    recover(killed)  # into killed_recovered, beside it
    assert unclosed_bags(bag_dir) == [] and os.path.isdir(f"{killed}_recovered")
