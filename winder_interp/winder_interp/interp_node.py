"""interp_node: winding job (parameters) -> minimum-deviation step commands.

In:  parameters (the fields of winder.job.Job, autostart, chunk_steps),
     service ~/start (std_srvs/Trigger).
Out: winder/job (std_msgs/String, JSON job description, latched),
     winder/path (trajectory_msgs/JointTrajectory, latched),
     winder/steps (std_msgs/Int32MultiArray chunks), /diagnostics.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import numpy.typing as npt

import rclpy
from builtin_interfaces.msg import Duration
from rcl_interfaces.msg import ParameterType
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from std_msgs.msg import Int32MultiArray, String
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from winder.interp import interpolate
from winder.job import AXES, FIELD_SPECS, Job, JobError
from winder.stream import describe_job
from winder_interp.contract import (
    ERROR,
    OK,
    QOS_LATCHED,
    QOS_STREAM,
    TOPIC_JOB,
    TOPIC_PATH,
    TOPIC_STEPS,
    Diagnostics,
    declare_all,
    float_param,
    int_param,
    pack_steps,
    plain_param,
)


def job_parameter_specs() -> dict[str, tuple[Any, Any]]:
    defaults = Job()
    specs: dict[str, tuple[Any, Any]] = {}
    for name, spec in FIELD_SPECS.items():
        unit = f" [{spec.unit}]" if spec.unit else ""
        text = f"{spec.description}{unit}, allowed {spec.range_text() if spec.kind is not str else 'see job_id rules'}"
        if spec.kind is str:
            specs[name] = (getattr(defaults, name), plain_param(ParameterType.PARAMETER_STRING, text))
        elif spec.kind is int:
            specs[name] = (getattr(defaults, name), int_param(text, int(spec.low or 0), int(spec.high or 0)))
        else:
            specs[name] = (
                float(getattr(defaults, name)),
                float_param(text, float(spec.low or 0.0), float(spec.high or 0.0)),
            )
    return specs


def check_job(values: dict[str, Any]) -> str | None:
    try:
        Job(**{k: v for k, v in values.items() if k in FIELD_SPECS})
    except JobError as exc:
        return str(exc)
    chunk = values.get("chunk_steps", 1)
    if not isinstance(chunk, int) or not 1 <= chunk <= 1 << 20:
        return f"chunk_steps={chunk!r} is invalid: must be an integer in [1, 1048576]"
    return None


class InterpNode(Node):
    def __init__(self) -> None:
        super().__init__("interp_node")
        specs = job_parameter_specs()
        specs["autostart"] = (
            True,
            plain_param(ParameterType.PARAMETER_BOOL, "start the job once the step stream has a subscriber"),
        )
        specs["chunk_steps"] = (8192, int_param("steps per winder/steps message", 1, 1 << 20))
        self.rejected = declare_all(self, specs, check_job)

        self.pub_job = self.create_publisher(String, TOPIC_JOB, QOS_LATCHED)
        self.pub_path = self.create_publisher(JointTrajectory, TOPIC_PATH, QOS_LATCHED)
        self.pub_steps = self.create_publisher(Int32MultiArray, TOPIC_STEPS, QOS_STREAM)
        self.diag = Diagnostics(self, "winder_interp")
        self.create_service(Trigger, "~/start", self.on_start)
        self.create_timer(0.02, self.tick)
        self.create_timer(1.0, self.report)

        self.job: Job | None = None
        self.pending: Iterator[npt.NDArray[np.int32]] | None = None  # generator of chunks of the running job
        self.sent = 0
        self.started_wall = 0.0
        self.autostarted = False
        self.finished = False
        if self.rejected:
            self.diag.publish("job", ERROR, f"parameters rejected at start: {', '.join(self.rejected)}", {})

    # -- in --------------------------------------------------------------
    def on_start(self, _req: Trigger.Request, resp: Trigger.Response) -> Trigger.Response:
        resp.success, resp.message = self.start_job()
        return resp

    def tick(self) -> None:
        if (
            not self.autostarted
            and self.get_parameter("autostart").value
            and self.pub_steps.get_subscription_count() > 0
        ):
            self.autostarted = True
            ok, why = self.start_job()
            if not ok:
                self.get_logger().error(why)
        self.send_some()

    # -- work ------------------------------------------------------------
    def start_job(self) -> tuple[bool, str]:
        if self.pending is not None:
            return False, f"job {self.job.job_id if self.job else '?'} is still being sent"
        values = {name: self.get_parameter(name).value for name in FIELD_SPECS}
        try:
            job = Job(**values)
        except JobError as exc:
            self.diag.publish("job", ERROR, f"job rejected: {exc}", {})
            return False, f"job rejected: {exc}"
        self.job = job
        self.sent = 0
        self.finished = False
        self.started_wall = time.monotonic()
        self.pub_job.publish(String(data=describe_job(job)))
        self.pub_path.publish(self.path_message(job))
        self.pending = self.chunks(job, self.get_parameter("chunk_steps").value)
        self.get_logger().info(f"job {job.job_id}: {job.total_steps} steps in {len(job.segments())} segments")
        return True, f"job {job.job_id} started: {job.total_steps} steps"

    def path_message(self, job: Job) -> JointTrajectory:
        msg = JointTrajectory()
        msg.header.frame_id = job.job_id
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.joint_names = list(AXES)
        scale = job.joint_step
        segs = job.segments()
        for pos in [segs[0].start] + [s.end for s in segs]:
            pt = JointTrajectoryPoint()
            pt.positions = [p * k for p, k in zip(pos, scale, strict=True)]
            pt.time_from_start = Duration()  # timing belongs to the profile node
            msg.points.append(pt)
        return msg

    @staticmethod
    def chunks(job: Job, size: int) -> Iterator[npt.NDArray[np.int32]]:
        for seg in job.segments():
            for first in range(0, seg.steps, size):
                stop = min(seg.steps, first + size)
                pos = interpolate(seg.start, seg.delta, first=first, stop=stop)
                rows = np.empty((pos.shape[0], 1 + pos.shape[1]), dtype=np.int32)
                rows[:, 0] = seg.index
                rows[:, 1:] = pos
                yield rows

    def send_some(self) -> None:
        if self.pending is None:
            return
        deadline = time.monotonic() + 0.015  # stay responsive to services and parameters
        while time.monotonic() < deadline:
            rows = next(self.pending, None)
            if rows is None:
                self.pending = None
                self.finished = True
                self.report()
                return
            self.pub_steps.publish(pack_steps(rows))
            self.sent += rows.shape[0]

    def report(self) -> None:
        if self.job is None:
            return
        total = self.job.total_steps
        state = "sent" if self.finished else "sending"
        self.diag.publish(
            "job",
            OK,
            f"job {self.job.job_id}: {state} {self.sent}/{total} steps",
            {
                "job_id": self.job.job_id,
                "steps_sent": self.sent,
                "steps_total": total,
                "progress": f"{self.sent / max(total, 1):.4f}",
                "state": state,
                "elapsed_s": f"{time.monotonic() - self.started_wall:.3f}",
            },
        )


def main(args: list[str] | None = None) -> None:
    rclpy.init(args=args)
    node = None
    try:
        node = InterpNode()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()

