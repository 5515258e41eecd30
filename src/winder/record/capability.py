"""Machine capability of a recipe's parts: Cm and Cmk per recorded scalar, ROS-free.

ISO 22514-3 (machine performance studies) judges a machine by parts it
wound one after another to one recipe, without adjustment between them: for
each characteristic, the sample mean x̄ and standard deviation s (n - 1 in
the denominator) of n such parts, and against the tolerance's limits LSL and
USL::

    Cm  = (USL - LSL) / (6 s)
    Cmk = min(USL - x̄, x̄ - LSL) / (3 s)

(the standard's quantile form with a normal distribution, whose 0.135 % and
99.865 % quantiles lie 3 s either side of the mean). A one-sided tolerance
(one limit ``None``) has no Cm and a Cmk of its one side. A study commonly
takes 50 parts (:data:`STUDY_PARTS`, the standard's recommendation); below
:data:`MIN_PARTS` no figure is given here.

The series come from the part index's rows (:func:`series`): every scalar a
tolerance may name (:func:`winder.record.parts.part_scalars`) but those the
recipe or the run's bookkeeping fixes (:data:`NOT_CHARACTERISTICS`), and a
resistance only where it was measured: a prediction is the same for every
part of a recipe, no sample of the machine's spread.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from winder.record.parts import COLUMNS, FROM_REPORT, part_scalars

__all__ = [
    "MIN_PARTS",
    "NOT_CHARACTERISTICS",
    "STUDY_PARTS",
    "Capability",
    "capability",
    "mean_sd",
    "series",
    "unit_of",
]

#: the fewest parts a capability is given for (issue 56's floor)
MIN_PARTS = 30
#: the parts a study takes unless told: the latest 50, what ISO 22514-3 recommends
STUDY_PARTS = 50

#: scalars of a part's record that are not the part's characteristics: fixed by
#: the recipe, the run's clock or the host, or another name's copy
NOT_CHARACTERISTICS = frozenset(
    {
        "started_ns",
        "ended_ns",
        "steps_total",
        "turns_commanded",
        "resistance_predicted_ohm",
        "resistance_measured_ohm",  # as resistance_ohm
        "path_tolerance_m",  # a setting of the run
        "progress",  # steps_done / steps_total
        "simulated",
        "pid",
        *FROM_REPORT.values(),  # the report's names of columns
    }
)
#: the columns of the part index that :func:`series` reads: the report and every number
READS = ("report", *(name for name, kind, _ in COLUMNS if kind.startswith(("REAL", "INTEGER"))))


#: a scalar's unit by how its name ends or begins (the index's and the final report's naming)
UNIT_SUFFIXES = (("_ohm", "Ω"), ("_n", "N"), ("_s", "s"), ("_m", "m"), ("_steps", "steps"))
UNIT_PREFIXES = (("steps_", "steps"), ("turns_", "turns"))
#: scalars that count events
COUNTS = frozenset({"breaks", "slips", "errors", "gaps", "stalls", "chunks_rejected"})


def unit_of(name: str) -> str:
    """The unit of scalar ``name`` as a chart's axis shows it ("" if its name does not say)."""
    for suffix, unit in UNIT_SUFFIXES:
        if name.endswith(suffix):
            return unit
    for prefix, unit in UNIT_PREFIXES:
        if name.startswith(prefix):
            return unit
    return "count" if name in COUNTS else ""


@dataclass(frozen=True)
class Capability:
    """One scalar's figures over a recipe's parts; None where there is none
    (``note`` says why)."""

    name: str
    n: int
    mean: float | None
    sd: float | None
    lsl: float | None
    usl: float | None
    cm: float | None
    cmk: float | None
    note: str = ""

    def to_json(self) -> dict[str, Any]:
        return {
            "n": self.n,
            "mean": self.mean,
            "sd": self.sd,
            "lsl": self.lsl,
            "usl": self.usl,
            "cm": self.cm,
            "cmk": self.cmk,
            "note": self.note,
        }


def mean_sd(values: Sequence[float]) -> tuple[float, float | None]:
    """The mean and the sample standard deviation (n - 1; None below 2 values)
    of ``values``, to a few units in the last place however far the values lie
    from zero: the mean from their correctly rounded sum, the deviations from
    it summed in squares the same way, less the square of their own sum over n
    (what the mean's rounding left: the corrected two-pass formula)."""
    n = len(values)
    if n == 0:
        raise ValueError("mean_sd of no values")
    low, high = min(values), max(values)
    if low == high:
        return float(low), (0.0 if n > 1 else None)
    mean = math.fsum(values) / n
    mean = min(max(mean, low), high)  # the rounding of a sum of n values may not leave their range
    if n < 2:
        return mean, None
    deviations = [x - mean for x in values]
    left = math.fsum(deviations)
    squares = math.fsum(d * d for d in deviations) - left * left / n
    return mean, math.sqrt(max(squares, 0.0) / (n - 1))


def capability(
    name: str,
    values: Sequence[float],
    lsl: float | None,
    usl: float | None,
    min_parts: int = MIN_PARTS,
) -> Capability:
    """``name``'s Cm and Cmk (module doc) over ``values`` against ``[lsl, usl]``
    (None: no limit on that side, or no tolerance at all)."""
    n = len(values)
    if n == 0:
        return Capability(name, 0, None, None, lsl, usl, None, None, "not recorded")
    mean, sd = mean_sd(values)
    notes: list[str] = []
    if lsl is None and usl is None:
        notes.append("no tolerance")
    elif n < min_parts:
        notes.append(f"{n} values, fewer than {min_parts}")
    elif sd is None or sd == 0.0:
        notes.append("no spread: every value the same")
    if notes:
        return Capability(name, n, mean, sd, lsl, usl, None, None, notes[0])
    assert sd is not None
    cm = None if lsl is None or usl is None else (usl - lsl) / (6.0 * sd)
    sides = [
        s
        for s in ((None if usl is None else usl - mean), (None if lsl is None else mean - lsl))
        if s is not None
    ]
    cmk = min(sides) / (3.0 * sd)
    note = "" if cm is not None else f"one-sided: Cmk of the {'upper' if lsl is None else 'lower'} limit only"
    return Capability(name, n, mean, sd, lsl, usl, cm, cmk, note)


def series(rows: Iterable[Mapping[str, Any]]) -> dict[str, list[float | None]]:
    """Each characteristic's value in every row, in the rows' order (None:
    that part did not record it): the scalars a tolerance names
    (:func:`winder.record.parts.part_scalars`) but :data:`NOT_CHARACTERISTICS`,
    ``resistance_ohm`` measured only. A scalar no row recorded is left out."""
    out: dict[str, list[float | None]] = {}
    count = 0
    for row in rows:
        scalars, _ = part_scalars(row)
        scalars["resistance_ohm"] = row.get("resistance_measured_ohm")
        for name, value in scalars.items():
            if name in NOT_CHARACTERISTICS:
                continue
            column = out.get(name)
            if column is None:
                column = out[name] = [None] * count
            column.append(None if value is None else float(value))
        count += 1
        for column in out.values():
            if len(column) < count:  # not in this row
                column.append(None)
    return {name: column for name, column in out.items() if any(v is not None for v in column)}
