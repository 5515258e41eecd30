"""The S-curve ramp: jerk-limited, seven phases, time-optimal.

Jerk up, constant acceleration, jerk down, cruise, and the mirror for the
deceleration; every degenerate case (``a_max`` or ``v_max`` not reached,
short moves, ``v_start != v_end``, boundary velocities at ``v_max``) and
time-optimal among monotone (``v >= 0``) motions with zero boundary
accelerations. Usually a *hill* (up to ``v_peak``, down to ``v_end``); a move
shorter than the direct ramp ``v_start -> v_end`` can still be possible as a
*valley* that first dips below both speeds. The peak (or bottom) velocity
comes from the closed form of :mod:`winder.motion.ramps._scurve`. Its phases
are polynomial (:mod:`winder.motion.ramps._poly`); its stop is the
jerk-limited time-optimal change of velocity to the end velocity.
"""

from __future__ import annotations

from winder.motion.ramps import _scurve
from winder.motion.ramps._poly import PolyRamp, ramp_into, ramp_up
from winder.motion.ramps.base import Profile, Ramp, Seg, needed


class ScurveRamp(PolyRamp):
    """The S-curve (``a_max``, ``j_max``)."""

    name = "scurve"
    rank = 0
    limits: tuple[str, ...] = ("a_max", "j_max")
    moves = True

    def plan(
        self,
        D: float,
        v0: float,
        v1: float,
        V: float,
        *,
        a_max: float | None,
        j_max: float | None,
        tau: float | None,
        exp_cut: object,
    ) -> Profile:
        return _plan(D, v0, v1, V, needed("a_max", a_max, self.name), needed("j_max", j_max, self.name))


RAMP: Ramp = ScurveRamp()


def _plan(D: float, v0: float, v1: float, V: float, A: float, J: float) -> Profile:
    tu = A / J  # unit time, velocity, distance of the limits
    vu = A * tu
    du = vu * tu
    # differences before scaling, so that a gap of one ulp survives it
    v0_high = v0 >= v1
    h, lo_v = (v0, v1) if v0_high else (v1, v0)
    Ds, hs, ls, gs, wvs = D / du, h / vu, lo_v / vu, (h - lo_v) / vu, (V - h) / vu
    segs: list[Seg] = []
    try:
        w, tju, tau, tc, tjd, tad = _scurve.scurve(Ds, hs, ls, gs, wvs, v0_high)
    except _scurve.Infeasible:
        try:
            u, tjd, tad, tju, tau = _scurve.valley(Ds, hs, ls, gs, v0_high)
        except _scurve.Infeasible as e:
            raise _scurve.Infeasible(e.d_min * du) from None
        # valley: down from v0 to min(v0, v1) - u, up to v1
        vv = max(lo_v - u * vu, 0.0)
        p, _ = ramp_up(segs, 0.0, v0, tjd * tu, tad * tu, J, -1.0)
        segs.append(Seg(0.0, p, vv, 0.0, 0.0))
        ramp_into(segs, D, v1, tju * tu, tau * tu, J, 1.0)
        return Profile("scurve", segs, (D, v1), v_max=V, a_max=A, j_max=J, tau=None, v_peak=h)
    tju, tau, tc, tjd, tad = tju * tu, tau * tu, tc * tu, tjd * tu, tad * tu
    vp = V if tc > 0.0 or w >= wvs else min(h + w * vu, V)  # w == wvs: the cruise regime
    p, _ = ramp_up(segs, 0.0, v0, tju, tau, J, 1.0)
    segs.append(Seg(tc, p, vp, 0.0, 0.0))
    ramp_into(segs, D, v1, tjd, tad, J, -1.0)
    return Profile("scurve", segs, (D, v1), v_max=V, a_max=A, j_max=J, tau=None, v_peak=vp)
