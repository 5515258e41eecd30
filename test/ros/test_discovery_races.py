"""Discovery races made deterministic (issue 40, "no discovery race left in
the product"): a node held up (SIGSTOP, then SIGCONT) so that what it sends
comes late, and a publisher that the graph names only after its first
message. Each place that acts on what it hears waits for the sender to be
named, or for the match it needs, never for a fixed time. Real processes
over DDS, or a real rclpy node whose graph look-ups are held back.
"""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import Procs, closed_bags, rosbags_read, spin_until
from support import wait
from support.cell import timed_rows
from support.ros_probe import ready_states, start_job

from winder.record.reader import read_run

pytestmark = pytest.mark.ros

#: one 8-turn layer: 4096 fork steps, 2.4 s of real time at full speed
JOB = {"turns_per_layer": 8, "layers": 1, "poles": 1, "fork_steps_per_rev": 512, "autostart": False}
#: the profile node's look-ahead in these runs (its default), s
LOOKAHEAD = 0.05


def test_a_consumer_that_takes_the_run_late_still_gets_its_look_ahead(
    tmp_path: Path, procs: Procs, ros: Any
) -> None:
    """The sim node (real time) is held up (SIGSTOP) as the run starts, so
    its winder/sim_config of the run reaches the profile node seconds after
    the job description. The profile node waits for it (it said so), not a
    fixed 1 s after which the steps went out without look-ahead: every step
    chunk reached the sim node at most the look-ahead (and a margin) ahead
    of its clock, and the run is done."""
    bags = tmp_path / "bags"
    ready = ready_states(ros)
    sim = procs.start("sim_node", "-p", f"bag_dir:={bags}", "-p", "real_time:=true")
    profile = procs.start("profile_node", "-p", f"lookahead:={LOOKAHEAD}")
    procs.start("interp_node", *[a for k, v in JOB.items() for a in ("-p", f"{k}:={str(v).lower()}")])
    # a first run: the interp node then knows the cell (it heard both roles ready), and the
    # sim node's "ready" after it is at most a second old when the second run is asked for
    reply = start_job(ros)
    assert reply.success, reply.message
    wait.until(lambda: closed_bags(bags), 120, f"the first run's bag in {bags}")
    spin_until(
        ros, lambda: ready.get("consumer") == "ready", 30, "the sim node ready again", heard=lambda: ready
    )
    os.kill(sim.pid, signal.SIGSTOP)
    try:
        reply = start_job(ros)
        assert reply.success, reply.message
        # the profile node has the job and waits: it says so after MODE_SAY (1 s), where the
        # fixed wait it had sent the steps without look-ahead after 1 s
        wait.until(
            lambda: any(said in procs.log(profile) for said in ("steps wait for", "without look-ahead")),
            30,
            "the profile node's word on the held-up consumer's sim_config",
            heard=lambda: procs.log(profile)[-1500:],
        )
    finally:
        os.kill(sim.pid, signal.SIGCONT)
    _first, bag = wait.until(
        lambda: (lambda b: b if len(b) == 2 else None)(closed_bags(bags)),
        120,
        f"the second run's bag in {bags}",
    )
    log = procs.log(profile)
    assert "without look-ahead" not in log, log
    run = read_run(bag)
    assert run.complete and run.report["state"] == "done", run.report
    raw = rosbags_read(bag)
    wall0 = int(json.loads(raw["/winder/sim_config"][0][1].data)["wall_start_ns"])
    # each chunk as it reached the sim node: its first step's time against the run time of its arrival
    leads = [int(np.asarray(m.data, np.int64)[0]) - (t - wall0) for t, m in raw["/winder/step_times"]]
    assert max(leads) < 0.5e9, sorted(leads)[-5:]  # without look-ahead the last chunks came ~2 s early
    assert timed_rows(raw).shape[0] == 4096


# -- a sender the graph names late, a receiver that does not run for a while ----------------------


