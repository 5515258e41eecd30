"""winder's own ROS types carry the core's records exactly (winder_interfaces).

A control event, a job description and a final report go out as
winder_interfaces messages (``winder.ros.interfaces``) and are read back by
their fields (``ControlEvent.from_message``, ``description_text``,
``JobReport.from_message``), from rclpy's bytes and from what rosbags decodes
of them: over wide random inputs, what comes back is what went out. The
oracle is the record itself (and, for a description, the JSON text that
``describe_job`` writes and ``parse_job_description`` checks, as before the
typed message). A typed description that lies about its job is refused in
one line, as the JSON one is.
"""

from __future__ import annotations

import math
from typing import Any

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from winder.contract.events import ControlEvent, EventError
from winder.contract.params import PROFILE_SPECS
from winder.contract.run import JobReport
from winder.contract.states import EventKind, EventSource
from winder.contract.stream import (
    RUN_TEXT_PATTERN,
    describe_job,
    description_text,
    parse_job_description,
    with_source,
)
from winder.errors import BadInputError
from winder.motion.job import Job, JobError
from winder.record.msgtypes import typestore_for

#: texts as ROS strings carry them (no NUL)
TEXT = st.characters(exclude_characters="\x00", exclude_categories=("Cs",))

RUN = "part_20261128_101010123_1"


def through_the_wire(msg: Any, name: str) -> tuple[Any, Any]:
    """``msg`` serialized by rclpy, then read back by rclpy and by rosbags
    (winder's bag store): the two readings."""
    from rclpy.serialization import deserialize_message, serialize_message

    raw = serialize_message(msg)
    return (
        deserialize_message(raw, type(msg)),
        typestore_for([name]).deserialize_cdr(raw, name),
    )


# -- control events -------------------------------------------------------------------


def maybe(strategy: st.SearchStrategy[Any]) -> st.SearchStrategy[Any]:
    return st.none() | strategy


@st.composite
def events(draw: st.DrawFn) -> ControlEvent:
    kind = draw(st.sampled_from(list(EventKind)))
    t_ns = draw(st.integers(0, 2**62))
    stops = kind.stops
    rest = draw(st.integers(t_ns, 2**63 - 1)) if stops else draw(maybe(st.integers(t_ns, 2**63 - 1)))
    steps = draw(st.integers(0, 2**62)) if stops else draw(maybe(st.integers(0, 2**62)))
    finite = st.floats(-1e12, 1e12, allow_nan=False)
    return ControlEvent(
        kind,
        draw(st.text(TEXT, max_size=30)),
        t_ns,
        rest,
        steps,
        draw(st.integers(-1, 10**6)),
        draw(st.integers(0, 10**9)),
        draw(finite) if kind is EventKind.OVERRIDE else None,
        job_id=draw(maybe(st.text(TEXT, min_size=1, max_size=12))),
        source=draw(maybe(st.sampled_from(list(EventSource)))),
        t_request_ns=draw(maybe(st.integers(0, 2**62))),
        latency_ns=draw(maybe(st.integers(0, 2**62))),
        v=draw(maybe(finite)),
        a=draw(maybe(finite)),
        stop_distance=draw(maybe(finite)),
        v_max=draw(maybe(finite)),
        note=draw(maybe(st.text(TEXT, min_size=1, max_size=20))),
    )


@given(events())
@settings(max_examples=300, deadline=None)
def test_an_event_comes_back_from_its_message_as_it_went(event: ControlEvent) -> None:
    from winder.ros.interfaces import control_event_msg

    by_rclpy, by_rosbags = through_the_wire(control_event_msg(event), "winder_interfaces/msg/ControlEvent")
    assert ControlEvent.from_message(by_rclpy) == event
    assert ControlEvent.from_message(by_rosbags) == event
    # and as the JSON of the bags before it says it
    assert ControlEvent.from_wire(event.to_wire()) == event


