"""`winder ctl` against real cells: the node processes over DDS, the command
run as a user runs it (a subprocess, its exit status, its one-line errors).

Oracles: the nodes' own parameter and lifecycle services, read here with
rclpy (not through `winder ctl`), the bag the run recorded, and the exit-code
table (winder.cli.exits).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest
from conftest import Procs, closed_bags, spin_until
from support import wait
from support.paths import ROOT
from support.ros_probe import heard_diagnostics

from winder.cli.exits import EXIT_ABORTED, EXIT_BAD_INPUT, EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK
from winder.procs import kill_telling_where, popen, signal_state
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
    before = get_params(ros, "interp_node", ["job_file"])
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
    # what the goal set was its run's: the node's settings are again what they were (issue 53, item 5)
    assert get_params(ros, "interp_node", ["job_file"]) == before
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
    # after the refused text the setting takes a number again (rclpy kept the text's type in the
    # descriptor, which ctl types a value by: "v_max='2500' is invalid: must be a number")
    code, out, err = ctl(procs, "param", "set", "profile_node", "v_max", "2500")
    assert (code, out) == (EXIT_OK, "/profile_node: v_max = 2500.0\n"), err
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


def state_watch(procs: Procs) -> subprocess.Popen[str]:
    """``winder ctl state --watch`` on the test's domain, its output piped."""
    return popen(
        [str(WINDER), "ctl", "state", "--watch", "--timeout", "60"],
        env=procs.env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def test_state_watch_prints_each_change_until_ctrl_c(procs: Procs, tmp_path: Path) -> None:
    bags = tmp_path / "bags"
    start_cell(procs, bags, "-p", "turns_per_layer:=4", "-p", "layers:=1", "-p", "poles:=1")
    watch = state_watch(procs)
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
        state = signal_state(watch.pid)  # what it blocks and ignores, should it not stop
        os.kill(watch.pid, signal.SIGINT)
        try:
            _, err = watch.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            kill_telling_where(watch)  # its stderr: where it hung
            _, err = watch.communicate()
            raise AssertionError(
                f"winder ctl state --watch did not stop on SIGINT within 30 s ({state}):\n{err}"
            ) from None
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


# -- a real-time cell mid-job: how old what state shows is, a killed node, the cell under load ----------

#: a long real-time job: 2000 turns of 1024 steps at 2 rev/s, 1000 s; every test ends it long before
LONG = ["--set", "turns_per_layer=2000", "--set", "layers=1", "--set", "poles=1"]
#: the age ``winder ctl state`` gives a part: "(2.3 s ago)", "(4.1 s ago: silent)"
AGO = re.compile(r"\((?:[^()]*; it said \S+ )?(\d+\.\d) s ago(?:: silent)?(?:; [^()]*)?\)$")


def start_real_time_cell(procs: Procs, bags: Path) -> dict[str, subprocess.Popen[bytes]]:
    return {
        "sim_node": procs.start("sim_node", "-p", f"bag_dir:={bags}", "-p", "real_time:=true"),
        "profile_node": procs.start("profile_node"),
        "interp_node": procs.start("interp_node", "-p", "autostart:=false"),
    }


class Lines:
    """The lines a process writes to its stdout, read as they come (a thread)."""

    def __init__(self, p: subprocess.Popen[str]) -> None:
        assert p.stdout is not None
        self.lines: list[str] = []
        self._thread = threading.Thread(target=self._read, args=(p.stdout,), daemon=True)
        self._thread.start()

    def _read(self, stream: Any) -> None:
        for line in stream:
            self.lines.append(line.rstrip("\n"))

    def until(self, cond: Any, timeout: float, what: str, running: subprocess.Popen[str]) -> str:
        """The first line (from ``start``) for which ``cond(line)``, waited for."""
        return str(
            wait.until(
                lambda: next((ln for ln in list(self.lines) if cond(ln)), ""),
                timeout,
                what,
                heard=lambda: self.lines[-10:],
                running=running,
            )
        )


def until_state(procs: Procs, cond: Any, what: str, timeout: float = 90) -> tuple[str, float, float]:
    """``winder ctl state`` asked again until its output satisfies ``cond``;
    that output, and when (time.monotonic()) that query started and ended."""
    seen: list[str] = []

    def ask() -> tuple[str, float, float] | None:
        began = time.monotonic()
        code, out, err = ctl(procs, "state", "--timeout", "10")
        seen[:] = [f"exit {code}", *out.splitlines(), *err.splitlines()]
        return (out, began, time.monotonic()) if code == EXIT_OK and cond(out) else None

    found = wait.until(ask, timeout, what, heard=lambda: seen, poll=0.2)
    return found[0], found[1], found[2]


def node_rows(out: str) -> dict[str, list[str]]:
    """The node lines of a ``winder ctl state`` output, by node: their words."""
    return {
        ln.split()[0]: ln.split()
        for ln in out.splitlines()[2:]
        if ln.startswith("  ") and "_node" in ln.split()[0]
    }


def under_way(seen: list[tuple[str, str, dict[str, str]]], run_id: str) -> bool:
    """Whether the consumer said run ``run_id`` is running with steps executed."""
    from conftest import is_consumer

    return any(
        is_consumer(n, v)
        and v.get("run_id") == run_id
        and v.get("state") == "running"
        and v.get("steps_done", "0") != "0"
        for n, _, v in seen
    )


def test_state_says_how_old_each_part_is(procs: Procs, ros: Any, tmp_path: Path) -> None:
    """Every part `winder ctl state` shows says how long ago its node said
    it. winder/state is latched and sent once per transition: its age is its
    sending's, so a later query shows it older by the time between the two
    (here: the nodes' next two statuses), while the nodes' statuses, sent
    every second, stay young."""
    start_cell(procs, tmp_path / "bags")
    seen = heard_diagnostics(ros)
    out, began, ended = until_state(
        procs, lambda o: len(node_rows(o)) == 3, "a state showing the three nodes"
    )
    lines = out.splitlines()
    assert lines[0].startswith("cell /  idle  no run yet"), out
    for ln in (lines[0], *lines[2:5]):
        assert AGO.search(ln), f"no age in {ln!r}: {out}"
    assert re.fullmatch(
        r"  ready     consumer ready \(\d+\.\d s ago\), profile ready \(\d+\.\d s ago\)", lines[1]
    ), out
    first = float(AGO.search(lines[0]).group(1))  # type: ignore[union-attr]
    n = len(seen)
    spin_until(
        ros,
        lambda: sum(name == "interp_node: job" for name, _, _ in seen[n:]) >= 2,
        30,
        "two more statuses of the interp node",
    )
    began2 = time.monotonic()
    code, again, err = ctl(procs, "state")
    ended2 = time.monotonic()
    assert code == EXIT_OK, err
    line = again.splitlines()[0]
    assert line.startswith("cell /  idle  no run yet"), again  # no transition meanwhile: the same message
    second = float(AGO.search(line).group(1))  # type: ignore[union-attr]
    # each age was taken at some moment of its query; each shown rounded to 0.1 s
    assert began2 - ended - 0.1 <= second - first <= ended2 - began + 0.1, (first, second, out, again)
    for ln in again.splitlines()[2:5]:  # repeated every second: never as old as the latched state
        assert float(AGO.search(ln).group(1)) < second, again  # type: ignore[union-attr]


def test_a_consumer_killed_mid_run_is_shown_gone_not_busy(procs: Procs, ros: Any, tmp_path: Path) -> None:
    """The consumer killed (SIGKILL: no goodbye) while a real-time run goes
    on: a query after it shows no consumer, not its last latched `busy` and
    `running`; a `state --watch` that heard it before says it fell silent,
    then that it is gone once its participant has left the graph."""
    cell = start_real_time_cell(procs, tmp_path / "bags")
    seen = heard_diagnostics(ros)
    code, out, err = ctl(procs, "start", *LONG, "--timeout", "60")
    assert code == EXIT_OK, out + err
    run_id = out.split()[1]
    spin_until(ros, lambda: under_way(seen, run_id), 60, f"run {run_id} under way")
    watch = state_watch(procs)
    try:
        lines = Lines(watch)
        lines.until(
            lambda ln: ln.split()[:3] == ["sim_node", "consumer", "running"],
            60,
            "the consumer running",
            watch,
        )
        lines.until(
            lambda ln: " running " in ln and run_id in ln and "steps" in ln, 60, "a change line", watch
        )
        os.kill(cell["sim_node"].pid, signal.SIGKILL)
        cell["sim_node"].wait(30)
        code, out, err = ctl(procs, "state")
        assert code == EXIT_OK, out + err
        assert "no consumer on the graph" in out and "consumer busy" not in out, out
        assert "sim_node" not in node_rows(out), out
        rows = node_rows(out)
        assert rows["interp_node"][1] == "interp" and rows["profile_node"][1] == "profile", out
        lines.until(
            lambda ln: "silent: /sim_node" in ln, 60, "the watch saying the consumer fell silent", watch
        )
        lines.until(lambda ln: "gone: /sim_node" in ln, 60, "the watch saying the consumer is gone", watch)
    finally:
        if watch.poll() is None:
            watch.send_signal(signal.SIGINT)
            try:
                watch.communicate(timeout=30)
            except subprocess.TimeoutExpired:
                watch.kill()
                watch.wait()


def _obeyed(
    procs: Procs, ros: Any, bags: Path, run_id: str, *, hold: subprocess.Popen[bytes] | None = None
) -> None:
    """Pause, resume and abort run ``run_id`` of a real-time cell with
    `winder ctl`; each obeyed: the cell says paused, running again, and the
    bag is closed aborted, far short of the job's end. With ``hold`` (a node's
    process): that process is stopped (SIGSTOP) for a second while the pause is asked."""
    states: list[str] = []
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from winder_interfaces.msg import CellState

    latched = QoSProfile(
        depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )
    ros.create_subscription(CellState, "/winder/state", lambda m: states.append(m.state), latched)
    if hold is None:
        code, out, err = ctl(procs, "pause")
    else:
        os.kill(hold.pid, signal.SIGSTOP)
        try:
            pause = popen(
                [str(WINDER), "ctl", "pause", "--timeout", "60"],
                env=procs.env,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
            time.sleep(1.0)  # the node held up for a second (the load; nothing is decided by it)
        finally:
            os.kill(hold.pid, signal.SIGCONT)
        out, err = pause.communicate(timeout=120)
        code = pause.returncode
    assert code == EXIT_OK and f"run {run_id}: pausing" in out, out + err
    spin_until(ros, lambda: "paused" in states, 60, "winder/state paused", heard=lambda: states)
    code, out, err = ctl(procs, "resume")
    assert code == EXIT_OK and f"run {run_id}: resuming" in out, out + err
    n = len(states)
    spin_until(
        ros,
        lambda: "running" in states[n:],
        60,
        "winder/state running after the resume",
        heard=lambda: states,
    )
    code, out, err = ctl(procs, "abort")
    assert code == EXIT_OK and f"run {run_id}: aborting" in out, out + err
    wait.until(lambda: closed_bags(bags), 120, f"the bag of run {run_id} closed")
    [bag] = closed_bags(bags)
    run = read_run(bag)
    assert run.plan.run_id == run_id and run.report["state"] == "aborted", run.report
    assert [e["event"] for e in run.events] == ["pause", "resume", "abort"], run.events
    done, total = int(run.report["steps_done"]), int(run.report["steps_total"])
    assert 0 < done < total // 4, run.report  # aborted mid-job, not after the job was sent in full


def test_a_real_time_run_is_paused_resumed_and_aborted_mid_job(
    procs: Procs, ros: Any, tmp_path: Path
) -> None:
    bags = tmp_path / "bags"
    start_real_time_cell(procs, bags)
    seen = heard_diagnostics(ros)
    code, out, err = ctl(procs, "start", *LONG, "--timeout", "60")
    assert code == EXIT_OK, out + err
    run_id = out.split()[1]
    spin_until(ros, lambda: under_way(seen, run_id), 60, f"run {run_id} under way")
    _obeyed(procs, ros, bags, run_id)


def test_ctl_answers_a_cell_under_load(procs: Procs, ros: Any, tmp_path: Path) -> None:
    """A busy loop on every core beside the cell, and the profile node held
    up (SIGSTOP) for a second while a pause is asked: `winder ctl state`
    shows every node of the running cell with its age, and the pause,
    resume and abort are obeyed."""
    for i in range(os.cpu_count() or 1):
        procs.launch([sys.executable, "-c", "while True: pass"], f"busy{i}")
    bags = tmp_path / "bags"
    cell = start_real_time_cell(procs, bags)
    seen = heard_diagnostics(ros)
    code, out, err = ctl(procs, "start", *LONG, "--timeout", "60")
    assert code == EXIT_OK, out + err
    run_id = out.split()[1]
    spin_until(ros, lambda: under_way(seen, run_id), 90, f"run {run_id} under way")
    out, _, _ = until_state(procs, lambda o: len(node_rows(o)) == 3, "a state showing the cell's three nodes")
    assert out.startswith(f"cell /  running  run {run_id}"), out
    for node, role in (("interp_node", "interp"), ("profile_node", "profile"), ("sim_node", "consumer")):
        row = node_rows(out)[node]
        assert row[1:4] == [role, "running", run_id], out
    assert all(AGO.search(ln) for ln in out.splitlines()[2:5]), out
    _obeyed(procs, ros, bags, run_id, hold=cell["profile_node"])


def test_a_start_the_cell_is_never_ready_for_says_why_not_no_reply(procs: Procs, tmp_path: Path) -> None:
    """The consumer waits for hardware that is not there (a bridge with no
    controller manager): `winder ctl start --set ... --timeout 5` asks again
    while the cell says not ready, and at the deadline says the cell's last
    word, in one line (before: "no reply from /interp_node/start_run within
    5 s", though every call was answered)."""
    procs.start("bridge_node", "-p", f"bag_dir:={tmp_path / 'bags'}")
    procs.start("profile_node")
    procs.start("interp_node", "-p", "autostart:=false")
    code, out, err = ctl(procs, "start", "--set", "turns_per_layer=4", "--timeout", "5")
    line = one_line(err)
    assert code == EXIT_FAILED, out + err  # the cell said no (the exit-code table)
    assert "not ready" in line and "consumer" in line and "(still, after 5 s)" in line, line
    assert "no reply" not in line, line
