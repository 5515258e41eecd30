"""The QoS of every topic of the cell, ROS-free: what the nodes offer
(:mod:`winder.ros.qos` turns these into rclpy profiles), what a bag records
as each topic's ``offered_qos_profiles`` (:mod:`winder.record.bag`) and what
``winder play`` offers again.

* job description, path, configs and the cell state: reliable,
  transient-local, depth 1 - a late joiner (a recorder, Foxglove) still gets
  the current job;
* steps and step times: reliable, keep-all - every step matters, a slow
  reader holds the writer's history instead of losing samples;
* joint states / commands, progress: reliable, depth 100;
* operator events (``winder/control``): reliable, transient-local, depth
  100 - every event of a run reaches a reader that joins during it;
* the simulated clock: best-effort, depth 1 (what rclpy's time source
  subscribes with);
* ``/diagnostics``: reliable, depth 10 (as diagnostic_updater).
"""

from __future__ import annotations

from dataclasses import dataclass

from winder.contract.topic_table import TOPICS

__all__ = [
    "CLOCK",
    "DIAGNOSTICS",
    "EVENTS",
    "LATCHED",
    "PROFILES",
    "STATE",
    "STREAM",
    "TOPIC_QOS",
    "Qos",
    "qos_of",
]


@dataclass(frozen=True)
class Qos:
    """The QoS policies winder sets; the others keep their ROS defaults."""

    reliable: bool
    transient_local: bool
    keep_all: bool
    depth: int

    def describe(self) -> str:
        """``reliable, transient-local, keep-last 1``: the words of the topic table (docs/INTEGRATING.md)."""
        return ", ".join(
            (
                "reliable" if self.reliable else "best-effort",
                "transient-local" if self.transient_local else "volatile",
                "keep-all" if self.keep_all else f"keep-last {self.depth}",
            )
        )


LATCHED = Qos(reliable=True, transient_local=True, keep_all=False, depth=1)
STREAM = Qos(reliable=True, transient_local=False, keep_all=True, depth=1000)
STATE = Qos(reliable=True, transient_local=False, keep_all=False, depth=100)
CLOCK = Qos(reliable=False, transient_local=False, keep_all=False, depth=1)
DIAGNOSTICS = Qos(reliable=True, transient_local=False, keep_all=False, depth=10)
EVENTS = Qos(reliable=True, transient_local=True, keep_all=False, depth=100)

#: each profile by the name the topic table (winder.contract.topic_table) gives it
PROFILES: dict[str, Qos] = {
    "latched": LATCHED,
    "stream": STREAM,
    "state": STATE,
    "clock": CLOCK,
    "diagnostics": DIAGNOSTICS,
    "events": EVENTS,
}

#: each topic of the cell (relative names, as in winder.contract.topics) and its QoS
TOPIC_QOS: dict[str, Qos] = {t.name: PROFILES[t.qos] for t in TOPICS}


def qos_of(topic: str) -> Qos | None:
    """The QoS of a cell topic by its full name in any namespace
    (``/cell1/winder/job``), None for a topic that is not the cell's."""
    if topic in TOPIC_QOS:
        return TOPIC_QOS[topic]
    for name, qos in TOPIC_QOS.items():
        if not name.startswith("/") and (topic == "/" + name or topic.endswith("/" + name)):
            return qos
    return None
