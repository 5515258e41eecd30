"""Residual vibration of a move with and without input shaping.

A *test move* is one axis' move of ``steps`` steps with an S-curve ramp; the
motor is the paper's (``StepperAxis.paper``) with its damping set for a
chosen damping ratio. Each *method* times the same steps differently:

* ``none``: the plan as it is;
* an input shaper (``zv``, ``mzv``, ``zvd``, ``ei``, ``2hump_ei``) designed
  for ``f_design = f_n * (1 + error)`` and the motor's damping ratio;
* ``scurve_1/f``: no shaper, the jerk limit lowered so that each jerk phase
  lasts ``1/f_design`` (a zero of the ramp's spectrum at that frequency):
  ``a_max * f`` where ``a_max`` is reached, ``v_max * f**2`` where the
  acceleration only peaks (the smaller of the two).

The test move is the physical move of the default fork (0.78 turn in 1 s,
up to 4.9 rad/s) in steps ten times finer than its own (2 pi / 51200 rad):
every commanded step starts a small ringing of its own, which no timing of
the steps removes; at the default step it is about one step peak to peak
and would hide what the time law does.

The *residual vibration* is the peak-to-peak tracking error (rotor minus
command, in steps) over the settle window once the command is at rest, from
the exact linear response or the nonlinear (sine-torque) model sampled at
``rate``. Its ratio to the unshaped move's is the *reduction*.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from winder.axis.model import StepperAxis
from winder.motion.profile import Profile, plan
from winder.motion.shaped import Motion, shape

__all__ = [
    "ERRORS",
    "METHODS",
    "Row",
    "TestMove",
    "motor_for",
    "move_for",
    "residual",
    "residual_table",
]

METHODS = ("none", "zv", "mzv", "zvd", "ei", "2hump_ei", "scurve_1/f")
ERRORS = (-0.2, -0.1, 0.0, 0.1, 0.2)


@dataclass(frozen=True)
class TestMove:
    """The move and how it is watched (steps, steps/s, /s^2, /s^3; s; Hz)."""

    __test__ = False  # a test move, not a pytest test class

    steps: int = 40_000
    v_max: float = 40_000.0
    a_max: float = 1e7
    j_max: float = 1e10
    step_angle: float = 2 * math.pi / 51_200
    settle: float = 0.25
    rate: float = 20_000.0


def motor_for(zeta: float, **overrides: float) -> StepperAxis:
    """The paper's motor with the viscous damping that gives ``zeta``."""
    ref = StepperAxis.paper(**overrides)
    d = 2.0 * zeta * math.sqrt(ref.stiffness * ref.J)
    return StepperAxis.paper(**{**overrides, "D": d})


def move_for(move: TestMove, method: str, f_design: float, zeta_design: float) -> Motion:
    """The test move timed by ``method`` (see the module doc)."""
    if method == "scurve_1/f":
        j = min(move.a_max * f_design, move.v_max * f_design**2)
        return plan("scurve", float(move.steps), v_max=move.v_max, a_max=move.a_max, j_max=j)
    base: Profile = plan("scurve", float(move.steps), v_max=move.v_max, a_max=move.a_max, j_max=move.j_max)
    return shape(base, method, f_design, zeta_design)


@dataclass
class Result:
    """One simulated move: the residual (steps, peak to peak), the steps the
    nonlinear model lost, the move's duration (s), and the error trace."""

    residual: float
    lost_steps: int
    duration: float
    t: npt.NDArray[np.float64] = field(repr=False)
    error: npt.NDArray[np.float64] = field(repr=False)


def residual(axis: StepperAxis, motion: Motion, move: TestMove, model: str) -> Result:
    """Simulate ``motion`` (its step times) on ``axis``; the residual vibration."""
    times = motion.step_times(move.steps)
    t = np.arange(0.0, times[-1] + move.settle, 1.0 / move.rate)
    r = axis.simulate(times, move.step_angle, t, model="linear" if model == "linear" else "nonlinear")
    err = (r.theta - r.command) / move.step_angle
    window = t >= times[-1]
    return Result(float(np.ptp(err[window])), int(r.lost_steps), float(times[-1]), t, err)


@dataclass(frozen=True)
class Row:
    model: str
    zeta: float
    method: str
    duration: float  #: the move's duration at the nominal design (s)
    added: float  #: over the unshaped move (s)
    residuals: tuple[float, ...]  #: at each of ERRORS (steps, peak to peak)
    lost: tuple[int, ...]  #: steps lost at each of ERRORS (nonlinear model)
    reference: float  #: the unshaped move's residual


def residual_table(
    models: Sequence[str] = ("linear", "nonlinear"),
    zetas: Sequence[float] = (0.52, 0.05),
    methods: Sequence[str] = METHODS,
    errors: Sequence[float] = ERRORS,
    move: TestMove = TestMove(),
    progress: object = None,
) -> list[Row]:
    """The residual-vibration table: every model, damping ratio and method at
    every design frequency error."""
    rows: list[Row] = []
    total = len(models) * len(zetas) * len(methods) * len(errors)
    done = 0
    for model in models:
        for zeta in zetas:
            axis = motor_for(zeta)
            f_n = axis.natural_frequency / (2 * math.pi)
            z = axis.damping_ratio
            ref = residual(axis, move_for(move, "none", f_n, z), move, model)
            for method in methods:
                res, lost = [], []
                nominal = ref.duration
                for e in errors:
                    if method == "none":
                        r = ref
                    else:
                        r = residual(axis, move_for(move, method, f_n * (1 + e), z), move, model)
                    if e == 0.0:
                        nominal = r.duration
                    res.append(r.residual)
                    lost.append(r.lost_steps)
                    done += 1
                    if callable(progress):
                        progress(done, total)
                rows.append(
                    Row(
                        model,
                        zeta,
                        method,
                        nominal,
                        nominal - ref.duration,
                        tuple(res),
                        tuple(lost),
                        ref.residual,
                    )
                )
    return rows
