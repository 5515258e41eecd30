"""Second-order model of the winder's stepper axes, exact, and the loss of steps.

The model is the rotor equation of the 2012 stepper paper (004, eq. 9) with the
commanded angle theta1 (a staircase) as the field's stable position::

    J*theta'' + D*theta' + T_m*sin(Z_r*(theta - theta1)) + T_load = 0,
    T_m = Z_r*L*i_a**2/2                      (peak holding torque, N*m)

and its linearisation around the command (eq. 12-13)::

    J*theta'' + D*theta' + K*(theta - theta1) = 0,   K = Z_r*T_m = Z_r**2*L*i_a**2/2
    G(s) = theta2/theta1 = Z_r**2*L*i_a**2 / (2*J*s**2 + 2*D*s + Z_r**2*L*i_a**2).

Everything is SI: angles in rad (mechanical), time in s, angular velocity in
rad/s, torque in N*m, inertia in kg*m**2, damping in N*m*s/rad, inductance in H,
current in A. The paper gives J = 1.05 g*cm*s**2; 1 g*cm*s**2 = 9.80665e-5
kg*m**2 (:data:`G_CM_S2`).

Step angle, tooth pitch and lost steps
--------------------------------------
The field's stable equilibria repeat every tooth pitch ``2*pi/Z_r`` (one
electrical period). A motor with ``m`` phases driven in full steps visits
``2*m`` field positions per electrical period (A, B, -A, -B for m = 2), so its
full step is ``2*pi/(2*m*Z_r)``: the paper's Z_r = 40 two-phase motor has
160 full steps per turn, 2.25 deg (a 1.8 deg motor has Z_r = 50). A microstep
drive with ideal sine/cosine currents commands finer angles with the same
torque law, so ``step_angle`` may be any angle. When the rotor falls more than
half a tooth pitch behind or ahead of the command it is past the unstable
equilibrium and settles one pitch away (counted once it has gone on into that
well, see :class:`SimResult`): one *slip* = one tooth pitch =
``2*m`` full steps (4 for the paper's motor) = ``pitch/|step_angle|`` commanded
steps (see :meth:`SimResult.lost_in`).

What the paper's numbers give
-----------------------------
T_m = 0.201 N*m, K = 8.04 N*m/rad, w_n = 279 rad/s (44.5 Hz), zeta = 0.52 with
D = 0.03 N*m*s/rad. Read in SI, that damping caps the speed: a constant-speed
run needs D*w <= T_m, so w <= T_m/D = 6.7 rad/s (:attr:`StepperAxis.pull_out_speed`;
about 6.0 rad/s in full steps, whose staircase ripple costs torque), below the
paper's own w_max = 20 rad/s, and with J/D = 3.4 ms the rotor has too little
inertia for a ramp to matter below that speed. The paper's comparison holds in
its linear analysis (G(s): the lag D*w/K at 20 rad/s is 0.95 of half a pitch,
and without a ramp the transient exceeds half a pitch) and, in the sine-torque
model, for a lightly damped rotor: D = 0.003 N*m*s/rad (zeta = 0.05) - or the
paper's D = 0.03 read in its own gravitational units, 0.03 gf*cm*s/rad =
2.9e-6 N*m*s/rad - where a start at 20 rad/s without ramp slips and the
exponential and S-curve starts in 1/16 microsteps do not (in full steps the
slow sweep through the 44.5 Hz resonance makes even the ramps slip). See
``test/test_motor.py`` and ``docs/img/motor_startup.png``.

Exact linear response
---------------------
Between steps the command is constant, so the error state z = (theta - theta1,
omega) evolves as z(t) = Phi(t - t_k) z(t_k) with the closed-form transition
matrix (sigma = zeta*w_n, beta**2 = sigma**2 - w_n**2)::

    Phi(t) = e**(-sigma*t) * [C*I + S*(A + sigma*I)],   C = cosh(beta*t),
    S = sinh(beta*t)/beta   (cos(w_d*t), sin(w_d*t)/w_d below critical damping),

written with ``sinc`` and ``expm1`` so that it is continuous and free of
cancellation across zeta = 1 (both forms tend to C = 1, S = t). A step of angle
d subtracts (d, 0) from z. The recurrence over N steps is evaluated with a
blocked scan: within blocks of ~sqrt(N) steps a vectorised loop runs across all
blocks at once from a zero state, the block-end states are chained by the same
scan one level up, and each step's state is corrected with Phi of its distance
to the previous block end. Every Phi is evaluated forward in time (contractive),
so the result is as accurate as the sequential recurrence, in O(N) numpy work
and O(sqrt(N)) Python iterations.

Below damping ratio ``MODAL_ZETA`` (0.95) :class:`LinearTracker` does not need
every step's state: the error is the real part of one complex mode, and the
state at a sample is a running sum of one complex exponential per step (see
``LinearTracker._advance_modal``); the scan serves the rest.
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal, overload

import numpy as np
import numpy.typing as npt

__all__ = [
    "G_CM_S2",
    "PAPER",
    "LinearTracker",
    "LoadStep",
    "NonlinearTracker",
    "SimResult",
    "StepperAxis",
    "measured_velocity",
]

#: kg*m**2 per g*cm*s**2 (the paper's inertia unit: gram-force * cm * s**2); also
#: N*m*s/rad per gf*cm*s/rad, e.g. ``StepperAxis.paper(D=0.03 * G_CM_S2)``.
G_CM_S2 = 9.80665e-5

#: The paper's motor (004, 2012, section 3), SI: Z_r, L [H], i_a [A], J [kg*m**2], D [N*m*s/rad].
PAPER: dict[str, float] = {
    "Zr": 40.0,
    "L": 0.01005,
    "i_a": 1.0,
    "J": 1.05 * G_CM_S2,
    "D": 0.03,
}

FloatArray = npt.NDArray[np.float64]

#: Damping ratios below which :class:`LinearTracker` sums modal terms (see
#: ``LinearTracker._advance_modal``); at and above it, the blocked scan.
#: kappa = -1 + i*zeta/sqrt(1 - zeta**2) stays below 3.1 in magnitude.
MODAL_ZETA = 0.95
#: Largest sigma*(t - b) within one window of the modal sum: terms up to e**30.
MODAL_WINDOW = 30.0
ArrayLike = float | Sequence[float] | npt.NDArray[np.floating]


def _positive(name: str, value: object, unit: str, *, allow_zero: bool = False) -> float:
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        v = math.nan
    if isinstance(value, bool) or not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name}={value!r} is invalid: must be finite and {bound} ({unit})")
    return v


def _vector(name: str, value: object, *, sorted_: bool = False) -> FloatArray:
    a = np.asarray(value, dtype=np.float64)
    if a.ndim == 0:
        a = a.reshape(1)
    if a.ndim != 1:
        raise ValueError(f"{name} has shape {a.shape}: must be a 1-D array of times/angles")
    if sorted_ and a.size > 1:
        # one pass: NaN fails every comparison, so it reads as unsorted unless
        # the order holds, and then only the ends can be infinite
        if not np.all(a[1:] >= a[:-1]):
            if not np.all(np.isfinite(a)):
                raise ValueError(f"{name} contains non-finite values: all must be finite")
            raise ValueError(f"{name} is not sorted: must be non-decreasing (s)")
        if not (math.isfinite(a[0]) and math.isfinite(a[-1])):
            raise ValueError(f"{name} contains non-finite values: all must be finite")
    elif not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains non-finite values: all must be finite")
    return a


def _angles(step_angle: object, n: int) -> FloatArray:
    a = np.asarray(step_angle, dtype=np.float64)
    if a.ndim == 0:
        a = np.full(n, float(a))
    elif a.ndim != 1 or a.size != n:
        raise ValueError(f"step_angle has shape {a.shape}: must be a scalar or one angle per step ({n})")
    if not np.all(np.isfinite(a)):
        raise ValueError("step_angle contains non-finite values: all must be finite (rad)")
    return a


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
                raise ValueError(f"LoadStep.{name}={v!r} is invalid: must be finite")


Load = float | LoadStep


@dataclass(frozen=True)
class SimResult:
    """Output of :meth:`StepperAxis.simulate` at the sample times ``t`` (SI).

    ``slips`` holds one entry per change of the rotor's equilibrium well
    relative to the command: -1 when the rotor dropped one pitch back (negative
    direction) relative to the command, +1 when it went one pitch ahead;
    ``slip_times`` when it happened (s). A slip is the error theta - theta1
    passing half a tooth pitch (the unstable equilibrium) beyond the current
    well and going on into the next one, to within a quarter pitch of its stable
    point (3/4 pitch from the old one); it is dated at the half-pitch crossing.
    An excursion past half a pitch that turns back - typically right after a
    command step, when the rotor's momentum carries it back over the hump - is
    no slip. A slip that is undone later counts twice in :attr:`lost_steps`
    and zero times in :attr:`offset_steps`.
    """

    t: FloatArray
    theta: FloatArray
    omega: FloatArray
    command: FloatArray
    slip_times: FloatArray
    slips: npt.NDArray[np.int64]
    pitch: float
    steps_per_pitch: int

    @property
    def error(self) -> FloatArray:
        """Tracking error theta - theta1 at the samples (rad)."""
        return self.theta - self.command

    @property
    def lost_steps(self) -> int:
        """Full steps slipped, every well change counted (``steps_per_pitch`` per slip)."""
        return int(self.steps_per_pitch * self.slips.size)

    @property
    def offset_steps(self) -> int:
        """Net full steps by which the rotor's well ends ahead (+) or behind (-) the command."""
        return int(self.steps_per_pitch * int(self.slips.sum()))

    def lost_in(self, step_angle: float) -> float:
        """Slipped angle counted in commanded steps of ``step_angle`` rad (e.g. microsteps)."""
        return float(self.slips.size * self.pitch / abs(step_angle))


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

    def __init__(self, axis: StepperAxis, method: Literal["auto", "modal", "scan"] = "auto") -> None:
        self._axis = axis
        self._t = -math.inf  # time of the held state (last applied step); -inf: at rest
        self._z = (0.0, 0.0)  # error state (theta - theta1, omega) just after that step
        self._cmd = 0.0  # theta1 after the applied steps (rad)
        zeta = axis.damping_ratio
        if method not in ("auto", "modal", "scan"):
            raise ValueError(f"method={method!r} is invalid: must be 'auto', 'modal' or 'scan'")
        if method == "modal" and not zeta < MODAL_ZETA:
            raise ValueError(f"method='modal' needs damping ratio < {MODAL_ZETA}, this axis has {zeta!r}")
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

        one complex exponential per step and a running sum. The base time b
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
        cmd_at = self._cmd + np.concatenate([[0.0], _cumulative(app_a)])  # after j steps
        k_all = np.searchsorted(app_t, ts, side="right")  # steps applied at each sample
        theta = np.empty(ts.size)
        omega = np.empty(ts.size)
        lo = s_lo = 0
        while True:
            hi = int(np.searchsorted(app_t, base + self._span, side="right")) if lo < n else n
            # this window's samples: all those that need no later step
            s_hi = ts.size if hi == n else int(np.searchsorted(k_all, hi, side="right"))
            # sums[j]: sum of d_k*e**(-lambda*(t_k - b)) over the window's first j steps;
            # the state at b after them is q + kappa*sums[j] (formed at the samples only)
            sums = np.empty(hi - lo + 1, np.complex128)
            sums[0] = 0.0
            if hi > lo:
                u = sums[1:]
                parts = u.view(np.float64).reshape(-1, 2)  # real and imaginary columns
                d = base - app_t[lo:hi]
                np.multiply(d, lam.real, out=parts[:, 0])  # lambda*d without a complex cast of d
                np.multiply(d, lam.imag, out=parts[:, 1])
                np.exp(u, out=u)
                parts *= app_a[lo:hi, None]
                np.cumsum(u, out=u)
            if s_hi > s_lo:
                k = k_all[s_lo:s_hi]
                qs = (q + kappa * sums[k - lo]) * np.exp(lam * (ts[s_lo:s_hi] - base))
                theta[s_lo:s_hi] = cmd_at[k] + qs.real
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


