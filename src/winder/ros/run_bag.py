"""``RunBag``: a consumer's recording of its runs, one rosbag2/MCAP
directory per run (parameter ``record``).

The run's description (and its winder/sim_config) is in the bag from its
first moment on, so a node killed at any time after leaves a bag that tells
which run it was; the job's path and the ramp its profile node planned it
with are recorded once each, whichever of them and the description comes
first; the statuses of the cell's other nodes on /diagnostics, each sent by
the node it names. A write that fails (a full disk) stops the recording and
is said once; the consumer then closes the run incomplete. A message's log
time is the wall-clock time of the run's start plus its run time.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from rclpy.node import Node
from rclpy.serialization import deserialize_message
from std_msgs.msg import String
from trajectory_msgs.msg import JointTrajectory

from winder.contract.params import bag_directory
from winder.contract.stream import JobPlan
from winder.contract.topics import TOPIC_DIAGNOSTICS, in_namespace
from winder.record.bag import BagRecorder, new_bag_path, run_bag_path, unclosed_bags, unclosed_line
from winder.ros.peers import Peers

__all__ = ["RunBag", "one_line"]


def one_line(exc: BaseException) -> str:
    return (str(exc).splitlines() or [type(exc).__name__])[0]


class RunBag:
    """The recording of a consumer node's runs (see the module doc).
    ``topics``: bag key -> (topic, type), relative names resolved in the
    node's namespace; ``failed`` is told why a recording stopped, in one line."""

    def __init__(
        self, node: Node, peers: Peers, topics: dict[str, tuple[str, str]], failed: Callable[[str], None]
    ) -> None:
        self.node, self.peers, self.failed = node, peers, failed
        self.topics = {
            key: (name if name.startswith("/") else node.resolve_topic_name(name), kind)
            for key, (name, kind) in topics.items()
        }
        self.path_raw: bytes | None = None  # the last winder/path heard, of any run
        self.profile_raw: bytes | None = None  # the last winder/profile_config heard
        self.start(None, 0)

    def start(self, plan: JobPlan | None, wall0_ns: int) -> None:
        """A run starts (None: no run) at this wall-clock time: nothing recorded yet."""
        self.plan = plan
        self.recorder: BagRecorder | None = None
        self.wall0_ns = wall0_ns
        self.failure = ""  # why the bag stopped recording (a full disk), if it did
        self.path_recorded = False
        self.profile_recorded = False
        self.skipped: frozenset[str] = frozenset()  # keys whose topics this run's bag does not name

    @property
    def path(self) -> Path | None:
        """The run's bag directory, if it records."""
        return self.recorder.path if self.recorder is not None else None

    @property
    def has_plan_documents(self) -> bool:
        """The run's path and ramp are in the bag."""
        return self.path_recorded and self.profile_recorded

    def check_dir(self, values: dict[str, Any]) -> None:
        """At start: the bags in ``bag_dir`` that a writer left unclosed (an
        earlier run of this node SIGKILLed, a full disk), named in one line
        with what closes them (they read as they are, without an index); the
        rest of the cell goes on as ever."""
        if not values.get("record"):
            return
        try:
            directory = bag_directory(values["bag_dir"])
        except ValueError:
            return
        said = unclosed_line(unclosed_bags(directory), f"bag_dir {directory}")
        if said:
            self.node.get_logger().warning(said)

    def open(
        self, values: dict[str, Any], job_raw: bytes, config_raw: bytes, skip: frozenset[str] = frozenset()
    ) -> str:
        """Open the run's bag with its description (and configuration) in it,
        naming every topic but those of the keys ``skip``; the reason in one
        line if it cannot be, else ""."""
        plan = self.plan
        assert plan is not None
        try:
            directory = bag_directory(values["bag_dir"])
            path = (
                run_bag_path(directory, plan.run_id) if plan.run_id else new_bag_path(directory, plan.job_id)
            )
            first = [(self.topics["job"][0], self.wall0_ns, job_raw)]
            if config_raw:
                first.append((self.topics["sim_config"][0], self.wall0_ns, config_raw))
            # a re-simulation says so in metadata.yaml, where rosbag2 tools show it
            custom = (
                {
                    "winder_run": "re-simulation",
                    "winder_source_bag": plan.source_bag,
                    "winder_source_run_id": plan.source_run_id,
                }
                if plan.source_bag
                else {}
            )
            # who ran it with which wire, where they were given (the part records them too)
            custom.update(
                {f"winder_{k}": v for k, v in (("operator", plan.operator), ("wire_lot", plan.wire_lot)) if v}
            )
            self.recorder = BagRecorder(
                path,
                {name: kind for key, (name, kind) in self.topics.items() if key not in skip},
                compression=values["bag_compression"],
                first=first,
                custom=custom,
            )
        except (OSError, ValueError) as exc:  # the disk changed since bag_dir was accepted
            return f"cannot open a bag: {one_line(exc)}"
        self.skipped = skip
        return ""

    def record(self, key: str, t_ns: int, data: bytes, *, exact: bool = False) -> None:
        """One message into the run's bag, if it records. A failed write (a
        full disk) stops the recording (:attr:`failure`)."""
        if self.recorder is None or not self.recorder.is_open or self.failure or key in self.skipped:
            return
        try:
            self.recorder.write(self.topics[key][0], self.wall0_ns + t_ns, data, exact=exact)
        except RuntimeError as exc:
            self.stopped(exc)

    def close(self) -> None:
        """Close the run's bag (its summary written); a failure is :attr:`failure`."""
        if self.recorder is None or not self.recorder.is_open:
            return
        try:
            self.recorder.close()
        except (RuntimeError, OSError) as exc:  # left unclosed: winder bag recover reads it
            self.stopped(exc)

    def stopped(self, exc: BaseException) -> None:
        if self.failure:
            return
        cause = exc.__cause__ or exc
        errno_ = getattr(cause, "errno", None)
        why = {28: "disk full", 27: "file size limit reached"}.get(errno_ or 0, one_line(cause))
        self.failure = why
        bag = self.path
        kept = (
            f"the bag {bag} keeps every chunk that reached the disk, which every MCAP reader opens as it is "
            f"(without an index if its summary did not fit): `winder bag recover {bag}` writes a closed copy"
            if bag is not None
            else "the bag keeps what reached the disk"
        )
        self.failed(f"recording stopped: {why}; {kept}; the job is closed incomplete")

    # -- the run's plan documents -------------------------------------------------------
    def take_path(self, raw: bytes, t_ns: int) -> None:
        self.path_raw = raw
        self.record_path(t_ns)

    def take_profile_config(self, raw: bytes, t_ns: int) -> None:
        self.profile_raw = raw
        self.record_profile_config(t_ns)

    def record_path(self, t_ns: int) -> None:
        """Record the run's path once. Job and path travel on two topics that
        match independently, so either may arrive first."""
        if self.plan is None or self.path_raw is None or self.path_recorded:
            return
        try:
            path = deserialize_message(self.path_raw, JointTrajectory)
        except Exception:  # not a path: nothing of it is recorded
            return
        if path.header.frame_id != (self.plan.run_id or self.plan.job_id):
            return  # an earlier run's path; this run's is on its way
        self.path_recorded = True
        self.record("path", t_ns, self.path_raw)

    def record_profile_config(self, t_ns: int) -> None:
        """Record the ramp the profile node planned the run with, once."""
        if self.plan is None or self.profile_raw is None or self.profile_recorded:
            return
        try:
            doc = json.loads(deserialize_message(self.profile_raw, String).data)
            ids = (doc.get("job_id"), doc.get("run_id", ""))
        except (ValueError, AttributeError, RecursionError):
            return
        if ids != (self.plan.job_id, self.plan.run_id):
            return  # an earlier run's ramp; this run's is on its way
        self.profile_recorded = True
        self.record("profile_config", t_ns, self.profile_raw)

    def statuses(self, raw: bytes, gid: bytes, names: list[str], t_ns: int) -> None:
        """Statuses on /diagnostics (their names): those of one node of this
        cell, sent by that node, are recorded (another cell's are its own
        bag's, a stranger's none; this node records its own as it publishes
        them)."""
        if self.recorder is None:
            return
        own = self.node.get_fully_qualified_name().lstrip("/") + ":"
        if all(n.startswith(own) for n in names):
            return
        ours = [n for n in names if in_namespace(n, self.node.get_namespace())]
        if not ours:
            return
        # one node's statuses, sent by that node (a stranger's status named like ours is not)
        node = ours[0].split(":", 1)[0].rsplit("/", 1)[-1]
        if all(n.split(":", 1)[0].rsplit("/", 1)[-1] == node for n in ours):
            # held while the graph does not name its sender yet (a node's first status can
            # come before its discovery info), recorded at the time it came
            self.peers.deliver_from(
                TOPIC_DIAGNOSTICS, gid, raw, lambda r: self.record("diagnostics", t_ns, r), [node]
            )
