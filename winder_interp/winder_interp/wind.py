"""The cell's ``Wind`` action (``winder_interfaces/action/Wind`` on
``winder/wind``), served by the interp node: a goal is a run.

* goal: ``job`` (a job file's text, the files ``winder run`` reads; "" = the
  node's settings as they are), ``goal_sha256`` (the goal's hash as sent: a
  goal cut at a NUL on its way is refused), ``overrides`` (``KEY=VALUE`` settings of
  the interp node for this run, as ``winder ctl start --set``) and
  ``operator_name`` and ``wire_lot`` (the run's, for its part: the interp
  node's settings ``operator`` and ``wire_lot`` for this run, "" = as they
  are; ``operator`` is a C++ keyword, no field's name). A job text is
  a whole job (:func:`goal_params`: what it gives the interp node and its
  ramp, the rest of the job at its defaults; every other node's section is
  theirs); the overrides win; all is set in one change, then the run starts.
* a goal the cell cannot take now (a run going on, a node not ready, a job
  or setting that is not valid) is accepted and ends at once ABORTED, its
  result's ``message`` the reason, in the words ``winder check`` and
  ``winder ctl start`` use: a rejected goal could not say why;
* feedback: ``run_id``, the state, the steps executed of the total, the
  coil, layer and turn they reached, and the wire's tension where the
  consumer measures one (NaN otherwise), twice a second and at each state;
* result: ``success`` (the run ended complete, its report naming no ``faults``: a run
  whose axes lost steps is done, not a success), ``run_id``, ``bag_path``,
  ``part_id`` (the run's part in the consumer's part index, docs/PARTS.md),
  ``message`` (the consumer's final word) and the typed final report, once
  the consumer has closed the run's bag and said how it ended; a consumer
  silent for the node's ``stall_abort`` ends the goal, the run given up;
* a cancel is an abort (the profile node's ``~/abort``: the axes braked to
  rest, the bag closed): the goal ends CANCELED with the aborted run's report.

Every message it acts on comes from the cell's own consumer
(:class:`winder.ros.peers.Peers`), as the interp node's receipts do.
"""

from __future__ import annotations

import bisect
import math
import time
import traceback
from dataclasses import dataclass, field
from typing import Any, Protocol

from geometry_msgs.msg import WrenchStamped
from rclpy.action.server import ActionServer, CancelResponse, GoalResponse, ServerGoalHandle
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from std_srvs.srv import Trigger

from winder.contract.jobfile import goal_facts, goal_sha256, load_job_text
from winder.contract.params import INTERP_SPECS, interp_setting
from winder.contract.run import JobReport
from winder.contract.states import FINAL_JOB_STATES, JobState, asks_again
from winder.contract.topics import ACTION_WIND, TOPIC_DIAGNOSTICS, TOPIC_STATE, TOPIC_TENSION
from winder.errors import BadInputError
from winder.motion.job import FIELD_SPECS, Job
from winder.ros.graph import Who, fully_qualified
from winder.ros.interfaces import job_report_msg
from winder.ros.peers import Peers
from winder.ros.qos import QOS_LATCHED_READER
from winder.ros.run_bag import one_line
from winder.ros.settings import Settings
from winder.ros.timers import steady_timer
from winder_interfaces.action import Wind
from winder_interfaces.msg import CellState

__all__ = ["JOB_SETTINGS", "WindCell", "WindServer", "goal_params", "job_params"]

#: s between feedbacks while a run goes on
FEEDBACK_PERIOD = 0.5
#: s a goal waits for a cell that is not ready yet (its nodes still discovering each other)
START_WAIT = 10.0


class WindCell(Protocol):
    """What the server needs of the interp node."""

    run_id: str
    job: Job | None
    consumed: int
    aborted: str
    operator_abort: bool
    settings: Settings

    def cannot_start(self) -> str: ...

    def start_with(self, params: list[Parameter]) -> tuple[bool, str]: ...

    def give_up(self, why: str) -> None: ...

    def run_setting(self, name: str) -> Any: ...


