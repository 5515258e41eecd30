"""The coil as it is laid in its bobbin: turns per layer, build height, turn
lengths, wire length, resistance, fill factor and where the wire finishes.
Pure functions of the geometry; the rules (docs/OPERATING.md: Coil geometry):

* the window is ``W`` wide (axial room between the flanges) and ``H`` high
  (radial room above the core); ``d`` is the wire's outer (insulated)
  diameter, ``d_bare`` its copper's;
* **helical**: a layer holds ``n = floor(W / d)`` turns; layers stack at a
  radial pitch ``p = d``;
* **orthocyclic**: layer 1 holds ``n1 = floor(W / d)``; each next layer lies
  in the grooves of the one below, shifted by ``d/2`` against it, so the even
  layers are shifted by ``d/2`` from the start flange and hold ``n1`` turns
  when ``W - n1*d >= d/2``, else ``n1 - 1``; the odd layers lie over layer 1
  and hold ``n1``. Layers stack at ``p = d*sqrt(3)/2``;
* build height ``h = d + (L - 1)*p``; the coil fits when ``h <= H`` and every
  layer's turns fit ``W`` (``turns*d``, plus ``d/2`` on a shifted layer);
* the centre of layer ``l`` lies ``r_l = d/2 + (l - 1)*p`` above the core; a
  turn of it is ``pi*(D_c + 2*r_l)`` long on a round core of diameter ``D_c``,
  ``2*(w + t) + 2*pi*r_l`` on a rectangular ``w x t`` core;
* wire length = sum over the layers of turns x turn length (over every coil);
  resistance at 20 C = ``rho*length / (pi*d_bare**2/4)``, ``rho`` = 1.7241e-8
  ohm m (annealed copper, IEC 60028); copper fill factor = the coil's turns x
  ``pi*d_bare**2/4 / (W*H)``;
* the wire finishes at the start flange after an even number of layers, at
  the far flange after an odd number.

**Exact fits.** Turn counts are decided in exact rational arithmetic on the
floats' binary values (``fractions.Fraction``), with a tolerance of
:data:`FIT_TOLERANCE` (1 nm): a layer whose turns stick out by at most 1 nm
fits. 1 nm is nothing to a wire, and it absorbs the rounding of lengths
typed in decimal (``W = 0.03 m`` for 60 turns of ``d = 0.0005 m`` holds 60, as
does ``W = 3 * 0.1`` for three turns of ``0.1``, although neither product is
exact in binary). Build height against ``H`` is compared in floating point
with the same tolerance (``sqrt(3)`` is not rational).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

from winder.errors import BadInputError
from winder.motion.takeup import Contour, contour_of_layer, takeup_ratio

__all__ = [
    "CORES",
    "FIT_TOLERANCE",
    "LAYS",
    "RHO_COPPER_20C",
    "Bobbin",
    "CoilGeometry",
    "Layer",
    "Winding",
    "layer_capacity",
    "layer_offset",
    "mm",
    "radial_pitch",
    "report",
    "wind_coil",
    "winding",
]

#: resistivity of annealed copper at 20 C, ohm m (IEC 60028)
RHO_COPPER_20C = 1.7241e-8
#: a layer fits when its turns stick out of the window by at most this, m
FIT_TOLERANCE = 1e-9
_TOL = Fraction(FIT_TOLERANCE)
LAYS = ("helical", "orthocyclic")
CORES = ("round", "rect")


def mm(metres: float) -> str:
    """A length in mm as a person reads it: at least one decimal, at most
    three (50.0, 1.25, 2.165)."""
    text = f"{metres * 1e3:.3f}".rstrip("0")
    return text + "0" if text.endswith(".") else text


@dataclass(frozen=True)
class Bobbin:
    """The window a coil is wound into and the core it is wound on. A
    window size of 0 is unchecked; a core size of 0 is not given (the turn
    lengths, wire length and resistance are then unknown)."""

    window_width: float = 0.0
    window_height: float = 0.0
    core: str = "round"  #: round (core_diameter) or rect (core_width x core_depth)
    core_diameter: float = 0.0
    core_width: float = 0.0
    core_depth: float = 0.0
    core_corner_radius: float = 0.0  #: a rect core's corners (0: sharp)

    @property
    def core_given(self) -> bool:
        if self.core == "round":
            return self.core_diameter > 0
        return self.core_width > 0 and self.core_depth > 0

    def contour(self, radius: float) -> Contour | None:
        """The wire's centre line of a layer whose centre lies ``radius``
        above the core (None: the core is not given)."""
        if not self.core_given:
            return None
        return contour_of_layer(
            self.core,
            radius,
            diameter=self.core_diameter,
            width=self.core_width,
            depth=self.core_depth,
            corner=self.core_corner_radius,
        )

    def turn_length(self, radius: float) -> float | None:
        """Length of one turn whose centre lies ``radius`` above the core
        (None: the core is not given): ``pi (D + 2 r_l)`` on a round core,
        ``2a + 2b - (8 - 2 pi)(r_c + r_l)`` with ``a = w + 2 r_l``, ``b = t + 2 r_l``
        on a rectangular one (``2 (w + t) + 2 pi r_l`` with sharp corners)."""
        if not self.core_given:
            return None
        if self.core == "round":
            return math.pi * (self.core_diameter + 2 * radius)
        contour = self.contour(radius)
        assert contour is not None
        return contour.length

    def takeup_ratio(self, radius: float) -> float | None:
        """How much faster the flyer draws the wire off a corner than off a
        flat over a turn of that layer (1 on a round core; None: not given)."""
        contour = self.contour(radius)
        return None if contour is None else takeup_ratio(contour)


def radial_pitch(d: float, lay: str) -> float:
    """Radial distance between the centres of neighbouring layers."""
    return d * math.sqrt(3) / 2 if lay == "orthocyclic" else d


def layer_offset(d: float, lay: str, number: int) -> float:
    """How far the first turn of layer ``number`` (from 1) is shifted from
    the start flange beyond lying against it: ``d/2`` on the even layers of
    an orthocyclic coil, else 0."""
    return d / 2 if lay == "orthocyclic" and number % 2 == 0 else 0.0


def layer_capacity(width: float, d: float, lay: str, number: int) -> int:
    """Turns of ``d`` wire that fit layer ``number`` (from 1) of a window
    ``width`` wide: the largest n with ``n*d + offset <= width`` (within
    :data:`FIT_TOLERANCE`), exactly."""
    room = Fraction(width) + _TOL - Fraction(layer_offset(d, lay, number))
    return max(0, math.floor(room / Fraction(d)))


@dataclass(frozen=True)
class Layer:
    """One layer of a coil as laid."""

    number: int  #: from 1, the first on the core
    turns: int
    offset: float  #: shift of its first turn from the start flange (m): 0 or d/2
    radius: float  #: its centre above the core, r_l (m)
    turn_length: float | None  #: one turn (m); None: the core is not given
    width: float  #: axial room its turns take, turns*d + offset (m)
    capacity: int | None  #: turns that fit it (None: the window width is unchecked)

    @property
    def length(self) -> float | None:
        """Wire in the layer, m."""
        return None if self.turn_length is None else self.turns * self.turn_length


@dataclass(frozen=True)
class CoilGeometry:
    """One coil as laid: its layers, and what they come to."""

    bobbin: Bobbin
    d: float
    d_bare: float
    lay: str
    layers: tuple[Layer, ...]
    asked: int | None  #: turns per layer asked (None: auto, as many as fit)
    resistivity: float = RHO_COPPER_20C  #: the conductor's, ohm m at 20 C

    @property
    def pitch(self) -> float:
        return radial_pitch(self.d, self.lay)

    @property
    def total_turns(self) -> int:
        return sum(layer.turns for layer in self.layers)

    @property
    def build_height(self) -> float:
        """h = d + (L - 1)*p: from the core to the top of the last layer."""
        return self.d + (len(self.layers) - 1) * self.pitch

    @property
    def wire_length(self) -> float | None:
        lengths = [layer.length for layer in self.layers]
        return None if any(x is None for x in lengths) else math.fsum(x for x in lengths if x is not None)

    @property
    def copper_area(self) -> float:
        return math.pi * self.d_bare**2 / 4

    @property
    def resistance(self) -> float | None:
        """Ohm at 20 C."""
        length = self.wire_length
        return None if length is None else self.resistivity * length / self.copper_area

    @property
    def fill_factor(self) -> float | None:
        """Copper area over window area (None: the window is not given whole)."""
        b = self.bobbin
        if b.window_width <= 0 or b.window_height <= 0:
            return None
        return self.total_turns * self.copper_area / (b.window_width * b.window_height)

    @property
    def finish_side(self) -> str:
        """Where the wire ends: the start flange after an even number of layers."""
        return "start" if len(self.layers) % 2 == 0 else "far"

    def overflow(self) -> str:
        """What does not fit and by how much, in one line ("" if it fits):
        the first layer whose turns are wider than the window, else the
        build height against the window's."""
        b, d = self.bobbin, self.d
        for layer in self.layers:
            if layer.capacity is None:
                continue
            if layer.turns > layer.capacity or layer.turns == 0:
                need = max(layer.turns, 1)  # auto: a layer that holds no turn needs one
                shifted = f" + {mm(layer.offset)} mm offset" if layer.offset else ""
                width = need * d + layer.offset
                at_most = f"at most {layer.capacity} turns fit" if layer.capacity else "no turn fits"
                turns = f"{need} turn{'s' if need != 1 else ''}"
                return (
                    f"layer {layer.number} needs {turns} x {mm(d)} mm{shifted} = {mm(width)} mm, "
                    f"the window is {mm(b.window_width)} mm wide: {mm(width - b.window_width)} mm over "
                    f"({at_most})"
                )
        h, height = self.build_height, b.window_height
        if height > 0 and h > height + FIT_TOLERANCE:
            fit = (
                1 + math.floor((height + FIT_TOLERANCE - d) / self.pitch)
                if height + FIT_TOLERANCE >= d
                else 0
            )
            return (
                f"{len(self.layers)} layers of {mm(d)} mm wire build {mm(h)} mm ({self.lay}, radial pitch "
                f"{mm(self.pitch)} mm), the window is {mm(height)} mm high: {mm(h - height)} mm over "
                f"(at most {fit} layers fit)"
            )
        return ""

    @property
    def fits(self) -> bool:
        return not self.overflow()


