"""``winder resim``: a recorded job's step times through the sim node again,
with another motor model or other motor parameters.

The sim node itself does the work, as a process of its own on a private
domain, so a re-simulation is exactly what a live run with those settings
would have been: the same exact linear response (or nonlinear model), the
same stream checks, the same bag. This module is the sim node's upstream in
place of the interp and profile nodes: it publishes the recorded job
description (with a new run id and the recording it comes from), the path,
the ramp configuration and the operator events, then the recorded
``winder/step_times`` chunks as they were recorded, keeping at most
:data:`IN_FLIGHT` steps ahead of the sim node's receipts (``winder/progress``),
and waits for the sim node's final report.
"""

from __future__ import annotations

import json
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import rclpy
from diagnostic_msgs.msg import KeyValue
from rclpy.executors import ExternalShutdownException
from std_msgs.msg import Int32MultiArray, Int64MultiArray, String
from trajectory_msgs.msg import JointTrajectory

from winder.contract.events import ControlEvent
from winder.contract.qos import EVENTS, LATCHED, STATE, STREAM
from winder.contract.states import ReadyState
from winder.contract.stream import RESIM_TAG, make_run_id, with_source
from winder.contract.topics import (
    READY_STATES,
    TOPIC_CONTROL,
    TOPIC_JOB,
    TOPIC_PATH,
    TOPIC_PROFILE_CONFIG,
    TOPIC_PROGRESS,
    TOPIC_READY,
    TOPIC_STEP_TIMES,
    TOPIC_STEPS,
)
from winder.record.replay import PlayPlan
from winder.ros.cell import CellResult, CellWatch, NodeProcesses, _result, cell_environment, ros_args
from winder.ros.chunks import TIMED_CDR
from winder.ros.interfaces import control_event_msg, job_description_msg
from winder.ros.player import refuse_live_cell
from winder.ros.qos import profile
from winder.ros.sender import SenderExecutor
from winder_interfaces.msg import ControlEvent as ControlEventMsg
from winder_interfaces.msg import JobDescription

__all__ = ["IN_FLIGHT", "Recorded", "resimulate"]

#: steps sent to the sim node and not yet simulated, at most
IN_FLIGHT = 1 << 17


@dataclass
class Recorded:
    """What a re-simulation takes from the recording (raw CDR payloads)."""

    path: bytes | None
    profile_config: bytes | None
    #: the run's operator events as the bag reader gives them (winder.record.reader.Run.events)
    events: tuple[dict[str, Any], ...]
    plan: PlayPlan  #: streams the step chunks
    step_topic: str


def _string(text: str) -> String:
    return String(data=text)


def _chunks(rec: Recorded) -> Iterator[bytes]:
    for topic, _t, data in rec.plan.messages():
        if topic.recorded == rec.step_topic:
            yield data


