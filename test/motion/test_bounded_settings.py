"""Job and run settings bounded before any work is sized from them (issue 53, item 9).

* a job's steps are counted from its turns and bounded before it is laid out:
  ``turns_per_layer=100000 x layers=1000 x poles=360`` (3.7*10^13 steps) kept
  ``winder interp`` walking for days, though no cell could run it within a
  week (:data:`MAX_JOB_STEPS`: the highest step rate for the longest a job may
  last);
* a layer's share of ``v_max`` (``first_layer_speed``, ``layer_speed``) scales
  its ramp's limits up to its cube: a share of 1e-300 made an acceleration of
  0.0 that the planner refused with a ValueError (an internal error, exit 70);
  shares are held to [:data:`MIN_LAYER_SHARE`, 1], and a limit that a layer's
  speed or pace takes out of the floats is refused in the planner's words;
* a list setting with an empty item (``coil_overrides ';;;'``, ``'1:'``,
  ``schedule ',,,'``) said nothing and was taken as saying less.

The "before" is shown, not timed: the laying out is replaced by a function
that fails, and the refusal must come first.
"""

from __future__ import annotations

import pytest

from winder.contract.params import PROFILE_SPECS, check_interp
from winder.errors import BadInputError
from winder.motion.job import (
    FIELD_SPECS,
    MAX_JOB_SECONDS,
    MAX_JOB_STEPS,
    MAX_STEP_RATE,
    MIN_LAYER_SHARE,
    Job,
    JobError,
)
from winder.motion.timeline import check_schedule
from winder.motion.timing import plan_job_timing, plan_segment
from winder.spec import SpecError

RAMP = {name: spec.default for name, spec in PROFILE_SPECS.items()}


@pytest.fixture
def no_moves(monkeypatch: pytest.MonkeyPatch) -> None:
    """Laying a job out in moves fails the test: its size is counted from its turns."""

    def forbidden(*_args: object, **_kwargs: object) -> None:
        raise AssertionError("the job was laid out in moves before it was bounded")

    monkeypatch.setattr(Job, "_lay_out", forbidden)


# -- a job's steps ---------------------------------------------------------------------------------


def test_the_bound_is_the_highest_step_rate_for_the_longest_a_job_may_last() -> None:
    assert MAX_JOB_STEPS == 7 * 24 * 3600 * 10**7
    assert MAX_JOB_SECONDS * MAX_STEP_RATE == MAX_JOB_STEPS
    assert PROFILE_SPECS["v_max"].high == MAX_STEP_RATE  # the profile node's v_max at most


def test_a_job_of_more_steps_than_any_cell_runs_in_a_week_is_refused_before_it_is_laid_out(
    no_moves: None,
) -> None:
    """The job of issue 53: 100000 turns of 1024 fork steps, 1000 layers, 360
    coils, 3.7*10^13 steps; 360 000 straight moves, within their own bound."""
    with pytest.raises(JobError) as err:
        Job(turns_per_layer=100_000, layers=1000, poles=360)
    text = str(err.value)
    assert "\n" not in text
    steps = 100_000 * 1024 * 1000 * 360 + round(359 * 1024 / 360)  # the layers and the pole indexes
    size = "turns_per_layer=100000 x layers=1000 x poles=360 with fork_steps_per_rev=1024"
    assert text.startswith(f"{size} is invalid: {steps} steps"), text
    assert f"at most {MAX_JOB_STEPS}" in text


def test_the_interp_node_check_refuses_it_the_same_way(no_moves: None) -> None:
    values = {name: spec.default for name, spec in FIELD_SPECS.items()}
    values.update({"turns_per_layer": 100_000, "layers": 1000, "poles": 360})
    with pytest.raises(JobError, match=f"at most {MAX_JOB_STEPS}"):
        check_interp(values)


def test_a_job_just_within_the_bound_is_taken_and_one_layer_a_coil_more_is_not(no_moves: None) -> None:
    """2^21 fork steps a turn, 1000 turns a layer (2.1*10^9 steps, within a
    layer's 2^31 - 1), 360 coils: 8 layers each are 6.04*10^12 steps, 9 are
    6.8*10^12."""
    big = {"fork_steps_per_rev": 2**21, "turns_per_layer": 1000, "poles": 360, "feed_step": 1e-3}
    steps = 2**21 * 1000 * 8 * 360 + round(359 * 1024 / 360)
    assert steps <= MAX_JOB_STEPS < steps + 2**21 * 1000 * 360
    Job.from_dict({**big, "layers": 8})
    with pytest.raises(JobError, match=f"is invalid: {steps + 2**21 * 1000 * 360} steps"):
        Job.from_dict({**big, "layers": 9})


@pytest.mark.parametrize(
    "fields",
    [
        {},
        {"reversal_dwell": 1.5},
        {"fork_steps_per_rev": 4},  # the feed the major axis of a helical layer: 250 feed steps a turn
        {"lay": "orthocyclic", "lay.crossover": 180.0},
        {
            "lay": "orthocyclic",
            "lay.crossover": 180.0,
            "layers": 5,
            "turns_per_layer": 7,
            "reversal_dwell": 2.0,
        },
        {"lay": "orthocyclic", "lay.crossover": 180.0, "coil_overrides": "2:layers=1;3:turns_per_layer=3"},
        {
            "lay": "orthocyclic",
            "lay.crossover": 180.0,
            "turns_per_layer": "auto",
            "bobbin.window_width": 0.05,
        },
        {"poles": 7, "pole_steps_per_rev": 1000, "coil_overrides": "4:turns_per_layer=9,direction=ccw"},
    ],
)
def test_the_steps_counted_before_are_the_steps_laid_out(fields: dict[str, object]) -> None:
    job = Job.from_dict(fields)
    counted = job._count_steps(job.winding)
    assert counted == sum(max(abs(d) for d in s.delta) for s in job.segments()) == job.total_steps


