"""sim_node: timed step commands -> simulated axes, /clock and an MCAP bag.

In:  winder/job (String, latched), winder/path (JointTrajectory, latched),
     winder/step_times (Int64MultiArray), /diagnostics (recorded),
     parameters: model, per-axis motor (``<axis>.J`` ...), output rate, pacing.
Out: winder/state (DiagnosticStatus, latched: the cell's state at each
     transition), /clock, winder/joint_commands and winder/joint_states (JointState at
     ``publish_rate`` Hz of simulated time), winder/sim_config (String, latched,
     the motor parameters in force), /diagnostics, and a rosbag2/MCAP
     directory ``<bag_dir>/<run id>`` holding all of them.

Time: /clock is the cell's simulated time. It never goes backwards in the
node's life: each job starts at the simulated time the last one ended (a
sample period later); the step times in the messages stay relative to their
job's start, and ``winder/sim_config`` records where the job starts on the
clock (``clock_origin_ns``). Joint states are stamped with /clock. In the bag,
a message's log time is the wall-clock time at which the job started plus the
simulated time since then, so every viewer shows the recording at its real
date and durations in simulated time; ``wall_start_ns`` in sim_config is that
start.

Each axis is a stepper driven through ``winder.axis``: the linear model is
exact between steps, the nonlinear one integrates the sine torque and reports
lost steps. The simulation advances to the time of the last step received and
never beyond, so /clock never runs ahead of the commands.
"""

from __future__ import annotations

import json
import math
import time
from collections import deque
from typing import Any

import numpy as np
import numpy.typing as npt
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Int64MultiArray, String
from trajectory_msgs.msg import JointTrajectory

from winder.axis import StepperAxis
from winder.contract.cdr import JointStateEncoder, encode_clocks
from winder.contract.eq7 import layer_of_samples, sample_deviation, step_deviation
from winder.contract.params import (
    MAX_JOB_SECONDS,
    MOTOR_FIELDS,
    SIM_SPECS,
    bag_directory,
    check_sim,
    stop_place,
)
from winder.contract.stream import TIMED_COLUMNS, JobPlan, StreamChecker, parse_job_description
from winder.contract.topics import (
    TOPIC_CLOCK,
    TOPIC_CONTROL,
    TOPIC_DIAGNOSTICS,
    TOPIC_JOB,
    TOPIC_JOINT_COMMANDS,
    TOPIC_JOINT_STATES,
    TOPIC_PATH,
    TOPIC_PROFILE_CONFIG,
    TOPIC_PROGRESS,
    TOPIC_SIM_CONFIG,
    TOPIC_STATE,
    TOPIC_STEP_TIMES,
    in_namespace,
    status_values,
)
from winder.motion.job import AXES
from winder.record.bag import BagRecorder, new_bag_path, run_bag_path, signals_held
from winder.ros.chunks import TIMED_CDR, waiting
from winder.ros.diagnostics import ERROR, OK, WARN, Diagnostics
from winder.ros.managed import ManagedNode
from winder.ros.qos import QOS_CLOCK, QOS_DIAGNOSTICS, QOS_EVENTS, QOS_LATCHED, QOS_STATE, QOS_STREAM
from winder.ros.ready import Announcer
from winder.ros.settings import Settings
from winder.ros.spin import spin
from winder.ros.timers import steady_timer

PATH_WAIT = 2.0  # s of wall time the steps wait for the job's path and profile config
# Running ahead of time, chunks are gathered and simulated together (one tracker
# call for many costs much less): up to BATCH_CHUNKS of them, at most
# BATCH_STEPS steps, waiting at most BATCH_WAIT wall seconds for the first.
BATCH_STEPS = 1 << 16
BATCH_CHUNKS = 8
BATCH_WAIT = 0.01
#: Samples simulated in one go, at most: the node's memory is bounded by this,
#: never by the simulated time a batch of steps covers (at 1 step/s, a chunk of
#: 8192 steps spans 8192 s: 1.6 million samples at 200 Hz).
SAMPLE_BATCH = 1 << 15
#: Step times beyond the longest a job may last are refused, not simulated.
MAX_STEP_NS = round(MAX_JOB_SECONDS * 1e9)
BAG_TYPES = {
    "job": "std_msgs/msg/String",
    "path": "trajectory_msgs/msg/JointTrajectory",
    "step_times": "std_msgs/msg/Int64MultiArray",
    "joint_states": "sensor_msgs/msg/JointState",
    "joint_commands": "sensor_msgs/msg/JointState",
    "sim_config": "std_msgs/msg/String",
    "profile_config": "std_msgs/msg/String",
    "clock": "rosgraph_msgs/msg/Clock",
    "diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
    "state": "diagnostic_msgs/msg/DiagnosticStatus",
    "control": "std_msgs/msg/String",
}


def one_line(exc: BaseException) -> str:
    return (str(exc).splitlines() or [type(exc).__name__])[0]


def make_axis(values: dict[str, Any], axis: str) -> StepperAxis:
    return StepperAxis(**{k: values[f"{axis}.{k}"] for k in ("Zr", "L", "i_a", "J", "D")})


class AxisSim:
    """One simulated axis: motor tracker + what is needed to convert units."""

    def __init__(self, motor: StepperAxis, model: str, load: float, step_angle: float, joint_step: float):
        self.motor = motor
        self.tracker: Any = motor.linear_tracker() if model == "linear" else motor.nonlinear_tracker(load)
        self.step_angle = step_angle  # motor rad per step
        self.joint_step = joint_step  # joint unit per step
        self.position = 0  # commanded step position after the last step received
        self.last_step_t = -math.inf  # time of this axis' last step (s)
        self.last_dir = 0.0  # its direction
        self.last_dt = math.inf  # and the interval before it (s)
        self.max_error_steps = 0.0

    @property
    def lost_steps(self) -> int:
        return int(getattr(self.tracker, "lost_steps", 0))


