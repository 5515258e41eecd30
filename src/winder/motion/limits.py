"""Axis limits: how fast and how hard a job drives each axis, and a watch
on the timed steps that stops a run before they would pass a limit (ROS-free).

A job's axes move along straight pieces in step space: within a piece each
axis is a fixed ratio ``r`` (its steps per step of the segment's major axis)
of the path, whose velocity and acceleration are the ramp's (steps/s of the
major axis; with a feed override ``k``, ``k`` and ``k**2`` times them). So an
axis' velocity is ``|r| * v`` and its acceleration ``|r| * a``, times its step
length, except where the ratio or the velocity jumps: at the corners of a
cam-laid layer and where a move starts or ends at the ramp's start speed
``v_start`` (a stepper's start/stop rate). A jump has no finite
acceleration, and the commands that carry it show it over whatever span one
measures; winder measures every axis over :data:`WINDOW_NS` (20 ms, the span
a drive's command filter smooths over), where a jump ``dv`` counts as
``dv / 20 ms``.

:func:`job_peaks` gives each axis' peaks from a job's plan, before a step is
timed (``winder check --limits``, the bridge when it arms a run): the peak
velocity is exact for a straight move and a bound for a cam-laid one (the
path's peak times the steepest piece's ratio, reached by any layer that
cruises over a turn); the acceleration is the path's peak times the ratio,
plus the largest jump over 20 ms. :class:`LimitWatch` measures the timed
steps themselves as the bridge takes them (ahead of their time, by the
profile node's look-ahead): the mean velocity over the last 20 ms before
each step, and its change from the 20 ms before, allowing for the steps
being whole (a position off the ideal line by at most 1.5 steps). A job that
:func:`job_peaks` passes never trips the watch.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from winder.motion.axes import AXES, AXIS_TABLE, FORK
from winder.motion.job import Job, Segment
from winder.motion.shaped import Motion, ShapedProfile
from winder.motion.timeline import parse_schedule
from winder.motion.timing import SegmentTiming, plan_job_timing

__all__ = [
    "NO_LIMIT",
    "WINDOW_NS",
    "AxisPeaks",
    "Breach",
    "LimitWatch",
    "Past",
    "TimedJob",
    "breach",
    "highest_override",
    "job_extent",
    "job_limits",
    "job_peaks",
    "move_peaks",
    "time_job",
    "travel_past",
]

#: a limit this large is none (the default of every limit parameter of the bridge)
NO_LIMIT = 1e9

#: velocity and acceleration are measured over this span (ns)
WINDOW_NS = 20_000_000
WINDOW_S = WINDOW_NS / 1e9
#: a whole-step position is off the ideal line by at most this many steps
#: (half a step of Bresenham rounding, and a step of the major axis' progress
#: since the last step); a windowed velocity by twice it over the window, an
#: acceleration by four times it over the window squared
QUANTUM = 1.5


class _Segment(Protocol):
    @property
    def start(self) -> tuple[int, ...]: ...
    @property
    def delta(self) -> tuple[int, ...]: ...
    @property
    def pieces(self) -> tuple[tuple[int, ...], ...]: ...
    @property
    def steps(self) -> int: ...


class _Timing(Protocol):
    @property
    def profiles(self) -> tuple[Motion, ...]: ...


@dataclass(frozen=True)
class AxisPeaks:
    """The most a job asks of one axis (joint units: m or rad)."""

    velocity: float  #: peak |velocity|, per s
    acceleration: float  #: peak |acceleration| along the pieces, per s^2
    jump: float  #: the largest velocity jump (a corner, a start or a stop at v_start), per s

    @property
    def windowed_acceleration(self) -> float:
        """The acceleration over :data:`WINDOW_NS`: the path's, and a jump over the window."""
        return self.acceleration + self.jump / WINDOW_S


def job_extent(segments: Sequence[_Segment], axes: int = len(AXES)) -> tuple[npt.NDArray[np.int64], ...]:
    """The least and greatest step count each axis reaches (AXES order): the
    extremes of the segments' corners (each piece is straight between them)."""
    lo, hi = np.zeros(axes, np.int64), np.zeros(axes, np.int64)
    for i, seg in enumerate(segments):
        corners = np.asarray(seg.start, np.int64) + np.cumsum(
            np.array([[0] * axes, *(seg.pieces or (seg.delta,))], np.int64), axis=0
        )
        if i == 0:
            lo, hi = corners.min(axis=0), corners.max(axis=0)
        else:
            lo, hi = np.minimum(lo, corners.min(axis=0)), np.maximum(hi, corners.max(axis=0))
    return lo, hi


