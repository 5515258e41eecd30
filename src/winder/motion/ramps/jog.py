"""Velocity (jog) mode: ramp to a target speed and hold, until stopped.

:func:`jog` ramps with the S-curve's blocks when a jerk limit is given, else
at constant acceleration, and holds the target velocity for ever;
:meth:`Jog.stop` gives the whole motion when a stop is commanded: up to then
the jog, from there the time-optimal ramp to rest from whatever state the
axis is in. Its profiles (kind ``"jog"``) are polynomial; :func:`plan`
plans no moves with it, and a jog stopped is not continued with another
speed (:meth:`JogRamp.continuation` is None).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from winder.motion.ramps import _scurve
from winder.motion.ramps._poly import PolyRamp, ramp_up
from winder.motion.ramps.base import F64, Limit, Phase, Profile, Ramp, Seg, bad, positive, real, speed


class JogRamp(PolyRamp):
    """The jog's ramp (``a_max``, ``j_max`` optional): velocity mode only."""

    name = "jog"
    rank = 9
    limits: tuple[str, ...] = ("a_max", "j_max")
    moves = False

    def plan(
        self, D: float, v0: float, v1: float, V: float, a_max: Limit, j_max: Limit, tau: Limit, exp_cut: float
    ) -> Profile:
        raise ValueError("kind='jog' plans no point-to-point moves: use jog()")

    def continuation(
        self, profile: Profile, v: float, a: float, distance: float, v_max: float, exp_cut: float
    ) -> Profile | None:
        return None


RAMP: Ramp = JogRamp()


