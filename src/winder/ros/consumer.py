"""``StepConsumer``: everything a node behind the step stream owes the cell,
written once, around an :class:`winder.ros.engine.Engine` that executes the
rows. The simulator (``sim_node``: ``SimEngine``), the ros2_control bridge
(``bridge_node``: ``BridgeEngine``) and a hardware driver
(:class:`winder.ros.driver.DriverNode`: the drive engine around a driver's
:class:`winder.ros.driver.Backend`) are each this class with an engine.

The node (docs/CONTRACT.md, "What a consumer must do") does the graph's part:

* handshake: ``winder/ready`` (role ``consumer``): ``ready`` once the step
  stream's and the job description's publishers are matched, the node
  active and its settings valid, ``busy`` during a run, ``blocked`` /
  ``inactive`` / ``waiting`` otherwise; repeated every second;
* trust: it acts only on the cell's own interp and profile nodes
  (:mod:`winder.ros.peers`), and is the cell's only consumer;
* run identity: a run starts with its description on ``winder/job``; chunks
  and events that arrive before it are kept for it, others dropped;
* intake: operator events on ``winder/control`` and the job's programmed
  stops booked; chunks checked (:class:`winder.ros.intake.RowGate`: gaps,
  repeats, reordering, times; each reported once as an ERROR) and handed to
  the engine, gathered in batches when it runs as fast as possible; a step
  timed before the engine's clock (``Engine.earliest_step_ns``) executed at
  the clock, never refused, and counted;
* recording (optional, parameter ``record``): a rosbag2/MCAP directory per
  run holding the contract's topics and the engine's own.

The run's part - its books, receipts, states, settling, the stall watch,
reports and the close - is :class:`winder.ros.consumer_run.ConsumerRun`,
which is also all the engine sees of the run (``RunPort``). The lifecycle
starts when the node is made, with its engine attached.
"""

from __future__ import annotations

import json
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Int64MultiArray, String
from trajectory_msgs.msg import JointTrajectory

