"""The cell integration contract, with the real node executables
started one by one as a cell starts them, on an isolated domain.

* one run identity: the same job started twice in one cell's life gives two
  complete bags named after two different run ids, each holding its run id;
  the start reply names the run;
* one status schema: every ``job`` status of the three nodes carries the
  common keys first, in every state they pass through;
* the time base: /clock never goes backwards across the two runs, each run's
  joint states are stamped on it while the bag's analysis still sees each
  job from 0, and the bag shows its real date;
* each cell's bag holds only its own namespace's diagnostics: an ERROR that
  another cell's node publishes meanwhile is neither recorded nor reported.
"""

from __future__ import annotations

import re
import signal
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import Procs, bag_closed, final_report, is_consumer, rosbags_read, spin_until
from support.paths import ROOT
from support.ros_probe import get_params, ros_spin, start_run

from winder.analysis.metrics import analyze
from winder.contract.stream import RUN_ID
from winder.contract.topics import STATUS_KEYS, cell_state_values
from winder.procs import die_with_parent, popen
from winder.record.bag import bags_in
from winder.record.reader import read_run

pytestmark = pytest.mark.ros


def _clock_qos() -> object:
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    return QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT)  # as /clock is published


SMALL = ["-p", "turns_per_layer:=3", "-p", "layers:=1", "-p", "poles:=2", "-p", "chunk_steps:=512"]


def test_the_same_job_twice_gives_two_runs_on_one_clock(tmp_path: Path, procs: Procs, ros: Any) -> None:
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from rosgraph_msgs.msg import Clock
    from std_srvs.srv import Trigger

    statuses: list[tuple[str, list[str], dict[str, str]]] = []

    def on_diag(m: Any) -> None:
        for s in m.status:
            statuses.append((s.name, [kv.key for kv in s.values], {kv.key: kv.value for kv in s.values}))

    ros.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 100)
    clock: list[int] = []
    ros.create_subscription(
        Clock, "/clock", lambda m: clock.append(m.clock.sec * 10**9 + m.clock.nanosec), _clock_qos()
    )
    foreign = ros.create_publisher(DiagnosticArray, "/diagnostics", 10)

    bags = tmp_path / "bags"
    procs.start("sim_node", "-p", f"bag_dir:={bags}")
    procs.start("profile_node")
    procs.start("interp_node", *SMALL, "-p", "autostart:=false")
    client = ros.create_client(Trigger, "/interp_node/start")
    spin_until(ros, client.service_is_ready, 30, "the start service")

    def done(run_id: str) -> bool:
        return any(
            is_consumer(n, v) and v.get("run_id") == run_id and v.get("state") == "done"
            for n, _, v in statuses
        )

    def start() -> str:
        t_end = time.monotonic() + 30
        while True:
            future = client.call_async(Trigger.Request())
            spin_until(ros, future.done, 30, "the start reply")
            reply = future.result()
            if reply.success or "not ready" not in reply.message or time.monotonic() > t_end:
                break
            ros_spin(ros, 0.3)  # the consumer or the profile node is still connecting
        assert reply.success, reply.message
        said = re.search(r"^run (\S+) started", reply.message)
        assert said, reply.message
        return said.group(1)

    # every node's 1 Hz status heard first: its /diagnostics writer is matched with ours, so
    # none of its statuses of the runs is lost to discovery (a loaded CI run once heard the
    # profile node only after both its runs' 'running')
    nodes = {"interp_node", "profile_node", "sim_node"}
    spin_until(ros, lambda: nodes <= {n.split(":")[0] for n, _, _ in statuses}, 30, "every node's status")
    first = start()
    # another cell's node reports an ERROR while this cell runs: not ours
    bad = DiagnosticStatus(level=DiagnosticStatus.ERROR, name="cell9/sim_node: job", message="elsewhere")
    bad.values = [KeyValue(key="state", value="incomplete")]
    for _ in range(3):
        foreign.publish(DiagnosticArray(status=[bad]))
        ros_spin(ros, 0.1)
    spin_until(ros, lambda: done(first), 60, "the first run to complete")
    second = start()
    spin_until(ros, lambda: done(second), 60, "the second run to complete")
    ros_spin(ros, 0.5)

    # two runs, two ids, two bags named after them, each holding its id
    assert first != second and RUN_ID.match(first) and RUN_ID.match(second)
    assert [p.name for p in bags_in(bags)] == sorted([first, second])
    now = time.time()
    for run_id in (first, second):
        run = read_run(bags / run_id)
        assert run.run_id == run_id and run.complete, (run_id, run.report)
        assert run.report["run_id"] == run_id and run.errors == ()
        assert run.states.t[0] == pytest.approx(0.0, abs=1e-9)  # each job seen from its start
        res = analyze(run)
        assert res.steps_recorded == res.steps_total and not any("ERROR" in n for n in res.notes)
        raw = rosbags_read(bags / run_id)
        assert "elsewhere" not in str([m for _, m in raw["/diagnostics"]])
        assert final_report(raw)["run_id"] == run_id
        # the bag's log times are wall-clock dates: this hour, not 1970
        meta = (bags / run_id / "metadata.yaml").read_text()
        start_ns = int(re.search(r"starting_time:\s*nanoseconds_since_epoch:\s*(\d+)", meta).group(1))
        assert abs(start_ns / 1e9 - now) < 600, start_ns
    origin2 = read_run(bags / second).sim_config.clock_origin_ns  # type: ignore[union-attr]
    assert origin2 > 0
    # /clock never goes backwards over the cell's life, across both runs
    c = np.array(clock)
    assert c.size > 100 and np.all(np.diff(c) > 0), np.nonzero(np.diff(c) <= 0)
    assert c[-1] > origin2
    # the cell's state, latched: a late subscriber hears how the last run ended
    from winder.ros.qos import QOS_LATCHED
    from winder_interfaces.msg import CellState

    late: list[Any] = []
    ros.create_subscription(CellState, "/winder/state", late.append, QOS_LATCHED)
    spin_until(ros, lambda: bool(late), 10, "the latched cell state")
    last = cell_state_values(late[-1])
    assert last["state"] == "done" and last["run_id"] == second, last
    # one status schema on every node, in every state seen
    states: dict[str, set[str]] = {}
    for name, keys, values in statuses:
        node = name.split(":")[0]
        if name.endswith(": job") and node in ("interp_node", "profile_node", "sim_node"):
            assert tuple(keys[: len(STATUS_KEYS)]) == STATUS_KEYS, (name, keys)
            states.setdefault(node, set()).add(values["state"])
    for node in ("interp_node", "profile_node", "sim_node"):
        assert {"running", "done"} <= states[node], states


