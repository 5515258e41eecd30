"""The tension a layer will see, predicted before it is wound.

A layer wound at its flyer's top speed ``omega`` draws its wire at ``omega
h(psi)`` (:mod:`winder.motion.takeup`): a periodic input, a peak off each
of a rectangle's four corners. The tensioner and free span (:mod:`winder.tension.tensioner`) are
linear, so the tension settles into a periodic steady state, computed
exactly for the sampled input (:func:`winder.tension.lti.periodic_orbit`,
:data:`SAMPLES` samples a turn, the input linear between them): its peak
and its minimum over a turn are the layer's. The wire's whirl around the
flyer adds ``rho v**2 / 2`` of stress at the take-up speed ``v``
(:meth:`winder.motion.material.Wire.whirl_stress`), counted against the
wire's maximum as tension ``rho v**2 A / 2``.

A layer whose peak passes the wire's maximum (times ``tension.max_share``) or
the alarm band's top, or whose minimum falls below the band's bottom (a
slack wire lays loose turns), does not fit; the highest flyer speed that
keeps it is found by bisection (the swing grows with the speed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from winder.motion.material import Wire
from winder.motion.shaped import Motion
from winder.motion.takeup import Contour
from winder.tension.lti import Discrete, periodic_orbit
from winder.tension.tensioner import Tensioner

__all__ = [
    "SAMPLES",
    "Bounds",
    "CoilMove",
    "LayerTension",
    "fastest_within",
    "predict_coil",
    "predict_layer",
    "wider",
]

#: input samples over a turn
SAMPLES = 1024


@dataclass(frozen=True)
class Bounds:
    """What a layer's tension must stay within: the alarm band around the set
    tension, and the wire's maximum (times the derating)."""

    set_tension: float
    alarm: float  #: the band's half-width, a fraction of the set tension
    max_tension: float  #: the wire's maximum x tension.max_share, N

    @property
    def low(self) -> float:
        return self.set_tension * (1 - self.alarm)

    @property
    def high(self) -> float:
        return min(self.set_tension * (1 + self.alarm), self.max_tension)


@dataclass(frozen=True)
class LayerTension:
    """A layer's predicted tension over a turn at its flyer's top speed."""

    flyer_speed: float  #: rad/s
    peak: float  #: N, in the free span
    minimum: float  #: N; 0: the wire goes slack (the linear model holds no further)
    whirl: float  #: N: the whirl's stress as tension, at the take-up's top speed
    coordinate: float  #: the tensioner's own at its extreme: dancer travel (m), servo feed speed (m/s)

    def overshoot(self, bounds: Bounds) -> float:
        """How far the swing about the set tension passes the bounds: the
        largest ratio of a swing (up to the peak, with the whirl against the
        wire's maximum; down to the minimum) to the room the bounds leave
        for it (<= 1: within; inf: no room at all)."""
        s = bounds.set_tension

        def ratio(swing: float, room: float) -> float:
            return swing / room if room > 0 else (math.inf if swing > 0 else 0.0)

        return max(
            ratio(self.peak - s, bounds.high - s),
            ratio(self.peak + self.whirl - s, bounds.max_tension - s),
            ratio(s - self.minimum, s - bounds.low),
        )

    def breach(self, bounds: Bounds, wire: Wire) -> str:
        """What passes the bounds, in words ("" if nothing)."""
        top = self.peak + self.whirl
        if top > bounds.max_tension:
            whirl = f" with {self.whirl:.3g} N of whirl" if self.whirl >= 0.001 * top else ""
            derated = ", derated" if bounds.max_tension < wire.max_tension * (1 - 1e-12) else ""
            yield_mpa, mm2 = wire.material.yield_stress / 1e6, wire.section * 1e6
            return (
                f"predicted peak tension {top:.4g} N{whirl} passes the wire's maximum "
                f"{bounds.max_tension:.4g} N (yield {yield_mpa:.4g} MPa x bare section {mm2:.4g} mm2"
                f"{derated})"
            )
        if self.peak > bounds.high:
            return (
                f"predicted peak tension {self.peak:.4g} N passes the alarm band's top {bounds.high:.4g} N "
                f"(tension.set {bounds.set_tension:.4g} N + tension.alarm {bounds.alarm:g})"
            )
        if self.minimum <= 0.0:
            return (
                "predicted tension falls to nothing: the wire goes slack and lays loose turns (the "
                f"alarm band's bottom is {bounds.low:.4g} N, tension.set {bounds.set_tension:.4g} N - "
                f"tension.alarm {bounds.alarm:g})"
            )
        if self.minimum < bounds.low:
            return (
                f"predicted tension falls to {self.minimum:.4g} N, below the alarm band's bottom "
                f"{bounds.low:.4g} N (tension.set {bounds.set_tension:.4g} N - tension.alarm "
                f"{bounds.alarm:g}): a slack wire lays loose turns"
            )
        return ""


