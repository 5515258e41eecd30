"""Inertia and damping of the axes, identified from a recorded run: ROS-free.

The model of every axis, in motor angle (what the sim node simulates, see
:mod:`winder.axis`)::

    J*theta'' + D*theta' = T_e
    T_e = K*(theta1 - theta),  K = Z_r**2*L*i_a**2/2           (linear model)
    T_e = T_m*sin(Z_r*(theta1 - theta)) - T_load, T_m = Z_r*L*i_a**2/2  (nonlinear)

with the command theta1 (a staircase: one ``motor_step_angle`` per step, at
the recorded step times) and the rotor angle theta and speed omega from the
joint states (joint = theta / motor_step_angle * joint_step). Z_r, L, i_a and
the load come from ``winder/sim_config``; J and D are estimated, and compared
with the values the sim node used.

The equations: the model integrated exactly over each window
--------------------------------------------------------------
Integrated from sample t_k to the end of a window t_{k+m} the model is exact,
with no derivative of the data::

    J*(omega_{k+m} - omega_k) + D*(theta_{k+m} - theta_k) = Q_k = integral of T_e dt.

Q_k is integrated piece by piece between the step times (where theta1 is
constant), with theta(t) the cubic Hermite interpolant of the samples
(theta, omega at both ends of each sample interval) and 4-point
Gauss-Legendre quadrature on each piece: exact for the linear model (the
integrand is a cubic). The only approximation is the Hermite interpolant of
the rotor angle between samples, O(h**4) with h the sample period: the
motor's natural frequency (44.5 Hz for the defaults) must be well sampled.
Measured on noiseless recordings of the real nodes: J within 2 % (D within
0.02 %) at the default 200 Hz, within 0.02 % at ``--publish-rate 2000``.
:data:`WINDOW` sums the equations of several sample intervals (at 2 kHz, 10)
so that noise in the data is averaged; the integration stays at the sample
rate.

(b) least squares: Q = J*dw + D*dth over all windows in which the axis moves,
solved for (J, D). Q is the dependent variable: noise in theta enters Q
averaged over the window, and the regressors dw, dth are differences of
measured states, so encoder quantisation does not bias the estimate.

(a) MRAS, the dispensing-machine thesis (paper 001, section 2.4). Its
reference model, with damping neglected and b = T_s/J::

    omega(k) = 2*omega(k-1) - omega(k-2) + b*dT_e(k-1),

is the difference of two consecutive window equations above with D = 0.
Extended to damping it reads (p1 = 1/J, p2 = D/J)::

    dw_k - dw_{k-1} = p1*(Q_k - Q_{k-1}) - p2*(dth_k - dth_{k-1}),

and Landau's discrete adaptive law updates the parameter vector p with the
a-priori error e(k) of the adjustable model::

    p(k) = p(k-1) + beta*phi(k)*e(k) / (1 + beta*phi(k).phi(k)),
    phi(k) = (dQ(k), -d(dth)(k)) / (their RMS over the record).

With one parameter this is the thesis' law b(k) = b(k-1) + beta*dT_e*e /
(1 + beta*dT_e**2). The regressors are normalised so that the gain beta is
dimensionless and one value suits any motor (the thesis' beta = 0.01 is in
its own torque units); larger beta converges faster and fluctuates more. The
paper's J-only law (D = 0) is run too, for comparison: with the default
damping ratio of 0.52 it is far off, which is why D is estimated with J.
The estimates start from b = 0 (J unknown); ``iterations_1pct`` counts the
updates until J stays within 1 % of the recorded value. The value reported
is the settled estimate: the mean over the last quarter of the updates
(:data:`SETTLE_PART`), with the band it swings in there (min and max) and
its relative standard deviation (``mras_spread``). The estimate wanders most
during long cruises at 200 Hz, where the step ripple is sampled coarsely
(a spread of several % at 200 Hz, under 0.5 % at 2 kHz); the last update
alone, which a job's final deceleration (the phase that excites the inertia
most) pulls close to the recorded value, is reported beside it, not as the
result.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterable, Iterator
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from winder.errors import BadBagError, BadInputError
from winder.motion.axes import AXES
from winder.record.reader import AxisConfig, Run
from winder.spec import Spec, interval

__all__ = [
    "GAIN",
    "GAIN_RANGE",
    "IDENTIFY_SPECS",
    "MIN_STEPS",
    "WINDOW",
    "WINDOW_MAX",
    "AxisIdentification",
    "AxisRecord",
    "Equations",
    "Identification",
    "Mras",
    "axis_record",
    "equations",
    "format_identification",
    "identification_json",
    "identify",
    "least_squares",
    "mras",
    "with_noise",
]

FloatArray = npt.NDArray[np.float64]

#: default window of the integrated equations (s); at least one sample interval
WINDOW = 0.005
#: the longest window (s): its equations are counted in samples (MIN_WINDOWS of
#: them must fit the motion), and a recording holds its samples in memory
WINDOW_MAX = 1.0
#: step events integrated together when a record holds them in memory
EVENT_BATCH = 1 << 16
#: default MRAS gain beta (dimensionless: the regressors are normalised)
GAIN = 3.0
#: the gains beta may be, least and most: far below, the estimate of 1/J
#: hardly leaves 0 (and J, its inverse, overflows); far above, the law is the
#: normalised projection law whatever beta is
GAIN_RANGE = (1e-6, 1e6)
#: ``winder identify``'s settings, checked before a recording is read
IDENTIFY_SPECS = {
    "gain": Spec("gain", float, GAIN, "MRAS adaptation gain beta, dimensionless", "", *GAIN_RANGE),
    "window": Spec(
        "window",
        float,
        WINDOW * 1e3,
        "equation window (at least one sample: a shorter one is one sample)",
        "ms",
        0.0,
        WINDOW_MAX * 1e3,
        low_open=True,
    ),
}
#: the MRAS fluctuation is measured over the last 1/SETTLE_PART of its updates
SETTLE_PART = 4
#: an axis that moved fewer commanded steps is not identified
MIN_STEPS = 32
#: ... nor one moving in fewer windows
MIN_WINDOWS = 20
#: ... nor one whose least-squares J has a larger relative standard error
MAX_REL_SE = 0.05

_GL_X, _GL_W = np.polynomial.legendre.leggauss(4)


@dataclass(frozen=True)
class AxisRecord:
    """One axis of a run in motor angle: samples ``t`` (s), ``theta`` (rad),
    ``omega`` (rad/s); the command as step events ``step_t`` (s) with the
    command angle ``command`` (rad) after each, ``command0`` before the first.

    ``source``, when given, gives the step events instead, batch by batch (a
    recording's rows are read again each time: see :func:`axis_record`)."""

    axis: str
    t: FloatArray
    theta: FloatArray
    omega: FloatArray
    step_t: FloatArray
    command: FloatArray
    command0: float
    motor: AxisConfig
    model: str
    source: Callable[[], Iterable[tuple[FloatArray, FloatArray]]] | None = field(default=None, repr=False)

    def events(self) -> Iterable[tuple[FloatArray, FloatArray]]:
        """The step events (times s, command angles rad), in batches."""
        if self.source is not None:
            return self.source()
        return (
            (self.step_t[i : i + EVENT_BATCH], self.command[i : i + EVENT_BATCH])
            for i in range(0, self.step_t.size, EVENT_BATCH)
        )

    @property
    def steps_moved(self) -> int:
        last, moved = self.command0, 0.0
        for _, ec in self.events():
            moved, last = _moved(moved, last, ec, self.motor.motor_step_angle)
        return round(moved)


def _moved(moved: float, last: float, ec: FloatArray, step_angle: float) -> tuple[float, float]:
    """Steps moved so far, after the command angles ``ec`` following ``last``: (moved, new last)."""
    if ec.size == 0:
        return moved, last
    return moved + float(np.abs(np.diff(ec / step_angle, prepend=last / step_angle)).sum()), float(ec[-1])


def _events(run: Run) -> Iterator[list[tuple[FloatArray, FloatArray]]]:
    """The step events of every axis (times s, command angles rad), a recorded
    chunk at a time: one walk over the recording."""
    assert run.sim_config is not None
    angles = [run.sim_config.axes[a].motor_step_angle for a in AXES]
    prev = list(run.plan.segments[0].start) if run.plan.segments else [0] * len(AXES)
    for rows in run.step_rows:
        if rows.shape[0] == 0:
            continue
        out = []
        for ax, sa in enumerate(angles):
            pos = rows[:, 2 + ax]
            moved = np.diff(pos, prepend=prev[ax]) != 0
            prev[ax] = int(pos[-1])
            out.append((rows[moved, 0] / 1e9, pos[moved] * sa))
        yield out


def _axis_events(run: Run, ax: int) -> Iterator[tuple[FloatArray, FloatArray]]:
    return (batch[ax] for batch in _events(run))


def axis_record(run: Run, axis: str) -> AxisRecord:
    """The signals of ``axis`` (feed, fork or pole) in motor angle; the step
    events are read from the recording when needed, a chunk at a time."""
    if run.sim_config is None:
        raise BadBagError(f"{run.path}: no winder/sim_config message: the motor constants are unknown")
    if axis not in AXES:
        raise BadInputError(f"axis={axis!r} is invalid: must be one of {', '.join(AXES)}")
    i = AXES.index(axis)
    motor = run.sim_config.axes[axis]
    sa = motor.motor_step_angle
    js = run.plan.joint_step[i]
    st = run.states
    start = run.plan.segments[0].start[i] if run.plan.segments else 0
    return AxisRecord(
        axis=axis,
        t=st.t.copy(),
        theta=st.pos[:, i] / js * sa,
        omega=st.vel[:, i] / js * sa,
        step_t=np.zeros(0),
        command=np.zeros(0),
        command0=start * sa,
        motor=motor,
        model=run.sim_config.model,
        source=lambda: _axis_events(run, i),
    )


def with_noise(
    rec: AxisRecord,
    *,
    counts_per_rev: int | None = None,
    omega_sigma: float = 0.0,
    theta_sigma: float = 0.0,
    seed: int = 0,
) -> AxisRecord:
    """``rec`` as a sensor would give it: theta read by an encoder of
    ``counts_per_rev`` counts (rounded to the middle of its count), Gaussian
    noise of ``theta_sigma`` rad and ``omega_sigma`` rad/s added."""
    rng = np.random.default_rng(seed)
    theta = rec.theta + rng.normal(0.0, theta_sigma, rec.theta.size) if theta_sigma else rec.theta.copy()
    if counts_per_rev:
        r = 2 * math.pi / counts_per_rev
        theta = (np.floor(theta / r) + 0.5) * r
    omega = rec.omega + rng.normal(0.0, omega_sigma, rec.omega.size) if omega_sigma else rec.omega.copy()
    return replace(rec, theta=theta, omega=omega)


@dataclass(frozen=True)
class Equations:
    """The window equations J*dw + D*dth = q (see module doc), one per window."""

    q: FloatArray  #: torque impulse (N*m*s)
    dw: FloatArray  #: speed change (rad/s)
    dth: FloatArray  #: angle change (rad)
    t: FloatArray  #: end time of each window (s)
    window: float  #: window length (s)
    moving: npt.NDArray[np.bool_]  #: the axis moves or is commanded in the window
    steps_moved: int = 0  #: commanded steps of the axis over the record


def _torque(rec: AxisRecord, err: FloatArray) -> FloatArray:
    m = rec.motor
    if rec.model == "linear":
        return m.stiffness * err
    return m.peak_torque * np.sin(m.Zr * err) - m.load_torque


class _Integrator:
    """The integrals Q of the model over every sample interval, from the step
    events given in batches (in time order). The intervals are integrated as
    soon as every event before their end is in hand, each in one piece of
    work, so the sums are the same however the events are cut into batches
    and memory holds only the events of the intervals not yet integrated."""

    def __init__(self, rec: AxisRecord, window: float) -> None:
        self.rec, self.window = rec, window
        t = rec.t
        self.n = t.size
        if self.n >= 3 and np.any(np.diff(t) <= 0):
            raise BadBagError(f"{rec.axis}: joint sample times do not increase")
        size = max(self.n - 1, 0)
        self.q = np.zeros(size)
        self.steps_in = np.zeros(size, np.int64)
        self.k_done = 0  #: the intervals before this are integrated
        self.cmd = rec.command0  #: the command at t[k_done] (after every event at or before it)
        self.pending_t: list[FloatArray] = []
        self.pending_c: list[FloatArray] = []
        self.last = rec.command0  #: the last command seen, for the steps moved
        self.moved = 0.0

    def run(self, events: Iterable[tuple[FloatArray, FloatArray]]) -> Equations:
        for et, ec in events:
            self.add(np.asarray(et, np.float64), np.asarray(ec, np.float64))
        return self.finish()

    def add(self, et: FloatArray, ec: FloatArray) -> None:
        if et.size == 0:
            return
        self.moved, self.last = _moved(self.moved, self.last, ec, self.rec.motor.motor_step_angle)
        self.pending_t.append(et)
        self.pending_c.append(ec)
        if self.n >= 3:
            # an interval is whole once an event at or after its end has come
            k_hi = min(int(np.searchsorted(self.rec.t[1:], et[-1], side="right")), self.n - 1)
            if k_hi > self.k_done:
                self._integrate(k_hi)

    def _integrate(self, k_hi: int) -> None:
        """Integrate the intervals k_done .. k_hi - 1 with the pending events."""
        t, th, w = self.rec.t, self.rec.theta, self.rec.omega
        et = np.concatenate(self.pending_t) if len(self.pending_t) > 1 else self.pending_t[0]
        ec = np.concatenate(self.pending_c) if len(self.pending_c) > 1 else self.pending_c[0]
        lo, hi = self.k_done, k_hi
        tt = t[lo : hi + 1]
        early = et <= tt[0]
        if np.any(early):
            self.cmd = float(ec[np.nonzero(early)[0][-1]])
        inside_m = (et > tt[0]) & (et < tt[-1])
        inside_t, inside_c = et[inside_m], ec[inside_m]
        # pieces between consecutive sample and step times; the command is constant on each
        edges = np.union1d(tt, inside_t)
        a0, a1 = edges[:-1], edges[1:]
        j = np.searchsorted(inside_t, a0, side="right") - 1
        cmd = (
            np.where(j >= 0, inside_c[np.maximum(j, 0)], self.cmd)
            if inside_c.size
            else np.full(a0.size, self.cmd)
        )
        k = np.clip(np.searchsorted(tt, a0, side="right") - 1, 0, hi - lo - 1) + lo
        h = t[k + 1] - t[k]
        th0, th1, w0, w1 = th[k], th[k + 1], w[k] * h, w[k + 1] * h
        half = 0.5 * (a1 - a0)
        mid = 0.5 * (a1 + a0)
        q = np.zeros(hi - lo)
        for x, wt in zip(_GL_X, _GL_W, strict=True):
            s = (mid + half * x - t[k]) / h
            s2 = s * s
            s3 = s2 * s
            theta = (
                (2 * s3 - 3 * s2 + 1) * th0
                + (s3 - 2 * s2 + s) * w0
                + (3 * s2 - 2 * s3) * th1
                + (s3 - s2) * w1
            )
            q += np.bincount(k - lo, weights=wt * half * _torque(self.rec, cmd - theta), minlength=hi - lo)
        self.q[lo:hi] = q
        if inside_t.size:
            where = np.clip(np.searchsorted(tt, inside_t, side="right") - 1, 0, hi - lo - 1)
            self.steps_in[lo:hi] += np.bincount(where, minlength=hi - lo)
        # the events up to the new start are spent: the command there is what they left
        spent = et <= tt[-1]
        if np.any(spent):
            self.cmd = float(ec[np.nonzero(spent)[0][-1]])
        keep = ~spent
        self.pending_t = [et[keep]] if np.any(keep) else []
        self.pending_c = [ec[keep]] if np.any(keep) else []
        self.k_done = hi

    def finish(self) -> Equations:
        rec, n = self.rec, self.n
        moved = round(self.moved)
        if n < 3:
            z = np.zeros(0)
            return Equations(z, z, z, z, 0.0, np.zeros(0, dtype=bool), moved)
        if self.k_done < n - 1:
            if not self.pending_t:
                self.pending_t, self.pending_c = [np.zeros(0)], [np.zeros(0)]
            self._integrate(n - 1)
        t, th, w = rec.t, rec.theta, rec.omega
        h_mean = float(t[-1] - t[0]) / (n - 1)
        # samples a window; one past the recording holds no equation (its count also no overflow)
        m = max(1, round(min(self.window / h_mean, n)))
        dw = np.diff(w)
        dth = np.diff(th)
        # the axis takes part in an interval if it is commanded or moves in it
        speed = np.maximum(np.abs(w[:-1]), np.abs(w[1:]))
        moving = (self.steps_in > 0) | (speed > 1e-9 * max(float(np.max(np.abs(w))), 1e-300))
        nw = (n - 1) // m
        cut = nw * m

        def group(v: npt.NDArray[Any]) -> npt.NDArray[Any]:
            out: npt.NDArray[Any] = v[:cut].reshape(nw, m).sum(axis=1)
            return out

        return Equations(
            q=group(self.q),
            dw=group(dw),
            dth=group(dth),
            t=t[m : cut + 1 : m],
            window=m * h_mean,
            moving=group(moving.astype(np.int64)) > 0,
            steps_moved=moved,
        )


def equations(rec: AxisRecord, window: float = WINDOW) -> Equations:
    """The model integrated over windows of about ``window`` s (module doc)."""
    return _Integrator(rec, window).run(rec.events())


def least_squares(eq: Equations) -> tuple[float, float, float, float]:
    """(J, D) from the window equations in which the axis moves, and their
    standard errors from the residuals."""
    sel = eq.moving
    X = np.column_stack([eq.dw[sel], eq.dth[sel]])
    y = eq.q[sel]
    if y.size < 3:
        return math.nan, math.nan, math.inf, math.inf
    scale = np.sqrt(np.mean(X * X, axis=0))
    scale[scale == 0] = 1.0
    sol, _, rank, _ = np.linalg.lstsq(X / scale, y, rcond=None)
    if rank < 2:
        return math.nan, math.nan, math.inf, math.inf
    p = sol / scale
    r = y - X @ p
    s2 = float(r @ r) / max(y.size - 2, 1)
    cov = s2 * np.linalg.inv((X / scale).T @ (X / scale)) / np.outer(scale, scale)
    return float(p[0]), float(p[1]), float(math.sqrt(cov[0, 0])), float(math.sqrt(cov[1, 1]))


@dataclass(frozen=True)
class Mras:
    """The MRAS estimate after every update (module doc): ``J`` and ``D`` (NaN
    while 1/J <= 0), the thesis' ``b`` = T_s/J, at the windows' end times ``t``."""

    t: FloatArray
    J: FloatArray
    D: FloatArray
    b: FloatArray
    gain: float

    @property
    def final(self) -> tuple[float, float]:
        """The estimate after the last update."""
        return (float(self.J[-1]), float(self.D[-1])) if self.J.size else (math.nan, math.nan)

    @property
    def settle_start(self) -> int:
        """The first update of the last 1/SETTLE_PART, over which the estimate
        is taken as settled (0 with no updates)."""
        return max(0, self.J.size - max(1, self.J.size // SETTLE_PART))

    def _tail(self, x: FloatArray) -> FloatArray:
        tail = x[self.settle_start :]
        return tail[np.isfinite(tail)]

    @property
    def spread(self) -> float:
        """Relative standard deviation of J over the last 1/SETTLE_PART of the updates."""
        j = self._tail(self.J)
        return float(j.std() / j.mean()) if j.size > 1 else math.nan

    @property
    def settled(self) -> tuple[float, float, float, float, float, float]:
        """The settled estimate and its spread: the mean, min and max of J and
        of D over the last 1/SETTLE_PART of the updates (J mean, J min, J max,
        D mean, D min, D max); the last update alone still swings with the
        excitation of the moment."""
        j, d = self._tail(self.J), self._tail(self.D)
        nan = math.nan
        jj = (float(j.mean()), float(j.min()), float(j.max())) if j.size else (nan, nan, nan)
        dd = (float(d.mean()), float(d.min()), float(d.max())) if d.size else (nan, nan, nan)
        return (*jj, *dd)

    def iterations_within(self, value: float, tol: float = 0.01) -> int | None:
        """Updates until J stays within ``tol`` of ``value`` for good (None: never)."""
        if self.J.size == 0:
            return None
        bad = ~(np.abs(self.J / value - 1) <= tol)
        if bad[-1]:
            return None
        idx = np.nonzero(bad)[0]
        return int(idx[-1] + 1) if idx.size else 0


def _check_gain(gain: float) -> None:
    if not (math.isfinite(gain) and GAIN_RANGE[0] <= gain <= GAIN_RANGE[1]):
        raise BadInputError(f"gain={gain!r} is invalid: must be in {interval(*GAIN_RANGE)}")


def mras(eq: Equations, gain: float = GAIN, *, damping: bool = True) -> Mras:
    """The thesis' MRAS with Landau's discrete law (module doc); ``damping=False``
    is the thesis' own J-only law (D taken as 0)."""
    _check_gain(gain)
    sel = np.nonzero(eq.moving)[0]
    sel = sel[sel >= 1]
    y = eq.dw[sel] - eq.dw[sel - 1]
    phi = np.column_stack([eq.q[sel] - eq.q[sel - 1], -(eq.dth[sel] - eq.dth[sel - 1])])
    if not damping:
        phi = phi[:, :1]
    z = np.zeros(0)
    if y.size == 0:
        return Mras(z, z, z, z, gain)
    scale = np.sqrt(np.mean(phi * phi, axis=0))
    scale[scale == 0] = 1.0
    ph = phi / scale
    p = np.zeros(ph.shape[1])
    traj = np.empty_like(ph)
    for i in range(y.size):  # recursive by nature: one update per window
        f = ph[i]
        e = y[i] - float(f @ p)
        p = p + f * (e / (1.0 / gain + float(f @ f)))  # beta/(1 + beta f.f), no beta*f*e to overflow
        traj[i] = p
    inv_j = traj[:, 0] / scale[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        J = np.where(inv_j > 0, 1.0 / inv_j, np.nan)
        D = traj[:, 1] / scale[1] * J if damping else np.zeros_like(J)
    return Mras(eq.t[sel], J, D, inv_j * eq.window, gain)


@dataclass(frozen=True)
class AxisIdentification:
    """J and D of one axis by least squares and by MRAS, against the recorded values."""

    axis: str
    identifiable: bool
    reason: str  #: why not, when not
    steps_moved: int
    windows: int  #: windows in which the axis moves
    J_true: float
    D_true: float
    ls_J: float
    ls_D: float
    ls_J_se: float  #: standard error (kg*m^2)
    ls_D_se: float
    mras_J: float  #: the settled estimate: the mean over the last quarter of the updates
    mras_D: float
    #: the settled estimate's band: min and max over the last quarter of the updates
    mras_J_band: tuple[float, float]
    mras_D_band: tuple[float, float]
    mras_J_last: float  #: the estimate after the last update
    mras_D_last: float
    mras_spread: float  #: relative std of J over the last quarter of the updates
    mras_iterations: int
    mras_iterations_1pct: int | None
    mras_time_1pct: float | None  #: s of the run at which J stays within 1 %
    paper_mras_J: float  #: the thesis' J-only law (D neglected)
    trajectory: Mras | None = field(default=None, repr=False)
    #: s of the run: the first of the updates the settled estimate is the mean of
    mras_settled_from: float | None = None

    #: the resonance of the identified axis: w_n = sqrt(K/J), zeta = D/(2 sqrt(K J)) with the
    #: least-squares J, D and the recorded stiffness K = Z_r^2 L i_a^2 / 2 (what `winder tune`
    #: and the profile node's shaper_freq / shaper_damping take)
    f_n: float = math.nan  #: Hz
    zeta: float = math.nan
    f_n_true: float = math.nan  #: of the recorded motor
    zeta_true: float = math.nan
    ls_J_err: float = math.nan  #: relative error against the recorded value
    ls_D_err: float = math.nan
    mras_J_err: float = math.nan
    mras_D_err: float = math.nan
    paper_mras_J_err: float = math.nan


@dataclass(frozen=True)
class Identification:
    label: str
    path: str
    model: str
    publish_rate: float
    window: float  #: s
    gain: float
    complete: bool
    axes: dict[str, AxisIdentification]
    notes: list[str] = field(default_factory=list)


def identify_axis(
    rec: AxisRecord, gain: float = GAIN, window: float = WINDOW, eq: Equations | None = None
) -> AxisIdentification:
    """Identify one axis from its record (module doc); ``eq``: its
    :func:`equations` with ``window``, if made already."""
    if eq is None:
        eq = equations(rec, window)
    moved = eq.steps_moved
    windows = int(np.count_nonzero(eq.moving))
    nan = math.nan
    base: dict[str, Any] = dict(axis=rec.axis, steps_moved=moved, windows=windows)
    base.update(J_true=rec.motor.J, D_true=rec.motor.D)
    k = rec.motor.Zr * rec.motor.peak_torque  # N m / rad
    base.update(resonance(k, rec.motor.J, rec.motor.D, "_true"))
    empty: dict[str, Any] = dict(
        ls_J=nan,
        ls_D=nan,
        ls_J_se=nan,
        ls_D_se=nan,
        mras_J=nan,
        mras_D=nan,
        mras_J_band=(nan, nan),
        mras_D_band=(nan, nan),
        mras_J_last=nan,
        mras_D_last=nan,
        mras_spread=nan,
        mras_iterations=0,
        mras_iterations_1pct=None,
        mras_time_1pct=None,
        paper_mras_J=nan,
    )
    if moved < MIN_STEPS or windows < MIN_WINDOWS:
        why = (
            f"not identifiable: too little excitation (the {rec.axis} axis moved {moved} steps "
            f"in {windows} windows; at least {MIN_STEPS} steps and {MIN_WINDOWS} windows needed)"
        )
        return AxisIdentification(identifiable=False, reason=why, **base, **empty)
    J, D, J_se, D_se = least_squares(eq)
    if not (math.isfinite(J) and J > 0 and math.isfinite(D) and J_se / J <= MAX_REL_SE):
        rel = (
            f"+-{100 * J_se / abs(J):.0f} %"
            if math.isfinite(J) and J and math.isfinite(J_se)
            else "undetermined"
        )
        why = f"not identifiable: too little excitation (least-squares J is {rel})"
        return AxisIdentification(identifiable=False, reason=why, **base, **empty)
    traj = mras(eq, gain)
    paper = mras(eq, gain, damping=False)
    found = resonance(k, J, D)
    mJ, j_lo, j_hi, mD, d_lo, d_hi = traj.settled
    it = traj.iterations_within(rec.motor.J)

    def err(x: float, ref: float) -> float:
        return x / ref - 1 if ref else math.nan

    return AxisIdentification(
        identifiable=True,
        reason="",
        **base,
        ls_J=J,
        ls_D=D,
        ls_J_se=J_se,
        ls_D_se=D_se,
        mras_J=mJ,
        mras_D=mD,
        mras_J_band=(j_lo, j_hi),
        mras_D_band=(d_lo, d_hi),
        mras_J_last=traj.final[0],
        mras_D_last=traj.final[1],
        mras_spread=traj.spread,
        mras_iterations=int(traj.J.size),
        mras_iterations_1pct=it,
        mras_time_1pct=None if it is None else float(traj.t[max(it - 1, 0)]),
        paper_mras_J=paper.final[0],
        trajectory=traj,
        mras_settled_from=float(traj.t[traj.settle_start]),
        ls_J_err=err(J, rec.motor.J),
        ls_D_err=err(D, rec.motor.D),
        mras_J_err=err(mJ, rec.motor.J),
        mras_D_err=err(mD, rec.motor.D),
        paper_mras_J_err=err(paper.final[0], rec.motor.J),
        f_n=found["f_n"],
        zeta=found["zeta"],
    )


def resonance(k: float, J: float, D: float, suffix: str = "") -> dict[str, float]:
    """f_n (Hz) and zeta of an axis of stiffness ``k`` with ``J`` and ``D``."""
    if not (k > 0 and J > 0 and math.isfinite(D)):
        return {f"f_n{suffix}": math.nan, f"zeta{suffix}": math.nan}
    wn = math.sqrt(k / J)
    return {f"f_n{suffix}": wn / (2 * math.pi), f"zeta{suffix}": max(D, 0.0) / (2 * math.sqrt(k * J))}


def identify(run: Run, gain: float = GAIN, window: float = WINDOW) -> Identification:
    """Identify J and D of every axis of a recorded run."""
    if not (math.isfinite(window) and 0 < window <= WINDOW_MAX):
        raise BadInputError(
            f"window={window!r} s is invalid: must be in {interval(0, WINDOW_MAX, low_open=True)} s"
        )
    _check_gain(gain)
    if run.sim_config is None:
        raise BadBagError(f"{run.path}: no winder/sim_config message: the motor constants are unknown")
    if len(run.states) < 3:
        raise BadBagError(f"{run.path}: fewer than 3 joint states recorded: nothing to identify")
    notes = list(run.notes)
    rate = run.sim_config.publish_rate
    if rate < 1000:
        notes.append(
            f"joint states at {rate:g} Hz: expect J errors of up to about 2 % from the sampling "
            "(record with --publish-rate 2000 for 0.1 %)"
        )
    records = [axis_record(run, a) for a in AXES]
    integrators = [_Integrator(rec, window) for rec in records]
    for batches in _events(run):
        for integ, (et, ec) in zip(integrators, batches, strict=True):
            integ.add(et, ec)
    axes = {
        rec.axis: identify_axis(rec, gain, window, integ.finish())
        for rec, integ in zip(records, integrators, strict=True)
    }
    h = float(run.states.t[-1] - run.states.t[0]) / (len(run.states) - 1)
    return Identification(
        label=run.label,
        path=str(run.path),
        model=run.sim_config.model,
        publish_rate=rate,
        window=max(1, round(window / h)) * h,
        gain=gain,
        complete=run.complete,
        axes=axes,
        notes=notes,
    )


# -- output -----------------------------------------------------------------------------


def _pct(x: float) -> str:
    """A relative error in %, signed; one that rounds to zero is 0.000 %, never -0.000 %."""
    if not math.isfinite(x):
        return "-"
    text = f"{100 * x:+.3f}"
    return f"{'0.000' if float(text) == 0.0 else text} %"


def _g(x: float) -> str:
    return "-" if not math.isfinite(x) else f"{x:.5g}"


def _band(band: tuple[float, float], true: float) -> str:
    """The min-max band of an estimate as errors against the recorded value."""
    lo, hi = band
    if not (math.isfinite(lo) and math.isfinite(hi) and true):
        return "-"
    return f"{_pct(lo / true - 1)} .. {_pct(hi / true - 1)}"


def format_identification(ident: Identification) -> str:
    """A readable table: per axis, recorded vs estimated J and D."""
    lines = [
        f"{ident.label}: {ident.model} model, joint states at {ident.publish_rate:g} Hz, "
        f"window {ident.window * 1e3:.3g} ms, MRAS gain {ident.gain:g}",
        f"{'axis':5s} {'':6s} {'recorded':>11s} {'least sq.':>11s} {'error':>10s} "
        f"{'MRAS mean':>11s} {'error':>10s}  MRAS min .. max, last quarter",
    ]
    for a in ident.axes.values():
        if not a.identifiable:
            lines.append(f"{a.axis:5s} {a.reason}")
            continue
        lines.append(
            f"{a.axis:5s} {'J':6s} {_g(a.J_true):>11s} {_g(a.ls_J):>11s} {_pct(a.ls_J_err):>10s} "
            f"{_g(a.mras_J):>11s} {_pct(a.mras_J_err):>10s}  {_band(a.mras_J_band, a.J_true)}"
        )
        lines.append(
            f"{'':5s} {'D':6s} {_g(a.D_true):>11s} {_g(a.ls_D):>11s} {_pct(a.ls_D_err):>10s} "
            f"{_g(a.mras_D):>11s} {_pct(a.mras_D_err):>10s}  {_band(a.mras_D_band, a.D_true)}"
        )
        tr = a.trajectory
        first = tr.settle_start + 1 if tr is not None else 0
        conv = (
            f"J within 1 % for good after update {a.mras_iterations_1pct} (t = {a.mras_time_1pct:.3f} s)"
            if a.mras_iterations_1pct is not None
            else "J never within 1 % for good"
        )
        lines.append(
            f"{'':5s} MRAS settled = the mean of updates {first}..{a.mras_iterations} "
            f"(t >= {a.mras_settled_from:.3f} s), J std +-{100 * a.mras_spread:.2g} %; "
            f"last update J {_pct(a.mras_J_last / a.J_true - 1)}"
        )
        lines.append(f"{'':5s} {conv}; the thesis' J-only law: J {_pct(a.paper_mras_J_err)}")
        lines.append(
            f"{'':5s} resonance (least squares): f_n {a.f_n:.2f} Hz, zeta {a.zeta:.3f}  "
            f"(recorded motor: {a.f_n_true:.2f} Hz, {a.zeta_true:.3f}); shaper_freq / shaper_damping"
        )
    lines += [f"note: {n}" for n in ident.notes]
    return "\n".join(lines)


def identification_json(idents: list[Identification], trajectory_points: int = 200) -> str:
    """JSON text; each MRAS trajectory thinned to about ``trajectory_points`` points."""

    def clean(x: Any) -> Any:
        if isinstance(x, float):
            return x if math.isfinite(x) else None
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        if isinstance(x, list):
            return [clean(v) for v in x]
        return x

    out = []
    for ident in idents:
        d = asdict(ident)
        for name, a in ident.axes.items():
            ax = d["axes"][name]
            ax.pop("trajectory", None)
            tr = a.trajectory
            if tr is not None and tr.J.size:
                step = max(1, tr.J.size // trajectory_points)
                ax["mras_trajectory"] = {
                    "t": tr.t[::step].tolist(),
                    "J": tr.J[::step].tolist(),
                    "D": tr.D[::step].tolist(),
                    "b": tr.b[::step].tolist(),
                }
        out.append(clean(d))
    return json.dumps(out, indent=2)
