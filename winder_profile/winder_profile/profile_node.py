"""profile_node: step commands -> timed step commands.

In:  winder/job (winder_interfaces/JobDescription, latched), winder/steps (Int32MultiArray),
     parameters (profile kind and limits, in steps of the segment's major axis).
Out: winder/step_times (std_msgs/Int64MultiArray: [t_ns, segment, feed, fork,
     pole]), winder/path (trajectory_msgs/JointTrajectory, latched: the corner
     points of the job with the time each is reached), winder/profile_config
     (String, latched: the ramp in force), winder/control
     (winder_interfaces/ControlEvent: operator commands as they take effect), /diagnostics.

Each segment is one move of its major axis' step count, ramped with the chosen
profile from and to the start/stop rate ``v_start``; step k of N happens when
the planned motion reaches k/N of the move. Segments follow each other with
``dwell`` seconds between them. The whole job is planned when its description
arrives, so a step's time depends only on its index, never on arrival order.

Operation (:mod:`winder.motion.timeline`): ``~/pause``, ``~/resume`` and
``~/abort`` (std_srvs/Trigger) and the parameter ``feed_override`` change the
time law of the running job from the moment they take effect; the job's
``schedule`` gives such commands at simulated times. Each is published on
winder/control as it takes effect. Steps are timed when they are sent: in a
real-time run (the consumer's winder/sim_config says so) no further than
``lookahead`` ahead of the cell's clock, so a command takes effect within it;
in a run the consumer says runs as fast as possible, as soon as they arrive,
and a command takes effect after the last step sent. A consumer that says
nothing (no winder/sim_config for the run within MODE_WAIT, or none at all)
is taken to execute the steps in real time from the first one: the steps go
out ``lookahead`` ahead of this node's wall clock since then, so a pause or
an abort is honoured within it whatever the consumer; its sim_config, when
it comes, takes over. Once every step is sent, a pause or abort is answered
(the run ends within the look-ahead) until the consumer's clock has passed
the last step. A resume in real time is timed ``lookahead`` ahead of the
consumer's clock as it runs on at rest: the clock last heard (the one waiting
in the reader taken first), carried on by the wall time since it was heard.
"""

from __future__ import annotations

import json
import struct
import time
from collections import deque
from dataclasses import replace
from typing import Any

import numpy as np
import numpy.typing as npt
from builtin_interfaces.msg import Duration
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.exceptions import InvalidHandle
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message
from rclpy.subscription import Subscription
from rclpy.timer import Timer
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Int32MultiArray, Int64MultiArray, String
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from winder.contract.events import ControlEvent
from winder.contract.params import PROFILE_SPECS, UNSHAPED, check_profile
from winder.contract.states import CellState, EventKind, EventSource, JobState, ReadyState
from winder.contract.stream import (
    STEP_COLUMNS,
    TIMED_COLUMNS,
    JobPlan,
    StreamChecker,
)
from winder.contract.topics import (
    TOPIC_CLOCK,
    TOPIC_CONTROL,
    TOPIC_JOB,
    TOPIC_PATH,
    TOPIC_PROFILE_CONFIG,
    TOPIC_SIM_CONFIG,
    TOPIC_STATE,
    TOPIC_STEP_TIMES,
    TOPIC_STEPS,
    status_values,
)
from winder.motion.axes import AXES
from winder.motion.timeline import Command, CommandError, Timeline, parse_schedule
from winder.motion.timing import SegmentTiming, plan_job_timing, shaping_report
from winder.ros.chunks import STEPS_CDR, TIMED_CDR
from winder.ros.diagnostics import ERROR, OK, WARN, Diagnostics
from winder.ros.graph import Who, participant
from winder.ros.interfaces import control_event_msg, job_plan
from winder.ros.managed import ManagedNode
from winder.ros.peers import Peers, Solo
from winder.ros.qos import QOS_CLOCK, QOS_EVENTS, QOS_LATCHED, QOS_LATCHED_READER, QOS_STREAM
from winder.ros.ready import Announcer
from winder.ros.sender import attributed, waiting
from winder.ros.settings import Settings
from winder.ros.spin import spin
from winder.ros.timers import steady_timer
from winder.spec import SpecError, check_all
from winder_interfaces.msg import CellState as CellStateMsg
from winder_interfaces.msg import ControlEvent as ControlEventMsg
from winder_interfaces.msg import JobDescription
from winder_profile import PARAMETERS

#: this node's part in the cell (winder.contract.topics.ROLES), in every job status
ROLE = "profile"
#: chunks kept at most while no run takes them (its description on its way)
MAX_EARLY = 4096
#: How long (s) at most a run's steps wait for the consumer's winder/sim_config
#: of the run (whether it runs in real time, and its clock) while the cell's
#: consumer is on the graph and publishes one: a consumer that takes the run
#: late (a loaded host, a process held up) is waited for, not guessed at (a
#: fixed 1 s sent a real-time run's steps without look-ahead under load).
#: Past it, or with no consumer left, the steps are paced on the wall clock
#: (``lookahead`` ahead of it, as for a real-time consumer), said once.
MODE_WAIT = 10.0
#: after this long (s) waiting for it, the wait is said once in the log
MODE_SAY = 1.0
#: s the graph must show the cell's consumer without a winder/sim_config writer before
#: it is taken as one that publishes none (a node's endpoints are discovered one by one)
MODE_ABSENT = 1.0
#: closes of runs not taken yet kept (winder/state heard before the run's description)
CLOSES_KEPT = 16
#: Steps timed per pass in a real-time run (the rest wait for the clock).
RELEASE_BLOCK = 4096


