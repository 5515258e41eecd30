"""winder.ros.intake, the consumer's chunks before they run: those kept
between runs (EarlyChunks) and a run's, checked into rows (RowGate). The
expected outcomes come from what the test did to a job's chunks (cut here
from the minimum-deviation path, timed here), never from the code."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from winder.contract.stream import describe_job, parse_job_description
from winder.motion.interp import interpolate
from winder.motion.job import Job
from winder.motion.timing import MAX_JOB_SECONDS
from winder.ros.chunks import TIMED_CDR
from winder.ros.intake import EARLY_CHUNKS, EarlyChunks, RowGate


def job_of(turns: int, layers: int, poles: int) -> Job:
    return Job(job_id="i", turns_per_layer=turns, layers=layers, poles=poles, fork_steps_per_rev=7)


def timed_chunks(job: Job, cut: int, dt_ns: int = 1000) -> list[bytes]:
    """The job's stream: every segment cut into chunks of ``cut`` rows, step k at (k + 1) * dt_ns."""
    out, k = [], 0
    for seg in job.segments():
        for a in range(0, seg.steps, cut):
            pos = interpolate(seg.start, seg.delta, first=a, stop=min(a + cut, seg.steps))
            n = pos.shape[0]
            t = (np.arange(k, k + n, dtype=np.int64) + 1) * dt_ns
            rows = np.column_stack([t, np.full(n, seg.index, np.int64), pos.astype(np.int64)])
            out.append(TIMED_CDR.encode(rows))
            k += n
    return out


def plan_of(job: Job):  # type: ignore[no-untyped-def]
    return parse_job_description(describe_job(job))


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 4), st.integers(1, 3), st.integers(2, 40), st.integers(0, 30))
def test_early_chunks_keep_the_new_runs_own_and_drop_the_last_runs_tail(
    turns: int, poles: int, cut: int, stale: int
) -> None:
    """Chunks of a run closed early still on their way, then the new run's:
    the new run takes exactly its own, in order, and the drop is said once."""
    job = job_of(turns, 2, poles)
    mine = timed_chunks(job, cut)
    old = timed_chunks(job, cut, dt_ns=3)[1 : 1 + stale]  # an earlier run's, past its first chunk
    said: list[str] = []
    early = EarlyChunks(said.append)
    for raw in [*old, *mine]:
        early.keep(raw)
    assert early.take(plan_of(job)) == mine
    assert len(said) == (1 if old else 0)
    if old:
        assert f"{len(old)} step chunks of an earlier run" in said[0]
    assert early.take(plan_of(job)) == []  # taken once


def test_early_chunks_are_bounded_and_keep_the_newest() -> None:
    early = EarlyChunks(lambda _s: None)
    for i in range(EARLY_CHUNKS + 5):
        early.keep(i.to_bytes(4, "little"))
    assert len(early.chunks) == EARLY_CHUNKS and early.chunks[0] == (5).to_bytes(4, "little")


def test_the_first_chunk_again_is_a_twin_only_the_second_time() -> None:
    """The early first chunk is accepted; the same bytes once more (the last
    run's twin of the same job) are the one dropped; a third is a repeat for
    the stream checks, no twin."""
    job = job_of(2, 1, 1)
    chunks = timed_chunks(job, 4)
    early = EarlyChunks(lambda _s: None)
    early.keep(chunks[0])
    assert early.take(plan_of(job)) == [chunks[0]]
    assert [early.is_twin(chunks[0]) for _ in range(3)] == [False, True, False]
    assert not early.is_twin(chunks[1])


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 4), st.integers(1, 3), st.integers(1, 30), st.data())
def test_row_gate_passes_a_clean_stream_and_moves_late_steps_to_the_clock(
    turns: int, layers: int, cut: int, data: st.DataObject
) -> None:
    job = job_of(turns, layers, 1)
    chunks = timed_chunks(job, cut)
    gate = RowGate(plan_of(job), lambda why: (_ for _ in ()).throw(AssertionError(why)))
    clock = data.draw(st.none() | st.integers(0, 1000 * job.total_steps))
    got = [gate.rows(raw, clock) for raw in chunks]
    rows = np.concatenate([r for r in got if r is not None])
    want = np.concatenate([TIMED_CDR.decode(raw) for raw in chunks])
    assert rows.shape == want.shape and np.array_equal(rows[:, 1:], want[:, 1:])
    # a step timed before the clock runs at the clock; the rest at their times (a plain loop)
    expect_t = [t if clock is None else max(t, clock) for t in want[:, 0].tolist()]
    assert rows[:, 0].tolist() == expect_t
    late = 0 if clock is None else sum(t < clock for t in want[:, 0].tolist())
    assert gate.late.keys().get("late_steps", "0") == str(late)
    assert gate.checker.complete and gate.checker.missing == 0
    assert gate.last_step_ns == int(want[-1, 0]) and gate.last_executed_ns == expect_t[-1]


def test_row_gate_refuses_times_that_do_not_increase_or_outlast_a_job() -> None:
    job = job_of(3, 1, 1)
    chunks = timed_chunks(job, 5)
    errors: list[str] = []
    gate = RowGate(plan_of(job), errors.append)
    assert gate.rows(chunks[0], None) is not None
    back = TIMED_CDR.decode(chunks[1]).copy()
    back[:, 0] -= 10**6  # before the last accepted step
    assert gate.rows(TIMED_CDR.encode(back), None) is None
    assert errors and "do not increase" in errors[-1] and f"{back.shape[0]} steps dropped" in errors[-1]
    far = TIMED_CDR.decode(chunks[2]).copy()
    far[:, 0] += round(MAX_JOB_SECONDS * 1e9)
    assert gate.rows(TIMED_CDR.encode(far), None) is None
    assert "later than a job may last" in errors[-1]
    assert gate.checker.missing == back.shape[0] + far.shape[0]
    assert gate.rows(b"\x00junk", None) is None and "bad step_times chunk" in errors[-1]
    assert gate.rows(chunks[3], None) is not None  # the stream goes on after them


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 4), st.integers(1, 3), st.integers(2, 40), st.integers(1, 30), st.integers(0, 2))
def test_row_gate_drops_an_earlier_runs_chunks_until_its_own_first_step(
    turns: int, poles: int, cut: int, stale: int, dt_extra: int
) -> None:
    """A run's description here, then chunks of an earlier run of the same job
    still on their way (past its first chunk, the way a woken profile node
    sends on a run its consumer closed), then the run's own stream: exactly
    the run's own rows pass, in order, the stream is clean (no gap, no
    repeat), and the drop is said once as a note, not as an error of the run."""
    job = job_of(turns, 2, poles)
    mine = timed_chunks(job, cut)
    old = timed_chunks(job, cut, dt_ns=1000 + dt_extra)[1 : 1 + stale]
    errors: list[str] = []
    notes: list[str] = []
    gate = RowGate(plan_of(job), errors.append, notes.append)
    got = [gate.rows(raw, None) for raw in [*old, *mine]]
    assert all(r is None for r in got[: len(old)])
    rows = np.concatenate([r for r in got if r is not None])
    assert np.array_equal(rows, np.concatenate([TIMED_CDR.decode(raw) for raw in mine]))
    assert errors == [] and gate.stale == len(old)
    assert len(notes) == (1 if old else 0) and "earlier run" in notes[0]
    assert gate.checker.complete and gate.checker.missing == 0 and gate.checker.gaps == 0
