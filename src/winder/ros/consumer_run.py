"""``ConsumerRun``: a consumer's run - its books, its reports and its close.

:class:`winder.ros.consumer.StepConsumer` (the node: the graph, the
handshake, the intake of a run's description, events and chunks) holds one
``ConsumerRun`` for its life; each run starts it again (:meth:`ConsumerRun.start`).
It keeps what a run owes the cell once its steps are accepted:

* the books: the run's description (``plan``), its operator states
  (:class:`winder.contract.run.RunLedger`), its chunks checked into rows
  (:class:`winder.ros.intake.RowGate`), the time execution reached (``t_ns``),
  the chunks received and not handed over yet (``inbox``), its errors;
* receipts on ``winder/progress`` (steps executed plus steps known missing):
  the interp node's flow control and its sign that the run is over;
* the run's states on ``winder/state`` as execution reaches them (a pause's
  rest, a programmed stop), and a programmed stop on ``/diagnostics`` too;
* the settling (every step executed or missing, or an abort's rest reached:
  the engine settles the axes, then the run closes);
* the stall watch: no steps for ``stall_timeout`` s is reported, for
  ``stall_abort`` s closes the run incomplete (a consumer never wedges the cell);
* the ``<node>: job`` status every second (:class:`winder.contract.run.JobReport`),
  and the final report once the bag is closed: that status, and typed on
  ``winder/report`` (winder_interfaces/JobReport);
* the run's part in the part index (:mod:`winder.record.parts`): ``running``
  from the bag's opening, completed from the final report at the close; an
  index that cannot be written is an error of the run, never its end.

It is the :class:`winder.ros.engine.RunPort` the node's engine sees: an
engine tells it what it executed and how far the run's time went, and asks
it what it may know; it never sees the node.
"""

from __future__ import annotations

import json
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

from diagnostic_msgs.msg import KeyValue
from rclpy.node import Node
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import String

from winder import __version__
from winder.contract.params import PARTS_DB_NONE, PROFILE_SPECS, bag_directory
from winder.contract.run import FAULTS_KEY, PART_ID_KEY, PART_INDEX_KEY, JobReport, RunLedger, Transition
from winder.contract.states import CellState, JobState
from winder.contract.stream import JobPlan, StreamChecker
from winder.contract.topics import TOPIC_PROGRESS, TOPIC_REPORT, TOPIC_STATE, TOPIC_STEP_TIMES, status_values
from winder.contract.trust import Intruders
from winder.errors import WinderError
from winder.record.bag import VERSION_KEY, signals_held
from winder.record.parts import PartEnd, PartIndex, index_path, part_start
from winder.ros.diagnostics import ERROR, OK, WARN, Diagnostics
from winder.ros.engine import Engine
from winder.ros.graph import Who
from winder.ros.intake import RowGate
from winder.ros.interfaces import job_report_msg, wall_stamp
from winder.ros.peers import Peers
from winder.ros.qos import QOS_LATCHED, QOS_STATE
from winder.ros.run_bag import RunBag
from winder.ros.settings import Settings
from winder_interfaces.msg import CellState as CellStateMsg
from winder_interfaces.msg import JobReport as JobReportMsg

__all__ = ["ConsumerRun"]