def resimulate(
    rec: Recorded,
    job_text: str,
    source_bag: str,
    sim_params: dict[str, Any],
    *,
    namespace: str = "",
    domain: int | None = None,
    timeout: float = 3600.0,
    progress: Callable[[float, str], None] | None = None,
) -> tuple[str, CellResult]:
    """Run the sim node on the recorded stream; (the new run id, the result)."""
    old = json.loads(job_text)
    # named so that it reads as a re-simulation wherever its run id shows (the bag's name)
    run_id = make_run_id(f"{old['job']['job_id']}{RESIM_TAG}", 1)
    description = with_source(job_text, run_id, source_bag)
    log_dir = Path(tempfile.mkdtemp(prefix="winder-resim-"))
    with cell_environment(domain) as env:
        procs = NodeProcesses(env, log_dir)
        rclpy.init(args=[])
        node = rclpy.create_node("winder_resim", namespace=namespace or "/")
        executor = SenderExecutor()  # the watch takes /diagnostics with each sender
        executor.add_node(node)  # (node.executor is a weak reference: this one keeps it)
        failure = ""
        try:
            # before this node declares the interp and profile node's endpoints and a sim node
            # starts: a live cell here would take them for its own (and its sim node would leave)
            refuse_live_cell(
                node,
                namespace,
                "would take the re-simulation's messages for its own, and not let its sim node join",
                "re-simulate once that cell has stopped, or on another ROS_DOMAIN_ID",
            )
            watch = CellWatch(node, namespace)
            watch.run_id = run_id
            # this run's nodes: the sim node, and this one, which plays the interp and the profile node
            watch.started = {"sim_node", node.get_name()}
            done = [0]
            ready: dict[str, str] = {}

            def on_progress(msg: KeyValue) -> None:
                if msg.key == run_id and msg.value.isdigit():
                    done[0] = max(done[0], int(msg.value))

            def on_ready(msg: KeyValue) -> None:
                if msg.value in READY_STATES:
                    ready[msg.key] = msg.value

            node.create_subscription(KeyValue, TOPIC_PROGRESS, on_progress, profile(STATE))
            node.create_subscription(KeyValue, TOPIC_READY, on_ready, profile(LATCHED))
            pub_job = node.create_publisher(JobDescription, TOPIC_JOB, profile(LATCHED))
            pub_path = node.create_publisher(JointTrajectory, TOPIC_PATH, profile(LATCHED))
            pub_profile = node.create_publisher(String, TOPIC_PROFILE_CONFIG, profile(LATCHED))
            pub_control = node.create_publisher(ControlEventMsg, TOPIC_CONTROL, profile(EVENTS))
            pub_steps = node.create_publisher(Int64MultiArray, TOPIC_STEP_TIMES, profile(STREAM))
            # this node plays the interp and the profile node for the sim node, which
            # acts only on those parts' messages: it declares their endpoints
            # (winder.contract.trust.SIGNS) though it sends no untimed steps
            node.create_publisher(Int32MultiArray, TOPIC_STEPS, profile(STREAM))
            procs.start("sim_node", ros_args(sim_params, namespace))

            def connected() -> bool:
                # the sim node says ready once its readers have matched this node's writers; the
                # description and the steps go to volatile readers, which get only what is sent
                # after this side's writers have matched them in turn: waited for too
                return (
                    ready.get("consumer") == ReadyState.READY
                    and pub_job.get_subscription_count() > 0
                    and pub_steps.get_subscription_count() > 0
                )

            failure = _wait(
                node, procs, connected, 60.0, "sim node ready with its job and step readers matched"
            )
            if not failure:
                pub_job.publish(job_description_msg(description))
                if rec.path is not None:
                    pub_path.publish(_path_of(rec.path, run_id))
                if rec.profile_config is not None:
                    pub_profile.publish(_string(_relabelled(rec.profile_config, run_id)))
                for doc in rec.events:
                    pub_control.publish(control_event_msg(ControlEvent.from_doc(doc, run_id=run_id)))
                failure = _stream(node, procs, rec, pub_steps, done, timeout)
            if not failure:
                t_end = time.monotonic() + timeout
                while watch.summary is None and not failure:
                    spin_once(node, 0.1)
                    if progress is not None:
                        progress(watch.progress, watch.sim_time)
                    failure = procs.dead() or ("" if time.monotonic() < t_end else "no final report in time")
        except ExternalShutdownException:
            raise KeyboardInterrupt from None
        finally:
            procs.stop()
            node.destroy_node()
            rclpy.try_shutdown()
    return run_id, _result(watch, failure, log_dir)


def _path_of(raw: bytes, run_id: str) -> JointTrajectory:
    """The recorded path (JointTrajectory CDR) for the new run: its header names the run."""
    from rclpy.serialization import deserialize_message

    path = deserialize_message(raw, JointTrajectory)
    path.header.frame_id = run_id
    return path


def _relabelled(raw: bytes, run_id: str) -> str:
    """The recorded ramp configuration of the run (JSON in a String's CDR)
    for the new run: the same, with the new run id."""
    from rclpy.serialization import deserialize_message

    event = json.loads(deserialize_message(raw, String).data)
    event["run_id"] = run_id
    return json.dumps(event)


def spin_once(node: Any, timeout: float) -> None:
    """One round of the node's own executor (a :class:`SenderExecutor`)."""
    assert node.executor is not None
    node.executor.spin_once(timeout_sec=timeout)


def _wait(node: Any, procs: NodeProcesses, cond: Callable[[], bool], timeout: float, what: str) -> str:
    t_end = time.monotonic() + timeout
    while not cond():
        spin_once(node, 0.05)
        dead = procs.dead()
        if dead:
            return dead
        if time.monotonic() > t_end:
            return f"no {what} within {timeout:g} s"
    return ""


def _stream(node: Any, procs: NodeProcesses, rec: Recorded, pub: Any, done: list[int], timeout: float) -> str:
    """The recorded chunks, in order, at most IN_FLIGHT steps ahead of the receipts."""
    sent = 0
    for raw in _chunks(rec):
        try:
            n = TIMED_CDR.decode(raw).shape[0]
        except ValueError:
            n = 0  # a chunk the sim node will refuse (and report), as it did live
        room = lambda sent=sent: sent - done[0] <= IN_FLIGHT  # noqa: E731
        failure = _wait(node, procs, room, timeout, "receipt from the sim node")
        if failure:
            return failure
        pub.publish(raw)
        sent += n
    return ""
