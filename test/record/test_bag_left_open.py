"""A bag whose writer stops without closing it - SIGKILL, a full disk, a
file size limit - opens as it is with the reference readers: the ``mcap``
library (its seeking reader, as ``make_reader`` gives it, and its stream
reader), rosbags' AnyReader on the rosbag2 directory, and winder's reader.
Each reads the same messages, and they are the head of what was written,
in order (every chunk the writer completed).

The states a kill can leave are every state between two of the writer's
writes (a write within one page is never cut in two): the first test looks
at the file after each write of a recording; the others kill real writer
processes and fill real disks."""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import NonSeekingReader, make_reader
from rosbags.highlevel import AnyReader
from support import wait

import winder.record.mcap_storage as storage_module
from winder.record.bag import BagRecorder, unclosed
from winder.record.raw import BagError, read_raw

TOPICS = {
    "/winder/job": "std_msgs/msg/String",
    "/winder/step_times": "std_msgs/msg/Int64MultiArray",
    "/winder/joint_states": "std_msgs/msg/UInt8MultiArray",
}

Sent = list[tuple[str, int, bytes]]

#: the recording the writer processes make: its messages follow from the seed alone
WRITER = """
import sys
import numpy as np
from pathlib import Path
sys.path[:0] = [{test!r}, {support!r}]
from test_bag_left_open import TOPICS, recording
from winder.record.bag import BagRecorder
sent = recording({seed}, {n}, {big})
rec = BagRecorder(Path({bag!r}), TOPICS, first=sent[:1], compression={compression!r})
print("open", flush=True)
try:
    for topic, t, data in sent[1:]:
        rec.write(topic, t, data, exact=True)
    rec.close()
except RuntimeError as exc:  # the disk: said, and the bag closed as far as it goes
    print("failed:", exc, flush=True)
    try:
        rec.close()
    except RuntimeError:
        pass
"""


def string_msg(text: str) -> bytes:
    data = text.encode() + b"\x00"
    return b"\x00\x01\x00\x00" + len(data).to_bytes(4, "little") + data


def bytes_msg(body: bytes) -> bytes:
    """A UInt8MultiArray (empty layout) holding ``body``."""
    return b"\x00\x01\x00\x00" + bytes(8) + len(body).to_bytes(4, "little") + body


def int64_msg(values: np.ndarray) -> bytes:
    head = b"\x00\x01\x00\x00" + bytes(8) + values.size.to_bytes(4, "little")
    return head + values.astype("<i8").tobytes()


