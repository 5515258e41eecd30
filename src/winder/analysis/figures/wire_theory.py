"""Figures: the wire, from :mod:`winder.motion.takeup` and :mod:`winder.tension`.

* ``wire_takeup.png`` - the take-up speed ``v = omega h(psi)`` over one flyer
  turn (:meth:`winder.motion.takeup.Contour.lever`) on a round core, a 2:1
  rectangular core and a square core of the same turn length, each a
  layer's contour from :meth:`winder.motion.coil.Bobbin.contour`: the least
  speed where a flat lies along the wire (twice a turn on the rectangle,
  four times on the square), the greatest off each of the four corners,
  and a flat line on the round core;
* ``wire_tension.png`` - the tension over a turn in the periodic steady
  state (the computation of :func:`winder.tension.predict.predict_layer`,
  whose peak and least it draws) with the default dancer and the default
  servo (:data:`winder.tension.tensioner.TENSIONER_SPECS`) at two flyer
  speeds, against the set tension, the warning and alarm bands and the
  wire's maximum.

Both on the coil of ``jobs/ortho_rect.yaml`` (0.5 mm wire, 0.45 mm copper,
layer 1, a 30 mm flyer; the tension on its 12 x 20 mm core with 1 mm
corners), at its top flyer speed (v_max 20 000 steps/s of 5120 a turn:
24.5 rad/s) and, for the tension, at its first layer's half of it.

    .venv/bin/python -m winder.analysis.figures.wire_theory [outdir]
"""

from __future__ import annotations

import math
import pathlib
import sys
from dataclasses import dataclass
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import numpy.typing as npt
from matplotlib.axes import Axes

from winder.contract.files import atomic_file, output_dir
from winder.motion.job import Job
from winder.motion.takeup import Contour
from winder.tension.lti import Discrete, periodic_orbit
from winder.tension.predict import SAMPLES, Bounds, LayerTension, predict_layer
from winder.tension.tensioner import TENSIONER_SPECS, Tensioner, tensioner_of

Floats = npt.NDArray[np.float64]

#: the coil of jobs/ortho_rect.yaml (its interp_node settings)
ORTHO_RECT: dict[str, Any] = {
    "job_id": "ortho_rect",
    "wire_diameter": 0.0005,
    "wire.bare_diameter": 0.00045,
    "bobbin.window_width": 0.03025,
    "bobbin.window_height": 0.004,
    "bobbin.core": "rect",
    "bobbin.core_width": 0.012,
    "bobbin.core_depth": 0.020,
    "bobbin.core_corner_radius": 0.001,
    "lay": "orthocyclic",
    "lay.crossover": 20.0,
    "lay.crossover_at": 80.0,
    "turns_per_layer": 60,
    "layers": 6,
    "reversal_dwell": 1.0,
    "first_layer_speed": 0.5,
    "poles": 1,
    "flyer_radius": 0.03,
    "fork_steps_per_rev": 5120,
    "feed_step": 5.0e-6,
    "pole_steps_per_rev": 5120,
}
#: its ramp's top speed, fork steps/s (profile_node's v_max)
V_MAX = 20000.0
#: the three cores of the take-up figure, each 60 mm round (the rectangle's
#: and the square's sides less what their 1 mm corners cut: the same turn length)
CORNER = 0.001
_PERIMETER = 2 * 0.020 + 2 * 0.010 - (8 - 2 * math.pi) * CORNER
CORES: dict[str, dict[str, Any]] = {
    "round": {"bobbin.core": "round", "bobbin.core_diameter": _PERIMETER / math.pi},
    "rectangle 2:1": {
        "bobbin.core": "rect",
        "bobbin.core_width": 0.020,
        "bobbin.core_depth": 0.010,
        "bobbin.core_corner_radius": CORNER,
    },
    "square": {
        "bobbin.core": "rect",
        "bobbin.core_width": 0.015,
        "bobbin.core_depth": 0.015,
        "bobbin.core_corner_radius": CORNER,
    },
}
COLOURS = {"round": "tab:green", "rectangle 2:1": "tab:blue", "square": "tab:orange"}
#: the free span of the default tensioners, m
SPAN = float(TENSIONER_SPECS["tensioner.span"].default)
#: flyer angles over a turn (the extremes are found on this grid)
GRID = 1 << 13


