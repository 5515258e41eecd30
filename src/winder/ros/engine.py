"""The execution half of a consumer: what runs the accepted steps.

A consumer node is a :class:`winder.ros.consumer.StepConsumer` (the contract
half: handshake, stream checks, receipts, operator events, stops, the stall
watch, reports, the bag) holding one :class:`Engine`, which executes the
rows the contract half accepted. The simulator (``winder_sim``), the
ros2_control bridge (``winder_bridge``) and :class:`winder.ros.driver.DriveEngine`
(the paced clock around a hardware driver's few-method
:class:`winder.ros.driver.Backend`) are engines. An engine sees the run
through :class:`RunPort` alone, a handful of questions and reports, and
never the consumer's books; it gets the node for its own publishers,
timers and services.

Only :meth:`Engine.execute` is required. A driver author writes a
:class:`winder.ros.driver.Backend` instead (begin, write, read), and never
an engine: the drive engine owns the pacing, the clock and the settling.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from rclpy.node import Node

    from winder.contract.stream import JobPlan
    from winder.ros.peers import Peers

__all__ = ["Engine", "RunPort"]


class RunPort(Protocol):
    """What an engine may know of the run and tell the consumer; the
    consumer (:class:`winder.ros.consumer.StepConsumer`) implements it."""

    #: the running run's description; None between runs
    plan: JobPlan | None
    #: every step is executed (or the abort's rest reached): the axes settle
    finishing: bool
    #: execution time reached since the run's start (ns)
    t_ns: int
    #: who sent what on the graph (the cell's own nodes: winder.ros.peers)
    peers: Peers

    @property
    def last_step_ns(self) -> int:
        """The time of the last step accepted, as the stream timed it (ns; -1: none yet)."""
        ...

    @property
    def at_rest(self) -> bool:
        """Paused by the operator, every step up to the rest executed."""
        ...

    def values(self) -> dict[str, Any]:
        """The node's settings in force."""
        ...

    def rest_ns(self) -> int | None:
        """The run time a pause brings the axes to rest at; None: no pause holds."""
        ...

    def transitions_ahead(self) -> bool:
        """Operator states are booked ahead of execution (a pause's rest after its last step)."""
        ...

    def abort_booked(self) -> bool:
        """The run is being aborted."""
        ...

    def chunks_waiting(self) -> bool:
        """Chunks were received and are not handed over yet."""
        ...

    def run_ramp(self) -> dict[str, Any] | None:
        """The ramp this run is timed with, as its profile node published it
        on winder/profile_config (its settings and ``feed_override``); None
        until this run's has come. ValueError if what came does not parse."""
        ...

    def executed(self, n: int) -> None:
        """``n`` more steps of the run are executed."""
        ...

    def reached(self, t_ns: int) -> None:
        """Execution reached ``t_ns``: the run's states due by then are announced."""
        ...

    def receipt(self) -> None:
        """Tell the interp node what is executed now (winder/progress)."""
        ...

    def settle_if_complete(self) -> None:
        """Every step executed or missing, nothing held: the engine is asked to settle."""
        ...

    def finish(self, complete: bool) -> None:
        """Close the run now (a fault: incomplete)."""
        ...

    def pump(self) -> None:
        """Do the due work now (from a timer of the engine's own)."""
        ...

    def record(self, key: str, t_ns: int, data: bytes, *, exact: bool = False) -> None:
        """One message into the run's bag (key: one of the consumer's or the engine's topics)."""
        ...

    def bag_topic(self, key: str) -> str:
        """The topic a bag key records."""
        ...

    def set_bag_topic(self, key: str, name: str, kind: str) -> None:
        """A bag key of the engine records another topic (from the next run's bag on)."""
        ...

    def publish_status(
        self, task: str, level: int, text: str, values: dict[str, object], *, t_ns: int | None = None
    ) -> None:
        """A status of the node on /diagnostics, into the bag too."""
        ...

    def error(self, why: str) -> None:
        """An error of the run: logged, a ``stream`` ERROR, counted in the report."""
        ...


