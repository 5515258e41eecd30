"""A stall of the producers on a busy machine: the step stream stands still
for longer than ``stall_timeout`` because a producer gets no CPU (here:
``SIGSTOP`` until the consumer has said so, then ``SIGCONT``).

As fast as possible nothing waits on the steps: a run that then completes
with every step is a warning in the summary, not a failed run (under load
``winder run jobs/stator_12.yaml`` exited 1 on such a stall with missing 0).
In real time the axes ran out of steps: that stays an ERROR."""

from __future__ import annotations

import os
import signal
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from conftest import Procs, final_report, is_consumer, rosbags_read
from support import wait
from support.cell import only_bag
from support.ros_probe import heard_diagnostics

from winder.cli.summary import report_run

pytestmark = pytest.mark.ros

#: a job of some 490 000 steps: seconds as fast as possible, long enough to be caught running
JOB_PARAMS = ["turns_per_layer:=120", "layers:=2", "poles:=2", "job_id:=stall"]


def heard_levels(ros: Any) -> list[tuple[int, str]]:
    """Every status the probe hears on /diagnostics from now on: (level, message)."""
    from diagnostic_msgs.msg import DiagnosticArray

    levels: list[tuple[int, str]] = []
    ros.create_subscription(
        DiagnosticArray,
        "/diagnostics",
        lambda m: levels.extend((s.level[0], s.message) for s in m.status),
        100,
    )
    return levels


def final_of(seen: list[tuple[str, str, dict[str, str]]]) -> dict[str, str] | None:
    """The consumer's last final report heard (done or incomplete), None before one."""
    done = [v for n, _, v in seen if is_consumer(n, v) and v.get("state") in ("done", "incomplete")]
    return done[-1] if done else None


def stalls(seen: list[tuple[str, str, dict[str, str]]]) -> list[tuple[str, str]]:
    return [(n, m) for n, m, _ in seen if "step stream stalled" in m]