class ConsumerRun:
    """One consumer's run (see the module doc). ``announce`` says the node's
    readiness, ``pump`` does the node's due work, ``take_control`` takes the
    operator events already here: the three things of the node's a run asks for."""

    def __init__(
        self,
        node: Node,
        engine: Engine,
        settings: Settings,
        recording: RunBag,
        peers: Peers,
        *,
        hardware_id: str,
        announce: Callable[[], None],
        pump: Callable[[], None],
        take_control: Callable[[], None],
    ) -> None:
        self.node, self.engine, self.settings = node, engine, settings
        self.recording, self.peers, self.hardware_id = recording, peers, hardware_id
        self.announce, self.pump, self.take_control = announce, pump, take_control
        self.log = node.get_logger()
        self.diag = Diagnostics(node, hardware_id)
        self.pub_progress = node.create_publisher(KeyValue, TOPIC_PROGRESS, QOS_STATE)
        self.pub_cell_state = node.create_publisher(CellStateMsg, TOPIC_STATE, QOS_LATCHED)
        self.pub_report = node.create_publisher(JobReportMsg, TOPIC_REPORT, QOS_LATCHED)
        #: the consumer's name in the graph, namespace first (who sent a state or a report)
        self.node_name = node.get_fully_qualified_name().lstrip("/")
        self.last_report: JobReport | None = None
        self.last_level, self.last_text = OK, ""
        self.clear()

    def clear(self) -> None:
        """Forget the last run."""
        self.plan: JobPlan | None = None
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
        self.part: tuple[PartIndex, str] | None = None  # the run's part: its index and id
        self.timer_of_run: Who | None = None  # the profile node (its process) that times the run

    def start(self, plan: JobPlan) -> None:
        """A run starts: fresh books for it."""
        self.clear()
        self.peers.run = Intruders()
        self.plan = plan
        self.recording.start(plan, self.wall0_ns)
        self.ledger = RunLedger(plan)
        self.gate = RowGate(plan, self.error, self.log.warning)
        self.checker = self.gate.checker

    def begin_part(self, values: dict[str, Any]) -> None:
        """The run's part, ``running``, in the index its ``parts_db`` names
        (once its bag is open: the part names it)."""
        assert self.plan is not None
        bag = self.recording.path
        try:
            path = self.index_path(values)
            if path is None:
                return
            index = PartIndex(path)
            part = part_start(
                self.plan,
                consumer=self.node_name,
                simulated=self.engine.simulated(),
                software_version=__version__,
                started_ns=self.wall0_ns,
                bag=str(bag.resolve()) if bag is not None else "",
            )
            self.part = (index, index.begin(part))
        except (WinderError, ValueError) as exc:  # ValueError: bag_dir refused since it was accepted
            self.error(f"run {self.plan.run_id}: its part is not recorded: {exc}")

    @staticmethod
    def index_path(values: dict[str, Any]) -> Path | None:
        """The part index the settings name (:func:`winder.record.parts.index_path`), None for
        ``none``; the bag directory is looked at only for ``auto``."""
        if values["parts_db"] in PARTS_DB_NONE:
            return None
        auto = values["parts_db"] == "auto" and values["record"]
        return index_path(values["parts_db"], bag_directory(values["bag_dir"]) if auto else None)

    def recover_parts(self, values: dict[str, Any]) -> None:
        """At start: the parts of this host's runs whose process was killed, marked incomplete, said once."""
        try:
            path = self.index_path(values)
            if path is None or not path.exists():
                return
            gone = PartIndex(path).recover()
        except (WinderError, ValueError) as exc:
            self.log.error(str(exc))
            return
        if gone:
            self.log.warning(
                f"part index {path}: {len(gone)} part(s) of runs whose process ended without closing "
                f"them marked incomplete: {', '.join(gone[:5])}{' ...' if len(gone) > 5 else ''}"
            )

    # -- what the engine may know (winder.ros.engine.RunPort) -------------------
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

    @property
    def at_rest(self) -> bool:
        """Paused by the operator, every step up to the rest executed."""
        return self.ledger is not None and self.ledger.at_rest and not self.finishing

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

    # -- what the engine tells ----------------------------------------------------
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

    def receipt(self) -> None:
        """The steps of the run executed so far, or known missing, on
        winder/progress: the interp node's flow control (at most max_in_flight
        steps sent and not yet executed) and its sign that the run is over;
        repeated every second, the sign this node is alive while it paces a
        real-time run. Refused chunks do not count: they were never the run's."""
        if self.plan is not None and self.checker is not None and self.ledger is not None:
            self.ledger.missing_steps = self.checker.missing
            self.pub_progress.publish(
                KeyValue(key=self.plan.run_id or self.plan.job_id, value=str(self.ledger.accounted))
            )

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

    def record(self, key: str, t_ns: int, data: bytes, *, exact: bool = False) -> None:
        """One message into the run's bag, if it records. A failed write (a
        full disk) stops the recording; the next pump then closes the run incomplete."""
        self.recording.record(key, t_ns, data, exact=exact)

    def error(self, why: str) -> None:
        self.errors.append(why)
        self.log.error(why)
        plan = self.plan
        self.publish_status(
            "stream",
            ERROR,
            why,
            {"job_id": plan.job_id if plan else "", "run_id": plan.run_id if plan else ""},
        )

    def publish_status(
        self, task: str, level: int, text: str, values: dict[str, object], *, t_ns: int | None = None
    ) -> None:
        """A status of this node on /diagnostics, and into the run's bag at
        once: an ERROR raised just before the run closes is in its bag too."""
        status = self.diag.status(task, level, text, values)
        self.record("diagnostics", self.t_ns if t_ns is None else t_ns, serialize_message(status))
        if self.node.context.ok():  # at a shutdown the bag still gets it: the run's end must not raise here
            self.diag.pub.publish(status)

    def cell_state(
        self, state: CellState, text: str, where: tuple[int, int, int] = (0, 0, 0), t_ns: int | None = None
    ) -> None:
        """winder/state: the cell's state at a transition, latched, and into the bag."""
        plan = self.plan
        t = self.t_ns if t_ns is None else t_ns
        coil, layer, turn = where
        msg = CellStateMsg(
            stamp=wall_stamp(),
            node=self.node_name,
            state=str(state),
            job_id=plan.job_id if plan else "",
            run_id=plan.run_id if plan else "",
            coil=coil,
            layer=layer,
            turn=turn,
            sim_time_s=t / 1e9,
            message=text,
        )
        if plan is not None:
            self.record("state", t, serialize_message(msg))
        if self.node.context.ok():
            self.pub_cell_state.publish(msg)

    # -- reports ------------------------------------------------------------------
    def job_report(self, state: JobState) -> JobReport:
        assert self.plan is not None and self.checker is not None
        run = self.peers.run  # the run's refused messages, and who sent them
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
                **({"foreign_messages": str(run.total), "intruders": run.summary()} if run.total else {}),
                **(
                    {"operator_events": str(self.ledger.events)} if self.ledger and self.ledger.events else {}
                ),
            },
        )

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
        report.extra[VERSION_KEY] = __version__  # which winder ran it, as its bag's metadata says
        faults = self.engine.faults()
        if faults:  # said as a key of its own too: a done run with faults is no success (CONTRACT 3.7)
            report.extra[FAULTS_KEY] = faults
        if self.part is not None:  # the run's part, and where it is (CONTRACT 3.7)
            report.extra[PART_ID_KEY] = self.part[1]
            report.extra[PART_INDEX_KEY] = str(self.part[0].path.resolve())
        ok = (complete or aborted) and not self.errors and not faults
        level = OK if ok else (WARN if complete or aborted else ERROR)
        state = "complete" if complete else ("aborted, the axes at rest" if aborted else "incomplete")
        text = f"job {self.plan.job_id}: {state}, {report.steps_done}/{self.plan.total_steps} steps"
        if self.errors:
            text += f", {len(self.errors)} stream errors (first: {self.errors[0]})"
        if faults:
            text += f", {faults}"
        return report, level, text

    def told_again(self, told: dict[str, Any]) -> None:
        """How the last run ended, as the process this one replaced closed it
        (winder.ros.rejoin): its final status and report never left that
        process, the others having dropped it; said now, and by the 1 Hz
        status from here on, as for any run that ended."""
        try:
            report = JobReport.from_values({str(k): str(v) for k, v in told["values"].items()})
            level, text = int(told["level"]), str(told["text"])
        except (KeyError, TypeError, ValueError, AttributeError):
            return
        self.last_report, self.last_level, self.last_text = report, level, text
        self.log.warning(f"the run this node closed before its restart: {text}")
        self.diag.publish("job", level, text, report.to_values())
        self.pub_report.publish(job_report_msg(report, self.node_name))

    def report(self) -> None:
        """The 1 Hz ``<node>: job`` status: the running run's, or how the last one ended."""
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

    # -- the stall watch ------------------------------------------------------------
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
        if self.lost_its_timer():
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
            self.log.warning(why)
            self.publish_status(
                "stream", self.stall_level(), why, {"job_id": self.plan.job_id, "run_id": self.plan.run_id}
            )
        if self.stalled:
            self.longest_stall = max(self.longest_stall, idle)
        if idle > settings["stall_abort"]:
            self.error(f"step stream stalled for {idle:.1f} s at {done} steps: job closed incomplete")
            self.finish(complete=False)

    def lost_its_timer(self) -> bool:
        """The profile node that times the run is another process now (it was
        restarted: by hand, or after a hold past the DDS lease,
        winder.ros.rejoin): the run's timing went with the old one, and no
        more of its steps will come. Closed incomplete at once, the axes at
        rest where the last step left them, instead of after stall_abort."""
        assert self.plan is not None and self.ledger is not None
        now = self.peers.owner("profile")
        if self.timer_of_run is None:
            self.timer_of_run = now
            return False
        if now is None or now == self.timer_of_run or now[:2] != self.timer_of_run[:2]:
            return False
        done = f"{self.ledger.executed_steps}/{self.plan.total_steps}"
        self.error(
            f"the profile node {now.fq} is a new process (restarted) at {done} steps: the run's timing went "
            "with the old one: job closed incomplete, the axes at rest"
        )
        self.finish(complete=False)
        return True

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

    # -- the close ------------------------------------------------------------------
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

    def closed_part(self, complete: bool) -> tuple[JobReport, int, str]:
        """:meth:`final_report`, and the run's part completed with it; a part
        that cannot be written is an error of the run, in that report."""
        report, level, text = self.final_report(complete)
        if self.part is None:
            return report, level, text
        index, part_id = self.part
        try:
            index.close(part_id, PartEnd(time.time_ns(), {k: str(v) for k, v in report.to_values().items()}))
        except WinderError as exc:
            self.part = None  # not tried again at this close
            self.error(f"run {report.run_id}: its part is not recorded: {exc}")
            report, level, text = self.final_report(complete)
        return report, level, text

    def _finish(self, complete: bool) -> None:
        assert self.plan is not None
        report, level, text = self.closed_part(complete)
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
        typed = job_report_msg(report, self.node_name)
        bag = self.recording.path
        if bag is not None:
            # the final report goes into the bag too, and the bag is closed
            # before anyone hears "done": whoever stops us then finds it complete
            self.record("diagnostics", self.t_ns, serialize_message(final))
            self.record("report", self.t_ns, serialize_message(typed))
            self.recording.close()
            if self.recording.failure:  # left unclosed: winder bag recover reads it
                report, level, text = self.closed_part(complete)  # no longer complete
                final = self.diag.status("job", level, text, report.to_values())
                typed = job_report_msg(report, self.node_name)
        if self.node.context.ok():
            self.log.info(text + (f"; bag {bag}" if bag else ""))
        self.last_report, self.last_level, self.last_text = report, level, text
        self.plan = None
        self.part = None
        self.finishing = False
        self.recording.start(None, self.wall0_ns)
        self.engine.end()
        if self.node.context.ok():  # at Ctrl-C the context is already shut down
            self.announce()  # ready first: whoever hears "done" can start the next run at once
            self.diag.pub.publish(final)
            self.pub_report.publish(typed)
