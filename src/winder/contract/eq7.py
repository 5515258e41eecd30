"""Eq. 7, one definition for the sim node's live summary and for ``winder
analyze`` (so both print the same figures for the same run): of the
commanded steps (:func:`step_deviation`) and of the simulated axes
(:func:`layer_of_samples`, :func:`sample_deviation`).

A commanded step counts if its row belongs to a layer segment; it is
measured against that layer's line, exactly (integer arithmetic). A layer
laid by a cam (orthocyclic, a reversal dwell) is measured against the piece
of its path whose fork range holds the point: the path it is meant to take.

A joint sample counts while a layer is wound: the command at the sample (the
last step row at or before it) is in a layer segment. It is measured against
the ideal line of the layer whose fork range holds the sample's fork
position, not the layer the command is in: an axis pair that lags along the
line is on the line, and at a corner a lagging sample still belongs to the
layer it is on. Samples before the first step row have no command segment
(-1) and do not count; samples after the last one (the settle time) keep
its segment.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from winder.contract.stream import JobPlan
from winder.motion.axes import FEED, FORK
from winder.motion.interp import line_distance

__all__ = ["layer_of_samples", "sample_deviation", "signed_path_distance", "step_deviation"]

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]


def layer_of_samples(plan: JobPlan, seg_now: npt.ArrayLike, y: npt.ArrayLike) -> IntArray:
    """For each sample (its command's segment ``seg_now``, -1 for none; its
    fork position ``y`` in steps): the layer segment it is measured against,
    -1 if it does not count (module doc)."""
    seg = np.asarray(seg_now, dtype=np.int64)
    yy = np.asarray(y, dtype=np.float64)
    out = np.full(seg.size, -1, np.int64)
    layer_ids = [i for i, s in enumerate(plan.segments) if s.kind.winds]
    if not layer_ids or seg.size == 0:
        return out
    kinds = np.array([s.kind.winds for s in plan.segments])
    ok = (seg >= 0) & (seg < kinds.size)
    winding = np.zeros(seg.size, dtype=bool)
    winding[ok] = kinds[seg[ok]]
    yw = yy[winding]
    starts = np.array([plan.segments[i].start[FORK.index] for i in layer_ids], dtype=np.float64)
    forward = all(plan.segments[i].delta[FORK.index] > 0 for i in layer_ids)
    if forward and np.all(np.diff(starts) > 0):  # the fork always turns forward: its ranges tile the axis
        which = np.clip(np.searchsorted(starts, yw, side="right") - 1, 0, len(layer_ids) - 1)
    else:
        # coils wound backward (coil_overrides direction ccw): fork ranges overlap, so a
        # sample belongs to the layer being wound when it was taken, or to the layer
        # before or after it if the axis is still (or already) in that one's range
        rank = np.full(len(plan.segments), -1, np.int64)
        rank[layer_ids] = np.arange(len(layer_ids))
        ends = starts + np.array([plan.segments[i].delta[FORK.index] for i in layer_ids], dtype=np.float64)
        lo, hi = np.minimum(starts, ends), np.maximum(starts, ends)
        which = np.maximum(rank[seg[winding]], 0)
        for step in (-1, 1):
            other = np.clip(which + step, 0, len(layer_ids) - 1)
            outside = (yw < lo[which]) | (yw > hi[which])
            inside_other = (yw >= lo[other]) & (yw <= hi[other])
            which = np.where(outside & inside_other, other, which)
    out[winding] = np.asarray(layer_ids, np.int64)[which]
    return out


def sample_deviation(plan: JobPlan, layer: npt.ArrayLike, x: npt.ArrayLike, y: npt.ArrayLike) -> FloatArray:
    """The eq. 5 distance (m) of each sample (x, y in steps of the feed and the
    fork) to the ideal line of its ``layer`` (:func:`layer_of_samples`); NaN
    where the layer is -1."""
    lay = np.asarray(layer, dtype=np.int64)
    xx = np.asarray(x, dtype=np.float64)
    yy = np.asarray(y, dtype=np.float64)
    out = np.full(lay.size, np.nan)
    lengths = (plan.step_lengths[FEED.index], plan.step_lengths[FORK.index])
    for i in (int(v) for v in np.unique(lay[lay >= 0])):
        m = lay == i
        s = plan.segments[i]
        out[m] = _path_distance(s.start, s.pieces or (s.delta,), xx[m], yy[m], lengths)
    return out


def _path_distance(
    start: tuple[int, ...],
    pieces: tuple[tuple[int, ...], ...],
    x: npt.NDArray[np.floating] | npt.NDArray[np.integer],
    y: npt.NDArray[np.floating] | npt.NDArray[np.integer],
    lengths: tuple[float, float],
) -> FloatArray:
    """The eq. 5 distance (m) of points (x, y in steps) to a layer's path: its
    one line, or the cam piece whose fork range holds each point."""
    if len(pieces) == 1:
        rel = np.column_stack(
            [np.asarray(x, np.float64) - start[FEED.index], np.asarray(y, np.float64) - start[FORK.index]]
        )
        return line_distance(rel, pieces[0][0], pieces[0][1], step_lengths=lengths)
    return np.abs(signed_path_distance(start, pieces, x, y, lengths))


def signed_path_distance(
    start: tuple[int, ...],
    pieces: tuple[tuple[int, ...], ...],
    x: npt.ArrayLike,
    y: npt.ArrayLike,
    lengths: tuple[float, float],
) -> FloatArray:
    """The distance (m) of points (x, y in steps of the feed and the fork) to
    a layer's path (its one line, or the cam piece whose fork range holds
    each point), signed by the side of it they are on: positive where
    ``dx*(y - y0) - (x - x0)*dy`` is."""
    xx, yy = np.asarray(x, np.float64), np.asarray(y, np.float64)
    fork = np.concatenate([[0], np.cumsum([abs(p[1]) for p in pieces])])
    feed = np.concatenate([[0], np.cumsum([p[0] for p in pieces])])
    sign = 1 if sum(p[1] for p in pieces) >= 0 else -1
    which = np.clip(
        np.searchsorted(fork, (yy - start[FORK.index]) * sign, side="right") - 1, 0, len(pieces) - 1
    )
    out = np.zeros(xx.size)
    for i in (int(v) for v in np.unique(which)):
        dx, dy = pieces[i][0], pieces[i][1]
        norm = math.hypot(dx * lengths[0], dy * lengths[1])
        if norm == 0:
            continue
        m = which == i
        cross = dx * (yy[m] - start[FORK.index] - sign * fork[i]) - (xx[m] - start[FEED.index] - feed[i]) * dy
        out[m] = cross * (lengths[0] * lengths[1] / norm)
    return out


def step_deviation(plan: JobPlan, segment: int, pos: npt.ArrayLike) -> FloatArray:
    """The eq. 5 distance (m) of commanded step positions ``pos`` (rows of
    feed, fork, ... in steps; the first two columns count) of layer segment
    ``segment`` to its ideal line."""
    s = plan.segments[segment]
    p = np.asarray(pos)[:, :2]
    lengths = (plan.step_lengths[FEED.index], plan.step_lengths[FORK.index])
    if len(s.pieces) > 1:
        return _path_distance(s.start, s.pieces, p[:, 0], p[:, 1], lengths)
    return line_distance(
        p,
        s.delta[FEED.index],
        s.delta[FORK.index],
        step_lengths=lengths,
        origin=(s.start[FEED.index], s.start[FORK.index]),
    )
