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
        self.parted: float | None = None  # the wire paid out when it parted (None: whole)
        self.cause = ""  # why it parted, where the simulation knows (pulled to its breaking load)
        self.watch = WireWatch(set_n, job.tension_slip_tolerance)
        self.fault: WireFault | None = None
        # the job's turns before each coil: a job's turn is these plus the coil's
        before: dict[int, int] = {}
        for seg in segments:
            if seg.kind.winds:
                before[seg.pole] = max(before.get(seg.pole, 0), seg.last_turn)
        self.turns_before = {p: sum(before.get(q, 0) for q in range(p)) for p in range(job.poles)}

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

    # -- where the flyer is -------------------------------------------------------
    def places(self, fork: Floats, segs: Ints) -> tuple[Ints, Ints, Ints, Floats]:
        """Per sample the coil, the layer and the coil's turn (from 1; 0 off a
        layer), and the job's turn as a fraction (turns done + the part of
        the present one), from the flyer's position (rad) and the segment."""
        coil = np.zeros(segs.size, np.int64)
        layer = np.zeros(segs.size, np.int64)
        turn = np.zeros(segs.size, np.int64)
        job_turn = np.zeros(segs.size)
        for i in np.unique(segs):
            if not 0 <= i < len(self.segments) or not self.segments[int(i)].kind.winds:
                continue
            seg = self.segments[int(i)]
            at = segs == i
            done = np.abs(fork[at] / self.fork_step - seg.start[FORK.index]) / seg.turn_steps
            done = np.clip(done, 0.0, float(seg.turns))
            coil[at], layer[at] = seg.pole + 1, seg.layer + 1
            turn[at] = seg.first_turn + np.minimum(np.floor(done).astype(np.int64) + 1, seg.turns)
            job_turn[at] = self.turns_before[seg.pole] + seg.first_turn + done
        return coil, layer, turn, job_turn

    # -- a block of samples -------------------------------------------------------
    def samples(self, t: Floats, fork: Floats, omega: Floats, segs: Ints) -> dict[str, Floats]:
        """The wire at the samples (times s, the flyer's simulated angle and
        speed, rad and rad/s, the segment): ``tension``, ``wire_pos`` and
        ``wire_vel`` (the supply's count, and the dancer's travel if a dancer)."""
        w = self.sim.advance(fork, omega, segs)
        coil, layer, turn, job_turn = self.places(fork, segs)
        tension = w.tension.copy()
        counted = w.supply.copy()
        if self.slip_turn:  # the counter misses slip_length over the turn, evenly
            counted -= self.slip_length * np.clip(job_turn - (self.slip_turn - 1), 0.0, 1.0)
        dancer = self.tensioner.kind == "dancer"
        vel = np.column_stack([w.supply_speed, w.coordinate_rate] if dancer else [w.supply_speed])
        start = self._parts(t, w.tension, w.takeup, counted, job_turn, coil)
        for band, (low, high) in self.bands.items():
            held = tension[:start]  # up to the break
            self.outside[band] += int(np.count_nonzero((held < low) | (held > high)))
        if self.parted is not None:  # from the break on the wire holds nothing; the supply stands
            tension[start:] = 0.0
            counted[start:] = self.parted
            vel[start:] = 0.0
        pos = np.column_stack([counted, w.coordinate] if dancer else [counted])
        if self.parted is not None:
            pos[start:, 1:] = 0.0  # the arm at rest
        expected = w.supply if self.parted is None else np.where(np.arange(t.size) < start, w.supply, counted)

        def place(k: int) -> tuple[int, int, int]:
            return int(coil[k]), int(layer[k]), int(turn[k])

        fault = self.watch.feed(t, tension, omega, place, counted, expected)
        if fault is not None and self.fault is None:
            self.fault = fault
        return {"tension": tension, "wire_pos": pos, "wire_vel": vel}

    def _parts(
        self,
        t: Floats,
        tension: Floats,
        takeup: Floats,
        counted: Floats,
        job_turn: Floats,
        coil: Ints,
    ) -> int:
        """Where in the block the wire parts (its first sample without it;
        the block's size if it holds): pulled to its tensile strength, or the
        injected break's turn reached. Notes a stretch past the yield."""
        if self.parted is not None:
            return 0
        wire, m = self.wire, self.wire.material
        stress = tension / wire.section + m.density * takeup**2 / 2
        over = np.flatnonzero(stress >= m.tensile_strength)
        injected = np.flatnonzero(job_turn >= self.break_turn - 1) if self.break_turn else over[:0]
        injected = injected[coil[injected] > 0]
        if not over.size and not injected.size:
            if stress.size and float(stress.max()) > m.yield_stress:
                self.stretched = max(self.stretched, float(stress.max()))
            return t.size
        k = int(min(over[0] if over.size else t.size, injected[0] if injected.size else t.size))
        if over.size and k == over[0]:
            self.cause = (
                f"pulled to its breaking load: {tension[k]:.4g} N at {takeup[k]:.3g} m/s, "
                f"{stress[k] / 1e6:.4g} MPa against its breaking load {wire.breaking_load:.4g} N, "
                f"{m.tensile_strength / 1e6:.4g} MPa"
            )
        else:
            self.cause = f"injected: fault.wire_break_turn {self.break_turn}"
        self.parted = float(counted[k - 1] if k else counted[0])
        return k

    # -- what the run reports ----------------------------------------------------------
    def fault_text(self) -> str:
        """The fault that stops the run, in words, with its cause where known ("" if none)."""
        if self.fault is None:
            return ""
        cause = f" ({self.cause})" if self.cause and self.fault.kind == "break" else ""
        return self.fault.text + cause

    def details(self) -> dict[str, object]:
        """The job report's keys of the wire."""
        w = self.sim
        return {
            "tension_peak_n": f"{w.peak:.4g}",
            "tension_min_n": f"{w.least:.4g}",
            TRAVEL_KEY.get(w.tensioner.kind, "tensioner_coordinate_max"): f"{w.travel:.4g}",
            "wire_taken_m": f"{w.taken:.6g}",
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
                f"{self.outside['alarm'] / self.rate:.3f} s ({self.sim.least:.4g}..{self.sim.peak:.4g} N)"
            )
        if self.stretched:
            m = self.wire.material
            rise = self.wire.resistance_rise(self.stretched)
            said.append(
                f"the wire was stretched past its yield ({self.stretched / 1e6:.4g} MPa against "
                f"{m.yield_stress / 1e6:.4g} MPa): its resistance rose by {rise:.3%} where it was"
            )
        return said