def job_on(core: dict[str, Any] | None = None) -> Job:
    """ortho_rect's job, on another core where given."""
    values = dict(ORTHO_RECT)
    if core is not None:
        values = {k: v for k, v in values.items() if not k.startswith("bobbin.core")} | core
    return Job.from_dict(values)


def top_speed(job: Job) -> float:
    """The flyer's top speed, rad/s: :data:`V_MAX` fork steps/s."""
    return V_MAX / job.fork_steps_per_rev * 2 * math.pi


def layer_one(job: Job) -> Contour:
    """The contour of coil 1's first layer."""
    contour = job.bobbin.contour(job.winding.coils[0].layers[0].radius)
    assert contour is not None
    return contour


@dataclass(frozen=True)
class TakeUp:
    """The take-up over a turn on one core."""

    contour: Contour
    psi: Floats  #: flyer angle, rad
    speed: Floats  #: m/s
    minima: Floats  #: flyer angles of the least speed (a longer flat along the wire)
    maxima: Floats  #: flyer angles of the greatest speed (off a corner)
    dips: Floats  #: flyer angles of a shorter flat along the wire (a rectangle's local least)


def _extremes(psi: Floats, v: Floats, value: float, tol: float) -> Floats:
    """The flyer angles of the grid's local extremes of ``v`` within ``tol`` of ``value``."""
    prev, nxt = np.roll(v, 1), np.roll(v, -1)
    local = ((v <= prev) & (v <= nxt)) | ((v >= prev) & (v >= nxt))
    out: Floats = psi[local & (np.abs(v - value) <= tol)]
    return out


def takeup(core: str, omega: float) -> TakeUp:
    """The take-up speed over a turn on one of :data:`CORES` at ``omega`` rad/s."""
    job = job_on(CORES[core])
    contour = layer_one(job)
    psi = np.linspace(0.0, 2 * math.pi, GRID, endpoint=False)
    v = omega * contour.lever(psi, job.flyer_radius)
    if contour.h_max - contour.h_min < 1e-12:  # a round core: no extremes, one speed
        none: Floats = np.zeros(0)
        return TakeUp(contour, psi, v, none, none, none)
    # near a flat the speed is a V (h' jumps there), near a corner a smooth top:
    # within a grid step's change of the closed-form extremes
    tol = float(np.max(np.abs(np.diff(v)))) * 1.01
    other = max(contour.a, contour.b) / 2  # h with a shorter flat along the wire
    dips = _extremes(psi, v, omega * other, tol) if other - contour.h_min > 2 * tol / omega else np.zeros(0)
    return TakeUp(
        contour,
        psi,
        v,
        _dedupe(_extremes(psi, v, omega * contour.h_min, tol)),
        _dedupe(_extremes(psi, v, omega * contour.h_max, tol)),
        _dedupe(dips),
    )


def _dedupe(angles: Floats) -> Floats:
    """One angle per cluster of neighbouring grid points (a flat's V can hit two)."""
    if angles.size == 0:
        return angles
    step = 2 * math.pi / GRID
    keep = [float(angles[0])]
    for a in angles[1:]:
        if a - keep[-1] > 3 * step:
            keep.append(float(a))
    if len(keep) > 1 and keep[0] + 2 * math.pi - keep[-1] <= 3 * step:
        keep.pop()
    return np.array(keep)


@dataclass(frozen=True)
class TensionTurn:
    """The tension over a turn in the periodic steady state."""

    kind: str
    omega: float
    psi: Floats  #: flyer angle, rad (SAMPLES + 1: the turn closed)
    tension: Floats  #: N, the linear model's (below 0: slack)
    predicted: LayerTension  #: predict_layer's extremes of the same


def tension_turn(job: Job, tensioner: Tensioner, omega: float) -> TensionTurn:
    """What :func:`~winder.tension.predict.predict_layer` computes over a turn,
    every sample kept: the take-up at :data:`~winder.tension.predict.SAMPLES`
    flyer angles, the tensioner stepped exactly from its periodic orbit."""
    contour, wire = layer_one(job), job.wire
    period = 2 * math.pi / omega
    psi = np.linspace(0.0, 2 * math.pi, SAMPLES, endpoint=False)
    speed = omega * contour.lever(psi, job.flyer_radius)
    system = Discrete(*tensioner.matrices(), period / SAMPLES)
    x0 = periodic_orbit(system, speed)
    _, out = system.run(x0, np.append(speed, speed[0]))
    return TensionTurn(
        tensioner.kind,
        omega,
        np.append(psi, 2 * math.pi),
        tensioner.set_tension + out[:, 0],
        predict_layer(contour, job.flyer_radius, omega, tensioner, wire),
    )


