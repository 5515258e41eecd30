"""A planned move convolved with an input shaper: the path parameter's time law.

An input shaper (:mod:`winder.shaping`) is a short train of impulses of
amplitudes ``A_m`` (positive, summing to 1) at times ``tau_m`` (``tau_0 = 0``).
Shaping a move ``s(t)`` (:class:`winder.motion.profile.Profile`: the major
axis' position, in steps, against time) gives

    s~(t) = sum_m A_m s(t - tau_m)

with ``s = 0`` before the move and ``s = distance`` after it. Every axis of a
segment follows the major axis' step index, so shaping the path parameter
changes only *when* each step happens, never *which* steps or in which order:
the wound geometry is exact. The shaped move lasts ``duration + tau_last``;
its velocity, acceleration and jerk are the same convex combinations, so no
limit of the plan is exceeded and the peaks usually drop (:attr:`peaks`).

Step times are the first times at which ``s~`` reaches each step position.
For a piecewise-polynomial ramp (its ``piecewise_polynomial``: the S-curve,
the trapezoid, the jog) ``s~`` is a cubic between the
breakpoints (the base's phase boundaries shifted by each impulse time): the
pieces' coefficients are taken once, at each piece's middle, and every step
is solved on its own piece by a safeguarded Newton iteration on the cubic
(bracketed by the piece, started at ``t(x) + sum_m A_m tau_m``, ``t(x)`` the
unshaped move's time of position ``x``: exact in a cruise), vectorised over
all the steps, to 1e-10 s. Any other ramp (the exponential) is solved
on the bracket ``[t(x), t(x) + tau_last]`` (``s~ <= s`` and
``s~(t + tau_last) >= s(t)``) by the same iteration on the sum of the
impulses' terms.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from winder.motion.profile import Profile

__all__ = ["TOLERANCE_S", "Motion", "ShapedProfile", "base_of", "shape", "shaped_like"]

F64 = NDArray[np.float64]

TOLERANCE_S = 1e-10
"""How close each shaped step time is to the exact crossing time (s)."""
_MAX_ITER = 200
_CHUNK = 1 << 15


class ShapedProfile:
    """A :class:`Profile` (the ``base``) shaped by impulses ``amplitudes`` at
    ``times``. It reads like a profile: ``kind``, ``distance``, ``duration``,
    ``v_start``, ``v_end``, ``v_peak``, the plan's limits, :meth:`sample`,
    :meth:`step_times`, :meth:`times_at`; plus ``shaper`` (its name, or
    "custom"), ``amplitudes``, ``times`` and :attr:`peaks`."""

    def __init__(
        self,
        base: Profile,
        amplitudes: ArrayLike,
        times: ArrayLike,
        *,
        shaper: str = "custom",
        f_n: float | None = None,
        zeta: float | None = None,
    ) -> None:
        a = np.array(amplitudes, dtype=np.float64).reshape(-1)
        t = np.array(times, dtype=np.float64).reshape(-1)
        if a.size == 0 or a.shape != t.shape:
            raise ValueError(f"amplitudes {a.shape} and times {t.shape} must be equal, non-empty vectors")
        if not (np.all(np.isfinite(a)) and np.all(a > 0.0) and abs(float(a.sum()) - 1.0) < 1e-12):
            raise ValueError(f"amplitudes={a.tolist()!r} are invalid: must be positive and sum to 1")
        if not (np.all(np.isfinite(t)) and t[0] == 0.0 and np.all(np.diff(t) > 0.0)):
            raise ValueError(f"times={t.tolist()!r} are invalid: must start at 0 and increase")
        self.base = base
        self.amplitudes = a
        self.times = t
        self.shaper = shaper
        self.f_n = f_n
        self.zeta = zeta
        self.kind = base.kind
        self.distance = base.distance
        self.duration = base.duration + float(t[-1])
        self.shaper_duration = float(t[-1])
        # the ramp's start/stop rate (the shaped move itself starts with the
        # first impulse's share of it and ends with the last one's)
        self.v_start, self.v_end = base.v_start, base.v_end
        self.v_max, self.a_max, self.j_max, self.tau = base.v_max, base.a_max, base.j_max, base.tau
        self._mean_delay = float(np.dot(a, t))
        self._peaks: dict[str, float] | None = None
        self._cubic: tuple[F64, ...] | None = None
        # a move of a piecewise-polynomial ramp is one cubic between the
        # breakpoints: solved piece by piece (else on the sum of the impulses' terms)
        self._polynomial = base.ramp.piecewise_polynomial

    def __repr__(self) -> str:
        return (
            f"ShapedProfile(shaper={self.shaper!r}, f_n={self.f_n!r}, zeta={self.zeta!r}, "
            f"base={self.base!r}, duration={self.duration!r})"
        )

    @property
    def t_stop(self) -> None:
        return None

    @property
    def v_peak(self) -> float:
        return self.peaks["v"]

    @property
    def limits(self) -> dict[str, float | None]:
        return self.base.limits

    # ------------------------------------------------------------------ sampling

    def _terms(self, t: F64) -> tuple[F64, F64, F64, F64]:
        """Sums over the impulses of the base's position, velocity,
        acceleration and jerk at ``t - tau_m``; the base is at rest (velocity
        0) outside its duration."""
        p = np.zeros(t.shape)
        v = np.zeros(t.shape)
        acc = np.zeros(t.shape)
        jerk = np.zeros(t.shape)
        T = self.base.duration
        for am, tm in zip(self.amplitudes.tolist(), self.times.tolist(), strict=True):
            u = t - tm
            pm, vm, aam, jm = self.base.sample(u)
            outside = (u < 0.0) | (u > T)
            vm[outside] = 0.0
            p += am * pm
            v += am * vm
            acc += am * aam
            jerk += am * jm
        return p, v, acc, jerk

    def sample(self, t: ArrayLike) -> tuple[F64, F64, F64, F64]:
        """Position, velocity, acceleration and jerk of the shaped move at ``t`` (s)."""
        ta = np.asarray(t, dtype=np.float64)
        if np.isnan(ta).any():
            raise ValueError("t contains NaN: sample times must be numbers")
        flat = ta.reshape(-1)
        p, v, a, j = self._terms(flat)
        np.clip(p, 0.0, self.distance, out=p)
        p[flat >= self.duration] = self.distance
        shape = ta.shape
        return p.reshape(shape), v.reshape(shape), a.reshape(shape), j.reshape(shape)

    @property
    def peaks(self) -> dict[str, float]:
        """Peak |velocity|, |acceleration| and |jerk| of the shaped move. Its
        acceleration is piecewise linear between the breakpoints (the base's
        phase boundaries shifted by each impulse time) for polynomial ramps,
        so the peaks of acceleration and jerk are at breakpoints and that of
        velocity at a breakpoint or where the acceleration crosses zero;
        exponential ramps are sampled densely besides."""
        if self._peaks is None:
            self._peaks = self._find_peaks()
        return self._peaks

    def _breakpoints(self) -> F64:
        edges = [ph.t_start for ph in self.base.phases] + [self.base.duration]
        b = np.add.outer(self.times, np.asarray(edges)).reshape(-1)
        b = np.unique(np.clip(b, 0.0, self.duration))
        return b

    def _find_peaks(self) -> dict[str, float]:
        b = self._breakpoints()
        lo, hi = b[:-1], b[1:]
        length = hi - lo
        keep = length > 0
        lo, hi, length = lo[keep], hi[keep], length[keep]
        dense = 16 if self._polynomial else 512
        frac = np.linspace(0.0, 1.0, dense + 1)[1:-1]
        inner = (lo[:, None] + length[:, None] * frac[None, :]).reshape(-1)
        eps = np.maximum(length * 1e-9, 1e-15)
        pts = np.concatenate([b, lo + eps, hi - eps, inner])
        _, v, a, j = self._terms(pts)
        v_peak = float(np.max(np.abs(v))) if v.size else 0.0
        if self._polynomial and lo.size:  # the vertex of v where the (linear) acceleration is 0
            _, _, a0, _ = self._terms(lo + eps)
            _, _, a1, _ = self._terms(hi - eps)
            cross = (a0 * a1 < 0.0) & (a0 != a1)
            if np.any(cross):
                s = a0[cross] / (a0[cross] - a1[cross])
                tz = lo[cross] + eps[cross] + s * (length[cross] - 2 * eps[cross])
                _, vz, _, _ = self._terms(tz)
                v_peak = max(v_peak, float(np.max(np.abs(vz))))
        return {
            "v": v_peak,
            "a": float(np.max(np.abs(a))) if a.size else 0.0,
            "j": float(np.max(np.abs(j))) if j.size else 0.0,
        }

    # ------------------------------------------------------------------ step timing

    def step_times(self, n: int) -> F64:
        """The ``n`` times at which the shaped position reaches ``k * distance / n``."""
        x = np.arange(1, int(n) + 1, dtype=np.float64) * (self.distance / int(n))
        x[-1] = self.distance
        out = self.times_at(x)
        out[-1] = self.duration  # as the plan's: the last step ends the move
        return out

    def times_at(self, positions: ArrayLike) -> F64:
        """The first times (s) at which the shaped position reaches each of
        ``positions`` (non-decreasing, within [0, distance])."""
        x = np.array(positions, dtype=np.float64, copy=True).reshape(-1)
        if not self._polynomial or self.times.size == 1:
            out = self.base.times_at(x)  # checks the positions; the lower end of each bracket
            for c in range(0, x.size, _CHUNK):
                sl = slice(c, min(c + _CHUNK, x.size))
                out[sl] = self._solve(x[sl], out[sl])
            return out
        if x.size and not (np.all(x[1:] >= x[:-1]) and x[0] >= 0.0 and x[-1] <= self.distance):
            raise ValueError(f"positions must be non-decreasing numbers in [0, distance={self.distance!r}]")
        out = np.empty_like(x)
        for c in range(0, x.size, _CHUNK):
            sl = slice(c, min(c + _CHUNK, x.size))
            out[sl] = self._solve_cubic(x[sl])
        return out

    def _pieces(self) -> tuple[F64, ...]:
        """The cubic pieces of a polynomial ramp's shaped position: each
        piece's start, end and middle (s), and its position, velocity,
        acceleration and jerk at the middle (the Taylor coefficients there:
        inside a piece every term is one cubic), and the position at its start."""
        if self._cubic is None:
            b = self._breakpoints()
            lo, hi = b[:-1], b[1:]
            keep = hi > lo
            lo, hi = lo[keep], hi[keep]
            mid = 0.5 * (lo + hi)
            p, v, a, j = self._terms(mid)
            w = lo - mid
            p_lo = p + w * (v + w * (0.5 * a + w * (j / 6.0)))
            self._cubic = (lo, hi, mid, p, v, 0.5 * a, j / 6.0, p_lo)
        return self._cubic

    def _solve_cubic(self, x: F64) -> F64:
        """The sorted targets ``x`` piece by piece (a target's piece: the
        first whose end reaches it): on a line (every impulse's term cruising,
        most of a long move) at once; on a cubic by a safeguarded Newton
        iteration, started at the unshaped time plus the mean impulse delay,
        with s~(lo) < x <= s~(hi) on the bracket throughout."""
        lo_t, hi_t, mid_t, c0, c1, c2, c3, p_lo = self._pieces()
        out = np.zeros_like(x)
        # targets in (p_lo[k], p_lo[k + 1]] are piece k's; x <= 0 is reached at time 0
        ends = np.searchsorted(x, p_lo, side="right")
        ends = np.append(ends, x.size)
        curved: list[tuple[int, int, int]] = []
        for k in range(lo_t.size):
            a, b = int(ends[k]), int(ends[k + 1])
            if k == 0:
                a = max(a, int(np.searchsorted(x, 0.0, side="right")))
            if b <= a:
                continue
            if c2[k] == 0.0 and c3[k] == 0.0 and c1[k] > 0.0:  # a line
                seg = out[a:b]
                np.subtract(x[a:b], c0[k], out=seg)
                seg /= c1[k]
                seg += mid_t[k]
            else:
                curved.append((a, b, k))
        if curved:  # one iteration over every target on a cubic, each with its piece's coefficients
            idx = np.concatenate([np.arange(a, b) for a, b, _ in curved])
            piece = np.repeat([k for _, _, k in curved], [b - a for a, b, _ in curved])
            out[idx] = self._newton(
                x[idx], mid_t[piece], lo_t[piece], hi_t[piece], c0[piece], c1[piece], c2[piece], c3[piece]
            )
        return out

    def _newton(self, x: F64, mid: F64, lo: F64, hi: F64, p: F64, v: F64, ha: F64, sj: F64) -> F64:
        """The first times at which each cubic p + v w + ha w^2 + sj w^3 (w =
        t - mid, t in [lo, hi]; one per target) reaches ``x``: safeguarded
        Newton, to TOLERANCE_S."""
        wl = lo - mid
        wh = hi - mid
        w = np.clip(self.base.times_at(x) + self._mean_delay - mid, wl, wh)
        a0 = p - x
        result = np.empty_like(x)
        todo = np.arange(x.size)
        for _ in range(_MAX_ITER):
            if todo.size == 0:
                break
            f = a0 + w * (v + w * (ha + w * sj))
            fp = v + w * (2.0 * ha + w * (3.0 * sj))
            below = f < 0.0
            wl = np.where(below, w, wl)
            wh = np.where(below, wh, w)
            with np.errstate(divide="ignore", invalid="ignore"):
                step = f / fp
            newton = w - step
            ok = (fp > 0.0) & (newton > wl) & (newton < wh) & np.isfinite(newton)
            nxt = np.where(ok, newton, 0.5 * (wl + wh))
            converged = ok & (np.abs(step) <= TOLERANCE_S)
            done = converged | (wh - wl <= TOLERANCE_S)
            if np.any(done):
                # a converged Newton step is the root; a closed bracket ends at its upper end
                result[todo[done]] = (mid + np.where(converged, newton, wh))[done]
                keep = ~done
                todo, a0, wl, wh, nxt = todo[keep], a0[keep], wl[keep], wh[keep], nxt[keep]
                mid, v, ha, sj = mid[keep], v[keep], ha[keep], sj[keep]
            w = nxt
        if todo.size:  # not reached in practice: the bracket halves at least every other step
            result[todo] = mid + wh
        return result

    def _solve(self, x: F64, t_base: F64) -> F64:
        """Safeguarded Newton: s~(lo) < x <= s~(hi) holds throughout."""
        if self.times.size == 1:
            return t_base
        lo = t_base.copy()
        hi = t_base + self.shaper_duration
        t = t_base + self._mean_delay
        result = np.empty_like(x)
        zero = x <= 0.0
        result[zero] = 0.0
        todo = np.flatnonzero(~zero)
        lo, hi, t, xs = lo[todo], hi[todo], t[todo], x[todo]
        for _ in range(_MAX_ITER):
            if todo.size == 0:
                break
            p, v, _, _ = self._terms(t)
            below = p < xs
            lo = np.where(below, t, lo)
            hi = np.where(below, hi, t)
            with np.errstate(divide="ignore", invalid="ignore"):
                step = (xs - p) / v
            newton = t + step
            ok = (v > 0.0) & (newton > lo) & (newton < hi) & np.isfinite(newton)
            nxt = np.where(ok, newton, 0.5 * (lo + hi))
            done = (ok & (np.abs(step) <= TOLERANCE_S)) | (hi - lo <= TOLERANCE_S)
            # a converged Newton step is the root; a closed bracket ends at its upper end
            res = np.where(ok & (np.abs(step) <= TOLERANCE_S), newton, hi)
            if np.any(done):
                result[todo[done]] = res[done]
                keep = ~done
                todo, lo, hi, xs, nxt = todo[keep], lo[keep], hi[keep], xs[keep], nxt[keep]
            t = nxt
        if todo.size:  # not reached in practice: the bracket halves at least every other step
            result[todo] = hi
        return result


def shape(base: Profile, kind: str, f_n: float, zeta: float) -> Profile | ShapedProfile:
    """``base`` shaped by the input shaper ``kind`` (``"none"``: ``base``
    itself) designed for the resonance ``f_n`` (Hz) with damping ratio ``zeta``."""
    if kind == "none":
        return base
    from winder.shaping import shaper  # only a shaped plan needs it

    amplitudes, times = shaper(kind, f_n, zeta)
    return ShapedProfile(base, amplitudes, times, shaper=kind, f_n=f_n, zeta=zeta)


Motion = Profile | ShapedProfile
"""A planned move: a profile, shaped or not."""


def base_of(motion: Motion) -> Profile:
    """The unshaped profile of a move."""
    return motion.base if isinstance(motion, ShapedProfile) else motion


def shaped_like(like: Motion, profile: Profile) -> Motion:
    """``profile`` shaped as ``like`` is (a move planned again, e.g. the rest
    of a move after a resume, keeps its shaper)."""
    if isinstance(like, ShapedProfile):
        return ShapedProfile(
            profile, like.amplitudes, like.times, shaper=like.shaper, f_n=like.f_n, zeta=like.zeta
        )
    return profile
