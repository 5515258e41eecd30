"""A hardware driver as a :class:`Backend`: a few methods, and a node that
does the rest.

A drive behind the cell needs to be told two things - a run starts here,
and these steps are due now - and to tell one back: where its axes are.
That is the whole of :class:`Backend`, modelled on ros2_control's
``SystemInterface`` (``on_activate``, ``write``, ``read``): a driver author
writes those methods and nothing else. :class:`DriverNode` holds the
backend and owes the cell everything a consumer must do (the
:class:`winder.ros.consumer.StepConsumer` duties: handshake, stream checks,
receipts, operator events, stops, stall watch, reports, the bag) plus what a
driver author once had to find in another driver's code:

* its lifecycle starts at the end of its making;
* a paced backend (one that executes each step at its time, as a drive
  does) gets its rows as their time comes on the node's clock. The clock
  starts with the run's first rows (before them the profile node would take
  a running clock for steps to release), runs with the wall clock, and
  stands at the last step received while the next ones are on their way (a
  drive without steps holds its position; a clock that ran on would make
  every step after a hiccup late), except where the run's time must go on
  without steps: at rest after a pause (every step up to its rest executed;
  the resume is timed ahead of this clock) and the settling at the end. It goes out on
  ``/clock`` every :data:`CLOCK_PERIOD_NS` and into the bag;
* steps that still come behind that clock are executed at it and counted late;
* receipts after every write, so the interp node's flow control and the
  run's close follow execution; the run settles ``settle_time`` s after its
  last step (an abort's rest), then closes;
* ``winder/joint_states`` (the backend's :meth:`Backend.read`, in joint
  units) at every clock tick, recorded, and the largest following error in
  the report.

:class:`winder.ros.mock_backend.MockBackend` is a working backend (the
commands followed at once or with a first-order lag, as
``mock_components/GenericSystem`` does) that passes the conformance suite;
a driver starts from it.
"""

from __future__ import annotations

import json
import signal
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from winder.contract.cdr import JointStateEncoder, encode_clocks
from winder.contract.params import CONSUMER_SPECS, check_consumer
from winder.contract.stream import JobPlan
from winder.contract.topic_table import PACED, recorded
from winder.contract.topics import TOPIC_CLOCK, TOPIC_JOINT_COMMANDS, TOPIC_JOINT_STATES, TOPIC_STEP_TIMES
from winder.motion.axes import AXIS_TABLE, Axis
from winder.ros.consumer import StepConsumer
from winder.ros.ctl import one_line as one_line_text
from winder.ros.diagnostics import ERROR
from winder.ros.engine import Engine, RunPort
from winder.ros.qos import QOS_CLOCK, QOS_STATE
from winder.ros.timers import steady_timer
from winder.ros.upstream import ProfileAbort
from winder.spec import Spec

__all__ = ["CLOCK_PERIOD_NS", "DRIVER_SPECS", "Backend", "DriveEngine", "DriverNode", "RunStart"]

#: the paced clock's period: /clock, winder/joint_states and the due rows every 10 ms
CLOCK_PERIOD_NS = 10_000_000

#: the settings every driver node has, besides the consumer's and its backend's own
DRIVER_SPECS: dict[str, Spec] = {
    "settle_time": Spec(
        "settle_time", float, 0.05, "rest after the run's last step before it closes", "s", 0.0, 60.0
    ),
    "in_position_timeout": Spec(
        "in_position_timeout",
        float,
        1.0,
        "how long a run waits, after its settle_time, for its axes to come within position_tolerance",
        "s",
        0.0,
        60.0,
    ),
    "position_tolerance": Spec(
        "position_tolerance",
        float,
        1.0,
        "how far an axis may be from its last command when the run closes (else it closes incomplete)",
        "steps",
        0.0,
        1e9,
    ),
    # at most the profile node's wait for the run's winder/sim_config (10 s), which goes out
    # once begin() has returned: a longer begin would have the run's steps paced without it
    "begin_timeout": Spec(
        "begin_timeout",
        float,
        5.0,
        "how long the backend's begin() may take; past it the run fails (the drive does not answer)",
        "s",
        0.0,
        10.0,
        low_open=True,
    ),
}

#: what a backend method gave back when it raised (or could not be called): the error is said
FAILED: Any = type("Failed", (), {"__repr__": lambda _self: "FAILED"})()


