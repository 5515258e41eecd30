"""What every ramp builds and what it promises: phases, :class:`Profile`, :class:`Ramp`.

A planned move is a list of phases (:class:`Seg`, a named record). Inside a
phase the motion follows the phase's *law*: the polynomial law (constant
jerk, position a cubic in time; :mod:`winder.motion.ramps._poly`) or one a
ramp brings (the exponential ramp's relaxation toward an asymptote). A law is
registered under an integer code in :data:`LAWS` and knows how to label,
sample and invert its phases; :class:`Profile` samples and times steps by
asking each phase's law, and knows nothing of the ramp kinds.

A ramp (:class:`Ramp`) is one module of :mod:`winder.motion.ramps` that
defines ``RAMP``: its planner, the time-optimal stop from any state of one of
its moves, and the continuation of a move with another peak velocity. The
package finds the modules by name and registers them in :data:`RAMPS`; the
point-to-point ones make :data:`winder.motion.profile.LIMITS`.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable
from typing import Any, NamedTuple, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from winder.errors import BadInputError
from winder.motion.ramps._scurve import Infeasible

__all__ = [
    "EXP_CUT",
    "LAWS",
    "MOVES",
    "POLY",
    "RAMPS",
    "Infeasible",
    "Limit",
    "Phase",
    "PhaseLaw",
    "Profile",
    "Ramp",
    "Seg",
    "Span",
    "join",
    "plan",
    "register",
    "tail",
]

F64 = NDArray[np.float64]

EXP_CUT = 0.01
"""Default truncation of the exponential ramp: the fraction of the velocity
change the plain exponential would still lack at the cut (``ln(1/EXP_CUT)``
time constants)."""

POLY = 0
"""Law code of a polynomial phase (constant jerk)."""

Limit = float | None
"""A limit of :func:`plan`, checked (finite, > 0), or None where not given."""

_CHUNK = 1 << 15  # elements per pass when inverting steps: stays in L2 cache
_INF = math.inf
try:  # np.clip without its Python layers (a few us a call): the same ufunc
    from numpy._core.umath import clip as _clip  # type: ignore[attr-defined]
except ImportError:  # numpy < 2
    from numpy.core.umath import clip as _clip  # type: ignore[no-redef]


class Seg(NamedTuple):
    """One phase as a ramp builds it: its duration, the position, velocity and
    acceleration at its start, its jerk, and its law (:data:`POLY` or a code a
    ramp registered; ``b`` and ``tau`` are that law's parameters: for the
    exponential, the velocity still to go toward the asymptote and the time
    constant)."""

    duration: float
    p0: float
    v0: float
    a0: float
    jerk: float
    law: int = POLY
    b: float = 0.0
    tau: float = 0.0


class Span(NamedTuple):
    """A phase placed in its profile, as the step timing reads it: its start and
    end time, the phase, and the state it ends in (the next phase's start;
    the last one's: the profile's end)."""

    t0: float
    t1: float
    seg: Seg
    p1: float
    v1: float
    a1: float


class Phase(NamedTuple):
    """One segment of a profile: start time, duration and its law.

    ``law`` is the constant jerk (a float) of a polynomial phase, or
    ``"exp-up"`` / ``"exp-down"`` for the exponential ramps."""

    t_start: float
    duration: float
    law: float | str


class PhaseLaw(Protocol):
    """How the motion goes inside a phase. ``A`` is :meth:`Profile._arrays`
    (one array a field of :class:`Seg`, plus ``t0``, ``t1`` and the end state
    ``p1``, ``v1``, ``a1`` of each phase) for the vectorised sampling; the
    step timing inverts one phase at a time (:class:`Span`)."""

    codes: tuple[int, ...]

    def label(self, seg: Seg) -> float | str:
        """What :attr:`Phase.law` says of the phase."""
        ...

    def sample(self, A: dict[str, Any], ie: NDArray[np.intp], tl: F64) -> tuple[F64, F64, F64, F64]:
        """Position, velocity, acceleration, jerk in the phases ``ie`` at the
        times ``tl`` from their starts (within them)."""
        ...

    def invert(self, span: Span, x: F64) -> None:
        """In place: the times at which the phase ``span`` (of non-zero
        duration) reaches the sorted positions ``x`` (within it)."""
        ...


LAWS: dict[int, PhaseLaw] = {}
"""The phase laws by code; a ramp with a law of its own registers it here."""


class Ramp(Protocol):
    """A kind of ramp: one module of :mod:`winder.motion.ramps` defining ``RAMP``."""

    name: str
    """The kind, as ``Profile.kind``, the node setting and ``winder run`` name it."""
    rank: int
    """Where it is listed among the kinds (settings, help texts)."""
    limits: tuple[str, ...]
    """The :func:`plan` keywords it uses beside the distance and the speeds."""
    moves: bool
    """Whether :func:`plan` plans point-to-point moves with it (the jog: no)."""
    piecewise_polynomial: bool
    """Whether its position is a cubic inside every phase (a shaped move of
    it is then solved piece by piece, :mod:`winder.motion.shaped`)."""

    def plan(
        self, D: float, v0: float, v1: float, V: float, a_max: Limit, j_max: Limit, tau: Limit, exp_cut: float
    ) -> Profile:
        """The move (limits checked, unused ones None); raises
        :class:`Infeasible` when no monotone move of length ``D`` exists."""
        ...

    def stop(self, profile: Profile, v: float, a: float, exp_cut: float) -> Profile:
        """The time-optimal stop of one of its moves from velocity ``v`` and
        acceleration ``a`` to the move's end velocity (positions from 0)."""
        ...

    def continuation(
        self, profile: Profile, v: float, a: float, distance: float, v_max: float, exp_cut: float
    ) -> Profile | None:
        """The rest of one of its moves from ``(v, a)``: ``distance`` more to
        its end velocity with the peak ``v_max``; None if none fits."""
        ...


