"""Velocity ramping and exact step timing for one axis.

Plan a point-to-point move (:func:`plan`) or an open-ended jog (:func:`jog`),
sample it (:meth:`Profile.sample`) and get the exact times at which the axis
crosses each step (:meth:`Profile.step_times`). Units are SI or dimensionless,
consistently: distance, velocity ``/s``, acceleration ``/s^2``, jerk ``/s^3``.

Kinds of ramp (the teaching-system paper, 2014, and the stepper paper, 2012;
authors and titles in docs/THEORY.md):

``"scurve"``
    Jerk-limited, seven phases (jerk up, constant acceleration, jerk down,
    cruise, and the mirror for the deceleration); every degenerate case
    (``a_max`` or ``v_max`` not reached, short moves, ``v_start != v_end``,
    boundary velocities at ``v_max``) and time-optimal among monotone
    (``v >= 0``) motions with zero boundary accelerations. Usually a *hill*
    (up to ``v_peak``, down to ``v_end``); but with a jerk limit a move shorter
    than the direct ramp ``v_start -> v_end`` can still be possible as a
    *valley* that first dips below both speeds (then ``v_peak`` is the higher
    boundary speed and phase 4 is the zero-length bottom). Moves shorter than
    every monotone motion raise ``ValueError`` naming the minimum distance.
    The peak (or bottom) velocity comes from a closed form, see
    :mod:`winder.motion.ramps._scurve`; limits of any magnitude (a jerk of 1e9 with
    ``a_max`` 0.5, or 1e-9) give the exact curve, nothing is discretised.
``"trapezoid"``
    Acceleration-limited (T-curve). The jerk is reported as 0: it is infinite
    (a Dirac impulse) at the corners, where the acceleration steps.
``"exponential"``
    The stepper start-up ramp of paper 004, ``v = v_start + (V - v_start)(1 - e^(-t/tau))``
    up and the decaying ``e^(-t/tau)`` down. The pure exponential never
    reaches ``V``, so the ramp is *truncated* as a table-driven stepper
    controller does it: the curve aims at a slightly higher asymptote
    ``W = v_start + (V - v_start)/(1 - eps)`` and reaches ``V`` exactly after
    ``tau * ln(1/eps)`` (``eps = exp_cut``, default 1 %: 4.6 time constants).
    The velocity is continuous; the acceleration drops at the cut by
    ``eps/(1 - eps)`` of its initial value (about 1 %, a kink a stepper
    absorbs, unlike the velocity step of cutting the plain curve at 99 %).
    The deceleration is the mirror: from ``V`` toward an asymptote slightly
    below ``v_end``, reaching ``v_end`` after the same time. A short move
    follows the same two curves but leaves the rising one early, at the
    reduced peak ``vp``, and enters the falling one at ``vp`` - what a
    controller with one acceleration table does. The time spent on the
    flatter of the two curves is the root of the (increasing, transcendental)
    distance equation, found by bracketed Newton (no closed form exists); all
    of it in velocity increments, so that ramps changing the speed by 1e-7 of
    itself lose no digits. Jerk is ``-a/tau`` inside the ramps (impulses at
    the corners not reported).

Velocity (jog) mode, :func:`jog`: ramp to a target speed and hold; :meth:`Jog.stop`
gives the time-optimal ramp to rest from whatever state the axis is in then.

Each ramp is one module of :mod:`winder.motion.ramps` (planner, phase law,
stop, continuation), found by name; this module is the public face of them:
:func:`plan`, :func:`jog`, :class:`Profile`, :data:`LIMITS`, :data:`KINDS`.

Every profile is a list of phases; inside a phase position is a cubic in time
(or, for the exponential, ``v`` relaxes toward an asymptote), evaluated relative
to the phase start (falling exponentials: to its end), so that durations of
1e6 s and more stay exact. Positions are non-decreasing everywhere, also
across phase boundaries where rounding would otherwise leave an ulp of overlap.
"""

from __future__ import annotations

from winder.motion.ramps import KINDS, LIMITS
from winder.motion.ramps.base import EXP_CUT, Phase, Profile, plan
from winder.motion.ramps.jog import Jog, jog

__all__ = ["EXP_CUT", "KINDS", "LIMITS", "Jog", "Phase", "Profile", "jog", "plan"]
