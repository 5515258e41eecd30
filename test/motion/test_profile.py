"""winder.motion.profile against independent oracles: ruckig's time-optimal trajectories,
closed forms derived here by hand, numerical integration (scipy) and brute-force
bisection written in this file. No expected value is copied from the code under test.
"""

from __future__ import annotations

import math
import re
import warnings

import numpy as np
import pytest
import ruckig
from hypothesis import HealthCheck, assume, event, given, settings
from hypothesis import strategies as st
from scipy import integrate, optimize

from winder.motion.profile import jog, plan

EPS = np.finfo(np.float64).eps
SETTINGS = {"deadline": None, "suppress_health_check": [HealthCheck.too_slow]}


# ----------------------------------------------------------------------------- oracles


def ramp_ref(v_lo: float, dv: float, a: float, j: float) -> tuple[float, float]:
    """(duration, distance) of the fastest velocity change by dv >= 0 starting at
    v_lo with zero acceleration at both ends, integrated phase by phase."""
    if dv * j <= a * a:  # triangular acceleration: two jerk phases of sqrt(dv/j)
        tj, ta = math.sqrt(dv / j), 0.0
    else:
        tj, ta = a / j, dv / a - a / j
    ap = j * tj
    # jerk +j for tj, constant ap for ta, jerk -j for tj
    d1 = v_lo * tj + j * tj**3 / 6
    v1 = v_lo + j * tj**2 / 2
    d2 = v1 * ta + ap * ta**2 / 2
    v2 = v1 + ap * ta
    d3 = v2 * tj + ap * tj**2 / 2 - j * tj**3 / 6
    return 2 * tj + ta, d1 + d2 + d3


def valley_parts(u: float, v0: float, v1: float, A: float, J: float) -> tuple[float, float]:
    """(duration, distance) of ramping down from v0 to min(v0, v1) - u and up to v1."""
    lo = min(v0, v1)
    t1, d1 = ramp_ref(lo - u, (v0 - lo) + u, A, J)
    t2, d2 = ramp_ref(lo - u, (v1 - lo) + u, A, J)
    return t1 + t2, d1 + d2


def scurve_duration_ref(D: float, v0: float, v1: float, V: float, A: float, J: float) -> float:
    """Brute force, no closed form, no scaling. A hill (up to a peak, cruise only
    at V, down) found by bisection on the peak increment w over max(v0, v1); or,
    below the direct ramp's distance, the shallowest valley: a golden-section
    search for the farthest-reaching depth, then bisection on the far side."""
    h = max(v0, v1)

    def parts(w: float) -> tuple[float, float]:
        tu, du = ramp_ref(v0, (h - v0) + w, A, J)
        td, dd = ramp_ref(v1, (h - v1) + w, A, J)
        return tu + td, du + dd

    if parts(0.0)[1] > D:
        lo_v = min(v0, v1)
        a, b = 0.0, lo_v
        for _ in range(200):  # the depth covering the most distance
            m1, m2 = a + 0.382 * (b - a), b - 0.382 * (b - a)
            if valley_parts(m1, v0, v1, A, J)[1] < valley_parts(m2, v0, v1, A, J)[1]:
                a = m1
            else:
                b = m2
        lo, hi = a, lo_v
        if valley_parts(hi, v0, v1, A, J)[1] > D:  # the dip to rest, to rounding
            return valley_parts(hi, v0, v1, A, J)[0]
        for _ in range(300):
            mid = 0.5 * (lo + hi)
            if mid in (lo, hi):
                break
            if valley_parts(mid, v0, v1, A, J)[1] > D:
                lo = mid
            else:
                hi = mid
        return valley_parts(lo, v0, v1, A, J)[0]
    tv, dv = parts(V - h)
    if dv <= D:
        return tv + (D - dv) / V
    lo, hi = 0.0, V - h
    for _ in range(300):
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        if parts(mid)[1] < D:
            lo = mid
        else:
            hi = mid
    return parts(hi)[0]


def duration_envelope(D, v0, v1, V, A, J, rel=1e-9):
    """Bounds for the time-optimal duration: the oracle's, to 1e-9, widened for
    valleys by the time a standstill-like bottom needs to cover 64 ulps of D
    (``cbrt(6 dD / J)``, from ``p = J t^3 / 6``): near a dip to rest the duration
    is that sensitive to the distance, and no float computation does better."""
    T = scurve_duration_ref(D, v0, v1, V, A, J)
    slack = rel * T
    if ramp_ref(min(v0, v1), abs(v1 - v0), A, J)[1] > D:
        slack += 2 * (6 * 64 * EPS * D / J) ** (1 / 3)
    return T - slack, T + slack


def min_distance_ref(v0: float, v1: float, A: float, J: float) -> float:
    """The shortest monotone move: the direct ramp, or dipping to rest and back."""
    lo = min(v0, v1)
    direct = ramp_ref(lo, abs(v1 - v0), A, J)[1]
    return min(direct, valley_parts(lo, v0, v1, A, J)[1])


