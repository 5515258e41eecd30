"""profile_node: step commands -> timed step commands.

In:  winder/job (std_msgs/String, latched), winder/steps (Int32MultiArray),
     parameters (profile kind and limits, in steps of the segment's major axis).
Out: winder/step_times (std_msgs/Int64MultiArray: [t_ns, segment, feed, fork,
     pole]), winder/path (trajectory_msgs/JointTrajectory, latched: the corner
     points of the job with the time each is reached), winder/profile_config
     (String, latched: the ramp in force), /diagnostics.

Each segment is one move of its major axis' step count, ramped with the chosen
profile from and to the start/stop rate ``v_start``; step k of N happens when
the planned motion reaches k/N of the move. Segments follow each other with
``dwell`` seconds between them. The whole job is planned when its description
arrives, so a step's time depends only on its index, never on arrival order.
"""

from __future__ import annotations

import json

import numpy as np
from builtin_interfaces.msg import Duration
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.subscription import Subscription
from std_msgs.msg import Int32MultiArray, Int64MultiArray, String
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from winder.contract.params import PROFILE_SPECS, SegmentTiming, check_profile, plan_timing
from winder.contract.stream import STEP_COLUMNS, TIMED_COLUMNS, JobPlan, StreamChecker, parse_job_description
from winder.contract.topics import (
    TOPIC_JOB,
    TOPIC_PATH,
    TOPIC_PROFILE_CONFIG,
    TOPIC_STEP_TIMES,
    TOPIC_STEPS,
    status_values,
)
from winder.motion.job import AXES
from winder.ros.chunks import STEPS_CDR, TIMED_CDR, waiting
from winder.ros.diagnostics import ERROR, OK, WARN, Diagnostics
from winder.ros.qos import QOS_LATCHED, QOS_STREAM
from winder.ros.ready import Announcer
from winder.ros.settings import Settings
from winder.ros.spin import spin
from winder.ros.timers import steady_timer
from winder.spec import SpecError, check_all


