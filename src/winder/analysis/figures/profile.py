"""Figures: the velocity profiles of papers 002 and 004, from :func:`winder.motion.profile.plan`.

* ``profile_scurve_240.png`` - paper 002's S-curve: target 240, v 8, a 0.5, j 0.05;
* ``profile_tcurve_210.png`` - paper 002's T-curve: target 210, v 8, a 0.5;
* ``profile_stepper_startup.png`` - paper 004's start-up to omega_max 20:
  S-curve (j 4, a_max 4) against the truncated exponential (1/tau = 0.85).

Position, velocity, acceleration and jerk against time, phase boundaries
shaded; the T-curve's jerk impulses at its corners are drawn as arrows.

    .venv/bin/python -m winder.analysis.figures.profile [outdir]
"""

from __future__ import annotations

import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes

from winder.contract.files import atomic_file, output_dir
from winder.motion.profile import Profile, plan

ROWS = (("position", ""), ("velocity", "/s"), ("acceleration", "/s²"), ("jerk", "/s³"))


def _times(prof: Profile, t_end: float, n: int = 4000) -> np.ndarray:
    """Uniform times plus both sides of every phase edge (so corners stay sharp)."""
    edges = np.array([ph.t_start for ph in prof.phases] + [prof.duration])
    t = np.concatenate([np.linspace(0.0, t_end, n), edges, np.nextafter(edges, -np.inf)])
    return np.unique(np.clip(t, 0.0, t_end))


def _shade_phases(ax: Axes, prof: Profile, t_end: float) -> None:
    for k, ph in enumerate(prof.phases):
        if ph.duration > 0 and k % 2 == 0:
            ax.axvspan(ph.t_start, min(ph.t_start + ph.duration, t_end), color="0.94", lw=0)


def _profile_figure(prof: Profile, title: str, path: pathlib.Path, unit: str) -> pathlib.Path:
    t = _times(prof, prof.duration)
    values = prof.sample(t)
    fig, axes = plt.subplots(4, 1, figsize=(8.5, 8.8), sharex=True, layout="constrained")
    for ax, (name, per), y in zip(axes, ROWS, values, strict=True):
        _shade_phases(ax, prof, prof.duration)
        ax.plot(t, y, color="tab:blue", lw=1.8)
        ax.set_ylabel(f"{name}\n[{unit}{per}]")
        ax.grid(True, alpha=0.3)
        ax.margins(x=0)
    # phase names on the velocity plot
    names: tuple[str, ...] = ("jerk +", "const a", "jerk -", "cruise", "jerk -", "const a", "jerk +")
    if prof.kind == "trapezoid":
        names = ("accelerate", "cruise", "decelerate")
    vmax = float(np.max(values[1]))
    for ph, name in zip(prof.phases, names, strict=False):
        if ph.duration > 0.04 * prof.duration:
            axes[1].text(
                ph.t_start + ph.duration / 2, 0.06 * vmax, name, ha="center", fontsize=8, color="0.35"
            )
    if prof.kind == "trapezoid":
        # infinite jerk at the corners: impulses of the acceleration step
        corners = [ph.t_start for ph in prof.phases[1:]] + [prof.duration]
        steps = np.diff(np.concatenate([[0.0], _corner_acc(prof), [0.0]]))
        for tc, da in zip([0.0, *corners], steps, strict=False):
            if da != 0.0:
                axes[3].annotate(
                    "", xy=(tc, np.sign(da) * 0.8), xytext=(tc, 0.0),
                    arrowprops={"arrowstyle": "-|>", "color": "tab:red", "lw": 1.5},
                )  # fmt: skip
        axes[3].set_ylim(-1, 1)
        axes[3].set_yticks([])
        axes[3].text(
            0.03, 0.92, "0 inside the phases; a Dirac impulse at each corner (arrows)",
            transform=axes[3].transAxes, fontsize=8, va="top", color="tab:red",
        )  # fmt: skip
    axes[-1].set_xlabel("time [s]")
    axes[0].set_title(title, fontsize=11)
    with atomic_file(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=110)
    plt.close(fig)
    return path


