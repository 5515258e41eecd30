"""The stepper model against oracles written here.

* linear model: the textbook step responses of a second-order system, summed
  step by step (one formula per damping case), a 60-digit ``decimal`` series of
  the same response near critical damping, ``scipy.signal.lsim``, and physics
  (final value, energy decay, no overshoot when over-damped);
* nonlinear model: ``scipy.integrate.solve_ivp`` (DOP853, rtol 1e-10) on the
  rotor equation in the absolute angle, piece by piece between steps; the
  static equilibrium under load in closed form;
* the loss of steps: the cases that must and must not slip, with S-curve and
  exponential step times computed here by bisection on their closed-form
  positions (independent of :mod:`winder.motion.profile`).
"""

from __future__ import annotations

import itertools
import math
from decimal import Decimal, localcontext

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from scipy import signal
from scipy.integrate import solve_ivp
from support.oracles import params, superpose

from winder.axis import (
    G_CM_S2,
    MODAL_ZETA,
    LinearTracker,
    LoadStep,
    StepperAxis,
    measured_velocity,
)
from winder.axis.linear import MODAL_WINDOW, _cumulative_at, _modal_terms, _sums_at
from winder.motion.profile import plan

PAPER = {"Zr": 40.0, "L": 0.01005, "i_a": 1.0, "J": 1.05 * 9.80665e-5, "D": 0.03}
FULL_STEP = 2 * math.pi / (2 * 2 * 40)  # two-phase, Z_r = 40: 2.25 deg
PITCH = 2 * math.pi / 40

# -- oracles -------------------------------------------------------------------


def decimal_step(wn: float, zeta: float, tau: float) -> tuple[float, float]:
    """s(tau), s'(tau) with 60 digits: e^(-sigma tau) and the power series of cosh / sinh
    in q = (sigma^2 - w_n^2) tau^2, valid on both sides of critical damping."""
    with localcontext() as ctx:
        ctx.prec = 60
        w, z, x = Decimal(wn), Decimal(zeta), Decimal(tau)
        sig = z * w
        q = w * w * (z * z - 1) * x * x
        c = Decimal(0)
        sh = Decimal(0)
        term = Decimal(1)  # q^n / (2n)!
        for n in range(200):
            c += term
            sh += term / (2 * n + 1)
            term = term * q / ((2 * n + 1) * (2 * n + 2))
            if abs(term) < Decimal(10) ** -70:
                break
        e = (-sig * x).exp()
        s = 1 - e * (c + sig * x * sh)
        ds = w * w * e * x * sh
        return float(s), float(ds)


def staircase(times: np.ndarray, angles: np.ndarray, t: np.ndarray) -> np.ndarray:
    order = np.argsort(times, kind="stable")
    cum = np.concatenate([[0.0], np.cumsum(angles[order])])
    return cum[np.searchsorted(times[order], t, side="right")]


def ivp_reference(
    axis_params: dict[str, float],
    times: np.ndarray,
    angles: np.ndarray,
    t: np.ndarray,
    load: LoadStep | float = 0.0,
    t_end: float | None = None,
) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Nonlinear rotor equation in the absolute angle, integrated by DOP853 piece by
    piece between steps (and the load step). Returns theta, omega at t and the
    final (theta, theta1) at t_end."""
    Zr, L, i_a, J, D = (axis_params[k] for k in ("Zr", "L", "i_a", "J", "D"))
    Tm = 0.5 * Zr * L * i_a**2
    if isinstance(load, LoadStep):
        lt, before, after = load.time, load.before, load.torque
    else:
        lt, before, after = math.inf, float(load), float(load)
    t_end = float(t[-1]) if t_end is None else t_end
    cuts = np.unique(np.concatenate([times, [lt] if lt < t_end else [], [t_end]]))
    cuts = cuts[(cuts > 0) & (cuts <= t_end)]
    th = np.full(t.size, np.nan)
    om = np.full(t.size, np.nan)
    y = np.zeros(2)
    t0 = 0.0
    for c in cuts:
        cmd = float(angles[times <= t0].sum())
        TL = after if t0 >= lt else before

        def f(_t: float, y: np.ndarray, cmd: float = cmd, TL: float = TL) -> list[float]:
            return [y[1], (-D * y[1] - Tm * math.sin(Zr * (y[0] - cmd)) - TL) / J]

        inside = (t >= t0) & (t <= c)
        at = np.unique(np.concatenate([t[inside], [c]]))
        sol = solve_ivp(f, (t0, c), y, method="DOP853", rtol=1e-10, atol=1e-13, t_eval=at)
        assert sol.success
        k = np.searchsorted(at, t[inside])
        th[inside], om[inside] = sol.y[0][k], sol.y[1][k]
        y = sol.y[:, -1]
        t0 = float(c)
    return th, om, float(y[0]), float(angles[times <= t_end].sum())


# -- step times of the three starts (computed here, not with winder.motion.profile) ----


def invert(position, n: int, step: float, t_hi: float) -> np.ndarray:
    """Times at which the increasing position(t) reaches k*step, k = 1..n (bisection)."""
    target = step * np.arange(1, n + 1)
    lo = np.zeros(n)
    hi = np.full(n, t_hi)
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        below = position(mid) < target
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    return 0.5 * (lo + hi)


def scurve_position(v_max: float, a_max: float, jerk: float):
    """Position of the paper's S-curve start (eqs. 18-23): jerk up, constant
    acceleration, jerk down to v_max, then cruise. Needs v_max >= a_max^2/jerk."""
    t1 = a_max / jerk
    v1 = 0.5 * jerk * t1**2
    t2 = (v_max - 2 * v1) / a_max
    assert t2 >= 0
    p1 = jerk * t1**3 / 6
    p2 = p1 + v1 * t2 + 0.5 * a_max * t2**2
    v2 = v1 + a_max * t2
    p3 = p2 + v2 * t1 + 0.5 * a_max * t1**2 - jerk * t1**3 / 6
    tr = 2 * t1 + t2

    def pos(t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        u2 = t - t1
        u3 = t - t1 - t2
        u4 = t - tr
        return np.select(
            [t < t1, t < t1 + t2, t < tr],
            [
                jerk * t**3 / 6,
                p1 + v1 * u2 + 0.5 * a_max * u2**2,
                p2 + v2 * u3 + 0.5 * a_max * u3**2 - jerk * u3**3 / 6,
            ],
            p3 + v_max * u4,
        )

    return pos, tr


def start_step_times(kind: str, v_max: float, step: float, duration: float) -> np.ndarray:
    """Step times of a start to v_max over [0, duration]: 'none', 'exp' or 'scurve'."""
    if kind == "none":
        n = int(v_max * duration / step)
        return step * np.arange(1, n + 1) / v_max
    if kind == "exp":
        tau = 1 / 0.85

        def pos(t: np.ndarray) -> np.ndarray:
            return v_max * (t + tau * np.expm1(-t / tau))

    else:
        pos, _ = scurve_position(v_max, 4.0, 4.0)
    n = int(pos(np.array([duration]))[0] / step)
    return invert(pos, n, step, duration)


def profile_step_times(kind: str, v_max: float, step: float, duration: float) -> np.ndarray:
    """Step times of a start to v_max over [0, duration] from :func:`winder.motion.profile.plan`
    (a move long enough to cruise past ``duration``), cut at ``duration``."""
    if kind == "none":
        return start_step_times("none", v_max, step, duration)
    n = math.ceil(2 * v_max * duration / step)
    distance = n * step  # so that step k is at k*step
    if kind == "scurve":
        prof = plan("scurve", distance, v_max=v_max, a_max=4.0, j_max=4.0)
    else:
        prof = plan("exponential", distance, v_max=v_max, tau=1 / 0.85)
    times = prof.step_times(n)
    return times[times <= duration]


def test_profile_s_curve_step_times_agree_with_the_closed_form_here() -> None:
    """The S-curve start of winder.motion.profile is the paper's (eqs. 18-23)."""
    step = FULL_STEP / 16
    ours = start_step_times("scurve", 20.0, step, 6.5)
    theirs = profile_step_times("scurve", 20.0, step, 6.5)
    n = min(ours.size, theirs.size)
    assert abs(ours.size - theirs.size) <= 1
    np.testing.assert_allclose(theirs[:n], ours[:n], rtol=0, atol=1e-9)


