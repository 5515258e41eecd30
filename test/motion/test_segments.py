"""One Segment type (issue 42, item 2): each segment's coil, layer, turns,
place and stop points against a brute-force walk of the job's coils, layers
and turns written here; a job laid out once; a job description's plan holds
the job's own segments, and descriptions recorded before still parse."""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import HealthCheck, given, reject, settings
from hypothesis import strategies as st

from winder.contract.params import stop_place, stop_points
from winder.contract.stream import JobPlan, SegmentPlan, describe_job, parse_job_description
from winder.motion.job import Job, JobError, Segment, SegmentKind
from winder.spec import SpecError

# -- the oracle: the job walked turn by turn, in plain loops --------------------------------------


def walk(job: Job) -> list[dict[str, object]]:
    """What every segment must say, from the job's settings alone: per coil
    (its turns per layer, layers and direction as asked) its layers, a pole
    index between coils; the feed reversing at every layer (across coils
    too), the fork turning one revolution a turn plus the reversal dwell, the
    pole indexing 360/poles deg (cumulative rounding). Helical jobs with
    given turns: the turns of a layer are its coil's turns per layer."""
    spr = job.fork_steps_per_rev
    dwell = math.floor(job.reversal_dwell * spr + 0.5)
    out: list[dict[str, object]] = []
    feed = fork = pole_pos = 0
    going = 1
    for coil in range(job.poles):
        c = job.coil(coil)
        if coil:
            to = round(coil * job.pole_steps_per_rev / job.poles)
            out.append(
                {
                    "kind": SegmentKind.INDEX,
                    "pole": coil,
                    "layer": -1,
                    "turns": 0,
                    "first_turn": 0,
                    "start": (feed, fork, pole_pos),
                    "end": (feed, fork, to),
                }
            )
            pole_pos = to
        before = 0
        for layer in range(c.layers):
            turns = 0
            fork_steps = 0
            for _turn in range(c.turns_per_layer):  # one revolution of the flyer a turn
                turns += 1
                fork_steps += spr
            fork_steps += dwell
            feed_steps = math.floor(turns * job.wire_diameter / job.feed_step * (1 + 1e-9) + 0.5)
            start = (feed, fork, pole_pos)
            feed += going * feed_steps
            fork += c.direction * fork_steps
            out.append(
                {
                    "kind": SegmentKind.LAYER,
                    "pole": coil,
                    "layer": layer,
                    "turns": turns,
                    "first_turn": before,
                    "start": start,
                    "end": (feed, fork, pole_pos),
                }
            )
            before += turns
            going = -going
    return out


def oracle_stop(job: Job, coil: int, turn: int) -> int | None:
    """The step index of the end of turn ``turn`` (from 1) of coil ``coil``
    (from 1) in its layer, counted by walking the coil's layers; None when it
    falls inside a layer whose feed outnumbers its fork steps."""
    c = job.coil(coil - 1)
    spr = job.fork_steps_per_rev
    dwell = math.floor(job.reversal_dwell * spr + 0.5)
    left = turn
    for _layer in range(c.layers):
        if left <= c.turns_per_layer:
            fork = c.turns_per_layer * spr + dwell
            feed = math.floor(c.turns_per_layer * job.wire_diameter / job.feed_step * (1 + 1e-9) + 0.5)
            if left == c.turns_per_layer:
                return max(fork, feed)
            return left * spr if fork >= feed else None
        left -= c.turns_per_layer
    raise AssertionError("turn out of the coil")


@st.composite
def jobs(draw: st.DrawFn) -> Job:
    poles = draw(st.integers(1, 4))
    overrides = []
    for coil in range(1, poles + 1):
        if draw(st.booleans()):
            parts = []
            if draw(st.booleans()):
                parts.append(f"turns_per_layer={draw(st.integers(1, 6))}")
            if draw(st.booleans()):
                parts.append(f"layers={draw(st.integers(1, 4))}")
            if draw(st.booleans()):
                parts.append(f"direction={draw(st.sampled_from(['cw', 'ccw']))}")
            if parts:
                overrides.append(f"{coil}:{','.join(parts)}")
    try:
        return make_job(draw, overrides, poles)
    except JobError:  # a reversal dwell where the feed leads: refused, not laid out
        reject()


def make_job(draw: st.DrawFn, overrides: list[str], poles: int) -> Job:
    return Job(
        job_id="seg",
        turns_per_layer=draw(st.integers(1, 6)),
        layers=draw(st.integers(1, 4)),
        poles=poles,
        fork_steps_per_rev=draw(st.sampled_from([8, 16, 64])),
        pole_steps_per_rev=draw(st.sampled_from([8, 100, 1024])),
        wire_diameter=draw(st.sampled_from([1e-4, 5e-4, 2.5e-3])),
        feed_step=1e-5,
        reversal_dwell=draw(st.sampled_from([0.0, 0.5, 1.0, 2.25])),
        coil_overrides=";".join(overrides),
    )


