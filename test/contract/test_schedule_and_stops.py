"""A schedule and programmed stops are checked as a setting as the run
would take them (issue 41): ``winder run --check`` passed ``jump@1``,
``pause@nan``, ``override@1=3``, ``pause@2,pause@1`` and a stop given twice,
and the run was refused a minute later. One check
(:func:`winder.motion.timeline.check_schedule`, :func:`winder.contract.params.stop_points`)
serves the interp node, its job files and ``winder run --check``.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from winder.cli import commands as cli
from winder.contract.params import INTERP_SPECS, check_interp, stop_points
from winder.motion.job import Job
from winder.motion.timeline import MAX_SCHEDULE, check_schedule, parse_schedule
from winder.spec import SpecError

BAD_SCHEDULES = [
    ("jump@1", "'jump@1' must be KIND@SECONDS"),
    ("pause@nan", "'pause@nan' must be KIND@SECONDS"),
    ("pause@inf", "SECONDS in [0, 1e+06]"),
    ("pause@1e308", "SECONDS in [0, 1e+06]"),
    ("pause@-1", "SECONDS in [0, 1e+06]"),
    ("override@1=3", "override factor 3 is not in [0.05, 2]"),
    ("override@1=nan", "override factor nan is not in [0.05, 2]"),
    ("override@1", "KIND@SECONDS"),
    ("pause@1=2", "KIND@SECONDS"),
    ("pause@2,resume@1", "'resume@1' is not later than 'pause@2', the command before it"),
    ("pause@1,pause@1", "'pause@1' is not later than 'pause@1'"),
    ("pause@1,pause@2", "'pause@2' pauses a paused job: resume first"),
    ("resume@1", "'resume@1' resumes a job that is not paused"),
    ("abort@1,resume@2", "'resume@2' comes after 'abort@1': an aborted job takes no more commands"),
    (",".join(f"override@{i}=1" for i in range(1, MAX_SCHEDULE + 2)), f"at most {MAX_SCHEDULE}"),
]


@pytest.mark.parametrize(("text", "words"), BAD_SCHEDULES, ids=[t[:30] for t, _ in BAD_SCHEDULES])
def test_a_schedule_the_run_cannot_take_is_refused_in_one_line(text: str, words: str) -> None:
    with pytest.raises(SpecError) as err:
        check_schedule(text)
    message = str(err.value)
    assert "\n" not in message and len(message) < 400
    assert message.startswith("schedule=") and " is invalid: " in message
    assert words in message, message


@pytest.mark.parametrize(
    "text",
    [
        "",
        "pause@1.5,resume@3,override@4=0.5,abort@9",
        "override@0=2,pause@0.5,override@0.6=0.05,abort@0.7",
        "pause@0.5,resume@0.8,pause@1.2,resume@1.5,abort@2.2",
        " pause@1 , resume@2 ",
    ],
)
def test_a_schedule_the_run_takes_is_taken(text: str) -> None:
    assert check_schedule(text) == parse_schedule(text)


def test_a_recorded_schedule_is_still_read_in_time_order() -> None:
    """What a job description carries is read as before (bags recorded with
    an unordered schedule stay readable); only a setting is held to the order."""
    assert [c.kind for c in parse_schedule("resume@2,pause@1")] == ["pause", "resume"]


def test_a_stop_given_twice_is_refused() -> None:
    job = Job()
    assert stop_points(job, "1:4,2:7") == sorted(stop_points(job, "2:7,1:4"))
    for text in ("1:4,1:4", "1:4, 1:04", "2:40,1:1,2:40"):
        with pytest.raises(SpecError, match=r"^stops=.* is invalid: \d+:\d+ is given twice"):
            stop_points(job, text)


def test_the_interp_node_check_holds_them_too() -> None:
    values = {name: spec.default for name, spec in INTERP_SPECS.items()}
    for name, text in (("schedule", "pause@2,pause@1"), ("stops", "1:4,1:4")):
        with pytest.raises(SpecError, match=f"^{name}="):
            check_interp({**values, name: text})


@pytest.mark.parametrize(
    "args",
    [
        ["--schedule", "jump@1"],
        ["--schedule", "pause@nan"],
        ["--schedule", "override@1=3"],
        ["--schedule", "pause@2,pause@1"],
        ["--stops", "1:4,1:4"],
        ["--stop-at-turn", "99999999999999999999999"],
    ],
)
def test_winder_run_check_refuses_them_at_once(
    args: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = cli.main(["run", "--check", *args, "--bag-dir", str(tmp_path / "b")])
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and not out, (code, out, err)
    assert lines[0].startswith(("winder run: error: schedule=", "winder run: error: stops=")), lines[0]
    assert not (tmp_path / "b").exists()


def test_winder_run_check_passes_a_good_schedule(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["--schedule", "pause@1,resume@2,override@3=0.5,abort@4", "--stops", "1:4,2:7"]
    assert cli.main(["run", "--check", *args, "--bag-dir", str(tmp_path / "b")]) == 0
    assert "every setting is valid" in capsys.readouterr().out
