"""States and events as types (winder.contract.states, winder.contract.events):
every enum holds exactly the wire strings docs/CONTRACT.md lists, and a
control event survives its trip over the wire unchanged."""

from __future__ import annotations

import json
import re

from hypothesis import given, settings
from hypothesis import strategies as st
from support.paths import ROOT

from winder.contract.events import ControlEvent
from winder.contract.states import FINAL_JOB_STATES, CellState, EventKind, EventSource, JobState, ReadyState
from winder.contract.topics import CELL_STATES, JOB_STATES, READY_STATES
from winder.motion.timeline import COMMANDS

CONTRACT = (ROOT / "docs" / "CONTRACT.md").read_text()


def section(title: str) -> str:
    """The text of the section whose heading starts with ``title`` (up to the next heading)."""
    m = re.search(rf"^#+ {re.escape(title)}.*?$(.*?)(?=^#)", CONTRACT, re.S | re.M)
    assert m, f"docs/CONTRACT.md has no section {title!r}"
    return m.group(1)


def row(text: str, key: str) -> str:
    """The value cells of the table row whose first cell is ``key`` (backquoted)."""
    m = re.search(rf"^\| `{re.escape(key)}` \|(.*)$", text, re.M)
    assert m, f"no table row `{key}`"
    return m.group(1)


def top_level_words(text: str) -> list[str]:
    """The backquoted words outside parentheses (``idle`` (node start), ... ->
    idle, ...): the values a row lists, not the words explaining them."""
    flat, depth = [], 0
    for ch in text:
        depth += ch == "("
        if depth == 0:
            flat.append(ch)
        depth -= ch == ")" and depth > 0
    return re.findall(r"`([a-z_]+)`", "".join(flat))


def test_cell_states_are_the_documented_ones() -> None:
    words = top_level_words(row(section("3.6 `winder/state`"), "state"))
    assert [s.value for s in CellState] == words
    assert tuple(CellState) == CELL_STATES


def test_job_states_are_the_documented_ones() -> None:
    m = re.search(r"`state` is one of `topics.JOB_STATES`:(.*?)\.\n", section("3.7 Job status"), re.S)
    assert m
    assert [s.value for s in JobState] == re.findall(r"`([a-z_]+)`", m.group(1))
    assert tuple(JobState) == JOB_STATES
    ended = re.search(r"\*\*Final report\*\*.*?`state` (.*?);", section("3.7 Job status"), re.S)
    assert ended
    assert [s.value for s in FINAL_JOB_STATES] == re.findall(r"`([a-z_]+)`", ended.group(1))


def test_ready_states_are_the_documented_ones() -> None:
    words = top_level_words(row(section("3.4 `winder/ready`"), "value"))
    assert [s.value for s in ReadyState] == words
    assert tuple(ReadyState) == READY_STATES


def test_event_kinds_and_sources_are_the_documented_ones() -> None:
    events = section("3.3 `winder/control`")
    assert [k.value for k in EventKind] == top_level_words(row(events, "event").split("|")[2])
    assert [s.value for s in EventSource] == top_level_words(row(events, "source").split("|")[2])
    assert tuple(EventKind) == COMMANDS  # the time law's commands (the motion layer's own tuple)


def test_members_are_their_wire_strings() -> None:
    assert all(s == s.value for s in (*CellState, *JobState, *ReadyState, *EventKind, *EventSource))
    assert f"{JobState.STALLED}" == "stalled"
    assert json.dumps({"state": ReadyState.BUSY}) == '{"state": "busy"}'
    assert JobState("aborted") is JobState.ABORTED


# -- control events over the wire ------------------------------------------------------------

ids = st.text(st.characters(codec="utf-8"), max_size=12)
nonneg = st.integers(0, 2**62)
finite = st.floats(allow_nan=False, allow_infinity=False)
maybe = st.none


@st.composite
def events(draw: st.DrawFn) -> ControlEvent:
    """A well-formed event as a producer builds it: steps for a pause or an
    abort, a factor for an override only, its rest not before it."""
    kind = draw(st.sampled_from(EventKind))
    t_ns = draw(nonneg)
    stops = kind.stops
    rest = draw(st.integers(t_ns, 2**63 - 1) | (st.none() if not stops else st.nothing()))
    return ControlEvent(
        kind,
        draw(ids),
        t_ns,
        t_rest_ns=rest if stops else draw(st.none() | st.integers(t_ns, 2**63 - 1)),
        steps=draw(nonneg) if stops else draw(maybe() | nonneg),
        segment=draw(st.integers(-1, 10**6)),
        step=draw(st.integers(0, 10**6)),
        factor=draw(finite) if kind is EventKind.OVERRIDE else None,
        job_id=draw(maybe() | ids),
        source=draw(maybe() | st.sampled_from(EventSource)),
        t_request_ns=draw(maybe() | st.integers()),
        latency_ns=draw(maybe() | st.integers()),
        v=draw(maybe() | finite),
        a=draw(maybe() | finite),
        stop_distance=draw(maybe() | finite),
        v_max=draw(maybe() | finite),
        note=draw(maybe() | ids),
    )


@given(events())
@settings(max_examples=300, deadline=None)
def test_an_event_survives_the_wire(event: ControlEvent) -> None:
    wire = event.to_wire()
    assert isinstance(json.loads(wire), dict)
    assert ControlEvent.from_wire(wire) == event


@given(events())
@settings(max_examples=100, deadline=None)
def test_the_wire_text_is_the_documented_object(event: ControlEvent) -> None:
    """Keys as CONTRACT.md §3.3 names them, plain JSON values, none that is null."""
    doc = json.loads(event.to_wire())
    assert doc["event"] == event.kind.value and doc["run_id"] == event.run_id and doc["t_ns"] == event.t_ns
    documented = set(
        re.findall(r"^\| `([a-z_]+)`(?:, `([a-z_]+)`)? \|", section("3.3 `winder/control`"), re.M)
    )
    keys = {k for pair in documented for k in pair if k}
    assert set(doc) <= keys and None not in doc.values()


def test_a_producer_event_reads_back_with_the_run_added() -> None:
    effect = {
        "event": "pause",
        "source": "call",
        "t_ns": 5,
        "t_rest_ns": 9,
        "steps": 3,
        "segment": 0,
        "step": 3,
    }
    event = ControlEvent.from_doc(effect, run_id="r", job_id="j", t_request_ns=4)
    assert (event.kind, event.source, event.run_id, event.job_id, event.rest_ns) == (
        EventKind.PAUSE,
        EventSource.CALL,
        "r",
        "j",
        9,
    )
    assert ControlEvent.from_wire(event.to_wire()) == event


def test_annotations_that_are_ill_formed_read_as_absent() -> None:
    text = json.dumps(
        {"event": "abort", "run_id": "r", "t_ns": 1, "steps": 2, "source": "x", "v": "fast", "note": 3}
    )
    event = ControlEvent.from_wire(text)
    assert event.kind is EventKind.ABORT and event.steps == 2 and event.rest_ns == 1
    assert (event.source, event.v, event.note) == (None, None, None)
