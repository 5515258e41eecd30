"""Interpolation against oracles written here: literal step-by-step loops of
each method, and the rule checked step by step on large random moves."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from winder.motion.interp import (
    MAX_STEPS,
    dda,
    deviation_stats,
    interpolate,
    line_distance,
    min_deviation,
    path_mismatch,
    point_by_point,
)

small = st.integers(-600, 600)
large = st.integers(-3_000_000, 3_000_000)


def brute_min_deviation(dx: int, dy: int) -> list[tuple[int, int]]:
    """The paper's rule, literally: major always steps; minor joins iff |F| shrinks."""
    sx, sy = (dx > 0) - (dx < 0), (dy > 0) - (dy < 0)
    x_major = abs(dx) >= abs(dy)
    x = y = 0
    out = []
    for _ in range(max(abs(dx), abs(dy))):
        if x_major:
            alone, both = (x + sx, y), (x + sx, y + sy)
        else:
            alone, both = (x, y + sy), (x + sx, y + sy)
        f_alone = abs(dx * alone[1] - alone[0] * dy)
        f_both = abs(dx * both[1] - both[0] * dy)
        x, y = both if f_both < f_alone else alone
        out.append((x, y))
    return out


def brute_dda(dx: int, dy: int, bits: int, preload: bool) -> list[tuple[int, int]]:
    cap = 2**bits
    acc_x = acc_y = cap // 2 if preload else 0
    x = y = 0
    out = []
    for _ in range(cap):
        acc_x += abs(dx)
        acc_y += abs(dy)
        moved = False
        if acc_x >= cap:
            acc_x -= cap
            x += 1 if dx > 0 else -1
            moved = True
        if acc_y >= cap:
            acc_y -= cap
            y += 1 if dy > 0 else -1
            moved = True
        if moved:
            out.append((x, y))
    return out


def brute_point_by_point(dx: int, dy: int) -> list[tuple[int, int]]:
    sx, sy = (dx > 0) - (dx < 0), (dy > 0) - (dy < 0)
    a, b = abs(dx), abs(dy)
    x = y = 0
    out = []
    for _ in range(a + b):
        f = a * y - x * b
        if (f >= 0 and x < a) or y == b:
            x += 1
        else:
            y += 1
        out.append((x * sx, y * sy))
    return out


@settings(max_examples=400)
@given(small, small)
def test_min_deviation_matches_literal_rule(dx: int, dy: int) -> None:
    path = min_deviation(dx, dy)
    assert path.dtype.kind == "i"
    assert path.shape == (max(abs(dx), abs(dy)), 2)
    assert [tuple(r) for r in path.tolist()] == brute_min_deviation(dx, dy)


def check_rule_every_step(path: np.ndarray, dx: int, dy: int) -> None:
    """Vectorised restatement of the rule at every step. int64 is exact here:
    |dx * y| < 2**62 for moves within 2**31 steps."""
    n = max(abs(dx), abs(dy))
    assert path.shape == (n, 2)
    if n == 0:
        return
    prev = np.vstack([[0, 0], path[:-1]]).astype(np.int64)
    major, minor = (0, 1) if abs(dx) >= abs(dy) else (1, 0)
    sgn = [(dx > 0) - (dx < 0), (dy > 0) - (dy < 0)]
    alone = prev.copy()
    alone[:, major] += sgn[major]
    both = alone.copy()
    both[:, minor] += sgn[minor]

    def f(p: np.ndarray) -> np.ndarray:
        return np.abs(dx * p[:, 1] - p[:, 0] * dy)

    want_both = f(both) < f(alone)  # strict: a tie takes the major step alone
    expected = np.where(want_both[:, None], both, alone)
    assert np.array_equal(path, expected)
    assert tuple(path[-1]) == (dx, dy)


@settings(max_examples=60, deadline=None)
@given(large, large)
def test_min_deviation_rule_on_large_moves(dx: int, dy: int) -> None:
    check_rule_every_step(min_deviation(dx, dy), dx, dy)


@pytest.mark.parametrize(("dx", "dy"), [(4_000_000, 3_999_999), (-1, 4_000_001), (2**22, -(2**21) - 1)])
def test_min_deviation_rule_on_chosen_large_moves(dx: int, dy: int) -> None:
    """Nearly diagonal, nearly axial, and a tie at every other step."""
    check_rule_every_step(min_deviation(dx, dy), dx, dy)


@settings(max_examples=100)
@given(large, large, st.data())
def test_window_equals_rows_of_the_full_path(dx: int, dy: int, data: st.DataObject) -> None:
    n = max(abs(dx), abs(dy))
    lo = data.draw(st.integers(0, n))
    hi = data.draw(st.integers(lo, min(n, lo + 70_000)))
    window = min_deviation(dx, dy, start=lo, stop=hi)
    assert np.array_equal(window, min_deviation(dx, dy)[lo:hi])
    # a window is also what interpolate() hands out
    assert np.array_equal(interpolate([0, 0], [dx, dy], first=lo, stop=hi), window)