_RK = ruckig.Ruckig(1)


def ruckig_duration(D, v0, v1, V, A, J) -> float | None:
    """Time-optimal duration by ruckig with min_velocity 0 (monotone), None if it
    finds no trajectory."""
    inp = ruckig.InputParameter(1)
    inp.current_position, inp.current_velocity, inp.current_acceleration = [0.0], [v0], [0.0]
    inp.target_position, inp.target_velocity, inp.target_acceleration = [D], [v1], [0.0]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [V], [A], [J]
    inp.min_velocity = [0.0]
    traj = ruckig.Trajectory(1)
    try:
        res = _RK.calculate(inp, traj)
    except ruckig.RuckigError:
        return None
    if res not in (ruckig.Result.Working, ruckig.Result.Finished):
        return None
    return traj.duration, traj


def dense_times(prof, n: int = 1500) -> np.ndarray:
    """Uniform times plus every phase edge and its float neighbours."""
    edges = np.array([ph.t_start for ph in prof.phases] + [prof.duration])
    near = np.concatenate([edges, np.nextafter(edges, -np.inf), np.nextafter(edges, np.inf)])
    t = np.concatenate([np.linspace(0.0, prof.duration, n), near])
    return np.unique(np.clip(t, 0.0, prof.duration))


def check_invariants(prof, D, v0, v1, V, A=None, J=None, continuous_acc=True):
    t = dense_times(prof)
    p, v, a, j = prof.sample(t)
    # limits
    assert np.all(v <= V) and np.all(v >= 0.0)
    if A is not None:
        assert np.all(np.abs(a) <= A)
    if J is not None:
        assert np.all(np.abs(j) <= J)
    # monotone position, exact ends
    assert np.all(np.diff(p) >= 0.0)
    ps, vs, as_, _ = prof.sample(np.array([-1.0, 0.0, prof.duration, prof.duration * 2 + 1]))
    assert ps[0] == 0.0 and ps[1] == 0.0 and vs[0] == v0 and vs[1] == v0
    assert ps[2] == D and ps[3] == D and vs[2] == v1 and vs[3] == v1
    assert as_[0] == 0.0 and as_[3] == 0.0
    # phases tile [0, duration]
    ph = prof.phases
    assert ph[0].t_start == 0.0
    assert math.isclose(ph[-1].t_start + ph[-1].duration, prof.duration, rel_tol=1e-14)
    # continuity at phase edges: left limit vs value at the edge
    edges = np.array([x.t_start for x in ph[1:] if x.t_start > 0.0])
    if edges.size:
        pl, vl, al, _ = prof.sample(np.nextafter(edges, -np.inf))
        pr, vr, ar, _ = prof.sample(edges)
        ulp = 4 * float(np.spacing(edges).max())  # the left limit is an ulp early
        assert np.allclose(pl, pr, rtol=0, atol=1e-12 * D + V * ulp)
        assert np.allclose(vl, vr, rtol=0, atol=1e-11 * V + (A or 0.0) * ulp)
        if continuous_acc and A is not None:
            assert np.allclose(al, ar, rtol=0, atol=1e-9 * A + (J or 0.0) * ulp)


def first_time_ref(prof, targets: np.ndarray) -> np.ndarray:
    """First time the sampled position reaches each target: plain bisection."""
    lo = np.zeros_like(targets)
    hi = np.full_like(targets, prof.duration)
    for _ in range(90):
        mid = 0.5 * (lo + hi)
        below = prof.sample(mid)[0] < targets
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    return hi


def check_steps(prof, n: int) -> np.ndarray:
    ts = prof.step_times(n)
    assert ts.dtype == np.float64 and ts.shape == (n,)
    assert ts[-1] == prof.duration
    assert np.all(np.diff(ts) > 0.0)
    targets = np.arange(1, n + 1) * prof.distance / n
    # the positions at the step times are the targets to rounding
    p = prof.sample(ts)[0]
    assert np.max(np.abs(p - targets)) <= 64 * EPS * prof.distance
    ref = first_time_ref(prof, targets)
    # equal times, except where the axis is so slow (v ~ 0 at a standstill end)
    # that the position is flat to rounding between the two: then both are right
    close = np.abs(ts - ref) <= 1e-9 * prof.duration
    flat = np.abs(prof.sample(ref)[0] - p) <= 64 * EPS * prof.distance
    assert np.all(close | flat)
    if n >= 20:
        assert np.mean(close) > 0.9
    return ts


# ----------------------------------------------------------------------------- strategies

log10 = st.floats(-2.0, 2.0)


