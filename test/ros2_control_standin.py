"""A stand-in for a ros2_control system, for the bridge's tests (ros2_control
itself cannot be installed here, docs/BRIDGE.md). One process, three nodes
named and namespaced as ros2_control makes them, behaving as documented:

* ``controller_manager``: the update loop at ``--rate`` Hz on the steady
  clock: read (the hardware's state interfaces), update (the controllers),
  write (nothing to do for a mock);
* ``<controller>`` (forward_command_controller/ForwardCommandController):
  subscribes ``~/commands`` (std_msgs/Float64MultiArray, reliable, as
  rclcpp's SystemDefaultsQoS); each update writes the last command received
  into the joints' position command interfaces; a command whose size is not
  the number of joints is rejected with an error log and ignored;
* or, with ``--interface trajectory``, ``<controller>``
  (joint_trajectory_controller/JointTrajectoryController, position command
  interface, no velocities or accelerations in the points: linear
  interpolation): subscribes ``~/joint_trajectory``
  (trajectory_msgs/JointTrajectory); a new trajectory replaces the one in
  force, starting at its ``header.stamp`` (zero: when it is received),
  each point at the start plus its ``time_from_start``; each update
  samples it: before its first point, the line from the position
  commanded when it arrived to the first point; between points, the line
  between them; after the last, the last point held. A trajectory whose
  joint names are not the controller's joints is rejected with an error log;
* ``joint_state_broadcaster``: publishes sensor_msgs/JointState on
  ``joint_states`` (relative: ``/<ns>/joint_states``) with the joints' names,
  position, velocity and effort at each update, stamped with the update's
  time (system clock, ROS time without use_sim_time);
* the hardware, mock_components/GenericSystem: each read copies the position
  command interfaces into the state interfaces (``--offset JOINT=VALUE``:
  ``position_state_following_offset`` of one joint); beyond the mock,
  ``--lag JOINT=TAU`` gives a joint a first-order lag of TAU s and
  ``--stuck JOINT`` freezes one, ``--silent-after S`` stops the broadcaster
  S s after the first command (a dead state stream), ``--corrupt-after S``
  makes it report ``--corrupt-value`` (default inf) for every joint from S s
  after the first command on (a broken encoder word); ``--homing`` adds a
  ``homing_controller`` node whose ``~/home`` (std_srvs/Trigger) homes every
  joint: the mock's positions go to 0, the home switches' place (a real
  machine's drives run to their switches; the bridge's ``homing_service``);
  ``--homing-silent`` adds one that never answers (a drive that hangs);
* with ``--load-cell NAME``, a force_torque_sensor_broadcaster named NAME
  (force_torque_sensor_broadcaster/ForceTorqueSensorBroadcaster, as its
  documentation and source have it: publishes geometry_msgs/WrenchStamped on
  ``~/wrench``, i.e. ``/<ns>/NAME/wrench``, SystemDefaultsQoS, at each
  update, stamped with the update's time, ``header.frame_id`` its
  ``frame_id``) over a one-axis load cell, force.x = the wire's tension:
  ``--tension`` N, steady; beyond the mock, it drops to 0 (the wire broke)
  from the first update where a joint's state reaches a position
  (``--tension-drop JOINT=POSITION``: a turn of the flyer) or ``--tension-drop-after S`` s
  after the first command; ``--impostor NODE`` adds another node, NODE,
  publishing 0 N on the same topic at the same rate (a neighbour no bridge
  may trust).

Like the controller manager, which "independent of the kernel installed"
configures SCHED_FIFO with priority 50 for its main thread (its user
documentation, "Determinism"), the stand-in asks for that policy, for the
whole process (its DDS threads carry the commands in), and falls back to
``nice -10`` and then to the default when the user may not: a starved Python
stand-in fell seconds behind its commands on two busy cores, a servo fault
that a real controller manager would not have caused.

    python ros2_control_standin.py --joints a,b,c [--controller NAME] [--rate HZ] [...] [--ros-args ...]
"""

from __future__ import annotations

import argparse
import bisect
import math
import os
import sys
import time
from typing import Any

import rclpy
from geometry_msgs.msg import WrenchStamped
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory


def pairs(items: list[str], kind: type) -> dict[str, float]:
    out = {}
    for item in items:
        name, _, value = item.partition("=")
        out[name] = kind(value)
    return out


