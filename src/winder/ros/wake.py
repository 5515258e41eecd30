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
never took it for gone on their side of some writer. And a process held
while another started (a profile node stopped for 4 s, the interp node
started meanwhile) learnt the newcomer's endpoints once woken but never its
node names: it could not tell the cell's interp node, and said "waiting"
for as long as it was watched (measured: 40 s, a hold well inside the
lease). So every node watches which participants are on its graph (each
process' ``/rosout`` publisher): when one comes, new or back after it left,
it republishes its own discovery info for it. Each announcement, after a
hold as after a newcomer, is made at once and again :data:`AGAIN` s later:
the first may go out before the others have matched this participant anew
(they find it again only at its next announcement, up to 0.25 s after it
woke), and a reader matched after a sample was sent did not always get it
(a loaded CI: the cell still not ready 30 s after a 12 s hold). A newcomer
costs each node three small samples: ``winder ctl`` is one each time it
runs.

A hold past the lease (:data:`REJOIN`) is more than a republish can mend:
the node restarts its process (:mod:`winder.ros.rejoin`). That hold is
measured by a thread of its own (:class:`HoldClock`), which only a hold of
the whole process stops: a long callback delays the node's timers but not
the thread, nor the DDS threads that keep the participant alive, and
restarting for it would cut a run for nothing."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from diagnostic_msgs.msg import KeyValue
from rclpy.node import Node

from winder.ros.dds import ANNOUNCEMENT, LEASE
from winder.ros.timers import steady_timer

__all__ = ["AGAIN", "HELD", "REJOIN", "TICK", "HoldClock", "WakeWatch"]

#: s between two looks at the steady clock
TICK = 0.5
#: a gap longer than this (s) between two looks is a hold: half the lease of
#: winder's profile, so that every hold that may have cost the participant its
#: place on another's graph is taken for one (a republish costs one sample)
HELD = 5.0
#: a hold of the whole process longer than this (s) may have cost the participant
#: its place on the others' graphs for good: the lease less two announcements
#: (the last one before the hold may have gone out up to one period before it)
REJOIN = LEASE - 2 * ANNOUNCEMENT
#: s between two looks of the :class:`HoldClock` thread
HOLD_TICK = 0.25
#: the hidden topic of the throwaway publisher (never published on)
TOPIC = "~/_wake"
#: every node's log topic: a publisher of it in every process of a cell
ROSOUT = "/rosout"
#: s after a hold or a participant's coming (new or back) that the node announces itself again
AGAIN = (1.5, 5.0)
#: s a participant that left is remembered (a hold that long is said by the held node itself)
FORGET = 600.0
#: participants that left remembered at most
LEFT_KEPT = 256


class HoldClock(threading.Thread):
    """A thread that measures how long the whole process was held: the
    longest gap between two of its looks since :meth:`take` last asked."""

    def __init__(self) -> None:
        super().__init__(name="winder-hold-clock", daemon=True)
        self.lock = threading.Lock()
        self.longest = 0.0

    def run(self) -> None:
        last = time.monotonic()
        while True:
            time.sleep(HOLD_TICK)
            now = time.monotonic()
            with self.lock:
                self.longest = max(self.longest, now - last)
            last = now

    def take(self) -> float:
        """The longest gap (s) since the last call, and start anew."""
        with self.lock:
            longest, self.longest = self.longest, 0.0
        return longest


class WakeWatch:
    """Watches ``node``'s steady clock; after a hold of more than
    :data:`HELD` s it republishes the participant's discovery info, and
    after a hold of the whole process past :data:`REJOIN` it calls
    ``rejoin`` with the hold (s) instead."""

    def __init__(self, node: Node, rejoin: Callable[[float], None] | None = None) -> None:
        self.node = node
        self.rejoin = rejoin
        self.hold_clock = HoldClock()
        self.hold_clock.start()
        self.last = time.monotonic()
        self.present: set[bytes] = set()  # the participants on the graph at the last look
        #: those seen to leave it since, and when (steady s): forgotten after FORGET s, for every
        #: `winder ctl` call is a participant that comes and goes for good
        self.left: dict[bytes, float] = {}
        self.again_at: list[float] = []  # steady s of the announcements still to make
        self.looked = False  # the graph at the start is no newcomer
        self.timer = steady_timer(node, TICK, self._tick)

    def _tick(self) -> None:
        now = time.monotonic()
        gap, self.last = now - self.last, now
        held = self.hold_clock.take()
        if held > REJOIN and self.rejoin is not None:
            self.rejoin(held)
            return
        if gap > HELD:
            self.woke(gap)
        self.look()
        if self.again_at and now >= self.again_at[0]:
            self.again_at = [t for t in self.again_at if t > now]
            self.republish()

    def look(self) -> None:
        """A participant new on the graph, or back after it left: it may lack this one's node names."""
        present = {bytes(i.endpoint_gid)[:12] for i in self.node.get_publishers_info_by_topic(ROSOUT)}
        now = time.monotonic()
        back = {p for p in present if self.left.pop(p, None) is not None}
        new = present - self.present - back if self.looked else set()
        self.looked = True
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
        if back or new:
            self.announce(now)

    def woke(self, gap: float) -> None:
        """The node was held up for ``gap`` s: rejoin the graph."""
        self.node.get_logger().warning(
            f"no timer for {gap:.1f} s (held up, starved or a long callback): announcing this node to the "
            "graph again"
        )
        self.announce(time.monotonic())

    def announce(self, now: float) -> None:
        """Republish now, and again after each of :data:`AGAIN`."""
        self.republish()
        self.again_at = sorted({*self.again_at, *(now + a for a in AGAIN)})

    def republish(self) -> None:
        """Make rmw publish this participant's ``ros_discovery_info`` again."""
        pub = self.node.create_publisher(KeyValue, TOPIC, 1)
        self.node.destroy_publisher(pub)
