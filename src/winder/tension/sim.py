"""The wire in a simulated run: the tension, the dancer and the supply spool
as the simulated flyer draws the wire.

At each sample the flyer's angle ``psi`` and speed ``omega`` (its axis'
simulated position and velocity, rad) and the layer being wound give the
take-up speed ``|omega| h(psi)`` (:mod:`winder.motion.takeup`; a coil wound
the other way mirrors the angle). The tensioner with its free span
(:mod:`winder.tension.tensioner`) is stepped exactly from sample to sample
with the take-up speed linear between them (:class:`winder.tension.lti.Discrete`),
from rest at the set tension. Out, per sample: the tension (N; 0 once the
wire goes slack, where the linear model stops holding), the tensioner's
coordinate (the dancer's travel, m; the servo's feed speed, m/s) and the
wire paid out by the supply (m): the wire taken up less what the span and
the tensioner hold.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from winder.motion.takeup import Contour
from winder.tension.lti import Discrete
from winder.tension.tensioner import Tensioner

__all__ = ["WireSample", "WireSim"]

Floats = npt.NDArray[np.float64]


@dataclass(frozen=True)
class WireSample:
    """The wire at a block of samples."""

    tension: Floats  #: N
    coordinate: Floats  #: dancer travel (m) or servo feed speed (m/s)
    supply: Floats  #: wire paid out since the run's start, m
    takeup: Floats  #: take-up speed, m/s
    supply_speed: Floats  #: the supply's pay-out speed, m/s
    coordinate_rate: Floats  #: the coordinate's rate (dancer, m/s; servo, m/s2)
    taken: Floats  #: wire taken up since the run's start, m


class WireSim:
    """The wire of one run (see the module doc): ``contours`` maps a segment
    index to the contour the flyer winds on there (None: no wire drawn, an
    index move), ``flyer_radius`` in m, ``period`` the sample period in s."""

    def __init__(
        self, tensioner: Tensioner, contours: dict[int, Contour | None], flyer_radius: float, period: float
    ) -> None:
        self.tensioner = tensioner
        self.contours = contours
        self.radius = flyer_radius
        self.a, self.b, c, d = tensioner.matrices()
        self.system = Discrete(self.a, self.b, c, d, period)
        self.period = period
        self.x = tensioner.steady(0.0)
        self.v = 0.0  # the take-up speed at the last sample
        self.taken = 0.0  # wire taken up so far, m
        self.started = False
        self.peak = tensioner.set_tension
        self.least = tensioner.set_tension
        self.travel = 0.0

    def takeup(self, psi: Floats, omega: Floats, segments: npt.NDArray[np.int64]) -> Floats:
        """The take-up speed at each sample (m/s)."""
        v = np.zeros(psi.size)
        for seg in np.unique(segments):
            contour = self.contours.get(int(seg))
            if contour is None:
                continue
            at = segments == seg
            w = omega[at]
            mirrored = np.where(w >= 0, psi[at], -psi[at])  # a coil wound the other way
            v[at] = np.abs(w) * contour.lever(mirrored, self.radius)
        return v

    def advance(self, psi: Floats, omega: Floats, segments: npt.NDArray[np.int64]) -> WireSample:
        """The wire at the next samples (flyer angle, speed and segment at each)."""
        v = self.takeup(np.asarray(psi, float), np.asarray(omega, float), np.asarray(segments, np.int64))
        n = v.size
        # from the last sample on (its state and speed), or from rest at the first sample
        inputs = np.concatenate([[self.v], v]) if self.started else v
        states = self.system.run(self.x, inputs)[0][inputs.size - n :]
        steps = np.cumsum(self.period * (inputs[1:] + inputs[:-1]) / 2)  # the wire taken, trapezoids
        taken = self.taken + (steps if self.started or not n else np.concatenate([[0.0], steps]))
        if n:
            self.started = True
            self.x, self.v, self.taken = states[-1].copy(), float(v[-1]), float(taken[-1])
        out = states @ self.system.c.T
        tension = np.maximum(self.tensioner.set_tension + out[:, 0], 0.0)
        held = self.tensioner.held(states)
        rates = states @ self.a.T + v[:, None] * self.b[None, :]  # x' = A x + B v, exactly
        if n:
            self.peak = max(self.peak, float(tension.max()))
            self.least = min(self.least, float(tension.min()))
            self.travel = max(self.travel, float(np.abs(out[:, 1]).max()))
        return WireSample(
            tension,
            out[:, 1].copy(),
            taken - held,
            v,
            v - self.tensioner.held(rates),
            (rates @ self.system.c.T)[:, 1],
            taken,
        )