def test_a_transient_stall_as_fast_as_possible_is_a_warning(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """The interp node held (``SIGSTOP``) with a small in-flight window: the
    stream runs dry within milliseconds, whatever the machine's load, until
    the consumer has reported the stall; then it goes on to the end."""
    from diagnostic_msgs.msg import DiagnosticStatus

    levels = heard_levels(ros)
    seen = heard_diagnostics(ros)
    bags = tmp_path / "bags"
    procs.start("sim_node", "-p", f"bag_dir:={bags}", "-p", "stall_timeout:=0.5")
    procs.start("profile_node")
    # 4096 steps in flight at most: the sim node has taken all it was sent within ms of the hold
    interp = procs.start(
        "interp_node", *[a for k in JOB_PARAMS for a in ("-p", k)], "-p", "max_in_flight:=4096"
    )
    wait.spin_until(
        ros,
        lambda: any(v.get("state") == "running" for n, _, v in seen if is_consumer(n, v)),
        60,
        "running from the consumer",
        heard=lambda: [m for _, m, _ in seen][-10:],
    )
    os.kill(interp.pid, signal.SIGSTOP)
    try:
        wait.spin_until(ros, lambda: stalls(seen), 30, "a stall report", heard=lambda: seen[-5:])
    finally:
        os.kill(interp.pid, signal.SIGCONT)

    wait.spin_until(ros, lambda: final_of(seen), 180, "the consumer's final report", heard=lambda: seen[-5:])
    report = final_of(seen)
    assert report is not None
    assert report["state"] == "done" and report["steps_missing"] == "0", report
    assert int(report["stalls"]) >= 1 and float(report["longest_stall_s"]) >= 0.5, report
    # the stall was said as a warning while it lasted, never as an error
    said = [(lvl, m) for lvl, m in levels if "step stream stalled" in m or m.endswith(": stalled")]
    assert said, levels[-10:]
    assert all(lvl == DiagnosticStatus.WARN[0] for lvl, _ in said), said
    assert not [m for lvl, m in levels if lvl == DiagnosticStatus.ERROR[0]], levels
    # and the bag's final report says the same
    recorded = final_report(rosbags_read(only_bag(tmp_path)))
    assert recorded["state"] == "done" and recorded["stalls"] == report["stalls"], recorded


def test_the_run_summary_warns_of_stalls(capsys: pytest.CaptureFixture[str]) -> None:
    """What ``winder run`` prints of a done run's stalls, and that it exits 0."""
    done = {"state": "done", "run_id": "r", "steps_done": "10", "steps_total": "10", "bag": ""}
    run = SimpleNamespace(
        summary={**done, "stalls": "2", "longest_stall_s": "3.4"}, errors=[], ok=True, message="", log_dir=""
    )
    assert report_run(run, 1.0, stops=False) == 0
    out = capsys.readouterr().out
    assert "  WARNING stalls     2, the step stream stood still up to 3.4 s, nothing lost\n" in out, out
    run.summary = done
    assert report_run(run, 1.0, stops=False) == 0
    assert "stalls" not in capsys.readouterr().out


def test_a_stall_in_real_time_is_an_error(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """The axes run out of steps: an ERROR while it lasts, whatever comes after."""
    from diagnostic_msgs.msg import DiagnosticStatus

    levels = heard_levels(ros)
    bags = tmp_path / "bags"
    procs.start(
        "sim_node",
        "-p", f"bag_dir:={bags}", "-p", "real_time:=true", "-p", "real_time_factor:=8.0",
        "-p", "stall_timeout:=0.5",
    )  # fmt: skip
    profile = procs.start("profile_node")
    procs.start("interp_node", "-p", "turns_per_layer:=20", "-p", "layers:=1", "-p", "poles:=1")
    wait.spin_until(
        ros, lambda: any(m.endswith(": running") for _, m in levels), 60, "the run running",
        heard=lambda: levels[-5:],
    )  # fmt: skip
    os.kill(profile.pid, signal.SIGSTOP)
    try:
        wait.spin_until(
            ros, lambda: [m for _, m in levels if "step stream stalled" in m], 60, "a stall report",
            heard=lambda: levels[-5:],
        )  # fmt: skip
    finally:
        os.kill(profile.pid, signal.SIGCONT)
    said = [lvl for lvl, m in levels if "step stream stalled" in m]
    assert said and all(lvl == DiagnosticStatus.ERROR[0] for lvl in said), levels[-10:]
    assert "as fast as possible" not in next(m for _, m in levels if "step stream stalled" in m)


def test_the_smallest_driver_runs_without_a_wait_or_a_stall(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """The driver docs/ARCHITECTURE.md promises (test/consumers/minimal_driver.py:
    ``execute`` only, ``begin`` not overridden) still says on winder/sim_config
    that it does not pace: the profile node does not wait for its word (it
    waited 10 s a run, and the driver's stall watch reported a stall)."""
    import sys

    from support.paths import TEST

    seen = heard_diagnostics(ros)
    driver = TEST / "consumers" / "minimal_driver.py"
    procs.launch(
        [sys.executable, str(driver), "--ros-args", "-p", f"bag_dir:={tmp_path / 'bags'}", "-p",
         "stall_timeout:=1.0"],
        "minimal_driver",
    )  # fmt: skip
    profile = procs.start("profile_node")
    procs.start("interp_node", "-p", "turns_per_layer:=4", "-p", "layers:=1", "-p", "poles:=1")

    wait.spin_until(ros, lambda: final_of(seen), 60, "the driver's final report", heard=lambda: seen[-5:])
    report = final_of(seen)
    assert report is not None and report["state"] == "done", report
    assert report["stalls"] == "0", report
    assert not stalls(seen), stalls(seen)
    log = procs.log(profile)
    assert "wait for" not in log and "without look-ahead" not in log, log


def test_no_steps_yet_in_real_time_is_a_warning(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """A real-time run whose first steps are late (a profile node planning a
    long job on a loaded machine took 3 s): the stall is said as a warning,
    the axes waiting at rest with the run's time not started; when the steps
    come the run completes with no ERROR. (Before: an ERROR, and an aborted
    run exited 1, "failed", instead of 3.)"""

    from diagnostic_msgs.msg import DiagnosticStatus
    from support.cell import FakeProfile

    from winder.motion.job import Job
    from winder.ros.chunks import pack_timed

    levels = heard_levels(ros)
    seen = heard_diagnostics(ros)
    bags = tmp_path / "bags"
    procs.start("sim_node", "-p", f"bag_dir:={bags}", "-p", "stall_timeout:=0.5", "-p", "real_time:=true")
    fake = FakeProfile(ros, Job(job_id="late", turns_per_layer=2, layers=1, poles=1, fork_steps_per_rev=256))
    wait.spin_until(ros, lambda: fake.pub.get_subscription_count() > 0, 30, "the sim node's step reader")
    wait.spin_until(ros, lambda: any(is_consumer(n, v) for n, _, v in seen), 30, "the sim node's status")
    fake.publish_job()
    wait.spin_until(ros, lambda: stalls(seen), 30, "a stall report", heard=lambda: seen[-5:])
    for chunk in fake.chunks(128):
        fake.pub.publish(pack_timed(chunk))

    wait.spin_until(ros, lambda: final_of(seen), 60, "the consumer's final report", heard=lambda: seen[-5:])
    report = final_of(seen)
    assert report is not None and report["state"] == "done", report
    said = [(lvl, m) for lvl, m in levels if "step stream stalled" in m]
    assert said and all(lvl == DiagnosticStatus.WARN[0] for lvl, _ in said), said
    assert "none yet: the axes wait at rest" in said[0][1], said
    assert not [m for lvl, m in levels if lvl == DiagnosticStatus.ERROR[0]], levels
