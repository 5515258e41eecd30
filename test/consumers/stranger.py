"""A neighbour on the cell's ``joint_states``: a node that is not the
ros2_control joint_state_broadcaster publishes sensor_msgs/JointState for
the bridge's joints, cycling through ``--values`` (each message all joints
at one value: ``100,inf`` = a 100 rad jump, then infinity), at ``--rate`` Hz,
stamped now. test_bridge_node.py checks that it changes nothing.

    python stranger.py --joints a,b,c [--values 100,inf] [--rate 200] [--ros-args -r __node:=neighbour]
"""

from __future__ import annotations

import argparse
import sys

import rclpy
from _spin import spin_until_stopped
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState


def main() -> None:
    argv = rclpy.utilities.remove_ros_args(sys.argv)[1:]
    ap = argparse.ArgumentParser()
    ap.add_argument("--joints", required=True)
    ap.add_argument("--values", default="100,inf")
    ap.add_argument("--rate", type=float, default=200.0)
    args = ap.parse_args(argv)
    joints = args.joints.split(",")
    values = [float(v) for v in args.values.split(",")]
    rclpy.init(args=sys.argv)
    node = rclpy.create_node("neighbour")
    pub = node.create_publisher(
        JointState, "joint_states", QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    )
    sent = [0]

    def publish() -> None:
        x = values[sent[0] % len(values)]
        msg = JointState(name=joints, position=[x] * len(joints), velocity=[0.0] * len(joints))
        msg.header.stamp = node.get_clock().now().to_msg()
        pub.publish(msg)
        sent[0] += 1

    node.create_timer(1.0 / args.rate, publish)
    node.get_logger().info(f"neighbour up: {joints} at {values}, {args.rate:g} Hz")
    spin_until_stopped(node)


if __name__ == "__main__":
    main()
