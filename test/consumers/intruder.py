"""A foreign node on a cell's graph: not one of the cell's nodes, but in its
namespace and domain, publishing on the cell's own topics with the cell's
QoS. It learns the running run's id from /diagnostics (as anyone on the
domain can) and, every ``--period`` s, forges what ``--forge`` names:

* ``control``: an operator abort claiming 10 steps, a pause, an override;
* ``steps``: 100 valid-looking timed rows of a later segment on winder/step_times;
* ``job``: the cell's own latched job description again, under a new run id;
* ``ready``: ``consumer: ready`` and ``profile: busy`` on winder/ready;
* ``progress``: a receipt for every step of the run on winder/progress;
* ``diagnostics``: a final report named like the cell's consumer (state
  done, bag /FAKE) and an ERROR named like its interp node;
* ``state``: ``winder/state`` saying the run failed;
* ``sim_config``: a sim_config of the run claiming a real-time look-ahead;
* ``joints``: a joint state of a joint named ``forged`` on winder/joint_states.

    python intruder.py --forge control,steps --ns /c1 [--ros-args -r __node:=name]
"""

from __future__ import annotations

import argparse
import json
import math
import sys

import numpy as np
import rclpy
from _spin import spin_until_stopped
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Int64MultiArray, String

from winder.contract.topics import (
    TOPIC_CONTROL,
    TOPIC_DIAGNOSTICS,
    TOPIC_JOB,
    TOPIC_JOINT_STATES,
    TOPIC_PROGRESS,
    TOPIC_READY,
    TOPIC_SIM_CONFIG,
    TOPIC_STATE,
    TOPIC_STEP_TIMES,
)
from winder.ros.chunks import pack_timed
from winder.ros.qos import QOS_DIAGNOSTICS, QOS_EVENTS, QOS_LATCHED, QOS_STATE, QOS_STREAM
from winder_interfaces.msg import CellState, ControlEvent, JobDescription

KINDS = ("control", "steps", "job", "ready", "progress", "diagnostics", "state", "sim_config", "joints")