def tension_turns(job: Job) -> dict[str, list[TensionTurn]]:
    """Each tensioner (its defaults) at the first layer's speed and the top speed."""
    omega = top_speed(job)
    wire = job.wire
    out: dict[str, list[TensionTurn]] = {}
    for kind in ("dancer", "servo"):
        tensioner = tensioner_of({"tensioner.kind": kind}, wire.stiffness_per_length, job.set_tension)
        out[kind] = [tension_turn(job, tensioner, w) for w in (omega * job.first_layer_speed, omega)]
    return out


def _takeup_figure(path: pathlib.Path) -> None:
    job = job_on()
    omega = top_speed(job)
    fig, ax = plt.subplots(figsize=(10, 5.2), layout="constrained")
    for name in CORES:
        got = takeup(name, omega)
        c = got.contour
        deg = np.degrees(got.psi)
        ratio = c.h_max / c.h_min
        ax.plot(
            deg, got.speed, color=COLOURS[name], lw=1.6,
            label=f"{name}: layer {c.a * 1e3:.2f} x {c.b * 1e3:.2f} mm, r {c.r * 1e3:.2f} mm, "
            f"turn {c.length * 1e3:.2f} mm, take-up ratio {ratio:.3f}",
        )  # fmt: skip
        for angles, value, marker, fill, what in (
            (got.minima, omega * c.h_min, "v", COLOURS[name], "least, a flat along the wire"),
            (got.dips, omega * max(c.a, c.b) / 2, "v", "white", "a shorter flat along the wire"),
            (got.maxima, omega * c.h_max, "^", COLOURS[name], "greatest, off a corner"),
        ):
            if angles.size:
                ax.plot(
                    np.degrees(angles), np.full(angles.size, value), ls="none", marker=marker,
                    color=COLOURS[name], mfc=fill, ms=8, mec="k", mew=0.6,
                    label=f"  {angles.size} x a turn {value:.4f} m/s: {what}",
                )  # fmt: skip
    mean = omega * layer_one(job_on(CORES["round"])).length / (2 * math.pi)
    ax.axhline(mean, color="0.4", lw=0.8, ls=":")
    ax.annotate(
        f"mean, every core: omega x turn / 2 pi = {mean:.4f} m/s", (135, mean), xytext=(0, 10),
        textcoords="offset points", ha="center", fontsize=8, bbox={"fc": "white", "ec": "none", "pad": 1},
    )  # fmt: skip
    ax.set_xlim(0, 360)
    ax.set_xticks(np.arange(0, 361, 45))
    ax.set_xlabel("flyer angle psi (deg; 0: the nozzle on the +x axis, the core's width along x)")
    ax.set_ylabel("take-up speed v = omega h (m/s)")
    ax.grid(True, lw=0.3)
    ax.legend(fontsize=7.5, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=1, frameon=False)
    ax.set_title(
        f"Take-up speed over one flyer turn at omega = {omega:.2f} rad/s, flyer radius "
        f"{job.flyer_radius * 1e3:g} mm,\nlayer 1 of {job.wire_diameter * 1e3:g} mm wire on three cores of "
        "the same turn length (flat line: the round core)",
        fontsize=10,
    )
    with atomic_file(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=110)
    plt.close(fig)


def _bands(ax: Axes, job: Job) -> None:
    """The set tension, the warning and alarm bands and the wire's maximum."""
    set_n, wire = job.set_tension, job.wire
    bounds = Bounds(set_n, job.tension_alarm, job.tension_limit)
    warn = (set_n * (1 - job.tension_warning), set_n * (1 + job.tension_warning))
    alarm, warning = f"{job.tension_alarm:.0%}", f"{job.tension_warning:.0%}"
    ax.axhspan(
        bounds.low, bounds.high, color="tab:orange", alpha=0.12, lw=0, label=f"alarm band, set +-{alarm}"
    )
    ax.axhspan(*warn, color="tab:green", alpha=0.16, lw=0, label=f"warning band, set +-{warning}")
    ax.axhline(set_n, color="k", lw=1.0, label=f"set tension {set_n:.4g} N")
    top = f"wire's maximum {wire.max_tension:.4g} N (yield x bare section)"
    ax.axhline(wire.max_tension, color="tab:red", lw=1.0, ls=":", label=top)