class _StepQueue:
    """The steps a tracker was given that no sample has reached yet, and the
    order rules of ``advance`` (see :class:`LinearTracker`), shared by both
    trackers."""

    def __init__(self) -> None:
        self.t = np.empty(0)  # pending step times (s)
        self.a = np.empty(0)  # their angles (rad)
        self.last_step = -math.inf
        self.last_sample = -math.inf

    def check(
        self, step_times: object, step_angles: object, t_samples: object
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Validated (step_times, step_angles, t_samples) of one advance() call."""
        return _check_chunk(step_times, step_angles, t_samples, self.last_step, self.last_sample)

    def due(self, st: FloatArray, sa: FloatArray, ts: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Queue the checked steps; return (times, angles) of those at or before
        the last sample (all of them to apply now), the rest stay pending."""
        if st.size:
            self.last_step = float(st[-1])
        ev_t = np.concatenate([self.t, st]) if self.t.size else st
        ev_a = np.concatenate([self.a, sa]) if self.a.size else sa
        if ts.size == 0:
            self.t, self.a = ev_t, ev_a
            return ev_t[:0], ev_a[:0]
        self.last_sample = float(ts[-1])
        n = int(np.searchsorted(ev_t, ts[-1], side="right"))
        self.t, self.a = ev_t[n:], ev_a[n:]
        return ev_t[:n], ev_a[:n]


def _check_chunk(
    step_times: object,
    step_angles: object,
    t_samples: object,
    last_step: float,
    last_sample: float,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Validated (step_times, step_angles, t_samples) of one advance() call."""
    st = _vector("step_times", step_times, sorted_=True)
    sa = _angles(step_angles, st.size)
    if st.size and st[0] < last_step:
        raise ValueError(
            f"step_times[0]={float(st[0])!r} is invalid: must be >= the last step time already "
            f"given ({last_step!r} s)"
        )
    if st.size and st[0] < last_sample:
        raise ValueError(
            f"step_times[0]={float(st[0])!r} is invalid: must be >= the last sample time already "
            f"returned ({last_sample!r} s)"
        )
    ts = _vector("t_samples", t_samples, sorted_=True)
    if ts.size and ts[0] < last_sample:
        raise ValueError(
            f"t_samples[0]={float(ts[0])!r} is invalid: must be >= the last sample time already "
            f"returned ({last_sample!r} s)"
        )
    return st, sa, ts


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
        axis: StepperAxis,
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
                raise ValueError(f"load={load!r} is invalid: must be a finite torque (N*m) or LoadStep")
            self._lt, self._l_before, self._l_after = math.inf, v, v
        if not math.isfinite(t0):
            raise ValueError(f"t0={t0!r} is invalid: must be finite (s)")
        _positive("max_phase_step", max_phase_step, "rad")
        if not (1e-15 <= rtol <= 1e-3):
            raise ValueError(f"rtol={rtol!r} is invalid: must be in [1e-15, 1e-3]")
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


@dataclass(frozen=True)
class StepperAxis:
    """A stepper axis: the paper's rotor equation (SI units throughout).

    Parameters: ``Zr`` rotor teeth, ``L`` phase inductance (H), ``i_a`` phase
    current (A), ``J`` rotor + load inertia (kg*m**2), ``D`` viscous damping
    (N*m*s/rad), ``phases`` number of motor phases m (full step
    2*pi/(2*m*Zr)).
    """

    Zr: float
    L: float
    i_a: float
    J: float
    D: float
    phases: int = 2
    _cache: dict[str, float] = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name, unit in (("Zr", "rotor teeth"), ("L", "H"), ("i_a", "A"), ("J", "kg*m**2")):
            object.__setattr__(self, name, _positive(name, getattr(self, name), unit))
        object.__setattr__(self, "D", _positive("D", self.D, "N*m*s/rad", allow_zero=True))
        if (
            isinstance(self.phases, bool)
            or not isinstance(self.phases, (int, np.integer))
            or not (1 <= self.phases <= 16)
        ):
            raise ValueError(f"phases={self.phases!r} is invalid: must be an integer in [1, 16]")
        K = self.Zr * self.peak_torque
        wn = math.sqrt(K / self.J)
        zeta = self.D / (2.0 * math.sqrt(K * self.J))
        self._cache.update(K=K, wn=wn, zeta=zeta)

    @classmethod
    def paper(cls, **overrides: float) -> StepperAxis:
        """The 2012 paper's motor (:data:`PAPER`), optionally with some values replaced."""
        unknown = sorted(set(overrides) - set(PAPER))
        if unknown:
            raise ValueError(f"paper({unknown[0]}=...) is invalid: only {list(PAPER)} can be replaced")
        p = {**PAPER, **overrides}
        return cls(p["Zr"], p["L"], p["i_a"], p["J"], p["D"])

    # -- derived quantities --------------------------------------------------

    @property
    def peak_torque(self) -> float:
        """T_m = Z_r*L*i_a**2/2: peak of the sine torque, the static pull-out torque (N*m)."""
        return 0.5 * self.Zr * self.L * self.i_a**2

    @property
    def stiffness(self) -> float:
        """K = Z_r*T_m, linearised torque per rad of error (N*m/rad)."""
        return self._cache["K"]

    @property
    def natural_frequency(self) -> float:
        """w_n = sqrt(K/J) (rad/s)."""
        return self._cache["wn"]

    @property
    def damping_ratio(self) -> float:
        """zeta = D / (2*sqrt(K*J))."""
        return self._cache["zeta"]

    @property
    def tooth_pitch(self) -> float:
        """2*pi/Z_r: the period of the sine torque, one electrical period (rad)."""
        return 2.0 * math.pi / self.Zr

    @property
    def full_step(self) -> float:
        """2*pi/(2*m*Z_r): full-step angle (rad); 2.25 deg for the paper's motor."""
        return self.tooth_pitch / (2 * self.phases)

    @property
    def steps_per_pitch(self) -> int:
        """Full steps per tooth pitch, 2*m: the full steps lost in one slip."""
        return 2 * self.phases

    @property
    def pull_out_speed(self) -> float:
        """T_m/D: above this speed viscous torque exceeds the peak torque, no
        constant-speed run exists whatever the ramp (rad/s; inf for D = 0)."""
        return math.inf if self.D == 0 else self.peak_torque / self.D

    @property
    def transfer_function(self) -> tuple[FloatArray, FloatArray]:
        """G(s) = theta2/theta1 as (num, den) coefficients in descending powers of s."""
        k2 = self.Zr**2 * self.L * self.i_a**2
        return np.array([k2]), np.array([2.0 * self.J, 2.0 * self.D, k2])

    # -- linear model ---------------------------------------------------------

    def _transition(self, tau: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Phi(tau) = expm(A*tau) of the error dynamics, tau >= 0, entries (m11, m12, m21, m22)."""
        wn, zeta = self._cache["wn"], self._cache["zeta"]
        sig = zeta * wn
        tau = np.asarray(tau, dtype=np.float64)
        if zeta < 1.0:
            wd = wn * math.sqrt((1.0 - zeta) * (1.0 + zeta))
            x = wd * tau
            decay = np.exp(-sig * tau)
            E = np.cos(x)
            E *= decay
            F = np.sin(x)
            F *= decay / wd  # wd >= w_n*1.5e-8 here: sin(x)/wd -> tau is exact enough
        elif zeta == 1.0:
            E = np.exp(-sig * tau)
            F = tau * E
        else:
            beta = wn * math.sqrt((zeta - 1.0) * (zeta + 1.0))
            slow = wn * wn / (sig + beta)  # sigma - beta without cancellation
            es = np.exp(-slow * tau)
            r = np.expm1(-2.0 * beta * tau)  # e**(-2*beta*tau) - 1
            E = es * (1.0 + 0.5 * r)
            F = es * (-r / (2.0 * beta))
        sF = sig * F
        return E + sF, F, -(wn * wn) * F, E - sF

    def _scan(self, t: FloatArray, b0: FloatArray, b1: FloatArray) -> tuple[FloatArray, FloatArray]:
        """z_k = Phi(t_k - t_{k-1}) z_{k-1} + b_k with z_{-1} = 0, for sorted t."""
        n = t.size
        if n <= 64:
            z0 = np.empty(n)
            z1 = np.empty(n)
            m11, m12, m21, m22 = (x.tolist() for x in self._transition(np.diff(t)))
            a0, a1 = float(b0[0]), float(b1[0])
            z0[0], z1[0] = a0, a1
            for k in range(1, n):
                a0, a1 = (
                    m11[k - 1] * a0 + m12[k - 1] * a1 + b0[k],
                    m21[k - 1] * a0 + m22[k - 1] * a1 + b1[k],
                )
                z0[k], z1[k] = a0, a1
            return z0, z1
        # blocks of B ~ n**(1/3) steps: B Python iterations over arrays of n/B blocks
        B = max(8, round(n ** (1 / 3)))
        nb = -(-n // B)
        pad = nb * B - n
        T = np.concatenate([t, np.full(pad, t[-1])]).reshape(nb, B)
        Tt = np.ascontiguousarray(T.T)  # (B, nb): row j = j-th step of every block
        B0 = np.ascontiguousarray(np.concatenate([b0, np.zeros(pad)]).reshape(nb, B).T)
        B1 = np.ascontiguousarray(np.concatenate([b1, np.zeros(pad)]).reshape(nb, B).T)
        m11, m12, m21, m22 = self._transition(np.diff(Tt, axis=0))
        # pass 1: each block from a zero state, keeping only its end state
        p0, p1 = B0[0].copy(), B1[0].copy()
        for j in range(1, B):
            p0, p1 = (
                m11[j - 1] * p0 + m12[j - 1] * p1 + B0[j],
                m21[j - 1] * p0 + m22[j - 1] * p1 + B1[j],
            )
        # chain the block ends one level up: the true state at the end of every block
        e0, e1 = self._scan(T[:, -1], p0, p1)
        # pass 2: the same recurrence from each block's true initial state
        c11, c12, c21, c22 = self._transition(Tt[0, 1:] - T[:-1, -1])
        y0 = np.empty((B, nb))
        y1 = np.empty((B, nb))
        y0[0], y1[0] = B0[0], B1[0]
        y0[0, 1:] += c11 * e0[:-1] + c12 * e1[:-1]
        y1[0, 1:] += c21 * e0[:-1] + c22 * e1[:-1]
        for j in range(1, B):
            q0, q1 = y0[j - 1], y1[j - 1]
            y0[j] = m11[j - 1] * q0 + m12[j - 1] * q1 + B0[j]
            y1[j] = m21[j - 1] * q0 + m22[j - 1] * q1 + B1[j]
        return y0.T.reshape(-1)[:n], y1.T.reshape(-1)[:n]

    def linear_tracker(self) -> LinearTracker:
        """A streaming exact linear response (see :class:`LinearTracker`)."""
        return LinearTracker(self)

    @overload
    def response(
        self,
        step_times: ArrayLike,
        step_angle: ArrayLike,
        t: ArrayLike,
        *,
        velocity: Literal[False] = False,
    ) -> FloatArray: ...

    @overload
    def response(
        self,
        step_times: ArrayLike,
        step_angle: ArrayLike,
        t: ArrayLike,
        *,
        velocity: Literal[True],
    ) -> tuple[FloatArray, FloatArray]: ...

    def response(
        self,
        step_times: ArrayLike,
        step_angle: ArrayLike,
        t: ArrayLike,
        *,
        velocity: bool = False,
    ) -> FloatArray | tuple[FloatArray, FloatArray]:
        """Exact rotor angle theta2 (rad) of the linear model at the times ``t`` (s).

        The command is a staircase from 0 with one step of ``step_angle`` (rad;
        a scalar or one signed angle per step) at each of ``step_times`` (s, any
        order); a step at exactly a sample time is applied before the sample. The
        axis is at rest at 0 before the first step. ``velocity=True`` returns
        (theta, omega) with omega in rad/s. Samples may be in any order.
        """
        st = _vector("step_times", step_times)
        sa = _angles(step_angle, st.size)
        ts = _vector("t", t)
        if st.size > 1 and np.any(st[1:] < st[:-1]):
            order = np.argsort(st, kind="stable")
            st, sa = st[order], sa[order]
        if ts.size > 1 and np.any(ts[1:] < ts[:-1]):
            s_order = np.argsort(ts, kind="stable")
            th_s, om_s = self.linear_tracker().advance(st, sa, ts[s_order])
            theta = np.empty_like(th_s)
            omega = np.empty_like(om_s)
            theta[s_order] = th_s
            omega[s_order] = om_s
        else:
            theta, omega = self.linear_tracker().advance(st, sa, ts)
        return (theta, omega) if velocity else theta

    # -- nonlinear model ------------------------------------------------------

    def nonlinear_tracker(
        self,
        load: Load = 0.0,
        *,
        t0: float = 0.0,
        max_phase_step: float = 0.5,
        rtol: float = 1e-11,
    ) -> NonlinearTracker:
        """Nonlinear simulation, streaming, from rest at 0 at ``t0`` (:class:`NonlinearTracker`)."""
        return NonlinearTracker(self, load, t0=t0, max_phase_step=max_phase_step, rtol=rtol)

    def simulate(
        self,
        step_times: ArrayLike,
        step_angle: ArrayLike,
        t: ArrayLike,
        *,
        load: Load = 0.0,
        model: Literal["nonlinear", "linear"] = "nonlinear",
        t0: float | None = None,
    ) -> SimResult:
        """Rotor response to a staircase command at the sorted sample times ``t`` (s).

        ``model="nonlinear"``: the sine-torque equation with ``load`` (a constant
        torque in N*m, or a :class:`LoadStep`), from rest at theta = 0 at ``t0``
        (default: the earliest of 0, the first step and the first sample), with
        the slips it suffers. ``model="linear"``: the exact linear response; the
        linear model cannot slip (``slips`` is empty; compare
        ``abs(result.error)`` with half a pitch for the paper's criterion).
        """
        st = _vector("step_times", step_times)
        sa = _angles(step_angle, st.size)
        ts = _vector("t", t, sorted_=True)
        order = np.argsort(st, kind="stable")
        st, sa = st[order], sa[order]
        cmd = np.concatenate([[0.0], np.cumsum(sa)])[np.searchsorted(st, ts, side="right")]
        no_slips = (np.empty(0), np.empty(0, dtype=np.int64))
        if model == "linear":
            if isinstance(load, LoadStep) or load != 0.0:
                raise ValueError(f"load={load!r} is invalid with model='linear': must be 0")
            theta, omega = self.linear_tracker().advance(st, sa, ts)
            slip_t, slips = no_slips
        elif model == "nonlinear":
            start = min(0.0, *(st[:1].tolist()), *(ts[:1].tolist())) if t0 is None else t0
            tr = self.nonlinear_tracker(load, t0=start)
            theta, omega = tr.advance(st, sa, ts)
            slip_t, slips = tr.slip_times, tr.slips
        else:
            raise ValueError(f"model={model!r} is invalid: must be 'nonlinear' or 'linear'")
        return SimResult(
            t=ts,
            theta=theta,
            omega=omega,
            command=cmd,
            slip_times=slip_t,
            slips=slips,
            pitch=self.tooth_pitch,
            steps_per_pitch=self.steps_per_pitch,
        )


def measured_velocity(theta: ArrayLike, period: float, *, resolution: float | None = None) -> FloatArray:
    """Velocity as a controller reads it from an encoder (rad/s).

    ``theta`` are true angles (rad) sampled every ``period`` s. With
    ``resolution`` (rad per count) the encoder reports floor(theta/resolution)
    counts. Returns the backward difference of the readings over one period, the
    same length as ``theta``; the first value is 0 (no earlier reading; the axis
    starts at rest). It estimates the mean velocity over the last period, so it
    lags the true velocity by period/2.
    """
    th = _vector("theta", theta)
    p = _positive("period", period, "s")
    if resolution is not None:
        r = _positive("resolution", resolution, "rad per count")
        th = np.floor(th / r) * r
    v = np.zeros(th.size)
    v[1:] = np.diff(th) / p
    return v
