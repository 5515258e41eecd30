"""Control charts of a recipe's parts (``winder parts chart``): PNG, matplotlib, Agg.

One panel per scalar, the parts in the order they were wound (oldest
first, numbered from 1): each part's value (an individuals chart), the
mean, the mean ± 3 s (s the sample standard deviation, the same s as the
capability's Cm and Cmk, :mod:`winder.record.capability`), and the
recipe's tolerance band shaded between its limits (a one-sided tolerance:
its one limit, the band open on the other side). Parts whose verdict is
``nok`` are marked with a red cross whatever the reason (a scalar within
its band may be on a part that failed on another). A panel's title names
the scalar, n, Cm and Cmk; the figure's the recipe, its job, the kind and
the span of time; above a panel's legend, why a figure is missing and which
limit lies too far from the values to be drawn (it would squash them to a
line). The layout is fixed (no constrained layout: it measures every label).
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from winder.contract.files import atomic_file
from winder.motion.tolerances import tolerance_text
from winder.record.capability import Capability

__all__ = ["ChartSeries", "plot_control_chart"]

DPI = 110
#: the layout, fixed (inches; a constrained layout would measure every label, 0.9 s of 1.5):
#: the figure's width, a panel's axes' height, the gap between two panels (the upper's x label,
#: the lower's title), the margins: left (y label), right (the legends), top (the figure's and the
#: first panel's titles), bottom (the last x label)
WIDTH, AXES, GAP = 10.0, 2.2, 0.85
LEFT, RIGHT, TOP, BOTTOM = 0.85, 2.35, 0.7, 0.55
#: the characters of a line of the notes above a panel's legend
NOTE_WIDTH = 34
#: a tolerance limit is drawn when it lies within this many times the values' span of them
NEAR = 3.0
#: a panel draws points and a line up to this many parts, then a line alone (dots would be a smear)
DOTS_UP_TO = 400


@dataclass(frozen=True)
class ChartSeries:
    """One panel: a scalar's values in part order (None: not recorded by
    that part), which parts are ``nok``, its figures and its unit."""

    values: Sequence[float | None]
    nok: Sequence[bool]
    figures: Capability
    unit: str


def _fmt(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


def _panel_title(s: ChartSeries) -> str:
    c = s.figures
    return f"{c.name}: n = {c.n}, Cm = {_fmt(c.cm)}, Cmk = {_fmt(c.cmk)}"


def plot_control_chart(charts: Sequence[ChartSeries], title: str, path: Path) -> Path:
    """The control chart of every series in ``charts``, one panel each, written to ``path`` (PNG)."""
    n = len(charts)
    height = TOP + n * AXES + (n - 1) * GAP + BOTTOM
    fig = Figure(figsize=(WIDTH, height), dpi=DPI)
    FigureCanvasAgg(fig)
    fig.subplots_adjust(
        left=LEFT / WIDTH,
        right=1 - RIGHT / WIDTH,
        top=1 - TOP / height,
        bottom=BOTTOM / height,
        hspace=GAP / AXES,
    )
    fig.suptitle(title, fontsize=11, y=1 - 0.12 / height, va="top")
    axes = fig.subplots(len(charts), 1, squeeze=False)[:, 0]
    for ax, s in zip(axes, charts, strict=True):
        c = s.figures
        xs = [i + 1 for i, v in enumerate(s.values) if v is not None]
        ys = [v for v in s.values if v is not None]
        dots = len(ys) <= DOTS_UP_TO
        ax.plot(xs, ys, color="tab:blue", lw=0.8, marker="o" if dots else None, ms=3, label="part's value")
        marked = zip(s.values, s.nok, strict=True)
        bad = [(i + 1, v) for i, (v, nok) in enumerate(marked) if nok and v is not None]
        if bad:
            ax.plot(
                [b[0] for b in bad],
                [b[1] for b in bad],
                ls="none",
                marker="x",
                ms=7,
                mew=1.8,
                color="tab:red",
                label=f"nok part ({len(bad)})",
                zorder=4,
            )
        if c.mean is not None:
            ax.axhline(c.mean, color="black", lw=1.0, label=f"mean {c.mean:.6g}")
        if c.mean is not None and c.sd:
            for k, sign in enumerate((1, -1)):
                ax.axhline(
                    c.mean + sign * 3 * c.sd,
                    color="tab:orange",
                    lw=1.0,
                    ls="--",
                    label=f"mean ± 3 s (s {c.sd:.3g})" if k == 0 else None,
                )
        low, high, off = _frame(ax, ys, c)
        if c.lsl is not None or c.usl is not None:
            span = high - low
            ax.axhspan(
                low - span if c.lsl is None else c.lsl,
                high + span if c.usl is None else c.usl,
                color="tab:green",
                alpha=0.12,
                lw=0,
                label=f"tolerance {tolerance_text(c.lsl, c.usl)}",
            )
            for limit in (c.lsl, c.usl):
                if limit is not None:
                    ax.axhline(limit, color="tab:green", lw=1.2)
        ax.set_title(_panel_title(s), fontsize=10, loc="left")
        ax.set_xlabel("part, in the order wound (1 = oldest)")
        ax.set_ylabel(f"{c.name} ({s.unit})" if s.unit else c.name)
        ax.set_xlim(0.5, max(len(s.values), 1) + 0.5)
        ax.grid(True, alpha=0.3)
        notes = "; ".join([c.note, *off] if c.note else off)  # why a figure is missing, a limit not drawn
        ax.legend(
            fontsize=8,
            loc="upper left",
            bbox_to_anchor=(1.01, 1.0),
            borderaxespad=0.0,
            title="\n".join(textwrap.wrap(notes, NOTE_WIDTH)) or None,
            title_fontsize=8,
            alignment="left",
        )
    with atomic_file(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=DPI)
    return path


def _frame(ax: Axes, ys: Sequence[float], c: Capability) -> tuple[float, float, list[str]]:
    """The y range, set: every value and the mean ± 3 s, and each tolerance
    limit near them (within :data:`NEAR` times their span); a limit further
    off would squash the values to a line, so it is named instead (the
    words returned). With a margin."""
    points = [*ys]
    if c.mean is not None and c.sd:
        points += [c.mean - 3 * c.sd, c.mean + 3 * c.sd]
    low, high = (min(points), max(points)) if points else (0.0, 1.0)
    span = high - low if high > low else max(abs(low) * 0.1, 1.0)
    off = []
    for name, limit in (("LSL", c.lsl), ("USL", c.usl)):
        if limit is None:
            continue
        if low - NEAR * span <= limit <= high + NEAR * span:
            low, high = min(low, limit), max(high, limit)
        else:
            off.append(f"{name} {limit:g} {'below' if limit < low else 'above'} the chart")
    pad = 0.08 * (high - low) if high > low else max(abs(low) * 0.05, 1.0)
    ax.set_ylim(low - pad, high + pad)
    return low - pad, high + pad, off
