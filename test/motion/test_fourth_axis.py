"""A fourth axis, from an ``Axis`` row alone: a follower driven as a cam of the
flyer (a dancer arm that swings twice a turn, as the take-up of a
rectangular core asks) runs through the library's interpolation, time law
and linear motor model with no library file edited for it (issue 42).

The follower's row is made here, beside the cell's ``AXIS_TABLE``; its moves
are the layer's cam pieces with a fourth column. Oracles: the cam's own
straight lines (each step within half a step of them, the minimum-deviation
bound), the time law's own limits, and scipy's ``lsim`` of the paper's
second-order transfer function for the follower's motor.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal

from winder.axis import StepperAxis
from winder.contract.params import PROFILE_SPECS
from winder.motion.axes import AXIS_TABLE, Axis
from winder.motion.interp import interpolate_pieces, pieces_mismatch
from winder.motion.timing import plan_segment

#: the follower: a rotary dancer arm, its column after the cell's three
DANCER = Axis("dancer", len(AXIS_TABLE), "rad", True, 1.0, "rad", "dancer_steps_per_rev", "a dancer arm")
TABLE = (*AXIS_TABLE, DANCER)
FEED, FORK = (a.index for a in AXIS_TABLE[:2])
PAPER = {"Zr": 40.0, "L": 0.01005, "i_a": 1.0, "J": 1.05 * 9.80665e-5, "D": 0.03}
RAMP = {k: s.default for k, s in PROFILE_SPECS.items()}


def cam_layer(turns: int, fork_per_turn: int, feed_per_turn: int, swing: int) -> list[tuple[int, ...]]:
    """The layer's pieces, one per quarter turn: the fork a quarter turn, the
    feed a quarter of its pitch, the dancer out and back twice a turn."""
    quarter = fork_per_turn // 4
    pieces = []
    for _ in range(turns):
        for q in range(4):
            feed = feed_per_turn // 4 + (1 if q < feed_per_turn % 4 else 0)
            piece = [0] * len(TABLE)
            piece[FEED], piece[FORK], piece[DANCER.index] = feed, quarter, swing if q % 2 == 0 else -swing
            pieces.append(tuple(piece))
    return pieces


@settings(max_examples=25)
@given(
    st.integers(1, 3),
    st.sampled_from([256, 512, 1024]),
    st.integers(1, 40),
    st.integers(1, 60),
)
def test_a_follower_of_the_flyer_is_stepped_within_half_a_step_of_its_cam(
    turns: int, fork_per_turn: int, feed_per_turn: int, swing: int
) -> None:
    pieces = cam_layer(turns, fork_per_turn, feed_per_turn, swing)
    start = np.zeros(len(TABLE), np.int64)
    rows = interpolate_pieces(start, pieces)
    assert rows.shape == (turns * fork_per_turn, len(TABLE))  # the fork is the major: a row per fork step
    assert np.array_equal(rows[:, FORK], np.arange(1, rows.shape[0] + 1))
    assert pieces_mismatch(start.tolist(), pieces, 0, rows) == -1
    # each piece's follower within half a step of its straight line, as the feed is of its own
    at, k0 = np.zeros(len(TABLE)), 0
    for piece in pieces:
        d = np.array(piece, float)
        k = np.arange(1, int(d[FORK]) + 1)
        part = rows[k0 : k0 + k.size]
        for ax in (FEED, DANCER.index):
            ideal = at[ax] + d[ax] * k / d[FORK]
            assert np.max(np.abs(part[:, ax] - ideal)) <= 0.5 + 1e-12
        at, k0 = at + d, k0 + k.size
    assert rows[-1, DANCER.index] == 0 and rows[-1, FEED] == turns * feed_per_turn


def test_the_follower_through_the_time_law_and_its_motor() -> None:
    """The layer timed by the profile node's ramp, the dancer's steps driven
    through the exact linear model: its angle agrees with scipy's lsim of
    G(s) = Zr^2 L i_a^2 / (2J s^2 + 2D s + Zr^2 L i_a^2) on the same staircase."""
    pieces = cam_layer(2, 512, 8, 24)
    rows = interpolate_pieces(np.zeros(len(TABLE), np.int64), pieces)
    motion = plan_segment(RAMP, rows.shape[0])
    t = motion.step_times(rows.shape[0])
    assert np.all(np.diff(t) > 0) and t[-1] == pytest.approx(motion.duration)
    _, vel, _, _ = motion.sample(np.linspace(0.0, motion.duration, 2001))
    assert vel.max() <= RAMP["v_max"] * (1 + 1e-9)  # the ramp's limit, in fork steps per s
    motor = StepperAxis(**PAPER)
    step = 2 * np.pi / (2 * 2 * PAPER["Zr"])  # a full step of the two-phase motor (rad)
    col = rows[:, DANCER.index]
    moves = np.diff(np.concatenate([[0], col]))
    ev = np.flatnonzero(moves)
    samples = np.linspace(0.0, t[-1] + 0.2, 4001)
    theta, _ = motor.linear_tracker().advance(t[ev], moves[ev] * step, samples)
    # the oracle: the commanded staircase through G(s), a sum of step responses, each from
    # scipy's state-space form of G and its matrix exponential (by eigenvectors)
    wn2 = PAPER["Zr"] ** 2 * PAPER["L"] * PAPER["i_a"] ** 2
    a_m, b_m, c_m, _ = signal.tf2ss([wn2], [2 * PAPER["J"], 2 * PAPER["D"], wn2])
    lam, vec = np.linalg.eig(a_m)
    left = c_m @ np.linalg.solve(a_m, vec)  # C A^-1 V
    right = np.linalg.solve(vec, b_m)[:, 0]  # V^-1 B
    tau = samples[None, :] - t[ev][:, None]  # (events, samples)
    e = np.exp(lam[None, None, :] * np.maximum(tau, 0.0)[:, :, None])  # e^(lambda tau)
    unit = (np.einsum("k,esk,k->es", left[0], e, right) - (left @ right)[0]).real  # C A^-1 (e^(A tau) - I) B
    want = ((tau >= 0) * unit * (moves[ev] * step)[:, None]).sum(axis=0)
    assert np.max(np.abs(theta - want)) < 1e-9 * step * max(1, np.abs(col).max())  # 2e-14 seen
    assert abs(theta[-1]) < 0.05 * step  # the arm back where it started, at rest
