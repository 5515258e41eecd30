"""Linear interpolation of a straight move into unit steps.

The unrolled winding path is the straight line from the origin to E = (x_E, y_E)
in step units. Every function here returns the *absolute position after each
step* as an integer array of shape (N, 2), the last row being (dx, dy).

* :func:`min_deviation` - the minimum-deviation rule of the RW400 paper (2016):
  the major axis always steps; the minor axis steps with it exactly when that
  makes |F| smaller, F = x_E*y - x*y_E; on a tie the major step alone is taken.
* :func:`dda` - the digital differential analyser with an n-bit register.
* :func:`point_by_point` - the classic point-by-point comparison method.
* :func:`deviation_stats` - the paper's eq. 7 error metric and friends.

Closed form of the minimum-deviation rule
-----------------------------------------
Mirror the move into the first octant, a = |major|, b = |minor| (b <= a). After
k major steps the minor position y_k satisfies, by induction on k, the rule
"step the minor axis iff |F + a| < |F|", i.e. iff 2*(a*y - k*b) + a < 0, so

    y_k = ceil(k*b/a - 1/2) = floor((2*k*b + a - 1) / (2*a)),

the nearest integer to k*b/a with halves rounded down (the tie rule). That makes
every step independent of the previous one, so the path is computed vectorised,
block by block so that the temporaries stay in the CPU cache.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from winder.errors import BadInputError

__all__ = [
    "MAX_STEPS",
    "DeviationStats",
    "dda",
    "deviation_stats",
    "interpolate",
    "interpolate_pieces",
    "line_distance",
    "min_deviation",
    "path_mismatch",
    "pieces_mismatch",
    "point_by_point",
]

#: Largest move per axis, in steps. Positions travel as int32 on the wire, and
#: 2*k*b + a stays below 2**64 in the unsigned closed form.
MAX_STEPS = 2**31 - 1

_BLOCK = 1 << 15  # rows per block: 512 KiB of output, the temporaries fit in L2

IntPath = npt.NDArray[np.int64]


def _check_delta(name: str, value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise BadInputError(
            f"{name}={value!r} is invalid: must be an integer number of steps in [-{MAX_STEPS}, {MAX_STEPS}]"
        )
    v = int(value)
    if abs(v) > MAX_STEPS:
        raise BadInputError(f"{name}={v} is invalid: must be in [-{MAX_STEPS}, {MAX_STEPS}] steps")
    return v


def _sign(v: int) -> int:
    return (v > 0) - (v < 0)


def min_deviation(dx: int, dy: int, *, start: int = 0, stop: int | None = None) -> IntPath:
    """Minimum-deviation interpolation of the move (0, 0) -> (dx, dy).

    Returns an int64 array of shape (N, 2), N = max(|dx|, |dy|): the absolute
    position after each step; the last row is (dx, dy); (0, 0) gives (0, 2).
    ``start``/``stop`` select the rows start..stop-1 only (a streaming window
    over a long move), with the same values as the full path's rows.
    """
    dx = _check_delta("dx", dx)
    dy = _check_delta("dy", dy)
    a, b = abs(dx), abs(dy)
    swap = b > a
    if swap:
        a, b = b, a
    stop = a if stop is None else stop
    if not (0 <= start <= stop <= a):
        raise ValueError(f"start={start}, stop={stop} is invalid: need 0 <= start <= stop <= {a}")
    rows = stop - start
    out = np.empty((rows, 2), dtype=np.int64)
    if rows == 0:
        return out
    major_col, minor_col = (1, 0) if swap else (0, 1)
    s_major = _sign(dy if swap else dx)
    s_minor = _sign(dx if swap else dy)
    major = out[:, major_col]
    minor = out[:, minor_col]

    block = min(_BLOCK, rows)
    k0 = np.arange(1, block + 1, dtype=np.int64)
    if s_major < 0:
        np.negative(k0, out=k0)
    # numerators 2*k*b + a - 1 of the first block, unsigned: unsigned division
    # by a scalar is markedly faster than signed floor division in numpy.
    num0 = np.arange(1, block + 1, dtype=np.uint64) * np.uint64(2 * b) + np.uint64(a - 1)
    num = np.empty(block, dtype=np.uint64)
    div = np.uint64(2 * a)
    num_step = np.uint64(2 * b * block)
    offset = np.uint64(2 * b * start)
    for lo in range(0, rows, block):
        hi = min(rows, lo + block)
        n = hi - lo
        np.add(k0[:n], s_major * (start + lo), out=major[lo:hi])
        np.add(num0[:n], offset, out=num[:n])
        np.floor_divide(num[:n], div, out=num[:n])
        if s_minor < 0:
            np.negative(num[:n].view(np.int64), out=minor[lo:hi])
        else:
            minor[lo:hi] = num[:n]
        offset += num_step
    return out


def dda(dx: int, dy: int, bits: int = 10, *, preload: bool = True) -> IntPath:
    """Digital differential analyser with a ``bits``-bit register.

    Each of the 2**bits iterations adds |dx| and |dy| to two accumulators of
    capacity 2**bits; an overflow emits one step on that axis. With ``preload``
    (the usual "improved DDA") the accumulators start half full, which rounds
    instead of truncating. Returns the absolute position after every iteration
    that emitted at least one step, shape (M, 2), last row (dx, dy).
    """
    dx = _check_delta("dx", dx)
    dy = _check_delta("dy", dy)
    if isinstance(bits, bool) or not isinstance(bits, (int, np.integer)) or not 1 <= bits <= 40:
        raise BadInputError(f"bits={bits!r} is invalid: must be an integer in [1, 40]")
    cap = 1 << int(bits)
    if max(abs(dx), abs(dy)) > cap:
        raise BadInputError(
            f"bits={bits} is too small for the move ({dx}, {dy}): "
            f"the register must hold max(|dx|, |dy|) <= 2**bits = {cap}"
        )
    k = np.arange(1, cap + 1, dtype=np.int64)
    p = cap // 2 if preload else 0
    x = (k * abs(dx) + p) >> int(bits)
    y = (k * abs(dy) + p) >> int(bits)
    moved = np.empty(cap, dtype=bool)
    moved[0] = (x[0] != 0) | (y[0] != 0)
    moved[1:] = (x[1:] != x[:-1]) | (y[1:] != y[:-1])
    out = np.empty((int(moved.sum()), 2), dtype=np.int64)
    out[:, 0] = x[moved] * _sign(dx)
    out[:, 1] = y[moved] * _sign(dy)
    return out


def point_by_point(dx: int, dy: int) -> IntPath:
    """Classic point-by-point comparison: one axis per step, |dx| + |dy| steps.

    In the mirrored first quadrant with F = |dx|*y - x*|dy|: step x while F >= 0
    (on or above the line), else step y.
    """
    dx = _check_delta("dx", dx)
    dy = _check_delta("dy", dy)
    a, b = abs(dx), abs(dy)
    total = a + b
    is_y = np.zeros(total, dtype=bool)
    if b:
        j = np.arange(1, b + 1, dtype=np.int64)
        if a:
            # x steps taken before the j-th y step: at height j-1 the x axis
            # advances while x <= a*(j-1)/b, i.e. up to floor(a*(j-1)/b) + 1.
            xs_before = np.minimum(a, (a * (j - 1)) // b + 1)
        else:
            xs_before = np.zeros(b, dtype=np.int64)
        is_y[xs_before + j - 1] = True
    out = np.empty((total, 2), dtype=np.int64)
    np.cumsum(~is_y, out=out[:, 0])
    np.cumsum(is_y, out=out[:, 1])
    out[:, 0] *= _sign(dx)
    out[:, 1] *= _sign(dy)
    return out


def interpolate(
    start: npt.ArrayLike, delta: npt.ArrayLike, *, first: int = 0, stop: int | None = None
) -> IntPath:
    """Minimum-deviation steps of a straight move in any number of axes.

    ``start`` and ``delta`` are integer vectors (steps). A winding layer moves
    feed and fork, an index move one axis; a move of three or more axes (a
    follower driven with the flyer, as a tensioner or a traverse is) steps its
    major axis (the largest ``|delta|``, the first of equals) every row and
    each other axis by the rule in its own plane with the major: each minor's
    deviation is the smallest it can be, as if it moved alone with the major.
    Returns the absolute positions after each step, (N, axes), or only the
    rows first..stop-1.
    """
    s = np.asarray(start, dtype=np.int64)
    d = np.asarray(delta, dtype=np.int64)
    if s.shape != d.shape or s.ndim != 1:
        raise ValueError(f"start {s.shape} and delta {d.shape} must be vectors of equal length")
    moving = np.flatnonzero(d)
    if moving.size > 2:
        return _interpolate_many(s, d, moving, first, stop)
    axes = list(moving) + [i for i in range(d.size) if i not in moving][: 2 - moving.size]
    if moving.size == 0:
        return np.empty((0, d.size), dtype=np.int64)
    if len(axes) == 1:  # a one-axis machine
        plane = min_deviation(int(d[axes[0]]), 0, start=first, stop=stop)[:, :1]
    else:
        plane = min_deviation(int(d[axes[0]]), int(d[axes[1]]), start=first, stop=stop)
    out = np.empty((plane.shape[0], d.size), dtype=np.int64)
    out[:] = s
    for col, ax in enumerate(axes[: plane.shape[1]]):
        out[:, ax] += plane[:, col]
    return out


def _interpolate_many(
    s: npt.NDArray[np.int64],
    d: npt.NDArray[np.int64],
    moving: npt.NDArray[np.intp],
    first: int,
    stop: int | None,
) -> IntPath:
    """:func:`interpolate` of a move of three or more axes: each minor in its
    plane with the major (the first of the largest ``|delta|``)."""
    major = int(moving[np.argmax(np.abs(d[moving]))])
    minors = [int(ax) for ax in moving if ax != major]
    # the major first: each plane has its rows, the major's column the same in every one
    planes = [min_deviation(int(d[major]), int(d[ax]), start=first, stop=stop) for ax in minors]
    out = np.empty((planes[0].shape[0], d.size), dtype=np.int64)
    out[:] = s
    out[:, major] += planes[0][:, 0]
    for ax, plane in zip(minors, planes, strict=True):
        out[:, ax] += plane[:, 1]
    return out


def path_mismatch(
    start: Sequence[int] | npt.NDArray[np.integer[Any]],
    delta: Sequence[int] | npt.NDArray[np.integer[Any]],
    first: int,
    pos: npt.ArrayLike,
) -> int:
    """Index of the first row of ``pos`` (n, axes) that differs from row
    ``first + i`` of :func:`interpolate` ``(start, delta)``, or -1 if none does.

    The same verdict as comparing with ``interpolate(start, delta, first=first,
    stop=first + n)``, without forming the path or dividing: in the mirrored
    first octant (a = |major|, b = |minor|) the k-th row has the major axis at
    k and the minor at m_k = floor((2*k*b + a - 1) / (2*a)) (module doc), i.e.
    exactly when 0 <= m_k <= b and 0 <= 2*k*b + a - 1 - 2*a*m_k < 2*a; an axis
    that does not move stays at its start. With m_k in 0..b every term is
    below 2**63 (|delta| <= MAX_STEPS), so int64 is exact; a row with m_k
    outside (a wild value, whose difference may wrap) is off the path whatever
    its wrapped r. ValueError as :func:`interpolate` for a bad move or window.
    """
    p = np.asarray(pos)
    s = [int(v) for v in start]
    d = [int(v) for v in delta]
    if len(s) != len(d):
        raise ValueError(f"start ({len(s)}) and delta ({len(d)}) must be vectors of equal length")
    if p.ndim != 2 or p.shape[1] != len(d):
        raise ValueError(f"pos has shape {p.shape}: must be (n, {len(d)})")
    moving = [i for i, v in enumerate(d) if v]
    if len(moving) > 2:  # each minor in its plane with the major, as interpolate; the others still
        major = max(moving, key=lambda i: (abs(d[i]), -i))
        hits = [
            path_mismatch([s[major], s[ax]], [d[major], d[ax]], first, p[:, [major, ax]])
            for ax in moving
            if ax != major
        ]
        still = [i for i in range(len(d)) if i not in moving]
        if still:  # an axis the move does not move stays at its start
            off = np.flatnonzero(np.any(p[:, still] != np.asarray(s)[still], axis=1))
            hits.append(int(off[0]) if off.size else -1)
        return min((h for h in hits if h >= 0), default=-1)
    for i in moving:
        _check_delta(f"delta[{i}]", d[i])
    n = p.shape[0]
    if not moving:  # the path has no rows: any row differs
        return 0 if n else -1
    major = max(moving, key=lambda i: (abs(d[i]), -i))  # the first of the longest, as interpolate
    a = abs(d[major])
    if not 0 <= first <= a - n:
        raise ValueError(f"start={first}, stop={first + n} is invalid: need 0 <= start <= stop <= {a}")
    if n == 0:
        return -1
    p = p.astype(np.int64, copy=False)
    idx = _iota(n)
    # the major axis at its start + k (or - k), k = first + 1 + idx
    k1 = first + 1
    if d[major] > 0:
        bad = (p[:, major] - idx) != s[major] + k1
    else:
        bad = (p[:, major] + idx) != s[major] - k1
    for ax in range(len(d)):
        if ax == major:
            continue
        b = abs(d[ax])
        if b == 0:
            bad |= p[:, ax] != s[ax]
            continue
        m: npt.NDArray[np.int64] = p[:, ax] - s[ax] if d[ax] > 0 else s[ax] - p[:, ax]
        bad |= m.view(np.uint64) > np.uint64(b)  # m outside 0..b
        r = idx * (2 * b)  # r = 2*k*b + a - 1 - 2*a*m
        r += 2 * b * k1 + a - 1
        m *= 2 * a
        r -= m
        bad |= r.view(np.uint64) >= np.uint64(2 * a)
    hit = int(np.argmax(bad))
    return hit if bad[hit] else -1


@dataclass(frozen=True)
class _Pieces:
    """A path of straight pieces, indexed: each piece's delta, where it
    starts (the sum of the deltas before it) and its first row (the sum of
    the major steps before it; one more entry: the path's rows)."""

    deltas: npt.NDArray[np.int64]  # (n, axes)
    at: npt.NDArray[np.int64]  # (n, axes)
    rows: npt.NDArray[np.int64]  # (n + 1,)


#: the last paths indexed, by identity (tuples only: a job's cam, laid out
#: once, is walked chunk by chunk; indexing it again for every chunk made a
#: layer of 10^5 turns cost hours)
_INDEXED: list[tuple[Sequence[Sequence[int]], _Pieces]] = []


def _indexed(pieces: Sequence[Sequence[int]]) -> _Pieces:
    global _INDEXED
    for known, index in _INDEXED:
        if known is pieces:
            return index
    d = np.asarray(pieces, dtype=np.int64)
    if d.ndim != 2:
        d = d.reshape(len(pieces), -1) if d.size else np.zeros((len(pieces), 0), np.int64)
    rows = np.zeros(len(pieces) + 1, np.int64)
    if d.size:
        np.cumsum(np.max(np.abs(d), axis=1), out=rows[1:])
    at = np.zeros_like(d)
    if len(d) > 1:
        np.cumsum(d[:-1], axis=0, out=at[1:])
    index = _Pieces(d, at, rows)
    if type(pieces) is tuple:  # immutable: it stays what was indexed
        _INDEXED = [(pieces, index), *_INDEXED[:3]]
    return index


def _piece_windows(
    pieces: Sequence[Sequence[int]], first: int, stop: int
) -> Iterator[tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], int, int, int]]:
    """For the rows ``first..stop-1`` of a path of straight ``pieces`` (each
    a delta; the rows of a piece follow those of the one before), each piece
    they touch: (its start, its delta, its rows' first and stop within it,
    and the offset of its first row in the window)."""
    index = _indexed(pieces)
    rows = index.rows
    i = int(np.searchsorted(rows[1:], first, side="right"))  # the first piece ending after row first
    while i < len(index.deltas) and rows[i] < stop:
        done, n = int(rows[i]), int(rows[i + 1] - rows[i])
        lo, hi = max(first - done, 0), min(stop - done, n)
        if lo < hi:
            yield index.at[i].copy(), index.deltas[i], lo, hi, done + lo - first
        i += 1


