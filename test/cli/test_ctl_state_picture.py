"""`winder ctl state` prints one picture of the cell: read right after a
transition (a pause reached, a run just finished) every node's line speaks
of the cell's run and was said at or after the cell's state it is shown
under, the consumer's agreeing with it; a node it heard nothing from is
named, never left out, and a stranger's status never stands in for it.

Before, it printed whatever each node had last said when the query began:
``cell / done`` above ``sim_node consumer running ... steps 3047/4096``, and
while paused at 1,864 steps ``sim_node running 1101/20480`` (issue 53).
Real node processes over DDS; the oracles are the profile node's own
word on where the axes came to rest, and winder/state as a probe hears it.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from conftest import Procs, spin_until
from support import wait
from support.paths import TEST
from support.ros_probe import heard_diagnostics
from test_ctl import AGO, LONG, WINDER, ctl, node_rows, start_real_time_cell, under_way, until_state

from winder.cli.exits import EXIT_OK
from winder.procs import popen

pytestmark = pytest.mark.ros

FORGER = TEST / "consumers" / "status_forger.py"


def cell_states(ros: Any) -> list[tuple[str, str]]:
    """Every winder/state (state, run id) the probe hears from now on."""
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from winder_interfaces.msg import CellState

    states: list[tuple[str, str]] = []
    latched = QoSProfile(
        depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )
    ros.create_subscription(CellState, "/winder/state", lambda m: states.append((m.state, m.run_id)), latched)
    return states


def age(line: str) -> float:
    found = AGO.search(line)
    assert found, f"no age in {line!r}"
    return float(found.group(1))


def one_picture(out: str, run_id: str) -> tuple[str, dict[str, list[str]], set[str]]:
    """The cell's state in a ``winder ctl state`` output, its node rows and
    the nodes whose line it marks as not showing that state, checked to be
    one picture: a row for each of the three nodes; each of run ``run_id``
    and said at or after the cell's state (younger: each age is shown
    rounded to 0.1 s), or marked as behind it and truly older (a node that
    said nothing newer within the query's bound: held up on a loaded
    machine, which the query then says rather than wait on)."""
    [cell] = [ln for ln in out.splitlines() if ln.startswith("cell /  ")]  # (Fast DDS may write to stdout)
    words = cell.split()
    assert words[3:5] == ["run", run_id], out
    rows = node_rows(out)
    assert set(rows) == {"interp_node", "profile_node", "sim_node"}, out
    marked = set()
    for node, row in rows.items():
        line = next(ln for ln in out.splitlines() if ln.split()[:1] == [node])
        if "nothing newer came" in line:
            assert "said before the cell's state" in line and age(line) >= age(cell), out
            marked.add(node)
            continue
        assert row[3] == run_id, f"{node} speaks of another run: {out}"
        assert age(line) <= age(cell) + 0.1, f"{node}'s line is older than the cell's state: {out}"
    return words[2], rows, marked


def test_a_paused_run_reads_as_one_picture(procs: Procs, ros: Any, tmp_path: Path) -> None:
    """Paused three times mid-run, the cell read the moment winder/state
    says paused: the consumer paused at the very step the profile node said
    the axes came to rest at, the profile node paused, the interp node's run
    going on (paused is no end of the run to it)."""
    start_real_time_cell(procs, tmp_path / "bags")
    states = cell_states(ros)
    seen = heard_diagnostics(ros)
    code, out, err = ctl(procs, "start", *LONG, "--timeout", "60")
    assert code == EXIT_OK, out + err
    run_id = out.split()[1]
    total = out.split("started: ")[1].split()[0]
    spin_until(ros, lambda: under_way(seen, run_id), 60, f"run {run_id} under way")
    whole = 0  # pictures with no line marked
    for _ in range(3):
        n = len(states)
        code, out, err = ctl(procs, "pause")
        assert code == EXIT_OK, out + err
        rest = re.search(r"at rest after (\d+) steps", out)
        assert rest, out
        spin_until(
            ros, lambda n=n: ("paused", run_id) in states[n:], 60, "winder/state paused", heard=lambda: states
        )
        code, out, err = ctl(procs, "state")  # right after the transition
        assert code == EXIT_OK, out + err
        state, rows, marked = one_picture(out, run_id)
        assert state == "paused", out
        said = {
            "sim_node": ["consumer", "paused", run_id, "steps", f"{rest.group(1)}/{total}"],
            "profile_node": ["profile", "paused", run_id],
            "interp_node": ["interp", "running", run_id],  # the run goes on, for the node that sends it
        }
        for node, words in said.items():
            assert node in marked or rows[node][1 : 1 + len(words)] == words, out
        whole += not marked
        m = len(states)
        code, out, err = ctl(procs, "resume")
        assert code == EXIT_OK, out + err
        spin_until(
            ros,
            lambda m=m: ("running", run_id) in states[m:],
            60,
            "winder/state running",
            heard=lambda: states,
        )
    code, out, err = ctl(procs, "abort")
    assert code == EXIT_OK, out + err
    assert whole, "every picture had a line marked behind the cell's state"


def test_a_just_finished_run_reads_as_one_picture(procs: Procs, ros: Any, tmp_path: Path) -> None:
    """Queries started one after another across the end of a real-time run
    (from half-way until a second after winder/state said done): each shows
    one picture; one that shows the cell done shows every node done with the
    run, the consumer with every step."""
    start_real_time_cell(procs, tmp_path / "bags")
    states = cell_states(ros)
    seen = heard_diagnostics(ros)
    job = ["--set", "turns_per_layer=10", "--set", "layers=1", "--set", "poles=1"]  # ~5 s in real time
    code, out, err = ctl(procs, "start", *job, "--timeout", "60")
    assert code == EXIT_OK, out + err
    run_id = out.split()[1]
    total = out.split("started: ")[1].split()[0]

    def half_way() -> bool:
        return any(
            n == "sim_node: job" and v.get("run_id") == run_id and float(v.get("progress") or 0) >= 0.5
            for n, _, v in seen
        )

    spin_until(ros, half_way, 60, f"run {run_id} half-way")
    queries: list[subprocess.Popen[str]] = []
    done_at = 0.0
    try:
        while not done_at or time.monotonic() - done_at < 1.0:
            queries.append(
                popen(
                    [str(WINDER), "ctl", "state"],
                    env=procs.env,
                    stdout=subprocess.PIPE,
                    stderr=subprocess.PIPE,
                    text=True,
                )
            )
            wait.spin_for(ros, 0.25)  # the next query a moment later (pacing, not a deadline)
            if not done_at and ("done", run_id) in states:
                done_at = time.monotonic()
            assert len(queries) < 60, f"run {run_id} did not end: {states}"
        outputs = [q.communicate(timeout=60) for q in queries]
    finally:
        for q in queries:
            if q.poll() is None:
                q.kill()
                q.wait()
    finished = 0  # pictures of the cell done with no line marked
    for (out, err), q in zip(outputs, queries, strict=True):
        assert q.returncode == EXIT_OK, out + err
        state, rows, marked = one_picture(out, run_id)
        if state == "done":
            said = {
                "sim_node": ["consumer", "done", run_id, "steps", f"{total}/{total}"],
                "profile_node": ["profile", "done", run_id],
                "interp_node": ["interp", "done", run_id],
            }
            for node, words in said.items():
                assert node in marked or rows[node][1 : 1 + len(words)] == words, out
            finished += not marked
        else:
            assert state == "running", out
            assert "sim_node" in marked or rows["sim_node"][2] in ("running", "stalled"), out
    assert finished, [o for o, _ in outputs]


def test_a_node_not_heard_from_is_named_and_no_stranger_stands_in(procs: Procs, tmp_path: Path) -> None:
    """The profile node held up (SIGSTOP) while a stranger publishes a status
    named like it (and a winder/state): `ctl state` ends, shows no line of
    the stranger's and no state of its, and names the profile node as the
    node it heard nothing from; the other two nodes' lines are there."""
    procs.start("sim_node", "-p", f"bag_dir:={tmp_path / 'bags'}")
    profile = procs.start("profile_node")
    procs.start("interp_node", "-p", "autostart:=false")
    until_state(procs, lambda o: len(node_rows(o)) == 3, "the cell up: every node heard")
    forger = procs.launch(
        [sys.executable, str(FORGER), "--speaks-for", "profile_node", "--run-id", "forged_1"], "forger"
    )
    wait.until(
        lambda: "forging" in procs.log(forger), 60, "the forger forging", heard=lambda: procs.log(forger)
    )
    os.kill(profile.pid, signal.SIGSTOP)
    try:
        code, out, err = ctl(procs, "state")
    finally:
        os.kill(profile.pid, signal.SIGCONT)
    assert code == EXIT_OK, out + err
    rows = node_rows(out)
    assert set(rows) == {"interp_node", "sim_node"}, out
    assert rows["sim_node"][1] == "consumer" and rows["interp_node"][1] == "interp", out
    named = [ln for ln in out.splitlines() if ln.startswith("  no ") and "profile" in ln]
    assert named, f"the profile node is not named: {out}"
    assert "forged_1" not in out, out
