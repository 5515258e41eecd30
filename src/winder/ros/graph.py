"""Who does what in a cell, from the ROS graph: nodes found by their part in
the cell (the topics they read and write), never by their node name, which a
launch may remap (``sim_node --ros-args -r __node:=axes``).

* the **consumer** of a cell in ``/ns``: the node in ``/ns`` that subscribes
  to ``/ns/winder/step_times`` and acknowledges on ``/ns/winder/progress``
  (the sim node, a ros2_control bridge, a hardware driver). A recorder that
  subscribes to every topic is no consumer: it acknowledges nothing.
* the **profile node**: the node in ``/ns`` that publishes
  ``/ns/winder/step_times``, ``/ns/winder/control`` and ``/ns/winder/path``.

The parts are :data:`winder.contract.trust.SIGNS`: the same that decide whose
messages a node acts on (:mod:`winder.ros.peers`).

Each function returns ``(name, namespace)`` pairs, sorted, without the
calling node itself; the graph is what this process has discovered so far,
so a caller polls until the node it waits for shows up.
"""

from __future__ import annotations

import os
from typing import NamedTuple

from rclpy.node import Node

from winder.contract.trust import SIGNS
from winder.ros.dds import DISCOVERY_SERVER_KEY

__all__ = [
    "Who",
    "consumers",
    "fully_qualified",
    "participant",
    "profile_nodes",
    "publishers_by_gid",
    "role_holders",
]

#: what rmw puts for a node's name or namespace it has not learned yet
UNKNOWN = "_UNKNOWN_"


class Who(NamedTuple):
    """A node on the graph: its name, its namespace and its DDS participant
    (the first 12 bytes of its endpoints' GIDs, hex). Two nodes of one name
    in two processes (a second cell started in the same namespace) are two
    participants: never taken for one another."""

    name: str
    namespace: str
    participant: str

    @property
    def fq(self) -> str:
        return fully_qualified(self.name, self.namespace)


def participant(gid: bytes | list[int]) -> str:
    """The DDS participant (process) of an endpoint's GID: its GUID prefix."""
    return bytes(gid)[:12].hex()


def publishers_by_gid(node: Node, topic: str) -> dict[bytes, Who]:
    """The publishers of ``topic`` (fully qualified) the graph names, by their
    endpoint GID. An endpoint is on the graph before its node's name is (rmw
    says _NODE_NAME_UNKNOWN_ until the node's discovery info comes): such an
    endpoint is left out, to be asked for again."""
    out = {}
    for info in node.get_publishers_info_by_topic(topic):
        if UNKNOWN not in info.node_name and UNKNOWN not in info.node_namespace:
            gid = bytes(info.endpoint_gid)
            out[gid] = Who(info.node_name, info.node_namespace, participant(gid))
    return out


def _ns(namespace: str) -> str:
    ns = namespace.strip("/")
    return "/" + ns if ns else "/"


def _endpoints(node: Node, namespace: str, topic: str, publishers: bool) -> set[Who]:
    """The nodes in ``namespace`` with a publisher (or a subscription) on the
    cell's ``topic`` (names the graph has learned only)."""
    ns = _ns(namespace)
    get = node.get_publishers_info_by_topic if publishers else node.get_subscriptions_info_by_topic
    return {
        Who(i.node_name, i.node_namespace, participant(i.endpoint_gid))
        for i in get(fully_qualified(topic, namespace))
        if i.node_namespace == ns
    }


def role_holders(node: Node, namespace: str, role: str) -> set[Who]:
    """The nodes in ``namespace`` that play ``role`` by their endpoints
    (:data:`winder.contract.trust.SIGNS`), ``node`` itself included. A topic
    of the part on which the graph shows no endpoint at all, anywhere, is,
    behind a discovery server (``ROS_DISCOVERY_SERVER``), one this process
    cannot see (the server tells a participant only of the topics it uses
    itself): it is left out of the test there, not failed. Elsewhere every
    topic of the part counts."""
    publishes, reads = SIGNS[role]
    partial = bool(os.environ.get(DISCOVERY_SERVER_KEY))  # a discovery server's client sees part of the graph
    found: list[set[Who]] = []
    for topics, publishers in ((publishes, True), (reads, False)):
        for topic in topics:
            full = fully_qualified(topic, namespace)
            if partial and node.count_publishers(full) + node.count_subscribers(full) == 0:
                continue
            found.append(_endpoints(node, namespace, topic, publishers))
    return set.intersection(*found) if found else set()


def _others(node: Node, namespace: str, role: str) -> list[tuple[str, str]]:
    me = (node.get_name(), node.get_namespace())
    return sorted({(w.name, w.namespace) for w in role_holders(node, namespace, role)} - {me})


def consumers(node: Node, namespace: str) -> list[tuple[str, str]]:
    """The step consumers of the cell in ``namespace`` on ``node``'s graph
    (normally one): subscribed to its ``winder/step_times``, publishing its
    ``winder/progress``."""
    return _others(node, namespace, "consumer")


def profile_nodes(node: Node, namespace: str) -> list[tuple[str, str]]:
    """The profile nodes of the cell in ``namespace`` (normally one):
    publishing its ``winder/step_times``, ``winder/control`` and ``winder/path``."""
    return _others(node, namespace, "profile")


def fully_qualified(name: str, namespace: str) -> str:
    """``/ns/name`` (``/name`` in the root namespace): where a node's services
    are, or a cell's topic."""
    ns = namespace.strip("/")
    return f"/{ns}/{name}" if ns else f"/{name}"