def test_min_deviation_zero_and_axis_moves() -> None:
    assert min_deviation(0, 0).shape == (0, 2)
    assert min_deviation(5, 0).tolist() == [[1, 0], [2, 0], [3, 0], [4, 0], [5, 0]]
    assert min_deviation(0, -3).tolist() == [[0, -1], [0, -2], [0, -3]]
    assert min_deviation(-3, -3).tolist() == [[-1, -1], [-2, -2], [-3, -3]]


@settings(max_examples=200)
@given(small, small)
def test_max_deviation_is_at_most_half_a_step(dx: int, dy: int) -> None:
    path = min_deviation(dx, dy)
    stats = deviation_stats(path, dx, dy)
    assert stats.max_minor <= 0.5 + 1e-12
    if path.shape[0]:
        a = max(abs(dx), abs(dy))
        f = np.abs(dx * path[:, 1] - path[:, 0] * dy)
        assert 2 * f.max() <= a  # exact, integer


@settings(max_examples=150)
@given(st.integers(-1000, 1000), st.integers(-1000, 1000), st.integers(10, 12), st.booleans())
def test_dda_matches_register_loop(dx: int, dy: int, bits: int, preload: bool) -> None:
    path = dda(dx, dy, bits, preload=preload)
    assert [tuple(r) for r in path.tolist()] == brute_dda(dx, dy, bits, preload)
    if dx or dy:
        assert tuple(path[-1]) == (dx, dy)


@settings(max_examples=200)
@given(small, small)
def test_point_by_point_matches_loop(dx: int, dy: int) -> None:
    path = point_by_point(dx, dy)
    assert path.shape == (abs(dx) + abs(dy), 2)
    assert [tuple(r) for r in path.tolist()] == brute_point_by_point(dx, dy)


@settings(max_examples=100)
@given(st.integers(-300, 300), st.integers(-300, 300), st.floats(1e-6, 1e-2), st.floats(1e-6, 1e-2))
def test_deviation_stats_is_perpendicular_distance(dx: int, dy: int, lx: float, ly: float) -> None:
    path = min_deviation(dx, dy)
    stats = deviation_stats(path, dx, dy, step_lengths=(lx, ly))
    if path.shape[0] == 0:
        assert stats.points == 0
        return
    # geometric oracle: distance to the line by projection in physical units
    p = path * np.array([lx, ly])
    e = np.array([dx * lx, dy * ly])
    u = e / np.linalg.norm(e)
    foot = np.outer(p @ u, u)
    dist = np.linalg.norm(p - foot, axis=1)
    # the projection oracle rounds at the scale of the coordinates
    tol = 1e-13 * float(np.linalg.norm(e))
    assert stats.mean == pytest.approx(dist.mean(), rel=1e-9, abs=tol)
    assert stats.max == pytest.approx(dist.max(), rel=1e-9, abs=tol)
    assert stats.rms == pytest.approx(math.sqrt(np.mean(dist**2)), rel=1e-9, abs=tol)


@pytest.mark.parametrize("feed_step_um", [5.0, 8.8, 10.0, 12.5, 25.0])
def test_min_deviation_not_worse_than_dda_on_rw400(feed_step_um: float) -> None:
    """Paper set-up: flyer radius 500 mm, wire 2.50 mm, register 2**10; one turn."""
    lx = feed_step_um * 1e-6
    ly = 2 * math.pi * 0.5 / 1024
    x, y = round(2.5e-3 / lx), 1024
    md = deviation_stats(min_deviation(x, y), x, y, step_lengths=(lx, ly)).mean
    for preload in (True, False):
        d = deviation_stats(dda(x, y, 10, preload=preload), x, y, step_lengths=(lx, ly)).mean
        assert md <= d * (1 + 1e-12)
    pbp = deviation_stats(point_by_point(x, y), x, y, step_lengths=(lx, ly)).mean
    assert md < pbp


def test_interpolate_three_axes() -> None:
    path = interpolate([10, 20, 30], [-4, 0, 9])
    assert path.shape == (9, 3)
    assert path[-1].tolist() == [6, 20, 39]
    assert np.all(path[:, 1] == 20)
    assert np.array_equal(path[:, [0, 2]] - [10, 30], min_deviation(-4, 9))
    assert interpolate([1, 2, 3], [0, 0, 0]).shape == (0, 3)


