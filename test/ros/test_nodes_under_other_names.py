"""A cell whose nodes run under other names, and settings that never drop
silently, with the real node executables on an isolated domain.

* the step consumer runs as ``sim_node --ros-args -r __node:=axes`` and the
  profile node as ``ramp``, both on their own (``winder run --external
  sim,profile``): the job runs to done with its progress and summary, the job
  file's ``consumer`` and ``profile_node`` sections and the command line's
  options reach those nodes through their parameter services, the bag's
  report is found by role and ``winder analyze`` prints it;
* a setting the external consumer refuses ends the run before it starts, in
  one line naming the setting;
* ``~/start_run`` with a ramp but no ``ramp.source`` runs that ramp; a ramp
  with ``ramp.source: profile_node`` is refused, nothing set;
* the graph names the consumer by its part (reads ``winder/step_times``,
  writes ``winder/progress``), and a third-party driver of another name that
  does not say its role runs a job through ``winder run`` all the same.
"""

from __future__ import annotations

import os
import pty
import re
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import pytest
from conftest import BIN, Procs, bag_closed, rosbags_read

from winder.contract.topics import ROLE_KEY, STATUS_KEYS
from winder.procs import popen
from winder.record.reader import read_run

pytestmark = pytest.mark.ros

JOB_FILE = """\
interp_node:
  ros__parameters:
    job_id: renamed
    turns_per_layer: 3
    layers: 1
    poles: 2
    fork_steps_per_rev: 512
profile_node:
  ros__parameters:
    profile: trapezoid
    v_max: 3000.0
    a_max: 30000.0
consumer:
  ros__parameters:
    publish_rate: 500.0
    fork:
      J: 2.0e-4
"""


def winder_on_a_terminal(procs: Procs, *args: str, timeout: float = 180.0) -> tuple[int, str, str]:
    """``winder ARGS`` with stderr on a terminal (a pty), as a user runs it:
    (exit status, stdout, what the terminal showed)."""
    master, slave = pty.openpty()
    shown: list[bytes] = []

    def drain() -> None:
        while True:
            try:
                data = os.read(master, 4096)
            except OSError:  # the last writer closed the terminal
                return
            if not data:
                return
            shown.append(data)

    reader = threading.Thread(target=drain, daemon=True)
    reader.start()
    try:
        p = popen(
            [str(BIN / "winder"), *args],
            env=procs.env,
            stdout=subprocess.PIPE,
            stderr=slave,
            stdin=subprocess.DEVNULL,
            text=True,
        )
        os.close(slave)
        out, _ = p.communicate(timeout=timeout)
        reader.join(timeout=10)
    finally:
        os.close(master)
    return p.returncode, out, b"".join(shown).decode(errors="replace")


