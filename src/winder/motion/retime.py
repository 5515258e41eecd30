"""Changing a planned move while it runs: feed hold, resume and feed override.

A move planned by :func:`winder.motion.profile.plan` can be cut at any time
``t`` of its motion and continued otherwise from the state it is in there
(position, velocity, acceleration; mid S-curve included):

* :func:`stop_tail` - the time-optimal stop from that state: with a jerk limit
  the acceleration goes with jerk ``-j_max`` to ``-a_p`` (through zero if it
  was accelerating), holds, and returns to zero exactly when the velocity is
  the move's end velocity (the start/stop rate, below which a stepper stops at
  once); ``a_p = min(a_max, sqrt(j_max dv + a^2/2))``. Without a jerk limit
  (trapezoid) it decelerates at ``-a_max`` at once. The exponential ramp
  leaves the motion for its own falling curve at the current velocity (the
  acceleration steps there, as at every corner of that ramp). The stop covers
  the least distance any motion within the limits can, and no motion on the
  planned move needs more than what is left of it.
* :func:`continue_tail` - the rest of the move with another ``v_max`` (a feed
  override): first the time-optimal change of velocity to the new ``v_max``
  (or, when that leaves too little distance, to the velocity where the
  acceleration is zero soonest), then a planned move from there to the end,
  time-optimal as :func:`plan` is. None when no such continuation fits in what
  is left (the move is already braking for its end: it keeps its plan).
* :func:`from_rest` - the rest of a move after a stop, planned from rest.

Tails start at position 0 and time 0 (the cut); the caller places them. All in
closed form except the exponential ramp's planner (as in :func:`plan`).
"""

from __future__ import annotations

import math

from winder.motion.profile import _EXP_DOWN, _POLY, EXP_CUT, Profile, _phi1, plan
from winder.motion.shaped import Motion, ShapedProfile, base_of, shaped_like

__all__ = ["continue_tail", "from_rest", "motion_state", "stop_tail"]

_Seg = tuple[float, ...]


def motion_state(profile: Motion, t: float) -> tuple[float, float, float]:
    """Position, velocity and acceleration of ``profile`` at ``t`` (s); at its
    start the acceleration it starts with (a tail may start accelerating)."""
    if isinstance(profile, ShapedProfile):  # it starts at rest, with the first impulse's share
        p, v, a, _ = profile.sample(max(t, 0.0))
        return float(p), float(v), float(a)
    if t <= 0.0:
        return 0.0, profile.v_start, float(profile._segs[0][3]) if profile._segs else 0.0
    p, v, a, _ = profile.sample(t)
    return float(p), float(v), float(a)


def _change(segs: list[_Seg], p: float, v: float, a: float, v1: float, A: float, J: float | None) -> float:
    """Append the time-optimal change from velocity ``v`` and acceleration
    ``a`` to velocity ``v1`` at zero acceleration (|a| <= A, |jerk| <= J; no J:
    the acceleration steps); return the end position."""
    if J is None:
        if v1 != v:
            T = abs(v1 - v) / A
            segs.append((T, p, v, math.copysign(A, v1 - v), 0.0, _POLY, 0.0, 0.0))
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
                segs.append((part, p, v, a, jerk, _POLY, 0.0, 0.0))
                p += part * (v + part * (0.5 * a + part * jerk / 6.0))
                v += part * (a + 0.5 * part * jerk)
                a = 0.0 if part == cross and cross < T else a + part * jerk
    return p


def _profile(like: Profile, segs: list[_Seg], end: float, v_max: float) -> Profile:
    if not segs:  # nothing to do: a zero-length phase keeps the profile well formed
        segs = [(0.0, 0.0, like.v_end, 0.0, 0.0, _POLY, 0.0, 0.0)]
    peak = like.v_end
    for T, _, v0, a0, j, law, *_rest in segs:  # the highest velocity: at a phase start or where a = 0
        peak = max(peak, v0)
        if law == _POLY and j != 0.0 and a0 * j < 0.0 and -a0 / j < T:
            peak = max(peak, v0 - a0 * a0 / (2.0 * j))
    return Profile(
        like.kind, segs, (end, like.v_end), v_max=v_max, a_max=like.a_max, j_max=like.j_max,
        tau=like.tau, v_peak=peak,
    )  # fmt: skip


def _join(like: Profile, segs: list[_Seg], d1: float, rest: Profile, v_max: float) -> Profile:
    """The phases ``segs`` (covering ``d1``), then the planned move ``rest``."""
    out = list(segs) + [(s[0], s[1] + d1, *s[2:]) for s in rest._segs]
    return _profile(like, out, d1 + rest.distance, v_max)