# -- construction ----------------------------------------------------------------


def test_paper_parameters_and_derived_quantities() -> None:
    ax = StepperAxis.paper()
    assert (ax.Zr, ax.L, ax.i_a, ax.D) == (40.0, 0.01005, 1.0, 0.03)
    assert pytest.approx(1.0297e-4, rel=1e-4) == ax.J
    assert pytest.approx(1.05 * 9.80665e-5, rel=1e-15) == ax.J
    assert pytest.approx(1.0297e-4, rel=1e-4) == 1.05 * G_CM_S2
    assert math.degrees(ax.full_step) == pytest.approx(2.25, rel=1e-14)
    assert ax.tooth_pitch == pytest.approx(PITCH, rel=1e-15)
    assert ax.steps_per_pitch == 4
    assert ax.peak_torque == pytest.approx(0.201, rel=1e-14)
    wn, zeta, K = params(**PAPER)
    assert ax.natural_frequency == pytest.approx(wn, rel=1e-14)
    assert ax.damping_ratio == pytest.approx(zeta, rel=1e-14)
    assert ax.stiffness == pytest.approx(K, rel=1e-14)
    assert ax.pull_out_speed == pytest.approx(0.201 / 0.03, rel=1e-14)
    assert StepperAxis(**PAPER) == ax


@pytest.mark.parametrize("name", ["Zr", "L", "i_a", "J", "D"])
@pytest.mark.parametrize("bad", [-1.0, math.nan, math.inf, "x", None])
def test_invalid_parameters_rejected_with_name_and_range(name: str, bad: object) -> None:
    with pytest.raises(ValueError, match=rf"^{name}=.*must be finite and >=? 0") as err:
        StepperAxis(**{**PAPER, name: bad})  # type: ignore[arg-type]
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("name", ["Zr", "L", "i_a", "J"])
def test_zero_rejected_except_damping(name: str) -> None:
    with pytest.raises(ValueError, match=rf"^{name}=0.0 is invalid: must be finite and > 0"):
        StepperAxis(**{**PAPER, name: 0.0})
    assert StepperAxis(**{**PAPER, "D": 0.0}).damping_ratio == 0.0


def test_transfer_function_is_the_papers_eq_13() -> None:
    num, den = StepperAxis.paper().transfer_function
    k2 = 40**2 * 0.01005 * 1.0**2
    np.testing.assert_allclose(num, [k2], rtol=1e-15)
    np.testing.assert_allclose(den, [2 * 1.05 * 9.80665e-5, 2 * 0.03, k2], rtol=1e-15)


positive = st.floats(1e-3, 1e3)


@given(Zr=st.floats(1, 500), L=positive, i_a=positive, J=st.floats(1e-8, 1e2), D=st.floats(0, 1e3))
def test_transfer_function_hypothesis(Zr: float, L: float, i_a: float, J: float, D: float) -> None:
    ax = StepperAxis(Zr, L, i_a, J, D)
    num, den = ax.transfer_function
    k2 = Zr * Zr * L * i_a * i_a
    np.testing.assert_allclose(num, [k2], rtol=1e-14)
    np.testing.assert_allclose(den, [2 * J, 2 * D, k2], rtol=1e-14)
    # G(0) = 1 and the poles are those of the error dynamics
    assert num[0] / den[-1] == pytest.approx(1.0, rel=1e-14)
    wn, zeta, _ = params(Zr, L, i_a, J, D)
    assert ax.natural_frequency == pytest.approx(wn, rel=1e-13)
    assert ax.damping_ratio == pytest.approx(zeta, rel=1e-13)