RAMPS: dict[str, Ramp] = {}
"""Every ramp by name, in rank order (filled by :mod:`winder.motion.ramps`)."""
MOVES: dict[str, Ramp] = {}
"""The ramps :func:`plan` plans moves with."""


def register(ramp: Ramp) -> Ramp:
    """Add ``ramp`` to :data:`RAMPS` (and :data:`MOVES`)."""
    RAMPS[ramp.name] = ramp
    if ramp.moves:
        MOVES[ramp.name] = ramp
    return ramp


# --------------------------------------------------------------------------- validation


def bad(name: str, value: object, allowed: str) -> ValueError:
    """The one-line error naming a parameter, its value and what it must be."""
    return ValueError(f"{name}={value!r} is invalid: must be {allowed}")


def real(name: str, x: object, allowed: str) -> float:
    """``x`` as a finite float, else :func:`bad`."""
    tx = type(x)
    if tx is float or tx is int:
        v = float(x)  # type: ignore[arg-type]
    elif isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_)):
        v = float(x)
    else:
        raise bad(name, x, allowed)
    if not math.isfinite(v):
        raise bad(name, x, allowed)
    return v


def positive(name: str, x: object) -> float:
    """``x`` as a finite float > 0."""
    if type(x) is float and 0.0 < x < math.inf:  # the common case, at once
        return x
    allowed = "a finite number > 0"
    v = real(name, x, allowed)
    if not v > 0.0:
        raise bad(name, x, allowed)
    return v


def speed(name: str, x: object, v_max: float | None) -> float:
    """``x`` as a finite float in [0, v_max] (v_max None: >= 0)."""
    if type(x) is float and 0.0 <= x < math.inf and (v_max is None or x <= v_max):
        return x
    allowed = "a finite number >= 0" if v_max is None else f"a finite number in [0, v_max={v_max!r}]"
    v = real(name, x, allowed)
    if v < 0.0 or (v_max is not None and v > v_max):
        raise bad(name, x, allowed)
    return v


def needed(name: str, x: float | None, kind: str) -> float:
    """A limit the ramp ``kind`` needs: not None."""
    if x is None:
        raise BadInputError(f"{name}=None is invalid: kind={kind!r} needs a finite number > 0")
    return x


# --------------------------------------------------------------------------- profiles