def job_params(given: dict[str, dict[str, Any]], digest: str, named: set[str]) -> list[Parameter]:
    """The interp node's parameters a job file sets (:func:`winder.contract.jobfile.load_job_file_hashed`'s
    ``given``): its interp_node section, its ramp as the run's (``ramp.*``,
    ``ramp.source: job``) and the file's sha256; none of the names ``named``
    (set in the same change: they win)."""
    out = [Parameter(k, value=v) for k, v in given["interp_node"].items() if k not in named]
    if "job_file_sha256" not in named:
        out.append(Parameter("job_file_sha256", value=digest))
    if given["profile_node"]:
        ramp = {"ramp.source": "job", **{f"ramp.{k}": v for k, v in given["profile_node"].items()}}
        out += [Parameter(k, value=v) for k, v in ramp.items() if k not in named]
    return out


#: what a job text is whole in: the job's fields, its stops and schedule (a field the text does
#: not give takes its default, not what an earlier goal left); the node's own settings
#: (autostart, chunk_steps, max_in_flight, stall_abort) are not the job's
JOB_SETTINGS = (*FIELD_SPECS, "stops", "stop_pause", "stop_resume", "schedule")


def goal_params(
    job: str, overrides: list[str], sha256: str = "", *, operator: str = "", wire_lot: str = ""
) -> list[Parameter]:
    """The change a goal asks for: its job text's settings, then its
    ``KEY=VALUE`` overrides (which win), its ``operator`` and ``wire_lot``
    (those given: the overrides ``operator=...``, ``wire_lot=...``, each
    given one way). A job text is a whole job: the
    settings of :data:`JOB_SETTINGS` it does not give take their defaults,
    and without a profile_node section the run is ramped by the profile
    node's settings. ``sha256`` (hex, "" for none) is what the sender hashed
    (:func:`winder.contract.jobfile.goal_sha256`): a goal that came otherwise
    is refused, for a string ends at its first NUL on its way (rcl's C
    strings), and a job or an override cut there is a valid goal nobody
    asked for. BadInputError (one line) if the job or an override cannot be
    used."""
    facts = goal_facts(operator, wire_lot)
    if sha256:
        wanted = sha256.strip().lower()
        if len(wanted) != 64 or any(c not in "0123456789abcdef" for c in wanted):
            raise BadInputError(f"goal_sha256: {sha256[:80]!r} is not a SHA-256 in hex (64 of 0-9a-f)")
        got = goal_sha256(job, overrides, operator=operator, wire_lot=wire_lot)
        if got != wanted:
            size = len(job.encode("utf-8"))
            also = "".join(f", {fact.split('=', 1)[0]}" for fact in facts)
            raise BadInputError(
                f"goal_sha256: the goal came as a {size}-byte job and {len(overrides)} overrides{also} "
                f"hashing to {got[:12]}..., not the {wanted[:12]}... sent (cut at a NUL byte, or changed "
                "on its way): nothing set"
            )
    values = dict(interp_setting(text, "overrides") for text in overrides)
    for fact in facts:
        name, value = interp_setting(fact, "goal")  # SpecError: "operator='a\x07' is invalid: must be ..."
        if name in values:
            raise BadInputError(f"goal: {name} given as a field and as an override: give it one way")
        values[name] = value
    params = [Parameter(k, value=v) for k, v in values.items()]
    if job.strip() and values.get("job_file"):
        raise BadInputError("overrides: job_file given beside the goal's job: give the job one way")
    if job.strip():
        given, digest = load_job_text(job, name="goal job")
        named = set(values) | {"job_file"}
        # the job is the goal's, not a file's: job_file is cleared, its hash is the text's
        params += [Parameter("job_file", value=""), *job_params(given, digest, named)]
        named |= {p.name for p in params}
        params += [Parameter(k, value=INTERP_SPECS[k].default) for k in JOB_SETTINGS if k not in named]
        if "ramp.source" not in named:
            params.append(Parameter("ramp.source", value="profile_node"))
    return params