def predict_layer(
    contour: Contour, flyer_radius: float, omega: float, tensioner: Tensioner, wire: Wire
) -> LayerTension:
    """The layer's tension over a turn at ``omega`` rad/s (see the module doc)."""
    if omega <= 0:
        return LayerTension(0.0, tensioner.set_tension, tensioner.set_tension, 0.0, 0.0)
    period = 2 * math.pi / omega
    psi = np.linspace(0.0, 2 * math.pi, SAMPLES, endpoint=False)
    speed = omega * contour.lever(psi, flyer_radius)
    system = Discrete(*tensioner.matrices(), period / SAMPLES)
    x0 = periodic_orbit(system, speed)
    _, out = system.run(x0, np.append(speed, speed[0]))
    tension = tensioner.set_tension + out[:, 0]
    v_top = float(speed.max())
    return LayerTension(
        omega,
        float(tension.max()),
        max(float(tension.min()), 0.0),
        wire.whirl_stress(v_top) * wire.section,
        float(np.abs(out[:, 1]).max()),
    )


def fastest_within(
    contour: Contour, flyer_radius: float, omega: float, tensioner: Tensioner, wire: Wire, bounds: Bounds
) -> float:
    """The highest flyer speed up to ``omega`` (rad/s) whose prediction stays
    within ``bounds`` and the tensioner's reach (0: none does)."""

    def ok(w: float) -> bool:
        got = predict_layer(contour, flyer_radius, w, tensioner, wire)
        return not got.breach(bounds, wire) and not tensioner.limit_words(got.peak, got.coordinate)

    if ok(omega):
        return omega
    lo, hi = 0.0, omega
    for _ in range(40):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    return lo


@dataclass(frozen=True)
class CoilMove:
    """One segment of a coil as the flyer moves it, for :func:`predict_coil`:
    its moves (each a profile of the segment's major axis from rest to rest,
    started ``starts`` s after the segment's start, which is ``t0`` s into
    the coil), how many fork radians one major step is (0: an index move,
    the flyer stands), its fork angle at its start, and its layer's contour
    (None: nothing wound)."""

    t0: float
    starts: tuple[float, ...]
    moves: tuple[Motion, ...]
    rad_per_step: float
    speed: float  #: the feed override: the moves run this many times as fast
    psi0: float
    contour: Contour | None
    layer: int  #: from 1 (0: an index move)


def predict_coil(
    coil: list[CoilMove], flyer_radius: float, tensioner: Tensioner, wire: Wire, rate: float
) -> dict[int, LayerTension]:
    """Each layer's tension over the coil wound as the run winds it: the
    flyer's exact motion (its ramps from and to rest, the dwells between
    segments with nothing drawn) sampled at ``rate`` Hz, the tensioner
    carried from one segment to the next from rest at the set tension. The
    extremes per layer include every transient a ramp or a reversal makes."""
    system = Discrete(*tensioner.matrices(), 1.0 / rate)
    x = tensioner.steady(0.0)
    out: dict[int, LayerTension] = {}
    last_v = 0.0
    t_end = 0.0
    for seg in coil:
        k = seg.speed
        end = seg.t0 + ((seg.starts[-1] + seg.moves[-1].duration) / k if seg.moves else 0.0)
        t = np.arange(math.ceil(t_end * rate), math.floor(end * rate) + 1) / rate
        v = np.zeros(t.size)
        omega = np.zeros(t.size)
        if seg.contour is not None and seg.rad_per_step:
            before = 0.0  # the major steps of the segment's earlier moves
            for start, move in zip(seg.starts, seg.moves, strict=True):
                local = (t - seg.t0) * k - start
                on = (local >= 0) & (local <= move.duration)
                p, w, _, _ = move.sample(local[on])
                psi = seg.psi0 + (before + p) * seg.rad_per_step
                omega[on] = w * k * abs(seg.rad_per_step)
                before += move.distance
                mirrored = psi if seg.rad_per_step > 0 else -psi
                v[on] = omega[on] * seg.contour.lever(mirrored, flyer_radius)
        if t.size:
            xs, ys = system.run(x, np.concatenate([[last_v], v]))
            x, last_v = xs[-1], float(v[-1])
            mine = t >= seg.t0  # the dwell before the segment is no layer's
            if seg.layer and mine.any():
                tension = tensioner.set_tension + ys[1:, 0][mine]
                speed = float(v[mine].max())
                got = LayerTension(
                    float(omega[mine].max()),
                    float(tension.max()),
                    max(float(tension.min()), 0.0),
                    wire.whirl_stress(speed) * wire.section,
                    float(np.abs(ys[1:, 1][mine]).max()),
                )
                had = out.get(seg.layer)
                out[seg.layer] = got if had is None else wider(had, got)
        t_end = end + 1.0 / rate
    return out


def wider(a: LayerTension, b: LayerTension) -> LayerTension:
    """The extremes of both predictions of a layer."""
    return LayerTension(
        max(a.flyer_speed, b.flyer_speed),
        max(a.peak, b.peak),
        min(a.minimum, b.minimum),
        max(a.whirl, b.whirl),
        max(a.coordinate, b.coordinate),
    )
