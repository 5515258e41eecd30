"""Who does what in a cell, from the ROS graph: nodes found by their part in
the cell (the topics they read and write), never by their node name, which a
launch may remap (``sim_node --ros-args -r __node:=axes``).

* the **consumer** of a cell in ``/ns``: the node in ``/ns`` that subscribes
  to ``/ns/winder/step_times`` and acknowledges on ``/ns/winder/progress``
  (the sim node, a ros2_control bridge, a hardware driver). A recorder that
  subscribes to every topic is no consumer: it acknowledges nothing.
* the **profile node**: the node in ``/ns`` that subscribes to
  ``/ns/winder/steps`` and publishes ``/ns/winder/step_times``.

Each function returns ``(name, namespace)`` pairs, sorted, without the
calling node itself; the graph is what this process has discovered so far,
so a caller polls until the node it waits for shows up.
"""

from __future__ import annotations

from rclpy.node import Node

from winder.contract.topics import TOPIC_PROGRESS, TOPIC_STEP_TIMES, TOPIC_STEPS

__all__ = ["consumers", "fully_qualified", "profile_nodes"]


def _ns(namespace: str) -> str:
    ns = namespace.strip("/")
    return "/" + ns if ns else "/"


def _endpoints(node: Node, namespace: str, topic: str, publishers: bool) -> set[tuple[str, str]]:
    """The nodes in ``namespace`` with a publisher (or a subscription) on the
    cell's ``topic``, but ``node`` itself."""
    ns = _ns(namespace)
    full = fully_qualified(topic, namespace)
    get = node.get_publishers_info_by_topic if publishers else node.get_subscriptions_info_by_topic
    infos = get(full)
    me = (node.get_name(), node.get_namespace())
    return {
        (info.node_name, info.node_namespace)
        for info in infos
        if info.node_namespace == ns and (info.node_name, info.node_namespace) != me
    }


def consumers(node: Node, namespace: str) -> list[tuple[str, str]]:
    """The step consumers of the cell in ``namespace`` on ``node``'s graph
    (normally one): subscribed to its ``winder/step_times``, publishing its
    ``winder/progress``."""
    readers = _endpoints(node, namespace, TOPIC_STEP_TIMES, publishers=False)
    return sorted(readers & _endpoints(node, namespace, TOPIC_PROGRESS, publishers=True))


def profile_nodes(node: Node, namespace: str) -> list[tuple[str, str]]:
    """The profile nodes of the cell in ``namespace`` (normally one):
    subscribed to its ``winder/steps``, publishing its ``winder/step_times``."""
    readers = _endpoints(node, namespace, TOPIC_STEPS, publishers=False)
    return sorted(readers & _endpoints(node, namespace, TOPIC_STEP_TIMES, publishers=True))


def fully_qualified(name: str, namespace: str) -> str:
    """``/ns/name`` (``/name`` in the root namespace): where a node's services
    are, or a cell's topic."""
    ns = namespace.strip("/")
    return f"/{ns}/{name}" if ns else f"/{name}"
