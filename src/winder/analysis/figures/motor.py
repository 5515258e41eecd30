"""Figure: why ramping matters - the paper's start-up comparison (004, figs. 5-7).

Three starts to w_max = 20 rad/s in 1/16 microsteps of the paper's Z_r = 40
two-phase motor: no ramp (steps at the full rate from t = 0), the exponential
ramp (1/tau = 0.85) and the S-curve (jerk 4, a_max 4), step times from
:func:`winder.motion.profile.plan`.

* rows 1-2, the paper's own analysis (linear G(s), its parameters): rotor
  velocity, and the tracking error against half a tooth pitch, past which the
  rotor would slip;
* row 3, the same motor with the sine torque: D = 0.03 N*m*s/rad makes the
  viscous torque at 20 rad/s three times the peak torque, so every start slips
  (pull-out speed T_m/D = 6.7 rad/s);
* row 4, a lightly damped rotor (D = 0.003, zeta = 0.05) with the sine
  torque: the start without ramp slips, the ramps do not.

    .venv/bin/python -m winder.analysis.figures.motor [outdir]
"""

from __future__ import annotations

import math
import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from winder.axis import SimResult, StepperAxis, measured_velocity
from winder.contract.files import atomic_file, output_dir
from winder.motion.profile import Profile, plan

W_MAX = 20.0  # rad/s, the paper's target
TAU = 1 / 0.85  # s, the paper's exponential time constant
A_MAX = 4.0  # rad/s^2
J_MAX = 4.0  # rad/s^3
MICRO = 16
T_END = 7.0  # s
T_ZOOM = 0.15  # s
COLORS = {"none": "tab:red", "exponential": "tab:blue", "scurve": "tab:green"}
LABELS = {
    "none": "no ramp",
    "exponential": "exponential, 1/tau = 0.85",
    "scurve": "S-curve, j = 4, a = 4",
}


def start_steps(kind: str, step: float) -> tuple[np.ndarray, Profile | None]:
    """Step times (s) of a start to W_MAX over [0, T_END], and the velocity profile."""
    if kind == "none":
        n = int(W_MAX * T_END / step)
        return step * np.arange(1, n + 1) / W_MAX, None
    n = math.ceil(2 * W_MAX * T_END / step)  # long enough to cruise past T_END
    distance = n * step
    if kind == "scurve":
        prof = plan("scurve", distance, v_max=W_MAX, a_max=A_MAX, j_max=J_MAX)
    else:
        prof = plan("exponential", distance, v_max=W_MAX, tau=TAU)
    times = prof.step_times(n)
    return times[times <= T_END], prof


def _simulate(axis: StepperAxis, times: np.ndarray, step: float, model: str) -> SimResult:
    t = np.unique(np.concatenate([np.linspace(0, T_ZOOM, 1501), np.linspace(0, T_END, 3501)]))
    return axis.simulate(times, step, t, model=model)  # type: ignore[arg-type]