# -- a layer's share of v_max ----------------------------------------------------------------------


@pytest.mark.parametrize("share", ["1e-300", "5e-324", "0.0009", "0", "1.5"])
def test_a_layer_speed_share_out_of_its_range_is_refused_naming_it(share: str) -> None:
    with pytest.raises(JobError) as err:
        Job.from_dict({"layer_speed": f"1:1={share}"})
    text = str(err.value)
    assert text == f"layer_speed: '1:1={share}': share {float(share):g} is invalid: must be in [0.001, 1]"


@pytest.mark.parametrize("share", [1e-300, 5e-324, 0.0009, 0.0])
def test_a_first_layer_speed_out_of_its_range_is_refused_naming_it(share: float) -> None:
    with pytest.raises(JobError, match=r"^first_layer_speed=.* is invalid: must be in \[0\.001, 1\]$"):
        Job.from_dict({"first_layer_speed": share})


def test_the_slowest_layer_is_planned_or_refused_in_one_line() -> None:
    """At the least shares a layer's limits are still numbers the planner
    takes: a layer at 0.001 x v_max plans; at 0.001 x 0.001 (both shares) it
    would last longer than a job may, said so in one line (was a ValueError
    from the planner, an internal error)."""
    job = Job.from_dict({"layer_speed": f"*:2={MIN_LAYER_SHARE}", "turns_per_layer": 2, "poles": 1})
    plan_job_timing(RAMP, job)
    slowest = Job.from_dict(
        {**job.to_dict(), "first_layer_speed": MIN_LAYER_SHARE, "layer_speed": "*:1=0.001"}
    )
    with pytest.raises(BadInputError) as err:
        plan_job_timing(RAMP, slowest)
    assert "\n" not in str(err.value) and "more than a job may last" in str(err.value)


@pytest.mark.parametrize(
    ("ramp", "speed", "pace"),
    [
        ({"v_max": 5e-324}, 0.5, 1.0),  # v_max x speed: 0.0
        ({"a_max": 1e-320}, 1.0, 0.001),  # a_max x pace^2: 0.0
        ({"j_max": 1e-310}, 1.0, 0.001),  # j_max x pace^3: 0.0
        ({"profile": "trapezoid", "a_max": 5e-324}, 1.0, 0.5),
    ],
)
def test_a_limit_a_layer_takes_out_of_the_floats_is_refused_in_the_planner_s_words(
    ramp: dict[str, object], speed: float, pace: float
) -> None:
    with pytest.raises(BadInputError) as err:
        plan_segment({**RAMP, **ramp}, 1000, speed, pace)
    text = str(err.value)
    assert type(err.value) is BadInputError  # not the planner's ValueError: a bug's exit 70
    assert (
        "\n" not in text and "the limits are too far apart to plan a 1000-step move in floating point" in text
    )


# -- list settings with an empty item --------------------------------------------------------------


@pytest.mark.parametrize("text", [";;;", ";", "2:layers=1;", ";2:layers=1", "2:layers=1;;3:layers=1", " ; "])
def test_coil_overrides_with_an_empty_item_are_refused(text: str) -> None:
    with pytest.raises(JobError) as err:
        Job.from_dict({"coil_overrides": text})
    assert str(err.value).startswith(f"coil_overrides={text!r} is invalid: it has an empty item")


@pytest.mark.parametrize(
    ("text", "why"), [("1:", "no KEY=VALUE"), ("1: ", "no KEY=VALUE"), ("1:layers=1,,", "an empty KEY=VALUE")]
)
def test_a_coil_override_that_changes_nothing_is_refused(text: str, why: str) -> None:
    with pytest.raises(JobError) as err:
        Job.from_dict({"coil_overrides": text})
    assert str(err.value) == f"coil_overrides: {text.strip()!r} must be COIL:KEY=VALUE[,KEY=VALUE]: {why}"


def test_the_interp_node_check_refuses_the_parameter_alike() -> None:
    values = {name: spec.default for name, spec in FIELD_SPECS.items()}
    with pytest.raises(SpecError, match="no KEY=VALUE"):
        check_interp({**values, "coil_overrides": "1:"})


@pytest.mark.parametrize("text", [";", "*:1=0.5;", "*:1=0.5;;1:2=0.5"])
def test_a_layer_speed_with_an_empty_item_is_refused(text: str) -> None:
    with pytest.raises(JobError, match=r"^layer_speed=.* is invalid: it has an empty item"):
        Job.from_dict({"layer_speed": text})


@pytest.mark.parametrize(
    "text", [",,,", ",", "pause@1,", ",pause@1", "pause@1,,resume@2", "pause@1, ,resume@2"]
)
def test_a_schedule_with_an_empty_item_is_refused(text: str) -> None:
    with pytest.raises(SpecError) as err:
        check_schedule(text)
    assert str(err.value).startswith(f"schedule={text!r} is invalid: it has an empty item")


def test_empty_lists_are_still_no_items() -> None:
    """An empty (or blank) setting is the list of none: the default."""
    assert check_schedule("") == [] and check_schedule("  ") == []
    job = Job.from_dict({"coil_overrides": " ", "layer_speed": " "})
    assert job.segments() == Job().segments() and job.layer_speeds == {}
    assert [c.kind for c in check_schedule(" pause@1 , resume@2 ")] == ["pause", "resume"]
