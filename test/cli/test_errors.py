"""One error family (issue 42, item 4): every error winder means a person to
read is a :class:`winder.errors.WinderError`, named by what the user must do;
the ``winder`` command takes only the input kinds for the user's mistake
(exit 2), and anything else for what it is, a bug: one line, the traceback in
a file, exit 70. A bare ``raise ValueError`` left in the library is an
internal check, each one listed here with its reason.
"""

from __future__ import annotations

import ast
import os
import re
from pathlib import Path

import pytest
from support.paths import ROOT

import winder.cli.commands as cli
from winder import errors
from winder.cli.common import UserError
from winder.cli.crash import crash_dir
from winder.cli.exits import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_INTERNAL, EXIT_OUTPUT, EXIT_TABLE
from winder.contract.files import OutputError
from winder.contract.jobfile import JobFileError
from winder.contract.params import OPERATION_SPECS
from winder.contract.run import EventError
from winder.motion.job import JobError
from winder.motion.timeline import OVERRIDE_RANGE, Command, CommandError, Timeline, parse_schedule
from winder.record.raw import BagError
from winder.spec import SpecError

SRC = ROOT / "src" / "winder"

# -- the family -----------------------------------------------------------------------------------


def test_the_family_and_its_kinds() -> None:
    kinds = (
        errors.BadInputError,
        errors.BadBagError,
        errors.RefusedError,
        errors.UnavailableError,
        errors.OutputError,
    )
    for kind in kinds:
        assert issubclass(kind, errors.WinderError)
    # the input kinds stay ValueErrors: a node rejects a bad value by catching ValueError and runs on
    assert issubclass(errors.BadInputError, ValueError)
    assert issubclass(errors.BadBagError, errors.BadInputError)
    for other in (errors.RefusedError, errors.UnavailableError, errors.OutputError):
        assert not issubclass(other, ValueError), other
    # the module's own names are the family, nothing else
    assert set(errors.__all__) == {k.__name__ for k in (*kinds, errors.WinderError)}


@pytest.mark.parametrize(
    ("cls", "kind"),
    [
        (SpecError, errors.BadInputError),
        (JobError, errors.BadInputError),
        (JobFileError, errors.BadInputError),
        (CommandError, errors.BadInputError),
        (EventError, errors.BadInputError),
        (UserError, errors.BadInputError),
        (BagError, errors.BadBagError),
        (OutputError, errors.OutputError),
    ],
)
def test_the_old_names_are_members(cls: type[Exception], kind: type[Exception]) -> None:
    """Each ad-hoc class of before keeps its name and is now a kind of the family."""
    assert issubclass(cls, kind) and issubclass(cls, errors.WinderError)


def test_the_ros_errors_are_members() -> None:
    """winder.ros.ctl's, player's and container's (imported here only if rclpy is)."""
    pytest.importorskip("rclpy")
    from winder.ros import container, ctl, player

    assert issubclass(ctl.UnansweredError, errors.UnavailableError)
    assert issubclass(ctl.NoSuchNodeError, errors.UnavailableError)
    assert ctl.RefusedError is errors.RefusedError
    assert issubclass(player.CellLiveError, errors.BadInputError)
    assert issubclass(container.LoadError, errors.BadInputError)


# -- one range, one place -----------------------------------------------------------------------


def test_the_override_range_is_written_from_its_constant() -> None:
    low, high = OVERRIDE_RANGE
    spec = OPERATION_SPECS["feed_override"]
    assert (spec.low, spec.high) == (low, high)
    words = f"[{low:g}, {high:g}]"
    with pytest.raises(SpecError, match=re.escape(f"override factor 3 is not in {words}")):
        parse_schedule("override@1=3")
    with pytest.raises(SpecError, match=re.escape(words)):
        spec.parse("3")
    with pytest.raises(CommandError, match=re.escape(f"feed_override=3 is invalid: must be in {words}")):
        Timeline.__new__(Timeline)._override(Command(0, "override", 3.0))  # refused before anything is read


