"""Peak-velocity solve of S-curve moves, in closed form (scalar ``math``).

Internal to :mod:`winder.motion.ramps.scurve`. All S-curve work is done in the units of
the limits themselves: time ``A/J``, velocity ``A**2/J``, distance ``A**3/J**2``.
There ``a_max = j_max = 1``, so a jerk of 1e9 with ``a_max`` 0.5 and a jerk of
1e-9 give the same well-scaled polynomials: the published "too large a jerk
deforms the curve" complaint comes from discretising in time, which this
module never does.

The move is a *hill*: the fastest ramp (zero acceleration at both ends) from
``v0`` up to the peak ``vp``, a cruise at ``vp`` (only when ``vp == v_max``),
and the fastest ramp down to ``v1``; or, when the distance is shorter than
the direct ramp ``v0 -> v1`` covers, a *valley*: the fastest ramp down to
``vv < min(v0, v1)`` and back up to ``v1``. Both are built from ramps with
zero acceleration at their ends, which is the structure of every
time-optimal monotone move with zero boundary accelerations (checked against
ruckig with ``min_velocity = 0`` in the tests).

Hill or valley? With infinite jerk (trapezoid) a valley always covers *more*
distance than the direct ramp, so it never helps. With a jerk limit it can
cover less: a ramp's distance is ``(v_a + v_b) * T/2`` and a triangular ramp's
duration grows only like ``sqrt(dv/J)``, so dipping deep (low ``v_a + v_b``)
can win. In unit limits (below) the valley's distance as a function of its
depth ``u = min(v0, v1) - vv`` is
``d(u) = (2l - u) G(u) + (h + l - u) G(h - l + u)`` with ``G(x) = T(x)/2``
concave, so ``d`` is concave: it rises from ``d(0)`` (the direct ramp) with
infinite slope, then falls to ``d(l)`` (dipping to rest). So

* ``D >= d(0)``: a hill (going up is faster per extra distance than dipping:
  ``dT/dD ~ 1/h`` against ``1/l``); when ``v0`` or ``v1`` is ``v_max`` the hill
  is the cruise at ``v_max``;
* ``d(l) <= D < d(0)``: the valley whose depth is the unique crossing of
  ``d(u) = D`` on the falling side (the shallowest valley: its duration
  ``T(u) + T(h - l + u)`` grows with depth);
* ``D < min(d(0), d(l))``: no monotone move of that length joins the two
  velocities; the error names that minimum.

With ``h = max(v0, v1)``, ``l = min(v0, v1)``, ``D`` the distance and
``w = vp - h`` the unknown, the distance ``d(w)`` is increasing, and its
shape changes at ``w = max(0, 1 - (h - l))`` (the long ramp gets a
constant-acceleration phase) and ``w = 1`` (the short one does too):

* both ramps have constant acceleration: a quadratic in ``w``;
* only the long ramp does (``s = sqrt(w)``): the quartic
  ``s^4/2 + s^3 + (h + 1/2) s^2 + 2 h s + (h + l)(h - l + 1)/2 - D = 0``;
* neither does: with ``s_h = sqrt(w)``, ``s_l = sqrt(w + h - l)`` (the
  jerk-phase lengths) and ``sigma = s_h + s_l`` (half the duration), the
  distance ``(l + vp) s_l + (h + vp) s_h`` becomes the depressed quartic
  ``sigma^4 + 4 (h + l) sigma^2 - 4 D sigma - (h - l)^2 = 0`` with exactly one
  positive root (one sign change), and ``s_h = (sigma - (h - l)/sigma)/2``.
  For ``h == l`` it reduces to the cubic ``sigma^3 + 4 h sigma - 4 D = 0``.

The valley has the same three regimes: a quadratic ``u^2 - (2l - 1) u +
(D - l - (h + l)(h - l + 1)/2) = 0`` (larger root), the quartic in
``s = sqrt(u)``: ``s^4 + 2 s^3 - (2l - 1) s^2 - 4 l s + 2D - (h + l)(h - l + 1) = 0``
and, both ramps triangular, ``sigma^4 - 4 (h + l) sigma^2 + 4 D sigma - (h - l)^2 = 0``
(smallest root in the regime, the shallowest valley).

The quartics are solved by Ferrari's method written for accuracy (the
resolvent cubic by the trigonometric/hyperbolic forms, the cancelling
quadratic coefficient from the product of both, ``C * C' = r``), the root in
the regime's bracket is picked, and a bracketed Newton step on the same
polynomial polishes the last bits (the polynomials are the distance equation
itself, never a squared form, so no spurious root can be polished into; for
the valley the bracket is split at the regime boundaries by the sign of
``d - D``, which is valid because the crossing is unique).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from math import sqrt

__all__ = ["SNAP", "Infeasible", "polish", "ramp", "scurve", "valley"]

_EPS = 2.220446049250313e-16
SNAP = 16 * _EPS
"""Relative tolerance below a minimum distance that is taken as rounding."""


class Infeasible(Exception):  # noqa: N818 - internal signal, turned into ValueError
    """No monotone move of the requested length joins the boundary velocities."""

    def __init__(self, d_min: float) -> None:
        super().__init__(d_min)
        self.d_min = d_min


def ramp(dv: float) -> tuple[float, float]:
    """Jerk-phase and constant-acceleration durations ``(tj, ta)`` of the fastest
    change of velocity by ``dv >= 0`` with zero acceleration at both ends, in
    the units ``a_max = j_max = 1``. Its duration is ``2 tj + ta`` and it covers
    ``(v_a + v_b)/2 * (2 tj + ta)`` (the velocity curve is point-symmetric)."""
    if dv >= 1.0:
        return 1.0, dv - 1.0
    return math.sqrt(dv), 0.0


def _hill(w: float, h: float, lo_v: float, gap: float) -> float:
    """Distance of the hill with peak ``h + w`` and no cruise (unit limits)."""
    # the ramp between h and the peak, then between l and the peak (:func:`ramp`, inlined)
    tj, ta = (1.0, w - 1.0) if w >= 1.0 else (sqrt(w), 0.0)
    d = (2.0 * h + w) * (tj + 0.5 * ta)
    x = gap + w
    tj, ta = (1.0, x - 1.0) if x >= 1.0 else (sqrt(x), 0.0)
    return d + (lo_v + h + w) * (tj + 0.5 * ta)


def _cubic_max_root(b: float, c: float, d: float) -> float:
    """Largest real root of ``x^3 + b x^2 + c x + d`` (trigonometric/hyperbolic form)."""
    s = b / 3.0
    p = c - b * s  # depressed: z^3 + p z + q, x = z - s
    q = d + s * (2.0 * s * s - c)
    m = math.sqrt(abs(p) / 3.0)
    m3 = m * m * m
    if m3 <= 1e-300 * abs(q):  # p negligible (or underflowing)
        return math.cbrt(-q) - s
    rho = -q / (2.0 * m3)  # z = m * u, u^3 +- 3u = 2 rho
    if p > 0.0:
        return 2.0 * m * math.sinh(math.asinh(rho) / 3.0) - s
    if abs(rho) <= 1.0:
        return 2.0 * m * math.cos(math.acos(rho) / 3.0) - s
    return 2.0 * m * math.copysign(math.cosh(math.acosh(abs(rho)) / 3.0), rho) - s


def _quadratic_roots(b: float, c: float) -> list[float]:
    """Real roots of ``x^2 + b x + c`` without cancellation."""
    disc = b * b - 4.0 * c
    if disc < 0.0:
        return []
    qq = -0.5 * (b + math.copysign(math.sqrt(disc), b))
    if qq == 0.0:
        return [0.0]
    return [qq, c / qq]


def _depressed_quartic_roots(p: float, q: float, r: float) -> list[float]:
    """Real roots of ``y^4 + p y^2 + q y + r`` (Ferrari)."""
    if q == 0.0:
        out = []
        for y2 in _quadratic_roots(p, r):
            if y2 >= 0.0:
                out += [math.sqrt(y2), -math.sqrt(y2)]
        return out
    # (y^2 + p/2 + m)^2 = 2m (y - q/(4m))^2 for a root m > 0 of the resolvent
    m = _cubic_max_root(p, 0.25 * p * p - r, -0.125 * q * q)
    if not m > 0.0:
        return []
    k = math.sqrt(2.0 * m)
    cp = 0.5 * p + m + q / (2.0 * k)  # y^2 - k y + cp
    cm = 0.5 * p + m - q / (2.0 * k)  # y^2 + k y + cm,  cp * cm == r
    if abs(cp) >= abs(cm):
        cm = r / cp
    else:
        cp = r / cm
    return _quadratic_roots(-k, cp) + _quadratic_roots(k, cm)


def polish(fn: Callable[[float], tuple[float, float]], x: float, lo: float, hi: float) -> float:
    """Bracketed Newton on an increasing ``fn`` (returns ``(value, slope)``) in [lo, hi]."""
    if not lo <= x <= hi:
        x = 0.5 * (lo + hi)
    for _ in range(100):
        fx, dfx = fn(x)
        if fx == 0.0:
            return x
        if fx < 0.0:
            lo = x
        else:
            hi = x
        xn = x - fx / dfx if dfx > 0.0 else 0.5 * (lo + hi)
        if not lo <= xn <= hi:
            xn = 0.5 * (lo + hi)
        if abs(xn - x) <= 2.0 * _EPS * abs(xn) or hi - lo <= 2.0 * _EPS * abs(hi):
            return xn
        x = xn
    return x


def scurve(
    D: float, h: float, lo_v: float, gap: float, wv: float, v0_high: bool
) -> tuple[float, float, float, float, float, float]:
    """Solve the hill in unit limits: ``h``/``lo_v`` the higher/lower boundary
    velocity, ``gap = h - lo_v`` and ``wv = v_max - h`` (differences passed in,
    computed before scaling, so that a one-ulp gap survives), ``v0_high``
    whether the start is the higher one.

    Returns ``(w, tj_up, ta_up, tc, tj_down, ta_down)``: the peak is ``h + w``
    (``w == wv`` at v_max), ``tc`` the cruise time. Raises :class:`Infeasible`
    when ``D`` is below the direct ramp's distance (then :func:`valley` is the
    answer, if any)."""
    g0 = 0.0 if v0_high else gap  # what the start lacks of h
    g1 = gap if v0_high else 0.0
    # d0 = _hill(0.0, h, lo_v, gap), the direct ramp's distance, written out (the hot path)
    tj, ta = (1.0, gap - 1.0) if gap >= 1.0 else (sqrt(gap), 0.0)
    d0 = 0.0 + (lo_v + h + 0.0) * (tj + 0.5 * ta)
    if d0 > D:
        if d0 * (1.0 - SNAP) > D:
            raise Infeasible(d0)
        D = d0  # the direct ramp, to rounding
    # dv = _hill(wv, h, lo_v, gap), written out: its ramps are the cruise's
    tjh, tah = (1.0, wv - 1.0) if wv >= 1.0 else (sqrt(wv), 0.0)  # between h and v_max
    x = gap + wv
    tjl, tal = (1.0, x - 1.0) if x >= 1.0 else (sqrt(x), 0.0)  # between l and v_max
    dv = (2.0 * h + wv) * (tjh + 0.5 * tah) + (lo_v + h + wv) * (tjl + 0.5 * tal)
    if dv <= D:  # cruise at v_max
        if v0_high:
            return wv, tjh, tah, (D - dv) / (h + wv), tjl, tal
        return wv, tjl, tal, (D - dv) / (h + wv), tjh, tah
    w1 = 1.0 - gap if gap < 1.0 else 0.0  # long ramp gets constant acceleration
    if wv > 1.0 and _hill(1.0, h, lo_v, gap) <= D:
        # both ramps trapezoidal: w^2 + (2h + 1) w + k0 = 0
        b = 2.0 * h + 1.0
        k0 = (h + lo_v) * (gap + 1.0) * 0.5 + h - D  # d(w=0) of this regime's formula - D
        w = -2.0 * k0 / (b + math.sqrt(b * b - 4.0 * k0)) if k0 < 0.0 else 0.0
        w = min(max(w, 1.0), wv)
    elif w1 < wv and _hill(w1, h, lo_v, gap) <= D:
        # long ramp trapezoidal, short one triangular: quartic in s = sqrt(w)
        k0 = (h + lo_v) * (gap + 1.0) * 0.5 - D
        s_lo, s_hi = math.sqrt(w1), math.sqrt(min(1.0, wv))

        def fm(s: float) -> tuple[float, float]:
            return (
                (((0.5 * s + 1.0) * s + h + 0.5) * s + 2.0 * h) * s + k0,
                ((2.0 * s + 3.0) * s + 2.0 * h + 1.0) * s + 2.0 * h,
            )

        # y = s + 1/2: y^4 + (2h - 1/2) y^2 + 2h y + (1/16 - 3h/2 + 2 k0)
        roots = _depressed_quartic_roots(2.0 * h - 0.5, 2.0 * h, 0.0625 - 1.5 * h + 2.0 * k0)
        s = _pick([y - 0.5 for y in roots], s_lo, s_hi)
        s = polish(fm, s, s_lo, s_hi)
        w = s * s
        if v0_high:  # the short (triangular) ramp is the one up from v0 == h
            return w, s, 0.0, 0.0, *ramp(gap + w)
        return w, *ramp(gap + w), 0.0, s, 0.0
    else:
        # both ramps triangular: depressed quartic in sigma = s_h + s_l
        w_hi = min(w1, wv)
        sg_lo = math.sqrt(gap)
        sg_hi = math.sqrt(w_hi) + math.sqrt(gap + w_hi)
        p4, q4, r4 = 4.0 * (h + lo_v), -4.0 * D, -gap * gap

        def fn(x: float) -> tuple[float, float]:
            return ((x * x + p4) * x + q4) * x + r4, (4.0 * x * x + 2.0 * p4) * x + q4

        if gap == 0.0:  # sigma^3 + p4 sigma = 4 D, hyperbolic form
            m = math.sqrt(p4 / 3.0)
            m3 = m * m * m
            if m3 > 1e-300 * D:
                sg = 2.0 * m * math.sinh(math.asinh(2.0 * D / m3) / 3.0)
            else:  # p4 negligible (or underflowing)
                sg = math.cbrt(4.0 * D)
        else:
            sg = _pick(_depressed_quartic_roots(p4, q4, r4), sg_lo, sg_hi)
        sg = polish(fn, sg, sg_lo, sg_hi)
        sh = max(0.5 * (sg - gap / sg), 0.0)
        sl = sg - sh
        w = sh * sh
        if v0_high:
            return w, sh, 0.0, 0.0, sl, 0.0
        return w, sl, 0.0, 0.0, sh, 0.0
    x0, x1 = g0 + w, g1 + w
    tj0, ta0 = (1.0, x0 - 1.0) if x0 >= 1.0 else (sqrt(x0), 0.0)
    tj1, ta1 = (1.0, x1 - 1.0) if x1 >= 1.0 else (sqrt(x1), 0.0)
    return w, tj0, ta0, 0.0, tj1, ta1


def _pick(roots: list[float], lo: float, hi: float) -> float:
    """The root inside [lo, hi], else the nearest one (the polish brackets it)."""
    best, best_gap = 0.5 * (lo + hi), math.inf
    for x in roots:
        gap = lo - x if x < lo else (x - hi if x > hi else 0.0)
        if gap < best_gap:
            best, best_gap = x, gap
    return best


def _valley(u: float, h: float, lo_v: float, gap: float) -> float:
    """Distance of the valley dipping ``u`` below ``lo_v`` (unit limits)."""
    tj, ta = ramp(u)  # between l and the bottom
    d = (2.0 * lo_v - u) * (tj + 0.5 * ta)
    tj, ta = ramp(gap + u)  # between h and the bottom
    return d + (h + lo_v - u) * (tj + 0.5 * ta)


def valley(
    D: float, h: float, lo_v: float, gap: float, v0_high: bool
) -> tuple[float, float, float, float, float]:
    """Solve the valley in unit limits (arguments as :func:`scurve`), for ``D``
    below the direct ramp's distance.

    Returns ``(u, tj_down, ta_down, tj_up, ta_up)``: the bottom is
    ``lo_v - u``, reached by the ramp down from ``v0``, left by the ramp up to
    ``v1``. Raises :class:`Infeasible` with the minimum distance."""
    d_rest = _valley(lo_v, h, lo_v, gap)
    if not d_rest <= D:
        if d_rest * (1.0 - SNAP) > D:
            raise Infeasible(min(_hill(0.0, h, lo_v, gap), d_rest))
        D = d_rest  # dip to rest, to rounding

    def g(u: float) -> float:  # < 0 before the crossing, >= 0 after (d is concave)
        return D - _valley(u, h, lo_v, gap)

    # the regime holding the crossing: split [0, lo_v] where the ramps change shape
    cuts = [0.0] + [c for c in (1.0 - gap, 1.0) if 0.0 < c < lo_v] + [lo_v]
    k = 1
    while k < len(cuts) - 1 and g(cuts[k]) < 0.0:
        k += 1
    u_lo, u_hi = cuts[k - 1], cuts[k]
    um = 0.5 * (u_lo + u_hi)  # classify the regime by its midpoint (robust to rounding)
    hl = h + lo_v
    if um >= 1.0:  # both ramps trapezoidal: u^2 - (2l - 1) u + c = 0, larger root
        b = 2.0 * lo_v - 1.0
        c = D - lo_v - hl * (gap + 1.0) * 0.5
        disc = b * b - 4.0 * c
        u = 0.5 * (b + math.sqrt(disc)) if disc >= 0.0 else 0.5 * (u_lo + u_hi)

        def fu(x: float) -> tuple[float, float]:
            return (x - b) * x + c, 2.0 * x - b

        u = polish(fu, u, u_lo, u_hi)
        su = ramp(u)
        sh = ramp(gap + u)
    elif um + gap >= 1.0:  # l side triangular, h side trapezoidal: quartic in sqrt(u)
        e = 2.0 * D - hl * (gap + 1.0)
        # y = s + 1/2: y^4 - (2l + 1/2) y^2 - 2l y + (1/16 + 3l/2 + e)
        roots = _depressed_quartic_roots(-2.0 * lo_v - 0.5, -2.0 * lo_v, 0.0625 + 1.5 * lo_v + e)
        s_lo, s_hi = math.sqrt(u_lo), math.sqrt(u_hi)

        def fs(x: float) -> tuple[float, float]:  # 2 (D - d(s)): increasing at the crossing
            return (
                (((x + 2.0) * x - (2.0 * lo_v - 1.0)) * x - 4.0 * lo_v) * x + e,
                ((4.0 * x + 6.0) * x - 2.0 * (2.0 * lo_v - 1.0)) * x - 4.0 * lo_v,
            )

        s = _pick_rising(fs, [y - 0.5 for y in roots], s_lo, s_hi)
        s = polish(fs, s, s_lo, s_hi)
        u = s * s
        su = (s, 0.0)
        sh = ramp(gap + u)
    else:  # both triangular: sigma = s_l + s_h, the jerk-phase lengths
        sg_lo = math.sqrt(u_lo) + math.sqrt(gap + u_lo)
        sg_hi = math.sqrt(u_hi) + math.sqrt(gap + u_hi)
        p4, q4, r4 = -4.0 * hl, 4.0 * D, -gap * gap

        def fsg(x: float) -> tuple[float, float]:  # 4 sigma (D - d(sigma))
            return ((x * x + p4) * x + q4) * x + r4, (4.0 * x * x + 2.0 * p4) * x + q4

        sg = _pick_rising(fsg, _depressed_quartic_roots(p4, q4, r4), sg_lo, sg_hi)
        sg = polish(fsg, sg, sg_lo, sg_hi)
        sl = max(0.5 * (sg - gap / sg), 0.0)
        u = sl * sl
        su = (sl, 0.0)
        sh = (sg - sl, 0.0)
    u = min(u, lo_v)
    if v0_high:  # down from h, up to l
        return u, sh[0], sh[1], su[0], su[1]
    return u, su[0], su[1], sh[0], sh[1]


def _pick_rising(
    fn: Callable[[float], tuple[float, float]], roots: list[float], lo: float, hi: float
) -> float:
    """The smallest root in [lo, hi] where ``fn`` crosses upward (the shallowest valley)."""
    for x in sorted(roots):
        if lo <= x <= hi and fn(x)[1] >= 0.0:
            return x
    return 0.5 * (lo + hi)