def interpolate_pieces(
    start: npt.ArrayLike, pieces: Sequence[Sequence[int]], *, first: int = 0, stop: int | None = None
) -> IntPath:
    """The minimum-deviation steps of a path of straight ``pieces`` (a cam:
    each piece a delta, walked by :func:`interpolate` from where the one
    before ended): rows ``first..stop-1`` of the path's rows, each piece
    contributing as many rows as its major axis has steps. One piece is
    :func:`interpolate`'s move exactly."""
    s = np.asarray(start, dtype=np.int64)
    if len(pieces) == 1:
        return interpolate(s, pieces[0], first=first, stop=stop)
    total = int(_indexed(pieces).rows[-1])
    stop = total if stop is None else stop
    if not 0 <= first <= stop <= total:
        raise ValueError(f"start={first}, stop={stop} is invalid: need 0 <= start <= stop <= {total}")
    out = np.empty((stop - first, s.size), dtype=np.int64)
    for at, d, lo, hi, row in _piece_windows(pieces, first, stop):
        out[row : row + hi - lo] = interpolate(s + at, d, first=lo, stop=hi)
    return out


def pieces_mismatch(
    start: Sequence[int] | npt.NDArray[np.integer[Any]],
    pieces: Sequence[Sequence[int]],
    first: int,
    pos: npt.ArrayLike,
) -> int:
    """:func:`path_mismatch` for a path of straight ``pieces``
    (:func:`interpolate_pieces`): the first row of ``pos`` off the path's rows
    from ``first`` on, or -1."""
    if len(pieces) == 1:
        return path_mismatch(start, pieces[0], first, pos)
    p = np.asarray(pos)
    s = np.asarray([int(v) for v in start], dtype=np.int64)
    total = int(_indexed(pieces).rows[-1])
    n = p.shape[0] if p.ndim == 2 else 0
    if p.ndim != 2 or p.shape[1] != s.size:
        raise ValueError(f"pos has shape {p.shape}: must be (n, {s.size})")
    if not 0 <= first <= total - n:
        raise ValueError(f"start={first}, stop={first + n} is invalid: need 0 <= start <= stop <= {total}")
    for at, d, lo, hi, row in _piece_windows(pieces, first, first + n):
        hit = path_mismatch((s + at).tolist(), d.tolist(), lo, p[row : row + hi - lo])
        if hit >= 0:
            return row + hit
    return -1


