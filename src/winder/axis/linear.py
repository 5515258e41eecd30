"""Exact linear response of the stepper axis, streaming (:class:`LinearTracker`).

Exact linear response
---------------------
Between steps the command is constant, so the error state z = (theta - theta1,
omega) evolves as z(t) = Phi(t - t_k) z(t_k) with the closed-form transition
matrix (``StepperAxis._transition`` in :mod:`winder.axis.model`; sigma = zeta*w_n,
beta**2 = sigma**2 - w_n**2)::

    Phi(t) = e**(-sigma*t) * [C*I + S*(A + sigma*I)],   C = cosh(beta*t),
    S = sinh(beta*t)/beta   (cos(w_d*t), sin(w_d*t)/w_d below critical damping),

written with ``sinc`` and ``expm1`` so that it is continuous and free of
cancellation across zeta = 1 (both forms tend to C = 1, S = t). A step of angle
d subtracts (d, 0) from z. The recurrence over N steps is evaluated with a
blocked scan (``StepperAxis._scan``): within blocks of ~N**(1/3) steps a
vectorised loop runs across all blocks at once from a zero state, the block-end
states are chained by the same scan one level up (recursively), and each step's state is
corrected with Phi of its distance to the previous block end. Every Phi is
evaluated forward in time (contractive), so the result is as accurate as the
sequential recurrence, in O(N) numpy work and O(N**(1/3)) Python iterations.

Below damping ratio ``MODAL_ZETA`` (0.95) :class:`LinearTracker` does not need
every step's state: the error is the real part of one complex mode, and the
state at a sample is a running sum of one complex exponential per step (see
``LinearTracker._advance_modal``); the scan serves the rest.
"""

from __future__ import annotations

import cmath
import math
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from winder.axis._checks import ArrayLike, FloatArray
from winder.axis._protocol import Motor
from winder.axis._steps import _StepQueue
from winder.errors import BadInputError

__all__ = ["MODAL_ZETA", "LinearTracker"]

#: Damping ratios below which :class:`LinearTracker` sums modal terms (see
#: ``LinearTracker._advance_modal``); at and above it, the blocked scan.
#: kappa = -1 + i*zeta/sqrt(1 - zeta**2) stays below 3.1 in magnitude.
MODAL_ZETA = 0.95
#: Largest sigma*(t - b) within one window of the modal sum: terms up to e**30.
MODAL_WINDOW = 30.0


