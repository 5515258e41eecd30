"""profile_node: step commands -> timed step commands.

In:  winder/job (std_msgs/String, latched), winder/steps (Int32MultiArray),
     parameters (profile kind and limits, in steps of the segment's major axis).
Out: winder/step_times (std_msgs/Int64MultiArray: [t_ns, segment, feed, fork,
     pole]), /diagnostics.

Each segment is one move of its major axis' step count, ramped with the chosen
profile from and to the start/stop rate ``v_start``; step k of N happens when
the planned motion reaches k/N of the move. Segments follow each other with
``dwell`` seconds between them. The whole job is planned when its description
arrives, so a step's time depends only on its index, never on arrival order.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
import rclpy
from rcl_interfaces.msg import ParameterType
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from std_msgs.msg import Int32MultiArray, Int64MultiArray, String

from winder.profile import plan
from winder.stream import STEP_COLUMNS, JobPlan, StreamChecker, parse_job_description
from winder_interp.contract import (
    ERROR,
    OK,
    QOS_LATCHED,
    QOS_STREAM,
    TOPIC_JOB,
    TOPIC_STEP_TIMES,
    TOPIC_STEPS,
    WARN,
    Diagnostics,
    declare_all,
    float_param,
    pack_timed,
    plain_param,
    unpack,
)

KINDS = ("scurve", "trapezoid", "exponential")


def plan_segment(values: dict[str, Any], steps: int) -> Any:
    """The profile of one segment of ``steps`` steps with the node's limits."""
    kind = values["profile"]
    kw: dict[str, Any] = {"v_max": values["v_max"], "v_start": values["v_start"], "v_end": values["v_start"]}
    if kind in ("scurve", "trapezoid"):
        kw["a_max"] = values["a_max"]
    if kind == "scurve":
        kw["j_max"] = values["j_max"]
    if kind == "exponential":
        kw["tau"] = values["tau"]
    return plan(kind, float(steps), **kw)


def check_limits(values: dict[str, Any]) -> str | None:
    if values.get("profile") not in KINDS:
        return f"profile={values.get('profile')!r} is invalid: must be one of {', '.join(KINDS)}"
    try:
        plan_segment(values, 1000)
    except ValueError as exc:
        return str(exc)
    return None


