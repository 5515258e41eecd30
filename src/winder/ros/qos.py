"""The cell's QoS profiles for rclpy, made from the ROS-free table in
:mod:`winder.contract.qos` (which says why each topic has the QoS it has)."""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from winder.contract import qos as table

__all__ = ["QOS_CLOCK", "QOS_DIAGNOSTICS", "QOS_EVENTS", "QOS_LATCHED", "QOS_STATE", "QOS_STREAM", "profile"]


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
