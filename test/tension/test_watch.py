"""The wire watch (winder.tension.watch) on signals made here: a break is a
tension below a tenth of the set tension for 10 ms while the flyer turns,
placed where the low run began; a slack moment shorter than that, or a
flyer at rest, is none; a slip is the first sample whose count is off by
more than the tolerance. Checked against a brute-force scan of the same
rule, over random signals cut into random blocks."""

from __future__ import annotations

import itertools

import numpy as np
import numpy.typing as npt
from hypothesis import given, settings
from hypothesis import strategies as st

from winder.tension.watch import BREAK_SHARE, BREAK_TIME, TURNING, Place, WireFault, WireWatch

F = npt.NDArray[np.float64]

RATE = 1000.0
SET = 5.0


def place(k0: int) -> Place:
    return lambda k: (1, 1, k0 + k)  # the sample's index stands for its turn: where, checked exactly


def feed_in_blocks(
    watch: WireWatch,
    t: F,
    tension: F,
    speed: F,
    cuts: list[int],
    paid: F | None = None,
    expected: F | None = None,
) -> WireFault | None:
    edges = [0, *sorted(set(cuts)), t.size]
    for lo, hi in itertools.pairwise(edges):
        if hi <= lo:
            continue
        sl = slice(lo, hi)
        got = watch.feed(
            t[sl],
            tension[sl],
            speed[sl],
            place(lo),
            None if paid is None else paid[sl],
            None if expected is None else expected[sl],
        )
        if got is not None:
            return got
    return None


def first_break(t: F, tension: F, speed: F) -> tuple[int, int] | None:
    """The rule, sample by sample: the first low run that lasts BREAK_TIME."""
    start = None
    for k in range(t.size):
        low = tension[k] < BREAK_SHARE * SET and abs(speed[k]) > TURNING
        if not low:
            start = None
            continue
        start = k if start is None else start
        if t[k] - t[start] >= BREAK_TIME:
            return start, k
    return None


@settings(max_examples=200, deadline=None)
@given(
    n=st.integers(20, 600),
    dips=st.lists(st.tuples(st.integers(0, 599), st.integers(1, 40)), max_size=5),
    rest=st.lists(st.tuples(st.integers(0, 599), st.integers(1, 60)), max_size=3),
    cuts=st.lists(st.integers(1, 599), max_size=8),
)
def test_a_break_is_a_low_run_of_10_ms_with_the_flyer_turning(
    n: int, dips: list[tuple[int, int]], rest: list[tuple[int, int]], cuts: list[int]
) -> None:
    t = np.arange(n) / RATE
    tension = np.full(n, SET) + 0.3 * np.sin(t * 40)
    speed = np.full(n, 20.0)
    for at, width in dips:
        tension[at : at + width] = 0.0
    for at, width in rest:
        speed[at : at + width] = 0.0
    got = feed_in_blocks(WireWatch(SET, 0.01), t, tension, speed, [c for c in cuts if c < n])
    want = first_break(t, tension, speed)
    if want is None:
        assert got is None
    else:
        assert got is not None and got.kind == "break"
        start, seen = want
        assert (got.turn, got.t_s, got.seen_s) == (start, t[start], t[seen])
        assert got.text.startswith(
            f"wire break at coil 1 layer 1 turn {start} ({t[start]:.3f} s into the run)"
        )


@settings(max_examples=200, deadline=None)
@given(
    n=st.integers(2, 500),
    at=st.integers(0, 499),
    size=st.floats(0.0, 0.05),
    tolerance=st.floats(0.001, 0.03),
    cuts=st.lists(st.integers(1, 499), max_size=6),
)
def test_a_slip_is_the_first_count_off_by_more_than_the_tolerance(
    n: int, at: int, size: float, tolerance: float, cuts: list[int]
) -> None:
    t = np.arange(n) / RATE
    expected = np.cumsum(np.full(n, 1e-4))
    paid = expected - size * np.clip((np.arange(n) - at) / 50.0, 0.0, 1.0)  # a slip ramping in over 50
    tension, speed = np.full(n, SET), np.full(n, 20.0)
    got = feed_in_blocks(
        WireWatch(SET, tolerance), t, tension, speed, [c for c in cuts if c < n], paid, expected
    )
    past = [k for k in range(n) if abs(paid[k] - expected[k]) > tolerance]
    if not past:
        assert got is None
    else:
        assert got is not None and got.kind == "slip" and got.turn == past[0] and got.t_s == t[past[0]]
        assert "paid out" in got.text and " less than the turns took" in got.text


def test_a_fault_is_said_once() -> None:
    watch = WireWatch(SET, 0.01)
    t = np.arange(100) / RATE
    assert watch.feed(t, np.zeros(100), np.full(100, 20.0), place(0)) is not None
    assert watch.feed(t + 0.1, np.zeros(100), np.full(100, 20.0), place(100)) is None
    assert watch.fault is not None and watch.fault.values() == {
        "fault": "break",
        "coil": 1,
        "layer": 1,
        "turn": 0,
        "t_s": "0.000000",
    }
