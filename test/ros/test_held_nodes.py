"""A node held up (SIGSTOP, as a starved host or a debugger holds it) for
longer than the DDS lease, and the cell after it (issue 53). Real processes
over DDS.

Before the fix: an idle cell whose node was held for 10 s or more never took
a run again (every start refused "not ready: ... waiting", every node alive):
the held process never took the others for gone, so its writers did not send
its node names again to readers that had dropped it, and the cell's nodes
could no longer tell its endpoints on the graph. Republishing them mended
most holds, but in 7 of 60 the others never learnt the held node's endpoints
again: a node held past the lease now restarts its process
(winder.ros.rejoin). A run under way when its sim or profile node was held
so long was given up only after stall_abort; it now closes at once, with the
hold as its reason. And a run the consumer
closed for its stall while the profile node was held was timed when the
profile node woke, its steps reaching the next run.
"""

from __future__ import annotations

import os
import signal
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import Procs, closed_bags
from support import wait
from support.ros_probe import ready_states, start_job

from winder.motion.interp import interpolate
from winder.motion.job import Job
from winder.record.reader import read_run

pytestmark = pytest.mark.ros

#: one 8-turn layer of 512 fork steps a turn: 4096 steps
JOB = {"turns_per_layer": 8, "layers": 1, "poles": 1, "fork_steps_per_rev": 512}
#: s a node is held: past the 10 s lease of winder's Fast DDS profile
HELD_S = 12.0
#: layers of the job a node is held in: about 20 s in real time, the hold inside it
LONG_LAYERS = 10


def job_args(**more: object) -> list[str]:
    return [a for k, v in {**JOB, **more}.items() for a in ("-p", f"{k}:={v}")]


def positions(**more: object) -> np.ndarray:
    return np.concatenate([interpolate(s.start, s.delta) for s in Job(**{**JOB, **more}).segments()])


def check_complete(bag: Path) -> None:
    """Every step of the job, once, in order, and nothing else."""
    run = read_run(bag)
    assert run.complete and run.report["state"] == "done", run.report
    assert run.report["steps_missing"] == "0" and run.report["gaps"] == "0", run.report
    assert np.array_equal(run.steps[:, 2:], positions())


def held(pid: int, seconds: float, ros: Any) -> None:
    """The process stopped for ``seconds`` (the probe serves its callbacks meanwhile)."""
    os.kill(pid, signal.SIGSTOP)
    try:
        wait.spin_for(ros, seconds)
    finally:
        os.kill(pid, signal.SIGCONT)


def ready(ros: Any, states: dict[str, str]) -> None:
    wait.spin_until(
        ros,
        lambda: states.get("consumer") == "ready" and states.get("profile") == "ready",
        60,
        "consumer and profile node ready",
        heard=lambda: states,
    )


def started(ros: Any) -> str:
    """A start taken (asked again while the cell is not ready: a node restarting); its run id."""
    replies: list[Any] = []
    wait.spin_until(
        ros,
        lambda: replies.append(start_job(ros, timeout=30.0)) or replies[-1].success,
        60,
        "a start taken",
        heard=lambda: replies[-1:],
    )
    return str(replies[-1].message.split()[1])  # "run <id> started: ..."


@pytest.mark.parametrize("node", ["interp_node", "profile_node", "sim_node"])
def test_an_idle_cell_takes_a_run_after_a_node_was_held(
    node: str, tmp_path: Path, procs: Procs, ros: Any
) -> None:
    """The cell idle and ready; one node held for 12 s, past the lease: it
    restarts its process (same pid) and the cell takes the next start, whose
    run winds every step."""
    bags = tmp_path / "bags"
    states = ready_states(ros)
    cell = {
        "interp_node": procs.start("interp_node", "-p", "autostart:=false", *job_args()),
        "profile_node": procs.start("profile_node"),
        "sim_node": procs.start("sim_node", "-p", f"bag_dir:={bags}", "-p", "real_time:=false"),
    }
    ready(ros, states)
    held(cell[node].pid, HELD_S, ros)
    wait.log_has(lambda: procs.log(cell[node]), "restarted after a hold of", 60)
    assert cell[node].poll() is None  # the same process, the program run again in it
    bag = bags / started(ros)
    wait.spin_until(ros, lambda: bag in closed_bags(bags), 60, f"the bag {bag} closed")
    check_complete(bag)


