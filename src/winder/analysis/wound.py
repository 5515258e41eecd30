"""The coil as wound: where each turn was laid, from the simulated axes in a
bag, against where it should lie.

A turn of a layer is laid where the feed stands while the flyer lays it: on
a helical layer when the flyer is half way through the turn (for turn k of a
layer, k from 0, the flyer ``(k + 1/2)`` turns past the layer's start); on an
orthocyclic layer, whose feed holds each turn and crosses over in a zone of
the flyer angle, in the middle of the turn's hold (between the end of the
crossover before it and the start of the one after it). The measured place
is the feed's position at the moment the measured flyer angle passes that
point (linear interpolation between joint samples); the intended place is
the commanded cam's (the layer's straight pieces) at the same angle. Both are
given as the distance of the wire's centre from the coil's start flange: the
feed position where the coil's first layer starts (helical), half a wire
diameter before the first turn's place (orthocyclic). The first turn of a
layer against the start flange is at d/2.

Per layer it reports the turns laid, the largest axial error, and these
defects (``tolerance``: 10 % of the wire diameter unless given):

* ``gap`` / ``overlap``: neighbouring turns of a layer further apart, or
  closer, than the wire diameter by more than the tolerance;
* ``offset``: a turn laid further than the tolerance from its place;
* ``flange``: a turn whose centre lies nearer a flange than half a wire
  diameter less the tolerance (it climbs onto the flange), or beyond it;
* ``crossover`` (orthocyclic): the feed moved by more than the tolerance
  while the turn held, outside its crossover zone;
* ``stretched`` / ``slack`` (a run that simulated the wire): the wire's
  stress (:func:`winder.analysis.wire.stresses`) passed its yield while the
  turn was wound (its size: the stretch it kept, strain x the turn's
  length), or its tension fell below the alarm band (size 0). A turn is
  wound from the moment the measured flyer begins it to the one it ends it.

The window is ``bobbin.window_width`` when the job sets one, else the room the
job's turns take (``turns_per_layer`` x d, plus d/2 on a shifted layer);
layers stack at the lay's radial pitch (d helical, d·√3/2 orthocyclic), the
centre of layer l at d/2 + (l - 1)·pitch above the core.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from winder.analysis.wire import stresses, tension_joints
from winder.motion.axes import FEED, FORK
from winder.motion.coil import radial_pitch
from winder.motion.job import Segment
from winder.record.reader import Run

__all__ = ["DEFECT_KINDS", "AsWound", "Defect", "LayerLaid", "TurnLaid", "as_wound"]

FloatArray = npt.NDArray[np.float64]

DEFECT_KINDS = ("gap", "overlap", "offset", "flange", "crossover", "stretched", "slack")
#: the default tolerance, as a fraction of the wire diameter
TOLERANCE = 0.10


@dataclass(frozen=True)
class TurnLaid:
    coil: int  #: from 1
    layer: int  #: from 1
    turn: int  #: from 1, in the order wound
    t_s: float  #: when the flyer laid it (half way through it, or its hold; s since the run's start)
    axial_m: float  #: measured centre, from the coil's start flange
    intended_m: float  #: where it should be
    radial_m: float  #: centre of its layer above the core

    @property
    def error_m(self) -> float:
        return self.axial_m - self.intended_m


@dataclass(frozen=True)
class Defect:
    kind: str  #: one of DEFECT_KINDS
    coil: int
    layer: int
    turn: int  #: the turn it concerns (a gap or overlap: the later of the two)
    #: by how much (gap/overlap: spacing - d; offset: error; flange: how far past d/2;
    #: stretched: the stretch the turn's wire kept; slack: 0)
    size_m: float
    t_s: float

    def to_json(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "coil": self.coil,
            "layer": self.layer,
            "turn": self.turn,
            "size_m": self.size_m,
            "t_s": self.t_s,
        }


@dataclass(frozen=True)
class LayerLaid:
    coil: int
    layer: int
    turns_planned: int
    turns_laid: int
    max_axial_error_m: float  #: NaN if no turn was laid
    radial_m: float
    defects: dict[str, int]  #: kind -> count

    def to_json(self) -> dict[str, Any]:
        err = self.max_axial_error_m
        return {
            "coil": self.coil,
            "layer": self.layer,
            "turns_planned": self.turns_planned,
            "turns": self.turns_laid,
            "max_axial_error_m": None if math.isnan(err) else err,
            "radial_m": self.radial_m,
            **{k: self.defects.get(k, 0) for k in DEFECT_KINDS},
        }


@dataclass
class AsWound:
    wire_m: float
    window_m: float
    tolerance_m: float
    turns: list[TurnLaid] = field(default_factory=list)
    layers: list[LayerLaid] = field(default_factory=list)
    defects: list[Defect] = field(default_factory=list)

    def turns_per_layer(self) -> list[list[int]]:
        """Turns laid per layer, coil by coil."""
        out: dict[int, list[int]] = {}
        for lay in self.layers:
            out.setdefault(lay.coil, []).append(lay.turns_laid)
        return [out[c] for c in sorted(out)]

    def to_json(self) -> dict[str, Any]:
        return {
            "wire_diameter_m": self.wire_m,
            "window_width_m": self.window_m,
            "tolerance_m": self.tolerance_m,
            "turns_per_layer": self.turns_per_layer(),
            "layers": [lay.to_json() for lay in self.layers],
            "defects": [d.to_json() for d in self.defects],
        }


def _segment_windows(run: Run) -> dict[int, tuple[float, float]]:
    """Each segment's first and last step time (s), from the recorded rows."""
    first: dict[int, int] = {}
    last: dict[int, int] = {}
    for rows in run.step_rows:
        if rows.shape[0] == 0:
            continue
        segs = rows[:, 1]
        for seg in np.unique(segs):
            times = rows[segs == seg, 0]
            s = int(seg)
            first[s] = min(first.get(s, int(times[0])), int(times.min()))
            last[s] = max(last.get(s, int(times[-1])), int(times.max()))
    return {s: (first[s] / 1e9, last[s] / 1e9) for s in first}


