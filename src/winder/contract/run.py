"""A run's bookkeeping on the consumer side, ROS-free: operator events, programmed
stops, the abort point, and the job report.

Every step consumer (the simulator, a hardware driver: :class:`winder.ros.consumer.StepConsumer`)
keeps the same books about the run it executes:

* :class:`ControlEvent` (:mod:`winder.contract.events`): one operator event
  of ``winder/control`` (pause, resume, abort, override), read and checked
  by :meth:`ControlEvent.from_wire`, which refuses anything that is not a
  well-formed event, in one line.
* :class:`RunLedger`: what the run has executed and what it must do next:
  the programmed stops met in the stream (:class:`ProgrammedStop`), the
  operator's pause (:class:`Hold`) and abort (:class:`AbortPoint`), and the
  state transitions (:class:`Transition`) to announce as execution reaches
  their time. An event that contradicts what was already executed (an abort
  claiming fewer steps than were executed) is refused, never acted on.
* :class:`JobReport`: the consumer's job status, live and final, as typed
  fields with one conversion to the status' key/values and back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from enum import Enum
from typing import Any

import numpy as np
import numpy.typing as npt

from winder.contract.events import EVENT_KINDS, ControlEvent, EventError
from winder.contract.params import stop_place
from winder.contract.states import CellState, EventKind
from winder.contract.stream import JobPlan
from winder.contract.topics import PROCESS_KEYS, status_values

__all__ = [
    "EVENT_KINDS",
    "FAULTS_KEY",
    "PART_ID_KEY",
    "PART_INDEX_KEY",
    "AbortPoint",
    "ControlEvent",
    "EventError",
    "Hold",
    "JobReport",
    "ProgrammedStop",
    "RunLedger",
    "StopPhase",
    "Transition",
    "commands_text",
    "shaper_text",
    "stops_text",
    "where_text",
]


class StopPhase(str, Enum):
    """Where the run is with respect to a programmed stop."""

    AHEAD = "ahead"  #: met in the stream, execution has not reached it
    PAUSED = "paused"  #: the axes rest there (announced)
    RESUMED = "resumed"  #: the run went on (announced)


@dataclass
class ProgrammedStop:
    """A programmed stop of the job met in the stream: the axes rest from the
    stop's step (``t_stop_ns``) to the next step (``t_resume_ns``, None until
    that step comes)."""

    t_stop_ns: int
    t_resume_ns: int | None
    place: tuple[int, int, int]  #: (coil, layer, turn), from 1
    phase: StopPhase = StopPhase.AHEAD

    @property
    def label(self) -> str:
        return f"{self.place[0]}:{self.place[2]}"


@dataclass(frozen=True)
class Hold:
    """An operator's pause: the axes rest at ``rest_ns`` after ``steps`` steps."""

    rest_ns: int
    steps: int


@dataclass(frozen=True)
class AbortPoint:
    """An operator's abort: the run ends at rest (``rest_ns``) after ``steps`` steps."""

    rest_ns: int
    steps: int


@dataclass(frozen=True)
class Transition:
    """A state of the cell to announce on ``winder/state`` once execution
    reaches ``t_ns``; ``place`` is (coil, layer, turn) (0s where not known)."""

    t_ns: int
    state: CellState
    text: str
    place: tuple[int, int, int]
    #: a programmed stop's transition (its job status says which stop), else an operator's
    stop: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "state", CellState(self.state))