class SimNode(ManagedNode):
    def __init__(self) -> None:
        super().__init__("sim_node")
        self.settings = Settings(self, SIM_SPECS, check_sim)

        self.pub_clock = self.create_publisher(Clock, TOPIC_CLOCK, QOS_CLOCK)
        self.pub_state = self.create_publisher(JointState, TOPIC_JOINT_STATES, QOS_STATE)
        self.pub_cmd = self.create_publisher(JointState, TOPIC_JOINT_COMMANDS, QOS_STATE)
        self.pub_config = self.create_publisher(String, TOPIC_SIM_CONFIG, QOS_LATCHED)
        self.pub_progress = self.create_publisher(KeyValue, TOPIC_PROGRESS, QOS_STATE)
        self.pub_cell_state = self.create_publisher(DiagnosticStatus, TOPIC_STATE, QOS_LATCHED)
        self.diag = Diagnostics(self, "winder_sim")
        self.ready = Announcer(self, "consumer")  # the start handshake (winder/ready)
        self.create_subscription(String, TOPIC_JOB, self.on_job, QOS_LATCHED, raw=True)
        self.create_subscription(JointTrajectory, TOPIC_PATH, self.on_path, QOS_LATCHED, raw=True)
        self.create_subscription(String, TOPIC_PROFILE_CONFIG, self.on_profile_config, QOS_LATCHED, raw=True)
        self.sub_control = self.create_subscription(
            String, TOPIC_CONTROL, self.on_control, QOS_EVENTS, raw=True
        )
        self.sub_times = self.create_subscription(
            Int64MultiArray,
            TOPIC_STEP_TIMES,
            self.on_step_times,
            QOS_STREAM,
            raw=True,
            # the handshake follows the stream's connection as it happens, not by polling
            event_callbacks=SubscriptionEventCallbacks(matched=lambda _info: self.announce()),
        )
        self.create_subscription(
            DiagnosticArray, TOPIC_DIAGNOSTICS, self.on_diagnostics, QOS_DIAGNOSTICS, raw=True
        )
        # pump() runs on events (a chunk, a job) and, while work waits on the
        # clock (pacing, batching), every 5 ms; idle, only the 1 Hz report runs
        self.pump_timer = steady_timer(self, 0.005, self.pump)
        steady_timer(self, 0.5, self.watch)
        steady_timer(self, 1.0, self.report)
        self.topic = {
            "job": self.resolve_topic_name(TOPIC_JOB),
            "path": self.resolve_topic_name(TOPIC_PATH),
            "step_times": self.resolve_topic_name(TOPIC_STEP_TIMES),
            "joint_states": self.resolve_topic_name(TOPIC_JOINT_STATES),
            "joint_commands": self.resolve_topic_name(TOPIC_JOINT_COMMANDS),
            "sim_config": self.resolve_topic_name(TOPIC_SIM_CONFIG),
            "profile_config": self.resolve_topic_name(TOPIC_PROFILE_CONFIG),
            "clock": self.resolve_topic_name(TOPIC_CLOCK),
            "diagnostics": TOPIC_DIAGNOSTICS,
            "state": self.resolve_topic_name(TOPIC_STATE),
            "control": self.resolve_topic_name(TOPIC_CONTROL),
        }
        self.clock_ns = -1  # the last /clock published in this node's life (ns)
        self.reset()
        self.early: list[bytes] = []
        self.early_events: deque[bytes] = deque(maxlen=100)  # winder/control of a run not started here yet
        self.path_raw: bytes | None = None
        self.profile_raw: bytes | None = None
        self.last_summary: dict[str, object] = {}
        self.last_level, self.last_text = OK, ""
        self.cell_state("idle", "no job yet")
        if self.settings.blocked():
            self.diag.publish("job", ERROR, str(self.settings.blocked()), {})
        self.start_lifecycle()

    # -- lifecycle (winder.ros.managed) ----------------------------------------
    def in_run(self) -> bool:
        return self.plan is not None

    def blocked_reason(self) -> str | None:
        return self.settings.blocked()

    def lifecycle_changed(self) -> None:
        self.announce()

    def reset(self) -> None:
        self.plan: JobPlan | None = None
        self.checker: StreamChecker | None = None
        self.bag: BagRecorder | None = None
        self.axes: list[AxisSim] = []
        self.rate = 1.0
        self.next_sample = 0  # index of the next sample, t = k / rate
        self.t_sim_ns = 0  # simulated time reached (ns), since the job's start
        self.origin_ns = 0  # /clock at the job's start
        self.wall0_ns = time.time_ns()  # wall-clock time of the job's start: the bag's time base
        self.out: deque[dict[str, Any]] = deque()  # computed samples waiting to be published
        self.inbox: deque[bytes] = deque()  # received chunks waiting to be simulated
        self.rest: npt.NDArray[np.int64] | None = None  # accepted rows beyond the last sample batch
        self.record_failure = ""  # why the bag stopped recording (a full disk), if it did
        self.inbox_since = time.monotonic()
        self.last_step_ns = -1
        self.path_recorded = False
        self.profile_recorded = False
        self.job_wall = time.monotonic()
        self.done_steps = 0
        self.finishing = False
        self.last_chunk_wall = time.monotonic()
        self.start_wall = time.monotonic()
        self.stalled = False
        self.stalls = 0
        self.errors: list[str] = []
        self.dev_cmd = [0.0, 0, 0.0]  # sum, count, max of command deviation (m)
        self.dev_act = [0.0, 0, 0.0]  # same for the simulated axes
        #: programmed stops met in the stream: [t_stop ns, t_resume ns (-1: not known yet),
        #: (coil, layer, turn), state: 0 ahead, 1 paused (announced), 2 resumed]
        self.pauses: list[list[Any]] = []
        #: where each programmed stop of the job is: (segment, step) -> (coil, layer, turn)
        self.stop_places: dict[tuple[int, int], tuple[int, int, int]] = {}
        self.wall_pace0 = 0.0  # wall time at which simulated time pace_sim0 was due
        self.pace_sim0 = 0.0
        self.pace_factor = 0.0  # the real_time_factor since wall_pace0
        #: operator events of the run (winder/control) as simulated time reaches
        #: them: [t ns, cell state, message, (segment, step)], in time order
        self.ops: list[tuple[int, str, str, tuple[int, int]]] = []
        self.op_state = ""  # the last operator state announced (pausing, paused, aborting)
        self.pause_open = -1  # a pause's rest time (ns) while no resume has come: the clock runs on
        self.pause_steps = 0  # the steps up to that rest
        self.abort_steps = -1  # an abort: the run ends once this many steps are simulated
        self.abort_rest_ns = 0
        self.last_seg = -1  # the segment of the last step row simulated (-1: none yet)

    # -- in --------------------------------------------------------------
    def on_job(self, raw: bytes) -> None:
        msg = deserialize_message(raw, String)
        try:
            plan = parse_job_description(msg.data)
        except ValueError as exc:
            self.error(f"job description rejected: {exc}")
            return
        if not self.active:
            self.error(f"job {plan.job_id} refused: {self.inactive_reason()}")
            return
        if self.plan is not None and self.finishing:
            # every step of the last job is simulated, its last samples are still
            # being paced out: they go out now and that job closes complete
            while self.out:
                block = self.out.popleft()
                self.publish_samples(block, block["k"].size)
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
        self.plan = plan
        if plan.stops:
            segs = plan.job.segments()
            self.stop_places = {(g, k): stop_place(plan.job, segs[g], k) for g, k in plan.stops}
        # the job starts on the cell's clock one sample after the last one published
        self.origin_ns = 0 if self.clock_ns < 0 else self.clock_ns + round(1e9 / values["publish_rate"])
        self.announce()
        self.checker = StreamChecker(plan)
        self.rate = float(values["publish_rate"])
        self.encoder = JointStateEncoder(AXES, plan.job_id)
        for i, axis in enumerate(AXES):
            sim = AxisSim(
                make_axis(values, axis),
                values["model"],
                values[f"{axis}.load_torque"],
                values[f"{axis}.motor_step_angle"],
                plan.joint_step[i],
            )
            sim.position = plan.segments[0].start[i] if plan.segments else 0
            self.axes.append(sim)
        config = String(
            data=json.dumps(
                {
                    "model": values["model"],
                    "axes": {axis: {k: values[f"{axis}.{k}"] for k in MOTOR_FIELDS} for axis in AXES},
                    "publish_rate": self.rate,
                    "settle_time": values["settle_time"],
                    "run_id": plan.run_id,
                    "clock_origin_ns": self.origin_ns,
                    "wall_start_ns": self.wall0_ns,
                    "real_time": bool(values["real_time"]),
                    "real_time_factor": values["real_time_factor"],
                    # a re-simulation (winder resim) names the recording its steps come from
                    **(
                        {"source_bag": plan.source_bag, "source_run_id": plan.source_run_id}
                        if plan.source_bag
                        else {}
                    ),
                }
            )
        )
        self.pub_config.publish(config)
        if values["record"]:
            try:
                directory = bag_directory(values["bag_dir"])
                path = (
                    run_bag_path(directory, plan.run_id)
                    if plan.run_id
                    else new_bag_path(directory, plan.job_id)
                )
                self.bag = BagRecorder(
                    path,
                    {self.topic[k]: t for k, t in BAG_TYPES.items()},
                    compression=values["bag_compression"],
                )
            except (OSError, ValueError) as exc:  # the disk changed since bag_dir was accepted
                self.error(
                    f"job {plan.job_id} runs unrecorded: cannot open a bag: {str(exc).splitlines()[0]}"
                )
            else:
                self.record("job", 0, raw)
                self.record("sim_config", 0, serialize_message(config))
        self.job_wall = time.monotonic()
        self.path_recorded = False
        self.profile_recorded = False
        self.record_path()
        self.record_profile_config()
        self.get_logger().info(
            f"run {plan.run_id or '-'}: job {plan.job_id}, {plan.total_steps} steps, {values['model']} model"
            + (f", recording to {self.bag.path}" if self.bag else "")
        )
        self.cell_state("running", f"run {plan.run_id or plan.job_id} started", where=(1, 1, 0))
        self.report()  # the run is on: its status at once, not at the next second
        events, self.early_events = list(self.early_events), deque(maxlen=100)
        for event in events:  # the run's own events that came before its description; others dropped
            self.handle_control(event)
        self.early_events.clear()
        early, self.early = self.early, []
        for chunk in early:  # in order, before any taken from the queue
            self.receive(chunk)
        self.pump()

    def on_path(self, raw: bytes) -> None:
        self.path_raw = raw
        self.record_path()

    def on_control(self, raw: bytes) -> None:
        self.handle_control(raw)
        self.pump()

    def handle_control(self, raw: bytes) -> None:
        """An operator event of the running run (winder/control): recorded, and
        its states announced as simulated time reaches them; an abort ends the
        run once the steps up to the rest are simulated. Events of other runs,
        or that do not parse, change nothing."""
        plan = self.plan
        try:
            event = json.loads(deserialize_message(raw, String).data)
            kind, t_ns = event["event"], int(event["t_ns"])
            seg, step = int(event.get("segment", -1)), int(event.get("step", 0))
        except (ValueError, KeyError, TypeError, RecursionError):
            return
        if not isinstance(event, dict) or t_ns < 0:
            return
        if plan is None or event.get("run_id") != plan.run_id:
            # the profile node may speak of a run before its job description is
            # here (a schedule is published as the run starts): kept for it
            self.early_events.append(raw)
            return
        self.record("control", self.t_sim_ns, raw)  # when it was heard; its own times are inside
        where = (seg, step)
        if kind == "pause":
            rest = int(event.get("t_rest_ns", t_ns))
            self.ops.append((t_ns, "pausing", "pausing: braking to rest", where))
            self.ops.append((rest, "paused", f"paused after {event.get('steps')} steps", where))
            self.pause_open, self.pause_steps = rest, int(event.get("steps", 0))
        elif kind == "resume":
            self.ops.append((t_ns, "running", "resumed", where))
            self.pause_open = -1
        elif kind == "abort":
            rest = int(event.get("t_rest_ns", t_ns))
            steps = int(event.get("steps", -1))
            if not 0 <= steps <= plan.total_steps:
                return
            self.ops.append((t_ns, "aborting", f"aborting: at rest after {steps} steps", where))
            self.abort_steps, self.abort_rest_ns, self.pause_open = steps, rest, -1
        elif kind == "override":
            self.get_logger().info(f"feed override {event.get('factor')} from {t_ns / 1e9:.6f} s")
        self.ops.sort(key=lambda op: op[0])

    def take_control(self) -> None:
        """Operator events already here, before any step is simulated: the
        executor may serve a busy step stream first, and an event must not
        come after the steps it times (the profile node sends it first)."""
        for raw in waiting(self.sub_control):
            self.handle_control(raw)

    def op_events(self, upto_ns: int) -> None:
        """Announce (and record) each operator state as simulated time reaches it."""
        plan = self.plan
        while self.ops and self.ops[0][0] <= upto_ns and plan is not None:
            t_ns, state, text, (seg, step) = self.ops.pop(0)
            self.op_state = "" if state == "running" else state
            segs = plan.job.segments()
            if 0 <= seg < len(segs) and segs[seg].kind == "layer":
                where = stop_place(plan.job, segs[seg], max(step, 0))
            else:
                where = (segs[seg].pole + 1 if 0 <= seg < len(segs) else 0, 0, 0)
            self.cell_state(state, f"run {plan.run_id}: {text}", where=where, t_ns=t_ns)

    def at_rest(self) -> bool:
        """Paused by the operator, every step up to the rest simulated."""
        return (
            self.plan is not None
            and self.checker is not None
            and self.pause_open >= 0
            and self.done_steps + self.checker.missing >= self.pause_steps
            and not self.finishing
        )

    def free_running(self) -> bool:
        """A real-time run at rest after a pause: its clock goes on."""
        return self.at_rest() and bool(self.settings.values()["real_time"])

    def on_profile_config(self, raw: bytes) -> None:
        self.profile_raw = raw
        self.record_profile_config()

    def record_profile_config(self) -> None:
        """Record the ramp the profile node planned this job with, once."""
        if self.plan is None or self.profile_raw is None or self.profile_recorded:
            return
        try:
            doc = json.loads(deserialize_message(self.profile_raw, String).data)
            ids = (doc.get("job_id"), doc.get("run_id", ""))
        except (ValueError, AttributeError):
            return
        if ids != (self.plan.job_id, self.plan.run_id):
            return  # an earlier run's ramp; this run's is on its way
        self.profile_recorded = True
        self.record("profile_config", self.t_sim_ns, self.profile_raw)

    def record_path(self) -> None:
        """Record the current job's path once. Job and path travel on two
        topics that match independently, so either may arrive first."""
        if self.plan is None or self.path_raw is None or self.path_recorded:
            return
        path = deserialize_message(self.path_raw, JointTrajectory)
        if path.header.frame_id != (self.plan.run_id or self.plan.job_id):
            return  # an earlier run's path; this run's is on its way
        self.path_recorded = True
        self.record("path", self.t_sim_ns, self.path_raw)

    def on_diagnostics(self, raw: bytes) -> None:
        """Record the statuses of this cell's nodes: another cell's are its own bag's."""
        if self.bag is None:
            return
        try:
            names = [st.name for st in deserialize_message(raw, DiagnosticArray).status]
        except Exception:  # not ours to judge; nothing of it is recorded
            return
        own = self.get_fully_qualified_name().lstrip("/") + ":"
        if all(n.startswith(own) for n in names):
            return  # this node records its own statuses as it publishes them (publish_status)
        if any(in_namespace(n, self.get_namespace()) for n in names):
            self.record("diagnostics", self.t_sim_ns, raw)

    def publish_status(self, task: str, level: int, text: str, values: dict[str, object]) -> None:
        """A status of this node on /diagnostics, and into the run's bag at
        once: an ERROR raised just before the run closes is in its bag too."""
        status = self.diag.status(task, level, text, values)
        self.record("diagnostics", self.t_sim_ns, serialize_message(status))
        self.diag.pub.publish(status)

    def on_step_times(self, raw: bytes) -> None:
        self.receive(raw)
        for more in waiting(self.sub_times):  # the chunks queued behind it, in one go
            self.receive(more)
        self.pump()

    def receive(self, raw: bytes) -> None:
        if self.plan is None or self.checker is None or self.finishing:
            self.early.append(raw)
            return
        self.last_chunk_wall = time.monotonic()
        if self.stalled:
            self.stalled = False
            self.get_logger().info("step stream resumed")
        self.record("step_times", self.t_sim_ns, raw)  # the bag keeps the stream as it arrived
        if not self.inbox:
            self.inbox_since = time.monotonic()
        self.inbox.append(raw)

    def pump(self) -> None:
        """Do the work that is due (:meth:`work`); keep the 5 ms timer running
        while work waits on the clock (pacing, batching, the path), stop it
        when there is none: an idle node wakes only for its 1 Hz report."""
        self.work()
        if self.inbox or self.rest is not None or self.out or self.finishing or self.free_running():
            if self.pump_timer.is_canceled():
                self.pump_timer.reset()
        else:
            self.pump_timer.cancel()

    def work(self) -> None:
        """Simulate queued chunks. In real-time mode one chunk at a time, once
        the samples of the last one are out: memory stays bounded, and the
        progress report holds the interp node back (flow control)."""
        self.take_control()
        settings = self.settings.values()
        now = time.monotonic()
        waiting = not (self.path_recorded and self.profile_recorded)
        if self.inbox and waiting and now - self.job_wall < PATH_WAIT:
            return  # hold the steps briefly: the bag should have path and ramp before they run
        if (
            not settings["real_time"]
            and 0 < len(self.inbox) < BATCH_CHUNKS
            and now - self.inbox_since < BATCH_WAIT
        ):
            return  # gather a few chunks: one tracker call for many costs less
        if self.rest is not None and not (settings["real_time"] and self.out and self.ahead(settings)):
            rest, self.rest = self.rest, None
            self.advance(rest, settings)
        while self.inbox and not self.finishing and self.rest is None:
            if settings["real_time"] and self.out and self.ahead(settings):
                break
            # as fast as possible: simulate every chunk waiting, up to
            # BATCH_STEPS, in one go (the per-call costs are paid once)
            batch: list[npt.NDArray[np.int64]] = []
            size = 0
            while self.inbox and size < BATCH_STEPS:
                rows = self.accept(self.inbox.popleft())
                if rows is not None:
                    batch.append(rows)
                    size += rows.shape[0]
                if settings["real_time"]:
                    break
            if batch:
                self.advance(np.concatenate(batch) if len(batch) > 1 else batch[0], settings)
            self.receipt()
        if not self.inbox:  # the job's last chunk may have been dropped, not simulated
            self.settle_if_complete(settings)
        if self.at_rest() and not (self.inbox or self.rest is not None or self.out):
            # at rest after a pause: the samples go on to the rest, and on with
            # the wall clock in a real-time run (until the resume's steps come)
            if settings["real_time"]:
                until = max(self.paced_until(settings["real_time_factor"]), self.pause_open / 1e9)
            else:
                until = self.pause_open / 1e9
            if until * 1e9 > max(self.last_step_ns, self.t_sim_ns):
                self.simulate(None, None, until=until)
        self.emit(settings)
        if self.record_failure and self.plan is not None:
            self.finish(complete=False)

    def ahead(self, settings: dict[str, Any]) -> bool:
        """In real time: the samples computed reach beyond what the wall clock
        allows now, so the next chunk can wait (memory stays bounded); short
        chunks (the profile node's look-ahead at a high real_time_factor) are
        simulated until they catch up with the clock."""
        if self.wall_pace0 == 0.0:
            return True
        return (self.next_sample - 1) / self.rate > self.paced_until(settings["real_time_factor"])

    def accept(self, raw: bytes) -> npt.NDArray[np.int64] | None:
        """The rows of a chunk that may be simulated, or None (reported)."""
        assert self.checker is not None
        try:
            rows = TIMED_CDR.decode(raw)
        except ValueError as exc:
            self.error(f"bad step_times chunk: {exc}")
            return None
        verdict = self.checker.check_rows(rows, TIMED_COLUMNS)  # positions tell gaps, repeats, reordering
        if verdict.kind != "ok":
            self.error(verdict.message)
        if not verdict.accept:
            self.checker.rejected_steps += rows.shape[0]
            return None
        seg, pos = int(rows[0, 1]), rows[:, 2:]
        late = int(rows[-1, 0]) > MAX_STEP_NS
        if late or np.any(rows[1:, 0] <= rows[:-1, 0]) or rows[0, 0] <= self.last_step_ns:
            # in sequence by position but not in time: the steps cannot be
            # simulated; they count as missing, never silently integrated
            why = f"later than a job may last ({MAX_JOB_SECONDS:g} s)" if late else "do not increase"
            self.error(f"segment {seg}: step times {why}; {rows.shape[0]} steps dropped")
            self.checker.done -= rows.shape[0]
            self.checker.missing += rows.shape[0]
            return None
        self.last_step_ns = int(rows[-1, 0])
        self.deviation_of_commands(seg, pos)
        self.note_stops(seg, rows)
        return rows

    def advance(self, rows: npt.NDArray[np.int64], settings: dict[str, Any]) -> None:
        """Simulate accepted rows (possibly of several chunks and segments) in
        batches of at most SAMPLE_BATCH samples: as fast as possible, each
        batch is published before the next; in real time, the rows beyond the
        first batch wait in ``self.rest`` until its samples are out."""
        assert self.checker is not None
        t_s = rows[:, 0] / 1e9
        n, lo = rows.shape[0], 0
        while lo < n:
            end = (self.next_sample + SAMPLE_BATCH - 1) / self.rate  # the batch's last sample
            hi = int(np.searchsorted(t_s, end, side="right"))  # a step at a sample goes before it
            if hi == lo:
                self.simulate(None, None, until=end)  # no step within the batch: samples only
            else:
                self.simulate(rows[lo:hi], t_s[lo:hi], until=float(t_s[hi - 1]) if hi == n else end)
            self.done_steps += hi - lo
            lo = hi
            if lo < n:
                if settings["real_time"]:
                    self.rest = rows[lo:]
                    return
                self.emit(settings)
        self.settle_if_complete(settings)

    def settle_if_complete(self, settings: dict[str, Any]) -> None:
        """Once every step of the job is simulated or counted missing: the
        settle time after the last simulated step, then the job closes."""
        if self.checker is None or self.finishing or self.rest is not None:
            return
        aborted_here = 0 <= self.abort_steps <= self.done_steps + self.checker.missing
        if not (self.checker.complete or aborted_here):
            return
        self.simulate(None, None, until=max(self.last_step_ns, 0) / 1e9 + settings["settle_time"])
        self.finishing = True

    # -- work ------------------------------------------------------------
    def simulate(
        self, rows: npt.NDArray[np.int64] | None, t_s: npt.NDArray[np.float64] | None, until: float
    ) -> None:
        """Advance every axis to ``until`` with the steps in ``rows``; queue the samples."""
        k1 = math.floor(until * self.rate + 1e-9) + 1
        ks = np.arange(self.next_sample, max(k1, self.next_sample), dtype=np.int64)
        samples = ks / self.rate
        self.next_sample = max(k1, self.next_sample)
        cmd_pos = np.empty((samples.size, len(AXES)))
        cmd_vel = np.zeros((samples.size, len(AXES)))
        act_pos = np.empty((samples.size, len(AXES)))
        act_vel = np.empty((samples.size, len(AXES)))
        # the command's segment at each sample: that of the last row at or before it (eq. 7)
        seg_of_sample = np.full(samples.size, self.last_seg, np.int64)
        j = np.empty(0, np.int64)
        if rows is not None and t_s is not None:
            j = np.searchsorted(t_s, samples, side="right") - 1  # last row at or before each sample
            seg_of_sample = np.where(j >= 0, rows[np.maximum(j, 0), 1], self.last_seg)
            self.last_seg = int(rows[-1, 1])
        for i, ax in enumerate(self.axes):
            if rows is not None and t_s is not None:
                p = rows[:, 2 + i]
                d = np.empty(p.size, np.int64)
                d[0] = p[0] - ax.position
                np.subtract(p[1:], p[:-1], out=d[1:])
                if np.count_nonzero(d) == d.size:  # the major axis: every row is its step
                    ev_t, dm = t_s, d
                else:
                    moved = d != 0
                    ev_t, dm = t_s[moved], d[moved]
                ev_a = dm * ax.step_angle
                # commanded step position at each sample (a step at a sample time counts)
                cmd_steps = np.where(j >= 0, p[np.maximum(j, 0)], ax.position)
                # commanded velocity: one step per interval since the axis' step
                # before; once the axis pauses it decays as 1 / (time since the step)
                v_steps = self.command_velocity(ax, ev_t, dm, samples)
                ax.position = int(p[-1])
            else:
                ev_t, ev_a = np.empty(0), np.empty(0)
                cmd_steps = np.full(samples.size, ax.position)
                v_steps = ax.last_dir / np.maximum(ax.last_dt, samples - ax.last_step_t)
            theta, omega = ax.tracker.advance(ev_t, ev_a, samples)
            actual_steps = theta / ax.step_angle
            if samples.size:
                ax.max_error_steps = max(ax.max_error_steps, float(np.max(np.abs(cmd_steps - actual_steps))))
            cmd_pos[:, i] = cmd_steps * ax.joint_step
            cmd_vel[:, i] = v_steps * ax.joint_step
            act_pos[:, i] = actual_steps * ax.joint_step
            act_vel[:, i] = omega / ax.step_angle * ax.joint_step
        if samples.size:
            self.deviation_of_axes(seg_of_sample, act_pos)
            self.out.append(
                {"k": ks, "cmd_pos": cmd_pos, "cmd_vel": cmd_vel, "act_pos": act_pos, "act_vel": act_vel}
            )

    @staticmethod
    def command_velocity(
        ax: AxisSim,
        ev_t: npt.NDArray[np.float64],
        dm: npt.NDArray[np.int64],
        samples: npt.NDArray[np.float64],
    ) -> npt.NDArray[np.float64]:
        """Commanded velocity (steps/s) at the samples from the axis' steps
        ``ev_t`` (s) of signs ``dm``: the direction of its last step over the
        longer of that step's interval and the time since it; updates the
        axis' last step, direction and interval."""
        m = ev_t.size
        if m == 0:
            return ax.last_dir / np.maximum(ax.last_dt, samples - ax.last_step_t)
        jj = np.searchsorted(ev_t, samples, side="right")  # this call's steps at or before each sample
        last = np.maximum(jj - 1, 0)
        before = np.where(jj >= 2, ev_t[np.maximum(jj - 2, 0)], ax.last_step_t)
        t_at = np.where(jj >= 1, ev_t[last], ax.last_step_t)
        dirs = np.where(jj >= 1, np.sign(dm[last]), ax.last_dir)
        with np.errstate(invalid="ignore"):  # -inf - -inf before an axis' first step, not chosen
            dts = np.where(jj >= 1, t_at - before, ax.last_dt)
        v: npt.NDArray[np.float64] = dirs / np.maximum(dts, samples - t_at)
        prev = float(ev_t[-2]) if m >= 2 else ax.last_step_t
        ax.last_step_t, ax.last_dir = float(ev_t[-1]), float(np.sign(dm[-1]))
        ax.last_dt = ax.last_step_t - prev
        return v

    def deviation_of_commands(self, seg: int, pos: npt.NDArray[np.int64]) -> None:
        """Eq. 7 of the commanded steps, as ``winder analyze`` computes it (winder.contract.eq7)."""
        assert self.plan is not None
        if self.plan.segments[seg].kind == "layer":
            self.accumulate(self.dev_cmd, step_deviation(self.plan, seg, pos))

    def deviation_of_axes(self, segs: npt.NDArray[np.int64], act_pos: npt.NDArray[np.float64]) -> None:
        """Eq. 7 of the samples, as ``winder analyze`` computes it (winder.contract.eq7)."""
        assert self.plan is not None
        js = self.plan.joint_step
        x, y = act_pos[:, 0] / js[0], act_pos[:, 1] / js[1]
        layer = layer_of_samples(self.plan, segs, y)
        if np.any(layer >= 0):
            dist = sample_deviation(self.plan, layer, x, y)
            self.accumulate(self.dev_act, dist[layer >= 0])

    @staticmethod
    def accumulate(acc: list[float], dist: npt.NDArray[np.float64]) -> None:
        """Add distances to a [sum, count, max] tally."""
        acc[0] += float(dist.sum())
        acc[1] += dist.size
        acc[2] = max(acc[2], float(dist.max()))

    # -- out -------------------------------------------------------------
    def emit(self, settings: dict[str, Any] | None = None) -> None:
        """Publish queued samples: all of them, or as far as the wall clock allows."""
        if not self.out:
            if self.finishing:
                self.finish(complete=True)
            return
        limit = math.inf
        settings = settings or self.settings.values()
        if settings["real_time"]:
            limit = self.paced_until(settings["real_time_factor"])
        while self.out:
            block = self.out[0]
            ks = block["k"]
            n = int(np.searchsorted(ks / self.rate, limit, side="right")) if math.isfinite(limit) else ks.size
            if n:
                self.publish_samples(block, n)
            if n < ks.size:
                for key in block:
                    block[key] = block[key][n:]
                return
            self.out.popleft()
        if self.finishing:
            self.finish(complete=True)

    def paced_until(self, factor: float) -> float:
        """Simulated time (s) the wall clock allows in real-time mode. A new
        real_time_factor changes the rate from now on: the time already
        elapsed keeps the factor it elapsed at (the clock never jumps)."""
        now = time.monotonic()
        if self.wall_pace0 == 0.0:
            self.wall_pace0, self.pace_sim0, self.pace_factor = now, 0.0, factor
        elif factor != self.pace_factor:
            self.pace_sim0 += (now - self.wall_pace0) * self.pace_factor
            self.wall_pace0, self.pace_factor = now, factor
        return self.pace_sim0 + (now - self.wall_pace0) * factor

    def note_stops(self, seg: int, rows: npt.NDArray[np.int64]) -> None:
        """The programmed stops in accepted rows: the axes rest from the stop's
        step to the next step (its time comes with it or with the next chunk)."""
        assert self.plan is not None and self.checker is not None
        for p in self.pauses:
            if p[1] < 0:
                p[1] = int(rows[0, 0])
                if self.plan.stop_resume == "call" and self.wall_pace0:
                    # the job waited for ~/resume: pacing goes on from here, it does not catch up
                    self.wall_pace0, self.pace_sim0 = time.monotonic(), self.t_sim_ns / 1e9
        if not self.plan.stops:
            return
        k = self.checker.step_index(seg, rows[:, 2:])
        wanted = [s for g, s in self.plan.stops if g == seg]
        for i in np.nonzero(np.isin(k, wanted))[0]:
            resume = int(rows[i + 1, 0]) if i + 1 < rows.shape[0] else -1
            self.pauses.append([int(rows[i, 0]), resume, self.stop_places[(seg, int(k[i]))], 0])

    def pause_events(self, upto_ns: int) -> None:
        """Announce (and record) each programmed stop as simulated time reaches
        it, and its end: the bag keeps every transition."""
        assert self.plan is not None
        for p in self.pauses:
            t_stop, t_resume, place, state = p
            label = f"{place[0]}:{place[2]}"
            if state == 0 and t_stop <= upto_ns:
                p[3] = state = 1
                self.pause_status("paused", f"paused at turn {label} (coil:turn)", t_stop, place)
            if state == 1 and 0 <= t_resume <= upto_ns:
                p[3] = 2
                self.pause_status("running", f"resumed after the stop at turn {label}", t_resume, place)

    def pause_status(self, state: str, text: str, t_ns: int, place: tuple[int, int, int]) -> None:
        assert self.plan is not None
        self.cell_state(state, text, where=place, t_ns=t_ns)
        values = self.summary(complete=False)
        values["state"] = state
        values["stop"] = f"{place[0]}:{place[2]}"
        status = self.diag.status("job", OK, f"run {self.plan.run_id if self.plan else ''}: {text}", values)
        self.record("diagnostics", t_ns, serialize_message(status))
        self.diag.pub.publish(status)

    def paused(self) -> bool:
        return any(p[3] == 1 for p in self.pauses)

    def waiting_for_resume(self) -> bool:
        """At a programmed stop that waits for ~/resume: no steps come, and that is no stall."""
        return (
            self.plan is not None and self.plan.stop_resume == "call" and any(p[1] < 0 for p in self.pauses)
        )

    def publish_samples(self, block: dict[str, Any], n: int) -> None:
        """The first ``n`` samples of a block: /clock first, then commands and
        states, each sample's three messages before the next sample's."""
        t_ns = np.rint(block["k"][:n] * (1e9 / self.rate)).astype(np.int64)
        stamps = t_ns + self.origin_ns  # on the cell's clock
        clocks = encode_clocks(stamps)
        cmds = self.encoder.encode(stamps, block["cmd_pos"][:n], block["cmd_vel"][:n])
        acts = self.encoder.encode(stamps, block["act_pos"][:n], block["act_vel"][:n])
        if n:
            self.clock_ns = int(stamps[n - 1])
        bag = self.bag if not self.record_failure else None
        topics = self.topic["clock"], self.topic["joint_commands"], self.topic["joint_states"]
        for r in range(n):
            t = int(t_ns[r])
            self.t_sim_ns = t
            self.pub_clock.publish(clocks[r])
            self.pub_cmd.publish(cmds[r])
            self.pub_state.publish(acts[r])
            if bag is not None:
                log = self.wall0_ns + t
                try:
                    bag.write(topics[0], log, clocks[r], exact=True)
                    bag.write(topics[1], log, cmds[r], exact=True)
                    bag.write(topics[2], log, acts[r], exact=True)
                except RuntimeError as exc:
                    self.recording_failed(exc)
                    bag = None
        if n and self.pauses:
            self.pause_events(int(t_ns[n - 1]))
        if n and self.ops:
            self.op_events(int(t_ns[n - 1]))

    def aborted(self) -> bool:
        """The run was aborted and every step up to the rest is simulated."""
        assert self.checker is not None
        return 0 <= self.abort_steps <= self.done_steps + self.checker.missing and not self.record_failure

    def summary(self, complete: bool) -> dict[str, object]:
        assert self.plan is not None and self.checker is not None
        wall = time.monotonic() - self.start_wall
        sim_s = self.t_sim_ns / 1e9
        return status_values(
            "done" if complete else ("aborted" if self.aborted() else "incomplete"),
            self.plan.job_id,
            self.plan.run_id,
            self.done_steps,
            self.plan.total_steps,
            **self.details(wall, sim_s),
        )

    def details(self, wall: float, sim_s: float) -> dict[str, object]:
        """The sim node's own status keys, after the common ones."""
        assert self.plan is not None and self.checker is not None
        return {
            "steps_missing": self.checker.missing,
            "gaps": self.checker.gaps,
            "chunks_rejected": self.checker.rejected,
            "sim_time_s": f"{sim_s:.6f}",
            "wall_time_s": f"{wall:.3f}",
            "real_time_factor": f"{sim_s / wall:.3f}" if wall > 0 else "inf",
            "lost_steps": sum(a.lost_steps for a in self.axes),
            "max_tracking_error_steps": f"{max((a.max_error_steps for a in self.axes), default=0.0):.4f}",
            "mean_deviation_command_m": f"{self.dev_cmd[0] / max(self.dev_cmd[1], 1):.6e}",
            "max_deviation_command_m": f"{self.dev_cmd[2]:.6e}",
            "mean_deviation_actual_m": f"{self.dev_act[0] / max(self.dev_act[1], 1):.6e}",
            "max_deviation_actual_m": f"{self.dev_act[2]:.6e}",
            "bag": str(self.bag.path.resolve()) if self.bag else "",
            "errors": len(self.errors),
            "stalls": self.stalls,
        }

    def finish(self, complete: bool) -> None:
        """End the job: final report into the bag, close it, then announce it.
        Signals wait meanwhile, so a Ctrl-C cannot split the three."""
        if self.plan is None:
            return
        self.take_control()  # the run's last events go into its bag
        with signals_held():
            self._finish(complete)

    def cell_state(
        self, state: str, text: str, where: tuple[int, int, int] = (0, 0, 0), t_ns: int | None = None
    ) -> None:
        """winder/state: the cell's state at a transition, latched, and into the bag."""
        plan = self.plan
        t = self.t_sim_ns if t_ns is None else t_ns
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
            level=bytes([ERROR if state == "failed" else OK]),
            name=f"{self.get_fully_qualified_name().lstrip('/')}: state",
            message=text,
            hardware_id="winder_sim",
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()],
        )
        if plan is not None:
            self.record("state", t, serialize_message(msg))
        if self.context.ok():
            self.pub_cell_state.publish(msg)

    def _finish(self, complete: bool) -> None:
        assert self.plan is not None
        values, level, text = self.final_report(complete)
        job = self.plan.job
        ended = {"done": "done", "aborted": "aborted"}.get(str(values["state"]), "failed")
        final = job.coil(job.poles - 1)
        last = (job.poles, final.layers, job.turns_of(job.poles - 1)) if ended == "done" else (0, 0, 0)
        self.cell_state(ended, text, where=last)
        final = self.diag.status("job", level, text, values)
        if self.bag is not None:
            # the final report goes into the bag too, and the bag is closed
            # before anyone hears "done": whoever stops us then finds it complete
            self.record("diagnostics", self.t_sim_ns, serialize_message(final))
            try:
                self.bag.close()
            except (RuntimeError, OSError) as exc:  # what reached the file stays readable
                self.recording_failed(exc)
                values, level, text = self.final_report(complete)  # no longer complete
                final = self.diag.status("job", level, text, values)
        if self.context.ok():
            self.get_logger().info(text + (f"; bag {self.bag.path}" if self.bag else ""))
        self.last_summary, self.last_level, self.last_text = values, level, text
        self.plan = None
        self.finishing = False
        self.bag = None
        if self.context.ok():  # at Ctrl-C the context is already shut down
            self.announce()  # ready first: whoever hears "done" can start the next run at once
            self.diag.pub.publish(final)

    def final_report(self, complete: bool) -> tuple[dict[str, object], int, str]:
        """The job's final status: values, level and message. A job whose
        recording failed is not complete, whatever the stream did."""
        assert self.plan is not None
        aborted = self.aborted()
        complete = complete and not self.record_failure and not aborted
        values = self.summary(complete)
        ok = (complete or aborted) and not self.errors and values["lost_steps"] == 0
        level = OK if ok else (WARN if complete or aborted else ERROR)
        state = "complete" if complete else ("aborted, the axes at rest" if aborted else "incomplete")
        text = f"job {self.plan.job_id}: {state}, {self.done_steps}/{self.plan.total_steps} steps"
        if self.errors:
            text += f", {len(self.errors)} stream errors (first: {self.errors[0]})"
        return values, level, text

    def record(self, key: str, t_ns: int, data: bytes, *, exact: bool = False) -> None:
        """One message into the job's bag, if it records. A failed write (a
        full disk) stops the recording; pump() then closes the job incomplete."""
        if self.bag is None or not self.bag.is_open or self.record_failure:
            return
        try:
            self.bag.write(self.topic[key], self.wall0_ns + t_ns, data, exact=exact)
        except RuntimeError as exc:
            self.recording_failed(exc)

    def recording_failed(self, exc: BaseException) -> None:
        if self.record_failure:
            return
        cause = exc.__cause__ or exc
        errno_ = getattr(cause, "errno", None)
        why = {28: "disk full", 27: "file size limit reached"}.get(errno_ or 0, one_line(cause))
        self.record_failure = why
        self.error(f"recording stopped: {why}; what was written stays readable, the job is closed incomplete")

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

    def watch(self) -> None:
        if self.plan is None or self.finishing:
            return
        if (self.waiting_for_resume() or self.pause_open >= 0) and not (
            self.inbox or self.rest is not None or self.out
        ):
            self.last_chunk_wall = time.monotonic()
            if any(p[3] == 0 for p in self.pauses):  # the axes are at the stop: say so
                self.pause_events(max(p[0] for p in self.pauses))
            return
        if self.inbox or self.rest is not None or self.out:
            self.last_chunk_wall = time.monotonic()  # pacing work already here: not a stall
            return
        idle = time.monotonic() - self.last_chunk_wall
        settings = self.settings.values()
        if idle > settings["stall_abort"]:
            done = f"{self.done_steps}/{self.plan.total_steps}"
            self.error(f"step stream stalled for {idle:.1f} s at {done} steps: job closed incomplete")
            self.finish(complete=False)
            return
        if not self.stalled and idle > settings["stall_timeout"]:
            # reported at once and while it lasts (report()); a stall that ends
            # with nothing lost does not fail the job, so it is not an error()
            self.stalled = True
            self.stalls += 1
            done = f"{self.done_steps}/{self.plan.total_steps}"
            why = f"step stream stalled: no steps for {idle:.1f} s at {done} steps"
            self.get_logger().warning(why)
            self.publish_status(
                "stream", ERROR, why, {"job_id": self.plan.job_id, "run_id": self.plan.run_id}
            )

    def receipt(self) -> None:
        """The steps of the job simulated so far, or known missing, on
        winder/progress: the interp node's flow control (at most max_in_flight
        steps sent and not yet simulated) and its sign that the job is over;
        repeated by report(), the sign this node is alive while it paces a
        real-time job. Refused chunks do not count: they were never the job's."""
        if self.plan is not None and self.checker is not None:
            done = self.done_steps + self.checker.missing
            self.pub_progress.publish(KeyValue(key=self.plan.run_id or self.plan.job_id, value=str(done)))

    def announce(self) -> None:
        """Tell the interp node whether a job can start here (winder/ready):
        ready once the step times' publisher is matched, so no chunk of the
        job can go out before this node hears it."""
        if self.plan is not None:
            state = "busy"
        elif self.settings.blocked():
            state = "blocked"
        elif not self.active:
            state = "inactive"
        else:
            state = "ready" if self.sub_times.get_publisher_count() > 0 else "waiting"
        self.ready.announce(state)

    def report(self) -> None:
        self.announce()
        self.ready.repeat()
        if self.plan is None:
            if self.last_summary:  # keep telling how the last job ended, as a status does
                s = self.last_summary
                self.diag.publish("job", self.last_level, self.last_text, s)
            else:
                why = self.settings.blocked()
                values = status_values("blocked" if why else "idle")
                self.diag.publish("job", ERROR if why else OK, why or "idle: waiting for a job", values)
            return
        self.receipt()
        values = self.summary(complete=False)
        values["state"] = "stalled" if self.stalled else ("paused" if self.paused() else "running")
        if self.op_state and not self.stalled:
            values["state"] = self.op_state
        self.publish_status(
            "job",
            ERROR if self.stalled else OK,
            f"run {self.plan.run_id or self.plan.job_id}: {values['state']}",
            values,
        )

    def shutdown(self) -> None:
        """Close the bag of a running job (Ctrl-C): readable, marked incomplete."""
        if self.plan is not None and self.bag is not None:
            self.finish(complete=False)


def main(args: list[str] | None = None) -> None:
    spin(SimNode, args)
