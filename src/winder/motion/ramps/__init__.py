"""The ramps, one module each, found by name.

Every module here whose name does not start with ``_`` (``base`` aside)
defines ``RAMP``, an object of the :class:`~winder.motion.ramps.base.Ramp`
protocol: its name and limits, its planner, its time-optimal stop and its
continuation; where its phases are not polynomial, it registers its phase
law (:data:`~winder.motion.ramps.base.LAWS`). Today: :mod:`.scurve`,
:mod:`.trapezoid`, :mod:`.exponential` and :mod:`.jog` (velocity mode).
A new ramp is one more module (and its oracle test); :data:`LIMITS`, the node
settings, ``winder run`` and the analysis follow from the registry.
"""

from __future__ import annotations

import importlib
import pkgutil

from winder.errors import BadInputError
from winder.motion.ramps import _poly
from winder.motion.ramps.base import EXP_CUT, MOVES, RAMPS, Phase, Profile, Ramp, Seg, plan, register

__all__ = ["EXP_CUT", "KINDS", "LIMITS", "MOVES", "RAMPS", "Phase", "Profile", "Ramp", "Seg", "plan", "ramp"]

assert _poly.LAW  # the polynomial law is registered before any ramp


def _load() -> None:
    found: list[Ramp] = []
    for info in pkgutil.iter_modules(__path__):
        if info.name.startswith("_") or info.name == "base":
            continue
        found.append(importlib.import_module(f"{__name__}.{info.name}").RAMP)
    for r in sorted(found, key=lambda r: r.rank):
        register(r)


_load()

LIMITS: dict[str, tuple[str, ...]] = {name: r.limits for name, r in MOVES.items()}
"""The point-to-point ramp kinds and the limits each one uses (its :func:`plan`
keywords beside the distance and the speeds)."""
KINDS = tuple(LIMITS)


def ramp(kind: str) -> Ramp:
    """The ramp named ``kind``."""
    try:
        return RAMPS[kind]
    except KeyError:
        raise BadInputError(
            f"kind={kind!r} is invalid: must be one of {', '.join(map(repr, RAMPS))}"
        ) from None
