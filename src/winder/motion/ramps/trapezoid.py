"""The trapezoid ramp (T-curve): acceleration-limited, three phases.

Constant acceleration ``a_max`` up to the peak, a cruise (only at ``v_max``),
constant deceleration down to ``v_end``. The jerk is reported as 0: it is
infinite (a Dirac impulse) at the corners, where the acceleration steps.
The peak velocity is a closed form (:func:`solve`); its phases are polynomial
(:mod:`winder.motion.ramps._poly`); its stop decelerates at ``-a_max`` at once.
"""

from __future__ import annotations

import math

from winder.motion.ramps._poly import PolyRamp
from winder.motion.ramps._scurve import SNAP, Infeasible
from winder.motion.ramps.base import Limit, Profile, Ramp, Seg, needed


class TrapezoidRamp(PolyRamp):
    """The trapezoid (``a_max``)."""

    name = "trapezoid"
    rank = 1
    limits: tuple[str, ...] = ("a_max",)
    moves = True

    def plan(
        self, D: float, v0: float, v1: float, V: float, a_max: Limit, j_max: Limit, tau: Limit, exp_cut: float
    ) -> Profile:
        A = needed("a_max", a_max, self.name)
        vp, tu, tc, td = solve(D, v0, v1, V, A)
        T = 0.0 + tu + tc + td  # as Profile adds the phases up
        return Profile.lazy(
            self.name, _phases, (D, v0, v1, A, vp, tu, tc, td), D, v1, T, v0, vp, V, A, None, None
        )


RAMP: Ramp = TrapezoidRamp()


def _phases(
    D: float, v0: float, v1: float, A: float, vp: float, tu: float, tc: float, td: float
) -> list[Seg]:
    """Up at ``a_max``, the cruise at ``vp``, down at ``-a_max`` (built back from ``D``)."""
    p = tu * (v0 + 0.5 * A * tu)
    pd = D - td * (v1 + 0.5 * A * td)
    return [Seg(tu, 0.0, v0, A, 0.0), Seg(tc, p, vp, 0.0, 0.0), Seg(td, pd, v1 + A * td, -A, 0.0)]


def solve(D: float, v0: float, v1: float, V: float, A: float) -> tuple[float, float, float, float]:
    """Trapezoid (infinite jerk). Returns ``(vp, t_up, tc, t_down)``; raises
    :class:`Infeasible` when ``D < |v1^2 - v0^2| / (2A)``."""
    h = v0 if v0 >= v1 else v1
    lo_v = v1 if v0 >= v1 else v0
    d0 = (h - lo_v) * (h + lo_v) / (2.0 * A)
    if d0 > D:
        if d0 * (1.0 - SNAP) > D:
            raise Infeasible(d0)
        D = d0
    dv = ((V - v0) * (V + v0) + (V - v1) * (V + v1)) / (2.0 * A)
    if dv <= D:
        return V, (V - v0) / A, (D - dv) / V, (V - v1) / A
    # vp^2 = A D + (v0^2 + v1^2)/2, written as the increment over h
    vp = math.sqrt(A * D + 0.5 * (v0 * v0 + v1 * v1))
    w = (A * D - 0.5 * (h - lo_v) * (h + lo_v)) / (vp + h)
    vp = min(h + w, V)
    return vp, ((h - v0) + w) / A, 0.0, ((h - v1) + w) / A