@pytest.fixture
def rclpy_default(procs: Procs) -> Any:
    """rclpy's default context on the test's domain (the live view and the
    cell watch make their nodes there), shut down after the test."""
    import rclpy

    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    rclpy.init(args=[], domain_id=procs.domain)
    try:
        yield rclpy
    finally:
        rclpy.try_shutdown()


class HiddenGraph:
    """A node's graph look-ups of publishers, with the endpoints of the nodes
    in ``hidden`` left out until :meth:`show`: as this node's graph is
    before a participant's discovery info comes (its data may come first)."""

    def __init__(self, node: Any, hidden: set[str]) -> None:
        self.hidden = hidden
        real = node.get_publishers_info_by_topic

        def look(topic: str, *args: Any, **kwargs: Any) -> Any:
            return [i for i in real(topic, *args, **kwargs) if i.node_name not in self.hidden]

        node.get_publishers_info_by_topic = look

    def show(self) -> None:
        self.hidden = set()


def fake_cell(rclpy: Any, namespace: str) -> tuple[list[Any], Any]:
    """An interp node's endpoints in ``namespace`` (so a cell plays a part
    there), and a node ``sim_node`` in the consumer's part publishing
    /diagnostics (a status is taken from the node in a part only); (the two
    nodes, sim_node's /diagnostics publisher)."""
    from diagnostic_msgs.msg import DiagnosticArray, KeyValue
    from std_msgs.msg import Int32MultiArray, Int64MultiArray

    from winder.ros.qos import QOS_DIAGNOSTICS, QOS_LATCHED, QOS_STATE, QOS_STREAM
    from winder_interfaces.msg import JobDescription

    interp = rclpy.create_node("interp_node", namespace=namespace)
    interp.create_publisher(JobDescription, "winder/job", QOS_LATCHED)
    interp.create_publisher(Int32MultiArray, "winder/steps", QOS_STREAM)
    sim = rclpy.create_node("sim_node", namespace=namespace)
    sim.create_subscription(Int64MultiArray, "winder/step_times", lambda _m: None, QOS_STREAM)
    sim.create_publisher(KeyValue, "winder/progress", QOS_STATE)
    return [interp, sim], sim.create_publisher(DiagnosticArray, "/diagnostics", QOS_DIAGNOSTICS)


def status(name: str, level: int = 0, message: str = "idle") -> Any:
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

    return DiagnosticArray(status=[DiagnosticStatus(name=name, level=bytes([level]), message=message)])


def spin_executor(executor: Any, cond: Any, timeout: float, what: str, heard: Any = None) -> Any:
    """Spin ``executor`` until ``cond()`` (:func:`support.wait.until`, one round a look)."""
    return wait.until(lambda: (executor.spin_once(timeout_sec=0.01), cond())[1], timeout, what, heard=heard)


def matched_both(pub: Any, node: Any, topic: str, timeout: float = 10.0) -> None:
    """Until ``pub`` has a matched reader and ``node``'s subscription on ``topic`` a matched writer."""
    [sub] = [s for s in node.subscriptions if s.topic_name == topic]
    wait.until(
        lambda: pub.get_subscription_count() > 0 and sub.get_publisher_count() > 0,
        timeout,
        f"{topic} matched both ways",
    )


def test_the_view_holds_a_status_heard_before_the_graph_names_its_sender(rclpy_default: Any) -> None:
    """A cell plays a part in /c1; its sim node's first /diagnostics array
    reaches the live view before the view's graph names the publisher. The
    view holds it (it was refused as unnamed, and dropped) and shows it once
    the graph names sim_node."""
    from winder.record.foxglove import Channels
    from winder.ros.view import LiveView

    channels = Channels()
    view = LiveView(channels, "/c1")
    nodes, pub = fake_cell(rclpy_default, "/c1")
    try:
        view.attach()
        assert view.node is not None and view.peers is not None and view.executor is not None
        spin_executor(view.executor, lambda: not view._no_cell(), 10, "the fake cell in /c1 seen by the view")
        graph = HiddenGraph(view.node, {"sim_node"})
        matched_both(pub, view.node, "/diagnostics")
        pub.publish(status("c1/sim_node: job"))
        peers = view.peers
        spin_executor(
            view.executor,
            lambda: peers.held.get("/diagnostics") or peers.unnamed or channels.counts["/diagnostics"],
            10,
            "the view's verdict on sim_node's status",
        )
        assert channels.counts["/diagnostics"] == 0  # not shown while its sender is not named
        graph.show()
        spin_executor(
            view.executor,
            lambda: channels.counts["/diagnostics"],
            5,
            "sim_node's status shown once the graph names it",
            heard=lambda: (peers.unnamed, peers.intruders.summary()),
        )
        assert peers.unnamed == 0 and not peers.intruders.total
    finally:
        view.close()
        for n in nodes:
            n.destroy_node()