@dataclass
class RunLedger:
    """What a consumer knows of the run it executes (see the module doc).

    The consumer tells it what it executed (:meth:`executed`) and what came
    (:meth:`note_rows`, :meth:`apply`); it answers what to announce
    (:meth:`due`), whether the axes rest (:attr:`at_rest`) and whether the run
    ended by an abort (:attr:`aborted`)."""

    plan: JobPlan
    executed_steps: int = 0  #: steps executed (the consumer's count)
    missing_steps: int = 0  #: steps known missing (never executed, counted as done for flow control)
    stops: list[ProgrammedStop] = field(default_factory=list)
    hold: Hold | None = None
    abort: AbortPoint | None = None
    #: the operator state announced last (None while running)
    op_state: CellState | None = None
    #: operator events booked (pause, resume, abort, override)
    events: int = 0
    _pending: list[Transition] = field(default_factory=list)
    _places: dict[tuple[int, int], tuple[int, int, int]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.plan.stops:
            segs = self.plan.segments
            self._places = {(g, k): stop_place(self.plan.job, segs[g], k) for g, k in self.plan.stops}

    # -- what came --------------------------------------------------------
    @property
    def accounted(self) -> int:
        """Steps executed or known missing: what receipts acknowledge."""
        return self.executed_steps + self.missing_steps

    def executed(self, n: int) -> None:
        self.executed_steps += n

    @property
    def has_stops(self) -> bool:
        """Whether the job has programmed stops (only then do rows need their step indexes)."""
        return bool(self._places)

    def note_rows(
        self, seg: int, t_ns: npt.NDArray[np.int64], step_index: npt.NDArray[np.integer[Any]] | None = None
    ) -> bool:
        """Accepted rows of segment ``seg``: their times and, when the job
        has programmed stops (:attr:`has_stops`), their 1-based step indexes.
        A stop waiting for its resume learns it from the first row; a
        programmed stop among the rows is noted. True when a stop that waited
        for ``~/resume`` (``stop_resume: call``) got its resume here."""
        resumed = False
        for p in self.stops:
            if p.t_resume_ns is None and t_ns.size:
                p.t_resume_ns = int(t_ns[0])
                resumed = resumed or self.plan.stop_resume == "call"
        if not self._places or step_index is None:
            return resumed
        wanted = [k for g, k in self._places if g == seg]
        for i in np.nonzero(np.isin(step_index, wanted))[0].tolist():
            resume = int(t_ns[i + 1]) if i + 1 < t_ns.size else None
            self.stops.append(ProgrammedStop(int(t_ns[i]), resume, self._places[(seg, int(step_index[i]))]))
        return resumed

    def apply(self, event: ControlEvent) -> Transition | None:
        """Book an event of this run; the transition it starts (already
        queued for :meth:`due`), or None. EventError if it is not this run's
        or contradicts what happened (an abort or pause claiming fewer steps
        than were executed, or more than the job has). A resume may come
        after the first steps it times (steps and events travel on two
        topics; a consumer held up takes both at once): its ``steps``, those
        before the resumed motion, may be fewer than were executed."""
        if event.run_id != self.plan.run_id:
            raise EventError(f"run_id={event.run_id!r} is not the running run {self.plan.run_id!r}")
        total = self.plan.total_steps
        least = 0 if event.kind is EventKind.RESUME else self.executed_steps
        if event.steps is not None and not least <= event.steps <= total:
            raise EventError(
                f"{event.kind} after steps={event.steps} is invalid: {self.executed_steps} steps are "
                f"executed already and the job has {total}"
            )
        if self.abort is not None:
            raise EventError(f"{event.kind} after the run's abort: it takes no more events")
        where = self._where(event.segment, event.step)
        self.events += 1
        first: Transition | None = None
        if event.kind is EventKind.PAUSE:
            assert event.steps is not None
            first = Transition(event.t_ns, CellState.PAUSING, "pausing: braking to rest", where)
            self._queue(
                first,
                Transition(event.rest_ns, CellState.PAUSED, f"paused after {event.steps} steps", where),
            )
            self.hold = Hold(event.rest_ns, event.steps)
        elif event.kind is EventKind.RESUME:
            first = Transition(event.t_ns, CellState.RUNNING, "resumed", where)
            self._queue(first)
            self.hold = None
        elif event.kind is EventKind.ABORT:
            assert event.steps is not None
            text = f"aborting: at rest after {event.steps} steps"
            first = Transition(event.t_ns, CellState.ABORTING, text, where)
            self._queue(first)
            self.abort, self.hold = AbortPoint(event.rest_ns, event.steps), None
        return first

    def _queue(self, *ts: Transition) -> None:
        self._pending.extend(ts)
        self._pending.sort(key=lambda t: t.t_ns)

    def _where(self, seg: int, step: int) -> tuple[int, int, int]:
        """(coil, layer, turn) of step ``step`` of segment ``seg``; the coil
        alone between layers; zeros if the segment is unknown."""
        segs = self.plan.segments
        if not 0 <= seg < len(segs):
            return (0, 0, 0)
        if segs[seg].kind.winds:
            return stop_place(self.plan.job, segs[seg], max(step, 0))
        return (segs[seg].pole + 1, 0, 0)

    # -- what to do -------------------------------------------------------
    def due(self, upto_ns: int) -> list[Transition]:
        """The transitions execution has reached at ``upto_ns``, in time order
        (each once): programmed stops reached and left, operator states."""
        out: list[Transition] = []
        for p in self.stops:
            if p.phase is StopPhase.AHEAD and p.t_stop_ns <= upto_ns:
                p.phase = StopPhase.PAUSED
                out.append(
                    Transition(
                        p.t_stop_ns,
                        CellState.PAUSED,
                        f"paused at turn {p.label} (coil:turn)",
                        p.place,
                        p.label,
                    )
                )
            if p.phase is StopPhase.PAUSED and p.t_resume_ns is not None and p.t_resume_ns <= upto_ns:
                p.phase = StopPhase.RESUMED
                out.append(
                    Transition(
                        p.t_resume_ns,
                        CellState.RUNNING,
                        f"resumed after the stop at turn {p.label}",
                        p.place,
                        p.label,
                    )
                )
        while self._pending and self._pending[0].t_ns <= upto_ns:
            t = self._pending.pop(0)
            self.op_state = None if t.state is CellState.RUNNING else t.state
            out.append(t)
        out.sort(key=lambda t: t.t_ns)
        return out

    def reach_stops(self) -> list[Transition]:
        """The stream stands still at a programmed stop it has not reached in
        time yet (it waits for a resume): the axes are there, say so."""
        ahead = [p.t_stop_ns for p in self.stops if p.phase is StopPhase.AHEAD]
        return self.due(max(ahead)) if ahead else []

    @property
    def transitions_ahead(self) -> bool:
        """Operator states booked for a time execution has not reached yet
        (the rest of a pause or an abort): a backend that executes on the
        wall clock keeps telling its time (:meth:`due`) until they are reached."""
        return bool(self._pending)

    @property
    def at_stop(self) -> bool:
        """At a programmed stop (announced, not left)."""
        return any(p.phase is StopPhase.PAUSED for p in self.stops)

    @property
    def waiting_for_resume(self) -> bool:
        """At a programmed stop that waits for ``~/resume``: no steps come, and that is no stall."""
        return self.plan.stop_resume == "call" and any(p.t_resume_ns is None for p in self.stops)

    @property
    def held(self) -> bool:
        """Paused by the operator (rest time booked, no resume yet)."""
        return self.hold is not None

    @property
    def at_rest(self) -> bool:
        """Paused by the operator, every step up to the rest executed and none
        beyond it: a step beyond the rest is the resumed motion's, whose event
        is on its way (steps and events travel on two topics)."""
        return self.hold is not None and self.accounted == self.hold.steps

    @property
    def aborted(self) -> bool:
        """Aborted, and every step up to the rest executed."""
        return self.abort is not None and self.accounted >= self.abort.steps


#: The final report's key of what the consumer's axes did that they were not commanded to, in
#: words with their units (the simulator: steps lost, the wire's path left, the wire's tension
#: outside its alarm band; :meth:`winder.ros.engine.Engine.faults`); absent when nothing. A run
#: that executed every step is still ``done``, and that is no success (CONTRACT.md 3.7).
FAULTS_KEY = "faults"
#: a final report's keys that name the run's part (docs/PARTS.md): its id, and the index file
#: that holds it (as the consumer's host names it); absent when the consumer keeps no index, or
#: the part could not be written (a ``stream`` ERROR of the run says why)
PART_ID_KEY = "part_id"
PART_INDEX_KEY = "part_index"


def _num(text: str, kind: type) -> Any:
    """``text`` as an int or a float; what is not one reads as 0 (an int) or
    NaN (a float): a report from elsewhere never raises here."""
    try:
        return kind(text)
    except ValueError:
        pass
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if kind is int:
        return int(value) if math.isfinite(value) else 0
    return value


@dataclass
class JobReport:
    """A consumer's job status (``"<node>: job"`` on /diagnostics): the
    common keys (:data:`winder.contract.topics.STATUS_KEYS`), the role, the
    stream's account, and the backend's own keys (``extra``, e.g. the
    simulator's lost steps and tracking error) after them."""

    state: str
    job_id: str = ""
    run_id: str = ""
    steps_done: int = 0
    steps_total: int = 0
    steps_missing: int = 0
    gaps: int = 0
    chunks_rejected: int = 0
    #: execution time reached since the run's start (s): simulated time, or the hardware's
    sim_time_s: float = 0.0
    wall_time_s: float = 0.0
    bag: str = ""
    errors: int = 0
    stalls: int = 0
    extra: dict[str, str] = field(default_factory=dict)

    @property
    def real_time_factor(self) -> float:
        return self.sim_time_s / self.wall_time_s if self.wall_time_s > 0 else math.inf

    @property
    def faults(self) -> str:
        """What the axes did that they were not commanded to (:data:`FAULTS_KEY`), "" if nothing:
        a ``done`` run with faults executed every step, but its part is not what was asked."""
        return self.extra.get(FAULTS_KEY, "")

    @property
    def part_id(self) -> str:
        """The run's part in the part index (:data:`PART_ID_KEY`), "" if none."""
        return self.extra.get(PART_ID_KEY, "")

    def to_values(self) -> dict[str, object]:
        """The status' key/values, in the contract's order."""
        return status_values(
            self.state,
            self.job_id,
            self.run_id,
            self.steps_done,
            self.steps_total,
            role="consumer",
            steps_missing=self.steps_missing,
            gaps=self.gaps,
            chunks_rejected=self.chunks_rejected,
            sim_time_s=f"{self.sim_time_s:.6f}",
            wall_time_s=f"{self.wall_time_s:.3f}",
            real_time_factor=f"{self.real_time_factor:.3f}" if self.wall_time_s > 0 else "inf",
            **self.extra,
            bag=self.bag,
            errors=self.errors,
            stalls=self.stalls,
        )

    @classmethod
    def from_values(cls, values: dict[str, str]) -> JobReport:
        """A report from a status' key/values (as received or recorded);
        missing keys take their defaults, unknown ones go to ``extra``."""
        known = {f.name: f for f in fields(cls) if f.name != "extra"}
        kwargs: dict[str, Any] = {}
        extra: dict[str, str] = {}
        skip = {"progress", "role", "real_time_factor", *PROCESS_KEYS}  # the sender's process is no report
        for key, text in values.items():
            f = known.get(key)
            if f is None:
                if key not in skip:
                    extra[key] = str(text)
                continue
            kind = {"int": int, "float": float}.get(str(f.type), str)
            kwargs[key] = _num(str(text), kind) if kind is not str else str(text)
        return cls(state=str(kwargs.pop("state", "")), extra=extra, **kwargs)

    @classmethod
    def from_message(cls, msg: Any) -> JobReport:
        """A report from a winder_interfaces/JobReport (``winder/report``, a
        Wind result: an rclpy message, or one rosbags decoded)."""
        kwargs = {f.name: getattr(msg, f.name) for f in fields(cls) if f.name not in ("state", "extra")}
        kinds = {"int": int, "float": float}
        typed = {k: kinds.get(str(f.type), str)(kwargs[k]) for f in fields(cls) if (k := f.name) in kwargs}
        return cls(state=str(msg.state), extra={kv.key: kv.value for kv in msg.extra}, **typed)


# -- a run told in words: one line each for the summaries of winder run and winder analyze ---------

#: an input shaper's name as its papers write it
SHAPER_NAMES = {"zv": "ZV", "mzv": "MZV", "zvd": "ZVD", "ei": "EI", "2hump_ei": "2-hump EI"}


def shaper_text(ramp: dict[str, Any]) -> str:
    """``"ZVD shaper at 12.5 Hz"`` for the ramp settings of a shaped run
    (the profile node's, or ``winder/profile_config``), "" without a shaper."""
    name = str(ramp.get("shaper") or "none")
    if name == "none":
        return ""
    freq = ramp.get("shaper_freq")
    at = f" at {float(freq):g} Hz" if isinstance(freq, (int, float)) and not isinstance(freq, bool) else ""
    return f"{SHAPER_NAMES.get(name, name)} shaper{at}"


def stops_text(plan: JobPlan) -> str:
    """The job's programmed stops in one line (their count, each as
    coil:turn as ``--stops`` takes it, the rest and how the job goes on), ""
    if it has none."""
    if not plan.stops:
        return ""
    segs = plan.segments
    places = [stop_place(plan.job, segs[seg], step) for seg, step in plan.stops if 0 <= seg < len(segs)]
    labels = ", ".join(f"{coil}:{turn}" for coil, _, turn in places)
    goes_on = "auto" if plan.stop_resume == "auto" else "waits for a resume"
    return f"{len(plan.stops)} ({labels}, rest {plan.stop_pause:g} s, {goes_on})"


def where_text(plan: JobPlan, seg: int, step: int) -> str:
    """Where step ``step`` of segment ``seg`` is: the coil and the turn into
    it (fractional: the turns of its coil's layers before it and the fork's
    turns into this one), or the coil alone between layers."""
    segs = plan.segments
    if not 0 <= seg < len(segs):
        return ""
    s = segs[seg]
    if not s.kind.winds:
        return f"coil {s.pole + 1}, between layers"
    return f"coil {s.pole + 1} turn {s.first_turn + step / s.turn_steps:.2f}"


def commands_text(events: list[dict[str, Any]] | tuple[dict[str, Any], ...], plan: JobPlan) -> str:
    """The operator's commands of a run (its ``winder/control`` events) in one
    line, each with the simulated time it took effect and, for a pause or an
    abort, when and where the axes came to rest; "" if there were none."""
    told = []
    for e in events:
        kind = str(e.get("event", "?"))
        t = e.get("t_ns")
        at = f" at {t / 1e9:.3f} s" if isinstance(t, int) else ""
        if kind in (EventKind.PAUSE, EventKind.ABORT):
            rest = e.get("t_rest_ns", t)
            where = (
                where_text(plan, e["segment"], e["step"])
                if isinstance(e.get("segment"), int) and isinstance(e.get("step"), int)
                else ""
            )
            detail = [f"at rest {rest / 1e9:.3f} s" if isinstance(rest, int) else "", where]
            told.append(f"{kind}{at} ({', '.join(d for d in detail if d)})")
        elif kind == EventKind.OVERRIDE:
            factor = e.get("factor")
            told.append(f"override x{factor:g}{at}" if isinstance(factor, (int, float)) else f"override{at}")
        else:
            told.append(f"{kind}{at}")
    return "; ".join(told)