_IOTA = np.arange(0, dtype=np.int64)


def _iota(n: int) -> npt.NDArray[np.int64]:
    """0, 1, ... n - 1, read-only, kept from call to call."""
    global _IOTA
    if _IOTA.size < n:
        _IOTA = np.arange(max(n, 2 * _IOTA.size), dtype=np.int64)
        _IOTA.flags.writeable = False
    return _IOTA[:n]


def _abs_f(
    p: npt.NDArray[Any], dx: int, dy: int, origin: tuple[int, int] = (0, 0)
) -> npt.NDArray[np.float64]:
    """|F| = |dx*(y - y0) - (x - x0)*dy| of each row (x, y): exact in int64
    for step positions (|dx*y| < 2**62 within MAX_STEPS), in float for real
    ones. Column by column: no copy of a strided (N, 2) view."""
    x0, y0 = (int(v) for v in origin)
    if np.issubdtype(p.dtype, np.integer):
        pi = p.astype(np.int64, copy=False)
        fi = int(dx) * pi[:, 1]
        fi -= pi[:, 0] * int(dy)
        if x0 or y0:
            fi -= int(dx) * y0 - x0 * int(dy)
        f: npt.NDArray[np.float64] = np.abs(fi, out=fi).astype(np.float64)
        return f
    return np.abs(dx * (p[:, 1].astype(np.float64) - y0) - (p[:, 0].astype(np.float64) - x0) * dy)