def _window_width(job: Any, turns: int, offset: float = 0.0) -> float:
    """The window's width: the job's, else the room its ``turns`` take (a
    shifted layer's ``offset`` included)."""
    for name in ("bobbin_window_width", "window_width", "coil_length"):
        value = getattr(job, name, 0.0)
        if isinstance(value, int | float) and value > 0:
            return float(value)
    return turns * float(job.wire_diameter) + offset


def _windows_from_ends(ends: dict[int, int]) -> dict[int, tuple[float, float]]:
    """Each segment's time span (s), from the time of every segment's last
    row (:attr:`winder.analysis.digest.Digest.segment_end`): from the end of
    the segment before it (a little wide across a pause: harmless)."""
    out: dict[int, tuple[float, float]] = {}
    before = 0
    for seg in sorted(ends):
        out[seg] = (before / 1e9, ends[seg] / 1e9)
        before = ends[seg]
    return out


def as_wound(
    run: Run, tolerance: float | None = None, segment_end: dict[int, int] | None = None
) -> AsWound | None:
    """The turns as laid by the simulated axes of ``run`` (None without joint
    samples). ``segment_end``: the digest's last row time per segment, if
    made already (else the rows are read again)."""
    states = run.states
    if len(states) < 2:
        return None
    job = run.plan.job
    d = float(job.wire_diameter)
    tol = TOLERANCE * d if tolerance is None else float(tolerance)
    feed_step = float(job.feed_step)
    fork_rad = 2 * math.pi / job.fork_steps_per_rev
    windows = _segment_windows(run) if segment_end is None else _windows_from_ends(segment_end)
    t = states.t
    feed = states.pos[:, 0]
    fork = states.pos[:, 1]
    layer_segments = [s for s in run.plan.segments if s.kind.winds]
    ortho = getattr(job, "lay", "helical") == "orthocyclic"
    pitch = radial_pitch(d, "orthocyclic" if ortho else "helical")
    coil_start: dict[int, tuple[float, int]] = {}  # coil -> (start flange feed position m, direction)
    joint = tension_joints(run)
    result = AsWound(wire_m=d, window_m=0.0, tolerance_m=tol)
    for seg in layer_segments:
        n = seg.turns
        if seg.pole not in coil_start:
            going = 1 if seg.delta[FEED.index] >= 0 else -1
            if ortho and seg.delta[FEED.index] == 0:  # a one-turn layer: the first crossover names the way
                going = next((1 if p[0] > 0 else -1 for p in seg.pieces if p[0]), 1)
            coil_start[seg.pole] = (
                seg.start[FEED.index] * feed_step - (going * d / 2 if ortho else 0.0),
                going,
            )
        flange, coil_dir = coil_start[seg.pole]
        width = _window_width(job, n, d / 2 if ortho and seg.layer % 2 else 0.0)
        result.window_m = max(result.window_m, width)
        radial = d / 2 + seg.layer * pitch
        marks = _marks(seg, n, job, ortho)
        laid = _lay(seg, marks, t, feed, fork, windows.get(seg.index), feed_step, fork_rad)
        turns = [
            TurnLaid(
                seg.pole + 1,
                seg.layer + 1,
                k + 1,
                ts,
                (f - flange) * coil_dir,
                (fi - flange) * coil_dir,
                radial,
            )
            for k, (ts, f, fi, _) in enumerate(laid)
        ]
        defects = _defects(turns, d, width, tol)
        if ortho:
            defects += [
                Defect("crossover", tt.coil, tt.layer, tt.turn, moved, tt.t_s)
                for tt, (_, _, _, moved) in zip(turns, laid, strict=True)
                if abs(moved) > tol
            ]
        spans = _turn_spans(
            seg, len(turns), t, fork, windows.get(seg.index), fork_rad, job.fork_steps_per_rev
        )
        defects += _wire_defects(run, seg, turns, spans, joint)
        result.turns += turns
        result.defects += defects
        errors = [abs(tt.error_m) for tt in turns]
        counts: dict[str, int] = {}
        for df in defects:
            counts[df.kind] = counts.get(df.kind, 0) + 1
        result.layers.append(
            LayerLaid(
                seg.pole + 1,
                seg.layer + 1,
                n,
                len(turns),
                max(errors) if errors else math.nan,
                radial,
                counts,
            )
        )
    return result


