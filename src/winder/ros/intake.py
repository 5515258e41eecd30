"""A consumer's step chunks before they are executed: those that come
between runs (:class:`EarlyChunks`) and a run's, checked into rows
(:class:`RowGate`).

Chunks carry no run id, and one writer's are delivered in order. A chunk
that comes while no run is on (its description on its way, or the last run
closing) is kept for the next run, which takes those of its own
(:meth:`EarlyChunks.take`). A run's stream begins with the chunk whose first
row is its first step (:func:`begins_run`): whatever comes before it, with
the run's description here already, is the tail of an earlier run still on
its way (a profile node held up while its consumer closed the run, woken
to send it on), and is dropped, never executed: taken as the new run's, a
chunk of the same job ahead of the new run made its axes jump ahead (a
"gap") and refused the run's own steps as repeats (issue 53). A run's chunks are checked
(:class:`winder.contract.stream.StreamChecker`: gaps, repeats, reordering),
their times too (strictly increasing, within a job's longest duration), and
a step timed before the engine's clock is moved to the clock and counted
(:class:`winder.contract.pacing.LateSteps`). Whatever is refused is said
once through ``error`` and never executed.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from winder.contract.pacing import LateSteps
from winder.contract.stream import TIMED_COLUMNS, JobPlan, StreamChecker
from winder.motion.timing import MAX_JOB_SECONDS
from winder.ros.chunks import TIMED_CDR

__all__ = ["EARLY_CHUNKS", "MAX_STEP_NS", "EarlyChunks", "RowGate", "begins_run"]

#: chunks kept for a run whose description has not come yet, at most
EARLY_CHUNKS = 4096
#: Step times beyond the longest a job may last are refused, not executed.
MAX_STEP_NS = round(MAX_JOB_SECONDS * 1e9)


def begins_run(plan: JobPlan, rows: npt.NDArray[np.int64]) -> bool:
    """Whether a chunk's first row is the run's first step: segment 0, one
    step from the job's start on each axis that moves."""
    if not plan.segments or not rows.shape[0] or rows[0, 1] != 0:
        return False
    first = np.asarray(plan.segments[0].start, np.int64)
    return bool(np.abs(rows[0, 2:] - first).max() == 1)


class EarlyChunks:
    """Chunks that came while no run took them, kept for the next run."""

    def __init__(self, say: Callable[[str], None]) -> None:
        self.say = say  # a warning or a note, in one line
        self.chunks: list[bytes] = []
        self.twin: bytes | None = None
        self.twin_taken = False

    def keep(self, raw: bytes) -> None:
        if len(self.chunks) >= EARLY_CHUNKS:
            self.chunks.pop(0)  # a closed run's stream still coming: the oldest can only be stale
        self.chunks.append(raw)

    def take(self, plan: JobPlan) -> list[bytes]:
        """The new run's chunks among those kept (the rest dropped, said once).
        Those of a run closed early (an abort, a stall, a fault) that were
        still on their way come first; the new run's begin with a chunk whose
        first row is its first step. With no such chunk, all of them."""
        early, self.chunks = self.chunks, []
        start = None
        for i in range(len(early) - 1, -1, -1):
            try:
                rows = TIMED_CDR.decode(early[i])
            except ValueError:
                continue
            if begins_run(plan, rows):
                start = i
                break
        stale = len(early) if start is None else start
        if stale:
            self.say(
                f"run {plan.run_id or plan.job_id}: {stale} step chunks of an earlier run, still on "
                "their way when it closed, dropped"
            )
        fresh = early[stale:]
        # the run's first chunk taken from before its description may be a twin: the
        # last run's of the same job (same steps, same times), closed early here
        self.twin = fresh[0] if fresh else None
        self.twin_taken = False  # the first is that chunk itself (not a twin): it is accepted
        return fresh

    def is_twin(self, raw: bytes) -> bool:
        """Whether ``raw`` is the run's first chunk again, byte for byte, after
        the one taken from before the run's description: that one was the last
        run's twin (a run closed early here, the same job started again at once).
        Executing either is the same; this one is no repeat of the stream."""
        if self.twin is None or raw != self.twin:
            return False
        if not self.twin_taken:
            self.twin_taken = True  # the early chunk itself: accepted as any other
            return False
        self.twin = None
        return True


class RowGate:
    """A run's chunks into the rows that may be executed (see the module doc)."""

    def __init__(
        self, plan: JobPlan, error: Callable[[str], None], note: Callable[[str], None] | None = None
    ) -> None:
        self.checker = StreamChecker(plan)
        self.error = error
        self.note = note or error  # an earlier run's chunks dropped: said once, no error of this run
        #: the run's first step has come (a job of no steps has no stream to wait for)
        self.begun = not plan.segments
        self.stale = 0  #: chunks dropped before it: an earlier run's, still on their way
        self.late = LateSteps()
        self.last_step_ns = -1  # time of the last step accepted, as the stream timed it
        self.last_executed_ns = -1  # the time it is executed at (later if it came late)

    def rows(self, raw: bytes, clock_ns: int | None) -> npt.NDArray[np.int64] | None:
        """The rows of a chunk that may be executed (those timed before the
        engine's clock ``clock_ns`` moved to it), or None (reported)."""
        checker = self.checker
        try:
            rows = TIMED_CDR.decode(raw)
        except ValueError as exc:
            self.error(f"bad step_times chunk: {exc}")
            return None
        if not self.begun:
            if not begins_run(checker.plan, rows):
                self.stale += 1
                if self.stale == 1:
                    self.note(
                        f"run {checker.plan.run_id or checker.plan.job_id}: step chunks that do not begin at "
                        "its first step (an earlier run's, still on their way): dropped until it comes"
                    )
                return None
            self.begun = True
        verdict = checker.check_rows(rows, TIMED_COLUMNS)  # positions tell gaps, repeats, reordering
        if verdict.kind != "ok":
            self.error(verdict.message)
        if not verdict.accept:
            checker.rejected_steps += rows.shape[0]
            return None
        late = int(rows[-1, 0]) > MAX_STEP_NS
        if late or np.any(rows[1:, 0] <= rows[:-1, 0]) or rows[0, 0] <= self.last_step_ns:
            # in sequence by position but not in time: the steps cannot be
            # executed; they count as missing, never silently run
            why = f"later than a job may last ({MAX_JOB_SECONDS:g} s)" if late else "do not increase"
            self.error(f"segment {int(rows[0, 1])}: step times {why}; {rows.shape[0]} steps dropped")
            checker.done -= rows.shape[0]
            checker.missing += rows.shape[0]
            return None
        self.last_step_ns = int(rows[-1, 0])
        timed = rows[:, 0]
        times = self.late.take(timed, clock_ns)
        if times is not timed:
            # behind the engine's clock (it ran past the time they were timed
            # for): executed at the clock, counted; reported once a run
            rows = rows.copy()
            rows[:, 0] = times
        self.last_executed_ns = int(rows[-1, 0])
        return rows
