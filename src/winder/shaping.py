"""Input shapers: impulse trains that cancel a resonance's vibration (ROS-free).

A lightly damped mode of natural frequency ``f_n`` (Hz) and damping ratio
``zeta`` rings after any fast change of its command. Convolving the command
with a short train of positive impulses (amplitudes ``A_i`` summing to 1 at
times ``t_i`` from 0) whose responses cancel at that mode removes the ringing
at a cost of ``t_last`` of delay. With ``K = exp(-zeta pi / sqrt(1 - zeta^2))``
and the damped period ``T_d = 1 / (f_n sqrt(1 - zeta^2))``, the published
closed forms (Singer and Seering 1990 for ZV/ZVD; Singhose et al. for EI and
its two-hump form; the MZV spacing of 3D-printer firmware):

=========  ===================================================  ======================
shaper     amplitudes (before normalising)                      times
=========  ===================================================  ======================
zv         1, K                                                 0, T_d/2
mzv        1 - 1/sqrt2, (sqrt2 - 1) K', (1 - 1/sqrt2) K'^2       0, 0.375 T_d, 0.75 T_d
zvd        1, 2K, K^2                                           0, T_d/2, T_d
ei         (1 + V)/4, (1 - V)/2 K, (1 + V)/4 K^2                0, T_d/2, T_d
2hump_ei   a1, (1/2 - a1) K, (1/2 - a1) K^2, a1 K^3              0, T_d/2, T_d, 3/2 T_d
=========  ===================================================  ======================

``K' = exp(-0.75 zeta pi / sqrt(1 - zeta^2))``; ``V`` is the vibration
tolerance (default 5 %); for 2-hump EI ``X = (V^2 (sqrt(1 - V^2) + 1))^(1/3)``
and ``a1 = (3X^2 + 2X + 3V^2) / (16 X)``. ZV and ZVD leave no vibration at
the design point (ZVD also none in the first derivative against frequency:
more robust, twice as long); EI and 2-hump EI trade a residual of ``V`` at
the design point for a wider band below ``V``. :func:`residual` gives the
vibration left, relative to the unshaped command's, at any frequency.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["KINDS", "V_TOL", "duration", "residual", "shaper"]

KINDS = ("zv", "mzv", "zvd", "ei", "2hump_ei")
V_TOL = 0.05

F64 = NDArray[np.float64]


def _bad(name: str, value: object, allowed: str) -> ValueError:
    return ValueError(f"{name}={value!r} is invalid: must be {allowed}")


def _checked(kind: object, f_n: object, zeta: object, v_tol: object) -> tuple[str, float, float, float]:
    if kind not in KINDS:
        raise _bad("kind", kind, "one of " + ", ".join(repr(k) for k in KINDS))
    out = []
    for name, x, lo, hi, lo_open, hi_open in (
        ("f_n", f_n, 0.0, math.inf, True, True),
        ("zeta", zeta, 0.0, 1.0, False, True),
        ("v_tol", v_tol, 0.0, 0.5, True, True),
    ):
        allowed = {
            "f_n": "a finite number > 0 (Hz)",
            "zeta": "a number in [0, 1) (an underdamped resonance)",
            "v_tol": "a number in (0, 0.5)",
        }[name]
        if isinstance(x, bool) or not isinstance(x, (int, float, np.floating, np.integer)):
            raise _bad(name, x, allowed)
        v = float(x)
        if not math.isfinite(v) or v < lo or v > hi or (lo_open and v == lo) or (hi_open and v == hi):
            raise _bad(name, x, allowed)
        out.append(v)
    return str(kind), out[0], out[1], out[2]


def shaper(kind: str, f_n: float, zeta: float, *, v_tol: float = V_TOL) -> tuple[F64, F64]:
    """(amplitudes, times) of the input shaper ``kind`` for the mode ``f_n``
    (Hz), ``zeta``: positive amplitudes summing to 1, times from 0 (s),
    increasing. ValueError (one line) for a bad argument."""
    kind, f, z, v = _checked(kind, f_n, zeta, v_tol)
    root = math.sqrt((1.0 - z) * (1.0 + z))
    k = math.exp(-z * math.pi / root)
    td = 1.0 / (f * root)
    if kind == "zv":
        a, t = [1.0, k], [0.0, 0.5]
    elif kind == "zvd":
        a, t = [1.0, 2.0 * k, k * k], [0.0, 0.5, 1.0]
    elif kind == "mzv":
        km = math.exp(-0.75 * z * math.pi / root)
        a1 = 1.0 - 1.0 / math.sqrt(2.0)
        a, t = [a1, (math.sqrt(2.0) - 1.0) * km, a1 * km * km], [0.0, 0.375, 0.75]
    elif kind == "ei":
        a1 = 0.25 * (1.0 + v)
        a, t = [a1, 0.5 * (1.0 - v) * k, a1 * k * k], [0.0, 0.5, 1.0]
    else:  # 2hump_ei
        v2 = v * v
        x = (v2 * (math.sqrt(1.0 - v2) + 1.0)) ** (1.0 / 3.0)
        a1 = (3.0 * x * x + 2.0 * x + 3.0 * v2) / (16.0 * x)
        a2 = (0.5 - a1) * k
        a, t = [a1, a2, a2 * k, a1 * k**3], [0.0, 0.5, 1.0, 1.5]
    amps = np.array(a)
    amps /= amps.sum()
    return amps, np.array(t) * td


def duration(kind: str, f_n: float, zeta: float, *, v_tol: float = V_TOL) -> float:
    """The shaper's length: the time of its last impulse (s), the delay it adds to a move."""
    return float(shaper(kind, f_n, zeta, v_tol=v_tol)[1][-1])


def residual(
    kind: str,
    f_design: float,
    zeta_design: float,
    f_actual: ArrayLike,
    zeta_actual: float | None = None,
    *,
    v_tol: float = V_TOL,
) -> F64:
    """Vibration left after the shaped command, relative to the unshaped
    command's, for a mode at ``f_actual`` (Hz; an array gives an array) of
    damping ``zeta_actual`` (default: the design's), with the shaper designed
    for ``f_design``, ``zeta_design``:
    ``exp(-zeta w t_N) |sum_i A_i exp(zeta w t_i) exp(i w_d t_i)|``."""
    amps, times = shaper(kind, f_design, zeta_design, v_tol=v_tol)
    z = zeta_design if zeta_actual is None else float(zeta_actual)
    _checked(kind, 1.0, z, v_tol)
    f = np.asarray(f_actual, dtype=np.float64)
    if np.any(~np.isfinite(f)) or np.any(f <= 0.0):
        raise _bad("f_actual", f_actual, "finite numbers > 0 (Hz)")
    w = 2.0 * math.pi * f[..., None]
    wd = w * math.sqrt((1.0 - z) * (1.0 + z))
    decay = np.exp(z * w * (times - times[-1]))  # exp(-zeta w (t_N - t_i)) <= 1: no overflow
    c = np.sum(amps * decay * np.cos(wd * times), axis=-1)
    s = np.sum(amps * decay * np.sin(wd * times), axis=-1)
    out: F64 = np.hypot(c, s)
    return out
