"""The cell under load (issue 40): a real-time run paused, its feed
overridden and resumed while the sim node is held up (SIGSTOP, then
SIGCONT), as a starved host holds it; and a consumer whose clock runs past
the resume's first steps before they come. Real processes over DDS.

Before the fix, the resumed steps came behind the sim node's clock (the
resume was timed from the clock the profile node heard before the sim node
stopped, plus the look-ahead; the sim node's free-running clock leapt to
the wall clock's pace when it woke; and a resume event that came after its
first steps was refused, so the node stayed at rest and its clock ran on)
and the sim node died with a ``ValueError`` traceback, every time. Now the
resume is timed ahead of the clock as it runs on, the free-running clock
never leaps, the resume is booked whenever it comes, and a step that still
comes behind the clock is executed at it, counted and reported.
"""

from __future__ import annotations

import os
import signal
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import Procs, closed_bags, is_consumer, rosbags_read, spin_until
from support import wait
from support.bags import control_docs
from support.paths import TEST
from support.ros_probe import heard_diagnostics, set_params

from winder.motion.interp import interpolate
from winder.motion.job import Job
from winder.record.reader import read_run

pytestmark = pytest.mark.ros

#: one 8-turn layer (4096 steps of the fork, 2.4 s at full speed)
JOB = {"turns_per_layer": 8, "layers": 1, "poles": 1, "fork_steps_per_rev": 512}
#: s the sim node is held up before and after the resume
HELD_S = 1.0
#: the test consumer's leap (test/consumers/late_clock.py: LEAP_S)
LEAP_S = 1.0
RATE = 200.0  # the sim node's publish_rate (default)


def positions() -> np.ndarray:
    """Every step position of the uninterrupted job, by the interpolation."""
    return np.concatenate([interpolate(s.start, s.delta) for s in Job(**JOB).segments()])


class Cell:
    """What the probe hears of a cell: its states, its clock, its statuses."""

    def __init__(self, ros: Any) -> None:
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
        from rosgraph_msgs.msg import Clock

        from winder_interfaces.msg import CellState

        self.ros = ros
        self.states: list[str] = []
        self.clock_ns = -1
        latched = QoSProfile(
            depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
        )
        ros.create_subscription(CellState, "/winder/state", lambda m: self.states.append(m.state), latched)
        ros.create_subscription(Clock, "/clock", self._clock, qos_profile_sensor_data)
        self.seen = heard_diagnostics(ros)

    def _clock(self, m: Any) -> None:
        self.clock_ns = max(self.clock_ns, m.clock.sec * 1_000_000_000 + m.clock.nanosec)

    def until(self, cond: Any, what: str, timeout: float = 60.0) -> Any:
        return spin_until(self.ros, cond, timeout, what, heard=lambda: (self.states, self.clock_ns / 1e9))

    def call(self, service: str) -> str:
        from std_srvs.srv import Trigger

        client = self.ros.create_client(Trigger, service)
        self.until(client.service_is_ready, f"the service {service}", 30)
        future = client.call_async(Trigger.Request())
        self.until(future.done, f"the reply of {service}", 30)
        reply = future.result()
        self.ros.destroy_client(client)
        assert reply.success, reply.message
        return str(reply.message)

    def finished(self, bags: Path) -> Path:
        """The run's bag, once closed (the probe hears the cell meanwhile)."""
        [bag] = self.until(lambda: closed_bags(bags), f"a closed bag in {bags}", 120)
        return bag

    def pause_and_slow_down(self) -> None:
        """Run 0.5 s, pause, wait for the axes to rest and the clock to run on,
        set feed_override 0.5."""
        self.until(lambda: "running" in self.states, "the run to start")
        self.until(lambda: self.clock_ns >= 500_000_000, "0.5 s of the run's clock")
        assert "pausing" in self.call("/profile_node/pause")
        self.until(lambda: self.states[-1:] == ["paused"], "the axes to rest")
        rest = self.clock_ns
        self.until(lambda: self.clock_ns > rest + 200_000_000, "the clock running on while paused")
        [result] = set_params(self.ros, "profile_node", {"feed_override": 0.5})
        assert result.successful, result.reason