def test_winder_run_holds_a_status_heard_before_the_graph_names_its_sender(rclpy_default: Any) -> None:
    """``winder run``'s watch of the cell (CellWatch) hears sim_node's one-shot
    stream ERROR before its graph names the publisher: it holds it and takes
    it once named (it was refused as unnamed, and the run's summary lacked it)."""
    from winder.ros.cell import CellWatch
    from winder.ros.sender import SenderExecutor

    node = rclpy_default.create_node("winder_cell", namespace="/c1")
    executor = SenderExecutor()
    executor.add_node(node)
    watch = CellWatch(node, "/c1")
    nodes, pub = fake_cell(rclpy_default, "/c1")
    try:
        graph = HiddenGraph(node, {"sim_node"})
        matched_both(pub, node, "/diagnostics")
        pub.publish(status("c1/sim_node: stream", 2, "segment 3: a gap"))
        spin_executor(
            executor,
            lambda: watch.peers.held.get("/diagnostics") or watch.peers.unnamed or watch.errors,
            10,
            "the watch's verdict on sim_node's status",
        )
        assert not watch.errors
        graph.show()
        spin_executor(executor, lambda: watch.errors, 5, "sim_node's ERROR taken once the graph names it")
        assert watch.errors == ["c1/sim_node: stream: segment 3: a gap"], watch.errors
    finally:
        executor.shutdown()
        node.destroy_node()
        for n in nodes:
            n.destroy_node()


