"""Conformance of a step consumer to the cell contract (docs/CONTRACT.md, §4).

Every test starts the real ``interp_node`` and ``profile_node`` and the
consumer under test as separate processes over DDS, on a ``ROS_DOMAIN_ID``
of the test's own (LOCALHOST discovery; one no other test picks, see
:func:`conftest.next_domain`), and watches the cell the way a
controller does: ``winder/ready``, ``winder/state``, ``winder/progress``,
``winder/control``, ``/diagnostics`` and the services. The consumer's
statuses are found by their role (``role: consumer`` in the cell's
namespace), never by a node name; several tests run it as ``axes``
(``--ros-args -r __node:=axes``).

Subjects (``CONSUMERS``): ``sim_node`` (in real time), ``bridge_node`` (the
ros2_control bridge, driving test/ros2_control_standin.py), the library's
mock drive (``winder.ros.mock_backend``: a ``Backend`` of three methods in a
``DriverNode``) paced and as fast as possible, the CiA 402 drives node
(``cia402_node``) on the drive twins of a virtual-bus drives file, paced
and as fast as possible, and any executable named by the environment::

    WINDER_CONSUMER="my_driver --ros-args -p port:=/dev/ttyUSB0" \\
        .venv/bin/python -m pytest test/contract/test_conformance.py

``WINDER_CONSUMER`` is a command line (split like a shell's; a bare first
word is looked up in the venv's bin, then on PATH); the optional
``WINDER_CONSUMER_EXTRA`` holds the command lines of processes it needs
beside it, separated by ``;`` (started before it, stopped after it). The
consumer must execute the steps at their times (real time, as a drive
does): pause, abort, a start while busy, a stall and a kill all act on a
run while it goes on. Each subject gets, after its own arguments,
``--ros-args`` with the consumer settings of the contract (``bag_dir``,
``record``, ``stall_timeout``, ``stall_abort``; ``params.CONSUMER_SPECS``)
and, in some tests, ``-r __node:=axes``.

Adding a consumer (the ros2_control bridge, a driver) is one
:class:`ConsumerSpec` in ``CONSUMERS``: its command line, its parameters for
these tests, and the processes it needs.

A subject that runs as fast as possible (``paced=False``) ends a run before
an operator could act on it: it takes the tests that need no run going on
(the handshake, a whole job, the report), the others take ``PACED``.

The checks, each a test: the handshake; a whole job; pause and resume;
abort, then ready and a second job; a Wind goal canceled, then one wound
(the action a line controller drives the cell with); a start refused while busy; a stall
reported and the run closed; a killed and restarted consumer; the status
keys, the final report and the names. The last two tests are of the interp
node: a consumer written from the topic contract alone that ignores aborts
(``test/consumers/naive_consumer.py``) must not wedge the cell, and an abort
whose braking steps the interp node had not sent yet still ends aborted.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from itertools import pairwise
from pathlib import Path
from typing import Any

import pytest
from conftest import BIN, Procs, bag_closed, next_domain, release_domain, spin_until
from support.paths import TEST

from winder.contract.topics import ROLE_KEY, STATUS_KEYS, cell_state_values, in_namespace

pytestmark = pytest.mark.ros

#: the consumer's job status keys after ``role`` that every consumer reports (CONTRACT.md §3.7)
CONSUMER_KEYS = (
    *("steps_missing", "gaps", "chunks_rejected", "sim_time_s", "wall_time_s", "real_time_factor"),
    *("bag", "errors", "stalls"),
)
FINAL = ("done", "aborted", "incomplete")
#: a quick job (4096 steps, 1.2 s at the ramp below) and one long enough to act on (8192, 2.2 s)
JOB = {"job_id": "conf", "turns_per_layer": 4, "layers": 1, "poles": 1, "fork_steps_per_rev": 1024}
LONG_JOB = {**JOB, "turns_per_layer": 8}
RAMP = {"v_max": 4096.0, "a_max": 32768.0, "j_max": 524288.0}
#: the consumer's stall watch, small; the interp node gives a run up later than the consumer closes it
CONSUMER_STALL = {"stall_timeout": 1.0, "stall_abort": 2.0}
INTERP_STALL_ABORT = 3.0
#: slack on the bounds the contract sets, for two shared cores
SLACK = 1.5


@pytest.fixture
def procs(tmp_path: Path) -> Iterator[Procs]:
    """conftest's ``procs``: a domain of ``WINDER_TEST_DOMAINS`` no other test
    process of the machine holds (the ``ros`` probe joins it)."""
    log_dir = tmp_path / "logs"
    log_dir.mkdir()
    ps = Procs(next_domain(), log_dir)
    try:
        yield ps
    finally:
        ps.stop_all()
        release_domain(ps.domain)


@dataclass(frozen=True)
class ConsumerSpec:
    """A consumer under test: its command line (a bare first word is an
    executable of the venv's bin, as ``ros2 run`` finds it), its parameters
    for these tests, and the processes it needs beside it (started first)."""

    id: str
    command: tuple[str, ...]
    params: dict[str, str] = field(default_factory=dict)
    extra: tuple[tuple[str, ...], ...] = ()
    #: it executes the steps at their times (a drive); False: as fast as it can, so a run ends
    #: before an operator could act on it, and only the tests that need no run going on take it
    paced: bool = True


#: the ros2_control stand-in's joints (test/ros2_control_standin.py), out of the cell's axis order
BRIDGE_JOINTS = {"pole_joint": "pole", "flyer": "fork", "feed_screw": "feed"}
CONSUMERS = [
    ConsumerSpec("sim_node", ("sim_node",), {"real_time": "true"}),
    ConsumerSpec(
        "bridge_node",
        ("bridge_node",),
        {
            "joints": f"[{','.join(BRIDGE_JOINTS)}]",
            "axes": f"[{','.join(BRIDGE_JOINTS.values())}]",
            "job_origin": "start_position",  # a run after an abort or a stall starts where the joints stopped
            # the stand-in is a Python process on two busy cores: its joints lag (test_bridge_node's limits)
            "joint_state_timeout": "0.5",
            "max_following_error.fork": "5.0",
            "max_following_error.pole": "1.0",
            "max_following_error.feed": "0.01",
        },
        extra=((sys.executable, str(TEST / "ros2_control_standin.py"), "--joints", ",".join(BRIDGE_JOINTS)),),
    ),
    # the library's mock drive (winder.ros.mock_backend): a Backend of three methods, no more
    ConsumerSpec("mock_driver", (sys.executable, "-m", "winder.ros.mock_backend"), {"lag": "0.005"}),
    ConsumerSpec(
        "mock_driver_fast",
        (sys.executable, "-m", "winder.ros.mock_backend"),
        {"real_time": "false"},
        paced=False,
    ),
    # the CiA 402 drives node (winder.ros.cia402_node) on its drive twins: a virtual-bus drives file
    ConsumerSpec(
        "cia402_twins", ("cia402_node",), {"drives_file": str(TEST / "drives" / "data" / "twin_cell.yaml")}
    ),
    ConsumerSpec(
        "cia402_twins_fast",
        ("cia402_node",),
        {"drives_file": str(TEST / "drives" / "data" / "twin_cell.yaml"), "real_time": "false"},
        paced=False,
    ),
]
if os.environ.get("WINDER_CONSUMER", "").strip():
    CONSUMERS.append(
        ConsumerSpec(
            "WINDER_CONSUMER",
            tuple(shlex.split(os.environ["WINDER_CONSUMER"])),
            extra=tuple(
                tuple(shlex.split(c))
                for c in os.environ.get("WINDER_CONSUMER_EXTRA", "").split(";")
                if c.strip()
            ),
        )
    )


#: the consumer written from the topic contract alone (not a subject: it ignores aborts on purpose)
NAIVE = ConsumerSpec("naive_consumer", (sys.executable, str(TEST / "consumers" / "naive_consumer.py")))


@pytest.fixture(params=CONSUMERS, ids=[c.id for c in CONSUMERS])
def consumer(request: pytest.FixtureRequest) -> ConsumerSpec:
    spec: ConsumerSpec = request.param
    return spec


#: the subjects that execute the steps at their times: a run is going on long enough to act on
PACED = [c for c in CONSUMERS if c.paced]


@pytest.fixture(params=PACED, ids=[c.id for c in PACED])
def paced(request: pytest.FixtureRequest) -> ConsumerSpec:
    """A subject of the tests that act on a run while it goes on."""
    spec: ConsumerSpec = request.param
    return spec


def resolve(argv: tuple[str, ...]) -> list[str]:
    """The command line with its executable found: the venv's first, then PATH."""
    first = argv[0]
    if "/" not in first:
        first = str(BIN / first) if (BIN / first).exists() else shutil.which(first) or first
    return [first, *argv[1:]]


def params(values: dict[str, Any]) -> list[str]:
    return [
        a for k, v in values.items() for a in ("-p", f"{k}:={str(v).lower() if isinstance(v, bool) else v}")
    ]


@dataclass
class Status:
    t: float  # monotonic time heard
    level: int
    name: str
    message: str
    values: dict[str, str]


class Cell:
    """One cell on the test's domain: interp and profile node, the consumer
    under test, and the probe (the ``ros`` fixture's node) hearing what a
    controller hears."""

    def __init__(self, procs: Procs, ros: Any, tmp_path: Path) -> None:
        from diagnostic_msgs.msg import DiagnosticArray, KeyValue
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from std_srvs.srv import Trigger

        from winder_interfaces.msg import CellState, ControlEvent

        self.procs, self.ros = procs, ros
        self.bags = tmp_path / "bags"
        self.statuses: list[Status] = []
        self.states: list[tuple[float, str, dict[str, str]]] = []  # winder/state: (heard, name, values)
        self.ready: list[tuple[float, str]] = []  # the consumer's winder/ready: (heard, value)
        self.receipts: list[tuple[float, str, int]] = []  # winder/progress: (heard, run id, steps)
        self.events: list[dict[str, Any]] = []  # winder/control
        reliable = ReliabilityPolicy.RELIABLE
        latched = QoSProfile(depth=100, reliability=reliable, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        plain = QoSProfile(depth=1000, reliability=reliable)

        def on_diag(msg: Any) -> None:
            now = time.monotonic()
            for s in msg.status:
                values = {kv.key: kv.value for kv in s.values}
                self.statuses.append(Status(now, s.level[0], s.name, s.message, values))

        def on_state(msg: Any) -> None:  # a winder_interfaces/CellState
            self.states.append((time.monotonic(), msg.node, cell_state_values(msg)))

        def on_ready(msg: Any) -> None:
            if msg.key == "consumer":
                self.ready.append((time.monotonic(), msg.value))

        def on_progress(msg: Any) -> None:
            if msg.value.isdigit():
                self.receipts.append((time.monotonic(), msg.key, int(msg.value)))

        def on_control(msg: Any) -> None:  # a winder_interfaces/ControlEvent, as its fields
            self.events.append({f: getattr(msg, f) for f in msg.get_fields_and_field_types()})

        ros.create_subscription(DiagnosticArray, "/diagnostics", on_diag, plain)
        ros.create_subscription(CellState, "/winder/state", on_state, latched)
        ros.create_subscription(KeyValue, "/winder/ready", on_ready, latched)
        ros.create_subscription(KeyValue, "/winder/progress", on_progress, plain)
        ros.create_subscription(ControlEvent, "/winder/control", on_control, latched)
        self.Trigger = Trigger
        self.clients = {
            name: ros.create_client(Trigger, f"/{node}/{name}")
            for node, name in (
                ("interp_node", "start"),
                ("profile_node", "pause"),
                ("profile_node", "resume"),
                ("profile_node", "abort"),
            )
        }
        self.consumer: subprocess.Popen[bytes] | None = None
        self.consumer_argv: list[str] = []
        self.profile: subprocess.Popen[bytes] | None = None
        self.interp: subprocess.Popen[bytes] | None = None

    # -- processes --------------------------------------------------------------
    def start_consumer(
        self, spec: ConsumerSpec, *, name: str = "", stall: dict[str, float] | None = None
    ) -> subprocess.Popen[bytes]:
        """The consumer under test (and, the first time, what it needs beside it)."""
        if not self.consumer_argv:
            for i, argv in enumerate(spec.extra):
                self.procs.launch(resolve(argv), f"extra{i}")
            settings = {"bag_dir": self.bags, "record": True, **(stall or CONSUMER_STALL), **spec.params}
            ros_args = ["--ros-args", *(["-r", f"__node:={name}"] if name else []), *params(settings)]
            self.consumer_argv = [*resolve(spec.command), *ros_args]
        self.consumer = self.procs.launch(self.consumer_argv, "consumer")
        return self.consumer

    def start_upstream(self, job: dict[str, Any] = LONG_JOB, **interp: Any) -> None:
        """The real profile and interp nodes (autostart off: the tests start each run)."""
        self.profile = self.procs.start("profile_node", *params(RAMP))
        settings = {**job, "autostart": False, "stall_abort": INTERP_STALL_ABORT, **interp}
        self.interp = self.procs.start("interp_node", *params(settings))

    def announcers(self) -> str:
        """Who publishes winder/ready on the domain (a stray consumer of another test would)."""
        infos = self.ros.get_publishers_info_by_topic("/winder/ready")
        return "winder/ready publishers: " + ", ".join(
            sorted(f"{i.node_namespace}/{i.node_name}" for i in infos)
        )

    def logs(self) -> str:
        """The tail of every process' log, for a failure message."""
        out = []
        for p, path in self.procs.procs:
            lines = path.read_text(errors="replace").strip().splitlines()
            # a process that ended: from its first ERROR or traceback on (what ended it), else the tail
            first = next((i for i, line in enumerate(lines) if "ERROR" in line or "Traceback" in line), None)
            text = lines[first:][:60] if p.poll() is not None and first is not None else lines[-15:]
            argv = p.args if isinstance(p.args, list) else [p.args]
            out.append(f"--- {Path(str(argv[0])).name} ({path.name}, exit {p.poll()}):\n" + "\n".join(text))
        return "\n".join(out)

    # -- what the probe heard --------------------------------------------------
    def wait(self, cond: Callable[[], object], timeout: float, what: str) -> None:
        try:
            spin_until(self.ros, cond, timeout, what)
        except AssertionError as exc:
            heard = [f"{s.name} [{s.level}] {s.message}" for s in self.statuses[-12:]]
            states = [v.get("state") for _, _, v in self.states]
            nodes = sorted(ns.rstrip("/") + "/" + n for n, ns in self.ros.get_node_names_and_namespaces())
            raise AssertionError(
                f"{exc}\nwinder/state: {states}\nconsumer winder/ready: {[v for _, v in self.ready][-10:]}\n"
                f"nodes on the domain: {nodes}\n"
                "last statuses:\n  " + "\n  ".join(heard) + "\n" + self.logs()
            ) from None

    def pause_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        spin_until(self.ros, lambda: time.monotonic() > end, seconds + 5, f"{seconds} s")

    def jobs(self, run_id: str | None = None) -> list[Status]:
        """The consumer's job statuses (role consumer, the root namespace), of ``run_id`` if given."""
        return [
            s
            for s in self.statuses
            if s.name.endswith(": job")
            and in_namespace(s.name, "")
            and s.values.get(ROLE_KEY) == "consumer"
            and (run_id is None or s.values.get("run_id") == run_id)
        ]

    def final(self, run_id: str) -> Status | None:
        return next((s for s in self.jobs(run_id) if s.values.get("state") in FINAL), None)

    def cell_states(self, run_id: str) -> list[str]:
        return [v["state"] for _, _, v in self.states if v.get("run_id") == run_id]

    def taken(self, run_id: str) -> int:
        return max((n for _, key, n in self.receipts if key == run_id), default=0)

    def node(self) -> str:
        """The consumer's node, as its last job status names it (``axes``, ``cell1/axes``)."""
        jobs = self.jobs()
        return jobs[-1].name.split(":", 1)[0] if jobs else ""

    def silence_s(self, t0: float, t1: float) -> float:
        """The longest time between two statuses of the consumer heard in
        [t0, t1]: its 1 Hz report not heard for much longer than a second
        means the process did not run (a machine starved of CPU)."""
        node = self.node()
        heard = [t0, *(s.t for s in self.statuses if s.name.startswith(node + ":") and t0 <= s.t <= t1), t1]
        return max(b - a for a, b in pairwise(heard))

    def silence(self, t0: float, t1: float) -> str:
        gap = self.silence_s(t0, t1)
        return f"the longest silence of {self.node()} in that time: {gap:.1f} s (its report is every 1 s)"

    def ready_since(self, t: float) -> bool:
        return any(v == "ready" and heard > t for heard, v in self.ready)

    # -- services ---------------------------------------------------------------
    def call(self, service: str, timeout: float = 15.0) -> Any:
        client = self.clients[service]
        self.wait(client.service_is_ready, 30, f"the service ~/{service}")
        future = client.call_async(self.Trigger.Request())
        self.wait(future.done, timeout, f"the reply of ~/{service}")
        return future.result()

    def start(self, timeout: float = 20.0) -> tuple[str, int]:
        """~/start, asked again while the cell says "not ready" (the contract's
        rule); the run id and its steps from the reply."""
        end = time.monotonic() + timeout
        while True:
            reply = self.call("start")
            if reply.success or "not ready" not in reply.message or time.monotonic() > end:
                break
            self.pause_for(0.2)
        assert reply.success, f"~/start refused: {reply.message}\n{self.logs()}"
        m = re.match(r"run (\S+) started: job \S+, (\d+) steps", reply.message)
        assert m, reply.message
        return m.group(1), int(m.group(2))

    def running(self, run_id: str, steps: int = 1, timeout: float = 20.0) -> None:
        """Wait until the run is running at the consumer and ``steps`` of it are acknowledged."""
        self.wait(
            lambda: "running" in self.cell_states(run_id) and self.taken(run_id) >= steps,
            timeout,
            f"run {run_id} running at the consumer (winder/state) with {steps} steps acknowledged",
        )

    def ends(self, run_id: str, timeout: float = 30.0) -> Status:
        """Wait for the consumer's final report of the run."""
        self.wait(
            lambda: self.final(run_id) is not None, timeout, f"the consumer's final report of run {run_id}"
        )
        report = self.final(run_id)
        assert report is not None
        return report

    def given_up(self, run_id: str) -> None:
        """Wait for the interp node to give the run up (no receipt for its stall_abort)."""
        self.wait(
            lambda: any(
                s.name == "interp_node: job"
                and s.values.get("run_id") == run_id
                and s.values["state"] == "incomplete"
                for s in self.statuses
            ),
            INTERP_STALL_ABORT + 10,
            f"the interp node to give run {run_id} up (its stall_abort {INTERP_STALL_ABORT} s)",
        )

    def handshake(self, timeout: float = 30.0) -> None:
        """The cell is up: the consumer's job status heard and its ready."""
        self.wait(
            lambda: self.jobs() and self.ready[-1:] and self.ready[-1][1] == "ready",
            timeout,
            "the consumer's job status (role consumer) and its ready on winder/ready",
        )


@pytest.fixture
def cell(procs: Procs, ros: Any, tmp_path: Path) -> Cell:
    return Cell(procs, ros, tmp_path)


def check_done(cell: Cell, run_id: str, total: int, report: Status) -> None:
    """A complete run's final report (CONTRACT.md §3.7) and receipts."""
    v = report.values
    assert v["state"] == "done", f"run {run_id} ended {v['state']}: {report.message}"
    assert int(v["steps_done"]) == int(v["steps_total"]) == total, v
    assert v.get("steps_missing") == "0", v
    assert v.get("errors", "0") == "0", f"stream errors in run {run_id}: {report.message}"
    assert "bag" in v, f"the final report has no bag key: {v}"
    if v["bag"]:  # the bag is closed before the report is announced
        assert bag_closed(Path(v["bag"])), f"bag {v['bag']} not closed at the final report"
    cell.wait(lambda: cell.taken(run_id) == total, 5, f"the receipts of run {run_id} to reach {total}")


# -- the checks ---------------------------------------------------------------------------


def test_handshake(cell: Cell, consumer: ConsumerSpec) -> None:
    """Alone, the consumer reports a job status with the common keys and role
    consumer, and does not say ready; once the profile node's stream is
    matched it says ready on winder/ready, repeated every second."""
    cell.start_consumer(consumer, name="axes")
    cell.wait(
        lambda: any(s.name.endswith(": job") for s in cell.statuses), 30, "a job status of the consumer"
    )
    cell.pause_for(2.0)
    jobs = [s for s in cell.statuses if s.name.endswith(": job")]
    for s in jobs:
        keys = list(s.values)
        assert keys[: len(STATUS_KEYS)] == list(STATUS_KEYS), (
            f"{s.name}: keys {keys}, want {STATUS_KEYS} first"
        )
        assert s.values.get(ROLE_KEY) == "consumer", f"{s.name}: no role: consumer ({s.values})"
        assert keys[len(STATUS_KEYS)] == ROLE_KEY, f"{s.name}: role must follow the common keys: {keys}"
        assert s.name == "axes: job", f"status named {s.name!r}: the node runs as axes"
    assert not any(v == "ready" for _, v in cell.ready), f"ready with no stream matched: {cell.ready}"
    t_up = time.monotonic()
    cell.start_upstream()
    cell.wait(lambda: cell.ready_since(t_up), 30, "the consumer's ready once the step stream is matched")
    first = next(t for t, v in cell.ready if v == "ready")
    cell.wait(
        lambda: sum(1 for t, v in cell.ready if v == "ready" and t > first) >= 2,
        5,
        "the consumer's ready repeated every second",
    )
    assert {s.values["state"] for s in cell.jobs()} <= {"idle"}, [s.values for s in cell.jobs()]


def test_a_whole_job(cell: Cell, consumer: ConsumerSpec) -> None:
    """A small job to done: winder/state running -> done, receipts up to the
    total, the final report done with every step and a bag key, ready again."""
    cell.start_consumer(consumer, name="axes")
    cell.start_upstream(JOB)
    cell.handshake()
    run_id, total = cell.start()
    report = cell.ends(run_id)
    check_done(cell, run_id, total, report)
    assert cell.cell_states(run_id) == ["running", "done"], cell.cell_states(run_id)
    busy = next((t for t, v in cell.ready if v == "busy"), None)
    assert busy is not None, f"the consumer never said busy during the run: {cell.ready}"
    cell.wait(lambda: cell.ready_since(busy), 5, "the consumer's ready after the run")


def test_pause_and_resume(cell: Cell, paced: ConsumerSpec) -> None:
    """~/pause: pausing, paused (no step executed while at rest, no stall
    reported); ~/resume: running; the run completes with every step."""
    cell.start_consumer(paced)
    cell.start_upstream()
    cell.handshake()
    run_id, total = cell.start()
    cell.running(run_id, 200)
    reply = cell.call("pause")
    assert reply.success and "pausing" in reply.message, reply.message
    cell.wait(lambda: cell.cell_states(run_id)[-1:] == ["paused"], 10, "winder/state paused")
    cell.pause_for(0.3)
    at_rest = cell.taken(run_id)
    cell.pause_for(1.5)  # longer than stall_timeout: a pause at rest is no stall
    assert cell.taken(run_id) == at_rest, f"steps executed while paused: {at_rest} -> {cell.taken(run_id)}"
    assert at_rest < total
    reply = cell.call("resume")
    assert reply.success and "resuming" in reply.message, reply.message
    report = cell.ends(run_id)
    check_done(cell, run_id, total, report)
    assert cell.cell_states(run_id) == ["running", "pausing", "paused", "running", "done"]
    node = cell.node()
    stalls = [
        s.message for s in cell.statuses if s.name.startswith(node + ":") and "stall" in s.message.lower()
    ]
    assert not stalls, f"a pause was reported as a stall: {stalls}"
    assert report.values.get("stalls", "0") == "0", report.values


def test_abort_then_ready_and_a_second_job(cell: Cell, paced: ConsumerSpec) -> None:
    """~/abort: aborting, aborted; the final report aborted after the abort's
    steps; ready again, and a second job starts and completes."""
    cell.start_consumer(paced, name="axes")
    cell.start_upstream()
    cell.handshake()
    run_id, total = cell.start()
    cell.running(run_id, 200)
    reply = cell.call("abort")
    assert reply.success and "aborting" in reply.message, reply.message
    report = cell.ends(run_id)
    v = report.values
    assert v["state"] == "aborted", f"run {run_id} ended {v['state']}: {report.message}"
    [abort] = [e for e in cell.events if e.get("event") == "abort" and e.get("run_id") == run_id]
    assert int(v["steps_done"]) + int(v["steps_missing"]) == abort["steps"] < total, (v, abort)
    assert cell.cell_states(run_id) == ["running", "aborting", "aborted"], cell.cell_states(run_id)
    cell.wait(
        lambda: cell.ready_since(report.t - 1.0) and cell.ready[-1][1] == "ready",
        5,
        "the consumer's ready after the abort",
    )
    second, total2 = cell.start(timeout=10)
    check_done(cell, second, total2, cell.ends(second))


def test_a_wind_goal_canceled_then_one_wound(cell: Cell, paced: ConsumerSpec) -> None:
    """The cell's Wind action (winder/wind) in front of this consumer: a
    goal's run canceled mid-job ends CANCELED, its result the consumer's
    aborted report; the next goal winds its part, SUCCEEDED, its result the
    consumer's final report and its bag."""
    from action_msgs.msg import GoalStatus
    from rclpy.action import ActionClient

    from winder_interfaces.action import Wind

    cell.start_consumer(paced, name="axes")
    cell.start_upstream()
    cell.handshake()
    client = ActionClient(cell.ros, Wind, "/winder/wind")
    cell.wait(client.server_is_ready, 30, "the interp node's Wind action server")

    def goal(job: dict[str, Any]) -> tuple[Any, Any, list[Any]]:
        feedback: list[Any] = []
        overrides = [f"{k}={v}" for k, v in job.items()]
        sent = client.send_goal_async(Wind.Goal(overrides=overrides), lambda m: feedback.append(m.feedback))
        cell.wait(sent.done, 30, "the goal's acceptance")
        assert sent.result().accepted
        return sent.result(), sent.result().get_result_async(), feedback

    handle, ending, feedback = goal(LONG_JOB)
    cell.wait(lambda: any(f.steps_done >= 200 for f in feedback), 30, "feedback of 200 steps executed")
    run_id = feedback[-1].run_id
    handle.cancel_goal_async()
    cell.wait(ending.done, 30, f"the end of the canceled goal of run {run_id}")
    answer = ending.result()
    report = cell.ends(run_id)  # the probe hears the final report by its own subscription
    assert answer.status == GoalStatus.STATUS_CANCELED, answer.result.message
    assert report.values["state"] == "aborted" == answer.result.report.state
    assert (
        answer.result.report.steps_done == int(report.values["steps_done"]) < answer.result.report.steps_total
    )
    assert "aborting" in cell.cell_states(run_id), cell.cell_states(run_id)
    handle, ending, feedback = goal(JOB)
    cell.wait(ending.done, 30, "the end of the second goal")
    answer = ending.result()
    assert answer.status == GoalStatus.STATUS_SUCCEEDED, answer.result.message
    result = answer.result
    report = cell.ends(result.run_id)
    check_done(cell, result.run_id, result.report.steps_total, report)
    assert (result.report.steps_done, result.bag_path) == (
        int(report.values["steps_done"]),
        report.values["bag"],
    )


def test_a_start_while_busy_is_refused(cell: Cell, paced: ConsumerSpec) -> None:
    """~/start during a run: refused with the reason; the run goes on to done."""
    cell.start_consumer(paced)
    cell.start_upstream()
    cell.handshake()
    run_id, total = cell.start()
    cell.running(run_id, 200)
    reply = cell.call("start")
    assert not reply.success, f"a second start during run {run_id} was accepted: {reply.message}"
    assert run_id in reply.message and "is running" in reply.message, reply.message
    check_done(cell, run_id, total, cell.ends(run_id))


def test_a_stall_is_reported_and_the_run_closed(cell: Cell, paced: ConsumerSpec) -> None:
    """The profile node stopped (SIGSTOP) mid-run: an ERROR mentioning the
    stall within stall_timeout, the run closed incomplete after stall_abort
    (winder/state failed); once the profile node goes on (SIGCONT), the
    consumer is ready and the cell takes the next start at once (CONTRACT.md
    5.3): the consumer's final report ends the run for the interp node too,
    which gave it up only after its own stall_abort (30 s here, its default)
    without receipts before ("job ... is running (11/3072 steps taken)")."""
    stall = {"stall_timeout": 0.5, "stall_abort": 2.0}
    cell.start_consumer(paced, stall=stall)
    cell.start_upstream(stall_abort=30.0)
    cell.handshake()
    run_id, _ = cell.start()
    cell.running(run_id, 500)
    assert cell.profile is not None
    node = cell.node()
    cell.profile.send_signal(signal.SIGSTOP)
    t_stop = time.monotonic()
    try:

        def stall_error() -> Status | None:
            return next(
                (
                    s
                    for s in cell.statuses
                    if s.name.startswith(node + ":")
                    and s.level == 2
                    and "stall" in s.message.lower()
                    and s.t > t_stop
                ),
                None,
            )

        cell.wait(
            stall_error, stall["stall_timeout"] + 2 * SLACK, "an ERROR status of the consumer on the stall"
        )
        error = stall_error()
        assert error is not None
        # promptly in the node's own time: a stretch in which it did not run at all (its 1 Hz
        # report not heard for over a second, a starved machine) is not the node's delay
        starved = max(0.0, cell.silence_s(t_stop - 1.0, error.t) - 1.0)
        assert error.t - t_stop <= stall["stall_timeout"] + SLACK + starved, (
            f"stall reported after {error.t - t_stop:.1f} s: {error.message!r}; "
            f"{cell.silence(t_stop - 1.0, error.t)}"
        )
        report = cell.ends(run_id, stall["stall_abort"] + 3 * SLACK)
        after = report.t - t_stop
        assert report.values["state"] == "incomplete", f"run {run_id} ended {report.values['state']}"
        starved = max(0.0, cell.silence_s(t_stop - 1.0, report.t) - 1.0)
        assert stall["stall_abort"] - 0.2 <= after <= stall["stall_abort"] + 2 * SLACK + starved, (
            f"closed {after:.1f} s in; {cell.silence(t_stop - 1.0, report.t)}"
        )
        assert int(report.values["steps_done"]) < int(report.values["steps_total"])
        assert cell.cell_states(run_id)[-1:] == ["failed"], cell.cell_states(run_id)
    finally:
        cell.profile.send_signal(signal.SIGCONT)
    cell.wait(
        lambda: cell.ready_since(report.t - 1.0) and cell.ready[-1][1] == "ready",
        10,
        "the consumer's ready after the stalled run",
    )
    # taken, not refused "is running" (start() asks again only while the cell says "not ready":
    # the profile node's word, stale after its stop, comes again within a second)
    second, total2 = cell.start(timeout=10)

    def given_up() -> list[str]:  # the interp node's side: the run ended by the consumer's report
        return [
            s.message
            for s in cell.statuses
            if s.name == "interp_node: job"
            and s.values.get("run_id") == run_id
            and s.values["state"] == "incomplete"
        ]

    cell.wait(given_up, 5, f"the interp node's status of run {run_id} given up")
    assert "its consumer closed the run" in given_up()[0], given_up()
    check_done(cell, second, total2, cell.ends(second))


def test_a_killed_consumer_restarted(cell: Cell, paced: ConsumerSpec) -> None:
    """SIGKILL the consumer mid-run and start it again: the interp node gives
    the run up after its stall_abort, and the cell starts and completes a new job."""
    proc = cell.start_consumer(paced, name="axes")
    cell.start_upstream()
    cell.handshake()
    run_id, _ = cell.start()
    cell.running(run_id, 200)
    proc.kill()
    proc.wait()
    cell.start_consumer(paced)
    cell.given_up(run_id)
    second, total2 = cell.start(timeout=30)
    check_done(cell, second, total2, cell.ends(second))


def test_status_keys_final_report_and_names(cell: Cell, consumer: ConsumerSpec) -> None:
    """Run as ``axes``: every job status has the common keys, then role
    consumer; the final report has the contract's consumer keys and says
    what the run was, and is repeated; statuses and winder/state are named
    after the node it runs as."""
    cell.start_consumer(consumer, name="axes")
    cell.start_upstream(JOB)
    cell.handshake()
    run_id, total = cell.start()
    report = cell.ends(run_id)
    check_done(cell, run_id, total, report)
    cell.wait(
        lambda: len([s for s in cell.jobs(run_id) if s.values.get("state") == "done"]) >= 2,
        5,
        "the final report repeated",
    )
    for s in cell.jobs():
        keys = list(s.values)
        assert keys[: len(STATUS_KEYS) + 1] == [*STATUS_KEYS, ROLE_KEY], f"{s.name}: {keys}"
        assert s.name == "axes: job", s.name
        if s.values["state"] == "running":
            assert s.values["run_id"] == run_id and s.values["steps_total"] == str(total), s.values
    v = report.values
    missing = [k for k in CONSUMER_KEYS if k not in v]
    assert not missing, f"the final report lacks {missing}: {v}"
    assert (v["job_id"], v["run_id"]) == (JOB["job_id"], run_id), v
    assert (v["gaps"], v["chunks_rejected"], v["errors"], v["stalls"]) == ("0", "0", "0", "0"), v
    assert v["progress"] == "1.0000", v
    assert report.level == 0, f"a clean run's final report is not OK: [{report.level}] {report.message}"
    assert report.message.startswith(f"job {JOB['job_id']}: complete, {total}/{total} steps"), report.message
    names = {name for _, name, _ in cell.states}  # the node each CellState names
    assert names == {"axes"}, names
    for _, _, values in cell.states:
        assert values["job_id"] in ("", JOB["job_id"]) and values["state"], values
    assert not [s.name for s in cell.statuses if "sim_node" in s.name], "a status still named sim_node"


# -- the interp node and a consumer that ignores aborts ---------------------------------------


def test_a_consumer_that_ignores_the_abort_does_not_wedge_the_cell(cell: Cell) -> None:
    """test/consumers/naive_consumer.py follows the topic contract but not
    winder/control: after ~/abort it stays busy. A start is refused at first
    ("consumer busy"); once it has said busy for the interp node's
    stall_abort after the run ended, the interp node reports it once (ERROR
    status, log line) and the next start goes ahead: the naive consumer takes
    the new run and completes it."""
    # the interp node gives a run up after stall_abort without receipts: long enough that a
    # loaded machine's pause in the naive consumer's receipts does not end the run before the
    # abort does (at 1.5 s a parallel run under load saw 'given up', never 'aborted')
    stall_abort = 3.0
    cell.start_consumer(NAIVE)
    # the consumer acknowledges steps as it executes them: a small window keeps
    # the run being timed while it goes on, so ~/abort has something to stop
    cell.start_upstream(stall_abort=stall_abort, max_in_flight=1024, chunk_steps=256)
    cell.handshake()
    run_id, total = cell.start()
    cell.wait(
        lambda: any(s.values["state"] == "running" for s in cell.jobs(run_id)) and cell.taken(run_id) >= 200,
        20,
        f"run {run_id} running at the naive consumer",
    )
    reply = cell.call("abort")
    assert reply.success and "aborting" in reply.message, reply.message

    def interp_aborted() -> Status | None:
        return next(
            (
                s
                for s in cell.statuses
                if s.name == "interp_node: job"
                and s.values.get("run_id") == run_id
                and s.values.get("state") == "aborted"
            ),
            None,
        )

    cell.wait(interp_aborted, 10, f"the interp node to end run {run_id} on the abort")
    ended = interp_aborted()
    assert ended is not None
    refused = cell.call("start")
    assert not refused.success and "consumer busy" in refused.message, (
        f"{refused.message}\n{cell.announcers()}\n{cell.logs()}"
    )
    assert cell.taken(run_id) < total and cell.jobs(run_id)[-1].values["state"] == "running"

    def verdict() -> list[Status]:
        return [
            s
            for s in cell.statuses
            if s.name == "interp_node: job" and s.level == 2 and "ignores the abort" in s.message
        ]

    cell.wait(verdict, stall_abort + 3 * SLACK, "the interp node's ERROR on the ignored abort")
    first = verdict()[0]
    assert (first.values["run_id"], first.values["state"]) == (run_id, "aborted"), first.values
    want = f"the consumer ignores the abort of run {run_id}: still busy"
    assert want in first.message and "docs/CONTRACT.md" in first.message, first.message
    assert first.t - ended.t >= stall_abort - 1.0, f"reported {first.t - ended.t:.1f} s after the run ended"
    assert cell.ready[-1][1] == "busy", cell.ready[-5:]  # the consumer still says busy
    second, total2 = cell.start(timeout=5)
    cell.wait(
        lambda: any(s.values.get("state") == "done" for s in cell.jobs(second)),
        20,
        f"the naive consumer to complete run {second}",
    )
    cell.wait(lambda: cell.taken(second) == total2, 5, f"the receipts of run {second} to reach {total2}")
    assert cell.interp is not None
    lines = [ln for ln in cell.procs.log(cell.interp).splitlines() if "ignores the abort" in ln]
    assert len(lines) == 1 and "ERROR" in lines[0] and run_id in lines[0], lines
    # it publishes no winder/sim_config: not waited for, not warned about; its steps are paced
    # on the profile node's wall clock (said once a run, at INFO), so an abort has a run to stop
    assert cell.profile is not None
    said = [ln for ln in cell.procs.log(cell.profile).splitlines() if "sim_config" in ln]
    assert said and all("[INFO]" in ln and "paced on the wall clock" in ln for ln in said), said


#: a run long enough to abort late in it (16384 steps, about 4.2 s at RAMP)
ABORT_JOB = {**JOB, "turns_per_layer": 16}


@pytest.mark.parametrize("subject", [*PACED, NAIVE], ids=[c.id for c in [*PACED, NAIVE]])
def test_an_abort_is_honoured_until_the_axes_rest(cell: Cell, subject: ConsumerSpec) -> None:
    """Late in a real-time run (over 60 % of its steps executed), with the
    cell's default window and look-ahead, ~/abort is honoured: the consumer
    executes the abort's braking steps and no step beyond them, and (if it
    follows winder/control) ends the run aborted. The naive consumer sends
    no winder/sim_config: the profile node paces its steps on its wall
    clock, so the abort has a run to stop there too (it used to be sent the
    whole run at once and refuse the abort: "no run is being timed")."""
    cell.start_consumer(subject)
    cell.start_upstream(ABORT_JOB)
    cell.handshake()
    run_id, total = cell.start()
    # (winder/state comes from a StepConsumer; the naive consumer's receipts say it runs)
    cell.wait(lambda: cell.taken(run_id) >= total * 0.6, 20, f"60 % of run {run_id} acknowledged")
    reply = cell.call("abort")
    assert reply.success and "aborting" in reply.message, f"{reply.message}\n{cell.logs()}"
    cell.wait(
        lambda: [e for e in cell.events if e.get("event") == "abort" and e.get("run_id") == run_id],
        10,
        f"the abort of run {run_id} on winder/control",
    )
    [abort] = [e for e in cell.events if e.get("event") == "abort" and e.get("run_id") == run_id]
    assert abort["steps"] < total, abort
    if subject is NAIVE:  # it ignores winder/control: it executes what it is sent, and nothing more comes
        cell.wait(lambda: cell.taken(run_id) == abort["steps"], 10, f"the receipts of run {run_id}'s abort")
        cell.pause_for(1.0)
    else:
        report = cell.ends(run_id)
        v = report.values
        assert v["state"] == "aborted", f"run {run_id} ended {v['state']}: {report.message}"
        assert int(v["steps_done"]) + int(v["steps_missing"]) == abort["steps"], (v, abort)
    assert cell.taken(run_id) <= abort["steps"], (cell.taken(run_id), abort)


def test_an_abort_ends_aborted_when_its_braking_steps_were_not_sent_yet(cell: Cell) -> None:
    """As fast as possible, an abort takes effect at the last step the profile
    node has timed and brakes on steps after it; with a window smaller than
    the job the interp node has not sent them yet. It sends them (up to the
    abort's steps, nothing beyond): the sim node ends the run aborted at rest,
    not incomplete after a stall."""
    cell.start_consumer(
        ConsumerSpec("sim_node", ("sim_node",)), stall={"stall_timeout": 1.0, "stall_abort": 5.0}
    )
    cell.start_upstream({**JOB, "turns_per_layer": 400}, max_in_flight=16384, chunk_steps=4096)
    cell.handshake()
    run_id, total = cell.start()
    cell.wait(lambda: cell.taken(run_id) >= 4096, 20, f"run {run_id} under way")
    reply = cell.call("abort")
    assert reply.success and "aborting" in reply.message, reply.message
    report = cell.ends(run_id)
    [abort] = [e for e in cell.events if e.get("event") == "abort" and e.get("run_id") == run_id]
    v = report.values
    assert v["state"] == "aborted", f"run {run_id} ended {v['state']}: {report.message}"
    assert int(v["steps_done"]) == abort["steps"] < total and v["steps_missing"] == "0", (v, abort)