def interrupted(exc: BaseException) -> bool:
    """Whether ``exc``, raised in a backend method, may be a real Ctrl-C of
    this process, to be passed on: a KeyboardInterrupt in the main thread
    while Python's own SIGINT handler is in force (a driver run outside
    winder's node main), which raises one wherever the main thread is and
    cannot be told from a backend's own. Under :func:`winder.ros.spin.spin` a
    signal never raises (it shuts the context down and the node ends after
    the callback), so there every exception of a backend method, a
    KeyboardInterrupt or a SystemExit too, is the backend's: a fault."""
    return (
        isinstance(exc, KeyboardInterrupt)
        and threading.current_thread() is threading.main_thread()
        and signal.getsignal(signal.SIGINT) is signal.default_int_handler
    )


def shown(value: object) -> str:
    """A value a backend returned, as a fault text names it: one line, short."""
    try:
        text = " ".join(repr(value).split())
    except Exception:  # a repr that raises: its type says enough
        return f"a {type(value).__name__}"
    return text if len(text) <= 60 else text[:57] + "..."


def raised(exc: BaseException) -> str:
    """``raised <type>: <its first line>``, whatever its str() does."""
    try:
        text = one_line_text(str(exc))
    except Exception:
        text = ""
    return f"raised {type(exc).__name__}" + (f": {text}" if text else "")


@dataclass(frozen=True)
class RunStart:
    """What a backend is told when a run starts.

    ``axes``: the cell's axes, in the order of a row's position columns
    (``rows[:, 2 + axis.index]``); ``joint_step``: each axis' joint units
    (m or rad) per step; ``start``: the step position each axis starts at
    (where the last run left it); ``settings``: the node's parameters, the
    backend's own among them."""

    job_id: str
    run_id: str
    axes: tuple[Axis, ...]
    joint_step: tuple[float, ...]
    start: npt.NDArray[np.int64]
    total_steps: int
    settings: dict[str, Any]


@runtime_checkable
class Backend(Protocol):
    """A drive (or a simulation of one) behind the cell: what a hardware
    driver writes. Only :meth:`begin`, :meth:`write` and :meth:`read` are
    needed; the others have defaults (inherit from ``Backend`` to get them).
    Every method is called one at a time: from the node's executor thread,
    except :meth:`begin`, which runs in a thread of its own for at most
    ``begin_timeout`` s (the executor waits for it; one that overruns fails
    its run, and no other method is called until it has returned).

    Optional beyond these, looked up by name (so that a backend written
    before it is still a ``Backend``): ``estop()``, the node's ``~/estop``
    (an emergency stop: a drive's quick stop, then disable; the run then
    closes incomplete with the reason "emergency stop"); it may return what
    the stop achieved, in words ("every axis quick-stopped" is said if it
    returns nothing), which ``winder ctl estop`` prints.

    Every return value is checked against what is documented here, and
    anything raised (``KeyboardInterrupt`` and ``SystemExit`` too, see
    :func:`interrupted`) is a driver error: the run closes incomplete naming
    it, the node takes the next run. Texts (a fault, a reason) are said in
    one line: the first."""

    #: the backend's own parameters (name -> Spec), declared on the node beside the consumer's
    specs: ClassVar[dict[str, Spec]] = {}
    #: whether its axes are simulated (a mock, a twin): its parts are kept apart from real ones
    simulated: bool = False

    def paces(self, settings: dict[str, Any]) -> bool:
        """Whether it executes each step at its time (a drive: True), so that
        the node hands rows over as they fall due on its clock; False: as
        fast as it can, every row at once (a simulation, a dry run)."""
        return True

    def missing(self) -> str:
        """Why it cannot take a run now (no drive there), in words; "" if it can."""
        return ""

    def begin(self, run: RunStart) -> dict[str, object]:
        """A run starts: set the axes up. Returns the configuration to publish
        on winder/sim_config and record (anything JSON can hold)."""
        ...

    def write(self, t_ns: int, rows: npt.NDArray[np.int64]) -> None:
        """Command these rows ``[t_ns, segment, position per axis...]`` (step
        positions, in time order), all due by ``t_ns`` (the run's time): they
        count as executed when this returns."""
        ...

    def read(self, t_ns: int) -> npt.NDArray[np.float64]:
        """Where the axes are at run time ``t_ns``, in steps (one per axis,
        in the order of :attr:`RunStart.axes`)."""
        ...

    def fault(self) -> str:
        """What went wrong (a servo fault, a lost step), in words; "" if nothing.
        A fault closes the run incomplete at once."""
        return ""

    def status(self) -> dict[str, object]:
        """Its own keys for the job status and the final report."""
        return {}

    def end(self) -> None:
        """The run closed and is reported: release what it held."""
        return None


