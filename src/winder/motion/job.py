"""Winding jobs: what an operator sets, validated, expanded into straight segments.

A job winds ``poles`` coils. Each coil is ``layers`` layers of
``turns_per_layer`` turns; during a layer the flyer (fork) turns once per turn
while the feed axis advances the rotor one wire diameter per turn, reversing at
every layer. Between coils the pole axis indexes the rotor by 360 deg / poles.
``coil_overrides`` changes single coils: ``"2:turns_per_layer=30;3:direction=ccw,layers=1"``
(coils counted from 1; ``direction`` cw, the fork turning forward as for every
other coil, or ccw, backward: the winding direction).

The coil's geometry (``bobbin.*``, ``wire.bare_diameter``, ``lay``) is laid
out by :mod:`winder.motion.coil`: a job whose coils do not fit their window
is refused, in the words of :meth:`winder.motion.coil.Winding.overflow`.
``turns_per_layer: auto`` winds as many turns as fit a layer. Setting names
with a dot (``bobbin.window_width``) are the job's public names (ROS
parameters, job files, ``--bobbin.window-width``); the dataclass fields are
the part after the last dot, or the name with its dot made ``_``
(:data:`ATTRIBUTES`).

Axes, in this order everywhere in winder: :data:`winder.motion.axes.AXIS_TABLE`
(feed, fork, pole; a segment's ``start`` and ``delta`` are in that order).

Units are SI (metres, radians). Unrolled, a layer is the straight line from its
start to (feed distance, flyer arc length) in the plane: the segment that
:func:`winder.motion.interp.interpolate` walks.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import InitVar, dataclass, fields, replace
from enum import StrEnum
from typing import Any

import numpy as np

from winder.motion.axes import FEED, FORK, POLE
from winder.motion.coil import CORES, LAYS, Bobbin, Winding, layer_capacity, winding
from winder.motion.material import MATERIALS, Material, Wire
from winder.motion.tolerances import parse_tolerances, tolerances_text
from winder.spec import Spec, SpecError, interval, shorten

__all__ = [
    "CAM_PIECES",
    "CROSSOVER_LAWS",
    "FIELD_SPECS",
    "MAX_JOB_SECONDS",
    "MAX_JOB_STEPS",
    "MAX_PIECES",
    "MAX_STEP_RATE",
    "MIN_LAYER_SHARE",
    "Coil",
    "Job",
    "JobError",
    "Segment",
    "SegmentKind",
    "parse_coil_overrides",
]

#: Steps of one axis in one segment, at most: positions travel as int32.
MAX_STEPS = 2**31 - 1
#: The longest a job may last, in simulated time: a week. Step times travel as
#: int64 nanoseconds (good for 292 years), but the sim node produces every
#: sample of that time; limits that would stretch a job beyond it are refused
#: (:mod:`winder.motion.timing` plans with it).
MAX_JOB_SECONDS = 7 * 24 * 3600.0
#: The highest step rate a ramp may set, steps/s (the profile node's ``v_max`` at most).
MAX_STEP_RATE = 1e7
#: Steps of a job, at most: what the highest step rate runs in :data:`MAX_JOB_SECONDS`.
#: A longer job could never run, and every tool that walks its steps (``winder
#: interp``: some 3*10^7 a second) would walk them for days; it is refused from
#: its turn counts before anything is laid out.
MAX_JOB_STEPS = round(MAX_JOB_SECONDS * MAX_STEP_RATE)
#: The least share of ``v_max`` a layer may be wound at (``first_layer_speed``,
#: a ``layer_speed`` share): a layer's ramp limits are scaled by its share up to
#: its cube, which must stay a number a ramp can plan with.
MIN_LAYER_SHARE = 1e-3
#: Straight moves of a job, at most (its segments' pieces: an orthocyclic
#: layer is two a turn): every node lays them out, about 0.1 kB and 1 us each
MAX_PIECES = 2**20
#: the orthocyclic crossover's cam laws (``lay.crossover_law``)
CROSSOVER_LAWS = ("cycloidal", "linear")
#: straight pieces a cycloidal crossover is laid in, at most (one fork step each at least)
CAM_PIECES = 16


def cycloid(u: float) -> float:
    """The cycloidal cam law over ``u`` in [0, 1]: ``u - sin(2 pi u) / (2 pi)``,
    from 0 to 1 with zero speed and zero acceleration at both ends; its speed
    ``1 - cos(2 pi u)`` peaks at 2, its acceleration at 2 pi."""
    return u - math.sin(2 * math.pi * u) / (2 * math.pi)


def crossover_cam(across: int, zone: int, law: str) -> list[tuple[int, int]]:
    """The straight pieces (feed steps, fork steps) of a crossover of
    ``across`` feed steps (signed) over ``zone`` fork steps, by ``law``: one
    piece (linear), or the cycloid through :data:`CAM_PIECES` points (at
    most one a fork step), each point rounded to whole steps."""
    if law == "linear" or across == 0:
        return [(across, zone)]
    n = min(CAM_PIECES, zone)
    points = [
        (math.floor(across * cycloid(i / n) + 0.5), math.floor(zone * i / n + 0.5)) for i in range(n + 1)
    ]
    return [(f1 - f0, k1 - k0) for (f0, k0), (f1, k1) in itertools.pairwise(points) if k1 > k0 or f1 != f0]


def steepest(pieces: Sequence[tuple[int, int]]) -> float:
    """The largest feed steps per fork step of a crossover's pieces (inf: a piece of no fork step)."""
    return max(abs(f) / k if k else (math.inf if f else 0.0) for f, k in pieces)


def steepest_crossing(across: Iterable[int], zone: int, law: str) -> float:
    """:func:`steepest` of the crossovers of ``across`` feed steps each (their
    sizes), each way the feed goes, over ``zone`` fork steps by ``law``."""
    return max(steepest(crossover_cam(s * a, zone, law)) for a in across for s in (1, -1))


#: the most a cycloid rises over one of its CAM_PIECES equal parts (its middle ones)
_CYCLOID_RISE = cycloid(0.5 + 1 / CAM_PIECES) - cycloid(0.5)


def shortest_zone(across: Iterable[int], zone: int, law: str) -> int:
    """The fewest fork steps, ``zone`` at least, over which the crossovers of
    ``across`` feed steps each keep the flyer leading every piece
    (:func:`steepest_crossing` at most 1). The search starts where it can
    first succeed: a linear crossover of ``a`` steps needs ``a`` fork steps;
    a cycloid's steepest part rises ``a`` x :data:`_CYCLOID_RISE` over about
    a ``CAM_PIECES``-th of the zone, give or take a step each (so a fine
    feed is answered in a few tries, not one try per fork step)."""
    sizes = {abs(a) for a in across}
    a = max(sizes, default=0)
    least = a if law == "linear" else math.floor(CAM_PIECES * (a * _CYCLOID_RISE - 2))
    z = max(zone, least, 1)
    while steepest_crossing(sizes, z, law) > 1:
        z += 1
    return z


class JobError(SpecError):
    """A job field is out of range; the message names field, value and range."""


def _f(
    name: str, low: float, high: float, unit: str, text: str, default: float, *, open_low: bool = True
) -> Spec:
    return Spec(name, float, default, text, unit, low, high, low_open=open_low)


def _i(name: str, low: int, high: int, text: str, default: int) -> Spec:
    return Spec(name, int, default, text, "", low, high)


