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
from winder.motion.ramps.base import Limit, Profile, Ramp, Seg, needed


class ScurveRamp(PolyRamp):
    """The S-curve (``a_max``, ``j_max``)."""

    name = "scurve"
    rank = 0
    limits: tuple[str, ...] = ("a_max", "j_max")
    moves = True

    def plan(
        self, D: float, v0: float, v1: float, V: float, a_max: Limit, j_max: Limit, tau: Limit, exp_cut: float
    ) -> Profile:
        if a_max is None or j_max is None:
            needed("a_max", a_max, self.name)
            needed("j_max", j_max, self.name)
        A, J = a_max, j_max
        assert A is not None and J is not None
        tu = A / J  # unit time, velocity, distance of the limits
        vu = A * tu
        du = vu * tu
        # differences before scaling, so that a gap of one ulp survives it
        v0_high = v0 >= v1
        h, lo_v = (v0, v1) if v0_high else (v1, v0)
        Ds, hs, ls, gs, wvs = D / du, h / vu, lo_v / vu, (h - lo_v) / vu, (V - h) / vu
        try:
            w, tju, tau_u, tc, tjd, tad = _scurve.scurve(Ds, hs, ls, gs, wvs, v0_high)
        except _scurve.Infeasible:
            try:
                u, tjd, tad, tju, tau_u = _scurve.valley(Ds, hs, ls, gs, v0_high)
            except _scurve.Infeasible as e:
                raise _scurve.Infeasible(e.d_min * du) from None
            # valley: down from v0 to min(v0, v1) - u, up to v1
            vv = max(lo_v - u * vu, 0.0)
            tjd, tad, tju, tau_u = tjd * tu, tad * tu, tju * tu, tau_u * tu
            T = 0.0 + tjd + tad + tjd + 0.0 + tju + tau_u + tju  # as Profile adds the phases up
            down_up = (D, v0, v1, J, tjd, tad, vv, tju, tau_u)
            return Profile.lazy("scurve", _valley, down_up, D, v1, T, v0, h, V, A, J, None)
        tju, tau_u, tc, tjd, tad = tju * tu, tau_u * tu, tc * tu, tjd * tu, tad * tu
        vp = V if tc > 0.0 or w >= wvs else min(h + w * vu, V)  # w == wvs: the cruise regime
        T = 0.0 + tju + tau_u + tju + tc + tjd + tad + tjd
        args = (D, v0, v1, J, tju, tau_u, vp, tc, tjd, tad)
        return Profile.lazy("scurve", _hill, args, D, v1, T, v0, vp, V, A, J, None)


RAMP: Ramp = ScurveRamp()


def _hill(
    D: float,
    v0: float,
    v1: float,
    J: float,
    tju: float,
    tau: float,
    vp: float,
    tc: float,
    tjd: float,
    tad: float,
) -> list[Seg]:
    """The phases of a hill: up from v0, the cruise at vp, down to v1 (built back from D)."""
    segs: list[Seg] = []
    p, _ = ramp_up(segs, 0.0, v0, tju, tau, J, 1.0)
    segs.append(Seg(tc, p, vp, 0.0, 0.0))
    ramp_into(segs, D, v1, tjd, tad, J, -1.0)
    return segs


def _valley(
    D: float, v0: float, v1: float, J: float, tjd: float, tad: float, vv: float, tju: float, tau: float
) -> list[Seg]:
    """The phases of a valley: down from v0 to vv, the (empty) bottom, up to v1."""
    segs: list[Seg] = []
    p, _ = ramp_up(segs, 0.0, v0, tjd, tad, J, -1.0)
    segs.append(Seg(0.0, p, vv, 0.0, 0.0))
    ramp_into(segs, D, v1, tju, tau, J, 1.0)
    return segs
