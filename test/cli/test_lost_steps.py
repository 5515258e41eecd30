"""A run whose simulated axes did not do what was commanded is no success
(issue 53, item 11): ``jobs/armature_fine.yaml`` ended ``done``, exit 0, with
2,624 full steps lost and its wire 8 mm off its path, and no WARNING.

Such a run stays ``done`` (every step was executed), but its final report
carries ``faults``, ``winder run`` prints ``WARNING faults`` and exits 6, and
the ``Wind`` result's ``success`` is false. Lost steps are counted in the
motor's full steps, every other step count in commanded steps, each line
saying which.

Oracles: the motor model's own geometry (a slip is one tooth pitch, 2*m = 4
full steps of the default two-phase motor; a full step 2*pi/(4*Z_r) over the
default 1/32 microstep ``motor_step_angle`` is 32 commanded steps), the
physics of the set-up (a motor whose viscous torque D*w at the ramp's top
speed exceeds its peak torque T_m cannot keep up, so it slips; a fork whose
lag D/K is longer than a turn leaves the feed's lay by millimetres), and the
bag the run wrote, read with rosbags.
"""

from __future__ import annotations

import math
import os
import re
import subprocess
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from conftest import BIN, Procs, closed_bags, final_report, rosbags_read
from ruamel.yaml import YAML
from support import wait
from support.domains import next_domain, release_domain
from support.paths import ROOT
from support.ros_probe import ready_states

from winder.cli.exits import EXIT_ABORTED, EXIT_FAILED, EXIT_FAULTED, EXIT_OK
from winder.cli.summary import report_run
from winder.contract.params import MOTOR_FIELDS, PROFILE_SPECS
from winder.motion.job import FIELD_SPECS

#: a short job (the default RW400 set-up, one layer of four turns: 4096 fork steps)
TINY = ["--turns-per-layer", "4", "--layers", "1", "--poles", "1"]
#: the fork's damping that puts its pull-out speed T_m/D below the default ramp's top speed
WEAK_D = 0.1
JOBS = sorted((ROOT / "jobs").glob("*.yaml"))