def test_a_message_that_is_no_event_is_refused_in_one_line() -> None:
    from winder_interfaces.msg import ControlEvent as Msg

    for msg, names in (
        (Msg(event="stop", run_id=RUN), "event='stop'"),
        (Msg(event="abort", run_id=RUN, t_ns=5, t_rest_ns=9, steps=-1), "steps=None"),
        (Msg(event="override", run_id=RUN, t_ns=5, t_rest_ns=-1, factor=math.nan), "factor=None"),
        (Msg(event="pause", run_id=RUN, t_ns=-3, steps=1), "t_ns=-3"),
        (Msg(event="pause", run_id=RUN, t_ns=10, t_rest_ns=4, steps=1), "t_rest_ns=4"),
    ):
        with pytest.raises(EventError) as caught:
            ControlEvent.from_message(msg)
        assert str(caught.value).startswith(names) and "\n" not in str(caught.value)


# -- job descriptions -----------------------------------------------------------------


@st.composite
def descriptions(draw: st.DrawFn) -> str:
    fields: dict[str, Any] = {
        "job_id": draw(st.from_regex(r"[a-z][a-z0-9_]{0,11}", fullmatch=True)),
        "turns_per_layer": draw(st.integers(1, 30)),
        "layers": draw(st.integers(1, 4)),
        "poles": draw(st.integers(1, 6)),
        "fork_steps_per_rev": draw(st.sampled_from([64, 200, 256, 1024])),
        "pole_steps_per_rev": draw(st.sampled_from([200, 1024])),
        "wire_diameter": draw(st.floats(0.0002, 0.004)),
        "feed_step": draw(st.sampled_from([1e-5, 2.5e-6, 5e-5])),
        "flyer_radius": draw(st.floats(0.05, 1.0)),
        "lay": draw(st.sampled_from(["helical", "orthocyclic"])),
        "lay.crossover": 180.0,
        "first_layer_speed": draw(st.floats(0.1, 1.0)),
        "tension.set": draw(st.sampled_from([0.0, 1.5])),
        "tension.derate": draw(st.booleans()),
    }
    try:
        job = Job.from_dict(fields)
    except JobError:
        assume(False)
    layer_segments = [s for s in job.segments() if s.kind.winds]
    stops = sorted(
        {
            (s.index, draw(st.integers(1, s.steps)))
            for s in draw(st.lists(st.sampled_from(layer_segments), max_size=3))
        }
    )
    ramp = None
    if draw(st.booleans()):
        ramp = {name: spec.default for name, spec in PROFILE_SPECS.items()}
        ramp["v_max"] = draw(st.floats(1.0, 1e6))
        ramp["profile"] = draw(st.sampled_from(["scurve", "trapezoid", "exponential"]))
    text = describe_job(
        job,
        draw(st.sampled_from(["", RUN])),
        ramp,
        stops,
        draw(st.sampled_from([0.0, 0.5, 12.25])),
        draw(st.sampled_from(["auto", "call"])),
        draw(st.sampled_from(["", "pause@1.5,resume@3"])),
        draw(st.sampled_from(["", "ab" * 32])),
        # who ran it with which wire: any text the rule takes (Unicode beyond the BMP too)
        operator=draw(st.from_regex(RUN_TEXT_PATTERN, fullmatch=True)),
        wire_lot=draw(st.from_regex(RUN_TEXT_PATTERN, fullmatch=True)),
    )
    if draw(st.booleans()):  # a re-simulation's
        text = with_source(text, RUN.replace("_1", "_2"), "/bags/" + draw(st.text("abc_/", min_size=1)))
    return text


@given(descriptions())
@settings(max_examples=120, deadline=None)
def test_a_description_comes_back_from_its_message_as_the_same_text(text: str) -> None:
    from winder.ros.interfaces import job_description_msg

    msg = job_description_msg(text)
    by_rclpy, by_rosbags = through_the_wire(msg, "winder_interfaces/msg/JobDescription")
    assert description_text(by_rclpy) == text
    assert description_text(by_rosbags) == text
    plan = parse_job_description(description_text(by_rclpy))
    assert plan == parse_job_description(text)
    # what a reader sees without parsing anything
    assert (by_rclpy.run_id, by_rclpy.job_id, by_rclpy.total_steps) == (
        plan.run_id,
        plan.job_id,
        plan.total_steps,
    )
    assert [(s.segment, s.step) for s in by_rclpy.stops] == list(plan.stops)
    assert by_rclpy.has_ramp == (plan.ramp is not None)
    assert (by_rclpy.operator_name, by_rclpy.wire_lot) == (plan.operator, plan.wire_lot)
    assert [
        (s.kind, tuple(s.start), tuple(s.delta), s.steps, s.pole, s.layer) for s in by_rclpy.segments
    ] == [(str(s.kind), tuple(s.start), tuple(s.delta), s.steps, s.pole, s.layer) for s in plan.segments]