class DriveEngine(Engine):
    """The engine around a :class:`Backend`: the paced clock, the settling,
    the joint states and a backend's errors (see the module doc)."""

    def __init__(self, backend: Backend) -> None:
        if not isinstance(backend, Backend):
            raise TypeError(f"{type(backend).__name__} is not a winder Backend (begin, write, read)")
        self.backend = backend
        self.broken = ""  # a driver error of this run (an exception in the backend), if any
        self.said: set[str] = set()  # the backend's methods whose error between runs was said
        #: a begin() that overran begin_timeout and still runs (its thread), and since when:
        #: no other method is called meanwhile, and the node takes no run
        self.busy: threading.Thread | None = None
        self.busy_since = 0.0
        self.clock_ns = -1  # the last /clock published in this node's life
        self.begin_run(False)

    def attach(self, node: Node, run: RunPort) -> None:
        super().attach(node, run)
        self.pub_clock = node.create_publisher(Clock, TOPIC_CLOCK, QOS_CLOCK)
        self.pub_states = node.create_publisher(JointState, TOPIC_JOINT_STATES, QOS_STATE)
        self.pub_commands = node.create_publisher(JointState, TOPIC_JOINT_COMMANDS, QOS_STATE)
        self.clock_timer = steady_timer(node, CLOCK_PERIOD_NS / 1e9, self.tick)
        self.clock_timer.cancel()  # runs while a paced run's clock does
        self.upstream = ProfileAbort(node, run.peers)  # told to abort the run at a fault

    def begin_run(self, paced: bool) -> None:
        self.paced = paced
        self.queue: list[npt.NDArray[np.int64]] = []  # accepted rows waiting for their time (paced)
        self.started = False  # the run's time runs: its first rows came
        self.t_ns_clock = 0  # the run's time on this node's clock (ns)
        self.wall_ns = 0  # the steady time it was last moved at
        self.horizon_ns = 0  # the time of the last row accepted
        self.origin_ns = 0  # the run's time 0 on the cell's clock
        self.commanded: npt.NDArray[np.int64] = np.zeros(len(AXIS_TABLE), np.int64)
        self.settle_until: int | None = None
        self.next_tick_ns = 0
        self.following = 0.0  # the largest |command - measured| seen (steps)
        self.joint_step = np.ones(len(AXIS_TABLE))
        #: the last sample published (run time, commanded and measured steps): velocities are differences
        self.last_sample: tuple[int, npt.NDArray[np.float64], npt.NDArray[np.float64]] | None = None
        self.last_published = -1  # the run time of the last sample published

    # -- the consumer's hooks, in terms of the backend ---------------------------------
    def begin(self, plan: JobPlan, values: dict[str, Any]) -> dict[str, object]:
        self.broken = ""
        self.upstream.find()  # the run's profile node, before any fault
        stuck = self.still_beginning()
        if stuck:  # a run's description came all the same (this node said "waiting")
            self.broken = f"driver error: {stuck}: the run is not set up"
            self.node.get_logger().error(f"{self.broken}; the run stops")
        paces = self.call("paces", self.backend.paces, values)
        if paces is not FAILED and not isinstance(paces, bool | np.bool_):
            self.bug("paces", f"returned {shown(paces)}: want True or False")
        # a paces() that failed: at their time (the run closes at the next pump anyway)
        self.begin_run(True if self.broken else bool(paces))
        self.origin_ns = 0 if self.clock_ns < 0 else self.clock_ns + CLOCK_PERIOD_NS
        start = np.array(plan.segments[0].start if plan.segments else [0] * len(AXIS_TABLE), np.int64)
        self.commanded = start.copy()
        self.joint_step = np.array(plan.joint_step, float)
        self.encoder = JointStateEncoder([a.name for a in AXIS_TABLE], plan.job_id)
        run = RunStart(
            plan.job_id, plan.run_id, AXIS_TABLE, plan.joint_step, start.copy(), plan.total_steps, values
        )
        config = {}
        if not self.broken:  # a drive whose run already failed is not set up
            got = self.begin_within(run, float(values["begin_timeout"]))
            if got is FAILED:
                pass
            elif not isinstance(got, dict):
                self.bug("begin", f"returned {shown(got)}: want a dict (the run's configuration)")
            else:
                try:
                    json.dumps(got)
                    config = got
                except Exception as exc:  # TypeError, ValueError, RecursionError...
                    why = one_line_text(str(exc))
                    self.bug("begin", f"returned a configuration JSON cannot hold ({why})")
        # the backend's own keys under "drive": none of them can stand for a key of the contract's
        return {"drive": config, "real_time": self.paced, "clock_origin_ns": self.origin_ns}

    def begin_within(self, run: RunStart, limit: float) -> Any:
        """``backend.begin(run)`` in a thread of its own, waited for at most
        ``limit`` s (``begin_timeout``): a drive that does not answer (a port
        that hangs) fails the run instead of holding the node. Until a begin
        that overran returns, no other method of the backend is called (one at
        a time, as every backend is promised) and the node takes no run
        (:meth:`missing`). FAILED if it raised or overran (said)."""
        box: list[tuple[bool, Any, str]] = []

        def run_begin() -> None:
            try:
                box.append((True, self.backend.begin(run), ""))
            except BaseException as exc:  # no signal lands in this thread: each one is the backend's
                box.append((False, exc, traceback.format_exc()))

        thread = threading.Thread(target=run_begin, name="backend-begin", daemon=True)
        since = time.monotonic()
        thread.start()
        end = since + limit
        # in slices: a signal that shuts the node down is not held up by a drive that hangs
        while thread.is_alive() and self.node.context.ok() and time.monotonic() < end:
            thread.join(min(0.1, max(end - time.monotonic(), 0.0)))
        if thread.is_alive():
            self.busy, self.busy_since = thread, since
            self.bug("begin", f"did not return within {limit:g} s (begin_timeout)")
            return FAILED
        ok, got, trace = box[0]
        if not ok:
            self.bug("begin", raised(got), trace=trace)
            return FAILED
        return got

    def paces(self) -> bool:
        return self.paced

    def execute(self, rows: npt.NDArray[np.int64]) -> None:
        if self.broken:
            return  # nothing more goes to a drive whose run failed: it closes at this pump
        if not self.paced:
            self.hand_over(int(rows[-1, 0]), rows)
            return
        if not self.started:  # the run's time starts with its first rows
            self.started, self.wall_ns = True, time.monotonic_ns()
            self.clock_timer.reset()
        self.horizon_ns = int(rows[-1, 0])
        self.queue.append(rows)

    def holding(self) -> bool:
        return bool(self.queue)

    def pending(self) -> bool:
        """Rows wait for their time, the axes settle, or an operator state is
        booked ahead of the clock (a pause's rest after its last step)."""
        if self.run.plan is None:
            return False
        if self.queue or (self.run.finishing and not self.rested()):
            return True
        return self.paced and self.started and self.run.transitions_ahead()

    def earliest_step_ns(self) -> int | None:
        return self.now_ns() if self.paced and self.started else None

    def work(self) -> None:
        if self.run.plan is None:
            return
        fault = self.faults()
        if fault:
            if not self.broken:  # the drive's own fault (a driver error was said where it happened)
                self.node.get_logger().error(f"{fault}; the run stops")
            ids: dict[str, object] = {"job_id": self.run.plan.job_id, "run_id": self.run.plan.run_id}
            self.run.publish_status("drive", ERROR, f"{fault}; the run stops", ids)
            self.upstream.ask(TOPIC_STEP_TIMES)  # the rest of the cell stops sending this run's steps
            self.run.finish(complete=False)
            return
        if self.paced and self.started:
            t = self.now_ns()
            due = self.take_due(t)
            if due is not None:
                self.hand_over(t, due)
            self.run.reached(t)
            if not self.queue and not self.run.chunks_waiting():
                self.run.settle_if_complete()

    def settle(self, until_ns: int) -> None:
        self.settle_until = until_ns + round(self.run.values()["settle_time"] * 1e9)
        if not self.paced:
            self.run.reached(self.settle_until)

    def complete(self) -> bool:
        """A run closes complete only with its axes in position and no driver
        error (checked where the consumer closes it: a check in the pump came a
        moment before the settle time was up, and the run then closed done
        whose axes were thousands of steps off)."""
        return self.run.plan is None or not (self.broken or not self.in_position())

    def position_error(self) -> tuple[int, float] | None:
        """The axis furthest from its last command and by how many steps;
        None if the read cannot be used (a driver error, said: self.broken)."""
        measured = self.measured(self.run.t_ns)
        if measured is None:
            return None
        error = np.abs(measured - self.commanded)
        worst = int(np.argmax(error))
        return worst, float(error[worst])

    def in_position(self) -> bool:
        """At the run's end: every axis within ``position_tolerance`` steps of
        its last command (CONTRACT.md: done is at the job's end position); if
        not, said as the run's fault."""
        got = self.position_error()
        if got is None:
            return False
        worst, error = got
        tolerance = self.run.values()["position_tolerance"]
        if not error > tolerance:
            return True
        waited = self.run.values()["settle_time"] + self.run.values()["in_position_timeout"]
        self.broken = (
            f"axes not in position {waited:g} s after the last step: {AXIS_TABLE[worst].name} "
            f"{error:.1f} steps from its command (position_tolerance {tolerance:g})"
        )
        self.node.get_logger().error(self.broken)
        return False

    def rested(self) -> bool:
        """The settle time after the run's last step has passed and the axes
        are in position, or in_position_timeout more has passed (a drive's
        read-back lags its commands: a professional controller's in-position
        window with a settle timeout, not one look at a fixed moment)."""
        if self.settle_until is None or not self.paced:
            return True
        now = self.now_ns()
        if now < self.settle_until:
            return False
        if now >= self.settle_until + round(self.run.values()["in_position_timeout"] * 1e9):
            return True
        got = self.position_error()
        return got is None or not got[1] > self.run.values()["position_tolerance"]

    def closing(self) -> None:
        if self.paced and self.started and self.run.plan is not None:
            self.publish_states(self.now_ns())

    def faults(self) -> str:
        if self.broken:
            return self.broken
        got = self.call("fault", self.backend.fault)
        if got is not FAILED and not isinstance(got, str):
            self.bug("fault", f'returned {shown(got)}: want a str ("" if nothing is wrong)')
        if self.broken or got is FAILED:
            return self.broken or "driver error: backend.fault() failed"
        return one_line_text(got)  # a text of many lines: its first

    def details(self) -> dict[str, object]:
        own: dict[str, object] = {}
        got = self.call("status", self.backend.status)
        if got is not FAILED and not (isinstance(got, dict) and all(isinstance(k, str) for k in got)):
            self.bug("status", f"returned {shown(got)}: want a dict with str keys")
        elif got is not FAILED:
            try:
                own = {k: one_line_text(str(v)) for k, v in got.items()}
            except Exception as exc:  # a value whose str() raises
                self.bug("status", f"returned a value that cannot be said ({raised(exc)})")
        return {"max_following_error_steps": f"{self.following:.4f}", **own}

    def simulated(self) -> bool:
        return getattr(self.backend, "simulated", False) is True

    def still_beginning(self) -> str:
        """Why no method of the backend may be called now: a begin() that
        overran begin_timeout has not returned ("" if none; one that has
        returned since is released here, its end() called as at a run's end)."""
        busy = self.busy
        if busy is not None and busy.is_alive():
            return (
                f"backend.begin() has not returned for {time.monotonic() - self.busy_since:.0f} s "
                "(it overran begin_timeout)"
            )
        if busy is not None:
            self.busy = None
            self.node.get_logger().info("backend.begin() returned, late: backend.end() called")
            self.end_backend()
        return ""

    def missing(self) -> str:
        stuck = self.still_beginning()
        if stuck:
            return f"{stuck}: no run until it does"
        got = self.call("missing", self.backend.missing)
        if got is FAILED:
            return "driver error: backend.missing() failed (in the node's log)"
        if not isinstance(got, str):
            self.bug("missing", f'returned {shown(got)}: want a str ("" if the drive is there)')
            return f"driver error: backend.missing() returned {shown(got)}, not a str"
        return one_line_text(got)

    def end(self) -> None:
        self.clock_timer.cancel()
        self.queue = []
        self.end_backend()

    def end_backend(self) -> None:
        got = self.call("end", self.backend.end)
        if got is not FAILED and got is not None:
            self.bug("end", f"returned {shown(got)}: want None")

    def estop(self) -> str:
        """An emergency stop (``~/estop``): the backend's ``estop()`` if it has
        one, and a run going on closed incomplete with the reason "emergency
        stop", the profile node told to abort. What was done, in words."""
        fn = getattr(self.backend, "estop", None)
        stopped = "every axis quick-stopped" if callable(fn) else "this backend has no estop(): the axes"
        got = self.call("estop", fn) if callable(fn) else None
        if got is FAILED:
            stopped = "backend.estop() failed (in the node's log)"
        elif isinstance(got, str) and got.strip():  # what the stop achieved, as the backend says it
            stopped = one_line_text(got)
        if self.run.plan is None:
            return f"emergency stop: {stopped}; no run was going on"
        run_id = self.run.plan.run_id
        if not self.broken:
            self.broken = "emergency stop"
            self.node.get_logger().error(f"emergency stop ({stopped}); the run stops")
        self.run.pump()  # the run closes now (work() sees the fault)
        return f"emergency stop: {stopped}; run {run_id} closed incomplete"

    # -- a backend that fails --------------------------------------------------------------
    def call(self, what: str, fn: Callable[..., Any], *args: Any) -> Any:
        """``fn(*args)``, a method of the backend, or FAILED. Anything raised
        in it (a KeyboardInterrupt or a SystemExit too: a driver's
        ``sys.exit()`` must not end the node) is a bug of the driver: said
        once with its traceback, the run closed incomplete at the next pump (a
        fault), the node goes on and takes the next run. Only what may be a
        real Ctrl-C is passed on (:func:`interrupted`). Not called at all
        while a begin() that overran still runs (FAILED)."""
        if self.busy is not None:
            return FAILED
        try:
            return fn(*args)
        except BaseException as exc:
            if interrupted(exc):
                raise
            self.bug(what, raised(exc), trace=traceback.format_exc())
            return FAILED

    def bug(self, what: str, text: str, trace: str = "") -> None:
        why = f"backend.{what}() {text}"
        run = getattr(self, "run", None)
        plan = run.plan if run is not None else None  # (None: while the node is being made)
        if not self.broken and plan is not None:
            self.broken = f"driver error: {why}"
            self.node.get_logger().error(f"{self.broken}; the run stops" + (f"\n{trace}" if trace else ""))
        elif plan is None and what not in self.said:  # between runs (missing, end): once a method
            self.said.add(what)
            self.node.get_logger().error(f"driver error: {why}" + (f"\n{trace}" if trace else ""))

    # -- the paced clock ---------------------------------------------------------------------
    def now_ns(self) -> int:
        """The run's time now (ns), the clock moved on (see the module doc)."""
        if not self.started:
            return 0
        now = time.monotonic_ns()
        t = self.t_ns_clock + (now - self.wall_ns)
        self.wall_ns = now
        free = self.run.finishing or self.run.at_rest
        if not free:
            t = min(t, max(self.horizon_ns, self.t_ns_clock))  # it waits for the next steps
        self.t_ns_clock = t
        return t

    def tick(self) -> None:
        """Every CLOCK_PERIOD_NS of a paced run: the due rows, the clock, the joint states."""
        if self.run.plan is None or not self.started:
            self.clock_timer.cancel()
            return
        self.run.pump()
        if self.run.plan is None:  # the pump closed the run
            return
        # the time the pump handed the rows over up to: a later look at the clock (the pump
        # took 30 ms on a loaded machine) showed a command behind it, then a leap
        t = self.run.t_ns
        stamp = self.origin_ns + t
        clock = encode_clocks([stamp])[0]
        self.clock_ns = stamp
        self.pub_clock.publish(clock)
        self.run.record("clock", t, clock, exact=True)
        self.publish_states(t)

    def take_due(self, t_ns: int) -> npt.NDArray[np.int64] | None:
        """The queued rows due by ``t_ns``, in order; the rest stay queued."""
        out: list[npt.NDArray[np.int64]] = []
        while self.queue:
            rows = self.queue[0]
            n = int(np.searchsorted(rows[:, 0], t_ns, side="right"))
            if n == 0:
                break
            out.append(rows[:n])
            if n < rows.shape[0]:
                self.queue[0] = rows[n:]
                break
            self.queue.pop(0)
        if not out:
            return None
        return out[0] if len(out) == 1 else np.concatenate(out)

    def hand_over(self, t_ns: int, rows: npt.NDArray[np.int64]) -> None:
        """Rows to the backend, then booked: executed, receipts, the run's time.
        Rows a write failed on are not executed (the run closes at this pump)."""
        got = self.call("write", self.backend.write, t_ns, rows)
        if got is not FAILED and got is not None:
            self.bug("write", f"returned {shown(got)}: want None (a write that fails raises)")
        if self.broken:
            return
        self.commanded = rows[-1, 2:].copy()
        self.run.executed(rows.shape[0])
        self.run.receipt()
        if not self.paced:
            self.run.reached(t_ns)
            self.publish_states(t_ns)

    def measured(self, t_ns: int) -> npt.NDArray[np.float64] | None:
        """The backend's ``read(t_ns)`` as one finite step position per axis;
        None (a driver error, said) if it raised or returned anything else:
        None, text, booleans, NaN, the wrong number of values."""
        got = self.call("read", self.backend.read, t_ns)
        if got is FAILED:
            return None
        try:
            values = np.asarray(got)
            numbers = values.dtype.kind in "iuf"  # not text, objects or booleans
            measured = values.astype(float).reshape(len(AXIS_TABLE)) if numbers else None
        except Exception:  # a ragged list, an object numpy cannot take
            measured = None
        if measured is None or not np.all(np.isfinite(measured)):
            self.bug("read", f"returned {shown(got)}: want {len(AXIS_TABLE)} finite step positions")
            return None
        return measured

    def publish_states(self, t_ns: int) -> None:
        """winder/joint_commands (the commanded position) and winder/joint_states
        (where the backend says the axes are), in joint units, each velocity the
        mean since an earlier sample; recorded, as the simulator's are."""
        measured = self.measured(t_ns)
        if measured is None:
            return
        commanded = self.commanded.astype(float)
        self.following = max(self.following, float(np.max(np.abs(measured - commanded))))
        if t_ns <= self.last_published:
            return  # one sample a time (the clock stood at the last step; a tick and the closing)
        self.last_published = t_ns
        last = self.last_sample
        dt = (t_ns - last[0]) / 1e9 if last is not None else 0.0
        stamp = np.array([self.origin_ns + t_ns], np.int64)
        for key, pub, now, before in (
            ("joint_commands", self.pub_commands, commanded, last[1] if last else None),
            ("joint_states", self.pub_states, measured, last[2] if last else None),
        ):
            vel = (now - before) / dt if before is not None and dt > 0 else np.zeros_like(now)
            pos_j, vel_j = (now * self.joint_step)[None, :], (vel * self.joint_step)[None, :]
            msg = self.encoder.encode(stamp, pos_j, vel_j)[0]
            if self.node.context.ok():  # at a Ctrl-C the run closes without the context: the bag has it
                pub.publish(msg)
            self.run.record(key, t_ns, msg, exact=True)
        if last is None or t_ns - last[0] >= CLOCK_PERIOD_NS // 2:
            # a velocity is the mean over half a clock period at least: two ticks close
            # together on a busy machine made one step over 0.1 ms a speed 5 times the real one
            self.last_sample = (t_ns, commanded, measured)