def test_a_cell_whose_nodes_run_under_other_names(tmp_path: Path, procs: Procs) -> None:
    job = tmp_path / "job.yaml"
    job.write_text(JOB_FILE)
    bags = tmp_path / "bags"
    procs.start("sim_node", "-r", "__node:=axes", "-p", f"bag_dir:={bags}")
    procs.start("profile_node", "-r", "__node:=ramp")
    status, out, terminal = winder_on_a_terminal(
        procs,
        "run",
        "--external",
        "sim,profile",
        str(job),
        "--feed.D",
        "0.02",  # an option for the external consumer: set on it, over the file's section
        "--v-max",
        "2500",  # and one for the external profile node
        "--timeout",
        "120",
    )
    assert status == 0, out + terminal
    assert "not started here   profile node, step consumer (--external profile,sim)" in out, out
    assert "external consumer  publish_rate=500.0, fork.J=0.0002, feed.D=0.02" in out, out
    assert "external profile   profile=trapezoid, v_max=2500.0, a_max=30000.0" in out, out
    # the progress bar follows the consumer's progress to the end; the summary is its final report
    assert "winding [" in terminal and "100.0%" in terminal, terminal
    assert "  state              done" in out and "  lost steps         0" in out, out
    bag = Path(re.search(r"  bag +(\S+)", out).group(1))  # type: ignore[union-attr]
    assert bag.parent == bags.resolve()
    # what winder run set on the external nodes is what the run ran with
    run = read_run(bag)
    assert run.complete and run.report["state"] == "done", run.report
    assert run.sim_config is not None and run.sim_config.publish_rate == 500.0
    assert run.sim_config.axes["fork"].J == 2.0e-4 and run.sim_config.axes["feed"].D == 0.02
    assert run.profile == "trapezoid" and run.profile_config["v_max"] == 2500.0
    assert run.profile_config["ramp_source"] == "profile_node"
    # every node's job status says its role right after the common keys
    roles: dict[str, set[str]] = {}
    for _, arr in rosbags_read(bag)["/diagnostics"]:
        for st in arr.status:
            keys = [kv.key for kv in st.values]
            if st.name.endswith(": job") and ROLE_KEY in keys:
                assert keys.index(ROLE_KEY) == len(STATUS_KEYS), (st.name, keys)
                roles.setdefault(st.name.split(":")[0], set()).add(st.values[len(STATUS_KEYS)].value)
    assert roles.get("interp_node") == {"interp"} and roles.get("ramp") == {"profile"}, roles
    # winder analyze finds the report of the consumer named axes
    r = subprocess.run(
        [str(BIN / "winder"), "analyze", str(bag), "--no-plots"],
        capture_output=True,
        text=True,
        timeout=120,
        stdin=subprocess.DEVNULL,
    )
    assert r.returncode == 0, r.stderr
    steps = int(run.report["steps_total"])
    assert re.search(r"state +done, closed", r.stdout), r.stdout
    assert f"{steps} simulated, {steps} recorded, of {steps}" in r.stdout, r.stdout


def test_a_setting_the_external_consumer_refuses_ends_the_run_unstarted(tmp_path: Path, procs: Procs) -> None:
    """The job file asks the external consumer for a bag directory it cannot
    write (a job file cannot check that: it is the consumer's host's): the
    consumer refuses it, the job never starts, the reason names the setting."""
    from support.cli import assert_one_line_error

    job = tmp_path / "job.yaml"
    job.write_text(JOB_FILE.replace("    publish_rate: 500.0\n", "    bag_dir: /proc/winder_bags\n"))
    bags = tmp_path / "bags"
    sim = procs.start("sim_node", "-r", "__node:=axes", "-p", f"bag_dir:={bags}")
    r = subprocess.run(
        [str(BIN / "winder"), "run", "--external", "sim", str(job), "--start-timeout", "60"],
        env=procs.env,
        capture_output=True,
        text=True,
        timeout=180,
        stdin=subprocess.DEVNULL,
    )
    assert_one_line_error(
        r,
        "job not started: the step consumer /axes refused the settings of this run",
        "bag_dir='/proc/winder_bags'",
    )
    assert not bags.exists() or not any(bags.iterdir())  # no run, no bag
    assert sim.poll() is None  # the consumer goes on, with its own settings


