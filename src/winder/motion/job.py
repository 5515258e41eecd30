"""Winding jobs: what an operator sets, validated, expanded into straight segments.

A job winds ``poles`` coils. Each coil is ``layers`` layers of
``turns_per_layer`` turns; during a layer the flyer (fork) turns once per turn
while the feed axis advances the rotor one wire diameter per turn, reversing at
every layer. Between coils the pole axis indexes the rotor by 360 deg / poles.
``coil_overrides`` changes single coils: ``"2:turns_per_layer=30;3:direction=ccw,layers=1"``
(coils counted from 1; ``direction`` cw, the fork turning forward as for every
other coil, or ccw, backward: the winding direction).

Axes, in this order everywhere in winder (``AXES``):

* ``feed`` - linear, ``feed_step`` metres per step;
* ``fork`` - rotary, ``fork_steps_per_rev`` steps per revolution;
* ``pole`` - rotary, ``pole_steps_per_rev`` steps per revolution.

Units are SI (metres, radians). Unrolled, a layer is the straight line from its
start to (feed distance, flyer arc length) in the plane: the segment that
:func:`winder.motion.interp.interpolate` walks.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any

from winder.spec import Spec, SpecError

__all__ = ["AXES", "FIELD_SPECS", "Coil", "Job", "JobError", "Segment", "parse_coil_overrides"]

AXES = ("feed", "fork", "pole")
#: Steps of one axis in one segment, at most: positions travel as int32.
MAX_STEPS = 2**31 - 1


class JobError(SpecError):
    """A job field is out of range; the message names field, value and range."""


def _f(
    name: str, low: float, high: float, unit: str, text: str, default: float, *, open_low: bool = True
) -> Spec:
    return Spec(name, float, default, text, unit, low, high, low_open=open_low)


def _i(name: str, low: int, high: int, text: str, default: int) -> Spec:
    return Spec(name, int, default, text, "", low, high)


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
        _i("turns_per_layer", 1, 100_000, "turns in one layer", 20),
        _i("layers", 1, 1_000, "layers per coil; the feed reverses at each layer", 2),
        _i("poles", 1, 360, "coils (poles); the pole axis indexes 360/poles deg between them", 4),
        _i("fork_steps_per_rev", 4, 2**24, "fork axis steps per revolution", 1024),
        _f("feed_step", 0.0, 1e-3, "m", "feed axis travel per step", 1e-5),
        _i("pole_steps_per_rev", 4, 2**24, "pole axis steps per revolution", 1024),
        _f("coil_length", 0.0, 10.0, "m", "axial room for one layer (0 = unchecked)", 0.0, open_low=False),
        Spec(
            "coil_overrides",
            str,
            "",
            "single coils that differ from the others: COIL:KEY=VALUE[,KEY=VALUE] separated by ';', "
            "KEY turns_per_layer, layers or direction (cw|ccw)",
            pattern=r"[0-9A-Za-z_:=,;\s]*",
            pattern_text='e.g. "2:turns_per_layer=30;3:direction=ccw,layers=1", or empty',
        ),
    )
}

#: what a coil override may set: the field's spec (direction: cw or ccw)
COIL_KEYS = ("turns_per_layer", "layers", "direction")


@dataclass(frozen=True)
class Coil:
    """How one coil is wound: its turns per layer, layers and direction (+1 cw, -1 ccw)."""

    turns_per_layer: int
    layers: int
    direction: int


def parse_coil_overrides(text: str, poles: int, base: Coil) -> dict[int, Coil]:
    """The coils ``text`` changes (0-based pole index -> Coil); JobError (one
    line) naming the item, the key and the allowed range."""
    out: dict[int, Coil] = {}
    for item in (t.strip() for t in text.split(";") if t.strip()):
        head, _, body = item.partition(":")
        try:
            coil = int(head)
        except ValueError:
            raise JobError(f"coil_overrides: {item!r} must be COIL:KEY=VALUE[,KEY=VALUE]") from None
        if not 1 <= coil <= poles:
            raise JobError(f"coil_overrides: coil {coil} is not in [1, {poles}] (poles)")
        values = {"turns_per_layer": base.turns_per_layer, "layers": base.layers, "direction": base.direction}
        for pair in (p.strip() for p in body.split(",") if p.strip()):
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
                    values[key] = FIELD_SPECS[key].parse(value)
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


@dataclass(frozen=True)
class Segment:
    """One straight move in steps: ``start`` + ``delta`` per axis (AXES order)."""

    index: int
    kind: str  #: "layer" (feed + fork) or "index" (pole)
    start: tuple[int, int, int]
    delta: tuple[int, int, int]
    pole: int  #: coil being wound (or indexed to)
    layer: int  #: layer within the coil (-1 for an index move)

    @property
    def end(self) -> tuple[int, int, int]:
        return tuple(s + d for s, d in zip(self.start, self.delta, strict=True))  # type: ignore[return-value]

    @property
    def steps(self) -> int:
        """Number of interpolation steps: the major axis' step count."""
        return max(abs(d) for d in self.delta)