@st.composite
def scurve_problem(draw, vlo=-2.0, vhi=2.0, alo=-2.0, ahi=2.0, jlo=-2.0, jhi=3.0):
    V = 10 ** draw(st.floats(vlo, vhi))
    A = 10 ** draw(st.floats(alo, ahi))
    J = 10 ** draw(st.floats(jlo, jhi))
    frac = st.one_of(st.just(0.0), st.just(1.0), st.floats(0.0, 1.0))
    v0 = V * draw(frac)
    v1 = draw(st.one_of(st.just(v0), st.builds(lambda f: V * f, frac)))
    dmin = min_distance_ref(v0, v1, A, J)
    # from just above the minimum distance to far beyond the ramps
    scale = max(dmin, V * V / A, V * math.sqrt(V / J))
    D = dmin + scale * 10 ** draw(st.floats(-9.0, 3.0))
    return D, v0, v1, V, A, J


# ----------------------------------------------------------------------------- papers


def test_paper_002_scurve_240():
    # j = 0.05, a = 0.5: jerk phase a/j = 10 s, constant phase v/a - a/j = 6 s,
    # ramp 26 s covering v/2 * 26 = 104; cruise (240 - 2*104)/8 = 4 s; total 56 s
    p = plan("scurve", 240, v_max=8, a_max=0.5, j_max=0.05)
    assert math.isclose(p.duration, 56.0, rel_tol=1e-15)
    assert [ph.duration for ph in p.phases] == pytest.approx([10, 6, 10, 4, 10, 6, 10], rel=1e-14)
    assert p.v_peak == 8.0
    # the first steps lie in the first jerk phase: p = j t^3 / 6
    ts = p.step_times(240)
    k = np.arange(1, 9)
    assert np.allclose(ts[:8], np.cbrt(6 * k / 0.05), rtol=1e-14, atol=0)
    # the cruise: p = 104 + 8 (t - 26)
    k = np.arange(105, 137)
    assert np.allclose(ts[k - 1], 26 + (k - 104) / 8, rtol=1e-15, atol=0)
    check_invariants(p, 240, 0, 0, 8, 0.5, 0.05)


def test_paper_002_tcurve_210():
    # ramp v/a = 16 s covering 64; cruise (210 - 128)/8 = 10.25 s; total 42.25 s
    p = plan("trapezoid", 210, v_max=8, a_max=0.5)
    assert math.isclose(p.duration, 42.25, rel_tol=1e-15)
    ts = p.step_times(210)
    k = np.arange(1, 65)
    assert np.allclose(ts[:64], np.sqrt(2 * k / 0.5), rtol=1e-15, atol=0)
    assert all(ph.law == 0.0 for ph in p.phases)
    check_invariants(p, 210, 0, 0, 8, 0.5, continuous_acc=False)


def test_paper_004_stepper_startup():
    # S-curve, j = a = 4, to omega 20: jerk phases 1 s, constant 20/4 - 1 = 4 s: 6 s
    j = jog(20, a_max=4, j_max=4)
    assert math.isclose(j.ramp_duration, 6.0, rel_tol=1e-15)
    # a move of 400: ramps of 6 s cover 60 each, cruise 280/20 = 14 s
    p = plan("scurve", 400, v_max=20, a_max=4, j_max=4)
    assert math.isclose(p.duration, 26.0, rel_tol=1e-15)
    # exponential, 1/tau = 0.85, cut at 1 %: ramps last tau ln(100)
    tau = 1 / 0.85
    e = plan("exponential", 400, v_max=20, tau=tau)
    tr = tau * math.log(100)
    assert math.isclose(e.phases[0].duration, tr, rel_tol=1e-14)
    assert math.isclose(e.phases[2].duration, tr, rel_tol=1e-14)
    W = 20 / 0.99  # asymptote reaching 20 at tr
    U = -20 / 0.99 * 0.01
    d_up = integrate.quad(lambda t: W * (1 - math.exp(-t / tau)), 0, tr, epsabs=1e-13)[0]
    d_dn = integrate.quad(lambda t: U + (20 - U) * math.exp(-t / tau), 0, tr, epsabs=1e-13)[0]
    assert math.isclose(e.duration, 2 * tr + (400 - d_up - d_dn) / 20, rel_tol=1e-12)
    check_invariants(e, 400, 0, 0, 20, continuous_acc=False)


# ----------------------------------------------------------------------------- S-curve


