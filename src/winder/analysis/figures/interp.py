"""Figure: the RW400 interpolation comparison (paper 000, fig. 4).

One turn of the paper's set-up (flyer radius 500 mm, wire 2.50 mm, fork 2**10
steps per revolution) with an 8.8 um feed step, the resolution at which the
paper's 2.199 um mean error is reproduced: the distance of every point of the
stepped path to the ideal line (eq. 5) for minimum deviation, the DDA (plain
and half-preloaded 2**10 register) and point-by-point comparison, with the
eq. 7 means in the legend; and a zoom on the first steps of the unrolled path.

    .venv/bin/python -m winder.analysis.figures.interp [outdir]
"""

from __future__ import annotations

import math
import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from winder.contract.files import atomic_file, output_dir
from winder.motion.interp import dda, deviation_stats, min_deviation, point_by_point

FEED_STEP = 8.8e-6  # m
FORK_STEPS = 1024
RADIUS = 0.5  # m
WIRE = 2.5e-3  # m


def make(outdir: pathlib.Path) -> list[pathlib.Path]:
    output_dir(outdir)
    lx, ly = FEED_STEP, 2 * math.pi * RADIUS / FORK_STEPS
    x, y = round(WIRE / lx), FORK_STEPS
    paths = {
        "minimum deviation": min_deviation(x, y),
        "DDA 2^10, half preload": dda(x, y, 10),
        "DDA 2^10, plain": dda(x, y, 10, preload=False),
        "point-by-point": point_by_point(x, y),
    }
    norm = math.hypot(x * lx, y * ly)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.6), gridspec_kw={"width_ratios": [2.2, 1]})
    styles = {
        "minimum deviation": ("C0", 1.6),
        "DDA 2^10, half preload": ("C2", 1.0),
        "DDA 2^10, plain": ("C3", 1.0),
        "point-by-point": ("C7", 0.8),
    }
    for name, p in paths.items():
        f = np.abs(x * p[:, 1] - p[:, 0] * y).astype(float)
        dist_um = f * lx * ly / norm * 1e6
        mean = deviation_stats(p, x, y, step_lengths=(lx, ly)).mean * 1e6
        arc = p[:, 1] * ly * 1e3
        color, lw = styles[name]
        ax1.plot(
            arc, dist_um, ".-", color=color, lw=lw, ms=3, label=f"{name}: mean {mean:.3f} um", alpha=0.85
        )
    ax1.set_xlabel("flyer arc length [mm]")
    ax1.set_ylabel("distance to the ideal line [um]")
    ax1.set_title(f"one turn of {x} feed x {y} fork steps (feed step {FEED_STEP * 1e6:g} um), first 120 mm")
    ax1.legend(loc="upper right", fontsize=8)
    ax1.set_xlim(0, 120)  # the pattern repeats; a window keeps it readable
    ax1.grid(alpha=0.3)

    n = 14
    k = np.array([0.0, n / y])  # the ideal line over the first n fork steps
    ax2.plot(k * x * lx * 1e6, k * y * ly * 1e3, "k--", lw=1, label="ideal line")
    for name in ("minimum deviation", "point-by-point"):
        p = np.vstack([[0, 0], paths[name]])
        m = p[:, 1] <= n
        color, lw = styles[name]
        # straight lines between positions: a diagonal is a step of both axes
        ax2.plot(p[m, 0] * lx * 1e6, p[m, 1] * ly * 1e3, "o-", color=color, lw=lw, ms=3, label=name)
    ax2.set_xlabel("feed [um]")
    ax2.set_ylabel("flyer arc [mm]")
    ax2.set_title("unrolled path, first steps")
    ax2.legend(fontsize=8, loc="lower right")
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    out = outdir / "interp_rw400.png"
    with atomic_file(out, "wb") as fh:
        fig.savefig(fh, format="png", dpi=110)
    plt.close(fig)
    return [out]


if __name__ == "__main__":
    for path in make(pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "docs/img")):
        print(path)