def recording(seed: int, n: int, big: int = 200_000) -> Sent:
    """A job description, then ``n`` messages: step chunks of up to ``big``
    bytes (compressible) and small joint states (random bytes), log times
    rising (equal ones too)."""
    rng = np.random.default_rng(seed)
    sent: Sent = [("/winder/job", 0, string_msg(f'{{"job": "seed {seed}"}}'))]
    t = 0
    for i in range(n):
        t += int(rng.integers(0, 3)) * 1000
        if rng.random() < 0.3:
            rows = np.cumsum(rng.integers(0, 3, int(rng.integers(1, big // 8))), axis=0) + i
            sent.append(("/winder/step_times", t, int64_msg(rows)))
        else:
            sent.append(("/winder/joint_states", t, bytes_msg(rng.bytes(int(rng.integers(0, 400))))))
    return sent


def read_all(bag: Path) -> dict[str, Any]:
    """What each reader reads of ``bag``: [(topic, log time, bytes)] in file order, or its error."""
    [mcap] = list(bag.glob("*.mcap"))
    got: dict[str, Any] = {}
    try:
        with mcap.open("rb") as f:
            got["mcap"] = [
                (ch.topic, m.log_time, bytes(m.data))
                for _, ch, m in make_reader(f).iter_messages(log_time_order=False)
            ]
    except Exception as exc:
        got["mcap"] = f"{type(exc).__name__}: {exc}"
    try:
        with mcap.open("rb") as f:
            got["mcap stream"] = [
                (ch.topic, m.log_time, bytes(m.data))
                for _, ch, m in NonSeekingReader(f).iter_messages(log_time_order=False)
            ]
    except Exception as exc:
        got["mcap stream"] = f"{type(exc).__name__}: {exc}"
    try:
        with AnyReader([bag]) as reader:
            got["rosbags"] = [(c.topic, t, bytes(d)) for c, t, d in reader.messages()]
    except Exception as exc:
        got["rosbags"] = f"{type(exc).__name__}: {exc}"
    try:
        raw = read_raw(bag)
        got["winder"] = [(raw.connections[cid].topic, t, bytes(d)) for cid, t, d in raw.messages]
    except Exception as exc:
        got["winder"] = f"{type(exc).__name__}: {exc}"
    return got


def agreed_head(bag: Path, sent: Sent) -> int:
    """The number of messages every reader reads of ``bag``, asserting that
    each reads the same ones and that they are the first ones of ``sent``."""
    got = read_all(bag)
    errors = {who: v for who, v in got.items() if isinstance(v, str)}
    assert not errors, f"{bag}: {errors}"
    first = got["rosbags"]
    assert all(v == first for v in got.values()), {who: len(v) for who, v in got.items()}
    n = len(first)
    assert first == sent[:n], f"{bag}: the {n} messages read are not the head of those written"
    return n


def agreed_head_of_file(mcap: Path, sent: Sent) -> int:
    """:func:`agreed_head` of a lone .mcap (no rosbag2 directory around it)."""
    with mcap.open("rb") as f:
        seeking = [(ch.topic, m.log_time, bytes(m.data)) for _, ch, m in make_reader(f).iter_messages()]
    with mcap.open("rb") as f:
        stream = [(ch.topic, m.log_time, bytes(m.data)) for _, ch, m in NonSeekingReader(f).iter_messages()]
    from rosbags.rosbag2.storage_mcap import McapReader

    reader = McapReader(mcap)
    reader.open()
    try:
        ros = [(c.topic, t, bytes(d)) for c, t, d in reader.messages(reader.connections)]
    finally:
        reader.close()
    own: Sent = []
    if not ros:  # winder's reader refuses a recording without a message, in one line
        with pytest.raises(BagError, match="before its first whole message"):
            read_raw(mcap)
    else:
        raw = read_raw(mcap)
        own = [(raw.connections[cid].topic, t, bytes(d)) for cid, t, d in raw.messages]
    assert seeking == stream == ros == own == sent[: len(own)], (
        len(seeking),
        len(stream),
        len(ros),
        len(own),
    )
    return len(own)


@contextlib.contextmanager
def every_state(bag: Path, name: str) -> Iterator[list[Path]]:
    """Copies of ``bag`` (its .mcap and metadata.yaml) after each write of its
    writer (winder.record.mcap_storage writes the file through one function)."""
    states: list[Path] = []
    write_all = storage_module._write_all

    def take(fd: int, pieces: Any, offset: int) -> None:
        write_all(fd, pieces, offset)
        copy = bag.parent / f"{name}{len(states):03d}"
        copy.mkdir()
        for f in bag.iterdir():  # (while the bag opens it is staged under another name)
            shutil.copyfile(f, copy / f.name)
        states.append(copy)

    storage_module._write_all = take
    try:
        yield states
    finally:
        storage_module._write_all = write_all


@pytest.mark.parametrize("compression", ["lz4", "none"])
def test_every_state_between_the_writers_writes_opens_with_every_reader(
    tmp_path: Path, compression: str
) -> None:
    """The file after each write the writer makes (where a kill may stop it):
    from the bag's open to its close every reader opens it and reads the same
    head of the messages, which never shrinks; the closed bag reads whole.
    The recording spans many chunks of every size (a chunk over 1 MiB, one
    of a few bytes at the close), so that the file grows at every chunk and
    the chunks' heads fall on either side of page boundaries."""
    sent = recording(5, 300)
    bag = tmp_path / "work" / "b"
    bag.parent.mkdir()
    # each state's metadata.yaml is the one of its moment: the bag's own, once it exists
    with every_state(tmp_path / "work" / f".b.opening-{os.getpid()}", "opening") as staged:
        rec = BagRecorder(bag, TOPICS, first=sent[:1], compression=compression)
    with every_state(bag, "state") as states:
        for topic, t, data in sent[1:]:
            rec.write(topic, t, data, exact=True)
        rec.close()
    assert len(states) > 20, len(states)  # several writes per chunk
    # while the bag opens it is staged under another name and renamed whole, with its
    # metadata.yaml; the staged file reads as well (without metadata.yaml, as an .mcap)
    for state in staged:
        assert agreed_head_of_file(state / "b.mcap", sent) >= 0
    heads = [agreed_head(state, sent) for state in states]
    # a state whose metadata.yaml still says "recording" is a bag left unclosed unless its
    # file has its summary already (the writer killed between the two)
    for state in states:
        if "winder_bag: recording" in (state / "metadata.yaml").read_text():
            assert unclosed(state) == (not read_raw(state).closed), state
    assert heads == sorted(heads) and heads[0] >= 1 and heads[-1] == len(sent)
    assert len(set(heads)) > 6  # the head grew chunk by chunk
    raw = read_raw(bag)
    assert raw.closed and not raw.recovered and not unclosed(bag)
    with next(bag.glob("*.mcap")).open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == len(sent)


def writer_process(bag: Path, seed: int, n: int, compression: str, big: int = 200_000) -> list[str]:
    test = Path(__file__).parent
    script = WRITER.format(
        test=str(test),
        support=str(test.parent),
        seed=seed,
        n=n,
        big=big,
        bag=str(bag),
        compression=compression,
    )
    return [sys.executable, "-c", script]


def test_a_writer_killed_at_any_moment_leaves_a_bag_every_reader_opens(tmp_path: Path) -> None:
    """``kill -9`` of a process recording a bag, at 12 moments of its
    recording (after 1 kB to 12 MB of file): every reader opens the bag and
    reads the same messages, the head of those written; metadata.yaml still
    says ``recording``, and the bag is one left unclosed."""
    rng = np.random.default_rng(11)
    heads = []
    for i in range(12):
        seed = int(rng.integers(1 << 30))
        sent = recording(seed, 900)
        bag = tmp_path / f"b{i}"
        compression = ["lz4", "zstd", "none"][i % 3]
        p = subprocess.Popen(writer_process(bag, seed, 900, compression), stdout=subprocess.PIPE, text=True)
        try:
            size = int(10 ** rng.uniform(3, 7.1))

            def grown(bag: Path = bag, size: int = size) -> bool:
                files = list(bag.glob("*.mcap")) if bag.is_dir() else []
                return bool(files) and files[0].stat().st_size >= size

            wait.until(grown, 60, f"{bag}: {size} bytes", poll=0.0005, running=p)
            p.send_signal(signal.SIGKILL)
        finally:
            p.kill()
            p.wait()
        if p.returncode == 0:  # it ended first: a closed bag, every message
            assert agreed_head(bag, sent) == len(sent)
            continue
        assert p.returncode == -signal.SIGKILL
        n = agreed_head(bag, sent)
        raw = read_raw(bag)
        if raw.closed:  # killed in its close, after the file's summary: whole, not left unclosed
            assert n == len(sent) and not unclosed(bag)
            continue
        heads.append(n)
        assert "winder_bag: recording" in (bag / "metadata.yaml").read_text()
        assert unclosed(bag)
        assert raw.recovered and "stopped without closing it" in " ".join(raw.notes)
    assert len(heads) >= 8 and max(heads) > 100, heads  # most were killed mid-recording


def limited_disk(tmp_path: Path, kind: str) -> tuple[Path, list[str]]:
    """A directory that takes about 1 MiB: a 1 MiB tmpfs (ENOSPC) where the
    machine lets the test mount one, else, as for ``fsize``, a 1 MiB file
    size limit on the writer (EFBIG); and the command prefix for the writer."""
    disk = tmp_path / "disk"
    disk.mkdir()
    if kind == "tmpfs":
        mount = ["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(disk)]
        if subprocess.run(mount, capture_output=True).returncode == 0:
            return disk, []
    return disk, ["prlimit", f"--fsize={1 << 20}"]


@pytest.mark.parametrize("kind", ["tmpfs", "fsize"])
@pytest.mark.parametrize("compression", ["none", "lz4"])
def test_a_full_disk_keeps_every_message_that_fits_and_every_reader_opens_it(
    tmp_path: Path, kind: str, compression: str
) -> None:
    """A writer whose disk fills up (or whose file size limit is reached)
    with a 1 MiB chunk pending: the chunk goes into the file in parts, as
    far as they fit, so the bag keeps nearly 1 MiB of messages (not one of
    them fitted whole), and every reader opens it and reads the same head of
    the messages written."""
    disk, prefix = limited_disk(tmp_path, kind)
    try:
        bag = disk / "b"
        seed = 7
        sent = recording(seed, 2000, big=40_000)
        r = subprocess.run(
            [*prefix, *writer_process(bag, seed, 2000, compression, big=40_000)],
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert r.returncode == 0, r.stdout + r.stderr
        assert "failed:" in r.stdout and ("No space left" in r.stdout or "File too large" in r.stdout), (
            r.stdout
        )
        n = agreed_head(bag, sent)
        kept = sum(len(d) for _, _, d in sent[:n])
        # what fits: the disk less metadata.yaml and the file's records (compressed chunks hold more)
        assert kept > 700_000, (n, kept)
        assert n < len(sent)
    finally:
        subprocess.run(["umount", str(disk)], capture_output=True)


#: a writer of a big message every 0.3 s (each closes a chunk), then idle: its bag stays open
SLOW_WRITER = """
import sys, time
from pathlib import Path
sys.path[:0] = [{test!r}, {support!r}]
from test_bag_left_open import TOPICS, int64_msg, string_msg
import numpy as np
from winder.record.bag import BagRecorder
rec = BagRecorder(Path({bag!r}), TOPICS, first=[("/winder/job", 0, string_msg("x"))], compression="none")
for i in range(1, 30):
    rec.write("/winder/step_times", i, int64_msg(np.arange(140_000) + i), exact=True)
    rec._hand_over()  # to the writer thread now, not with the next batch
    time.sleep(0.3)
time.sleep(600)
"""


def test_an_open_bags_metadata_counts_follow_its_chunks(tmp_path: Path) -> None:
    """metadata.yaml of a bag being written is refreshed as its chunks reach
    the file (every METADATA_SECONDS): a writer killed after a few seconds
    leaves counts that rosbags reports and that are those of messages in the
    file (never more than it reads)."""
    from winder.record.bag import METADATA_SECONDS

    bag = tmp_path / "b"
    test = Path(__file__).parent
    script = SLOW_WRITER.format(test=str(test), support=str(test.parent), bag=str(bag))
    p = subprocess.Popen([sys.executable, "-c", script])
    try:

        def counted() -> int:
            text = (bag / "metadata.yaml").read_text() if (bag / "metadata.yaml").exists() else ""
            counts = [int(x.split(":")[1]) for x in text.splitlines() if x.startswith("  message_count:")]
            return counts[0] if counts and counts[0] > 2 else 0

        wait.until(counted, 10 * METADATA_SECONDS, "metadata.yaml counting the bag's chunks", running=p)
    finally:
        p.kill()
        p.wait()
    with AnyReader([bag]) as reader:
        counted_by_metadata = reader.message_count
        read = sum(1 for _ in reader.messages())
    assert 2 < counted_by_metadata <= read
    assert "winder_bag: recording" in (bag / "metadata.yaml").read_text()