#: ``turns_per_layer: auto``: as many turns as fit each layer
AUTO = "auto"


@dataclass(frozen=True)
class _TurnsSpec(Spec):
    """An integer setting that may also be ``auto`` (kept as the text)."""

    def range_text(self) -> str:
        return f"{super().range_text()} or {AUTO}"

    def check(self, value: Any) -> Any:
        return AUTO if value == AUTO else super().check(value)

    def parse(self, text: str) -> Any:
        return AUTO if text.strip() == AUTO else super().parse(text)


class _TolerancesSpec(Spec):
    """The recipe's tolerances (:mod:`winder.motion.tolerances`): their JSON
    text, or the map a job file writes, kept as the canonical text."""

    def range_text(self) -> str:
        return 'a JSON map of name: [min, max], e.g. {"resistance_ohm": [11.5, 12.5]}, or empty'

    def check(self, value: Any) -> Any:
        if not isinstance(value, (str, Mapping)):
            raise SpecError(f"{self.name}={shorten(str(value))} is invalid: must be {self.range_text()}")
        return tolerances_text(parse_tolerances(value, self.name))

    def parse(self, text: str) -> Any:
        return self.check(text)


#: Job fields with their allowed ranges. The numbers bound what a physical
#: winding cell can be (a 10 m flyer or a 10 cm wire is a typing error).
#: Defaults: the RW400 set-up of the 2016 paper (flyer radius 500 mm, wire
#: 2.50 mm, fork register 2**10), four poles of two layers of 20 turns.
FIELD_SPECS: dict[str, Spec] = {
    s.name: s
    for s in (
        Spec(
            "job_id",
            str,
            "rw400",
            "name of the job; names the bag",
            pattern=r"[A-Za-z0-9][A-Za-z0-9_\-]{0,63}",
            pattern_text="1-64 letters, digits, '_' or '-', starting with a letter or digit",
        ),
        _f("wire_diameter", 0.0, 0.02, "m", "wire diameter", 2.5e-3),
        _f("flyer_radius", 0.0, 5.0, "m", "flyer (fork) radius", 0.5),
        _TurnsSpec(
            "turns_per_layer",
            int,
            20,
            "turns in one layer (auto: as many as fit the layer, per bobbin.window_width and lay)",
            "",
            1,
            100_000,
        ),
        _i("layers", 1, 1_000, "layers per coil; the feed reverses at each layer", 2),
        _i("poles", 1, 360, "coils (poles); the pole axis indexes 360/poles deg between them", 4),
        _i("fork_steps_per_rev", 4, 2**24, "fork axis steps per revolution", 1024),
        _f("feed_step", 0.0, 1e-3, "m", "feed axis travel per step", 1e-5),
        _i("pole_steps_per_rev", 4, 2**24, "pole axis steps per revolution", 1024),
        _f(
            "coil_length",
            0.0,
            10.0,
            "m",
            "deprecated name of bobbin.window_width (0 = not given)",
            0.0,
            open_low=False,
        ),
        _f(
            "bobbin.window_width",
            0.0,
            10.0,
            "m",
            "axial room between the bobbin's flanges for a layer (0 = unchecked)",
            0.0,
            open_low=False,
        ),
        _f(
            "bobbin.window_height",
            0.0,
            10.0,
            "m",
            "radial room above the core for the layers (0 = unchecked)",
            0.0,
            open_low=False,
        ),
        Spec(
            "bobbin.core",
            str,
            "round",
            "the core's section: round (bobbin.core_diameter) or rect (bobbin.core_width x "
            "bobbin.core_depth)",
            choices=CORES,
        ),
        _f(
            "bobbin.core_diameter",
            0.0,
            10.0,
            "m",
            "round core's diameter (0 = not given)",
            0.0,
            open_low=False,
        ),
        _f(
            "bobbin.core_width",
            0.0,
            10.0,
            "m",
            "rectangular core's width w (0 = not given)",
            0.0,
            open_low=False,
        ),
        _f(
            "bobbin.core_depth",
            0.0,
            10.0,
            "m",
            "rectangular core's depth t (0 = not given)",
            0.0,
            open_low=False,
        ),
        _f(
            "bobbin.core_corner_radius",
            0.0,
            5.0,
            "m",
            "rectangular core's corner radius r_c (0 = sharp corners), at most half its smaller side",
            0.0,
            open_low=False,
        ),
        _f(
            "wire.bare_diameter",
            0.0,
            0.02,
            "m",
            "the bare conductor's diameter, without insulation (0 = wire_diameter)",
            0.0,
            open_low=False,
        ),
        Spec(
            "lay",
            str,
            "helical",
            "how the turns are laid: helical (each turn one wire diameter on) or orthocyclic (each "
            "layer in the grooves of the one below, crossing over within lay.crossover)",
            choices=LAYS,
        ),
        _f("lay.crossover", 0.0, 360.0, "deg", "orthocyclic: the crossover zone, in flyer angle", 60.0),
        Spec(
            "lay.crossover_law",
            str,
            "cycloidal",
            "orthocyclic: the feed's cam law across the crossover zone: cycloidal (its acceleration "
            "rises and falls smoothly, no jump in speed; peak speed twice the mean) or linear (a "
            "constant speed, with a jump at both ends)",
            choices=CROSSOVER_LAWS,
        ),
        _f(
            "lay.crossover_at",
            0.0,
            360.0,
            "deg",
            "orthocyclic: flyer angle where the crossover zone starts, in [0, 360)",
            0.0,
            open_low=False,
        ),
        _f(
            "reversal_dwell",
            0.0,
            1000.0,
            "turns",
            "turns wound in place at a flange before the layer reverses",
            0.0,
            open_low=False,
        ),
        _f(
            "first_layer_speed",
            MIN_LAYER_SHARE,
            1.0,
            "",
            "speed of layer 1, a fraction of v_max",
            1.0,
            open_low=False,
        ),
        Spec(
            "layer_speed",
            str,
            "",
            "single layers at a fraction of v_max: COIL:LAYER=SHARE separated by ';' (COIL * = every "
            "coil; times first_layer_speed on layer 1); tension.derate fills it in for a run",
            pattern=r"[0-9*.:=;eE+\-\s]*",
            pattern_text='e.g. "*:3=0.8;2:4=0.75", or empty',
        ),
        Spec(
            "wire.material",
            str,
            "copper",
            "the conductor: copper or aluminium (annealed; its figures below, 0 = the material's)",
            choices=tuple(MATERIALS),
        ),
        _f(
            "wire.yield_stress",
            0.0,
            1e9,
            "Pa",
            "where the conductor starts to flow (0 = the material's)",
            0.0,
            open_low=False,
        ),
        _f(
            "wire.modulus",
            0.0,
            1e12,
            "Pa",
            "the conductor's Young's modulus (0 = the material's)",
            0.0,
            open_low=False,
        ),
        _f(
            "wire.density",
            0.0,
            3e4,
            "kg/m3",
            "the conductor's density (0 = the material's)",
            0.0,
            open_low=False,
        ),
        _f("wire.resistivity", 0.0, 1e-6, "ohm m", "at 20 C (0 = the material's)", 0.0, open_low=False),
        _f(
            "tension.set", 0.0, 1e4, "N", "the wire's set tension (0 = half its maximum)", 0.0, open_low=False
        ),
        _f(
            "tension.warning",
            0.0,
            1.0,
            "",
            "the warning band: the set tension +- this fraction of it",
            0.2,
            open_low=False,
        ),
        _f(
            "tension.alarm",
            0.0,
            1.0,
            "",
            "the alarm band: the set tension +- this fraction of it",
            0.4,
            open_low=False,
        ),
        _f(
            "tension.max_share", 0.05, 1.0, "", "the share of the wire's maximum tension a job may reach", 1.0
        ),
        _f(
            "tension.slip_tolerance",
            0.0,
            100.0,
            "m",
            "a slip or count mismatch: the wire paid out may differ from what the turns took by this much",
            0.01,
        ),
        Spec(
            "tension.derate",
            bool,
            False,
            "cap the flyer's speed per layer so the predicted peak tension stays within the limit "
            "(false: such a job is refused)",
        ),
        Spec(
            "coil_overrides",
            str,
            "",
            "single coils that differ from the others: COIL:KEY=VALUE[,KEY=VALUE] separated by ';', "
            "KEY turns_per_layer, layers or direction (cw|ccw)",
            pattern=r"[0-9A-Za-z_:=,;\s]*",
            pattern_text='e.g. "2:turns_per_layer=30;3:direction=ccw,layers=1", or empty',
        ),
        _TolerancesSpec(
            "tolerances",
            str,
            "",
            "the part's tolerances, each recorded scalar's [min, max] (docs/PARTS.md): they set "
            "the verdict of every part wound to this job",
        ),
    )
}

