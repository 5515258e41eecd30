"""The cell's states and event kinds as types (ROS-free).

Each enum's values are exactly the wire strings docs/CONTRACT.md lists (a
test parses the document and compares). They are :class:`enum.StrEnum`: a
member is its string (``CellState.RUNNING == "running"``, ``json.dumps`` and
``KeyValue(value=...)`` take it as it is), so code on the wire side needs no
conversion, and a value received is read back with ``CellState(text)``
(ValueError for anything else).
"""

from __future__ import annotations

from enum import StrEnum

__all__ = [
    "FINAL_JOB_STATES",
    "LASTING",
    "NOT_READY",
    "CellState",
    "EventKind",
    "EventSource",
    "JobState",
    "ReadyState",
    "asks_again",
]


class CellState(StrEnum):
    """The ``state`` of ``winder/state`` (CONTRACT.md §3.6)."""

    IDLE = "idle"  #: node start
    RUNNING = "running"  #: a run accepted; after a resume or a programmed stop
    PAUSING = "pausing"  #: braking for a pause (from its ``t_ns``)
    PAUSED = "paused"  #: at rest: a pause's ``t_rest_ns``, or a programmed stop
    ABORTING = "aborting"  #: braking for an abort (from its ``t_ns``)
    DONE = "done"  #: the run ended complete
    ABORTED = "aborted"  #: the run ended at rest by an abort
    FAILED = "failed"  #: the run ended incomplete otherwise


class JobState(StrEnum):
    """The ``state`` of every node's ``"<node>: job"`` status (CONTRACT.md §3.7)."""

    IDLE = "idle"  #: no run yet
    RUNNING = "running"  #: a run in progress
    PAUSING = "pausing"  #: braking for a pause
    PAUSED = "paused"  #: at rest (a pause, or a programmed stop)
    ABORTING = "aborting"  #: braking for an abort
    STALLED = "stalled"  #: running, but its step stream stopped
    DONE = "done"  #: the last run ended complete
    ABORTED = "aborted"  #: ended by an abort, the axes at rest
    INCOMPLETE = "incomplete"  #: ended short otherwise (stalled for good, cut off...)
    BLOCKED = "blocked"  #: the node's settings are refused, it takes no run


class ReadyState(StrEnum):
    """A ``value`` of the start handshake on ``winder/ready`` (CONTRACT.md §3.4)."""

    READY = "ready"  #: idle, its input stream connected
    WAITING = "waiting"  #: its input stream not connected yet
    BUSY = "busy"  #: in a run
    BLOCKED = "blocked"  #: its settings refused
    INACTIVE = "inactive"  #: a managed node not active


class EventKind(StrEnum):
    """The ``event`` of a ``winder/control`` message (CONTRACT.md §3.3)."""

    PAUSE = "pause"
    RESUME = "resume"
    ABORT = "abort"
    OVERRIDE = "override"

    @property
    def stops(self) -> bool:
        """A pause or an abort: the axes brake to rest."""
        return self in (EventKind.PAUSE, EventKind.ABORT)


class EventSource(StrEnum):
    """The ``source`` of a ``winder/control`` event (CONTRACT.md §3.3)."""

    CALL = "call"  #: a service, or a ``feed_override`` set during the run
    SCHEDULE = "schedule"  #: the job's ``schedule``
    SETTING = "setting"  #: a ``feed_override`` != 1 in force at the run's start


#: the job states a consumer's final report ends a run with (CONTRACT.md §3.7)
FINAL_JOB_STATES = (JobState.DONE, JobState.ABORTED, JobState.INCOMPLETE)

#: the start replies that mean "ask again": a node of the cell is still connecting
NOT_READY = "job not started: not ready"
#: states on winder/ready that asking again does not change (an orchestrator's, or a setting's)
LASTING = (" inactive", " blocked")


def asks_again(reason: str) -> bool:
    """Whether a refused start is worth asking again: the cell is only not
    ready yet (its nodes still finding each other), not inactive or blocked."""
    return reason.startswith(NOT_READY) and not any(word in reason for word in LASTING)
