"""Damaged recordings: random byte flips and truncations of a real bag, written
by the sim node's own writer in every compression mode. The contract: the
reader either refuses the file in one line or returns only messages that were
written, byte for byte; whenever a message is missing, the result says so
(damaged chunks named, or the file marked cut short); `winder analyze` never
shows a traceback and flags what it could not read. A damaged value never
reaches a figure."""

from __future__ import annotations

import random
import shutil
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from support.bags import rewrite
from support.cli import run_cli

from winder.record.bag import COMPRESSIONS, BagRecorder
from winder.record.raw import BagError, RawBag, read_raw
from winder.record.reader import read_run

pytestmark = pytest.mark.ros  # the bags come from real runs of the three nodes

FLIPS = 60  # per compression mode
CUTS = 20


def messages(raw: RawBag) -> Counter[tuple[str, int, bytes]]:
    return Counter((raw.connections[cid].topic, t, bytes(d)) for cid, t, d in raw.messages)


def check(path: Path, original: Counter[tuple[str, int, bytes]]) -> str:
    """Read a damaged bag; return what happened: refused, whole, or flagged."""
    try:
        raw = read_raw(path)
    except BagError as exc:
        assert str(exc) and "\n" not in str(exc)
        return "refused"
    got = messages(raw)
    assert not got - original, f"{path}: {sum((got - original).values())} messages that were never written"
    if got == original:
        return "whole"
    assert raw.damaged or raw.recovered or not raw.closed, f"{path}: messages missing, nothing flagged"
    return "flagged"


@pytest.mark.parametrize("compression", COMPRESSIONS)
def test_flipped_bytes_and_truncations_never_pass_as_good(
    bag: Any,
    tmp_path: Path,
    compression: str,
) -> None:
    source = read_raw(bag("lin2k"))
    clean = rewrite(source, tmp_path / "clean", compression)
    original = messages(read_raw(clean))
    assert original == messages(source)  # the rewrite itself is faithful
    mcap = next(clean.glob("*.mcap"))
    data = mcap.read_bytes()
    rng = random.Random(f"winder-{compression}")
    outcomes: Counter[str] = Counter()
    for i in range(FLIPS + CUTS):
        case = tmp_path / f"case{i}"
        shutil.copytree(clean, case)
        damaged = bytearray(data)
        if i < FLIPS:
            at = rng.randrange(8, len(damaged) - 8)  # past the magic: that case is refused outright
            damaged[at] ^= 1 << rng.randrange(8)
        else:
            damaged = damaged[: rng.randrange(8, len(damaged))]
        (case / mcap.name).write_bytes(bytes(damaged))
        outcomes[check(case, original)] += 1
        shutil.rmtree(case)
    # byte flips inside the chunks are the most likely: they must be found
    assert outcomes["flagged"] + outcomes["refused"] >= CUTS, outcomes


