"""Pacing a run's accepted step rows out in real time, ROS-free.

:class:`Pacer` holds the rows accepted and not yet due; at each command tick
the joints' commanded positions are the step counts of the last row due
(``t_ns <= t``) times the joints' step lengths: one ``searchsorted`` over the
held time column, no loop over rows. :class:`CommandHistory` keeps the
positions commanded over the last second or more, so that a measured position
can be compared with what was commanded over the stretch before it was
measured (:func:`following_error`). :class:`LateSteps` books the steps that
come behind a consumer's clock: they go at the clock (a drive cannot go back
in time), counted, never refused (:func:`at_clock`).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

__all__ = ["CommandHistory", "LateSteps", "Pacer", "at_clock", "following_error", "ns_not_before"]


class Pacer:
    """The rows of one run waiting for their time.

    ``columns``: for each joint, the row column of the axis it drives (rows
    are ``[t_ns, segment, feed, fork, pole]``); ``start``: the axes' step
    positions before the first row (in those columns' order); ``step_len``:
    each joint's travel per step (m or rad). The commanded position is
    :attr:`offset` (0 unless set: the job's origin) + step count * step length."""

    def __init__(
        self,
        columns: list[int],
        start: npt.NDArray[np.int64],
        step_len: npt.NDArray[np.float64],
        capacity: int = 4096,
    ) -> None:
        self.columns = np.asarray(columns, np.int64)
        self.step_len = np.asarray(step_len, np.float64)
        self.t = np.empty(capacity, np.int64)
        self.steps = np.empty((capacity, self.columns.size), np.int64)
        self.lo = 0  # first held row (not due yet)
        self.hi = 0  # end of the held rows
        self.counts = np.asarray(start, np.int64).copy()  # step counts in force
        self.offset = np.zeros(self.columns.size)  # joint position of step 0 (m, rad)
        self.position = self.counts * self.step_len  # commanded positions in force (m, rad)
        self.due = 0  # rows that fell due and were not taken by take_due() yet

    @property
    def held(self) -> int:
        """Rows accepted, not due yet."""
        return self.hi - self.lo

    def add(self, rows: npt.NDArray[np.int64]) -> None:
        """Accepted rows, after those held (their times increase)."""
        n = rows.shape[0]
        if self.hi + n > self.t.size:  # the rows already due make room (memory: the held rows)
            keep = self.hi - self.lo
            if keep + n <= self.t.size:
                t, steps = self.t, self.steps  # numpy copies overlapping slices correctly
            else:
                size = 2 * (keep + n)
                t, steps = np.empty(size, np.int64), np.empty((size, self.columns.size), np.int64)
            t[:keep], steps[:keep] = self.t[self.lo : self.hi], self.steps[self.lo : self.hi]
            self.t, self.steps, self.lo, self.hi = t, steps, 0, keep
        self.t[self.hi : self.hi + n] = rows[:, 0]
        self.steps[self.hi : self.hi + n] = rows[:, self.columns]
        self.hi += n

    def advance(self, t_ns: int) -> bool:
        """Execution reaches ``t_ns``: the rows at or before it fall due and
        the last of them sets the positions. True if any fell due."""
        if self.lo == self.hi or self.t[self.lo] > t_ns:
            return False
        j = self.lo + int(np.searchsorted(self.t[self.lo : self.hi], t_ns, side="right"))
        self.counts[:] = self.steps[j - 1]
        np.multiply(self.counts, self.step_len, out=self.position)
        self.position += self.offset  # + 0.0 leaves the product exact
        self.due += j - self.lo
        self.lo = j
        return True

    def advance_grid(self, times: npt.NDArray[np.int64]) -> npt.NDArray[np.float64]:
        """:meth:`advance` to each of the increasing ``times`` in turn: the
        positions in force at each, (len(times), joints); the rows fall due
        as with one advance to the last."""
        held = self.t[self.lo : self.hi]
        due = np.searchsorted(held, times, side="right")  # held rows due by each time
        counts = np.where((due > 0)[:, None], self.steps[self.lo + np.maximum(due, 1) - 1], self.counts)
        out: npt.NDArray[np.float64] = counts * self.step_len
        out += self.offset
        if times.size:
            self.advance(int(times[-1]))
        return out

    def set_origin(self, at_start: npt.NDArray[np.float64]) -> None:
        """Step 0 of the job lies where the start counts put the joints at ``at_start``."""
        self.offset = np.asarray(at_start, np.float64) - self.counts * self.step_len
        self.position[:] = at_start

    def take_due(self) -> int:
        """Rows that fell due since the last call."""
        n, self.due = self.due, 0
        return n


class CommandHistory:
    """The positions commanded over the last ``size`` changes (at 1 kHz, a
    second at least), each with the (system clock) time it went out; before
    the first, the initial position is in force."""

    def __init__(self, initial: npt.NDArray[np.float64], size: int = 1024) -> None:
        self.size = size
        self.t = np.empty(2 * size, np.int64)
        self.pos = np.empty((2 * size, initial.size), np.float64)
        self.t[0] = np.iinfo(np.int64).min  # in force before the first command
        self.pos[0] = initial
        self.n = 1

    def push(self, t_ns: int, position: npt.NDArray[np.float64]) -> None:
        if self.n == self.t.size:  # keep the newest half, in order
            self.t[: self.size] = self.t[self.size :]
            self.pos[: self.size] = self.pos[self.size :]
            self.n = self.size
        self.t[self.n] = t_ns
        self.pos[self.n] = position
        self.n += 1

    def push_many(self, t_ns: npt.NDArray[np.int64], positions: npt.NDArray[np.float64]) -> None:
        """:meth:`push` of each row of ``positions`` at ``t_ns`` (increasing)."""
        for i in range(0, t_ns.size, self.size):  # never more than the newest half at once
            n = min(self.size, t_ns.size - i)
            if self.n + n > self.t.size:
                keep = self.size - n  # the newest entries that stay beside the new ones
                self.t[:keep] = self.t[self.n - keep : self.n]
                self.pos[:keep] = self.pos[self.n - keep : self.n]
                self.n = keep
            self.t[self.n : self.n + n] = t_ns[i : i + n]
            self.pos[self.n : self.n + n] = positions[i : i + n]
            self.n += n

    def span(self, t_from: int, t_to: int) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """The least and greatest position of each joint commanded in force
        at some instant of ``[t_from, t_to]`` (ns)."""
        t = self.t[: self.n]
        a = max(int(np.searchsorted(t, t_from, side="right")) - 1, 0)
        b = max(int(np.searchsorted(t, t_to, side="right")), a + 1)
        block = self.pos[a:b]
        return block.min(axis=0), block.max(axis=0)


def following_error(
    low: npt.NDArray[np.float64], high: npt.NDArray[np.float64], measured: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """The following error (commanded minus measured) of each joint against
    the span ``[low, high]`` it was commanded over: 0 inside it, positive
    below it (lagging a move up), negative above it."""
    out: npt.NDArray[np.float64] = np.where(
        measured < low, low - measured, np.where(measured > high, high - measured, 0.0)
    )
    return out


def ns_not_before(t_s: float) -> int:
    """The first whole ns not before ``t_s`` (s) as a consumer compares it:
    ``ns / 1e9 >= t_s`` in floating point (a clock in s, as step times in ns)."""
    ns = math.ceil(t_s * 1e9)
    while ns / 1e9 < t_s:
        ns += 1
    while (ns - 1) / 1e9 >= t_s:
        ns -= 1
    return ns


def at_clock(t_ns: npt.NDArray[np.int64], clock_ns: int) -> tuple[npt.NDArray[np.int64], int, int]:
    """When steps timed ``t_ns`` (non-decreasing, ns) go on a consumer whose
    clock stands at ``clock_ns``: each step timed before the clock goes at the
    clock, the others at their time. (times, how many were behind, how far
    the first of them was behind in ns); ``t_ns`` itself when none was."""
    n = int(np.searchsorted(t_ns, clock_ns, side="left"))  # the steps strictly before the clock
    if n == 0:
        return t_ns, 0, 0
    out = t_ns.copy()
    out[:n] = clock_ns
    return out, n, clock_ns - int(t_ns[0])


class LateSteps:
    """The steps of a run that came behind the consumer's clock (in a
    real-time run, steps timed for a moment its clock had already passed):
    each is executed at the clock (:func:`at_clock`) and counted here, with
    how far behind one came at most. They are reported once a run
    (:meth:`report`), when they stopped coming, with the numbers."""

    def __init__(self) -> None:
        self.count = 0
        self.behind_max_ns = 0
        self.behind = False  # the last step taken came late: more may follow
        self.reported = False  # the run's one report of them is out

    def take(self, t_ns: npt.NDArray[np.int64], clock_ns: int | None) -> npt.NDArray[np.int64]:
        """The times steps timed ``t_ns`` (non-decreasing) are executed at,
        the clock at ``clock_ns`` (None: the consumer takes any time); the late
        ones counted."""
        if clock_ns is None or t_ns.size == 0:
            self.behind = False
            return t_ns
        out, n, behind = at_clock(t_ns, clock_ns)
        self.behind = n == t_ns.size
        if n:
            self.count += n
            self.behind_max_ns = max(self.behind_max_ns, behind)
        return out

    @property
    def behind_max_ms(self) -> float:
        return self.behind_max_ns / 1e6

    def text(self) -> str:
        """The run's late steps in one line."""
        return (
            f"late steps: {self.count} steps came behind the clock, up to {self.behind_max_ms:.3f} ms "
            "behind; executed at the clock, not at their time"
        )

    def report(self, *, closing: bool = False) -> str:
        """The run's one report of its late steps (:meth:`text`): once a step
        came on time after them, or when the run closes; "" before that, and
        after the report."""
        if not self.count or self.reported or (self.behind and not closing):
            return ""
        self.reported = True
        return self.text()

    def keys(self) -> dict[str, str]:
        """The job report's keys: ``late_steps`` and ``late_steps_behind_max_ms``, if any came."""
        if not self.count:
            return {}
        return {"late_steps": str(self.count), "late_steps_behind_max_ms": f"{self.behind_max_ms:.3f}"}
