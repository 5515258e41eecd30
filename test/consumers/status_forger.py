"""A foreign node that forges the end of a cell's run on /diagnostics: it
learns the running run's id from /diagnostics (as anyone on the domain can)
and, every ``--period`` s, publishes a final ``job`` status of that run
(state done, every step, ``bag /FAKE``, ``role: consumer``) speaking for
``--speaks-for`` (a node name in its own namespace: the cell's consumer's,
``sim_node``; or ``self``, its own name, as a node that plays no part in the
cell may say anything of itself), and ``winder/state`` saying the run is
done. It plays no part in the cell: it reads and writes none of the step
topics.

``--run-id``: the run to forge the end of, from the start (not learned).

    python status_forger.py --speaks-for self [--run-id ID] [--ros-args -r __ns:=/c1 -r __node:=name]
"""

from __future__ import annotations

import argparse
import sys

import rclpy
from _spin import spin_until_stopped
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node

from winder.contract.topics import TOPIC_DIAGNOSTICS, TOPIC_STATE
from winder.ros.qos import QOS_DIAGNOSTICS, QOS_LATCHED
from winder_interfaces.msg import CellState


class Forger(Node):
    def __init__(self, speaks_for: str, period: float, run_id: str) -> None:
        super().__init__("forger")
        ns = self.get_namespace().strip("/")
        name = self.get_name() if speaks_for == "self" else speaks_for
        self.status_name = f"{ns}/{name}: job" if ns else f"{name}: job"
        self.node = f"{ns}/{name}" if ns else name
        self.run_id = run_id
        self.learns = not run_id
        self.sent = 0
        self.pub = self.create_publisher(DiagnosticArray, TOPIC_DIAGNOSTICS, QOS_DIAGNOSTICS)
        self.pub_state = self.create_publisher(CellState, TOPIC_STATE, QOS_LATCHED)
        self.create_subscription(DiagnosticArray, TOPIC_DIAGNOSTICS, self.on_diagnostics, QOS_DIAGNOSTICS)
        self.create_timer(period, self.tick)

    def on_diagnostics(self, msg: DiagnosticArray) -> None:
        if not self.learns:
            return
        for st in msg.status:
            values = {kv.key: kv.value for kv in st.values}
            if values.get("run_id") and values.get("state") == "running" and st.name != self.status_name:
                self.run_id = values["run_id"]

    def tick(self) -> None:
        if not self.run_id:
            return
        done = [KeyValue(key=k, value=v) for k, v in (
            ("state", "done"), ("job_id", "forged"), ("run_id", self.run_id), ("steps_done", "1"),
            ("steps_total", "1"), ("progress", "1.0000"), ("role", "consumer"), ("bag", "/FAKE"),
        )]  # fmt: skip
        status = DiagnosticStatus(level=b"\x00", name=self.status_name, message="done", values=done)
        self.pub.publish(DiagnosticArray(status=[status]))
        self.pub_state.publish(CellState(node=self.node, state="done", run_id=self.run_id, message="forged"))
        self.sent += 1
        if self.sent == 1:
            print(f"forger: forging the end of run {self.run_id} as {self.status_name}", flush=True)


def main() -> None:
    args = rclpy.utilities.remove_ros_args(sys.argv)[1:]
    parser = argparse.ArgumentParser()
    parser.add_argument("--speaks-for", default="self")
    parser.add_argument("--period", type=float, default=0.05)
    parser.add_argument("--run-id", default="")
    opts = parser.parse_args(args)
    rclpy.init()
    spin_until_stopped(Forger(opts.speaks_for, opts.period, opts.run_id))


if __name__ == "__main__":
    main()