@dataclass(frozen=True)
class Job:
    """A winding job. Defaults: the RW400 set-up of the 2016 paper (flyer radius
    500 mm, wire 2.50 mm, fork register 2**10), four poles of two layers."""

    job_id: str = FIELD_SPECS["job_id"].default
    wire_diameter: float = FIELD_SPECS["wire_diameter"].default
    flyer_radius: float = FIELD_SPECS["flyer_radius"].default
    turns_per_layer: int = FIELD_SPECS["turns_per_layer"].default
    layers: int = FIELD_SPECS["layers"].default
    poles: int = FIELD_SPECS["poles"].default
    fork_steps_per_rev: int = FIELD_SPECS["fork_steps_per_rev"].default
    feed_step: float = FIELD_SPECS["feed_step"].default
    pole_steps_per_rev: int = FIELD_SPECS["pole_steps_per_rev"].default
    coil_length: float = FIELD_SPECS["coil_length"].default
    coil_overrides: str = FIELD_SPECS["coil_overrides"].default

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, check_field(f.name, getattr(self, f.name)))
        base = Coil(self.turns_per_layer, self.layers, 1)
        coils = parse_coil_overrides(self.coil_overrides, self.poles, base)
        wound = tuple(coils.get(p, base) for p in range(self.poles))
        object.__setattr__(self, "_coils", wound)
        for p, c in enumerate(wound):
            if c != base:  # each coil's layers checked as the common one is below
                try:
                    replace(self, turns_per_layer=c.turns_per_layer, layers=c.layers, coil_overrides="")
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
        if self.coil_length > 0 and self.turns_per_layer * self.wire_diameter > self.coil_length:
            raise JobError(
                f"turns_per_layer={self.turns_per_layer} is invalid: "
                f"{self.turns_per_layer} turns of {self.wire_diameter:g} m wire need "
                f"{self.turns_per_layer * self.wire_diameter:g} m, coil_length is "
                f"{self.coil_length:g} m (at most {int(self.coil_length / self.wire_diameter)} turns fit)"
            )
        layer_length = self.turns_per_layer * self.wire_diameter
        feed_steps = layer_length / self.feed_step
        if not feed_steps < MAX_STEPS:  # also inf: a tiny feed_step overflows the ratio
            raise JobError(
                f"feed_step={self.feed_step:g} m is invalid with turns_per_layer={self.turns_per_layer} of "
                f"{self.wire_diameter:g} m wire: a layer would take {feed_steps:.3g} feed steps, "
                f"more than 2**31 - 1 (feed_step must be at least {layer_length / MAX_STEPS:.3g} m)"
            )
        if self.layer_fork_steps > 2**31 - 1:
            raise JobError(
                f"turns_per_layer={self.turns_per_layer} is invalid: a layer of "
                f"{self.layer_fork_steps} fork steps exceeds 2**31 - 1 steps"
            )

    # -- derived quantities ------------------------------------------------
    @property
    def layer_feed_steps(self) -> int:
        """Feed steps of one layer, rounded to the nearest step, halves up. The
        ratio is nudged by 1e-9 relative so that decimal inputs such as
        99 um / 6 um, which land a hair below .5 in binary, round as written."""
        return self.feed_steps_of(self.turns_per_layer)

    @property
    def layer_fork_steps(self) -> int:
        return self.turns_per_layer * self.fork_steps_per_rev

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

    def segments(self) -> list[Segment]:
        """The ordered straight moves of the job, in steps."""
        out: list[Segment] = []
        pos = [0, 0, 0]
        direction = 1
        for pole in range(self.poles):
            if pole > 0:
                delta = (0, 0, self.pole_position(pole) - self.pole_position(pole - 1))
                out.append(Segment(len(out), "index", tuple(pos), delta, pole, -1))  # type: ignore[arg-type]
                pos[2] += delta[2]
            coil = self.coil(pole)
            fork = coil.direction * coil.turns_per_layer * self.fork_steps_per_rev
            for layer in range(coil.layers):
                delta = (direction * self.feed_steps_of(coil.turns_per_layer), fork, 0)
                out.append(Segment(len(out), "layer", tuple(pos), delta, pole, layer))  # type: ignore[arg-type]
                pos[0] += delta[0]
                pos[1] += delta[1]
                direction = -direction
        return out

    @property
    def total_steps(self) -> int:
        return sum(s.steps for s in self.segments())

    def to_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> Job:
        unknown = sorted(set(values) - set(FIELD_SPECS))
        if unknown:
            raise JobError(f"unknown job field {unknown[0]!r}: known fields are {', '.join(FIELD_SPECS)}")
        return cls(**values)


def check_field(name: str, value: Any) -> Any:
    """Validate one job field; return it converted to its type or raise JobError."""
    spec = FIELD_SPECS.get(name)
    if spec is None:
        raise JobError(f"unknown job field {name!r}: known fields are {', '.join(FIELD_SPECS)}")
    try:
        return spec.check(value)
    except SpecError as exc:
        raise JobError(str(exc)) from None
