"""bridge_node: the cell's timed steps -> ros2_control hardware, in real time.

A :class:`winder.ros.consumer.StepConsumer`: the base does everything the
cell asks of a consumer (handshake, stream checks, receipts, operator events,
programmed stops, stall watch, winder/state, the job status and final
report, the bag); this node paces the accepted steps out to a
``forward_command_controller/ForwardCommandController`` and watches the
measured joint states.

Out: ``<controller>/commands`` (std_msgs/Float64MultiArray, at ``rate`` Hz
during a run: each joint's commanded position in SI units, the step count of
the last row due times the joint's step length), ``clock`` (the cell's clock,
200 Hz at most, never backwards over the node's life), winder/sim_config
(``real_time: true``, ``clock_origin_ns``: the profile node sends steps only
its look-ahead ahead of that clock). In: ``joint_states``
(sensor_msgs/JointState from a joint_state_broadcaster; joints by name,
unknown names ignored), trusted only from the node ``broadcaster`` names
(by its publisher's GID, as the graph names it): another publisher's
messages are ignored, counted (``foreign_joint_states``) and warned about
once per node, so a neighbour can neither stop a run nor become its
origin; a position from the broadcaster that is not finite or beyond
±FAR_POSITION is a servo fault with its reason (between runs: the
hardware is not ready), never an origin. Both topics are relative: in the namespace of this
node, which must be the controller manager's (ros2_control puts a controller
``X`` of the controller manager in ``/ns`` at ``/ns/X``, so it listens on
``/ns/X/commands``, and the broadcaster publishes ``/ns/joint_states``). All
three are recorded into the run's bag.

Time: a run's time starts when the bridge arms it: every joint has been
measured since the run's start (with ``job_origin`` zero: within
``max_following_error`` of the job's start position), the controller
listens, and the run's first steps are here (until then the profile node
sends only its look-ahead); the cell's clock is then ``clock_origin_ns`` +
the steady time since. Nothing is commanded before, so a run never starts
with a jump. Steps that come after their time (a profile node starved of
CPU) go out at once and are counted (``late_steps`` in the job status).

Servo fault: a measured position further than ``max_following_error.<axis>``
from every position commanded over the ``command_delay`` before its stamp
(the time a command takes to show in the measurement), or no measured
position of a joint for ``joint_state_timeout`` s, stops the run at once:
no further command (the controller holds the last one), an ERROR status
naming the joint, the error and the limit, the profile node's ``~/abort``
called (so the interp node stops sending and is ready for a new start), and
the run closed incomplete with its bag.

Wire watch: with ``load_cell`` (a force_torque_sensor_broadcaster's
controller name) the bridge takes geometry_msgs/WrenchStamped on
``<load_cell>/wrench`` (relative, as the commands), trusted only from the
node ``load_cell`` names (as joint_states from ``broadcaster``), force.x
the wire's tension (N). While a run's time runs, each reading goes to
:class:`winder.tension.watch.WireWatch` with the flyer's measured speed
(the fork joint's velocity from joint_states, else its position's change
between messages) and where the run is (the segment executed at the
reading's time and the fork commanded then: coil, layer, turn); a break
(the tension below a tenth of the job's set tension while the flyer
turns) stops the run as a servo fault does, with a ``wire`` ERROR status.
The readings are counted against the job's tension bands and recorded.

Soft limits and homing: ``min_position.<axis>``/``max_position.<axis>``
bound what a run may command. Every command is one of the job's positions
from the run's origin, so the job's extent (its segments' corners) is
checked against them when the run is armed, before the first command: a job
that would leave them is refused (a servo fault naming the joint, the
position and the limit), nothing moves. With ``require_homing`` (as it is
set when each run starts: switched on between runs, it holds the next one) a
run is not taken (the consumer says ``waiting``: "not homed"; one taken
before it said so is refused before any command) until ``~/home`` has run:
it calls ``homing_service`` (the drive's or a homing controller's
std_srvs/Trigger) or, without one, references the axes where they stand; the
reference is lost with the broadcaster (no joint_states for a second). The
limits are the joints' positions after homing, as a CNC's are.
``max_velocity.<axis>``/``max_acceleration.<axis>`` bound how fast and how
hard (:mod:`winder.motion.limits`): the run's job, timed with the ramp its
profile node published on winder/profile_config, is checked when the run
is armed (refused before any command), and every step is watched as it
comes, ahead of its time by the look-ahead (a feed override, a ramp changed
mid-run): steps that would pass a limit over 20 ms are a servo fault before
they are due.

Threads: the hardware side runs in a thread of its own, on the steady clock:
during a run, a tick every 1/``rate`` s sends the command, and every 5 ms
the clock and takes the measured states that came (checks them, queues them
for the bag); between runs it only looks every 0.1 s whether joint states still come (the
hardware is there: ``ready``). The joint states are taken from a subscription
of a helper node that no executor waits on (``<node>_io``), so neither they
nor the commands wake the executor: rclpy's executor costs 0.1-0.5 ms of CPU
per wake-up with a consumer's dozens of entities, a 1 kHz timer or a 100 Hz
subscription in it alone would be over the budget (bench/bench_bridge.py).
The thread shares the pacer, the command history and the record queue with
the executor under one lock, and hands a fault to the executor through a
guard condition; the load cell's readings are taken and watched in the
thread too, with the joint states; everything else (the base's bookkeeping,
the bag, the fault's report) runs in the executor, woken by the step stream and every
0.25 s after the last pump while rows wait (``pump_period``).
"""

from __future__ import annotations

import bisect
import struct
import threading
import time
from collections import deque
from typing import Any

import numpy as np
import numpy.typing as npt
import rclpy
from geometry_msgs.msg import WrenchStamped
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.client import Client
from rclpy.node import Node
from rclpy.task import Future
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from winder.contract.cdr import (
    CommandPayload,
    JointStateReader,
    clock_payload,
    joint_state_names,
    trajectory_payload,
)
from winder.contract.pacing import CommandHistory, Pacer, following_error
from winder.contract.params import BRIDGE_SPECS, check_bridge
from winder.contract.stream import JobPlan
from winder.contract.topics import (
    TOPIC_CLOCK,
    TOPIC_PROFILE_CONFIG,
    TOPIC_STEP_TIMES,
    check_node_name,
    check_relative_name,
)
from winder.motion.axes import AXES, FORK, axis
from winder.motion.job import Segment
from winder.motion.limits import NO_LIMIT, LimitWatch, job_extent, job_limits, travel_past
from winder.ros.consumer import StepConsumer
from winder.ros.diagnostics import ERROR
from winder.ros.engine import Engine, RunPort
from winder.ros.graph import fully_qualified, publishers_by_gid
from winder.ros.qos import QOS_CLOCK, QOS_STATE
from winder.ros.sender import attributed
from winder.ros.sender import waiting as taken_with_sender
from winder.ros.spin import spin
from winder.ros.upstream import ProfileAbort
from winder.spec import SpecError
from winder.tension.watch import WireWatch
from winder_bridge import PARAMETERS

