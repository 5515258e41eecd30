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

from winder.contract.stream import StreamChecker, describe_job, parse_job_description, with_source
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


# -- hardening: rows that are single steps but not the job's, and lying job descriptions


@settings(max_examples=300, deadline=None)
@given(jobs_and_chunks(), st.data())
def test_rows_off_the_path_are_refused_and_change_nothing(case, data: st.DataObject) -> None:
    """A chunk whose rows are shifted, negated, out of int32 range or past the
    segment's end is refused as "bad" and leaves the checker where it was: the
    true chunk is still accepted after it, and the stream completes."""
    job, chunks = case
    k = data.draw(st.integers(0, len(chunks) - 1))
    seg, pos = chunks[k]
    segment = job.segments()[seg]
    major = int(np.argmax(np.abs(segment.delta)))
    how = data.draw(st.sampled_from(["shift", "negate", "int32", "past_end", "one_row"]))
    bad = pos.astype(np.int64).copy()
    if how == "shift":  # a whole column moved: still single steps inside the chunk
        bad[:, data.draw(st.integers(0, 2))] += data.draw(st.integers(1, 10**5) | st.integers(-(10**5), -1))
    elif how == "negate":
        bad[:, major] = -bad[:, major]
        if np.array_equal(bad, pos):  # zero stays zero
            return
    elif how == "int32":
        bad[-1, data.draw(st.integers(0, 2))] = 2**31 - 1
        if np.array_equal(bad, pos):
            return
    elif how == "past_end":  # the same shape, moved past the segment's last step
        bad = interpolate(
            segment.start, [2 * d for d in segment.delta], first=segment.steps, stop=segment.steps + 3
        )
    else:  # one row's minor axis off by one
        r = data.draw(st.integers(0, pos.shape[0] - 1))
        minor = [i for i in range(3) if i != major][data.draw(st.integers(0, 1))]
        bad[r, minor] += data.draw(st.sampled_from([-1, 1]))
    # a shift along the path itself gives true rows of other steps: not damage
    k0 = (int(bad[0, major]) - segment.start[major]) * (1 if segment.delta[major] > 0 else -1)
    if 1 <= k0 <= segment.steps - bad.shape[0] + 1 and np.array_equal(
        bad, interpolate(segment.start, segment.delta, first=k0 - 1, stop=k0 - 1 + bad.shape[0])
    ):
        return
    c = checker(job)
    for s, p in chunks[:k]:
        assert c.check(s, p).accept
    before = (c.done, c.missing, c.gaps, c.segment, c.position.tolist())
    v = c.check(seg, bad)
    assert (v.accept, v.kind) == (False, "bad"), (how, v)
    assert v.message and "\n" not in v.message
    assert (c.done, c.missing, c.gaps, c.segment, c.position.tolist()) == before
    for s, p in chunks[k:]:
        assert c.check(s, p).kind == "ok"
    assert c.complete and c.missing == 0 and c.rejected == 1


def _json_values() -> st.SearchStrategy[object]:
    scalars = st.none() | st.booleans() | st.integers(-(2**70), 2**70) | st.floats() | st.text(max_size=8)
    return st.recursive(
        scalars,
        lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
        max_leaves=12,
    )


@settings(max_examples=400, deadline=None)
@given(st.data())
def test_a_damaged_job_description_is_refused_in_one_line(data: st.DataObject) -> None:
    """Any change to a description's structure, or any JSON at all, gives back
    the same job or a one-line ValueError: never another exception, never a
    different job accepted."""
    import json

    job = Job(job_id="d", turns_per_layer=3, layers=2, poles=2, fork_steps_per_rev=16)
    doc = json.loads(describe_job(job))
    how = data.draw(st.sampled_from(["any", "key", "segment", "total"]))
    if how == "any":
        text = json.dumps(data.draw(_json_values()))
    elif how == "key":
        key = data.draw(st.sampled_from(sorted(doc)))
        doc[key] = data.draw(_json_values())
        text = json.dumps(doc)
    elif how == "segment":
        i = data.draw(st.integers(0, len(doc["segments"]) - 1))
        field = data.draw(st.sampled_from(["kind", "start", "delta", "steps", None]))
        if field is None:
            doc["segments"][i] = data.draw(_json_values())
        else:
            doc["segments"][i][field] = data.draw(_json_values())
        text = json.dumps(doc)
    else:  # a job that lies about its size (a consumer would wait for ever)
        doc["total_steps"] = data.draw(st.integers(0, 10**15))
        text = json.dumps(doc)
    try:
        plan = parse_job_description(text)
    except ValueError as exc:
        assert str(exc) and "\n" not in str(exc)
        return
    assert plan.job == job and plan.total_steps == job.total_steps
    assert [(s.start, s.delta, s.steps) for s in plan.segments] == [
        (s.start, s.delta, s.steps) for s in job.segments()
    ]


def test_a_resimulation_names_its_source_and_nothing_else_changes() -> None:
    """winder resim's job description: a new run id and the source; a source
    that is not {bag, run_id} is refused in one line."""
    import json

    job = Job(turns_per_layer=2, poles=2, layers=1)
    text = describe_job(job, run_id="rw400_20261124_101010123_1")
    resim = parse_job_description(with_source(text, "rw400_20261124_111111123_1", "/bags/a"))
    plan = parse_job_description(text)
    assert (resim.source_bag, resim.source_run_id) == ("/bags/a", "rw400_20261124_101010123_1")
    assert resim.run_id == "rw400_20261124_111111123_1" and (plan.source_bag, plan.source_run_id) == ("", "")
    assert resim.segments == plan.segments and resim.total_steps == plan.total_steps
    for bad in ([], {"bag": ""}, {"bag": 3}, {"bag": "x", "run_id": "not a run"}, "x"):
        doc = json.loads(text)
        doc["source"] = bad
        with pytest.raises(ValueError, match="source"):
            parse_job_description(json.dumps(doc))


@settings(max_examples=200, deadline=None)
@given(jobs_and_chunks(), st.data())
def test_a_chunk_continues_the_stream_exactly_when_it_lies_beyond_where_it_stands(
    case, data: st.DataObject
) -> None:
    """After any prefix of the chunks: each later chunk continues the
    stream, each earlier one (a repeat: the same job's next run) does not,
    nor a chunk of another job; asking counts nothing."""
    job, chunks = case
    cut = data.draw(st.integers(0, len(chunks)))
    c = checker(job)
    for seg, pos in chunks[:cut]:
        c.check(seg, pos)

    def rows(seg: int, pos: np.ndarray) -> np.ndarray:
        return np.column_stack([np.full(pos.shape[0], seg), pos])

    columns = ("segment", "feed", "fork", "pole")
    before = (c.done, c.rejected, c.missing, c.gaps)
    for i, (seg, pos) in enumerate(chunks):
        assert c.continues(rows(seg, pos), columns) == (i >= cut), (i, cut)
    other = Job(job_id="o", turns_per_layer=7, layers=1, poles=1, fork_steps_per_rev=1000)
    [far] = other.segments()
    assert not c.continues(rows(len(job.segments()) + 5, interpolate(far.start, far.delta)), columns)
    assert (c.done, c.rejected, c.missing, c.gaps) == before
