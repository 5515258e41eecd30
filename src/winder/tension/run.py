"""The wire of one simulated run, as the sim node drives it sample by sample
(ROS-free): the wire drawn by the simulated flyer (:class:`winder.tension.sim.WireSim`),
what happens to it (the bands, a stretch past the yield, a break at the
tensile strength, the faults injected for tests and operator training) and
the watch that catches a break or a slip from what the sensors show
(:class:`winder.tension.watch.WireWatch`).

Per block of samples :meth:`WireRun.samples` gives what the sim node
publishes: the tension (the load cell; 0 once the wire broke), the supply's
pay-out counter (the wire paid out, as counted: a slip makes it miss some)
and the tensioner's coordinate, and their rates. Injected faults (the sim
node's ``fault.*`` settings):

* ``fault.wire_break_turn`` N: the wire parts as the flyer starts the job's
  turn N (counted from 1 over its coils): no tension from there, the
  supply stands;
* ``fault.slip_turn`` N: over the job's turn N the supply's counter misses
  ``fault.slip_length`` of the wire drawn (spread evenly over the turn).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from winder.motion.axes import FORK
from winder.motion.job import Job, Segment
from winder.motion.takeup import Contour
from winder.tension.sim import WireSim
from winder.tension.tensioner import tensioner_of
from winder.tension.watch import WireFault, WireWatch

__all__ = ["TRAVEL_KEY", "WireRun"]

Floats = npt.NDArray[np.float64]
Ints = npt.NDArray[np.int64]

#: the job report's key of the tensioner's largest excursion
TRAVEL_KEY = {"dancer": "dancer_travel_max_m", "servo": "servo_feed_max_m_s"}


class WireRun:
    """The wire of a run of ``job`` over its ``segments`` (see the module
    doc), sampled at ``rate`` Hz; ``values``: the sim node's settings (the
    tensioner, the faults); ``fork_step``: the fork joint's rad a step.
    :meth:`of` makes one, or says why the wire is not simulated."""

    def __init__(
        self, job: Job, segments: Sequence[Segment], values: dict[str, Any], rate: float, fork_step: float
    ) -> None:
        self.job, self.segments, self.rate, self.fork_step = job, segments, rate, fork_step
        self.wire = job.wire
        contours: dict[int, Contour | None] = {}
        for seg in segments:
            if seg.kind.winds:
                contours[seg.index] = job.bobbin.contour(job.winding.coils[seg.pole].layers[seg.layer].radius)
        self.tensioner = tensioner_of(values, self.wire.stiffness_per_length, job.set_tension)
        self.sim = WireSim(self.tensioner, contours, job.flyer_radius, 1.0 / rate)
        set_n = job.set_tension
        self.bands = {
            "warning": (set_n * (1 - job.tension_warning), set_n * (1 + job.tension_warning)),
            "alarm": (set_n * (1 - job.tension_alarm), set_n * (1 + job.tension_alarm)),
        }
        self.outside = {"warning": 0, "alarm": 0}  # samples with the tension outside each band
        self.stretched = 0.0  # the highest stress past the wire's yield (Pa; 0: none)
        self.break_turn = int(values.get("fault.wire_break_turn", 0))
        self.slip_turn = int(values.get("fault.slip_turn", 0))
        self.slip_length = float(values.get("fault.slip_length", 0.0))
        self.parted: float | None = None  # the supply's count when the wire parted (None: whole)
        self.last_count = 0.0  # the supply's count at the last sample
        self.slipped = 0.0  # the share of the injected slip the counter has missed
        self.peak = self.least = job.set_tension  # the tension's range over the run's samples (N)
        self.travel = 0.0  # the tensioner's largest excursion
        self.taken = 0.0  # the wire the turns took (m)
        self.cause = ""  # why it parted, where the simulation knows (pulled to its breaking load)
        self.watch = WireWatch(set_n, job.tension_slip_tolerance)
        self.fault: WireFault | None = None
        # the job's turns before each coil: a job's turn is these plus the coil's
        turns = [coil.total_turns for coil in job.winding.coils]
        self.turns_before = {p: sum(turns[:p]) for p in range(job.poles)}
        self.total_turns = sum(turns)

    @classmethod
    def of(
        cls, job: Job, segments: Sequence[Segment], values: dict[str, Any], rate: float, fork_step: float
    ) -> tuple[WireRun | None, str]:
        """The run's wire, or None and why not ("": the job does not give its
        core, so nothing of the wire is known)."""
        if not job.bobbin.core_given:
            return None, ""
        wire = cls(job, segments, values, rate, fork_step)
        why = wire.tensioner.unstable()
        return (None, why) if why else (wire, "")

    def idle_faults(self) -> list[str]:
        """The injected faults that cannot fire in this job (a turn beyond its turns), in words."""
        return [
            f"{name} {turn} is beyond the job's {self.total_turns} turns: it never fires"
            for name, turn in (
                ("fault.wire_break_turn", self.break_turn),
                ("fault.slip_turn", self.slip_turn),
            )
            if turn > self.total_turns
        ]

    # -- where the flyer is -------------------------------------------------------
    def places(self, fork: Floats, segs: Ints) -> tuple[Ints, Ints, Ints, Ints, Floats]:
        """Per sample the coil, the layer and the coil's turn in progress
        (from 1; 0 off a layer), the job's turn in progress (from 1, counted
        over its coils; 0 off a layer) and how far into it the flyer is (0
        to 1), from the flyer's position (rad) and the segment. A layer's
        reversal dwell belongs to its last turn (:meth:`Segment.turn_end`)."""
        coil = np.zeros(segs.size, np.int64)
        layer = np.zeros(segs.size, np.int64)
        turn = np.zeros(segs.size, np.int64)
        job_turn = np.zeros(segs.size, np.int64)
        into = np.zeros(segs.size)
        for i in np.unique(segs):
            if not 0 <= i < len(self.segments) or not self.segments[int(i)].kind.winds:
                continue
            seg = self.segments[int(i)]
            at = segs == i
            done = np.maximum(np.abs(fork[at] / self.fork_step - seg.start[FORK.index]) / seg.turn_steps, 0.0)
            k = np.minimum(np.floor(done).astype(np.int64), seg.turns - 1)  # the turn in progress, from 0
            coil[at], layer[at] = seg.pole + 1, seg.layer + 1
            turn[at] = seg.first_turn + k + 1
            job_turn[at] = self.turns_before[seg.pole] + seg.first_turn + k + 1
            into[at] = np.clip(done - k, 0.0, 1.0)
        return coil, layer, turn, job_turn, into

    # -- a block of samples -------------------------------------------------------
    def samples(self, t: Floats, fork: Floats, omega: Floats, segs: Ints) -> tuple[dict[str, Floats], int]:
        """The wire at the samples (times s, the flyer's simulated angle and
        speed, rad and rad/s, the segment): ``tension``, ``wire_pos`` and
        ``wire_vel`` (the supply's count, and the dancer's travel if a
        dancer), and how many of them the run keeps: all, or up to the
        sample at which the watch saw a fault (the axes stop there; the
        run's figures count no sample after it)."""
        w = self.sim.advance(fork, omega, segs)
        coil, layer, turn, job_turn, into = self.places(fork, segs)
        tension = w.tension.copy()
        counted = w.supply.copy()
        if self.slip_turn:  # the counter misses slip_length over the turn, evenly, and for good
            share = np.where(job_turn == self.slip_turn, into, (job_turn > self.slip_turn).astype(float))
            missed = np.maximum.accumulate(np.maximum(share, self.slipped))
            counted -= self.slip_length * missed
            self.slipped = float(missed[-1]) if missed.size else self.slipped
        dancer = self.tensioner.kind == "dancer"
        vel = np.column_stack([w.supply_speed, w.coordinate_rate] if dancer else [w.supply_speed])
        start = self._parts(t, w.tension, w.takeup, counted, job_turn)
        if self.parted is not None:  # from the break on the wire holds nothing; the supply stands
            tension[start:] = 0.0
            counted[start:] = self.parted
            vel[start:] = 0.0
        if counted.size:
            self.last_count = float(counted[-1])
        pos = np.column_stack([counted, w.coordinate] if dancer else [counted])
        if self.parted is not None:
            pos[start:, 1:] = 0.0  # the arm at rest
        expected = w.supply if self.parted is None else np.where(np.arange(t.size) < start, w.supply, counted)

        def place(k: int) -> tuple[int, int, int]:
            return int(coil[k]), int(layer[k]), int(turn[k])

        fault = self.watch.feed(t, tension, omega, place, counted, expected)
        keep = t.size
        if fault is not None and self.fault is None:
            self.fault = fault
            keep = int(np.searchsorted(t, fault.seen_s, side="right"))
        self._tally(tension[:keep], np.abs(w.coordinate[:keep]), w.taken[:keep])
        return {"tension": tension, "wire_pos": pos, "wire_vel": vel}, keep

    def _tally(self, tension: Floats, travel: Floats, taken: Floats) -> None:
        """The run's figures over the samples it keeps: the tension's range,
        the time outside each band, the tensioner's travel, the wire taken."""
        if not tension.size:
            return
        self.peak = max(self.peak, float(tension.max()))
        self.least = min(self.least, float(tension.min()))
        self.travel = max(self.travel, float(travel.max()))
        self.taken = float(taken[-1])
        for band, (low, high) in self.bands.items():
            self.outside[band] += int(np.count_nonzero((tension < low) | (tension > high)))

    def _parts(self, t: Floats, tension: Floats, takeup: Floats, counted: Floats, job_turn: Ints) -> int:
        """Where in the block the wire parts (its first sample without it;
        the block's size if it holds): pulled to its tensile strength, or the
        flyer starting the injected break's turn. Notes a stretch past the yield."""
        if self.parted is not None:
            return 0
        wire, m = self.wire, self.wire.material
        stress = tension / wire.section + m.density * takeup**2 / 2
        over = np.flatnonzero(stress >= m.tensile_strength)
        injected = np.flatnonzero(job_turn >= self.break_turn) if self.break_turn else over[:0]
        if not over.size and not injected.size:
            if stress.size and float(stress.max()) > m.yield_stress:
                self.stretched = max(self.stretched, float(stress.max()))
            return t.size
        k = int(min(over[0] if over.size else t.size, injected[0] if injected.size else t.size))
        if k and float(stress[:k].max()) > m.yield_stress:
            self.stretched = max(self.stretched, float(stress[:k].max()))
        if over.size and k == over[0]:
            self.cause = (
                f"pulled to its breaking load: {tension[k]:.4g} N at {takeup[k]:.3g} m/s, "
                f"{stress[k] / 1e6:.4g} MPa against its breaking load {wire.breaking_load:.4g} N, "
                f"{m.tensile_strength / 1e6:.4g} MPa"
            )
        else:
            self.cause = f"injected: fault.wire_break_turn {self.break_turn}"
        self.parted = float(counted[k - 1]) if k else self.last_count
        return k

    # -- what the run reports ----------------------------------------------------------
    def fault_text(self) -> str:
        """The fault that stops the run, in words, with its cause where known ("" if none)."""
        if self.fault is None:
            return ""
        if self.fault.kind == "break":
            # the watch sees the tension only: the simulation knows whether the wire parted
            cause = self.cause or "the wire is whole: it went slack"
        else:
            cause = f"injected: fault.slip_turn {self.slip_turn}" if self.slip_turn else ""
        return self.fault.text + (f" ({cause})" if cause else "")

    def details(self) -> dict[str, object]:
        """The job report's keys of the wire."""
        return {
            "tension_peak_n": f"{self.peak:.4g}",
            "tension_min_n": f"{self.least:.4g}",
            TRAVEL_KEY.get(self.tensioner.kind, "tensioner_coordinate_max"): f"{self.travel:.4g}",
            "wire_taken_m": f"{self.taken:.6g}",
            "tension_outside_warning_s": f"{self.outside['warning'] / self.rate:.3f}",
            "tension_outside_alarm_s": f"{self.outside['alarm'] / self.rate:.3f}",
        }

    def faults(self) -> list[str]:
        """What went wrong with the wire, in words (the run's fault): the
        break or slip, or the time outside the alarm band and a stretch past
        the yield."""
        if self.fault is not None:
            return [self.fault_text()]
        said = []
        if self.outside["alarm"]:
            low, high = self.bands["alarm"]
            said.append(
                f"the wire's tension left the alarm band ({low:.4g}..{high:.4g} N) for "
                f"{self.outside['alarm'] / self.rate:.3f} s ({self.least:.4g}..{self.peak:.4g} N)"
            )
        if self.stretched:
            m = self.wire.material
            rise = self.wire.resistance_rise(self.stretched)
            said.append(
                f"the wire was stretched past its yield ({self.stretched / 1e6:.4g} MPa against "
                f"{m.yield_stress / 1e6:.4g} MPa): its resistance rose by {rise:.3%} where it was"
            )
        return said
