"""The ramp a motor and its load allow: ``winder tune``.

Given a job and each axis' motor (J, D, load torque, step angle; resonance
f_n and damping ratio zeta follow from them), find the ramp limits (v_max,
a_max, j_max) and input shaper that wind the job fastest, such that

* every axis' torque stays ``margin`` below the motor's pull-out torque at
  every instant: ``J*alpha + D*omega + |T_load| <= (1 - margin) * T_m`` (in
  this model the sine torque's peak ``T_m`` does not fall with speed: the
  drive holds the current), and
* the nonlinear (sine-torque) model of every moving axis loses no step on
  any of the job's distinct moves.

The search is a fixed grid, so the answer is the same every time: for each
shaper (none, zv, zvd, ei) and jerk time (``1/f_n`` of the major axis, a
quarter and a sixteenth of it), 20 peak speeds up to the torque's cruise
limit; each speed takes the largest acceleration the torque leaves at that
speed. Candidates are ranked by job time (the exact plan of every segment,
:func:`winder.motion.timing.plan_timing`) and the fastest one whose moves
the nonlinear model runs without a slip is the answer.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from winder.axis.model import StepperAxis
from winder.contract.params import PROFILE_SPECS, SIM_SPECS
from winder.errors import BadInputError
from winder.motion.axes import AXES
from winder.motion.interp import interpolate
from winder.motion.job import Job
from winder.motion.timing import plan_timing
from winder.spec import interval

__all__ = [
    "MARGIN",
    "MARGIN_RANGE",
    "Axis",
    "Candidate",
    "TuneResult",
    "axes_of",
    "check_limits",
    "check_size",
    "tune",
]

MARGIN = 0.3
#: the torque margin, at least and below (the high end open: no torque left at all)
MARGIN_RANGE = (0.0, 1.0)
SHAPERS = ("none", "zv", "zvd", "ei")
JERK_TIMES = (1.0, 0.25, 0.0625)  #: jerk phase in periods of the major axis' resonance
SPEEDS = 20
SETTLE = 0.5  #: simulated time after a move's last step (s)
#: steps of a move, at most: every distinct move is simulated whole, each
#: candidate's (a move of 10^6 steps took 20 s and 200 MB; one of 1.3*10^9
#: was killed for its memory)
MAX_MOVE_STEPS = 2**21


@dataclass(frozen=True)
class Axis:
    """One axis' motor as the sim node has it."""

    name: str
    motor: StepperAxis
    step_angle: float  #: motor angle per commanded step (rad)
    load: float  #: constant load torque (N m)

    @property
    def f_n(self) -> float:
        return self.motor.natural_frequency / (2 * math.pi)

    @property
    def zeta(self) -> float:
        return self.motor.damping_ratio


def axes_of(sim: dict[str, Any]) -> list[Axis]:
    """Every axis' motor from the sim node's settings (defaults where absent)."""
    values = {n: s.default for n, s in SIM_SPECS.items()}
    values.update(sim)
    out = []
    for ax in AXES:
        m = StepperAxis(
            values[f"{ax}.Zr"], values[f"{ax}.L"], values[f"{ax}.i_a"], values[f"{ax}.J"], values[f"{ax}.D"]
        )
        out.append(Axis(ax, m, float(values[f"{ax}.motor_step_angle"]), float(values[f"{ax}.load_torque"])))
    return out


@dataclass(frozen=True)
class Candidate:
    shaper: str
    jerk_time: float  #: periods of the major axis' resonance
    ramp: dict[str, Any]
    job_time: float  #: s
    lost_steps: int | None = None  #: None: not simulated


@dataclass
class TuneResult:
    ramp: dict[str, Any]  #: the profile node's settings found
    job_time: float
    current_time: float
    current_lost: int
    checked: list[Candidate] = field(default_factory=list)  #: simulated, in order


def _ratios(job: Job) -> list[tuple[int, list[float]]]:
    """Each distinct move: its step count and each axis' steps per major step."""
    seen: dict[tuple[int, tuple[float, ...]], None] = {}
    for s in job.segments():
        n = s.steps
        r = tuple(abs(d) / n for d in s.delta)
        seen[(n, r)] = None
    return [(n, list(r)) for n, r in seen]


def accel_limit(axes: Sequence[Axis], ratios: Sequence[list[float]], v: float, margin: float) -> float:
    """The largest a_max (major steps/s^2) the torque allows at the peak speed
    ``v`` on every move (-inf if the cruise alone is too much)."""
    best = math.inf
    for r in ratios:
        for ax, ri in zip(axes, r, strict=True):
            if ri == 0.0:
                continue
            k = ri * ax.step_angle  # rad per major step
            spare = (1 - margin) * ax.motor.peak_torque - abs(ax.load) - ax.motor.D * v * k
            best = min(best, spare / (ax.motor.J * k))
    return best


def speed_limit(axes: Sequence[Axis], ratios: Sequence[list[float]], margin: float) -> float:
    """The peak speed (major steps/s) at which the cruise torque alone reaches the margin."""
    best = math.inf
    for r in ratios:
        for ax, ri in zip(axes, r, strict=True):
            if ri == 0.0 or ax.motor.D == 0.0:
                continue
            k = ri * ax.step_angle
            best = min(best, ((1 - margin) * ax.motor.peak_torque - abs(ax.load)) / (ax.motor.D * k))
    return best