SETTINGS = settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@SETTINGS
@given(jobs())
def test_each_segment_says_what_the_walk_of_its_job_says(job: Job) -> None:
    segs = job.segments()
    expected = walk(job)
    assert len(segs) == len(expected)
    for s, e in zip(segs, expected, strict=True):
        got = {
            "kind": s.kind,
            "pole": s.pole,
            "layer": s.layer,
            "turns": s.turns,
            "first_turn": s.first_turn,
            "start": s.start,
            "end": s.end,
        }
        assert got == e, s.index
        assert s.index == segs.index(s)
        assert s.last_turn == s.first_turn + s.turns
        lo, hi = s.fork_range
        assert lo <= hi and {lo, hi} == {s.start[1], s.end[1]}
        assert abs(s.delta[s.major]) == s.steps
        assert s.turn_steps == (job.fork_steps_per_rev if s.kind.winds else 0)
    for coil in range(job.poles):  # a coil's layers count its turns on from each other
        layers = [s for s in segs if s.kind.winds and s.pole == coil]
        assert [s.layer for s in layers] == list(range(job.coil(coil).layers))
        assert layers[-1].last_turn == job.turns_of(coil)


@SETTINGS
@given(jobs(), st.data())
def test_stop_points_are_the_turn_ends_the_walk_finds(job: Job, data: st.DataObject) -> None:
    coil = data.draw(st.integers(1, job.poles))
    turn = data.draw(st.integers(1, job.turns_of(coil - 1)))
    step = oracle_stop(job, coil, turn)
    if step is None:
        with pytest.raises(SpecError, match="outnumber its fork steps"):
            stop_points(job, f"{coil}:{turn}")
        return
    [(seg, k)] = stop_points(job, f"{coil}:{turn}")
    segment = job.segments()[seg]
    assert (segment.pole + 1, k) == (coil, step)
    assert segment.first_turn < turn <= segment.last_turn
    assert k in segment.stop_points
    # the inverse: where the axes rest is that turn of that coil
    assert stop_place(job, segment, k) == (coil, segment.layer + 1, turn)
    assert segment.turn_at(k) == turn


@SETTINGS
@given(jobs())
def test_a_layers_stop_points_are_its_turns_ends(job: Job) -> None:
    spr = job.fork_steps_per_rev
    for s in job.segments():
        if not s.kind.winds:
            assert s.stop_points == () and not s.stops_inside
            continue
        fork, feed = abs(s.delta[1]), abs(s.delta[0])
        assert s.stops_inside == (fork >= feed)
        if fork >= feed:
            assert s.stop_points == (*(t * spr for t in range(1, s.turns)), s.steps)
            for t in range(1, s.turns + 1):  # each turn's end is where its turn is complete
                assert s.turn_at(s.turn_end(t)) == s.first_turn + t
                # a step short of the fork's turn end: one turn less (the dwell after the last is its own)
                assert s.turn_at(t * spr - 1) == s.first_turn + t - 1
        else:
            assert s.stop_points == (s.steps,)
            if s.turns > 1:
                with pytest.raises(ValueError, match="do not end on step indices"):
                    s.turn_end(1)
        with pytest.raises(ValueError, match="has turns"):
            s.turn_end(s.turns + 1)


def orthocyclic_auto() -> Job:
    """An orthocyclic coil of three auto layers: the shifted layer holds a turn less."""
    return Job.from_dict(
        {
            "lay": "orthocyclic",
            "lay.crossover": 180.0,
            "turns_per_layer": "auto",
            "bobbin.window_width": 0.0101,
            "layers": 3,
            "poles": 1,
        }
    )


def test_stop_points_follow_layers_of_unequal_turns() -> None:
    """Orthocyclic, auto: the shifted layers hold one turn less; a stop is
    found in the layer that holds the turn, not at turns_per_layer x layer."""
    job = orthocyclic_auto()
    layers = [s for s in job.segments() if s.kind.winds]
    turns = [s.turns for s in layers]
    assert turns[0] == turns[1] + 1, turns  # the shifted layer holds one less
    first_of_2 = turns[0] + 1
    [(seg, k)] = stop_points(job, f"1:{first_of_2}")
    assert (seg, k) == (layers[1].index, job.fork_steps_per_rev)
    [(seg, k)] = stop_points(job, f"1:{turns[0] + turns[1]}")
    assert (seg, k) == (layers[1].index, layers[1].steps)
    assert stop_place(job, layers[2], job.fork_steps_per_rev) == (1, 3, turns[0] + turns[1] + 1)


# -- laid out once ------------------------------------------------------------------------------


def test_segments_are_laid_out_once_per_job(monkeypatch: pytest.MonkeyPatch) -> None:
    calls = []
    lay_out = Job._lay_out

    def counted(self: Job) -> list[Segment]:
        calls.append(self)
        return lay_out(self)

    monkeypatch.setattr(Job, "_lay_out", counted)
    job = Job(turns_per_layer=3, layers=2, poles=3)
    first = job.segments()
    assert job.segments() is first and job.total_steps == sum(s.steps for s in first)
    assert len(calls) == 1
    plan = parse_job_description(describe_job(job))
    assert plan.segments is plan.job.segments()  # the plan's segments: its job's, the same tuple
    assert len(calls) == 2  # the description's job, laid out once for its check and its plan
    assert plan.segments == first  # equal jobs, equal segments
    assert job == plan.job and hash(job) == hash(plan.job)  # the cache is no field