# -- linear response ---------------------------------------------------------------


def damped(zeta: float) -> StepperAxis:
    """The paper's motor with the damping that gives ``zeta``."""
    _, _, K = params(**PAPER)
    return StepperAxis.paper(D=2 * zeta * math.sqrt(K * PAPER["J"]))


@pytest.mark.parametrize("zeta", [0.0, 0.05, 0.5213, 0.9, 1.0, 1.3, 5.0, 40.0])
def test_linear_matches_superposed_step_responses(zeta: float) -> None:
    ax = damped(zeta) if zeta != 0.5213 else StepperAxis.paper()
    rng = np.random.default_rng(7)
    wn, z, _ = params(ax.Zr, ax.L, ax.i_a, ax.J, ax.D)
    if zeta == 1.0:
        z = 1.0  # the critical formula (the axis' zeta may be 1 +- 1 ulp)
    n = 150
    times = np.sort(rng.uniform(0.0, 0.3, n))
    times[10] = times[9]  # two steps at the same instant
    angles = rng.choice([-1.0, 1.0, 2.0], n) * FULL_STEP
    t = np.concatenate([np.linspace(-0.01, 0.4, 3000), times[:20]])  # incl. samples at steps
    th, om = ax.response(times, angles, t, velocity=True)
    th_ref, om_ref = superpose(wn, z, times, angles, t)
    total = np.abs(angles).sum()
    assert np.max(np.abs(th - th_ref)) <= 1e-9 * total
    assert np.max(np.abs(om - om_ref)) <= 1e-9 * total * wn
    assert np.all(th[t < times[0]] == 0.0)


@pytest.mark.parametrize("delta", [-1e-4, -1e-7, -1e-10, -1e-13, 0.0, 1e-13, 1e-10, 1e-7, 1e-4])
def test_near_critical_has_no_cancellation(delta: float) -> None:
    """zeta = 1 + delta against a 60-digit series of the response, continuous at zeta = 1."""
    ax = damped(1.0 + delta)
    wn = ax.natural_frequency
    zeta = ax.damping_ratio
    tau = np.concatenate([np.geomspace(1e-6, 60, 40) / wn, [0.0]])
    th, om = ax.response([0.0], 1.0, tau, velocity=True)
    ref = np.array([decimal_step(wn, zeta, x) for x in tau])
    np.testing.assert_allclose(th, ref[:, 0], rtol=0, atol=1e-14)
    np.testing.assert_allclose(om, ref[:, 1], rtol=0, atol=1e-14 * wn)


def test_linear_against_lsim_on_the_grid_and_off_it() -> None:
    ax = StepperAxis.paper()
    num, den = ax.transfer_function
    sys = signal.lti(num, den)
    dt = 1e-5
    grid = np.arange(0, 0.3 + dt / 2, dt)
    # steps on grid points: lsim's zero-order hold is exact there
    k = np.arange(1, 120) * 157
    times = grid[k]
    angles = np.where(np.arange(k.size) < 60, 1.0, -1.0) * FULL_STEP
    u = staircase(times, angles, grid)
    _, y, _ = signal.lsim(sys, u, grid, interp=False)
    th = ax.response(times, angles, grid)
    assert np.max(np.abs(th - y)) <= 1e-8 * FULL_STEP
    # steps off the grid: lsim holds them until the next grid point (approximate)
    times_off = times + 0.37 * dt
    th_off = ax.response(times_off, angles, grid)
    _, y_off, _ = signal.lsim(sys, staircase(times_off, angles, grid), grid, interp=False)
    err = np.max(np.abs(th_off - y_off))
    assert err <= 2 * FULL_STEP * ax.natural_frequency * dt
    assert err > 1e-9 * FULL_STEP  # and it is lsim that is off: see the superposition tests


wide = st.tuples(
    st.floats(1, 200),  # Zr
    st.floats(1e-4, 1.0),  # L
    st.floats(0.05, 10.0),  # i_a
    st.floats(1e-7, 1e-1),  # J
)


@st.composite
def axis_and_train(draw: st.DrawFn) -> tuple[StepperAxis, np.ndarray, np.ndarray, np.ndarray]:
    Zr, L, i_a, J = draw(wide)
    _, _, K = params(Zr, L, i_a, J, 0.0)
    zeta = draw(st.one_of(st.floats(0.0, 0.999), st.floats(1.001, 50.0), st.just(1.0)))
    D = 2 * zeta * math.sqrt(K * J)
    ax = StepperAxis(Zr, L, i_a, J, D)
    wn = ax.natural_frequency
    n = draw(st.integers(1, 120))
    gaps = np.array(draw(st.lists(st.floats(0.0, 5.0), min_size=n, max_size=n)))
    times = (np.cumsum(gaps) - 1.0) / wn  # normalised to the axis' dynamics, some < 0
    signs = np.array(draw(st.lists(st.sampled_from([-3.0, -1.0, 1.0, 2.0]), min_size=n, max_size=n)))
    step = draw(st.floats(1e-4, 1.0))
    m = draw(st.integers(1, 300))
    t = np.sort(np.array(draw(st.lists(st.floats(-2.0, 2.0 + 6 * n), min_size=m, max_size=m)))) / wn
    return ax, times, signs * step, t