def _marks(seg: Segment, n: int, job: Any, ortho: bool) -> FloatArray:
    """Where each turn of layer ``seg`` is measured, in fork steps from the
    layer's start: (start, middle, end) of the stretch the feed holds the
    turn (orthocyclic) or the turn's middle three times (helical)."""
    spr = float(job.fork_steps_per_rev)
    k = np.arange(n, dtype=np.float64)
    if not ortho:
        mid = (k + 0.5) * spr
        return np.stack([mid, mid, mid], axis=1)
    za, zc = job.crossover_zone
    lo = np.maximum((k - 1) * spr + za + zc, 0.0)
    hi = np.maximum(k * spr + za, lo)
    return np.stack([lo, (lo + hi) / 2, hi], axis=1)


def _progress(
    seg: Segment, t: FloatArray, fork: FloatArray, window: tuple[float, float] | None, fork_rad: float
) -> tuple[int, int, FloatArray, float] | None:
    """The samples ``lo:hi`` of layer ``seg`` (its time ``window``, with a
    sample's margin either side), the measured flyer's progress along the
    layer at each (rad, non-decreasing) and the layer's start on that scale;
    None if fewer than two."""
    if window is None:
        return None
    t0, t1 = window
    lo = max(int(np.searchsorted(t, t0, side="right")) - 1, 0)
    hi = min(int(np.searchsorted(t, t1, side="left")) + 2, t.size)
    if hi - lo < 2:
        return None
    direction = 1 if seg.delta[FORK.index] >= 0 else -1
    angle = np.maximum.accumulate(direction * fork[lo:hi])
    return lo, hi, angle, direction * seg.start[FORK.index] * fork_rad


def _turn_spans(
    seg: Segment,
    n: int,
    t: FloatArray,
    fork: FloatArray,
    window: tuple[float, float] | None,
    fork_rad: float,
    spr: int,
) -> FloatArray:
    """(n, 2): when the measured flyer began and ended each of the first ``n``
    turns of ``seg`` (s)."""
    got = _progress(seg, t, fork, window, fork_rad)
    if got is None or n <= 0:
        return np.zeros((0, 2))
    lo, hi, angle, base = got
    when = np.interp(base + np.arange(n + 1) * spr * fork_rad, angle, t[lo:hi])
    return np.stack([when[:-1], when[1:]], axis=1)


