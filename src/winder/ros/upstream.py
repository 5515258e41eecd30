"""A consumer that stops a run on its own (a servo fault, a driver error)
tells the cell's profile node to abort it, so that the rest of the cell stops
sending its steps: they would otherwise still be on their way when the next
run starts, and chunks carry no run id (a run started right after a driver
error found its first chunk twice). ``bridge_node`` and
:class:`winder.ros.driver.DriverNode` use it."""

from __future__ import annotations

from typing import Any

from rclpy.client import Client
from rclpy.node import Node
from rclpy.task import Future
from std_srvs.srv import Trigger

from winder.ros.graph import fully_qualified
from winder.ros.peers import Peers
from winder.ros.timers import steady_timer

__all__ = ["ABORT_RETRY", "ABORT_TRIES", "ProfileAbort"]

#: s without an answer before the abort is asked again, and how many times at most
ABORT_RETRY = 1.0
ABORT_TRIES = 5


class ProfileAbort:
    """``~/abort`` of the cell's profile node, found by its role on the graph."""

    def __init__(self, node: Node, peers: Peers) -> None:
        self.node, self.peers = node, peers
        self.clients: dict[str, Client] = {}
        self.client: Client | None = None
        self.future: Future | None = None
        self.timer: Any = None
        self.tries = 0

    def find(self) -> Client | None:
        """The client of the profile node whose step times this node acts on
        (``peers.owner``: the one pinned, or the only one the graph shows; None
        while the graph shows none, or two and none pinned). Made early (at a
        run's start, or while idle), so that its replies match when a fault comes."""
        who = self.peers.owner("profile")
        if who is None:
            return self.client
        service = fully_qualified(who.name, who.namespace) + "/abort"
        if service not in self.clients:
            self.clients[service] = self.node.create_client(Trigger, service)
        self.client = self.clients[service]
        return self.client

    def ask(self, topic: str) -> None:
        """Ask the profile node (the one publishing ``topic``) to abort the run."""
        client = self.client or self.find()
        logger = self.node.get_logger()
        if client is None:
            where = self.node.get_namespace()
            logger.error(f"no profile node in {where} (none publishes {topic}): nothing to abort")
            return
        if not client.service_is_ready():
            logger.warning(f"{client.srv_name} not ready: the abort request may be lost")
        self.tries = 0
        self._ask(client)

    def _ask(self, client: Client) -> None:
        """One abort request; asked again after ABORT_RETRY s without an answer
        (a DDS service may drop a reply while its response topic still matches)."""
        self._drop_timer()
        if self.future is not None and not self.future.done():
            client.remove_pending_request(self.future)
            if self.tries >= ABORT_TRIES:
                self.node.get_logger().error(f"{client.srv_name}: no answer to {ABORT_TRIES} abort requests")
                return
        self.tries += 1
        future = client.call_async(Trigger.Request())
        future.add_done_callback(lambda f: self._answered(client.srv_name, f))
        self.future = future
        self.timer = steady_timer(self.node, ABORT_RETRY, lambda: self._ask(client))

    def _drop_timer(self) -> None:
        if self.timer is not None:
            self.node.destroy_timer(self.timer)
            self.timer = None

    def _answered(self, service: str, future: Future) -> None:
        self._drop_timer()
        logger = self.node.get_logger()
        resp = future.result()
        if resp is None:
            logger.error(f"{service}: no answer")
        elif resp.success:
            logger.info(f"{service}: {resp.message}")
        else:
            logger.warning(f"{service} refused: {resp.message}")