@dataclass(frozen=True)
class Past:
    """A travel past a soft limit: the axis' (or joint's) index, the side
    (``min``, ``max``), where the travel goes and the limit (m or rad)."""

    index: int
    side: str
    at: float
    limit: float


def travel_past(
    lo: npt.ArrayLike, hi: npt.ArrayLike, lows: npt.ArrayLike, highs: npt.ArrayLike
) -> Past | None:
    """The first axis whose travel ``lo``..``hi`` leaves its range
    ``lows``..``highs`` (``min_position``, ``max_position``); None if none does."""
    arrays = (np.asarray(x, np.float64) for x in (lo, hi, lows, highs))
    for j, (a, b, low, high) in enumerate(zip(*arrays, strict=True)):
        if a < low:
            return Past(j, "min", float(a), float(low))
        if b > high:
            return Past(j, "max", float(b), float(high))
    return None


def move_peaks(motion: Motion) -> tuple[float, float]:
    """Peak |velocity| and |acceleration| of one move (steps/s, steps/s^2)."""
    shaped = motion if isinstance(motion, ShapedProfile) else ShapedProfile(motion, [1.0], [0.0])
    peaks = shaped.peaks
    return peaks["v"], peaks["a"]


def window_change(
    lengths: npt.NDArray[np.float64], ratios: npt.NDArray[np.float64], reach: float
) -> npt.NDArray[np.float64]:
    """The largest change of each axis' ratio (its steps per major step)
    between two points of a cam ``reach`` major steps apart: a window of
    that length from piece ``i`` (of ``lengths`` major steps) to piece ``j``
    exists where ``a_j - b_i < reach < b_j - a_i`` (``a``, ``b``: the
    pieces' starts and ends). A straight move's is 0; a cam's crossover at
    once (reach beyond its pieces, or a linear one) its whole rise; a cam
    law spread over many pieces less, the more pieces the window cannot span."""
    n = lengths.size
    out = np.zeros(ratios.shape[1] if ratios.ndim == 2 else 0)
    if n < 2:
        return out
    b = np.cumsum(lengths)
    a = b - lengths
    lo = np.searchsorted(b, a + reach, side="right")  # the first piece a window from piece i can end in
    hi = np.searchsorted(a, b + reach, side="left") - 1  # the last
    for d in range(int(np.max(hi - lo, initial=-1)) + 1):
        j = lo + d
        ok = (j <= hi) & (j < n)
        if ok.any():
            out = np.maximum(out, np.abs(ratios[j[ok]] - ratios[ok]).max(axis=0))
    return out


def job_peaks(
    segments: Sequence[_Segment],
    timings: Sequence[_Timing],
    joint_step: Sequence[float],
    override: float = 1.0,
) -> list[AxisPeaks]:
    """Each axis' peaks (the order of ``joint_step``: the cell's AXES) for a
    job's ``segments`` timed by ``timings`` (:func:`winder.motion.timing.plan_timing`),
    at feed override ``override``."""
    n = len(joint_step)
    vel, acc, jump = np.zeros(n), np.zeros(n), np.zeros(n)
    moves: dict[int, tuple[float, float, float]] = {}
    # a job of 10^5 layers has a few kinds of layer: each kind worked out once
    done: set[tuple[tuple[tuple[int, ...], ...], tuple[int, ...]]] = set()
    for seg, timing in zip(segments, timings, strict=True):
        key = (seg.pieces, tuple(id(m) for m in timing.profiles))
        if seg.steps == 0 or key in done:
            continue
        done.add(key)
        v_peak = a_peak = v_rest = 0.0
        for move in timing.profiles:
            got = moves.get(id(move))
            if got is None:
                v, a = move_peaks(move)
                got = moves[id(move)] = (v, a, max(move.v_start, move.v_end))
            v_peak, a_peak, v_rest = max(v_peak, got[0]), max(a_peak, got[1]), max(v_rest, got[2])
        ratios = np.array(
            [[d / max(abs(x) for x in piece) for d in piece] for piece in seg.pieces if any(piece)]
        )
        steepest = np.abs(ratios).max(axis=0)
        vel = np.maximum(vel, steepest * v_peak)
        acc = np.maximum(acc, steepest * a_peak)
        lengths = np.array([max(abs(x) for x in piece) for piece in seg.pieces if any(piece)], float)
        corner = window_change(lengths, ratios, v_peak * override * WINDOW_S) * v_peak  # 0: straight
        jump = np.maximum(jump, np.maximum(corner, steepest * v_rest))
    step = np.abs(np.asarray(joint_step, dtype=np.float64))
    k = float(override)
    return [
        AxisPeaks(float(v * s * k), float(a * s * k * k), float(j * s * k))
        for v, a, j, s in zip(vel, acc, jump, step, strict=True)
    ]