def check_size(job: Job) -> None:
    """ValueError (one line) if a move of ``job`` is too long to simulate
    whole (:data:`MAX_MOVE_STEPS`): checked from the step counts, before
    anything is simulated or allocated."""
    longest = max(job.segments(), key=lambda s: s.steps, default=None)
    if longest is not None and longest.steps > MAX_MOVE_STEPS:
        what = longest.kind.words
        raise BadInputError(
            f"job {job.job_id}: a {what} of {longest.steps} steps is too long to tune: each distinct move "
            f"is simulated whole, at most {MAX_MOVE_STEPS} steps (fewer turns_per_layer or "
            "fork_steps_per_rev)"
        )


def lost_steps(job: Job, ramp: dict[str, Any], axes: Sequence[Axis]) -> int:
    """Steps the nonlinear model loses over the job's distinct moves, every
    moving axis simulated from rest with its steps at the ramp's times (as the
    profile node times them, to the nanosecond)."""
    lost = 0
    done: set[tuple[int, tuple[int, ...]]] = set()
    for seg in job.segments():
        key = (seg.steps, tuple(abs(d) for d in seg.delta))
        if key in done:
            continue
        done.add(key)
        timing, _ = plan_timing(ramp, [seg.steps])
        k = np.arange(1, seg.steps + 1)
        t = timing[0].times_ns(k) / 1e9
        pos = interpolate([0] * len(seg.delta), [abs(d) for d in seg.delta])
        for i, ax in enumerate(axes):
            if seg.delta[i] == 0:
                continue
            moved = np.diff(np.concatenate([[0], pos[:, i]])) != 0
            ts = t[moved]
            samples = np.linspace(0.0, float(ts[-1]) + SETTLE, 400)
            r = ax.motor.simulate(ts, ax.step_angle, samples, load=ax.load, model="nonlinear")
            lost += round(r.lost_in(ax.step_angle))  # in the axis' own commanded steps
    return lost


def _ramp(base: dict[str, Any], **changes: Any) -> dict[str, Any]:
    out = dict(base)
    out.update(changes)
    return out


def check_limits(ramp: dict[str, Any]) -> dict[str, Any]:
    """Clip a ramp's limits into their settings' ranges."""
    out = dict(ramp)
    for name in ("v_max", "a_max", "j_max"):
        spec = PROFILE_SPECS[name]
        assert spec.high is not None
        out[name] = float(min(out[name], spec.high))
    return out


def tune(
    job: Job,
    profile: dict[str, Any],
    axes: Sequence[Axis],
    *,
    margin: float = MARGIN,
    progress: Callable[[int, int], None] | None = None,
) -> TuneResult:
    """The fastest ramp for ``job`` on ``axes`` with the torque ``margin``
    and no lost step (see the module doc). ``profile``: the current ramp
    (its v_start and dwell are kept)."""
    if not MARGIN_RANGE[0] <= margin < MARGIN_RANGE[1]:
        raise BadInputError(
            f"margin={margin!r} is invalid: must be in {interval(*MARGIN_RANGE, high_open=True)}"
        )
    check_size(job)
    current = {n: s.default for n, s in PROFILE_SPECS.items()}
    current.update(profile)
    segments = [s.steps for s in job.segments()]
    _, cur_ns = plan_timing(current, segments, job.stops if hasattr(job, "stops") else ())
    moves = _ratios(job)
    ratios = [r for _, r in moves]
    v_cap = min(speed_limit(axes, ratios, margin), PROFILE_SPECS["v_max"].high or math.inf)
    # the major axis of most of the job: its resonance sets the jerk time and the shaper
    major = max(range(len(AXES)), key=lambda i: sum(n * r[i] for n, r in moves))
    f_n, zeta = axes[major].f_n, min(axes[major].zeta, PROFILE_SPECS["shaper_damping"].high or 0.0)
    if not (math.isfinite(v_cap) and v_cap > 0):
        raise BadInputError(f"margin={margin:g}: the motors have no torque left for any speed")
    candidates: list[Candidate] = []
    for shaper in SHAPERS:
        for jt in JERK_TIMES:
            for i in range(SPEEDS):
                v = v_cap * (0.25 + 0.75 * i / (SPEEDS - 1))
                a = accel_limit(axes, ratios, v, margin)
                if not a > 0.0:
                    continue
                j = a * f_n / jt
                ramp = check_limits(
                    _ramp(
                        current, profile="scurve", v_max=v, a_max=a, j_max=j,
                        shaper=shaper, shaper_freq=f_n, shaper_damping=zeta,
                    )
                )  # fmt: skip
                try:
                    _, ns = plan_timing(ramp, segments)
                except ValueError:
                    continue
                candidates.append(Candidate(shaper, jt, ramp, ns / 1e9))
    candidates.sort(key=lambda c: (c.job_time, SHAPERS.index(c.shaper), -c.jerk_time))
    checked: list[Candidate] = []
    for n, cand in enumerate(candidates):
        if progress is not None:
            progress(n + 1, len(candidates))
        lost = lost_steps(job, cand.ramp, axes)
        checked.append(Candidate(cand.shaper, cand.jerk_time, cand.ramp, cand.job_time, lost))
        if lost == 0:
            return TuneResult(cand.ramp, cand.job_time, cur_ns / 1e9, lost_steps(job, current, axes), checked)
    raise BadInputError(f"margin={margin:g}: every ramp tried loses steps in the nonlinear model")
