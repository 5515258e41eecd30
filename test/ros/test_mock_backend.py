"""winder.ros.mock_backend.MockBackend, the drive a driver author copies: it
follows a held command exactly as a first-order lag does (closed form
``x(t) = c + (x0 - c) e^{-t/lag}``), at once with no lag; and the
:class:`winder.ros.driver.Backend` protocol asks of a driver only what the
docs say. (The node around it runs the whole cell contract in
test/contract/test_conformance.py, paced and as fast as possible.)"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from winder.motion.axes import AXIS_TABLE
from winder.ros.driver import Backend, RunStart
from winder.ros.mock_backend import MockBackend


def started(lag: float, start: list[int]) -> MockBackend:
    mock = MockBackend()
    run = RunStart("j", "r", AXIS_TABLE, (1e-4, 0.01, 0.01), np.array(start, np.int64), 10, {"lag": lag})
    mock.begin(run)
    return mock


@given(
    st.floats(1e-4, 5.0),
    st.lists(st.integers(-(10**6), 10**6), min_size=3, max_size=3),
    st.lists(st.integers(-(10**6), 10**6), min_size=3, max_size=3),
    st.lists(st.floats(0.0, 2.0), min_size=1, max_size=8),
)
def test_a_held_command_is_followed_as_a_first_order_lag(
    lag: float, start: list[int], command: list[int], reads: list[float]
) -> None:
    mock = started(lag, start)
    t_write = 1_000_000
    mock.write(t_write, np.array([[t_write, 0, *command]], np.int64))
    for dt in sorted(reads):  # read at any times after the write: the same curve
        t = t_write + round(dt * 1e9)
        got = mock.read(t)
        for x0, c, x in zip(start, command, got, strict=True):
            want = c + (x0 - c) * math.exp(-(t - t_write) / 1e9 / lag)
            assert math.isclose(x, want, rel_tol=1e-9, abs_tol=1e-9 * (abs(c) + abs(x0) + 1))


@given(
    st.floats(1e-3, 1.0),
    st.integers(-1000, 1000),
    st.integers(-1000, 1000),
    st.integers(-1000, 1000),
    st.lists(st.integers(1, 10**9), min_size=3, max_size=3),
)
def test_each_row_is_a_step_of_the_command_at_its_own_time(
    lag: float, x0: int, c1: int, c2: int, gaps: list[int]
) -> None:
    """Two rows handed over in one write, at t1 and t2, read at t3: the lag
    followed the start until t1, c1 until t2, c2 until t3 (not one jump at the write)."""
    t1 = gaps[0]
    t2, t3 = t1 + gaps[1], t1 + gaps[1] + gaps[2]
    mock = started(lag, [x0, 0, 0])
    mock.write(t2, np.array([[t1, 0, c1, 0, 0], [t2, 0, c2, 0, 0]], np.int64))
    x2 = c1 + (x0 - c1) * math.exp(-(t2 - t1) / 1e9 / lag)
    x3 = c2 + (x2 - c2) * math.exp(-(t3 - t2) / 1e9 / lag)
    assert math.isclose(mock.read(t3)[0], x3, rel_tol=1e-9, abs_tol=1e-9 * 3000)


def test_without_a_lag_the_axes_are_where_they_are_told() -> None:
    mock = started(0.0, [5, 6, 7])
    assert list(mock.read(0)) == [5, 6, 7]
    mock.write(10, np.array([[5, 0, 1, 2, 3], [10, 0, 2, 3, 4]], np.int64))
    assert list(mock.read(10)) == [2, 3, 4]
    assert mock.status() == {"commands_written": 1}


def test_a_backend_of_three_methods_gets_the_rest() -> None:
    """begin, write and read, inherited from Backend: the defaults a DriverNode calls are there."""

    class Three(Backend):
        def begin(self, run: RunStart) -> dict[str, object]:
            return {}

        def write(self, t_ns: int, rows: np.ndarray) -> None:
            pass

        def read(self, t_ns: int) -> np.ndarray:
            return np.zeros(3)

    drive = Three()
    assert isinstance(drive, Backend) and isinstance(MockBackend(), Backend)
    assert not isinstance(object(), Backend)
    assert (drive.paces({}), drive.missing(), drive.fault(), drive.status(), drive.end()) == (
        True, "", "", {}, None
    )  # fmt: skip
    assert Three.specs == {}
