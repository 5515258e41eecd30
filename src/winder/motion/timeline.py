"""The time law of a running job under an operator's commands (ROS-free).

A job's motion is a sequence of *moves* (a segment, or the part of one between
programmed stops), each from rest to rest, planned by
:func:`winder.motion.timing.plan_timing`. A :class:`Timeline` starts as that
plan and takes commands at a simulated time ``t`` (ns since the job's start):

* ``pause`` (feed hold): the move in motion at ``t`` stops with the
  time-optimal jerk-limited stop from its state at ``t``
  (:func:`winder.motion.retime.stop_tail`); everything after waits.
* ``resume``: the rest of that move is planned from rest, from ``t`` (or from
  the moment the axes came to rest, if later); the moves after it follow with
  their planned rests between them.
* ``override`` ``f`` in :data:`OVERRIDE_RANGE` ([0.05, 2]): ``v_max`` becomes ``f`` times the ramp's;
  the move in motion changes its speed with a jerk-limited transition
  (:func:`winder.motion.retime.continue_tail`) unless it is already braking
  for its end, and every later move is planned with it.
* ``abort``: a pause after which nothing follows: the job ends with the axes at
  rest, :attr:`Timeline.end_step` tells where.

Commands change the times of steps, never their positions: a step keeps its
place in its segment, and :meth:`Timeline.times_ns` gives the time of any step
the law already fixes. Without commands the times are exactly
:meth:`SegmentTiming.times_ns`'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from winder.errors import BadInputError
from winder.motion.retime import continue_tail, from_rest, motion_state, stop_tail
from winder.motion.shaped import Motion
from winder.motion.timing import SegmentTiming
from winder.spec import SpecError, interval, shorten

__all__ = [
    "COMMANDS",
    "OVERRIDE_RANGE",
    "OVERRIDE_TEXT",
    "SCHEDULE_SECONDS",
    "Command",
    "CommandError",
    "Timeline",
    "check_schedule",
    "parse_schedule",
]

COMMANDS = ("pause", "resume", "abort", "override")
#: a feed override's factor, at least and at most: the one place it is written
#: (the profile node's feed_override setting, the schedule, the messages)
OVERRIDE_RANGE = (0.05, 2.0)
#: the range as every message writes it
OVERRIDE_TEXT = interval(*OVERRIDE_RANGE)
#: a scheduled command's time (s since the run's start), at least and at most
SCHEDULE_SECONDS = (0.0, 1e6)
_SNAP = 1e-9  # relative: a stop this close to a move's end ends the move


def _reached(position: float) -> float:
    """The furthest step position counted as reached by a stop at ``position``
    (steps since the move's start): a step within _SNAP of it is."""
    return position * (1 + _SNAP) + _SNAP


class CommandError(BadInputError):
    """A command the job cannot take now (one line: why)."""


@dataclass(frozen=True)
class Command:
    """An operator command at a simulated time (ns since the job's start)."""

    t_ns: int
    kind: str
    value: float = 1.0


#: commands a schedule holds, at most (each one replans the moves after it)
MAX_SCHEDULE = 1000


def _schedule_items(text: str) -> list[tuple[str, Command]]:
    """The commands of a schedule as written (item, command); SpecError (one
    line) naming the item and the rule."""
    items = [t for t in text.replace(" ", "").split(",") if t]
    if len(items) > MAX_SCHEDULE:
        raise SpecError(f"schedule={shorten(text)} is invalid: {len(items)} commands, at most {MAX_SCHEDULE}")
    out = []
    for item in items:
        kind, _, rest = item.partition("@")
        at, _, value = rest.partition("=")
        rule = (
            f"schedule={shorten(text)} is invalid: {shorten(item)} must be KIND@SECONDS "
            f"(KIND one of {', '.join(COMMANDS)}; override@SECONDS=FACTOR)"
        )
        try:
            t = float(at)
            f = float(value) if value else 1.0
        except ValueError:
            raise SpecError(rule) from None
        if (
            kind not in COMMANDS
            or not (math.isfinite(t) and SCHEDULE_SECONDS[0] <= t <= SCHEDULE_SECONDS[1])
            or (kind == "override") != bool(value)
        ):
            raise SpecError(f"{rule}; SECONDS in {interval(*SCHEDULE_SECONDS)}")
        if kind == "override" and not OVERRIDE_RANGE[0] <= f <= OVERRIDE_RANGE[1]:
            raise SpecError(
                f"schedule={shorten(text)} is invalid: override factor {f:g} is not in {OVERRIDE_TEXT}"
            )
        out.append((item, Command(round(t * 1e9), kind, f)))
    return out


def parse_schedule(text: str) -> list[Command]:
    """``"pause@1.5,resume@3,override@4=0.5,abort@9"`` (times in s of simulated
    time since the job's start) as commands in time order; SpecError (one
    line) naming the item and the rule. What a job description carries is
    read with it; a setting is checked with :func:`check_schedule`."""
    return sorted((c for _, c in _schedule_items(text)), key=lambda c: c.t_ns)


def check_schedule(text: str) -> list[Command]:
    """:func:`parse_schedule` as a setting is checked (the interp node's
    ``schedule``, ``winder run --schedule``, ``--check`` included): besides
    each item's rule, the commands are written in increasing time (none
    twice, none at the time of the one before), and each can be taken where
    it stands: a pause while running, a resume while paused, nothing after an
    abort; and no item is empty (``",,,"``: two commas side by side, or one at
    an end, say nothing, and are not taken as no command). SpecError (one
    line) naming the item and the rule."""
    written = text.split(",")
    if text.strip() and not all(t.strip() for t in written):
        raise SpecError(
            f"schedule={shorten(text)} is invalid: it has an empty item (two ',' side by side, or one at an "
            "end); leave out the ',' or give the command"
        )
    items = _schedule_items(text)
    paused, aborted = False, ""
    for i, (item, cmd) in enumerate(items):
        bad = f"schedule={shorten(text)} is invalid: {shorten(item)}"
        if i and cmd.t_ns <= items[i - 1][1].t_ns:
            before = items[i - 1][0]
            raise SpecError(
                f"{bad} is not later than {shorten(before)}, the command before it: the times must increase"
            )
        if aborted:
            raise SpecError(f"{bad} comes after {shorten(aborted)}: an aborted job takes no more commands")
        if cmd.kind == "pause" and paused:
            raise SpecError(f"{bad} pauses a paused job: resume first")
        if cmd.kind == "resume" and not paused:
            raise SpecError(f"{bad} resumes a job that is not paused: pause first")
        paused = {"pause": True, "resume": False}.get(cmd.kind, paused)
        aborted = item if cmd.kind == "abort" else ""
    return [c for _, c in items]


@dataclass
class _Piece:
    t0: int  # ns: when it starts
    p0: float  # where it starts, in steps since the move's start
    profile: Motion  # times from t0, positions from p0
    kind: str = "plan"  # plan, stop, override, resume


@dataclass
class _Move:
    seg: int
    k0: int  # steps of the segment before the move: it covers k0+1 .. k1
    k1: int
    profile: Motion  # as planned, from rest to rest
    gap_ns: int  # the planned rest after it (a dwell, a programmed stop's pause)
    pieces: list[_Piece] = field(default_factory=list)
    speed: float = 1.0  # its fraction of v_max (a job's first_layer_speed), under any override
    waiting: bool = False  # it waits for a resume: not started yet
    rest_at: float | None = None  # a stop left it here; the rest waits for a resume

    @property
    def length(self) -> int:
        return self.k1 - self.k0

    @property
    def start_ns(self) -> int:
        return self.pieces[0].t0

    @property
    def end_ns(self) -> int:
        last = self.pieces[-1]
        return last.t0 + round(last.profile.duration * 1e9)


class Timeline:
    """The time law of a job's moves, changed by commands (see the module doc)."""

    def __init__(self, values: dict[str, Any], timings: list[SegmentTiming]) -> None:
        self.v_max = float(values["v_max"])
        self.factor = 1.0
        self.moves: list[_Move] = []
        self.by_seg: dict[int, list[int]] = {}
        for seg, timing in enumerate(timings):
            k0 = 0
            for k1, profile, start in zip(timing.ends, timing.profiles, timing.starts_ns, strict=True):
                t0 = timing.t0_ns + start
                mv = _Move(seg, k0, k1, profile, 0, [_Piece(t0, 0.0, profile)], speed=timing.speed)
                if self.moves:
                    self.moves[-1].gap_ns = t0 - self.moves[-1].end_ns
                self.by_seg.setdefault(seg, []).append(len(self.moves))
                self.moves.append(mv)
                k0 = k1
        self.paused = False  # a pause or abort holds what follows
        self.held = len(self.moves)  # the first move that waits (or whose rest waits)
        self.rest_ns = 0  # when the axes came (or come) to rest at the pause
        self.gap_left_ns = 0  # of a rest between moves the pause fell into
        self.aborted = False
        self.end_step: tuple[int, int] | None = None  # after an abort: (segment, last step index)
        self.events: list[dict[str, Any]] = []

    # -- steps -----------------------------------------------------------
    def times_ns(self, seg: int, k: npt.NDArray[np.integer[Any]]) -> tuple[npt.NDArray[np.int64], int]:
        """The times (ns) of the longest prefix of steps ``k`` (1-based indices
        of segment ``seg``, increasing) that the law fixes now, and its length:
        steps after a pause wait for the resume; after an abort, steps beyond
        the end are never timed."""
        out = np.empty(k.shape, np.int64)
        done = 0
        for m in self.by_seg.get(seg, ()):
            mv = self.moves[m]
            lo = int(np.searchsorted(k, mv.k0, side="right"))
            hi = int(np.searchsorted(k, mv.k1, side="right"))
            if hi <= lo or lo > done:
                continue
            if mv.waiting:
                return out[:done], done
            x = (k[lo:hi] - mv.k0).astype(np.float64)
            limit = len(x)
            if mv.rest_at is not None:
                limit = int(np.searchsorted(x, _reached(mv.rest_at), side="right"))
            # a step a stop came within _SNAP of counts as reached at the rest
            # (the pause's event counts it): it stays the stop's, not the resume's
            starts = [_reached(pc.p0) if pc.kind == "resume" else pc.p0 for pc in mv.pieces[1:]]
            which = np.searchsorted(
                np.asarray(starts), x[:limit], side="left"
            )  # x <= p0 of the next: this one
            for i, pc in enumerate(mv.pieces):
                sel = which == i
                if not sel.any():
                    continue
                local = np.clip(x[:limit][sel] - pc.p0, 0.0, pc.profile.distance)
                out[lo : lo + limit][sel] = pc.t0 + np.rint(pc.profile.times_at(local) * 1e9).astype(np.int64)
            done = lo + limit
            if limit < len(x):
                return out[:done], done
        return out[:done], done

    def beyond_end(self, seg: int, k: npt.NDArray[np.integer[Any]]) -> npt.NDArray[np.bool_]:
        """After an abort: which steps ``k`` of segment ``seg`` are past its end."""
        if self.end_step is None:
            return np.zeros(k.shape, bool)
        end_seg, end_k = self.end_step
        return (
            np.full(k.shape, True)
            if seg > end_seg
            else (k > end_k if seg == end_seg else np.zeros(k.shape, bool))
        )

    @property
    def duration_ns(self) -> int:
        """When the last move ends as the law stands (ends of waiting moves as planned)."""
        return max((mv.end_ns for mv in self.moves if not mv.waiting), default=0)

    # -- where the motion is ----------------------------------------------
    def _locate(self, t: int) -> tuple[int, int | None]:
        """(move, piece) in motion at ``t``; (move, None) at rest before that
        move (a rest between moves, or a move waiting); (len, None) after all."""
        for m, mv in enumerate(self.moves):
            if mv.waiting or t < mv.start_ns:
                return m, None
            if t < mv.end_ns:
                i = max(j for j, pc in enumerate(mv.pieces) if pc.t0 <= t)
                return m, i
        return len(self.moves), None

    def _steps_before(self, m: int) -> int:
        return sum(mv.length for mv in self.moves[:m])

    def _shift_from(self, m: int, start: int) -> None:
        """Moves ``m`` on start at ``start``, one after another with their planned rests."""
        for mv in self.moves[m:]:
            mv.waiting = False
            mv.pieces = [_Piece(start, 0.0, mv.pieces[0].profile if mv.pieces else mv.profile)]
            start = mv.end_ns + mv.gap_ns

    def _replan_from(self, m: int) -> None:
        """Moves ``m`` on (not started) with the current override."""
        v = self.v_max * self.factor
        for mv in self.moves[m:]:
            prof = mv.profile if self.factor == 1.0 else from_rest(mv.profile, float(mv.length), v * mv.speed)
            mv.pieces = [_Piece(mv.pieces[0].t0, 0.0, prof)]

    # -- commands ----------------------------------------------------------
    def apply(self, cmd: Command, source: str = "call") -> dict[str, Any]:
        """Apply one command at its time; the event (what happens, when), or
        CommandError (one line) if the job cannot take it now."""
        if self.aborted:
            raise CommandError("the job is aborted: it takes no more commands")
        handler = {
            "pause": self._pause,
            "resume": self._resume,
            "abort": self._abort,
            "override": self._override,
        }
        event = handler[cmd.kind](cmd)
        event = {"event": cmd.kind, "source": source, "t_ns": cmd.t_ns, **event}
        self.events.append(event)
        return event

    def _stop(self, t: int) -> dict[str, Any]:
        """Bring the motion at ``t`` to rest and hold what follows."""
        m, i = self._locate(t)
        if m == len(self.moves):
            raise CommandError("the job's motion is over: nothing to stop")
        state: dict[str, Any] = {"v": 0.0, "a": 0.0, "stop_distance": 0.0}
        if i is None:  # at rest between moves: what follows waits
            nxt = self.moves[m]
            self.gap_left_ns = max(nxt.start_ns - t, 0) if not nxt.waiting else self.gap_left_ns
            self.held, self.rest_ns = m, t
            for mv in self.moves[m:]:
                mv.waiting = True
            seg, step = (self.moves[m - 1].seg, self.moves[m - 1].k1) if m else (nxt.seg, nxt.k0)
            return {**state, "t_rest_ns": t, "segment": seg, "step": step, "steps": self._steps_before(m)}
        mv = self.moves[m]
        pc = mv.pieces[i]
        if pc.kind == "stop":
            raise CommandError("the axes are already stopping")
        tau = (t - pc.t0) / 1e9
        p, v, a = motion_state(pc.profile, tau)
        tail = stop_tail(pc.profile, tau)
        pos = pc.p0 + p
        del mv.pieces[i + 1 :]
        mv.pieces.append(_Piece(t, pos, tail, "stop"))
        rest = pos + tail.distance
        self.rest_ns = t + round(tail.duration * 1e9)
        self.gap_left_ns = mv.gap_ns
        if rest >= mv.length * (1 - _SNAP) - _SNAP:  # the stop ends the move: the next ones wait
            self.held = m + 1
        else:
            mv.rest_at = rest
            self.held = m
        for later in self.moves[m + 1 :]:
            later.waiting = True
        step = mv.k0 + min(math.floor(_reached(rest)), mv.length)
        return {
            "v": v, "a": a, "stop_distance": tail.distance, "t_rest_ns": self.rest_ns,
            "segment": mv.seg, "step": step, "steps": self._steps_before(m) + step - mv.k0,
        }  # fmt: skip

    def _pause(self, cmd: Command) -> dict[str, Any]:
        if self.paused:
            raise CommandError("already paused: resume first")
        event = self._stop(cmd.t_ns)
        self.paused = True
        return event

    def _resume(self, cmd: Command) -> dict[str, Any]:
        if not self.paused:
            raise CommandError("not paused: nothing to resume")
        t = max(cmd.t_ns, self.rest_ns)
        m = self.held
        if m < len(self.moves) and self.moves[m].rest_at is not None:
            mv = self.moves[m]
            rest = mv.rest_at
            assert rest is not None
            mv.rest_at = None
            prof = from_rest(mv.profile, mv.length - rest, self.v_max * self.factor * mv.speed)
            mv.pieces.append(_Piece(t, rest, prof, "resume"))
            self._shift_from(m + 1, mv.end_ns + mv.gap_ns)
            seg, step = mv.seg, mv.k0 + math.floor(_reached(rest))
            steps = self._steps_before(m) + step - mv.k0
        else:
            self._shift_from(m, t + self.gap_left_ns)
            prev = self.moves[m - 1] if m else None
            seg, step = (prev.seg, prev.k1) if prev else (0, 0)
            steps = self._steps_before(m)
        self.paused = False
        return {"t_ns": t, "segment": seg, "step": step, "steps": steps}

    def _abort(self, cmd: Command) -> dict[str, Any]:
        if self.paused:  # at rest already (or stopping): the job ends where the stop ends
            m = self.held
            mv = self.moves[m] if m < len(self.moves) else None
            if mv is not None and mv.rest_at is not None:
                step = mv.k0 + min(math.floor(_reached(mv.rest_at)), mv.length)
                steps, seg = self._steps_before(m) + step - mv.k0, mv.seg
            else:
                prev = self.moves[m - 1] if m else None
                seg, step = (prev.seg, prev.k1) if prev else (0, 0)
                steps = self._steps_before(m)
            event = {"v": 0.0, "a": 0.0, "stop_distance": 0.0, "t_rest_ns": max(cmd.t_ns, self.rest_ns)}
            event.update(segment=seg, step=step, steps=steps)
        else:
            event = self._stop(cmd.t_ns)
        self.paused = True
        self.aborted = True
        self.end_step = (int(event["segment"]), int(event["step"]))
        return event

    def _override(self, cmd: Command) -> dict[str, Any]:
        f = cmd.value
        if not OVERRIDE_RANGE[0] <= f <= OVERRIDE_RANGE[1]:
            raise CommandError(f"feed_override={f:g} is invalid: must be in {OVERRIDE_TEXT}")
        self.factor = f
        v = self.v_max * f
        note = "applied"
        m, i = self._locate(cmd.t_ns)
        if self.paused:
            held = self.moves[self.held] if self.held < len(self.moves) else None
            self._replan_from(self.held + (1 if held is not None and held.rest_at is not None else 0))
            return {"factor": f, "v_max": v, "note": "paused: applies from the resume"}
        if i is not None:
            mv = self.moves[m]
            pc = mv.pieces[i]
            tau = (cmd.t_ns - pc.t0) / 1e9
            p, _, _ = motion_state(pc.profile, tau)
            pos = pc.p0 + p
            tail = (
                continue_tail(pc.profile, tau, mv.length - pos, v * mv.speed) if pc.kind != "stop" else None
            )
            if tail is None:
                note = "the move is braking for its end: the override applies from the next one"
            else:
                del mv.pieces[i + 1 :]
                mv.pieces.append(_Piece(cmd.t_ns, pos, tail, "override"))
            self._replan_from(m + 1)
            self._shift_from(m + 1, mv.end_ns + mv.gap_ns)
        elif m < len(self.moves):
            note = "at rest: applies from the next move"
            self._replan_from(m)
            self._shift_from(m, self.moves[m].start_ns)
        return {"factor": f, "v_max": v, "note": note}
