"""`winder run` ends a run only on the word of the cell's own consumer
(docs/SECURITY.md): a foreign node in the cell's namespace that names
itself, says ``role: consumer`` and forges the end of the running run (a
final ``done`` job status of the run, ``bag /FAKE``) is named and ignored.
Before, a status was believed when its sender was the node it named: the
forger's own name passed, and its role was taken from its payload, so
`winder run` printed its forged summary and left the run going.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from conftest import Procs
from support.paths import TEST
from test_only_the_cell_acts import JOB, bag_of, winder_run

from winder.record.reader import read_run

pytestmark = pytest.mark.ros

FORGER = TEST / "consumers" / "status_forger.py"


def test_a_forger_that_says_it_is_the_consumer_ends_no_run(tmp_path: Path, procs: Procs) -> None:
    forger = procs.launch(
        [sys.executable, str(FORGER), "--speaks-for", "self", "--ros-args", "-r", "__ns:=/c1"], "forger"
    )
    # paced to the wall clock (77 s simulated in ~5 s): the forger finds the run going
    paced = ["--real-time", "--real-time-factor", "15"]
    r = winder_run(procs, tmp_path / "bags", "--namespace", "/c1", *JOB, *paced)
    assert forger.poll() is None, procs.log(forger)
    assert "forging the end of run" in procs.log(forger), procs.log(forger)  # into this very run
    assert r.returncode == 0, r.stdout + r.stderr
    assert "/FAKE" not in r.stdout, r.stdout
    assert "  state              done" in r.stdout and "(missing 0, gaps 0)" in r.stdout, r.stdout
    assert "ignored, foreign" in r.stdout and "/c1/forger" in r.stdout, r.stdout
    run = read_run(bag_of(r.stdout))
    assert run.complete and run.report["state"] == "done", run.report
    assert run.report["steps_done"] == run.report["steps_total"], run.report