def brute_many(start: list[int], delta: list[int]) -> list[list[int]]:
    """The rule of a move of several axes, literally: the major (the first of the
    largest |delta|) steps every row; each other axis steps with it exactly when
    that makes its own |F| = |d_major * y - x * d_minor| smaller (a tie: not)."""
    major = max(range(len(delta)), key=lambda i: (abs(delta[i]), -i))
    a = abs(delta[major])
    sign = [(v > 0) - (v < 0) for v in delta]
    rel = [0] * len(delta)
    out = []
    for _ in range(a):
        rel[major] += sign[major]
        for ax in range(len(delta)):
            if ax == major or not delta[ax]:
                continue
            alone = abs(delta[major] * rel[ax] - rel[major] * delta[ax])
            both = abs(delta[major] * (rel[ax] + sign[ax]) - rel[major] * delta[ax])
            if both < alone:
                rel[ax] += sign[ax]
        out.append([s + r for s, r in zip(start, rel, strict=True)])
    return out


@settings(max_examples=300)
@given(
    st.lists(st.integers(-60, 60), min_size=3, max_size=5),
    st.lists(st.integers(-(10**6), 10**6), min_size=5, max_size=5),
    st.data(),
)
def test_a_move_of_many_axes_steps_each_minor_by_the_rule(
    delta: list[int], start: list[int], data: st.DataObject
) -> None:
    """A follower driven with the flyer (a fourth axis, a tensioner) moves with
    feed and fork in one move: the literal rule per minor (brute_many), every
    window of it, and path_mismatch agreeing with it (a row changed in any one
    column is found)."""
    start = start[: len(delta)]
    path = interpolate(start, delta)
    assert path.tolist() == brute_many(start, delta)
    n = path.shape[0]
    first = data.draw(st.integers(0, n))
    stop = data.draw(st.integers(first, n))
    assert np.array_equal(interpolate(start, delta, first=first, stop=stop), path[first:stop])
    assert path_mismatch(start, delta, first, path[first:stop]) == -1
    if stop > first:
        row = data.draw(st.integers(first, stop - 1))
        col = data.draw(st.integers(0, len(delta) - 1))
        bad = path[first:stop].copy()
        bad[row - first, col] += data.draw(st.sampled_from([-1, 1]))
        assert path_mismatch(start, delta, first, bad) == row - first


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: min_deviation(1.5, 2), r"dx=1\.5 is invalid"),  # type: ignore[arg-type]
        (lambda: min_deviation(1, MAX_STEPS + 1), r"dy=2147483648 is invalid: must be in"),
        (lambda: min_deviation(True, 2), r"dx=True is invalid"),
        (lambda: dda(5, 3, bits=0), r"bits=0 is invalid"),
        (lambda: dda(2000, 3, bits=10), r"bits=10 is too small"),
        (lambda: point_by_point("3", 1), r"dx='3' is invalid"),  # type: ignore[arg-type]
    ],
)
def test_bad_input_names_the_parameter(call, match: str) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ValueError, match=match):
        call()


@settings(max_examples=300, deadline=None)
@given(
    st.integers(-(2**31), 2**31),
    st.integers(-(2**31), 2**31),
    st.tuples(st.integers(-(2**30), 2**30), st.integers(-(2**30), 2**30)),
    st.integers(0, 2**32 - 1),
    st.floats(1e-7, 1e-2),
    st.floats(1e-7, 1e-2),
)
def test_line_distance_is_the_perpendicular_distance_to_the_moved_line(
    dx: int, dy: int, origin: tuple[int, int], seed: int, lx: float, ly: float
) -> None:
    """eq. 5 in physical units, from any start, against the cross product of
    the physical vectors computed here in exact rationals."""
    from fractions import Fraction

    rng = np.random.default_rng(seed)
    pts = np.column_stack(
        [origin[0] + rng.integers(-(2**31), 2**31, 20), origin[1] + rng.integers(-(2**31), 2**31, 20)]
    )
    got = line_distance(pts, dx, dy, step_lengths=(lx, ly), origin=origin)
    got_real = line_distance(pts.astype(np.float64), dx, dy, step_lengths=(lx, ly), origin=origin)
    for (x, y), g, gr in zip(pts.tolist(), got, got_real, strict=True):
        if dx == 0 and dy == 0:
            assert g == 0.0
            continue
        cross = (
            abs(Fraction(dx) * (y - origin[1]) - Fraction(x - origin[0]) * dy) * Fraction(lx) * Fraction(ly)
        )
        ref = float(cross) / math.hypot(dx * lx, dy * ly)
        assert g == pytest.approx(ref, rel=1e-12, abs=1e-300)
        # real positions: float products, rounding relative to their size
        size = (
            (abs(dx * (y - origin[1])) + abs((x - origin[0]) * dy)) * lx * ly / math.hypot(dx * lx, dy * ly)
        )
        assert abs(gr - ref) <= 1e-15 * size + 1e-12 * ref