@pytest.mark.parametrize("node", ["profile_node", "sim_node"])
def test_a_run_whose_node_was_held_past_the_lease_closes_at_once(
    node: str, tmp_path: Path, procs: Procs, ros: Any
) -> None:
    """A real-time run; its sim or profile node held 12 s in the middle of
    it: the run closes incomplete when the node is back, saying why, not
    after stall_abort (60 s here: the bag must close well before); the
    steps it executed are the job's first ones, exactly; the cell then
    winds the next run whole (the interp node given the short job again)."""
    from support.ros_probe import set_params

    bags = tmp_path / "bags"
    states = ready_states(ros)
    cell = {
        "interp_node": procs.start("interp_node", "-p", "autostart:=false", *job_args(layers=LONG_LAYERS)),
        "profile_node": procs.start("profile_node"),
        "sim_node": procs.start(
            "sim_node", "-p", f"bag_dir:={bags}", "-p", "real_time:=true", "-p", "stall_abort:=60.0"
        ),
    }
    ready(ros, states)
    first = bags / started(ros)
    wait.spin_until(ros, lambda: first.exists(), 30, f"the bag {first}")
    wait.spin_for(ros, 2.0)  # into the run
    held(cell[node].pid, HELD_S, ros)
    wait.spin_until(
        ros, lambda: first in closed_bags(bags), 30, f"the bag {first} closed (stall_abort is 60 s)"
    )
    run = read_run(first)
    assert run.report["state"] == "incomplete", run.report
    why = "held up" if node == "sim_node" else "is a new process (restarted)"
    assert any(why in e for e in run.errors), run.errors  # the run's ERROR, in its bag
    n = run.steps.shape[0]
    assert 0 < n < positions(layers=LONG_LAYERS).shape[0]
    assert np.array_equal(run.steps[:, 2:], positions(layers=LONG_LAYERS)[:n])  # the job's first steps
    [res] = set_params(ros, "interp_node", {"layers": 1})
    assert res.successful, res.reason
    bag = bags / started(ros)
    wait.spin_until(ros, lambda: bag in closed_bags(bags), 60, f"the bag {bag} closed")
    check_complete(bag)


def test_a_run_the_consumer_closed_is_timed_no_more(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """A real-time run started while the profile node is held, past the sim
    node's stall_abort: the sim node closes the run incomplete. When the profile
    node wakes it times none of that run's steps (it says it dropped them),
    and the next run of the same job executes each of its own steps once:
    nothing of the closed run reaches it."""
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from winder_interfaces.msg import CellState

    bags = tmp_path / "bags"
    states = ready_states(ros)
    seen: list[tuple[str, str]] = []
    latched = QoSProfile(
        depth=50, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )
    ros.create_subscription(CellState, "/winder/state", lambda m: seen.append((m.run_id, m.state)), latched)
    procs.start("interp_node", "-p", "autostart:=false", "-p", "stall_abort:=3.0", *job_args())
    profile = procs.start("profile_node", "-p", "lookahead:=0.05")
    procs.start("sim_node", "-p", f"bag_dir:={bags}", "-p", "real_time:=true", "-p", "stall_abort:=3.0")
    wait.spin_until(
        ros,
        lambda: states.get("consumer") == "ready" and states.get("profile") == "ready",
        60,
        "consumer and profile node ready",
        heard=lambda: states,
    )
    # a first run, wound whole: the interp node has heard everyone ready
    reply = start_job(ros)
    assert reply.success, reply.message
    bag = bags / reply.message.split()[1]
    wait.spin_until(ros, lambda: bag in closed_bags(bags), 60, f"the bag {bag} closed", heard=lambda: seen)
    # held before the next run's start: the sim node takes the run, the profile node sleeps through it
    os.kill(profile.pid, signal.SIGSTOP)
    try:
        reply = start_job(ros)
        assert reply.success, reply.message
        first = reply.message.split()[1]  # "run <id> started: ..."
        wait.spin_until(
            ros, lambda: (first, "failed") in seen, 30, "the sim node closing the run", heard=lambda: seen
        )
    finally:
        os.kill(profile.pid, signal.SIGCONT)
    wait.log_has(lambda: procs.log(profile), f"run {first}: closed by the consumer (failed)", 30)
    # the interp node takes the next start once the consumer's final report is heard (it comes
    # after the state: CONTRACT.md 5.3 #12)
    replies: list[Any] = []
    wait.spin_until(
        ros,
        lambda: (
            replies.append(start_job(ros, timeout=30.0))
            or replies[-1].success
            or "is running" not in replies[-1].message
        ),
        60,
        "a start taken",
        heard=lambda: replies[-1:],
    )
    reply = replies[-1]
    assert reply.success, reply.message
    second = reply.message.split()[1]
    bag = bags / second
    wait.spin_until(ros, lambda: bag in closed_bags(bags), 60, f"the bag {bag} closed", heard=lambda: seen)
    check_complete(bag)