def _corner_acc(prof: Profile) -> list[float]:
    """The constant acceleration of each trapezoid phase."""
    mids = np.array([ph.t_start + ph.duration / 2 for ph in prof.phases])
    return [float(a) for a in prof.sample(mids)[2]]


def _startup_figure(path: pathlib.Path) -> pathlib.Path:
    w_max, tau, j, a = 20.0, 1 / 0.85, 4.0, 4.0
    distance = 400.0  # long enough that both reach w_max and cruise
    sc = plan("scurve", distance, v_max=w_max, a_max=a, j_max=j)
    ex = plan("exponential", distance, v_max=w_max, tau=tau)
    t_end = 9.0
    fig, axes = plt.subplots(3, 1, figsize=(8.5, 7.6), sharex=True, layout="constrained")
    t_sc = sc.phases[2].t_start + sc.phases[2].duration
    t_ex = ex.phases[0].duration
    runs = (
        (sc, "tab:green", f"S-curve, j = {j:g}, a_max = {a:g}: at ω_max after {t_sc:.2f} s"),
        (ex, "tab:blue", f"exponential, 1/τ = 0.85, cut at 1 %: at ω_max after {t_ex:.2f} s"),
    )
    for prof, color, label in runs:
        t = _times(prof, t_end)
        p, v, acc, _ = prof.sample(t)
        for ax, y in zip(axes, (p, v, acc), strict=True):
            ax.plot(t, y, color=color, lw=1.8, label=label)
    units = ("rad", "rad/s", "rad/s²")
    for ax, (name, _), u in zip(axes, ROWS, units, strict=False):
        ax.set_ylabel(f"{name}\n[{u}]")
        ax.grid(True, alpha=0.3)
        ax.margins(x=0)
    axes[1].axhline(w_max, color="0.5", lw=0.8, ls="--")
    axes[1].text(t_end * 0.99, w_max * 0.93, "ω_max = 20", ha="right", fontsize=8, color="0.4")
    axes[2].annotate(
        "exponential: full acceleration at once\n(W - v_start)/τ, a step at t = 0",
        xy=(0.0, float(ex.sample(1e-9)[2])), xytext=(1.0, 15.5), fontsize=8,
        arrowprops={"arrowstyle": "->", "color": "0.4"},
    )  # fmt: skip
    t_cut = ex.phases[0].duration
    a_cut = float(ex.sample(np.nextafter(t_cut, 0.0))[2])
    axes[2].annotate(
        f"exponential cut at {t_cut:.2f} s: a steps {a_cut:.2f} -> 0\n"
        "(1 % of its start; v reaches 20 exactly)",
        xy=(t_cut, a_cut), xytext=(5.8, 6.0), fontsize=8,
        arrowprops={"arrowstyle": "->", "color": "0.4"},
    )  # fmt: skip
    axes[1].legend(loc="lower right", fontsize=8)
    axes[-1].set_xlabel("time [s]")
    axes[0].set_title("Paper 004: stepper start-up to ω_max = 20, S-curve vs exponential", fontsize=11)
    with atomic_file(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=110)
    plt.close(fig)
    return path


def make(outdir: pathlib.Path) -> list[pathlib.Path]:
    """Write the three profile figures into ``outdir``; return the paths written."""
    outdir = pathlib.Path(outdir)
    output_dir(outdir)
    sc = plan("scurve", 240.0, v_max=8.0, a_max=0.5, j_max=0.05)
    tc = plan("trapezoid", 210.0, v_max=8.0, a_max=0.5)
    return [
        _profile_figure(
            sc,
            f"Paper 002 S-curve: target 240, v 8, a 0.5, j 0.05 - {sc.duration:g} s "
            "(jerk phases 10 s, constant a 6 s, cruise 4 s)",
            outdir / "profile_scurve_240.png",
            "units",
        ),
        _profile_figure(
            tc,
            f"Paper 002 T-curve: target 210, v 8, a 0.5 - {tc.duration:g} s (ramps 16 s, cruise 10.25 s)",
            outdir / "profile_tcurve_210.png",
            "units",
        ),
        _startup_figure(outdir / "profile_stepper_startup.png"),
    ]


if __name__ == "__main__":
    out = pathlib.Path(sys.argv[1]) if len(sys.argv) > 1 else pathlib.Path("docs/img")
    for p in make(out):
        print(p)