class ProfileNode(Node):
    def __init__(self) -> None:
        super().__init__("profile_node")
        specs = {
            "profile": ("scurve", plain_param(ParameterType.PARAMETER_STRING, "scurve | trapezoid | exponential")),
            "v_max": (5120.0, float_param("peak step rate of the major axis [steps/s]", 0.0, 1e7)),
            "a_max": (40000.0, float_param("acceleration limit (scurve, trapezoid) [steps/s^2]", 0.0, 1e10)),
            "j_max": (400000.0, float_param("jerk limit (scurve) [steps/s^3]", 0.0, 1e14)),
            "tau": (0.05, float_param("time constant of the exponential ramp [s]", 0.0, 100.0)),
            "v_start": (0.0, float_param("start/stop step rate, each segment starts and ends at it [steps/s]", 0.0, 1e7)),
            "dwell": (0.0, float_param("pause between segments [s]", 0.0, 3600.0)),
        }
        self.rejected = declare_all(self, specs, check_limits)
        self.names = list(specs)

        self.pub = self.create_publisher(Int64MultiArray, TOPIC_STEP_TIMES, QOS_STREAM)
        self.diag = Diagnostics(self, "winder_profile")
        self.create_subscription(String, TOPIC_JOB, self.on_job, QOS_LATCHED)
        self.sub_steps = None  # created once the timed stream has a reader
        self.create_timer(0.05, self.connect)
        self.create_timer(1.0, self.report)

        self.plan: JobPlan | None = None
        self.checker: StreamChecker | None = None
        self.seg_t0_ns: npt.NDArray[np.int64] = np.zeros(0, np.int64)
        self.profiles: list[Any] = []
        self.cached: tuple[int, npt.NDArray[np.float64]] | None = None
        self.early: list[bytes] = []
        self.timed = 0
        self.error = ""
        if self.rejected:
            self.error = f"parameters rejected at start: {', '.join(self.rejected)}"

    def connect(self) -> None:
        if self.sub_steps is None and self.pub.get_subscription_count() > 0:
            self.sub_steps = self.create_subscription(
                Int32MultiArray, TOPIC_STEPS, self.on_steps, QOS_STREAM, raw=True
            )

    # -- in --------------------------------------------------------------
    def on_job(self, msg: String) -> None:
        try:
            job = parse_job_description(msg.data)
        except ValueError as exc:
            self.fail(f"job description rejected: {exc}")
            return
        values = {n: self.get_parameter(n).value for n in self.names}
        try:
            profiles = [plan_segment(values, s.steps) for s in job.segments]
        except ValueError as exc:
            self.fail(f"job {job.job_id} cannot be ramped: {exc}")
            return
        dwell_ns = round(values["dwell"] * 1e9)
        t0 = np.zeros(len(profiles), np.int64)
        acc = 0
        for i, p in enumerate(profiles):
            t0[i] = acc
            acc += round(p.duration * 1e9) + dwell_ns
        self.plan, self.profiles, self.seg_t0_ns = job, profiles, t0
        self.checker = StreamChecker(job)
        self.cached = None
        self.timed = 0
        self.error = ""
        self.get_logger().info(
            f"job {job.job_id}: {values['profile']} ramps, {len(profiles)} segments, "
            f"{(acc - dwell_ns) / 1e9:.3f} s"
        )
        early, self.early = self.early, []
        for raw in early:
            self.on_steps(raw)

    def on_steps(self, raw: bytes) -> None:
        if self.plan is None or self.checker is None:
            self.early.append(raw)  # the job description is on its way
            return
        try:
            rows = unpack(deserialize_message(raw, Int32MultiArray), STEP_COLUMNS)
        except ValueError as exc:
            self.fail(f"bad steps chunk: {exc}")
            return
        seg = int(rows[0, 0])
        pos = rows[:, 1:].astype(np.int64)
        verdict = self.checker.check(seg, pos)
        if verdict.kind != "ok":
            self.get_logger().error(verdict.message)
            self.diag.publish("stream", ERROR, verdict.message, {"kind": verdict.kind, "missing": verdict.missing})
        if not verdict.accept:
            return
        k = self.checker.step_index(seg, pos)
        times = self.segment_times(seg)[k - 1]
        out = np.empty((rows.shape[0], 5), np.int64)
        out[:, 0] = self.seg_t0_ns[seg] + np.rint(times * 1e9).astype(np.int64)
        out[:, 1:] = rows
        self.pub.publish(pack_timed(out))
        self.timed += rows.shape[0]
        if self.checker.complete:
            self.report()

    def segment_times(self, seg: int) -> npt.NDArray[np.float64]:
        if self.cached is None or self.cached[0] != seg:
            assert self.plan is not None
            self.cached = (seg, self.profiles[seg].step_times(self.plan.segments[seg].steps))
        return self.cached[1]

    # -- out -------------------------------------------------------------
    def fail(self, why: str) -> None:
        self.error = why
        self.get_logger().error(why)
        self.diag.publish("job", ERROR, why, {})

    def report(self) -> None:
        if self.plan is None:
            if self.error:
                self.diag.publish("job", ERROR, self.error, {})
            return
        total = self.plan.total_steps
        level = ERROR if self.error else (WARN if self.checker and self.checker.gaps else OK)
        self.diag.publish(
            "job",
            level,
            self.error or f"job {self.plan.job_id}: timed {self.timed}/{total} steps",
            {
                "job_id": self.plan.job_id,
                "profile": self.get_parameter("profile").value,
                "steps_timed": self.timed,
                "steps_total": total,
                "progress": f"{self.timed / max(total, 1):.4f}",
                "gaps": self.checker.gaps if self.checker else 0,
                "job_duration_s": f"{(self.seg_t0_ns[-1] + round(self.profiles[-1].duration * 1e9)) / 1e9:.6f}",
            },
        )


def main(args: list[str] | None = None) -> None:
    rclpy.init(args=args)
    node = None
    try:
        node = ProfileNode()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()