def _apart(value: float, limit: float) -> tuple[str, str]:
    """``value`` and ``limit`` in words, with the digits that tell them apart
    (12.56637 past 12.56637061 read "12.5664 beyond 12.5664" at 6 digits)."""
    for digits in (6, 9, 12, 17):
        a, b = f"{value:.{digits}g}", f"{limit:.{digits}g}"
        if a != b:
            return a, b
    return a, b


def breach(peaks: Sequence[AxisPeaks], values: dict[str, Any]) -> str:
    """The first limit (``max_velocity.<axis>``, ``max_acceleration.<axis>``
    in ``values``) a job's ``peaks`` (AXES order) pass, in words; "" if none."""
    for p, ax in zip(peaks, AXIS_TABLE, strict=True):
        axis, unit = ax.name, ax.unit
        v_lim = float(values.get(f"max_velocity.{axis}", NO_LIMIT))
        a_lim = float(values.get(f"max_acceleration.{axis}", NO_LIMIT))
        if p.velocity > v_lim:
            got, lim = _apart(p.velocity, v_lim)
            return (
                f"the job drives the {axis} axis at up to {got} {unit}/s, beyond "
                f"max_velocity.{axis} = {lim} {unit}/s"
            )
        if p.windowed_acceleration > a_lim:
            got, lim = _apart(p.windowed_acceleration, a_lim)
            how = f" ({p.jump:.6g} {unit}/s of it at once)" if p.jump else ""
            return (
                f"the job accelerates the {axis} axis at up to {got} {unit}/s^2 "
                f"over {WINDOW_S * 1e3:g} ms{how}, beyond max_acceleration.{axis} = {lim} {unit}/s^2"
            )
    return ""


@dataclass(frozen=True)
class Breach:
    """A step that passes a limit: which (``velocity``, ``acceleration``),
    the watched joint's index, the step's time (ns of the run), the value
    measured over the window and the limit (joint units)."""

    kind: str
    joint: int
    t_ns: int
    value: float
    limit: float