@settings(max_examples=250, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(axis_and_train())
def test_linear_hypothesis_against_superposition(
    case: tuple[StepperAxis, np.ndarray, np.ndarray, np.ndarray],
) -> None:
    ax, times, angles, t = case
    wn, zeta, _ = params(ax.Zr, ax.L, ax.i_a, ax.J, ax.D)
    if abs(zeta - 1.0) < 1e-6:
        zeta = 1.0
    th, om = ax.response(times, angles, t, velocity=True)
    th_ref, om_ref = superpose(wn, zeta, times, angles, t)
    total = np.abs(angles).sum()
    assert np.max(np.abs(th - th_ref), initial=0.0) <= 1e-9 * total
    assert np.max(np.abs(om - om_ref), initial=0.0) <= 1e-9 * total * wn


def test_response_order_of_inputs_does_not_matter() -> None:
    ax = StepperAxis.paper()
    rng = np.random.default_rng(3)
    times = rng.uniform(0, 0.2, 200)
    angles = rng.normal(size=200) * FULL_STEP
    t = rng.uniform(-0.01, 0.3, 500)
    th = ax.response(times, angles, t)
    sorted_t = np.sort(t)
    o = np.argsort(times)
    th2 = ax.response(times[o], angles[o], sorted_t)
    np.testing.assert_allclose(np.sort(t), sorted_t)
    np.testing.assert_allclose(th[np.argsort(t)], th2, rtol=0, atol=1e-15 * np.abs(angles).sum())


@st.composite
def chunked(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[int], list[int]]:
    n = draw(st.integers(0, 400))
    m = draw(st.integers(1, 400))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    times = np.sort(rng.uniform(0, 0.5, n))
    if n > 4:
        times[3] = times[2]
    t = np.sort(np.concatenate([rng.uniform(-0.01, 0.6, m), times[: min(n, 5)]]))
    angles = rng.choice([-1.0, 1.0], n) * FULL_STEP
    cuts = sorted(draw(st.lists(st.floats(-0.02, 0.62), max_size=8)))
    # chunk by time: call i gets the steps and samples in [cut_{i-1}, cut_i)
    sc = [int(np.searchsorted(times, c, side="left")) for c in cuts]
    tc = [int(np.searchsorted(t, c, side="left")) for c in cuts]
    return times, angles, t, sc, tc


@settings(max_examples=150, deadline=None)
@given(chunked(), st.booleans())
def test_linear_tracker_chunked_equals_one_shot(case, steps_early: bool) -> None:
    times, angles, t, sc, tc = case
    ax = StepperAxis.paper(D=0.01)
    th1, om1 = ax.response(times, angles, t, velocity=True)
    tr = ax.linear_tracker()
    ths, oms = [], []
    s_edges = [0, *sc, times.size]
    t_edges = [0, *tc, t.size]
    done = 0  # steps delivered so far
    for i in range(len(t_edges) - 1):
        # in order: the steps of this chunk; early: also those of the next chunk
        upto = s_edges[min(i + (2 if steps_early else 1), len(s_edges) - 1)]
        th, om = tr.advance(times[done:upto], angles[done:upto], t[t_edges[i] : t_edges[i + 1]])
        done = upto
        ths.append(th)
        oms.append(om)
    total = np.abs(angles).sum() + 1.0
    np.testing.assert_allclose(np.concatenate(ths), th1, rtol=0, atol=1e-12 * total)
    np.testing.assert_allclose(np.concatenate(oms), om1, rtol=0, atol=1e-12 * total * 300)


def test_tracker_rejects_out_of_order_input() -> None:
    tr = StepperAxis.paper().linear_tracker()
    tr.advance([0.0, 0.1], FULL_STEP, [0.05, 0.2])
    with pytest.raises(ValueError, match=r"^step_times\[0\]=0.15 is invalid: must be >= the last sample"):
        tr.advance([0.15], FULL_STEP, [0.3])
    with pytest.raises(ValueError, match=r"^t_samples\[0\]=0.1 is invalid"):
        tr.advance([], FULL_STEP, [0.1])
    with pytest.raises(ValueError, match="not sorted"):
        tr.advance([0.5, 0.4], FULL_STEP, [0.6])
    with pytest.raises(ValueError, match="one angle per step"):
        tr.advance([0.5, 0.6], [FULL_STEP] * 3, [0.7])
    # a step at exactly the last returned sample time is applied after it
    th, _ = tr.advance([0.2], FULL_STEP, [0.2, 0.2 + 1e-9])
    assert th[0] == pytest.approx(th[1], abs=1e-6)


@pytest.mark.parametrize("zeta", [0.0, 0.05, 0.5213, 0.94])
def test_modal_sum_over_many_windows_matches_superposition(zeta: float) -> None:
    """Below MODAL_ZETA the tracker sums modal terms in windows of 30/sigma s
    (0.21 s for the paper's motor): a 3 s train with pauses longer than a
    window, fed in uneven chunks, against the textbook superposition."""
    ax = damped(zeta) if zeta != 0.5213 else StepperAxis.paper()
    wn, z, _ = params(ax.Zr, ax.L, ax.i_a, ax.J, ax.D)
    rng = np.random.default_rng(5)
    bursts = [np.sort(rng.uniform(a, a + 0.15, 120)) for a in (0.0, 0.1, 0.9, 1.0, 2.7)]
    times = np.concatenate(bursts)
    times.sort()
    angles = rng.choice([-1.0, 1.0], times.size) * FULL_STEP
    t = np.sort(np.concatenate([np.linspace(-0.05, 3.2, 700), times[::37]]))
    th_ref, om_ref = superpose(wn, z, times, angles, t)
    tr = ax.linear_tracker()
    ths, oms = [], []
    for lo, hi in [(-math.inf, 0.05), (0.05, 0.95), (0.95, 0.951), (0.951, math.inf)]:
        th, om = tr.advance(
            times[(times >= lo) & (times < hi)], angles[(times >= lo) & (times < hi)], t[(t >= lo) & (t < hi)]
        )
        ths.append(th)
        oms.append(om)
    total = np.abs(angles).sum()
    np.testing.assert_allclose(np.concatenate(ths), th_ref, rtol=0, atol=1e-11 * total)
    np.testing.assert_allclose(np.concatenate(oms), om_ref, rtol=0, atol=1e-11 * total * wn)


@st.composite
def modal_case(draw: st.DrawFn) -> tuple[StepperAxis, np.ndarray, np.ndarray, np.ndarray, list[float]]:
    zeta = draw(st.floats(0.0, MODAL_ZETA, exclude_max=True))
    wn = draw(st.floats(1.0, 1e4))
    _, _, K = params(**PAPER)
    J = K / wn**2
    ax = StepperAxis(PAPER["Zr"], PAPER["L"], PAPER["i_a"], J, 2 * zeta * math.sqrt(K * J))
    # zeta just under the bound can come back from D as the bound itself (rounding)
    assume(ax.damping_ratio < MODAL_ZETA)
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    n = draw(st.integers(0, 3000))
    span = draw(st.floats(1e-3, 200.0)) / wn  # up to ~30 windows at zeta = 0.95
    times = np.sort(rng.uniform(0, span, n))
    angles = rng.choice([-1.0, 1.0], n) * draw(st.floats(1e-6, 1.0))
    t = np.sort(rng.uniform(-0.1 * span, 1.2 * span, draw(st.integers(1, 300))))
    cuts = sorted(draw(st.lists(st.floats(0.0, 1.0), max_size=5)))
    return ax, times, angles, t, [c * span for c in cuts]


@settings(max_examples=200, deadline=None)
@given(modal_case())
def test_modal_and_scan_trackers_agree(case) -> None:
    """The two exact methods, independent in their arithmetic (complex modal
    sums vs the real transition-matrix scan), on wide random trains."""
    ax, times, angles, t, cuts = case
    out = {}
    for method in ("modal", "scan"):
        tr = LinearTracker(ax, method)
        parts = []
        edges = [-math.inf, *cuts, math.inf]
        for lo, hi in itertools.pairwise(edges):
            m, w = (times >= lo) & (times < hi), (t >= lo) & (t < hi)
            parts.append(tr.advance(times[m], angles[m], t[w]))
        out[method] = (np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]))
    total = np.abs(angles).sum() + abs(float(angles[0])) if angles.size else 1.0
    wn = ax.natural_frequency
    np.testing.assert_allclose(out["modal"][0], out["scan"][0], rtol=0, atol=1e-11 * total)
    np.testing.assert_allclose(out["modal"][1], out["scan"][1], rtol=0, atol=1e-11 * total * wn)


