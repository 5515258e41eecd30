"""A step consumer written from the topic contract (docs/INTEGRATING.md) alone: rclpy,
standard messages and winder_interfaces' types, no winder import, no StepConsumer.

It announces itself on winder/ready, takes a run from winder/job, executes
the timed steps of winder/step_times at their times (as a drive would, in
wall time), acknowledges them on winder/progress and reports a
``<node>: job`` status on /diagnostics. It does NOT follow winder/control:
after an abort the rest of the run never comes and it stays ``busy``, the
consumer test_conformance.py's ignored-abort test starts the cell with.

    python naive_consumer.py [--ros-args -r __node:=axes]
"""

from __future__ import annotations

import sys
import time
from collections import deque

import rclpy
from _spin import spin_until_stopped
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Int64MultiArray

from winder_interfaces.msg import JobDescription

RELIABLE = ReliabilityPolicy.RELIABLE
LATCHED = QoSProfile(depth=1, reliability=RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
STREAM = QoSProfile(depth=1000, reliability=RELIABLE, history=HistoryPolicy.KEEP_ALL)
PROGRESS = QoSProfile(depth=100, reliability=RELIABLE)
DIAGNOSTICS = QoSProfile(depth=10, reliability=RELIABLE)


class NaiveConsumer(Node):
    def __init__(self) -> None:
        super().__init__("naive_consumer")
        self.pub_ready = self.create_publisher(KeyValue, "winder/ready", LATCHED)
        self.pub_progress = self.create_publisher(KeyValue, "winder/progress", PROGRESS)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", DIAGNOSTICS)
        self.create_subscription(JobDescription, "winder/job", self.on_job, LATCHED)
        self.sub_times = self.create_subscription(Int64MultiArray, "winder/step_times", self.on_steps, STREAM)
        self.state, self.job_id, self.run_id = "idle", "", ""
        self.total = self.done = 0
        self.t0 = 0.0  # wall time of the run's start (its first chunk)
        self.due: deque[int] = deque()  # step times (ns) received, not executed yet
        self.create_timer(0.02, self.execute)
        self.create_timer(1.0, self.report)

    def on_job(self, msg: JobDescription) -> None:
        self.job_id, self.run_id = msg.job_id, msg.run_id
        self.total, self.done, self.t0 = msg.total_steps, 0, 0.0
        self.due.clear()
        self.state = "running"
        self.report()

    def on_steps(self, msg: Int64MultiArray) -> None:
        if self.state != "running":
            return
        if not self.t0:
            self.t0 = time.monotonic()
        self.due.extend(msg.data[0::5])  # rows t_ns, segment, feed, fork, pole

    def execute(self) -> None:
        """The steps whose time has come are done: acknowledge them."""
        now_ns = (time.monotonic() - self.t0) * 1e9
        n = 0
        while self.due and self.due[0] <= now_ns:
            self.due.popleft()
            n += 1
        if n:
            self.done += n
            self.pub_progress.publish(KeyValue(key=self.run_id, value=str(self.done)))
            if self.done >= self.total:
                self.state = "done"
                self.report()

    def report(self) -> None:
        """winder/ready and the job status, at once on a change and every second."""
        if self.state == "running":
            ready = "busy"
        else:
            ready = "ready" if self.sub_times.get_publisher_count() > 0 else "waiting"
        self.pub_ready.publish(KeyValue(key="consumer", value=ready))
        values = {
            "state": self.state,
            "job_id": self.job_id,
            "run_id": self.run_id,
            "steps_done": self.done,
            "steps_total": self.total,
            "progress": f"{self.done / self.total:.4f}" if self.total else "0.0000",
            "role": "consumer",
        }
        status = DiagnosticStatus(
            level=DiagnosticStatus.OK,
            name=f"{self.get_fully_qualified_name().lstrip('/')}: job",
            message=f"run {self.run_id}: {self.state}" if self.run_id else "idle: waiting for a job",
            hardware_id="naive_consumer",
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()],
        )
        self.pub_diag.publish(DiagnosticArray(status=[status]))


def main() -> None:
    rclpy.init(args=sys.argv)
    node = NaiveConsumer()
    spin_until_stopped(node)


if __name__ == "__main__":
    main()
