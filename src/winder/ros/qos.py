"""The cell's QoS profiles for rclpy, made from the ROS-free table in
:mod:`winder.contract.qos` (which says why each topic has the QoS it has)."""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from winder.contract import qos as table

__all__ = [
    "QOS_CLOCK",
    "QOS_DIAGNOSTICS",
    "QOS_EVENTS",
    "QOS_LATCHED",
    "QOS_LATCHED_READER",
    "QOS_STATE",
    "QOS_STREAM",
    "profile",
]


def profile(q: table.Qos) -> QoSProfile:
    """The rclpy profile of a :class:`winder.contract.qos.Qos`."""
    return QoSProfile(
        depth=q.depth,
        reliability=ReliabilityPolicy.RELIABLE if q.reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if q.transient_local else DurabilityPolicy.VOLATILE,
        history=HistoryPolicy.KEEP_ALL if q.keep_all else HistoryPolicy.KEEP_LAST,
    )


QOS_LATCHED = profile(table.LATCHED)
QOS_STREAM = profile(table.STREAM)
QOS_STATE = profile(table.STATE)
QOS_CLOCK = profile(table.CLOCK)
QOS_DIAGNOSTICS = profile(table.DIAGNOSTICS)
QOS_EVENTS = profile(table.EVENTS)

#: A cell node's reader of a latched topic with several writers (the cell's own
#: and strangers', whose messages it checks by sender: winder.ros.peers; the
#: handshake's roles on winder/ready): latched as the writers are, but deeper.
#: Keep-last counts the samples of every writer together, so at depth 1 a
#: stranger publishing every 50 ms replaced the cell's own job description in
#: the reader's queue before the node took it, and the run never started
#: (test_only_the_cell_acts); on winder/ready a consumer's "busy" was lost behind
#: the profile node's repeated "ready", and a start let through.
QOS_LATCHED_READER = QoSProfile(
    depth=10,
    reliability=QOS_LATCHED.reliability,
    durability=QOS_LATCHED.durability,
    history=HistoryPolicy.KEEP_LAST,
)