@settings(max_examples=2500, **SETTINGS)
@given(scurve_problem())
def test_scurve_time_optimal_vs_ruckig(prob):
    D, v0, v1, V, A, J = prob
    p = plan("scurve", D, v_max=V, a_max=A, j_max=J, v_start=v0, v_end=v1)
    assume(p.duration < 5e3)
    lo, hi = duration_envelope(D, v0, v1, V, A, J)
    rk = ruckig_duration(D, v0, v1, V, A, J)
    if rk is None:
        # ruckig gives up on some boundary cases (e.g. v_start == v_max and a
        # cruise of a microsecond); the bisection oracle still applies
        event("ruckig found no trajectory")
        assert lo <= p.duration <= hi
        return
    T, traj = rk
    if not math.isclose(p.duration, T, rel_tol=1e-6):
        # ruckig accepts a target missed by its tolerance (a direct ramp ~1e-10
        # too long instead of a valley), or misses the optimum at extreme scales:
        # then the brute-force oracle decides, and ruckig must be the slower one
        # or be off target
        event("ruckig disagrees")
        assert lo <= p.duration <= hi
        assert p.duration < T or traj.at_time(T)[0][0] != D
        return
    # the same motion: positions and velocities at a few times
    for t in np.linspace(0, T, 7)[1:-1]:
        pr, vr, _ = traj.at_time(t)
        ps, vs, _, _ = p.sample(t)
        assert abs(ps - pr[0]) <= 1e-6 * D + 1e-6 * V * T
        assert abs(vs - vr[0]) <= 1e-6 * V


def test_scurve_durations_are_ruckigs_to_1e_12():
    """Over 2,000 random problems (the planning benchmark's: limits over four
    decades, distances over six, the boundary speeds at 0, v_max or between)
    the duration is ruckig's to 1e-12 relative; where ruckig is further off
    (a cruise at v_max of a few hundred microseconds, timed by ruckig to
    ~1e-14 s) the brute-force oracle decides, to 1e-14."""
    import random

    rng = random.Random(34)
    checked = by_oracle = 0
    while checked < 2000:
        V, A, J = (10 ** rng.uniform(-2, 2) for _ in range(3))
        v0 = V * rng.choice([0.0, 1.0, rng.random()])
        v1 = V * rng.choice([0.0, 1.0, rng.random()])
        D = 10 ** rng.uniform(-3, 3)
        try:
            p = plan("scurve", D, v_max=V, a_max=A, j_max=J, v_start=v0, v_end=v1)
        except ValueError:
            assert min_distance_ref(v0, v1, A, J) * (1 + 1e-12) > D
            continue
        rk = ruckig_duration(D, v0, v1, V, A, J) if p.duration < 5e3 else None
        if rk is None:
            continue
        checked += 1
        if abs(p.duration - rk[0]) > 1e-12 * rk[0]:
            by_oracle += 1
            ref = scurve_duration_ref(D, v0, v1, V, A, J)
            assert abs(p.duration - ref) <= 1e-14 * ref
            assert abs(rk[0] - p.duration) <= 1e-13  # ruckig's own time resolution
    assert by_oracle <= 10


@settings(max_examples=300, **SETTINGS)
@given(scurve_problem(), st.floats(1e-5, 0.5))
def test_scurve_infeasible_below_direct_ramp(prob, short):
    _, v0, v1, V, A, J = prob
    assume(abs(v1 - v0) > 1e-3 * V)
    dmin = min_distance_ref(v0, v1, A, J)
    assume(ramp_ref(0, abs(v1 - v0), A, J)[0] < 5e3)
    D = dmin * (1 - short)
    assume(dmin - D > 1e-7)  # beyond ruckig's own position tolerance
    with pytest.raises(ValueError, match=r"^distance=.* needs distance >= ") as err:
        plan("scurve", D, v_max=V, a_max=A, j_max=J, v_start=v0, v_end=v1)
    d_said = float(err.value.args[0].rsplit(">= ", 1)[1])
    assert math.isclose(d_said, dmin, rel_tol=1e-12)
    assert ruckig_duration(D, v0, v1, V, A, J) is None  # ruckig finds no monotone move either


@settings(max_examples=800, **SETTINGS)
@given(scurve_problem(vlo=-6, vhi=6, alo=-6, ahi=6, jlo=-9, jhi=9))
def test_scurve_invariants_any_scale(prob):
    D, v0, v1, V, A, J = prob
    p = plan("scurve", D, v_max=V, a_max=A, j_max=J, v_start=v0, v_end=v1)
    lo, hi = duration_envelope(D, v0, v1, V, A, J)
    assert lo <= p.duration <= hi
    check_invariants(p, D, v0, v1, V, A, J)


@pytest.mark.parametrize(("A", "J"), [(0.5, 1e9), (0.5, 1e-9), (1e6, 1e-3), (1e-6, 1e6), (3.0, 3.0)])
@pytest.mark.parametrize(("v0", "v1"), [(0, 0), (0, 8), (8, 0), (8, 8), (2, 7), (7, 7)])
def test_scurve_extreme_limits(A, J, v0, v1):
    V = 8.0
    D = min_distance_ref(v0, v1, A, J) + 240.0
    p = plan("scurve", D, v_max=V, a_max=A, j_max=J, v_start=v0, v_end=v1)
    assert math.isclose(p.duration, scurve_duration_ref(D, v0, v1, V, A, J), rel_tol=1e-12)
    check_invariants(p, D, v0, v1, V, A, J)
    check_steps(p, 2000)