#: the dataclass field of each job setting: the part after its last dot
#: (``bobbin.window_width``: ``window_width``), but ``wire.bare_diameter``:
#: ``bare_diameter`` and ``lay.crossover*``: ``crossover*``
ATTRIBUTES = {
    name: name.replace(".", "_") if name.startswith("tension.") else name.rsplit(".", 1)[-1]
    for name in FIELD_SPECS
}
#: the job setting of each dataclass field
SETTINGS = {attr: name for name, attr in ATTRIBUTES.items()}

#: what a coil override may set: the field's spec (direction: cw or ccw)
COIL_KEYS = ("turns_per_layer", "layers", "direction")


@dataclass(frozen=True)
class Coil:
    """How one coil is wound: its turns per layer, layers and direction (+1
    cw, -1 ccw). As asked (:func:`parse_coil_overrides`) ``turns_per_layer``
    0 stands for auto; :meth:`Job.coil` gives the turns of its layer 1."""

    turns_per_layer: int
    layers: int
    direction: int


def _list_items(name: str, text: str, sep: str = ";") -> list[str]:
    """The items of a setting that lists them separated by ``sep``, each
    stripped; none for a blank text. JobError (one line) for an empty item
    (two separators side by side, or one at an end): a list typed so says
    nothing, and is not taken as saying less."""
    if not text.strip():
        return []
    items = [t.strip() for t in text.split(sep)]
    if not all(items):
        raise JobError(
            f"{name}={shorten(text)} is invalid: it has an empty item (two '{sep}' side by side, or one "
            f"at an end); leave out the '{sep}' or give the item"
        )
    return items


def parse_layer_speeds(text: str, layers: Sequence[int]) -> dict[tuple[int, int], float]:
    """The layers ``text`` slows down, ``(pole, layer)`` from 0 -> share of
    ``v_max`` in [:data:`MIN_LAYER_SHARE`, 1], for coils of ``layers`` layers
    each; JobError (one line) naming the item and the allowed range. A layer
    given twice (``*`` and its coil) takes the last."""
    out: dict[tuple[int, int], float] = {}
    shares = interval(MIN_LAYER_SHARE, 1.0)
    for item in _list_items("layer_speed", text):
        head, _, body = item.partition(":")
        layer_text, _, share_text = body.partition("=")
        try:
            coils = range(len(layers)) if head.strip() == "*" else [int(head) - 1]
            layer, share = int(layer_text), float(share_text)
        except ValueError:
            raise JobError(f"layer_speed: {item!r} must be COIL:LAYER=SHARE (COIL a number or *)") from None
        if any(not 0 <= c < len(layers) for c in coils):
            raise JobError(f"layer_speed: coil {head.strip()} is not in [1, {len(layers)}] (poles)")
        if not MIN_LAYER_SHARE <= share <= 1.0:  # also nan
            raise JobError(f"layer_speed: {item!r}: share {share:g} is invalid: must be in {shares}")
        for pole in coils:
            if not 1 <= layer <= layers[pole]:
                raise JobError(
                    f"layer_speed: {item!r}: layer {layer} is not in [1, {layers[pole]}] "
                    f"(the layers of coil {pole + 1})"
                )
            out[(pole, layer - 1)] = share
    return out


def parse_coil_overrides(text: str, poles: int, base: Coil) -> dict[int, Coil]:
    """The coils ``text`` changes (0-based pole index -> Coil); JobError (one
    line) naming the item, the key and the allowed range (an empty item, or a
    coil with nothing to change, ``"1:"``, too)."""
    out: dict[int, Coil] = {}
    for item in _list_items("coil_overrides", text):
        head, _, body = item.partition(":")
        rule = f"coil_overrides: {item!r} must be COIL:KEY=VALUE[,KEY=VALUE]"
        try:
            coil = int(head)
        except ValueError:
            raise JobError(rule) from None
        if not 1 <= coil <= poles:
            raise JobError(f"coil_overrides: coil {coil} is not in [1, {poles}] (poles)")
        pairs = [p.strip() for p in body.split(",")]
        if not all(pairs):  # "1:" changes nothing; "1:layers=2,,": an empty pair
            raise JobError(f"{rule}: {'no KEY=VALUE' if not any(pairs) else 'an empty KEY=VALUE'}")
        values = {"turns_per_layer": base.turns_per_layer, "layers": base.layers, "direction": base.direction}
        for pair in pairs:
            key, _, value = pair.partition("=")
            key, value = key.strip(), value.strip()
            if key == "direction":
                if value not in ("cw", "ccw"):
                    raise JobError(
                        f"coil_overrides: coil {coil} direction={value!r} is invalid: must be cw or ccw"
                    )
                values["direction"] = 1 if value == "cw" else -1
            elif key in ("turns_per_layer", "layers"):
                try:
                    parsed = FIELD_SPECS[key].parse(value)
                    values[key] = 0 if parsed == AUTO else parsed
                except SpecError as exc:
                    raise JobError(f"coil_overrides: coil {coil}: {exc}") from None
            else:
                raise JobError(
                    f"coil_overrides: coil {coil}: unknown key {key!r}: must be one of {', '.join(COIL_KEYS)}"
                )
        if coil - 1 in out:
            raise JobError(f"coil_overrides: coil {coil} is given twice")
        out[coil - 1] = Coil(**values)
    return out


class SegmentKind(StrEnum):
    """What a segment of a job does (its value is the word bags and job
    descriptions carry)."""

    LAYER = "layer"  #: lays a layer: the flyer turns while the feed advances (a line, or a cam)
    INDEX = "index"  #: indexes the rotor to the next coil: the pole axis alone

    @property
    def words(self) -> str:
        """The segment kind in a message."""
        return "layer" if self is SegmentKind.LAYER else "pole index"

    @property
    def winds(self) -> bool:
        """Whether wire is laid in it (a layer), so turns and stops fall in it."""
        return self is SegmentKind.LAYER


