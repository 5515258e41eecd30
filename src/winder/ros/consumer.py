"""``StepConsumer``: everything a node behind the step stream owes the cell,
written once, around an :class:`winder.ros.engine.Engine` that executes the
rows. The simulator (``sim_node``: ``SimEngine``), the ros2_control bridge
(``bridge_node``: ``BridgeEngine``) and a hardware driver
(:class:`winder.ros.driver.DriverNode`: the drive engine around a driver's
:class:`winder.ros.driver.Backend`) are each this class with an engine.

What it does (docs/CONTRACT.md, "What a consumer must do"):

* handshake: ``winder/ready`` (role ``consumer``): ``ready`` once the step
  stream's publisher is matched and the node is active and its settings
  valid, ``busy`` during a run, ``blocked`` / ``inactive`` / ``waiting``
  otherwise; repeated every second;
* run identity: a run starts with its description on ``winder/job``; chunks
  and events that arrive before it are kept for it, others dropped;
* stream checks (:class:`winder.contract.stream.StreamChecker`: gaps,
  repeats, reordering; step times that do not increase or lie beyond a job's
  longest duration), each reported once as an ERROR;
* late steps: a step timed before the engine's clock (``Engine.earliest_step_ns``)
  is executed at the clock, never refused, and counted
  (:class:`winder.contract.pacing.LateSteps`): one ERROR per run, once
  they stopped coming, and ``late_steps`` in the job report;
* receipts on ``winder/progress`` (the interp node's flow control and its
  sign that the job is over): steps executed plus steps known missing;
* operator events on ``winder/control`` (pause, resume, abort, override) and
  the job's programmed stops, booked in a :class:`winder.contract.run.RunLedger`
  and announced on ``winder/state`` as execution reaches them; an abort ends
  the run once its steps are executed;
* the stall watch: no steps for ``stall_timeout`` s is reported, for
  ``stall_abort`` s closes the run incomplete (so a consumer never wedges
  the cell);
* ``/diagnostics``: the ``<node>: job`` status every second, with the
  contract's keys (:class:`winder.contract.run.JobReport`), and the final
  report when the run closes;
* recording (optional, parameter ``record``): a rosbag2/MCAP directory per
  run holding the contract's topics and the engine's own, closed before
  the final report is announced.

What the engine does (:class:`winder.ros.engine.Engine`: its hooks, and the
run it sees through :class:`winder.ros.engine.RunPort`): set the axes up
when a run begins, execute the accepted rows (now or as they fall due),
tell what it executed and how far the run's time went, settle the axes,
end. The lifecycle starts when the node is made, with its engine attached.
"""

from __future__ import annotations

import json
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Int64MultiArray, String
from trajectory_msgs.msg import JointTrajectory

from winder.contract.params import PROFILE_SPECS
from winder.contract.run import ControlEvent, EventError, JobReport, RunLedger, Transition
from winder.contract.states import CellState, EventKind, JobState, ReadyState
from winder.contract.stream import JobPlan, StreamChecker, parse_job_description
from winder.contract.topics import (
    TOPIC_CONTROL,
    TOPIC_DIAGNOSTICS,
    TOPIC_JOB,
    TOPIC_PATH,
    TOPIC_PROFILE_CONFIG,
    TOPIC_PROGRESS,
    TOPIC_SIM_CONFIG,
    TOPIC_STATE,
    TOPIC_STEP_TIMES,
    status_values,
)
from winder.contract.trust import Intruders
from winder.record.bag import (
    signals_held,
)
from winder.ros.diagnostics import ERROR, OK, WARN, Diagnostics
from winder.ros.engine import Engine
from winder.ros.intake import EarlyChunks, RowGate
from winder.ros.managed import ManagedNode
from winder.ros.peers import Peers, Solo
from winder.ros.qos import QOS_EVENTS, QOS_LATCHED, QOS_LATCHED_READER, QOS_STATE, QOS_STREAM
from winder.ros.ready import Announcer
from winder.ros.run_bag import RunBag, one_line
from winder.ros.sender import attributed, waiting
from winder.ros.settings import Settings
from winder.ros.timers import steady_timer
from winder.spec import Spec

__all__ = ["CONSUMER_TOPICS", "StepConsumer"]

