"""Feed hold, resume, abort and feed override on the time law,
ROS-free: :mod:`winder.motion.retime` and :mod:`winder.motion.timeline`.

Oracles: ruckig's time-optimal velocity-mode stop (duration and distance from
the same state), the closed forms of the trapezoid's braking distance and of
the exponential ramp's falling curve (integrated by scipy), the uninterrupted
plan (:meth:`SegmentTiming.times_ns`) for every step before a command, and the
limits checked by sampling every piece of the law.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st
from scipy import integrate
from support.oracles import ruckig_change, ruckig_stop

from winder.contract.params import PROFILE_SPECS
from winder.motion.profile import EXP_CUT, plan
from winder.motion.retime import continue_tail, motion_state, stop_tail
from winder.motion.timeline import Command, CommandError, Timeline, parse_schedule
from winder.motion.timing import plan_timing
from winder.spec import SpecError

RAMP = {k: s.default for k, s in PROFILE_SPECS.items()}
FAST = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def ramp_distance(v: float, A: float, J: float) -> float:
    """Closed form: distance of the S-curve ramp from v to rest, zero acceleration at both ends."""
    T = 2 * math.sqrt(v / J) if v * J <= A * A else v / A + A / J
    return 0.5 * v * T


def check_limits(prof, V: float, A: float | None, J: float | None, t0: float = 0.0) -> None:
    """Velocity in [0, V], |a| <= A and |jerk| <= J from ``t0`` on (sampled densely)."""
    t = np.linspace(t0, prof.duration, 4001)
    edges = np.array([ph.t_start for ph in prof.phases if ph.t_start >= t0])
    t = np.unique(np.concatenate([t, edges, np.nextafter(edges, np.inf)]))
    t = t[t <= prof.duration]
    p, v, a, j = prof.sample(t)
    scale = max(V, A or 0.0, J or 0.0)
    assert np.all(np.diff(p) >= 0.0)
    assert v.max() <= V * (1 + 1e-9) and v.min() >= 0.0
    if A is not None:
        assert np.abs(a).max() <= A * (1 + 1e-9)
    if J is not None:
        assert np.abs(j).max() <= J * (1 + 1e-9) + 1e-12 * scale


@FAST
@given(
    st.floats(10, 1e5),  # distance
    st.floats(1, 4),  # log10 v_max
    st.floats(1, 5),  # log10 a_max
    st.floats(2, 7),  # log10 j_max
    st.floats(0, 0.3),  # v_start / v_max
    st.floats(0, 1),  # where the stop comes, of the move's duration
)
@example(10.0, 3.0, 4.75, 6.78125, 0.0, 0.5)  # ruckig refuses the limit a hair above here
def test_scurve_stop_is_rucking_time_optimal_stop(D, lv, la, lj, fs, where):
    V, A, J = 10**lv, 10**la, 10**lj
    prof = plan("scurve", D, v_max=V, a_max=A, j_max=J, v_start=V * fs, v_end=V * fs)
    t = where * prof.duration
    p, v, a = motion_state(prof, t)
    tail = stop_tail(prof, t)
    T, dist = ruckig_stop(v, a, V * fs, A, J)
    assume(1e-9 * prof.duration < T)
    # where the state is an ulp from reaching v_end with a = 0, the stop time is
    # sqrt-sensitive to rounding (ruckig and this code round differently)
    slack = math.sqrt(1e-13 * max(v, 1.0) / J)
    assert math.isclose(tail.duration, T, rel_tol=1e-6, abs_tol=1e-9 * prof.duration + slack)
    assert math.isclose(tail.distance, dist, rel_tol=1e-6, abs_tol=1e-9 * D + v * slack)
    # no stop on the planned move needs more than what is left of it
    assert p + tail.distance <= D * (1 + 1e-9)
    check_limits(tail, V, A, J)
    end = tail.sample(np.array([tail.duration]))
    assert math.isclose(float(end[1][0]), V * fs, abs_tol=1e-9 * V)


@FAST
@given(st.floats(10, 1e5), st.floats(1, 4), st.floats(1, 5), st.floats(0, 0.3), st.floats(0, 1))
def test_trapezoid_stop_is_the_closed_form(D, lv, la, fs, where):
    V, A = 10**lv, 10**la
    prof = plan("trapezoid", D, v_max=V, a_max=A, v_start=V * fs, v_end=V * fs)
    t = where * prof.duration
    _, v, _ = motion_state(prof, t)
    tail = stop_tail(prof, t)
    v1 = V * fs
    assert math.isclose(tail.distance, (v - v1) * (v + v1) / (2 * A), rel_tol=1e-9, abs_tol=1e-12 * D)
    assert math.isclose(tail.duration, (v - v1) / A, rel_tol=1e-9, abs_tol=1e-12)


@FAST
@given(st.floats(100, 1e5), st.floats(1, 4), st.floats(-2, 0), st.floats(0, 0.3), st.floats(0, 1))
def test_exponential_stop_rides_the_falling_curve(D, lv, ltau, fs, where):
    V, tau = 10**lv, 10**ltau
    v1 = V * fs
    prof = plan("exponential", D, v_max=V, tau=tau, v_start=v1, v_end=v1)
    t = where * prof.duration
    _, v, _ = motion_state(prof, t)
    assume(v > v1 * (1 + 1e-6) + 1e-9)
    tail = stop_tail(prof, t)
    # the falling curve of the ramp: v(s) = v1 + bd (exp((T - s)/tau) - 1), v(0) = v
    bd = (V - v1) / (1 - EXP_CUT) * EXP_CUT
    T = tau * math.log1p((v - v1) / bd)
    dist, _ = integrate.quad(lambda s: v1 + bd * math.expm1((T - s) / tau), 0.0, T, epsabs=0, epsrel=1e-12)
    assert math.isclose(tail.duration, T, rel_tol=1e-9)
    assert math.isclose(tail.distance, dist, rel_tol=1e-8)


@FAST
@given(
    st.floats(2000, 1e5),
    st.floats(2, 4),
    st.floats(2, 5),
    st.floats(3, 7),
    st.floats(0.05, 2.0),
    st.floats(0, 1),
    st.sampled_from(["scurve", "trapezoid", "exponential"]),
)
def test_override_tail_holds_the_new_limits(D, lv, la, lj, f, where, kind):
    V, A, J = 10**lv, 10**la, 10**lj
    kw = {"scurve": {"a_max": A, "j_max": J}, "trapezoid": {"a_max": A}, "exponential": {"tau": V / A}}[kind]
    prof = plan(kind, D, v_max=V, **kw)
    t = where * prof.duration
    p, v, a = motion_state(prof, t)
    tail = continue_tail(prof, t, D - p, V * f)
    if tail is None:  # only a move already braking for its end keeps its plan
        if kind == "scurve":
            # too little is left for a change of speed and a ramp down from there
            v_nat = max(v + a * abs(a) / (2 * J), 0.0)
            T = abs(a) / J  # bringing the acceleration to zero at once (closed form)
            need = [ruckig_change(v, a, V * f, A, J) + ramp_distance(V * f, A, J)]
            if v_nat <= V * f:
                settle = v * T + a * T * T / 2 - math.copysign(J, a) * T**3 / 6
                need.append(settle + ramp_distance(v_nat, A, J))
            assert D - p < min(need) * (1 + 1e-9) + 1e-9
        elif kind == "trapezoid":
            vt = min(V * f, v)
            assert D - p < abs(v * v - vt * vt) / (2 * A) + vt * vt / (2 * A) + 1e-9 * D
        return
    assert math.isclose(tail.distance, D - p, rel_tol=1e-9, abs_tol=1e-9)
    dt = 1e-12 * tail.duration
    _, v0, a0, _ = tail.sample(np.array([dt]))
    # within dt the speed moves by at most the tail's acceleration: A, or f·V/tau = f·A for an
    # exponential ramp towards f·V (at f = 2 exactly the old bound 2·A·dt: failed by 1e-11)
    assert math.isclose(float(v0[0]), v, rel_tol=1e-9, abs_tol=1e-9 * V + 2 * max(1.0, f) * A * dt)
    if kind == "scurve":  # jerk-limited: the acceleration is continuous
        assert math.isclose(float(a0[0]), a, rel_tol=1e-9, abs_tol=1e-9 * A + 2 * J * dt)
    # past the transition (the first phase edge at rest acceleration within the new
    # v_max: a jerk-limited change may first pass through a higher speed) the speed stays within it
    edges = [ph.t_start for ph in tail.phases]
    _, vel, acc, _ = tail.sample(np.array(edges))
    cap = V * f * (1 + 1e-9)
    within = [e for e, x, u in zip(edges, acc, vel, strict=True) if e > 0 and x == 0.0 and u <= cap]
    settled = within[0] if within else tail.duration
    if kind != "exponential":
        check_limits(tail, max(V * f, v, v + a * abs(a) / (2 * J) if kind == "scurve" else v) * (1 + 1e-9), A,
                     J if kind == "scurve" else None)  # fmt: skip
        _, vs, _, _ = tail.sample(np.linspace(settled, tail.duration, 500))
        assert vs.max() <= V * f * (1 + 1e-9) + 1e-9


# ----------------------------------------------------------------------------- the job's timeline


def job_steps(seed: int) -> list[int]:
    rng = np.random.default_rng(seed)
    return [int(x) for x in rng.integers(1, 20_000, rng.integers(1, 6))]


def all_times(tl: Timeline, steps: list[int]) -> np.ndarray:
    out = []
    for seg, n in enumerate(steps):
        k = np.arange(1, n + 1)
        t, done = tl.times_ns(seg, k)
        assert done == n
        out.append(t)
    return np.concatenate(out)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10**6), st.sampled_from(["scurve", "trapezoid", "exponential"]), st.floats(0, 0.5))
def test_without_commands_the_times_are_the_plans(seed, kind, dwell):
    steps = job_steps(seed)
    ramp = {**RAMP, "profile": kind, "dwell": dwell}
    timing, total = plan_timing(ramp, steps, [(0, steps[0] // 2)] if steps[0] > 2 else [], 0.25)
    tl = Timeline(ramp, timing)
    for seg, n in enumerate(steps):
        k = np.arange(1, n + 1)
        t, done = tl.times_ns(seg, k)
        assert done == n and np.array_equal(t, timing[seg].times_ns(k))
    assert tl.duration_ns == total


@settings(max_examples=60, deadline=None)
@given(
    st.integers(0, 10**6),
    st.sampled_from(["scurve", "trapezoid", "exponential"]),
    st.floats(0, 1),
    st.floats(0, 2),
    st.floats(0.05, 2),
)
# found by hypothesis in CI: the stop came 5e-7 steps short of step 3493, which
# the pause counted as reached; after the resume that step was timed 0.36 ms after the rest
@example(1592, "scurve", 1 / 3, 0.0, 1.0)
def test_pause_resume_override_keep_every_step_in_order(seed, kind, where, rest, f):
    steps = job_steps(seed)
    ramp = {**RAMP, "profile": kind, "dwell": 0.1}
    timing, total = plan_timing(ramp, steps)
    plain = all_times(Timeline(ramp, timing), steps)
    tl = Timeline(ramp, timing)
    t_pause = round(where * total)
    try:
        ev = tl.apply(Command(t_pause, "pause"))
    except CommandError:
        assert t_pause >= total  # only a job whose motion is over takes no pause
        return
    assert ev["t_rest_ns"] >= t_pause
    # the steps up to the pause keep their times; the step at rest is the last before the resume
    before = plain <= t_pause
    n_rest = ev["steps"]
    held = [tl.times_ns(seg, np.arange(1, n + 1))[1] for seg, n in enumerate(steps)]
    assert sum(held) == n_rest
    tl.apply(Command(ev["t_rest_ns"] + round(rest * 1e9), "resume"))
    tl.apply(Command(ev["t_rest_ns"] + round(rest * 1e9) + 1_000_000, "override", f))
    times = all_times(tl, steps)
    assert np.array_equal(times[before], plain[before])
    assert np.all(np.diff(times) > 0)
    if n_rest < len(times):  # motion goes on only after the resume
        assert times[n_rest] > ev["t_rest_ns"] + round(rest * 1e9)
        assert np.all(times[:n_rest] <= ev["t_rest_ns"])


def test_stop_distance_within_a_step_of_the_closed_form_and_abort_ends_there():
    ramp = {**RAMP, "profile": "scurve"}
    timing, _total = plan_timing(ramp, [40_000])
    tl = Timeline(ramp, timing)
    t = 300_000_000  # 0.3 s: mid S-curve (constant acceleration at 8192 steps/s^2)
    prof = timing[0].profiles[0]
    p, v, a = motion_state(prof, 0.3)
    assert 0 < v < ramp["v_max"] and a > 0
    ev = tl.apply(Command(t, "abort"))
    T, dist = ruckig_stop(v, a, 0.0, ramp["a_max"], ramp["j_max"])
    assert abs(ev["stop_distance"] - dist) < 1e-6
    assert ev["steps"] == math.floor(p + ev["stop_distance"] + 1e-9) and abs(ev["steps"] - (p + dist)) <= 1
    assert tl.end_step == (0, ev["steps"])
    assert ev["t_rest_ns"] == t + round(T * 1e9)
    k = np.arange(1, 40_001)
    times, done = tl.times_ns(0, k)
    assert done == ev["steps"] and times[-1] <= ev["t_rest_ns"]
    assert tl.beyond_end(0, k).sum() == 40_000 - ev["steps"]
    with pytest.raises(CommandError, match="aborted"):
        tl.apply(Command(t + 10**9, "resume"))


def test_commands_refused_when_they_cannot_apply():
    ramp = dict(RAMP)
    timing, total = plan_timing(ramp, [5000, 5000])
    tl = Timeline(ramp, timing)
    with pytest.raises(CommandError, match="not paused"):
        tl.apply(Command(10, "resume"))
    tl.apply(Command(10**8, "pause"))
    with pytest.raises(CommandError, match="already paused"):
        tl.apply(Command(2 * 10**8, "pause"))
    with pytest.raises(CommandError, match="over"):
        Timeline(ramp, timing).apply(Command(total + 1, "pause"))
    with pytest.raises(CommandError, match=r"\[0.05, 2\]"):
        tl.apply(Command(10**9, "override", 3.0))


def test_a_pause_between_moves_holds_the_next_one():
    ramp = {**RAMP, "dwell": 1.0}
    timing, _total = plan_timing(ramp, [3000, 3000])
    end0 = timing[0].duration_ns
    tl = Timeline(ramp, timing)
    ev = tl.apply(Command(end0 + 200_000_000, "pause"))  # 0.2 s into the 1 s dwell
    assert ev["stop_distance"] == 0 and ev["steps"] == 3000
    assert tl.times_ns(1, np.arange(1, 3001))[1] == 0
    tl.apply(Command(end0 + 5_000_000_000, "resume"))
    t1, done = tl.times_ns(1, np.arange(1, 3001))
    plan1 = timing[1].times_ns(np.arange(1, 3001))
    # the rest of the dwell (0.8 s) follows the resume, then the planned move
    assert done == 3000 and np.array_equal(t1 - t1[0], plan1 - plan1[0])
    assert t1[0] - plan1[0] == 4_800_000_000


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("pause@x", "KIND@SECONDS"),
        ("halt@1", "KIND@SECONDS"),
        ("override@1", "KIND@SECONDS"),
        ("override@1=5", r"\[0.05, 2\]"),
        ("pause@-1", r"\[0, 1e\+06\]"),
    ],
)
def test_schedule_errors_name_the_item(text, match):
    with pytest.raises(SpecError, match=match):
        parse_schedule(text)


def test_schedule_in_time_order():
    cmds = parse_schedule("resume@2, pause@1.5,override@3=0.5")
    assert [(c.kind, c.t_ns, c.value) for c in cmds] == [
        ("pause", 1_500_000_000, 1.0),
        ("resume", 2_000_000_000, 1.0),
        ("override", 3_000_000_000, 0.5),
    ]