def test_scurve_pure_cruise_and_hill():
    # v_start = v_end = v_max: nothing to ramp, any distance is a cruise
    p = plan("scurve", 1e-9, v_max=8, a_max=0.5, j_max=0.05, v_start=8, v_end=8)
    assert p.duration == 1e-9 / 8
    # v_start = v_end = 7 < v_max and a long move: a hill up to 8, never a valley
    p = plan("scurve", 1e4, v_max=8, a_max=0.5, j_max=0.05, v_start=7, v_end=7)
    assert p.v_peak == 8.0
    _, v, _, _ = p.sample(dense_times(p))
    assert v.min() == 7.0
    # a short one: a small hill, peak above 7 (time-optimal, ruckig agrees)
    q = plan("scurve", 1.0, v_max=8, a_max=0.5, j_max=0.05, v_start=7, v_end=7)
    assert 7.0 < q.v_peak < 8.0
    assert math.isclose(q.duration, ruckig_duration(1.0, 7, 7, 8, 0.5, 0.05)[0], rel_tol=1e-12)


def test_scurve_valley_below_both_speeds():
    # 1 -> 0.0625 with a = j = 1: the direct ramp covers 1.0625 * sqrt(0.9375);
    # a shorter move must dip below 0.0625 first (ruckig, min_velocity 0, agrees)
    v0, v1, V, A, J = 1.0, 0.0625, 1.0, 1.0, 1.0
    direct = ramp_ref(v1, v0 - v1, A, J)[1]
    assert math.isclose(direct, 1.0625 * math.sqrt(0.9375), rel_tol=1e-15)
    D = 1.020724004450905
    p = plan("scurve", D, v_max=V, a_max=A, j_max=J, v_start=v0, v_end=v1)
    T, _ = ruckig_duration(D, v0, v1, V, A, J)
    assert math.isclose(p.duration, T, rel_tol=1e-9)
    _, v, _, _ = p.sample(dense_times(p))
    assert v.min() < 0.01 < v1
    check_invariants(p, D, v0, v1, V, A, J)
    check_steps(p, 1000)
    # round trip: the move dipping u = 0.06 below v1 (on the falling side of d(u))
    u = 0.06
    Tu, Du = valley_parts(u, v0, v1, A, J)
    assert valley_parts(u + 1e-6, v0, v1, A, J)[1] < Du < direct
    q = plan("scurve", Du, v_max=V, a_max=A, j_max=J, v_start=v0, v_end=v1)
    assert math.isclose(q.duration, Tu, rel_tol=1e-12)
    # shorter than dipping to rest: impossible
    rest = valley_parts(v1, v0, v1, A, J)[1]
    with pytest.raises(ValueError, match=r"needs distance >= "):
        plan("scurve", rest * 0.999, v_max=V, a_max=A, j_max=J, v_start=v0, v_end=v1)


def test_scurve_million_seconds_ten_million_steps():
    # cruise-dominated: ramps 26 s each (paper limits), cruise (D - 208)/8
    D = 8e6
    p = plan("scurve", D, v_max=8, a_max=0.5, j_max=0.05)
    assert math.isclose(p.duration, 52 + (D - 208) / 8, rel_tol=1e-15)
    n = 10**7
    ts = p.step_times(n)
    assert ts[-1] == p.duration
    assert np.all(np.diff(ts) > 0.0)
    k = np.array([131, 10**5, 4 * 10**6, 9_999_869])  # the cruise: 104 < x < D - 104
    x = k * D / n
    assert np.allclose(ts[k - 1], 26 + (x - 104) / 8, rtol=2 * EPS, atol=0)
    # the deceleration, by symmetry: t(D - x) = T - t(x) for the first ramp's steps
    head = ts[:12]
    tail = p.duration - ts[n - 2 - np.arange(12)]
    assert np.allclose(head, tail, rtol=0, atol=1e-9)


# ----------------------------------------------------------------------------- trapezoid


@settings(max_examples=600, **SETTINGS)
@given(st.floats(-3, 3), st.floats(-3, 3), st.floats(0, 1), st.floats(0, 1), st.floats(-6, 3))
def test_trapezoid_closed_form(lv, la, f0, f1, ld):
    V, A = 10**lv, 10**la
    v0, v1 = V * f0, V * f1
    dmin = abs(v1 * v1 - v0 * v0) / (2 * A)
    D = dmin + V * V / A * 10**ld
    p = plan("trapezoid", D, v_max=V, a_max=A, v_start=v0, v_end=v1)
    # triangle if the peak sqrt(A D + (v0^2 + v1^2)/2) stays below V; the ramp
    # times (vp - v)/A written as (vp^2 - v^2) / (A (vp + v)) against cancellation
    vp = math.sqrt(A * D + (v0 * v0 + v1 * v1) / 2)
    if vp <= V:
        T = (
            (A * D + (v1 - v0) * (v1 + v0) / 2) / (vp + v0) + (A * D + (v0 - v1) * (v0 + v1) / 2) / (vp + v1)
        ) / A
    else:
        vp = V
        T = (2 * V - v0 - v1) / A + (D - (2 * V * V - v0 * v0 - v1 * v1) / (2 * A)) / V
    assert math.isclose(p.duration, T, rel_tol=1e-10)
    assert math.isclose(p.v_peak, vp, rel_tol=1e-12)
    check_invariants(p, D, v0, v1, V, A, continuous_acc=False)
    if ld > -4:  # step positions resolvable against the bisection oracle
        check_steps(p, 200)


