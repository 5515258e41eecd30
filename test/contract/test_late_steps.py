"""Steps that come behind a consumer's clock (issue 40): executed at the
clock, counted, reported once; never a crash.

Oracles: a loop over the steps one at a time (which are behind, where each
goes, how far behind), the exact linear response summed step by step
(``support.oracles.superpose``) for the steps moved to the clock, and the
float comparison a consumer makes for the clock's nanosecond.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support.oracles import params, superpose

from winder.axis import StepperAxis
from winder.cli.summary import report_run
from winder.contract.pacing import LateSteps, at_clock, ns_not_before

PAPER = {"Zr": 40.0, "L": 0.01005, "i_a": 1.0, "J": 1.05 * 9.80665e-5, "D": 0.03}
MICROSTEP = 2 * math.pi / (4 * 40 * 32)  # the sim node's default: 1/32 of a 2.25 deg full step


def loop_at_clock(times: list[int], clock: int) -> tuple[list[int], int, int]:
    """The oracle: one step at a time."""
    out, late, behind = [], 0, 0
    for t in times:
        if t < clock:
            late += 1
            behind = max(behind, clock - t)
            out.append(clock)
        else:
            out.append(t)
    return out, late, behind


increasing = st.lists(st.integers(0, 10**12), min_size=0, max_size=60).map(sorted)


@given(increasing, st.integers(-10, 10**12 + 10))
def test_steps_behind_the_clock_go_at_it_the_rest_at_their_time(times: list[int], clock: int) -> None:
    t = np.asarray(times, np.int64)
    out, n, behind = at_clock(t, clock)
    want, n_want, behind_want = loop_at_clock(times, clock)
    assert out.tolist() == want and (n, behind) == (n_want, behind_want)
    assert np.all(np.diff(out) >= 0)  # still in order: a tracker takes them
    if n == 0:
        assert out is t  # nothing copied when none is late


@given(
    st.lists(st.integers(1, 10**9), min_size=1, max_size=200).map(lambda d: np.cumsum(d).tolist()),
    st.data(),
)
@settings(max_examples=200)
def test_late_steps_are_counted_over_a_run_and_reported_once_when_they_stop(
    times: list[int], data: st.DataObject
) -> None:
    """A stream cut into chunks, each met by a clock that never goes back:
    the count and the largest lag are the loop's over every step; the one
    report comes after the first chunk whose last step was on time (or when
    the run closes), never twice."""
    cuts = sorted(data.draw(st.sets(st.integers(1, len(times) - 1), max_size=8))) if len(times) > 1 else []
    chunks = np.split(np.asarray(times, np.int64), cuts)
    late = LateSteps()
    clock, n_want, behind_want, reports = -1, 0, 0, []
    still_behind = False
    for chunk in chunks:
        clock = max(clock, data.draw(st.integers(int(chunk[0]) - 2 * 10**9, int(chunk[-1]) + 10**9)))
        _, n, behind = loop_at_clock(chunk.tolist(), clock)
        n_want += n
        behind_want = max(behind_want, behind)
        late.take(chunk, clock)
        still_behind = n == chunk.size
        text = late.report()
        if text:
            reports.append(text)
            assert not still_behind  # they stopped coming: the report has the numbers of all so far
            assert text.startswith(
                f"late steps: {n_want} steps came behind the clock, up to {behind_want / 1e6:.3f} ms"
            )
        clock = max(clock, int(chunk[-1]))  # the consumer executed up to the chunk's last step
    assert (late.count, late.behind_max_ns) == (n_want, behind_want)
    closing = late.report(closing=True)
    if n_want:
        assert len(reports) + bool(closing) == 1  # once a run
        assert bool(closing) == (still_behind and not reports)
        assert late.keys() == {
            "late_steps": str(n_want),
            "late_steps_behind_max_ms": f"{behind_want / 1e6:.3f}",
        }
    else:
        assert reports == [] and closing == "" and late.keys() == {}
    assert late.report(closing=True) == ""


def test_the_report_names_how_many_and_how_far_behind() -> None:
    late = LateSteps()
    late.take(np.array([1_000_000, 2_000_000, 9_000_000], np.int64), 4_500_000)
    assert late.report() == (
        "late steps: 2 steps came behind the clock, up to 3.500 ms behind; "
        "executed at the clock, not at their time"
    )
    assert late.report() == "" and late.keys()["late_steps_behind_max_ms"] == "3.500"
    assert late.take(np.array([7], np.int64), None).tolist() == [7]  # a consumer that takes any time


@given(st.floats(0.0, 1e6, allow_nan=False), st.sampled_from([1.0, 200.0, 1000.0, 3.0, 7.0]))
def test_the_clock_in_ns_is_the_first_ns_a_consumer_takes_as_not_before_it(t: float, rate: float) -> None:
    for s in (t, math.floor(t * rate) / rate):  # any time, and one on a sample grid
        ns = ns_not_before(s)
        assert ns / 1e9 >= s and (ns - 1) / 1e9 < s


def test_steps_moved_to_the_clock_keep_the_linear_model_exact() -> None:
    """As the sim node does: steps, then samples on with no steps (a paused
    real-time run's clock), then a chunk timed partly before the last sample.
    Fed as timed, the tracker refuses it (the sim node's crash, a ValueError);
    moved to the clock it takes it, and every sample equals the response
    summed step by step to the steps where they were executed."""
    axis = StepperAxis(**PAPER)
    wn, zeta, _ = params(**PAPER)
    rate = 200.0
    a_ns = np.arange(1, 11, dtype=np.int64) * 5_000_000 - 1_234  # ten steps before 0.05 s
    b_ns = np.arange(60, 121, dtype=np.int64) * 5_000_000 + 2_345  # 0.300.. 0.600 s, the clock at 0.5 s
    samples = np.arange(0, 121) / rate
    first, rest = samples[samples <= 0.5], samples[samples > 0.5]

    tracker = axis.linear_tracker()
    th_a, _ = tracker.advance(a_ns / 1e9, MICROSTEP, first)
    as_timed = axis.linear_tracker()
    as_timed.advance(a_ns / 1e9, MICROSTEP, first)
    with pytest.raises(ValueError, match=r"must be >= the last sample time already returned \(0\.5 s\)"):
        as_timed.advance(b_ns / 1e9, MICROSTEP, rest)

    late = LateSteps()
    clock = ns_not_before(float(first[-1]))
    executed = late.take(b_ns, clock)
    assert late.count == int(np.count_nonzero(b_ns < 500_000_000)) == 40
    assert late.behind_max_ns == clock - int(b_ns[0])
    th_b, om_b = tracker.advance(executed / 1e9, MICROSTEP, rest)

    angles_a = np.full(a_ns.size, MICROSTEP)
    ref_a, _ = superpose(wn, zeta, a_ns / 1e9, angles_a, first)
    ref_b, om_ref = superpose(
        wn, zeta, np.r_[a_ns, executed] / 1e9, np.full(a_ns.size + executed.size, MICROSTEP), rest
    )
    total = MICROSTEP * (a_ns.size + executed.size)
    assert np.max(np.abs(th_a - ref_a)) <= 1e-9 * total
    assert np.max(np.abs(th_b - ref_b)) <= 1e-9 * total
    assert np.max(np.abs(om_b - om_ref)) <= 1e-9 * total * wn


def finished_run(extra: dict[str, str]) -> SimpleNamespace:
    """What ``winder run`` hands its summary: a done run's final report with ``extra``."""
    values = {
        "state": "done",
        "run_id": "r",
        "steps_done": "10",
        "steps_total": "10",
        "lost_steps": "0",
        "bag": "",
        **extra,
    }
    return SimpleNamespace(summary=values, errors=[], ok=True, message="done", log_dir="")


def test_the_run_summary_names_late_steps(capsys: pytest.CaptureFixture[str]) -> None:
    report_run(finished_run({"late_steps": "41", "late_steps_behind_max_ms": "1000.250"}), 1.0, stops=False)
    out = capsys.readouterr().out
    assert "  late steps         41  (up to 1000.250 ms behind the clock, executed at it)\n" in out
    report_run(finished_run({}), 1.0, stops=False)
    assert "late steps" not in capsys.readouterr().out
