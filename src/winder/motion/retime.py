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
closed form except the exponential ramp's planner (as in :func:`plan`). Each
ramp owns its stop and its continuation
(:class:`winder.motion.ramps.base.Ramp`); this module cuts the move and asks
the move's ramp.
"""

from __future__ import annotations

from winder.motion.profile import EXP_CUT, Profile, plan
from winder.motion.shaped import Motion, ShapedProfile, base_of, shaped_like

__all__ = ["continue_tail", "from_rest", "motion_state", "stop_tail"]


def motion_state(profile: Motion, t: float) -> tuple[float, float, float]:
    """Position, velocity and acceleration of ``profile`` at ``t`` (s); at its
    start the acceleration it starts with (a tail may start accelerating)."""
    if isinstance(profile, ShapedProfile):  # it starts at rest, with the first impulse's share
        p, v, a, _ = profile.sample(max(t, 0.0))
        return float(p), float(v), float(a)
    if t <= 0.0:
        segs = profile.segments
        return 0.0, profile.v_start, float(segs[0].a0) if segs else 0.0
    p, v, a, _ = profile.sample(t)
    return float(p), float(v), float(a)


def stop_tail(motion: Motion, t: float, *, exp_cut: float = EXP_CUT) -> Profile:
    """The time-optimal stop from the state of ``motion`` at ``t`` (s) to its
    end velocity; positions from the cut (0), ``distance`` is the stop
    distance, ``duration`` the stop time. A shaped move stops from its
    (shaped) state with its ramp's limits, unshaped: at once."""
    _, v, a = motion_state(motion, t)
    profile = base_of(motion)
    return profile.ramp.stop(profile, v, a, exp_cut)


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
    if not distance > 0.0 or v_max < profile.v_end:
        return None
    return profile.ramp.continuation(profile, v, a, distance, v_max, exp_cut)