def test_start_run_with_a_ramp_runs_that_ramp(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """``ramp.profile: trapezoid`` without ``ramp.source``: the run brings its
    ramp (the profile node's own is scurve); with ``ramp.source:
    profile_node`` beside it the call is refused, nothing set, no run."""
    from support.ros_probe import get_params, ros_spin, start_run

    bags = tmp_path / "bags"
    procs.start("sim_node", "-p", f"bag_dir:={bags}")
    procs.start("profile_node")  # its own ramp: scurve
    procs.start("interp_node", "-p", "autostart:=false")
    job = {"job_id": "tap", "turns_per_layer": 3, "layers": 1, "poles": 2}
    ramp = {"ramp.profile": "trapezoid", "ramp.v_max": 3000.0, "ramp.a_max": 20000.0}
    refused = start_run(ros, {**job, **ramp, "ramp.source": "profile_node"})
    assert not refused.successful, refused.reason
    assert "ramp.profile given but ramp.source is 'profile_node'" in refused.reason, refused.reason
    assert "set ramp.source: job" in refused.reason and "\n" not in refused.reason
    assert get_params(ros, "interp_node", ["job_id", "ramp.profile"]) == ["rw400", "scurve"]  # nothing set
    assert not bags.exists() or not any(bags.iterdir())
    started = start_run(ros, {**job, **ramp})
    assert started.successful, started.reason
    run_id = re.match(r"run (\S+) started", started.reason).group(1)  # type: ignore[union-attr]
    t_end = time.monotonic() + 60
    while not bag_closed(bags / run_id) and time.monotonic() < t_end:
        ros_spin(ros, 0.2)
    run = read_run(bags / run_id)
    assert run.complete and run.profile == "trapezoid" and run.profile_config["v_max"] == 3000.0
    assert run.profile_config["ramp_source"] == "job"
    # what the call set was the run's: the node's own settings are what they were (issue 53)
    assert get_params(ros, "interp_node", ["ramp.source", "ramp.profile"]) == ["profile_node", "scurve"]


def test_the_graph_and_the_watch_find_the_consumer_by_its_part(ros: Any) -> None:
    """winder.ros.graph.consumers: the node of the cell's namespace that reads
    its winder/step_times and writes its winder/progress, whatever its name;
    not a recorder that only reads, not a node of another namespace, not the
    caller. The cell's watch takes the job status of a consumer that names no
    role (a driver written before roles) for the part the graph shows it in."""
    import rclpy
    from conftest import spin_until
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from std_msgs.msg import Int64MultiArray
    from std_msgs.msg import String as Str

    from winder.contract.trust import SIGNS
    from winder.ros.cell import CellWatch
    from winder.ros.graph import consumers, fully_qualified

    made = []

    def node(name: str, namespace: str, reads: bool, acks: bool) -> None:
        n = rclpy.create_node(name, namespace=namespace, context=ros.context)
        if reads:
            n.create_subscription(Int64MultiArray, "winder/step_times", lambda _m: None, 10)
        if acks:
            n.create_publisher(KeyValue, "winder/progress", 10)
        n.create_publisher(Str, "winder/other", 10)
        made.append(n)

    try:
        node("axes", "/", reads=True, acks=True)  # the consumer, under another name
        node("recorder", "/", reads=True, acks=False)  # reads everything, acknowledges nothing
        node("axes", "/cell2", reads=True, acks=True)  # another cell's consumer
        spin_until(ros, lambda: len(consumers(ros, "/cell2")) == 1, 10, "the graph")
        spin_until(ros, lambda: consumers(ros, "") == [("axes", "/")], 10, "the cell's consumer")
        assert consumers(ros, "/cell2") == [("axes", "/cell2")]
        assert fully_qualified("axes", "/cell2") == "/cell2/axes" and fully_qualified("axes", "/") == "/axes"
        assert consumers(made[0], "") == []  # the caller itself is left out

        watch = CellWatch(ros, "")
        watch.run_id = "r1"

        def status(name: str, **values: str) -> DiagnosticArray:
            kvs = [KeyValue(key=k, value=v) for k, v in values.items()]
            return DiagnosticArray(status=[DiagnosticStatus(name=name, message="m", values=kvs)])

        # the watch takes an array for the part the graph shows its sender in (Peers.deliver_by_part):
        # the consumer's, whatever its name (the recorder plays none); and only the sender's own status
        [axes] = watch.peers.holders("consumer")
        assert axes.name == "axes" and watch.peers.part(axes) == "consumer"
        assert not any(w.name == "recorder" for r in SIGNS for w in watch.peers.holders(r))
        watch._on_diagnostics(status("recorder: job", run_id="r1", state="done"), "consumer", axes)
        assert watch.summary is None and not watch.heard_consumer
        watch._on_diagnostics(
            status("axes: job", run_id="r1", state="running", progress="0.5"), "consumer", axes
        )
        assert watch.heard_consumer and watch.progress == 0.5
        watch._on_diagnostics(
            status("axes: job", run_id="r1", state="done", progress="1.0"), "consumer", axes
        )
        assert watch.summary is not None and watch.summary["state"] == "done"
    finally:
        for n in made:
            n.destroy_node()


#: A third-party step consumer in a few lines of rclpy and winder_interfaces, no winder import: it
#: takes each chunk as it comes, acknowledges it and reports its job status
#: under its own node name WITHOUT a role (a driver written before roles). It
#: declares no parameters, records no bag, and its report has none of the
#: simulator's keys.
DRIVER = """
import sys, rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Int64MultiArray
from winder_interfaces.msg import JobDescription
R = ReliabilityPolicy.RELIABLE
LATCHED = QoSProfile(depth=1, reliability=R, durability=DurabilityPolicy.TRANSIENT_LOCAL)
rclpy.init(args=sys.argv)
node = rclpy.create_node("driver")
ready = node.create_publisher(KeyValue, "winder/ready", LATCHED)
progress = node.create_publisher(KeyValue, "winder/progress", QoSProfile(depth=100, reliability=R))
diag = node.create_publisher(DiagnosticArray, "/diagnostics", QoSProfile(depth=10, reliability=R))
run = {"state": "idle", "job_id": "", "run_id": "", "done": 0, "total": 0}
def report():
    busy = run["state"] == "running"
    idle = "ready" if times.get_publisher_count() else "waiting"
    ready.publish(KeyValue(key="consumer", value="busy" if busy else idle))
    values = dict(state=run["state"], job_id=run["job_id"], run_id=run["run_id"], steps_done=run["done"],
                  steps_total=run["total"], progress=f"{run['done'] / max(run['total'], 1):.4f}")
    name = node.get_fully_qualified_name().lstrip("/") + ": job"
    kvs = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
    diag.publish(DiagnosticArray(status=[DiagnosticStatus(name=name, message=run["state"], values=kvs)]))
def on_job(msg):
    run.update(state="running", job_id=msg.job_id, run_id=msg.run_id, done=0, total=msg.total_steps)
    report()
def on_steps(msg):
    if run["state"] != "running":
        return
    run["done"] += len(msg.data) // 5
    progress.publish(KeyValue(key=run["run_id"], value=str(run["done"])))
    if run["done"] >= run["total"]:
        run["state"] = "done"
        report()
node.create_subscription(JobDescription, "winder/job", on_job, LATCHED)
times = node.create_subscription(Int64MultiArray, "winder/step_times", on_steps,
                                 QoSProfile(depth=1000, reliability=R, history=HistoryPolicy.KEEP_ALL))
node.create_timer(1.0, report)
try:
    rclpy.spin(node)
except KeyboardInterrupt:
    pass
"""


def test_a_third_party_consumer_that_names_no_role(tmp_path: Path, procs: Procs) -> None:
    """A driver of another name that does not say its role: winder run finds
    its job status by its part on the graph, runs the job to done and prints
    the summary its report has (no simulator keys: no deviation, no lost
    steps, no bag); settings it does not have are refused, named, before
    anything starts."""
    import subprocess
    import sys

    from support.cli import assert_one_line_error

    driver = procs.launch([sys.executable, "-c", DRIVER, "--ros-args", "-r", "__node:=axes"], "driver")
    small = ["--job-id", "third", "--turns-per-layer", "2", "--layers", "1", "--poles", "1"]
    run = [str(BIN / "winder"), "run", "--external", "sim", *small, "--timeout", "120"]
    options: dict[str, Any] = {"env": procs.env, "capture_output": True, "text": True, "timeout": 180}
    r = subprocess.run([*run, "--start-timeout", "30"], stdin=subprocess.DEVNULL, **options)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "  state              done" in r.stdout and "  bag                -" in r.stdout, r.stdout
    assert "mean deviation" not in r.stdout and "lost steps" not in r.stdout, r.stdout
    refused = subprocess.run([*run, "--fork.J", "2e-4"], stdin=subprocess.DEVNULL, **options)
    assert_one_line_error(
        refused,
        # rclpy's reason lists no name ("undeclared parameter(s): []"): winder run names them
        "job not started: the step consumer /axes refused the settings of this run (fork.J): ",
        "undeclared parameter",
    )
    assert driver.poll() is None