class Profile:
    """A planned motion: phases of constant jerk (or of a ramp's own law).

    Attributes: ``kind``, ``distance``, ``duration`` (s), ``v_start``,
    ``v_end``, ``v_peak`` (highest velocity reached), ``v_max``, ``a_max``,
    ``j_max``, ``tau`` (the limits it was planned with, ``None`` if unused),
    ``phases`` (list of :class:`Phase`), ``segments`` (list of :class:`Seg`)
    and ``t_stop`` (for a stopped jog: when the stop began). Built by
    :func:`plan` and :meth:`winder.motion.ramps.jog.Jog.stop`.

    A planner may hand over its phases as a builder (:meth:`lazy`).
    """

    __slots__ = (
        "_arr",
        "_build",
        "_segs",
        "_spans",
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
    _segs: list[Seg] | None
    _t0: list[float]

    def __init__(
        self,
        kind: str,
        segs: list[Seg],
        end: tuple[float, float],
        *,
        v_max: float | None,
        a_max: float | None,
        j_max: float | None,
        tau: float | None,
        v_peak: float,
        t_stop: float | None = None,
    ) -> None:
        self.kind = kind
        self.distance = end[0]
        self.v_end = end[1]
        self.v_peak = v_peak
        self.v_max = v_max
        self.a_max = a_max
        self.j_max = j_max
        self.tau = tau
        self.t_stop = t_stop
        self._arr: dict[str, Any] | None = None
        self._spans: tuple[list[Span], F64] | None = None
        self._build: tuple[Callable[..., list[Seg]], tuple[float, ...]] | None = None
        self.duration = self._settle(segs)
        self.v_start = segs[0].v0 if segs else end[1]

    @classmethod
    def lazy(
        cls,
        kind: str,
        build: Callable[..., list[Seg]],
        args: tuple[float, ...],
        D: float,
        v_end: float,
        duration: float,
        v_start: float,
        v_peak: float,
        v_max: float | None,
        a_max: float | None,
        j_max: float | None,
        tau: float | None,
    ) -> Profile:
        """A profile whose phases ``build(*args)`` makes when first needed
        (sampling, step timing), not for a plan only asked its duration: the
        planner gives the ``duration`` they add up to (in their order, from
        0) and the start velocity."""
        self = cls.__new__(cls)
        self.kind = kind
        self.distance = D
        self.v_end = v_end
        self.duration = duration
        self.v_start = v_start
        self.v_peak = v_peak
        self.v_max = v_max
        self.a_max = a_max
        self.j_max = j_max
        self.tau = tau
        self.t_stop = None
        self._arr = None
        self._spans = None
        self._segs = None
        self._build = (build, args)
        return self

    def _settle(self, segs: list[Seg]) -> float:
        """Keep ``segs`` (made monotone) and their start times; return the duration."""
        # Phases built forward (acceleration) and backward (deceleration, so the
        # end is exact) may overlap by an ulp where they meet: keep the phase
        # start positions non-decreasing (and in [0, end]) so that sampled
        # positions are monotone.
        lo = 0.0
        for i in range(len(segs)):
            if segs[i].p0 < lo:
                segs[i] = segs[i]._replace(p0=lo)
            lo = segs[i].p0
        hi = self.distance
        for i in range(len(segs) - 1, -1, -1):
            if segs[i].p0 > hi:
                segs[i] = segs[i]._replace(p0=hi)
            hi = segs[i].p0
        t0 = [0.0] * len(segs)
        t = 0.0
        for i, s in enumerate(segs):
            t0[i] = t
            t = t + s.duration
        self._t0 = t0
        self._segs = segs  # last: whoever sees the phases sees their start times
        return t

    @property
    def segments(self) -> list[Seg]:
        """The phases as built (the list itself: do not change it)."""
        segs = self._segs
        if segs is None:
            assert self._build is not None
            build, args = self._build  # kept: two threads may build at once, alike
            self._settle(build(*args))
            segs = self._segs
            assert segs is not None
        return segs

    @property
    def ramp(self) -> Ramp:
        """The ramp this profile was planned with."""
        return RAMPS[self.kind]

    def __repr__(self) -> str:
        return (
            f"Profile(kind={self.kind!r}, distance={self.distance!r}, duration={self.duration!r}, "
            f"v_start={self.v_start!r}, v_peak={self.v_peak!r}, v_end={self.v_end!r})"
        )

    @property
    def phases(self) -> list[Phase]:
        """The segments as ``(t_start, duration, jerk or "exp-up"/"exp-down")``."""
        segs = self.segments
        return [Phase(t0, s.duration, LAWS[s.law].label(s)) for t0, s in zip(self._t0, segs, strict=True)]

    @property
    def limits(self) -> dict[str, float | None]:
        """The limits the profile was planned with."""
        return {"v_max": self.v_max, "a_max": self.a_max, "j_max": self.j_max, "tau": self.tau}

    # ------------------------------------------------------------------ arrays

    def _arrays(self) -> dict[str, Any]:
        if self._arr is None:
            segs = self.segments
            n = len(segs)
            a = np.array(segs, dtype=np.float64).reshape(n, 8)
            t0 = np.array(self._t0, dtype=np.float64)
            # end state of each phase: the next one's start state (the last: the end)
            p1 = np.concatenate((a[1:, 1], (self.distance,)))
            v1 = np.concatenate((a[1:, 2], (self.v_end,)))
            t1 = np.concatenate((t0[1:], (self.duration,)))
            self._arr = {
                "t0": t0, "t1": t1, "T": a[:, 0], "p0": a[:, 1], "v0": a[:, 2], "a0": a[:, 3],
                "j": a[:, 4], "exp": a[:, 5] != POLY, "law": a[:, 5], "b": a[:, 6], "tau": a[:, 7],
                "p1": p1, "v1": v1, "a1": np.concatenate((a[1:, 3], (0.0,))),
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
        np.clip(i, 0, len(self.segments) - 1, out=i)
        tau = tf - A["t0"][i]
        np.clip(tau, 0.0, A["T"][i], out=tau)  # outside [0, duration]: overwritten below
        v0, a0, j = A["v0"][i], A["a0"][i], A["j"][i]
        p = A["p0"][i] + tau * (v0 + tau * (0.5 * a0 + tau * (j / 6.0)))
        v = v0 + tau * (a0 + 0.5 * tau * j)
        acc = a0 + tau * j
        jerk = j.copy()
        other = A["exp"][i]
        if other.any():  # phases of a ramp's own law
            k = np.flatnonzero(other)
            codes = A["law"][i[k]]
            done: list[PhaseLaw] = []
            for c in np.unique(codes).tolist():
                law = LAWS[int(c)]
                if law in done:
                    continue
                done.append(law)
                kk = k[np.isin(codes, law.codes)]
                p[kk], v[kk], acc[kk], jerk[kk] = law.sample(A, i[kk], tau[kk])
        # rounding guards: positions monotone across phases, no limit exceeded by an ulp
        np.clip(p, A["p0"][i], A["p1"][i], out=p)
        np.clip(v, 0.0, A["v_hi"], out=v)
        if self.a_max is not None:
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
            raise bad("n", n, "an integer >= 1")
        n = int(n)
        D = self.distance
        if not (D > 0.0 and math.isfinite(D)):
            raise BadInputError(f"distance={D!r}: the motion covers no distance, it has no steps")
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

    def _span_list(self) -> tuple[list[Span], F64]:
        """The phases placed (:class:`Span`) and the position each ends at."""
        if self._spans is None:
            segs = self.segments
            t0 = self._t0
            n = len(segs)
            spans = [
                Span(t0[i], t0[i + 1], segs[i], segs[i + 1].p0, segs[i + 1].v0, segs[i + 1].a0)
                for i in range(n - 1)
            ]
            if n:
                spans.append(Span(t0[-1], self.duration, segs[-1], self.distance, self.v_end, 0.0))
            self._spans = spans, np.array([sp.p1 for sp in spans], dtype=np.float64)
        return self._spans

    def _invert(self, x: F64) -> None:
        """Replace sorted positions ``x`` (in [0, distance]) by their times, in place."""
        spans, p1 = self._span_list()
        # positions in (p0_i, p1_i] belong to phase i; position 0 to time 0
        start = int(np.searchsorted(x, 0.0, side="right"))
        x[:start] = 0.0
        ends = np.searchsorted(x, p1, side="right").tolist()
        for sp, hi in zip(spans, ends, strict=True):
            lo = start
            start = max(start, hi)
            if hi <= lo:
                continue
            for c in range(lo, hi, _CHUNK):
                _invert_phase(sp, x[c : min(c + _CHUNK, hi)])


def _invert_phase(sp: Span, x: F64) -> None:
    """Times (in place) at which the phase ``sp`` reaches the positions ``x``."""
    if sp.seg.duration == 0.0:  # an ulp of position left between two phases built from either end
        x.fill(sp.t0)
    else:
        LAWS[sp.seg.law].invert(sp, x)
    _clip(x, sp.t0, sp.t1, out=x)


# --------------------------------------------------------------------------- planning


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
    """Plan a monotone point-to-point move of ``distance`` (> 0) with the ramp ``kind``.

    ``kind`` is one of :data:`MOVES` (``"scurve"`` needs ``a_max`` and
    ``j_max``, ``"trapezoid"`` ``a_max``, ``"exponential"`` ``tau``, the time
    constant; ``exp_cut`` in (0, 0.5] sets where it is truncated, see
    :mod:`winder.motion.profile`). Limits a kind does not use are checked but
    ignored. ``v_start`` and ``v_end`` must lie in [0, v_max]; boundary
    accelerations are zero.

    Raises :class:`ValueError` naming the parameter, its value and the
    allowed range; or, when no monotone move of that length joins ``v_start``
    and ``v_end``, naming the minimum distance.
    """
    try:
        ramp = MOVES[kind]
    except (KeyError, TypeError):
        raise bad("kind", kind, "one of " + ", ".join(repr(k) for k in MOVES)) from None
    if (  # the common case at once; else each checked in turn, the first bad one named
        type(distance) is float
        and type(v_max) is float
        and type(v_start) is float
        and type(v_end) is float
        and 0.0 < distance < _INF
        and 0.0 < v_max < _INF
        and 0.0 <= v_start <= v_max
        and 0.0 <= v_end <= v_max
    ):
        D, V, v0, v1 = distance, v_max, v_start, v_end
    else:
        D = positive("distance", distance)
        V = positive("v_max", v_max)
        v0 = speed("v_start", v_start, V)
        v1 = speed("v_end", v_end, V)
    A = a_max if a_max is None or (type(a_max) is float and 0.0 < a_max < _INF) else positive("a_max", a_max)
    J = j_max if j_max is None or (type(j_max) is float and 0.0 < j_max < _INF) else positive("j_max", j_max)
    tc = tau if tau is None or (type(tau) is float and 0.0 < tau < _INF) else positive("tau", tau)
    try:
        return ramp.plan(D, v0, v1, V, A, J, tc, exp_cut)
    except Infeasible as e:
        lim = ", ".join(f"{k}={x!r}" for k, x in (("a_max", A), ("j_max", J), ("tau", tc)) if x)
        raise BadInputError(
            f"distance={distance!r} is invalid: too short for v_start={v0!r} -> v_end={v1!r} "
            f"({kind}, {lim}); a monotone move needs distance >= {e.d_min!r}"
        ) from None


# --------------------------------------------------------------------------- tails


def tail(like: Profile, segs: list[Seg], end: float, v_max: float) -> Profile:
    """A profile of ``like``'s kind and limits (a piece of a move changed while
    it runs, :mod:`winder.motion.retime`) made of ``segs``, ending at ``end``
    with ``like``'s end velocity; its peak read from the phases."""
    if not segs:  # nothing to do: a zero-length phase keeps the profile well formed
        segs = [Seg(0.0, 0.0, like.v_end, 0.0, 0.0)]
    peak = like.v_end
    for s in segs:  # the highest velocity: at a phase start or where a = 0
        peak = max(peak, s.v0)
        T, a0, j = s.duration, s.a0, s.jerk
        if s.law == POLY and j != 0.0 and a0 * j < 0.0 and -a0 / j < T:
            peak = max(peak, s.v0 - a0 * a0 / (2.0 * j))
    return Profile(
        like.kind, segs, (end, like.v_end), v_max=v_max, a_max=like.a_max, j_max=like.j_max,
        tau=like.tau, v_peak=peak,
    )  # fmt: skip


def join(like: Profile, segs: list[Seg], d1: float, rest: Profile, v_max: float) -> Profile:
    """The phases ``segs`` (covering ``d1``), then the planned move ``rest``."""
    out = list(segs) + [s._replace(p0=s.p0 + d1) for s in rest.segments]
    return tail(like, out, d1 + rest.distance, v_max)
