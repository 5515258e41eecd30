"""The wire as recorded: its tension per layer, the stress and the stretch it
took, what the supply paid out and whether it broke or slipped. ROS-free.

A tension sample (winder/tension) is taken with a joint sample (the sim
node stamps both alike): it belongs to the layer its joint sample is
measured against (:func:`winder.analysis.metrics.sample_layers`, eq. 7's
rule). Its stress is ``tension / section`` plus the whirl of the free wire
around the flyer, ``rho v**2 / 2`` at the take-up speed ``v = |omega|
h(psi)`` of the layer's contour (:mod:`winder.motion.takeup`, as the sim
node works it out; the core not given, the tension's part alone). The
whirl is worked out only where it may lift the stress past the yield (its
bound ``rho (|omega| h_max)**2 / 2``): below the yield nothing of it counts.
A stress past the yield leaves the plastic stretch and the resistance rise
of :class:`winder.motion.material.Wire`.

The faults come from the ERROR statuses the sim node publishes for the wire
(a status named ``<node>: wire``): its values ``fault`` (``break`` or
``slip``), ``coil``, ``layer``, ``turn`` and ``t_s``; a status recorded
before those keys gives what it has (the kind from its message, the rest
None).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from winder.motion.axes import FORK
from winder.motion.job import Job, Segment
from winder.record.reader import Run

__all__ = ["FAULTS", "LayerTension", "fault", "layer_tensions", "paid_out", "stresses", "tension_joints"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: the wire's faults the sim node names in its ``wire`` status
FAULTS = ("break", "slip")


def tension_joints(run: Run) -> IntArray:
    """For each tension sample, the index of the joint sample taken at its
    time (within a microsecond), -1 where there is none."""
    st, tt = run.states.t, run.tension.t
    out = np.full(tt.size, -1, np.int64)
    if not st.size or not tt.size:
        return out
    i = np.searchsorted(st, tt)
    before, after = np.clip(i - 1, 0, st.size - 1), np.clip(i, 0, st.size - 1)
    j = np.where(np.abs(st[before] - tt) <= np.abs(st[after] - tt), before, after).astype(np.int64)
    ok = np.abs(st[j] - tt) < 1e-6
    out[ok] = j[ok]
    return out


def stresses(job: Job, seg: Segment, tension: FloatArray, psi: FloatArray, omega: FloatArray) -> FloatArray:
    """The wire's stress (Pa) at samples of layer ``seg`` of ``job`` with
    ``tension`` (N) and the flyer at ``psi`` (rad) turning at ``omega``
    (rad/s): exact wherever it may pass the yield, elsewhere the tension's
    part (module doc)."""
    wire = job.wire
    out: FloatArray = tension / wire.section
    contour = job.bobbin.contour(job.winding.coils[seg.pole].layers[seg.layer].radius)
    if contour is None or not out.size:
        return out
    per_v2 = wire.whirl_stress(1.0)  # the whirl's stress is this times the take-up speed squared
    may = np.flatnonzero(out + per_v2 * (omega * contour.h_max) ** 2 > wire.material.yield_stress)
    if may.size:
        w = omega[may]
        mirrored = np.where(w >= 0, psi[may], -psi[may])  # a coil wound the other way
        out[may] += per_v2 * (w * contour.lever(mirrored, job.flyer_radius)) ** 2
    return out


@dataclass(frozen=True)
class LayerTension:
    """The recorded tension while one layer was wound."""

    segment: int
    coil: int  #: from 1
    layer: int  #: from 1
    samples: IntArray  #: its tension samples (indices into ``run.tension``)
    min_n: float
    mean_n: float
    max_n: float
    stress: float  #: the peak stress, Pa
    stretch: float  #: the plastic strain it left (0: never past the yield)
    resistance_rise: float  #: the relative rise of the resistance with that stretch

    def to_json(self) -> dict[str, Any]:
        return {
            "coil": self.coil,
            "layer": self.layer,
            "min_n": self.min_n,
            "mean_n": self.mean_n,
            "max_n": self.max_n,
            "stretch": self.stretch,
            "resistance_rise": self.resistance_rise,
        }


def layer_tensions(run: Run, layers: IntArray) -> list[LayerTension]:
    """The tension of each layer wound, in winding order: ``layers`` the layer
    segment of each joint sample (-1: none); the samples after the wire broke
    (where its status says when) left out."""
    if not layers.size or layers.size != len(run.states) or not len(run.tension):
        return []
    joint = tension_joints(run)
    seg_of = np.where(joint >= 0, layers[np.maximum(joint, 0)], -1)
    broke = fault(run, "break")
    if broke is not None and broke["t_s"] is not None:  # a time said in text: to a microsecond
        seg_of[run.tension.t > broke["t_s"] + 1e-6] = -1
    wire = run.plan.job.wire
    st, fork = run.states, FORK.index
    order = np.argsort(seg_of, kind="stable")  # the samples of each layer together, in time order
    segs, first = np.unique(seg_of[order], return_index=True)
    out = []
    for i, at in zip(segs.tolist(), np.split(order, first[1:]), strict=True):
        if i < 0:
            continue
        seg = run.plan.segments[i]
        tension = run.tension.tension[at]
        j = joint[at]
        peak = float(stresses(run.plan.job, seg, tension, st.pos[j, fork], st.vel[j, fork]).max())
        out.append(
            LayerTension(
                i,
                seg.pole + 1,
                seg.layer + 1,
                at,
                float(tension.min()),
                float(tension.mean()),
                float(tension.max()),
                peak,
                wire.plastic_strain(peak),
                wire.resistance_rise(peak),
            )
        )
    return out


def paid_out(run: Run) -> float | None:
    """The wire the supply paid out, m: the last recorded position of its
    joint (None if the joint states do not hold it)."""
    supply = run.states.extra.get("supply")
    if supply is None:
        return None
    known = supply[np.isfinite(supply)]
    return float(known[-1]) if known.size else None


def _int(text: str | None) -> int | None:
    try:
        return int(text) if text is not None else None
    except ValueError:
        return None


def _float(text: str | None) -> float | None:
    try:
        x = float(text) if text is not None else math.nan
    except ValueError:
        return None
    return x if math.isfinite(x) else None


def _kind(status: dict[str, str]) -> str:
    """The fault a wire status tells: its ``fault`` value, else from its message."""
    said = status.get("fault", "").strip().lower()
    if said:
        return said
    return "slip" if "slip" in status.get("message", "").lower() else "break"


def fault(run: Run, kind: str) -> dict[str, Any] | None:
    """The first recorded wire fault of ``kind`` (one of FAULTS): where and
    when (None where its status does not say), and what it said; None if
    there was none."""
    for status in run.error_statuses:
        if status.get("name", "").endswith(": wire") and _kind(status) == kind:
            return {
                "fault": kind,
                "coil": _int(status.get("coil")),
                "layer": _int(status.get("layer")),
                "turn": _int(status.get("turn")),
                "t_s": _float(status.get("t_s")),
                "message": status.get("message", ""),
            }
    return None