def check_complete(bag: Path) -> tuple[Any, dict[str, list[tuple[int, Any]]]]:
    """The run is done with every step of the uninterrupted job, once, in order."""
    run = read_run(bag)
    assert run.complete and run.report["state"] == "done", run.report
    assert run.report["steps_missing"] == "0" and run.report["gaps"] == "0", run.report
    assert np.array_equal(run.steps[:, 2:], positions())
    assert np.all(np.diff(run.steps[:, 0]) > 0)
    return run, rosbags_read(bag)


def control_events(raw: dict[str, list[tuple[int, Any]]]) -> list[dict[str, Any]]:
    return control_docs(raw.get("/winder/control", []))


def test_sim_node_held_up_around_the_resume(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """Real time; pause, feed override 0.5; the sim node stopped (SIGSTOP)
    for 1 s, the resume called, 1 s more, then SIGCONT: the sim node lives,
    the run ends done with every step, no step came behind its clock (the
    profile node carried the clock it heard on by the wall time since, and
    the woken sim node's clock went on from where it stood), no traceback."""
    cell = Cell(ros)
    bags = tmp_path / "bags"
    sim = procs.start("sim_node", "-p", f"bag_dir:={bags}", "-p", "real_time:=true")
    procs.start("profile_node", "-p", "lookahead:=0.05")
    procs.start("interp_node", *[a for k, v in JOB.items() for a in ("-p", f"{k}:={v}")])
    cell.pause_and_slow_down()
    os.kill(sim.pid, signal.SIGSTOP)
    try:
        # the stimulus, not a wait for a result: the sim node held up, its clock unheard
        wait.spin_for(ros, HELD_S)
        held = cell.clock_ns  # its last (what was on its way came meanwhile)
        assert "resuming" in cell.call("/profile_node/resume")
        wait.spin_for(ros, HELD_S)
    finally:
        os.kill(sim.pid, signal.SIGCONT)
    cell.until(lambda: cell.states[-1:] == ["running"], "the resume's running state")
    bag = cell.finished(bags)
    assert sim.poll() is None, procs.log(sim)
    log = procs.log(sim)
    assert "Traceback" not in log and "ValueError" not in log and "event refused" not in log, log
    run, raw = check_complete(bag)
    assert "late_steps" not in run.report, run.report
    assert not [m for n, m, v in cell.seen if is_consumer(n, v) and "behind" in m]
    pause, override, resume = control_events(raw)
    assert [e["event"] for e in (pause, override, resume)] == ["pause", "override", "resume"]
    # the resume was timed from the clock carried on over the time the sim node was held
    # (not from the clock heard before it stopped): a second and the look-ahead ahead of it
    assert resume["t_request_ns"] >= held + 0.9e9, (resume, held)
    assert resume["t_ns"] >= resume["t_request_ns"] + 50_000_000
    first = int(np.searchsorted(run.steps[:, 0], resume["t_ns"]))
    assert first == pause["steps"]  # at rest from the pause to the resume


def test_steps_behind_the_clock_are_executed_at_it_counted_and_reported(
    tmp_path: Path, procs: Procs, ros: Any
) -> None:
    """Real time; pause, feed override 0.5, resume, with a consumer whose
    clock is LEAP_S beyond the first resumed step when it comes
    (test/consumers/late_clock.py, the sim node otherwise): it lives, runs
    the job to its end with every step, executes the steps behind its clock
    at the clock (the samples go on from there), counts them in its final
    report (``late_steps``, ``late_steps_behind_max_ms``: exactly the
    recorded steps timed before its clock) and reports them once as a
    stream ERROR on /diagnostics with the same numbers; no traceback."""
    cell = Cell(ros)
    bags = tmp_path / "bags"
    late = procs.launch(
        [
            sys.executable,
            str(TEST / "consumers" / "late_clock.py"),
            "--ros-args",
            "-p",
            f"bag_dir:={bags}",
            "-p",
            "real_time:=true",
        ],
        "late_clock",
    )
    procs.start("profile_node", "-p", "lookahead:=0.05")
    procs.start("interp_node", *[a for k, v in JOB.items() for a in ("-p", f"{k}:={v}")])
    cell.pause_and_slow_down()
    assert "resuming" in cell.call("/profile_node/resume")
    bag = cell.finished(bags)
    assert late.poll() is None, procs.log(late)
    log = procs.log(late)
    assert "Traceback" not in log, log
    run, raw = check_complete(bag)
    pause, _override, resume = control_events(raw)
    t = run.steps[:, 0]  # as the stream timed them (the bag keeps the stream as it came)
    first = int(t[pause["steps"]])  # the first step after the rest
    assert first > resume["t_ns"]
    # the clock the steps met: the last sample (200 Hz) at or before first + LEAP_S
    period = round(1e9 / RATE)
    clock = (first + round(LEAP_S * 1e9)) // period * period
    # a step at the clock's very nanosecond is on time or not as the rounding of the sample goes
    behind = [
        int(np.count_nonzero(t < clock)) - pause["steps"],
        int(np.count_nonzero(t <= clock + 1)) - pause["steps"],
    ]
    n_late = int(run.report["late_steps"])
    assert n_late in behind, (run.report, behind)
    assert n_late > 100  # a second of the motion at half speed
    behind_ms = run.report["late_steps_behind_max_ms"]
    assert abs(float(behind_ms) - (clock - first) / 1e6) <= 5.01e-4, (behind_ms, clock - first)  # .3f
    # once, as a stream ERROR, with the numbers of the final report
    errors = [
        (s.message, s.level)
        for _, arr in raw["/diagnostics"]
        for s in arr.status
        if s.name.endswith(": stream") and s.message.startswith("late steps")
    ]
    text = f"late steps: {n_late} steps came behind the clock, up to {behind_ms} ms"
    assert len(errors) == 1 and errors[0][0].startswith(text) and errors[0][1] == 2, (errors, text)
    assert any(m.startswith(text) for n, m, _ in cell.seen if n.endswith("sim_node: stream")), cell.seen
    assert run.report["errors"] == "1", run.report
    # the samples went on from the clock: joint states' stamps never go back, none missing
    stamps = np.array(
        [m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for _, m in raw["/winder/joint_states"]]
    )
    assert np.all(np.diff(stamps) == period), np.unique(np.diff(stamps))


def test_a_consumer_late_with_its_sim_config_can_still_be_paused_and_aborted(
    tmp_path: Path, procs: Procs, ros: Any
) -> None:
    """Issue 41: a real-time consumer whose set-up of a run takes 12 s
    (test/consumers/slow_start.py), so its winder/sim_config of the run
    comes after the profile node's MODE_WAIT (10 s). The profile node paces
    the steps on its wall clock meanwhile (it used to send every step at
    once, "without look-ahead", and then refuse pause and abort, "no run is
    being timed", for the rest of the run); the consumer's sim_config takes
    over when it comes; a pause and then an abort in the middle of the run
    are honoured: the run ends aborted at the abort's steps, short of the
    total."""
    cell = Cell(ros)
    bags = tmp_path / "bags"
    long_job = {**JOB, "turns_per_layer": 24}  # 12288 steps, about 6.4 s
    procs.env["SLOW_START_S"] = "12"
    slow = TEST / "consumers" / "slow_start.py"
    sim = procs.launch(
        [sys.executable, str(slow), "--ros-args", "-p", f"bag_dir:={bags}", "-p", "real_time:=true"],
        "slow_start",
    )
    profile = procs.start("profile_node")
    procs.start("interp_node", *[a for k, v in long_job.items() for a in ("-p", f"{k}:={v}")])
    wait.log_has(lambda: procs.log(profile), "10 s at most", 60, running=profile)  # waiting for it
    cell.until(lambda: "running" in cell.states and cell.clock_ns >= 1_000_000_000, "1 s of the run's clock")
    assert "pausing" in cell.call("/profile_node/pause")
    cell.until(lambda: cell.states[-1:] == ["paused"], "the axes to rest")
    assert "resuming" in cell.call("/profile_node/resume")
    cell.until(lambda: cell.states[-1:] == ["running"], "the resume's running state")
    rested = cell.clock_ns
    cell.until(lambda: cell.clock_ns >= rested + 500_000_000, "0.5 s more of the run")
    assert "aborting" in cell.call("/profile_node/abort")
    bag = cell.finished(bags)
    run = read_run(bag)
    events = control_events(rosbags_read(bag))
    assert [e["event"] for e in events] == ["pause", "resume", "abort"], events
    abort = events[-1]
    assert run.report["state"] == "aborted", run.report
    assert int(run.report["steps_done"]) == abort["steps"] < 12288, (run.report, abort)
    assert "Traceback" not in procs.log(sim)
    said = procs.log(profile)
    assert "paced on the wall clock" in said and "its own clock paces them from now on" in said, said