def wind_coil(
    bobbin: Bobbin,
    d: float,
    d_bare: float,
    lay: str,
    turns_per_layer: int | None,
    layers: int,
    resistivity: float = RHO_COPPER_20C,
) -> CoilGeometry:
    """The coil of ``layers`` layers of ``turns_per_layer`` turns each (None:
    auto, each layer as many turns as fit it; needs the window width) of
    ``d`` wire (copper ``d_bare``) laid ``lay`` in ``bobbin``."""
    if turns_per_layer is None and bobbin.window_width <= 0:
        raise BadInputError("turns_per_layer=auto needs the window width")
    p = radial_pitch(d, lay)
    out = []
    for number in range(1, layers + 1):
        capacity = layer_capacity(bobbin.window_width, d, lay, number) if bobbin.window_width > 0 else None
        turns = capacity if turns_per_layer is None else turns_per_layer
        assert turns is not None
        offset = layer_offset(d, lay, number)
        radius = d / 2 + (number - 1) * p
        out.append(
            Layer(number, turns, offset, radius, bobbin.turn_length(radius), turns * d + offset, capacity)
        )
    return CoilGeometry(bobbin, d, d_bare, lay, tuple(out), turns_per_layer, resistivity)


@dataclass(frozen=True)
class Winding:
    """Every coil of a job as laid (one per pole, in winding order)."""

    coils: tuple[CoilGeometry, ...]

    @property
    def total_turns(self) -> int:
        return sum(c.total_turns for c in self.coils)

    @property
    def wire_length(self) -> float | None:
        lengths = [c.wire_length for c in self.coils]
        return None if any(x is None for x in lengths) else math.fsum(x for x in lengths if x is not None)

    @property
    def resistance(self) -> float | None:
        """Ohm at 20 C of the whole wire, every coil in series."""
        length = self.wire_length
        return (
            None
            if length is None or not self.coils
            else self.coils[0].resistivity * length / self.coils[0].copper_area
        )

    @property
    def uniform(self) -> bool:
        """Every coil is laid the same."""
        return all(c.layers == self.coils[0].layers for c in self.coils)

    def overflow(self) -> str:
        """The first coil that does not fit, in one line ("" if all fit); the
        coil is named when the coils differ."""
        for i, coil in enumerate(self.coils):
            why = coil.overflow()
            if why:
                return why if self.uniform else f"coil {i + 1}: {why}"
        return ""

    @property
    def fits(self) -> bool:
        return not self.overflow()


