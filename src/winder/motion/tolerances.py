"""A recipe's tolerances and a part's verdict against them, ROS-free.

A job file's ``tolerances:`` section names a part's recorded scalars and the
range each must lie in (both ends included)::

    tolerances:
      resistance_ohm: [11.5, 12.5]
      tension_max_n: [-.inf, 3.0]   # one-sided: no lower limit
      turns_error: [0, 0]

An open end, ``-.inf`` below or ``.inf`` above (what ROS reads as the
infinities; ``null`` in the JSON text, which has none), is no limit on that
side: a one-sided tolerance, as an upper specification limit alone; never
both ends.

In the job they are one field, ``tolerances``, the map's JSON text
(``'{"resistance_ohm": [11.5, 12.5]}'``, what ``ros2 param set`` and
``--params-file`` give); a job file may write the map itself, as above.
A name is any scalar of the part's record (:mod:`winder.record.parts`): a
column (``resistance_ohm``: the measured resistance once entered, the
predicted one before; ``tension_max_n``; ``turns_error``: turns counted
minus commanded; ``cycle_time_s``; ...) or a numeric key of the run's final
report by its name (``max_tracking_error_steps``). :func:`check_tolerances`
refuses a malformed section in one line naming the key, the value and what
is allowed; :func:`verdict` is the part's verdict: ``ok`` when the run
completed and every tolerance holds, ``nok`` with every reason otherwise (a
scalar the run did not record is a reason too: a tolerance that cannot be
checked is not met). A recipe without tolerances: ``ok`` iff the run completed.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping

from winder.spec import SpecError

__all__ = [
    "NOK",
    "OK",
    "Tolerances",
    "check_tolerances",
    "parse_tolerances",
    "tolerance_text",
    "tolerances_text",
    "verdict",
    "within",
]

OK, NOK = "ok", "nok"
#: a tolerance's name: a scalar's name as the record and the report spell them
NAME = re.compile(r"^[a-z][a-z0-9_]{0,63}$")
#: tolerances by name: (lowest, highest) allowed, both included; None: no limit on that side
Tolerances = dict[str, tuple[float | None, float | None]]


def _number(value: object) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    number = float(value)
    return number if math.isfinite(number) else None


def _end(value: object, open_value: float) -> float | bool | None:
    """A tolerance's end: a finite number; None (no limit) for null or the
    infinity on its side (``open_value``: -inf for the lower end); False for anything else."""
    if value is None:
        return None
    if isinstance(value, float) and value == open_value:
        return None
    number = _number(value)
    return False if number is None else number


def check_tolerances(doc: object, where: str = "tolerances") -> Tolerances:
    """The tolerances of a ``tolerances:`` map (``{name: [min, max]}``),
    checked; :class:`SpecError` in one line (``where`` names the section)
    for anything else."""
    if doc is None:
        return {}
    if not isinstance(doc, Mapping):
        raise SpecError(f"{where} is {json.dumps(doc, default=str)[:60]}: expected a map of name: [min, max]")
    out: Tolerances = {}
    for key, value in doc.items():
        if not isinstance(key, str) or not NAME.match(key):
            raise SpecError(
                f"{where}.{key} is not a scalar's name: expected lower case letters, digits and _ "
                "(a part's field or a final report's key)"
            )
        pair = list(value) if isinstance(value, (list, tuple)) else None
        low, high = (
            (_end(pair[0], -math.inf), _end(pair[1], math.inf))
            if pair is not None and len(pair) == 2
            else (False, False)
        )
        if (
            low is False
            or high is False
            or (low is None and high is None)
            or (low is not None and high is not None and low > high)
        ):
            shown = json.dumps(value, default=str)[:60]
            raise SpecError(
                f"{where}.{key}={shown} is invalid: expected [min, max], two finite numbers with min <= max, "
                "or one end open (null, or -.inf / .inf on its side) for no limit there"
            )
        out[key] = (low, high)
    return out


def parse_tolerances(value: object, where: str = "tolerances") -> Tolerances:
    """The tolerances of the job field: its JSON text ("" none), or the map itself."""
    if isinstance(value, str):
        if not value.strip():
            return {}
        try:
            value = json.loads(value)
        except (json.JSONDecodeError, RecursionError) as exc:
            raise SpecError(
                f"{where}={json.dumps(value)[:60]} is invalid: not a JSON map of name: [min, max] "
                f"({str(exc).splitlines()[0]})"
            ) from None
    return check_tolerances(value, where)


def tolerances_text(tolerances: Mapping[str, tuple[float | None, float | None]]) -> str:
    """The job field's canonical text of ``tolerances`` ("" for none): compact JSON, in their order."""
    if not tolerances:
        return ""
    return json.dumps({k: [lo, hi] for k, (lo, hi) in tolerances.items()}, separators=(",", ":"))


def tolerance_text(low: float | None, high: float | None) -> str:
    """A tolerance as a reason shows it: ``[11.5, 12.5]``; one-sided ``(-inf, 3]``, ``[0, inf)``."""
    return ("(-inf" if low is None else f"[{low:g}") + ", " + ("inf)" if high is None else f"{high:g}]")


def within(value: float, low: float | None, high: float | None) -> bool:
    """Whether ``value`` lies in the tolerance (both ends included; None: no limit)."""
    return (low is None or low <= value) and (high is None or value <= high)


def verdict(
    state: str,
    scalars: Mapping[str, float | None],
    tolerances: Mapping[str, tuple[float | None, float | None]],
    faults: str = "",
    notes: Mapping[str, str] | None = None,
    errors: int = 0,
) -> tuple[str, list[str]]:
    """The verdict (``ok``/``nok``) and every reason for ``nok``, in order:
    the run not completed (``state`` is not ``done``), its faults, its
    errors (the report's count of ERRORs it raised: a stream's gap), then each
    tolerance not met, in the recipe's order. ``notes`` adds words to a
    scalar's name in a reason (``resistance_ohm`` "(predicted)")."""
    reasons: list[str] = []
    if state != "done":
        reasons.append(f"run not completed: {state}")
    if faults:
        reasons.append(f"faults: {faults}")
    if errors:
        reasons.append(f"{errors} error(s) in the run's report")
    for name, (low, high) in tolerances.items():
        value = scalars.get(name)
        said = f"{name}{' ' + notes[name] if notes and name in notes else ''}"
        if value is None or not math.isfinite(value):
            reasons.append(
                f"{said} not recorded: its tolerance {tolerance_text(low, high)} cannot be checked"
            )
        elif not within(value, low, high):
            reasons.append(f"{said} {value:.6g} outside {tolerance_text(low, high)}")
    return (NOK if reasons else OK), reasons