def first_off(pos: np.ndarray, path: np.ndarray) -> int:
    """The oracle: index of the first row that differs from ``path``, or -1."""
    off = np.flatnonzero(np.any(pos != path, axis=1))
    return int(off[0]) if off.size else -1


#: how a corrupted value differs: near the path, by 2**j (its products wrap
#: onto the right ones modulo 2**64), or anything at all
CHANGE = st.one_of(
    st.tuples(st.just("add"), st.integers(-3, 3)),
    st.tuples(st.just("add"), st.integers(31, 63).map(lambda j: 2**j)),
    st.tuples(st.just("set"), st.integers(-(2**63), 2**63 - 1)),
)
MOVE = st.one_of(st.integers(-6, 6), st.integers(-(2**40), 2**40))


@settings(max_examples=400, deadline=None)
@given(
    st.integers(2, 4),
    st.lists(MOVE, min_size=2, max_size=2),
    st.lists(st.integers(-(2**31), 2**31), min_size=4, max_size=4),
    st.data(),
)
def test_path_mismatch_agrees_with_interpolate(
    n_axes: int, moves: list[int], starts: list[int], data: st.DataObject
) -> None:
    """path_mismatch (no division) against rows of interpolate, on the path and
    off it in up to three values, near or wild: the same first bad row. Moves
    beyond MAX_STEPS are refused by both."""
    axes = data.draw(st.permutations(range(n_axes)))[:2]
    delta = [0] * n_axes
    for ax, v in zip(axes, moves, strict=True):
        delta[ax] = v
    start = starts[:n_axes]
    if any(abs(v) > MAX_STEPS for v in delta):
        with pytest.raises(ValueError, match="invalid"):
            interpolate(start, delta, first=0, stop=0)
        with pytest.raises(ValueError, match="invalid"):
            path_mismatch(start, delta, 0, np.empty((0, n_axes), np.int64))
        return
    a = max(abs(v) for v in delta)
    n = data.draw(st.integers(0, min(a, 200)))
    first = data.draw(st.one_of(st.integers(0, a - n), st.just(a - n)))  # the end, where products are largest
    path = interpolate(start, delta, first=first, stop=first + n)
    pos = path.copy()
    assert path_mismatch(start, delta, first, pos) == -1
    if n == 0:
        return
    for _ in range(data.draw(st.integers(1, 3))):
        row, col = data.draw(st.integers(0, n - 1)), data.draw(st.integers(0, n_axes - 1))
        how, v = data.draw(CHANGE)
        value = v if how == "set" else int(pos[row, col]) + v
        pos[row, col] = (value + 2**63) % 2**64 - 2**63  # as int64 wraps
    assert path_mismatch(start, delta, first, pos) == first_off(pos, path)
    # whole chunks moved along the path: a window shifted by a few steps
    shift = data.draw(st.integers(-3, 3))
    if 0 <= first + shift <= a - n:
        other = interpolate(start, delta, first=first + shift, stop=first + shift + n)
        assert path_mismatch(start, delta, first, other) == first_off(other, path)


def test_path_mismatch_every_single_change_of_small_moves() -> None:
    """Every row of every move up to 6 x 6 steps (and one of 3 axes), each of
    its values changed by +-1, +-2 or 2**61..2**63 (wrapping onto the right
    products): the first bad row, as the oracle says."""
    changes = [1, -1, 2, -2, 2**61, 2**62, 2**63]
    for dx in range(-6, 7):
        for dy in range(-6, 7):
            start, delta = [7, -3, 11], [dx, 0, dy]
            path = interpolate(start, delta)
            a = path.shape[0]
            for first in range(a):
                window = path[first:]
                assert path_mismatch(start, delta, first, window) == -1
                for row in range(window.shape[0]):
                    for col in range(3):
                        for c in changes:
                            pos = window.copy()
                            pos[row, col] = (int(pos[row, col]) + c + 2**63) % 2**64 - 2**63
                            assert path_mismatch(start, delta, first, pos) == first_off(pos, window)


def test_path_mismatch_window_and_move_as_interpolate() -> None:
    pos = interpolate([0, 0], [5, 3])
    assert path_mismatch([0, 0], [5, 3], 0, pos) == -1
    assert path_mismatch((0, 0), (5, 3), 2, pos[2:]) == -1
    assert path_mismatch([0, 0], [5, 3], 1, pos[2:]) == 0
    assert path_mismatch([1, 2, 3], [0, 0, 0], 0, np.zeros((1, 3), np.int64)) == 0  # no path
    with pytest.raises(ValueError, match="stop=6 is invalid"):
        path_mismatch([0, 0], [5, 3], 1, pos)