@settings(max_examples=300, deadline=None)
@given(
    st.floats(0.0, 1e4),
    st.floats(1e-3, 1e5),
    st.integers(0, 5000),
    st.floats(1e-4, 1e3),
    st.integers(0, 2**32 - 1),
)
def test_modal_terms_equal_the_complex_exp(sigma: float, wd: float, n: int, span: float, seed: int) -> None:
    """The modal sum's terms a*exp(lambda*d) (phase table and Taylor series,
    or the complex exp for a wide phase range) against numpy's complex exp of
    the same rounded argument: within a few ulps of each term."""
    rng = np.random.default_rng(seed)
    lam = complex(-sigma, wd)
    width = min(span, MODAL_WINDOW / sigma) if sigma > 0 else span
    d = -np.sort(rng.uniform(0.0, width, n))
    a = rng.choice([-1.0, 1.0], n) * rng.uniform(1e-6, 1.0)
    out = np.empty(n, np.complex128)
    _modal_terms(lam, d, a, out)
    arg = np.empty(n, np.complex128)
    arg.real, arg.imag = d * lam.real, d * lam.imag
    ref = np.exp(arg) * a
    np.testing.assert_allclose(out, ref, rtol=4e-15, atol=0)


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 400), st.integers(1, 50), st.booleans(), st.integers(0, 2**32 - 1))
def test_sums_at_points_equal_the_running_sum(n: int, m: int, whole: bool, seed: int) -> None:
    """The modal tracker's sums at the samples (segment sums, then their
    running sum) against the running sum over every element: exactly for
    counts of +-1, to rounding for complex terms."""
    rng = np.random.default_rng(seed)
    at = np.sort(rng.integers(0, n + 1, m))
    signs = rng.choice([-1.0, 1.0], n) if whole else rng.integers(-3, 4, n).astype(np.float64)
    ref = np.concatenate([[0.0], np.cumsum(signs)])[at]
    assert np.array_equal(_sums_at(signs, at), ref)
    z = rng.normal(size=n) + 1j * rng.normal(size=n)
    ref_z = np.concatenate([[0.0], np.cumsum(z)])[at]
    np.testing.assert_allclose(_sums_at(z, at), ref_z, rtol=0, atol=1e-13 * (np.abs(z).sum() + 1))
    if whole:  # steps of one angle: theta1 counted in integers, one rounding
        unit = 2 * math.pi / 5120
        assert np.array_equal(_cumulative_at(signs * unit, at), unit * ref)


def test_modal_method_needs_an_under_damped_axis() -> None:
    with pytest.raises(ValueError, match=r"^method='modal' needs damping ratio < 0.95"):
        LinearTracker(damped(1.0), "modal")
    with pytest.raises(ValueError, match=r"^method='fast' is invalid"):
        LinearTracker(damped(0.5), "fast")  # type: ignore[arg-type]


@pytest.mark.parametrize("zeta", [0.1, 0.5213, 1.0, 3.0])
def test_final_value_is_the_total_command(zeta: float) -> None:
    ax = damped(zeta)
    rng = np.random.default_rng(11)
    times = np.sort(rng.uniform(0, 0.1, 300))
    angles = rng.choice([-1.0, 1.0, 1.0], 300) * FULL_STEP  # reversing feed
    wn, z = ax.natural_frequency, ax.damping_ratio
    slow = wn * (z - math.sqrt(z * z - 1)) if z > 1 else z * wn
    th, om = ax.response(times, angles, [times[-1] + 60 / slow], velocity=True)
    assert th[0] == pytest.approx(angles.sum(), abs=1e-12 * np.abs(angles).sum())
    assert abs(om[0]) < 1e-12 * wn * np.abs(angles).sum()