def test_the_readme_controller_runs_a_cell(tmp_path: Path, procs: Procs) -> None:
    """docs/cell_controller.py, the docs' example of a line controller (an
    ActionClient of the cell's Wind action), against the three node
    executables started one by one, the consumer under another node name: its
    goal winds the job set in the cell, and it exits 0 with the run done and
    its bag and part named. With no cell on the graph it gives up after its
    timeout, in one line, exit 2."""
    import subprocess
    import sys

    script = ROOT / "docs" / "cell_controller.py"
    t0 = time.monotonic()
    alone = subprocess.run(
        [sys.executable, str(script), "", "2"], env=procs.env, capture_output=True, text=True, timeout=60
    )
    assert alone.returncode == 2 and time.monotonic() - t0 < 30, alone.stdout + alone.stderr
    assert alone.stdout.strip() == "cell_controller: no winder/wind action server within 2 s", alone.stdout
    bags = tmp_path / "bags"
    procs.start("sim_node", "-r", "__node:=axes", "-p", f"bag_dir:={bags}")
    procs.start("profile_node")
    procs.start("interp_node", *SMALL, "-p", "autostart:=false")
    out = subprocess.run(
        [sys.executable, str(script)], env=procs.env, capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stdout + out.stderr
    run_id = re.search(r"started run (\S+)", out.stdout).group(1)  # type: ignore[union-attr]
    assert f"run {run_id}: done" in out.stdout and str(bags / run_id) in out.stdout, out.stdout
    assert out.stdout.rstrip().endswith(f", part {run_id}"), out.stdout  # its part: the run's id
    assert read_run(bags / run_id).complete


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_the_readme_controller_cancels_its_goal_when_told_to_stop(
    tmp_path: Path, procs: Procs, ros: Any, sig: signal.Signals
) -> None:
    """docs/cell_controller.py started as a shell starts ``cmd &`` (SIGINT
    ignored: a supervisor's script may start it so) and told to stop mid-run
    by SIGTERM or SIGINT: its goal ends CANCELED (the action's own status topic says
    so), the run is aborted (the bag's final report) and the controller exits
    128 + the signal's number. Before, SIGTERM ended it with the run going on
    and SIGINT did nothing."""
    import subprocess
    import sys

    from action_msgs.msg import GoalStatus, GoalStatusArray
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from support.bags import finished_run

    statuses: list[int] = []  # every status the server published, in order (one goal here)
    qos = QoSProfile(
        depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )  # as the action server offers its status
    on_status = lambda m: statuses.extend(s.status for s in m.status_list)  # noqa: E731
    ros.create_subscription(GoalStatusArray, "/winder/wind/_action/status", on_status, qos)
    bags = tmp_path / "bags"
    # the job set in the cell, paced in real time: the signal comes well within the run
    procs.start("sim_node", "-p", f"bag_dir:={bags}", "-p", "real_time:=true")
    procs.start("profile_node")
    procs.start("interp_node", "-p", "autostart:=false")
    die = die_with_parent(signal.SIGTERM)

    def in_background() -> None:  # as a shell starts `cmd &` (POSIX: SIGINT ignored)
        die()
        signal.signal(signal.SIGINT, signal.SIG_IGN)

    log = tmp_path / "cell_controller.log"
    with log.open("wb") as out:
        p = subprocess.Popen(
            [sys.executable, str(ROOT / "docs" / "cell_controller.py")],
            env=procs.env,
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=subprocess.STDOUT,
            preexec_fn=in_background,
        )
    procs.children.started.append((p, "cell_controller", log))  # stopped at teardown if the test fails
    text = lambda: log.read_text(errors="replace")  # noqa: E731
    under_way = lambda: "  coil 1: running" in text() or p.poll() is not None  # noqa: E731
    spin_until(ros, under_way, 90, "the run under way", text)
    assert p.poll() is None, text()
    run_id = re.search(r"started run (\S+)", text()).group(1)  # type: ignore[union-attr]
    p.send_signal(sig)
    spin_until(ros, lambda: p.poll() is not None, 60, f"exit of the controller after {sig.name}", heard=text)
    assert p.returncode == 128 + sig, (p.returncode, text())
    canceled = lambda: GoalStatus.STATUS_CANCELED in statuses  # noqa: E731
    spin_until(ros, canceled, 10, "the goal CANCELED", heard=lambda: statuses)
    assert GoalStatus.STATUS_SUCCEEDED not in statuses and GoalStatus.STATUS_ABORTED not in statuses, statuses
    run = finished_run(bags, run_id)
    assert run.report["state"] == "aborted", run.report
    assert f"{sig.name}: canceling the goal\nrun {run_id}: aborted" in text(), text()


def test_a_dead_consumer_is_not_ready(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """The sim node killed (SIGKILL) after it said ready: its latched "ready"
    no longer counts once it stops repeating it (a start was accepted, and
    its chunks went nowhere), a start is refused as not ready, and a new sim
    node makes the cell ready again and records the run."""
    import signal

    from std_srvs.srv import Trigger

    bags = tmp_path / "bags"
    sim = procs.start("sim_node", "-p", f"bag_dir:={bags}")
    procs.start("profile_node")
    procs.start("interp_node", *SMALL, "-p", "autostart:=false")
    client = ros.create_client(Trigger, "/interp_node/start")
    spin_until(ros, client.service_is_ready, 30, "the start service")
    # everyone connected and announced: the consumer's and the profile node's latched ready heard
    from diagnostic_msgs.msg import KeyValue

    from winder.ros.qos import QOS_LATCHED_READER

    ready: dict[str, str] = {}
    ros.create_subscription(
        KeyValue, "/winder/ready", lambda m: ready.__setitem__(m.key, m.value), QOS_LATCHED_READER
    )
    spin_until(
        ros,
        lambda: ready.get("consumer") == "ready" and ready.get("profile") == "ready",
        30,
        "ready from the consumer and the profile node on winder/ready",
        heard=lambda: ready,
    )
    sim.send_signal(signal.SIGKILL)
    sim.wait()
    # the subject is time: once its announcements stop for 3 s (FRESH) the latched ready no
    # longer counts; a start asked sooner would rightly be taken, so this waits out the 3 s
    ros_spin(ros, 4.0)
    future = client.call_async(Trigger.Request())
    spin_until(ros, future.done, 30, "the start reply")
    reply = future.result()
    assert not reply.success and "not ready" in reply.message and "consumer" in reply.message, reply.message
    procs.start("sim_node", "-p", f"bag_dir:={bags}")
    t_end = time.monotonic() + 30
    while True:
        future = client.call_async(Trigger.Request())
        spin_until(ros, future.done, 30, "the start reply")
        reply = future.result()
        if reply.success or time.monotonic() > t_end:
            break
        ros_spin(ros, 0.3)
    assert reply.success, reply.message
    run_id = re.match(r"run (\S+) started", reply.message).group(1)  # type: ignore[union-attr]
    t_end = time.monotonic() + 60
    while not bag_closed(bags / run_id) and time.monotonic() < t_end:
        ros_spin(ros, 0.2)
    assert read_run(bags / run_id).complete


def test_start_run_sets_up_and_starts_in_one_call(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """~/start_run (rcl_interfaces/SetParametersAtomically): a request with a
    bad value sets nothing and starts nothing (the reason names it); a good
    one sets the job and the ramp it brings and starts the run, whose bag
    holds that ramp, not the profile node's own (scurve)."""
    bags = tmp_path / "bags"
    procs.start("sim_node", "-p", f"bag_dir:={bags}")
    procs.start("profile_node")  # its own ramp: scurve
    procs.start("interp_node", "-p", "autostart:=false")

    def call(values: dict[str, Any]) -> Any:
        return start_run(ros, values)

    setup = {
        "job_id": "tap",
        "turns_per_layer": 3,
        "layers": 1,
        "poles": 2,
        "ramp.source": "job",
        "ramp.profile": "trapezoid",
        "ramp.v_max": 3000.0,
        "ramp.a_max": 20000.0,
    }
    bad = call({**setup, "poles": 0})
    assert not bad.successful and "poles" in bad.reason and "0" in bad.reason, bad.reason
    assert get_params(ros, "interp_node", ["job_id", "ramp.source"]) == ["rw400", "profile_node"]  # untouched
    assert not bags.exists() or not any(bags.iterdir())
    good = call(setup)
    assert good.successful, good.reason
    run_id = re.match(r"run (\S+) started", good.reason).group(1)  # type: ignore[union-attr]
    assert run_id.startswith("tap_")
    t_end = time.monotonic() + 60
    while not bag_closed(bags / run_id) and time.monotonic() < t_end:
        ros_spin(ros, 0.2)
    run = read_run(bags / run_id)
    assert run.complete and run.plan.job.poles == 2
    assert run.profile == "trapezoid" and run.profile_config["v_max"] == 3000.0
    assert run.profile_config["ramp_source"] == "job"


def test_winder_run_ignores_other_cells_errors(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """``winder run`` fails a run on its own nodes' ERROR statuses only: a cell
    without a namespace and one in /c1 both finish with exit 0 while other
    cells' nodes (/c10 shares /c1's first letters) report ERRORs all along."""
    import subprocess

    from conftest import BIN
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from support.cell import SMALL_JOB, job_args

    foreign = ros.create_publisher(DiagnosticArray, "/diagnostics", 10)
    bad = [
        DiagnosticStatus(level=DiagnosticStatus.ERROR, name=name, message="elsewhere")
        for name in ("c10/sim_node: job", "cell9/interp_node: job", "c1/deeper/sim_node: job")
    ]
    runs = {
        ns: popen(
            [str(BIN / "winder"), "run", "--bag-dir", str(tmp_path / f"bags{ns}"), *job_args(SMALL_JOB)]
            + (["--namespace", ns] if ns else []),
            env=procs.env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            stdin=subprocess.DEVNULL,
        )
        for ns in ("", "/c1")
    }
    published = 0

    def finished() -> bool:
        nonlocal published
        foreign.publish(DiagnosticArray(status=bad))
        published += 1
        return all(p.poll() is not None for p in runs.values())

    spin_until(ros, finished, 240, "both runs to end")
    assert published > 10  # the ERRORs went out while the runs were on the graph
    for ns, p in runs.items():
        out, err = p.communicate()
        assert p.returncode == 0, (ns, out, err)
        assert "ERROR reports" not in out and "elsewhere" not in out + err, (ns, out)