def _wire_defects(
    run: Run, seg: Segment, turns: list[TurnLaid], spans: FloatArray, joint: npt.NDArray[np.int64]
) -> list[Defect]:
    """The turns of ``seg`` wound stretched or slack (module doc), from the
    tension samples within each turn's ``spans``; ``joint``: the joint sample
    of each tension sample (:func:`winder.analysis.wire.tension_joints`)."""
    tt = run.tension.t
    if not tt.size or spans.shape[0] != len(turns) or not turns:
        return []
    first = np.searchsorted(tt, spans[:, 0], side="left")
    last = np.searchsorted(tt, spans[:, 1], side="left")
    lo, hi = int(first[0]), int(last[-1])
    if hi <= lo:
        return []
    job = run.plan.job
    j = np.maximum(joint[lo:hi], 0)
    known = joint[lo:hi] >= 0  # a tension sample without its joint sample: its tension's stress alone
    psi = np.where(known, run.states.pos[j, FORK.index], 0.0)
    omega = np.where(known, run.states.vel[j, FORK.index], 0.0)
    tension = run.tension.tension[lo:hi]
    stress = stresses(job, seg, tension, psi, omega)
    wire, slack = job.wire, job.set_tension * (1 - job.tension_alarm)
    length = job.bobbin.turn_length(job.winding.coils[seg.pole].layers[seg.layer].radius) or 0.0
    out = []
    for tt_, a, b in zip(turns, (first - lo).tolist(), (last - lo).tolist(), strict=True):
        if b <= a:
            continue
        peak = float(stress[a:b].max())
        if peak > wire.material.yield_stress:
            out.append(
                Defect(
                    "stretched", tt_.coil, tt_.layer, tt_.turn, wire.plastic_strain(peak) * length, tt_.t_s
                )
            )
        if float(tension[a:b].min()) < slack:
            out.append(Defect("slack", tt_.coil, tt_.layer, tt_.turn, 0.0, tt_.t_s))
    return out


def _lay(
    seg: Segment,
    marks: FloatArray,
    t: FloatArray,
    feed: FloatArray,
    fork: FloatArray,
    window: tuple[float, float] | None,
    feed_step: float,
    fork_rad: float,
) -> list[tuple[float, float, float, float]]:
    """(time, measured feed m, intended feed m, measured feed travel over the
    hold m) of each turn of ``seg`` whose measuring point (``marks``' middle,
    fork steps from the layer's start) the measured flyer reached."""
    n = marks.shape[0]
    got = _progress(seg, t, fork, window, fork_rad)
    if got is None or n <= 0:
        return []
    lo, hi, angle, base = got
    at = base + marks * fork_rad
    reached = at[:, 2] <= angle[-1]
    if not reached.any():
        return []
    at = at[reached]
    when = np.interp(at, angle, t[lo:hi])
    measured = np.interp(when, t[lo:hi], feed[lo:hi])
    # the cam as commanded: feed (steps) against fork progress, through the pieces' ends
    knots_fork = np.concatenate([[0.0], np.cumsum([abs(p[1]) for p in seg.pieces])])
    knots_feed = seg.start[FEED.index] + np.concatenate(
        [[0.0], np.cumsum([p[FEED.index] for p in seg.pieces])]
    )
    intended = np.interp(marks[reached, 1], knots_fork, knots_feed) * feed_step
    moved = measured[:, 2] - measured[:, 0]
    return list(
        zip(when[:, 1].tolist(), measured[:, 1].tolist(), intended.tolist(), moved.tolist(), strict=True)
    )


def _defects(turns: list[TurnLaid], d: float, width: float, tol: float) -> list[Defect]:
    out: list[Defect] = []
    for i, tt in enumerate(turns):
        if abs(tt.error_m) > tol:
            out.append(Defect("offset", tt.coil, tt.layer, tt.turn, tt.error_m, tt.t_s))
        past = max(d / 2 - tt.axial_m, tt.axial_m - (width - d / 2))
        if past > tol:
            out.append(Defect("flange", tt.coil, tt.layer, tt.turn, past, tt.t_s))
        if i > 0:
            spacing = abs(tt.axial_m - turns[i - 1].axial_m) - d
            if spacing > tol:
                out.append(Defect("gap", tt.coil, tt.layer, tt.turn, spacing, tt.t_s))
            elif spacing < -tol:
                out.append(Defect("overlap", tt.coil, tt.layer, tt.turn, spacing, tt.t_s))
    return out