def test_a_flipped_byte_in_a_chunk_is_named_and_the_rest_read(bag: Any, tmp_path: Path) -> None:
    """One flip in the middle of a compressed chunk: that chunk is skipped and
    named; the chunks after it are read; `winder analyze` says DAMAGED."""
    clean = rewrite(read_raw(bag("lin2k")), tmp_path / "clean", "lz4")
    original = messages(read_raw(clean))
    mcap = next(clean.glob("*.mcap"))
    data = bytearray(mcap.read_bytes())
    chunks = []  # (position, length) of the chunk records, walking the file by record lengths
    pos = 8
    while data[pos] != 0x0F:  # up to DataEnd
        length = int.from_bytes(data[pos + 1 : pos + 9], "little")
        if data[pos] == 0x06:
            chunks.append((pos, length))
        pos += 9 + length
    assert len(chunks) >= 3
    first, length = chunks[1]  # a chunk in the middle
    data[first + 9 + length // 2] ^= 0x10
    mcap.write_bytes(bytes(data))
    raw = read_raw(clean)
    assert raw.damaged and "skipped" in raw.damaged[0] and str(first) in raw.damaged[0]
    got = messages(raw)
    assert got and not got - original and got != original
    r = run_cli("analyze", str(clean), "--no-plots")
    assert "Traceback" not in r.stderr
    assert "DAMAGED" in r.stdout and "chunk(s) skipped" in r.stdout


def test_a_file_that_only_starts_like_mcap_fails_fast(tmp_path: Path) -> None:
    """300 MB of noise behind the MCAP magic: refused in one line (the reader
    walks records by their lengths; it does not scan the noise)."""
    junk = tmp_path / "junk"
    junk.mkdir()
    rng = random.Random(7)
    with (junk / "junk.mcap").open("wb") as f:
        f.write(b"\x89MCAP0\r\n")
        block = rng.randbytes(1 << 20)
        for _ in range(300):
            f.write(block)
    with pytest.raises(BagError) as err:
        read_raw(junk)
    assert "\n" not in str(err.value)


def chunk_spans(data: bytes) -> list[tuple[int, int]]:
    """(start, end) of each chunk record, walking the file by record lengths up to DataEnd."""
    spans, pos = [], 8
    while data[pos] != 0x0F:
        end = pos + 9 + int.from_bytes(data[pos + 1 : pos + 9], "little")
        if data[pos] == 0x06:
            spans.append((pos, end))
        pos = end
    return spans


def recover_says(path: Path, *args: str) -> str:
    r = run_cli("bag", "recover", str(path), *args)
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stdout + r.stderr
    assert "complete (" not in r.stdout  # the old wording, whatever was missing
    return r.stdout


def test_recover_never_calls_a_damaged_bag_complete(bag: Any, tmp_path: Path) -> None:
    """`winder bag recover` says what it saved and that it is incomplete, for a
    truncated file, a cut last chunk, a damaged chunk and a whole file without
    the run's final report; only a whole bag with its report is left alone."""
    src = bag("lin2k")
    whole = recover_says(src)
    assert "the file is whole" in whole and "final report: done" in whole and "nothing to recover" in whole
    total = read_run(src).plan.total_steps
    mcap = next(src.glob("*.mcap"))
    data = mcap.read_bytes()
    spans = chunk_spans(data)
    cuts = {
        "truncated": len(data) * 2 // 3,
        "last chunk cut": (spans[-1][0] + spans[-1][1]) // 2,  # the final report is in it
    }
    for what, cut in cuts.items():
        d = tmp_path / what.replace(" ", "_")
        d.mkdir()
        shutil.copy(src / "metadata.yaml", d)
        (d / mcap.name).write_bytes(data[:cut])
        said = recover_says(d)
        assert "recovered " in said and "into " in said, what
        last = said.strip().splitlines()[-1]
        assert last.startswith("incomplete: the file was cut short"), (what, said)
        assert "no final report" in last and f" of {total} steps recorded" in last, (what, said)
        # the recovered bag is whole, but still not the whole run
        again = recover_says(d.with_name(d.name + "_recovered"))
        assert again.startswith(f"{d}_recovered: incomplete: the file is whole"), again
        assert "no final report" in again and "nothing more to recover" in again
    flipped = tmp_path / "flipped"
    shutil.copytree(src, flipped)
    broken = bytearray(data)
    start, end = spans[len(spans) // 2]
    broken[(start + end) // 2] ^= 0x10
    (flipped / mcap.name).write_bytes(bytes(broken))
    said = recover_says(flipped)
    assert f"damaged: chunk at byte {start} skipped" in said, said
    assert "incomplete: 1 damaged chunk(s) skipped" in said, said
    # closed, undamaged, and no final report: the consumer's statuses never recorded
    raw = read_raw(src)
    silent = tmp_path / "no_report"
    rec = BagRecorder(silent, {c.topic: c.msgtype for c in raw.connections.values()}, compression="none")
    for cid, t, payload in raw.messages:
        if raw.connections[cid].topic != "/diagnostics":
            rec.write(raw.connections[cid].topic, t, payload, exact=True)
    rec.close()
    said = recover_says(silent)
    assert said.startswith(f"{silent}: incomplete: the file is whole") and "no final report" in said, said
    assert not (tmp_path / "no_report_recovered").exists()


def refusal(call: Any) -> str | None:
    try:
        call()
    except BagError as exc:
        return str(exc)
    return None


def test_play_refuses_what_analyze_refuses(bag: Any, tmp_path: Path) -> None:
    """Every damaged bag `winder analyze` refuses, `winder play` refuses with
    the same line (it refuses more: a gap it cannot replay); a foreign bag, a
    job description that is not one and a step chunk of the wrong shape are
    refused by both commands in the same one line, exit 2, no traceback."""
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.typesys import Stores, get_typestore
    from support.bags import write_bag
    from support.cli import assert_one_line_error

    from winder.record.replay import plan_play

    clean = rewrite(read_raw(bag("lin2k")), tmp_path / "clean", "none")
    mcap = next(clean.glob("*.mcap"))
    data = mcap.read_bytes()
    rng = random.Random("winder-play")
    same = 0
    for i in range(FLIPS + CUTS):
        case = tmp_path / f"case{i}"
        shutil.copytree(clean, case)
        damaged = bytearray(data)
        if i < FLIPS:
            damaged[rng.randrange(8, len(damaged) - 8)] ^= 1 << rng.randrange(8)
        else:
            damaged = damaged[: rng.randrange(8, len(damaged))]
        (case / mcap.name).write_bytes(bytes(damaged))
        analyzed = refusal(lambda case=case: read_run(case))
        played = refusal(lambda case=case: plan_play(case))
        if analyzed is not None:
            assert played == analyzed, (i, analyzed, played)
            same += 1
        shutil.rmtree(case)
    store = get_typestore(Stores.ROS2_JAZZY)
    String = store.types["std_msgs/msg/String"]
    Ints = store.types["std_msgs/msg/Int64MultiArray"]
    job = read_run(clean).plan.text
    foreign = tmp_path / "foreign"
    write_bag(foreign, [("/chatter", "std_msgs/msg/String", 1, String(data="hi"))], StoragePlugin.MCAP)
    bad_job = tmp_path / "bad_job"
    not_json = String(data="{not json")
    write_bag(bad_job, [("/winder/job", "std_msgs/msg/String", 1, not_json)], StoragePlugin.MCAP)
    bad_chunk = tmp_path / "bad_chunk"
    no_layout = store.types["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0)
    chunk = Ints(layout=no_layout, data=np.arange(7))
    write_bag(
        bad_chunk,
        [("/winder/job", "std_msgs/msg/String", 1, String(data=job)),
         ("/winder/step_times", "std_msgs/msg/Int64MultiArray", 2, chunk)],
        StoragePlugin.MCAP,
    )  # fmt: skip
    for path, needles in [
        (foreign, [str(foreign), "not a winder bag"]),
        (bad_job, [str(bad_job), "/winder/job"]),
        (bad_chunk, ["/winder/step_times", "chunk layout"]),  # (analyze's line does not name the bag)
    ]:
        a = run_cli("analyze", str(path), "--no-plots")
        assert_one_line_error(a, *needles)
        p = run_cli("play", str(path))
        assert_one_line_error(p, *needles)
        assert p.stderr == a.stderr.replace("winder analyze", "winder play"), (a.stderr, p.stderr)
    print(f"{same} damaged bags refused by analyze, each by play in the same words")
