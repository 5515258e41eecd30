"""winder.ros.driver.DriverNode with a backend that fails: an exception in a
driver's method (a SystemExit or a KeyboardInterrupt too), a return value
that is not what the method promises (a read() of None or of text), a
begin() that does not return within begin_timeout, is a bug of the driver,
not of the cell. The run closes incomplete, named (``driver error:
backend.write() raised ...``, once, with its traceback in the driver's log;
a drive's fault text in one line), ``winder run`` exits 1 "failed", and the
node stays up and takes the next run to done."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from conftest import BIN, Procs
from support.paths import TEST

pytestmark = pytest.mark.ros

SMALL = ["--job-id", "faulty", "--turns-per-layer", "2", "--layers", "1", "--poles", "1"]


def bags(tmp_path: Path) -> list[str]:
    """The driver's bags in the test's own directory (not the repository's bags/)."""
    return ["--ros-args", "-p", f"bag_dir:={tmp_path / 'bags'}"]


#: what goes wrong (faulty_drive.py --fail) -> what the run's report says
FAILURES = {
    "write": "driver error: backend.write() raised RuntimeError: the drive's buffer index ran past its end",
    "begin": "driver error: backend.begin() raised OSError: /dev/ttyDRIVE: no such device",
    "json": "driver error: backend.begin() returned a configuration JSON cannot hold",
    "nan": "driver error: backend.read() returned array([nan, nan, nan]): want 3 finite step positions",
    "none": "driver error: backend.read() returned None: want 3 finite step positions",
    "text": "driver error: backend.read() returned ['0', '0', '0']: want 3 finite step positions",
    "exit": "driver error: backend.write() raised SystemExit: 3",
    "interrupt": "driver error: backend.write() raised KeyboardInterrupt",
    "hang": "driver error: backend.begin() did not return within 1 s (begin_timeout)",
    "lines": "fork drive: following error; the run stops",
    "stuck": "axes not in position 1.05 s after the last step: fork",
}
#: the failures that are something raised: a traceback in the driver's log, once
RAISED = ("write", "begin", "exit", "interrupt")
#: the driver's settings for a failure (begin_timeout below faulty_drive.HANG_S)
SETTINGS = {"hang": ["-p", "begin_timeout:=1.0"]}


@pytest.mark.parametrize("fail", list(FAILURES))
def test_a_driver_that_fails_closes_its_run_and_takes_the_next(
    procs: Procs, tmp_path: Path, fail: str
) -> None:
    drive = procs.launch(
        [
            sys.executable,
            str(TEST / "consumers" / "faulty_drive.py"),
            "--fail",
            fail,
            "--fail-run",
            "1",
            *bags(tmp_path),
            *SETTINGS.get(fail, []),
        ],
        "faulty_drive",
    )
    run = [str(BIN / "winder"), "run", "--external", "sim", *SMALL, "--timeout", "120"]
    run += ["--start-timeout", "60"]
    options = {"env": procs.env, "capture_output": True, "text": True, "timeout": 180}
    first = subprocess.run(run, stdin=subprocess.DEVNULL, **options)  # type: ignore[call-overload]
    said = first.stdout + first.stderr
    assert first.returncode == 1, said
    assert FAILURES[fail] in said, said
    assert "Traceback" not in said, said
    assert drive.poll() is None, procs.log(drive)
    log = procs.log(drive)
    errors = [line for line in log.splitlines() if line.startswith("[ERROR]")]
    assert len(errors) == 1 and FAILURES[fail] in errors[0], log  # said once
    if fail in RAISED:  # an exception: its traceback in the driver's log, once
        assert log.count("Traceback") == 1 and 'faulty_drive.py", line' in log, log
    if fail == "lines":  # a fault text of many lines: its first, nowhere the others
        assert "3000 counts" not in said and "3000 counts" not in log, said + log
    second = subprocess.run(run, stdin=subprocess.DEVNULL, **options)  # type: ignore[call-overload]
    assert second.returncode == 0, second.stdout + second.stderr
    assert "  state              done" in second.stdout, second.stdout
    if fail == "hang":  # no run was taken until the late begin() returned, and end() was called then
        assert "backend.begin() returned, late: backend.end() called" in procs.log(drive)


def test_winder_run_ends_when_its_external_consumer_dies_mid_run(procs: Procs, tmp_path: Path) -> None:
    """SIGKILL the external driver mid-run: ``winder run --external sim``
    says the consumer left the graph and ends non-zero, once the graph no
    longer shows it (its lease), instead of waiting out its --timeout."""
    import signal

    from support import wait

    drive = procs.launch(
        [sys.executable, str(TEST / "consumers" / "faulty_drive.py"), *bags(tmp_path)], "faulty_drive"
    )
    long_job = ["--job-id", "killed", "--turns-per-layer", "40", "--layers", "1", "--poles", "1"]
    long_job += ["--timeout", "600", "--start-timeout", "60"]
    run = subprocess.Popen(
        [str(BIN / "winder"), "run", "--external", "sim", *long_job],
        env=procs.env,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        wait.log_has(lambda: procs.log(drive), "run killed_", 60, "the driver's run")
        drive.send_signal(signal.SIGKILL)
        out, _ = run.communicate(timeout=120)  # the lease (about 10 s) and CONSUMER_GONE_S, not 600 s
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
    assert run.returncode not in (0, None), out
    assert "the step consumer left the graph mid-run" in out, out
    assert "Traceback" not in out, out


def test_winder_run_names_why_its_external_consumer_is_blocked(procs: Procs, tmp_path: Path) -> None:
    """A driver started with a value it refuses holds the default and takes no
    job: it says so, and ``winder run`` names its reason when the start gives
    up (it said only "consumer blocked")."""
    drive = procs.launch(
        [sys.executable, "-m", "winder.ros.mock_backend", *bags(tmp_path), "-p", "settle_time:=-1.0"], "mock"
    )
    run = [str(BIN / "winder"), "run", "--external", "sim", *SMALL, "--start-timeout", "8"]
    options = {"env": procs.env, "capture_output": True, "text": True, "timeout": 120}
    r = subprocess.run(run, stdin=subprocess.DEVNULL, **options)  # type: ignore[call-overload]
    assert r.returncode != 0, r.stdout + r.stderr
    assert "settings rejected at start: settle_time" in r.stderr, r.stdout + r.stderr
    assert "the node holds the default 0.05 and takes no job until a valid value is set" in procs.log(drive)
