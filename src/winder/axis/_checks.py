"""Input checks shared by the axis modules: finite positive parameters, 1-D
arrays of times and angles, one angle per step, and the array type aliases."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from winder.errors import BadInputError

FloatArray = npt.NDArray[np.float64]
ArrayLike = float | Sequence[float] | npt.NDArray[np.floating]


def _positive(name: str, value: object, unit: str, *, allow_zero: bool = False) -> float:
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        v = math.nan
    if isinstance(value, bool) or not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise BadInputError(f"{name}={value!r} is invalid: must be finite and {bound} ({unit})")
    return v


def _vector(name: str, value: object, *, sorted_: bool = False) -> FloatArray:
    a = np.asarray(value, dtype=np.float64)
    if a.ndim == 0:
        a = a.reshape(1)
    if a.ndim != 1:
        raise ValueError(f"{name} has shape {a.shape}: must be a 1-D array of times/angles")
    if sorted_ and a.size > 1:
        # one pass: NaN fails every comparison, so it reads as unsorted unless
        # the order holds, and then only the ends can be infinite
        if not np.all(a[1:] >= a[:-1]):
            if not np.all(np.isfinite(a)):
                raise ValueError(f"{name} contains non-finite values: all must be finite")
            raise ValueError(f"{name} is not sorted: must be non-decreasing (s)")
        if not (math.isfinite(a[0]) and math.isfinite(a[-1])):
            raise ValueError(f"{name} contains non-finite values: all must be finite")
    elif not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains non-finite values: all must be finite")
    return a


def _angles(step_angle: object, n: int) -> FloatArray:
    a = np.asarray(step_angle, dtype=np.float64)
    if a.ndim == 0:
        a = np.full(n, float(a))
    elif a.ndim != 1 or a.size != n:
        raise ValueError(f"step_angle has shape {a.shape}: must be a scalar or one angle per step ({n})")
    if not np.all(np.isfinite(a)):
        raise ValueError("step_angle contains non-finite values: all must be finite (rad)")
    return a
