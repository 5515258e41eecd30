"""A winder process that ends leaves the ROS graph at once, and quickly.

rclpy's LifecycleNode kept its state machine, and through it the node's
handle, after ``destroy_node``: the process' DDS participant was only
removed by the interpreter's teardown (0.15 s a process, 0.1 s of it a sleep
in Fast DDS's exit), and a process that skipped that teardown stayed on the
graph for the whole lease (10 s) (:meth:`winder.ros.managed.ManagedNode.destroy_node`,
:func:`winder.ros.spin.leave`). Real node processes, a probe node on the
test's domain watching the graph."""

from __future__ import annotations

import signal
import subprocess
from pathlib import Path
from typing import Any

import pytest
from conftest import BIN, Procs, bag_closed, final_report, rosbags_read
from support import wait
from support.bags import mcap_size
from support.ros_probe import spin_until

from winder.procs import popen
from winder.record.bag import bags_in

pytestmark = pytest.mark.ros

#: well under the 10 s lease of winder's DDS profile (a participant that did not say goodbye stays
#: that long), over what a loaded machine takes to hear it said: 3 s was passed once in a fresh-clone
#: CI run (four workers and a busy loop on two cores, 2026-11-28), the probe's DDS threads starved
GONE_WITHIN = 6.0


def names(ros: Any) -> set[str]:
    return {n for n, _ in ros.get_node_names_and_namespaces()} - {ros.get_name()}


def gone(ros: Any, who: set[str] | None, what: str) -> None:
    """``who`` (None: every node but the probe) leaves the graph within
    GONE_WITHIN s; the failure names who was still there."""
    left = (lambda: names(ros) & who) if who is not None else (lambda: names(ros))
    spin_until(ros, lambda: not left(), GONE_WITHIN, what, heard=lambda: sorted(names(ros)))


def gone_after_exit(procs: Procs, ros: Any, p: subprocess.Popen[bytes], expected: set[str]) -> None:
    """``p``'s nodes are on the graph; SIGINT ends it with status 0 and they leave within GONE_WITHIN s."""
    spin_until(ros, lambda: expected <= names(ros), 60, f"{sorted(expected)} on the graph")
    assert procs.stop(p) == 0, procs.log(p)
    gone(ros, expected, f"{sorted(expected)} gone from the graph")
    assert "Traceback" not in procs.log(p)


@pytest.mark.parametrize("node", ["interp_node", "profile_node", "sim_node"])
def test_a_node_process_leaves_the_graph_when_it_ends(
    procs: Procs, ros: Any, tmp_path: Path, node: str
) -> None:
    p = procs.start(node, "-p", f"bag_dir:={tmp_path / 'bags'}") if node == "sim_node" else procs.start(node)
    gone_after_exit(procs, ros, p, {node})


def test_a_container_leaves_the_graph_when_it_ends(procs: Procs, ros: Any, tmp_path: Path) -> None:
    p = procs.launch(
        [
            str(BIN / "winder_container"),
            "winder_sim.sim_node:SimNode",
            "winder_profile.profile_node:ProfileNode",
            "winder_interp.interp_node:InterpNode",
            "--ros-args",
            "-p",
            f"bag_dir:={tmp_path / 'bags'}",
            "-p",
            "autostart:=false",
        ],
        "container",
    )
    gone_after_exit(procs, ros, p, {"interp_node", "profile_node", "sim_node"})


@pytest.mark.parametrize("mode", [[], ["--one-process"]], ids=["three processes", "one process"])
def test_winder_run_leaves_nothing_on_the_graph(
    procs: Procs, ros: Any, tmp_path: Path, mode: list[str]
) -> None:
    """After ``winder run`` has printed its summary and exited, neither its
    own node nor the cell's are on the graph a moment later."""
    seen: set[str] = set()
    # paced to the wall clock (~3 s): the probe sees the nodes before the run
    # ends, however slowly a loaded machine's discovery reaches it
    job = ["--turns-per-layer", "2", "--layers", "1", "--poles", "1", "--real-time"]
    run = subprocess.Popen(
        [str(BIN / "winder"), "run", *job, *mode, "--bag-dir", str(tmp_path / "bags")],
        env=procs.env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
    )

    def ended() -> bool:  # and every node the graph showed meanwhile, in seen
        seen.update(names(ros))  # the probe's graph is kept by DDS' threads: no spinning needed
        return run.poll() is not None

    wait.until(ended, 120, "the end of winder run", heard=lambda: sorted(seen))
    out = run.stdout.read().decode() if run.stdout else ""
    assert run.returncode == 0, out
    assert "state              done" in out, out
    assert {"winder_cell", "interp_node", "profile_node", "sim_node"} <= seen, seen
    gone(ros, None, "the graph empty")


@pytest.mark.usefixtures("hangup_taken")
def test_sighup_ends_winder_run_as_sigint_does(procs: Procs, ros: Any, tmp_path: Path) -> None:
    """SIGHUP (its terminal closed) to ``winder run`` mid-run: it says it was
    interrupted (status 130, no traceback), stops its cell, whose bag is
    closed with the run's final report (incomplete), and its own node and
    the cell's leave the graph at once. (SIGHUP killed it outright: status
    -1, nothing said, ``/winder_cell`` on the graph for the whole DDS lease.)"""
    bags = tmp_path / "bags"
    cell = {"winder_cell", "interp_node", "profile_node", "sim_node"}
    run = popen(
        [str(BIN / "winder"), "run", "--bag-dir", str(bags), "--turns-per-layer", "400"],
        env=procs.env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
    )
    try:
        # mid-run: its bag holds its first chunks, and the probe sees the whole cell
        wait.until(lambda: mcap_size(bags) > 30_000, 60, "the run's first 30 kB in its bag", running=run)
        spin_until(ros, lambda: cell <= names(ros), 30, f"{sorted(cell)} on the graph")
        run.send_signal(signal.SIGHUP)
        out, err = run.communicate(timeout=60)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
    assert run.returncode == 130, out + err
    assert err.strip().splitlines()[-1] == "winder run: interrupted" and "Traceback" not in err, err
    gone(ros, cell, f"{sorted(cell)} gone from the graph")
    [bag] = bags_in(bags)
    assert bag_closed(bag)
    assert final_report(rosbags_read(bag))["state"] == "incomplete"
