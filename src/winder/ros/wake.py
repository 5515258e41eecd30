"""A node that was held up (SIGSTOP, a starved host, a debugger) and the
graph it wakes into.

A DDS participant silent for its lease (10 s in winder's profile) is dropped
by the others; when it speaks again they discover it anew. But the held
process itself may never have dropped them: its reliable writers still take
their readers for matched and acknowledged, and send them none of what they
already acknowledged. What they miss is rmw's ``ros_discovery_info`` sample
(the node names of the participant's endpoints, latched): its endpoints came
back on the others' graphs under ``_NODE_NAME_UNKNOWN_``, so no node could
tell the cell's profile node or consumer any more (``winder.ros.graph``),
and an idle cell refused every start until a node was restarted (issue 53).

:class:`WakeWatch` sees the hold as a gap in its steady timer, and makes rmw
publish that sample again (it does so whenever the participant's entities
change: a publisher made and destroyed), which every reader, matched anew or
not, takes.

The other side of the same hold: the held process may itself have dropped
the others on waking (its lease timers ran before the announcements waiting
in its sockets) and found them again, while they, having dropped it too,
never took it for gone on their side of some writer. So every node also
watches which participants are on its graph (each process' ``/rosout``
publisher): when one it saw leave comes back, it republishes its own
discovery info for it."""

from __future__ import annotations

import time

from diagnostic_msgs.msg import KeyValue
from rclpy.node import Node

from winder.ros.timers import steady_timer

__all__ = ["HELD", "TICK", "WakeWatch"]

#: s between two looks at the steady clock
TICK = 0.5
#: a gap longer than this (s) between two looks is a hold: half the lease of
#: winder's profile, so that every hold that may have cost the participant its
#: place on another's graph is taken for one (a republish costs one sample)
HELD = 5.0
#: the hidden topic of the throwaway publisher (never published on)
TOPIC = "~/_wake"
#: every node's log topic: a publisher of it in every process of a cell
ROSOUT = "/rosout"
#: s a participant that left is remembered (a hold that long is said by the held node itself)
FORGET = 600.0
#: participants that left remembered at most
LEFT_KEPT = 256


class WakeWatch:
    """Watches ``node``'s steady clock; after a hold of more than
    :data:`HELD` s it republishes the participant's discovery info."""

    def __init__(self, node: Node) -> None:
        self.node = node
        self.last = time.monotonic()
        self.present: set[bytes] = set()  # the participants on the graph at the last look
        #: those seen to leave it since, and when (steady s): forgotten after FORGET s, for every
        #: `winder ctl` call is a participant that comes and goes for good
        self.left: dict[bytes, float] = {}
        self.timer = steady_timer(node, TICK, self._tick)

    def _tick(self) -> None:
        now = time.monotonic()
        gap, self.last = now - self.last, now
        if gap > HELD:
            self.woke(gap)
        self.look()

    def look(self) -> None:
        """A participant back on the graph after it left: it may lack this one's node names."""
        present = {bytes(i.endpoint_gid)[:12] for i in self.node.get_publishers_info_by_topic(ROSOUT)}
        now = time.monotonic()
        back = {p for p in present if self.left.pop(p, None) is not None}
        for gone in self.present - present:
            self.left[gone] = now
        if len(self.left) > LEFT_KEPT or (self.left and now - next(iter(self.left.values())) > FORGET):
            self.left = {p: t for p, t in self.left.items() if now - t <= FORGET}
            while len(self.left) > LEFT_KEPT:
                self.left.pop(next(iter(self.left)))
        self.present = present
        if back:
            self.node.get_logger().info(
                f"{len(back)} participant(s) back on the graph after a silence: announcing this node again"
            )
            self.republish()

    def woke(self, gap: float) -> None:
        """The node was held up for ``gap`` s: rejoin the graph."""
        self.node.get_logger().warning(
            f"no timer for {gap:.1f} s (held up, starved or a long callback): announcing this node to the "
            "graph again"
        )
        self.republish()

    def republish(self) -> None:
        """Make rmw publish this participant's ``ros_discovery_info`` again."""
        pub = self.node.create_publisher(KeyValue, TOPIC, 1)
        self.node.destroy_publisher(pub)
