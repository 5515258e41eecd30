"""Running a cell: ``winder run`` on a test's domain, the small job most
node tests wind, what its bag should hold, and a stand-in profile node."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path
from typing import Any

import numpy as np

from support.paths import BIN
from support.ros_probe import spin_until
from winder.contract.stream import describe_job
from winder.motion.interp import interpolate
from winder.motion.job import Job
from winder.procs import run

SMALL_JOB = {"turns_per_layer": 3, "layers": 3, "poles": 2, "fork_steps_per_rev": 256, "job_id": "small"}


def servo_rect_job(job_id: str, *, layers: int, v_max: float, bandwidth: float, extra: str = "") -> str:
    """A job file of 6 turns a layer of 0.5 mm wire (0.45 mm copper) on a
    12 x 20 mm core, 512 fork steps a turn, wound with a servo tensioner of
    ``bandwidth`` Hz at ``v_max``; ``extra``: more interp_node lines."""
    return f"""\
interp_node:
  ros__parameters:
    job_id: {job_id}
    wire_diameter: 0.0005
    wire.bare_diameter: 0.00045
    bobbin.core: rect
    bobbin.core_width: 0.012
    bobbin.core_depth: 0.02
    bobbin.core_corner_radius: 0.001
    flyer_radius: 0.03
    turns_per_layer: 6
    layers: {layers}
    poles: 1
    fork_steps_per_rev: 512
{extra}profile_node:
  ros__parameters:
    v_max: {v_max}
sim_node:
  ros__parameters:
    tensioner.kind: servo
    tensioner.bandwidth: {bandwidth}
"""


def timed_rows(bag: dict[str, list[tuple[int, Any]]], topic: str = "/winder/step_times") -> np.ndarray:
    chunks = []
    for _, msg in bag[topic]:
        dims = msg.layout.dim
        assert dims[1].label == "t_ns,segment,feed,fork,pole"
        chunks.append(np.asarray(msg.data, dtype=np.int64).reshape(dims[0].size, dims[1].size))
    return np.vstack(chunks)


def expected_end(job: dict[str, Any]) -> tuple[int, int, int]:
    """Final axis positions worked out by hand from the job fields."""
    turns, layers, poles = job["turns_per_layer"], job["layers"], job["poles"]
    fork = job.get("fork_steps_per_rev", 1024)
    feed_per_layer = round(turns * job.get("wire_diameter", 2.5e-3) / job.get("feed_step", 1e-5))
    feed_end = 0
    direction = 1
    for _ in range(poles * layers):
        feed_end += direction * feed_per_layer
        direction = -direction
    pole_end = round((poles - 1) * job.get("pole_steps_per_rev", 1024) / poles)
    return feed_end, poles * layers * turns * fork, pole_end


def winder_run(
    tmp_path: Path, domain: int, *args: str, timeout: float = 240
) -> subprocess.CompletedProcess[str]:
    """``winder run`` into ``tmp_path/bags`` on ``domain``, dying with the test process."""
    env = {"ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "PATH": str(BIN)}
    (tmp_path / "tmp").mkdir(exist_ok=True)  # where the run keeps its node logs
    env["TMPDIR"] = str(tmp_path / "tmp")

    return run(
        [str(BIN / "winder"), "run", "--bag-dir", str(tmp_path / "bags"), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, **env},
        stdin=subprocess.DEVNULL,
    )


def job_args(job: dict[str, Any]) -> list[str]:
    out = []
    for k, v in job.items():
        out += [f"--{k.replace('_', '-')}", str(v)]
    return out


def only_bag(tmp_path: Path) -> Path:
    from winder.record.bag import bags_in

    bags = bags_in(tmp_path / "bags")
    assert len(bags) == 1, bags
    return bags[0]


class FakeProfile:
    """Plays the profile node: sends the job and hand-made timed chunks."""

    def __init__(self, node: Any, job: Job) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from std_msgs.msg import Int32MultiArray, Int64MultiArray
        from trajectory_msgs.msg import JointTrajectory

        from winder.ros.qos import QOS_LATCHED, QOS_STREAM
        from winder_interfaces.msg import ControlEvent, JobDescription

        self.node = node
        self.job = job
        self.pub_job = node.create_publisher(JobDescription, "/winder/job", QOS_LATCHED)
        self.pub = node.create_publisher(Int64MultiArray, "/winder/step_times", QOS_STREAM)
        # it stands in for the cell's interp and profile node, and the sim node acts only on
        # theirs (docs/SECURITY.md): it has their parts' endpoints (winder.contract.trust.SIGNS)
        self.parts = [
            node.create_publisher(Int32MultiArray, "/winder/steps", QOS_STREAM),
            node.create_publisher(ControlEvent, "/winder/control", QOS_STREAM),
            node.create_publisher(JointTrajectory, "/winder/path", QOS_LATCHED),
        ]
        self.statuses: list[tuple[int, str, dict[str, str]]] = []
        node.create_subscription(DiagnosticArray, "/diagnostics", self._diag, 100)

    def _diag(self, msg: Any) -> None:
        for s in msg.status:
            self.statuses.append(
                (s.level[0], s.name + " | " + s.message, {kv.key: kv.value for kv in s.values})
            )

    def publish_job(self) -> None:
        """The job's description on winder/job, as the interp node sends it."""
        from winder.ros.interfaces import job_description_msg

        self.pub_job.publish(job_description_msg(describe_job(self.job)))

    def chunks(self, size: int) -> list[np.ndarray]:
        out = []
        t = 0
        for seg in self.job.segments():
            path = interpolate(seg.start, seg.delta)
            for i in range(0, path.shape[0], size):
                rows = path[i : i + size]
                chunk = np.empty((rows.shape[0], 5), np.int64)
                chunk[:, 0] = t + 1_000_000 * np.arange(1, rows.shape[0] + 1)  # 1 ms per step
                t = int(chunk[-1, 0])
                chunk[:, 1] = seg.index
                chunk[:, 2:] = rows
                out.append(chunk)
        return out

    def send(self, chunks: list[np.ndarray]) -> None:
        from winder.ros.chunks import pack_timed

        spin_until(
            self.node, lambda: self.pub.get_subscription_count() > 0, 30, "the sim node's subscription"
        )
        # and its 1 Hz status heard: its /diagnostics writer is matched with ours, so the
        # one-shot ERROR a bad chunk gets is not lost to discovery
        spin_until(
            self.node,
            lambda: any(name.startswith("sim_node: ") for _, name, _ in self.statuses),
            30,
            "the sim node's status",
        )
        self.publish_job()
        # the job description taken first, as the real profile node sends it: the sim node's run is on
        spin_until(
            self.node,
            lambda: any(
                name.startswith("sim_node: ") and v.get("job_id") == self.job.job_id
                for _, name, v in self.statuses
            ),
            30,
            f"the sim node's run of job {self.job.job_id}",
            heard=lambda: [name for _, name, _ in self.statuses[-5:]],
        )
        for c in chunks:
            self.pub.publish(pack_timed(c))
