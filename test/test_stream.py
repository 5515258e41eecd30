"""StreamChecker, the step stream's integrity check in the profile and sim
nodes, against what was done to a job's chunks: each chunk cut from the
minimum-deviation path here (as the interp node cuts them), then dropped,
repeated, swapped or damaged. The expected verdicts and counts come from
those operations, not from the checker."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from winder.contract.stream import StreamChecker, describe_job, parse_job_description
from winder.motion.interp import interpolate
from winder.motion.job import Job


@st.composite
def jobs_and_chunks(draw: st.DrawFn) -> tuple[Job, list[tuple[int, np.ndarray]]]:
    job = Job(
        job_id="s",
        turns_per_layer=draw(st.integers(1, 6)),
        layers=draw(st.integers(1, 3)),
        poles=draw(st.integers(1, 3)),
        fork_steps_per_rev=draw(st.sampled_from([4, 7, 64])),
        feed_step=draw(st.sampled_from([1e-5, 2.5e-4, 1e-3])),
    )
    chunks = []
    for seg in job.segments():
        cuts = sorted(set(draw(st.lists(st.integers(1, max(seg.steps - 1, 1)), max_size=4))))
        edges = [0, *[c for c in cuts if c < seg.steps], seg.steps]
        for a, b in itertools.pairwise(edges):
            chunks.append((seg.index, interpolate(seg.start, seg.delta, first=a, stop=b)))
    return job, chunks


def checker(job: Job) -> StreamChecker:
    return StreamChecker(parse_job_description(describe_job(job)))


@settings(max_examples=200, deadline=None)
@given(jobs_and_chunks())
def test_clean_stream_is_accepted_whole(case) -> None:
    job, chunks = case
    c = checker(job)
    for seg, pos in chunks:
        v = c.check(seg, pos)
        assert (v.accept, v.kind) == (True, "ok"), v.message
    assert c.done == job.total_steps and c.missing == 0 and c.gaps == 0 and c.complete


@settings(max_examples=200, deadline=None)
@given(jobs_and_chunks(), st.data())
def test_dropped_chunk_is_one_gap_of_its_size(case, data: st.DataObject) -> None:
    job, chunks = case
    if len(chunks) < 2:
        return
    drop = data.draw(st.integers(0, len(chunks) - 2))  # the last one would only end the stream early
    c = checker(job)
    kinds = [c.check(seg, pos).kind for i, (seg, pos) in enumerate(chunks) if i != drop]
    assert kinds.count("gap") == 1 and kinds.count("ok") == len(chunks) - 2
    assert c.missing == chunks[drop][1].shape[0] and c.gaps == 1
    assert c.done == job.total_steps - c.missing and c.complete


@settings(max_examples=200, deadline=None)
@given(jobs_and_chunks(), st.data())
def test_repeated_and_swapped_chunks_are_refused(case, data: st.DataObject) -> None:
    job, chunks = case
    i = data.draw(st.integers(0, len(chunks) - 1))
    c = checker(job)
    for seg, pos in chunks[: i + 1]:
        c.check(seg, pos)
    v = c.check(*chunks[i])  # the same chunk again
    assert (v.accept, v.kind) == (False, "duplicate")
    if i + 2 < len(chunks):  # the next two in the wrong order: a gap, then a late chunk
        g = c.check(*chunks[i + 2])
        assert (g.accept, g.kind, g.missing) == (True, "gap", chunks[i + 1][1].shape[0])
        late = c.check(*chunks[i + 1])
        assert (late.accept, late.kind) == (False, "reorder")
    assert c.rejected == (2 if i + 2 < len(chunks) else 1)


@settings(max_examples=300, deadline=None)
@given(jobs_and_chunks(), st.data())
def test_damaged_rows_inside_a_chunk_are_refused(case, data: st.DataObject) -> None:
    job, chunks = case
    long = [k for k, (_, pos) in enumerate(chunks) if pos.shape[0] >= 3]
    if not long:
        return
    k = data.draw(st.sampled_from(long))
    seg, pos = chunks[k]
    bad = pos.copy()
    how = data.draw(st.sampled_from(["skip", "repeat", "jump", "reverse", "back"]))
    r = data.draw(st.integers(1, pos.shape[0] - 2))
    if how == "skip":  # a row lost inside the chunk
        bad = np.delete(bad, r, axis=0)
    elif how == "repeat":  # a row twice
        bad = np.insert(bad, r, bad[r], axis=0)
    elif how == "jump":  # one axis moves by two or more (+3 on a step of -1, 0 or +1)
        bad[r:, data.draw(st.integers(0, 2))] += 3
    elif how == "reverse":
        bad = bad[::-1].copy()
    else:  # a row that steps back
        bad[r] = bad[r - 1]
        bad[r, int(np.argmax(np.abs(job.segments()[seg].delta)))] -= int(
            np.sign(job.segments()[seg].delta[int(np.argmax(np.abs(job.segments()[seg].delta)))])
        )
    c = checker(job)
    for s, p in chunks[:k]:
        c.check(s, p)
    v = c.check(seg, bad)
    assert not v.accept, (how, v)
    assert v.kind in ("bad", "reorder", "duplicate")


def test_bad_segment_and_empty_chunk() -> None:
    job = Job(job_id="s", turns_per_layer=1, layers=1, poles=1, fork_steps_per_rev=8)
    c = checker(job)
    assert c.check(5, np.zeros((1, 3), np.int64)).message == "segment 5 out of range 0..0"
    assert c.check(0, np.zeros((0, 3), np.int64)).message == "empty chunk"
    with pytest.raises(AssertionError):
        assert c.check(0, np.zeros((2, 3), np.int64)).accept