class ProfileNode(Node):
    def __init__(self) -> None:
        super().__init__("profile_node")
        self.settings = Settings(self, PROFILE_SPECS, check_profile)

        self.pub = self.create_publisher(
            Int64MultiArray,
            TOPIC_STEP_TIMES,
            QOS_STREAM,
            event_callbacks=PublisherEventCallbacks(matched=lambda _info: self.connect()),
        )
        self.pub_config = self.create_publisher(String, TOPIC_PROFILE_CONFIG, QOS_LATCHED)
        self.pub_path = self.create_publisher(JointTrajectory, TOPIC_PATH, QOS_LATCHED)
        self.diag = Diagnostics(self, "winder_profile")
        self.ready = Announcer(self, "profile")  # the start handshake (winder/ready)
        self.create_subscription(String, TOPIC_JOB, self.on_job, QOS_LATCHED)
        self.sub_steps: Subscription | None = None  # created once the timed stream has a reader
        # connect() and announce() follow the streams' matching as it happens;
        # the 1 Hz report repeats both (and is the only timer)
        steady_timer(self, 1.0, self.report)
        self.create_service(Trigger, "~/resume", self.on_resume)

        self.plan: JobPlan | None = None
        self.checker: StreamChecker | None = None
        self.timing: list[SegmentTiming] = []
        self.early: list[bytes] = []
        self.timed = 0
        self.error = ""
        self.ramp_kind = ""  # the ramp kind of the run being timed
        #: a programmed stop waiting for ~/resume (stop_resume call): the stops
        #: still ahead, the one the job waits at, and the timed rows held beyond it
        self.holds: list[tuple[int, int]] = []
        self.waiting_at: tuple[int, int] | None = None
        self.held: list[np.ndarray] = []

    def connect(self) -> None:
        if self.sub_steps is None and self.pub.get_subscription_count() > 0:
            self.sub_steps = self.create_subscription(
                Int32MultiArray,
                TOPIC_STEPS,
                self.on_steps,
                QOS_STREAM,
                raw=True,
                event_callbacks=SubscriptionEventCallbacks(matched=lambda _info: self.announce()),
            )
            self.announce()

    # -- in --------------------------------------------------------------
    def on_job(self, msg: String) -> None:
        try:
            job = parse_job_description(msg.data)
        except ValueError as exc:
            self.fail(f"job description rejected: {exc}")
            return
        if job.ramp is not None:  # the run brings its ramp: it is checked here as a setting would be
            try:
                values = check_all(PROFILE_SPECS, job.ramp)
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
            timing, duration_ns = plan_timing(
                values, [s.steps for s in job.segments], job.stops, job.stop_pause
            )
        except ValueError as exc:
            self.fail(f"job {job.job_id} cannot be ramped: {exc}")
            return
        self.plan, self.timing = job, timing
        self.holds = list(job.stops) if job.stop_resume == "call" else []
        self.waiting_at, self.held = None, []
        self.ramp_kind = str(values["profile"])
        # the ramp in force for this job, latched: the sim node records it
        config = {
            "job_id": job.job_id,
            "run_id": job.run_id,
            **values,
            "ramp_source": source,
            "job_duration_s": duration_ns / 1e9,
        }
        self.pub_config.publish(String(data=json.dumps(config)))
        self.pub_path.publish(self.path_message(job))
        self.checker = StreamChecker(job)
        self.timed = 0
        self.error = ""
        self.get_logger().info(
            f"job {job.job_id}: {values['profile']} ramps, {len(timing)} segments, {duration_ns / 1e9:.3f} s"
        )
        self.report()  # the run is on: its status at once
        early, self.early = self.early, []
        for raw in early:  # in order, before any taken from the queue
            self.time_chunk(raw)

    def on_steps(self, raw: bytes) -> None:
        self.time_chunk(raw)
        if self.sub_steps is not None:
            for more in waiting(self.sub_steps):  # the chunks queued behind it, in one go
                self.time_chunk(more)

    def time_chunk(self, raw: bytes) -> None:
        if self.plan is None or self.checker is None:
            self.early.append(raw)  # the job description is on its way
            return
        try:
            rows = STEPS_CDR.decode(raw)
        except ValueError as exc:
            self.fail(f"bad steps chunk: {exc}")
            return
        verdict = self.checker.check_rows(rows, STEP_COLUMNS)
        if verdict.kind != "ok":
            self.get_logger().error(verdict.message)
            self.diag.publish(
                "stream", ERROR, verdict.message, {"kind": verdict.kind, "missing": verdict.missing}
            )
        if not verdict.accept:
            return
        # the times of just these steps: segments are planned over their step
        # count, so step k sits at position k (memory per chunk, not per segment)
        seg = int(rows[0, 0])
        k = self.checker.step_index(seg, rows[:, 1:])
        out = np.empty((rows.shape[0], len(TIMED_COLUMNS)), np.int64)
        out[:, 0] = self.timing[seg].times_ns(k)
        out[:, 1:] = rows
        self.send(out, seg, k)
        self.timed += rows.shape[0]
        if self.checker.complete:
            self.report()

    def send(self, out: np.ndarray, seg: int, k: np.ndarray) -> None:
        """Publish timed rows, up to a programmed stop that waits for ~/resume:
        the rows beyond it are held until the call (their times are planned
        already: the run's step times are those of the automatic resume)."""
        if self.waiting_at is not None:
            self.held.append(out)
            return
        stop = next((s for s in self.holds if s[0] == seg and s[1] in k), None)
        if stop is None:
            self.pub.publish(TIMED_CDR.encode(out))
            return
        cut = int(np.nonzero(k == stop[1])[0][0]) + 1
        self.pub.publish(TIMED_CDR.encode(out[:cut]))
        self.holds.remove(stop)
        self.waiting_at = stop
        if cut < out.shape[0]:
            self.held.append(out[cut:])
        self.get_logger().info(f"programmed stop at segment {stop[0]}, step {stop[1]}: waiting for ~/resume")
        self.report()

    def on_resume(self, _req: Trigger.Request, resp: Trigger.Response) -> Trigger.Response:
        """Go on after a programmed stop that waits for a call."""
        if self.waiting_at is None or self.plan is None:
            resp.success, resp.message = False, "not at a programmed stop: nothing to resume"
            return resp
        stop, held = self.waiting_at, self.held
        self.waiting_at, self.held = None, []
        for i, out in enumerate(held):
            seg = int(out[0, 1])
            k = self.checker.step_index(seg, out[:, 2:]) if self.checker else np.zeros(0, np.int64)
            self.send(out, seg, k)
            if self.waiting_at is not None:  # the next stop is in what was held
                self.held.extend(held[i + 1 :])
                break
        resp.success = True
        resp.message = f"run {self.plan.run_id or self.plan.job_id}: resumed after the stop at step {stop[1]}"
        self.get_logger().info(resp.message)
        self.report()
        return resp

    def path_message(self, job: JobPlan) -> JointTrajectory:
        """The job's corner points (joint units) with the time each is reached:
        the start at 0, each segment's end when its move ends. ``frame_id``
        names the run (its id; the job id for a job without one)."""
        msg = JointTrajectory()
        msg.header.frame_id = job.run_id or job.job_id
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.joint_names = list(AXES)
        ends = [t.t0_ns + t.duration_ns for t in self.timing]
        corners = [(job.segments[0].start, 0)] + [(s.end, t) for s, t in zip(job.segments, ends, strict=True)]
        for pos, t_ns in corners:
            pt = JointTrajectoryPoint()
            pt.positions = [p * k for p, k in zip(pos, job.joint_step, strict=True)]
            pt.time_from_start = Duration(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)
            msg.points.append(pt)
        return msg

    def job_duration_ns(self) -> int:
        return self.timing[-1].t0_ns + self.timing[-1].duration_ns if self.timing else 0

    # -- out -------------------------------------------------------------
    def fail(self, why: str) -> None:
        self.error = why
        self.get_logger().error(why)
        self.diag.publish("job", ERROR, why, self.values("incomplete"))

    def values(self, state: str) -> dict[str, object]:
        """This node's job status values in ``state`` (the common keys first)."""
        if self.plan is None:
            return status_values(state, profile=self.settings.values()["profile"])
        profile = self.ramp_kind or self.settings.values()["profile"]
        return status_values(
            state,
            self.plan.job_id,
            self.plan.run_id,
            self.timed,
            self.plan.total_steps,
            profile=profile,
            gaps=self.checker.gaps if self.checker else 0,
            job_duration_s=f"{self.job_duration_ns() / 1e9:.6f}",
        )

    def announce(self) -> None:
        """winder/ready: ready once the steps' subscription is matched (see connect())."""
        if self.settings.blocked():
            self.ready.announce("blocked")
        elif self.sub_steps is not None and self.sub_steps.get_publisher_count() > 0:
            self.ready.announce("ready")
        else:
            self.ready.announce("waiting")

    def report(self) -> None:
        self.connect()
        self.announce()
        self.ready.repeat()
        blocked = self.settings.blocked()
        if blocked:
            self.diag.publish("job", ERROR, blocked, self.values("blocked"))
            return
        if self.plan is None:
            if self.error:
                self.diag.publish("job", ERROR, self.error, self.values("incomplete"))
            else:
                self.diag.publish("job", OK, "idle: waiting for a job", self.values("idle"))
            return
        total = self.plan.total_steps
        level = ERROR if self.error else (WARN if self.checker and self.checker.gaps else OK)
        state = "incomplete" if self.error else ("done" if self.timed >= total else "running")
        if self.waiting_at is not None and not self.error:
            state = "paused"
        self.diag.publish(
            "job",
            level,
            self.error or f"run {self.plan.run_id or self.plan.job_id}: timed {self.timed}/{total} steps",
            self.values(state),
        )


def main(args: list[str] | None = None) -> None:
    spin(ProfileNode, args)
