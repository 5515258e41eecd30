"""Pacing a run's accepted step rows out in real time, ROS-free.

:class:`Pacer` holds the rows accepted and not yet due; at each command tick
the joints' commanded positions are the step counts of the last row due
(``t_ns <= t``) times the joints' step lengths: one ``searchsorted`` over the
held time column, no loop over rows. :class:`CommandHistory` keeps the
positions commanded over the last second or more, so that a measured position
can be compared with what was commanded over the stretch before it was
measured (:func:`following_error`).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["CommandHistory", "Pacer", "following_error"]


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