def winding(
    bobbin: Bobbin,
    d: float,
    d_bare: float,
    lay: str,
    coils: Sequence[tuple[int | None, int]],
    resistivity: float = RHO_COPPER_20C,
) -> Winding:
    """Every coil ``(turns_per_layer or None for auto, layers)`` laid in
    ``bobbin``, of a conductor of ``resistivity`` (ohm m at 20 C)."""
    made: dict[tuple[int | None, int], CoilGeometry] = {}
    for key in coils:
        if key not in made:
            made[key] = wind_coil(bobbin, d, d_bare, lay, *key, resistivity)
    return Winding(tuple(made[key] for key in coils))


def _coil_dict(coil: CoilGeometry) -> dict[str, Any]:
    return {
        "layers": [
            {
                "layer": layer.number,
                "turns": layer.turns,
                "capacity": layer.capacity,
                "offset_m": layer.offset,
                "width_m": layer.width,
                "radius_m": layer.radius,
                "turn_length_m": layer.turn_length,
                "takeup_ratio": coil.bobbin.takeup_ratio(layer.radius),
                "wire_length_m": layer.length,
            }
            for layer in coil.layers
        ],
        "total_turns": coil.total_turns,
        "build_height_m": coil.build_height,
        "fill_factor": coil.fill_factor,
        "wire_length_m": coil.wire_length,
        "resistance_ohm": coil.resistance,
        "finish_side": coil.finish_side,
        "fits": coil.fits,
        "overflow": coil.overflow(),
    }