def _distance_scale(dx: int, dy: int, step_lengths: tuple[float, float]) -> float:
    """Factor from |F| (steps squared) to the physical distance |F| / |OE| (eq. 5)."""
    lx, ly = (float(v) for v in step_lengths)
    if not (math.isfinite(lx) and math.isfinite(ly) and lx > 0 and ly > 0):
        raise BadInputError(f"step_lengths={step_lengths!r} is invalid: must be two finite numbers > 0")
    return lx * ly / math.hypot(dx * lx, dy * ly)


def line_distance(
    points: npt.ArrayLike,
    dx: int,
    dy: int,
    *,
    step_lengths: tuple[float, float] = (1.0, 1.0),
    origin: tuple[int, int] = (0, 0),
) -> npt.NDArray[np.float64]:
    """Perpendicular distance of each point (x, y), in steps (integers, or real
    positions of a simulated axis), to the line from the move's start
    ``origin`` along (dx, dy), in the physical units of ``step_lengths`` (eq. 5)."""
    p = np.asarray(points)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"points have shape {p.shape}: must be (N, 2)")
    if dx == 0 and dy == 0:
        return np.zeros(p.shape[0])
    return _abs_f(p, dx, dy, origin) * _distance_scale(dx, dy, step_lengths)


@dataclass(frozen=True)
class DeviationStats:
    """Distance of a stepped path to its ideal line, in step units (or the
    physical units of ``step_lengths`` if given)."""

    mean: float  #: eq. 7: mean Euclidean (perpendicular) distance of the points
    max: float  #: largest distance
    rms: float  #: root mean square distance
    max_minor: float  #: largest distance measured along the minor axis, in steps
    points: int  #: number of points measured


def deviation_stats(
    path: npt.ArrayLike,
    dx: int,
    dy: int,
    *,
    step_lengths: tuple[float, float] = (1.0, 1.0),
) -> DeviationStats:
    """Deviation of ``path`` (positions after each step, shape (N, 2)) from the
    line (0, 0) -> (dx, dy).

    The distance of point (x, y) is |F| / |OE| with F = dx*y - x*dy (eq. 5),
    evaluated in physical units when ``step_lengths = (l_x, l_y)`` is given.
    ``max_minor`` is |F| / |major| in steps: the minimum-deviation rule keeps it
    at most 1/2.
    """
    p = np.asarray(path)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"path has shape {p.shape}: must be (N, 2)")
    if p.shape[0] == 0 or (dx == 0 and dy == 0):
        return DeviationStats(0.0, 0.0, 0.0, 0.0, int(p.shape[0]))
    f = _abs_f(p, dx, dy)
    dist = f * _distance_scale(dx, dy, step_lengths)
    return DeviationStats(
        mean=float(dist.mean()),
        max=float(dist.max()),
        rms=float(np.sqrt(np.mean(dist * dist))),
        max_minor=float(f.max() / max(abs(dx), abs(dy))),
        points=int(p.shape[0]),
    )
