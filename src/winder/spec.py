"""Typed, ranged settings: one definition serves the job, the CLI options, the
ROS parameter descriptors and the checks, so a value is validated in one place
and every rejection reads the same: ``name=value is invalid: must be ...``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from winder.errors import BadInputError

__all__ = ["Spec", "SpecError", "interval", "shorten"]


def shorten(text: str, keep: int = 60) -> str:
    """``text`` as a message quotes it: its repr, or, when longer than
    ``keep`` characters, its first ``keep`` and last 8 characters around
    "..." and its length (``'/xxxx...xxxx' (301 characters)``), so that a
    refusal stays one readable line whatever was typed."""
    if len(text) <= keep + 12:
        return repr(text)
    return f"{text[:keep] + '...' + text[-8:]!r} ({len(text)} characters)"


class SpecError(BadInputError):
    """A setting is out of range; the message names it, its value and the range."""


def interval(low: float, high: float, *, low_open: bool = False, high_open: bool = False) -> str:
    """A range as every message writes it: ``[0.05, 2]``, ``(0, 1e+07]``, ``[0, 1)``.
    A range kept as a constant is written from it, never retyped."""
    return f"{'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"


@dataclass(frozen=True)
class Spec:
    """One setting: type (bool, int, float or str), default, range or choices."""

    name: str
    kind: type
    default: Any
    description: str
    unit: str = ""
    low: float | None = None
    high: float | None = None
    low_open: bool = False  #: the low bound itself is not allowed
    choices: Sequence[str] = ()
    pattern: str = ""  #: regular expression a string must match
    pattern_text: str = ""  #: how to say the pattern to a person

    def range_text(self) -> str:
        if self.choices:
            return "one of " + ", ".join(self.choices)
        if self.pattern_text:
            return self.pattern_text
        if self.low is None or self.high is None:
            return "a " + self.kind.__name__
        lo = "(" if self.low_open else "["
        unit = f" {self.unit}" if self.unit else ""
        if self.kind is int:
            return f"{lo}{int(self.low)}, {int(self.high)}]{unit}"
        return interval(self.low, self.high, low_open=self.low_open) + unit

    def help(self) -> str:
        return f"{self.description}; {self.range_text()}; default {self.default!r}"

    def check(self, value: Any) -> Any:
        """``value`` converted to this setting's type, or SpecError."""
        name = self.name
        if self.kind is bool:
            if not isinstance(value, (bool, np.bool_)):
                raise SpecError(f"{name}={value!r} is invalid: must be true or false")
            return bool(value)
        if self.kind is str:
            if not isinstance(value, str):
                raise SpecError(f"{name}={value!r} is invalid: must be a string, {self.range_text()}")
            if self.choices and value not in self.choices:
                raise SpecError(f"{name}={shorten(value)} is invalid: must be {self.range_text()}")
            if self.pattern and not re.fullmatch(self.pattern, value):
                raise SpecError(f"{name}={shorten(value)} is invalid: must be {self.pattern_text}")
            return value
        if self.kind is int:
            if isinstance(value, (float, np.floating)) and math.isfinite(value) and float(value).is_integer():
                value = int(value)
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
                raise SpecError(f"{name}={value!r} is invalid: must be an integer in {self.range_text()}")
            v: float = int(value)
        else:
            if isinstance(value, (bool, np.bool_)) or not isinstance(
                value, (int, float, np.integer, np.floating)
            ):
                raise SpecError(f"{name}={value!r} is invalid: must be a number in {self.range_text()}")
            v = float(value)
            if not math.isfinite(v):
                raise SpecError(f"{name}={v!r} is invalid: must be a finite number in {self.range_text()}")
        if self.low is not None and (v <= self.low if self.low_open else v < self.low):
            raise SpecError(f"{name}={value!r} is invalid: must be in {self.range_text()}")
        if self.high is not None and v > self.high:
            raise SpecError(f"{name}={value!r} is invalid: must be in {self.range_text()}")
        return v

    def parse(self, text: str) -> Any:
        """A value typed on a command line, converted and checked."""
        if self.kind is str:
            return self.check(text)
        if self.kind is bool:
            low = text.strip().lower()
            if low in ("true", "1", "yes", "on"):
                return True
            if low in ("false", "0", "no", "off"):
                return False
            raise SpecError(f"{self.name}={text!r} is invalid: must be true or false")
        try:
            value: Any = int(text) if self.kind is int else float(text)
        except ValueError:
            word = "an integer" if self.kind is int else "a number"
            raise SpecError(
                f"{self.name}={text!r} is invalid: must be {word} in {self.range_text()}"
            ) from None
        return self.check(value)


def check_all(specs: dict[str, Spec], values: dict[str, Any]) -> dict[str, Any]:
    """Every value checked by its spec; unknown names rejected."""
    out = {}
    for name, value in values.items():
        spec = specs.get(name)
        if spec is None:
            raise SpecError(f"unknown setting {name!r}: known are {', '.join(specs)}")
        out[name] = spec.check(value)
    return out