def report(laid: Winding) -> dict[str, Any]:
    """What ``winder check --json`` prints of a winding: coil 1's layers,
    turns (``turns_per_coil``), build height, fill factor, finish side; the
    whole job's turns (``total_turns``), wire length and resistance (every
    coil in series); ``fits`` and the refusal's words (``overflow``, "" if it
    fits) over every coil; ``coils``: each coil's own values. Lengths in m,
    resistance in ohm at 20 C; null where the bobbin does not say (a core or
    window size not given)."""
    first = laid.coils[0]
    b = first.bobbin
    one = _coil_dict(first)
    return {
        "lay": first.lay,
        "core": b.core,
        "core_diameter_m": b.core_diameter if b.core == "round" else None,
        "core_width_m": b.core_width if b.core == "rect" else None,
        "core_depth_m": b.core_depth if b.core == "rect" else None,
        "core_corner_radius_m": b.core_corner_radius if b.core == "rect" else None,
        "wire_diameter_m": first.d,
        "bare_diameter_m": first.d_bare,
        "window_width_m": b.window_width or None,
        "window_height_m": b.window_height or None,
        "radial_pitch_m": first.pitch,
        "coils_count": len(laid.coils),
        "layers": one["layers"],
        "turns_per_coil": first.total_turns,
        "total_turns": laid.total_turns,
        "build_height_m": first.build_height,
        "fill_factor": first.fill_factor,
        "wire_length_m": laid.wire_length,
        "resistance_ohm": laid.resistance,
        "finish_side": first.finish_side,
        "fits": laid.fits,
        "overflow": laid.overflow(),
        "uniform": laid.uniform,
        "coils": [{"coil": i + 1, **_coil_dict(c)} for i, c in enumerate(laid.coils)],
    }
