"""A stall of the producers on a busy machine: the step stream stands still
for longer than ``stall_timeout`` because the profile node gets no CPU (here:
``SIGSTOP`` until the consumer has said so, then ``SIGCONT``).

As fast as possible nothing waits on the steps: a run that then completes
with every step is a warning in the summary, not a failed run (under load
``winder run jobs/stator_12.yaml`` exited 1 on such a stall with missing 0).
In real time the axes ran out of steps: that stays an ERROR."""

from __future__ import annotations

import os
import signal
import subprocess
from pathlib import Path
from typing import Any

import pytest
from conftest import Procs, final_report, rosbags_read
from support import wait
from support.cell import only_bag
from support.paths import BIN
from support.ros_probe import heard_diagnostics

from winder.procs import popen

pytestmark = pytest.mark.ros

#: a job of some 290 000 steps: a few seconds as fast as possible, long enough to be caught running
JOB = ["--turns-per-layer", "120", "--layers", "2", "--poles", "2", "--job-id", "stall"]


def stalls(seen: list[tuple[str, str, dict[str, str]]]) -> list[tuple[str, str]]:
    return [(n, m) for n, m, _ in seen if "step stream stalled" in m]


def test_a_transient_stall_as_fast_as_possible_is_a_warning(tmp_path: Path, procs: Procs, ros: Any) -> None:
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

    levels: list[tuple[int, str]] = []
    ros.create_subscription(
        DiagnosticArray,
        "/diagnostics",
        lambda m: levels.extend((s.level[0], s.message) for s in m.status),
        100,
    )
    seen = heard_diagnostics(ros)
    env = {
        **os.environ,
        "ROS_DOMAIN_ID": str(procs.domain),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "TMPDIR": str(tmp_path),
    }
    run = popen(
        [str(BIN / "winder"), "run", "--bag-dir", str(tmp_path / "bags"), *JOB, "--stall-timeout", "0.5"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        stdin=subprocess.DEVNULL,
    )
    try:
        profile = wait.child(run.pid, "profile_node", 60)
        wait.spin_until(
            ros,
            lambda: any("running" in m for n, m, _ in seen if "sim_node" in n),
            60,
            "running from sim_node",
            heard=lambda: [m for _, m, _ in seen][-10:],
        )
        os.kill(profile, signal.SIGSTOP)
        try:
            wait.spin_until(ros, lambda: stalls(seen), 30, "a stall report", heard=lambda: seen[-5:])
        finally:
            os.kill(profile, signal.SIGCONT)
        out, err = run.communicate(timeout=180)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
    assert run.returncode == 0, (out, err)
    # one stall at least: the one made here (on a loaded machine the producers may stall more)
    line = next((ln for ln in out.splitlines() if ln.startswith("  WARNING stalls")), out)
    assert "the step stream stood still up to" in line and line.endswith(", nothing lost"), line
    assert "ERROR reports" not in out, out
    # the stall was said as a warning while it lasted, never as an error
    said = [(lvl, m) for lvl, m in levels if "stalled" in m or m.endswith(": stalled")]
    assert said, levels[-10:]
    assert all(lvl == DiagnosticStatus.WARN[0] for lvl, _ in said), said
    report = final_report(rosbags_read(only_bag(tmp_path)))
    assert report["state"] == "done" and report["steps_missing"] == "0", report
    assert int(report["stalls"]) >= 1 and float(report["longest_stall_s"]) >= 0.5, report


def test_a_stall_in_real_time_is_an_error(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """The axes run out of steps: an ERROR while it lasts, whatever comes after."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

    levels: list[tuple[int, str]] = []
    ros.create_subscription(
        DiagnosticArray,
        "/diagnostics",
        lambda m: levels.extend((s.level[0], s.message) for s in m.status),
        100,
    )
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
