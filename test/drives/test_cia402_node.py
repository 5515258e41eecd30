"""``winder run --drives`` and ``cia402_node`` on drive twins: the real
command and node processes over DDS, a drives file on python-can's virtual
bus (the node serves a twin per axis in its own process), and the bag read
back. Oracles: the job's own step count, the recorded final report, the
exit-code table."""

from __future__ import annotations

import sqlite3
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from support import wait
from support.cli import assert_one_line_error
from support.paths import TEST

from winder.cli.exits import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK
from winder.procs import popen
from winder.record.bag import bags_in
from winder.record.reader import read_run

pytestmark = pytest.mark.ros

WINDER = Path(sys.executable).with_name("winder")
DRIVES = TEST / "drives" / "data" / "twin_cell.yaml"
#: 4 turns of 1024 fork steps (1 s at this ramp); 40 turns for a run long enough to stop
SMALL = ("--turns-per-layer", "4", "--layers", "1", "--poles", "1", "--v-max", "4096")
LONG = ("--turns-per-layer", "40", "--layers", "1", "--poles", "1", "--v-max", "4096")


def winder_run(procs: Any, bags: Path, *words: str) -> subprocess.Popen[str]:
    return popen(
        [str(WINDER), "run", "--drives", str(DRIVES), "--bag-dir", str(bags), *words],
        env=procs.env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
    )


def ctl(procs: Any, *words: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(WINDER), "ctl", *words], env=procs.env, capture_output=True, text=True, timeout=120
    )


def only_bag(bags: Path) -> Path:
    [bag] = bags_in(bags)
    return bag


def test_winder_run_drives_winds_a_small_job_on_the_twins(procs: Any, tmp_path: Path) -> None:
    bags = tmp_path / "bags"
    p = winder_run(procs, bags, *SMALL)
    out, err = p.communicate(timeout=180)
    assert p.returncode == EXIT_OK, out + err
    assert f"the CiA 402 drives of {DRIVES}" in out
    run = read_run(only_bag(bags))
    assert run.complete, run.report
    assert run.report["steps_done"] == run.report["steps_total"] == str(run.plan.total_steps)
    assert run.plan.total_steps == 4 * 1024
    assert int(run.report["syncs"]) > 0  # the steps went out as SYNC cycles on the bus
    assert len(run.states.t) > 10  # joint states from the twins' TPDOs, recorded
    # its part, beside the bag by default, is a twin's: simulated, never counted with real ones
    with sqlite3.connect(f"{(bags / 'parts.sqlite').as_uri()}?mode=ro", uri=True) as con:
        parts = con.execute("SELECT run_id, simulated, state FROM parts").fetchall()
    assert parts == [(run.run_id, 1, "done")]


def test_ctl_estop_mid_run_stops_the_drives_and_closes_the_run(procs: Any, tmp_path: Path) -> None:
    bags = tmp_path / "bags"
    p = winder_run(procs, bags, *LONG)

    def running() -> bool:
        assert p.poll() is None, p.communicate()
        return "running" in ctl(procs, "state", "--timeout", "10").stdout

    wait.until(running, 120, "the cell's state running")
    r = ctl(procs, "estop", "--timeout", "30")
    assert r.returncode == EXIT_OK, r.stdout + r.stderr
    assert r.stdout.startswith("emergency stop: every axis quick-stopped; run "), r.stdout
    assert r.stdout.strip().endswith(" closed incomplete"), r.stdout
    out, err = p.communicate(timeout=120)
    assert p.returncode == EXIT_FAILED, out + err  # incomplete
    assert "emergency stop" in out.splitlines()[-2] + err
    run = read_run(only_bag(bags))
    assert run.closed and run.report["state"] == "incomplete"
    assert run.report["faults"] == "emergency stop"
    assert 0 < int(run.report["steps_done"]) < run.plan.total_steps


def test_a_bad_drives_file_is_refused_before_anything_starts(procs: Any, tmp_path: Path) -> None:
    bad = tmp_path / "drives.yaml"
    bad.write_text(DRIVES.read_text().replace("node_id: 2", "node_id: 200"))
    bags = tmp_path / "bags"
    r = subprocess.run(
        [str(WINDER), "run", "--drives", str(bad), "--bag-dir", str(bags), *SMALL],
        env=procs.env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert_one_line_error(r, f"{bad}: axes.fork.node_id=200 is invalid: must be an integer in [1, 127]")
    assert r.returncode == EXIT_BAD_INPUT
    assert r.stdout == ""  # no plan printed, no domain taken
    assert not bags.exists()  # no bag directory made: no node started
