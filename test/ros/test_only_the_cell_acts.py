"""Only the cell acts on the cell: real cells (``winder run``, the three node
processes over DDS on the test's own domain) while a foreign node on the same
domain and namespace forges what the cell's nodes act on, and while a second
cell, a second node of a role, and a player try to join.

Each run is compared with an undisturbed run of the same job: the same step
stream (every recorded row equal), the same operator events, done; the
intruder named in the summary and in the consumer's final report, and
nothing of it in the bag.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import BIN, Procs, final_report, rosbags_read
from support import wait
from support.bags import control_docs
from support.paths import TEST

from winder.procs import popen
from winder.record.reader import read_run

pytestmark = pytest.mark.ros

INTRUDER = TEST / "consumers" / "intruder.py"
#: a small job with operator events: a pause and a resume from the schedule, then an override
JOB = ["--turns-per-layer", "30", "--layers", "2", "--poles", "2"]
EVENTS = ["--schedule", "pause@1.0,resume@1.5,override@2.0=0.8"]


def winder_run(
    procs: Procs, bags: Path, *args: str, timeout: float = 240
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(BIN / "winder"), "run", "--bag-dir", str(bags), *args],
        env=procs.env,
        capture_output=True,
        text=True,
        timeout=timeout,
        stdin=subprocess.DEVNULL,
    )


def long_run(procs: Procs, bags: Path) -> subprocess.Popen[str]:
    """``winder run`` of a job that lasts ~14 s (the default job, 84.5 s of
    simulated time, paced to the wall clock at 6 x, so that a fast machine
    does not end it before the test acts; 400 turns a layer at 160 x ran
    195 s: a real-time cell keeps ~8 x at most with the default look-ahead),
    in the background: the live cell
    (its output into files beside the bags, read by :func:`finish`: a pipe
    nobody reads while the test goes on could fill and stop it)."""
    bags.mkdir(parents=True, exist_ok=True)
    return popen(
        [
            *(str(BIN / "winder"), "run", "--bag-dir", str(bags)),
            *("--real-time", "--real-time-factor", "6"),
        ],
        env=procs.env,
        stdout=(bags.parent / f"{bags.name}.out").open("w"),
        stderr=(bags.parent / f"{bags.name}.err").open("w"),
        text=True,
        stdin=subprocess.DEVNULL,
    )


def recording(run: subprocess.Popen[str], bags: Path) -> None:
    """Until a :func:`long_run`'s run records (its bag has its .mcap file): the live cell is up."""
    wait.until(
        lambda: list(bags.glob("*/*.mcap")),
        60,
        f"the live cell's recording in {bags}",
        heard=lambda: (bags.parent / f"{bags.name}.err").read_text()[-1500:],
        running=run,
    )


def finish(run: subprocess.Popen[str], bags: Path, timeout: float = 240) -> tuple[str, str]:
    """Wait for a :func:`long_run`; its stdout and stderr."""
    run.wait(timeout=timeout)
    return (bags.parent / f"{bags.name}.out").read_text(), (bags.parent / f"{bags.name}.err").read_text()


def bag_of(out: str) -> Path:
    found = re.search(r"^  bag +(\S+)", out, re.M)
    assert found, out
    return Path(found.group(1))


def recorded(bag: Path) -> tuple[np.ndarray, list[dict[str, Any]], dict[str, list[tuple[int, Any]]]]:
    """The run's timed step rows as recorded, its operator events without
    their run id, and every message."""
    msgs = rosbags_read(bag)
    chunks = [np.asarray(m.data, np.int64).reshape(-1, 5) for _, m in msgs["/c1/winder/step_times"]]
    rows = np.concatenate(chunks)

    events = control_docs(msgs.get("/c1/winder/control", []))
    for doc in events:
        doc.pop("run_id")
    return rows, events, msgs


@pytest.mark.parametrize(
    "forge",
    [
        "control",
        "steps",
        "job",
        "ready,progress,sim_config",
        "diagnostics,state",
    ],
)
def test_forged_messages_change_nothing(tmp_path: Path, procs: Procs, forge: str) -> None:
    clean = winder_run(procs, tmp_path / "clean", "--namespace", "/c1", *JOB, *EVENTS)
    assert clean.returncode == 0, clean.stdout + clean.stderr
    intruder = procs.launch(
        [sys.executable, str(INTRUDER), "--forge", forge, "--ros-args", "-r", "__ns:=/c1"], "intruder"
    )
    # paced to the wall clock (77 s simulated in ~5 s): on a loaded machine the
    # intruder, started just before, must still find the run going to forge into it
    paced = ["--real-time", "--real-time-factor", "15"]
    r = winder_run(procs, tmp_path / "attacked", "--namespace", "/c1", *JOB, *EVENTS, *paced)
    assert intruder.poll() is None, "the intruder stopped before the run"
    assert r.returncode == 0, r.stdout + r.stderr
    assert "  state              done" in r.stdout, r.stdout
    assert "(missing 0, gaps 0)" in r.stdout, r.stdout
    # the intruder did forge into this very run, and was named, not obeyed
    assert "forging" in "".join(p.read_text() for p in procs.log_dir.glob("intruder*.log"))
    assert "ignored, foreign" in r.stdout and "/c1/intruder" in r.stdout, r.stdout
    rows_clean, events_clean, _ = recorded(bag_of(clean.stdout))
    rows, events, msgs = recorded(bag_of(r.stdout))
    assert np.array_equal(rows, rows_clean), "the recorded step stream differs from the undisturbed run's"
    assert events == events_clean
    report = final_report(msgs, "c1")
    assert report["state"] == "done" and report["steps_done"] == report["steps_total"]
    if forge not in ("diagnostics,state", "ready,progress,sim_config"):
        # what reached the consumer was refused and counted in its report
        assert "/c1/intruder" in report.get("intruders", ""), report
    # nothing the intruder sent is in the bag: one job description, statuses only of the cell's nodes
    assert len(msgs["/c1/winder/job"]) == 1
    names = {st.name for _, arr in msgs["/diagnostics"] for st in arr.status}
    assert all(n.split(":")[0] in ("c1/interp_node", "c1/profile_node", "c1/sim_node") for n in names), names
    assert all(st.message != "forged" for _, st in msgs.get("/c1/winder/state", []))
    run = read_run(bag_of(r.stdout))
    assert run.complete and run.report["state"] == "done"


