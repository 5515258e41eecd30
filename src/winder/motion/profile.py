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
    :mod:`winder._scurve`; limits of any magnitude (a jerk of 1e9 with
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

Every profile is a list of phases; inside a phase position is a cubic in time
(or, for the exponential, ``v`` relaxes toward an asymptote), evaluated relative
to the phase start (falling exponentials: to its end), so that durations of
1e6 s and more stay exact. Positions are non-decreasing everywhere, also
across phase boundaries where rounding would otherwise leave an ulp of overlap.
"""

from __future__ import annotations

import math
import numbers
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from winder.motion import _scurve

__all__ = ["EXP_CUT", "KINDS", "LIMITS", "Jog", "Phase", "Profile", "jog", "plan"]

#: The ramp kinds and the limits each one uses (its :func:`plan` keywords beside
#: the distance and the speeds): the one list of kinds the node settings, the
#: segment planner and the analysis read.
LIMITS: dict[str, tuple[str, ...]] = {
    "scurve": ("a_max", "j_max"),
    "trapezoid": ("a_max",),
    "exponential": ("tau",),
}
KINDS = tuple(LIMITS)
EXP_CUT = 0.01
"""Default truncation of the exponential ramp: the fraction of the velocity
change the plain exponential would still lack at the cut (``ln(1/EXP_CUT)``
time constants)."""

_CHUNK = 1 << 15  # elements per pass when inverting steps: stays in L2 cache
_POLY, _EXP_UP, _EXP_DOWN = 0, 1, 2  # phase laws; exponential phases keep in slot 6 the
# velocity still to go toward the asymptote, at the start (rising) or the end (falling)

F64 = NDArray[np.float64]


class Phase(NamedTuple):
    """One segment of a profile: start time, duration and its law.

    ``law`` is the constant jerk (a float) of a polynomial phase, or
    ``"exp-up"`` / ``"exp-down"`` for the exponential ramps."""

    t_start: float
    duration: float
    law: float | str


# --------------------------------------------------------------------------- validation


def _bad(name: str, value: object, allowed: str) -> ValueError:
    return ValueError(f"{name}={value!r} is invalid: must be {allowed}")


def _real(name: str, x: object, allowed: str) -> float:
    tx = type(x)
    if tx is float or tx is int:
        v = float(x)  # type: ignore[arg-type]
    elif isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_)):
        v = float(x)
    else:
        raise _bad(name, x, allowed)
    if not math.isfinite(v):
        raise _bad(name, x, allowed)
    return v


def _positive(name: str, x: object) -> float:
    allowed = "a finite number > 0"
    v = _real(name, x, allowed)
    if not v > 0.0:
        raise _bad(name, x, allowed)
    return v


def _speed(name: str, x: object, v_max: float | None) -> float:
    allowed = "a finite number >= 0" if v_max is None else f"a finite number in [0, v_max={v_max!r}]"
    v = _real(name, x, allowed)
    if v < 0.0 or (v_max is not None and v > v_max):
        raise _bad(name, x, allowed)
    return v


def _needed(name: str, x: float | None, kind: str) -> float:
    if x is None:
        raise ValueError(f"{name}=None is invalid: kind={kind!r} needs a finite number > 0")
    return x


# --------------------------------------------------------------------------- profiles


class Profile:
    """A planned motion: phases of constant jerk (or exponential ramps).

    Attributes: ``kind``, ``distance``, ``duration`` (s), ``v_start``,
    ``v_end``, ``v_peak`` (highest velocity reached), ``v_max``, ``a_max``,
    ``j_max``, ``tau`` (the limits it was planned with, ``None`` if unused),
    ``phases`` (list of :class:`Phase`) and ``t_stop`` (for a stopped jog: when
    the stop began). Built by :func:`plan` and :meth:`Jog.stop`.
    """

    __slots__ = (
        "_arr",
        "_segs",
        "_t0",
        "a_max",
        "distance",
        "duration",
        "j_max",
        "kind",
        "t_stop",
        "tau",
        "v_end",
        "v_max",
        "v_peak",
        "v_start",
    )

    def __init__(
        self,
        kind: str,
        segs: list[tuple[float, ...]],
        end: tuple[float, float],
        *,
        v_max: float | None,
        a_max: float | None,
        j_max: float | None,
        tau: float | None,
        v_peak: float,
        t_stop: float | None = None,
    ) -> None:
        # segs: (T, p0, v0, a0, j, law, v_inf, tau); end: (position, velocity) at the end.
        # Phases built forward (acceleration) and backward (deceleration, so the
        # end is exact) may overlap by an ulp where they meet: keep the phase
        # start positions non-decreasing (and in [0, end]) so that sampled
        # positions are monotone.
        lo = 0.0
        for i in range(len(segs)):
            if segs[i][1] < lo:
                segs[i] = (segs[i][0], lo, *segs[i][2:])
            lo = segs[i][1]
        hi = end[0]
        for i in range(len(segs) - 1, -1, -1):
            if segs[i][1] > hi:
                segs[i] = (segs[i][0], hi, *segs[i][2:])
            hi = segs[i][1]
        self.kind = kind
        self._segs = segs
        t0 = [0.0] * len(segs)
        t = 0.0
        for i, s in enumerate(segs):
            t0[i] = t
            t = t + s[0]
        self._t0 = t0
        self.duration = t
        self.distance = end[0]
        self.v_start = segs[0][2] if segs else end[1]
        self.v_end = end[1]
        self.v_peak = v_peak
        self.v_max = v_max
        self.a_max = a_max
        self.j_max = j_max
        self.tau = tau
        self.t_stop = t_stop
        self._arr: dict[str, Any] | None = None

    def __repr__(self) -> str:
        return (
            f"Profile(kind={self.kind!r}, distance={self.distance!r}, duration={self.duration!r}, "
            f"v_start={self.v_start!r}, v_peak={self.v_peak!r}, v_end={self.v_end!r})"
        )

    @property
    def phases(self) -> list[Phase]:
        """The segments as ``(t_start, duration, jerk or "exp-up"/"exp-down")``."""
        out = []
        for t0, s in zip(self._t0, self._segs, strict=True):
            law: float | str = s[4]
            if s[5] != _POLY:
                law = "exp-up" if s[5] == _EXP_UP else "exp-down"
            out.append(Phase(t0, s[0], law))
        return out

    @property
    def limits(self) -> dict[str, float | None]:
        """The limits the profile was planned with."""
        return {"v_max": self.v_max, "a_max": self.a_max, "j_max": self.j_max, "tau": self.tau}

    # ------------------------------------------------------------------ arrays

    def _arrays(self) -> dict[str, Any]:
        if self._arr is None:
            segs = self._segs
            n = len(segs)
            a = np.array(segs, dtype=np.float64).reshape(n, 8)
            t0 = np.array(self._t0, dtype=np.float64)
            # end state of each phase: the next one's start state (the last: the end)
            p1 = np.append(a[1:, 1], self.distance)
            v1 = np.append(a[1:, 2], self.v_end)
            t1 = np.append(t0[1:], self.duration)
            self._arr = {
                "t0": t0, "t1": t1, "T": a[:, 0], "p0": a[:, 1], "v0": a[:, 2], "a0": a[:, 3],
                "j": a[:, 4], "exp": a[:, 5] != _POLY, "law": a[:, 5], "b": a[:, 6], "tau": a[:, 7],
                "p1": p1, "v1": v1, "a1": np.append(a[1:, 3], 0.0),
                "v_hi": max(self.v_peak, self.v_start, self.v_end),
            }  # fmt: skip
        return self._arr

    # ------------------------------------------------------------------ sampling

    def sample(self, t: ArrayLike) -> tuple[F64, F64, F64, F64]:
        """Position, velocity, acceleration and jerk at the times ``t`` (s).

        Up to 0 the start state (position 0, ``v_start``, no acceleration; the
        jerk at exactly 0 is the first phase's), from ``duration`` on the end
        state (``distance``, ``v_end``). Arrays have the shape of ``t``; inside
        a phase the values are right-continuous at its start."""
        ta = np.asarray(t, dtype=np.float64)
        if np.isnan(ta).any():
            raise ValueError("t contains NaN: sample times must be numbers")
        A = self._arrays()
        tf = ta.reshape(-1)
        i = np.searchsorted(A["t0"], tf, side="right") - 1
        np.clip(i, 0, len(self._segs) - 1, out=i)
        tau = tf - A["t0"][i]
        np.clip(tau, 0.0, A["T"][i], out=tau)  # outside [0, duration]: overwritten below
        v0, a0, j = A["v0"][i], A["a0"][i], A["j"][i]
        p = A["p0"][i] + tau * (v0 + tau * (0.5 * a0 + tau * (j / 6.0)))
        v = v0 + tau * (a0 + 0.5 * tau * j)
        acc = a0 + tau * j
        jerk = j.copy()
        ex = A["exp"][i]
        if ex.any():
            k = np.flatnonzero(ex)
            ie = i[k]
            tc, b = A["tau"][ie], A["b"][ie]
            up = A["law"][ie] == _EXP_UP
            # rising: from the start, v = v0 + b (1 - e^-x); falling: from the end,
            # v = v1 + b (e^y - 1) with y the time left (units of tau)
            y = np.where(up, -tau[k], A["T"][ie] - tau[k]) / tc
            vr = np.where(up, A["v0"][ie], A["v1"][ie])
            e = np.exp(y)
            dp = tc * (vr * np.abs(y) + b * _phi(y))
            p[k] = np.where(up, A["p0"][ie] + dp, A["p1"][ie] - dp)
            v[k] = vr + b * np.where(up, -np.expm1(y), np.expm1(y))
            acc[k] = np.where(up, b, -b) / tc * e
            jerk[k] = -acc[k] / tc
        # rounding guards: positions monotone across phases, no limit exceeded by an ulp
        np.clip(p, A["p0"][i], A["p1"][i], out=p)
        np.clip(v, 0.0, A["v_hi"], out=v)
        if self.a_max is not None and self.kind != "exponential":
            np.clip(acc, -self.a_max, self.a_max, out=acc)
        # the boundary states exactly (at t = 0 the jerk is that of the first phase)
        before = tf <= 0.0
        after = tf >= self.duration
        p[before], v[before], acc[before] = 0.0, self.v_start, 0.0
        jerk[tf < 0.0] = 0.0
        p[after], v[after], acc[after], jerk[after] = self.distance, self.v_end, 0.0, 0.0
        shape = ta.shape
        return p.reshape(shape), v.reshape(shape), acc.reshape(shape), jerk.reshape(shape)

    # ------------------------------------------------------------------ step timing

    def step_times(self, n: int) -> F64:
        """The ``n`` times at which the position reaches ``k * distance / n``, k = 1..n.

        Each phase's polynomial is inverted in closed form relative to the
        phase end where its acceleration is zero (cubics: ``2 c sinh(asinh(r)/3)``
        or ``2 c sin(asin(r)/3)``; quadratics and cruises: stable
        rationalised forms); exponential phases by a few vectorised Newton
        steps that converge monotonically (convex in the reference time).
        No sampling, no accumulation: every time has only the rounding error
        of its own target ``k * distance / n`` (about 1 ulp of position) mapped
        through the local velocity. The last time is ``duration`` exactly.
        The result is non-decreasing, and strictly increasing as long as
        consecutive step times are more than one float64 ulp apart: near
        t = 1e6 s that ulp is about 1.2e-10 s, so steps closer than that
        (e.g. > 8e9 steps/s) collapse onto the same representable time.
        A step position that is reached at a phase boundary gets the earliest
        time it is reached.
        """
        if isinstance(n, (bool, np.bool_)) or not isinstance(n, (numbers.Integral)) or n < 1:
            raise _bad("n", n, "an integer >= 1")
        n = int(n)
        D = self.distance
        if not (D > 0.0 and math.isfinite(D)):
            raise ValueError(f"distance={D!r}: the motion covers no distance, it has no steps")
        out = np.arange(1, n + 1, dtype=np.float64)
        out *= D
        out /= n
        out[-1] = D
        self._invert(out)
        out[-1] = self.duration
        return out

    def times_at(self, positions: ArrayLike) -> F64:
        """The first times (s) at which the position reaches each of ``positions``,
        which must be non-decreasing and within [0, distance]."""
        x = np.array(positions, dtype=np.float64, copy=True).reshape(-1)
        if x.size:
            if not (np.all(np.diff(x) >= 0.0) and x[0] >= 0.0 and x[-1] <= self.distance):
                raise ValueError(
                    f"positions must be non-decreasing numbers in [0, distance={self.distance!r}]"
                )
            self._invert(x)
        return x

    def _invert(self, x: F64) -> None:
        """Replace sorted positions ``x`` (in [0, distance]) by their times, in place."""
        A = self._arrays()
        # positions in (p0_i, p1_i] belong to phase i; position 0 to time 0
        start = int(np.searchsorted(x, 0.0, side="right"))
        x[:start] = 0.0
        ends = np.searchsorted(x, A["p1"], side="right")
        for i in range(len(self._segs)):
            lo, hi = start, int(ends[i])
            start = max(start, hi)
            if hi <= lo:
                continue
            for c in range(lo, hi, _CHUNK):
                _invert_phase(A, i, x[c : min(c + _CHUNK, hi)])


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


def _invert_phase(A: dict[str, Any], i: int, x: F64) -> None:
    """Times (in place) at which phase ``i`` reaches the positions ``x``."""
    t0, t1, T = float(A["t0"][i]), float(A["t1"][i]), float(A["T"][i])
    p0, v0, a0, j = float(A["p0"][i]), float(A["v0"][i]), float(A["a0"][i]), float(A["j"][i])
    p1, v1 = float(A["p1"][i]), float(A["v1"][i])
    if T == 0.0:  # an ulp of position left between two phases built from either end
        x.fill(t0)
    elif A["exp"][i]:
        up = A["law"][i] == _EXP_UP
        _invert_exp(x, t0, t1, p0, v0, p1, v1, float(A["b"][i]), float(A["tau"][i]), bool(up))
    elif j == 0.0 and a0 == 0.0:  # cruise
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
        a1 = float(A["a1"][i])
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
    np.clip(x, t0, t1, out=x)


def _stable_quadratic(d: F64, v: float, a: float) -> None:
    """In place: the root ``s >= 0`` of ``v s + a s^2 / 2 = d`` (a > 0)."""
    r = d * (2.0 * a)
    r += v * v
    np.sqrt(r, out=r)
    r += v
    d *= 2.0
    np.divide(d, r, out=d, where=r > 0.0)


def _odd_cubic(d: F64, vz: float, j: float) -> None:
    """In place: the smallest root ``s >= 0`` of ``vz s + j s^3 / 6 = d`` (d >= 0).

    j > 0: ``s = 2c sinh(asinh(r)/3)``; j < 0: ``s = 2c sin(asin(r)/3)`` with
    ``c = sqrt(2 vz/|j|)``, ``r = 3 d / (|j| c^3)`` - no cancellation anywhere,
    and ``s ~ d/vz`` for small d keeps full relative precision."""
    c = math.sqrt(2.0 * vz / abs(j)) if vz > 0.0 else 0.0
    c3j = abs(j) * c * c * c
    scale = 3.0 / c3j if c3j > 0.0 else math.inf
    if not scale < 1e300:  # from rest (or a negligible vz): j s^3 / 6 = d
        d *= 6.0 / abs(j)
        np.cbrt(d, out=d)
        return
    d *= scale
    if j > 0.0:
        np.arcsinh(d, out=d)
        d *= 1.0 / 3.0
        np.sinh(d, out=d)
    else:
        np.minimum(d, 1.0, out=d)
        np.arcsin(d, out=d)
        d *= 1.0 / 3.0
        np.sin(d, out=d)
    d *= 2.0 * c


def _invert_exp(
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


# --------------------------------------------------------------------------- builders


def _ramp_up(
    segs: list[tuple[float, ...]], p: float, v: float, tj: float, ta: float, J: float, sgn: float
) -> tuple[float, float]:
    """Append the 3 phases of a zero-to-zero acceleration ramp (sgn +1 up, -1 down)
    starting at position p with velocity v; return the end position and velocity."""
    a = sgn * J * tj
    js = sgn * J
    segs.append((tj, p, v, 0.0, js, _POLY, 0.0, 0.0))
    p = p + tj * (v + tj * tj * js / 6.0)
    v = v + 0.5 * js * tj * tj
    segs.append((ta, p, v, a, 0.0, _POLY, 0.0, 0.0))
    p = p + ta * (v + 0.5 * a * ta)
    v = v + a * ta
    segs.append((tj, p, v, a, -js, _POLY, 0.0, 0.0))
    p = p + tj * (v + tj * (0.5 * a - tj * js / 6.0))
    v = v + tj * (a - 0.5 * js * tj)
    return p, v


def _ramp_into(D: float, v1: float, tj: float, ta: float, J: float, sgn: float) -> list[tuple[float, ...]]:
    """The 3 phases of a zero-to-zero acceleration ramp ending at position D with
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
    return [
        (tj, p1, v1s, 0.0, js, _POLY, 0.0, 0.0),
        (ta, p2, v2, a, 0.0, _POLY, 0.0, 0.0),
        (tj, p3, v3, a, -js, _POLY, 0.0, 0.0),
    ]


def _plan_scurve(D: float, v0: float, v1: float, V: float, A: float, J: float) -> Profile:
    tu = A / J  # unit time, velocity, distance of the limits
    vu = A * tu
    du = vu * tu
    # differences before scaling, so that a gap of one ulp survives it
    v0_high = v0 >= v1
    h, lo_v = (v0, v1) if v0_high else (v1, v0)
    Ds, hs, ls, gs, wvs = D / du, h / vu, lo_v / vu, (h - lo_v) / vu, (V - h) / vu
    segs: list[tuple[float, ...]] = []
    try:
        w, tju, tau, tc, tjd, tad = _scurve.scurve(Ds, hs, ls, gs, wvs, v0_high)
    except _scurve.Infeasible:
        try:
            u, tjd, tad, tju, tau = _scurve.valley(Ds, hs, ls, gs, v0_high)
        except _scurve.Infeasible as e:
            raise _scurve.Infeasible(e.d_min * du) from None
        # valley: down from v0 to min(v0, v1) - u, up to v1
        vv = max(lo_v - u * vu, 0.0)
        p, _ = _ramp_up(segs, 0.0, v0, tjd * tu, tad * tu, J, -1.0)
        segs.append((0.0, p, vv, 0.0, 0.0, _POLY, 0.0, 0.0))
        segs += _ramp_into(D, v1, tju * tu, tau * tu, J, 1.0)
        return Profile("scurve", segs, (D, v1), v_max=V, a_max=A, j_max=J, tau=None, v_peak=h)
    tju, tau, tc, tjd, tad = tju * tu, tau * tu, tc * tu, tjd * tu, tad * tu
    vp = V if tc > 0.0 or w >= wvs else min(h + w * vu, V)  # w == wvs: the cruise regime
    p, _ = _ramp_up(segs, 0.0, v0, tju, tau, J, 1.0)
    segs.append((tc, p, vp, 0.0, 0.0, _POLY, 0.0, 0.0))
    segs += _ramp_into(D, v1, tjd, tad, J, -1.0)
    return Profile("scurve", segs, (D, v1), v_max=V, a_max=A, j_max=J, tau=None, v_peak=vp)


def _plan_trapezoid(D: float, v0: float, v1: float, V: float, A: float) -> Profile:
    vp, tu, tc, td = _scurve.trapezoid(D, v0, v1, V, A)
    segs: list[tuple[float, ...]] = [(tu, 0.0, v0, A, 0.0, _POLY, 0.0, 0.0)]
    p = tu * (v0 + 0.5 * A * tu)
    segs.append((tc, p, vp, 0.0, 0.0, _POLY, 0.0, 0.0))
    pd = D - td * (v1 + 0.5 * A * td)
    segs.append((td, pd, v1 + A * td, -A, 0.0, _POLY, 0.0, 0.0))
    return Profile("trapezoid", segs, (D, v1), v_max=V, a_max=A, j_max=None, tau=None, v_peak=vp)


def _phi1(x: float) -> float:
    """Scalar ``expm1(x) - x`` without cancellation."""
    if abs(x) >= 0.5:
        return math.expm1(x) - x
    acc = 1.0 / math.factorial(17)
    for k in range(16, 1, -1):
        acc = acc * x + 1.0 / math.factorial(k)
    return acc * x * x


def _plan_exponential(D: float, v0: float, v1: float, V: float, tau: float, eps: float) -> Profile:
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
        if d_min * (1.0 - _scurve.SNAP) > D:
            raise _scurve.Infeasible(d_min)
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

            yd = _scurve._polish(f, yd_of(du_g - gap), yd_of(h_d), cut)
            dd_v = min(bd * math.expm1(yd), V - v1)
            yu = yu_of(dd_v + gap)
            vp = min(v1 + dd_v, V)
        else:

            def f(y: float) -> tuple[float, float]:
                du_v = -bu * math.expm1(-y)
                dd_v = du_v - gap
                v = v0 + du_v
                return d_up(y) + d_dn(yd_of(dd_v)) - D, tau * v * (1.0 + (bu - du_v) / (bd + dd_v))

            yu = _scurve._polish(f, yu_of(du_g), yu_of(h_u), cut)
            du_v = min(-bu * math.expm1(-yu), V - v0)
            yd = yd_of(du_v - gap)
            vp = min(v0 + du_v, V)
        tc = max(D - d_up(yu) - d_dn(yd), 0.0) / vp  # the rounding residue, as a cruise
    tu, td = tau * yu, tau * yd
    du, dd = d_up(yu), d_dn(yd)
    segs: list[tuple[float, ...]] = [(tu, 0.0, v0, bu / tau, -bu / tau**2, _EXP_UP, bu, tau)]
    segs.append((tc, du, vp, 0.0, 0.0, _POLY, 0.0, 0.0))
    a_dn = -(bd + (vp - v1)) / tau  # at the start of the falling curve
    segs.append((td, D - dd, vp, a_dn, -a_dn / tau, _EXP_DOWN, bd, tau))
    return Profile("exponential", segs, (D, v1), v_max=V, a_max=None, j_max=None, tau=tau, v_peak=vp)


# --------------------------------------------------------------------------- public API


def plan(
    kind: str,
    distance: float,
    *,
    v_max: float,
    a_max: float | None = None,
    j_max: float | None = None,
    tau: float | None = None,
    v_start: float = 0.0,
    v_end: float = 0.0,
    exp_cut: float = EXP_CUT,
) -> Profile:
    """Plan a monotone point-to-point move of ``distance`` (> 0).

    ``kind`` is ``"scurve"`` (needs ``a_max`` and ``j_max``), ``"trapezoid"``
    (needs ``a_max``) or ``"exponential"`` (needs ``tau``, the time constant;
    ``exp_cut`` in (0, 0.5] sets where it is truncated, see the module doc).
    Limits a kind does not use are checked but ignored. ``v_start`` and
    ``v_end`` must lie in [0, v_max]; boundary accelerations are zero.

    Raises :class:`ValueError` naming the parameter, its value and the
    allowed range; or, when no monotone move of that length joins ``v_start``
    and ``v_end``, naming the minimum distance.
    """
    if kind not in KINDS:
        raise _bad("kind", kind, "one of 'scurve', 'trapezoid', 'exponential'")
    D = _positive("distance", distance)
    V = _positive("v_max", v_max)
    v0 = _speed("v_start", v_start, V)
    v1 = _speed("v_end", v_end, V)
    A = None if a_max is None else _positive("a_max", a_max)
    J = None if j_max is None else _positive("j_max", j_max)
    tc = None if tau is None else _positive("tau", tau)
    try:
        if kind == "scurve":
            return _plan_scurve(D, v0, v1, V, _needed("a_max", A, kind), _needed("j_max", J, kind))
        if kind == "trapezoid":
            return _plan_trapezoid(D, v0, v1, V, _needed("a_max", A, kind))
        eps = _real("exp_cut", exp_cut, "a finite number in (0, 0.5]")
        if not 0.0 < eps <= 0.5:
            raise _bad("exp_cut", exp_cut, "a finite number in (0, 0.5]")
        return _plan_exponential(D, v0, v1, V, _needed("tau", tc, kind), eps)
    except _scurve.Infeasible as e:
        lim = ", ".join(f"{k}={x!r}" for k, x in (("a_max", A), ("j_max", J), ("tau", tc)) if x)
        raise ValueError(
            f"distance={distance!r} is invalid: too short for v_start={v0!r} -> v_end={v1!r} "
            f"({kind}, {lim}); a monotone move needs distance >= {e.d_min!r}"
        ) from None


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
        segs: list[tuple[float, ...]] = []
        if dv != 0.0 and j_max is not None:
            tu = a_max / j_max
            tj, ta = _scurve.ramp(abs(dv) / (a_max * tu))
            if sgn > 0:
                p, _ = _ramp_up(segs, 0.0, v_start, tj * tu, ta * tu, j_max, 1.0)
            else:
                p, _ = _ramp_up(segs, 0.0, v_start, tj * tu, ta * tu, j_max, -1.0)
        elif dv != 0.0:
            T = abs(dv) / a_max
            segs.append((T, 0.0, v_start, sgn * a_max, 0.0, _POLY, 0.0, 0.0))
            p = T * 0.5 * (v_start + v_target)
        else:
            p = 0.0
        self.ramp_duration = sum(s[0] for s in segs)
        segs.append((math.inf, p, v_target, 0.0, 0.0, _POLY, 0.0, 0.0))
        kind = "jog"
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
        ts = _real("t_stop", t_stop, "a finite number >= 0")
        if ts < 0.0:
            raise _bad("t_stop", t_stop, "a finite number >= 0")
        pr = self._profile
        A, J = self.a_max, self.j_max
        segs: list[tuple[float, ...]] = []
        for t0, s in zip(pr._t0, pr._segs, strict=True):
            if t0 >= ts:
                break
            segs.append((min(s[0], ts - t0), *s[1:]))
        pp, vv, aa, _ = (float(q) for q in pr.sample(ts))
        if ts <= 0.0:
            pp, vv, aa = 0.0, self.v_start, 0.0
        if J is None:
            T = vv / A
            segs.append((T, pp, vv, -A, 0.0, _POLY, 0.0, 0.0))
            end = pp + 0.5 * vv * T
        else:
            p, v, a = pp, vv, aa
            if a > 0.0:  # jerk -J until the acceleration is 0
                t1 = a / J
                segs.append((t1, p, v, a, -J, _POLY, 0.0, 0.0))
                p = p + t1 * (v + t1 * (0.5 * a - J * t1 / 6.0))
                v = v + 0.5 * a * t1
                a = 0.0
            vz = v + a * a / (2.0 * J)  # velocity where a virtual zero-acceleration start was
            ap = max(min(A, math.sqrt(J) * math.sqrt(vz)), -a)  # no underflow of J vz
            t1 = (ap + a) / J
            ta = max((vz - ap * ap / J) / ap, 0.0) if ap > 0.0 else 0.0
            segs.append((t1, p, v, a, -J, _POLY, 0.0, 0.0))
            p = p + t1 * (v + t1 * (0.5 * a - J * t1 / 6.0))
            v = v + t1 * (a - 0.5 * J * t1)
            segs.append((ta, p, v, -ap, 0.0, _POLY, 0.0, 0.0))
            p = p + ta * (v - 0.5 * ap * ta)
            v = v - ap * ta
            t3 = ap / J
            segs.append((t3, p, v, -ap, J, _POLY, 0.0, 0.0))
            end = p + t3 * (v + t3 * (-0.5 * ap + J * t3 / 6.0))
        if vv <= 0.0 and aa == 0.0:
            end = pp
        return Profile(
            "jog", segs, (end, 0.0), v_max=pr.v_max, a_max=A, j_max=J, tau=None,
            v_peak=pr.v_peak, t_stop=ts,
        )  # fmt: skip


def jog(v_target: float, *, a_max: float, j_max: float | None = None, v_start: float = 0.0) -> Jog:
    """Velocity (jog) mode: ramp to ``v_target`` (>= 0) and hold until :meth:`Jog.stop`.

    S-curve ramp if ``j_max`` is given, else trapezoidal."""
    vt = _speed("v_target", v_target, None)
    A = _positive("a_max", a_max)
    J = None if j_max is None else _positive("j_max", j_max)
    v0 = _speed("v_start", v_start, None)
    return Jog(vt, A, J, v0)