#: s of wall time the steps wait for the job's path and profile config (so the bag has them first)
PATH_WAIT = 2.0
#: As fast as possible, chunks are gathered and handed over together (one
#: backend call for many costs less): up to BATCH_CHUNKS of them, at most
#: BATCH_STEPS steps, waiting at most BATCH_WAIT wall seconds for the first.
BATCH_STEPS = 1 << 16
BATCH_CHUNKS = 8
BATCH_WAIT = 0.01
#: the contract's topics every consumer's bag holds: key -> (name, type)
CONSUMER_TOPICS = {
    "job": (TOPIC_JOB, "std_msgs/msg/String"),
    "path": (TOPIC_PATH, "trajectory_msgs/msg/JointTrajectory"),
    "step_times": (TOPIC_STEP_TIMES, "std_msgs/msg/Int64MultiArray"),
    "sim_config": (TOPIC_SIM_CONFIG, "std_msgs/msg/String"),
    "profile_config": (TOPIC_PROFILE_CONFIG, "std_msgs/msg/String"),
    "diagnostics": (TOPIC_DIAGNOSTICS, "diagnostic_msgs/msg/DiagnosticArray"),
    "state": (TOPIC_STATE, "diagnostic_msgs/msg/DiagnosticStatus"),
    "control": (TOPIC_CONTROL, "std_msgs/msg/String"),
}


