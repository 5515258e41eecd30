"""Input shapers (winder.shaping) against the published closed forms, written
out again here, and against simulation: the closed-form step response of an
underdamped second-order mode, superposed over the impulse train, must not
ring after the last impulse at the design point (ZV, MZV, ZVD exactly; EI and
2-hump EI within their tolerance), and its ringing elsewhere is what
:func:`residual` says. scipy's lsim cross-checks the closed-form response."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from winder.shaping import KINDS, V_TOL, duration, residual, shaper


def closed_form(kind: str, f: float, z: float, v: float = V_TOL) -> tuple[list[float], list[float]]:
    r = math.sqrt(1 - z * z)
    k = math.exp(-z * math.pi / r)
    td = 1 / (f * r)
    if kind == "zv":
        a, t = [1, k], [0, td / 2]
    elif kind == "zvd":
        a, t = [1, 2 * k, k * k], [0, td / 2, td]
    elif kind == "mzv":
        k2 = math.exp(-0.75 * z * math.pi / r)
        a, t = (
            [1 - 1 / math.sqrt(2), (math.sqrt(2) - 1) * k2, (1 - 1 / math.sqrt(2)) * k2**2],
            [0, 0.375 * td, 0.75 * td],
        )
    elif kind == "ei":
        a, t = [(1 + v) / 4, (1 - v) / 2 * k, (1 + v) / 4 * k * k], [0, td / 2, td]
    else:
        x = (v * v * (math.sqrt(1 - v * v) + 1)) ** (1 / 3)
        a1 = (3 * x * x + 2 * x + 3 * v * v) / (16 * x)
        a, t = [a1, (0.5 - a1) * k, (0.5 - a1) * k * k, a1 * k**3], [0, td / 2, td, 1.5 * td]
    s = sum(a)
    return [x / s for x in a], t


def step_response(t: np.ndarray, f: float, z: float) -> np.ndarray:
    """Unit step response of w^2 / (s^2 + 2 z w s + w^2), 0 before t = 0."""
    w = 2 * math.pi * f
    wd = w * math.sqrt(1 - z * z)
    tt = np.maximum(t, 0.0)
    y = 1 - np.exp(-z * w * tt) * (np.cos(wd * tt) + z / math.sqrt(1 - z * z) * np.sin(wd * tt))
    return np.where(t >= 0, y, 0.0)


def ringing_after(
    amps: list[float] | np.ndarray, times: list[float] | np.ndarray, f: float, z: float
) -> float:
    """Largest |y - 1| of the shaped step response after the last impulse."""
    t = times[-1] + np.linspace(0.0, 4.0 / f, 4001)
    y = sum(a * step_response(t - ti, f, z) for a, ti in zip(amps, times, strict=True))
    return float(np.max(np.abs(y - 1)))


@pytest.mark.parametrize("kind", KINDS)
@settings(max_examples=30, deadline=None)
@given(f=st.floats(0.1, 5000.0), z=st.floats(0.0, 0.95))
def test_amplitudes_and_times_are_the_closed_forms(kind: str, f: float, z: float) -> None:
    amps, times = shaper(kind, f, z)
    a, t = closed_form(kind, f, z)
    assert amps == pytest.approx(a, rel=1e-12)
    assert times == pytest.approx(t, rel=1e-12, abs=0)
    assert abs(amps.sum() - 1.0) <= 4e-16
    assert times[0] == 0.0 and np.all(np.diff(times) > 0) and np.all(amps > 0)
    assert duration(kind, f, z) == times[-1]


@pytest.mark.parametrize("kind", KINDS)
@settings(max_examples=25, deadline=None)
@given(f=st.floats(1.0, 500.0), z=st.floats(0.0, 0.6))
def test_shaped_step_leaves_no_ringing_at_the_design_point(kind: str, f: float, z: float) -> None:
    amps, times = shaper(kind, f, z)
    # the unshaped step's ringing over the same window (from its own start)
    unshaped = ringing_after([1.0], [0.0], f, z)
    left = ringing_after(amps, times, f, z)
    if kind in ("zv", "mzv", "zvd", "2hump_ei"):
        assert left <= 1e-9 * max(unshaped, 1e-300) + 1e-12
    else:  # EI: a residual of v_tol of the unshaped vibration at the design point, by design
        assert left <= (V_TOL + 1e-9) * unshaped + 1e-12


@pytest.mark.parametrize("kind", KINDS)
@settings(max_examples=25, deadline=None)
@given(f=st.floats(1.0, 500.0), z=st.floats(0.0, 0.6), err=st.sampled_from([-0.2, -0.1, 0.1, 0.2]))
def test_residual_is_the_simulated_ringing_off_the_design_point(
    kind: str, f: float, z: float, err: float
) -> None:
    amps, times = shaper(kind, f, z)
    actual = f * (1 + err)
    # the envelope of the ringing after the last impulse, at that moment, against the unshaped one's
    w = 2 * math.pi * actual
    wd = w * math.sqrt(1 - z * z)
    tn = times[-1]
    c = sum(a * math.exp(-z * w * (tn - ti)) * math.cos(wd * ti) for a, ti in zip(amps, times, strict=True))
    s = sum(a * math.exp(-z * w * (tn - ti)) * math.sin(wd * ti) for a, ti in zip(amps, times, strict=True))
    assert float(residual(kind, f, z, actual)) == pytest.approx(math.hypot(c, s), rel=1e-9, abs=1e-15)
    # and by simulation: the shaped ringing's peak after the last impulse, over
    # the unshaped one's a whole number of periods from its start, tracks that ratio
    if z == 0.0:
        left = ringing_after(amps, times, actual, 0.0)
        assert left == pytest.approx(float(residual(kind, f, 0.0, actual)), rel=1e-3, abs=1e-9)


def test_closed_form_response_matches_scipy() -> None:
    from scipy import signal

    f, z = 44.5, 0.05
    w = 2 * math.pi * f
    t = np.linspace(0.0, 0.3, 30001)
    _, y, _ = signal.lsim(([w * w], [1.0, 2 * z * w, w * w]), np.ones_like(t), t)
    assert np.max(np.abs(y - step_response(t, f, z))) < 1e-6


def test_robustness_ranks_as_published() -> None:
    f, z = 44.5, 0.05
    at = {k: float(np.max(residual(k, f, z, [0.9 * f, 1.1 * f]))) for k in KINDS}
    assert at["zvd"] < at["zv"] and at["ei"] < at["zv"] and at["mzv"] < at["zv"]
    band = residual("ei", f, z, np.linspace(0.9 * f, 1.1 * f, 201))
    assert np.max(band) <= 0.06  # EI stays near its 5 % tolerance over +-10 %


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (("zz", 10.0, 0.1), "kind='zz'"),
        (("zv", 0.0, 0.1), "f_n=0.0"),
        (("zv", math.inf, 0.1), "f_n=inf"),
        (("zv", 10.0, 1.0), "zeta=1.0"),
        (("zv", 10.0, -0.1), "zeta=-0.1"),
        (("zv", 10.0, math.nan), "zeta=nan"),
        (("zv", "10", 0.1), "f_n='10'"),
    ],
)
def test_bad_arguments_name_the_parameter_and_the_range(args: tuple[object, ...], needle: str) -> None:
    with pytest.raises(ValueError) as err:
        shaper(*args)  # type: ignore[arg-type]
    assert needle in str(err.value) and "must be" in str(err.value)


def test_the_sensitivity_figure_is_written(tmp_path: object) -> None:
    from pathlib import Path

    from winder.analysis.figures.resonance import plot_sensitivity

    p = plot_sensitivity(44.5, 0.05, Path(str(tmp_path)) / "s.png")
    assert p.stat().st_size > 10_000 and p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
