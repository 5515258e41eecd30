"""The contract every ramp of winder.motion.ramps keeps, checked for each registered one.

A new ramp module is held to these at once; its own oracle test (closed
forms, a reference library: test_profile.py holds those of today's ramps)
says that its moves are the right ones. The oracles here are written in the
test: the registry read from the folder, positions integrated from the
sampled velocity (Simpson's rule), first crossings by plain bisection on the
sampled position.
"""

from __future__ import annotations

import itertools
import math
import pkgutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from winder.motion import ramps
from winder.motion.profile import KINDS, LIMITS, Profile, plan
from winder.motion.ramps.base import MOVES, RAMPS
from winder.motion.retime import continue_tail, stop_tail

SETTINGS = {"deadline": None, "suppress_health_check": [HealthCheck.too_slow], "max_examples": 100}
FOLDER = Path(ramps.__file__).parent


def test_every_module_of_the_folder_is_a_registered_ramp() -> None:
    names = {m.name for m in pkgutil.iter_modules([str(FOLDER)])}
    plug_ins = sorted(n for n in names if not n.startswith("_") and n != "base")
    assert sorted(RAMPS) == plug_ins
    assert [r.rank for r in RAMPS.values()] == sorted(r.rank for r in RAMPS.values())
    assert tuple(n for n, r in RAMPS.items() if r.moves) == KINDS
    assert KINDS[:3] == ("scurve", "trapezoid", "exponential")  # today's, first (the default first)
    assert {n: r.limits for n, r in MOVES.items()} == LIMITS
    assert all(set(r.limits) <= {"a_max", "j_max", "tau"} for r in RAMPS.values())


def test_plan_names_the_kinds_it_knows() -> None:
    with pytest.raises(ValueError, match=r"kind='jog' is invalid: must be one of 'scurve', 'trapezoid', "):
        plan("jog", 1.0, v_max=1.0, a_max=1.0)
    assert ramps.ramp("jog").moves is False
    with pytest.raises(ValueError, match="kind='sine' is invalid"):
        ramps.ramp("sine")


def log_uniform(lo: float, hi: float) -> st.SearchStrategy[float]:
    return st.floats(math.log10(lo), math.log10(hi)).map(lambda e: 10.0**e)


@st.composite
def moves(draw: st.DrawFn, kind: str) -> Profile:
    V = draw(log_uniform(0.1, 100.0))
    limits = {name: draw(log_uniform(0.1, 100.0)) for name in LIMITS[kind]}
    v0 = V * draw(st.sampled_from([0.0, 1.0, 0.3, 0.7]))
    v1 = V * draw(st.sampled_from([0.0, 1.0, 0.5]))
    D = draw(log_uniform(0.01, 1000.0))
    try:
        prof = plan(kind, D, v_max=V, v_start=v0, v_end=v1, **limits)
    except ValueError:
        assume(False)
        raise
    assume(prof.duration < 1e4)
    return prof


def integrated(prof: Profile, t_end: float) -> float:
    """Distance from 0 to ``t_end``: Simpson's rule on the sampled velocity, per phase."""
    edges = sorted({0.0, t_end, *(ph.t_start for ph in prof.phases if 0.0 < ph.t_start < t_end)})
    total = 0.0
    for a, b in itertools.pairwise(edges):
        t = np.linspace(a, b, 401)
        # inside the phase: sample a hair inside its ends, so each side's law is used
        t[0], t[-1] = a + (b - a) * 1e-12, b - (b - a) * 1e-12
        v = prof.sample(t)[1]
        h = (b - a) / 400
        total += h / 3 * (v[0] + v[-1] + 4 * v[1:-1:2].sum() + 2 * v[2:-1:2].sum())
    return total


def first_crossing(prof: Profile, x: np.ndarray) -> np.ndarray:
    lo, hi = np.zeros_like(x), np.full_like(x, prof.duration)
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        below = prof.sample(mid)[0] < x
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return hi


@pytest.mark.parametrize("kind", KINDS)
@settings(**SETTINGS)
@given(data=st.data())
def test_a_move_is_what_its_velocity_integrates_to_and_its_steps_are_its_crossings(
    kind: str, data: st.DataObject
) -> None:
    prof = data.draw(moves(kind))
    D, T = prof.distance, prof.duration
    assert math.isclose(integrated(prof, T), D, rel_tol=1e-7, abs_tol=1e-9 * prof.v_max)
    p, v, a, _ = prof.sample(np.linspace(0.0, T, 501))
    assert np.all(np.diff(p) >= 0.0) and np.all(v >= 0.0) and np.all(v <= prof.v_max)
    if prof.a_max is not None:
        assert np.all(np.abs(a) <= prof.a_max)
    n = 257
    got = prof.step_times(n)
    assert got[-1] == T and np.all(np.diff(got) >= 0.0)
    x = np.arange(1, n, dtype=np.float64) * (D / n)
    assert np.allclose(got[:-1], first_crossing(prof, x), rtol=0.0, atol=1e-9 * max(T, 1.0))
    assert prof.ramp is RAMPS[kind]


@pytest.mark.parametrize("kind", KINDS)
@settings(**SETTINGS)
@given(data=st.data(), where=st.floats(0.0, 1.0))
def test_a_stop_and_a_continuation_start_in_the_state_they_leave(
    kind: str, data: st.DataObject, where: float
) -> None:
    prof = data.draw(moves(kind))
    t = where * prof.duration
    p, v, _, _ = (float(q) for q in prof.sample(t))
    stop = stop_tail(prof, t)
    assert stop.v_end == prof.v_end and stop.sample(stop.duration)[1] == prof.v_end
    assert stop.distance >= 0.0
    if stop.duration > 0.0:  # (below its end velocity, the start/stop rate, a move may stop at once)
        ps, vs, _, _ = (float(q) for q in stop.sample(0.0))
        assert ps == 0.0 and math.isclose(vs, v, rel_tol=1e-9, abs_tol=1e-12 * prof.v_max)
        assert math.isclose(integrated(stop, stop.duration), stop.distance, rel_tol=1e-7, abs_tol=1e-9)
    rest = prof.distance - p
    cont = continue_tail(prof, t, rest, prof.v_max * 0.8)
    if cont is not None:
        pc, vc, _, _ = (float(q) for q in cont.sample(0.0))
        assert pc == 0.0 and math.isclose(vc, v, rel_tol=1e-9, abs_tol=1e-12 * prof.v_max)
        assert math.isclose(cont.distance, rest, rel_tol=1e-12, abs_tol=1e-12)
        assert cont.sample(cont.duration)[1] == prof.v_end
        # (it may overshoot the new peak while its acceleration comes down, never the old limit)
        assert np.all(cont.sample(np.linspace(0.0, cont.duration, 201))[1] <= prof.v_max)
