"""interp_node: winding job (parameters) -> minimum-deviation step commands.

In:  parameters (the fields of winder.motion.job.Job, the ramp a run may bring
     (ramp.*), autostart, chunk_steps), services ~/start (std_srvs/Trigger:
     start a run with the settings as they are) and ~/start_run
     (rcl_interfaces/SetParametersAtomically: set the run's settings and start
     it, in one call, all or nothing; a ramp.* value in it makes the run bring
     that ramp, ramp.source job), winder/ready, winder/progress.
Out: winder/job (winder_interfaces/JobDescription, the job with the run id, latched),
     winder/steps (std_msgs/Int32MultiArray chunks), /diagnostics.

Every start is a run with its own id (:func:`winder.contract.stream.make_run_id`):
the start reply names it, the job description carries it to the other nodes,
every status of the run reports it and the sim node names the run's bag after it.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import numpy.typing as npt
from diagnostic_msgs.msg import KeyValue
from rcl_interfaces.msg import SetParametersResult
from rcl_interfaces.srv import SetParametersAtomically
from rclpy.parameter import Parameter
from std_msgs.msg import Int32MultiArray
from std_srvs.srv import Trigger

from winder.contract.jobfile import check_interp_settings, load_job_file_hashed
from winder.contract.params import INTERP_SPECS, run_ramp, stop_points
from winder.contract.run import ControlEvent, EventError
from winder.contract.states import EventKind, JobState, ReadyState
from winder.contract.stream import describe_job, make_run_id
from winder.contract.topics import (
    TOPIC_CONTROL,
    TOPIC_DIAGNOSTICS,
    TOPIC_JOB,
    TOPIC_PROGRESS,
    TOPIC_STEPS,
    status_values,
)
from winder.motion.interp import interpolate_pieces
from winder.motion.job import FIELD_SPECS, Job
from winder.ros.chunks import STEPS_CDR
from winder.ros.diagnostics import ERROR, OK, Diagnostics
from winder.ros.interfaces import job_description_msg
from winder.ros.managed import ManagedNode
from winder.ros.peers import Peers, Solo
from winder.ros.qos import QOS_EVENTS, QOS_LATCHED, QOS_STATE, QOS_STREAM
from winder.ros.ready import FRESH, Readiness
from winder.ros.settings import Settings
from winder.ros.spin import spin
from winder.ros.timers import steady_timer
from winder.spec import SpecError
from winder_interfaces.msg import ControlEvent as ControlEventMsg
from winder_interfaces.msg import JobDescription
from winder_interp import PARAMETERS
from winder_interp.wind import WindServer, job_params

#: this node's part in the cell (winder.contract.topics.ROLES), in every job status
ROLE = "interp"


class InterpNode(ManagedNode):
    def __init__(self) -> None:
        super().__init__("interp_node")
        self.settings = Settings(self, PARAMETERS, check_interp_settings)
        self.settings.add_pre_set(self.with_job_file)
        given = self.settings.values()["job_file"]
        if given:  # given at start (-p job_file:=...): load it as a change would
            result = self.set_parameters([Parameter("job_file", value=given)])[0]
            if not result.successful:
                self.settings.rejected.append(result.reason)

        self.pub_job = self.create_publisher(JobDescription, TOPIC_JOB, QOS_LATCHED)
        self.pub_steps = self.create_publisher(Int32MultiArray, TOPIC_STEPS, QOS_STREAM)
        self.diag = Diagnostics(self, "winder_interp")
        self.create_service(Trigger, "~/start", self.on_start)
        self.create_service(SetParametersAtomically, "~/start_run", self.on_start_run)
        # receipts and events count only from the cell's own consumer and profile node
        self.peers = Peers(self)
        self.solo = Solo(self, "interp", self.peers, self.leave)  # one interp node per cell
        self.solo.on_settled = self.on_ready  # an autostart that waited for it goes now
        # the Wind action: a goal is a run (it hears the consumer's statuses through solo)
        self.wind = WindServer(self, self, self.peers)
        self.solo.also = self.on_statuses  # the goal's, and the consumer's close of a run
        self.diag.foreign = self.peers.intruders.summary  # its statuses name what it refused
        self.peers.on_new = lambda: self.report()  # at once, not at the next second
        self.peers.subscribe(KeyValue, TOPIC_PROGRESS, self.on_progress, QOS_STATE)
        self.peers.subscribe(ControlEventMsg, TOPIC_CONTROL, self.on_control, QOS_EVENTS)
        # the start handshake: consumer and profile node ready (an autostart waits for it)
        self.readiness = Readiness(self, on_change=self.on_ready, peers=self.peers)
        # tick() sends a running job's chunks every 20 ms; idle, only the 1 Hz report runs
        self.tick_timer = steady_timer(self, 0.02, self.tick)
        steady_timer(self, 1.0, self.report)

        self.job: Job | None = None
        self.run_settings: dict[str, Any] = {}  # the settings the last run started with
        self.run_id = ""
        self.runs = 0  # runs started in this node's life
        self.pending: Iterator[npt.NDArray[np.int32]] | None = None  # generator of chunks of the running job
        self.sent = 0
        self.consumed = 0
        self.started_wall = 0.0
        self.autostarted = False
        self.finished = False
        self.aborted = ""  # why the running job was given up, if it was
        self.operator_abort = False  # it was aborted on purpose (~/abort, a schedule)
        self.last_receipt_wall = 0.0
        # a consumer that ignores an abort (docs/CONTRACT.md, 4.1 item 8) must not wedge the cell
        self.ended_wall = 0.0  # when the last run ended here by an abort or a give-up (0: it did not)
        self.progress_wall = 0.0  # when the consumer last took a step of the run
        self.busy_wall = 0.0  # since when the consumer says busy on winder/ready (0: it does not)
        self.abort_ignored = ""  # the report on it, made once per run
        if self.settings.blocked():
            self.diag.publish(
                "job", ERROR, str(self.settings.blocked()), status_values(JobState.BLOCKED, role=ROLE)
            )
        self.start_lifecycle()

    def destroy_node(self) -> None:
        """The action server first: it holds the node's handle, and with it the
        process' DDS participant, which stayed on the graph after the process
        ended (rclpy's destroy_node leaves waitables alone)."""
        self.wind.destroy()
        super().destroy_node()

    # -- lifecycle (winder.ros.managed) ----------------------------------------
    def in_run(self) -> bool:
        return self.running()

    def parameters_now(self) -> dict[str, Any]:
        """A restarted interp node never autostarts (winder.ros.rejoin): the part
        its first start wound is not wound again unasked."""
        return {**super().parameters_now(), "autostart": False}

    def blocked_reason(self) -> str | None:
        return self.settings.blocked()

    def lifecycle_changed(self) -> None:
        if self.active:
            self.wake()  # an autostart waits for the activation

    def with_job_file(self, params: list[Parameter]) -> list[Parameter]:
        """Setting ``job_file`` sets what the file says, in the same change:
        the job from its interp_node section, the ramp the run brings from
        its profile_node section (``ramp.*``, ``ramp.source`` job) and the
        file's sha256 (``job_file_sha256``, into the run's bag). Values set
        in the same change win over the file's. A file that cannot be used is
        left to the check, which refuses the change with the file's reason.
        A change of the job's fields without a job file (or a hash) clears
        the hash: the job is no longer the file's. A relative path is read
        from this node's working directory and set as the absolute path it
        names there (``winder ctl`` sends the caller's absolute path)."""
        named = {p.name for p in params}
        path = next((p.value for p in params if p.name == "job_file"), None)
        if path and isinstance(path, str) and not os.path.isabs(os.path.expanduser(path)):
            # relative: from this node's working directory, as ROS reads --params-file; the
            # parameter keeps the absolute path, so a get and every error name the file tried
            path = os.path.abspath(os.path.expanduser(path))
            params = [Parameter("job_file", value=path) if p.name == "job_file" else p for p in params]
        if not path or not isinstance(path, str):
            hashed = bool(self.get_parameter("job_file_sha256").value)
            if hashed and named & FIELD_SPECS.keys() and "job_file_sha256" not in named:
                return [*params, Parameter("job_file_sha256", value="")]
            return params
        try:
            given, digest = load_job_file_hashed(path)
        except (SpecError, ValueError):
            return params
        return params + job_params(given, digest, named)

    # -- in --------------------------------------------------------------
    def on_start(self, _req: Trigger.Request, resp: Trigger.Response) -> Trigger.Response:
        resp.success, resp.message = self.start_job()
        return resp

    def on_start_run(
        self, req: SetParametersAtomically.Request, resp: SetParametersAtomically.Response
    ) -> SetParametersAtomically.Response:
        """Set up and start a run in one call: the request's parameters (job
        fields, ramp.*) are set all together or not at all, and the run starts
        with them. A ``ramp.*`` value means the run brings its ramp: the call
        sets ``ramp.source`` to ``job`` too, unless it names ``ramp.source``
        itself (``profile_node`` with a ``ramp.*`` value is refused: the value
        would not ramp the run). Nothing is set when the cell cannot start a
        run now (a run going on, a node not ready); the reason is in
        ``result.reason``, the start reply in it when the run starts."""
        try:
            params = [Parameter.from_parameter_msg(p) for p in req.parameters]
        except Exception as exc:  # a type rclpy cannot take
            params, why = [], f"run not set up: {exc}".splitlines()[0]
        else:
            why = ""
        ok, message = self.start_with(params) if not why else (False, why)
        resp.result = SetParametersResult(successful=ok, reason=message)
        return resp

    def start_with(self, params: list[Parameter]) -> tuple[bool, str]:
        """Set ``params`` all together or not at all, and start a run with
        them (none: with the settings as they are): whether it started, and
        the start reply or the reason (a ``ramp.*`` value makes the run bring
        its ramp: see :func:`with_run_ramp`). The values are the run's, not
        the node's: once the run has started with them (its job description
        carries them) or was refused, the node's settings are again what they
        were before the call, so that nothing of one goal or ``~/start_run``
        (a schedule's abort, stops that wait for a call, another job) reaches
        a later start (issue 53)."""
        why = self.cannot_start()
        if why:
            return False, why
        if not params:
            return self.start_job()
        params, refused = with_run_ramp(params)
        if refused:
            return False, refused
        before = {name: self.get_parameter(name).value for name in INTERP_SPECS}
        rejected = list(self.settings.rejected)  # start-up values refused: the node stays blocked by them
        try:
            result = self.set_parameters_atomically(params)
        except Exception as exc:  # an undeclared name, a type rclpy cannot take
            why = f"run not set up: {exc}".splitlines()[0]
            result = SetParametersResult(successful=False, reason=why)
        if not result.successful:
            return False, result.reason or "run not set up"
        try:
            return self.start_job()
        finally:
            self.restore(before)
            self.settings.rejected = rejected

    def run_setting(self, name: str) -> Any:
        """A setting of the last run, as it started (the node's before any run)."""
        return (self.run_settings or self.settings.values())[name]

    def restore(self, before: dict[str, object]) -> None:
        """The node's settings back to ``before`` (those a run's start changed)."""
        changed = [
            Parameter(name, value=value)
            for name, value in before.items()
            if self.get_parameter(name).value != value
        ]
        if not changed:
            return
        if any(p.name == "job_file" for p in changed):
            # setting job_file loads the file's values for every name the change does not give:
            # give them all, so each is what it was (a value set by hand after the file included)
            changed = [Parameter(name, value=value) for name, value in before.items()]
        if all(p.name != "job_file_sha256" for p in changed):  # named, or the change clears it
            changed.append(Parameter("job_file_sha256", value=before["job_file_sha256"]))
        result = self.set_parameters_atomically(changed)
        if not result.successful:  # the earlier settings no longer hold (a job file changed on disk)
            self.get_logger().warning(
                f"settings not restored after the run's start ({result.reason}): the run's stay in force"
            )

    def cannot_start(self) -> str:
        """Why a run cannot start now ("" if it can)."""
        if not self.active:
            return f"job not started: {self.inactive_reason()}"
        if self.running():
            assert self.job is not None
            return (
                f"job {self.job.job_id} run {self.run_id} is running ({self.consumed}/{self.job.total_steps} "
                f"steps taken, {self.sent} sent): start refused, the running job goes on"
            )
        reported = bool(self.abort_ignored)
        if self.ignores_abort() and not reported:
            self.report()  # the ERROR at once, before the start it lets through
        if not self.solo.settled():  # another interp node may run here: it is not known yet
            return "job not started: not ready: not yet known to be the cell's only interp node"
        waiting = self.readiness.missing(excused=("consumer",) if self.abort_ignored else ())
        return f"job not started: {waiting}" if waiting else ""

    def on_ready(self) -> None:
        """A change on winder/ready: note since when the consumer says busy."""
        if self.readiness.states.get("consumer") is not ReadyState.BUSY:
            self.busy_wall = 0.0
        elif not self.busy_wall:
            self.busy_wall = time.monotonic()
        self.wake()

    def ignores_abort(self) -> bool:
        """Whether the consumer ignores the end of the last run: the run ended
        here (an abort, or given up after stall_abort) and the consumer still
        says busy, with no step taken, for longer than stall_abort. Reported
        once (a log line, then the job status is an ERROR until the next
        start); from then on that busy does not hold a start: the next job
        description replaces the run at the consumer."""
        if self.abort_ignored:
            return True
        now = time.monotonic()
        if self.job is None or not self.ended_wall or not self.busy_wall:
            return False
        if (
            self.readiness.states.get("consumer") is not ReadyState.BUSY
            or now - self.readiness.heard["consumer"] > FRESH
        ):
            return False  # not busy, or not heard from lately: nothing to excuse
        stuck = now - max(self.ended_wall, self.busy_wall, self.progress_wall)
        if stuck <= self.run_setting("stall_abort"):
            return False
        self.abort_ignored = (
            f"the consumer ignores the abort of run {self.run_id}: still busy {now - self.ended_wall:.1f} s "
            "after it ended (docs/CONTRACT.md); its busy no longer holds a start: the next job replaces "
            "the run"
        )
        self.get_logger().error(f"consumer state busy: {self.abort_ignored}")
        return True

    def wake(self) -> None:
        """Something happened that may let work go on: run tick() now and on its timer."""
        if self.tick_timer.is_canceled():
            self.tick_timer.reset()
        self.tick()

    def tick(self) -> None:
        autostart = self.settings.values()["autostart"] and self.active
        if not self.autostarted and autostart and not self.readiness.missing() and self.solo.settled():
            self.autostarted = True
            ok, why = self.start_job()
            if not ok:
                self.get_logger().error(why)
        self.send_some()
        if self.pending is None and self.running():  # all sent, not all taken yet
            self.abort_if_stalled()
        if not self.running() and self.pending is None:
            self.tick_timer.cancel()  # nothing to do until a start or a readiness change

    # -- work ------------------------------------------------------------
    def running(self) -> bool:
        """The job is not over: steps still to send, or (with a sim node
        acknowledging) steps sent that it has not taken yet."""
        if self.job is None or self.aborted:
            return False
        if self.pending is not None:
            return True
        return self.paced() and self.consumed < self.job.total_steps

    def paced(self) -> bool:
        """A sim node acknowledges the steps it takes (winder/progress)."""
        return self.count_publishers(self.resolve_topic_name(TOPIC_PROGRESS)) > 0

    def start_job(self) -> tuple[bool, str]:
        if self.running():
            return False, self.cannot_start()
        blocked = self.settings.blocked()
        if blocked:
            self.diag.publish("job", ERROR, blocked, status_values(JobState.BLOCKED, role=ROLE))
            return False, blocked
        waiting = self.cannot_start()
        if waiting:
            return False, waiting
        values = self.settings.values()
        try:
            job = Job.from_dict({k: values[k] for k in FIELD_SPECS})
        except SpecError as exc:
            self.diag.publish(
                "job", ERROR, f"job rejected: {exc}", status_values(JobState.BLOCKED, role=ROLE)
            )
            return False, f"job rejected: {exc}"
        self.runs += 1
        self.job = job
        self.run_settings = values  # the run's, whatever the node's settings become
        self.run_id = make_run_id(job.job_id, self.runs)
        self.sent = 0
        self.consumed = 0
        self.finished = False
        self.aborted = ""
        self.operator_abort = False
        self.started_wall = self.last_receipt_wall = self.progress_wall = time.monotonic()
        self.ended_wall, self.abort_ignored = 0.0, ""
        stops = stop_points(job, values["stops"]) if values["stops"] else []
        text = describe_job(
            job,
            self.run_id,
            run_ramp(values),
            stops,
            values["stop_pause"],
            values["stop_resume"],
            values["schedule"],
            values["job_file_sha256"],
            operator=values["operator"],
            wire_lot=values["wire_lot"],
        )
        self.pub_job.publish(job_description_msg(text))
        self.pending = self.chunks(job, values["chunk_steps"])
        if self.tick_timer.is_canceled():
            self.tick_timer.reset()
        self.get_logger().info(
            f"run {self.run_id}: job {job.job_id}, {job.total_steps} steps in {len(job.segments())} segments"
        )
        self.report()
        return True, (
            f"run {self.run_id} started: job {job.job_id}, {job.total_steps} steps; "
            f"bag {self.run_id} (in the consumer's bag_dir, if it records)"
        )

    @staticmethod
    def chunks(job: Job, size: int) -> Iterator[npt.NDArray[np.int32]]:
        for seg in job.segments():
            for first in range(0, seg.steps, size):
                stop = min(seg.steps, first + size)
                pos = interpolate_pieces(seg.start, seg.pieces, first=first, stop=stop)
                rows = np.empty((pos.shape[0], 1 + pos.shape[1]), dtype=np.int32)
                rows[:, 0] = seg.index
                rows[:, 1:] = pos
                yield rows

    def on_progress(self, msg: KeyValue) -> None:
        """A receipt: steps of the running job the sim node has taken. Anything
        else on the topic (another job's, not a count, more than was sent) is
        ignored with a warning: it must not move the flow control."""
        if self.job is None or msg.key not in (self.run_id, self.job.job_id):
            return
        value = msg.value.strip()
        if not (value.isdigit() and value.isascii() and int(value) <= self.sent):
            self.get_logger().warning(
                f"{TOPIC_PROGRESS}: receipt {msg.value[:40]!r} for job {msg.key} ignored: "
                f"must be a step count in [0, {self.sent}]",
                throttle_duration_sec=5.0,
            )
            return
        if int(value) > self.consumed:
            self.progress_wall = time.monotonic()  # a step taken: not stuck on the run
        was_running = self.running()
        self.consumed = max(self.consumed, int(value))
        self.last_receipt_wall = time.monotonic()  # a repeated receipt: the sim node is alive
        if was_running and not self.running():
            self.report()  # the run is over: "done" at once, not at the next second
        if self.pending is not None:
            self.send_some()  # the window has room again: fill it now, not at the next tick

    def on_statuses(self, raw: bytes, gid: bytes, statuses: list[Any]) -> None:
        """/diagnostics (Solo hands every array over): the Wind goal's, and
        the consumer's final report of the running run closed incomplete (its
        stall watch, a fault, a failed recording), which ends the run here at
        once: no receipt comes after it, and waiting for them refused every
        start for stall_abort though the consumer said ready before its report
        (docs/CONTRACT.md 5.3). Only the cell's consumer counts (Peers)."""
        self.wind.on_statuses(raw, gid, statuses)
        run_id = self.run_id
        closed = [
            st.message
            for st in statuses
            if (values := {kv.key: kv.value for kv in st.values}).get("role") == "consumer"
            and values.get("run_id") == run_id
            and values.get("state") == JobState.INCOMPLETE
        ]
        if self.job is None or self.aborted or not closed:
            return

        def act(_raw: bytes) -> None:
            if self.job is not None and self.run_id == run_id and self.running():
                self.give_up(
                    f"job {self.job.job_id} given up, incomplete: its consumer closed the run: {closed[-1]}"
                )

        self.peers.deliver(TOPIC_DIAGNOSTICS, gid, raw, act, role="consumer")

    def on_control(self, msg: ControlEventMsg) -> None:
        """An abort of the running run (winder/control): send it up to the
        abort's ``steps`` (the profile node brakes on them), nothing beyond.
        The profile node brings the axes to rest and the sim node closes the
        run aborted; events of other runs, or ill-formed, change nothing."""
        try:
            event = ControlEvent.from_message(msg)
        except EventError:
            return
        if event.kind is not EventKind.ABORT or self.job is None:
            return
        if event.run_id != self.run_id or self.aborted:
            return
        steps = event.steps
        self.pending = self.up_to(steps) if steps is not None else None
        self.ended_wall = time.monotonic()
        self.operator_abort = True
        total = self.job.total_steps
        self.aborted = f"run {self.run_id} aborted: the axes stop after {steps} of {total} steps"
        self.get_logger().info(self.aborted)
        self.report()

    def up_to(self, steps: int) -> Iterator[npt.NDArray[np.int32]] | None:
        """The chunks still to send of a run that ends after ``steps`` (an
        abort: the profile node brakes on steps not sent yet, when the window
        held them back), nothing beyond; None if they are all sent."""
        rest, sent = self.pending, self.sent
        if rest is None or sent >= steps:
            return None

        def cut(rest: Iterator[npt.NDArray[np.int32]], sent: int) -> Iterator[npt.NDArray[np.int32]]:
            for rows in rest:
                yield rows[: steps - sent]
                sent += rows.shape[0]
                if sent >= steps:
                    return

        return cut(rest, sent)

    def send_some(self) -> None:
        if self.pending is None or self.pub_steps.get_subscription_count() == 0:
            return  # nothing to send, or nobody to send it to yet
        # flow control: with a sim node reporting progress, keep at most
        # max_in_flight steps between us and it; without one, send freely
        window = self.run_setting("max_in_flight")
        paced = self.paced()
        deadline = time.monotonic() + 0.015  # stay responsive to services and parameters
        while time.monotonic() < deadline:
            if paced and self.sent - self.consumed >= window:
                self.abort_if_stalled()
                return
            rows = next(self.pending, None)
            if rows is None:
                self.pending = None
                self.finished = True
                self.report()
                return
            self.pub_steps.publish(STEPS_CDR.encode(rows))
            self.sent += rows.shape[0]

    def abort_if_stalled(self) -> None:
        """Stop sending a job whose receipts stopped: its sim node died or was
        restarted and will never take the steps in flight. The sim node closes
        its side after the same time; the next start runs a new job."""
        quiet = time.monotonic() - self.last_receipt_wall
        if self.job is None or quiet <= self.run_setting("stall_abort"):
            return
        self.give_up(
            f"job {self.job.job_id} given up, incomplete: no receipt from the consumer for {quiet:.1f} s "
            f"(stall_abort) at {self.consumed}/{self.sent} steps taken of {self.sent} sent"
        )

    def give_up(self, why: str) -> None:
        """The running run is over for this node, incomplete: nothing more is
        sent, and the next start is not held by it (its consumer went)."""
        if self.job is None or self.aborted:
            return
        self.get_logger().error(why)
        self.pending = None
        self.aborted = why
        self.ended_wall = self.ended_wall or time.monotonic()
        self.report()

    def report(self) -> None:
        if (
            not self.autostarted
            and self.settings.values()["autostart"]
            and not self.readiness.missing()
            and self.solo.settled()
        ):
            self.wake()  # autostart switched on while the cell was ready already
            return
        blocked = self.settings.blocked()
        if blocked:  # repeated, as a status is: late listeners hear it too
            self.diag.publish("job", ERROR, blocked, status_values(JobState.BLOCKED, role=ROLE))
            return
        if self.job is None:
            self.diag.publish("job", OK, "idle: no job started", status_values(JobState.IDLE, role=ROLE))
            return
        total = self.job.total_steps
        ignored = self.ignores_abort()  # checked every second: reported once, as soon as it holds
        state = (
            JobState.INCOMPLETE if self.aborted else (JobState.RUNNING if self.running() else JobState.DONE)
        )
        if self.operator_abort:
            state = JobState.ABORTED
        sending = "sending" if self.pending is not None else "all sent"
        self.diag.publish(
            "job",
            ERROR if (self.aborted and not self.operator_abort) or ignored else OK,
            self.abort_ignored or self.aborted or f"run {self.run_id}: {sending}, {self.sent}/{total} steps",
            status_values(
                state,
                self.job.job_id,
                self.run_id,
                self.sent,
                total,
                role=ROLE,
                steps_taken=self.consumed,
                elapsed_s=f"{time.monotonic() - self.started_wall:.3f}",
            ),
        )


def with_run_ramp(params: list[Parameter]) -> tuple[list[Parameter], str]:
    """A ``~/start_run`` request's parameters with what its ramp values
    mean: any ``ramp.*`` value given (``ramp.profile: trapezoid``) makes the
    run bring its ramp, so ``ramp.source: job`` is added when the request
    does not name the source; a request that names ``ramp.source`` other
    than ``job`` beside ramp values is refused (the reason, "" if none), as
    its ramp would silently not apply."""
    named = {p.name: p for p in params}
    ramp = [p.name for p in params if p.name.startswith("ramp.") and p.name != "ramp.source"]
    if not ramp:
        return params, ""
    source = named.get("ramp.source")
    if source is None:
        return [*params, Parameter("ramp.source", value="job")], ""
    if source.value != "job":
        return params, (
            f"run not set up: {ramp[0]} given but ramp.source is {source.value!r}: the run would ramp "
            "with the profile node's settings, not the ramp given; set ramp.source: job (or leave it "
            "out) to run with the ramp given"
        )
    return params, ""


def main(args: list[str] | None = None) -> None:
    spin(InterpNode, args)