def _tension_figure(path: pathlib.Path) -> None:
    job = job_on()
    wire = job.wire
    turns = tension_turns(job)
    set_n = job.set_tension
    top = max(max(float(t.tension.max()) for t in runs) for runs in turns.values())
    fig, axes = plt.subplots(2, 1, figsize=(10, 8.6), sharex=True, layout="constrained")
    styles = ("--", "-")
    colours = {"dancer": "tab:blue", "servo": "tab:purple"}
    inset = axes[0].inset_axes((0.52, 0.50, 0.46, 0.40))
    for ax, (kind, runs) in zip(axes, turns.items(), strict=True):
        _bands(ax, job)
        for style, t in zip(styles, runs, strict=True):
            p = t.predicted
            deg = np.degrees(t.psi)
            held = np.maximum(t.tension, 0.0)
            slack = " (0: slack, the linear model holds no further)" if p.minimum <= 0 else ""
            ax.plot(
                deg, held, color=colours[kind], ls=style, lw=1.5,
                label=f"omega {t.omega:.2f} rad/s ({t.omega * 30 / math.pi:.0f} rpm): "
                f"{p.minimum:.3g}..{p.peak:.3g} N{slack}",
            )  # fmt: skip
            if kind == "dancer":
                inset.plot(deg, held, color=colours[kind], ls=style, lw=1.2)
        tensioner = tensioner_of({"tensioner.kind": kind}, wire.stiffness_per_length, set_n)
        if kind == "dancer":
            what = (
                f"dancer: arm {tensioner.mass * 1e3:g} g on {tensioner.spring:g} N/m, damping "
                f"{tensioner.damping:g} N s/m, stroke {tensioner.stroke * 1e3:g} mm, supply gain "
                f"{tensioner.supply_gain:g} 1/s"
            )
        else:
            what = (
                f"servo: PI tension loop of {tensioner.bandwidth:g} Hz, force limit "
                f"{tensioner.force_limit:g} N"
            )
        ax.set_title(f"{what}; free span {SPAN:g} m: K = EA/L = {tensioner.stiffness:.4g} N/m", fontsize=9.5)
        ax.set_ylabel("tension (N)")
        ax.set_ylim(0, max(top, wire.max_tension) * 1.1)
        ax.grid(True, lw=0.3)
        ax.legend(fontsize=7.5, loc="upper left")
    inset.axhline(set_n, color="k", lw=0.8)
    lo = min(float(t.tension.min()) for t in turns["dancer"])
    hi = max(float(t.tension.max()) for t in turns["dancer"])
    pad = (hi - lo) * 0.15
    inset.set_ylim(lo - pad, hi + pad)
    inset.set_xlim(0, 360)
    inset.set_xticks(np.arange(0, 361, 90))
    inset.tick_params(labelsize=7)
    inset.set_title("the dancer's, magnified (N)", fontsize=8)
    inset.grid(True, lw=0.3)
    inset.set_facecolor("white")
    axes[-1].set_xlim(0, 360)
    axes[-1].set_xticks(np.arange(0, 361, 45))
    axes[-1].set_xlabel("flyer angle psi over one turn (deg), periodic steady state")
    fig.suptitle(
        f"Tension over a turn: jobs/ortho_rect.yaml, layer 1 on its {job.core_width * 1e3:g} x "
        f"{job.core_depth * 1e3:g} mm core (corners {job.core_corner_radius * 1e3:g} mm), "
        f"{wire.bare_diameter * 1e3:g} mm copper,\nthe default tensioners at the first layer's speed "
        "(dashed) and the job's top speed (solid)",
        fontsize=10,
    )
    with atomic_file(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=110)
    plt.close(fig)


def make(outdir: pathlib.Path) -> list[pathlib.Path]:
    """Write ``wire_takeup.png`` and ``wire_tension.png`` into ``outdir``; return the paths written."""
    outdir = pathlib.Path(outdir)
    output_dir(outdir)
    paths = [outdir / "wire_takeup.png", outdir / "wire_tension.png"]
    _takeup_figure(paths[0])
    _tension_figure(paths[1])
    return paths


if __name__ == "__main__":
    out = pathlib.Path(sys.argv[1]) if len(sys.argv) > 1 else pathlib.Path("docs/img")
    for p in make(out):
        print(p)