@dataclass(frozen=True)
class Segment:
    """One move of a job, in steps: ``start`` + ``delta`` per axis (AXES
    order), and where it is in the winding: its coil (``pole``), layer and
    turns. The one record of a segment every node, the bag's reader and the
    analysis use (:attr:`Job.segments`; a job description's plan holds the
    same records). It answers what its callers ask: its turns, its fork
    range, whether the axes may stop inside it and after which step each of
    its turns ends (:meth:`turn_end`, :meth:`turn_at`)."""

    index: int
    kind: SegmentKind
    start: tuple[int, int, int]
    delta: tuple[int, int, int]
    pole: int  #: coil being wound (or indexed to), from 0
    layer: int  #: layer within the coil, from 0 (-1 for an index move)
    #: a layer laid by a cam of the flyer (orthocyclic, or with a reversal
    #: dwell): its straight pieces, each a delta in steps (AXES order), the
    #: fork the major axis of each, summing to ``delta``; () for one straight move
    cam: tuple[tuple[int, int, int], ...] = ()
    turns: int = 0  #: turns laid in it (0 for an index move)
    #: turns of its coil laid before it (its coil's earlier layers): its
    #: first turn is turn ``first_turn + 1`` of the coil
    first_turn: int = 0
    #: fork steps of one turn (the job's ``fork_steps_per_rev``; 0 for an index move)
    turn_steps: int = 0

    @property
    def pieces(self) -> tuple[tuple[int, int, int], ...]:
        """The straight pieces of the move: the cam's, or the one line ``delta``."""
        return self.cam or (self.delta,)

    @property
    def end(self) -> tuple[int, int, int]:
        return tuple(s + d for s, d in zip(self.start, self.delta, strict=True))  # type: ignore[return-value]

    @property
    def steps(self) -> int:
        """Number of interpolation steps: the major axis' step count."""
        return max(abs(d) for d in self.delta)

    @property
    def major(self) -> int:
        """Index of the axis with the most steps (the first of equals): the
        step index counts its steps."""
        return max(range(len(self.delta)), key=lambda i: abs(self.delta[i]))

    @property
    def fork_range(self) -> tuple[int, int]:
        """The fork positions (steps) it spans, low and high: the flyer turns
        one way through a segment."""
        a, b = self.start[FORK.index], self.start[FORK.index] + self.delta[FORK.index]
        return (a, b) if a <= b else (b, a)

    @property
    def last_turn(self) -> int:
        """The coil's turn (from 1) its last turn is; ``first_turn`` for an index move."""
        return self.first_turn + self.turns

    @property
    def stops_inside(self) -> bool:
        """Whether the axes may stop inside it at a turn's end: a layer whose
        every step is a fork step (the fork its major axis), so each of its
        turns ends on a step index. Any segment may stop at its end."""
        return self.kind.winds and abs(self.delta[FORK.index]) >= abs(self.delta[FEED.index])

    def turn_end(self, turn: int) -> int:
        """The step index after which its turn ``turn`` (from 1, counted
        within the segment) is complete: the fork at the turn's end; the
        segment's last step (after the reversal dwell) for its last turn.
        ValueError for a turn it does not have, or one inside a layer that
        may not stop inside (:attr:`stops_inside`)."""
        if not 1 <= turn <= self.turns:
            raise ValueError(f"segment {self.index} has turns 1..{self.turns}, not {turn}")
        if turn == self.turns:
            return self.steps
        if not self.stops_inside:
            raise ValueError(f"segment {self.index}: its turns do not end on step indices")
        return turn * self.turn_steps

    @property
    def stop_points(self) -> tuple[int, ...]:
        """The step indices the axes may stop after within it, each the end
        of one of its turns (:meth:`turn_end`), ascending: every turn's end in
        a layer that may stop inside, else its end alone; () for an index move."""
        if not self.kind.winds or self.turns < 1:
            return ()
        if not self.stops_inside:
            return (self.steps,)
        return tuple(self.turn_end(t) for t in range(1, self.turns + 1))

    def turn_at(self, k: int) -> int:
        """The coil's turn (from 1; 0 before its first) completed after step
        ``k`` of this layer: the inverse of :meth:`turn_end` over the coil's
        turns; ``first_turn`` for an index move."""
        if not self.kind.winds:
            return self.first_turn
        within = self.turns if k >= self.steps else min(max(k, 0) // self.turn_steps, self.turns)
        return self.first_turn + within


@dataclass(frozen=True)
class Job:
    """A winding job. Defaults: the RW400 set-up of the 2016 paper (flyer radius
    500 mm, wire 2.50 mm, fork register 2**10), four poles of two layers.

    Fields are the job's settings (:data:`FIELD_SPECS`) by their
    :data:`ATTRIBUTES` names; :meth:`from_dict` and :meth:`to_dict` use the
    settings' names. ``check_fit=False`` builds a job whose coils need not
    fit their window (``winder check`` reports such a job before it refuses
    it); every other check still holds."""

    job_id: str = FIELD_SPECS["job_id"].default
    wire_diameter: float = FIELD_SPECS["wire_diameter"].default
    flyer_radius: float = FIELD_SPECS["flyer_radius"].default
    turns_per_layer: int | str = FIELD_SPECS["turns_per_layer"].default  #: or "auto"
    layers: int = FIELD_SPECS["layers"].default
    poles: int = FIELD_SPECS["poles"].default
    fork_steps_per_rev: int = FIELD_SPECS["fork_steps_per_rev"].default
    feed_step: float = FIELD_SPECS["feed_step"].default
    pole_steps_per_rev: int = FIELD_SPECS["pole_steps_per_rev"].default
    coil_length: float = FIELD_SPECS["coil_length"].default  #: deprecated: window_width
    coil_overrides: str = FIELD_SPECS["coil_overrides"].default
    window_width: float = FIELD_SPECS["bobbin.window_width"].default
    window_height: float = FIELD_SPECS["bobbin.window_height"].default
    core: str = FIELD_SPECS["bobbin.core"].default
    core_diameter: float = FIELD_SPECS["bobbin.core_diameter"].default
    core_width: float = FIELD_SPECS["bobbin.core_width"].default
    core_depth: float = FIELD_SPECS["bobbin.core_depth"].default
    core_corner_radius: float = FIELD_SPECS["bobbin.core_corner_radius"].default
    bare_diameter: float = FIELD_SPECS["wire.bare_diameter"].default
    lay: str = FIELD_SPECS["lay"].default
    crossover: float = FIELD_SPECS["lay.crossover"].default
    crossover_at: float = FIELD_SPECS["lay.crossover_at"].default
    crossover_law: str = FIELD_SPECS["lay.crossover_law"].default
    reversal_dwell: float = FIELD_SPECS["reversal_dwell"].default
    first_layer_speed: float = FIELD_SPECS["first_layer_speed"].default
    layer_speed: str = FIELD_SPECS["layer_speed"].default
    material: str = FIELD_SPECS["wire.material"].default
    yield_stress: float = FIELD_SPECS["wire.yield_stress"].default
    modulus: float = FIELD_SPECS["wire.modulus"].default
    density: float = FIELD_SPECS["wire.density"].default
    resistivity: float = FIELD_SPECS["wire.resistivity"].default
    tension_set: float = FIELD_SPECS["tension.set"].default
    tension_warning: float = FIELD_SPECS["tension.warning"].default
    tension_alarm: float = FIELD_SPECS["tension.alarm"].default
    tension_max_share: float = FIELD_SPECS["tension.max_share"].default
    tension_derate: bool = FIELD_SPECS["tension.derate"].default
    tension_slip_tolerance: float = FIELD_SPECS["tension.slip_tolerance"].default
    tolerances: str = FIELD_SPECS["tolerances"].default  #: JSON text (winder.motion.tolerances)
    check_fit: InitVar[bool] = True

    def __post_init__(self, check_fit: bool) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, check_field(SETTINGS[f.name], getattr(self, f.name)))
        self._check_geometry()
        self._check_wire()
        auto = self.turns_per_layer == AUTO
        base = Coil(0 if auto else int(self.turns_per_layer), self.layers, 1)
        coils = parse_coil_overrides(self.coil_overrides, self.poles, base)
        asked = tuple(coils.get(p, base) for p in range(self.poles))
        if any(c.turns_per_layer == 0 for c in asked):
            self._check_auto_turns(auto)
        laid = winding(
            self.bobbin,
            self.wire_diameter,
            self.bare_diameter or self.wire_diameter,
            self.lay,
            [(c.turns_per_layer or None, c.layers) for c in asked],
            self.wire.material.resistivity,
        )
        object.__setattr__(self, "_winding", laid)
        wound = tuple(
            replace(c, turns_per_layer=g.layers[0].turns) for c, g in zip(asked, laid.coils, strict=True)
        )
        object.__setattr__(self, "_coils", wound)
        first = layer_capacity(self.bobbin.window_width, self.wire_diameter, self.lay, 1) if auto else 0
        object.__setattr__(self, "_base_turns", first if auto else base.turns_per_layer)
        if check_fit and not laid.fits:
            raise JobError(laid.overflow())
        self._check_flyer_clears(laid)
        self._check_size(laid)
        _ = self.layer_speeds  # layer_speed parsed against the coils' layers (JobError, one line)
        checked = {(base.turns_per_layer, base.layers)}
        for p, c in enumerate(wound):
            if (
                asked[p] != base and c.turns_per_layer > 0 and (c.turns_per_layer, c.layers) not in checked
            ):  # each coil's layers checked as the common one is below
                checked.add((c.turns_per_layer, c.layers))
                try:
                    replace(  # one coil of it: the job's size is checked above
                        self,
                        turns_per_layer=c.turns_per_layer,
                        layers=c.layers,
                        poles=1,
                        coil_overrides="",
                        layer_speed="",  # the job's layers' speeds are checked against the job's coils
                        check_fit=False,
                    )
                except JobError as exc:
                    raise JobError(f"coil_overrides: coil {p + 1}: {exc}") from None
        steps_per_turn = self.wire_diameter / self.feed_step
        if steps_per_turn < 1.0:
            raise JobError(
                f"feed_step={self.feed_step:g} m is invalid for wire_diameter="
                f"{self.wire_diameter:g} m: must be at most the wire diameter "
                "(the feed must advance at least one step per turn)"
            )
        if self.wire_diameter >= 2 * math.pi * self.flyer_radius:
            raise JobError(
                f"wire_diameter={self.wire_diameter:g} m is invalid: must be smaller than "
                f"the flyer circumference {2 * math.pi * self.flyer_radius:g} m"
            )
        turns = self.layer_turns
        layer_length = turns * self.wire_diameter
        feed_steps = layer_length / self.feed_step
        if not feed_steps < MAX_STEPS:  # also inf: a tiny feed_step overflows the ratio
            raise JobError(
                f"feed_step={self.feed_step:g} m is invalid with turns_per_layer={turns} of "
                f"{self.wire_diameter:g} m wire: a layer would take {feed_steps:.3g} feed steps, "
                f"more than 2**31 - 1 (feed_step must be at least {layer_length / MAX_STEPS:.3g} m)"
            )
        self._check_cam()
        if self.layer_fork_steps > 2**31 - 1:
            raise JobError(
                f"turns_per_layer={turns} is invalid: a layer of "
                f"{self.layer_fork_steps} fork steps exceeds 2**31 - 1 steps"
            )
        self._check_steps(laid)

    def _check_auto_turns(self, auto: bool) -> None:
        """``turns_per_layer: auto`` (here or in a coil override) resolves to
        as many turns as fit layer 1 of the window (the most of any layer):
        checked against ``turns_per_layer``'s own range before anything is
        laid out or sized from it (JobError, one line)."""
        where = "turns_per_layer=auto" if auto else "coil_overrides: turns_per_layer=auto"
        width = self.bobbin.window_width
        if width <= 0:
            raise JobError(
                f"{where} is invalid without bobbin.window_width: give the window's width "
                "(as many turns as fit it are wound)"
            )
        spec = FIELD_SPECS["turns_per_layer"]
        high = int(spec.high or 0)
        fit = layer_capacity(width, self.wire_diameter, self.lay, 1)
        if fit > high:
            given = f"bobbin.window_width={width:g} m" if self.window_width else f"coil_length={width:g} m"
            raise JobError(
                f"{where} is invalid: {fit} turns of {self.wire_diameter:g} m wire fit a layer of "
                f"{given}, turns_per_layer must be in [{int(spec.low or 1)}, {high}]; give turns_per_layer "
                "(the turns wound in the window's first part), or a narrower window"
            )

    def _check_size(self, laid: Winding) -> None:
        """The job's moves are few enough to lay out (JobError, one line),
        checked from the turn counts before any move is made: a layer is one
        straight piece (two with a reversal dwell); an orthocyclic layer is a
        cam of a hold and a crossover a turn (the crossover one piece, or
        :data:`CAM_PIECES` by the cycloidal law) and one more, and
        each piece is a Python object that every node of the cell holds
        (:data:`MAX_PIECES`)."""
        per_turn = 1 + (1 if self.crossover_law == "linear" else CAM_PIECES)  # a hold, a crossover
        if self.lay == "orthocyclic":
            pieces = sum(per_turn * c.total_turns + len(c.layers) for c in laid.coils)
        else:
            pieces = sum(len(c.layers) for c in laid.coils) * (2 if self.dwell_fork_steps else 1)
        pieces += self.poles - 1  # the index moves
        object.__setattr__(self, "_moves", pieces)
        if pieces > MAX_PIECES:
            turns = laid.total_turns
            raise JobError(
                f"turns_per_layer={self.layer_turns} x layers={self.layers} x poles={self.poles} "
                f"(lay={self.lay}) is invalid: {turns} turns make {pieces} straight moves, a job may have "
                f"at most {MAX_PIECES} (an orthocyclic job about {MAX_PIECES // per_turn} turns); wind fewer "
                "turns per job"
            )

    def _check_steps(self, laid: Winding) -> None:
        """The job's steps are few enough for a cell to run within a week
        (JobError, one line; :data:`MAX_JOB_STEPS`), counted from its turns
        (:meth:`_count_steps`) once each layer's steps are known to be in
        range, before any move is made or timed."""
        steps = self._count_steps(laid)
        if steps > MAX_JOB_STEPS:
            raise JobError(
                f"turns_per_layer={self.layer_turns} x layers={self.layers} x poles={self.poles} with "
                f"fork_steps_per_rev={self.fork_steps_per_rev} is invalid: {steps} steps, a job may have at "
                f"most {MAX_JOB_STEPS} (what the highest step rate, {MAX_STEP_RATE:g} steps/s, runs in the "
                f"longest a job may last, {MAX_JOB_SECONDS:g} s); wind fewer turns per job"
            )

    def _count_steps(self, laid: Winding) -> int:
        """The job's steps (:attr:`total_steps`), counted from its turns before
        anything is laid out: a layer's major axis is the fork (its turns and
        the reversal dwell; an orthocyclic cam keeps the fork major,
        :meth:`_check_cam`) or a helical layer's feed, and the index moves
        turn the pole axis once round at most."""
        spr, dwell = self.fork_steps_per_rev, self.dwell_fork_steps
        helical = self.lay != "orthocyclic"
        each: dict[int, int] = {}  # coils asked alike are one geometry (winding): counted once
        for coil in laid.coils:
            if id(coil) not in each:
                each[id(coil)] = sum(
                    max(layer.turns * spr + dwell, self.feed_steps_of(layer.turns) if helical else 0)
                    for layer in coil.layers
                )
        return sum(each[id(coil)] for coil in laid.coils) + self.pole_position(self.poles - 1)

    def _check_cam(self) -> None:
        """The cam's pieces can be stepped with the fork as the major axis
        (JobError, one line): the feed never outruns the flyer, so its step
        rate stays below the fork's (at most ``v_max``) at any speed. Checked
        on the cam as it is laid, whole steps: every crossover it lays (a
        turn's, two half diameters; a climb's, one), each way the feed goes
        (a cycloid's points round to steps unlike forward and back)."""
        spr = self.fork_steps_per_rev
        if self.lay == "orthocyclic":
            if self.crossover_at + self.crossover > 360.0:
                raise JobError(
                    f"lay.crossover_at={self.crossover_at:g} with lay.crossover={self.crossover:g} is "
                    "invalid: the crossover zone must lie within a turn (crossover_at + crossover <= 360 deg)"
                )
            turns = max(self.layer_turns_of(p, 0) for p in range(self.poles))
            # the places of the turns in half wire diameters from the coil's first turn (turn_place)
            halves = np.arange(2 * max(turns, 2) + 2, dtype=np.float64)
            places = np.floor(halves * (self.wire_diameter / (2 * self.feed_step) * (1 + 1e-9)) + 0.5)
            crossings = {int(x) for gap in (1, 2) for x in np.unique(places[gap:] - places[:-gap])}
            zone = self.crossover_zone[1]
            law = self.crossover_law
            if steepest_crossing(crossings, zone, law) > 1:
                across = max(crossings)
                need = math.ceil(shortest_zone(crossings, zone, law) / spr * 3600.0) / 10.0
                peak = " at its peak" if law != "linear" else ""
                raise JobError(
                    f"lay.crossover={self.crossover:g} deg is too short: the feed crosses {across} steps "
                    f"({self.wire_diameter:g} m) in {zone} fork steps (lay.crossover_law {law}), faster "
                    f"than the flyer turns{peak}; the shortest crossover zone that would do is {need:g} deg "
                    f"(or a coarser feed_step{', or lay.crossover_law linear' if law != 'linear' else ''})"
                )
        elif self.dwell_fork_steps > 0:
            for p in range(self.poles):
                turns = self.layer_turns_of(p, 0)
                if self.feed_steps_of(turns) > turns * spr:
                    raise JobError(
                        f"reversal_dwell={self.reversal_dwell:g} is invalid with feed_step="
                        f"{self.feed_step:g} m: the feed is the major axis of a layer "
                        f"({self.feed_steps_of(turns)} feed steps against {turns * spr} fork steps); "
                        "a dwell needs the flyer to lead"
                    )

    def _check_wire(self) -> None:
        """The set tension against what the wire takes (JobError, one line)."""
        if self.tension_warning > self.tension_alarm:
            raise JobError(
                f"tension.warning={self.tension_warning:g} is invalid: must be at most tension.alarm="
                f"{self.tension_alarm:g} (the warning band lies inside the alarm band)"
            )
        wire = self.wire
        top = self.tension_limit
        if self.tension_set > top:
            derate = f" x tension.max_share {self.tension_max_share:g}" if self.tension_max_share < 1 else ""
            raise JobError(
                f"tension.set={self.tension_set:g} N is invalid: must be at most the wire's maximum "
                f"{wire.max_tension:.4g} N{derate} (yield {wire.material.yield_stress / 1e6:.4g} MPa x bare "
                f"section {wire.section * 1e6:.4g} mm2)"
            )

    def _check_flyer_clears(self, laid: Winding) -> None:
        """The flyer's nozzle circles outside every layer (JobError, one line)."""
        for i, coil in enumerate(laid.coils):
            top = coil.layers[-1] if coil.layers else None
            contour = self.bobbin.contour(top.radius) if top is not None else None
            if top is not None and contour is not None and contour.h_max >= self.flyer_radius:
                raise JobError(
                    f"flyer_radius={self.flyer_radius:g} m is invalid: coil {i + 1}'s layer {top.number} "
                    f"reaches {contour.h_max:g} m from the flyer's axis; the flyer must circle outside "
                    "the coil"
                )

    def _check_geometry(self) -> None:
        """The bobbin, wire and lay settings together (JobError, one line)."""
        if self.window_width > 0 and self.coil_length > 0 and self.window_width != self.coil_length:
            raise JobError(
                f"coil_length={self.coil_length:g} m is invalid beside bobbin.window_width="
                f"{self.window_width:g} m: coil_length is the deprecated name of bobbin.window_width; "
                "give one"
            )
        if self.bare_diameter > self.wire_diameter:
            raise JobError(
                f"wire.bare_diameter={self.bare_diameter:g} m is invalid: must be at most wire_diameter="
                f"{self.wire_diameter:g} m (the copper is inside the insulation)"
            )
        if self.core == "round" and (self.core_width > 0 or self.core_depth > 0):
            raise JobError(
                "bobbin.core=round is invalid with bobbin.core_width or bobbin.core_depth: a round core "
                "has bobbin.core_diameter; set bobbin.core: rect for a rectangular one"
            )
        if self.core == "rect":
            if self.core_diameter > 0:
                raise JobError(
                    "bobbin.core=rect is invalid with bobbin.core_diameter: a rectangular core has "
                    "bobbin.core_width and bobbin.core_depth"
                )
            if (self.core_width > 0) != (self.core_depth > 0):
                raise JobError(
                    "bobbin.core=rect is invalid with only one of bobbin.core_width and bobbin.core_depth: "
                    "give both (or neither)"
                )
        corner = self.core_corner_radius
        if corner > 0 and self.core != "rect":
            raise JobError(
                f"bobbin.core_corner_radius={corner:g} m is invalid with bobbin.core={self.core}: only a "
                "rectangular core has corners"
            )
        if corner > 0 and not self.core_width > 0:
            raise JobError(
                f"bobbin.core_corner_radius={corner:g} m is invalid without the core's size: give "
                "bobbin.core_width and bobbin.core_depth"
            )
        half = min(self.core_width, self.core_depth) / 2
        if corner > 0 and corner > half:
            raise JobError(
                f"bobbin.core_corner_radius={corner:g} m is invalid: must be at most half the core's smaller "
                f"side, {half:g} m (bobbin.core_width {self.core_width:g} m x bobbin.core_depth "
                f"{self.core_depth:g} m)"
            )
        if self.crossover_at >= 360.0:
            raise JobError(f"lay.crossover_at={self.crossover_at:g} is invalid: must be in [0, 360) deg")

    # -- the wire (winder.motion.material) ------------------------------------
    @property
    def wire(self) -> Wire:
        """The wire: its material's figures, those the job sets in their place."""
        base = MATERIALS[self.material]
        mine = Material(
            base.name,
            self.yield_stress or base.yield_stress,
            self.modulus or base.modulus,
            self.density or base.density,
            self.resistivity or base.resistivity,
            base.hardening,
            max(base.tensile_strength, self.yield_stress),
        )
        return Wire(mine, self.bare_diameter or self.wire_diameter)

    @property
    def tension_limit(self) -> float:
        """The highest tension the job may reach, N: the wire's maximum x ``tension.max_share``."""
        return self.wire.max_tension * self.tension_max_share

    @property
    def set_tension(self) -> float:
        """The set tension, N (``tension.set``, or half the wire's maximum
        tension a job may reach: its maximum x ``tension.max_share``)."""
        return self.tension_set or self.tension_limit / 2

    # -- the coil as laid (winder.motion.coil) ------------------------------
    @property
    def bobbin(self) -> Bobbin:
        return Bobbin(
            self.window_width or self.coil_length,
            self.window_height,
            self.core,
            self.core_diameter,
            self.core_width,
            self.core_depth,
            self.core_corner_radius,
        )

    @property
    def winding(self) -> Winding:
        """Every coil as laid in the bobbin (one per pole)."""
        return self._winding  # type: ignore[attr-defined, no-any-return]

    @property
    def shape(self) -> str:
        """The job in one phrase, as every report names it: "4 poles x 2 layers x 20 turns"."""

        def count(n: int, what: str) -> str:
            return f"{n} {what}" if n == 1 else f"{n} {what}s"

        coils = [
            tuple(self.layer_turns_of(p, k) for k in range(self.coil(p).layers)) for p in range(self.poles)
        ]
        if all(c == (self.layer_turns,) * self.layers for c in coils):
            return " x ".join(
                (count(self.poles, "pole"), count(self.layers, "layer"), count(self.layer_turns, "turn"))
            )
        # layers of different turns (an orthocyclic coil's shifted ones), or coils that differ:
        # the turns as laid, never a product that rounds them ("3 layers x 60 turns" for 179)
        if len(set(coils)) == 1:
            each = coils[0]
            return (
                f"{count(self.poles, 'pole')} x {count(sum(each), 'turn')} in "
                f"{count(len(each), 'layer')} ({', '.join(map(str, each))})"
            )
        turns = sorted(sum(c) for c in coils)
        return f"{count(self.poles, 'pole')} of {turns[0]} to {turns[-1]} turns ({sum(turns)} turns)"

    @property
    def straight_moves(self) -> int:
        """The straight moves (segments' pieces) the job is laid out in, at
        most: counted from its turns before anything is laid out, and
        bounded by :data:`MAX_PIECES`."""
        return self._moves  # type: ignore[attr-defined, no-any-return]

    @property
    def layer_turns(self) -> int:
        """Turns of layer 1 of a coil without overrides (``turns_per_layer``, auto resolved)."""
        return self._base_turns  # type: ignore[attr-defined, no-any-return]

    # -- derived quantities ------------------------------------------------
    @property
    def layer_feed_steps(self) -> int:
        """Feed steps of one layer, rounded to the nearest step, halves up. The
        ratio is nudged by 1e-9 relative so that decimal inputs such as
        99 um / 6 um, which land a hair below .5 in binary, round as written."""
        return self.feed_steps_of(self.layer_turns)

    @property
    def layer_fork_steps(self) -> int:
        return self.layer_turns * self.fork_steps_per_rev

    @property
    def step_lengths(self) -> tuple[float, float, float]:
        """Travel per step of (feed, fork arc at the flyer radius, pole) in m, m, rad."""
        return (
            self.feed_step,
            2 * math.pi * self.flyer_radius / self.fork_steps_per_rev,
            2 * math.pi / self.pole_steps_per_rev,
        )

    @property
    def joint_step(self) -> tuple[float, float, float]:
        """Joint travel per step: feed in m, fork and pole in rad."""
        return (
            self.feed_step,
            2 * math.pi / self.fork_steps_per_rev,
            2 * math.pi / self.pole_steps_per_rev,
        )

    def coil(self, pole: int) -> Coil:
        """How coil ``pole`` (0-based) is wound, its overrides applied."""
        return self._coils[pole]  # type: ignore[attr-defined, no-any-return]

    def turns_of(self, pole: int) -> int:
        """Turns of coil ``pole`` (0-based) over its layers."""
        c = self.coil(pole)
        return c.turns_per_layer * c.layers

    def feed_steps_of(self, turns: int) -> int:
        """Feed steps of a layer of ``turns`` turns (rounded as :attr:`layer_feed_steps`)."""
        exact = turns * self.wire_diameter / self.feed_step
        return math.floor(exact * (1 + 1e-9) + 0.5)

    def pole_position(self, pole: int) -> int:
        """Pole-axis step position of coil ``pole`` (cumulative rounding: the
        last index lands exactly on a full revolution)."""
        return round(pole * self.pole_steps_per_rev / self.poles)

    def segments(self) -> tuple[Segment, ...]:
        """The ordered moves of the job, in steps: per coil its layers (each a
        straight line, or a cam of the flyer: :meth:`layer_cam`), and the
        pole index between coils. Laid out once per job (a job does not
        change): every call returns the same tuple."""
        return self._laid_out

    @functools.cached_property
    def _laid_out(self) -> tuple[Segment, ...]:
        # a frozen dataclass: cached_property stores in the instance's
        # __dict__ past the frozen __setattr__; not a field, so neither
        # compared, hashed nor copied by dataclasses.replace
        return tuple(self._lay_out())

    def _lay_out(self) -> list[Segment]:
        out: list[Segment] = []
        pos = [0, 0, 0]
        direction = 1
        for pole in range(self.poles):
            if pole > 0:
                delta = (0, 0, self.pole_position(pole) - self.pole_position(pole - 1))
                out.append(Segment(len(out), SegmentKind.INDEX, tuple(pos), delta, pole, -1))  # type: ignore[arg-type]
                pos[POLE.index] += delta[POLE.index]
            coil = self.coil(pole)
            origin, first = pos[0], direction
            before = 0  # turns of this coil laid before the layer
            for layer in range(coil.layers):
                cam = self.layer_cam(pole, layer, origin, first, pos[0])
                net = (sum(p[0] for p in cam), sum(p[1] for p in cam), 0)
                begin = (pos[0], pos[1], pos[2])
                turns = self.layer_turns_of(pole, layer)
                out.append(
                    Segment(
                        len(out),
                        SegmentKind.LAYER,
                        begin,
                        net,
                        pole,
                        layer,
                        cam if len(cam) > 1 else (),
                        turns=turns,
                        first_turn=before,
                        turn_steps=self.fork_steps_per_rev,
                    )
                )
                before += turns
                delta = net
                pos[FEED.index] += delta[FEED.index]
                pos[FORK.index] += delta[FORK.index]
                direction = -direction
        return out

    def layer_turns_of(self, pole: int, layer: int) -> int:
        """Turns of layer ``layer`` (0-based) of coil ``pole`` (0-based): on an
        orthocyclic coil wound ``auto`` the shifted layers may hold one less."""
        geometry = self.winding.coils[pole].layers
        return geometry[layer].turns if layer < len(geometry) else self.coil(pole).turns_per_layer

    @property
    def dwell_fork_steps(self) -> int:
        """Fork steps of the reversal dwell at the end of each layer."""
        return math.floor(self.reversal_dwell * self.fork_steps_per_rev + 0.5)

    def turn_place(self, layer: int, k: int) -> int:
        """Orthocyclic: the feed position (steps from the coil's first turn,
        along the coil's first direction) of turn ``k`` (0-based, counted
        from the start flange) of layer ``layer`` (0-based): the odd layers
        (1, 3, ...) at ``k*d``, the shifted even ones at ``(k + 1/2)*d``;
        rounded to the nearest step as :meth:`feed_steps_of`."""
        halves = 2 * k + (layer % 2)
        return math.floor(halves * self.wire_diameter / (2 * self.feed_step) * (1 + 1e-9) + 0.5)

    def layer_cam(
        self, pole: int, layer: int, origin: int, first: int, at: int
    ) -> tuple[tuple[int, int, int], ...]:
        """The straight pieces (feed, fork, pole deltas, steps) of layer
        ``layer`` of coil ``pole``, whose first layer starts at feed
        ``origin`` going ``first`` (+1/-1); the layer starts at feed ``at``.

        * helical: the line of ``turns`` turns, one wire diameter on per
          turn, then ``reversal_dwell`` turns of the flyer in place;
        * orthocyclic, a cam of the flyer angle: the feed holds each turn
          at its place (:meth:`turn_place`) and crosses over to the next within
          the zone ``[crossover_at, crossover_at + crossover)`` of each turn
          (degrees of the flyer, from the layer's start, whole turns of the
          flyer from the coil's start); the last turn holds for the
          reversal dwell, and in the last zone of the layer the wire climbs to
          the next layer's first turn (half a wire diameter on or back). The
          fork is the major axis of every piece (:meth:`_check_cam`)."""
        coil = self.coil(pole)
        turns = self.layer_turns_of(pole, layer)
        spr = self.fork_steps_per_rev
        dwell = self.dwell_fork_steps
        sgn = coil.direction
        going = first if layer % 2 == 0 else -first  # this layer's feed direction
        if self.lay != "orthocyclic":
            line = (going * self.feed_steps_of(turns), sgn * turns * spr, 0)
            return (line, (0, sgn * dwell, 0)) if dwell else (line,)
        if turns < 1:  # no turn fits the layer (a job built with check_fit=False): it cannot be laid
            raise JobError(self.winding.overflow() or f"layer {layer + 1} of coil {pole + 1} holds no turn")
        # the places of this layer's turns in the order the flyer lays them
        order = range(turns) if layer % 2 == 0 else range(turns - 1, -1, -1)
        places = [origin + first * self.turn_place(layer, k) for k in order]
        if layer + 1 < coil.layers:
            nxt = self.layer_turns_of(pole, layer + 1)
            k_next = 0 if (layer + 1) % 2 == 0 else nxt - 1
            climb_to: int | None = origin + first * self.turn_place(layer + 1, k_next)
        else:
            climb_to = None
        za, zc = self.crossover_zone
        end = turns * spr + dwell
        pieces: list[tuple[int, int]] = []  # (feed, fork progress), merged below
        feed, fork = at, 0

        def go(to_feed: int, to_fork: int) -> None:
            nonlocal feed, fork
            if to_fork > fork or to_feed != feed:
                pieces.append((to_feed - feed, to_fork - fork))
                feed, fork = to_feed, to_fork

        if places[0] != at:  # never: a layer starts where the last one climbed to
            raise JobError(f"layer {layer + 1} of coil {pole + 1} starts off its first turn's place")

        def cross(to_feed: int, zone_at: int) -> None:  # the crossover: the cam law over the zone
            go(feed, zone_at)
            for df, dk in crossover_cam(to_feed - feed, zc, self.crossover_law):
                go(feed + df, fork + dk)

        for r in range(turns - 1):
            cross(places[r + 1], r * spr + za)
        if climb_to is not None:
            cross(climb_to, (end - za - zc) // spr * spr + za)  # the last zone that ends within the layer
        go(feed, end)
        merged: list[tuple[int, int]] = []
        for df, dk in pieces:  # holds side by side are one hold
            if merged and df == 0 and merged[-1][0] == 0:
                merged[-1] = (0, merged[-1][1] + dk)
            else:
                merged.append((df, dk))
        return tuple((df, sgn * dk, 0) for df, dk in merged)

    @property
    def crossover_zone(self) -> tuple[int, int]:
        """Orthocyclic: where the crossover zone starts in each turn and how
        long it is, in fork steps (rounded to the nearest step; at least one)."""
        spr = self.fork_steps_per_rev
        start = math.floor(self.crossover_at / 360.0 * spr + 0.5)
        return start, max(1, math.floor(self.crossover / 360.0 * spr + 0.5))

    def segment_speed(self, segment: Segment) -> float:
        """The fraction of ``v_max`` a segment runs at: its layer's (:meth:`layer_share`); 1 off a layer."""
        return self.layer_share(segment.pole, segment.layer) if segment.kind.winds else 1.0

    def segment_pace(self, segment: Segment) -> float:
        """How much a segment is slowed down in time: its layer's
        ``layer_speed`` share (its ramp's acceleration x share**2, jerk x
        share**3: :func:`winder.motion.timing.plan_segment`); 1 elsewhere."""
        return self.layer_speeds.get((segment.pole, segment.layer), 1.0) if segment.kind.winds else 1.0

    def layer_share(self, pole: int, layer: int) -> float:
        """The fraction of ``v_max`` layer ``layer`` of coil ``pole`` (from 0)
        is wound at: ``first_layer_speed`` on the first layer of every coil,
        times its ``layer_speed`` share where it has one."""
        first = self.first_layer_speed if layer == 0 else 1.0
        return first * self.layer_speeds.get((pole, layer), 1.0)

    @functools.cached_property
    def layer_speeds(self) -> dict[tuple[int, int], float]:
        """``layer_speed`` parsed: ``(pole, layer)`` from 0 -> share of ``v_max``."""
        return parse_layer_speeds(self.layer_speed, [len(c.layers) for c in self.winding.coils])

    @functools.cached_property
    def total_steps(self) -> int:
        """Steps of the whole job (its segments' steps), counted once."""
        return sum(s.steps for s in self.segments())

    def to_dict(self) -> dict[str, Any]:
        """The job's settings by their names (``bobbin.window_width``)."""
        return {SETTINGS[f.name]: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_dict(cls, values: Mapping[str, Any], *, check_fit: bool = True) -> Job:
        """The job of the settings ``values`` (by their names; the others at
        their defaults)."""
        unknown = sorted(set(values) - set(FIELD_SPECS))
        if unknown:
            raise JobError(f"unknown job field {unknown[0]!r}: known fields are {', '.join(FIELD_SPECS)}")
        return cls(**{ATTRIBUTES[k]: v for k, v in values.items()}, check_fit=check_fit)


def check_field(name: str, value: Any) -> Any:
    """Validate one job field; return it converted to its type or raise JobError."""
    spec = FIELD_SPECS.get(name)
    if spec is None:
        raise JobError(f"unknown job field {name!r}: known fields are {', '.join(FIELD_SPECS)}")
    try:
        return spec.check(value)
    except SpecError as exc:
        raise JobError(str(exc)) from None
