"""The exponential ramp: the stepper start-up ramp of paper 004, truncated.

``v = v_start + (V - v_start)(1 - e^(-t/tau))`` up and the decaying
``e^(-t/tau)`` down. The pure exponential never reaches ``V``, so the ramp is
*truncated* as a table-driven stepper controller does it: the curve aims at
a slightly higher asymptote ``W = v_start + (V - v_start)/(1 - eps)`` and
reaches ``V`` exactly after ``tau * ln(1/eps)`` (``eps = exp_cut``). The
deceleration is the mirror. A short move leaves the rising curve early, at
the reduced peak, and enters the falling one there; the time on the flatter
curve is the root of the (increasing, transcendental) distance equation,
found by bracketed Newton, all in velocity increments.

Its phases follow a law of their own (:data:`LAW`, codes :data:`EXP_UP` and
:data:`EXP_DOWN`): positions relax toward an asymptote, measured from the
start (rising) or back from the end (falling); steps are inverted by a few
vectorised Newton steps that converge monotonically. Its stop leaves the
move for its own falling curve at the current velocity.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from winder.motion.ramps._scurve import SNAP, Infeasible, polish
from winder.motion.ramps.base import (
    LAWS,
    POLY,
    Limit,
    Profile,
    Ramp,
    Seg,
    Span,
    bad,
    join,
    needed,
    plan,
    real,
    tail,
)

F64 = NDArray[np.float64]

EXP_UP, EXP_DOWN = 1, 2
"""Law codes of the rising and the falling curve; their :class:`Seg` keeps in
``b`` the velocity still to go toward the asymptote, at the start (rising) or
the end (falling), and in ``tau`` the time constant."""


class ExponentialRamp:
    """The truncated exponential (``tau``; ``exp_cut``)."""

    name = "exponential"
    rank = 2
    limits: tuple[str, ...] = ("tau",)
    moves = True
    piecewise_polynomial = False

    def plan(
        self, D: float, v0: float, v1: float, V: float, a_max: Limit, j_max: Limit, tau: Limit, exp_cut: float
    ) -> Profile:
        eps = real("exp_cut", exp_cut, "a finite number in (0, 0.5]")
        if not 0.0 < eps <= 0.5:
            raise bad("exp_cut", exp_cut, "a finite number in (0, 0.5]")
        return _plan(D, v0, v1, V, needed("tau", tau, self.name), eps)

    def stop(self, profile: Profile, v: float, a: float, exp_cut: float) -> Profile:
        seg, dist = _fall(profile, v, profile.v_end, float(profile.v_max or v), exp_cut)
        return tail(profile, [seg], dist, float(profile.v_max or v))

    def continuation(
        self, profile: Profile, v: float, a: float, distance: float, v_max: float, exp_cut: float
    ) -> Profile | None:
        v1 = profile.v_end
        kw = {
            "v_max": v_max,
            "a_max": profile.a_max,
            "j_max": profile.j_max,
            "tau": profile.tau,
            "exp_cut": exp_cut,
        }
        if v <= v_max:
            try:
                return plan(self.name, distance, v_start=v, v_end=v1, **kw)  # type: ignore[arg-type]
            except ValueError:
                return None
        seg, d1 = _fall(profile, v, v_max, v_max, exp_cut)
        if not d1 < distance:
            return None
        try:
            rest = plan(self.name, distance - d1, v_start=v_max, v_end=v1, **kw)  # type: ignore[arg-type]
        except ValueError:
            return None
        return join(profile, [seg], d1, rest, v_max)


RAMP: Ramp = ExponentialRamp()


class _ExpLaw:
    """``v`` relaxing toward an asymptote: rising from the start, falling to the end."""

    codes: tuple[int, ...] = (EXP_UP, EXP_DOWN)

    def label(self, seg: Seg) -> float | str:
        return "exp-up" if seg.law == EXP_UP else "exp-down"

    def sample(self, A: dict[str, Any], ie: NDArray[np.intp], tl: F64) -> tuple[F64, F64, F64, F64]:
        tc, b = A["tau"][ie], A["b"][ie]
        up = A["law"][ie] == EXP_UP
        # rising: from the start, v = v0 + b (1 - e^-x); falling: from the end,
        # v = v1 + b (e^y - 1) with y the time left (units of tau)
        y = np.where(up, -tl, A["T"][ie] - tl) / tc
        vr = np.where(up, A["v0"][ie], A["v1"][ie])
        e = np.exp(y)
        dp = tc * (vr * np.abs(y) + b * _phi(y))
        p = np.where(up, A["p0"][ie] + dp, A["p1"][ie] - dp)
        v = vr + b * np.where(up, -np.expm1(y), np.expm1(y))
        acc = np.where(up, b, -b) / tc * e
        return p, v, acc, -acc / tc

    def invert(self, span: Span, x: F64) -> None:
        s = span.seg
        _invert(x, span.t0, span.t1, s.p0, s.v0, span.p1, span.v1, s.b, s.tau, s.law == EXP_UP)


LAW = _ExpLaw()
LAWS[EXP_UP] = LAWS[EXP_DOWN] = LAW


def _phi(x: F64) -> F64:
    """``expm1(x) - x`` without cancellation near 0 (series for |x| < 0.5)."""
    out: F64 = np.expm1(x) - x
    small = np.abs(x) < 0.5
    if small.any():
        xs = x[small]
        acc = np.full_like(xs, 1.0 / math.factorial(17))
        for k in range(16, 1, -1):
            acc = acc * xs + 1.0 / math.factorial(k)
        out[small] = acc * xs * xs
    return out


def _phi1(x: float) -> float:
    """Scalar ``expm1(x) - x`` without cancellation."""
    if abs(x) >= 0.5:
        return math.expm1(x) - x
    acc = 1.0 / math.factorial(17)
    for k in range(16, 1, -1):
        acc = acc * x + 1.0 / math.factorial(k)
    return acc * x * x


def _invert(
    x: F64,
    t0: float,
    t1: float,
    p0: float,
    v0: float,
    p1: float,
    v1: float,
    b: float,
    tc: float,
    rising: bool,
) -> None:
    """In place: times in an exponential phase. Rising phases are measured from
    the start, falling ones back from the end, so that the distance is an
    increasing convex function ``h(y) = v_r tc y + b tc phi(+-y)`` of the
    reference time ``y`` (units of tau) and Newton converges monotonically
    from above after the first step."""
    if rising:
        d = x - p0  # h(y) = v0 tc y + b tc (y + expm1(-y)),  b = v_inf - v0 > 0
        vr, sgn = v0, -1.0
    else:
        d = p1 - x  # back from the end: h(y) = v1 tc y + b tc (expm1(y) - y), b = v1 - v_inf > 0
        vr, sgn = v1, 1.0
    np.maximum(d, 0.0, out=d)
    ymax = (t1 - t0) / tc
    dn = d / tc
    # quadratic model v_r y + b y^2 / 2 = dn: a lower bound when rising, upper when falling
    den = np.sqrt(vr * vr + 2.0 * b * dn)
    den += vr
    y = np.divide(2.0 * dn, den, out=np.zeros_like(dn), where=den > 0.0)
    np.minimum(y, ymax, out=y)
    for _ in range(40):
        e = np.exp(sgn * y)
        f = vr * y + b * _phi(sgn * y) * 1.0 - dn
        df = vr + b * sgn * (e - 1.0)
        step = np.divide(f, df, out=np.zeros_like(f), where=df > 0.0)
        y -= step
        np.clip(y, 0.0, ymax, out=y)
        if not (np.abs(step) > 4e-16 * np.maximum(y, 1e-300)).any():
            break
    y *= tc
    if rising:
        np.add(t0, y, out=x)
    else:
        np.subtract(t1, y, out=x)


def _plan(D: float, v0: float, v1: float, V: float, tau: float, eps: float) -> Profile:
    # Everything in velocity *increments* over the boundary velocities (the peak
    # is v0 + du_v = v1 + dd_v): when the ramps change the speed by little
    # compared with the speed itself, forming the peak velocity first would lose
    # those digits.
    K = 1.0 / (1.0 - eps)
    bu = (V - v0) * K  # W - v0: the rising curve aims at W, reaches V after `cut` tau
    bd = (V - v1) * K * eps  # v1 - U: the falling curve aims at U, reaches v1 likewise
    gap = v1 - v0
    cut = -math.log(eps)  # ramp length in time constants

    # times on the curves in units of tau, from the increments
    def yu_of(du_v: float) -> float:
        if du_v <= 0.0:
            return 0.0
        return cut if du_v >= V - v0 else -math.log1p(-du_v / bu)

    def yd_of(dd_v: float) -> float:
        if dd_v <= 0.0:
            return 0.0
        return cut if dd_v >= V - v1 else math.log1p(dd_v / bd)

    def d_up(y: float) -> float:
        return tau * (v0 * y + bu * _phi1(-y))

    def d_dn(y: float) -> float:
        return tau * (v1 * y + bd * _phi1(y))

    h_u, h_d = max(gap, 0.0), max(-gap, 0.0)  # increments at the lowest peak max(v0, v1)
    d_min = d_up(yu_of(h_u)) + d_dn(yd_of(h_d))
    if not d_min <= D:
        if d_min * (1.0 - SNAP) > D:
            raise Infeasible(d_min)
        vp, yu, yd = max(v0, v1), yu_of(h_u), yd_of(h_d)  # the shortest move, to rounding
        tc = 0.0
    elif d_up(yu_of(V - v0)) + d_dn(yd_of(V - v1)) <= D:
        yu, yd = yu_of(V - v0), yd_of(V - v1)
        vp, tc = V, (D - d_up(yu) - d_dn(yd)) / V
    else:
        # Solve for the time on the flatter curve at the junction (the smaller
        # acceleration, tau a = bu - du_v rising, bd + dd_v falling): the
        # increments, and the other curve's time, depend smoothly on it.
        dfull = d_up(yu_of(V - v0)) + d_dn(yd_of(V - v1))
        frac = (D - d_min) / (dfull - d_min)  # secant guess
        du_g = h_u + (V - max(v0, v1)) * frac
        if bd + (du_g - gap) < bu - du_g:

            def f(y: float) -> tuple[float, float]:
                dd_v = bd * math.expm1(y)
                du_v = dd_v + gap
                v = v1 + dd_v
                return d_up(yu_of(du_v)) + d_dn(y) - D, tau * v * (1.0 + (bd + dd_v) / (bu - du_v))

            yd = polish(f, yd_of(du_g - gap), yd_of(h_d), cut)
            dd_v = min(bd * math.expm1(yd), V - v1)
            yu = yu_of(dd_v + gap)
            vp = min(v1 + dd_v, V)
        else:

            def f(y: float) -> tuple[float, float]:
                du_v = -bu * math.expm1(-y)
                dd_v = du_v - gap
                v = v0 + du_v
                return d_up(y) + d_dn(yd_of(dd_v)) - D, tau * v * (1.0 + (bu - du_v) / (bd + dd_v))

            yu = polish(f, yu_of(du_g), yu_of(h_u), cut)
            du_v = min(-bu * math.expm1(-yu), V - v0)
            yd = yd_of(du_v - gap)
            vp = min(v0 + du_v, V)
        tc = max(D - d_up(yu) - d_dn(yd), 0.0) / vp  # the rounding residue, as a cruise
    tu, td = tau * yu, tau * yd
    du, dd = d_up(yu), d_dn(yd)
    segs = [Seg(tu, 0.0, v0, bu / tau, -bu / tau**2, EXP_UP, bu, tau)]
    segs.append(Seg(tc, du, vp, 0.0, 0.0))
    a_dn = -(bd + (vp - v1)) / tau  # at the start of the falling curve
    segs.append(Seg(td, D - dd, vp, a_dn, -a_dn / tau, EXP_DOWN, bd, tau))
    return Profile("exponential", segs, (D, v1), v_max=V, a_max=None, j_max=None, tau=tau, v_peak=vp)


def _fall(like: Profile, v: float, v_to: float, v_max: float, eps: float) -> tuple[Seg, float]:
    """The falling curve (of a move with peak ``v_max``) from ``v`` down to
    ``v_to``: its phase and the distance it covers."""
    assert like.tau is not None
    v1, tau = like.v_end, like.tau
    bd = (v_max - v1) / (1.0 - eps) * eps  # v1 minus the curve's asymptote
    if bd <= 0.0 or v <= v_to:
        return Seg(0.0, 0.0, v, 0.0, 0.0, POLY), 0.0
    ya, yb = math.log1p((v - v1) / bd), math.log1p((v_to - v1) / bd)  # time left to v1, in tau
    dist = tau * (v1 * (ya - yb) + bd * (_phi1(ya) - _phi1(yb)))
    b = bd + (v_to - v1)  # the phase ends at v_to: what is left toward the asymptote there
    a0 = -(bd + (v - v1)) / tau
    return Seg(tau * (ya - yb), 0.0, v, a0, -a0 / tau, EXP_DOWN, b, tau), dist