def message_texts(path: Path) -> list[str]:
    """The string literals of a module's code (f-strings' literal parts too), docstrings aside."""
    tree = ast.parse(path.read_text(), str(path))
    docs = {
        id(node.body[0].value)
        for node in ast.walk(tree)
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
        and node.body
        and isinstance(node.body[0], ast.Expr)
        and isinstance(node.body[0].value, ast.Constant)
    }
    return [
        node.value
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs
    ]


def test_no_message_retypes_the_override_range() -> None:
    """Its numbers are written in one place, the constant; every message is made from it."""
    low, high = OVERRIDE_RANGE
    typed = f"{low:g}, {high:g}"
    found = sorted(
        str(p.relative_to(ROOT)) for p in SRC.rglob("*.py") if any(typed in t for t in message_texts(p))
    )
    assert found == [], f"the feed override range typed out in {found}: write it from OVERRIDE_RANGE"


# -- the command line: bad input, and a bug -----------------------------------------------------


def _main(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    code = cli.main(argv)
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return code, lines[0]


@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (["run", "--check", "--v-max", "-1"], ["v_max=-1.0 is invalid", "must be in (0, 1e+07] steps/s"]),
        (["check", "--turns-per-layer", "0"], ["turns_per_layer=0 is invalid", "[1, "]),
        (["run", "--check", "--feed-override", "3"], ["feed_override=3.0 is invalid", "[0.05, 2]"]),
        (["run", "--check", "--schedule", "override@1=9"], ["override factor 9 is not in [0.05, 2]"]),
        (["run", "--check", "--namespace", "/1x"], ["namespace='/1x' is invalid"]),
        (["analyze", "/nonexistent/bag"], ["/nonexistent/bag"]),
    ],
)
def test_bad_input_is_one_line_and_exit_2(
    argv: list[str], needles: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    code, line = _main(argv, capsys)
    assert code == EXIT_BAD_INPUT, line
    assert line.startswith(f"winder {argv[0]}: error: "), line
    for needle in needles:
        assert needle in line, line


def test_a_bad_job_file_is_one_line_and_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    job = tmp_path / "job.yaml"
    job.write_text("interp_node:\n  ros__parameters:\n    layers: -3\n")
    code, line = _main(["check", str(job)], capsys)
    assert code == EXIT_BAD_INPUT and "layers" in line and "-3" in line and str(job) in line, line


@pytest.fixture
def state_home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    home = tmp_path / "state"
    monkeypatch.setenv("XDG_STATE_HOME", str(home))
    return home


def _crash_in(monkeypatch: pytest.MonkeyPatch, exc: BaseException) -> None:
    """``winder check`` made to raise ``exc`` from inside the command."""

    def broken(_args: object) -> int:
        def deep() -> None:
            raise exc

        deep()
        return 0

    monkeypatch.setattr(cli, "cmd_check", broken)


@pytest.mark.parametrize(
    "exc",
    [
        ValueError("an internal check failed"),
        KeyError("segment"),
        ZeroDivisionError("float division by zero"),
    ],
    ids=["ValueError", "KeyError", "ZeroDivisionError"],
)
def test_an_internal_error_is_one_line_exit_70_and_a_traceback_file(
    exc: Exception, state_home: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    _crash_in(monkeypatch, exc)
    code, line = _main(["check", "--layers", "2"], capsys)
    assert code == EXIT_INTERNAL == 70 and EXIT_INTERNAL in EXIT_TABLE
    name = type(exc).__name__
    m = re.fullmatch(rf"winder check: internal error: {name}: (.+) \(a bug; the traceback is in (.+)\)", line)
    assert m, line
    assert str(exc) in m.group(1) or repr(exc.args[0]) in m.group(1), line
    path = Path(m.group(2))
    assert path.parent == crash_dir() == state_home / "winder" / "crash"
    text = path.read_text()
    assert "Traceback (most recent call last)" in text and "in deep" in text and f"{name}:" in text
    assert "winder check --layers 2" in text  # the command line that hit it


def test_an_internal_error_whose_traceback_cannot_be_saved_is_still_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    blocked = tmp_path / "file"
    blocked.write_text("")
    monkeypatch.setenv("XDG_STATE_HOME", str(blocked))  # a file: no directory under it
    monkeypatch.setattr("tempfile.gettempdir", lambda: str(blocked))
    _crash_in(monkeypatch, RuntimeError("boom"))
    code, line = _main(["check"], capsys)
    assert code == EXIT_INTERNAL, line
    assert line.startswith("winder check: internal error: RuntimeError: boom (a bug; its traceback could not")


@pytest.mark.parametrize(
    ("exc", "want"),
    [
        (errors.BadInputError("x=1 is invalid: must be 2"), EXIT_BAD_INPUT),
        (errors.BadBagError("b: not a winder bag"), EXIT_BAD_INPUT),
        (FileNotFoundError(2, "No such file or directory", "/x/job.yaml"), EXIT_BAD_INPUT),
        (errors.OutputError("out: cannot be written: No space left on device"), EXIT_OUTPUT),
        (errors.RefusedError("job not started: busy"), EXIT_FAILED),
        (errors.UnavailableError("no reply from /interp_node within 5 s"), EXIT_FAILED),
    ],
)
def test_each_kind_has_its_exit_status(
    exc: Exception,
    want: int,
    state_home: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    _crash_in(monkeypatch, exc)
    code, line = _main(["check"], capsys)
    assert code == want and line.startswith("winder check: error: ") and "internal" not in line, line
    assert not state_home.exists()  # no traceback saved for the user's errors


def test_the_installed_command_says_one_line_for_a_bug(tmp_path: Path) -> None:
    """As a user sees it: the console script, a bug made by a sitecustomize
    that breaks ``winder check`` (no traceback on the terminal)."""
    from support.cli import run_cli

    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(
        "import winder.cli.commands as c\n"
        "def broken(args):\n    raise ValueError('bug in check')\n"
        "c.cmd_check = broken\n"
    )
    env = {**os.environ, "PYTHONPATH": str(hook), "XDG_STATE_HOME": str(tmp_path / "state")}
    r = run_cli("check", env=env)
    assert r.returncode == EXIT_INTERNAL, r.stderr
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    path = Path(r.stderr.strip().rsplit("the traceback is in ", 1)[1].rstrip(")"))
    assert path.is_relative_to(tmp_path / "state") and "ValueError: bug in check" in path.read_text()


# -- no new bare ValueError for the user ---------------------------------------------------------

#: Every ``raise ValueError`` left in src/winder, by file and function: an
#: internal check (a caller's programming error: arrays the code made, calls out
#: of order, values only the code passes), never the user's input. A user-facing
#: refusal raises a kind of winder.errors (BadInputError, BadBagError, ...)
#: instead; a new bare one fails this test until it is converted or listed here
#: with its reason.
INTERNAL_VALUE_ERRORS: dict[str, tuple[int, str]] = {
    "analysis/figures/analysis.py::envelope_indices": (3, "plot arrays and columns the figure code makes"),
    "axis/_checks.py::_vector": (5, "the simulator's time/angle arrays: shape, order, finiteness"),
    "record/capability.py::mean_sd": (1, "no values: the caller counts its values first (the 30-part rule)"),
    "record/parts.py::_known": (1, "columns the code names (the CLI's choices), never the user's text"),
    "axis/_checks.py::_angles": (2, "step angle arrays the caller builds"),
    "axis/_steps.py::_check_chunk": (3, "a streaming tracker fed out of order"),
    "axis/nonlinear.py::NonlinearTracker.advance": (2, "a streaming tracker fed before its start"),
    "contract/cdr.py::JointStateEncoder.encode": (1, "array shapes the bridge builds"),
    "contract/cdr.py::trajectory_payload": (1, "array shapes the bridge builds"),
    "contract/cdr.py::MultiArrayCodec.__init__": (1, "a dtype the code chooses"),
    "contract/cdr.py::MultiArrayCodec.encode": (1, "row arrays the profile node builds"),
    "contract/files.py::atomic_file": (1, "a file mode the code passes"),
    "contract/topics.py::status_values": (2, "a state and role from the code's own tables"),
    "motion/interp.py::min_deviation": (1, "a row window the caller computes"),
    "motion/interp.py::interpolate": (1, "vectors from the job's segments"),
    "motion/interp.py::path_mismatch": (3, "vectors, rows and windows the checker computes"),
    "motion/interp.py::interpolate_pieces": (1, "a row window the caller computes"),
    "motion/interp.py::pieces_mismatch": (2, "rows and windows the checker computes"),
    "motion/interp.py::line_distance": (1, "point arrays the analysis builds"),
    "motion/interp.py::deviation_stats": (1, "path arrays the analysis builds"),
    "motion/job.py::Segment.turn_end": (2, "a turn the code asks of a segment (stop_points checks stops)"),
    "motion/ramps/base.py::Profile.sample": (1, "sample times the code makes"),
    "motion/ramps/base.py::Profile.times_at": (1, "positions the code makes"),
    "motion/ramps/jog.py::JogRamp.plan": (1, "an API misuse: a jog is planned by jog()"),
    "motion/ramps/jog.py::Jog.times_at": (1, "positions the code makes"),
    "motion/shaped.py::ShapedProfile.__init__": (3, "impulses from winder.shaping's closed forms"),
    "motion/shaped.py::ShapedProfile.sample": (1, "sample times the code makes"),
    "motion/shaped.py::ShapedProfile.times_at": (1, "positions the code makes"),
    "record/reader.py::StepArray.__init__": (1, "a chunk size the code passes"),
}


def bare_value_errors(root: Path = SRC) -> dict[str, int]:
    """``file::function`` -> how many ``raise ValueError`` it holds, over src/winder."""
    found: dict[str, int] = {}

    def walk(node: ast.AST, where: str, stack: list[str]) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                walk(child, where, [*stack, child.name])
                continue
            if isinstance(child, ast.Raise) and child.exc is not None:
                exc = child.exc.func if isinstance(child.exc, ast.Call) else child.exc
                if isinstance(exc, ast.Name) and exc.id == "ValueError":
                    key = f"{where}::{'.'.join(stack) or '<module>'}"
                    found[key] = found.get(key, 0) + 1
            walk(child, where, stack)

    for path in sorted(root.rglob("*.py")):
        walk(ast.parse(path.read_text(), str(path)), str(path.relative_to(root)), [])
    return found


def test_the_scan_finds_a_bare_value_error(tmp_path: Path) -> None:
    """The oracle of the next test: it sees a raise in a method, and counts them."""
    pkg = tmp_path / "winder"
    pkg.mkdir()
    (pkg / "m.py").write_text(
        "class A:\n    def f(self, x):\n        if x:\n            raise ValueError(f'x={x}')\n"
        "        raise ValueError\n"
    )
    assert bare_value_errors(pkg) == {"m.py::A.f": 2}


def test_every_bare_value_error_left_is_an_internal_check() -> None:
    found = bare_value_errors()
    new = {k: n for k, n in found.items() if n > INTERNAL_VALUE_ERRORS.get(k, (0, ""))[0]}
    assert not new, (
        f"raise ValueError in {new}: a refusal of the user's input raises a kind of winder.errors "
        "(BadInputError, BadBagError, ...); an internal check is listed in INTERNAL_VALUE_ERRORS "
        "with its reason"
    )
    gone = {k for k, (n, _) in INTERNAL_VALUE_ERRORS.items() if found.get(k, 0) < n}
    assert not gone, f"INTERNAL_VALUE_ERRORS lists more than is left in {sorted(gone)}: update it"
