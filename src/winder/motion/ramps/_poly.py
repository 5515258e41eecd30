"""The polynomial phase law (constant jerk) and the pieces the polynomial ramps share.

Inside a polynomial phase the position is a cubic in the time from the phase
start; :data:`LAW` inverts it in closed form (registered as
:data:`winder.motion.ramps.base.POLY`). The S-curve, the trapezoid and the
jog build their moves from the same blocks: :func:`ramp_up` and
:func:`ramp_into` (the fastest change of velocity between two states of zero
acceleration, built forward or backward from the end), :func:`change` (the
time-optimal change of velocity from any state) and :func:`continuation`
(the rest of a move with another peak velocity).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from winder.motion.ramps.base import LAWS, POLY, Profile, Seg, Span, join, plan, tail

F64 = NDArray[np.float64]


class _PolyLaw:
    """Constant jerk: ``p0 + v0 s + a0 s^2/2 + j s^3/6`` of the time ``s`` from the start."""

    codes: tuple[int, ...] = (POLY,)

    def label(self, seg: Seg) -> float | str:
        return seg.jerk

    def sample(self, A: dict[str, Any], ie: NDArray[np.intp], tl: F64) -> tuple[F64, F64, F64, F64]:
        v0, a0, j = A["v0"][ie], A["a0"][ie], A["j"][ie]
        p = A["p0"][ie] + tl * (v0 + tl * (0.5 * a0 + tl * (j / 6.0)))
        return p, v0 + tl * (a0 + 0.5 * tl * j), a0 + tl * j, j.copy()

    def invert(self, span: Span, x: F64) -> None:
        t0, t1, (T, p0, v0, a0, j, *_), p1, v1, a1 = span
        if j == 0.0 and a0 == 0.0:  # cruise
            x -= p0
            x /= v0
            x += t0
        elif j == 0.0:  # constant acceleration: anchor at the slower end
            if a0 > 0.0:
                x -= p0  # tau = 2 d / (v0 + sqrt(v0^2 + 2 a d))
                _stable_quadratic(x, v0, a0)
                x += t0
            else:
                np.subtract(p1, x, out=x)  # measured back from the end
                _stable_quadratic(x, v1, -a0)
                np.subtract(t1, x, out=x)
        else:
            # anchor at the instant of zero acceleration - the phase start or end, or
            # outside the phase when a stop begins mid-ramp - where the position is
            # the odd cubic p_z + v_z s + j s^3 / 6 of the signed time s from it
            if a0 == 0.0:
                sz, pz, vz = 0.0, p0, v0
            elif a1 == 0.0:
                sz, pz, vz = T, p1, v1
            else:
                sz = -a0 / j
                pz = p0 + sz * (v0 + sz * (0.5 * a0 + sz * j / 6.0))
                vz = v0 + sz * (a0 + 0.5 * sz * j)
            if sz <= 0.0:  # anchor at or before the start: s >= 0
                x -= pz
                np.maximum(x, 0.0, out=x)
                _odd_cubic(x, vz, j)
                x += t0 + sz
            elif sz >= T:  # at or after the end: s <= 0, solved for -s
                np.subtract(pz, x, out=x)
                np.maximum(x, 0.0, out=x)
                _odd_cubic(x, vz, j)
                np.subtract(t0 + sz if sz > T else t1, x, out=x)
            else:  # inside (never built: phases are split there), solved by symmetry
                x -= pz
                sg = np.sign(x)
                np.abs(x, out=x)
                _odd_cubic(x, vz, j)
                x *= sg
                x += t0 + sz


LAW = _PolyLaw()
LAWS[POLY] = LAW


def _stable_quadratic(d: F64, v: float, a: float) -> None:
    """In place: the root ``s >= 0`` of ``v s + a s^2 / 2 = d`` (a > 0)."""
    r = d * (2.0 * a)
    r += v * v
    np.sqrt(r, out=r)
    r += v
    d *= 2.0
    np.divide(d, r, out=d, where=r > 0.0)


#: beyond this r the odd cubic is solved from its pure cubic root (:func:`_odd_cubic`)
ODD_CUBIC_FAR = 1e6


def _odd_cubic(d: F64, vz: float, j: float) -> None:
    """In place: the smallest root ``s >= 0`` of ``vz s + j s^3 / 6 = d`` (d >= 0).

    j > 0: ``s = 2c sinh(asinh(r)/3)``; j < 0: ``s = 2c sin(asin(r)/3)`` with
    ``c = sqrt(2 vz/|j|)``, ``r = 3 d / (|j| c^3)`` - no cancellation anywhere,
    and ``s ~ d/vz`` for small d keeps full relative precision. Beyond
    ``r`` = :data:`ODD_CUBIC_FAR` (j > 0), where ``vz`` hardly counts, asinh's
    absolute error (an ulp of ln 2r) would grow into sinh's result (72 ulps of
    a move's distance at vz = 7e-200): there the pure cubic's root
    ``(6 d / j)^(1/3)`` is refined by Newton (from above, on a convex
    function: each relative step under 1/(1 + (2r)^(2/3)), then squared)."""
    c = math.sqrt(2.0 * vz / abs(j)) if vz > 0.0 else 0.0
    c3j = abs(j) * c * c * c
    scale = 3.0 / c3j if c3j > 0.0 else math.inf
    if not scale < 1e300:  # from rest (or a negligible vz): j s^3 / 6 = d
        d *= 6.0 / abs(j)
        np.cbrt(d, out=d)
        return
    if j < 0.0:
        d *= scale
        np.minimum(d, 1.0, out=d)
        np.arcsin(d, out=d)
        d *= 1.0 / 3.0
        np.sin(d, out=d)
        d *= 2.0 * c
        return
    far = d > ODD_CUBIC_FAR / scale
    dd = d[far]
    if dd.size:
        s = np.cbrt(dd * (6.0 / j))
        for _ in range(3):
            s -= (s * (vz + s * s * (j / 6.0)) - dd) / (vz + s * s * (0.5 * j))
    d *= scale
    np.arcsinh(d, out=d)
    d *= 1.0 / 3.0
    np.sinh(d, out=d)
    d *= 2.0 * c
    if dd.size:
        d[far] = s


# --------------------------------------------------------------------------- builders


def ramp_up(
    segs: list[Seg], p: float, v: float, tj: float, ta: float, J: float, sgn: float
) -> tuple[float, float]:
    """Append the 3 phases of a zero-to-zero acceleration ramp (sgn +1 up, -1 down)
    starting at position p with velocity v; return the end position and velocity."""
    a = sgn * J * tj
    js = sgn * J
    segs.append(Seg(tj, p, v, 0.0, js))
    p = p + tj * (v + tj * tj * js / 6.0)
    v = v + 0.5 * js * tj * tj
    segs.append(Seg(ta, p, v, a, 0.0))
    p = p + ta * (v + 0.5 * a * ta)
    v = v + a * ta
    segs.append(Seg(tj, p, v, a, -js))
    p = p + tj * (v + tj * (0.5 * a - tj * js / 6.0))
    v = v + tj * (a - 0.5 * js * tj)
    return p, v


def ramp_into(segs: list[Seg], D: float, v1: float, tj: float, ta: float, J: float, sgn: float) -> None:
    """Append the 3 phases of a zero-to-zero acceleration ramp ending at position D with
    velocity v1, accelerating (sgn +1) or decelerating (sgn -1); built backward
    from the end, so that the end is exact."""
    a = sgn * J * tj  # the constant acceleration
    js = sgn * J  # jerk of the first phase
    # last phase: jerk -js, acceleration a -> 0, ends at (D, v1)
    v3 = v1 - 0.5 * js * tj * tj
    p3 = D - tj * (v1 - js * tj * tj / 6.0)
    # middle: constant a, ends at (p3, v3)
    v2 = v3 - a * ta
    p2 = p3 - ta * (v3 - 0.5 * a * ta)
    # first: jerk js from acceleration 0, ends at (p2, v2)
    v1s = v2 - 0.5 * js * tj * tj
    p1 = p2 - tj * (v2 - js * tj * tj / 3.0)
    segs.append(Seg(tj, p1, v1s, 0.0, js))
    segs.append(Seg(ta, p2, v2, a, 0.0))
    segs.append(Seg(tj, p3, v3, a, -js))


def change(segs: list[Seg], p: float, v: float, a: float, v1: float, A: float, J: float | None) -> float:
    """Append the time-optimal change from velocity ``v`` and acceleration
    ``a`` to velocity ``v1`` at zero acceleration (|a| <= A, |jerk| <= J; no J:
    the acceleration steps); return the end position."""
    if J is None:
        if v1 != v:
            T = abs(v1 - v) / A
            segs.append(Seg(T, p, v, math.copysign(A, v1 - v), 0.0))
            p += T * 0.5 * (v + v1)
        return p
    v_nat = v + a * abs(a) / (2.0 * J)  # where the acceleration reaches zero soonest
    s = 1.0 if v1 >= v_nat else -1.0  # work mirrored so that the change goes up
    a0, dv = s * a, s * (v1 - v)
    ap2 = J * dv + 0.5 * a0 * a0
    # a target at (or, by rounding, an ulp beside) the velocity where the
    # acceleration reaches zero: no sqrt-amplified sliver of a phase
    ulps = 64 * 2.220446049250313e-16 * (J * max(abs(v), abs(v1)) + a0 * a0)
    ap = math.sqrt(ap2) if ap2 > ulps else 0.0
    hold = 0.0
    if ap > A:
        ap = A
        hold = max((dv - (2.0 * A * A - a0 * a0) / (2.0 * J)) / A, 0.0)
    ap = max(ap, a0)
    for T, jerk in (((ap - a0) / J, s * J), (hold, 0.0), (ap / J, -s * J)):
        if jerk == 0.0:
            a = s * ap
        # a phase is split where its acceleration crosses zero (there the
        # position's inversion is anchored)
        cross = min(-a / jerk, T) if jerk != 0.0 and a * jerk < 0.0 else 0.0
        for part in (cross, T - cross):
            if part > 0.0:
                segs.append(Seg(part, p, v, a, jerk))
                p += part * (v + part * (0.5 * a + part * jerk / 6.0))
                v += part * (a + 0.5 * part * jerk)
                a = 0.0 if part == cross and cross < T else a + part * jerk
    return p


def continuation(
    profile: Profile, v: float, a: float, distance: float, v_max: float, exp_cut: float
) -> Profile | None:
    """The rest of a polynomial ramp's move from ``(v, a)``: first the
    time-optimal change of velocity to ``v_max`` (or, when that leaves too
    little distance, to the velocity where the acceleration is zero soonest),
    then a move planned from there to the end; None if neither fits."""
    assert profile.a_max is not None
    J = profile.j_max
    v1 = profile.v_end
    v_nat = v + a * abs(a) / (2.0 * J) if J is not None else v
    targets = [v_max] if v_nat > v_max else [v_max, v_nat]
    for vt in targets:
        segs: list[Seg] = []
        d1 = change(segs, 0.0, v, a, vt, profile.a_max, J)
        if not d1 < distance:
            continue
        try:
            rest = plan(
                profile.kind, distance - d1, v_max=v_max, a_max=profile.a_max, j_max=J,
                tau=profile.tau, v_start=min(vt, v_max), v_end=v1, exp_cut=exp_cut,
            )  # fmt: skip
        except ValueError:
            continue
        return join(profile, segs, d1, rest, v_max)
    return None


class PolyRamp:
    """What the polynomial ramps share: the stop is the time-optimal change of
    velocity to the end velocity (jerk-limited when the move has ``j_max``,
    else at ``-a_max`` at once), the continuation is :func:`continuation`."""

    piecewise_polynomial = True

    def stop(self, profile: Profile, v: float, a: float, exp_cut: float) -> Profile:
        assert profile.a_max is not None
        segs: list[Seg] = []
        end = change(segs, 0.0, v, a, profile.v_end, profile.a_max, profile.j_max)
        return tail(profile, segs, max(end, 0.0), float(profile.v_max or v))

    def continuation(
        self, profile: Profile, v: float, a: float, distance: float, v_max: float, exp_cut: float
    ) -> Profile | None:
        return continuation(profile, v, a, distance, v_max, exp_cut)
