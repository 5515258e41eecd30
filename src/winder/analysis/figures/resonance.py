"""Figures of input shaping and tuning: a move ringing against the same move shaped, the
shapers' residual vibration against frequency error, and job time against
lost steps as the ramp limits rise (``winder resonance``, ``winder tune``)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import numpy as np
from matplotlib.figure import Figure

from winder.analysis.resonance import Result
from winder.contract.files import atomic_file
from winder.shaping import KINDS, residual

__all__ = ["plot_limits_sweep", "plot_ringing", "plot_sensitivity"]


def _save(fig: Figure, path: Path) -> Path:
    with atomic_file(path, "wb") as fh:  # its directory made if missing
        fig.savefig(fh, format="png", dpi=110, pil_kwargs={"compress_level": 1})
    return path


def plot_ringing(results: dict[str, Result], zeta: float, f_n: float, path: Path) -> Path:
    """Tracking error (steps) of the same move, unshaped and shaped, around its end."""
    fig = Figure(figsize=(8.0, 4.2))
    ax = fig.add_subplot(1, 1, 1)
    end = max(r.duration for r in results.values())
    for label, r in results.items():
        w = r.t >= end - 0.15
        ax.plot(r.t[w] - r.duration, r.error[w], lw=1.0, label=f"{label}: {r.residual:.2f} steps p-p")
    ax.axvline(0.0, color="0.5", lw=0.8, ls="--")
    ax.set_xlabel("time since the move's last step (s)")
    ax.set_ylabel("tracking error (steps)")
    ax.set_title(f"Residual vibration, f_n = {f_n:.1f} Hz, zeta = {zeta:g} (linear model)")
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return _save(fig, path)


def plot_sensitivity(f_n: float, zeta: float, path: Path) -> Path:
    """Residual vibration (% of the unshaped) of every shaper against the actual frequency."""
    fig = Figure(figsize=(8.0, 4.2))
    ax = fig.add_subplot(1, 1, 1)
    ratio = np.linspace(0.5, 1.5, 801)
    ax.plot(ratio, np.full_like(ratio, 100.0), color="0.4", lw=1.0, label="none")
    for kind in KINDS:
        ax.plot(ratio, 100 * residual(kind, f_n, zeta, ratio * f_n), lw=1.2, label=kind)
    ax.axhline(5.0, color="0.5", lw=0.8, ls="--")
    ax.set_xlabel("actual / design frequency")
    ax.set_ylabel("residual vibration (%)")
    ax.set_ylim(0, 105)
    ax.set_title(f"Input shapers designed for {f_n:.1f} Hz, zeta = {zeta:g}")
    ax.legend(loc="upper center", ncol=6, fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return _save(fig, path)


def plot_limits_sweep(
    scales: Sequence[float], times: Sequence[float], lost: Sequence[int], current: float, path: Path
) -> Path:
    """Job time and steps lost (nonlinear model) as the tuned limits are scaled."""
    fig = Figure(figsize=(8.0, 4.2))
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(scales, times, "o-", color="C0", label="job time")
    ax.axhline(current, color="C0", lw=0.8, ls=":", label=f"current settings: {current:.2f} s")
    ax.axvline(1.0, color="0.5", lw=0.8, ls="--")
    ax.set_xlabel("limits (v_max, a_max, j_max) / tuned")
    ax.set_ylabel("job time (s)", color="C0")
    ax2 = ax.twinx()
    ax2.plot(scales, lost, "s-", color="C3", label="steps lost")
    ax2.set_ylabel("steps lost (nonlinear model)", color="C3")
    ax2.set_ylim(bottom=-0.05 * max(1, max(lost)), top=1.15 * max(1, max(lost)))
    ax.set_title("Job time against lost steps as the limits rise")
    lines = ax.get_legend_handles_labels()
    more = ax2.get_legend_handles_labels()
    ax.legend(lines[0] + more[0], lines[1] + more[1], loc="upper center", fontsize=8)
    ax.grid(alpha=0.3)
    if not math.isfinite(current):
        ax.set_ylim(auto=True)
    fig.tight_layout()
    return _save(fig, path)