@pytest.mark.parametrize("zeta", [0.0, 0.05, 0.5213, 1.0, 2.0])
def test_energy_of_the_error_decays_and_is_conserved_without_damping(zeta: float) -> None:
    ax = damped(zeta)
    times = np.arange(1, 40) * 2e-3
    angles = np.full(times.size, FULL_STEP)
    t = np.linspace(times[-1], times[-1] + 0.2, 4001)
    th, om = ax.response(times, angles, t, velocity=True)
    K = 0.5 * ax.Zr**2 * ax.L * ax.i_a**2
    energy = 0.5 * ax.J * om**2 + 0.5 * K * (th - angles.sum()) ** 2
    scale = energy[0]
    if zeta == 0.0:
        np.testing.assert_allclose(energy, scale, rtol=1e-10)
    else:
        assert np.all(np.diff(energy) <= 1e-12 * scale)
        # dE/dt = -D*omega^2: the energy lost over the window equals the damping work
        work = np.sum(0.5 * (om[1:] ** 2 + om[:-1] ** 2) * np.diff(t)) * ax.D
        assert energy[0] - energy[-1] == pytest.approx(work, rel=1e-4)


@pytest.mark.parametrize("zeta", [1.0, 1.0 + 1e-9, 1.5, 10.0])
def test_no_overshoot_when_over_damped(zeta: float) -> None:
    ax = damped(zeta)
    t = np.linspace(0, 100 / ax.natural_frequency * zeta, 20001)
    th, om = ax.response([0.0], FULL_STEP, t, velocity=True)
    assert np.all(th <= FULL_STEP * (1 + 1e-15))
    assert np.all(om >= -1e-15 * FULL_STEP * ax.natural_frequency)


def test_simulate_linear_is_the_response_with_the_command() -> None:
    ax = StepperAxis.paper()
    times = np.arange(1, 50) * 3e-3
    t = np.linspace(0, 0.2, 777)
    r = ax.simulate(times, FULL_STEP, t, model="linear")
    np.testing.assert_array_equal(r.theta, ax.response(times, FULL_STEP, t))
    np.testing.assert_allclose(r.command, staircase(times, np.full(49, FULL_STEP), t))
    assert r.lost_steps == 0 and r.slips.size == 0
    with pytest.raises(ValueError, match="model="):
        ax.simulate(times, FULL_STEP, t, model="quadratic")  # type: ignore[arg-type]


# -- nonlinear model ---------------------------------------------------------------


NONLINEAR_CASES = {
    "paper, 4 rad/s, full steps": (PAPER, "none", 4.0, FULL_STEP, 0.0),
    "light damping, reversing": ({**PAPER, "D": 0.003}, "rev", 3.0, FULL_STEP, 0.0),
    "paper, load step 0.1 N*m": (PAPER, "none", 2.0, FULL_STEP / 4, LoadStep(0.2, 0.1)),
    "critically damped, overspeed": (
        {**PAPER, "D": 2 * math.sqrt(8.04 * PAPER["J"])},
        "none",
        12.0,
        FULL_STEP,
        0.0,
    ),
}


@pytest.mark.parametrize("name", list(NONLINEAR_CASES))
def test_nonlinear_against_solve_ivp(name: str) -> None:
    p, kind, v, step, load = NONLINEAR_CASES[name]
    duration = 0.3
    times = start_step_times("none", v, step, duration)
    angles = np.full(times.size, step)
    if kind == "rev":
        angles[times > duration / 2] *= -1
    t = np.linspace(0, duration + 0.05, 701)
    ax = StepperAxis(**p)
    r = ax.simulate(times, angles, t, load=load)
    th, om, _, _ = ivp_reference(p, times, angles, t, load)
    scale = np.abs(angles).sum()
    assert np.max(np.abs(r.theta - th)) <= 1e-7 * scale
    assert np.max(np.abs(r.omega - om)) <= 1e-7 * scale * ax.natural_frequency
    np.testing.assert_allclose(r.command, staircase(times, angles, t))


def test_small_amplitude_nonlinear_is_the_linear_model() -> None:
    ax = StepperAxis.paper()
    a = 1e-4 * PITCH  # sin(x) = x (1 - x^2/6): relative difference ~ (Zr*a)^2 / 6
    times = np.arange(1, 30) * 1e-3
    angles = a * np.where(np.arange(29) % 7 < 4, 1.0, -1.0)
    t = np.linspace(0, 0.1, 1001)
    nl = ax.simulate(times, angles, t)
    lin = ax.response(times, angles, t)
    err = np.max(np.abs(nl.theta - lin))
    amp = np.max(np.abs(lin)) + np.max(np.abs(nl.error))
    assert err <= 1e-6 * amp
    assert nl.lost_steps == 0


def test_nonlinear_tracker_chunked_equals_one_shot() -> None:
    ax = StepperAxis.paper(D=0.003)
    times = start_step_times("none", 25.0, FULL_STEP, 0.2)  # overspeed: it slips
    t = np.linspace(0, 0.25, 500)
    one = ax.simulate(times, FULL_STEP, t, load=LoadStep(0.1, 0.05))
    tr = ax.nonlinear_tracker(load=LoadStep(0.1, 0.05))
    cuts = [0.0, 0.013, 0.05, 0.0501, 0.12, 0.2, 0.3]
    out = []
    for lo, hi in itertools.pairwise(cuts):
        s = (times >= lo) & (times < hi)
        out.append(tr.advance(times[s], FULL_STEP, t[(t >= lo) & (t < hi)]))
    th = np.concatenate([o[0] for o in out])
    om = np.concatenate([o[1] for o in out])
    np.testing.assert_allclose(th, one.theta, rtol=0, atol=1e-12 * times.size * FULL_STEP)
    np.testing.assert_allclose(om, one.omega, rtol=0, atol=1e-9)
    assert one.lost_steps > 0
    np.testing.assert_array_equal(tr.slip_times, one.slip_times)
    np.testing.assert_array_equal(tr.slips, one.slips)
    assert tr.lost_steps == one.lost_steps and tr.offset_steps == one.offset_steps