def test_a_second_node_of_a_role_leaves_on_a_status_heard_before_its_sender_is_named(
    rclpy_default: Any,
) -> None:
    """A profile node (Solo) hears the status of an earlier profile node of
    its namespace before its graph names that status' publisher: it holds
    the status and leaves once the graph names the sender (it skipped it,
    and took the cell's runs until the next status a second later)."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    from winder.ros.peers import Peers, Solo
    from winder.ros.qos import QOS_DIAGNOSTICS
    from winder.ros.sender import SenderExecutor

    node = rclpy_default.create_node("profile_b", namespace="/c3")
    executor = SenderExecutor()
    executor.add_node(node)
    left: list[str] = []
    solo = Solo(node, "profile", Peers(node), left.append)
    earlier = rclpy_default.create_node("profile_node", namespace="/c3")
    pub = earlier.create_publisher(DiagnosticArray, "/diagnostics", QOS_DIAGNOSTICS)
    try:
        graph = HiddenGraph(node, {"profile_node"})
        matched_both(pub, node, "/diagnostics")
        values = {"role": "profile", "pid": "1", "host": "elsewhere", "started_ns": "1"}
        st = DiagnosticStatus(name="c3/profile_node: job", message="idle")
        st.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        pub.publish(DiagnosticArray(status=[st]))
        spin_executor(
            executor,
            lambda: solo.peers.held.get("/diagnostics") or left,
            10,
            "the profile node's verdict on the earlier node's status",
        )
        assert not left  # its sender is not named yet: not acted on
        graph.show()
        spin_executor(executor, lambda: left, 5, "the later node leaving once the graph names the earlier")
        assert "/c3/profile_node (pid 1 on elsewhere)" in left[0], left
    finally:
        executor.shutdown()
        node.destroy_node()
        earlier.destroy_node()


def test_a_held_message_outlasts_a_stretch_in_which_its_node_did_not_run(procs: Procs, ros: Any) -> None:
    """A message held for the graph to show its sender's part (the live
    view's patient verdict) while the node does not run at all for longer
    than the hold (its process held up): the hold counts the node's own
    time, so the message is judged, and acted on, once the graph shows the
    part, not refused at the first look after the node woke up."""
    import time

    from diagnostic_msgs.msg import KeyValue
    from std_msgs.msg import Int64MultiArray

    from winder.ros.peers import HOLD, Peers
    from winder.ros.qos import QOS_LATCHED, QOS_STATE, QOS_STREAM
    from winder_interfaces.msg import CellState

    peers = Peers(ros, "/", patient=True)
    sim = rclpy_node(ros, "sim_node")
    sim.create_publisher(CellState, "/winder/state", QOS_LATCHED)
    [gid] = wait.until(
        lambda: [bytes(i.endpoint_gid) for i in ros.get_publishers_info_by_topic("/winder/state")],
        10,
        "sim_node's winder/state publisher on the graph",
    )
    acted: list[bytes] = []
    peers.deliver("winder/state", gid, b"state", acted.append, "consumer")
    assert peers.held.get("winder/state") and not acted  # named, but not the consumer yet
    time.sleep(HOLD + 0.5)  # the stimulus: the node does not run (no executor turns), longer than the hold
    ticks: list[float] = []
    timer = ros.create_timer(0.05, lambda: ticks.append(time.monotonic()))
    spin_until(ros, lambda: len(ticks) >= 2, 10, "two turns of the executor after the stretch")
    ros.destroy_timer(timer)
    assert peers.unnamed == 0, "refused at the first look after the node ran again"
    # the sender now shows as the cell's step consumer (it publishes winder/progress, reads step times)
    sim.create_publisher(KeyValue, "/winder/progress", QOS_STATE)
    sim.create_subscription(Int64MultiArray, "/winder/step_times", lambda _m: None, QOS_STREAM)
    spin_until(ros, lambda: acted, 5, "the held message acted on", heard=lambda: (peers.unnamed, peers.held))
    assert acted == [b"state"] and peers.unnamed == 0


def rclpy_node(ros: Any, name: str, namespace: str = "/") -> Any:
    """Another node in the probe's context."""
    import rclpy

    return rclpy.create_node(name, namespace=namespace, context=ros.context)


def test_a_clock_reader_matched_after_the_last_sample_still_hears_the_clock(
    tmp_path: Path, procs: Procs, ros: Any
) -> None:
    """A real-time sim node that has run every step it was sent waits with
    its clock standing still; the profile node sends more only as that clock
    comes within its look-ahead. A /clock reader that matched the sim node's
    writer after its last sample (the profile node's, made when the run's
    sim_config came: late under load) heard nothing and the run stood still
    for good ("step stream stalled ... at 2/2048 steps" in a loaded run of
    test_bag_on_signals). Here the reader is made only once the steps sent
    are executed: it hears the clock where it stands."""
    from rosgraph_msgs.msg import Clock
    from support.cell import FakeProfile

    from winder.motion.job import Job
    from winder.ros.qos import QOS_CLOCK

    job = Job(job_id="still", turns_per_layer=2, layers=1, poles=1, fork_steps_per_rev=256)
    bags = tmp_path / "bags"
    procs.start("sim_node", "-p", f"bag_dir:={bags}", "-p", "real_time:=true", "-p", "stall_timeout:=60.0")
    fake = FakeProfile(ros, job)
    first = fake.chunks(10)[0]  # ten steps, 1 ms apart: the rest never comes
    fake.send([first])

    def executed() -> int:
        done = [int(v.get("steps_done", 0)) for _, _, v in fake.statuses if v.get("run_id") is not None]
        return max(done, default=0)

    wait.spin_until(ros, lambda: executed() >= 10, 30, "the sim node's status with 10 steps done",
                    heard=lambda: fake.statuses[-3:])  # fmt: skip
    heard: list[Clock] = []
    ros.create_subscription(Clock, "/clock", heard.append, QOS_CLOCK)  # matched only now
    wait.spin_until(ros, lambda: heard, 10, "a /clock message on a reader matched after the last sample")
    t_ns = heard[-1].clock.sec * 1_000_000_000 + heard[-1].clock.nanosec
    assert t_ns >= int(first[-1, 0]), (
        t_ns,
        int(first[-1, 0]),
    )  # where it stands: at the last step or past it


