"""The QoS of every topic of the cell, chosen on purpose:

* job description, path and configs: reliable, transient-local, depth 1 - a
  late joiner (a recorder, Foxglove) still gets the current job;
* steps and step times: reliable, keep-all - every step matters, a slow reader
  holds the writer's history instead of losing samples;
* joint states / commands: reliable, depth 100;
* progress (diagnostic_msgs/KeyValue: job id, steps consumed), reliable depth
  100: the sim node's receipt that lets the interp node keep at most
  ``max_in_flight`` steps in the pipeline (memory stays bounded);
* operator events (``winder/control``): reliable, transient-local, depth
  100 - every event of a run reaches a reader that joins during it;
* ``/clock``: best-effort, depth 1 (what rclpy's time source subscribes with);
* ``/diagnostics``: reliable, depth 10 (as diagnostic_updater).
"""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

QOS_LATCHED = QoSProfile(
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
    history=HistoryPolicy.KEEP_LAST,
)
QOS_STREAM = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_ALL)
QOS_STATE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
QOS_CLOCK = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
QOS_DIAGNOSTICS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
QOS_EVENTS = QoSProfile(
    depth=100,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
    history=HistoryPolicy.KEEP_LAST,
)