# -- loss of steps ----------------------------------------------------------------


@pytest.mark.parametrize("T_load", [0.75, 0.95])
def test_load_step_below_pull_out_holds_at_the_static_lag(T_load: float) -> None:
    """Holding torque test (load step at 0.2 s): the rotor settles where
    T_m*sin(Zr*e) + T_L = 0, e = -asin(T_L/T_m)/Zr, and loses nothing."""
    ax = StepperAxis.paper()
    Tm = 0.5 * 40 * 0.01005
    r = ax.simulate([], 0.0, np.linspace(0, 0.6, 601), load=LoadStep(0.2, T_load * Tm))
    assert r.lost_steps == 0 and r.slips.size == 0
    assert r.theta[-1] == pytest.approx(-math.asin(T_load) / 40, rel=1e-9)
    assert np.all(r.theta[r.t < 0.2] == 0.0)


def test_load_step_beyond_pull_out_slips_backwards_from_0_2_s() -> None:
    ax = StepperAxis.paper()
    Tm = 0.5 * 40 * 0.01005
    load = LoadStep(0.2, 1.2 * Tm)
    t = np.linspace(0, 0.4, 401)
    r = ax.simulate([], 0.0, t, load=load)
    assert r.lost_steps > 0
    assert np.all(r.slips == -1)  # pushed back (positive load opposes positive rotation)
    assert 0.2 < r.slip_times[0] < 0.25
    assert np.all(np.diff(r.slip_times) > 0)
    # every slip is one pitch: the rotor has gone back by (number of slips) pitches
    th, _, _, _ = ivp_reference(PAPER, np.empty(0), np.empty(0), t, load)
    assert r.offset_steps == -ax.steps_per_pitch * r.slips.size
    assert round((th[-1] - 0.0) / PITCH) in (r.slips.sum(), r.slips.sum() - 1)
    np.testing.assert_allclose(r.theta, th, rtol=0, atol=1e-6 * abs(th[-1]))


def test_slip_count_matches_the_settled_offset_of_solve_ivp() -> None:
    """Overspeed burst then stop: the rotor settles a whole number of pitches behind;
    the slips counted must be exactly that offset."""
    p = {**PAPER, "D": 0.003}
    ax = StepperAxis(**p)
    times = start_step_times("none", 18.0, FULL_STEP, 0.05)
    angles = np.full(times.size, FULL_STEP)
    t_end = 1.5
    r = ax.simulate(times, angles, [t_end])
    _, _, th_end, cmd_end = ivp_reference(p, times, angles, np.array([t_end]))
    offset = (th_end - cmd_end) / PITCH
    assert abs(offset - round(offset)) < 1e-3  # settled in a well
    assert round(offset) < 0
    assert r.offset_steps == ax.steps_per_pitch * round(offset)
    assert r.lost_steps >= abs(r.offset_steps)
    assert r.lost_in(FULL_STEP) == r.lost_steps
    assert r.lost_in(FULL_STEP / 16) == 16 * r.lost_steps


def test_an_excursion_past_half_a_pitch_that_turns_back_is_no_slip() -> None:
    """Second step while the rotor is still rushing towards the first: the error
    jumps to about -0.6 pitch, past the unstable point, but the rotor's momentum
    carries it back over the hump into its own well (solve_ivp: it settles at 0)."""
    p = {**PAPER, "D": 0.003}
    ax = StepperAxis(**p)
    times = np.array([0.0, 0.004])
    angles = np.array([0.3, 0.4]) * PITCH
    t = np.linspace(0, 0.5, 20001)
    r = ax.simulate(times, angles, t)
    th, _, th_end, cmd_end = ivp_reference(p, times, angles, t)
    assert np.min(th - staircase(times, angles, t)) < -0.55 * PITCH
    assert abs(th_end - cmd_end) < 1e-3 * PITCH
    assert r.slips.size == 0 and r.lost_steps == 0
    # the same jump from rest is a slip: the rotor falls back into the well behind
    r = ax.simulate([0.0], [0.6 * PITCH], t)
    _, _, th_end, cmd_end = ivp_reference(p, np.array([0.0]), np.array([0.6 * PITCH]), t)
    assert round((th_end - cmd_end) / PITCH) == -1
    np.testing.assert_array_equal(r.slips, [-1])
    assert r.slip_times[0] == 0.0  # dated at the step that put it past the hump
    assert r.lost_steps == 4 and r.offset_steps == -4


def test_paper_motor_cannot_reach_the_papers_20_rad_s_with_any_start() -> None:
    """D = 0.03 N*m*s/rad: viscous torque at 20 rad/s is 0.6 N*m, three times the peak
    torque 0.201 N*m, so every start to 20 rad/s slips - the S-curve too."""
    ax = StepperAxis.paper()
    assert ax.pull_out_speed < 20.0
    for kind in ("none", "scurve"):
        times = start_step_times(kind, 20.0, FULL_STEP, 4.0 if kind == "scurve" else 0.3)
        r = ax.simulate(times, FULL_STEP, [times[-1]])
        assert r.lost_steps > 0, kind
        assert r.offset_steps < 0