class ProfileNode(ManagedNode):
    def __init__(self) -> None:
        super().__init__("profile_node")
        self.settings = Settings(self, PARAMETERS, check_profile)
        self.add_post_set_parameters_callback(self.on_settings_set)

        self.pub = self.create_publisher(
            Int64MultiArray,
            TOPIC_STEP_TIMES,
            QOS_STREAM,
            event_callbacks=PublisherEventCallbacks(matched=lambda _info: self.connect()),
        )
        self.pub_config = self.create_publisher(String, TOPIC_PROFILE_CONFIG, QOS_LATCHED)
        self.pub_path = self.create_publisher(JointTrajectory, TOPIC_PATH, QOS_LATCHED)
        self.diag = Diagnostics(self, "winder_profile")
        self.ready = Announcer(self, "profile", recheck=self.announce)  # the start handshake (winder/ready)
        # messages are acted on only when the cell's node owning the topic sent them
        self.peers = Peers(self)
        self.solo = Solo(self, "profile", self.peers, self.leave)  # one profile node per cell
        self.solo.on_settled = self.settled
        self.job_waiting: bytes | None = None  # a job description that came before the node settled
        self.diag.foreign = self.peers.intruders.summary  # its statuses name what it refused
        self.peers.on_new = lambda: self.report()  # at once, not at the next second
        attributed(self, JobDescription, TOPIC_JOB, self.on_job, QOS_LATCHED_READER)
        self.sub_steps: Subscription | None = None  # created once the timed stream has a reader
        # connect() and announce() follow the streams' matching as it happens;
        # the 1 Hz report repeats both (and is the only timer)
        steady_timer(self, 1.0, self.report)
        self.create_service(Trigger, "~/resume", self.on_resume)
        self.create_service(Trigger, "~/pause", lambda _q, r: self.reply(r, *self.command(EventKind.PAUSE)))
        self.create_service(Trigger, "~/abort", lambda _q, r: self.reply(r, *self.command(EventKind.ABORT)))
        self.pub_control = self.create_publisher(ControlEventMsg, TOPIC_CONTROL, QOS_EVENTS)
        attributed(self, String, TOPIC_SIM_CONFIG, self.on_sim_config_raw, QOS_LATCHED_READER)
        # the consumer's word that it closed a run (winder/state): its steps are timed no more
        self.sub_state = self.peers.subscribe(
            CellStateMsg, TOPIC_STATE, self.on_cell_state, QOS_LATCHED_READER
        )
        self.sim_config_topic = self.resolve_topic_name(TOPIC_SIM_CONFIG)
        self.sub_clock: Subscription | None = None  # only while a real-time run is timed
        self.last_sim_config: String | None = None

        self.plan: JobPlan | None = None
        self.checker: StreamChecker | None = None
        self.timeline: Timeline | None = None
        self.early: list[bytes] = []
        self.timed = 0
        self.closed = ""  # the consumer closed the run being timed: its final state
        #: runs the consumer closed before this node took them (their final states, the last few)
        self.closes: dict[str, CellState] = {}
        self.error = ""
        self.ramp_kind = ""  # the ramp kind of the run being timed
        #: accepted step rows not sent yet, with their step indices in the segment
        self.queue: deque[tuple[npt.NDArray[np.int32], npt.NDArray[np.int64]]] = deque()
        self.t_sent_ns = -1  # time of the last step sent
        self.dropped = 0  # steps beyond the end of an aborted run, never sent
        #: the run's look-ahead: None = unbounded (as fast as possible), known
        #: once the consumer's sim_config for the run came (or MODE_WAIT passed)
        self.lookahead_ns: int | None = None
        self.mode_known = False
        self.mode_said = False  # the wait for the run's sim_config was said in the log
        #: consumers seen without a sim_config writer, and since when (steady s)
        self.unconfigured: dict[Who, float] = {}
        self.job_wall = 0.0
        self.clock_origin_ns = 0
        self.t_now_ns = -1  # the cell's clock, as time since the run's start (real-time runs)
        self.t_now_wall = 0.0  # when it was heard (time.monotonic())
        self.clock_factor = 1.0  # the consumer's real_time_factor: its clock's s per wall s
        #: a run paced on this node's wall clock (the consumer said nothing): when its
        #: first step went out (time.monotonic()), and the timer that moves its clock
        self.wall_origin: float | None = None
        self.wall_timer: Timer | None = None
        #: a programmed stop waiting for ~/resume (stop_resume call): the stops
        #: still ahead, and the one the job waits at
        self.holds: list[tuple[int, int]] = []
        self.waiting_at: tuple[int, int] | None = None
        self.start_lifecycle()

    # -- lifecycle (winder.ros.managed) ----------------------------------------
    def in_run(self) -> bool:
        return self.plan is not None and not self.run_over()

    def blocked_reason(self) -> str | None:
        return self.settings.blocked()

    def lifecycle_changed(self) -> None:
        self.announce()

    def connect(self) -> None:
        if self.sub_steps is None and self.pub.get_subscription_count() > 0:
            self.sub_steps = attributed(
                self,
                Int32MultiArray,
                TOPIC_STEPS,
                self.on_steps,
                QOS_STREAM,
                event_callbacks=SubscriptionEventCallbacks(matched=lambda _info: self.announce()),
            )
            self.announce()

    # -- in --------------------------------------------------------------
    def on_job(self, raw: bytes, gid: bytes) -> None:
        self.peers.deliver(TOPIC_JOB, gid, raw, self.take_job)

    def settled(self) -> None:
        """The node knows it is the cell's only profile node: say ready, and
        take a job description that came before."""
        raw, self.job_waiting = self.job_waiting, None
        if raw is not None:
            self.take_job(raw)
        self.announce()

    def take_job(self, raw: bytes) -> None:
        """A run's description from the cell's interp node."""
        if not self.solo.settled():  # not sure yet to be the cell's only profile node: kept till it is
            self.job_waiting = raw
            return
        try:
            job = job_plan(raw)
        except Exception as exc:  # ValueError, or not even a JobDescription
            self.fail(f"job description rejected: {(str(exc).splitlines() or [type(exc).__name__])[0]}")
            return
        if self.plan is not None and job.run_id and job.run_id == self.plan.run_id:
            return  # the running run's own description again: it cannot restart it
        if not self.active:
            self.fail(f"job {job.job_id} refused: {self.inactive_reason()}")
            return
        if job.ramp is not None:  # the run brings its ramp: it is checked here as a setting would be
            try:
                # a ramp from before shapers existed is an unshaped one
                values = check_all(PROFILE_SPECS, {**UNSHAPED, **job.ramp})
                missing = sorted(set(PROFILE_SPECS) - set(values))
                if missing:
                    raise SpecError(f"the ramp lacks {', '.join(missing)}")
                check_profile(values)
            except SpecError as exc:
                self.fail(f"job {job.job_id} refused: its ramp: {exc}")
                return
            source = "job"
        else:
            blocked = self.settings.blocked()
            if blocked:
                self.fail(f"job {job.job_id} refused: {blocked}")
                return
            values, source = self.settings.values(), "profile_node"
        try:
            timing, duration_ns = plan_job_timing(values, job.job, job.stops, job.stop_pause)
        except ValueError as exc:
            self.fail(f"job {job.job_id} cannot be ramped: {exc}")
            return
        self.end_clock()
        self.plan, self.timeline, self.closed = job, Timeline(values, timing), ""
        closed_before = self.closes.pop(job.run_id, None) if job.run_id else None
        self.holds = list(job.stops) if job.stop_resume == "call" else []
        self.waiting_at = None
        self.queue.clear()
        self.t_sent_ns, self.dropped, self.t_now_ns = -1, 0, -1
        self.lookahead_ns, self.mode_known, self.job_wall = None, False, time.monotonic()
        self.mode_said = False
        if self.last_sim_config is not None:  # the consumer's word on this run may be here already
            self.on_sim_config(self.last_sim_config)
        self.ramp_kind = str(values["profile"])
        # the ramp in force for this job, latched: the sim node records it
        config = {
            "job_id": job.job_id,
            "run_id": job.run_id,
            **values,
            "ramp_source": source,
            "job_duration_s": duration_ns / 1e9,
            **shaping_report(timing),
        }
        self.pub_config.publish(String(data=json.dumps(config)))
        self.pub_path.publish(self.path_message(job, timing, self.get_clock().now().to_msg()))
        self.checker = StreamChecker(job)
        self.timed = 0
        self.error = ""
        shaped = ""
        if config.get("shaped"):
            shaped = f", {values['shaper']} shaper at {values['shaper_freq']:g} Hz"
        self.get_logger().info(
            f"job {job.job_id}: {values['profile']} ramps{shaped}, {len(timing)} segments, "
            f"{duration_ns / 1e9:.3f} s"
        )
        override = self.settings.values()["feed_override"]
        commands = [Command(0, EventKind.OVERRIDE, override)] if override != 1.0 else []
        for cmd in commands + parse_schedule(job.schedule):  # checked with the description
            source = (
                EventSource.SCHEDULE if cmd.t_ns or cmd.kind != EventKind.OVERRIDE else EventSource.SETTING
            )
            try:
                self.publish_event(self.timeline.apply(cmd, source), cmd.t_ns)
            except CommandError as exc:
                self.get_logger().warning(f"{source}: {cmd.kind} at {cmd.t_ns / 1e9:g} s not applied: {exc}")
        self.report()  # the run is on: its status at once
        if closed_before is not None:  # the consumer closed it before this node took it
            self.on_cell_state(CellStateMsg(run_id=job.run_id, state=closed_before))
        early, self.early = self.early, []
        for raw in early:  # in order, before any taken from the queue
            self.time_chunk(raw)

    def on_steps(self, raw: bytes, gid: bytes) -> None:
        self.peers.deliver(TOPIC_STEPS, gid, raw, self.time_chunk)
        if self.sub_steps is not None:
            for more, sender in waiting(self.sub_steps):  # the chunks queued behind it, in one go
                self.peers.deliver(TOPIC_STEPS, sender, more, self.time_chunk)

    def time_chunk(self, raw: bytes) -> None:
        if self.plan is None or self.checker is None:
            self.keep_early(raw)  # the job description is on its way
            return
        try:
            rows = STEPS_CDR.decode(raw)
        except ValueError as exc:
            self.fail(f"bad steps chunk: {exc}")
            return
        if self.closed and self.checker.continues(rows, STEP_COLUMNS):
            # the consumer closed the run: its steps still coming are dropped (counted when it closed)
            self.checker.check_rows(rows, STEP_COLUMNS)
            return
        if self.run_over() and not self.checker.continues(rows, STEP_COLUMNS):
            # every step of the run is sent (or dropped past its abort): a chunk that does not go
            # on from it is the next run's, whose description can come after its first steps (two
            # topics). Taken for this run's, the next run's steps were dropped as duplicates and
            # it never started (the same job again, adversarial pass of issue 41)
            self.keep_early(raw)
            return
        verdict = self.checker.check_rows(rows, STEP_COLUMNS)
        if verdict.kind != "ok":
            self.get_logger().error(verdict.message)
            self.diag.publish(
                "stream", ERROR, verdict.message, {"kind": verdict.kind, "missing": verdict.missing}
            )
        if not verdict.accept:
            return
        # segments are planned over their step count, so step k sits at
        # position k; the rows are timed when they are sent (release())
        seg = int(rows[0, 0])
        self.queue.append((rows, self.checker.step_index(seg, rows[:, 1:]).astype(np.int64)))
        self.release()

    def keep_early(self, raw: bytes) -> None:
        """Keep a chunk for the run whose description comes next (MAX_EARLY at most)."""
        if len(self.early) < MAX_EARLY:
            self.early.append(raw)

    def release(self) -> None:
        """Time and send the queued steps the law fixes now: all of them, or in
        a real-time run those up to ``lookahead`` ahead of the clock and the
        first one beyond (so the consumer's clock never waits for a step);
        none beyond a pause (until the resume), a programmed stop that waits
        for ~/resume, or the end of an aborted run (those are dropped)."""
        tl = self.timeline
        if tl is None or self.plan is None or not self.mode_ready():
            return
        # the consumer's states waiting in the reader first: a node that wakes from a hold finds
        # the run's steps, its sim_config and the consumer's close of it all queued, and the
        # executor hands them out in its own order, not theirs
        for raw, gid in waiting(self.sub_state):
            self.peers.deliver(TOPIC_STATE, gid, raw, self.take_cell_state)
        if self.closed:
            return
        sent_before = self.timed + self.dropped
        while self.queue and self.waiting_at is None:
            rows, k = self.queue[0]
            seg = int(rows[0, 0])
            lead = self.t_sent_ns - max(self.t_now_ns, 0)
            if self.lookahead_ns is not None and lead > self.lookahead_ns // 2:
                break  # more than half the look-ahead is out: steps go in blocks, not one per clock tick
            n_try = len(k) if self.lookahead_ns is None else min(len(k), RELEASE_BLOCK)
            times, n = tl.times_ns(seg, k[:n_try])
            if self.lookahead_ns is not None:
                horizon = max(self.t_now_ns, 0) + self.lookahead_ns
                cut = int(np.searchsorted(times, horizon, side="right"))
                if cut < n and (cut > 0 or self.t_sent_ns <= horizon):
                    cut += 1  # the first step beyond the horizon
                n = cut
            stop = next((s for s in self.holds if s[0] == seg and s[1] in k[:n]), None)
            if stop is not None:
                n = int(np.nonzero(k[:n] == stop[1])[0][0]) + 1
            if n:
                out = np.empty((n, len(TIMED_COLUMNS)), np.int64)
                out[:, 0] = times[:n]
                out[:, 1:] = rows[:n]
                self.pub.publish(TIMED_CDR.encode(out))
                self.t_sent_ns = int(times[n - 1])
                self.timed += n
            if stop is not None:
                self.holds.remove(stop)
                self.waiting_at = stop
                self.get_logger().info(
                    f"programmed stop at segment {stop[0]}, step {stop[1]}: waiting for ~/resume"
                )
            rest_k = k[n:]
            if tl.end_step is not None and rest_k.size and tl.beyond_end(seg, rest_k).all():
                self.dropped += rest_k.size  # past the end of an aborted run
                self.queue.popleft()
                continue
            if n < len(k):
                self.queue[0] = (rows[n:], rest_k)
                if n < n_try or n == 0:
                    break  # the law fixes no more now (a pause, the look-ahead)
                continue
            self.queue.popleft()
        if self.timed + self.dropped != sent_before and (self.run_over() or self.waiting_at is not None):
            if self.run_over():
                self.end_clock()
            self.report()

    def run_over(self) -> bool:
        """Every step of the run is sent, or dropped past the end of an abort."""
        return self.plan is not None and self.timed + self.dropped >= self.plan.total_steps

    def mode_ready(self) -> bool:
        """Whether the run's look-ahead is known: the consumer's sim_config for
        it came, or the cell's consumer publishes none (a consumer that does
        not pace in real time need not: it is not waited for). While the
        cell's consumer (as the graph shows it: the node this one knew when
        it said ready) publishes one, it is waited for, however late it
        takes the run, up to MODE_WAIT s; past that, or with no consumer on
        the graph any more, the steps are paced on the wall clock (said once)."""
        if self.mode_known or self.plan is None:
            return self.mode_known
        consumer = self.peers.owner("consumer")
        if consumer is not None and not self.configures(consumer):
            # it publishes no configuration: it does not pace, nothing to wait for. Told
            # from the graph, whose endpoints of one node come one by one: only once no
            # sim_config writer of it has shown for MODE_ABSENT s (remembered for the node)
            first = self.unconfigured.setdefault(consumer, time.monotonic())
            if time.monotonic() - first >= MODE_ABSENT:
                self.pace_by_wall(f"{consumer.fq} publishes none", warn=False)
                return True
            return False
        if consumer is not None:
            self.unconfigured.pop(consumer, None)
        waited = time.monotonic() - self.job_wall
        run = self.plan.run_id or self.plan.job_id
        if consumer is not None and waited <= MODE_WAIT:
            if waited > MODE_SAY and not self.mode_said:
                self.mode_said = True
                self.get_logger().info(
                    f"run {run}: its steps wait for {consumer.fq}'s {TOPIC_SIM_CONFIG} of the run "
                    f"(whether it runs in real time), {MODE_WAIT:g} s at most"
                )
            return False
        why = (
            f"none from {consumer.fq} within {MODE_WAIT:g} s" if consumer else "no step consumer on the graph"
        )
        self.pace_by_wall(why)
        return True

    def pace_by_wall(self, why: str, warn: bool = True) -> None:
        """The consumer said nothing of how it runs: it is taken to execute
        the steps in real time from the first one (a drive does), so the
        steps go out ``lookahead`` ahead of this node's wall clock, started
        now, and a pause or abort is honoured within it. Said once: a
        warning when the consumer's sim_config was waited for in vain."""
        assert self.plan is not None
        lookahead = self.settings.values()["lookahead"]
        (self.get_logger().warning if warn else self.get_logger().info)(
            f"no {TOPIC_SIM_CONFIG} for run {self.plan.run_id or self.plan.job_id} ({why}): its steps are "
            f"paced on the wall clock from now, {lookahead:g} s ahead (a consumer that runs as fast as "
            f"possible says so in its {TOPIC_SIM_CONFIG}: real_time false)"
        )
        self.mode_known = True
        self.lookahead_ns = round(lookahead * 1e9)
        self.wall_origin = time.monotonic()
        self.t_now_ns, self.t_now_wall, self.clock_factor = 0, self.wall_origin, 1.0
        if self.wall_timer is None:
            self.wall_timer = steady_timer(self, max(lookahead / 4, 0.005), self.wall_tick)

    def wall_tick(self) -> None:
        """The wall-paced run's clock moves on: the steps it brings into the
        look-ahead go out."""
        self.wall_now()
        self.release()

    def wall_now(self) -> None:
        """A wall-paced run's clock: the wall time since its first step."""
        if self.wall_origin is not None:
            now = time.monotonic()
            self.t_now_ns, self.t_now_wall = round((now - self.wall_origin) * 1e9), now

    def configures(self, consumer: Who) -> bool:
        """Whether the graph shows ``consumer`` publishing winder/sim_config."""
        return any(
            Who(i.node_name, i.node_namespace, participant(i.endpoint_gid)) == consumer
            for i in self.get_publishers_info_by_topic(self.sim_config_topic)
        )

    def on_sim_config_raw(self, raw: bytes, gid: bytes) -> None:
        self.peers.deliver(TOPIC_SIM_CONFIG, gid, raw, self.take_sim_config)

    def take_sim_config(self, raw: bytes) -> None:
        try:
            msg = deserialize_message(raw, String)
        except Exception:  # not a String: nothing to act on
            return
        self.on_sim_config(msg)

    def on_sim_config(self, msg: String) -> None:
        """The consumer's configuration of the run: a real-time run gets the
        look-ahead, and the clock it is measured on. It may come before the
        job description does: the last one is kept for it. One that comes
        after MODE_WAIT passed takes over the wall clock's pacing from then
        on (and a run as fast as possible gets its steps at once)."""
        self.last_sim_config = msg
        late = self.wall_origin is not None
        if self.plan is None or (self.lookahead_ns is not None and not late) or self.run_over():
            return
        try:
            config = json.loads(msg.data)
        except (json.JSONDecodeError, RecursionError):
            return
        if not isinstance(config, dict) or config.get("run_id") != self.plan.run_id:
            return
        run = self.plan.run_id or self.plan.job_id
        if self.mode_said and not self.mode_known:
            self.get_logger().info(
                f"run {run}: the consumer's {TOPIC_SIM_CONFIG} came after "
                f"{time.monotonic() - self.job_wall:.1f} s; its steps go out"
            )
        origin = config.get("clock_origin_ns")
        real_time = config.get("real_time") is True and isinstance(origin, int)
        if late:
            self.end_wall_clock()
            self.lookahead_ns, self.t_now_ns = None, -1
            self.get_logger().warning(
                f"run {run}: the consumer's {TOPIC_SIM_CONFIG} came after its steps were paced on the wall "
                + (
                    "clock: its own clock paces them from now on"
                    if real_time
                    else "clock: the rest goes out now"
                )
            )
        if real_time:
            assert isinstance(origin, int)
            self.clock_origin_ns = origin
            factor = config.get("real_time_factor")
            self.clock_factor = 1.0
            if isinstance(factor, int | float) and not isinstance(factor, bool) and 0.0 < factor < 1e6:
                self.clock_factor = float(factor)
            self.lookahead_ns = round(self.settings.values()["lookahead"] * 1e9)
            # a consumer that commits commands ahead of its clock needs the steps that far ahead at
            # all times: steps go out in blocks when less than half the look-ahead is out, so twice it
            wanted = config.get("lookahead_min_s")
            if isinstance(wanted, int | float) and not isinstance(wanted, bool) and 0.0 < wanted <= 10.0:
                self.lookahead_ns = max(self.lookahead_ns, round(2 * wanted * 1e9))
            if self.sub_clock is None:
                self.sub_clock = self.create_subscription(
                    Clock, TOPIC_CLOCK, self.on_clock, QOS_CLOCK, raw=True
                )
        self.mode_known = True
        self.release()

    def take_cell_state(self, raw: bytes) -> None:
        try:
            msg = deserialize_message(raw, CellStateMsg)
        except Exception:  # not a CellState: nothing to act on
            return
        self.on_cell_state(msg)

    def on_cell_state(self, msg: CellStateMsg) -> None:
        """The consumer's ``winder/state``: a run it closed (done, aborted,
        failed) is over here too. Its steps not timed yet are dropped, never
        sent: the consumer will execute none of them, and sent after the
        close they reached the next run (issue 53: a consumer that closed a
        run for its stall while this node still waited for its
        winder/sim_config; this node then paced the closed run on its wall
        clock, and the next run took those steps and refused its own pause)."""
        if msg.state not in (CellState.DONE, CellState.ABORTED, CellState.FAILED) or not msg.run_id:
            return
        plan = self.plan
        if plan is None or msg.run_id != plan.run_id:
            # a run this node has not taken yet (its description held, or on its way): kept for it
            self.closes[msg.run_id] = CellState(msg.state)
            while len(self.closes) > CLOSES_KEPT:
                self.closes.pop(next(iter(self.closes)))
            return
        if self.closed or self.run_over():
            return
        untimed = plan.total_steps - self.timed - self.dropped
        self.closed = msg.state
        self.queue.clear()
        self.holds, self.waiting_at = [], None
        self.dropped += untimed
        self.mode_known = True
        self.end_clock()
        why = (
            f"run {plan.run_id}: closed by the consumer ({msg.state}) with {untimed} of its steps not "
            f"timed yet: they are dropped, never sent"
        )
        if msg.state == CellState.FAILED:
            self.fail(why)
        elif self.timeline is not None and self.timeline.aborted:  # this node's own abort: as it braked
            self.get_logger().info(why)
        else:
            self.get_logger().warning(why)
        self.report()

    def on_clock(self, raw: bytes) -> None:
        """The cell's clock (builtin_interfaces/Time after the CDR header)."""
        if len(raw) < 12:
            return
        sec, nsec = struct.unpack_from("<iI", raw, 4)
        t = sec * 1_000_000_000 + nsec - self.clock_origin_ns
        if t > self.t_now_ns:
            self.t_now_ns, self.t_now_wall = t, time.monotonic()
        self.release()

    def take_clock(self) -> None:
        """The clock message waiting in the reader, if one is (a busy node
        serves a call before it): heard now."""
        sub = self.sub_clock
        if sub is None:
            return
        try:
            with sub.handle:
                got = sub.handle.take_message(sub.msg_type, sub.raw)
        except InvalidHandle:  # destroyed meanwhile (shutdown)
            return
        if got is not None:
            self.on_clock(got[0])

    def clock_at_rest_ns(self) -> int:
        """The consumer's clock now, at rest after a pause: in a real-time run
        it runs on with the wall clock (the sim node's, from where it stands),
        so the clock last heard is carried on by the wall time since it was
        heard. (A consumer held up meanwhile is behind that: never ahead.)"""
        if self.t_now_ns < 0:
            return self.t_now_ns
        return self.t_now_ns + round((time.monotonic() - self.t_now_wall) * self.clock_factor * 1e9)

    def end_clock(self) -> None:
        if self.sub_clock is not None:
            self.destroy_subscription(self.sub_clock)
            self.sub_clock = None
        self.end_wall_clock()

    def end_wall_clock(self) -> None:
        if self.wall_timer is not None:
            self.destroy_timer(self.wall_timer)
            self.wall_timer = None
        self.wall_origin = None

    # -- operation -------------------------------------------------------
    @staticmethod
    def reply(resp: Trigger.Response, ok: bool, message: str) -> Trigger.Response:
        resp.success, resp.message = ok, message
        return resp

    def command(self, kind: EventKind, value: float = 1.0) -> tuple[bool, str]:
        """Apply an operator command to the running run now: in a real-time run
        at the later of the clock and the last step sent (within the
        look-ahead), otherwise after the last step sent. (ok, one line)."""
        tl, plan = self.timeline, self.plan
        if tl is None or plan is None:
            return False, f"{kind} refused: no run is being timed"
        if self.lookahead_ns is not None:
            self.take_clock()  # the clock as fresh as it is here
            self.wall_now()
        if self.run_over():
            return self.in_tail(kind, plan)
        real_time = self.lookahead_ns is not None and self.t_now_ns >= 0
        if real_time and kind is EventKind.RESUME:
            # the consumer's clock ran on while it rested: the resume is timed from
            # where that clock is now, not from where it was last heard (the resumed
            # steps came behind it, and a sim node died of them: issue 40)
            t_req = self.clock_at_rest_ns()
        else:
            t_req = self.t_now_ns if real_time else max(self.t_sent_ns, 0)
        t = max(self.t_sent_ns, t_req, 0)
        if kind is EventKind.RESUME and self.lookahead_ns is not None:
            t = max(t, t_req + self.lookahead_ns)  # the new steps reach the consumer before they are due
        try:
            effect = tl.apply(Command(t, kind, value))
        except CommandError as exc:
            return False, f"{kind} refused: {exc}"
        event = self.publish_event(effect, t_req)
        rest = f"at rest after {event.steps} steps at {(event.t_rest_ns or 0) / 1e9:.6f} s"
        what = {
            EventKind.PAUSE: f"pausing: {rest}",
            EventKind.ABORT: f"aborting: {rest}",
            EventKind.RESUME: f"resuming at {t / 1e9:.6f} s",
            EventKind.OVERRIDE: f"feed override {value:g}: {event.note or ''}",
        }[kind]
        message = f"run {plan.run_id or plan.job_id}: {what}"
        self.get_logger().info(message)
        self.release()
        self.report()
        return True, message

    def in_tail(self, kind: EventKind, plan: JobPlan) -> tuple[bool, str]:
        """A command once every step of the run is sent. In a real-time run
        whose axes have not reached the last step yet (the consumer's clock,
        carried on by the wall time since it was heard), a pause or abort is
        answered: the steps out are within the look-ahead, and the axes stop
        at the run's end, that soon. A run its consumer closed has stopped:
        a pause or abort is answered so (a bridge that faults closes its run,
        then asks for the abort; either may be heard first). Otherwise the
        run is over for the time law: refused with why."""
        run = plan.run_id or plan.job_id
        if self.closed:
            if not kind.stops:
                return False, f"{kind} refused: run {run} is closed by its consumer ({self.closed})"
            message = (
                f"run {run}: {kind}: the run is closed by its consumer already ({self.closed}): "
                f"its steps not timed were dropped, nothing more is sent"
            )
            self.get_logger().info(message)
            return True, message
        tl = self.timeline
        if tl is not None and tl.aborted:
            return False, f"{kind} refused: run {run} is aborted already; its axes come to rest"
        now = self.clock_at_rest_ns()
        if self.lookahead_ns is not None and now >= 0 and now < self.t_sent_ns and kind.stops:
            left = (self.t_sent_ns - now) / 1e9
            message = (
                f"run {run}: {kind}: every step is already sent (within the look-ahead): the axes "
                f"stop at the run's end at {self.t_sent_ns / 1e9:.6f} s, {left:.3f} s from now"
            )
            self.get_logger().info(message)
            return True, message
        if self.lookahead_ns is None:
            return False, f"{kind} refused: run {run} runs as fast as possible and every step is timed"
        return False, f"{kind} refused: run {run}'s axes are at its end: nothing left to {kind}"

    def publish_event(self, effect: dict[str, Any], t_request: int) -> ControlEvent:
        """An operator event on winder/control: the time law's account of a
        command (``effect``) with the run and the latency from the request
        (simulated time) to the moment it takes effect. The event published."""
        assert self.plan is not None
        event = ControlEvent.from_doc(
            effect, run_id=self.plan.run_id, job_id=self.plan.job_id, t_request_ns=t_request
        )
        event = replace(event, latency_ns=event.t_ns - t_request)
        self.pub_control.publish(control_event_msg(event))
        return event

    def on_settings_set(self, params: list[Parameter]) -> None:
        """A new feed_override acts on the run being timed at once."""
        for p in params:
            if p.name == "feed_override" and self.timeline is not None and not self.run_over():
                ok, why = self.command(EventKind.OVERRIDE, float(p.value))
                if not ok:
                    self.get_logger().warning(why)

    def on_resume(self, _req: Trigger.Request, resp: Trigger.Response) -> Trigger.Response:
        """Go on after a pause, or after a programmed stop that waits for a call."""
        if self.timeline is not None and self.timeline.paused and not self.timeline.aborted:
            return self.reply(resp, *self.command(EventKind.RESUME))
        if self.waiting_at is None or self.plan is None:
            why = "resume refused: not paused, not at a programmed stop: nothing to resume"
            return self.reply(resp, False, why)
        stop = self.waiting_at
        self.waiting_at = None
        resp.success = True
        resp.message = f"run {self.plan.run_id or self.plan.job_id}: resumed after the stop at step {stop[1]}"
        self.get_logger().info(resp.message)
        self.release()
        self.report()
        return resp

    @staticmethod
    def path_message(job: JobPlan, timing: list[SegmentTiming], stamp: Any) -> JointTrajectory:
        """The job's corner points (joint units) with the time each is reached:
        the start at 0, each segment's end when its move ends. ``frame_id``
        names the run (its id; the job id for a job without one)."""
        msg = JointTrajectory()
        msg.header.frame_id = job.run_id or job.job_id
        msg.header.stamp = stamp
        msg.joint_names = list(AXES)
        ends = [t.t0_ns + t.duration_ns for t in timing]
        corners = [(job.segments[0].start, 0)] + [(s.end, t) for s, t in zip(job.segments, ends, strict=True)]
        for pos, t_ns in corners:
            pt = JointTrajectoryPoint()
            pt.positions = [p * k for p, k in zip(pos, job.joint_step, strict=True)]
            pt.time_from_start = Duration(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)
            msg.points.append(pt)
        return msg

    def job_duration_ns(self) -> int:
        return self.timeline.duration_ns if self.timeline else 0

    # -- out -------------------------------------------------------------
    def fail(self, why: str) -> None:
        self.error = why
        self.get_logger().error(why)
        self.diag.publish("job", ERROR, why, self.values(JobState.INCOMPLETE))

    def values(self, state: JobState) -> dict[str, object]:
        """This node's job status values in ``state`` (the common keys first)."""
        if self.plan is None:
            return status_values(state, role=ROLE, profile=self.settings.values()["profile"])
        profile = self.ramp_kind or self.settings.values()["profile"]
        return status_values(
            state,
            self.plan.job_id,
            self.plan.run_id,
            self.timed,
            self.plan.total_steps,
            role=ROLE,
            profile=profile,
            gaps=self.checker.gaps if self.checker else 0,
            job_duration_s=f"{self.job_duration_ns() / 1e9:.6f}",
        )

    def announce(self) -> None:
        """winder/ready: ready once the steps' subscription is matched (see connect())."""
        if self.settings.blocked():
            self.ready.announce(ReadyState.BLOCKED)
        elif not self.active:
            self.ready.announce(ReadyState.INACTIVE)
        else:
            why = []
            if self.sub_steps is None or self.sub_steps.get_publisher_count() == 0:
                why.append("no publisher of winder/steps matched")
            if not self.solo.settled():  # it is the cell's only profile node
                why.append("not yet known to be the cell's only profile node")
            unknown = self.peers.knows("interp", "consumer")  # it tells the cell's nodes from others
            if unknown:
                why.append(unknown)
            self.ready.announce(ReadyState.WAITING if why else ReadyState.READY, "; ".join(why))

    def report(self) -> None:
        self.release()  # steps waiting for the run's mode (MODE_WAIT) go out
        self.connect()
        self.announce()
        self.ready.repeat()
        blocked = self.settings.blocked()
        if blocked:
            self.diag.publish("job", ERROR, blocked, self.values(JobState.BLOCKED))
            return
        if self.plan is None:
            if self.error:
                self.diag.publish("job", ERROR, self.error, self.values(JobState.INCOMPLETE))
            else:
                self.diag.publish("job", OK, "idle: waiting for a job", self.values(JobState.IDLE))
            return
        total = self.plan.total_steps
        level = ERROR if self.error else (WARN if self.checker and self.checker.gaps else OK)
        state = (
            JobState.INCOMPLETE
            if self.error
            else (JobState.DONE if self.timed >= total else JobState.RUNNING)
        )
        tl = self.timeline
        if self.closed and not self.error:  # the consumer closed it: as it said
            state = JobState.DONE if self.closed == CellState.DONE else JobState.ABORTED
        elif not self.error and tl is not None and tl.aborted:
            state = JobState.ABORTED if self.run_over() else JobState.ABORTING
        elif (self.waiting_at is not None or (tl is not None and tl.paused)) and not self.error:
            state = JobState.PAUSED
        self.diag.publish(
            "job",
            level,
            self.error or f"run {self.plan.run_id or self.plan.job_id}: timed {self.timed}/{total} steps",
            self.values(state),
        )


def main(args: list[str] | None = None) -> None:
    spin(ProfileNode, args)