def make(outdir: pathlib.Path) -> list[pathlib.Path]:
    """Write ``motor_startup.png`` into ``outdir``; return the paths written."""
    outdir = pathlib.Path(outdir)
    output_dir(outdir)
    paper = StepperAxis.paper()
    light = StepperAxis.paper(D=0.003)
    step = paper.full_step / MICRO
    half = paper.tooth_pitch / 2
    kinds = ("none", "exponential", "scurve")
    steps = {k: start_steps(k, step) for k in kinds}
    runs = {
        (name, k): _simulate(ax, steps[k][0], step, model)
        for name, ax, model in (
            ("linear", paper, "linear"),
            ("paper", paper, "nonlinear"),
            ("light", light, "nonlinear"),
        )
        for k in kinds
    }

    fig, axes = plt.subplots(4, 2, figsize=(13, 13), sharex="col", constrained_layout=True)
    for col, t_max in enumerate((T_ZOOM, T_END)):
        for k in kinds:
            c = COLORS[k]
            lin = runs[("linear", k)]
            on = lin.t <= t_max
            prof = steps[k][1]
            v_cmd = np.where(lin.t > 0, W_MAX, 0.0) if prof is None else prof.sample(lin.t)[1]
            ax = axes[0, col]
            ax.plot(lin.t[on], v_cmd[on], color=c, lw=0.8, ls="--")
            ax.plot(lin.t[on], lin.omega[on], color=c, lw=1.0, label=LABELS[k])
            peak = np.max(np.abs(lin.error)) / half
            ax = axes[1, col]
            ax.plot(
                lin.t[on], lin.error[on] / half, color=c, lw=1.0,
                label=f"{LABELS[k]}: peak |error| = {peak:.2f}",
            )  # fmt: skip
            nl = runs[("paper", k)]
            axes[2, col].plot(
                nl.t[on], nl.omega[on], color=c, lw=0.8,
                label=f"{LABELS[k]}: {nl.lost_steps} full steps lost",
            )  # fmt: skip
            li = runs[("light", k)]
            axes[3, col].plot(
                li.t[on], li.error[on] / paper.tooth_pitch, color=c, lw=1.0,
                label=f"{LABELS[k]}: {li.lost_steps} full steps lost",
            )  # fmt: skip
        # the S-curve's velocity as an encoder reads it (4000 counts/rev, every 10 ms)
        if col == 1:
            period = 1e-2
            te = np.arange(0, T_END, period)
            th = paper.response(steps["scurve"][0], step, te)
            v_enc = measured_velocity(th, period, resolution=2 * math.pi / 4000)
            axes[0, 1].plot(
                te,
                v_enc,
                color="k",
                lw=0.6,
                alpha=0.6,
                drawstyle="steps-post",
                label="S-curve read by a 4000/rev encoder every 10 ms",
            )
        for level in (-1.0, 1.0):
            axes[1, col].axhline(level, color="k", lw=0.8, ls=":")
        axes[2, col].axhline(paper.pull_out_speed, color="k", lw=0.8, ls=":")
        for level in (-0.5, 0.5):
            axes[3, col].axhline(level, color="k", lw=0.8, ls=":")
        axes[3, col].set_xlabel("time (s)")
        axes[0, col].set_xlim(0, t_max)
    axes[3, 1].set_ylim(-3, 1)
    axes[3, 0].set_ylim(-3, 1)
    zeta_p, zeta_l = paper.damping_ratio, light.damping_ratio
    axes[0, 0].set_title(
        f"Paper motor, linear G(s) (the paper's analysis), zeta = {zeta_p:.2f}: first {T_ZOOM} s"
    )
    axes[0, 1].set_title("... whole start (dashed: commanded velocity)")
    axes[0, 0].set_ylabel("rotor velocity (rad/s)")
    axes[1, 0].set_ylabel("tracking error / half tooth pitch")
    axes[1, 1].set_title("|error| > half a pitch (dotted) = past the unstable point: a slip")
    axes[2, 0].set_ylabel("rotor velocity (rad/s)")
    axes[2, 0].set_title(
        f"Paper motor, sine torque: pull-out speed T_m/D = {paper.pull_out_speed:.1f} rad/s (dotted)"
    )
    axes[2, 1].set_title("D = 0.03 N m s/rad: 20 rad/s is out of reach whatever the ramp")
    axes[3, 0].set_ylabel("tracking error (tooth pitches)")
    axes[3, 0].set_title(f"Light damping D = 0.003 (zeta = {zeta_l:.2f}), sine torque")
    axes[3, 1].set_title("no ramp slips at once; exponential and S-curve pull in (dotted: +-1/2 pitch)")
    for ax in axes.flat:
        ax.grid(True, lw=0.3)
    for r, where in enumerate(("lower right", "upper right", "lower right", "lower right")):
        axes[r, 1].legend(fontsize=7, loc=where)
    fig.suptitle(
        f"Stepper start-up to {W_MAX:g} rad/s, Z_r = 40 two-phase motor, 1/{MICRO} microsteps "
        f"({math.degrees(step):.4f} deg): no ramp vs exponential vs S-curve",
        fontsize=12,
    )
    path = outdir / "motor_startup.png"
    with atomic_file(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=110)
    plt.close(fig)
    return [path]


if __name__ == "__main__":
    out = pathlib.Path(sys.argv[1]) if len(sys.argv) > 1 else pathlib.Path("docs/img")
    for p in make(out):
        print(p)
