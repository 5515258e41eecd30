"""The tensioner and the free span: the wire's tension as the coil draws it.

Between the tensioner and the coil the wire runs free over a span of
length ``L``: a spring of stiffness ``K = E A / L`` (:class:`winder.motion.material.Wire`).
Its tension is the set tension plus ``K`` times its stretch ``q``, which
grows with the wire the coil takes (at the take-up speed ``v``,
:mod:`winder.motion.takeup`) and shrinks with the wire the tensioner lets
through. Two tensioners, each a linear system of the take-up speed
(:class:`winder.tension.lti.Discrete` steps them exactly):

* **servo** - an active feeder with a tension loop: it feeds at ``g e + g
  w_i z`` (``e`` the tension error, ``z`` its integral), with ``g = w_b /
  K`` for a loop bandwidth ``w_b = 2 pi f_b`` and ``w_i = w_b / 4`` (the
  critically damped PI: the loop's two poles meet at ``-w_b / 2``). States
  ``[e, z]``: ``e' = K (v - g e - g w_i z)``, ``z' = e``; holds the set
  tension at any steady speed. Its force limit bounds the tension it can
  hold back: a prediction beyond it is said.
* **dancer** - an arm of mass ``m`` on a spring ``k_d`` with damping ``c``
  carrying a pulley, so its travel ``y`` stores ``2 y`` of wire, and the
  spring's preload holds ``2 T_set`` at the centre; its stroke bounds the
  travel. Its supply spool (``tensioner.supply``):

  - **driven** (a motor pays out as the arm asks): ``k_p y + k_i int y``.
    States ``[q, y, y', int y]``: ``q' = v - 2 y' - k_p y - k_i int y``,
    ``m y'' = 2 K q - k_d y - c y'``. Holds the arm centred, and the set
    tension, at any steady speed.
  - **braked** (the wire pulls the spool round against a friction brake the
    arm releases as it is pulled): the spool, of inertia ``J`` and radius
    ``r``, is a mass ``M = J / r**2`` at the wire, pulled by the tension
    and held by the brake, whose force is the set tension with the arm
    centred, less ``k_b y`` (a friction brake: its force does not depend on
    the speed). States ``[q, y, y', u]`` (``u`` the spool's pay-out speed):
    ``q' = v - 2 y' - u``, ``m y'' = 2 K q - k_d y - c y'``, ``M u' = K q +
    k_b y``. Holds the set tension at any steady speed too, the arm centred;
    the spool's inertia against the span makes a slow mode the arm's
    damping alone damps (the arm that swings on every start and reversal).

Both outputs: the tension (N) and the tensioner's own coordinate (the
servo's feed speed, m/s; the dancer's travel, m).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from winder.errors import BadInputError
from winder.spec import Spec

__all__ = ["KINDS", "TENSIONER_SPECS", "Tensioner", "tensioner_of"]

Floats = npt.NDArray[np.float64]

KINDS = ("servo", "dancer")
#: how a dancer's supply spool pays out (``tensioner.supply``)
SUPPLIES = ("driven", "braked")


def _f(name: str, low: float, high: float, unit: str, help_: str, default: float) -> Spec:
    return Spec(name, float, default, help_, unit, low, high, low_open=True)


#: the tensioner's settings (job keys), with defaults a winding engineer recognises
TENSIONER_SPECS: dict[str, Spec] = {
    s.name: s
    for s in (
        Spec(
            "tensioner.kind",
            str,
            "dancer",
            "dancer (an arm) or servo (a feeder)",
            choices=KINDS,
        ),
        _f("tensioner.span", 0.01, 20.0, "m", "free wire between the tensioner and the coil", 0.5),
        _f("tensioner.bandwidth", 0.1, 1000.0, "Hz", "servo: the tension loop's bandwidth", 30.0),
        _f("tensioner.force_limit", 0.001, 1e4, "N", "servo: the most tension it can hold", 20.0),
        _f("tensioner.dancer_mass", 1e-4, 10.0, "kg", "dancer: the arm's moving mass at the pulley", 0.02),
        _f("tensioner.dancer_spring", 0.01, 1e5, "N/m", "dancer: the arm's spring rate", 50.0),
        _f("tensioner.dancer_damping", 1e-4, 1e4, "N s/m", "dancer: the arm's damping", 1.0),
        _f("tensioner.dancer_stroke", 1e-3, 2.0, "m", "dancer: the arm's travel, end stop to end stop", 0.08),
        _f("tensioner.supply_gain", 0.01, 1e4, "1/s", "dancer: supply pay-out per metre of arm travel", 20.0),
        Spec(
            "tensioner.supply",
            str,
            "driven",
            "dancer: the supply spool: driven (a motor pays out as the arm asks) or braked (the wire "
            "pulls the spool round against a brake the arm releases as it is pulled)",
            choices=SUPPLIES,
        ),
        _f(
            "tensioner.spool_mass",
            1e-4,
            1e3,
            "kg",
            "braked supply: the spool's inertia with its wire, over its radius squared (J / r^2)",
            0.25,
        ),
        _f(
            "tensioner.brake_gain",
            0.01,
            1e6,
            "N/m",
            "braked supply: the brake force the arm releases per metre it is pulled",
            100.0,
        ),
    )
}


@dataclass(frozen=True)
class Tensioner:
    """A tensioner with its free span, as a linear system of the take-up
    speed (m/s) whose outputs are the tension (N) and its own coordinate."""

    kind: str  #: servo or dancer
    stiffness: float  #: K = E A / L of the free span, N/m
    set_tension: float  #: N
    bandwidth: float = 30.0  #: servo: Hz
    force_limit: float = 20.0  #: servo: N
    mass: float = 0.02  #: dancer: kg
    spring: float = 50.0  #: dancer: N/m
    damping: float = 1.0  #: dancer: N s/m
    stroke: float = 0.08  #: dancer: m
    supply_gain: float = 20.0  #: dancer: 1/s (a driven supply)
    supply: str = "driven"  #: dancer: driven or braked
    spool_mass: float = 0.25  #: braked supply: J / r^2, kg
    brake_gain: float = 100.0  #: braked supply: N/m

    def matrices(self) -> tuple[Floats, Floats, Floats, Floats]:
        """``(A, B, C, D)`` of the deviation from the set tension; a steady
        wind at ``v`` has the state :meth:`steady`."""
        if self.kind not in KINDS:
            raise BadInputError(f"tensioner.kind={self.kind!r} is invalid: must be one of {', '.join(KINDS)}")
        k = self.stiffness
        if self.kind == "servo":
            wb = 2 * math.pi * self.bandwidth
            g, wi = wb / k, wb / 4
            a = np.array([[-k * g, -k * g * wi], [1.0, 0.0]])
            b = np.array([k, 0.0])
            c = np.array([[1.0, 0.0], [g, g * wi]])  # tension error; feed speed
            return a, b, c, np.array([0.0, 0.0])
        m, kd, cd, kp = self.mass, self.spring, self.damping, self.supply_gain
        if self.supply == "braked":
            ms, kb = self.spool_mass, self.brake_gain
            a = np.array(
                [
                    [0.0, 0.0, -2.0, -1.0],
                    [0.0, 0.0, 1.0, 0.0],
                    [2 * k / m, -kd / m, -cd / m, 0.0],
                    [k / ms, kb / ms, 0.0, 0.0],
                ]
            )
            b = np.array([1.0, 0.0, 0.0, 0.0])
            c = np.array([[k, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])  # tension error; arm travel
            return a, b, c, np.array([0.0, 0.0])
        ki = kp**2 / 4  # the supply loop critically damped on its own
        a = np.array(
            [
                [0.0, -kp, -2.0, -ki],
                [0.0, 0.0, 1.0, 0.0],
                [2 * k / m, -kd / m, -cd / m, 0.0],
                [0.0, 1.0, 0.0, 0.0],
            ]
        )
        b = np.array([1.0, 0.0, 0.0, 0.0])
        c = np.array([[k, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])  # tension error; arm travel
        return a, b, c, np.array([0.0, 0.0])

    def held(self, states: Floats) -> Floats:
        """The wire the span and the tensioner hold at ``states`` (rows), m,
        beyond what they hold at rest: the span's stretch, and the dancer's
        loop (twice its travel)."""
        states = np.atleast_2d(states)
        if self.kind == "servo":
            return np.asarray(states[:, 0] / self.stiffness, dtype=np.float64)
        return np.asarray(states[:, 0] + 2 * states[:, 1], dtype=np.float64)

    def steady(self, speed: float) -> Floats:
        """The state of a steady wind at ``speed`` m/s: the set tension, the arm centred."""
        if self.kind == "servo":
            wb = 2 * math.pi * self.bandwidth
            return np.array([0.0, speed / (wb / self.stiffness * wb / 4)])
        if self.supply == "braked":  # the spool turns at the wire's speed, the brake holding the set tension
            return np.array([0.0, 0.0, 0.0, speed])
        ki = self.supply_gain**2 / 4
        return np.array([0.0, 0.0, 0.0, speed / ki])

    def unstable(self) -> str:
        """Why these settings make the tensioner oscillate with this wire (a
        pole of its linear system not in the left half-plane), in one line;
        "" if they do not."""
        a, _, _, _ = self.matrices()
        poles = np.linalg.eigvals(a)
        worst = complex(poles[int(np.argmax(poles.real))])
        if worst.real < -1e-9 * max(1.0, abs(worst)):
            return ""
        hz = abs(worst.imag) / (2 * math.pi)
        if self.kind == "servo":  # (a PI loop on a spring: stable for any positive gain)
            return f"the servo tensioner's tension loop is unstable ({hz:.3g} Hz): raise tensioner.bandwidth"
        if self.supply == "braked":
            return (
                f"the dancer and its braked spool would oscillate ({hz:.3g} Hz, growing at "
                f"{worst.real:.3g} 1/s) with tensioner.dancer_damping {self.damping:g} N s/m, "
                f"tensioner.spool_mass {self.spool_mass:g} kg and tensioner.brake_gain {self.brake_gain:g} "
                f"N/m on a span of {self.stiffness:.4g} N/m: raise the damping"
            )
        return (
            f"the dancer would oscillate ({hz:.3g} Hz, growing at {worst.real:.3g} 1/s) with "
            f"tensioner.dancer_damping {self.damping:g} N s/m and tensioner.supply_gain "
            f"{self.supply_gain:g} 1/s on a span of {self.stiffness:.4g} N/m: raise the damping or lower "
            "the supply gain"
        )

    def cannot_hold(self) -> str:
        """Why the tensioner cannot hold the set tension at all, in words ("" if it can)."""
        if self.kind == "servo" and self.set_tension > self.force_limit:
            return (
                f"tensioner.force_limit {self.force_limit:g} N is below the set tension "
                f"{self.set_tension:.4g} N: the servo cannot hold it"
            )
        return ""

    def limit_words(self, peak: float, travel: float) -> str:
        """What the tensioner cannot do at a predicted peak tension and
        travel, in words ("" if it can)."""
        held = self.cannot_hold()
        if held:
            return held
        if self.kind == "servo" and peak > self.force_limit:
            return f"the servo tensioner holds at most {self.force_limit:g} N (tensioner.force_limit)"
        if self.kind == "dancer" and travel > self.stroke / 2:
            return (
                f"the dancer travels {travel * 1e3:.1f} mm from its centre, beyond its stroke's half "
                f"({self.stroke / 2 * 1e3:.1f} mm, tensioner.dancer_stroke): it hits its end stop"
            )
        return ""


def tensioner_of(values: dict[str, Any], ea: float, set_tension: float) -> Tensioner:
    """The tensioner the settings ``values`` (``tensioner.*``, missing ones at
    their defaults) describe, for a wire of ``E A`` = ``ea`` N."""
    v = {n: s.default for n, s in TENSIONER_SPECS.items()} | {
        k: x for k, x in values.items() if k in TENSIONER_SPECS
    }
    return Tensioner(
        str(v["tensioner.kind"]),
        ea / float(v["tensioner.span"]),
        set_tension,
        bandwidth=float(v["tensioner.bandwidth"]),
        force_limit=float(v["tensioner.force_limit"]),
        mass=float(v["tensioner.dancer_mass"]),
        spring=float(v["tensioner.dancer_spring"]),
        damping=float(v["tensioner.dancer_damping"]),
        stroke=float(v["tensioner.dancer_stroke"]),
        supply_gain=float(v["tensioner.supply_gain"]),
        supply=str(v["tensioner.supply"]),
        spool_mass=float(v["tensioner.spool_mass"]),
        brake_gain=float(v["tensioner.brake_gain"]),
    )
