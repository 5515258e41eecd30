"""A node held up (SIGSTOP, as a starved host or a debugger holds it) for
longer than the DDS lease, and the cell after it (issue 53). Real processes
over DDS.

Before the fix: an idle cell whose node was held for 10 s or more never took
a run again (every start refused "not ready: ... waiting", every node alive):
the held process never took the others for gone, so its writers did not send
its node names again to readers that had dropped it, and the cell's nodes
could no longer tell its endpoints on the graph. And a run the consumer
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


def job_args(**more: object) -> list[str]:
    return [a for k, v in {**JOB, **more}.items() for a in ("-p", f"{k}:={v}")]


def positions() -> np.ndarray:
    return np.concatenate([interpolate(s.start, s.delta) for s in Job(**JOB).segments()])


def check_complete(bag: Path) -> None:
    """Every step of the job, once, in order, and nothing else."""
    run = read_run(bag)
    assert run.complete and run.report["state"] == "done", run.report
    assert run.report["steps_missing"] == "0" and run.report["gaps"] == "0", run.report
    assert np.array_equal(run.steps[:, 2:], positions())


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
