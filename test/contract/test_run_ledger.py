"""The consumer's run bookkeeping (winder.contract.run), without DDS: control
events parsed or refused, the ledger's transitions against a brute-force
walk, and the job report's key/values round trip."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from winder.contract.params import stop_points
from winder.contract.run import (
    ControlEvent,
    EventError,
    JobReport,
    RunLedger,
    StopPhase,
)
from winder.contract.stream import describe_job, parse_job_description
from winder.contract.topics import STATUS_KEYS
from winder.motion.interp import interpolate
from winder.motion.job import Job

RUN = "j_20261125_101010123_1"


def plan_of(stops: str = "", resume: str = "auto", **fields: object):  # type: ignore[no-untyped-def]
    job = Job(job_id="j", turns_per_layer=3, layers=2, poles=2, fork_steps_per_rev=512, **fields)  # type: ignore[arg-type]
    points = stop_points(job, stops) if stops else []
    return parse_job_description(
        describe_job(job, run_id=RUN, stops=points, stop_pause=0.5, stop_resume=resume)
    )


def event(kind: str, **doc: object) -> str:
    return json.dumps({"event": kind, "run_id": RUN, "t_ns": 10, **doc})


# -- ControlEvent.from_wire -----------------------------------------------------------------


def test_a_well_formed_event_is_read_field_by_field() -> None:
    e = ControlEvent.from_wire(event("abort", t_rest_ns=20, steps=7, segment=1, step=3))
    assert (e.kind, e.run_id, e.t_ns, e.t_rest_ns, e.steps, e.segment, e.step) == (
        "abort",
        RUN,
        10,
        20,
        7,
        1,
        3,
    )
    o = ControlEvent.from_wire(event("override", factor=0.5))
    assert (o.kind, o.factor, o.rest_ns, o.t_rest_ns, o.steps) == ("override", 0.5, 10, None, None)


@pytest.mark.parametrize(
    ("text", "names"),
    [
        ("[1]", "not a JSON object"),
        ("{", "not JSON"),
        ("[" * 100000, "bytes"),
        ("[" * 4000, "not JSON"),
        (json.dumps({"event": "jump", "run_id": RUN, "t_ns": 1}), "event='jump'"),
        (json.dumps({"event": "pause", "run_id": 3, "t_ns": 1, "steps": 1}), "run_id=3"),
        (json.dumps({"event": "pause", "run_id": RUN, "t_ns": -1, "steps": 1}), "t_ns=-1"),
        (json.dumps({"event": "pause", "run_id": RUN, "t_ns": 1.5, "steps": 1}), "t_ns=1.5"),
        (json.dumps({"event": "pause", "run_id": RUN, "t_ns": True, "steps": 1}), "t_ns=True"),
        (json.dumps({"event": "abort", "run_id": RUN, "t_ns": 5}), "steps=None"),
        (json.dumps({"event": "abort", "run_id": RUN, "t_ns": 5, "steps": -2}), "steps=-2"),
        (json.dumps({"event": "abort", "run_id": RUN, "t_ns": 5, "t_rest_ns": 4, "steps": 2}), "t_rest_ns=4"),
        (json.dumps({"event": "override", "run_id": RUN, "t_ns": 5, "factor": "x"}), "factor='x'"),
        (json.dumps({"event": "abort", "run_id": RUN, "t_ns": 5, "steps": 2, "pad": "x" * 5000}), "bytes"),
    ],
)
def test_anything_else_is_refused_in_one_line_naming_the_key(text: str, names: str) -> None:
    with pytest.raises(EventError) as err:
        ControlEvent.from_wire(text)
    assert names in str(err.value) and "\n" not in str(err.value)


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=12,
)


@given(
    st.dictionaries(
        st.sampled_from(["event", "run_id", "t_ns", "t_rest_ns", "steps", "segment", "step", "factor", "x"]),
        json_values | st.sampled_from(["pause", "resume", "abort", "override", RUN]),
        max_size=9,
    )
)
@settings(max_examples=400, deadline=None)
def test_any_json_is_an_event_or_a_one_line_refusal(doc: dict[str, object]) -> None:
    try:
        e = ControlEvent.from_wire(json.dumps(doc))
    except EventError as exc:
        assert "\n" not in str(exc)
        return
    # accepted: what was accepted is exactly what the document says
    assert e.kind == doc["event"] and e.run_id == doc["run_id"] and e.t_ns == doc["t_ns"] >= 0
    assert e.rest_ns == doc.get("t_rest_ns", doc["t_ns"]) >= e.t_ns
    if e.kind in ("pause", "abort"):
        assert isinstance(doc["steps"], int) and e.steps == doc["steps"] >= 0


# -- the ledger --------------------------------------------------------------------


def test_an_event_of_another_run_or_against_what_was_executed_changes_nothing() -> None:
    ledger = RunLedger(plan_of())
    ledger.executed(40)
    with pytest.raises(EventError, match="not the running run"):
        ledger.apply(
            ControlEvent.from_wire(event("abort", steps=50).replace(RUN, "other_20261125_101010123_1"))
        )
    with pytest.raises(EventError, match="40 steps are executed already"):
        ledger.apply(ControlEvent.from_wire(event("abort", steps=10)))  # claims fewer steps than ran
    total = ledger.plan.total_steps
    with pytest.raises(EventError, match=f"the job has {total}"):
        ledger.apply(ControlEvent.from_wire(event("pause", steps=total + 1)))
    assert ledger.abort is None and ledger.hold is None and ledger.due(10**12) == []


def test_an_abort_ends_the_run_once_its_steps_are_executed_and_takes_no_more_events() -> None:
    ledger = RunLedger(plan_of())
    ledger.executed(40)
    first = ledger.apply(ControlEvent.from_wire(event("abort", t_rest_ns=90, steps=55, segment=0, step=55)))
    assert first is not None and first.state == "aborting"
    assert not ledger.aborted
    ledger.executed(14)
    assert not ledger.aborted
    ledger.missing_steps = 1  # a step known missing counts as accounted for
    assert ledger.aborted
    with pytest.raises(EventError, match="after the run's abort"):
        ledger.apply(ControlEvent.from_wire(event("resume")))


@pytest.mark.parametrize("missing", [0, 1])
def test_a_resume_that_comes_after_its_first_steps_ends_the_rest(missing: int) -> None:
    """Steps and events travel on two topics (issue 40: a consumer held up
    took the resumed steps before their event): at rest once every step up
    to the pause's rest is executed, no longer once a step beyond it is
    (executed, or known missing); the resume that comes after them is booked,
    not refused, and announced at its time."""
    ledger = RunLedger(plan_of())
    ledger.executed(5)
    ledger.apply(ControlEvent.from_wire(event("pause", t_ns=100, t_rest_ns=300, steps=20)))
    ledger.executed(14)
    assert ledger.held and not ledger.at_rest
    ledger.executed(1)
    assert ledger.at_rest  # all 20 steps up to the rest
    ledger.executed(1 - missing)
    ledger.missing_steps = missing
    assert ledger.held and not ledger.at_rest  # the 21st: the motion goes on
    first = ledger.apply(ControlEvent.from_wire(event("resume", t_ns=900, steps=20)))
    assert first is not None and not ledger.held and not ledger.at_rest
    assert [(t.t_ns, t.state) for t in ledger.due(10**9)] == [
        (100, "pausing"),
        (300, "paused"),
        (900, "running"),
    ]
    # a pause or an abort claiming fewer steps than were executed is still refused
    with pytest.raises(EventError, match="21 steps are executed already" if not missing else "20 steps"):
        ledger.apply(ControlEvent.from_wire(event("pause", t_ns=950, t_rest_ns=960, steps=19)))


def test_pause_and_resume_are_announced_in_time_order_as_execution_reaches_them() -> None:
    ledger = RunLedger(plan_of())
    ledger.apply(
        ControlEvent.from_wire(
            json.dumps({"event": "pause", "run_id": RUN, "t_ns": 100, "t_rest_ns": 300, "steps": 20})
        )
    )
    ledger.apply(ControlEvent.from_wire(json.dumps({"event": "resume", "run_id": RUN, "t_ns": 500})))
    assert [t.state for t in ledger.due(99)] == []
    assert ledger.transitions_ahead  # a wall-clock backend keeps telling its time
    assert [t.state for t in ledger.due(300)] == ["pausing", "paused"]
    assert ledger.op_state == "paused" and not ledger.held  # the resume is booked already
    assert ledger.transitions_ahead
    assert [(t.t_ns, t.state) for t in ledger.due(10**9)] == [(500, "running")]
    assert ledger.op_state is None and ledger.due(10**10) == [] and not ledger.transitions_ahead


@given(st.integers(1, 12), st.sampled_from(["auto", "call"]), st.data())
@settings(max_examples=60, deadline=None)
def test_programmed_stops_are_found_in_the_stream_as_a_brute_force_walk_finds_them(
    n_stops: int, resume: str, data: st.DataObject
) -> None:
    turns = [f"{c}:{t}" for c in (1, 2) for t in range(1, 7)]
    chosen = data.draw(st.lists(st.sampled_from(turns), min_size=1, max_size=n_stops, unique=True))
    plan = plan_of(",".join(chosen), resume)
    ledger = RunLedger(plan)
    # the oracle: walk every step of the job, count the fork's revolutions per coil
    job = plan.job
    want = []
    t = 0
    rows_by_seg = []
    for seg in job.segments():
        pos = interpolate(seg.start, seg.delta)
        times = list(range(t + 1, t + 1 + pos.shape[0]))
        t += pos.shape[0]
        rows_by_seg.append((seg, times))
        if seg.kind != "layer":
            continue
        # the oracle: a turn of the layer ends at the first row where the fork
        # has turned w whole revolutions from the layer's start
        turned = abs(pos[:, 1].astype(int) - seg.start[1])
        for w in range(1, job.coil(seg.pole).turns_per_layer + 1):
            k = int((turned == w * job.fork_steps_per_rev).argmax())
            coil_turn = seg.layer * job.coil(seg.pole).turns_per_layer + w
            if f"{seg.pole + 1}:{coil_turn}" in chosen:
                want.append((times[k], (seg.pole + 1, seg.layer + 1, coil_turn)))
    for seg, times in rows_by_seg:
        ledger.note_rows(seg.index, np.array(times, np.int64), np.arange(1, len(times) + 1))
    got = [(p.t_stop_ns, p.place) for p in ledger.stops]
    assert sorted(set(got)) == sorted(set(want))
    assert all(p.t_resume_ns is not None and p.t_resume_ns > p.t_stop_ns for p in ledger.stops[:-1])
    # every stop is announced paused, then running, in time order
    states = [(t.t_ns, t.state) for t in ledger.due(10**12)]
    assert states == sorted(states)
    assert sum(1 for _, s in states if s == "paused") == len(ledger.stops)
    assert all(p.phase is not StopPhase.AHEAD for p in ledger.stops)


# -- the job report ----------------------------------------------------------------


@given(
    st.sampled_from(["running", "done", "aborted", "incomplete"]),
    st.integers(0, 10**9),
    st.integers(0, 10**9),
    st.integers(0, 10**6),
    st.floats(0, 1e6, allow_nan=False),
    st.floats(0, 1e5, allow_nan=False),
    st.text(alphabet="abc/_.", max_size=20),
    st.dictionaries(
        st.sampled_from(["lost_steps", "max_tracking_error_steps", "x"]), st.text("0123456789.", max_size=6)
    ),
)
@settings(max_examples=200, deadline=None)
def test_the_report_survives_its_key_values(
    state: str,
    done: int,
    total: int,
    missing: int,
    sim_s: float,
    wall: float,
    bag: str,
    extra: dict[str, str],
) -> None:
    report = JobReport(state, "j", RUN, done, total, missing, 1, 2, sim_s, wall, bag, 3, 4, extra)
    values = {k: str(v) for k, v in report.to_values().items()}
    assert list(values)[: len(STATUS_KEYS)] == list(STATUS_KEYS) and values["role"] == "consumer"
    back = JobReport.from_values(values)
    assert back.extra == extra and back.bag == bag and back.state == state
    assert (back.steps_done, back.steps_total, back.steps_missing, back.errors, back.stalls) == (
        done,
        total,
        missing,
        3,
        4,
    )
    assert math.isclose(back.sim_time_s, sim_s, abs_tol=5.01e-7) and math.isclose(
        back.wall_time_s, wall, abs_tol=5.01e-4
    )
    assert values["progress"] == (f"{done / total:.4f}" if total else "0.0000")


@given(st.dictionaries(st.text(max_size=12), st.text(max_size=12), max_size=12))
@settings(max_examples=200, deadline=None)
def test_a_report_from_anywhere_never_raises(values: dict[str, str]) -> None:
    r = JobReport.from_values(values)
    assert isinstance(r.steps_done, int) and isinstance(r.sim_time_s, float)
    assert set(r.extra) <= set(values)