def test_a_description_that_lies_about_its_job_is_refused_in_one_line() -> None:
    from winder.ros.interfaces import job_description_msg

    text = describe_job(Job.from_dict({"job_id": "part", "turns_per_layer": 3, "poles": 2}), RUN)

    def lie(change: Any) -> str:
        msg = job_description_msg(text)
        change(msg)
        with pytest.raises(BadInputError) as caught:
            parse_job_description(description_text(msg))
        assert "\n" not in str(caught.value)
        return str(caught.value)

    assert "job_id" in lie(lambda m: setattr(m, "job_id", "other"))
    assert "total_steps" in lie(lambda m: setattr(m, "total_steps", 10**15))
    assert "segment 1" in lie(lambda m: setattr(m.segments[1], "delta", [1, 2, 3]))
    assert "format" in lie(lambda m: setattr(m, "format", "winder.job/2"))

    def more_turns(m: Any) -> None:  # the job's fields say more turns than its segments wind
        for kv in m.job:
            if kv.key == "turns_per_layer":
                kv.value = "4"

    assert "segment" in lie(more_turns)

    def no_job_id(m: Any) -> None:  # the job's id left out: the job is the default's, not the message's
        m.job = [kv for kv in m.job if kv.key != "job_id"]

    assert "job_id 'part' is not its job's ('rw400')" in lie(no_job_id)


def test_a_value_as_a_job_file_writes_it_is_taken_as_its_setting_takes_it() -> None:
    """A typed description's values may be written as a job file or --set
    writes them (``.5``, ``+2``, ``yes``), not only as JSON: each is read as
    its setting reads it, and the description is that job's."""
    from diagnostic_msgs.msg import KeyValue

    from winder.ros.interfaces import job_description_msg

    job = Job.from_dict({"job_id": "part", "flyer_radius": 0.5, "poles": 2, "tension.derate": True})
    msg = job_description_msg(describe_job(job, RUN))
    written = {"flyer_radius": ".5", "poles": "+2", "tension.derate": "yes"}
    msg.job = [KeyValue(key=kv.key, value=written.get(kv.key, kv.value)) for kv in msg.job]
    assert {kv.key: kv.value for kv in msg.job}["poles"] == "+2"
    plan = parse_job_description(description_text(msg))
    assert (plan.job.flyer_radius, plan.job.poles, plan.job.tension_derate) == (0.5, 2, True)
    assert plan.job == job


# -- final reports --------------------------------------------------------------------


@given(
    st.sampled_from(["done", "aborted", "incomplete"]),
    st.integers(0, 2**63),
    st.integers(0, 2**63),
    st.integers(0, 2**32 - 1),
    st.floats(0, 1e9, allow_nan=False),
    st.text(TEXT, max_size=40),
    st.dictionaries(st.text(TEXT, min_size=1, max_size=12), st.text(TEXT, max_size=12), max_size=6),
)
@settings(max_examples=200, deadline=None)
def test_a_report_comes_back_from_its_message_as_it_went(
    state: str, done: int, total: int, count: int, seconds: float, bag: str, extra: dict[str, str]
) -> None:
    from winder.ros.interfaces import job_report_msg

    report = JobReport(
        state, "j", RUN, done, total, done, count, count, seconds, seconds, bag, count, count, extra
    )
    msg = job_report_msg(report, "cell1/axes")
    by_rclpy, by_rosbags = through_the_wire(msg, "winder_interfaces/msg/JobReport")
    assert JobReport.from_message(by_rclpy) == report
    assert JobReport.from_message(by_rosbags) == report
    assert by_rclpy.node == by_rosbags.node == "cell1/axes" and by_rclpy.stamp.sec > 0