def realtime_priority() -> str:
    """SCHED_FIFO 50 as the controller manager asks for, else nice -10, else
    nothing: the policy the process got."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(50))
        return "SCHED_FIFO 50"
    except (OSError, AttributeError):
        pass
    try:
        os.nice(-10)
        return "nice -10"
    except OSError:
        return "default (no permission for SCHED_FIFO or a negative nice)"


def main() -> None:
    argv = rclpy.utilities.remove_ros_args(sys.argv)[1:]
    ap = argparse.ArgumentParser()
    ap.add_argument("--joints", required=True)
    ap.add_argument("--controller", default=None)
    ap.add_argument("--interface", choices=("forward", "trajectory"), default="forward")
    ap.add_argument("--rate", type=float, default=250.0)
    ap.add_argument("--initial", action="append", default=[], metavar="JOINT=VALUE")
    ap.add_argument("--offset", action="append", default=[], metavar="JOINT=VALUE")
    ap.add_argument("--lag", action="append", default=[], metavar="JOINT=TAU")
    ap.add_argument("--stuck", action="append", default=[], metavar="JOINT")
    ap.add_argument("--silent-after", type=float, default=math.inf)
    ap.add_argument("--corrupt-after", type=float, default=math.inf)
    ap.add_argument("--corrupt-value", type=float, default=math.inf)
    ap.add_argument("--homing", action="store_true")
    ap.add_argument("--homing-silent", action="store_true")
    ap.add_argument("--load-cell", default="")
    ap.add_argument("--tension", type=float, default=10.0)
    ap.add_argument("--tension-drop", default="", metavar="JOINT=POSITION")
    ap.add_argument("--tension-drop-after", type=float, default=math.inf)
    ap.add_argument("--impostor", default="")
    args = ap.parse_args(argv)
    joints = args.joints.split(",")
    if args.controller is None:
        args.controller = (
            "joint_trajectory_controller" if args.interface == "trajectory" else "forward_position_controller"
        )
    initial, offset, lag = pairs(args.initial, float), pairs(args.offset, float), pairs(args.lag, float)

    policy = realtime_priority()  # before rclpy.init: the DDS threads inherit it
    rclpy.init(args=sys.argv)
    cm = rclpy.create_node("controller_manager")
    ctrl = rclpy.create_node(args.controller)
    jsb = rclpy.create_node("joint_state_broadcaster")
    log = ctrl.get_logger()

    command = [initial.get(j, 0.0) for j in joints]  # the position command interfaces
    state = list(command)  # the position state interfaces
    velocity = [0.0] * len(joints)
    last_msg: list[list[float] | None] = [None]
    first_command = [math.inf]
    refused = [0.0]

    def on_commands(msg: Float64MultiArray) -> None:
        if len(msg.data) != len(joints):
            now = time.monotonic()
            if now - refused[0] > 1.0:  # RCLCPP_ERROR_THROTTLE, 1 s
                refused[0] = now
                log.error(
                    f"command size ({len(msg.data)}) does not match number of interfaces ({len(joints)})"
                )
            return
        last_msg[0] = list(msg.data)
        if first_command[0] == math.inf:
            first_command[0] = time.monotonic()
            log.info(f"first command: {list(msg.data)}")

    # the trajectory in force: (start ns, point times ns, positions), and where it set out from
    traj: list[Any] = [None]

    def on_trajectory(msg: JointTrajectory) -> None:
        if list(msg.joint_names) != joints:
            log.error(f"joints {list(msg.joint_names)} of the trajectory are not the controller's {joints}")
            return
        if not msg.points:
            return
        now = time.time_ns()
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        start = stamp or now
        times = [start + d.sec * 1_000_000_000 + d.nanosec for d in (p.time_from_start for p in msg.points)]
        traj[0] = (now, list(command), times, [list(p.positions) for p in msg.points])
        if first_command[0] == math.inf:
            first_command[0] = time.monotonic()
            log.info(f"first trajectory: {len(msg.points)} points")

    def sample_trajectory() -> None:
        if traj[0] is None:
            return
        received, before, times, points = traj[0]
        now = time.time_ns()
        k = bisect.bisect_right(times, now)
        if k >= len(times):
            command[:] = points[-1]
            return
        t_a, p_a = (received, before) if k == 0 else (times[k - 1], points[k - 1])
        t_b, p_b = times[k], points[k]
        f = 1.0 if t_b <= t_a else min(max((now - t_a) / (t_b - t_a), 0.0), 1.0)
        command[:] = [a + (b - a) * f for a, b in zip(p_a, p_b, strict=True)]

    homing = rclpy.create_node("homing_controller") if args.homing or args.homing_silent else None

    def on_home(_req: Trigger.Request, resp: Trigger.Response) -> Trigger.Response:
        command[:] = [0.0] * len(joints)  # at the switches: the joints' zero
        state[:] = [0.0] * len(joints)
        last_msg[0], traj[0] = None, None  # the controller's last command is no longer in force
        resp.success, resp.message = True, f"homed {', '.join(joints)}"
        log.info(resp.message)
        return resp

    async def never_answer(_req: Trigger.Request, resp: Trigger.Response) -> Trigger.Response:
        await Future()  # never done: the call is never answered
        return resp

    if homing is not None:
        homing.create_service(Trigger, "~/home", never_answer if args.homing_silent else on_home)
    reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    if args.interface == "trajectory":
        ctrl.create_subscription(JointTrajectory, "~/joint_trajectory", on_trajectory, reliable)
    else:
        ctrl.create_subscription(Float64MultiArray, "~/commands", on_commands, reliable)
    pub = jsb.create_publisher(JointState, "joint_states", reliable)
    # the load cell's broadcaster (and a neighbour on its topic): the wire's tension
    fts = rclpy.create_node(args.load_cell) if args.load_cell else None
    impostor = rclpy.create_node(args.impostor) if args.impostor and fts is not None else None
    pub_wrench = fts.create_publisher(WrenchStamped, "~/wrench", reliable) if fts is not None else None
    pub_impostor = (
        impostor.create_publisher(WrenchStamped, f"{args.load_cell}/wrench", reliable)
        if impostor is not None
        else None
    )
    drop_joint, _, drop_at = args.tension_drop.partition("=")
    broke = [False]

    def wrench(force: float, stamp: Any) -> WrenchStamped:
        msg = WrenchStamped()
        msg.header.stamp = stamp
        msg.header.frame_id = "load_cell"
        msg.wrench.force.x = force
        return msg

    dt = 1.0 / args.rate
    last = [time.monotonic()]

    def update() -> None:
        now = time.monotonic()
        period, last[0] = now - last[0], now
        # read: the mock copies commands into states (with the extras of this stand-in)
        for i, j in enumerate(joints):
            before = state[i]
            if j in args.stuck:
                pass
            elif j in lag:
                state[i] += (command[i] + offset.get(j, 0.0) - state[i]) * (1 - math.exp(-period / lag[j]))
            else:
                state[i] = command[i] + offset.get(j, 0.0)
            velocity[i] = (state[i] - before) / period if period > 0 else 0.0
        # update: the broadcaster publishes the states, the forward controller writes its command
        if now - first_command[0] < args.silent_after:
            measured = list(state)
            if now - first_command[0] >= args.corrupt_after:
                measured = [args.corrupt_value] * len(joints)
            msg = JointState(
                name=joints, position=measured, velocity=list(velocity), effort=[0.0] * len(joints)
            )
            msg.header.stamp = cm.get_clock().now().to_msg()
            pub.publish(msg)
        if pub_wrench is not None:
            stamp = cm.get_clock().now().to_msg()
            if drop_joint and state[joints.index(drop_joint)] >= float(drop_at):
                broke[0] = True
            if now - first_command[0] >= args.tension_drop_after:
                broke[0] = True
            pub_wrench.publish(wrench(0.0 if broke[0] else args.tension, stamp))
            if pub_impostor is not None:
                pub_impostor.publish(wrench(0.0, stamp))
        if args.interface == "trajectory":
            sample_trajectory()
        elif last_msg[0] is not None:
            command[:] = last_msg[0]

    cm.create_timer(dt, update, clock=Clock(clock_type=ClockType.STEADY_TIME))
    ex = SingleThreadedExecutor()
    nodes = [n for n in (cm, ctrl, jsb, homing, fts, impostor) if n is not None]
    for n in nodes:
        ex.add_node(n)
    cm.get_logger().info(f"stand-in up: joints {joints}, {args.controller}, {args.rate:g} Hz, {policy}")
    try:
        ex.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        for n in nodes:
            n.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