@dataclass
class Running:
    """The goal whose run goes on."""

    handle: ServerGoalHandle
    run_id: str
    total: int
    job: Job
    #: the steps before each segment, for the coil, layer and turn a step count reached
    offsets: list[int]
    done: Future = field(default_factory=Future)
    state: str = JobState.RUNNING
    tension: float = math.nan
    report: JobReport | None = None
    consumer: str = ""  #: the consumer that sent the report (its name in the graph)
    message: str = ""
    abort_asked: bool = False
    #: when the consumer last spoke of the run (its job status, every second; a state)
    heard: float = field(default_factory=time.monotonic)


class WindServer:
    """The ``Wind`` action server of the interp node ``node`` (see the module doc)."""

    def __init__(self, node: Node, cell: WindCell, peers: Peers) -> None:
        self.node, self.cell, self.peers = node, cell, peers
        self.log = node.get_logger()
        self.goal: Running | None = None
        self.waiting: set[bytes] = set()  # the ids of goals waiting for the cell to be ready
        self.server = ActionServer(
            node,
            Wind,
            ACTION_WIND,  # relative: /<ns>/winder/wind
            execute_callback=self.execute,
            goal_callback=lambda _goal: GoalResponse.ACCEPT,
            cancel_callback=self.on_cancel,
        )
        peers.subscribe(CellState, TOPIC_STATE, self.on_state, QOS_LATCHED_READER)
        # the tension comes at every simulated sample (thousands a second as fast as possible): the
        # feedback wants the last one, so the reader keeps one and takes it when it can
        latest = QoSProfile(
            depth=1, reliability=ReliabilityPolicy.BEST_EFFORT, history=HistoryPolicy.KEEP_LAST
        )
        peers.subscribe(WrenchStamped, TOPIC_TENSION, self.on_tension, latest, role="consumer")
        self.timer = steady_timer(node, FEEDBACK_PERIOD, self.feedback)
        self.abort_client: Any = None

    def node_stall_abort(self) -> float:
        """The interp node's stall_abort (s): how long a run may go without word from its consumer."""
        return float(self.cell.run_setting("stall_abort"))

    def destroy(self) -> None:
        """The action server goes (before its node: it holds the node's handle)."""
        self.server.destroy()

    # -- a goal ------------------------------------------------------------------
    async def execute(self, handle: ServerGoalHandle) -> Wind.Result:
        """A goal, from its request to its result; an error of the server's
        own ends it ABORTED saying so (its traceback in the node's log)."""
        try:
            return await self.wind(handle)
        except Exception as exc:
            self.log.error(f"goal {goal_id(handle)}: internal error\n{traceback.format_exc()}")
            if handle.is_active:
                handle.abort()
            return Wind.Result(
                message=f"internal error of the Wind server: {one_line(exc)} (in the interp node's log)"
            )

    async def wind(self, handle: ServerGoalHandle) -> Wind.Result:
        request = handle.request
        result = Wind.Result()
        if self.goal is not None:
            result.message = self.cell.cannot_start() or (
                f"job {self.goal.job.job_id} run {self.goal.run_id} is running (a Wind goal's): "
                "start refused, the running job goes on"
            )
            handle.abort()
            return result
        try:
            params = goal_params(
                request.job,
                list(request.overrides),
                request.goal_sha256,
                operator=request.operator_name,
                wire_lot=request.wire_lot,
            )
        except BadInputError as exc:
            result.message = f"job rejected: {one_line(exc)}"
            handle.abort()
            return result
        self.waiting.add(goal_key(handle))
        try:
            waited = await self.until_ready(handle)
        finally:
            self.waiting.discard(goal_key(handle))
        ok, message = self.cell.start_with(params) if not waited else (False, waited)
        job = self.cell.job
        if not ok or job is None:
            result.message = message
            if handle.is_cancel_requested:  # given up while the cell was not ready
                handle.canceled()
            else:
                handle.abort()
            return result
        offsets = [0]
        for seg in job.segments():
            offsets.append(offsets[-1] + seg.steps)
        goal = self.goal = Running(handle, self.cell.run_id, job.total_steps, job, offsets)
        self.log.info(f"goal {goal_id(handle)}: {message}")
        self.feedback()
        try:
            await goal.done
        finally:
            self.goal = None
        return self.finish(goal)

    async def until_ready(self, handle: ServerGoalHandle) -> str:
        """Wait while the cell is only not ready yet (its nodes still finding
        each other), as ``winder ctl start`` asks again, for at most
        :data:`START_WAIT` s or until the goal is canceled: "" once it can
        start, else why it cannot."""
        end = time.monotonic() + START_WAIT
        while True:
            why = self.cell.cannot_start()
            if handle.is_cancel_requested:
                return why or "goal canceled before its run started"
            if not asks_again(why):
                return why
            if time.monotonic() > end:
                return f"{why} (still, after {START_WAIT:g} s)"
            await self.pause(0.1)

    async def pause(self, seconds: float) -> None:
        """Let ``seconds`` pass on the steady clock, the executor serving everything else."""
        tick: Future = Future()
        timer = steady_timer(self.node, seconds, lambda: tick.done() or tick.set_result(True))
        try:
            await tick
        finally:
            timer.cancel()
            self.node.destroy_timer(timer)

    def finish(self, goal: Running) -> Wind.Result:
        """The goal's last feedback and its result, its state set: SUCCEEDED,
        CANCELED or ABORTED."""
        result = Wind.Result(run_id=goal.run_id, message=goal.message)
        report = goal.report
        if report is not None:  # the last feedback: where the run ended, as its report says
            goal.state = report.state
            self.publish(goal, min(report.steps_done, goal.total))
            result.success = report.state == JobState.DONE and not report.faults  # done, as commanded
            result.bag_path = report.bag
            result.part_id = report.part_id  # its part in the consumer's part index ("" none)
            result.report = job_report_msg(report, goal.consumer)
        if result.success:
            goal.handle.succeed()
        elif goal.handle.is_cancel_requested:
            goal.handle.canceled()
        else:
            goal.handle.abort()
        return result

    def on_cancel(self, handle: ServerGoalHandle) -> CancelResponse:
        """A cancel is an abort of the goal's run (the profile node brakes the
        axes to rest); the goal ends CANCELED once the consumer closed the run."""
        if goal_key(handle) in self.waiting:
            return CancelResponse.ACCEPT  # it stops waiting for the cell to be ready
        goal = self.goal
        if goal is None or goal.handle is not handle:
            return CancelResponse.REJECT
        if goal.abort_asked:
            return CancelResponse.ACCEPT  # asked already: the run is being aborted
        profile = self.peers.owner("profile")
        if profile is None:
            self.log.error(f"goal of run {goal.run_id}: cancel refused: no profile node to abort the run")
            return CancelResponse.REJECT
        goal.abort_asked = True
        self.ask_abort(goal, profile)
        return CancelResponse.ACCEPT

    def ask_abort(self, goal: Running, profile: Who) -> None:
        """The profile node ``profile``'s ``~/abort`` for the goal's run."""
        service = fully_qualified("abort", fully_qualified(profile.name, profile.namespace))
        if self.abort_client is None or self.abort_client.srv_name != service:
            self.abort_client = self.node.create_client(Trigger, service)
        future = self.abort_client.call_async(Trigger.Request())

        def answered(f: Future) -> None:
            reply = f.result()
            if reply is not None and not reply.success:
                # refused (every step of an as-fast-as-possible run timed already): the run ends
                # as it ends, and a later cancel asks again
                goal.abort_asked = False
                self.log.warning(f"goal of run {goal.run_id}: cancel: {service}: {reply.message}")

        future.add_done_callback(answered)
        self.log.info(f"goal of run {goal.run_id} canceled: aborting the run ({service})")

    # -- what the consumer says ---------------------------------------------------
    def on_statuses(self, raw: bytes, gid: bytes, statuses: list[Any]) -> None:
        """/diagnostics (the interp node's Solo hands every array over): the
        consumer's job status of the goal's run, and its final report."""
        goal = self.goal
        if goal is None:
            return
        mine = []  # the statuses that speak of the goal's run as its consumer: only those are judged
        for st in statuses:
            values = {kv.key: kv.value for kv in st.values}
            if values.get("role") == "consumer" and values.get("run_id") == goal.run_id:
                mine.append((st, values))
        if not mine:
            return

        def act(_raw: bytes) -> None:
            goal.heard = time.monotonic()
            for st, values in mine:
                state = values.get("state", "")
                # the states come from winder/state, in order; the status adds what it alone says
                stalled = state == JobState.STALLED or goal.state == JobState.STALLED
                if stalled and state != goal.state and state not in FINAL_JOB_STATES:
                    goal.state = state
                    self.feedback()
                if state in FINAL_JOB_STATES and not goal.done.done():
                    goal.state = state
                    goal.report = JobReport.from_values(values)
                    goal.consumer = st.name.split(":", 1)[0]
                    goal.message = st.message
                    goal.done.set_result(True)

        self.peers.deliver(TOPIC_DIAGNOSTICS, gid, raw, act, role="consumer")

    def on_state(self, msg: CellState) -> None:
        goal = self.goal
        if goal is not None and msg.run_id == goal.run_id and msg.state:
            goal.state, goal.heard = msg.state, time.monotonic()
            self.feedback()

    def on_tension(self, msg: WrenchStamped) -> None:
        if self.goal is not None:
            self.goal.tension = float(msg.wrench.force.x)

    # -- feedback -------------------------------------------------------------------
    def feedback(self) -> None:
        """The goal's progress; a run the interp node gave up ends the goal."""
        goal = self.goal
        if goal is None:
            return
        cell = self.cell
        if goal.done.done():
            return
        if cell.run_id == goal.run_id and cell.aborted and not cell.operator_abort:
            goal.message = cell.aborted  # given up: the consumer may never close it
            goal.done.set_result(True)
            return
        silent = time.monotonic() - goal.heard
        if silent > self.node_stall_abort():
            # the consumer went (killed, its host down): no final report will come
            goal.message = (
                f"run {goal.run_id}: no word from the consumer for {silent:.0f} s (stall_abort): given up, "
                "how the run ended is not known (a bag cut short: winder bag recover)"
            )
            if cell.run_id == goal.run_id:
                cell.give_up(goal.message)  # the node's run is over too: the next start is not held by it
            else:
                self.log.error(goal.message)
            goal.done.set_result(True)
            return
        self.publish(goal, min(cell.consumed, goal.total) if cell.run_id == goal.run_id else 0)

    def publish(self, goal: Running, done: int) -> None:
        """One feedback of ``goal``, ``done`` steps executed."""
        if not goal.handle.is_active:
            return
        coil, layer, turn = place(goal, done)
        goal.handle.publish_feedback(
            Wind.Feedback(
                run_id=goal.run_id,
                state=str(goal.state),
                steps_done=done,
                steps_total=goal.total,
                coil=coil,
                layer=layer,
                turn=turn,
                tension_n=goal.tension,
            )
        )


def place(goal: Running, steps: int) -> tuple[int, int, int]:
    """(coil, layer, turn), from 1, that ``steps`` executed steps reached."""
    segments = goal.job.segments()
    if not segments:
        return 0, 0, 0
    i = min(max(bisect.bisect_right(goal.offsets, steps) - 1, 0), len(segments) - 1)
    seg = segments[i]
    k = steps - goal.offsets[i]
    return seg.pole + 1, max(seg.layer + 1, 0), seg.turn_at(k)


def goal_key(handle: ServerGoalHandle) -> bytes:
    """A goal's id (its handle is not hashable)."""
    return bytes(handle.goal_id.uuid)


def goal_id(handle: ServerGoalHandle) -> str:
    return goal_key(handle).hex()[:8]