class StepConsumer(ManagedNode):
    """The consumer half of the cell (see the module doc). ``specs`` must
    hold :data:`winder.contract.params.CONSUMER_SPECS`; ``topics`` are the
    backend's own recorded topics, key -> (name, type)."""

    def __init__(
        self,
        name: str,
        specs: dict[str, Spec],
        check: Callable[[dict[str, Any]], None],
        engine: Engine,
        *,
        hardware_id: str,
        topics: dict[str, tuple[str, str]] | None = None,
    ) -> None:
        super().__init__(name)
        self.engine = engine
        self.settings = Settings(self, specs, check)
        self.diag = Diagnostics(self, hardware_id)
        self.hardware_id = hardware_id
        self.pub_progress = self.create_publisher(KeyValue, TOPIC_PROGRESS, QOS_STATE)
        self.pub_cell_state = self.create_publisher(DiagnosticStatus, TOPIC_STATE, QOS_LATCHED)
        self.pub_config = (
            self.create_publisher(String, TOPIC_SIM_CONFIG, QOS_LATCHED) if self.engine.configures else None
        )
        self.ready = Announcer(self, "consumer", recheck=self.announce)
        # a job description starts a run now: volatile, so a consumer that
        # (re)starts never takes the last run's latched description for a new
        # run; "ready" waits for this subscription's match too (announce())
        # every message acted on is taken with its publisher, and acted on only
        # when that is the cell's node owning the topic (winder.ros.peers)
        self.peers = Peers(self)
        # one consumer per cell; the statuses it takes are recorded (on_diagnostics)
        self.solo = Solo(self, "consumer", self.peers, self.leave, also=self.on_diagnostics)
        self.solo.on_settled = self.settled
        self.job_waiting: bytes | None = None  # a job description that came before the node settled
        self.sub_job = attributed(
            self,
            String,
            TOPIC_JOB,
            self.on_job,
            # volatile: a description latched before this node came is not a run of its own;
            # deep: see QOS_LATCHED_READER
            QoSProfile(
                depth=QOS_LATCHED_READER.depth,
                reliability=ReliabilityPolicy.RELIABLE,
                durability=DurabilityPolicy.VOLATILE,
            ),
            event_callbacks=SubscriptionEventCallbacks(matched=lambda _info: self.announce()),
        )
        attributed(self, JointTrajectory, TOPIC_PATH, self.on_path, QOS_LATCHED_READER)
        attributed(self, String, TOPIC_PROFILE_CONFIG, self.on_profile_config, QOS_LATCHED_READER)
        self.sub_control = attributed(self, String, TOPIC_CONTROL, self.on_control, QOS_EVENTS)
        self.sub_times = attributed(
            self,
            Int64MultiArray,
            TOPIC_STEP_TIMES,
            self.on_step_times,
            QOS_STREAM,
            # the handshake follows the stream's connection as it happens, not by polling
            event_callbacks=SubscriptionEventCallbacks(matched=lambda _info: self.announce()),
        )
        # pump() runs on events (a chunk, a job) and, while work waits on the
        # clock (pacing, batching), every 5 ms; idle, only the 1 Hz report runs
        self.pump_timer = steady_timer(self, self.engine.pump_period, self.pump)
        # a chunk or event held until the graph named its sender is acted on
        # later, from the peers' retry timer: the pump must run then too, or
        # the chunk would wait in the inbox for the next event
        self.peers.on_late = self.pump
        steady_timer(self, 0.5, self.watch)
        steady_timer(self, 1.0, self.report)
        self.recording = RunBag(self, self.peers, {**CONSUMER_TOPICS, **(topics or {})}, self.error)
        self.plan: JobPlan | None = None
        self.reset()
        self.early = EarlyChunks(self.get_logger().warning)  # chunks that came between runs
        self.early_events: deque[bytes] = deque(maxlen=100)  # winder/control of a run not started here yet
        self.last_report: JobReport | None = None
        self.last_level, self.last_text = OK, ""
        self.cell_state(CellState.IDLE, "no job yet")
        if self.settings.blocked():
            self.diag.publish(
                "job", ERROR, str(self.settings.blocked()), status_values(JobState.BLOCKED, role="consumer")
            )
        else:
            self.recording.check_dir(self.settings.values())
        engine.attach(self, self)
        self.start_lifecycle()

    # -- lifecycle (winder.ros.managed) ----------------------------------------
    def in_run(self) -> bool:
        return self.plan is not None

    def blocked_reason(self) -> str | None:
        return self.settings.blocked()

    def lifecycle_changed(self) -> None:
        self.announce()

    def reset(self) -> None:
        """Forget the last run."""
        self.plan = None
        self.ledger: RunLedger | None = None
        self.gate: RowGate | None = None  # the run's chunks into rows
        self.checker: StreamChecker | None = None  # the gate's stream checks
        self.t_ns = 0  # execution time reached (ns) since the run's start
        self.wall0_ns = time.time_ns()  # wall-clock time of the run's start: the bag's time base
        self.recording.start(None, self.wall0_ns)
        self.inbox: deque[bytes] = deque()  # received chunks waiting to be executed
        self.inbox_since = time.monotonic()
        self.job_wall = time.monotonic()
        self.finishing = False
        self.last_chunk_wall = time.monotonic()
        self.start_wall = time.monotonic()
        self.stalled = False
        self.stalls = 0
        self.longest_stall = 0.0  #: the longest time without steps while the run waited on them (s)
        self.errors: list[str] = []
        self.foreign = 0  # control messages of the run refused

    # -- a run starts -----------------------------------------------------------
    def on_job(self, raw: bytes, gid: bytes) -> None:
        self.peers.deliver(TOPIC_JOB, gid, raw, self.take_job)

    def settled(self) -> None:
        """The node knows it is the cell's only consumer (winder.ros.peers.Solo):
        say ready, and take a job description that came before."""
        raw, self.job_waiting = self.job_waiting, None
        if raw is not None:
            self.take_job(raw)
        self.announce()

    def take_job(self, raw: bytes) -> None:
        """A run's description from the cell's interp node."""
        if not self.solo.settled():  # not sure yet to be the cell's only consumer: kept till it is
            self.job_waiting = raw
            return
        try:
            plan = parse_job_description(deserialize_message(raw, String).data)
        except Exception as exc:  # ValueError, or not even a String
            self.error(f"job description rejected: {one_line(exc)}")
            return
        if self.plan is not None and plan.run_id and plan.run_id == self.plan.run_id:
            return  # the running run's own description again: it cannot restart it
        if not self.active:
            self.error(f"job {plan.job_id} refused: {self.inactive_reason()}")
            return
        if self.plan is not None and self.finishing:
            # every step of the last run is executed, it only settles: it closes complete now
            self.engine.flush()
            self.finish(complete=True)
        elif self.plan is not None:
            self.error(
                f"job {plan.job_id} arrived while {self.plan.job_id} runs: "
                "the running job is closed incomplete"
            )
            self.finish(complete=False)
        blocked = self.settings.blocked()
        if blocked:
            self.error(f"job {plan.job_id} refused: {blocked}")
            return
        values = self.settings.values()
        self.reset()
        self.peers.run = Intruders()
        self.plan = plan
        self.recording.start(plan, self.wall0_ns)
        self.ledger = RunLedger(plan)
        self.gate = RowGate(plan, self.error)
        self.checker = self.gate.checker
        self.announce()
        config = self.engine.begin(plan, values)
        if config is None and self.pub_config is not None:
            # a backend that configures nothing still says whether it paces: the profile node
            # waits for this word while the consumer publishes on winder/sim_config
            config = {"real_time": self.engine.paces()}
        config_raw = b""
        if config is not None and self.pub_config is not None:
            doc = {**config, "run_id": plan.run_id, "wall_start_ns": self.wall0_ns}
            if plan.source_bag:  # a re-simulation (winder resim) names the recording its steps come from
                doc.update(source_bag=plan.source_bag, source_run_id=plan.source_run_id)
            msg_config = String(data=json.dumps(doc))
            self.pub_config.publish(msg_config)
            config_raw = serialize_message(msg_config)
        if values["record"]:
            why = self.recording.open(values, raw, config_raw, self.engine.unrecorded())
            if why:
                self.error(f"job {plan.job_id} runs unrecorded: {why}")
        self.job_wall = time.monotonic()
        self.recording.record_path(self.t_ns)
        self.recording.record_profile_config(self.t_ns)
        self.get_logger().info(
            f"run {plan.run_id or '-'}: job {plan.job_id}, {plan.total_steps} steps"
            + (f", recording to {self.recording.path}" if self.recording.path else "")
        )
        self.cell_state(CellState.RUNNING, f"run {plan.run_id or plan.job_id} started", where=(1, 1, 0))
        self.report()  # the run is on: its status at once, not at the next second
        events, self.early_events = list(self.early_events), deque(maxlen=100)
        for event in events:  # the run's own events that came before its description; others dropped
            self.handle_control(event, early=True)
        early = self.early.take(plan)
        # the stall watch counts from now, the run set up (its plan, its bag):
        # on a machine starting other cells that alone took over 2 s
        self.last_chunk_wall = time.monotonic()
        for chunk in early:  # in order, before any taken from the queue
            self.receive(chunk)
        self.pump()

    def on_path(self, raw: bytes, gid: bytes) -> None:
        self.peers.deliver(TOPIC_PATH, gid, raw, self.take_path)

    def take_path(self, raw: bytes) -> None:
        self.recording.take_path(raw, self.t_ns)

    def on_profile_config(self, raw: bytes, gid: bytes) -> None:
        self.peers.deliver(TOPIC_PROFILE_CONFIG, gid, raw, self.take_profile_config)

    def take_profile_config(self, raw: bytes) -> None:
        self.recording.take_profile_config(raw, self.t_ns)
        self.engine.profile_config_heard()

    # -- operator events --------------------------------------------------------
    def on_control(self, raw: bytes, gid: bytes) -> None:
        self.peers.deliver(TOPIC_CONTROL, gid, raw, self.handle_control)
        self.pump()

    def handle_control(self, raw: bytes, *, early: bool = False) -> None:
        """An operator event (winder/control) of the running run: booked,
        recorded, its states announced as execution reaches them. Events of a
        run not started here yet are kept for it; anything that does not
        parse, or contradicts the run, changes nothing (reported once)."""
        try:
            event = ControlEvent.from_wire(deserialize_message(raw, String).data)
        except Exception:  # EventError, or not even a String: no event to act on
            return
        if self.plan is None or self.ledger is None or event.run_id != self.plan.run_id:
            # the profile node may speak of a run before its description is
            # here (a schedule is published as the run starts): kept for it
            if not early:
                self.early_events.append(raw)
            return
        try:
            self.ledger.apply(event)
        except EventError as exc:
            self.foreign += 1
            if self.foreign == 1:
                self.get_logger().warning(f"winder/control: event refused: {exc}")
            return
        self.record("control", self.t_ns, raw)  # when it was heard; its own times are inside
        if event.kind is EventKind.OVERRIDE:
            self.get_logger().info(f"feed override {event.factor} from {event.t_ns / 1e9:.6f} s")

    def take_control(self) -> None:
        """Operator events already here, before any step is executed: the
        executor may serve a busy step stream first, and an event must not
        come after the steps it times (the profile node sends it first)."""
        for raw, gid in waiting(self.sub_control):
            self.peers.deliver(TOPIC_CONTROL, gid, raw, self.handle_control)

    # -- the step stream --------------------------------------------------------
    def on_step_times(self, raw: bytes, gid: bytes) -> None:
        self.peers.deliver(TOPIC_STEP_TIMES, gid, raw, self.receive)
        for more, sender in waiting(self.sub_times):  # the chunks queued behind it, in one go
            self.peers.deliver(TOPIC_STEP_TIMES, sender, more, self.receive)
        self.pump()

    def receive(self, raw: bytes) -> None:
        if self.plan is None or self.checker is None or self.finishing:
            self.early.keep(raw)
            return
        self.last_chunk_wall = time.monotonic()
        if self.stalled:
            self.stalled = False
            self.get_logger().info("step stream resumed")
        self.record("step_times", self.t_ns, raw)  # the bag keeps the stream as it arrived
        if not self.inbox:
            self.inbox_since = time.monotonic()
        self.inbox.append(raw)

    def accept(self, raw: bytes) -> npt.NDArray[np.int64] | None:
        """The rows of a chunk that may be executed, or None (reported)."""
        assert self.gate is not None and self.ledger is not None
        if self.early.is_twin(raw):
            self.get_logger().info("the run's first chunk came again: the earlier one was the last run's")
            return None
        rows = self.gate.rows(raw, self.engine.earliest_step_ns())
        if rows is None:
            return None
        seg = int(rows[0, 1])
        self.engine.checked(seg, rows)
        index = self.gate.checker.step_index(seg, rows[:, 2:]) if self.ledger.has_stops else None
        if self.ledger.note_rows(seg, rows[:, 0], index):
            self.engine.resume_pacing()
        return rows

    def pump(self) -> None:
        """Do the work that is due; keep the 5 ms timer running while work
        waits on the clock (pacing, batching, the path), stop it when there
        is none: an idle node wakes only for its 1 Hz report."""
        self.take_control()
        if self.plan is not None:
            self._work()
        engine = self.engine
        if self.plan is not None and (self.inbox or engine.holding() or engine.pending() or self.finishing):
            if self.engine.pump_from_last or self.pump_timer.is_canceled():
                self.pump_timer.reset()
        else:
            self.pump_timer.cancel()

    def _work(self) -> None:
        now = time.monotonic()
        if self.inbox and not self.recording.has_plan_documents and now - self.job_wall < PATH_WAIT:
            return  # hold the steps briefly: the bag should have path and ramp before they run
        batching = self.engine.batches()
        gather = batching and 0 < len(self.inbox) < BATCH_CHUNKS and now - self.inbox_since < BATCH_WAIT
        while self.inbox and not gather and not self.finishing and self.engine.accepts_more():
            batch: list[npt.NDArray[np.int64]] = []
            size = 0
            while self.inbox and size < BATCH_STEPS:
                rows = self.accept(self.inbox.popleft())
                if rows is not None:
                    batch.append(rows)
                    size += rows.shape[0]
                if not batching:
                    break
            if batch:
                self.engine.execute(np.concatenate(batch) if len(batch) > 1 else batch[0])
                # the stall clock counts waiting for steps, not executing them: a batch the
                # nonlinear model took seconds over is no stall of the stream
                self.last_chunk_wall = time.monotonic()
            self.receipt()
        late = self.gate.late.report() if self.gate else ""  # once a run, when they stopped coming
        if late:
            self.error(late)
        if not self.inbox:  # the run's last chunk may have been dropped, not executed
            self.settle_if_complete()
        self.engine.work()
        if self.plan is not None and self.finishing and not self.engine.pending():
            self.finish(complete=True)
        if self.recording.failure and self.plan is not None:
            self.finish(complete=False)

    def settle_if_complete(self) -> None:
        """Once every step of the run is executed or counted missing (or the
        abort's rest is reached): the axes settle, then the run closes."""
        if self.checker is None or self.ledger is None or self.finishing or self.engine.holding():
            return
        self.ledger.missing_steps = self.checker.missing
        if not (self.checker.complete or self.ledger.aborted):
            return
        assert self.gate is not None
        self.engine.settle(max(self.gate.last_executed_ns, 0))
        self.finishing = True

    # -- the engine's view of the run (winder.ros.engine.RunPort) ----------------------
    def values(self) -> dict[str, Any]:
        return self.settings.values()

    def rest_ns(self) -> int | None:
        hold = self.ledger.hold if self.ledger is not None else None
        return hold.rest_ns if hold is not None else None

    def transitions_ahead(self) -> bool:
        return self.ledger is not None and bool(self.ledger.transitions_ahead)

    def abort_booked(self) -> bool:
        return self.ledger is not None and self.ledger.abort is not None

    @property
    def last_step_ns(self) -> int:
        return self.gate.last_step_ns if self.gate is not None else -1

    def chunks_waiting(self) -> bool:
        return bool(self.inbox)

    def run_ramp(self) -> dict[str, Any] | None:
        raw, plan = self.recording.profile_raw, self.plan
        if raw is None or plan is None:
            return None
        doc = json.loads(deserialize_message(raw, String).data)
        if (doc.get("job_id"), doc.get("run_id", "")) != (plan.job_id, plan.run_id):
            return None  # an earlier run's: this run's is on its way
        return {k: doc[k] for k in (*PROFILE_SPECS, "feed_override") if k in doc}

    def bag_topic(self, key: str) -> str:
        return self.recording.topics[key][0]

    def set_bag_topic(self, key: str, name: str, kind: str) -> None:
        self.recording.topics[key] = (name, kind)

    def executed(self, n: int) -> None:
        """``n`` more steps of the run are executed."""
        if self.ledger is not None:
            self.ledger.executed(n)

    def reached(self, t_ns: int) -> None:
        """Execution reached ``t_ns`` (since the run's start): announce what is due."""
        self.t_ns = t_ns
        if self.ledger is not None:
            for t in self.ledger.due(t_ns):
                self.transition(t)

    def transition(self, t: Transition) -> None:
        """A state of the run reached: on winder/state, and (a programmed stop) on /diagnostics."""
        assert self.plan is not None
        if not t.stop:
            self.cell_state(t.state, f"run {self.plan.run_id}: {t.text}", where=t.place, t_ns=t.t_ns)
            return
        self.cell_state(t.state, t.text, where=t.place, t_ns=t.t_ns)
        values = self.job_report(JobState(t.state)).to_values()
        values["stop"] = t.stop
        self.publish_status("job", OK, f"run {self.plan.run_id}: {t.text}", values, t_ns=t.t_ns)

    @property
    def at_rest(self) -> bool:
        """Paused by the operator, every step up to the rest executed."""
        return self.ledger is not None and self.ledger.at_rest and not self.finishing

    # -- reports ------------------------------------------------------------------
    def job_report(self, state: JobState) -> JobReport:
        assert self.plan is not None and self.checker is not None
        return JobReport(
            state,
            self.plan.job_id,
            self.plan.run_id,
            self.ledger.executed_steps if self.ledger else 0,
            self.plan.total_steps,
            steps_missing=self.checker.missing,
            gaps=self.checker.gaps,
            chunks_rejected=self.checker.rejected,
            sim_time_s=self.t_ns / 1e9,
            wall_time_s=time.monotonic() - self.start_wall,
            bag=str(self.recording.path.resolve()) if self.recording.path else "",
            errors=len(self.errors),
            stalls=self.stalls,
            extra={
                **({"longest_stall_s": f"{self.longest_stall:.1f}"} if self.stalls else {}),
                **{k: str(v) for k, v in self.engine.details().items()},
                **(self.gate.late.keys() if self.gate else {}),
                **self.intruder_keys(),
                **self.event_keys(),
            },
        )

    def event_keys(self) -> dict[str, str]:
        """How many operator events the run booked (``operator_events``), if any."""
        events = self.ledger.events if self.ledger else 0
        return {"operator_events": str(events)} if events else {}

    def intruder_keys(self) -> dict[str, str]:
        """The run's refused messages, if any: ``foreign_messages`` and who sent them."""
        run = self.peers.run
        return {"foreign_messages": str(run.total), "intruders": run.summary()} if run.total else {}

    def aborted(self) -> bool:
        """The run was aborted and every step up to the rest is executed."""
        return self.ledger is not None and self.ledger.aborted and not self.recording.failure

    def final_report(self, complete: bool) -> tuple[JobReport, int, str]:
        """The run's final status: report, level and message. A run whose
        recording failed is not complete, whatever the stream did."""
        assert self.plan is not None
        if self.ledger is not None and self.checker is not None:
            self.ledger.missing_steps = self.checker.missing
        aborted = self.aborted()
        complete = complete and not self.recording.failure and not aborted
        report = self.job_report(
            JobState.DONE if complete else (JobState.ABORTED if aborted else JobState.INCOMPLETE)
        )
        faults = self.engine.faults()
        ok = (complete or aborted) and not self.errors and not faults
        level = OK if ok else (WARN if complete or aborted else ERROR)
        state = "complete" if complete else ("aborted, the axes at rest" if aborted else "incomplete")
        text = f"job {self.plan.job_id}: {state}, {report.steps_done}/{self.plan.total_steps} steps"
        if self.errors:
            text += f", {len(self.errors)} stream errors (first: {self.errors[0]})"
        if faults:
            text += f", {faults}"
        return report, level, text

    def finish(self, complete: bool) -> None:
        """End the run: final report into the bag, close it, then announce it.
        Signals wait meanwhile, so a Ctrl-C cannot split the three."""
        if self.plan is None:
            return
        if complete and not self.engine.complete():
            complete = False
        self.engine.closing()
        self.take_control()  # the run's last events go into its bag
        late = self.gate.late.report(closing=True) if self.gate else ""  # still coming late at the close
        if late:
            self.error(late)
        with signals_held():
            self._finish(complete)

    def _finish(self, complete: bool) -> None:
        assert self.plan is not None
        report, level, text = self.final_report(complete)
        job = self.plan.job
        ended = {JobState.DONE: CellState.DONE, JobState.ABORTED: CellState.ABORTED}.get(
            JobState(report.state), CellState.FAILED
        )
        final_coil = job.coil(job.poles - 1)
        last = (
            (job.poles, final_coil.layers, job.turns_of(job.poles - 1))
            if ended is CellState.DONE
            else (0, 0, 0)
        )
        self.cell_state(ended, text, where=last)
        final = self.diag.status("job", level, text, report.to_values())
        bag = self.recording.path
        if bag is not None:
            # the final report goes into the bag too, and the bag is closed
            # before anyone hears "done": whoever stops us then finds it complete
            self.record("diagnostics", self.t_ns, serialize_message(final))
            self.recording.close()
            if self.recording.failure:  # left unclosed: winder bag recover reads it
                report, level, text = self.final_report(complete)  # no longer complete
                final = self.diag.status("job", level, text, report.to_values())
        if self.context.ok():
            self.get_logger().info(text + (f"; bag {bag}" if bag else ""))
        self.last_report, self.last_level, self.last_text = report, level, text
        self.plan = None
        self.finishing = False
        self.recording.start(None, self.wall0_ns)
        self.engine.end()
        if self.context.ok():  # at Ctrl-C the context is already shut down
            self.announce()  # ready first: whoever hears "done" can start the next run at once
            self.diag.pub.publish(final)

    def cell_state(
        self, state: CellState, text: str, where: tuple[int, int, int] = (0, 0, 0), t_ns: int | None = None
    ) -> None:
        """winder/state: the cell's state at a transition, latched, and into the bag."""
        plan = self.plan
        t = self.t_ns if t_ns is None else t_ns
        coil, layer, turn = where
        values = {
            "state": state,
            "job_id": plan.job_id if plan else "",
            "run_id": plan.run_id if plan else "",
            "coil": coil,
            "layer": layer,
            "turn": turn,
            "sim_time_s": f"{t / 1e9:.6f}",
        }
        msg = DiagnosticStatus(
            level=bytes([ERROR if state == CellState.FAILED else OK]),
            name=f"{self.get_fully_qualified_name().lstrip('/')}: state",
            message=text,
            hardware_id=self.hardware_id,
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()],
        )
        if plan is not None:
            self.record("state", t, serialize_message(msg))
        if self.context.ok():
            self.pub_cell_state.publish(msg)

    def record(self, key: str, t_ns: int, data: bytes, *, exact: bool = False) -> None:
        """One message into the run's bag, if it records. A failed write (a
        full disk) stops the recording; pump() then closes the run incomplete."""
        self.recording.record(key, t_ns, data, exact=exact)

    def error(self, why: str) -> None:
        self.errors.append(why)
        self.get_logger().error(why)
        plan = self.plan
        self.publish_status(
            "stream",
            ERROR,
            why,
            {"job_id": plan.job_id if plan else "", "run_id": plan.run_id if plan else ""},
        )

    def on_diagnostics(self, raw: bytes, gid: bytes, statuses: list[Any]) -> None:
        """The statuses of this cell's nodes, into the run's bag (the messages
        Solo takes on /diagnostics)."""
        self.recording.statuses(raw, gid, [st.name for st in statuses], self.t_ns)

    def publish_status(
        self, task: str, level: int, text: str, values: dict[str, object], *, t_ns: int | None = None
    ) -> None:
        """A status of this node on /diagnostics, and into the run's bag at
        once: an ERROR raised just before the run closes is in its bag too."""
        status = self.diag.status(task, level, text, values)
        self.record("diagnostics", self.t_ns if t_ns is None else t_ns, serialize_message(status))
        if self.context.ok():  # at a shutdown the bag still gets it: the run's end must not raise here
            self.diag.pub.publish(status)

    def watch(self) -> None:
        """The stall watch (every 0.5 s)."""
        if self.plan is None or self.ledger is None or self.finishing:
            return
        # step chunks held until the graph names their sender (winder.ros.peers) are work that is here
        held = bool(self.peers.held.get(TOPIC_STEP_TIMES))
        busy = bool(self.inbox) or self.engine.holding() or self.engine.pending() or held
        if (self.ledger.waiting_for_resume or self.ledger.held) and not busy:
            self.last_chunk_wall = time.monotonic()
            for t in self.ledger.reach_stops():  # the axes are at the stop: say so
                self.transition(t)
            return
        if busy:
            self.last_chunk_wall = time.monotonic()  # work already here: not a stall
            return
        idle = time.monotonic() - self.last_chunk_wall
        settings = self.settings.values()
        done = f"{self.ledger.executed_steps}/{self.plan.total_steps}"
        if not self.stalled and idle > settings["stall_timeout"]:
            # reported at once and while it lasts (report()); a stall that ends
            # with nothing lost does not fail the run, so it is not an error().
            # Reported before a close too: a watch that comes late still says it
            self.stalled = True
            self.stalls += 1
            why = f"step stream stalled: no steps for {idle:.1f} s at {done} steps"
            if not self.engine.paces():
                why += " (as fast as possible: nothing waits on the steps; the run fails if steps are lost)"
            elif not self.checker or not self.checker.done:
                why += " (none yet: the axes wait at rest, the run's time has not started)"
            self.get_logger().warning(why)
            self.publish_status(
                "stream", self.stall_level(), why, {"job_id": self.plan.job_id, "run_id": self.plan.run_id}
            )
        if self.stalled:
            self.longest_stall = max(self.longest_stall, idle)
        if idle > settings["stall_abort"]:
            self.error(f"step stream stalled for {idle:.1f} s at {done} steps: job closed incomplete")
            self.finish(complete=False)

    def stall_level(self) -> int:
        """How bad a stall is while it lasts: in real time the axes run out of
        steps (ERROR); as fast as possible nothing waits on them, and a run
        that then completes lost nothing (WARN: the summary counts it); nor
        before the run's first step, whose time has not started: the axes
        wait at rest (a profile node that took 3 s to plan a long job on a
        loaded machine made an aborted run exit 1, 'failed', make flakes)."""
        if not self.checker or not self.checker.done:
            return WARN
        return ERROR if self.engine.paces() else WARN

    def receipt(self) -> None:
        """The steps of the run executed so far, or known missing, on
        winder/progress: the interp node's flow control (at most max_in_flight
        steps sent and not yet executed) and its sign that the run is over;
        repeated by report(), the sign this node is alive while it paces a
        real-time run. Refused chunks do not count: they were never the run's."""
        if self.plan is not None and self.checker is not None and self.ledger is not None:
            self.ledger.missing_steps = self.checker.missing
            self.pub_progress.publish(
                KeyValue(key=self.plan.run_id or self.plan.job_id, value=str(self.ledger.accounted))
            )

    def announce(self) -> None:
        """Tell the interp node whether a run can start here (winder/ready):
        ready once the step times' and the job description's publishers are
        matched, so neither the run's description nor a chunk of it can go
        out before this node hears it."""
        if self.plan is not None:
            state = ReadyState.BUSY
        elif self.settings.blocked():
            state = ReadyState.BLOCKED
        elif not self.active:
            state = ReadyState.INACTIVE
        else:
            heard = self.sub_times.get_publisher_count() > 0 and self.sub_job.get_publisher_count() > 0
            # and it can tell the cell's own interp and profile node from anyone else
            known = heard and self.solo.settled() and not self.peers.knows("interp", "profile")
            state = ReadyState.READY if known and not self.engine.missing() else ReadyState.WAITING
        self.ready.announce(state)

    def report(self) -> None:
        """The 1 Hz report: readiness again, and the job status."""
        self.announce()
        self.ready.repeat()
        if self.plan is None or self.ledger is None:
            if self.last_report is not None:  # keep telling how the last run ended, as a status does
                self.diag.publish("job", self.last_level, self.last_text, self.last_report.to_values())
            else:
                why = self.settings.blocked()
                values = status_values(JobState.BLOCKED if why else JobState.IDLE, role="consumer")
                self.diag.publish("job", ERROR if why else OK, why or "idle: waiting for a job", values)
            return
        self.receipt()
        state = (
            JobState.STALLED
            if self.stalled
            else (JobState.PAUSED if self.ledger.at_stop else JobState.RUNNING)
        )
        if self.ledger.op_state is not None and not self.stalled:
            state = JobState(self.ledger.op_state)
        self.publish_status(
            "job",
            self.stall_level() if self.stalled else OK,
            f"run {self.plan.run_id or self.plan.job_id}: {state}",
            self.job_report(state).to_values(),
        )

    def shutdown(self) -> None:
        """Close the bag of a running run (Ctrl-C, SIGTERM, SIGHUP): closed,
        readable by every reader, the run marked incomplete. The bag is closed
        even when the run's books cannot be (the context went down under
        them): its file must not stay without a summary. (A SIGKILL runs
        nothing here: its bag is left unclosed, for ``winder bag recover``.)"""
        bag = self.recording.recorder
        try:
            if self.plan is not None and bag is not None:
                self.finish(complete=False)
        finally:
            if bag is not None and bag.is_open:
                try:
                    bag.close()
                except (RuntimeError, OSError) as exc:  # left unclosed: winder bag recover reads it
                    self.get_logger().error(
                        f"bag {bag.path}: {one_line(exc)}; left unclosed: `winder bag recover {bag.path}` "
                        "writes it out closed"
                    )
            # a thread of the engine's still running holds the node: its destruction waits for
            # the interpreter's teardown, which the process must then not skip (winder.ros.spin)
            self.let_go = self.engine.shutdown()