def test_the_plan_segment_type_is_the_segment() -> None:
    assert SegmentPlan is Segment
    plan = parse_job_description(describe_job(Job(lay="orthocyclic", crossover=180.0, poles=2)))
    assert all(type(s) is Segment for s in plan.segments)
    assert all(len(s.pieces) > 1 for s in plan.segments if s.kind.winds)  # the cams travel with it


# -- descriptions recorded before ----------------------------------------------------------------

#: a description as the interp node published it (and bags hold it): no
#: field of the segment records beyond kind, start, delta, steps, pole, layer
RECORDED = (
    '{"format":"winder.job/1","run_id":"","ramp":null,"stops":[],"stop_pause":0.0,"stop_resume":"auto",'
    '"schedule":"","job_file_sha256":"","job":{"job_id":"old","wire_diameter":0.0025,"flyer_radius":0.5,'
    '"turns_per_layer":2,"layers":2,"poles":2,"fork_steps_per_rev":8,"feed_step":1e-05,'
    '"pole_steps_per_rev":8,"coil_length":0.0,"coil_overrides":"","bobbin.window_width":0.0,'
    '"bobbin.window_height":0.0,"bobbin.core":"round","bobbin.core_diameter":0.0,"bobbin.core_width":0.0,'
    '"bobbin.core_depth":0.0,"wire.bare_diameter":0.0,"lay":"helical","lay.crossover":60.0,'
    '"lay.crossover_at":0.0,"reversal_dwell":0.0,"first_layer_speed":1.0},"axes":["feed","fork","pole"],'
    '"joint_step":[1e-05,0.7853981633974483,0.7853981633974483],'
    '"step_lengths":[1e-05,0.39269908169872414,0.7853981633974483],"total_steps":2004,'
    '"segments":[{"kind":"layer","start":[0,0,0],"delta":[500,16,0],"steps":500,"pole":0,"layer":0},'
    '{"kind":"layer","start":[500,16,0],"delta":[-500,16,0],"steps":500,"pole":0,"layer":1},'
    '{"kind":"index","start":[0,32,0],"delta":[0,0,4],"steps":4,"pole":1,"layer":-1},'
    '{"kind":"layer","start":[0,32,4],"delta":[500,16,0],"steps":500,"pole":1,"layer":0},'
    '{"kind":"layer","start":[500,48,4],"delta":[-500,16,0],"steps":500,"pole":1,"layer":1}]}'
)


def _oldest(text: str) -> str:
    """The description as the first bags hold it: no run id, ramp, stops,
    schedule or file digest, and the job's first fields only."""
    doc = json.loads(text)
    for key in ("run_id", "ramp", "stops", "stop_pause", "stop_resume", "schedule", "job_file_sha256"):
        del doc[key]
    first = (
        "job_id",
        "wire_diameter",
        "flyer_radius",
        "turns_per_layer",
        "layers",
        "poles",
        "fork_steps_per_rev",
        "feed_step",
        "pole_steps_per_rev",
    )
    doc["job"] = {k: v for k, v in doc["job"].items() if k in first}
    return json.dumps(doc, separators=(",", ":"))


@pytest.mark.parametrize("text", [RECORDED, _oldest(RECORDED)], ids=["recorded", "oldest"])
def test_descriptions_recorded_before_still_parse(text: str) -> None:
    plan: JobPlan = parse_job_description(text)
    assert [(s.kind, s.pole, s.layer, s.turns, s.first_turn) for s in plan.segments] == [
        (SegmentKind.LAYER, 0, 0, 2, 0),
        (SegmentKind.LAYER, 0, 1, 2, 2),
        (SegmentKind.INDEX, 1, -1, 0, 0),
        (SegmentKind.LAYER, 1, 0, 2, 0),
        (SegmentKind.LAYER, 1, 1, 2, 2),
    ]
    assert [s.major for s in plan.segments] == [0, 0, 2, 0, 0]  # the feed leads these layers
    assert not any(s.stops_inside for s in plan.segments)
    assert plan.total_steps == 2004


def test_todays_description_is_the_recorded_one() -> None:
    """The wire format is unchanged: the job of the recorded description is
    described today in the same text."""
    job = parse_job_description(RECORDED).job
    assert describe_job(job) == RECORDED


def test_where_a_run_rests_counts_the_turns_of_layers_of_unequal_turns() -> None:
    from winder.contract.run import where_text

    job = orthocyclic_auto()
    plan = parse_job_description(describe_job(job))
    assert [s.turns for s in plan.segments] == [4, 3, 4]
    assert [where_text(plan, i, 0) for i in range(3)] == [
        "coil 1 turn 0.00",
        "coil 1 turn 4.00",
        "coil 1 turn 7.00",
    ]
