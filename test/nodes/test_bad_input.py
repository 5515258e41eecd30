"""The bad-input matrix: every job, profile and motor parameter with
non-finite, negative, zero, absurdly large and wrongly typed values, through
the command line, through ``--ros-args -p`` at start, and through a parameter
set at run time. Which values are bad is worked out here from the documented
ranges (docs/OPERATING.md), not asked of the code under test."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import pytest
from conftest import Procs
from support import wait
from support.ros_probe import set_params

from winder.cli import commands as cli_main
from winder.contract.params import INTERP_SPECS, PROFILE_SPECS, SIM_SPECS
from winder.spec import Spec

NODE_SPECS = {"interp_node": INTERP_SPECS, "profile_node": PROFILE_SPECS, "sim_node": SIM_SPECS}
CANDIDATES: list[Any] = [
    math.nan,
    math.inf,
    -math.inf,
    -1.0,
    0.0,
    1e300,
    -(10**12),
    10**12,
    2.5,
    "text",
    True,
]


def is_bad(spec: Spec, value: Any) -> bool:
    """Outside the documented range or of the wrong type."""
    if spec.kind is bool:
        return not isinstance(value, bool)
    if spec.kind is str:
        if not isinstance(value, str):
            return True
        if spec.choices:
            return value not in spec.choices
        return bool(spec.pattern) and re.fullmatch(spec.pattern, value) is None
    if isinstance(value, (bool, str)):
        return True
    if spec.kind is int and not float(value).is_integer():
        return True
    v = float(value)
    if not math.isfinite(v):
        return True
    assert spec.low is not None and spec.high is not None
    return v > spec.high or v < spec.low or (spec.low_open and v == spec.low)


def bad_values(spec: Spec) -> list[Any]:
    if spec.kind is str:
        # a control character: what a run's operator or wire lot refuses (a NUL cuts a ROS string)
        return [v for v in ("", "no such thing!", "ring\x07") if is_bad(spec, v)]
    return [v for v in CANDIDATES if is_bad(spec, v)]


# the interp node's ramp.* settings are the profile node's (same specs), which winder run sets;
# its job_file is winder run's positional JOB_FILE (test_job_files.py), and job_file_sha256
# that file's hash, which winder run sets itself (test_coil.py); tolerances (a JSON map) and
# parts_db (a path, "" or auto) are texts no pattern describes: their checks have cases of
# their own (test/record/test_parts.py, test/cli/test_parts_command.py)
CLI_SPECS = {
    n: s
    for n, s in {**INTERP_SPECS, **PROFILE_SPECS, **SIM_SPECS}.items()
    if not n.startswith("ramp.") and n not in ("job_file", "job_file_sha256", "tolerances", "parts_db")
}
CLI_CASES = [
    (name, v)
    for name, spec in CLI_SPECS.items()
    if spec.kind is not bool and name not in ("autostart", "chunk_steps", "max_in_flight")
    for v in bad_values(spec)
]


def test_matrix_covers_every_parameter_kind() -> None:
    covered = {name for name, _ in CLI_CASES}
    settable = {
        n
        for n, s in CLI_SPECS.items()
        if s.kind is not bool and n not in ("autostart", "chunk_steps", "max_in_flight")
    }
    # strings without a pattern or choices (bag_dir) accept any non-empty text
    assert covered == settable
    assert len(CLI_CASES) > 200


@pytest.mark.parametrize(("name", "value"), CLI_CASES)
def test_cli_rejects_bad_value_in_one_line(name: str, value: Any, capsys: pytest.CaptureFixture[str]) -> None:
    text = value if isinstance(value, str) else ("true" if value is True else repr(value))
    extra = [] if name == "bag_dir" else ["--bag-dir", "/nonexistent/never-created"]
    # --name=value: how a value that starts with '-' (like -inf) is given
    code = cli_main.main(["run", f"--{name.replace('_', '-')}={text}", *extra])
    err = capsys.readouterr().err
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"winder run: error: {name}=")
    assert "is invalid" in lines[0]
    assert not Path("/nonexistent/never-created").exists()


def start_override(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float) and math.isnan(value):
        return ".nan"
    if isinstance(value, float) and math.isinf(value):
        return ".inf" if value > 0 else "-.inf"
    if isinstance(value, str):
        return f"'{value}'" if value else "''"
    return repr(value)


KINDS = ["nan", "negative", "zero", "huge", "text"]


def pick(spec: Spec, kind: str) -> Any | None:
    """The value of a kind for one parameter, if that value is bad for it."""
    value = {"nan": math.nan, "negative": -1.0, "zero": 0.0, "huge": 1e300, "text": "text"}[kind]
    if spec.kind is int and kind in ("negative", "zero", "huge"):
        value = {"negative": -1, "zero": 0, "huge": 10**12}[kind]
    if spec.kind is str:
        return "no such thing!" if kind == "text" and is_bad(spec, "no such thing!") else None
    if spec.kind is bool:
        return "text" if kind == "text" else None
    return value if is_bad(spec, value) else None


@pytest.mark.ros
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("executable", list(NODE_SPECS))
def test_bad_overrides_at_start_are_all_reported(
    tmp_path: Path, procs: Procs, executable: str, kind: str
) -> None:
    specs = NODE_SPECS[executable]
    bad = {n: v for n, s in specs.items() if (v := pick(s, kind)) is not None}
    if not bad:
        pytest.fail(f"no bad {kind} value for {executable}: the matrix is wrong")
    args = []
    for n, v in bad.items():
        args += ["-p", f"{n}:={start_override(v)}"]
    if executable == "sim_node" and "bag_dir" not in bad:
        args += ["-p", f"bag_dir:={tmp_path / 'bags'}"]
    p = procs.start(executable, *args)

    def unreported() -> list[str]:
        log = procs.log(p)
        return [n for n in bad if not (f"{n}=" in log or f"parameter {n}" in log.lower())]

    wait.until(
        lambda: not unreported(),
        30,
        f"{executable}'s report of each bad {kind} value",
        heard=lambda: (f"not reported: {unreported()}", procs.log(p)[-1000:]),
        running=p,
    )
    log = procs.log(p)
    assert p.poll() is None, log
    for n in bad:
        assert f"{n}=" in log or f"parameter {n}" in log.lower(), f"{n} not reported:\n{log}"
    assert procs.stop(p) == 0
    assert "Traceback" not in procs.log(p)
    assert not (tmp_path / "bags").exists()


@pytest.mark.ros
@pytest.mark.parametrize("executable", list(NODE_SPECS))
def test_bad_values_set_at_run_time_are_all_refused(
    tmp_path: Path, procs: Procs, ros: Any, executable: str
) -> None:
    args = ["-p", "autostart:=false"] if executable == "interp_node" else []
    if executable == "sim_node":
        args = ["-p", f"bag_dir:={tmp_path / 'bags'}"]
    p = procs.start(executable, *args)
    specs = NODE_SPECS[executable]
    cases = [
        (n, v) for n, s in specs.items() for v in bad_values(s) if not (isinstance(v, int) and abs(v) > 2**62)
    ]
    assert cases
    for name, value in cases:
        [res] = set_params(ros, executable, {name: value})
        assert not res.successful, f"{name}={value!r} accepted"
        assert name in res.reason, res.reason
    assert p.poll() is None
    assert "Traceback" not in procs.log(p)