class LinearTracker:
    """Streaming exact response of the linear model, fed steps and samples in chunks.

    Semantics of :meth:`advance`: samples are evaluated with every step delivered
    so far whose time is <= the sample time (a step at exactly a sample time is
    applied *before* that sample). Across calls, step times and sample times must
    each be non-decreasing, and a step delivered after a sample was returned must
    not be earlier than that sample; one at exactly that time is applied after it
    (it was not known yet). Under these rules chunked results equal the one-shot
    :meth:`StepperAxis.response` to rounding. Steps later than the last sample of
    a call are kept pending until a sample reaches them.
    """

    def __init__(self, axis: Motor, method: Literal["auto", "modal", "scan"] = "auto") -> None:
        self._axis = axis
        self._t = -math.inf  # time of the held state (last applied step); -inf: at rest
        self._z = (0.0, 0.0)  # error state (theta - theta1, omega) just after that step
        self._cmd = 0.0  # theta1 after the applied steps (rad)
        zeta = axis.damping_ratio
        if method not in ("auto", "modal", "scan"):
            raise BadInputError(f"method={method!r} is invalid: must be 'auto', 'modal' or 'scan'")
        if method == "modal" and not zeta < MODAL_ZETA:
            raise BadInputError(f"method='modal' needs damping ratio < {MODAL_ZETA}, this axis has {zeta!r}")
        self._modal = method == "modal" or (method == "auto" and zeta < MODAL_ZETA)
        if self._modal:
            wn = axis.natural_frequency
            sig = zeta * wn
            wd = wn * math.sqrt((1.0 - zeta) * (1.0 + zeta))
            self._lam = complex(-sig, wd)
            self._kappa = complex(-1.0, sig / wd)
            # widest time span over which the modal terms of one window are
            # summed: e**(sigma*span) stays far from overflow
            self._span = MODAL_WINDOW / sig if sig > 0 else math.inf
            self._q = 0j  # modal error state at self._t (see _advance_modal)
        self._queue = _StepQueue()

    @property
    def command(self) -> float:
        """Commanded angle theta1 of the steps applied so far (rad)."""
        return self._cmd

    def advance(
        self, step_times: ArrayLike, step_angles: ArrayLike, t_samples: ArrayLike
    ) -> tuple[FloatArray, FloatArray]:
        """Add steps (times in s, signed angles in rad, scalar or per step) and return
        (theta, omega) at the non-decreasing ``t_samples`` (rad, rad/s)."""
        st, sa, ts = self._queue.check(step_times, step_angles, t_samples)
        app_t, app_a = self._queue.due(st, sa, ts)
        if ts.size == 0:
            return np.empty(0), np.empty(0)
        n = app_t.size

        if self._modal:
            return self._advance_modal(app_t, app_a, ts)
        if math.isinf(self._t):
            times, b0, b1 = app_t, -app_a, np.zeros(n)
            cmd = _cumulative(app_a)
        else:
            times = np.concatenate([[self._t], app_t])
            b0 = np.concatenate([[self._z[0]], -app_a])
            b1 = np.concatenate([[self._z[1]], np.zeros(n)])
            cmd = self._cmd + np.concatenate([[0.0], _cumulative(app_a)])
        if times.size == 0:
            return np.zeros(ts.size), np.zeros(ts.size)
        z0, z1 = self._axis._scan(times, b0, b1)
        k = np.searchsorted(times, ts, side="right") - 1
        before = int(np.searchsorted(k, 0))  # samples before the first step: at rest at 0
        k = k[before:]
        m11, m12, m21, m22 = self._axis._transition(ts[before:] - times[k])
        za, zb = z0[k], z1[k]
        theta = np.zeros(ts.size)
        omega = np.zeros(ts.size)
        theta[before:] = cmd[k] + (m11 * za + m12 * zb)
        omega[before:] = m21 * za + m22 * zb
        self._t = float(times[-1])
        self._z = (float(z0[-1]), float(z1[-1]))
        self._cmd = float(cmd[-1])
        return theta, omega

    def _advance_modal(
        self, app_t: FloatArray, app_a: FloatArray, ts: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """Below critical damping the error e = theta - theta1 is Re(q) and
        omega = Re(lambda*q) for the complex modal state q, lambda = -sigma +
        i*w_d: between steps q(t) = q(t0)*e**(lambda*(t - t0)), and a step of
        angle d adds kappa*d, kappa = -1 + i*sigma/w_d. The state at a sample
        is therefore a sum, with no pass over every step's state:

            q(s) = e**(lambda*(s - b)) * (q(b) + kappa * sum_{b <= t_k <= s} d_k*e**(-lambda*(t_k - b)))

        one complex exponential per step and a running sum, formed at the
        samples only (segment sums between them, then a sum over those). The base time b
        moves to the first step after each window of ``MODAL_WINDOW / sigma``
        seconds, so no term exceeds e**MODAL_WINDOW. Every term is rounded
        relative to its own size and the factor e**(lambda*(s - b)) scales it
        back to its true contribution, so the error is that of summing the
        contributions directly. The state is held at the last sample time."""
        lam, kappa = self._lam, self._kappa
        n = app_t.size
        base, q = self._t, self._q
        if math.isinf(base):  # at rest (q = 0): any base up to the first event
            base = min(float(app_t[0]), float(ts[0])) if n else float(ts[0])
        k_all = np.searchsorted(app_t, ts, side="right")  # steps applied at each sample
        cmd_at = self._cmd + _cumulative_at(app_a, np.append(k_all, n))  # theta1 there, and at the end
        theta = np.empty(ts.size)
        omega = np.empty(ts.size)
        lo = s_lo = 0
        while True:
            hi = int(np.searchsorted(app_t, base + self._span, side="right")) if lo < n else n
            # this window's samples: all those that need no later step
            s_hi = ts.size if hi == n else int(np.searchsorted(k_all, hi, side="right"))
            # sums[i]: sum of d_k*e**(-lambda*(t_k - b)) over the window's steps up to
            # sample i (the last: all of them); the state at b after them is q + kappa*sums[i]
            u = np.empty(hi - lo, np.complex128)
            _modal_terms(lam, base - app_t[lo:hi], app_a[lo:hi], u)
            sums = _sums_at(u, np.append(k_all[s_lo:s_hi] - lo, hi - lo))
            if s_hi > s_lo:
                qs = (q + kappa * sums[:-1]) * np.exp(lam * (ts[s_lo:s_hi] - base))
                theta[s_lo:s_hi] = cmd_at[s_lo:s_hi] + qs.real
                omega[s_lo:s_hi] = (lam * qs).real
            q_end = q + kappa * complex(sums[-1])  # at b, after all of the window's steps
            if hi == n:
                break
            nb = float(app_t[hi])
            q = q_end * cmath.exp(lam * (nb - base))
            base, lo, s_lo = nb, hi, s_hi
        t_end = float(ts[-1])  # every applied step is <= the last sample
        self._q = q_end * cmath.exp(lam * (t_end - base))
        self._t = t_end
        self._cmd = float(cmd_at[-1])
        return theta, omega


#: Grid of the phase table in :func:`_modal_terms` (rad): a power of two, so
#: that a phase splits exactly into a grid point and a remainder of at most
#: half of it.
PHASE_GRID = 2.0**-3
#: Taylor coefficients of cos(r) - 1 and sin(r)/r - 1 in r**2, highest first:
#: for |r| <= PHASE_GRID/2 the next terms are below 3e-19 and 2e-21.
_COS = (1 / 40320, -1 / 720, 1 / 24, -1 / 2)
_SIN = (1 / 362880, -1 / 5040, 1 / 120, -1 / 6)


def _modal_terms(lam: complex, d: FloatArray, a: FloatArray, out: npt.NDArray[np.complex128]) -> None:
    """``out = a * exp(lam * d)``, the modal sum's terms, with two calls of libm
    per grid point of the phase instead of a complex exp per step.

    The phase phi = Im(lam)*d is rounded as in the complex exp of the rounded
    argument; it splits exactly into h + r, h a multiple of PHASE_GRID and |r|
    at most half of it. cos and sin of the few h of one call come from libm
    (a table), those of r from their Taylor series (truncation below 3e-19);
    the rotation adds a few roundings to those of exp, as the complex
    product of two values does. The magnitude exp(Re(lam)*d) is a real exp.
    A call whose phases span more grid points than a quarter of its terms
    takes the complex exp directly.
    """
    n = d.size
    parts = out.view(np.float64).reshape(-1, 2)  # real and imaginary columns
    phi = d * lam.imag
    grid = np.rint(phi * (1.0 / PHASE_GRID))
    g0, g1 = (float(grid.min()), float(grid.max())) if n else (0.0, 0.0)
    if g1 - g0 > n // 4 + 64:  # long pauses between few steps: the table would cost more
        np.multiply(d, lam.real, out=parts[:, 0])  # lambda*d without a complex cast of d
        parts[:, 1] = phi
        np.exp(out, out=out)
        parts *= a[:, None]
        return
    # r = phi - h exactly: h is a multiple of PHASE_GRID, which is a multiple of the ulp of phi
    r = grid * PHASE_GRID
    np.subtract(phi, r, out=r)
    at = (grid - g0).astype(np.intp)
    table = np.arange(int(g1 - g0) + 1, dtype=np.float64)
    table += g0
    table *= PHASE_GRID
    ch, sh = np.cos(table).take(at), np.sin(table).take(at)
    r2 = r * r
    c = r2 * _COS[0]
    for k in _COS[1:]:
        c += k
        c *= r2
    sr = r2 * _SIN[0]
    for k in _SIN[1:]:
        sr += k
        sr *= r2
    sr *= r
    sr += r  # sin(r)
    # cos(h + r) = ch*cos(r) - sh*sin(r), with cos(r) = 1 + c; sin(h + r) = sh*cos(r) + ch*sin(r)
    cos = ch * c
    cos += ch
    np.multiply(sh, sr, out=r2)
    cos -= r2
    sin = sh * c
    sin += sh
    np.multiply(ch, sr, out=r2)
    sin += r2
    mag = d * lam.real
    np.exp(mag, out=mag)
    mag *= a
    np.multiply(mag, cos, out=parts[:, 0])
    np.multiply(mag, sin, out=parts[:, 1])


def _sums_at(x: npt.NDArray[Any], at: npt.NDArray[np.intp]) -> npt.NDArray[Any]:
    """``sum(x[:i])`` for each ``i`` of the non-decreasing ``at`` (0..x.size):
    the sums of the segments between those points, then a running sum over
    them; numpy's cumsum over every element costs ten times more."""
    out = np.zeros(at.size, x.dtype)
    cuts = np.unique(at[at > 0])
    if cuts.size == 0:
        return out
    seg = np.add.reduceat(x[: cuts[-1]], np.concatenate(([0], cuts[:-1])))
    np.cumsum(seg, out=seg)  # seg[j] = sum(x[:cuts[j]])
    first = int(np.searchsorted(at, 0, side="right"))  # the points at 0 keep their 0
    out[first:] = seg[np.searchsorted(cuts, at[first:])]
    return out


def _cumulative_at(a: FloatArray, at: npt.NDArray[np.intp]) -> FloatArray:
    """``sum(a[:i])`` for each ``i`` of ``at`` (see :func:`_sums_at`); exact
    (one rounding) when all angles have the same magnitude, as :func:`_cumulative`."""
    if a.size:
        unit = abs(float(a[0]))
        signs = a / unit if unit else a
        if unit and np.all(np.abs(signs) == 1.0):
            return unit * _sums_at(signs, at)  # counts of +-1: exact below 2**53 steps
    return _sums_at(a, at)


def _cumulative(a: FloatArray) -> FloatArray:
    """Running sum of step angles; exact (one rounding per entry) when all have the
    same magnitude, as in a feed of +-step, by counting steps in integers."""
    if a.size:
        unit = abs(float(a[0]))
        signs = a / unit if unit else a
        if unit and np.all(np.abs(signs) == 1.0):
            # a float running sum of +-1 is exact below 2**53 steps
            return unit * np.cumsum(signs, out=signs)
    return np.cumsum(a)
