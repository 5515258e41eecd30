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