@pytest.mark.parametrize("kind", ["none", "exp", "scurve"])
def test_paper_motor_below_pull_out_never_slips(kind: str) -> None:
    """At 5 rad/s (D*w = 0.15 N*m < 0.201 N*m) even a start without ramp pulls in:
    J/D = 3.4 ms, too little inertia for the ramp to matter."""
    ax = StepperAxis.paper()
    times = start_step_times(kind, 5.0, FULL_STEP, 3.0 if kind != "none" else 0.5)
    t = np.linspace(0, times[-1], 3000)
    r = ax.simulate(times, FULL_STEP, t)
    assert r.lost_steps == 0 and r.slips.size == 0
    assert np.max(np.abs(r.error)) < PITCH / 2


def test_papers_linear_criterion_no_ramp_exceeds_half_pitch_s_curve_does_not() -> None:
    """The paper's own analysis (linear G(s), its parameters, w_max = 20 rad/s) in
    1/16 microsteps: without a ramp the tracking error peaks above half a tooth
    pitch (a slip by the half-pitch rule), with the S-curve or exponential start
    it stays below. The lag D*w/K alone is 0.95 of half a pitch at 20 rad/s."""
    ax = StepperAxis.paper()
    step = FULL_STEP / 16
    peaks = {}
    for kind, dur in (("none", 0.3), ("exp", 7.0), ("scurve", 6.5)):
        times = profile_step_times(kind, 20.0, step, dur)
        # the lag is largest right after a step: sample there
        r = ax.simulate(times, step, times, model="linear")
        peaks[kind] = np.max(np.abs(r.error)) / (PITCH / 2)
    assert peaks["none"] > 1.1
    assert peaks["scurve"] < 0.99
    assert peaks["exp"] < 0.99
    assert peaks["scurve"] > 0.95 * 20 * 0.03 / 8.04 / (PITCH / 2)


@pytest.mark.parametrize("kind", ["none", "exp", "scurve"])
def test_ramping_matters_for_a_lightly_damped_rotor(kind: str) -> None:
    """The paper's motor with a light damping D = 0.003 N*m*s/rad (zeta = 0.05, an
    undamped hybrid stepper; pull-out 67 rad/s) in 1/16 microsteps: the full-speed
    start at 20 rad/s must slip, the S-curve (jerk 4, a_max 4) and exponential
    (1/tau = 0.85) starts must not."""
    ax = StepperAxis.paper(D=0.003)
    step = FULL_STEP / 16
    duration = {"none": 0.3, "exp": 5.0, "scurve": 6.3}[kind]
    times = profile_step_times(kind, 20.0, step, duration)
    r = ax.simulate(times, step, np.linspace(0, times[-1], 2000))
    if kind == "none":
        assert r.lost_steps > 100
        assert r.slip_times[0] < 0.02  # it never pulls in
    else:
        assert r.lost_steps == 0 and r.slips.size == 0
        assert np.max(np.abs(r.error)) < 0.25 * PITCH
        assert r.omega[-1] == pytest.approx(
            20.0 * (1 - math.exp(-0.85 * 5.0)) if kind == "exp" else 20.0, rel=0.05
        )


def test_full_steps_resonate_where_microsteps_do_not() -> None:
    """Same light damping, S-curve start: in full steps the step rate sweeps slowly
    through the natural frequency (44.5 Hz at 1.75 rad/s) and the rotor slips there."""
    ax = StepperAxis.paper(D=0.003)
    times = start_step_times("scurve", 20.0, FULL_STEP, 6.3)
    r = ax.simulate(times, FULL_STEP, [times[-1]])
    assert r.lost_steps > 0
    f_n = ax.natural_frequency / (2 * math.pi)
    pos, _ = scurve_position(20.0, 4.0, 4.0)
    # the first slip happens while the step rate is near f_n or one of its subharmonics
    k = np.searchsorted(times, r.slip_times[0])
    rate = 1 / np.median(np.diff(times[max(k - 20, 0) : k + 1]))
    assert rate < 1.5 * f_n
    assert pos(np.array([r.slip_times[0]]))[0] > 0


# -- encoder velocity ----------------------------------------------------------------


def test_measured_velocity_of_a_constant_acceleration_lags_half_a_period() -> None:
    a, p = 3.0, 1e-3
    t = np.arange(0, 200) * p
    v = measured_velocity(0.5 * a * t**2, p)
    assert v[0] == 0.0
    np.testing.assert_allclose(v[1:], a * (t[1:] - p / 2), rtol=1e-9, atol=1e-12)


def test_measured_velocity_quantised_to_encoder_counts() -> None:
    res = 2 * math.pi / 4000  # 1000-line quadrature encoder
    p = 1e-3
    t = np.arange(0, 500) * p
    theta = 0.7 * t + 0.3 * np.sin(25 * t)
    v = measured_velocity(theta, p, resolution=res)
    counts = np.floor(theta / res)
    np.testing.assert_allclose(v[1:], np.diff(counts) * res / p, rtol=1e-12)
    true_mean = np.diff(theta) / p
    assert np.max(np.abs(v[1:] - true_mean)) <= res / p * (1 + 1e-9)
    with pytest.raises(ValueError, match=r"^period="):
        measured_velocity(theta, 0.0)
    with pytest.raises(ValueError, match=r"^resolution="):
        measured_velocity(theta, p, resolution=-1.0)


def test_measured_velocity_next_to_the_true_velocity_of_the_model() -> None:
    ax = StepperAxis.paper()
    times = start_step_times("scurve", 5.0, FULL_STEP / 16, 3.0)
    p = 1e-3
    t = np.arange(0, 3.0, p)
    th, om = ax.response(times, FULL_STEP / 16, t, velocity=True)
    v = measured_velocity(th, p)
    # the backward difference is the mean of the true velocity over the period
    mean = np.array([np.mean(om[k - 1 : k + 1]) for k in range(1, t.size)])
    assert np.max(np.abs(v[1:] - mean)) < 0.05 * 5.0
