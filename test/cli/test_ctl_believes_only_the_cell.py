"""`winder ctl` believes only the cell's own nodes (docs/SECURITY.md): a
foreign node in the cell's namespace forges the end of the running run (a
final ``done`` job status of the run, ``bag /FAKE``, ``role: consumer``, and
``winder/state`` done), speaking for the cell's consumer or for itself,
while `winder ctl start --wait` follows the run and `winder ctl state`
reads the cell. Real node processes over DDS; the oracles are the bag the
run wrote and the exit-code table (winder.cli.exits).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from conftest import Procs, closed_bags
from support import wait
from support.paths import TEST
from test_ctl import LONG, WINDER, Lines, ctl, node_rows, one_line

from winder.cli.exits import EXIT_ABORTED, EXIT_OK
from winder.procs import popen
from winder.record.reader import read_run

pytestmark = pytest.mark.ros

FORGER = TEST / "consumers" / "status_forger.py"
NS = "/ty"


def start_cell(procs: Procs, bags: Path) -> None:
    """A real-time cell in :data:`NS`, its interp node waiting for a start."""
    here = ["-r", f"__ns:={NS}"]
    procs.start("sim_node", *here, "-p", f"bag_dir:={bags}", "-p", "real_time:=true")
    procs.start("profile_node", *here)
    procs.start("interp_node", *here, "-p", "autostart:=false")


def steps_of(line: str) -> int:
    """The steps a ``--wait`` progress line says were executed (``  running    steps 283 of ...``)."""
    words = line.split()
    return int(words[2]) if len(words) > 2 and words[1] == "steps" and words[2].isdigit() else -1


@pytest.mark.parametrize("speaks_for", ["sim_node", "self"])
def test_a_forged_end_of_the_run_ends_no_wait_and_shows_nowhere(
    procs: Procs, tmp_path: Path, speaks_for: str
) -> None:
    """The issue's case (a node ``/ty/intruder`` publishing ``ty/sim_node: job``
    done, the run's id, ``bag /FAKE``, 8 % into the run: ``--wait`` printed
    ``done, bag /FAKE`` and exited 0 while the run went on) and a forger
    that names itself and says it is the consumer: the follower goes on
    through the forging, `ctl state` shows the run running, and the run
    ends as the cell ends it (an abort here: exit 3, its real bag), the
    forger named as ignored."""
    bags = tmp_path / "bags"
    start_cell(procs, bags)
    follow = popen(
        [str(WINDER), "ctl", "start", "--namespace", NS, *LONG, "--wait", "--timeout", "60"],
        env=procs.env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        lines = Lines(follow)
        first = lines.until(lambda ln: ln.startswith("run "), 90, "the run id", follow)
        run_id = first.split()[1]
        lines.until(lambda ln: steps_of(ln) > 0, 90, "the run under way", follow)
        forger = procs.launch(
            [sys.executable, str(FORGER), "--speaks-for", speaks_for, "--ros-args", "-r", f"__ns:={NS}"],
            "forger",
        )
        wait.until(
            lambda: "forging the end of run " + run_id in procs.log(forger),
            60,
            "the forger forging into the run",
            heard=lambda: procs.log(forger)[-500:],
        )
        # the follower has taken two more of the cell's statuses while the forger forged (20 a second)
        n = len(lines.lines)
        wait.until(
            lambda: sum(steps_of(ln) > 0 for ln in lines.lines[n:]) >= 2 or follow.poll() is not None,
            60,
            "two more progress lines",
            heard=lambda: lines.lines[-10:],
        )
        assert follow.poll() is None, lines.lines
        assert not any("/FAKE" in ln or " done" in ln for ln in lines.lines), lines.lines
        code, out, err = ctl(procs, "state", "--namespace", NS)
        assert code == EXIT_OK, out + err
        # (the line, not the output's start: Fast DDS writes its own errors to stdout, its
        # shared-memory port locks contended on a busy machine)
        assert any(ln.startswith(f"cell {NS}  running  run {run_id}") for ln in out.splitlines()), out
        rows = node_rows(out)
        assert rows["ty/sim_node"][1:4] == ["consumer", "running", run_id], out
        assert "/FAKE" not in out and "forger" not in " ".join(rows), out
        assert forger.poll() is None, procs.log(forger)
        code, out, err = ctl(procs, "abort", "--namespace", NS)
        assert code == EXIT_OK and f"run {run_id}: aborting" in out, out + err
        follow.wait(timeout=120)
        lines._thread.join(timeout=30)  # every line it wrote read
    finally:
        if follow.poll() is None:
            follow.kill()
            follow.wait()
    assert follow.stderr is not None
    err = follow.stderr.read()
    assert follow.returncode == EXIT_ABORTED, "\n".join(lines.lines) + err
    said = lines.lines[-1]
    [bag] = closed_bags(bags)
    assert said == f"run {run_id}: aborted, bag {bag.resolve()}", lines.lines
    assert f"run {run_id} ended aborted" in one_line(err), err
    # the forger was heard, and named, not believed
    assert any(ln.startswith(f"  ignored, foreign  {NS}/forger (") for ln in lines.lines), lines.lines
    run = read_run(bag)
    assert run.plan.run_id == run_id and run.report["state"] == "aborted", run.report
