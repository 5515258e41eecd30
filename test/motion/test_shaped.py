"""Shaped moves (winder.motion.shaped) against oracles written here.

The oracle of a shaped move is the definition: s~(t) = sum_m A_m s(t - tau_m)
with s the planned (unshaped) profile, which has its own tests against closed
forms (test_profile.py). Crossing times are found here by plain bisection on
that sum, 80 halvings; impulse trains are written out in the test (the ZV
closed form) or drawn at random.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from winder.contract.params import PROFILE_SPECS
from winder.motion.profile import Profile, plan
from winder.motion.shaped import ShapedProfile
from winder.motion.timeline import Command, Timeline
from winder.motion.timing import plan_segment, plan_timing, shaping_report


def zv(f_n: float, zeta: float) -> tuple[list[float], list[float]]:
    """The ZV shaper, written out from its closed form."""
    k = math.exp(-zeta * math.pi / math.sqrt(1 - zeta**2))
    td = 1 / (f_n * math.sqrt(1 - zeta**2))
    return [1 / (1 + k), k / (1 + k)], [0.0, td / 2]


def oracle_position(base: Profile, amps: list[float], times: list[float], t: np.ndarray) -> np.ndarray:
    total = np.zeros_like(t)
    for a, tau in zip(amps, times, strict=True):
        total += a * base.sample(t - tau)[0]
    return total


def oracle_times(base: Profile, amps: list[float], times: list[float], x: np.ndarray) -> np.ndarray:
    """First times the shaped position reaches x: bisection on [0, end]."""
    lo = np.zeros_like(x)
    hi = np.full_like(x, base.duration + times[-1])
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        reached = oracle_position(base, amps, times, mid) >= x
        hi = np.where(reached, mid, hi)
        lo = np.where(reached, lo, mid)
    return hi


def random_base(draw: Any) -> Profile:
    kind = draw(st.sampled_from(["scurve", "trapezoid", "exponential"]))
    steps = draw(st.integers(10, 200_000))
    v_max = draw(st.floats(100.0, 1e5))
    kw: dict[str, float] = {
        "a_max": draw(st.floats(1e3, 1e7)),
        "j_max": draw(st.floats(1e5, 1e11)),
        "tau": draw(st.floats(1e-3, 0.5)),
    }
    v0 = draw(st.sampled_from([0.0, 0.0, 0.1])) * v_max
    try:
        return plan(kind, float(steps), v_max=v_max, v_start=v0, v_end=v0, **kw)
    except ValueError:
        return plan(kind, float(steps), v_max=v_max, **kw)


@st.composite
def cases(draw: Any) -> tuple[Profile, list[float], list[float]]:
    base = random_base(draw)
    n = draw(st.integers(1, 5))
    raw = [draw(st.floats(0.05, 1.0)) for _ in range(n)]
    amps = [r / sum(raw) for r in raw]
    gaps = [draw(st.floats(1e-4, 0.05)) for _ in range(n - 1)]
    times = [0.0, *np.cumsum(gaps).tolist()]
    return base, amps, times


@settings(max_examples=60, deadline=None)
@given(cases())
def test_shaped_step_times_are_the_crossing_times_of_the_shaped_motion(
    case: tuple[Profile, list[float], list[float]],
) -> None:
    base, amps, times = case
    shaped = ShapedProfile(base, amps, times)
    n = round(base.distance)
    k = np.unique(np.linspace(1, n, 300).astype(np.int64))
    x = k.astype(np.float64)
    got = shaped.times_at(x)
    want = oracle_times(base, amps, times, x)
    # to 1 ns of the crossing; where the motion comes to rest (the last step)
    # the crossing is only defined to the rounding of the position (a few ulps
    # of the distance can be 1e-7 s at a jerk-limited stop): within 1 ns of a
    # time the oracle's position is within those ulps of the target
    ulps = 8 * np.spacing(base.distance)
    close = np.abs(got - want) <= 1e-9 * max(1.0, float(want[-1]))
    before = oracle_position(base, amps, times, got - 1e-9) <= x + ulps
    after = oracle_position(base, amps, times, got + 1e-9) >= x - ulps
    assert np.all(close | (before & after))
    all_times = shaped.step_times(n)
    assert np.all(np.diff(all_times) > 0.0)  # strictly increasing
    assert all_times[-1] == pytest.approx(base.duration + times[-1], abs=1e-12)
    assert shaped.duration == base.duration + times[-1]


@settings(max_examples=40, deadline=None)
@given(cases())
def test_shaped_motion_never_exceeds_the_plan_and_its_peaks_are_exact(
    case: tuple[Profile, list[float], list[float]],
) -> None:
    base, amps, times = case
    shaped = ShapedProfile(base, amps, times)
    t = np.linspace(0.0, shaped.duration, 20_001)
    _, v, a, j = shaped.sample(t)
    peaks = shaped.peaks
    # the dense samples never beat the reported peaks (which include the exact vertices)
    assert np.max(np.abs(v)) <= peaks["v"] * (1 + 1e-9) + 1e-9
    assert np.max(np.abs(a)) <= peaks["a"] * (1 + 1e-9) + 1e-9
    assert np.max(np.abs(j)) <= peaks["j"] * (1 + 1e-9) + 1e-9
    # a convex combination of the plan: no limit exceeded
    assert peaks["v"] <= max(base.v_peak, base.v_start) * (1 + 1e-12)
    if base.kind != "exponential":
        assert base.a_max is not None
        assert peaks["a"] <= base.a_max * (1 + 1e-12)
    if base.kind == "scurve":
        assert base.j_max is not None
        assert peaks["j"] <= base.j_max * (1 + 1e-12)


def test_zv_shaping_lowers_the_peak_acceleration_and_lengthens_the_move_by_its_duration() -> None:
    base = plan("scurve", 5000.0, v_max=2048.0, a_max=8192.0, j_max=65536.0 * 16)
    amps, times = zv(44.5, 0.05)
    shaped = ShapedProfile(base, amps, times)
    assert shaped.duration == base.duration + times[1]
    # a_max is held for 0.25 s, far longer than the impulse spacing: both
    # copies accelerate at a_max together
    assert shaped.peaks["a"] == pytest.approx(8192.0, rel=1e-12)
    # a ramp that is over (2 sqrt(v/j) = 6.3 ms) before the second impulse
    # (11.2 ms): the copies' accelerations never overlap, the peak is the
    # larger impulse's share of sqrt(v j)
    quick = plan("scurve", 5000.0, v_max=100.0, a_max=1e6, j_max=1e7)
    peak = ShapedProfile(quick, amps, times).peaks["a"]
    assert peak == pytest.approx(max(amps) * math.sqrt(100.0 * 1e7), rel=1e-9)


def test_a_cruise_is_delayed_by_the_mean_impulse_time() -> None:
    base = plan("trapezoid", 1e5, v_max=1000.0, a_max=1e4)
    amps, times = zv(20.0, 0.1)
    shaped = ShapedProfile(base, amps, times)
    x = np.array([5e4, 6e4])  # deep inside the cruise, for every copy
    assert shaped.times_at(x) == pytest.approx(base.times_at(x) + amps[1] * times[1], abs=1e-12)


def test_the_path_parameter_keeps_every_step_in_place_only_times_change() -> None:
    values = {name: spec.default for name, spec in PROFILE_SPECS.items()}
    plain, total = plan_timing(values, [3000, 400, 3000])
    values.update(shaper="zvd", shaper_freq=44.5, shaper_damping=0.05)
    shaped, total_s = plan_timing(values, [3000, 400, 3000])
    assert len(plain) == len(shaped)
    zvd_duration = 1 / (44.5 * math.sqrt(1 - 0.05**2))
    assert total_s - total == pytest.approx(3 * zvd_duration * 1e9, abs=3)  # one shaper per move
    for p, s in zip(plain, shaped, strict=True):
        k = np.arange(1, p.ends[-1] + 1)
        tp, ts = p.times_ns(k) - p.t0_ns, s.times_ns(k) - s.t0_ns  # from each segment's start
        assert np.all(np.diff(ts) > 0)
        assert np.all(ts >= tp)  # shaping only delays
        assert np.all(ts - tp <= round(zvd_duration * 1e9) + 1)
    report = shaping_report(shaped)["shaped"]
    assert report["peak"]["a"] <= values["a_max"] and report["peak"]["j"] <= values["j_max"]
    assert report["shaper_duration_s"] == pytest.approx(zvd_duration)
    assert shaping_report(plain) == {}


def test_a_paused_shaped_move_resumes_shaped_and_keeps_its_steps() -> None:
    values = {name: spec.default for name, spec in PROFILE_SPECS.items()}
    values.update(shaper="zv", shaper_freq=30.0, shaper_damping=0.1)
    timing, _ = plan_timing(values, [6000])
    tl = Timeline(values, timing)
    k = np.arange(1, 6001)
    before, n = tl.times_ns(0, k)
    assert n == 6000
    t_pause = int(before[2999])
    tl.apply(Command(t_pause, "pause", 0.0))
    held, n_held = tl.times_ns(0, k)
    assert 2999 < n_held < 6000
    assert np.array_equal(held[:3000], before[:3000])  # what happened before the pause stays
    assert np.all(np.diff(held) > 0)
    tl.apply(Command(t_pause + 10**9, "resume", 0.0))
    after, n_after = tl.times_ns(0, k)
    assert n_after == 6000 and np.all(np.diff(after) > 0)
    resumed = tl.moves[0].pieces[-1]
    assert resumed.kind == "resume" and isinstance(resumed.profile, ShapedProfile)


@pytest.mark.parametrize(
    ("name", "value", "needle"),
    [
        ("shaper", "zz", "shaper='zz'"),
        ("shaper_freq", 0.0, "shaper_freq=0"),
        ("shaper_damping", 0.99, "shaper_damping=0.99"),
    ],
)
def test_bad_shaper_settings_name_the_setting_and_the_range(name: str, value: object, needle: str) -> None:
    from winder.spec import SpecError

    with pytest.raises(SpecError) as err:
        PROFILE_SPECS[name].check(value)
    assert needle in str(err.value).replace(".0", "")
    assert "\n" not in str(err.value)


def test_plan_segment_shapes_with_the_settings() -> None:
    values = {name: spec.default for name, spec in PROFILE_SPECS.items()}
    values.update(shaper="ei", shaper_freq=50.0, shaper_damping=0.2)
    m = plan_segment(values, 2000)
    assert isinstance(m, ShapedProfile) and m.shaper == "ei"
    assert m.times[0] == 0.0 and m.amplitudes.sum() == pytest.approx(1.0, abs=1e-15)


@settings(max_examples=25, deadline=None)
@given(cases())
def test_every_step_of_a_long_shaped_move_is_the_sums_crossing(
    case: tuple[Profile, list[float], list[float]],
) -> None:
    """All the steps (chunks, lines and cubics, their seams) of the piecewise
    cubic solution against the Newton iteration on the impulses' sum itself."""
    base, amps, times = case
    shaped = ShapedProfile(base, amps, times)
    n = min(round(base.distance), 200_000)
    x = np.arange(1, n + 1, dtype=np.float64) * (base.distance / n)
    got = shaped.times_at(x)
    ref = shaped._solve(x, base.times_at(x))  # the exponential ramp's way: Newton on sum_m A_m s(t - tau_m)
    # the last step ends the move at rest, where the crossing is defined only to
    # the rounding of the position (step_times gives it the duration exactly)
    assert np.all(np.abs(got[:-1] - ref[:-1]) <= 1e-9 * max(1.0, float(ref[-1])))
    assert np.all(np.diff(got) >= 0.0)
