"""Who may change a run, ROS-free: which of the cell's roles owns each topic,
how a role is recognised on the graph, and the count of what came from
anyone else (docs/SECURITY.md). :class:`winder.ros.peers.Peers` applies it.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass, field

from winder.contract.topic_table import ROLES, TOPICS

__all__ = ["OTHER_PROCESS", "OWNERS", "ROLE_NAMES", "SHOWN", "SIGNS", "Intruders", "without_senders"]

#: The role whose node alone may publish each of the cell's topics that a
#: node acts on (``winder/ready`` is owned by the role its key names, a
#: ``/diagnostics`` status by the node its name names).
OWNERS = {t.name: t.owner for t in TOPICS if t.trusted}

#: The role whose node alone may publish each topic a live view shows
#: (``winder view``, ``winder run --foxglove``): those of :data:`OWNERS`, and
#: the consumer's joint states, joint commands, wire tension, final reports
#: and clock, which no node of the cell acts on. (A ``/diagnostics`` status:
#: the node it names.)
SHOWN = {t.name: t.owner for t in TOPICS if t.owner and (t.trusted or t.shown)}

#: How each role shows on the graph, in the cell's namespace: the topics its
#: node publishes, and those it reads. A node that merely publishes on a
#: cell's topic (a forger, ``winder play``) plays no part; two nodes that
#: both look like one role make the cell refuse to start until one leaves
#: (:class:`winder.ros.peers.Peers`). ``winder resim`` plays the interp and
#: the profile node at once and declares both parts' endpoints.
SIGNS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    role: (
        tuple(t.name for t in TOPICS if t.published_sign and t.owner == role),
        tuple(t.name for t in TOPICS if t.read_sign == role),
    )
    for role in ROLES
}

ROLE_NAMES = {"interp": "interp node", "profile": "profile node", "consumer": "step consumer"}

#: what follows a refused sender's name when it is named like the cell's own node
#: in that role but runs in another process (another cell's, an impersonator)
OTHER_PROCESS = " (other process)"


@dataclass
class Intruders:
    """Messages refused, per foreign sender and topic."""

    counts: dict[tuple[str, str], int] = field(default_factory=dict)

    def count(self, sender: str, topic: str) -> bool:
        """Count one refused message; True the first time this sender is
        refused at all (the moment to report it)."""
        first = not any(s == sender for s, _ in self.counts)
        self.counts[sender, topic] = self.counts.get((sender, topic), 0) + 1
        return first

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def senders(self) -> list[str]:
        return sorted({s for s, _ in self.counts})

    def summary(self) -> str:
        """``"/intruder (12 on /winder/control)"``, one entry per sender, or ""."""
        parts = []
        for sender in self.senders():
            topics = [(t, n) for (s, t), n in sorted(self.counts.items()) if s == sender]
            parts.append(f"{sender} ({', '.join(f'{n} on {t}' for t, n in topics)})")
        return "; ".join(parts)


def without_senders(summary: str, senders: Collection[str]) -> str:
    """An :meth:`Intruders.summary` text without the entries of ``senders``
    (fully qualified node names: the cell's own nodes, which a discovery
    race may have had refused); an entry of a node named like one of them in
    another process (:data:`OTHER_PROCESS`) stays."""
    kept = []
    for entry in summary.split("; ") if summary else []:
        name, _, rest = entry.partition(" ")
        if name in senders and not (" " + rest).startswith(OTHER_PROCESS):
            continue
        kept.append(entry)
    return "; ".join(kept)