class PartHidden:
    """A node's graph look-ups of publishers with those on ``topic`` left out
    until :meth:`show`: as this node's graph is before the discovery of one
    endpoint of a node whose others it knows (the graph learns a node's
    endpoints one by one)."""

    def __init__(self, node: Any, topic: str) -> None:
        self.hidden: str | None = topic
        real = node.get_publishers_info_by_topic

        def look(name: str, *args: Any, **kwargs: Any) -> Any:
            return [] if name == self.hidden else real(name, *args, **kwargs)

        node.get_publishers_info_by_topic = look

    def show(self) -> None:
        self.hidden = None


def test_a_nodes_message_heard_before_the_graph_shows_its_part_is_held_not_blamed(
    rclpy_default: Any,
) -> None:
    """The interp node's readiness (:class:`Readiness`) hears the profile
    node's latched word on winder/ready while its graph names the sender
    but does not show its winder/path publisher yet, so not its part. It
    holds the word and takes it once the part shows; the cell's own profile
    node is never counted as foreign (it was refused, warned about, named
    in the interp node's statuses and so in ``winder run``'s summary as
    "ignored, foreign", and its word was lost till it was said again)."""
    from diagnostic_msgs.msg import KeyValue
    from std_msgs.msg import Int64MultiArray
    from trajectory_msgs.msg import JointTrajectory

    from winder.contract.topics import TOPIC_READY
    from winder.ros.peers import Peers
    from winder.ros.qos import QOS_EVENTS, QOS_LATCHED, QOS_STREAM
    from winder.ros.ready import Readiness
    from winder.ros.sender import SenderExecutor
    from winder_interfaces.msg import ControlEvent

    node = rclpy_default.create_node("interp_node", namespace="/c5")
    executor = SenderExecutor()
    executor.add_node(node)
    peers = Peers(node)
    readiness = Readiness(node, peers=peers)
    graph = PartHidden(node, "/c5/winder/path")
    profile = rclpy_default.create_node("profile_node", namespace="/c5")
    profile.create_publisher(Int64MultiArray, "winder/step_times", QOS_STREAM)
    profile.create_publisher(ControlEvent, "winder/control", QOS_EVENTS)
    profile.create_publisher(JointTrajectory, "winder/path", QOS_LATCHED)
    ready = profile.create_publisher(KeyValue, "winder/ready", QOS_LATCHED)
    try:
        matched_both(ready, node, "/c5/winder/ready")
        wait.until(  # every other endpoint of the part named: only winder/path is not shown yet
            lambda: all(
                any(i.node_name == "profile_node" for i in node.get_publishers_info_by_topic(t))
                for t in ("/c5/winder/ready", "/c5/winder/step_times", "/c5/winder/control")
            ),
            10,
            "the profile node's other endpoints named on the graph",
        )
        ready.publish(KeyValue(key="profile", value="waiting"))
        spin_executor(
            executor,
            lambda: peers.held.get(TOPIC_READY) or peers.intruders.total or readiness.states,
            10,
            "the interp side's verdict on the profile node's word",
        )
        assert not peers.intruders.total, peers.intruders.summary()
        assert "profile" not in readiness.states  # not acted on while its part does not show
        graph.show()
        spin_executor(
            executor,
            lambda: readiness.states.get("profile"),
            5,
            "the word taken once the graph shows the profile node's part",
            heard=lambda: (peers.unnamed, peers.intruders.summary()),
        )
        assert readiness.states == {"profile": "waiting"}
        assert peers.intruders.total == 0 and peers.unnamed == 0
    finally:
        executor.shutdown()
        node.destroy_node()
        profile.destroy_node()


