"""`winder ctl` against real cells: the node processes over DDS, the command
run as a user runs it (a subprocess, its exit status, its one-line errors).

Oracles: the nodes' own parameter and lifecycle services, read here with
rclpy (not through `winder ctl`), the bag the run recorded, and the exit-code
table (winder.cli.exits).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from conftest import Procs, closed_bags, spin_until
from support.paths import ROOT

from winder.cli.exits import EXIT_ABORTED, EXIT_BAD_INPUT, EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK
from winder.procs import popen
from winder.record.reader import read_run

pytestmark = pytest.mark.ros

WINDER = Path(sys.executable).with_name("winder")
TINY = """\
interp_node:
  ros__parameters:
    job_id: tiny
    turns_per_layer: 4
    layers: 1
    poles: 1
    fork_steps_per_rev: 512
"""


def ctl(procs: Procs, *words: str, cwd: Path | None = None, timeout: float = 120) -> tuple[int, str, str]:
    out = subprocess.run(
        [str(WINDER), "ctl", *words],
        env=procs.env,
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=cwd,
    )
    return out.returncode, out.stdout, out.stderr


def one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def start_cell(procs: Procs, bags: Path, *interp: str) -> None:
    procs.start("sim_node", "-p", f"bag_dir:={bags}")
    procs.start("profile_node")
    procs.start("interp_node", "-p", "autostart:=false", *interp)


def get_params(ros: Any, node: str, names: list[str]) -> list[Any]:
    """Parameter values read with rclpy, not through winder ctl."""
    from rcl_interfaces.srv import GetParameters
    from rclpy.parameter import parameter_value_to_python

    client = ros.create_client(GetParameters, f"/{node}/get_parameters")
    spin_until(ros, client.service_is_ready, 30, f"/{node}/get_parameters")
    fut = client.call_async(GetParameters.Request(names=names))
    spin_until(ros, fut.done, 10, "the parameters")
    return [parameter_value_to_python(v) for v in fut.result().values]


def lifecycle_label(ros: Any, node: str) -> str:
    from lifecycle_msgs.srv import GetState

    client = ros.create_client(GetState, f"/{node}/get_state")
    spin_until(ros, client.service_is_ready, 30, f"/{node}/get_state")
    fut = client.call_async(GetState.Request())
    spin_until(ros, fut.done, 10, "the lifecycle state")
    return str(fut.result().current_state.label)


def test_without_a_cell_every_command_ends_in_time_naming_what_it_waited_for(
    procs: Procs, tmp_path: Path
) -> None:
    """No node on the domain: each command gives up after --timeout, one
    line, exit 1; input that is wrong whatever the cell is exits 2 at once."""
    t0 = time.monotonic()
    code, _, err = ctl(procs, "state", "--timeout", "2")
    assert code == EXIT_FAILED and "winder/state" in one_line(err), err
    code, _, err = ctl(procs, "param", "get", "interp_node", "layers", "--timeout", "2")
    assert code == EXIT_FAILED and "/interp_node" in one_line(err), err
    code, _, err = ctl(procs, "start", "--timeout", "2")
    assert code == EXIT_FAILED and "interp node" in one_line(err), err
    assert time.monotonic() - t0 < 60
    # a missing job file: its absolute path, from this command's working directory
    code, _, err = ctl(procs, "start", "jobs/none.yaml", cwd=tmp_path)
    assert code == EXIT_BAD_INPUT and str(tmp_path / "jobs" / "none.yaml") in one_line(err), err
    code, _, err = ctl(procs, "start", "--set", "turns_per_layer=0")
    line = one_line(err)
    assert code == EXIT_BAD_INPUT and "turns_per_layer=0" in line and "[1, 100000]" in line, err
    code, _, err = ctl(procs, "start", "--set", "no_such_thing=1")
    assert code == EXIT_BAD_INPUT and "no_such_thing" in one_line(err), err
    code, _, err = ctl(procs, "lifecycle", "interp_node", "explode")
    assert code == EXIT_BAD_INPUT and "explode" in one_line(err), err


def test_start_a_run_from_a_relative_job_file_and_follow_it(procs: Procs, ros: Any, tmp_path: Path) -> None:
    """`winder ctl start JOB --set ... --wait` on a running cell: the job file
    named relative to the caller, a value over it, the run id printed, the
    end state followed; the bag holds that run with those values."""
    bags = tmp_path / "bags"
    start_cell(procs, bags)
    work = tmp_path / "work"
    (work / "jobs").mkdir(parents=True)
    (work / "jobs" / "tiny.yaml").write_text(TINY)
    code, out, err = ctl(
        procs, "start", "jobs/tiny.yaml", "--set", "layers=2", "--wait", "--timeout", "60", cwd=work
    )
    assert code == EXIT_OK, out + err
    run_id = out.splitlines()[0].removeprefix("run ")
    assert run_id.startswith("tiny_"), out
    assert out.strip().splitlines()[-1].startswith(f"run {run_id}: done, bag "), out
    [bag] = closed_bags(bags)
    run = read_run(bag)
    assert run.plan.run_id == run_id and run.report["state"] == "done"
    assert run.plan.job.turns_per_layer == 4 and run.plan.job.layers == 2  # the file's, and --set over it
    assert get_params(ros, "interp_node", ["job_file"]) == [str(work / "jobs" / "tiny.yaml")]
    # the cell is idle again: state says so, with every node's status
    code, out, err = ctl(procs, "state")
    assert code == EXIT_OK, err
    lines = out.splitlines()
    assert lines[0].startswith("cell /  done  run " + run_id), out
    assert "consumer ready" in lines[1] and "profile ready" in lines[1], out
    for node, role in (("interp_node", "interp"), ("profile_node", "profile"), ("sim_node", "consumer")):
        assert any(ln.split()[:2] == [node, role] and run_id in ln for ln in lines[2:]), out
    # a value the node refuses: its reason, one line, exit 2, nothing started
    code, out, err = ctl(procs, "start", "--set", "coil_length=0.001")
    assert code == EXIT_BAD_INPUT and "the window is 1.0 mm wide" in one_line(err), out + err
    assert len(closed_bags(bags)) == 1


def test_param_get_set_list_and_their_refusals(procs: Procs, ros: Any, tmp_path: Path) -> None:
    start_cell(procs, tmp_path / "bags", "-p", "turns_per_layer:=12")
    code, out, err = ctl(procs, "param", "get", "interp_node", "turns_per_layer")
    assert (code, out) == (EXIT_OK, "12\n"), err
    code, out, err = ctl(procs, "param", "list", "profile_node")
    assert code == EXIT_OK, err
    rows = dict(line.split(None, 1) for line in out.splitlines())
    assert rows["profile"] == "scurve" and "v_max" in rows and "feed_override" in rows
    # an integer typed for a double: the declared type
    code, out, err = ctl(procs, "param", "set", "profile_node", "v_max", "3000")
    assert (code, out) == (EXIT_OK, "/profile_node: v_max = 3000.0\n"), err
    assert get_params(ros, "profile_node", ["v_max"]) == [3000.0]
    # refused by the node: its reason in one line, exit 2, the value unchanged
    code, _, err = ctl(procs, "param", "set", "profile_node", "v_max", "-5")
    assert code == EXIT_BAD_INPUT and "v_max" in one_line(err) and "-5" in err, err
    code, _, err = ctl(procs, "param", "set", "profile_node", "v_max", "fast")
    assert code == EXIT_BAD_INPUT and "v_max" in one_line(err) and "fast" in err, err
    code, _, err = ctl(procs, "param", "set", "interp_node", "managed", "true")  # read-only
    assert code == EXIT_BAD_INPUT and "managed" in one_line(err), err
    assert get_params(ros, "profile_node", ["v_max"]) == [3000.0]
    # an unknown parameter, an unknown node
    code, _, err = ctl(procs, "param", "get", "interp_node", "no_such_param")
    assert code == EXIT_BAD_INPUT and "no parameter 'no_such_param'" in one_line(err), err
    code, _, err = ctl(procs, "param", "set", "interp_node", "no_such_param", "1")
    assert code == EXIT_BAD_INPUT and "no_such_param" in one_line(err), err
    code, _, err = ctl(procs, "param", "get", "no_such_node", "x")
    line = one_line(err)
    assert code == EXIT_BAD_INPUT and "no node /no_such_node" in line and "/interp_node" in line, err
    # a relative job_file: from the caller's working directory, and the path tried when missing
    code, _, err = ctl(procs, "param", "set", "interp_node", "job_file", "gone.yaml", cwd=tmp_path)
    assert code == EXIT_BAD_INPUT and f"{tmp_path / 'gone.yaml'}: no such job file" in one_line(err), err


def test_the_node_reads_a_relative_job_file_from_its_directory_and_names_the_path_tried(
    procs: Procs, ros: Any
) -> None:
    """What `ros2 param set /interp_node job_file x.yaml` sends (a relative
    path, set through the standard service): refused with the absolute path
    the node tried (its working directory: this test's)."""
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter

    procs.start("interp_node", "-p", "autostart:=false")
    client = ros.create_client(SetParameters, "/interp_node/set_parameters")
    spin_until(ros, client.service_is_ready, 30, "/interp_node/set_parameters")
    request = SetParameters.Request(
        parameters=[Parameter("job_file", value="jobs/none.yaml").to_parameter_msg()]
    )
    fut = client.call_async(request)
    spin_until(ros, fut.done, 10, "the reply")
    [result] = fut.result().results
    assert not result.successful and str(Path.cwd() / "jobs" / "none.yaml") in result.reason, result.reason
    request = SetParameters.Request(
        parameters=[Parameter("job_file", value="jobs/rw400.yaml").to_parameter_msg()]
    )
    here = ROOT
    if Path.cwd().resolve() == here:  # the repository's job file, read from the node's directory
        fut = client.call_async(request)
        spin_until(ros, fut.done, 10, "the reply")
        assert fut.result().results[0].successful, fut.result().results[0].reason
        assert get_params(ros, "interp_node", ["job_file"]) == [str(Path.cwd() / "jobs" / "rw400.yaml")]


def test_lifecycle_transitions_and_an_invalid_one(procs: Procs, ros: Any, tmp_path: Path) -> None:
    start_cell(procs, tmp_path / "bags")
    code, out, err = ctl(procs, "lifecycle", "profile_node", "get")
    assert (code, out) == (EXIT_OK, "/profile_node: active\n"), err
    code, _, err = ctl(procs, "lifecycle", "profile_node", "activate")  # active already: no such transition
    line = one_line(err)
    assert code == EXIT_BAD_INPUT and "cannot activate" in line and "'active'" in line, err
    code, out, err = ctl(procs, "lifecycle", "profile_node", "deactivate")
    assert (code, out) == (EXIT_OK, "/profile_node: deactivate: active -> inactive\n"), err
    assert lifecycle_label(ros, "profile_node") == "inactive"
    code, _, err = ctl(procs, "start", "--timeout", "3")  # an inactive profile node: the cell says no
    assert code == EXIT_FAILED and "not ready" in one_line(err), err
    code, out, err = ctl(procs, "lifecycle", "profile_node", "activate")
    assert (code, out) == (EXIT_OK, "/profile_node: activate: inactive -> active\n"), err
    code, _, err = ctl(procs, "lifecycle", "nobody", "get")
    assert code == EXIT_BAD_INPUT and "no node /nobody" in one_line(err), err
    assert all(p.poll() is None for p, _ in procs.procs)  # the invalid transition hurt no node


def test_state_watch_prints_each_change_until_ctrl_c(procs: Procs, tmp_path: Path) -> None:
    bags = tmp_path / "bags"
    start_cell(procs, bags, "-p", "turns_per_layer:=4", "-p", "layers:=1", "-p", "poles:=1")
    watch = popen(
        [str(WINDER), "ctl", "state", "--watch", "--timeout", "60"],
        env=procs.env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert watch.stdout is not None
        first = watch.stdout.readline()
        assert first.startswith("cell /  "), first
        code, out, err = ctl(procs, "start", "--timeout", "60")
        assert code == EXIT_OK, out + err
        run_id = out.split()[1]
        end = time.monotonic() + 120
        seen: list[str] = []
        while not any(" done " in s + " " and run_id in s for s in seen):
            assert time.monotonic() < end and watch.poll() is None, seen
            seen.append(watch.stdout.readline())
        assert any(" running " in s for s in seen), seen
        os.kill(watch.pid, signal.SIGINT)
        _, err = watch.communicate(timeout=30)
        assert watch.returncode == EXIT_INTERRUPTED and "Traceback" not in err, err
    finally:
        if watch.poll() is None:
            watch.kill()
            watch.wait()


def test_a_followed_run_that_is_aborted_ends_with_exit_3_and_a_busy_cell_refuses_a_start(
    procs: Procs, tmp_path: Path
) -> None:
    """A real-time run followed with --wait: a second start while it runs is
    the cell's refusal (exit 1, the interp node's reply); `winder ctl abort`
    ends it, and the follower says so and exits 3 (the exit-code table's
    "run aborted")."""
    bags = tmp_path / "bags"
    procs.start("sim_node", "-p", f"bag_dir:={bags}", "-p", "real_time:=true")
    procs.start("profile_node")
    procs.start("interp_node", "-p", "autostart:=false")
    argv = ["start", "--set", "turns_per_layer=40", "--set", "poles=1", "--wait", "--timeout", "60"]
    follow = popen(
        [str(WINDER), "ctl", *argv],
        env=procs.env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert follow.stdout is not None
        run_id = follow.stdout.readline().split()[1]
        code, _, err = ctl(procs, "start")
        line = one_line(err)
        assert code == EXIT_FAILED and f"run {run_id} is running" in line, err
        code, out, err = ctl(procs, "abort")
        assert code == EXIT_OK and "aborting" in out, out + err
        out, err = follow.communicate(timeout=60)
        assert follow.returncode == EXIT_ABORTED, out + err
        assert out.strip().splitlines()[-1].startswith(f"run {run_id}: aborted"), out
        assert f"run {run_id} ended aborted" in one_line(err), err
    finally:
        if follow.poll() is None:
            follow.kill()
            follow.wait()
