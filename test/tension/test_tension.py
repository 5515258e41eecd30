"""winder.tension against independent references: scipy's matrix
exponential and its linear simulation (lsim interpolates the input linearly
between samples, as the first-order hold here does), transfer functions
derived by hand from the tensioners' equations, steady states and the
published figures of magnet wire."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg
import scipy.signal
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from winder.errors import BadInputError
from winder.motion.material import MATERIALS, Wire
from winder.motion.takeup import Contour
from winder.tension.lti import Discrete, expm, periodic_orbit
from winder.tension.predict import Bounds, fastest_within, predict_layer
from winder.tension.tensioner import Tensioner, tensioner_of

COPPER = MATERIALS["copper"]


#: entries of the random matrices: 0 or at least 1e-9 in size. scipy's expm works a triangular
#: matrix's off-diagonal terms out as (e^a - e^b) / (a - b), and with a = 1.5e-166, b = 0 it gave 0
#: where e^A holds 1 (a fresh-clone run found it; winder's expm had 1)
ENTRIES = st.floats(-50, 50).map(lambda x: x if abs(x) >= 1e-9 else 0.0)


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 6).flatmap(lambda n: arrays(np.float64, (n, n), elements=ENTRIES)))
def test_expm_is_scipys(a: np.ndarray) -> None:
    want = scipy.linalg.expm(a)
    # norm-wise: both are exact to a few ulps of the result's norm times the squarings' growth
    assert np.linalg.norm(expm(a) - want) <= 1e-9 * max(1.0, float(np.linalg.norm(want)))


def test_expm_of_a_triangular_matrix_is_its_closed_form() -> None:
    """The case scipy got wrong: [[a, 1], [0, b]] has e^A = [[e^a, (e^a - e^b)/(a - b)], [0, e^b]],
    1 in the corner as a -> b = 0 (worked with expm1 to keep its digits)."""
    for a in (1.5e-166, 1e-12, 0.3, -2.0):
        want = np.array([[math.exp(a), math.expm1(a) / a], [0.0, 1.0]])
        assert np.allclose(expm(np.array([[a, 1.0], [0.0, 0.0]])), want, rtol=1e-14, atol=0)


def servo(k: float = 3e4, fb: float = 30.0) -> Tensioner:
    return Tensioner("servo", k, 5.0, bandwidth=fb)


def dancer(k: float = 3e4) -> Tensioner:
    return Tensioner("dancer", k, 5.0)


@settings(max_examples=30, deadline=None)
@given(
    st.sampled_from([("servo", "driven"), ("dancer", "driven"), ("dancer", "braked")]),
    st.floats(1e2, 1e5),
    st.floats(1e-4, 2e-3),
    st.data(),
)
def test_stepping_is_scipys_lsim_with_a_linear_input(
    kinds: tuple[str, str], k: float, h: float, data: st.DataObject
) -> None:
    t = Tensioner(kinds[0], k, 5.0, supply=kinds[1])
    a, b, c, d = t.matrices()
    u = np.array(data.draw(st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=60)))
    x0 = np.array(data.draw(st.lists(st.floats(-1e-3, 1e-3), min_size=a.shape[0], max_size=a.shape[0])))
    times = h * np.arange(u.size)
    _, y_ref, x_ref = scipy.signal.lsim((a, b[:, None], c, d[:, None]), u, times, X0=x0)
    xs, ys = Discrete(a, b, c, d, h).run(x0, u)
    # two exact discretisations in floating point: a stiff span (a dancer's 500 Hz and more at
    # 1 ms steps) leaves them 1e-9 of the largest value apart
    scale = max(1.0, float(np.abs(x_ref).max()))
    assert np.allclose(xs, x_ref, rtol=1e-7, atol=1e-8 * scale)
    assert np.allclose(ys, y_ref, rtol=1e-7, atol=1e-8 * max(1.0, float(np.abs(y_ref).max())))


def test_a_steady_wind_holds_the_set_tension_and_the_arm_centred() -> None:
    for t in (servo(), dancer(), Tensioner("dancer", 3e4, 5.0, supply="braked")):
        sys_ = Discrete(*t.matrices(), 1e-3)
        x0 = t.steady(0.7)
        xs, ys = sys_.run(x0, np.full(500, 0.7))
        assert np.allclose(xs, x0, rtol=0, atol=1e-9 * max(1.0, float(np.abs(x0).max())))
        assert np.allclose(ys[:, 0], 0.0, atol=1e-9)
        if t.kind == "dancer":
            assert np.allclose(ys[:, 1], 0.0, atol=1e-12)  # the arm at its centre
        else:
            assert np.allclose(ys[:, 1], 0.7, rtol=1e-9)  # the feeder feeds what the coil takes


@settings(max_examples=20, deadline=None)
@given(st.floats(1e3, 1e5), st.floats(1.0, 100.0), st.floats(1.0, 300.0))
def test_servo_ripple_is_its_transfer_function(k: float, fb: float, f_in: float) -> None:
    """A sinusoidal take-up speed: the periodic tension swings by |H(jw)| times
    it, H(s) = K s / (s^2 + K g s + K g w_i) with g = w_b / K, w_i = w_b / 4
    (from e' = K (v - g e - g w_i z), z' = e)."""
    t = servo(k, fb)
    w = 2 * math.pi * f_in
    n = 4096
    period = 1 / f_in
    u = 0.1 * np.sin(2 * math.pi * np.arange(n) / n)
    sys_ = Discrete(*t.matrices(), period / n)
    _, ys = sys_.run(periodic_orbit(sys_, u), np.append(u, u[0]))
    wb = 2 * math.pi * fb
    h = abs(k * 1j * w / ((1j * w) ** 2 + wb * 1j * w + wb * wb / 4))
    assert math.isclose((ys[:, 0].max() - ys[:, 0].min()) / 2, 0.1 * h, rel_tol=2e-3)


def test_periodic_orbit_comes_back_and_is_where_a_long_run_settles() -> None:
    t = dancer(2e4)
    n = 512
    u = 0.3 + 0.05 * np.cos(4 * math.pi * np.arange(n) / n) ** 3
    sys_ = Discrete(*t.matrices(), 0.2 / n)
    x0 = periodic_orbit(sys_, u)
    xs, _ = sys_.run(x0, np.append(u, u[0]))
    assert np.allclose(xs[-1], x0, rtol=1e-9, atol=1e-12)
    x = t.steady(0.3)
    for _ in range(200):  # 40 s of it, from a steady wind: every transient gone
        xs, _ = sys_.run(x, np.append(u, u[0]))
        x = xs[-1]
    assert np.allclose(x, x0, rtol=1e-6, atol=1e-9)


def test_the_published_figures_of_magnet_wire() -> None:
    """Winding-tension charts: about 10 000 psi of the bare copper section; AWG 30
    (0.254 mm) 3.49 N, AWG 42 (0.0635 mm) 0.218 N; 4 MPa of whirl at 30 m/s;
    +2 % resistance for 1 % stretch."""
    assert math.isclose(COPPER.yield_stress, 10_000 * 6894.757, rel_tol=1e-3)
    assert math.isclose(Wire(COPPER, 0.254e-3).max_tension, 3.49, rel_tol=2e-3)
    assert math.isclose(Wire(COPPER, 0.0635e-3).max_tension, 0.218, rel_tol=3e-3)
    wire = Wire(COPPER, 0.254e-3)
    assert math.isclose(wire.whirl_stress(30.0), 4.0e6, rel_tol=1e-2)
    one_percent = COPPER.yield_stress + 0.01 * COPPER.hardening
    assert math.isclose(wire.resistance_rise(one_percent), 0.0201, rel_tol=1e-9)
    assert wire.plastic_strain(COPPER.yield_stress * 0.99) == 0.0
    assert MATERIALS["aluminium"].yield_stress < COPPER.yield_stress
    assert MATERIALS["aluminium"].density < COPPER.density


def test_a_round_core_sees_no_ripple_and_a_flat_bobbin_needs_a_slower_flyer() -> None:
    wire = Wire(COPPER, 0.45e-3)
    t = tensioner_of({"tensioner.kind": "servo"}, wire.stiffness_per_length, wire.max_tension / 2)
    got = predict_layer(Contour(0.02, 0.02, 0.01), 0.05, 30.0, t, wire)
    assert math.isclose(got.peak, t.set_tension, rel_tol=1e-9) and math.isclose(
        got.minimum, t.set_tension, rel_tol=1e-9
    )
    bounds = Bounds(t.set_tension, 0.4, wire.max_tension)
    flat = Contour(0.09, 0.01, 0.0)
    fast = predict_layer(flat, 0.06, 30.0, t, wire)
    assert fast.breach(bounds, wire)  # the 9:1 bobbin at 30 rad/s: out of the band
    ok = fastest_within(flat, 0.06, 30.0, t, wire, bounds)
    assert 0 < ok < 30.0
    assert not predict_layer(flat, 0.06, ok, t, wire).breach(bounds, wire)
    assert predict_layer(flat, 0.06, ok * 1.01, t, wire).breach(bounds, wire)


def test_tensioner_settings_are_read_by_name_with_defaults() -> None:
    t = tensioner_of({"tensioner.span": 2.0, "other": 1}, 100.0, 3.0)
    assert t.kind == "dancer" and t.stiffness == 50.0 and t.set_tension == 3.0
    with pytest.raises(BadInputError, match=r"tensioner\.kind='nope' is invalid"):
        Tensioner("nope", 1.0, 1.0).matrices()  # only the two kinds