class Engine:
    """What executes a consumer's accepted rows (see the module doc).
    :meth:`attach` hands it the node and the run; the hooks are called from
    the node's executor, one at a time."""

    #: whether :meth:`begin`'s configuration is published on winder/sim_config
    configures = True
    #: s between pumps while work waits on the clock (an engine with a pacing
    #: thread of its own needs the pump less often)
    pump_period = 0.005
    #: whether each pump (a chunk's too) restarts the pump's period, so that
    #: the timer fires only ``pump_period`` after the last pump: an engine
    #: whose pump is a bookkeeping round, not its clock, wakes for the step
    #: chunks alone while they come often enough
    pump_from_last = False

    node: Node
    run: RunPort

    def attach(self, node: Node, run: RunPort) -> None:
        """The engine joins its node (before the node's lifecycle starts):
        make publishers, timers and services here."""
        self.node, self.run = node, run

    def begin(self, plan: JobPlan, values: dict[str, Any]) -> dict[str, object] | None:
        """A run starts with these settings; the winder/sim_config document, or None."""
        return None

    def execute(self, rows: npt.NDArray[np.int64]) -> None:
        """Execute accepted timed rows ``[t_ns, segment, axes...]`` (now or when
        due), telling the run :meth:`RunPort.executed` and :meth:`RunPort.reached`."""
        raise NotImplementedError

    def accepts_more(self) -> bool:
        """Whether the next chunk may be handed to :meth:`execute` now."""
        return True

    def batches(self) -> bool:
        """Whether chunks are gathered and handed over many at a time (as fast as possible)."""
        return False

    def holding(self) -> bool:
        """Accepted rows wait in the engine, not executed yet."""
        return False

    def work(self) -> None:
        """The engine's due work, on every pump (pacing out what is due)."""

    def pending(self) -> bool:
        """Work waits on the clock: keep pumping every ``pump_period``; no stall."""
        return False

    def checked(self, seg: int, rows: npt.NDArray[np.int64]) -> None:
        """Rows accepted, before they are executed (the simulator measures their deviation)."""

    def settle(self, until_ns: int) -> None:
        """No more steps come: bring the axes to rest until ``until_ns``."""

    def flush(self) -> None:
        """A new run arrives while this one settles: finish what is pending at once."""

    def resume_pacing(self) -> None:
        """A programmed stop that waited for ``~/resume`` got its steps: pacing goes on from now."""

    def paces(self) -> bool:
        """Whether execution follows the wall clock now (a real-time run)."""
        return False

    def earliest_step_ns(self) -> int | None:
        """The engine's clock (ns since the run's start): the earliest time it
        can still execute a step at. A step timed before it is executed at it,
        counted late and reported (a drive cannot go back in time). None: it
        executes a step at any time given (the default)."""
        return None

    def missing(self) -> str:
        """Why it cannot take a run now (its hardware is not there), in words;
        "" if it can. Announced as "waiting"."""
        return ""

    def profile_config_heard(self) -> None:
        """A winder/profile_config came (:meth:`RunPort.profile_config`)."""

    def closing(self) -> None:
        """The run is about to close: stop executing, account for what was
        executed, record what is pending."""

    def complete(self) -> bool:
        """Whether a run whose steps are all executed may close complete
        (a drive: its axes in position, no driver error)."""
        return True

    def faults(self) -> str:
        """What went wrong in a run that executed every step (the simulator:
        lost steps), in words; "" if nothing."""
        return ""

    def unrecorded(self) -> frozenset[str]:
        """The bag keys of its own this run will not write (its bag does not
        name those topics): asked once the run has begun."""
        return frozenset()

    def details(self) -> dict[str, object]:
        """The engine's own status keys (after the contract's)."""
        return {}

    def simulated(self) -> bool:
        """Whether the axes it drives are simulated (a simulator, a drive's
        twin): its runs' parts are kept apart from real ones (docs/PARTS.md)."""
        return False

    def end(self) -> None:
        """The run closed and is reported: release its resources."""

    def shutdown(self) -> bool:
        """The node goes down (after the run, if any, is closed): stop threads.
        False: a thread of it still runs (and holds the node)."""
        return True