class Jog:
    """Velocity mode: ramp from ``v_start`` to ``v_target`` and hold, until :meth:`stop`.

    ``duration`` is infinite; :meth:`sample` and :meth:`times_at` work as for
    a :class:`Profile`. ``ramp_duration`` is when the target velocity is reached.
    """

    def __init__(self, v_target: float, a_max: float, j_max: float | None, v_start: float) -> None:
        self.v_target = v_target
        self.v_start = v_start
        self.a_max = a_max
        self.j_max = j_max
        dv = v_target - v_start
        sgn = 1.0 if dv >= 0.0 else -1.0
        segs: list[Seg] = []
        if dv != 0.0 and j_max is not None:
            tu = a_max / j_max
            tj, ta = _scurve.ramp(abs(dv) / (a_max * tu))
            if sgn > 0:
                p, _ = ramp_up(segs, 0.0, v_start, tj * tu, ta * tu, j_max, 1.0)
            else:
                p, _ = ramp_up(segs, 0.0, v_start, tj * tu, ta * tu, j_max, -1.0)
        elif dv != 0.0:
            T = abs(dv) / a_max
            segs.append(Seg(T, 0.0, v_start, sgn * a_max, 0.0))
            p = T * 0.5 * (v_start + v_target)
        else:
            p = 0.0
        self.ramp_duration = sum(s.duration for s in segs)
        segs.append(Seg(math.inf, p, v_target, 0.0, 0.0))
        kind = RAMP.name
        self._profile = Profile(
            kind, segs, (math.inf if v_target > 0 else p, v_target),
            v_max=max(v_start, v_target), a_max=a_max, j_max=j_max, tau=None,
            v_peak=max(v_start, v_target),
        )  # fmt: skip

    def __repr__(self) -> str:
        return (
            f"Jog(v_target={self.v_target!r}, v_start={self.v_start!r}, a_max={self.a_max!r}, "
            f"j_max={self.j_max!r})"
        )

    @property
    def duration(self) -> float:
        """Infinite: a jog holds its velocity until stopped."""
        return math.inf

    @property
    def phases(self) -> list[Phase]:
        """The ramp phases and the final (infinite) hold."""
        return self._profile.phases

    def sample(self, t: ArrayLike) -> tuple[F64, F64, F64, F64]:
        """Position, velocity, acceleration, jerk at ``t``; before 0 the start state."""
        return self._profile.sample(t)

    def times_at(self, positions: ArrayLike) -> F64:
        """First times at which the jog reaches the (non-decreasing) positions."""
        x = np.array(positions, dtype=np.float64, copy=True).reshape(-1)
        if x.size:
            reach = self._profile.distance
            if not (np.all(np.diff(x) >= 0.0) and x[0] >= 0.0 and x[-1] <= reach):
                raise ValueError(f"positions must be non-decreasing numbers in [0, {reach!r}]")
            self._profile._invert(x)
        return x

    def stop(self, t_stop: float) -> Profile:
        """The whole motion when a stop is commanded at ``t_stop`` (s, >= 0).

        Up to ``t_stop`` it is this jog; from there the time-optimal ramp to
        rest from the state at ``t_stop``, which may be mid-ramp with non-zero
        acceleration: with a jerk limit the acceleration ``a`` first goes with
        jerk ``-j_max`` to ``-a_p`` (through 0 when ``a > 0``), holds, and
        returns to 0 exactly at zero velocity, ``a_p = min(a_max,
        sqrt(j_max v + a^2/2))`` (it never undershoots: a jog never
        decelerates so hard that ``v - a^2/(2 j_max)`` is below its target).
        Without a jerk limit it decelerates at ``-a_max`` at once. The returned
        :class:`Profile` (kind ``"jog"``, ``t_stop`` set) starts at the jog's
        t = 0 and ends at rest; its ``distance`` is where it stops.
        """
        ts = real("t_stop", t_stop, "a finite number >= 0")
        if ts < 0.0:
            raise bad("t_stop", t_stop, "a finite number >= 0")
        pr = self._profile
        A, J = self.a_max, self.j_max
        segs: list[Seg] = []
        for ph, s in zip(pr.phases, pr.segments, strict=True):
            if ph.t_start >= ts:
                break
            segs.append(s._replace(duration=min(s.duration, ts - ph.t_start)))
        pp, vv, aa, _ = (float(q) for q in pr.sample(ts))
        if ts <= 0.0:
            pp, vv, aa = 0.0, self.v_start, 0.0
        if J is None:
            T = vv / A
            segs.append(Seg(T, pp, vv, -A, 0.0))
            end = pp + 0.5 * vv * T
        else:
            p, v, a = pp, vv, aa
            if a > 0.0:  # jerk -J until the acceleration is 0
                t1 = a / J
                segs.append(Seg(t1, p, v, a, -J))
                p = p + t1 * (v + t1 * (0.5 * a - J * t1 / 6.0))
                v = v + 0.5 * a * t1
                a = 0.0
            vz = v + a * a / (2.0 * J)  # velocity where a virtual zero-acceleration start was
            ap = max(min(A, math.sqrt(J) * math.sqrt(vz)), -a)  # no underflow of J vz
            t1 = (ap + a) / J
            ta = max((vz - ap * ap / J) / ap, 0.0) if ap > 0.0 else 0.0
            segs.append(Seg(t1, p, v, a, -J))
            p = p + t1 * (v + t1 * (0.5 * a - J * t1 / 6.0))
            v = v + t1 * (a - 0.5 * J * t1)
            segs.append(Seg(ta, p, v, -ap, 0.0))
            p = p + ta * (v - 0.5 * ap * ta)
            v = v - ap * ta
            t3 = ap / J
            segs.append(Seg(t3, p, v, -ap, J))
            end = p + t3 * (v + t3 * (-0.5 * ap + J * t3 / 6.0))
        if vv <= 0.0 and aa == 0.0:
            end = pp
        return Profile(
            RAMP.name, segs, (end, 0.0), v_max=pr.v_max, a_max=A, j_max=J, tau=None,
            v_peak=pr.v_peak, t_stop=ts,
        )  # fmt: skip


def jog(v_target: float, *, a_max: float, j_max: float | None = None, v_start: float = 0.0) -> Jog:
    """Velocity (jog) mode: ramp to ``v_target`` (>= 0) and hold until :meth:`Jog.stop`.

    S-curve ramp if ``j_max`` is given, else trapezoidal."""
    vt = speed("v_target", v_target, None)
    A = positive("a_max", a_max)
    J = None if j_max is None else positive("j_max", j_max)
    v0 = speed("v_start", v_start, None)
    return Jog(vt, A, J, v0)