def test_trapezoid_triangle_from_rest():
    p = plan("trapezoid", 10.0, v_max=1e6, a_max=2.0)
    assert math.isclose(p.duration, 2 * math.sqrt(10.0 / 2.0), rel_tol=1e-15)
    check_steps(p, 5000)


# ----------------------------------------------------------------------------- exponential


def quad(f, a, b, scale):
    """Adaptive quadrature to ~1e-12; its roundoff warnings on the flat tails of
    the exponential are expected (the result is still good to ~1e-13)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", integrate.IntegrationWarning)
        return integrate.quad(f, a, b, epsabs=1e-14 * scale, epsrel=1e-12)[0]


def exp_oracle(D, v0, v1, V, tau, eps=0.01):
    """Duration of the truncated exponential move, by quadrature and brentq."""
    K = 1 / (1 - eps)
    W = v0 + (V - v0) * K
    U = v1 - (V - v1) * K * eps
    tr = tau * math.log(1 / eps)

    def vup(t):
        return W + (v0 - W) * math.exp(-t / tau)

    def vdn(t):
        return U + (V - U) * math.exp(-t / tau)

    def up(vp):  # time to reach vp on the rising curve, distance so far
        t = 0.0 if vp <= v0 else -tau * math.log(1 - (vp - v0) * (1 - eps) / (V - v0))
        return t, quad(vup, 0, t, V * tau)

    def down(vp):  # enter the falling curve at vp, ride it to its end
        if vp <= v1:
            return 0.0, 0.0
        s = 0.0 if vp >= V else -tau * math.log(eps + (vp - v1) * (1 - eps) / (V - v1))
        return tr - s, quad(vdn, s, tr, V * tau)

    (tu, du), (td, dd) = up(V), down(V)
    if du + dd <= D:
        return tu + td + (D - du - dd) / V, V
    h = max(v0, v1)
    if up(h)[1] + down(h)[1] > D:
        return None  # no monotone move that short
    vp = optimize.brentq(lambda x: up(x)[1] + down(x)[1] - D, h, V, xtol=1e-15, rtol=1e-15)
    return up(vp)[0] + down(vp)[0], vp


@settings(max_examples=150, **SETTINGS)
@given(st.floats(-1, 2), st.floats(-1.5, 1), st.floats(0, 1), st.floats(0, 1), st.floats(-3, 2))
def test_exponential_vs_quadrature(lv, lt, f0, f1, ld):
    V, tau = 10**lv, 10**lt
    v0, v1 = V * f0, V * f1
    # the oracle solves for the peak velocity: hopeless for a velocity change of
    # a few ulps, which the truncated exponential still stretches over ln(100) tau
    assume(all(V - v > 1e-9 * V or v == V for v in (v0, v1)))
    D = V * tau * 10**ld
    ref = exp_oracle(D, v0, v1, V, tau)
    if ref is None:
        with pytest.raises(ValueError, match=r"^distance="):
            plan("exponential", D, v_max=V, tau=tau, v_start=v0, v_end=v1)
        return
    T, vp = ref
    # the oracle's ramp times come from vp - v0 and vp - v1: with a peak only
    # a millionth above the boundary speeds they lose the digits it is judged by
    # (plan() works in velocity increments; such ramps: test_exponential_steps)
    assume(vp == V or vp - max(v0, v1) > 1e-6 * V)
    p = plan("exponential", D, v_max=V, tau=tau, v_start=v0, v_end=v1)
    assert math.isclose(p.duration, T, rel_tol=1e-9)
    assert math.isclose(p.v_peak, vp, rel_tol=1e-9)
    check_invariants(p, D, v0, v1, V, continuous_acc=False)
    check_steps(p, 200)


def test_exponential_steps():
    p = plan("exponential", 50.0, v_max=20, tau=1 / 0.85)  # short: reduced peak
    assert p.v_peak < 20
    check_steps(p, 3000)
    q = plan("exponential", 400.0, v_max=20, tau=1 / 0.85, v_start=2, v_end=5)
    check_steps(q, 3000)
    # ramps that change the speed by 4e-7 of itself: no digits lost on the way
    V, v = 748.4765023305584, 748.4762222345018
    r = plan("exponential", 64.77687029206871, v_max=V, tau=0.019024991263299765, v_start=v, v_end=v)
    check_invariants(r, r.distance, v, v, V, continuous_acc=False)
    check_steps(r, 400)


# ----------------------------------------------------------------------------- step timing


@settings(max_examples=150, **SETTINGS)
@given(scurve_problem(vlo=-3, vhi=3, alo=-3, ahi=3, jlo=-4, jhi=4), st.integers(1, 3000))
def test_step_times_vs_bisection(prob, n):
    D, v0, v1, V, A, J = prob
    p = plan("scurve", D, v_max=V, a_max=A, j_max=J, v_start=v0, v_end=v1)
    # steps must be resolvable in float64 at the end of the move
    assume(p.duration / n > 1e4 * np.spacing(p.duration))
    check_steps(p, n)


def test_step_times_exact_where_a_ramp_ends_at_a_vanishing_speed():
    """A move that ends at 7.2e-200 steps/s (found by the property test
    above): its last phase is solved from its end, where the speed is all
    but zero; the sinh form lost 72 ulps of the distance there (asinh's
    error at r ~ 1e296), the cubic root refined by Newton keeps it to
    rounding. Bisection (first_time_ref) is the oracle."""
    p = plan("scurve", 1.1, v_max=1, a_max=1, j_max=1, v_start=1, v_end=7.196265462462796e-200)
    check_steps(p, 325)


def test_step_times_small_n_and_arbitrary_positions():
    p = plan("scurve", 3.0, v_max=2, a_max=1, j_max=1, v_start=0.5, v_end=1.0)
    assert p.step_times(1).tolist() == [p.duration]
    x = np.array([0.0, 0.0, 1e-12, 1.5, 3.0])
    t = p.times_at(x)
    assert t[0] == 0.0 and t[1] == 0.0 and t[-1] == p.duration
    assert np.allclose(p.sample(t)[0], x, rtol=0, atol=4 * EPS * 3)


# ----------------------------------------------------------------------------- jog


def ruckig_stop_duration(v, a, A, J):
    inp = ruckig.InputParameter(1)
    inp.control_interface = ruckig.ControlInterface.Velocity
    inp.current_position, inp.current_velocity, inp.current_acceleration = [0.0], [v], [a]
    inp.target_velocity, inp.target_acceleration = [0.0], [0.0]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [1e9], [A], [J]
    traj = ruckig.Trajectory(1)
    assert _RK.calculate(inp, traj) in (ruckig.Result.Working, ruckig.Result.Finished)
    return traj.duration


@settings(max_examples=400, **SETTINGS)
@given(st.floats(-2, 2), st.floats(-2, 2), st.floats(-2, 3), st.floats(0, 1), st.floats(0, 1.3))
def test_jog_stop_time_optimal(lv, la, lj, fs, fstop):
    V, A, J = 10**lv, 10**la, 10**lj
    vt, vs = V, V * fs
    for target, start in ((vt, vs), (vs, vt)):  # speeding up and slowing down
        g = jog(target, a_max=A, j_max=J, v_start=start)
        dv = abs(target - start)
        ramp = 2 * math.sqrt(dv / J) if dv * J <= A * A else dv / A + A / J
        assert math.isclose(g.ramp_duration, ramp, rel_tol=1e-12, abs_tol=1e-300)
        ts = fstop * g.ramp_duration
        s = g.stop(ts)
        _p0, v0, a0, _ = g.sample(ts)
        assume(ruckig_stop_duration(float(v0), float(a0), A, J) < 5e3)
        # the stop is ruckig's time-optimal velocity-mode stop from the same state
        T = ruckig_stop_duration(float(v0), float(a0), A, J)
        # (the stop time is sqrt-sensitive to the state where the jog itself was
        # about to stop, v = a^2 / 2j: ruckig and sample() round differently there)
        tol = 1e-6 * (ts + T) + 1e-12 * A / J  # (ruckig rounds 1e-161 s to 0)
        assert math.isclose(s.duration - ts, T, rel_tol=1e-7, abs_tol=tol)
        # identical to the jog before the stop, at rest at the end, limits held
        t = np.linspace(0, ts, 50)
        t = t[t < ts]  # at ts itself the jerks differ
        for x, y in zip(g.sample(t), s.sample(t), strict=True):
            assert np.allclose(x, y, rtol=1e-12, atol=1e-12 * max(V, A, J))
        for x, y in zip(g.sample(ts)[:3], s.sample(ts)[:3], strict=True):  # p, v, a continuous
            assert math.isclose(x, y, rel_tol=1e-12, abs_tol=1e-12 * max(V, A, J))
        check_invariants(s, s.distance, start, 0.0, max(vt, vs), A, J)


def test_jog_trapezoid_stop_and_sampling():
    g = jog(6.0, a_max=2.0)
    assert g.ramp_duration == 3.0 and math.isinf(g.duration)
    p, v, _a, _ = g.sample([1.0, 10.0])
    assert p.tolist() == [1.0, 9.0 + 6.0 * 7.0] and v.tolist() == [2.0, 6.0]
    s = g.stop(1.0)  # mid-ramp at v = 2: brake at -2 for 1 s
    assert math.isclose(s.duration, 2.0) and math.isclose(s.distance, 2.0)
    assert math.isclose(g.times_at([9.0])[0], 3.0)
    check_steps(s, 100)


def test_jog_stop_mid_acceleration_steps():
    g = jog(20, a_max=4, j_max=4)
    s = g.stop(5.5)  # in the last jerk phase, acceleration 2 > 0
    assert s.t_stop == 5.5
    check_steps(s, 4000)
    _, v, a, _ = s.sample([s.duration])
    assert v[0] == 0.0 and a[0] == 0.0


# ----------------------------------------------------------------------------- bad input

GOOD = {"v_max": 8.0, "a_max": 0.5, "j_max": 0.05}


@pytest.mark.parametrize(
    ("kind", "distance", "kw", "name"),
    [
        ("scurve", 10, {**GOOD, "a_max": -1.0}, "a_max"),
        ("scurve", 10, {**GOOD, "a_max": 0.0}, "a_max"),
        ("scurve", 10, {**GOOD, "a_max": math.nan}, "a_max"),
        ("scurve", 10, {**GOOD, "a_max": math.inf}, "a_max"),
        ("scurve", 10, {**GOOD, "a_max": "0.5"}, "a_max"),
        ("scurve", 10, {**GOOD, "a_max": True}, "a_max"),
        ("scurve", 10, {**GOOD, "a_max": None}, "a_max"),
        ("scurve", 10, {**GOOD, "j_max": None}, "j_max"),
        ("scurve", 10, {**GOOD, "j_max": -1e-9}, "j_max"),
        ("scurve", 10, {**GOOD, "j_max": [1.0]}, "j_max"),
        ("scurve", 10, {**GOOD, "v_max": 0}, "v_max"),
        ("scurve", 10, {**GOOD, "v_max": -math.inf}, "v_max"),
        ("scurve", 0.0, GOOD, "distance"),
        ("scurve", -1, GOOD, "distance"),
        ("scurve", math.nan, GOOD, "distance"),
        ("scurve", math.inf, GOOD, "distance"),
        ("scurve", "10", GOOD, "distance"),
        ("scurve", None, GOOD, "distance"),
        ("scurve", 10, {**GOOD, "v_start": -1.0}, "v_start"),
        ("scurve", 10, {**GOOD, "v_start": 8.5}, "v_start"),
        ("scurve", 10, {**GOOD, "v_end": math.nan}, "v_end"),
        ("scurve", 10, {**GOOD, "v_end": 9}, "v_end"),
        ("trapezoid", 10, {"v_max": 8}, "a_max"),
        ("exponential", 10, {"v_max": 8}, "tau"),
        ("exponential", 10, {"v_max": 8, "tau": -2}, "tau"),
        ("exponential", 10, {"v_max": 8, "tau": 1, "exp_cut": 0.7}, "exp_cut"),
        ("sinus", 10, GOOD, "kind"),
        (3, 10, GOOD, "kind"),
        ("scurve", 1.0, {**GOOD, "v_end": 8.0}, "distance"),  # cannot reach 8 in time
    ],
)
def test_bad_plan_input(kind, distance, kw, name):
    with pytest.raises(ValueError) as err:
        plan(kind, distance, **kw)
    msg = str(err.value)
    assert msg.startswith(f"{name}=") and "\n" not in msg
    assert "invalid" in msg
    value = {"kind": kind, "distance": distance}.get(name, kw.get(name))
    assert repr(value) in msg


@pytest.mark.parametrize(
    ("call", "name"),
    [
        (lambda: jog(-1.0, a_max=1), "v_target"),
        (lambda: jog(1.0, a_max=0), "a_max"),
        (lambda: jog(1.0, a_max=1, j_max=-1), "j_max"),
        (lambda: jog(1.0, a_max=1, v_start=math.nan), "v_start"),
        (lambda: jog(1.0, a_max=1).stop(-1.0), "t_stop"),
        (lambda: jog(1.0, a_max=1).stop(math.inf), "t_stop"),
        (lambda: plan("scurve", 1, **GOOD).step_times(0), "n"),
        (lambda: plan("scurve", 1, **GOOD).step_times(2.5), "n"),
        (lambda: plan("scurve", 1, **GOOD).step_times("3"), "n"),
    ],
)
def test_bad_other_input(call, name):
    with pytest.raises(ValueError, match=rf"^{re.escape(name)}=.* is invalid: must be "):
        call()
