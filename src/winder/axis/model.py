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
``test/axis/test_stepper_model.py`` and ``docs/img/motor_startup.png``.

The rest of the axis is beside this module: the exact linear response (the
transition matrix and blocked scan used here, the modal sums) in
:mod:`winder.axis.linear`, the nonlinear integration and its slips in
:mod:`winder.axis.nonlinear`, the encoder in :mod:`winder.axis.encoder`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal, overload

import numpy as np
import numpy.typing as npt

from winder.axis._checks import ArrayLike, FloatArray, _angles, _positive, _vector
from winder.axis.linear import LinearTracker
from winder.axis.nonlinear import Load, LoadStep, NonlinearTracker
from winder.errors import BadInputError

__all__ = [
    "G_CM_S2",
    "PAPER",
    "SimResult",
    "StepperAxis",
]

#: kg*m**2 per g*cm*s**2 (the paper's inertia unit: gram-force * cm * s**2); also
#: N*m*s/rad per gf*cm*s/rad, e.g. ``StepperAxis.paper(D=0.03 * G_CM_S2)``.
G_CM_S2 = 9.80665e-5

#: Fastest natural frequency the model takes (rad/s): eight orders of magnitude
#: above a real stepper (the paper's: 279 rad/s), yet where a job's phases
#: w_n*t and exponentials stay finite in float64.
MAX_NATURAL_FREQUENCY = 1e12

#: The paper's motor (004, 2012, section 3), SI: Z_r, L [H], i_a [A], J [kg*m**2], D [N*m*s/rad].
PAPER: dict[str, float] = {
    "Zr": 40.0,
    "L": 0.01005,
    "i_a": 1.0,
    "J": 1.05 * G_CM_S2,
    "D": 0.03,
}


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
            raise BadInputError(f"phases={self.phases!r} is invalid: must be an integer in [1, 16]")
        K = self.Zr * self.peak_torque
        wn = math.sqrt(K / self.J) if K > 0 else 0.0
        zeta = self.D / (2.0 * math.sqrt(K * self.J)) if K * self.J > 0 else math.inf
        # each value alone may be in range and the motor still not be one the
        # model can compute: K underflowing to 0 (L or i_a of 1e-300), w_n
        # overflowing (J of 1e-300), zeta infinite
        if not (0.0 < K < math.inf and 0.0 < wn <= MAX_NATURAL_FREQUENCY and math.isfinite(zeta)):
            raise BadInputError(
                f"Zr={self.Zr:g}, L={self.L:g} H, i_a={self.i_a:g} A, J={self.J:g} kg*m**2, D={self.D:g} "
                f"give K={K:.3g} N*m/rad, w_n={wn:.3g} rad/s, zeta={zeta:.3g}: the model needs K > 0, "
                f"a finite zeta and w_n in (0, {MAX_NATURAL_FREQUENCY:g}] rad/s"
            )
        self._cache.update(K=K, wn=wn, zeta=zeta)

    @classmethod
    def paper(cls, **overrides: float) -> StepperAxis:
        """The 2012 paper's motor (:data:`PAPER`), optionally with some values replaced."""
        unknown = sorted(set(overrides) - set(PAPER))
        if unknown:
            raise BadInputError(f"paper({unknown[0]}=...) is invalid: only {list(PAPER)} can be replaced")
        p = {**PAPER, **overrides}
        return cls(p["Zr"], p["L"], p["i_a"], p["J"], p["D"])

    # -- derived quantities --------------------------------------------------

    @property
    def peak_torque(self) -> float:
        """T_m = Z_r*L*i_a**2/2: peak of the sine torque, the static pull-out torque (N*m)."""
        return 0.5 * self.Zr * self.L * (self.i_a * self.i_a)  # i_a**2 would raise OverflowError

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
                raise BadInputError(f"load={load!r} is invalid with model='linear': must be 0")
            theta, omega = self.linear_tracker().advance(st, sa, ts)
            slip_t, slips = no_slips
        elif model == "nonlinear":
            start = min(0.0, *(st[:1].tolist()), *(ts[:1].tolist())) if t0 is None else t0
            tr = self.nonlinear_tracker(load, t0=start)
            theta, omega = tr.advance(st, sa, ts)
            slip_t, slips = tr.slip_times, tr.slips
        else:
            raise BadInputError(f"model={model!r} is invalid: must be 'nonlinear' or 'linear'")
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
