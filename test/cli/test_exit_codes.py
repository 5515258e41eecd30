"""One exit-code table for every ``winder`` command: the table in
docs/RELIABILITY.md is the code's (winder.cli.exits), and each class really ends with its
code, made to happen with the real cell: a bad option, a run aborted by its
schedule, a run whose consumer is killed, Ctrl-C, a refused ``winder ctl``,
an output that cannot be written (an internal error, a bug, is made to happen
in test_errors.py; a run whose axes lose steps, exit 6, in test_lost_steps.py)."""

from __future__ import annotations

import os
import re
import signal
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from conftest import BIN, next_domain, release_domain
from support import wait
from support.bags import mcap_size
from support.paths import ROOT

from winder.cli.exits import (
    EXIT_ABORTED,
    EXIT_BAD_INPUT,
    EXIT_FAILED,
    EXIT_FAULTED,
    EXIT_INTERNAL,
    EXIT_INTERRUPTED,
    EXIT_NODE_DIED,
    EXIT_OK,
    EXIT_OUTPUT,
    EXIT_TABLE,
)
from winder.procs import popen

TINY = ["--turns-per-layer", "4", "--layers", "1", "--poles", "1"]


@pytest.fixture
def env() -> Iterator[dict[str, str]]:
    domain = next_domain()
    yield {**os.environ, "ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    release_domain(domain)


def winder(*args: str, env: dict[str, str] | None = None, cwd: Path | None = None) -> tuple[int, str]:
    r = subprocess.run(
        [str(BIN / "winder"), *args],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
        cwd=cwd,
        stdin=subprocess.DEVNULL,
    )
    assert "Traceback" not in r.stderr, r.stderr
    return r.returncode, r.stderr


def test_the_documented_table_is_the_codes_table() -> None:
    text = (ROOT / "docs" / "RELIABILITY.md").read_text()
    section = text.split("## Exit codes", 1)[1].split("\n#", 1)[0]
    rows = re.findall(r"^\| (\d+) \| ([^|]+) \| (.+) \|$", section, re.MULTILINE)
    table = {int(code): (name.strip(), when.strip()) for code, name, when in rows}
    assert table == EXIT_TABLE
    codes = [EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_ABORTED, EXIT_NODE_DIED, EXIT_OUTPUT, EXIT_FAULTED]
    assert sorted(EXIT_TABLE) == [*codes, EXIT_INTERNAL, EXIT_INTERRUPTED] and len(set(codes)) == len(codes)


def test_bad_input_and_unwritable_output(tmp_path: Path) -> None:
    for args in (["run", "--v-max", "-1", "--check"], ["run", "--no-such-option"], ["analyze"], ["export"]):
        code, err = winder(*args)
        assert code == EXIT_BAD_INPUT and len(err.strip().splitlines()) == 1, (args, err)
    missing = tmp_path / "missing.yaml"
    assert winder("run", str(missing), "--check")[0] == EXIT_BAD_INPUT
    (tmp_path / "plain").write_text("")
    code, err = winder("figures", str(tmp_path / "plain" / "figs"))
    assert code == EXIT_OUTPUT and "plain is a file" in err, err


@pytest.mark.ros
def test_a_run_aborted_by_its_schedule(env: dict[str, str], tmp_path: Path) -> None:
    code, err = winder("run", *TINY, "--schedule", "abort@0.3", "--bag-dir", str(tmp_path), env=env)
    assert code == EXIT_ABORTED, err


@pytest.mark.ros
def test_a_refused_ctl_command_fails(env: dict[str, str]) -> None:
    code, err = winder("ctl", "pause", "--timeout", "1", env=env)  # no cell on this domain
    assert code == EXIT_FAILED and len(err.strip().splitlines()) == 1, err


def _child(parent: int, name: str, timeout: float = 60.0) -> int:
    """The pid of ``parent``'s child process whose command line names ``name``."""

    def found() -> int:
        for entry in Path("/proc").iterdir():
            if not entry.name.isdigit():
                continue
            try:
                ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
                argv = (entry / "cmdline").read_bytes().split(b"\0")
            except (OSError, IndexError, ValueError):
                continue
            if ppid == parent and any(a.endswith(name.encode()) for a in argv):
                return int(entry.name)
        return 0

    return int(
        wait.until(found, timeout, f"child {name} of {parent}", poll=0.2)
    )  # each look reads all of /proc


def _start_run(env: dict[str, str], tmp_path: Path) -> subprocess.Popen[str]:
    # a real-time run of some 10 s (20 turns of 1024 steps at 2048 steps/s): time to act on it mid-run
    argv = [str(BIN / "winder"), "run", "--turns-per-layer", "20", "--layers", "1", "--poles", "1"]
    argv += ["--real-time", "--bag-dir", str(tmp_path)]
    return popen(
        argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, stdin=subprocess.DEVNULL
    )


def _wait_running(run: subprocess.Popen[str], tmp_path: Path, timeout: float = 60.0) -> None:
    """Until the run is under way: its bag's file holds its first chunks (30 kB)."""
    wait.until(
        lambda: mcap_size(tmp_path) > 30_000,
        timeout,
        "the run's first 30 kB in its bag",
        heard=lambda: f"{mcap_size(tmp_path)} bytes",
        running=run,
    )


@pytest.mark.ros
def test_a_run_whose_consumer_is_killed(env: dict[str, str], tmp_path: Path) -> None:
    run = _start_run(env, tmp_path)
    try:
        _wait_running(run, tmp_path)
        os.kill(_child(run.pid, "sim_node"), signal.SIGKILL)
        _, err = run.communicate(timeout=120)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
    assert run.returncode == EXIT_NODE_DIED, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert "sim_node exited with status -9" in err, err


@pytest.mark.ros
def test_ctrl_c_interrupts_a_run(env: dict[str, str], tmp_path: Path) -> None:
    run = _start_run(env, tmp_path)
    try:
        _wait_running(run, tmp_path)
        run.send_signal(signal.SIGINT)
        _, err = run.communicate(timeout=120)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
    assert run.returncode == EXIT_INTERRUPTED and "Traceback" not in err, err