#: the measured joint states (joint_state_broadcaster's default topic, relative)
TOPIC_MEASURED = "joint_states"
#: the cell's clock goes out at this rate at most (the profile node measures
#: its look-ahead against it; 200 Hz is what the sim node publishes)
CLOCK_PERIOD_NS = 5_000_000
#: a measurement stamped further than this from this host's clock is compared
#: with the commands before it arrived (its stamp is on another clock)
STAMP_TRUST_NS = 1_000_000_000
#: a measured position beyond this (rad or m) is no position of a winding axis:
#: a broken encoder word or a driver's sentinel, never an origin
FAR_POSITION = 1e9
#: a joint_states publisher the graph does not name yet is looked up again after this long
GRAPH_LOOK_NS = 50_000_000
#: between runs, the thread looks this often whether joint states still come
IDLE_POLL = 0.1
#: the hardware counts as there (winder/ready) while joint_states came within this
HARDWARE_FRESH_NS = 1_000_000_000
#: a run waits this long (or joint_state_timeout if longer) for the joint
#: states and the controller before it is refused; nothing moves meanwhile
ARM_WAIT_NS = 2_000_000_000
#: rows held at most (accepted, not due): further chunks wait in the inbox
MAX_HELD = 1 << 16
#: interface trajectory: each trajectory holds the points of this many batches ahead
AHEAD_BATCHES = 4
#: the message type of the commands with interface trajectory
TRAJECTORY_TYPE = "trajectory_msgs/msg/JointTrajectory"
#: a force_torque_sensor_broadcaster's topic (``~/wrench``: relative to its node) and message type
WRENCH = "wrench"
WRENCH_TYPE = "geometry_msgs/msg/WrenchStamped"
#: load cell readings taken at most per look (its subscription keeps the last 100)
WRENCHES_PER_LOOK = 100
#: a run whose time ran this long without a reading of the load cell says so (once)
LOAD_CELL_SILENT_NS = 1_000_000_000
#: a gap between two readings longer than this counts no time outside a band (the cell was silent)
BAND_HOLD_MAX_S = 0.1
#: The bridge's own recorded topics (the commands topic follows ``controller`` and ``interface``).
BRIDGE_TOPICS = {
    "commands": ("forward_position_controller/commands", "std_msgs/msg/Float64MultiArray"),
    "joint_states": (TOPIC_MEASURED, "sensor_msgs/msg/JointState"),
    "clock": (TOPIC_CLOCK, "rosgraph_msgs/msg/Clock"),
    # the load cell's readings: <load_cell>/wrench (recorded only with a load_cell)
    "tension": (f"load_cell/{WRENCH}", WRENCH_TYPE),
}
# Commands and measured states: reliable, volatile, keep-last 100 (QOS_STATE),
# which matches ros2_control's SystemDefaultsQoS (reliable) on both topics.
# The load cell's wrench: the same (force_torque_sensor_broadcaster publishes
# ``~/wrench`` with SystemDefaultsQoS too).


def check_load_cell(values: dict[str, Any], namespace: str) -> None:
    """``load_cell`` as ROS takes it in the bridge's ``namespace``: its topic
    ``<load_cell>/wrench`` and its node's names within the length ROS allows
    (the table's pattern checks its form). SpecError, one line, otherwise."""
    name = values.get("load_cell", "")
    if not name:
        return
    try:
        check_relative_name("load_cell", name, namespace, (f"/{WRENCH}",))
        check_node_name(name, namespace, "load_cell")
    except ValueError as exc:
        raise SpecError(str(exc)) from None


def wrench_force_x(raw: bytes) -> tuple[int, float] | None:
    """(stamp ns, force.x) of a little-endian CDR geometry_msgs/WrenchStamped
    payload, or None if it is not one."""
    if len(raw) < 16 or raw[1] != 1:
        return None
    sec, nsec, flen = struct.unpack_from("<iII", raw, 4)
    off = 12 + flen  # the body's offset past the frame id
    off += -off % 8  # force.x, a float64
    if 4 + off + 48 > len(raw):
        return None
    (fx,) = struct.unpack_from("<d", raw, 4 + off)
    return sec * 1_000_000_000 + nsec, float(fx)


class VelocityPick:
    """The measured velocity of one joint in sensor_msgs/JointState payloads
    (None: the message gives no velocity for it). The layout (names, counts)
    is parsed once and reused while the bytes before the positions and the
    velocity count stay the same, as they do from a joint_state_broadcaster."""

    def __init__(self, joint: str) -> None:
        self.joint = joint
        self.prefix = b""  # bytes 12 (after the stamp) .. the position data of the known layout
        self.count_at = 0  # payload offset of the velocity count
        self.count = b""  # the velocity count's bytes
        self.at = -1  # payload offset of the joint's velocity (-1: none)

    def read(self, raw: bytes) -> float | None:
        known = (
            self.prefix
            and raw.startswith(self.prefix, 12)
            and raw.startswith(self.count, self.count_at)
            and (self.at < 0 or len(raw) >= self.at + 8)
        )
        if not known and not self.parse(raw):
            return None
        if self.at < 0:
            return None
        (v,) = struct.unpack_from("<d", raw, self.at)
        return float(v) if abs(v) < FAR_POSITION else None  # NaN or a sentinel: no velocity

    def parse(self, raw: bytes) -> bool:
        self.prefix, self.at = b"", -1
        if len(raw) < 12 or raw[1] != 1:
            return False
        body = memoryview(raw)[4:]
        try:
            names, off = joint_state_names(body)
            (npos,) = struct.unpack_from("<I", body, off)
            off += 4
            if npos:
                off += -off % 8
            pos_at = off
            off += 8 * npos
            (nvel,) = struct.unpack_from("<I", body, off)
        except struct.error:
            return False
        vel_at = off + 4 + (-(off + 4) % 8 if nvel else 0)
        if npos != len(names) or 4 + vel_at + 8 * nvel > len(raw):
            return False
        self.prefix = bytes(raw[12 : 4 + pos_at])
        self.count_at, self.count = 4 + off, bytes(raw[4 + off : 8 + off])
        if nvel == len(names) and self.joint in names:
            self.at = 4 + vel_at + 8 * names.index(self.joint)
        return True


class Senders:
    """The nodes that publish on one topic, by their publishers' GIDs as the
    graph names them, and the messages ignored per node (under the engine's
    lock)."""

    def __init__(self) -> None:
        self.names: dict[bytes, str] = {}  # publisher GID -> its node's full name
        self.ignored: dict[str, int] = {}  # messages ignored, by the publishing node
        self.look_ns = 0  # when the graph was last asked

    def who(self, io: Node, topic: str, gid: bytes, now: int) -> str | None:
        """The node that published with ``gid``; a publisher the graph does
        not name yet is asked for again (at most every GRAPH_LOOK_NS): None
        meanwhile."""
        who = self.names.get(gid)
        if who is None and now - self.look_ns >= GRAPH_LOOK_NS:
            self.look_ns = now
            for g, w in publishers_by_gid(io, topic).items():
                self.names[g] = fully_qualified(w.name, w.namespace)
            who = self.names.get(gid)
        return who

    def ignore(self, who: str) -> bool:
        """A message of ``who`` ignored: counted; True for its first."""
        self.ignored[who] = self.ignored.get(who, 0) + 1
        return self.ignored[who] == 1

    def summary(self) -> tuple[int, str]:
        """Messages ignored, and their nodes."""
        return sum(self.ignored.values()), ", ".join(sorted(n for n, c in self.ignored.items() if c))