@pytest.fixture
def env() -> Iterator[dict[str, str]]:
    domain = next_domain()
    yield {**os.environ, "ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    release_domain(domain)


def run(env: dict[str, str], bags: Path, *args: str) -> subprocess.CompletedProcess[str]:
    r = subprocess.run(
        [str(BIN / "winder"), "run", *args, "--bag-dir", str(bags)],
        capture_output=True,
        text=True,
        timeout=240,
        env=env,
        stdin=subprocess.DEVNULL,
    )
    assert "Traceback" not in r.stderr, r.stderr
    return r


def default_motor() -> tuple[float, float, float]:
    """The default motor's peak torque T_m = Z_r*L*i_a^2/2 (N m), its full step
    2*pi/(2*m*Z_r) for m = 2 phases (rad), and its commanded step (rad)."""
    zr, inductance, current = (MOTOR_FIELDS[k].default for k in ("Zr", "L", "i_a"))
    return zr * inductance * current**2 / 2, 2 * math.pi / (4 * zr), MOTOR_FIELDS["motor_step_angle"].default


def test_the_weak_motor_cannot_hold_the_ramps_top_speed() -> None:
    """The premise of the next test, from the physics alone: at the default
    ramp's v_max the weak fork's viscous torque exceeds its peak torque."""
    peak, _, step = default_motor()
    omega = PROFILE_SPECS["v_max"].default * step  # rad/s of the motor at the ramp's top speed
    assert WEAK_D * omega > peak


def ended(state: str, **extra: str) -> SimpleNamespace:
    """What ``winder run`` hands its summary: a run's final report with ``extra``."""
    values = {"state": state, "run_id": "r", "steps_done": "10", "steps_total": "10", "bag": "", **extra}
    ok = state == "done"
    return SimpleNamespace(summary=values, errors=[], ok=ok, message=f"job j: {state}", log_dir="")


@pytest.mark.parametrize(
    ("state", "extra", "status"),
    [
        ("done", {}, EXIT_OK),
        ("done", {"faults": "4 full steps lost (fork 4; 128 commanded steps)"}, EXIT_FAULTED),
        ("aborted", {}, EXIT_ABORTED),
        ("aborted", {"faults": "4 full steps lost (fork 4; 128 commanded steps)"}, EXIT_FAULTED),
        ("done", {"faults": "4 full steps lost", "errors": "1"}, EXIT_FAILED),
        ("incomplete", {"faults": "4 full steps lost"}, EXIT_FAILED),
    ],
)
def test_the_exit_status_of_a_run_with_faults(
    capsys: pytest.CaptureFixture[str], state: str, extra: dict[str, str], status: int
) -> None:
    """Faults outrank an abort (the axes rest, but not where commanded);
    errors and an incomplete run outrank faults; each non-zero status comes
    with one line on stderr, a fault with a WARNING line in the summary."""
    assert report_run(ended(state, lost_steps="4", **extra), 1.0, stops=False) == status
    out, err = capsys.readouterr()
    assert ("  WARNING faults     4 full steps lost" in out) == ("faults" in extra), out
    assert len(err.strip().splitlines()) == (status != EXIT_OK), err


def test_lost_steps_name_their_unit_in_a_report_without_the_commanded_count(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A report of an older sim node (no ``lost_commanded_steps``, no axis of the tracking error)."""
    report_run(ended("done", lost_steps="0", max_tracking_error_steps="8.1447"), 1.0, stops=False)
    out = capsys.readouterr().out
    assert "  lost steps         0 full steps\n" in out
    assert "  max tracking error 8.145 commanded steps\n" in out


@pytest.mark.ros
def test_a_run_whose_flyer_loses_steps_is_done_with_faults_and_exits_6(
    env: dict[str, str], tmp_path: Path
) -> None:
    r = run(env, tmp_path, *TINY, "--job-id", "weak", "--model", "nonlinear", "--fork.D", str(WEAK_D))
    out = r.stdout
    assert r.returncode == EXIT_FAULTED, out + r.stderr
    assert "  state              done" in out, out
    lost = re.search(r"^  lost steps +(\d+) full steps \((\d+) commanded steps\)$", out, re.M)
    assert lost, out
    full, commanded = int(lost[1]), int(lost[2])
    _, full_step, step = default_motor()
    assert full > 0 and full % 4 == 0, full  # whole slips, a tooth pitch (4 full steps) each
    assert commanded == round(full * full_step / step) == 32 * full
    assert re.search(r"^  max tracking error [\d.]+ commanded steps \(fork\)$", out, re.M), out
    [warning] = [line for line in out.splitlines() if line.startswith("  WARNING faults")]
    assert f"{full} full steps lost (fork {full}; {commanded} commanded steps)" in warning, warning
    # one line on stderr says why the status is not 0
    assert len(r.stderr.strip().splitlines()) == 1 and "full steps lost" in r.stderr, r.stderr
    # the bag: the final status and the typed report carry the faults, the state stays done
    [bag] = closed_bags(tmp_path)
    msgs = rosbags_read(bag)
    status = final_report(msgs)
    assert status["state"] == "done" and int(status["lost_steps"]) == full
    assert int(status["lost_commanded_steps"]) == commanded
    assert status["faults"].startswith(f"{full} full steps lost"), status
    [(_, report)] = msgs["/winder/report"]
    extra = {kv.key: kv.value for kv in report.extra}
    assert report.state == "done" and extra["faults"] == status["faults"]
    statuses = [st for _, arr in msgs["/diagnostics"] for st in arr.status]
    finals = [st for st in statuses if st.message.startswith("job weak: ")]
    assert finals and {int(st.level) for st in finals} == {1}, finals  # WARN


@pytest.mark.ros
def test_a_run_whose_axes_leave_the_wires_path_without_losing_a_step_is_faulted(
    env: dict[str, str], tmp_path: Path
) -> None:
    """The linear model loses no step, but a fork whose lag D/K (0.6 s) is
    longer than a quarter turn lays the wire where the feed has gone on:
    about 3 mm off the path of 2.5 mm wire, more than half its diameter."""
    r = run(env, tmp_path, *TINY, "--job-id", "lag", "--model", "linear", "--fork.D", "5")
    out = r.stdout
    assert r.returncode == EXIT_FAULTED, out + r.stderr
    assert re.search(r"^  lost steps +0 full steps \(0 commanded steps\)$", out, re.M), out
    half = FIELD_SPECS["wire_diameter"].default / 2
    warning = next(line for line in out.splitlines() if line.startswith("  WARNING faults"))
    assert f"over the {half * 1e6:.1f} um allowed" in warning and "full steps lost" not in warning, warning
    status = final_report(rosbags_read(closed_bags(tmp_path)[0]))
    assert float(status["path_tolerance_m"]) == pytest.approx(half)
    assert float(status["max_deviation_actual_m"]) > half and status["state"] == "done"


def _first_layer(path: Path) -> list[str]:
    """One coil's first layer of a shipped job (a job whose coil_overrides name
    later coils without them: they would name coils the job no longer has)."""
    interp = YAML(typ="safe").load(path.read_text())["interp_node"]["ros__parameters"]
    overrides = ["--coil-overrides", ""] if "coil_overrides" in interp else []
    return ["--poles", "1", "--layers", "1", *overrides]


@pytest.mark.ros
@pytest.mark.parametrize("path", JOBS, ids=[p.stem for p in JOBS])
def test_each_shipped_job_winds_its_first_layer_without_lost_steps(
    env: dict[str, str], tmp_path: Path, path: Path
) -> None:
    r = run(env, tmp_path, str(path), *_first_layer(path))
    assert r.returncode == EXIT_OK, r.stdout + r.stderr
    assert re.search(r"^  lost steps +0 full steps \(0 commanded steps\)$", r.stdout, re.M), r.stdout
    assert "WARNING faults" not in r.stdout, r.stdout
    status = final_report(rosbags_read(closed_bags(tmp_path)[0]))
    assert status["state"] == "done" and "faults" not in status, status
    assert float(status["max_deviation_actual_m"]) <= float(status["path_tolerance_m"])


@pytest.mark.ros
def test_a_wind_goal_whose_flyer_loses_steps_is_no_success(procs: Procs, tmp_path: Path, ros: Any) -> None:
    """The line controller's view: the goal's run is done, its report names
    the faults, and the result's success is false (the goal ends ABORTED)."""
    from action_msgs.msg import GoalStatus
    from rclpy.action import ActionClient

    from winder_interfaces.action import Wind

    client = ActionClient(ros, Wind, "/winder/wind")
    try:
        states = ready_states(ros)
        procs.start("interp_node", "-p", "autostart:=false")
        procs.start("profile_node")
        procs.start(
            "sim_node", "-p", f"bag_dir:={tmp_path}", "-p", "model:=nonlinear", "-p", f"fork.D:={WEAK_D}"
        )
        wait.spin_until(
            ros,
            lambda: states.get("consumer") == "ready" and states.get("profile") == "ready",
            60,
            "consumer and profile node ready on winder/ready",
            heard=lambda: states,
        )
        wait.spin_until(ros, client.server_is_ready, 60, "the interp node's winder/wind action server")
        job = "interp_node:\n  ros__parameters:\n    job_id: weakgoal\n    turns_per_layer: 4\n"
        job += "    layers: 1\n    poles: 1\n"
        sent = client.send_goal_async(Wind.Goal(job=job))
        handle = wait.spin_until(ros, lambda: sent.done() and sent.result(), 30, "the goal's acceptance")
        assert handle.accepted
        result = handle.get_result_async()
        wait.spin_until(ros, result.done, 120, "the goal's result")
        answer = result.result()
    finally:
        client.destroy()
    report = answer.result.report
    extra = {kv.key: kv.value for kv in report.extra}
    assert report.state == "done" and int(extra["lost_steps"]) > 0, extra
    assert "full steps lost" in extra["faults"] and "full steps lost" in answer.result.message
    assert answer.result.success is False and answer.status == GoalStatus.STATUS_ABORTED


@pytest.mark.ros
def test_ctl_start_wait_of_a_run_with_faults_exits_6(procs: Procs, tmp_path: Path) -> None:
    """`winder ctl start --wait` ends a run that is done with faults as
    `winder run` does: the run's end printed, one line naming the faults on
    stderr, exit 6 (it exited 0, as for a clean run)."""
    procs.start("interp_node", "-p", "autostart:=false")
    procs.start("profile_node")
    procs.start("sim_node", "-p", f"bag_dir:={tmp_path}", "-p", "model:=nonlinear", "-p", f"fork.D:={WEAK_D}")
    argv = ["ctl", "start", "--set", "turns_per_layer=4", "--set", "layers=1", "--set", "poles=1"]
    r = subprocess.run(
        [str(BIN / "winder"), *argv, "--wait", "--timeout", "60"],
        env=procs.env,
        capture_output=True,
        text=True,
        timeout=240,
        stdin=subprocess.DEVNULL,
    )
    assert r.returncode == EXIT_FAULTED, r.stdout + r.stderr
    assert re.search(r"^run \S+: done, bag ", r.stdout, re.M), r.stdout
    [line] = r.stderr.strip().splitlines()
    assert "ended done with faults" in line and "full steps lost" in line, r.stderr
    status = final_report(rosbags_read(closed_bags(tmp_path)[0]))
    assert status["state"] == "done" and "full steps lost" in status["faults"], status