class DriverNode(StepConsumer):
    """A consumer node around a :class:`Backend` (see the module doc)."""

    #: publishes /clock, winder/joint_commands and winder/joint_states, recorded as the simulator's are
    TOPICS: ClassVar[dict[str, tuple[str, str]]] = recorded(PACED)

    def __init__(self, backend: Backend, name: str = "driver", hardware_id: str | None = None) -> None:
        engine = DriveEngine(backend)
        specs = self.parameters(type(backend))
        super().__init__(
            name, specs, check_consumer, engine, hardware_id=hardware_id or name, topics=self.TOPICS
        )
        self.backend = backend
        self.create_service(Trigger, "~/estop", self.on_estop)

    def on_estop(self, _request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """``~/estop`` (beside the profile node's ``~/abort``): see :meth:`DriveEngine.estop`."""
        engine = self.engine
        assert isinstance(engine, DriveEngine)
        response.message = engine.estop()
        response.success = not response.message.startswith("emergency stop: backend.estop() failed")
        return response

    @staticmethod
    def parameters(backend: type[Backend]) -> dict[str, Spec]:
        """The parameters a driver node around a ``backend`` declares: the
        consumer's, the driver's and the backend's own (what its ``--help`` lists)."""
        return {**CONSUMER_SPECS, **DRIVER_SPECS, **backend.specs}