from winder.contract.run import ControlEvent, EventError, JobReport
from winder.contract.states import CellState, EventKind, JobState, ReadyState
from winder.contract.stream import JobPlan
from winder.contract.topic_table import EVERY, recorded
from winder.contract.topics import (
    TOPIC_CONTROL,
    TOPIC_JOB,
    TOPIC_PATH,
    TOPIC_PROFILE_CONFIG,
    TOPIC_SIM_CONFIG,
    TOPIC_STEP_TIMES,
    status_values,
)
from winder.ros.consumer_run import ConsumerRun
from winder.ros.diagnostics import ERROR
from winder.ros.engine import Engine
from winder.ros.intake import EarlyChunks
from winder.ros.interfaces import job_plan
from winder.ros.managed import ManagedNode
from winder.ros.peers import Peers, Solo
from winder.ros.qos import QOS_EVENTS, QOS_LATCHED, QOS_LATCHED_READER, QOS_STREAM
from winder.ros.ready import Announcer
from winder.ros.run_bag import RunBag, one_line
from winder.ros.sender import attributed, waiting
from winder.ros.settings import Settings
from winder.ros.timers import steady_timer
from winder.spec import Spec
from winder_interfaces.msg import ControlEvent as ControlEventMsg
from winder_interfaces.msg import JobDescription

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
CONSUMER_TOPICS = recorded(EVERY)


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
        self.pub_config = (
            self.create_publisher(String, TOPIC_SIM_CONFIG, QOS_LATCHED) if self.engine.configures else None
        )
        #: the last run's winder/sim_config (its run id, the message), said again until its steps come
        self.config_msg: tuple[str, String] | None = None
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
            JobDescription,
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
        self.sub_control = attributed(self, ControlEventMsg, TOPIC_CONTROL, self.on_control, QOS_EVENTS)
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
        self.recording = RunBag(
            self, self.peers, {**CONSUMER_TOPICS, **(topics or {})}, lambda why: self.run.error(why)
        )
        #: the run: its books, reports and close, and all the engine sees of it
        self.run = ConsumerRun(
            self,
            engine,
            self.settings,
            self.recording,
            self.peers,
            hardware_id=hardware_id,
            announce=self.announce,
            pump=self.pump,
            take_control=self.take_control,
        )
        steady_timer(self, 0.5, self.run.watch)
        steady_timer(self, 1.0, self.report)
        self.early = EarlyChunks(self.get_logger().warning)  # chunks that came between runs
        self.early_events: deque[bytes] = deque(maxlen=100)  # winder/control of a run not started here yet
        self.run.cell_state(CellState.IDLE, "no job yet")
        if self.settings.blocked():
            self.run.diag.publish(
                "job", ERROR, str(self.settings.blocked()), status_values(JobState.BLOCKED, role="consumer")
            )
        else:
            self.recording.check_dir(self.settings.values())
            self.run.recover_parts(self.settings.values())
        engine.attach(self, self.run)
        told = self.restart.carried_for(self) if self.restart is not None else None
        if told is not None:  # how the run the held process closed ended (winder.ros.rejoin)
            self.run.told_again(told)
        self.start_lifecycle()

    @property
    def plan(self) -> JobPlan | None:
        """The running run's description; None between runs."""
        return self.run.plan

    @property
    def last_report(self) -> JobReport | None:
        """How the last run ended."""
        return self.run.last_report

    def handover(self) -> dict[str, Any] | None:
        """For the process that replaces this one (winder.ros.rejoin): how the
        run it closed at the restart ended; None if it closed none."""
        if not self.restarting or self.run.last_report is None:
            return None
        values = {k: str(v) for k, v in self.run.last_report.to_values().items()}
        return {"values": values, "level": int(self.run.last_level), "text": self.run.last_text}

    # -- lifecycle (winder.ros.managed) ----------------------------------------
    def in_run(self) -> bool:
        return self.plan is not None

    def blocked_reason(self) -> str | None:
        return self.settings.blocked()

    def lifecycle_changed(self) -> None:
        self.announce()

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
            plan = job_plan(raw)
        except Exception as exc:  # ValueError, or not even a JobDescription
            self.run.error(f"job description rejected: {one_line(exc)}")
            return
        if self.plan is not None and plan.run_id and plan.run_id == self.plan.run_id:
            return  # the running run's own description again: it cannot restart it
        if not self.active:
            self.run.error(f"job {plan.job_id} refused: {self.inactive_reason()}")
            return
        if self.plan is not None and self.run.finishing:
            # every step of the last run is executed, it only settles: it closes complete now
            self.engine.flush()
            self.run.finish(complete=True)
        elif self.plan is not None:
            self.run.error(
                f"job {plan.job_id} arrived while {self.plan.job_id} runs: "
                "the running job is closed incomplete"
            )
            self.run.finish(complete=False)
        blocked = self.settings.blocked()
        if blocked:
            self.run.error(f"job {plan.job_id} refused: {blocked}")
            return
        values = self.settings.values()
        self.run.start(plan)
        self.announce()
        config = self.engine.begin(plan, values)
        if config is None and self.pub_config is not None:
            # a backend that configures nothing still says whether it paces: the profile node
            # waits for this word while the consumer publishes on winder/sim_config
            config = {"real_time": self.engine.paces()}
        config_raw = b""
        if config is not None and self.pub_config is not None:
            doc = {**config, "run_id": plan.run_id, "wall_start_ns": self.run.wall0_ns}
            if plan.source_bag:  # a re-simulation (winder resim) names the recording its steps come from
                doc.update(source_bag=plan.source_bag, source_run_id=plan.source_run_id)
            msg_config = String(data=json.dumps(doc))
            self.pub_config.publish(msg_config)
            self.config_msg = (plan.run_id, msg_config)
            config_raw = serialize_message(msg_config)
        if values["record"]:
            why = self.recording.open(values, raw, config_raw, self.engine.unrecorded())
            if why:
                self.run.error(f"job {plan.job_id} runs unrecorded: {why}")
        self.run.begin_part(values)
        self.run.job_wall = time.monotonic()
        self.recording.record_path(self.run.t_ns)
        self.recording.record_profile_config(self.run.t_ns)
        self.get_logger().info(
            f"run {plan.run_id or '-'}: job {plan.job_id}, {plan.total_steps} steps"
            + (f", recording to {self.recording.path}" if self.recording.path else "")
        )
        self.run.cell_state(CellState.RUNNING, f"run {plan.run_id or plan.job_id} started", where=(1, 1, 0))
        self.report()  # the run is on: its status at once, not at the next second
        events, self.early_events = list(self.early_events), deque(maxlen=100)
        for event in events:  # the run's own events that came before its description; others dropped
            self.handle_control(event, early=True)
        early = self.early.take(plan)
        # the stall watch counts from now, the run set up (its plan, its bag):
        # on a machine starting other cells that alone took over 2 s
        self.run.last_chunk_wall = time.monotonic()
        for chunk in early:  # in order, before any taken from the queue
            self.receive(chunk)
        self.pump()

    def on_path(self, raw: bytes, gid: bytes) -> None:
        self.peers.deliver(TOPIC_PATH, gid, raw, self.take_path)

    def take_path(self, raw: bytes) -> None:
        self.recording.take_path(raw, self.run.t_ns)

    def on_profile_config(self, raw: bytes, gid: bytes) -> None:
        self.peers.deliver(TOPIC_PROFILE_CONFIG, gid, raw, self.take_profile_config)

    def take_profile_config(self, raw: bytes) -> None:
        self.recording.take_profile_config(raw, self.run.t_ns)
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
        run = self.run
        try:
            event = ControlEvent.from_message(deserialize_message(raw, ControlEventMsg))
        except Exception:  # EventError, or not even a ControlEvent: no event to act on
            return
        if self.plan is None or run.ledger is None or event.run_id != self.plan.run_id:
            # the profile node may speak of a run before its description is
            # here (a schedule is published as the run starts): kept for it
            if not early:
                self.early_events.append(raw)
            return
        try:
            run.ledger.apply(event)
        except EventError as exc:
            run.foreign += 1
            if run.foreign == 1:
                self.get_logger().warning(f"winder/control: event refused: {exc}")
            return
        run.record("control", run.t_ns, raw)  # when it was heard; its own times are inside
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
        run = self.run
        if self.plan is None or run.checker is None or run.finishing:
            self.early.keep(raw)
            return
        run.last_chunk_wall = time.monotonic()
        if self.early.is_twin(raw):
            # the same bytes as the first chunk, taken from before the run's description (the
            # last run's of the same job, closed early here): in the bag once, executed once
            self.get_logger().info("the run's first chunk came again: the earlier one was the last run's")
            return
        if run.stalled:
            run.stalled = False
            self.get_logger().info("step stream resumed")
        run.record("step_times", run.t_ns, raw)  # the bag keeps the stream as it arrived
        if not run.inbox:
            run.inbox_since = time.monotonic()
        run.inbox.append(raw)

    def accept(self, raw: bytes) -> npt.NDArray[np.int64] | None:
        """The rows of a chunk that may be executed, or None (reported)."""
        run = self.run
        assert run.gate is not None and run.ledger is not None
        rows = run.gate.rows(raw, self.engine.earliest_step_ns())
        if rows is None:
            return None
        seg = int(rows[0, 1])
        self.engine.checked(seg, rows)
        index = run.gate.checker.step_index(seg, rows[:, 2:]) if run.ledger.has_stops else None
        if run.ledger.note_rows(seg, rows[:, 0], index):
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
        if self.plan is not None and (
            self.run.inbox or engine.holding() or engine.pending() or self.run.finishing
        ):
            if self.engine.pump_from_last or self.pump_timer.is_canceled():
                self.pump_timer.reset()
        else:
            self.pump_timer.cancel()

    def _work(self) -> None:
        run = self.run
        now = time.monotonic()
        if run.inbox and not self.recording.has_plan_documents and now - run.job_wall < PATH_WAIT:
            return  # hold the steps briefly: the bag should have path and ramp before they run
        batching = self.engine.batches()
        gather = batching and 0 < len(run.inbox) < BATCH_CHUNKS and now - run.inbox_since < BATCH_WAIT
        while run.inbox and not gather and not run.finishing and self.engine.accepts_more():
            batch: list[npt.NDArray[np.int64]] = []
            size = 0
            while run.inbox and size < BATCH_STEPS:
                rows = self.accept(run.inbox.popleft())
                if rows is not None:
                    batch.append(rows)
                    size += rows.shape[0]
                if not batching:
                    break
            if batch:
                self.engine.execute(np.concatenate(batch) if len(batch) > 1 else batch[0])
                # the stall clock counts waiting for steps, not executing them: a batch the
                # nonlinear model took seconds over is no stall of the stream
                run.last_chunk_wall = time.monotonic()
            run.receipt()
        late = run.gate.late.report() if run.gate else ""  # once a run, when they stopped coming
        if late:
            run.error(late)
        if not run.inbox:  # the run's last chunk may have been dropped, not executed
            run.settle_if_complete()
        self.engine.work()
        if self.plan is not None and run.finishing and not self.engine.pending():
            run.finish(complete=True)
        if self.recording.failure and self.plan is not None:
            run.finish(complete=False)

    def on_diagnostics(self, raw: bytes, gid: bytes, statuses: list[Any]) -> None:
        """The statuses of this cell's nodes, into the run's bag (the messages
        Solo takes on /diagnostics)."""
        self.recording.statuses(raw, gid, [st.name for st in statuses], self.run.t_ns)

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
            why = []
            if self.sub_times.get_publisher_count() == 0:
                why.append("no publisher of winder/step_times matched")
            if self.sub_job.get_publisher_count() == 0:
                why.append("no publisher of winder/job matched")
            if not self.solo.settled():
                why.append("not yet known to be the cell's only consumer")
            # and it can tell the cell's own interp and profile node from anyone else
            unknown = self.peers.knows("interp", "profile")
            if unknown:
                why.append(unknown)
            missing = "" if why else self.engine.missing()  # asked of a cell that is there (it logs)
            if missing:
                why.append(missing)
            state = ReadyState.WAITING if why else ReadyState.READY
            self.ready.announce(state, "; ".join(why))
            return
        self.ready.announce(state)

    def report(self) -> None:
        """The 1 Hz report: readiness again, the run's configuration again
        while none of its steps has come (the profile node waits for it: one
        lost under load, or refused while the graph did not name this node
        yet, held the run's steps back until this node gave the run up), and
        the job status."""
        config, plan = self.config_msg, self.plan
        waits = plan is not None and config is not None and config[0] == plan.run_id
        if waits and config is not None and self.pub_config is not None and self.run.last_step_ns < 0:
            self.pub_config.publish(config[1])
        self.announce()
        self.ready.repeat()
        self.run.report()

    def shutdown(self) -> None:
        """Close the bag of a running run (Ctrl-C, SIGTERM, SIGHUP): closed,
        readable by every reader, the run marked incomplete. The bag is closed
        even when the run's books cannot be (the context went down under
        them): its file must not stay without a summary. (A SIGKILL runs
        nothing here: its bag is left unclosed, for ``winder bag recover``.)"""
        bag = self.recording.recorder
        try:
            if self.plan is not None and bag is not None:
                if self.restarting:  # held past the DDS lease (winder.ros.rejoin): the run's error
                    self.run.error(self.restarting)
                self.run.finish(complete=False)
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