def test_winder_runs_summary_never_lists_the_cells_own_nodes_as_foreign(
    rclpy_default: Any, tmp_path: Path
) -> None:
    """The cell's sim node says (``intruders`` in its status) that it refused
    the cell's own profile node (a discovery race: it heard it before its
    graph showed it in its part), a stranger, and a node named like the
    profile node in another process. ``winder run``'s summary (its
    ``ignored, foreign`` line) lists the stranger and the other process'
    node, never the cell's own nodes."""
    from diagnostic_msgs.msg import KeyValue

    from winder.ros.cell import CellWatch, _result
    from winder.ros.sender import SenderExecutor

    node = rclpy_default.create_node("winder_cell", namespace="/c1")
    executor = SenderExecutor()
    executor.add_node(node)
    watch = CellWatch(node, "/c1")
    watch.started = {"interp_node", "profile_node", "sim_node"}  # as run_cell sets it
    nodes, pub = fake_cell(rclpy_default, "/c1")
    said = (
        "/c1/intruder (2 on /c1/winder/control); /c1/profile_node (1 on /c1/winder/ready); "
        "/c1/profile_node (other process) (3 on /c1/winder/step_times)"
    )
    try:
        matched_both(pub, node, "/diagnostics")
        msg = status("c1/sim_node: job", message="running")
        msg.status[0].values = [KeyValue(key="intruders", value=said)]
        pub.publish(msg)
        spin_executor(executor, lambda: watch.foreign, 10, "the sim node's status taken by the watch")
        result = _result(watch, "", tmp_path)
        assert result.intruders == (
            "c1/sim_node: /c1/intruder (2 on /c1/winder/control); "
            "/c1/profile_node (other process) (3 on /c1/winder/step_times)"
        ), result.intruders
    finally:
        executor.shutdown()
        node.destroy_node()
        for n in nodes:
            n.destroy_node()


def test_a_sender_in_a_part_no_node_plays_is_refused_in_its_name_after_the_hold(
    rclpy_default: Any,
) -> None:
    """The other side of the hold above: a node publishing on winder/control
    in a namespace where no node plays the profile node's part (a forger)
    is held, and refused in its name once the hold ends (:data:`HOLD` s of
    the node's own time), never acted on."""
    from winder.contract.topics import TOPIC_CONTROL
    from winder.ros.peers import HOLD, Peers
    from winder.ros.qos import QOS_EVENTS
    from winder.ros.sender import SenderExecutor
    from winder_interfaces.msg import ControlEvent

    node = rclpy_default.create_node("interp_node", namespace="/c6")
    executor = SenderExecutor()
    executor.add_node(node)
    peers = Peers(node)
    acted: list[Any] = []
    peers.subscribe(ControlEvent, TOPIC_CONTROL, acted.append, QOS_EVENTS)
    forger = rclpy_default.create_node("forger", namespace="/c6")
    pub = forger.create_publisher(ControlEvent, "winder/control", QOS_EVENTS)
    try:
        matched_both(pub, node, "/c6/winder/control")
        wait.until(
            lambda: any(
                i.node_name == "forger" for i in node.get_publishers_info_by_topic("/c6/winder/control")
            ),
            10,
            "the forger named on the graph",
        )
        pub.publish(ControlEvent(event="abort", run_id="r", t_ns=1, t_rest_ns=2, steps=10))
        spin_executor(executor, lambda: peers.held.get(TOPIC_CONTROL), 10, "the forger's message held")
        spin_executor(
            executor,
            lambda: peers.intruders.total,
            HOLD + 10,
            "the forger refused once the hold ends",
            heard=lambda: (peers.unnamed, peers.held),
        )
        assert peers.intruders.summary() == "/c6/forger (1 on /c6/winder/control)"
        assert not acted and peers.unnamed == 0
    finally:
        executor.shutdown()
        node.destroy_node()
        forger.destroy_node()
