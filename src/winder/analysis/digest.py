"""One pass over the step rows of a run: everything the analysis and its
figures take from them, in memory that does not grow with the job. ROS-free.

A 10^7-step job has 400 MB of step rows; :func:`digest` reads them a
recorded chunk at a time (:attr:`winder.record.reader.Run.step_rows`) and
keeps only

* running sums: rows, steps moved per axis, eq. 7 of every layer (sum, sum of
  squares, maximum, per turn), the time of the last row of every segment;
* the segment the command is in at every joint sample (the samples grow with
  the job's duration, not its steps);
* the command kinematics of each segment's major axis (:mod:`.metrics`),
  computed by a stencil that slides over a buffer of a few strides
  (:class:`SegmentKinematics`), kept as peaks, as a trace thinned to at most
  :data:`TRACE_POINTS` points, and whole over the first segment each axis
  moves in (at most :data:`ZOOM_POINTS` points);
* what the figures zoom into: the rows around each axis' first moves, a
  thinned path per layer, an eighth of a turn of the first layer.

Every number equals the one computed over all rows at once, up to the
rounding of the sums (tests check this against the whole-array functions
for many ways of cutting the rows into chunks).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from winder.contract.eq7 import signed_path_distance, step_deviation
from winder.contract.stream import JobPlan
from winder.motion.axes import AXES, FEED, FORK
from winder.motion.job import Segment

__all__ = [
    "END_STRIDES",
    "STRIDE_TIME",
    "TRACE_POINTS",
    "ZOOM_POINTS",
    "Digest",
    "FirstMove",
    "LayerStats",
    "SegmentKinematics",
    "Trace",
    "digest",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: the shortest time the finite-difference stencil of the step-time derivatives spans (s)
STRIDE_TIME = 0.002
#: the stencil keeps this many strides away from the start and end of a move
END_STRIDES = 8
#: the whole-run traces are thinned to at most this many points (a plot shows no more)
TRACE_POINTS = 40_000
#: points of the command kinematics kept whole over an axis' first segment (the zoom)
ZOOM_POINTS = 1 << 16
#: step rows kept after an axis' first move (the tracking zoom)
ZOOM_ROWS = 1 << 16
#: the first moves of an axis that the tracking zoom shows
ZOOM_STEPS = 40
#: points of all layers together in the unrolled-path overview
PATH_POINTS = 40_000
#: step times the kinematics stencil keeps behind its position, at least
KEEP_MIN = 1 << 16
#: rows worked on at once: a long recorded chunk is taken in pieces of this many
PIECE_ROWS = 1 << 14


# -- the command kinematics, sliding -----------------------------------------------


def _empty() -> FloatArray:
    return np.zeros(0)


class SegmentKinematics:
    """The kinematics of one move from its step times, given in pieces.

    Feed it ``(k, t_ns)``: step k of the move happened at t_ns (k = 0 is the
    start; any order within a piece, pieces in increasing k). It calls ``emit(t,
    v, a, j)`` with what :func:`winder.analysis.metrics.step_kinematics` gives
    for the whole move, in order, as soon as the stencil around a step is
    whole; :meth:`finish` gives the rest. It keeps the step times of the last
    :data:`KEEP_MIN` steps (or four of the widest strides seen, if more): a
    stencil that would reach further back (a move more than ~30x faster than
    anything before it within 65536 steps) is counted in ``lost`` instead.
    """

    def __init__(
        self,
        steps: int,
        emit: Callable[[FloatArray, FloatArray, FloatArray, FloatArray], None],
        *,
        stride_time: float = STRIDE_TIME,
    ) -> None:
        self.n = steps + 1
        self.mclip = max(1, (self.n - 1) // (2 * END_STRIDES + 1))
        self.stride_time = stride_time
        self.emit = emit
        self.base = 0  #: the step index of buf[0]
        self.top = 0  #: one past the highest step index seen
        self.buf = np.zeros(0)
        self.done = 0  #: the next step index to evaluate
        self.max_m = 1
        self.lost = 0
        self.small = self.n < 2 * END_STRIDES + 1

    def add(self, k: IntArray, t_ns: npt.NDArray[np.int64] | FloatArray) -> None:
        if self.small:
            return
        ok = (k >= self.base) & (k <= self.n - 1)
        k, t = k[ok], t_ns[ok]
        if k.size == 0:
            return
        hi = int(k.max()) + 1
        if hi > self.top:
            grow = np.full(hi - self.top, np.nan)
            self.buf = np.concatenate([self.buf, grow]) if self.buf.size else grow
            self.top = hi
        self.buf[k - self.base] = t
        self._run(final=False)

    def finish(self) -> None:
        if not self.small and self.top > 0:
            self._run(final=True)

    def _get(self, idx: IntArray) -> FloatArray:
        inside = (idx >= self.base) & (idx < self.top)
        out = np.full(idx.shape, np.nan)
        out[inside] = self.buf[idx[inside] - self.base]
        return out

    def _run(self, *, final: bool) -> None:
        lo = self.done
        hi = self.top if final else self.top - 1  # the step spacing at k needs k + 1
        if hi <= lo:
            return
        k = np.arange(lo, hi, dtype=np.int64)
        n = self.n
        after, before = self._get(np.minimum(k + 1, n - 1)), self._get(np.maximum(k - 1, 0))
        span = np.where((k == 0) | (k == n - 1), 1e9, 2e9)
        local = (after - before) / span
        with np.errstate(invalid="ignore", divide="ignore"):
            m = np.ceil(self.stride_time / local)
        m = np.where(np.isfinite(m), np.clip(m, 1, self.mclip), 1).astype(np.int64)
        fits = (k >= END_STRIDES * m) & (k <= n - 1 - END_STRIDES * m)
        if not final:
            waiting = np.nonzero(fits & (k + 2 * m >= self.top))[0]
            if waiting.size:
                k, m, fits = k[: waiting[0]], m[: waiting[0]], fits[: waiting[0]]
        self.done = lo + k.size
        k, m = k[fits], m[fits]
        if k.size:
            self.max_m = max(self.max_m, int(m.max()))
            short = k - 2 * m < self.base
            self.lost += int(np.count_nonzero(short))
            k, m = k[~short], m[~short]
            self._stencil(k, m)
        self._trim()

    def _stencil(self, k: IntArray, m: IntArray) -> None:
        # second-order central differences of t(k) (t in ns, exact integers in float64); higher
        # orders overshoot where a profile's acceleration or jerk jumps
        mf = m.astype(np.float64)
        t0, tp, tm = self._get(k), self._get(k + m), self._get(k - m)
        tp2, tm2 = self._get(k + 2 * m), self._get(k - 2 * m)
        d1 = (tp - tm) / (2 * mf) * 1e-9  # s per step
        d2 = (tp - 2 * t0 + tm) / mf**2 * 1e-9
        # the jerk is the difference quotient of the acceleration a stride either side (from
        # the same five step times): the mean jerk between those times, so it stays within the
        # move's largest |jerk|, where 3 a^2 / v - t3 v^4 overshot at a jump of the jerk (+13 %
        # at the peak of a triangular acceleration, where the jerk jumps by 2 J)
        d1p, d2p = (tp2 - t0) / (2 * mf) * 1e-9, (tp2 - 2 * tp + t0) / mf**2 * 1e-9
        d1m, d2m = (t0 - tm2) / (2 * mf) * 1e-9, (t0 - 2 * tm + tm2) / mf**2 * 1e-9
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            v = 1.0 / d1
            a = -d2 / d1**3
            j = (d2m / d1m**3 - d2p / d1p**3) / ((tp - tm) * 1e-9)
        good = np.isfinite(v) & np.isfinite(a) & np.isfinite(j)
        if np.any(good):
            self.emit(t0[good] * 1e-9, v[good], a[good], j[good])

    def _trim(self) -> None:
        keep = max(KEEP_MIN, 4 * self.max_m)
        base = max(self.base, self.done - keep)
        if base - self.base > max(self.buf.size // 2, 4096):
            self.buf = self.buf[base - self.base :].copy()
            self.base = base


# -- traces -------------------------------------------------------------------------


@dataclass
class Trace:
    """The command kinematics of one axis (joint units): peaks, a thinned
    whole-run trace (every ``stride``-th point, the stride doubling as the run
    goes on) and the points of the first segment the axis moves in."""

    first_segment: int  #: the plan's first segment that moves the axis (-1: none)
    peak_v: float = math.nan
    peak_a: float = math.nan
    peak_j: float = math.nan
    stride: int = 1
    count: int = 0
    thin: list[FloatArray] = field(default_factory=list)  #: (4, k) blocks of t, v, a, j
    thin_points: int = 0
    first: list[FloatArray] = field(default_factory=list)
    first_count: int = 0

    def add(self, segment: int, t: FloatArray, v: FloatArray, a: FloatArray, j: FloatArray) -> None:
        block = np.vstack([t, v, a, j])
        for name, x in (("peak_v", v), ("peak_a", a), ("peak_j", j)):
            p = float(np.max(np.abs(x)))
            old = getattr(self, name)
            setattr(self, name, p if math.isnan(old) else max(old, p))
        idx = self.count + np.arange(t.size)
        self.count += t.size
        kept = block[:, idx % self.stride == 0]
        self.thin.append(kept)
        self.thin_points += kept.shape[1]
        if self.thin_points > 2 * TRACE_POINTS:
            self._coarsen()
        if segment == self.first_segment and self.first_count < ZOOM_POINTS:
            take = min(t.size, ZOOM_POINTS - self.first_count)
            self.first.append(block[:, :take])
            self.first_count += take

    def _coarsen(self) -> None:
        whole = np.hstack(self.thin)
        self.stride *= 2
        self.thin = [whole[:, ::2].copy()]
        self.thin_points = self.thin[0].shape[1]

    def whole_run(self) -> tuple[FloatArray, ...]:
        """(t, v, a, j), thinned."""
        if not self.thin:
            return (_empty(),) * 4
        w = np.hstack(self.thin)
        return w[0], w[1], w[2], w[3]

    def first_move(self) -> tuple[FloatArray, ...]:
        """(t, v, a, j) over the first segment the axis moves in (whole, up to ZOOM_POINTS)."""
        if not self.first:
            return (_empty(),) * 4
        w = np.hstack(self.first)
        return w[0], w[1], w[2], w[3]


# -- eq. 7 per layer ------------------------------------------------------------------


@dataclass
class LayerStats:
    """Eq. 7 of the commanded steps of one layer segment (m), and what its
    figures show: the path thinned (all layers together to about PATH_POINTS
    rows), and (first layer
    only) the signed distance of every step within 1/16 turn of its middle."""

    segment: int
    plan: Segment
    scale: float  #: metres per unit of |F|
    turns: int
    per_rev: int
    points: int = 0
    total: float = 0.0
    total_sq: float = 0.0
    max: float = 0.0
    turn_sum: FloatArray = field(default_factory=_empty)
    turn_count: IntArray = field(default_factory=lambda: np.zeros(0, np.int64))
    path: list[IntArray] = field(default_factory=list)  #: (feed, fork) rows, thinned
    zoom: tuple[int, int] | None = None  #: fork range of the zoom (first layer only)
    zoom_rows: list[FloatArray] = field(default_factory=list)  #: (fork, signed distance m)
    path_stride: int = 1  #: every path_stride-th row goes into ``path``

    def __post_init__(self) -> None:
        self.turn_sum = np.zeros(self.turns)
        self.turn_count = np.zeros(self.turns, np.int64)

    @property
    def mean(self) -> float:
        return self.total / self.points if self.points else math.nan

    def turn_means(self) -> FloatArray:
        seen = self.turn_count > 0
        out: FloatArray = self.turn_sum[seen] / self.turn_count[seen]
        return out

    def add(self, rows: IntArray, plan: JobPlan) -> None:
        """The step rows of this layer, of the job ``plan``: their eq. 7 distances
        (:func:`winder.contract.eq7.step_deviation`, as the sim node's live summary)."""
        s = self.plan
        rel = rows[:, 2:4] - np.asarray(s.start[:2])
        dist = step_deviation(plan, self.segment, rows[:, 2:4])
        tid = turn_index(np.abs(rel[:, 1]).astype(np.float64), self.per_rev, self.turns)
        idx = self.points + np.arange(rows.shape[0])
        self.points += dist.size
        self.total += float(dist.sum())
        self.total_sq += float(dist @ dist)
        self.max = max(self.max, float(dist.max()))
        self.turn_sum += np.bincount(tid, weights=dist, minlength=self.turns)
        self.turn_count += np.bincount(tid, minlength=self.turns)
        self.path.append(rows[idx % self.path_stride == 0][:, 2:4].copy())
        if self.zoom is not None:
            lo, hi = self.zoom
            m = (rows[:, 3] >= lo) & (rows[:, 3] <= hi)
            if np.any(m):
                signed = signed_path_distance(
                    s.start,
                    s.pieces or (s.delta,),
                    rows[m, 2],
                    rows[m, 3],
                    (plan.step_lengths[FEED.index], plan.step_lengths[FORK.index]),
                )
                self.zoom_rows.append(np.vstack([rows[m, 3].astype(np.float64), signed]))


def turn_index(y_rel: FloatArray, per_rev: int, turns: int) -> IntArray:
    """Turn index (0-based) of points at fork offsets ``y_rel`` (steps) into a layer."""
    out: IntArray = np.clip(np.ceil(y_rel / per_rev) - 1, 0, turns - 1).astype(np.int64)
    return out


# -- first moves ----------------------------------------------------------------------


@dataclass
class FirstMove:
    """Where an axis first moves: the time (ns), segment and position before
    it, the times of its first ZOOM_STEPS + 1 moves, and the rows (time ns,
    position) from that first move on (up to ZOOM_ROWS)."""

    t0: int
    segment: int
    before: int
    move_times: list[int] = field(default_factory=list)
    rows: list[IntArray] = field(default_factory=list)
    kept: int = 0

    def zoom_rows(self) -> IntArray:
        return np.hstack(self.rows) if self.rows else np.zeros((2, 0), np.int64)


# -- the pass ---------------------------------------------------------------------------


@dataclass
class Digest:
    """What :func:`digest` keeps of a run's step rows (module doc)."""

    rows: int = 0
    first_t: int | None = None  #: ns, the first row's time
    last_t: int | None = None  #: ns, the last row's time
    increasing: bool = True  #: the row times increase everywhere
    moved: list[int] = field(default_factory=lambda: [0] * len(AXES))
    layers: dict[int, LayerStats] = field(default_factory=dict)
    traces: dict[str, Trace] = field(default_factory=dict)
    first_moves: dict[str, FirstMove | None] = field(default_factory=dict)
    segment_end: dict[int, int] = field(default_factory=dict)  #: segment -> time (ns) of its last row
    sample_segment: IntArray = field(default_factory=lambda: np.zeros(0, np.int64))
    lost_stencils: int = 0  #: kinematics points lost to a too-short buffer (see SegmentKinematics)


class _Pass:
    def __init__(
        self, plan: JobPlan, sample_t: FloatArray, stride_time: float, rests: Iterable[tuple[int, int]] = ()
    ) -> None:
        self.plan = plan
        # each segment's moves, from rest to rest: (first step count, last step count)
        cuts: dict[int, set[int]] = {}
        for seg, step in rests:
            if 0 <= seg < len(plan.segments) and 0 < step < plan.segments[seg].steps:
                cuts.setdefault(seg, set()).add(step)
        self.moves: dict[int, list[tuple[int, int]]] = {}
        for i, s in enumerate(plan.segments):
            ends = [0, *sorted(cuts.get(i, ())), s.steps]
            self.moves[i] = list(itertools.pairwise(ends))
        self.d = Digest()
        self.stride_time = stride_time
        lx, ly = plan.step_lengths[FEED.index], plan.step_lengths[FORK.index]
        job = plan.job
        first_layer = True
        layer_steps = sum(s.steps for s in plan.segments if s.kind.winds)
        for i, s in enumerate(plan.segments):
            if not s.kind.winds:
                continue
            norm = math.hypot(s.delta[FEED.index] * lx, s.delta[FORK.index] * ly)
            layer = LayerStats(
                i,
                s,
                lx * ly / norm if norm else 0.0,
                abs(s.delta[FORK.index]) // job.fork_steps_per_rev,  # this layer's turns (its coil's)
                job.fork_steps_per_rev,
                path_stride=max(1, layer_steps // PATH_POINTS),
            )
            if first_layer:
                y_mid = s.start[FORK.index] + s.delta[FORK.index] // 2
                layer.zoom = (y_mid - job.fork_steps_per_rev // 16, y_mid + job.fork_steps_per_rev // 16)
                first_layer = False
            self.d.layers[i] = layer
        for ax, name in enumerate(AXES):
            first = next((i for i, s in enumerate(plan.segments) if s.delta[ax] != 0), -1)
            self.d.traces[name] = Trace(first)
            self.d.first_moves[name] = None
        self.prev = np.asarray(plan.segments[0].start if plan.segments else (0,) * len(AXES), np.int64)
        self.kin: dict[tuple[int, int], SegmentKinematics] = {}  #: (segment, move) -> its stencil
        self.closed: set[tuple[int, int]] = set()
        order = np.argsort(sample_t, kind="stable")
        self.sample_order = order
        self.sample_ns = np.round(sample_t[order] * 1e9).astype(np.int64)
        self.sample_seg = np.full(sample_t.size, -1, np.int64)
        self.p = 0
        self.last_seg = -1

    def add(self, rows: IntArray) -> None:
        if rows.shape[0] == 0:
            return
        d = self.d
        ts = rows[:, 0]
        if (d.last_t is not None and ts[0] <= d.last_t) or np.any(np.diff(ts) <= 0):
            d.increasing = False
        if d.first_t is None:
            d.first_t = int(ts[0])
        d.rows += rows.shape[0]
        d.last_t = int(ts[-1])
        self._moves(rows)
        self._samples(ts, rows[:, 1])
        seg = rows[:, 1]
        cut = np.nonzero(np.diff(seg))[0] + 1
        for part in np.split(rows, cut) if cut.size else (rows,):
            self._segment_rows(int(part[0, 1]), part)

    def _moves(self, rows: IntArray) -> None:
        d = self.d
        pos = rows[:, 2:5]
        steps = np.diff(np.vstack([self.prev[None, :], pos]), axis=0)
        for ax, name in enumerate(AXES):
            col = steps[:, ax]
            d.moved[ax] += int(np.abs(col).sum())
            first = d.first_moves[name]
            if first is None:
                nz = np.nonzero(col)[0]
                if not nz.size:
                    continue
                i = int(nz[0])
                first = FirstMove(
                    int(rows[i, 0]), int(rows[i, 1]), int(self.prev[ax] if i == 0 else pos[i - 1, ax])
                )
                d.first_moves[name] = first
                start = i
            else:
                start = 0
            if len(first.move_times) <= ZOOM_STEPS:
                nz = np.nonzero(col[start:])[0] + start
                first.move_times += [int(x) for x in rows[nz[: ZOOM_STEPS + 1 - len(first.move_times)], 0]]
            if first.kept < ZOOM_ROWS:
                take = rows[start : start + ZOOM_ROWS - first.kept]
                first.rows.append(np.vstack([take[:, 0], take[:, 2 + ax]]))
                first.kept += take.shape[0]
        self.prev = pos[-1].copy()

    def _samples(self, ts: IntArray, segs: IntArray) -> None:
        """The segment of the command at each joint sample: that of the last row at or before it."""
        ns, out, order = self.sample_ns, self.sample_seg, self.sample_order
        p = self.p
        g = int(np.searchsorted(ns, ts[0], side="left"))
        if g > p:
            out[order[p:g]] = self.last_seg
        b = int(np.searchsorted(ns, ts[-1], side="right"))
        if b > g:
            idx = np.clip(np.searchsorted(ts, ns[g:b], side="right") - 1, 0, ts.size - 1)
            out[order[g:b]] = segs[idx]
        self.p = max(p, b, g)
        self.last_seg = int(segs[-1])

    def _segment_rows(self, i: int, rows: IntArray) -> None:
        d = self.d
        d.segment_end[i] = int(rows[-1, 0])
        if not 0 <= i < len(self.plan.segments):
            return
        layer = d.layers.get(i)
        if layer is not None:
            layer.add(rows, self.plan)
        if not rows.shape[0]:
            return
        s = self.plan.segments[i]
        k = np.abs(rows[:, 2 + s.major] - s.start[s.major])
        # a move is differentiated on its own: across a rest (a programmed stop, a pause, the
        # end of an abort) t(k) jumps and is singular on either side, as at a segment's start
        touched = [
            (n, lo, hi)
            for n, (lo, hi) in enumerate(self.moves[i])
            if (i, n) not in self.closed and np.any((k >= lo) & (k <= hi))
        ]
        if not touched:
            return
        first = (i, touched[0][0])
        for key in [key for key in self.kin if key < first]:  # the stream has moved on: finish them
            self._close(key)
        for n, lo, hi in touched:
            kin = self.kin.get((i, n))
            if kin is None:
                kin = self.kin[(i, n)] = self._kinematics(i, hi - lo)
            m = (k >= lo) & (k <= hi)
            kin.add(k[m] - lo, rows[m, 0])

    def _kinematics(self, i: int, steps: int) -> SegmentKinematics:
        """The stencil of a move of ``steps`` steps of segment ``i``."""
        s = self.plan.segments[i]
        js = self.plan.joint_step
        ratios = [(name, s.delta[ax] / s.steps * js[ax]) for ax, name in enumerate(AXES)] if s.steps else []

        def emit(t: FloatArray, v: FloatArray, a: FloatArray, j: FloatArray) -> None:
            for name, r in ratios:
                if r != 0:
                    self.d.traces[name].add(i, t, v * r, a * r, j * r)

        return SegmentKinematics(steps, emit, stride_time=self.stride_time)

    def _close(self, key: tuple[int, int]) -> None:
        kin = self.kin.pop(key)
        kin.finish()
        self.d.lost_stencils += kin.lost
        self.closed.add(key)

    def finish(self) -> Digest:
        for i in sorted(self.kin):
            self._close(i)
        if self.p < self.sample_ns.size:
            self.sample_seg[self.sample_order[self.p :]] = self.last_seg
        self.d.sample_segment = self.sample_seg
        return self.d


def digest(
    plan: JobPlan,
    rows: Iterable[IntArray],
    sample_t: FloatArray,
    stride_time: float = STRIDE_TIME,
    rests: Iterable[tuple[int, int]] = (),
) -> Digest:
    """One pass over step ``rows`` (chunks of (k, 5) int64, in stream order) of
    a job ``plan``; ``sample_t`` are the joint sample times (s) whose command
    segment is wanted. ``rests``: (segment, steps of it done) where the axes
    came to rest within a segment besides the plan's programmed stops (an
    operator's pause or abort): the kinematics take each move between rests
    on its own."""
    p = _Pass(plan, np.asarray(sample_t, dtype=np.float64), stride_time, [*plan.stops, *rests])
    for chunk in rows:
        chunk = np.asarray(chunk, dtype=np.int64)
        for i in range(0, chunk.shape[0], PIECE_ROWS):
            p.add(chunk[i : i + PIECE_ROWS])
    return p.finish()
