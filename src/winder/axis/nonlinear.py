"""Nonlinear model of the stepper axis, streaming, with the loss of steps
(:class:`NonlinearTracker`), and the load torque it takes (:class:`LoadStep`).

The rotor equation (004, eq. 9, see :mod:`winder.axis.model`) in the error
e = theta - theta1, between command steps (theta1 constant)::

    e' = w,   w' = -(D/J)*w - (T_m/J)*sin(Z_r*e) - T_load/J

is integrated with Gragg-Bulirsch-Stoer extrapolation (``_gbs``); a command
step of angle d subtracts d from e.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from winder.axis._checks import ArrayLike, FloatArray, _positive
from winder.axis._protocol import Motor
from winder.axis._steps import _StepQueue
from winder.errors import BadInputError

__all__ = ["Load", "LoadStep", "NonlinearTracker"]

#: the integrator's relative tolerance, at least and at most
RTOL_RANGE = (1e-15, 1e-3)


@dataclass(frozen=True)
class LoadStep:
    """Load torque ``before`` for t < ``time``, ``torque`` from ``time`` on (N*m, s).

    The dispensing-machine thesis (001) tests its drive with a load step at 0.2 s.
    A positive load torque acts against positive rotation (paper's sign, eq. 9).
    """

    time: float
    torque: float
    before: float = 0.0

    def __post_init__(self) -> None:
        for name in ("time", "torque", "before"):
            v = getattr(self, name)
            if not math.isfinite(float(v)):
                raise BadInputError(f"LoadStep.{name}={v!r} is invalid: must be finite")


Load = float | LoadStep


class NonlinearTracker:
    """Streaming integration of the nonlinear model (sine torque, load), with slips.

    The axis is at rest at theta = 0 with theta1 = 0 at time ``t0``. The same
    :meth:`advance` contract as :class:`LinearTracker` (steps and samples
    non-decreasing, a step at exactly a sample time applied before it). The
    equation is integrated between consecutive events (steps, samples, the load
    step) with Gragg-Bulirsch-Stoer extrapolation (modified midpoint rule,
    polynomial extrapolation in h**2) on macro-steps no longer than
    ``max_phase_step`` radians of the fastest rate max(w_n, D/J), each accepted
    when two extrapolation orders agree to ``rtol`` of a tooth pitch (or of a
    pitch times that rate for the velocity); a macro-step that does not converge
    is halved. Slips (well changes, see :class:`SimResult`) are checked after
    every macro-step and every command step; their time is interpolated
    linearly within the macro-step. Cumulative slips: :attr:`slip_times`,
    :attr:`slips`, :attr:`lost_steps`, :attr:`offset_steps`.
    """

    def __init__(
        self,
        axis: Motor,
        load: Load = 0.0,
        *,
        t0: float = 0.0,
        max_phase_step: float = 0.5,
        rtol: float = 1e-11,
    ) -> None:
        self._axis = axis
        if isinstance(load, LoadStep):
            self._lt, self._l_before, self._l_after = load.time, load.before, load.torque
        else:
            v = float(load)
            if not math.isfinite(v):
                raise BadInputError(f"load={load!r} is invalid: must be a finite torque (N*m) or LoadStep")
            self._lt, self._l_before, self._l_after = math.inf, v, v
        if not math.isfinite(t0):
            raise BadInputError(f"t0={t0!r} is invalid: must be finite (s)")
        _positive("max_phase_step", max_phase_step, "rad")
        if not (RTOL_RANGE[0] <= rtol <= RTOL_RANGE[1]):
            raise BadInputError(
                f"rtol={rtol!r} is invalid: must be in [{RTOL_RANGE[0]:g}, {RTOL_RANGE[1]:g}]"
            )
        self._rate = axis.natural_frequency * max(1.0, 2.0 * axis.damping_ratio)
        self._hmax = max_phase_step / self._rate
        self._tol_e = rtol * axis.tooth_pitch
        self._tol_w = rtol * axis.tooth_pitch * self._rate
        self._t = float(t0)
        self._e = 0.0  # theta - theta1 (rad)
        self._w = 0.0  # omega (rad/s)
        self._cmd = 0.0  # theta1 (rad)
        self._well = 0  # index of the well the rotor is in, relative to the command
        self._half_d = 0  # side (-1, +1) on which the rotor is past half a pitch, 0: not
        self._half_t = math.nan  # when it went past
        self._queue = _StepQueue()
        self._slip_t: list[float] = []
        self._slip_s: list[int] = []

    @property
    def slip_times(self) -> FloatArray:
        """Times of all slips so far (s)."""
        return np.asarray(self._slip_t, dtype=np.float64)

    @property
    def slips(self) -> npt.NDArray[np.int64]:
        """Signed slips so far, one per well change (+1 one pitch ahead, -1 behind)."""
        return np.asarray(self._slip_s, dtype=np.int64)

    @property
    def lost_steps(self) -> int:
        """Full steps slipped so far, every well change counted."""
        return self._axis.steps_per_pitch * len(self._slip_s)

    @property
    def offset_steps(self) -> int:
        """Net full steps of the rotor's well ahead (+) / behind (-) the command."""
        return self._axis.steps_per_pitch * sum(self._slip_s)

    @property
    def command(self) -> float:
        """Commanded angle theta1 of the steps applied so far (rad)."""
        return self._cmd

    def advance(
        self, step_times: ArrayLike, step_angles: ArrayLike, t_samples: ArrayLike
    ) -> tuple[FloatArray, FloatArray]:
        """Add steps and return (theta, omega) at ``t_samples``; see :class:`LinearTracker`."""
        st, sa, ts = self._queue.check(step_times, step_angles, t_samples)
        if st.size and st[0] < self._t:
            raise ValueError(f"step_times[0]={float(st[0])!r} is invalid: must be >= t0={self._t!r} s")
        if ts.size and ts[0] < self._t:
            raise ValueError(f"t_samples[0]={float(ts[0])!r} is invalid: must be >= t0={self._t!r} s")
        app_t, app_a = self._queue.due(st, sa, ts)
        theta = np.empty(ts.size)
        omega = np.empty(ts.size)
        n = app_t.size
        ev_list = app_t.tolist()
        ang_list = app_a.tolist()
        i = 0
        for j, s in enumerate(ts.tolist()):
            while i < n and ev_list[i] <= s:
                self._run_to(ev_list[i])
                self._step(ang_list[i], ev_list[i])
                i += 1
            self._run_to(s)
            theta[j] = self._cmd + self._e
            omega[j] = self._w
        return theta, omega

    # -- integration -------------------------------------------------------

    def _step(self, angle: float, t: float) -> None:
        self._cmd += angle
        self._e -= angle
        self._check_well(self._e + angle, self._e, t, t)

    def _check_well(self, e_from: float, e_to: float, t_from: float, t_to: float) -> None:
        """Register slips on the error segment (t_from, e_from) -> (t_to, e_to)."""
        p = self._axis.tooth_pitch

        def crossing(level: float) -> float:
            span = e_to - e_from
            frac = (level - e_from) / span if span != 0.0 else 1.0
            return t_from + min(max(frac, 0.0), 1.0) * (t_to - t_from)

        while True:
            k = self._well
            if e_to <= (k - 0.75) * p:
                d = -1
            elif e_to >= (k + 0.75) * p:
                d = 1
            else:
                break
            t_half = self._half_t if self._half_d == d else crossing((k + 0.5 * d) * p)
            self._slip_t.append(t_half)
            self._slip_s.append(d)
            self._well = k + d
            self._half_d = 0
        k = self._well
        d = -1 if e_to < (k - 0.5) * p else (1 if e_to > (k + 0.5) * p else 0)
        if d != self._half_d:
            self._half_d = d
            self._half_t = crossing((k + 0.5 * d) * p) if d else math.nan

    def _run_to(self, t_end: float) -> None:
        lt = self._lt
        if self._t < lt < t_end:
            self._integrate(lt)
        self._integrate(t_end)

    def _integrate(self, t_end: float) -> None:
        t = self._t
        if t_end <= t:
            return
        ax = self._axis
        a = ax.D / ax.J
        b = ax.peak_torque / ax.J
        c = (self._l_after if t >= self._lt else self._l_before) / ax.J
        zr = ax.Zr
        total = t_end - t
        nsteps = max(1, math.ceil(total / self._hmax))
        h = total / nsteps
        e, w = self._e, self._w
        for k in range(nsteps):
            t1 = t_end if k == nsteps - 1 else self._t + (k + 1) * h
            e1, w1 = self._macro(e, w, t1 - t, a, b, c, zr)
            self._check_well(e, e1, t, t1)
            e, w, t = e1, w1, t1
        self._e, self._w, self._t = e, w, t_end

    def _macro(
        self, e: float, w: float, H: float, a: float, b: float, c: float, zr: float
    ) -> tuple[float, float]:
        res = _gbs(e, w, H, a, b, c, zr, self._tol_e, self._tol_w)
        if res is not None:
            return res
        e1, w1 = self._macro(e, w, 0.5 * H, a, b, c, zr)
        return self._macro(e1, w1, 0.5 * H, a, b, c, zr)


_GBS_KMAX = 8


def _gbs(
    e0: float,
    w0: float,
    H: float,
    a: float,
    b: float,
    c: float,
    zr: float,
    tol_e: float,
    tol_w: float,
) -> tuple[float, float] | None:
    """One Gragg-Bulirsch-Stoer macro-step of e' = w, w' = -a*w - b*sin(zr*e) - c.

    Substep counts n_j = 2, 4, 6, ..., Gragg's smoothing, Aitken-Neville
    extrapolation in h**2. Returns None when no order up to 2*_GBS_KMAX agrees
    with the previous one to the tolerances.
    """
    sin = math.sin
    f0 = -a * w0 - b * sin(zr * e0) - c
    te: list[float] = []
    tw: list[float] = []
    for j in range(_GBS_KMAX):
        n = 2 * (j + 1)
        h = H / n
        h2 = 2.0 * h
        ep, wp = e0, w0
        ec, wc = e0 + h * w0, w0 + h * f0
        for _ in range(n - 1):
            fw = -a * wc - b * sin(zr * ec) - c
            ep, ec = ec, ep + h2 * wc
            wp, wc = wc, wp + h2 * fw
        fw = -a * wc - b * sin(zr * ec) - c
        ne = 0.5 * (ec + ep + h * wc)
        nw = 0.5 * (wc + wp + h * fw)
        # Aitken-Neville: row j from row j-1 (te, tw hold row j-1)
        row_e = [ne]
        row_w = [nw]
        for i in range(j):
            r = (n / (2 * (j - i))) ** 2 - 1.0
            row_e.append(row_e[i] + (row_e[i] - te[i]) / r)
            row_w.append(row_w[i] + (row_w[i] - tw[i]) / r)
        if j >= 2 and (abs(row_e[j] - row_e[j - 1]) <= tol_e and abs(row_w[j] - row_w[j - 1]) <= tol_w):
            return row_e[j], row_w[j]
        te, tw = row_e, row_w
    return None