def _exp_fall(like: Profile, v: float, v_to: float, v_max: float, eps: float) -> tuple[_Seg, float]:
    """The exponential ramp's falling curve (of a move with peak ``v_max``)
    from ``v`` down to ``v_to``: its phase and the distance it covers."""
    assert like.tau is not None
    v1, tau = like.v_end, like.tau
    bd = (v_max - v1) / (1.0 - eps) * eps  # v1 minus the curve's asymptote
    if bd <= 0.0 or v <= v_to:
        return (0.0, 0.0, v, 0.0, 0.0, _POLY, 0.0, 0.0), 0.0
    ya, yb = math.log1p((v - v1) / bd), math.log1p((v_to - v1) / bd)  # time left to v1, in tau
    dist = tau * (v1 * (ya - yb) + bd * (_phi1(ya) - _phi1(yb)))
    b = bd + (v_to - v1)  # the phase ends at v_to: what is left toward the asymptote there
    a0 = -(bd + (v - v1)) / tau
    return (tau * (ya - yb), 0.0, v, a0, -a0 / tau, _EXP_DOWN, b, tau), dist


def stop_tail(motion: Motion, t: float, *, exp_cut: float = EXP_CUT) -> Profile:
    """The time-optimal stop from the state of ``motion`` at ``t`` (s) to its
    end velocity; positions from the cut (0), ``distance`` is the stop
    distance, ``duration`` the stop time. A shaped move stops from its
    (shaped) state with its ramp's limits, unshaped: at once."""
    _, v, a = motion_state(motion, t)
    profile = base_of(motion)
    v1 = profile.v_end
    if profile.kind == "exponential":
        seg, dist = _exp_fall(profile, v, v1, float(profile.v_max or v), exp_cut)
        return _profile(profile, [seg], dist, float(profile.v_max or v))
    assert profile.a_max is not None
    segs: list[_Seg] = []
    end = _change(segs, 0.0, v, a, v1, profile.a_max, profile.j_max)
    return _profile(profile, segs, max(end, 0.0), float(profile.v_max or v))


def from_rest(motion: Motion, distance: float, v_max: float, *, exp_cut: float = EXP_CUT) -> Motion:
    """A move of ``distance`` from rest to rest (the start/stop rate) with
    ``motion``'s kind, limits and shaper and the peak ``v_max``."""
    profile = base_of(motion)
    return shaped_like(motion, plan(
        profile.kind, distance, v_max=v_max, a_max=profile.a_max, j_max=profile.j_max,
        tau=profile.tau, v_start=profile.v_end, v_end=profile.v_end, exp_cut=exp_cut,
    ))  # fmt: skip


def continue_tail(
    motion: Motion, t: float, distance: float, v_max: float, *, exp_cut: float = EXP_CUT
) -> Profile | None:
    """The rest of a move from the state of ``motion`` at ``t`` (s): ``distance``
    more to its end velocity, now with the peak ``v_max``; None if no
    continuation with a jerk-limited change of speed fits (keep the plan).
    From a shaped move's state the rest is unshaped."""
    _, v, a = motion_state(motion, t)
    profile = base_of(motion)
    v1 = profile.v_end
    if not distance > 0.0 or v_max < v1:
        return None
    kw = {
        "v_max": v_max,
        "a_max": profile.a_max,
        "j_max": profile.j_max,
        "tau": profile.tau,
        "exp_cut": exp_cut,
    }
    if profile.kind == "exponential":
        if v <= v_max:
            try:
                return plan("exponential", distance, v_start=v, v_end=v1, **kw)  # type: ignore[arg-type]
            except ValueError:
                return None
        seg, d1 = _exp_fall(profile, v, v_max, v_max, exp_cut)
        if not d1 < distance:
            return None
        try:
            rest = plan("exponential", distance - d1, v_start=v_max, v_end=v1, **kw)  # type: ignore[arg-type]
        except ValueError:
            return None
        return _join(profile, [seg], d1, rest, v_max)
    assert profile.a_max is not None
    J = profile.j_max
    v_nat = v + a * abs(a) / (2.0 * J) if J is not None else v
    targets = [v_max] if v_nat > v_max else [v_max, v_nat]
    for vt in targets:
        segs: list[_Seg] = []
        d1 = _change(segs, 0.0, v, a, vt, profile.a_max, J)
        if not d1 < distance:
            continue
        try:
            rest = plan(profile.kind, distance - d1, v_start=min(vt, v_max), v_end=v1, **kw)  # type: ignore[arg-type]
        except ValueError:
            continue
        return _join(profile, segs, d1, rest, v_max)
    return None