def test_a_second_cell_in_the_namespace_is_refused(tmp_path: Path, procs: Procs) -> None:
    first = long_run(procs, tmp_path / "a")
    try:
        recording(first, tmp_path / "a")  # the first cell runs
        second = winder_run(procs, tmp_path / "b", timeout=120)
        out, err = finish(first, tmp_path / "a")
    finally:
        if first.poll() is None:
            first.kill()
    assert second.returncode == 2, second.stdout + second.stderr
    # said by winder run, or by its node that found the other cell's first
    said = r"another cell runs in namespace /|another [a-z ]+ already runs in /"
    assert re.search(said, second.stderr), second.stderr
    assert "Traceback" not in second.stderr
    assert not (tmp_path / "b").exists() or not any((tmp_path / "b").iterdir())
    assert first.returncode == 0, out + err
    assert "(missing 0, gaps 0)" in out and "  state              done" in out, out
    assert read_run(bag_of(out)).complete


def test_a_second_node_of_a_role_leaves(tmp_path: Path, procs: Procs) -> None:
    first = long_run(procs, tmp_path / "a")
    try:
        recording(first, tmp_path / "a")  # the first cell runs
        seconds = [procs.start(node, "-p", f"bag_dir:={tmp_path / 'b'}") for node in ("sim_node",)]
        seconds += [procs.start(node) for node in ("profile_node", "interp_node")]
        for p in seconds:
            assert p.wait(timeout=30) == 2
        out, err = finish(first, tmp_path / "a")
    finally:
        if first.poll() is None:
            first.kill()
    logs = "".join(p.read_text() for p in procs.log_dir.glob("*.log"))
    for role in ("step consumer", "profile node", "interp node"):
        assert f"another {role} already runs in /" in logs, logs
    assert first.returncode == 0, out + err
    assert "(missing 0, gaps 0)" in out and "  state              done" in out, out


def test_play_into_a_live_cell_is_refused_and_forced_changes_nothing(tmp_path: Path, procs: Procs) -> None:
    recorded_run = winder_run(procs, tmp_path / "rec", *JOB)
    assert recorded_run.returncode == 0, recorded_run.stderr
    bag = bag_of(recorded_run.stdout)
    live = long_run(procs, tmp_path / "live")

    def play(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [str(BIN / "winder"), "play", str(bag), *args],
            env=procs.env,
            capture_output=True,
            text=True,
            timeout=120,
            stdin=subprocess.DEVNULL,
        )

    try:
        # the live cell is up once its run records (a fixed wait was too short on a loaded machine)
        recording(live, tmp_path / "live")
        refused = play()
        forced = play("--force", "--rate", "20")
        out, err = finish(live, tmp_path / "live")
    finally:
        if live.poll() is None:
            live.kill()
    assert refused.returncode == 2, refused.stdout + refused.stderr
    assert "a live cell runs in /" in refused.stderr and "--namespace" in refused.stderr, refused.stderr
    assert "Traceback" not in refused.stderr
    assert forced.returncode == 0, forced.stdout + forced.stderr
    # the live run took nothing of the recording: done, every step, the player named
    assert live.returncode == 0, out + err
    assert "  state              done" in out and "(missing 0, gaps 0)" in out, out
    assert "/winder_player" in out, out
    live_bag = rosbags_read(bag_of(out))
    assert len(live_bag["/winder/job"]) == 1


def test_resim_into_a_live_cell_is_refused_in_one_line(tmp_path: Path, procs: Procs) -> None:
    """``winder resim`` of a recording whose namespace holds a live cell is
    refused as ``winder play`` refuses it: one line naming the live cell,
    exit status 2, no sim node started and no bag written (it ended with
    "sim_node exited with status 2", status 4, no reason); the live run goes
    on undisturbed, done."""
    recorded_run = winder_run(procs, tmp_path / "rec", *JOB)
    assert recorded_run.returncode == 0, recorded_run.stderr
    bag = bag_of(recorded_run.stdout)
    live = long_run(procs, tmp_path / "live")
    try:
        recording(live, tmp_path / "live")  # the live cell is up once its run records
        refused = subprocess.run(
            [str(BIN / "winder"), "resim", str(bag), "--bag-dir", str(tmp_path / "resim")],
            env=procs.env,
            capture_output=True,
            text=True,
            timeout=120,
            stdin=subprocess.DEVNULL,
        )
        out, err = finish(live, tmp_path / "live")
    finally:
        if live.poll() is None:
            live.kill()
    assert refused.returncode == 2, refused.stdout + refused.stderr
    lines = refused.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in refused.stderr, refused.stderr
    said = r"winder resim: error: a live cell runs in / \(/(interp|profile|sim)_node[^)]*\) and .*"
    assert re.fullmatch(said, lines[0]) and "ROS_DOMAIN_ID" in lines[0], lines[0]
    assert not (tmp_path / "resim").exists() or not any((tmp_path / "resim").iterdir())
    assert live.returncode == 0, out + err
    assert "  state              done" in out and "(missing 0, gaps 0)" in out, out
    assert "ignored, foreign" not in out, out