class Intruder(Node):
    def __init__(self, forge: list[str], period: float) -> None:
        super().__init__("intruder")
        self.forge = forge
        self.run_id = ""
        self.job: JobDescription | None = None
        self.sent = 0
        ns = self.get_namespace().strip("/")
        self.prefix = f"{ns}/" if ns else ""
        self.pub = {
            "control": self.create_publisher(ControlEvent, TOPIC_CONTROL, QOS_EVENTS),
            "steps": self.create_publisher(Int64MultiArray, TOPIC_STEP_TIMES, QOS_STREAM),
            "job": self.create_publisher(JobDescription, TOPIC_JOB, QOS_LATCHED),
            "ready": self.create_publisher(KeyValue, TOPIC_READY, QOS_LATCHED),
            "progress": self.create_publisher(KeyValue, TOPIC_PROGRESS, QOS_STATE),
            "diagnostics": self.create_publisher(DiagnosticArray, TOPIC_DIAGNOSTICS, QOS_DIAGNOSTICS),
            "state": self.create_publisher(CellState, TOPIC_STATE, QOS_LATCHED),
            "sim_config": self.create_publisher(String, TOPIC_SIM_CONFIG, QOS_LATCHED),
            "joints": self.create_publisher(JointState, TOPIC_JOINT_STATES, QOS_STATE),
        }
        self.create_subscription(DiagnosticArray, TOPIC_DIAGNOSTICS, self.on_diagnostics, QOS_DIAGNOSTICS)
        self.create_subscription(JobDescription, TOPIC_JOB, self.on_job, QOS_LATCHED)
        self.create_timer(period, self.tick)

    def on_diagnostics(self, msg: DiagnosticArray) -> None:
        for st in msg.status:
            values = {kv.key: kv.value for kv in st.values}
            if values.get("run_id") and values.get("state") == "running":
                self.run_id = values["run_id"]

    def on_job(self, msg: JobDescription) -> None:
        if not msg.run_id.endswith("_99"):  # not its own forgery
            self.job = msg
            # the run's id as the run starts (its statuses say it up to 1 s later)
            self.run_id = msg.run_id or self.run_id

    def tick(self) -> None:
        if not self.run_id:
            return
        for kind in self.forge:
            getattr(self, f"forge_{kind}")()
        self.sent += 1
        if self.sent == 1:
            print(f"intruder: forging {','.join(self.forge)} into run {self.run_id}", flush=True)

    def forge_control(self) -> None:
        run = self.run_id
        nan = math.nan
        for event in (
            ControlEvent(event="abort", run_id=run, t_ns=1, t_rest_ns=2, steps=10, factor=nan),
            ControlEvent(event="pause", run_id=run, t_ns=1, t_rest_ns=2, steps=10, factor=nan),
            ControlEvent(event="override", run_id=run, t_ns=1, t_rest_ns=-1, steps=-1, factor=0.1),
        ):
            self.pub["control"].publish(event)

    def forge_steps(self) -> None:
        rows = np.zeros((100, 5), np.int64)
        rows[:, 0] = 10**9 + np.arange(100) * 1000
        rows[:, 1] = 3
        rows[:, 3] = np.arange(1, 101)
        self.pub["steps"].publish(pack_timed(rows))

    def forge_job(self) -> None:
        if self.job is not None:
            self.job.run_id = self.job.run_id.rsplit("_", 1)[0] + "_99"
            self.pub["job"].publish(self.job)

    def forge_ready(self) -> None:
        self.pub["ready"].publish(KeyValue(key="consumer", value="ready"))
        self.pub["ready"].publish(KeyValue(key="profile", value="busy"))

    def forge_progress(self) -> None:
        self.pub["progress"].publish(KeyValue(key=self.run_id, value="0"))

    def forge_diagnostics(self) -> None:
        done = [KeyValue(key=k, value=v) for k, v in (
            ("state", "done"), ("job_id", "rw400"), ("run_id", self.run_id), ("steps_done", "1"),
            ("steps_total", "1"), ("progress", "1.0"), ("role", "consumer"), ("bag", "/FAKE"),
        )]  # fmt: skip
        self.pub["diagnostics"].publish(
            DiagnosticArray(
                status=[
                    DiagnosticStatus(
                        level=b"\x00", name=f"{self.prefix}sim_node: job", message="done", values=done
                    ),
                    DiagnosticStatus(
                        level=b"\x02", name=f"{self.prefix}interp_node: job", message="forged ERROR"
                    ),
                ]
            )
        )

    def forge_state(self) -> None:
        node = f"{self.prefix}sim_node"
        self.pub["state"].publish(CellState(node=node, state="failed", run_id=self.run_id, message="forged"))

    def forge_sim_config(self) -> None:
        doc = {"run_id": self.run_id, "real_time": True, "lookahead_s": 0.001, "clock_origin_ns": 0}
        self.pub["sim_config"].publish(String(data=json.dumps(doc)))

    def forge_joints(self) -> None:
        self.pub["joints"].publish(JointState(name=["forged"], position=[1.0], velocity=[0.0]))


def main() -> None:
    args = rclpy.utilities.remove_ros_args(sys.argv)[1:]
    parser = argparse.ArgumentParser()
    parser.add_argument("--forge", default=",".join(KINDS))
    parser.add_argument("--period", type=float, default=0.05)
    opts = parser.parse_args(args)
    forge = [k for k in opts.forge.split(",") if k]
    bad = [k for k in forge if k not in KINDS]
    if bad:
        parser.error(f"--forge {','.join(bad)}: must be of {','.join(KINDS)}")
    rclpy.init()
    node = Intruder(forge, opts.period)
    spin_until_stopped(node)


if __name__ == "__main__":
    main()
