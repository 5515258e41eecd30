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

Sources, and where they differ. The residual is Singer and Seering's
percentage vibration (as Newman, Hong and Vaughan 2018 restate it). ZV, ZVD
and this MZV are exact for every ``zeta``: scaling impulse ``i`` by
``exp(zeta w t_i)`` turns the damped problem into the undamped one, so they
leave no vibration at the design point (Klipper's ``shaper_defs.py`` has the
same ZV and ZVD; its present MZV, a general ``n``-impulse solve, gives these
amplitudes and times for ``n = 3``). The EI and 2-hump EI rows are
Singhose's *undamped* closed forms (the 2-hump ``X`` from the multi-hump EI
paper, Singhose et al., J. Dyn. Sys. Meas. Control 1997) with the damping
carried by the same ``K`` scaling, as earlier Klipper releases and
Snapmaker's Marlin-based firmware write them. At ``zeta = 0`` they are exactly Singhose's shapers (EI: ``V``
at the design point, a hump with zero slope there; 2-hump EI: 0 at the
design point between two humps of height ``V``). For ``zeta > 0`` the
published damped EI and 2-hump EI are Singhose's curve fits in ``zeta`` and
``V``, which present Klipper uses, and the forms here differ from them:
their humps drop below ``V`` (EI at the design point: ``V K^2 / sum(a)``,
4.2 % at ``zeta = 0.05``), their zeros lift off 0, and the band below ``V``
is a little narrower (EI at ``zeta = 0.05``: 0.794 to 1.21 ``f_n`` against
0.786 to 1.22; 2-hump EI: 0.633 to 1.38 against 0.619 to 1.40, with a
0.5 % longer shaper). Kept because they are closed forms whose humps never
exceed ``V``, and the rest of winder (shaped profiles,
``winder resonance``) was measured with them.
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


def _number(
    name: str, x: object, allowed: str, lo: float, hi: float, *, lo_open: bool, hi_open: bool
) -> float:
    """``x`` as a float if it is a real number (not a bool) in the interval, else the one-line ValueError."""
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, float, np.integer, np.floating)):
        raise _bad(name, x, allowed)
    v = float(x)
    inside = (lo < v if lo_open else lo <= v) and (v < hi if hi_open else v <= hi)
    if not (math.isfinite(v) and inside):
        raise _bad(name, x, allowed)
    return v


def _kind(kind: object) -> str:
    if not isinstance(kind, str) or kind not in KINDS:
        raise _bad("kind", kind, "one of " + ", ".join(repr(k) for k in KINDS))
    return kind


def _f(name: str, x: object) -> float:
    v = _number(name, x, "a finite number > 0 (Hz)", 0.0, math.inf, lo_open=True, hi_open=True)
    if not math.isfinite(1.0 / v):  # a subnormal frequency: its period overflows
        raise _bad(name, x, "a finite number > 0 (Hz) whose period 1/f is finite")
    return v


def _zeta(name: str, x: object) -> float:
    return _number(
        name, x, "a number in [0, 1) (an underdamped resonance)", 0.0, 1.0, lo_open=False, hi_open=True
    )


def _v_tol(x: object) -> float:
    return _number("v_tol", x, "a number in (0, 0.5)", 0.0, 0.5, lo_open=True, hi_open=True)


def shaper(kind: str, f_n: float, zeta: float, *, v_tol: float = V_TOL) -> tuple[F64, F64]:
    """(amplitudes, times) of the input shaper ``kind`` (one of :data:`KINDS`;
    ``"none"``, no shaper, is refused) for the mode ``f_n`` (Hz), ``zeta`` in
    [0, 1): positive amplitudes summing to 1, times from 0 (s), increasing.
    ``v_tol`` in (0, 0.5) is the EI shapers' vibration tolerance (the others
    ignore it). ValueError (one line, naming the parameter, its value and the
    allowed range) for a bad argument."""
    return _impulses(_kind(kind), _f("f_n", f_n), _zeta("zeta", zeta), _v_tol(v_tol))


def _impulses(kind: str, f: float, z: float, v: float) -> tuple[F64, F64]:
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
    command's, for a mode at ``f_actual`` (Hz) of damping ``zeta_actual``
    (default: the design's), with the shaper designed for ``f_design``,
    ``zeta_design``: Singer and Seering's percentage vibration
    ``exp(-zeta w t_N) |sum_i A_i exp(zeta w t_i) exp(i w_d t_i)|`` with
    ``w = 2 pi f_actual``, ``w_d = w sqrt(1 - zeta^2)``, i.e. the ringing
    amplitude the shaped step leaves after its last impulse over the amplitude
    a single step would leave. Vectorised: an array of frequencies gives an
    array of the same shape, a number a 0-d array (``float()`` it).
    ValueError (one line) for a bad argument."""
    zd = _zeta("zeta_design", zeta_design)
    amps, times = _impulses(_kind(kind), _f("f_design", f_design), zd, _v_tol(v_tol))
    z = zd if zeta_actual is None else _zeta("zeta_actual", zeta_actual)
    try:
        f = np.asarray(f_actual, dtype=np.float64)
    except (TypeError, ValueError):
        raise _bad("f_actual", f_actual, "a finite number > 0 (Hz) or an array of them") from None
    bad = ~np.isfinite(f) | (f <= 0.0)
    if f.ndim == 0 and bad:
        raise _bad("f_actual", f_actual, "a finite number > 0 (Hz)")
    if np.any(bad):
        i = tuple(int(k) for k in np.argwhere(bad)[0])
        at = ", ".join(map(str, i))
        count = f"{int(bad.sum())} of {f.size} are not"
        raise _bad(f"f_actual[{at}]", float(f[i]), f"a finite number > 0 (Hz) ({count})")
    w = 2.0 * math.pi * f[..., None]
    wd = w * math.sqrt((1.0 - z) * (1.0 + z))
    decay = np.exp(z * w * (times - times[-1]))  # exp(-zeta w (t_N - t_i)) <= 1: no overflow
    c = np.sum(amps * decay * np.cos(wd * times), axis=-1)
    s = np.sum(amps * decay * np.sin(wd * times), axis=-1)
    out: F64 = np.hypot(c, s)
    return out