class BridgeEngine(Engine):
    """The hardware side of the bridge (see the module doc)."""

    #: the base's pump only accounts for what the command thread executed
    #: (receipts, the run's transitions, the bag): 0.25 s after the last
    #: pump is soon enough, and while the step chunks come (the look-ahead
    #: the profile node keeps: every ~0.12 s at most) they pump alone
    pump_period = 0.25
    pump_from_last = True

    def attach(self, node: Node, run: RunPort) -> None:
        super().attach(node, run)
        values = self.run.values()
        # The hardware side: a helper node no executor spins holds the joint
        # states' subscription (taken by the command thread) and the commands'
        # and clock's publishers (used by it), so that none of them wakes or
        # weighs on the executor. Their names are resolved here, with this
        # node's namespace and remappings.
        self.io = rclpy.create_node(
            f"{self.node.get_name()}_io",
            namespace=self.node.get_namespace(),
            context=self.node.context,
            use_global_arguments=False,
            enable_rosout=False,
            start_parameter_services=False,
        )
        self.controller = ""
        self.pub_cmd = self.commands_publisher(values["controller"], values["interface"])
        self.pub_clock = self.io.create_publisher(Clock, self.node.resolve_topic_name(TOPIC_CLOCK), QOS_CLOCK)
        self.run.set_bag_topic(
            "joint_states", self.node.resolve_topic_name(TOPIC_MEASURED), BRIDGE_TOPICS["joint_states"][1]
        )
        # taken with each message's publisher GID: only the broadcaster's count
        self.sub_states = attributed(
            self.io, JointState, self.run.bag_topic("joint_states"), lambda _m, _g: None, QOS_STATE
        )
        self.state_senders = Senders()  # joint_states' publishers, and the messages ignored
        # the load cell's wrench (load_cell): its subscription, taken by the command thread too
        self.load_cell = ""
        self.sub_wrench: Any = None
        self.wrench_senders = Senders()
        self.hardware_bad = ""  # the broadcaster's last message between runs is no position
        self.idle_pos = np.full(len(values["joints"]), np.nan)  # the joints as last measured between runs
        self.homed = False  # ~/home ran, and the broadcaster was not lost since
        self.homing_clients: dict[str, Client] = {}
        # ~/home waits for the homing service: in a group of its own (with that client and the
        # wait's timer), so the wait never holds the node's other callbacks back (a coroutine
        # holds its group until it ends: a homing service that never answered wedged the node)
        self.homing_group = ReentrantCallbackGroup()
        self.homing_now = False  # a ~/home is under way
        self.node.create_service(Trigger, "~/home", self.on_home, callback_group=self.homing_group)
        self.guard = self.node.create_guard_condition(self.on_alarm)
        self.reader = JointStateReader(values["joints"])
        self.upstream = ProfileAbort(self.node, self.run.peers)  # the profile node told to abort at a fault
        # shared with the command thread, under self.lock
        self.lock = threading.Lock()
        self.running = False  # a run is on: the thread ticks
        self.armed = False  # its time runs: the thread commands
        self.faulted = False
        self.pacer: Pacer | None = None
        self.outbox: deque[tuple[str, int, bytes, bool]] = deque()  # (bag key, run time, payload, exact)
        self.heard_ns = 0  # monotonic time of the last joint_states message
        self.clock_ns = -1  # the last clock published in this node's life
        self.alarm: tuple[str, dict[str, object], str] | None = None  # a fault for the executor
        self.go = threading.Event()  # set while a run is on
        self.quit = False
        self.missing_said = ""
        self.new_run(values)
        self.wrench_subscription(values["load_cell"])
        self.thread = threading.Thread(target=self.command_loop, name="bridge-commands", daemon=True)
        self.thread.start()

    def commands_publisher(self, controller: str, interface: str = "forward") -> Any:
        """The publisher of ``<controller>/commands`` (interface forward) or
        ``<controller>/joint_trajectory`` (trajectory): a new one if the
        controller or the interface changed."""
        if (controller, interface) == (self.controller, getattr(self, "interface_in_use", "forward")):
            return self.pub_cmd
        if self.controller:
            self.io.destroy_publisher(self.pub_cmd)
        self.controller, self.interface_in_use = controller, interface
        if interface == "trajectory":
            topic = self.node.resolve_topic_name(f"{controller}/joint_trajectory")
            self.run.set_bag_topic("commands", topic, TRAJECTORY_TYPE)
            return self.io.create_publisher(JointTrajectory, topic, QOS_STATE)
        topic = self.node.resolve_topic_name(f"{controller}/commands")
        self.run.set_bag_topic("commands", topic, BRIDGE_TOPICS["commands"][1])
        return self.io.create_publisher(Float64MultiArray, topic, QOS_STATE)

    def wrench_subscription(self, load_cell: str) -> None:
        """The subscription of ``<load_cell>/wrench`` (none without a load
        cell): a new one if the load cell changed; swapped under the lock
        (the command thread takes it)."""
        if load_cell == self.load_cell:
            return
        sub = None
        if load_cell:
            topic = self.node.resolve_topic_name(f"{load_cell}/{WRENCH}")
            self.run.set_bag_topic("tension", topic, WRENCH_TYPE)
            sub = attributed(self.io, WrenchStamped, topic, lambda _m, _g: None, QOS_STATE)
        with self.lock:
            old, self.sub_wrench, self.load_cell = self.sub_wrench, sub, load_cell
            self.wrench_senders = Senders()
        if old is not None:
            self.io.destroy_subscription(old)

    def new_run(self, values: dict[str, Any]) -> None:
        """A run's settings and state before it starts (also: the node's, before any run)."""
        self.rate = float(values["rate"])
        self.point_ns = round(1e9 / self.rate)  # a commanded position every point_ns of run time
        self.trajectory = values.get("interface", "forward") == "trajectory"
        # the thread's tick: a command (forward), or a trajectory of the next two batches
        self.period_ns = round(values["batch"] * 1e9) if self.trajectory else self.point_ns
        # the points sent and not passed yet: their run times and positions
        self.point_t = np.empty(0, np.int64)
        self.point_pos = np.empty((0, len(values["joints"])))
        self.frontier = 0  # run time of the last point sent (trajectory)
        self.wall_t0 = 0  # system clock time of run time 0 (the trajectories' stamps)
        self.timeout_ns = round(values["joint_state_timeout"] * 1e9)
        self.delay_ns = round(values["command_delay"] * 1e9)
        self.origin_here = values["job_origin"] == "start_position"
        self.settle_ns = round(values["settle_time"] * 1e9)
        self.joints: list[str] = list(values["joints"])
        self.axes: list[str] = list(values["axes"])
        self.limits = np.array([values[f"max_following_error.{a}"] for a in self.axes])
        self.pos_lo = np.array([values[f"min_position.{a}"] for a in self.axes])
        self.pos_hi = np.array([values[f"max_position.{a}"] for a in self.axes])
        self.v_max = np.array([values[f"max_velocity.{a}"] for a in self.axes])
        self.a_max = np.array([values[f"max_acceleration.{a}"] for a in self.axes])
        self.limit_values = {
            k: values[k] for a in self.axes for k in (f"max_velocity.{a}", f"max_acceleration.{a}")
        }
        self.limit_watch: LimitWatch | None = None  # the run's steps against max_velocity/max_acceleration
        self.ramp_breach = ""  # the run's job, timed with its ramp, passes a limit (refused at arming)
        self.ramp_checked = False
        self.ramp_said = False
        self.early_breach = ""  # steps past a limit came before the run was armed
        #: the job's extent in each joint's step counts (its corners' least and greatest)
        self.extent = (np.zeros(len(self.axes), np.int64), np.zeros(len(self.axes), np.int64))
        self.units = [BRIDGE_SPECS[f"max_following_error.{a}"].unit for a in self.axes]
        broadcaster = check_node_name(values["broadcaster"], self.node.get_namespace(), "broadcaster")
        self.broadcaster = broadcaster
        if self.reader.joints != self.joints:
            self.reader = JointStateReader(self.joints)
        self.cmd = CommandPayload(len(self.joints))
        self.payload = self.cmd.bytes()  # the command in force
        self.history = CommandHistory(np.zeros(len(self.joints)))
        self.last_seen = np.zeros(len(self.joints), np.int64)  # monotonic ns of each joint's last measurement
        self.measured = np.full(len(self.joints), np.nan)  # and its position
        self.origin_ns = 0
        self.begin_ns = time.monotonic_ns()
        self.t0_ns = 0  # monotonic time of the run's start (armed)
        self.t_tick = 0  # run time of the last command
        self.next_clock = 0  # run time from which the next clock goes out
        self.settle_until: int | None = None
        self.fault_text = ""
        self.max_error = np.zeros(len(self.joints))
        self.ticks = 0
        self.max_gap_ns = 0
        self.states_in_run = 0
        self.bad_states = 0
        self.why_not_armed = "no joint_states yet"
        self.late_rows = 0
        self.max_late_ns = 0
        self.fault_task = ""  # the fault's status task: servo, or wire
        # the load cell (load_cell): its node, the run's watch and what its readings showed
        self.fork_j = self.axes.index(FORK.name) if FORK.name in self.axes else -1
        self.velocity = VelocityPick(self.joints[self.fork_j]) if self.fork_j >= 0 else None
        cell = str(values.get("load_cell", ""))
        self.load_cell_fq = check_node_name(cell, self.node.get_namespace(), "load_cell") if cell else ""
        self.watch: WireWatch | None = None  # set when a run with a load cell begins
        self.segments: tuple[Segment, ...] = ()
        self.seg_t: list[int] = []  # run time of the first row of each segment executed, in order
        self.seg_id: list[int] = []  # and that segment
        self.fork_speed = float("nan")  # the flyer's measured speed (rad/s): NaN until measured
        self.fork_last: tuple[int, float] | None = None  # the fork's last measured (stamp, position)
        self.bands = [(0.0, 0.0), (0.0, 0.0)]  # the warning and alarm bands (N)
        self.outside = [0.0, 0.0]  # s of the run with the tension outside each band
        self.tension_last: tuple[float, float] | None = None  # the last reading watched: (t s, N)
        self.tension_peak = -float("inf")
        self.tension_min = float("inf")
        self.wrenches_in_run = 0  # readings of the load cell taken during the run
        self.bad_wrenches = 0
        self.silence_said = False

    # -- the consumer's hooks ---------------------------------------------------
    def begin(self, plan: JobPlan, values: dict[str, Any]) -> dict[str, object]:
        self.stop_pacing()
        self.pub_cmd = self.commands_publisher(values["controller"], values["interface"])
        self.wrench_subscription(values["load_cell"])
        which = [AXES.index(a) for a in values["axes"]]
        start = np.array([plan.segments[0].start[i] if plan.segments else 0 for i in which], np.int64)
        step_len = np.array([plan.joint_step[i] for i in which])
        pacer = Pacer([2 + i for i in which], start, step_len)
        lo, hi = job_extent(plan.segments)
        with self.lock:
            self.new_run(values)
            self.extent = (lo[which], hi[which])
            self.pacer = pacer
            self.limit_watch = LimitWatch([2 + i for i in which], start, step_len, self.v_max, self.a_max)
            self.history = CommandHistory(pacer.position.copy())
            self.outbox.clear()
            self.alarm = None
            self.faulted = False
            # the run starts on the cell's clock a clock period after the last one published
            self.origin_ns = 0 if self.clock_ns < 0 else self.clock_ns + CLOCK_PERIOD_NS
            if self.sub_wrench is not None:
                self.watch_wire(plan)
            self.running = True
            unhomed = self.unhomed(values)
            if unhomed:  # the run's own settings: require_homing set since the last run counts
                self.raise_fault(f"servo fault: the run cannot start: {unhomed}; nothing was commanded", {})
        self.go.set()
        self.upstream.find()  # the run's profile node
        self.check_ramp()
        return {
            "real_time": True,
            "clock_origin_ns": self.origin_ns,
            "rate": self.rate,
            "interface": "trajectory" if self.trajectory else "forward",
            **(
                {"batch": self.period_ns / 1e9, "lookahead_min_s": (AHEAD_BATCHES + 2) * self.period_ns / 1e9}
                if self.trajectory
                else {}
            ),
            "controller_topic": self.run.bag_topic("commands"),
            "joint_states_topic": self.run.bag_topic("joint_states"),
            **({"load_cell_topic": self.run.bag_topic("tension")} if self.load_cell else {}),
            "joints": dict(zip(self.joints, self.axes, strict=True)),  # joint -> the cell axis it drives
            "job_origin": "start_position" if self.origin_here else "zero",
            "max_following_error": dict(zip(self.joints, self.limits.tolist(), strict=True)),
            "command_delay": self.delay_ns / 1e9,
            "joint_state_timeout": self.timeout_ns / 1e9,
            "settle_time": self.settle_ns / 1e9,
        }

    def watch_wire(self, plan: JobPlan) -> None:
        """(Under the lock, as a run with a load cell begins.) The run's wire
        watch, from its job's set tension and bands; readings that came
        between runs are dropped (they are no part of it)."""
        job = plan.job
        set_n = job.set_tension
        self.watch = WireWatch(set_n, job.tension_slip_tolerance)
        self.segments = plan.segments
        self.bands = [
            (set_n * (1 - share), set_n * (1 + share)) for share in (job.tension_warning, job.tension_alarm)
        ]
        for _ in taken_with_sender(self.sub_wrench, 1 << 12):
            pass

    def profile_config_heard(self) -> None:
        self.check_ramp()

    def check_ramp(self) -> None:
        """The run's job, timed with the ramp its profile node planned it with
        (winder/profile_config), against max_velocity/max_acceleration: a job
        that passes one is refused when the run is armed, before any command
        (after that, at once). Without the ramp the steps are still watched
        as they come (execute)."""
        if self.run.plan is None or self.ramp_checked or not self.watching_limits():
            return
        try:
            ramp = self.run.run_ramp()
            if ramp is None:
                return  # none yet, or an earlier run's: this run's is on its way
            _, why = job_limits(
                self.run.plan.job,
                ramp,
                self.limit_values,
                self.run.plan.stops,
                self.run.plan.stop_pause,
                self.run.plan.schedule,
            )
        except Exception as exc:  # a ramp this node cannot plan: the steps are watched as they come
            self.node.get_logger().warning(f"the run's ramp cannot be checked against the limits: {exc}")
            why = ""
        with self.lock:  # the breach first: the command thread arms once the ramp is checked
            self.ramp_breach = why
            self.ramp_checked = True
            if why and self.armed:
                self.raise_fault(f"servo fault: {why} (soft limit); the run stops", {})

    def watching_limits(self) -> bool:
        """The run has a velocity or an acceleration limit to hold."""
        return self.limit_watch is not None and self.limit_watch.active

    def paces(self) -> bool:
        return True

    def accepts_more(self) -> bool:
        return self.pacer is None or self.pacer.held < MAX_HELD

    def execute(self, rows: npt.NDArray[np.int64]) -> None:
        with self.lock:
            assert self.pacer is not None
            if self.watch is not None:  # where each segment starts: the wire watch's places
                segs = rows[:, 1]
                for i in [0, *(np.flatnonzero(segs[1:] != segs[:-1]) + 1).tolist()]:
                    if not self.seg_id or int(segs[i]) != self.seg_id[-1]:
                        self.seg_t.append(int(rows[i, 0]))
                        self.seg_id.append(int(segs[i]))
            # came after their time (trajectory: after the points for their time went out): now
            sent = self.frontier if self.trajectory else self.t_tick
            if self.armed and rows[0, 0] < sent:
                self.late_rows += int(np.count_nonzero(rows[:, 0] < sent))
                self.max_late_ns = max(self.max_late_ns, sent - int(rows[0, 0]))
            if self.early_breach:
                return  # the run is refused when it would be armed (try_arm)
            over = self.limit_watch.feed(rows) if self.limit_watch is not None else None
            if over is not None:
                j = over.joint
                ax = axis(self.axes[j])
                unit = ax.velocity_unit if over.kind == "velocity" else ax.acceleration_unit
                what = (
                    f"the steps would drive joint {self.joints[j]} ({self.axes[j]} axis) at {over.value:.6g} "
                    f"{unit} over 20 ms"
                )
                limit = f"max_{over.kind}.{self.axes[j]} = {over.limit:g} {unit} (soft limit)"
                if not self.armed:  # the whole job's check, when its ramp comes, says more: at arming
                    self.early_breach = f"{what} {over.t_ns / 1e9:.3f} s into it, beyond {limit}"
                    return
                self.raise_fault(
                    f"servo fault: {what} {over.t_ns / 1e9:.3f} s into the run, beyond {limit}; "
                    "stopped before they were due",
                    {"joint": self.joints[j], "axis": self.axes[j], "value": f"{over.value:.6g}"},
                )
                return
            self.pacer.add(rows)

    def holding(self) -> bool:
        pacer = self.pacer
        return pacer is not None and (pacer.held > 0 or pacer.due > 0)

    def pending(self) -> bool:
        """Waiting to arm, settling, or an operator state booked ahead of the
        command thread's time: a pause's rest comes after its last step, and
        with no rows left to pace the pump stopped before it was reached (the
        run stayed 'pausing', test_pause_and_resume[bridge_node] on a loaded
        machine)."""
        if self.run.plan is None or self.fault_text:
            return False
        if not self.armed:
            # waiting to arm is work while the steps to arm with are here (the joints or the
            # ramp may still be on their way); without steps the run's clock does not run, so
            # nothing booked on it comes, and the stall watch minds the stream (a run whose steps
            # never came waited for ever, an abort of it too)
            return self.pacer is not None and self.pacer.held > 0 and not self.abort_unarmed()
        if not self.run.finishing and self.run.transitions_ahead():
            return True
        return self.settle_until is not None and self.t_tick < self.settle_until

    def abort_unarmed(self) -> bool:
        """The run was aborted before its time started: nothing was commanded."""
        return not self.armed and self.run.abort_booked()

    def work(self) -> None:
        if self.run.plan is None or self.fault_text:
            return
        if self.abort_unarmed():  # nothing moved: the run closes at once, its abort done
            self.stop_pacing()
            self.node.get_logger().info("run aborted before it started: nothing was commanded")
            self.run.finish(complete=False)
            return
        self.account()
        if not self.run.chunks_waiting():
            self.run.settle_if_complete()

    def settle(self, until_ns: int) -> None:
        self.settle_until = until_ns + self.settle_ns

    def flush(self) -> None:
        self.stop_pacing()

    def closing(self) -> None:
        """Commands stop (the controller holds the last one); what the thread
        executed is accounted and every message is in the bag before the base
        closes it."""
        self.stop_pacing()
        if self.run.plan is not None:
            self.account()

    def end(self) -> None:
        with self.lock:
            self.pacer = None

    def faults(self) -> str:
        return self.fault_text

    def unrecorded(self) -> frozenset[str]:
        return frozenset() if self.load_cell else frozenset({"tension"})

    def details(self) -> dict[str, object]:
        with self.lock:  # the command thread adds to them
            foreign, foreign_nodes = self.state_senders.summary()
            wire = self.wire_details()
        errors = {
            f"max_following_error.{j}": f"{e:.6g}" for j, e in zip(self.joints, self.max_error, strict=True)
        }
        return {
            "rate_hz": f"{self.rate:g}",
            "commands_sent": self.ticks,
            "max_command_gap_ms": f"{self.max_gap_ns / 1e6:.3f}",
            "joint_states_received": self.states_in_run,
            "late_steps": self.late_rows,
            "foreign_joint_states": foreign,
            "foreign_joint_state_publishers": foreign_nodes,
            "max_step_lateness_ms": f"{self.max_late_ns / 1e6:.3f}",
            **errors,
            "servo_fault": self.fault_text if self.fault_task != "wire" else "",
            **wire,
        }

    def wire_details(self) -> dict[str, object]:
        """(Under the lock.) The load cell's status keys (none without one): its node, the
        readings, the tension's peak and least (N) and the time outside
        each band (s) while the run's time ran, foreign wrenches, the wire's
        fault."""
        if not self.load_cell_fq:
            return {}
        foreign, foreign_nodes = self.wrench_senders.summary()
        seen = self.tension_min <= self.tension_peak
        return {
            "load_cell": self.load_cell_fq,
            "tension_samples": self.wrenches_in_run,
            "tension_peak_n": f"{self.tension_peak:.4g}" if seen else "",
            "tension_min_n": f"{self.tension_min:.4g}" if seen else "",
            "tension_outside_warning_s": f"{self.outside[0]:.3f}",
            "tension_outside_alarm_s": f"{self.outside[1]:.3f}",
            "foreign_wrenches": foreign,
            "foreign_wrench_publishers": foreign_nodes,
            "wire_fault": self.fault_text if self.fault_task == "wire" else "",
        }

    def account(self) -> None:
        """Tell the base what the command thread executed (receipts on
        winder/progress, the run's transitions) and record what went out."""
        with self.lock:
            if self.pacer is None:
                return
            n, t = self.pacer.take_due(), self.t_tick
        self.drain()
        if n:
            self.run.executed(n)
        if not self.node.context.ok():  # Ctrl-C: the run closes, nothing more is published
            self.run.t_ns = t
            return
        if n:
            self.run.receipt()
        self.run.reached(t)

    def drain(self) -> None:
        """Everything the thread queued for the bag, in time order."""
        out = self.outbox
        while out:
            key, t, payload, exact = out.popleft()
            self.run.record(key, t, payload, exact=exact)

    # -- readiness --------------------------------------------------------------
    def missing(self) -> str:
        """The hardware is not there (no joint_states for a while, or nobody
        subscribes to the commands): a run is not started into the void."""
        if self.run.plan is None and self.upstream.client is None:
            self.upstream.find()  # early: its replies match by a fault
        why = self.hardware_missing()
        if why and self.homed:
            self.homed = False
            self.node.get_logger().warning(f"the axes' reference is lost ({why}): home them again (~/home)")
        if not why:
            why = self.unhomed(self.run.values())
        if why != self.missing_said:
            self.missing_said = why
            if why:
                self.node.get_logger().info(f"waiting for the hardware: {why}")
        return why

    def unhomed(self, values: dict[str, Any]) -> str:
        """Why a run may not start for want of homing ("" if it may), from the
        settings ``values`` as they are now: ``require_homing`` switched on
        between runs holds the next start as one given at the node's start
        does (it was read from the last run's settings, and the next run ran
        unhomed to its end)."""
        if values["require_homing"] and not self.homed:
            return (
                f"the axes are not homed (require_homing): call {self.node.get_fully_qualified_name()}/home"
            )
        return ""

    def hardware_missing(self) -> str:
        if not self.running:  # the controller the next run will command (its settings may have changed)
            values = self.run.values()
            with self.lock:
                self.pub_cmd = self.commands_publisher(values["controller"], values["interface"])
        if time.monotonic_ns() - self.heard_ns > HARDWARE_FRESH_NS:
            if self.hardware_bad:
                return self.hardware_bad
            return (
                f"no {self.run.bag_topic('joint_states')} from {self.broadcaster} for "
                f"{HARDWARE_FRESH_NS / 1e9:g} s"
            )
        if self.pub_cmd.get_subscription_count() == 0:
            return f"nobody subscribes to {self.run.bag_topic('commands')}"
        return ""

    # -- homing -------------------------------------------------------------------
    async def on_home(self, _req: Trigger.Request, resp: Trigger.Response) -> Trigger.Response:
        """~/home: refused during a run or without the hardware; else the
        homing service called (if one is set) and, once it says so, the axes
        are homed: the soft limits hold for the positions measured from now."""
        if self.homing_now:
            resp.success, resp.message = False, "home refused: homing is under way"
            self.node.get_logger().warning(resp.message)
            return resp
        self.homing_now = True
        try:
            resp.success, resp.message = await self.home()
        except Exception as exc:  # a reply, always: the caller would wait for ever
            resp.success, resp.message = False, f"home failed: {type(exc).__name__}: {exc}"
        finally:
            self.homing_now = False
        (self.node.get_logger().info if resp.success else self.node.get_logger().warning)(resp.message)
        return resp

    async def home(self) -> tuple[bool, str]:
        if self.run.plan is not None:
            return False, f"home refused: run {self.run.plan.run_id or self.run.plan.job_id} is on"
        values = self.run.values()
        why = self.hardware_missing()
        if why:
            return False, f"home refused: {why}"
        service, name = str(values["homing_service"]), ""
        if service:
            name = service if service.startswith("/") else self.node.resolve_service_name(service)
            client = self.homing_clients.get(name)
            if client is None:
                client = self.homing_clients[name] = self.node.create_client(
                    Trigger, name, callback_group=self.homing_group
                )
            if not client.service_is_ready():
                return (
                    False,
                    f"home refused: no service {name} (homing_service): is the homing controller up?",
                )
            call = client.call_async(Trigger.Request())
            limit = float(values["homing_timeout"])
            if not await self.done_within(call, limit):
                client.remove_pending_request(call)
                return False, (
                    f"home failed: no answer from {name} within {limit:g} s (homing_timeout); "
                    "the axes are not homed"
                )
            reply = call.result()
            if reply is None or not reply.success:
                return False, f"home failed: {name} said: {reply.message if reply else 'nothing'}"
        self.homed = True
        with self.lock:
            at = self.idle_pos.copy()
        where = ", ".join(
            f"{j} {x:.6g} {u}" for j, x, u in zip(self.joints, at.tolist(), self.units, strict=True)
        )
        limits = [
            f"{a} [{lo:g}, {hi:g}] {u}"
            for a, lo, hi, u in zip(
                self.axes,
                [values[f"min_position.{a}"] for a in self.axes],
                [values[f"max_position.{a}"] for a in self.axes],
                self.units,
                strict=True,
            )
            if lo > -NO_LIMIT or hi < NO_LIMIT
        ]
        how = f"by {name}" if service else f"where they stand: {where}"
        return True, f"homed {how}; soft limits: {', '.join(limits) or 'none set'}"

    async def done_within(self, future: Future, timeout: float) -> bool:
        """Await ``future`` for ``timeout`` s at most (the node's other callbacks
        go on meanwhile): whether it is done."""
        gate = Future(executor=self.node.executor)

        def open_gate(*_: object) -> None:
            if not gate.done():
                gate.set_result(None)

        future.add_done_callback(open_gate)
        timer = self.node.create_timer(timeout, open_gate, callback_group=self.homing_group)
        try:
            await gate
        finally:
            timer.cancel()
            self.node.destroy_timer(timer)
        return bool(future.done())

    # -- the command thread --------------------------------------------------------
    def command_loop(self) -> None:
        """A tick every ``period_ns`` of the steady clock while a run is on;
        between runs, a look at the joint states every IDLE_POLL s."""
        while not self.quit:
            if not self.go.wait(IDLE_POLL):
                with self.lock:
                    for raw, gid in taken_with_sender(self.sub_states, 64):
                        now = time.monotonic_ns()
                        if self.from_broadcaster(gid, now):
                            self.idle_measurement(raw, now)
                continue
            due = time.monotonic_ns()
            while self.go.is_set() and not self.quit:
                due += self.period_ns
                wait = due - time.monotonic_ns()
                if wait > 0:
                    time.sleep(wait / 1e9)
                elif wait < -self.period_ns:
                    due = time.monotonic_ns()  # fell behind: go on from now, no burst of ticks
                try:
                    with self.lock:
                        self.tick()
                except Exception as exc:  # the context is shutting down
                    if self.node.context.ok():
                        self.node.get_logger().error(f"command thread: {exc}")
                    self.go.clear()

    def tick(self) -> None:
        """(Under the lock.) One command: the rows due now set the positions
        (interface trajectory: the trajectory of the next two batches); every
        CLOCK_PERIOD_NS (trajectory: every tick) the clock, and the measured
        states that came (and before the run's time starts: each tick, and
        its start); all queued for the bag."""
        if not self.running or self.faulted:
            return
        now = time.monotonic_ns()
        t = now - self.t0_ns
        # every CLOCK_PERIOD_NS (to the tick) once armed; a trajectory's tick is a batch apart
        look = self.trajectory or not self.armed or t >= self.next_clock
        if look:  # a take costs ~20 us even when nothing came: not every tick
            for raw, gid in taken_with_sender(self.sub_states, 64):
                if self.from_broadcaster(gid, now):
                    self.heard_ns = now
                    self.measurement(raw, now)
            if self.sub_wrench is not None and not self.faulted:
                self.take_wrenches(now)
            if self.faulted:
                return
        if not self.armed:
            self.try_arm(now)
            if not self.armed:
                return
            t, look = 0, True
        assert self.pacer is not None
        if self.ticks:
            self.max_gap_ns = max(self.max_gap_ns, t - self.t_tick)
        if self.trajectory:
            self.send_trajectory(t)
            self.check_silence(now)
            return
        if self.pacer.advance(t) or not self.ticks:  # the positions changed: a new command
            self.cmd.values[:] = self.pacer.position
            self.payload = self.cmd.bytes()
            self.history.push(time.time_ns(), self.pacer.position)
        if look:
            self.next_clock = t + CLOCK_PERIOD_NS - self.period_ns // 2
            self.clock_ns = self.origin_ns + t
            clock = clock_payload(self.clock_ns)
            self.pub_clock.publish(clock)
            self.outbox.append(("clock", t, clock, True))
        self.pub_cmd.publish(self.payload)
        self.outbox.append(("commands", t, self.payload, True))
        self.t_tick = t
        self.ticks += 1
        if look:
            self.check_silence(now)

    def send_trajectory(self, t: int) -> None:
        """(Under the lock.) Interface trajectory: one JointTrajectory from
        run time ``t`` on, a point every ``point_ns`` to AHEAD_BATCHES
        batches ahead (the points already sent for that stretch, then new
        ones: a point is the last row due by its time, as a forward command
        is), stamped with the system clock time of ``t`` (a
        JointTrajectoryController replaces its trajectory with it from
        there: a tick up to AHEAD_BATCHES - 1 batches late leaves it points
        to follow); and the clock. The steps must be here that far ahead:
        the run's sim_config asks the profile node for the steps
        AHEAD_BATCHES + 2 batches ahead at least (``lookahead_min_s``: the
        points sent, a batch to the next tick, a batch for the clock the
        profile node has seen)."""
        assert self.pacer is not None
        passed = int(np.searchsorted(self.point_t, t, side="right"))
        horizon = t + AHEAD_BATCHES * self.period_ns
        m = max(self.frontier, t) // self.point_ns + 1
        grid = np.arange(m, horizon // self.point_ns + 1, dtype=np.int64) * self.point_ns
        if grid.size:
            positions = self.pacer.advance_grid(grid)
            self.point_t = np.concatenate((self.point_t[passed:], grid))
            self.point_pos = np.concatenate((self.point_pos[passed:], positions))
            self.history.push_many(self.wall_t0 + grid, positions)
            self.frontier = int(grid[-1])
        elif passed:
            self.point_t, self.point_pos = self.point_t[passed:], self.point_pos[passed:]
        payload = trajectory_payload(
            self.wall_t0 + t,
            self.run.plan.run_id if self.run.plan is not None else "",
            self.joints,
            self.point_t - t,
            self.point_pos,
        )
        self.pub_cmd.publish(payload)
        self.outbox.append(("commands", t, payload, True))
        self.clock_ns = self.origin_ns + t
        clock = clock_payload(self.clock_ns)
        self.pub_clock.publish(clock)
        self.outbox.append(("clock", t, clock, True))
        self.t_tick = t
        self.ticks += 1

    def check_silence(self, now: int) -> None:
        """(Under the lock.) A servo fault if a joint was not measured for joint_state_timeout."""
        late = now - int(self.last_seen.min())
        if late > self.timeout_ns:
            j = int(np.argmin(self.last_seen))
            self.raise_fault(
                f"servo fault: joint {self.joints[j]} ({self.axes[j]} axis): no measured position on "
                f"{self.run.bag_topic('joint_states')} for {late / 1e6:.1f} ms, beyond "
                f"joint_state_timeout = {self.timeout_ns / 1e9:g} s",
                {"joint": self.joints[j], "axis": self.axes[j], "silent_s": f"{late / 1e9:.3f}"},
            )

    def from_broadcaster(self, gid: bytes, now: int) -> bool:
        """(Under the lock.) Whether a joint_states message with publisher
        ``gid`` is the broadcaster's, by the node the graph names for it.
        A publisher the graph does not name yet is asked for again (at most
        every GRAPH_LOOK_NS) and its message ignored meanwhile; another
        node's is ignored, counted and warned about once per node."""
        who = self.state_senders.who(self.io, self.run.bag_topic("joint_states"), gid, now)
        if who is None:
            return False  # not named yet: neither trusted nor blamed
        if who == self.broadcaster:
            return True
        if self.state_senders.ignore(who):
            self.node.get_logger().warning(
                f"{self.run.bag_topic('joint_states')}: joint states from {who}, not from the broadcaster "
                f"{self.broadcaster}: ignored (counted in the status' foreign_joint_states)"
            )
        return False

    # -- the load cell ------------------------------------------------------------
    def from_load_cell(self, gid: bytes, now: int) -> bool:
        """(Under the lock.) Whether a wrench with publisher ``gid`` is the
        load cell's (its node, as the graph names it): as
        :meth:`from_broadcaster`."""
        topic = self.run.bag_topic("tension")
        who = self.wrench_senders.who(self.io, topic, gid, now)
        if who is None:
            return False
        if who == self.load_cell_fq:
            return True
        if self.wrench_senders.ignore(who):
            self.node.get_logger().warning(
                f"{topic}: a wrench from {who}, not from the load cell {self.load_cell_fq}: ignored "
                "(counted in the status' foreign_wrenches)"
            )
        return False

    def take_wrenches(self, now: int) -> None:
        """(Under the lock, each look during a run.) The load cell's readings
        that came: recorded; while the run's time runs, counted against the
        bands and watched (a break is a fault)."""
        times: list[int] = []
        forces: list[float] = []
        wall = time.time_ns()
        for raw, gid in taken_with_sender(self.sub_wrench, WRENCHES_PER_LOOK):
            if not self.from_load_cell(gid, now):
                continue
            self.outbox.append(("tension", self.t_tick, raw, False))
            got = wrench_force_x(raw)
            if got is None:
                self.bad_wrenches += 1
                if self.bad_wrenches == 1:
                    self.node.get_logger().warning(
                        f"{self.run.bag_topic('tension')}: a message that is not a WrenchStamped: ignored"
                    )
                continue
            self.wrenches_in_run += 1
            stamp, force = got
            if self.armed:  # the run's time: the reading's stamp on it (or its arrival)
                times.append((stamp if abs(stamp - wall) < STAMP_TRUST_NS else wall) - self.wall_t0)
                forces.append(force)
        if times:
            self.watch_tension(times, forces)
        elif self.armed and not self.silence_said and now - self.t0_ns > LOAD_CELL_SILENT_NS:
            if self.wrenches_in_run == 0:  # said once a run
                self.node.get_logger().warning(
                    f"no reading of the load cell {self.load_cell_fq} on {self.run.bag_topic('tension')} "
                    f"{LOAD_CELL_SILENT_NS / 1e9:g} s into the run: the wire is not watched (is the "
                    "force_torque_sensor_broadcaster active?)"
                )
            self.silence_said = True

    def watch_tension(self, times: list[int], forces: list[float]) -> None:
        """(Under the lock.) Readings of the run (run time ns, N): the bands'
        time (each reading holds until the next), the peak and the least, and
        the wire watch with the flyer's speed; a break stops the run."""
        for t_ns, force in zip(times, forces, strict=True):
            t = t_ns / 1e9
            last = self.tension_last
            if last is not None and 0.0 < t - last[0] <= BAND_HOLD_MAX_S:
                for b, (low, high) in enumerate(self.bands):
                    if not low <= last[1] <= high:
                        self.outside[b] += t - last[0]
            self.tension_last = (t, force)
            self.tension_peak = max(self.tension_peak, force)
            self.tension_min = min(self.tension_min, force)
        if self.watch is None:
            return
        fault = self.watch.feed(
            np.array(times) / 1e9,
            np.array(forces),
            np.full(len(times), self.fork_speed),
            lambda k: self.place_at(times[k]),
        )
        if fault is not None:
            self.raise_fault(fault.text, {**fault.values(), "load_cell": self.load_cell_fq}, task="wire")

    def place_at(self, t_ns: int) -> tuple[int, int, int]:
        """(Under the lock.) Where the run was at run time ``t_ns``: (coil,
        layer, turn of the coil, from 1) of the segment executed then and
        the fork commanded then; (0, 0, 0) off a layer."""
        i = bisect.bisect_right(self.seg_t, t_ns) - 1
        if not self.seg_id or self.pacer is None or self.fork_j < 0:
            return (0, 0, 0)
        seg = self.segments[self.seg_id[max(i, 0)]]
        if not seg.kind.winds or seg.turn_steps <= 0:
            return (0, 0, 0)
        at = self.wall_t0 + t_ns
        commanded = float(self.history.span(at, at)[0][self.fork_j])
        j = self.fork_j
        steps = round((commanded - float(self.pacer.offset[j])) / float(self.pacer.step_len[j]))
        done = min(abs(steps - seg.start[FORK.index]) // seg.turn_steps, seg.turns - 1)
        return seg.pole + 1, seg.layer + 1, seg.first_turn + int(done) + 1

    def measured_fork_speed(self, raw: bytes, stamp: int, position: float) -> None:
        """(Under the lock.) The flyer's speed from a broadcaster's message:
        the larger of the fork joint's velocity, if it gives one, and its
        position's change since the last message (a mock_components system
        without calculate_dynamics reports a velocity of 0 on a moving joint)."""
        v = self.velocity.read(raw) if self.velocity is not None else None
        last, self.fork_last = self.fork_last, (stamp, position)
        if last is not None and stamp > last[0] and position == position:
            moved = (position - last[1]) / ((stamp - last[0]) / 1e9)
            v = moved if v is None or abs(moved) > abs(v) else v
        if v is not None and v == v:
            self.fork_speed = v

    def idle_measurement(self, raw: bytes, now: int) -> None:
        """(Under the lock.) The broadcaster's message between runs: the
        hardware is there if it measures a position for every joint it
        names that is one (finite, within ±FAR_POSITION)."""
        got = self.reader.read(raw)
        if got is None:
            return
        bad = self.no_position(got[1])
        self.hardware_bad = bad
        if not bad:
            self.heard_ns = now
            seen = ~np.isnan(got[1])
            self.idle_pos[seen] = got[1][seen]

    def no_position(self, pos: Any) -> str:
        """Why a measurement's positions (NaN: a joint not in it) are no
        positions of the joints, or ''."""
        for j, x in enumerate(pos):
            if x != x:  # NaN: not measured in this message
                continue
            if not abs(x) <= FAR_POSITION:
                what = "not finite" if abs(x) == float("inf") else f"beyond ±{FAR_POSITION:g}"
                return (
                    f"joint {self.joints[j]} ({self.axes[j]} axis) measured at {x:g} {self.units[j]} by "
                    f"{self.broadcaster}: {what}, no position of the axis"
                )
        return ""

    def measurement(self, raw: bytes, now: int) -> None:
        """(Under the lock.) One joint_states message of the run: recorded;
        before the run's time starts, checked against the job's start; then
        against the commands (following error). A message that measures
        every joint (a joint_state_broadcaster's) is read and checked in
        plain Python: at 100 Hz numpy's per-call cost was a tenth of the
        bridge's CPU; another (a joint missing or NaN) with numpy."""
        every = self.reader.read_all(raw)
        if every is not None:
            stamp, values = every
            self.last_seen[:] = now
            self.measured[:] = values
            pos, seen = self.measured, None
        else:
            got = self.reader.read(raw)
            if got is None:
                self.bad_states += 1
                if self.bad_states == 1:
                    self.node.get_logger().warning(
                        f"{self.run.bag_topic('joint_states')}: a message that is not a JointState with "
                        "one position per name: ignored"
                    )
                return
            stamp, pos = got
            seen = ~np.isnan(pos)
            self.last_seen[seen] = now
            self.measured[seen] = pos[seen]
        self.outbox.append(("joint_states", self.t_tick, raw, False))
        self.states_in_run += 1
        if self.watch is not None and self.fork_j >= 0:
            self.measured_fork_speed(raw, stamp, float(pos[self.fork_j]))
        bad = self.no_position(pos)
        if bad:  # a broken measurement: never an origin, never a position to follow
            self.raise_fault(f"servo fault: {bad}", {"reason": bad})
            return
        wall = time.time_ns()
        when = stamp if abs(stamp - wall) < STAMP_TRUST_NS else wall
        low, high = self.history.span(when - self.delay_ns, when)
        if not self.armed:
            if not self.origin_here:
                self.check_start(pos.copy(), np.ones(pos.size, bool) if seen is None else seen, low)
            return
        if seen is None:
            self.check_following(values, low, high)
            return
        error = np.where(seen, following_error(low, high, np.where(seen, pos, low)), 0.0)
        size = np.abs(error)
        np.maximum(self.max_error, size, out=self.max_error)
        if (size > self.limits).any():
            j = int(np.argmax(size / self.limits))
            self.following_fault(j, float(error[j]), float(pos[j]), float(low[j]), float(high[j]))

    def check_following(
        self, pos: list[float], low: npt.NDArray[np.float64], high: npt.NDArray[np.float64]
    ) -> None:
        """(Under the lock.) :func:`winder.contract.pacing.following_error`
        of every joint, one float at a time; the largest error, and a fault
        for the joint furthest beyond its limit."""
        worst, worst_j = 1.0, -1
        for j, (m, lo, hi) in enumerate(zip(pos, low.tolist(), high.tolist(), strict=True)):
            size = lo - m if m < lo else (m - hi if m > hi else 0.0)
            if size > self.max_error[j]:
                self.max_error[j] = size
            if size > self.limits[j] * worst:  # beyond the limit, and the worst so far
                worst, worst_j = size / self.limits[j], j
        if worst_j >= 0:
            m, lo, hi = pos[worst_j], float(low[worst_j]), float(high[worst_j])
            self.following_fault(worst_j, lo - m if m < lo else hi - m, m, lo, hi)

    def following_fault(self, j: int, error: float, measured: float, low: float, high: float) -> None:
        """(Under the lock.) Joint ``j`` is further than its limit from every
        position commanded over command_delay: a servo fault."""
        unit = self.units[j]
        self.raise_fault(
            f"servo fault: joint {self.joints[j]} ({self.axes[j]} axis): following error "
            f"{error:+.6g} {unit} beyond max_following_error.{self.axes[j]} = {self.limits[j]:g} "
            f"{unit} (measured {measured:.6g}, commanded {low:.6g} to {high:.6g} over command_delay)",
            {
                "joint": self.joints[j],
                "axis": self.axes[j],
                "following_error": f"{error:.6g}",
                "limit": f"{self.limits[j]:g}",
                "unit": unit,
            },
        )

    def check_start(
        self, pos: npt.NDArray[np.float64], seen: npt.NDArray[np.bool_], start: npt.NDArray[np.float64]
    ) -> None:
        """(Under the lock.) With ``job_origin`` zero the joints must be at the
        job's start (within max_following_error): else the run would begin
        with a jump, and it does not start."""
        off = np.where(seen, np.abs(pos - np.where(seen, start, pos)), 0.0)
        if (off > self.limits).any():
            j = int(np.argmax(off / self.limits))
            unit = self.units[j]
            self.raise_fault(
                f"servo fault: the run cannot start: joint {self.joints[j]} ({self.axes[j]} axis) is at "
                f"{pos[j]:.6g} {unit}, the job starts at {start[j]:.6g} {unit}, more than "
                f"max_following_error.{self.axes[j]} = {self.limits[j]:g} {unit} apart (bring the axes to "
                "the job's start, or set job_origin start_position)",
                {"joint": self.joints[j], "axis": self.axes[j], "at": f"{pos[j]:.6g}", "unit": unit},
            )

    def try_arm(self, now: int) -> None:
        """(Under the lock.) Start the run's time once every joint was
        measured since its start, the controller listens and the run's first
        steps are here (they are timed from it); refuse the run if the joints
        or the controller are not there within ARM_WAIT_NS."""
        if (self.last_seen <= self.begin_ns).any():
            missing = [j for j, s in zip(self.joints, self.last_seen, strict=True) if s <= self.begin_ns]
            self.why_not_armed = f"no joint_states for {', '.join(missing)}"
        elif self.pub_cmd.get_subscription_count() == 0:
            topic = self.run.bag_topic("commands")
            self.why_not_armed = f"nobody subscribes to {topic} (is {self.controller} loaded and active?)"
        else:
            self.why_not_armed = ""
        if self.why_not_armed:
            wait = max(self.timeout_ns, ARM_WAIT_NS)
            if now - self.begin_ns > wait:
                self.raise_fault(
                    f"servo fault: the run cannot start: {self.why_not_armed} within {wait / 1e9:g} s", {}
                )
            return
        if self.pacer is None or (self.pacer.held == 0 and not self.early_breach):
            return  # the axes are ready; the steps are on their way (the stall watch minds them)
        if self.watching_limits() and not self.ramp_checked:
            # the job is checked against max_velocity/max_acceleration before anything moves; a
            # profile node that publishes no ramp leaves only the watch on the steps as they come
            if now - self.begin_ns < ARM_WAIT_NS:
                self.why_not_armed = (
                    f"the run's ramp ({TOPIC_PROFILE_CONFIG}) is not here to check the limits"
                )
                return
            if not self.ramp_said:
                self.ramp_said = True
                self.node.get_logger().warning(
                    f"no {TOPIC_PROFILE_CONFIG} for this run within {ARM_WAIT_NS / 1e9:g} s: its job is not "
                    "checked against the velocity and acceleration limits before it starts; its steps are, "
                    "as they come"
                )
        if self.origin_here:  # the job starts where the joints are
            self.pacer.set_origin(self.measured)
            self.history = CommandHistory(self.pacer.position.copy())
        if self.beyond_limits():
            return
        if self.ramp_breach or self.early_breach:
            why = f"{self.ramp_breach} (soft limit)" if self.ramp_breach else self.early_breach
            self.raise_fault(f"servo fault: the run cannot start: {why}; nothing was commanded", {})
            return
        self.t0_ns = now
        self.wall_t0 = time.time_ns()  # the same instant on the system clock: the trajectories' stamps
        self.point_t, self.point_pos = self.point_t[:0], self.point_pos[:0]
        self.frontier = 0
        self.next_clock = 0
        self.armed = True
        batches = f", a trajectory every {self.period_ns / 1e6:g} ms" if self.trajectory else ""
        self.node.get_logger().info(
            f"run armed: commanding {', '.join(self.joints)} at {self.rate:g} Hz{batches} "
            f"on {self.run.bag_topic('commands')}"
        )

    def beyond_limits(self) -> bool:
        """(Under the lock, at arming.) The job's extent from the run's origin
        against the soft limits: a fault naming the first joint it would take
        beyond one (True), before any command."""
        assert self.pacer is not None
        lo = self.pacer.offset + self.extent[0] * self.pacer.step_len
        hi = self.pacer.offset + self.extent[1] * self.pacer.step_len
        past = travel_past(lo, hi, self.pos_lo, self.pos_hi)
        if past is None:
            return False
        j, unit = past.index, self.units[past.index]
        self.raise_fault(
            f"servo fault: the run cannot start: the job takes joint {self.joints[j]} "
            f"({self.axes[j]} axis) to {past.at:.6g} {unit}, beyond {past.side}_position.{self.axes[j]} = "
            f"{past.limit:g} {unit} (soft limit); nothing was commanded",
            {
                "joint": self.joints[j],
                "axis": self.axes[j],
                "at": f"{past.at:.6g}",
                "limit": f"{past.limit:g}",
            },
        )
        return True

    def raise_fault(self, text: str, values: dict[str, object], task: str = "servo") -> None:
        """(Under the lock, in the thread.) No further command at once; the
        executor reports the fault (a status of ``task``: servo, or wire for
        the load cell's) and closes the run (on_alarm)."""
        if self.faulted:
            return
        self.faulted = True
        self.armed = False
        self.alarm = (text, values, task)
        self.guard.trigger()

    def stop_pacing(self) -> None:
        """No further tick; one under way finishes first."""
        self.go.clear()
        with self.lock:
            self.running = False
            self.armed = False

    # -- faults ------------------------------------------------------------------
    def on_alarm(self) -> None:
        """The command thread raised a fault (a servo fault, or the wire's)."""
        with self.lock:
            alarm, self.alarm = self.alarm, None
        if alarm is not None:
            self.servo_fault(*alarm)

    def servo_fault(self, text: str, values: dict[str, object], task: str = "servo") -> None:
        """Stop the run: commands hold, the fault reported (an ERROR status of
        ``task``), the profile node told to abort (the rest of the cell stops
        sending), the run closed."""
        if self.run.plan is None or self.fault_text:
            return
        self.stop_pacing()
        self.fault_text, self.fault_task = text, task
        self.node.get_logger().error(text)
        self.run.publish_status(
            task, ERROR, text, {"job_id": self.run.plan.job_id, "run_id": self.run.plan.run_id, **values}
        )
        self.upstream.ask(TOPIC_STEP_TIMES)
        self.run.finish(complete=False)

    def shutdown(self) -> bool:
        self.quit = True
        self.go.set()
        self.thread.join(timeout=1.0)
        # a command thread still waiting holds its node: its destruction waits for the
        # interpreter's teardown, which the process must then not skip (winder.ros.spin.leave)
        let_go = not self.thread.is_alive()
        self.io.destroy_node()
        return let_go


class BridgeNode(StepConsumer):
    """The bridge node: the cell's consumer in front of ros2_control."""

    def __init__(self) -> None:
        super().__init__(
            "bridge_node",
            PARAMETERS,
            # the topics `controller` and `load_cell` name must be names ROS takes in this node's namespace
            self.check,
            BridgeEngine(),
            hardware_id="winder_bridge",
            topics=BRIDGE_TOPICS,
        )

    def check(self, values: dict[str, Any]) -> None:
        check_bridge(values, namespace=self.get_namespace())
        check_load_cell(values, self.get_namespace())


def main(args: list[str] | None = None) -> None:
    spin(BridgeNode, args)