class LimitWatch:
    """Velocity and acceleration limits on timed steps, as they come.

    ``columns``: the step-count column of each watched joint in a row
    (``[t_ns, seq, feed, fork, pole]``); ``start``: each one's count before
    the first row; ``step_len``: its length per step (m or rad);
    ``v_max``/``a_max``: its limits (``NO_LIMIT``: none). :meth:`feed` takes
    rows in time order and gives the first that passes a limit (None if none)."""

    def __init__(
        self,
        columns: Sequence[int],
        start: npt.NDArray[np.int64],
        step_len: npt.NDArray[np.float64],
        v_max: npt.NDArray[np.float64],
        a_max: npt.NDArray[np.float64],
    ) -> None:
        self.columns = list(columns)
        w = WINDOW_S
        step = np.abs(step_len)
        self.active = bool(((v_max < NO_LIMIT) | (a_max < NO_LIMIT)).any())
        # in steps: the limit, widened by what whole steps can add over a window
        with np.errstate(divide="ignore", invalid="ignore"):
            self.v_steps = np.where(step > 0, v_max / step, np.inf) * w + 2 * QUANTUM
            self.a_steps = np.where(step > 0, a_max / step, np.inf) * w * w + 4 * QUANTUM
        self.step_len = step
        self.v_max, self.a_max = v_max, a_max
        # the rows of the last two windows (times, counts); a row at -inf holds the start
        self.t = np.array([np.iinfo(np.int64).min], np.int64)
        self.c = np.asarray(start, np.int64).reshape(1, -1)

    def feed(self, rows: npt.NDArray[np.int64]) -> Breach | None:
        if not self.active or rows.shape[0] == 0:
            return None
        t = np.concatenate((self.t, rows[:, 0]))
        c = np.concatenate((self.c, rows[:, self.columns]))
        new = np.arange(len(self.t), len(t))

        def at(when: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:  # the counts in force at `when`
            return c[np.searchsorted(t, when, side="right") - 1]

        now = c[new]
        back1 = at(t[new] - WINDOW_NS)
        back2 = at(t[new] - 2 * WINDOW_NS)
        dv = np.abs(now - back1)
        da = np.abs(now - 2 * back1 + back2)
        over_v = dv > self.v_steps
        over_a = da > self.a_steps
        keep = t >= t[-1] - 2 * WINDOW_NS
        keep[np.searchsorted(t, t[-1] - 2 * WINDOW_NS, side="right") - 1] = True  # the row in force then
        self.t, self.c = t[keep], c[keep]
        if not (over_v.any() or over_a.any()):
            return None
        i, j = divmod(int(np.argmax((over_v | over_a).reshape(-1))), len(self.columns))
        w, when = WINDOW_S, int(t[new[i]])
        if over_v[i, j]:
            return Breach("velocity", j, when, float(dv[i, j] * self.step_len[j] / w), float(self.v_max[j]))
        return Breach(
            "acceleration", j, when, float(da[i, j] * self.step_len[j] / (w * w)), float(self.a_max[j])
        )


def highest_override(ramp: dict[str, Any], schedule: str = "") -> float:
    """The highest feed override a run will have: the profile node's
    ``feed_override`` in ``ramp``, or one its ``schedule`` sets."""
    overrides = [c.value for c in parse_schedule(schedule) if c.kind == "override"]
    return max([float(ramp.get("feed_override", 1.0)), *overrides])


def job_limits(
    job: Job,
    ramp: dict[str, Any],
    limits: dict[str, Any],
    stops: Sequence[tuple[int, int]] = (),
    pause: float = 0.0,
    schedule: str = "",
) -> tuple[list[AxisPeaks], str]:
    """A job timed with the ``ramp`` settings (the profile node's) against
    the bridge's velocity and acceleration ``limits``, at the highest feed
    override it will run at (``feed_override``, or one its ``schedule``
    sets): each axis' peaks (AXES order) and the first limit passed, in
    words ("" if none). ValueError (one line) if the ramp cannot plan the job."""
    segments = job.segments()
    timings, _ = plan_job_timing(ramp, job, stops, pause)
    override = highest_override(ramp, schedule)
    peaks = job_peaks(segments, timings, job.joint_step, override)
    why = breach(peaks, limits)
    if why and override != 1.0:
        why += f", at feed override {override:g}"
    return peaks, why


@dataclass(frozen=True)
class TimedJob:
    """A job's segments timed once with a ramp at the highest feed override
    the run will have (``override``): what the flyer's speeds per layer and
    the tension predicted for them (winder.tension.plan) are read from."""

    job: Job
    segments: Sequence[Segment]
    timings: Sequence[SegmentTiming]
    override: float
    duration_ns: int  #: the job's, at feed override 1 (without stops)
    _peaks: dict[int, float] = field(default_factory=dict, compare=False, repr=False)

    def fork_peak(self, i: int) -> float:
        """The flyer's top speed in segment ``i`` (rad/s): the path's peak step
        rate over its moves times the fork's share of it (1 where the fork is
        the major axis, as in any layer of more fork steps a turn than feed
        steps), at 2 pi / ``fork_steps_per_rev`` rad a step."""
        seg, timing = self.segments[i], self.timings[i]
        v = max((self._peak(m) for m in timing.profiles), default=0.0)
        share = max(abs(p[FORK.index]) / max(abs(x) for x in p) for p in seg.pieces if any(p))
        return float(v * share * self.override * 2 * np.pi / self.job.fork_steps_per_rev)

    def _peak(self, move: Motion) -> float:
        if id(move) not in self._peaks:
            self._peaks[id(move)] = move_peaks(move)[0]
        return self._peaks[id(move)]

    def flyer_speeds(self) -> dict[tuple[int, int], float]:
        """The flyer's top speed (rad/s) in each layer laid, ``(coil, layer)`` from 0."""
        out: dict[tuple[int, int], float] = {}
        for i, seg in enumerate(self.segments):
            if seg.kind.winds:
                key = (seg.pole, seg.layer)
                out[key] = max(out.get(key, 0.0), self.fork_peak(i))
        return out


def time_job(job: Job, ramp: dict[str, Any], schedule: str = "") -> TimedJob:
    """The job timed with the ``ramp`` settings (the profile node's) at the
    highest feed override the run will have. ValueError (one line) if the
    ramp cannot plan the job."""
    segments = job.segments()
    timings, duration_ns = plan_job_timing(ramp, job)
    return TimedJob(job, segments, timings, highest_override(ramp, schedule), duration_ns)
