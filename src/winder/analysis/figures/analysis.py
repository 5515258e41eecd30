"""Figures of a recorded run: motion, tracking, winding accuracy, identification.

PNG files (matplotlib, Agg) written by ``winder analyze`` and ``winder
identify`` into ``<bag>/plots/`` (a ``plots`` folder inside the bag
directory, which rosbag2 tools ignore; for a lone ``.mcap`` file
``<name>_plots/`` beside it):

* ``motion.png`` - velocity, acceleration and jerk of each axis over the run:
  commanded (from the step times) and simulated (joint states);
* ``tracking.png`` - commanded and simulated position, a zoom into the start
  of each axis' first move (the staircase and the rotor following it) and the
  tracking error in steps;
* ``operations.png`` (a run with operator commands) - the velocity of the
  moving axes around the commands, each marked where it takes effect;
* ``winding.png`` - eq. 7 over the whole job: the signed distance of the
  simulated axes to each layer's ideal line against the turns wound, with the
  band the commanded steps stay in; the mean deviation of every turn in % of
  the wire; a zoom into the middle of the first layer (every commanded step
  and sample) and one around the axes' largest deviation;
* ``identify.png`` - the MRAS estimates of J and D converging, the band they
  settle in over the last quarter of their updates, against the
  least-squares estimate and the recorded value.

What is drawn is what the data hold. A long line is cut to what its pixel
columns show (:func:`envelope`: in each column the first, lowest, highest and
last sample, so a spike one sample wide stays), dense dots to one per
occupied pixel (:func:`pixel_points`); nothing is subsampled blindly.
Legends go into a corner that no curve crosses (:func:`place_legend`), else
into a band above the data made for them.

Drawing is matplotlib's Python code, some 40 ms per panel (ticks, labels,
text) whatever the data: the layout is fixed (constrained or tight layout
measures every label of every panel), PNG compression is the fastest level,
and with two or more cores each figure is drawn in a process of its own.
"""

from __future__ import annotations

import math
import textwrap
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
import numpy.typing as npt
from matplotlib.axes import Axes
from matplotlib.backend_bases import RendererBase
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.legend import Legend
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.path import Path as MplPath
from matplotlib.ticker import MaxNLocator
from matplotlib.transforms import Bbox

from winder.analysis.digest import ZOOM_STEPS, Digest, turn_index
from winder.analysis.identify import Identification
from winder.analysis.metrics import Analysis, digest_run, paired_error, sample_layers
from winder.analysis.wire import FAULTS, LayerTension, fault, layer_tensions, tension_joints
from winder.contract.eq7 import layer_of_samples, sample_deviation, signed_path_distance
from winder.contract.files import OutputError, atomic_file, output_dir
from winder.contract.run import shaper_text, where_text
from winder.contract.states import EventKind, JobState
from winder.contract.stream import JobPlan
from winder.motion.axes import AXES, AXIS_TABLE, FEED, FORK
from winder.record.reader import Run

__all__ = [
    "envelope",
    "envelope_indices",
    "pixel_points",
    "place_legend",
    "plot_analysis",
    "plot_identification",
    "plots_dir",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

CMD, ACT, IDEAL = "tab:blue", "tab:orange", "k"
#: joint units and the scale to show them in
SHOW = {a.name: (a.show_scale, a.show_unit) for a in AXIS_TABLE}
DPI = 100
#: fixed margins (fractions of the figure): matplotlib's constrained layout
#: measured every tick label of every panel and took most of the plotting time
MARGINS = {"left": 0.06, "right": 0.985, "bottom": 0.06, "wspace": 0.22}
#: PNG compression: level 1 writes the figures several times faster than the
#: default 6 for files about a third larger
PNG = {"compress_level": 1}
#: at most this many intervals between tick labels on a linear axis (matplotlib
#: picks up to 9 on a wide panel; every tick is five artists to make, lay out
#: and draw, a millisecond each: a fifth of the drawing time went into ticks)
TICK_BINS = 4
#: settings every figure here is drawn with: titles at a fixed height (matplotlib
#: otherwise measures the tick labels of every panel to lift them), a thin grid
#: made with the ticks (ax.grid() afterwards goes over every tick again)
RC: dict[Any, Any] = {"axes.titley": 1.0, "axes.titlepad": 5.0, "axes.grid": True, "grid.linewidth": 0.3}
#: artists a legend may cover: marks of a time or place (event lines, layer ends),
#: not data
BACKGROUND = "background"
CORNERS: tuple[Any, ...] = ("upper left", "upper right", "lower left", "lower right")


def plots_dir(run_path: Path) -> Path:
    """Where the figures of the recording at ``run_path`` go (module doc)."""
    p = Path(run_path)
    return p / "plots" if p.is_dir() else p.with_name(p.stem + "_plots")


# -- what a pixel shows ---------------------------------------------------------------


def _cells(v: FloatArray, lo: float, hi: float, k: int) -> IntArray:
    """The cell (0 .. k-1) of each v among k cells of equal width over [lo, hi].
    The fraction of the range first, then the cell: k / (hi - lo) would
    overflow for a subnormal range; a range beyond the largest float is halved
    first (a subnormal one never gets there)."""
    if not hi > lo:
        return np.zeros(v.size, np.int64)
    frac = (v - lo) / (hi - lo) if math.isfinite(hi - lo) else (v / 2 - lo / 2) / (hi / 2 - lo / 2)
    return np.minimum((frac * k).astype(np.int64), k - 1)


def _columns(x: FloatArray, columns: int) -> IntArray:
    """The column (0 .. columns-1) of each x, columns of equal width over x's range."""
    return _cells(x, float(x[0]), float(x[-1]), columns)


def envelope_indices(x: npt.ArrayLike, y: npt.ArrayLike, columns: int) -> IntArray:
    """The samples a line through (x, y) needs at ``columns`` pixel columns
    across x's range: in each column its first and last sample and its lowest
    and highest (the first of equal ones), in their order (M4 aggregation,
    Jugel et al., VLDB 2014). Drawn, they give the picture of every sample:
    the line enters and leaves each column where it did, and spans the same
    height in it. NaN samples count as neither lowest nor highest. ``x`` must
    not decrease (a time, a position along the job)."""
    xx = np.asarray(x, dtype=np.float64)
    yy = np.asarray(y, dtype=np.float64)
    if xx.shape != yy.shape or xx.ndim != 1:
        raise ValueError(f"x and y have shapes {xx.shape} and {yy.shape}: must be equal and 1-D")
    if columns < 1:
        raise ValueError(f"columns={columns!r} is invalid: must be >= 1")
    n = xx.size
    if n and not (np.isfinite(xx[0]) and np.isfinite(xx[-1]) and np.all(np.diff(xx) >= 0)):
        raise ValueError("x must be finite and must not decrease")
    if n <= 4 * columns:
        return np.arange(n, dtype=np.int64)
    col = _columns(xx, columns)
    starts = np.flatnonzero(np.diff(col, prepend=-1))
    counts = np.diff(np.append(starts, n))
    ends = starts + counts - 1
    index = np.arange(n, dtype=np.int64)
    keep = [starts, ends]
    for fill, reduce in ((np.inf, np.minimum), (-np.inf, np.maximum)):
        v = np.where(np.isnan(yy), fill, yy)
        best = np.repeat(reduce.reduceat(v, starts), counts)
        keep.append(np.minimum.reduceat(np.where(v == best, index, n), starts))
    out: IntArray = np.unique(np.concatenate(keep))
    return out


def envelope(x: npt.ArrayLike, y: npt.ArrayLike, columns: int) -> tuple[FloatArray, FloatArray]:
    """(x, y) cut to what ``columns`` pixel columns show (:func:`envelope_indices`)."""
    idx = envelope_indices(x, y, columns)
    return np.asarray(x, dtype=np.float64)[idx], np.asarray(y, dtype=np.float64)[idx]


def pixel_points(x: npt.ArrayLike, y: npt.ArrayLike, columns: int, rows: int) -> IntArray:
    """The first sample in each occupied cell of a ``columns`` x ``rows`` grid
    over the data's range, in their order: dots a pixel wide, drawn only
    there, look like all of them. NaN samples are left out."""
    xx = np.asarray(x, dtype=np.float64)
    yy = np.asarray(y, dtype=np.float64)
    ok = np.flatnonzero(np.isfinite(xx) & np.isfinite(yy))
    if ok.size <= columns * rows // 4 or ok.size < 2:
        return ok.astype(np.int64)

    def cell(v: FloatArray, k: int) -> IntArray:
        return _cells(v, float(v.min()), float(v.max()), k)

    _, first = np.unique(cell(xx[ok], columns) * rows + cell(yy[ok], rows), return_index=True)
    out: IntArray = ok[np.sort(first)].astype(np.int64)
    return out


def _width(ax: Axes) -> int:
    return max(1, math.ceil(ax.bbox.width))


def _line(ax: Axes, x: npt.ArrayLike, y: npt.ArrayLike, *fmt: str, **kw: Any) -> list[Line2D]:
    """A line without markers through every sample, cut to the panel's pixel columns."""
    xe, ye = envelope(x, y, _width(ax))
    return ax.plot(xe, ye, *fmt, **kw)


def _dots(ax: Axes, x: FloatArray, y: FloatArray, **kw: Any) -> list[Line2D]:
    """Dots of every sample, one per occupied pixel of the panel."""
    idx = pixel_points(x, y, _width(ax), max(1, math.ceil(ax.bbox.height)))
    return ax.plot(x[idx], y[idx], ".", **kw)


# -- legends that hide nothing ------------------------------------------------------------


class _Obstacles:
    """What a legend must not cover in an axes, in display coordinates: its
    lines (NaN breaks them), areas (filled paths), dots (centres and radius)
    and texts. Artists with the gid :data:`BACKGROUND` are left out."""

    def __init__(self, ax: Axes, renderer: RendererBase) -> None:
        ax.get_xlim(), ax.get_ylim()  # matplotlib autoscales lazily: the limits are final from here
        self.paths: list[tuple[MplPath, bool]] = []
        self.dots: list[tuple[FloatArray, float]] = []
        self.texts = [t.get_window_extent(renderer) for t in ax.texts if t.get_visible()]
        for line in ax.lines:
            if line.get_gid() == BACKGROUND or not line.get_visible():
                continue
            v = line.get_transform().transform(line.get_xydata())
            if line.get_linestyle() in ("None", "none", "", " "):
                r = max(float(line.get_markersize()), 1.0) * DPI / 72 / 2
                self.dots.append((v[np.all(np.isfinite(v), axis=1)], r))
            else:
                self.paths.append((_nan_broken(v), False))
        for patch in ax.patches:
            if patch.get_gid() != BACKGROUND and patch.get_visible():
                self.paths.append((patch.get_transform().transform_path(patch.get_path()), True))
        for coll in ax.collections:
            if coll.get_gid() != BACKGROUND and coll.get_visible():
                tr = coll.get_transform()
                self.paths += [(tr.transform_path(p), True) for p in coll.get_paths()]

    def hit(self, box: Bbox) -> bool:
        """Whether ``box`` covers any of them."""
        if any(box.overlaps(t) for t in self.texts):
            return True
        for v, r in self.dots:
            x, y = v[:, 0], v[:, 1]
            if np.any((x >= box.x0 - r) & (x <= box.x1 + r) & (y >= box.y0 - r) & (y <= box.y1 + r)):
                return True
        return any(np.asarray(p.vertices).size and p.intersects_bbox(box, filled=f) for p, f in self.paths)


def _nan_broken(v: FloatArray) -> MplPath:
    """A polyline through the rows of ``v``, broken where a row is not finite."""
    ok = np.all(np.isfinite(v), axis=1)
    if ok.all():
        return MplPath(v)
    codes = np.full(v.shape[0], MplPath.LINETO, dtype=MplPath.code_type)
    codes[0] = MplPath.MOVETO
    codes[1:][~ok[:-1]] = MplPath.MOVETO
    return MplPath(v[ok], codes[ok]) if ok.any() else MplPath(np.zeros((0, 2)))


def place_legend(ax: Axes, renderer: RendererBase, **kw: Any) -> Legend | None:
    """The axes' legend where it covers no curve, dot or area (artists with the
    gid :data:`BACKGROUND` excepted): the first free corner; else the top of
    the y range is raised to make a band for it over the data (and the
    corners tried again). Call it once the limits are final."""
    handles, labels = ax.get_legend_handles_labels()
    if not handles:
        return None
    opts: dict[str, Any] = {"fontsize": 8, "framealpha": 0.9, **kw}
    leg = ax.legend(handles, labels, loc="upper left", **opts)
    for attempt in range(2):
        obstacles = _Obstacles(ax, renderer)
        for ncol in dict.fromkeys((1, min(len(handles), 3))):
            leg.set_ncols(ncol)
            for loc in CORNERS:
                leg.set_loc(loc)
                if not obstacles.hit(leg.get_window_extent(renderer).padded(2)):
                    return leg
        if attempt == 0:
            # a band above the data as high as the legend in up to three columns
            leg.set_ncols(min(len(handles), 3))
            leg.set_loc("upper left")
            box = leg.get_window_extent(renderer)
            if box.width > ax.bbox.width:
                leg.set_ncols(1)
                box = leg.get_window_extent(renderer)
            lo, hi = ax.get_ylim()
            room = max(ax.bbox.height - box.height - 12, 0.2 * ax.bbox.height)
            ax.set_ylim(lo, hi + (hi - lo) * (box.height + 12) / room)
    leg.set_loc("upper left")
    return leg


# -- common parts ------------------------------------------------------------------------


def _figure(size: tuple[float, float]) -> tuple[Figure, RendererBase]:
    fig = Figure(figsize=size, dpi=DPI)
    canvas = FigureCanvasAgg(fig)
    # FigureCanvasAgg.get_renderer is not annotated in matplotlib's stubs
    return fig, canvas.get_renderer()  # type: ignore[no-untyped-call]


def _save(fig: Figure, path: Path) -> Path:
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            loc = axis.get_major_locator()
            if isinstance(loc, MaxNLocator):
                loc.set_params(nbins=TICK_BINS)
    with atomic_file(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=DPI, pil_kwargs=PNG)
    return path


def _title(run: Run) -> str:
    """One line: the run, its job, ramp (and shaper), motor model and how it ended."""
    j = run.plan.job
    model = f"{run.sim_config.model} motor model" if run.sim_config else "no motor model"
    shaper = shaper_text(run.profile_config)
    ramp = f"{run.profile or '?'} profile" + (f", {shaper}" if shaper else "")
    return f"{run.label}: {j.shape}, {ramp}, {model} ({_ending(run)})"


def _ending(run: Run) -> str:
    """How the recorded run ended, in a few words: complete, aborted (when, and
    where the axes came to rest), cut short, or incomplete."""
    if run.complete:
        return "complete"
    abort = next((e for e in reversed(run.events) if e.get("event") == EventKind.ABORT), None)
    if run.report.get("state") == JobState.ABORTED and abort is not None:
        rest = abort.get("t_rest_ns", abort["t_ns"]) / 1e9
        seg, step = abort.get("segment"), abort.get("step")
        where = where_text(run.plan, seg, step) if isinstance(seg, int) and isinstance(step, int) else ""
        said = f"aborted at {abort['t_ns'] / 1e9:.3f} s, at rest {rest:.3f} s" + (
            f" in {where}" if where else ""
        )
        return said + ("" if run.closed and not run.damaged else ", recording incomplete")
    return "cut short, recovered" if run.recovered else "incomplete"


def _first_ramp(d: Digest, axis: str, t: FloatArray, v: FloatArray) -> tuple[float, float] | None:
    """Time window around the first acceleration of ``axis``: from just before
    its first step until shortly after its commanded speed first levels off
    (``t``, ``v``: its command over the segment of that first step)."""
    first = d.first_moves[axis]
    if first is None:
        return None
    t0 = first.t0 / 1e9
    t_seg_end = d.segment_end.get(first.segment, first.t0) / 1e9
    m = (t >= t0) & (t <= t_seg_end)
    if np.any(m):
        peak = np.max(np.abs(v[m]))
        reach = t[m][np.nonzero(np.abs(v[m]) >= 0.99 * peak)[0][0]]
        t1 = min(reach + 0.25 * (reach - t0) + 0.02, t_seg_end + 0.05)
    else:
        t1 = t0 + 0.5
    return t0 - 0.03 * max(t1 - t0, 0.1), t1


def _mark_events(ax: Axes, run: Run, label: bool) -> None:
    """The operator's commands on a time axis: a pause shaded from the moment
    it takes effect to the resume (the rest dotted), an abort and an override
    as lines. With ``label``, each kind of mark is named once in the legend,
    however often it occurs."""
    end = float(run.states.t[-1]) if len(run.states) else 0.0
    pause: dict[str, Any] | None = None
    named: set[str] = set()

    def once(name: str) -> str | None:
        if not label or name in named:
            return None
        named.add(name)
        return name

    for e in run.events:
        t = e["t_ns"] / 1e9
        kind = e.get("event")
        if kind in (EventKind.PAUSE, EventKind.ABORT):
            color = "black" if kind == EventKind.PAUSE else "tab:red"
            ax.axvline(t, color=color, lw=1.0, label=once(f"{kind} takes effect"), gid=BACKGROUND)
            ax.axvline(e.get("t_rest_ns", e["t_ns"]) / 1e9, color=color, lw=0.8, ls=":",
                       label=once(f"{kind}: at rest"), gid=BACKGROUND)  # fmt: skip
            pause = e if kind == EventKind.PAUSE else None
        elif kind == EventKind.RESUME:
            ax.axvline(t, color="tab:green", lw=1.0, label=once("resume"), gid=BACKGROUND)
            if pause is not None:
                ax.axvspan(pause["t_ns"] / 1e9, t, color="tab:gray", alpha=0.12, gid=BACKGROUND)
            pause = None
        elif kind == EventKind.OVERRIDE:
            name = once(f"override x{e.get('factor', 1.0):g}")
            ax.axvline(t, color="tab:purple", lw=1.0, ls="--", label=name, gid=BACKGROUND)
    if pause is not None:
        ax.axvspan(
            pause["t_ns"] / 1e9, max(end, pause["t_ns"] / 1e9), color="tab:gray", alpha=0.12, gid=BACKGROUND
        )


# -- motion.png ---------------------------------------------------------------------------


def _motion(run: Run, d: Digest, out: Path) -> Path:
    return _save(motion_figure(run, d), out / "motion.png")


def motion_figure(run: Run, d: Digest) -> Figure:
    """motion.png's figure: velocity, acceleration and jerk of each axis that
    moves, commanded and simulated (the whole run and a zoom into its first
    acceleration). An axis that never moves (the pole of a one-pole job) has
    no column. The simulated axis' jerk, the differences of its sampled
    velocity, swings with the step ripple far beyond the command's: it is
    drawn as dots, those beyond the panel's scale as marks at its edge."""
    st = run.states
    acc = np.asarray(np.gradient(st.vel, st.t, axis=0)) if len(st) >= 3 else np.zeros((0, len(AXES)))
    jerk = np.asarray(np.gradient(acc, st.t, axis=0)) if len(st) >= 3 else np.zeros((0, len(AXES)))
    shown = [c for c in range(len(AXES)) if d.moved[c] > 0] or list(range(len(AXES)))
    cols = len(shown)
    width = max(1.0 + 4.7 * cols, 12.0)  # 12 in at least: a figure of one or two columns too
    fig, renderer = _figure((width, 12))
    # margins in inches as those of three columns, whatever the figure's width
    room = {**MARGINS, "left": MARGINS["left"] * 15 / width, "right": 1 - (1 - MARGINS["right"]) * 15 / width}
    gs = fig.add_gridspec(4, cols, **room, top=0.92, hspace=0.4)
    axes = np.empty((4, cols), dtype=object)
    for i in range(cols):
        axes[0, i] = fig.add_subplot(gs[0, i])
        axes[1, i] = fig.add_subplot(gs[1, i])
        for r in (2, 3):  # the zoom rows share their time window
            axes[r, i] = fig.add_subplot(gs[r, i], sharex=axes[1, i])
    names = ("velocity", "acceleration", "jerk")
    rate = run.sim_config.publish_rate if run.sim_config else math.nan
    beyond = False
    for i, c in enumerate(shown):
        axis = AXES[c]
        scale, unit = SHOW[axis]
        tc, vc, _, _ = d.traces[axis].whole_run()
        t, v, a, j = d.traces[axis].first_move()
        ax = axes[0, i]
        if len(st):
            _line(ax, st.t, st.vel[:, c] * scale, color=ACT, lw=0.6, label="simulated axis")
        if vc.size:
            _dots(ax, tc, vc * scale, color=CMD, ms=1.0, label="command")
        ax.set_title(f"{axis}: whole run", fontsize=10)
        _mark_events(ax, run, label=i == 0)
        ax.set_ylabel(f"{axis} velocity ({unit}/s)")
        ax.set_xlabel("time (s)")
        window = _first_ramp(d, axis, t, v) if v.size else None
        for r, (cmd, act) in enumerate(((v, st.vel[:, c]), (a, acc[:, c]), (j, jerk[:, c]))):
            ax = axes[r + 1, i]
            if r < 2:
                ax.tick_params(labelbottom=False)
            if window is None:
                ax.text(
                    0.5, 0.5, f"no command kinematics of the {axis} axis", ha="center", transform=ax.transAxes
                )
                continue
            lo, hi = window
            ms = (st.t >= lo) & (st.t <= hi)
            mc = (t >= lo) & (t <= hi)
            label = f"simulated axis, sampled at {rate:g} Hz"
            if r < 2:
                ax.plot(st.t[ms], act[ms] * scale, ".-", color=ACT, lw=0.7, ms=2.5, label=label)
            _line(ax, t[mc], cmd[mc] * scale, "-", color=CMD, lw=1.4, label="command (from the step times)")
            ax.set_xlim(lo, hi)
            if r == 2:
                lim = 2.5 * max(float(np.max(np.abs(cmd[mc]))) if np.any(mc) else 0.0, 1e-12) * scale
                ax.set_ylim(-lim, lim)
                ts, ys = st.t[ms], act[ms] * scale
                inside = np.abs(ys) <= lim
                ax.plot(ts[inside], ys[inside], ".", color=ACT, ms=2.5, label=label)
                for sign, mark in ((1, "^"), (-1, "v")):
                    out = sign * ys > lim
                    if np.any(out):
                        beyond = True
                        edge = np.full(int(out.sum()), sign * 0.97 * lim)
                        ax.plot(ts[out], edge, mark, color=ACT, ms=3, alpha=0.6)
            power = ("/s", "/s²", "/s³")[r]
            ax.set_ylabel(f"{axis} {names[r]} ({unit}{power})")
            if r == 0:
                ax.set_title(f"{axis}: its first acceleration (zoom)", fontsize=10)
        axes[3, i].set_xlabel("time (s)")
    if beyond:  # named in the zoom's legend: a legend in a jerk panel would stretch its scale
        axes[1, 0].plot([], [], "^", color=ACT, ms=3, alpha=0.6, label="simulated jerk beyond the scale")
    place_legend(axes[0, 0], renderer, markerscale=6)
    place_legend(axes[1, 0], renderer)
    fig.suptitle(
        _title(run) + "\ncommand: from each segment's step times (not near rest); "
        "axes: the recorded joint velocity and its differences",
        fontsize=10,
    )
    return fig


# -- operations.png -------------------------------------------------------------------------


#: wire.png: a panel for each layer wound, WIRE_COLUMNS to a row; of more than WIRE_LAYERS
#: layers, the WIRE_LAYERS with the highest peaks
WIRE_LAYERS, WIRE_COLUMNS = 8, 4
#: the colours of the layers in wire.png, none the bands' green, the maximum's red or
#: the grey of the tension between layers (they repeat after eight layers)
LAYER_COLOURS = (
    "tab:blue",
    "tab:orange",
    "tab:purple",
    "tab:brown",
    "tab:pink",
    "tab:cyan",
    "tab:olive",
    "navy",
)


def wire_figure(run: Run, d: Digest | None = None) -> Figure:
    """wire.png's figure: the wire's tension over the run as recorded,
    coloured by the layer it was wound in, in the job's bands (the set
    tension, the warning and alarm bands) and below the wire's maximum (times
    ``tension.max_share``); below it a panel per layer (of more than
    WIRE_LAYERS, those with the highest peaks) against the turns into the
    layer, in its colour, and two turns of the flyer around the peak, in the
    same bands. ``d``: the run's digest, if made already."""
    d = d if d is not None else digest_run(run)
    layers = layer_tensions(run, sample_layers(run, d))
    shown = sorted(sorted(range(len(layers)), key=lambda k: -layers[k].max_n)[:WIRE_LAYERS])
    rows = math.ceil(len(shown) / WIRE_COLUMNS)
    height = 0.9 + 3.3 + 2.35 * rows + 3.0  # inches: title, the run, the layers, the zoom
    fig, _ = _figure((13, height))

    def box(
        top: float, tall: float, left: float = 0.07, width: float = 0.72
    ) -> tuple[float, float, float, float]:
        return (left, 1 - (top + tall) / height, width, tall / height)  # from the top, in inches

    ax = fig.add_axes(box(0.6, 2.6))
    zoom = fig.add_axes(box(height - 2.75, 2.2))
    _wire_run(run, ax, layers, {kind: fault(run, kind) for kind in FAULTS})
    joint = tension_joints(run)
    for k, i in enumerate(shown):
        col, row = k % WIRE_COLUMNS, k // WIRE_COLUMNS
        width = (0.975 - 0.07 - 0.05 * (WIRE_COLUMNS - 1)) / WIRE_COLUMNS
        panel = fig.add_axes(box(4.25 + 2.35 * row, 1.6, 0.07 + col * (width + 0.05), width))
        _wire_layer(run, panel, layers[i], joint, LAYER_COLOURS[i % len(LAYER_COLOURS)], ax.get_ylim())
        if col == 0:
            panel.set_ylabel("tension (N)")
    _wire_zoom(run, zoom)
    return fig


def _wire_bands(run: Run, ax: Axes, label: bool) -> None:
    """The set tension, the warning and alarm bands and the wire's maximum."""
    job = run.plan.job
    set_n = job.set_tension
    for frac, alpha, name in (
        (job.tension_alarm, 0.10, f"alarm band (tension.alarm {job.tension_alarm:g})"),
        (job.tension_warning, 0.16, f"warning band (tension.warning {job.tension_warning:g})"),
    ):
        span = (set_n * (1 - frac), set_n * (1 + frac))
        ax.axhspan(*span, color="tab:green", alpha=alpha, lw=0, label=name if label else None, gid=BACKGROUND)
    ax.axhline(
        set_n, color="tab:green", lw=0.8, label=f"set {set_n:.4g} N" if label else None, gid=BACKGROUND
    )
    derated = f" x tension.max_share {job.tension_max_share:g}" if job.tension_max_share < 1 else ""
    top = job.tension_limit
    said = f"the wire's maximum{derated}: {top:.4g} N" if label else None
    ax.axhline(top, color="tab:red", lw=1.0, ls="--", label=said, gid=BACKGROUND)


#: what the wire did at each of its faults, in wire.png
FAULT_VERBS = {"break": "broke", "slip": "slipped"}


def _wire_run(
    run: Run, ax: Axes, layers: list[LayerTension], faults: dict[str, dict[str, Any] | None]
) -> None:
    """The tension over the whole run, each layer's samples in its colour,
    and when the wire broke or slipped (where its status says)."""
    job = run.plan.job
    tension = run.tension
    _wire_bands(run, ax, label=True)
    _line(ax, tension.t, tension.tension, color="0.55", lw=0.6, label="tension (between layers)")
    n = len(LAYER_COLOURS)
    for k, colour in enumerate(LAYER_COLOURS[: len(layers)]):  # one line a colour, however many layers
        mine = layers[k::n]
        t, y = _broken_at_gaps(
            np.sort(np.concatenate([lay.samples for lay in mine])), tension.t, tension.tension
        )
        label = f"coil {mine[0].coil} layer {mine[0].layer}" + (
            f", every {n}th layer after" if len(mine) > 1 else ""
        )
        _line(ax, t, y, color=colour, lw=0.7, label=label)
    said = ""
    for kind, f in faults.items():
        if f is None:
            continue
        verb = FAULT_VERBS.get(kind, kind)
        said += f", the wire {verb}" + (" (when: not recorded)" if f["t_s"] is None else "")
        if f["t_s"] is not None:
            ls = ":" if kind == "break" else "-."
            ax.axvline(f["t_s"], color="k", lw=1.2, ls=ls, label=f"the wire {verb} at {f['t_s']:.3f} s")
    peak, least = float(tension.tension.max()), float(tension.tension.min())
    ax.set_xlim(float(tension.t[0]), float(tension.t[-1]) if len(tension) > 1 else float(tension.t[0]) + 1)
    ax.set_ylim(0.0, max(job.tension_limit, peak) * 1.08)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("wire tension (N)")
    below = (
        f"; below, the {WIRE_LAYERS} of {len(layers)} layers with the highest peaks"
        if len(layers) > WIRE_LAYERS
        else ""
    )
    ax.set_title(
        f"{run.label}: the wire ({job.wire.material.name}, {job.wire.bare_diameter * 1e3:g} mm): "
        f"tension {least:.4g}..{peak:.4g} N{said}{below}",
        loc="left",
    )
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)


def _broken_at_gaps(idx: IntArray, x: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``x[idx]``, ``y[idx]`` with a point of NaN height between samples that
    are not neighbours (a line through them does not bridge what lies between)."""
    gaps = np.flatnonzero(np.diff(idx) > 1) + 1
    xs = x[idx]
    return np.insert(xs, gaps, xs[gaps - 1]), np.insert(y[idx], gaps, np.nan)


def _wire_layer(
    run: Run, ax: Axes, lay: LayerTension, joint: IntArray, colour: str, ylim: tuple[float, float]
) -> None:
    """One layer's tension against the turns into it, in the bands."""
    seg = run.plan.segments[lay.segment]
    spr = run.plan.job.fork_steps_per_rev
    j = joint[lay.samples]
    steps = run.states.pos[j, FORK.index] / run.plan.joint_step[FORK.index]
    turns = np.abs(steps - seg.start[FORK.index]) / spr
    _wire_bands(run, ax, label=False)
    # against the flyer's progress (the turns it reached: it may go back a little at a stop)
    progress = np.maximum.accumulate(turns)
    tension = run.tension.tension[lay.samples]
    _line(ax, progress, tension, color=colour, lw=0.7)
    k = int(np.argmax(tension))  # the peak, a dot: seen where the line is one pixel wide
    ax.plot(progress[k : k + 1], tension[k : k + 1], "o", color=colour, ms=4)
    ax.set_xlim(0.0, max(float(seg.turns), float(turns.max()) if turns.size else 0.0) or 1.0)
    ax.set_ylim(*ylim)
    ax.set_xlabel("turns into the layer")
    stretched = f", stretched {100 * lay.stretch:.3g} %" if lay.stretch > 0 else ""
    ax.set_title(
        f"coil {lay.coil} layer {lay.layer}: {lay.min_n:.4g}..{lay.max_n:.4g} N{stretched}",
        loc="left",
        fontsize=8.5,
        color="tab:red" if lay.stretch > 0 else "k",
    )


def _wire_zoom(run: Run, zoom: Axes) -> None:
    """Two turns of the flyer around the tension's peak: the swing the
    corners make, four times a turn on a rectangle."""
    job = run.plan.job
    tension = run.tension
    set_n = job.set_tension
    k = int(np.argmax(tension.tension))
    peak = float(tension.tension[k])
    lo_t, hi_t = _turn_either_side(run, float(tension.t[k]))
    m = (tension.t >= lo_t) & (tension.t <= hi_t)
    near = tension.tension[m]
    _wire_bands(run, zoom, label=False)
    zoom.plot(tension.t[m], near, color=ACT, lw=0.9, marker=".", ms=2)
    lo, hi = float(min(near.min(), set_n)), float(max(near.max(), set_n))
    pad = 0.1 * (hi - lo) or 0.05 * max(abs(hi), 1e-9)
    zoom.set_ylim(lo - pad, hi + pad)
    zoom.set_xlabel("time (s)")
    zoom.set_ylabel("wire tension (N)")
    zoom.set_title(
        f"around the peak, {peak:.4g} N at {tension.t[k]:.3f} s: {_flyer_words(run, lo_t, hi_t)}",
        loc="left",
    )


#: s either side of wire.png's peak at most, when the flyer takes longer for its turn (near rest)
ZOOM_MAX = 0.5


def _turn_either_side(run: Run, t: float) -> tuple[float, float]:
    """The times the flyer was one turn before and one turn past where it
    was at ``t`` (its recorded angle), each at most :data:`ZOOM_MAX` s away."""
    st = run.states
    if len(st) < 2:
        return t - ZOOM_MAX, t + ZOOM_MAX
    angle = st.pos[:, AXES.index("fork")]
    here = float(np.interp(t, st.t, angle))
    away = np.abs(angle - here) >= 2 * math.pi
    before = np.flatnonzero(away & (st.t <= t))
    after = np.flatnonzero(away & (st.t >= t))
    lo = float(st.t[before[-1]]) if before.size else float(st.t[0])
    hi = float(st.t[after[0]]) if after.size else float(st.t[-1])
    return max(lo, t - ZOOM_MAX), min(hi, t + ZOOM_MAX)


def _flyer_words(run: Run, lo: float, hi: float) -> str:
    """What the flyer did from ``lo`` to ``hi`` s: the turns it made and its
    speed there, recorded (one number when it held it within 1 %)."""
    st = run.states
    m = (st.t >= lo) & (st.t <= hi)
    if not np.any(m):
        return "no joint samples"
    fork = AXES.index("fork")
    turns = abs(float(np.interp(hi, st.t, st.pos[:, fork]) - np.interp(lo, st.t, st.pos[:, fork]))) / (
        2 * math.pi
    )
    speed = np.abs(st.vel[m, fork])
    slow, fast = float(speed.min()), float(speed.max())
    said = f"{fast:.3g} rad/s" if fast - slow <= 0.01 * fast else f"{slow:.3g}..{fast:.3g} rad/s"
    return f"{turns:.3g} turns of the flyer at {said}"


def _operations(run: Run, d: Digest, out: Path) -> Path:
    return _save(operations_figure(run, d), out / "operations.png")


def operations_figure(run: Run, d: Digest) -> Figure:
    """operations.png's figure: the velocity of the moving axes around the
    operator's commands (from half a second before the first to two after the
    last)."""
    st = run.states
    times = [e["t_ns"] / 1e9 for e in run.events] + [e.get("t_rest_ns", e["t_ns"]) / 1e9 for e in run.events]
    end = float(st.t[-1]) if len(st) else max(times)
    lo, last = max(min(times) - 0.5, 0.0), max(times)
    # two seconds after the last mark, or the run's end; never so close that a
    # mark (an abort's rest, a sample period before the end) sits on the frame
    hi = max(min(last + 2.0, end), last + 0.08 * (last - lo) + 0.1)
    moving = [c for c, axis in enumerate(AXES) if len(st) and np.ptp(st.pos[:, c]) > 0]
    rows = max(len(moving), 1)
    fig, _ = _figure((13, 1.0 + 3.0 * rows))
    top = 1 - 0.85 / (1.0 + 3.0 * rows)
    gs = fig.add_gridspec(rows, 1, left=0.07, right=0.79, bottom=0.5 / (1.0 + 3.0 * rows), top=top)
    first: Axes | None = None
    for row, c in enumerate(moving):
        axis = AXES[c]
        scale, unit = SHOW[axis]
        ax = fig.add_subplot(gs[row, 0], sharex=first)
        first = first or ax
        m = (st.t >= lo) & (st.t <= hi)
        _line(ax, st.t[m], st.vel[m, c] * scale, color=ACT, lw=0.7, label="simulated axis")
        tc, vc, _, _ = d.traces[axis].whole_run()
        mc = (tc >= lo) & (tc <= hi)
        _dots(ax, tc[mc], vc[mc] * scale, color=CMD, ms=1.5, label="command (from the step times)")
        _mark_events(ax, run, label=row == 0)
        ax.set_xlim(lo, hi)
        ax.set_ylabel(f"{axis} velocity ({unit}/s)")
        if row == 0:  # beside the panels: nothing under it
            ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, markerscale=4)
        if row < len(moving) - 1:
            ax.tick_params(labelbottom=False)
        else:
            ax.set_xlabel("time since the run's start (s, simulated)")
    fig.suptitle(
        _title(run) + "\noperator commands: where each takes effect, the rest the axes brake to", fontsize=10
    )
    return fig


# -- tracking.png --------------------------------------------------------------------------


def _tracking(run: Run, d: Digest, out: Path) -> Path:
    cm, st = run.commands, run.states
    fig, renderer = _figure((15, 9.5))
    gs = fig.add_gridspec(3, 3, **MARGINS, top=0.92, hspace=0.32)
    axes = np.array([[fig.add_subplot(gs[r, c]) for c in range(3)] for r in range(3)], dtype=object)
    for c in range(3):
        axes[2, c].sharex(axes[0, c])
    js = run.plan.joint_step
    i_s, diff = paired_error(run)
    for c, axis in enumerate(AXES):
        scale, unit = SHOW[axis]
        ax = axes[0, c]
        _line(ax, cm.t, cm.pos[:, c] * scale, color=CMD, lw=1.2, label="command")
        _line(ax, st.t, st.pos[:, c] * scale, color=ACT, lw=0.8, ls="--", label="simulated axis")
        ax.set_ylabel(f"{axis} position ({unit})")
        ax.set_title(axis)
        # zoom: the start of the axis' first move, from the step rows (exact staircase)
        ax = axes[1, c]
        first = d.first_moves[axis]
        if first is not None:
            t0 = first.t0 / 1e9
            t_end = first.move_times[min(ZOOM_STEPS, len(first.move_times) - 1)] / 1e9 + 0.01
            rows = first.zoom_rows()
            sel = rows[0] / 1e9 <= t_end
            ts = np.concatenate([[t0 - 0.02], rows[0, sel] / 1e9, [t_end]])
            ps = np.concatenate([[first.before], rows[1, sel], [rows[1, sel][-1]]])
            ax.step(ts, ps, where="post", color=CMD, lw=1.0, label="command (steps)")
            m = (st.t >= t0 - 0.02) & (st.t <= t_end)
            ax.plot(st.t[m], st.pos[m, c] / js[c], ".-", color=ACT, lw=0.8, ms=2.5, label="simulated axis")
            ax.set_xlim(t0 - 0.02, t_end)
            ax.set_title(f"the first {ZOOM_STEPS} steps of the first {axis} move (zoom)", fontsize=9)
        else:  # an empty frame would read as a missing figure: say why it is empty
            ax.text(
                0.5,
                0.5,
                f"the {axis} axis does not move in this run",
                ha="center",
                va="center",
                transform=ax.transAxes,
                fontsize=9,
                color="0.35",
            )
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(f"{axis}: no move to zoom into", fontsize=9)
        ax.set_ylabel(f"{axis} position (steps)")
        ax.set_xlabel("time (s)")
        ax = axes[2, c]
        err = diff[:, c] / js[c]
        _line(ax, st.t[i_s], err, color="tab:red", lw=0.6)
        peak = float(np.max(np.abs(err))) if err.size else math.nan
        ax.set_title(f"tracking error command - axis: max |e| = {peak:.3f} steps", fontsize=9)
        ax.set_ylabel("tracking error (steps)")
        ax.set_xlabel("time (s)")
        if run.sim_config is not None:
            half = run.sim_config.axes[axis].pitch_steps / 2
            if err.size and np.max(np.abs(err)) > 0.4 * half:
                for s in (-half, half):
                    ax.axhline(s, color="k", ls=":", lw=0.8)
                ax.text(0.01, 0.02, "dotted: +-1/2 tooth pitch", transform=ax.transAxes, fontsize=8)
    place_legend(axes[0, 0], renderer)
    place_legend(axes[1, 0], renderer)
    axes[0, 0].set_xlabel("time (s)")
    fig.suptitle(_title(run), fontsize=10)
    return _save(fig, out / "tracking.png")


# -- winding.png ----------------------------------------------------------------------------


def _layers(plan: JobPlan) -> dict[int, tuple[float, int]]:
    """Each layer segment: the turns wound before it (all layers of all coils
    in winding order) and its own turns."""
    spr = plan.job.fork_steps_per_rev
    out: dict[int, tuple[float, int]] = {}
    done = 0.0
    for i, s in enumerate(plan.segments):
        if s.kind.winds:
            turns = abs(s.delta[FORK.index]) // spr
            out[i] = (done, turns)
            done += turns
    return out


def _per_turn_command(d: Digest, layers: dict[int, tuple[float, int]]) -> tuple[FloatArray, FloatArray]:
    """(turn centre in winding order, mean distance of the commanded steps of that turn)."""
    xs, ys = [], []
    for i in sorted(d.layers):
        lay = d.layers[i]
        seen = np.flatnonzero(lay.turn_count > 0)
        xs.append(layers[i][0] + seen + 0.5)
        ys.append(lay.turn_sum[seen] / lay.turn_count[seen])
    return (np.concatenate(xs), np.concatenate(ys)) if xs else (np.zeros(0), np.zeros(0))


def _signed_samples(run: Run, d: Digest) -> tuple[IntArray, FloatArray]:
    """For every joint sample: the layer it is measured against (-1: none) and
    its eq. 7 distance to that layer's line (:func:`winder.contract.eq7.sample_deviation`),
    signed by the side of the line it is on, m; NaN outside the layers."""
    plan = run.plan
    js = plan.joint_step
    n = len(run.states)
    if n == 0 or d.sample_segment.size != n:
        return np.full(n, -1, np.int64), np.full(n, np.nan)
    x = run.states.pos[:, FEED.index] / js[FEED.index]
    y = run.states.pos[:, FORK.index] / js[FORK.index]
    layer = layer_of_samples(plan, d.sample_segment, y)
    dist = sample_deviation(plan, layer, x, y)
    for i in (int(v) for v in np.unique(layer[layer >= 0])):
        m = layer == i
        s = plan.segments[i]
        cross = signed_path_distance(
            s.start,
            s.pieces or (s.delta,),
            x[m],
            y[m],
            (plan.step_lengths[FEED.index], plan.step_lengths[FORK.index]),
        )
        dist[m] = np.where(cross < 0, -dist[m], dist[m])
    return layer, dist


def _winding(run: Run, analysis: Analysis, d: Digest, out: Path) -> Path:
    plan = run.plan
    wire = plan.job.wire_diameter
    layers = _layers(plan)
    fig, renderer = _figure((15, 9.5))
    gs = fig.add_gridspec(2, 3, **MARGINS, top=0.91, hspace=0.3)
    ax_job = fig.add_subplot(gs[0, :2])
    ax_turn = fig.add_subplot(gs[1, :2], sharex=ax_job)
    ax_mid = fig.add_subplot(gs[0, 2])
    ax_worst = fig.add_subplot(gs[1, 2])
    layer, signed = _signed_samples(run, d)
    cmd_max = {r.segment: r.max for r in analysis.command.layers}

    # the whole job: the signed distance of every sample against the turns wound
    for i, (before, turns) in layers.items():
        if i in cmd_max:
            ax_job.fill_between(
                [before, before + turns],
                -cmd_max[i] * 1e6,
                cmd_max[i] * 1e6,
                color=CMD,
                alpha=0.15,
                lw=0,
                label="commanded steps: within +- the layer's eq. 7 max" if i == min(cmd_max) else None,
            )
        ax_job.axvline(before + turns, color="0.6", lw=0.6, gid=BACKGROUND)
    pos = _turns_wound(run, layer, layers)
    m = np.flatnonzero(layer >= 0)
    if m.size:
        order = m[np.argsort(pos[m], kind="stable")]
        _line(
            ax_job,
            pos[order],
            signed[order] * 1e6,
            color=ACT,
            lw=0.6,
            label="simulated axes (each pixel column: its lowest to highest sample)",
        )
    ax_job.axhline(0, color=IDEAL, lw=0.8, label="ideal line")
    ax_job.set_ylabel("signed distance to the ideal line (um)")
    ax_job.set_xlabel("turns wound (all layers of all coils in winding order)")
    c, a = analysis.command, analysis.actual
    ax_job.set_title(
        f"eq. 7 over the whole job (vertical lines: layer ends): command mean {c.mean * 1e6:.3f} um, "
        f"max {c.max * 1e6:.3f} um"
        + (f"; axes mean {a.mean * 1e6:.3f} um, max {a.max * 1e6:.3f} um" if a else ""),
        fontsize=10,
    )

    # per turn: eq. 7 over each turn, in % of the wire diameter
    ax_turn.axhline(0.1, color="0.5", lw=3.0, alpha=0.5, label="0.1 % (the paper's RW400 measurement)")
    for label, color, (x, per_turn) in (
        ("command", CMD, _per_turn_command(d, layers)),
        ("simulated axes", ACT, _per_turn_axes(run, layer, signed, layers)),
    ):
        if per_turn.size:
            ax_turn.plot(
                x,
                100 * per_turn / wire,
                ".-",
                color=color,
                ms=3,
                lw=0.8,
                label=f"{label}: worst {100 * per_turn.max() / wire:.4f} %, "
                f"mean {100 * per_turn.mean() / wire:.4f} %",
            )
    for before, turns in layers.values():
        ax_turn.axvline(before + turns, color="0.6", lw=0.6, gid=BACKGROUND)
    ax_turn.set_xlabel("turns wound (all layers of all coils in winding order)")
    ax_turn.set_ylabel("mean deviation of the turn (% of wire diameter)")
    ax_turn.set_title("eq. 7 of each turn", fontsize=10)
    ax_turn.set_ylim(bottom=0)

    _zoom_middle(run, d, ax_mid)
    _zoom_worst(run, analysis, layer, signed, ax_worst)
    if layers:
        total = max(b + t for b, t in layers.values())
        ax_job.set_xlim(-0.01 * total, 1.01 * total)
    for ax in (ax_job, ax_turn, ax_mid, ax_worst):
        place_legend(ax, renderer)
    fig.suptitle(_title(run), fontsize=10)
    return _save(fig, out / "winding.png")


def _turns_wound(run: Run, layer: IntArray, layers: dict[int, tuple[float, int]]) -> FloatArray:
    """For every joint sample measured against a layer: the turns wound when
    it was taken (the turns before its layer and its fork position in it,
    held inside the layer); NaN for the others."""
    plan = run.plan
    n = len(plan.segments)
    before, turns, start = np.zeros(n), np.zeros(n), np.zeros(n)
    for i, (b, t) in layers.items():
        before[i], turns[i], start[i] = b, t, plan.segments[i].start[FORK.index]
    out = np.full(layer.size, np.nan)
    m = layer >= 0
    if np.any(m):
        lay = layer[m]
        y = run.states.pos[m, FORK.index] / plan.joint_step[FORK.index]
        out[m] = before[lay] + np.clip(np.abs(y - start[lay]) / plan.job.fork_steps_per_rev, 0, turns[lay])
    return out


def _zoom_middle(run: Run, d: Digest, ax: Axes) -> None:
    """An eighth of a turn in the middle of the first layer: every commanded
    step and sample, signed distance to the line."""
    plan = run.plan
    spr = plan.job.fork_steps_per_rev
    lx, ly = plan.step_lengths[FEED.index], plan.step_lengths[FORK.index]
    js = plan.joint_step
    first = next((i for i, s in enumerate(plan.segments) if s.kind.winds), None)
    if first is None or first not in d.layers or d.layers[first].zoom is None:
        ax.text(0.5, 0.5, "no layer wound", ha="center", transform=ax.transAxes)
        return
    s = plan.segments[first]
    zoom = d.layers[first].zoom
    assert zoom is not None
    y_lo, y_hi = zoom
    if d.layers[first].zoom_rows:
        fork, dist = np.hstack(d.layers[first].zoom_rows)
        ax.plot(fork / spr, dist * 1e6, ".-", color=CMD, lw=0.5, ms=3, label="commanded steps")
    st = run.states
    if len(st):
        x = st.pos[:, FEED.index] / js[FEED.index] - s.start[FEED.index]
        y = st.pos[:, FORK.index] / js[FORK.index] - s.start[FORK.index]
        m = (y + s.start[FORK.index] >= y_lo) & (y + s.start[FORK.index] <= y_hi)
        dist = signed_path_distance(
            s.start, s.pieces or (s.delta,), x[m] + s.start[FEED.index], y[m] + s.start[FORK.index], (lx, ly)
        )
        ax.plot(
            (y[m] + s.start[FORK.index]) / spr,
            dist * 1e6,
            "o-",
            color=ACT,
            ms=3,
            lw=0.8,
            label="simulated axes",
        )
    ax.axhline(0, color=IDEAL, lw=0.8, label="ideal line")
    ax.set_xlabel("fork position (turns)")
    ax.set_ylabel("signed distance to the ideal line (um)")
    ax.set_title(f"zoom: 1/8 turn mid layer 1 (a feed step is {lx * 1e6:g} um)", fontsize=10)


def _zoom_worst(run: Run, analysis: Analysis, layer: IntArray, signed: FloatArray, ax: Axes) -> None:
    """The samples around the axes' largest distance to the line, in time."""
    st = run.states
    if not np.any(np.isfinite(signed)):
        ax.text(0.5, 0.5, "no joint samples while a layer is wound", ha="center", transform=ax.transAxes)
        return
    k = int(np.nanargmax(np.abs(signed)))
    tk = float(st.t[k])
    m = np.abs(st.t - tk) <= 0.4
    seg = run.plan.segments
    lay = int(layer[k])
    cmd = next((r.max for r in analysis.command.layers if r.segment == lay), math.nan)
    if math.isfinite(cmd):
        ax.axhspan(-cmd * 1e6, cmd * 1e6, color=CMD, alpha=0.15, lw=0, label="the layer's commanded steps")
    ax.plot(st.t[m], signed[m] * 1e6, ".-", color=ACT, lw=0.8, ms=3, label="simulated axes")
    ax.axhline(0, color=IDEAL, lw=0.8, label="ideal line")
    ax.set_xlim(tk - 0.4, tk + 0.4)
    fork = np.abs(st.vel[:, 1])
    share = 100 * fork[k] / max(float(fork.max()), 1e-300)
    ax.set_title(
        f"zoom: the axes' largest distance, {abs(signed[k]) * 1e6:.2f} um, in coil {seg[lay].pole + 1} "
        f"layer {seg[lay].layer + 1}\n(t = {tk:.3f} s; the fork at {share:.0f} % of its top speed)",
        fontsize=10,
    )
    ax.set_xlabel("time (s)")
    ax.set_ylabel("signed distance to the ideal line (um)")


def _per_turn_axes(
    run: Run, layer: IntArray, dist: FloatArray, layers: dict[int, tuple[float, int]]
) -> tuple[FloatArray, FloatArray]:
    """(turn centre in winding order, mean distance of the joint samples of
    that turn), each sample measured against the layer whose fork range holds it."""
    plan = run.plan
    spr = plan.job.fork_steps_per_rev
    y = run.states.pos[:, FORK.index] / plan.joint_step[FORK.index] if len(run.states) else np.zeros(0)
    xs, ys = [], []
    for i in (int(v) for v in np.unique(layer[layer >= 0])):
        m = layer == i
        before, turns = layers[i]
        tid = turn_index(np.abs(y[m] - plan.segments[i].start[FORK.index]), spr, turns)
        sums, counts = np.bincount(tid, weights=np.abs(dist[m])), np.bincount(tid)
        seen = np.flatnonzero(counts > 0)
        xs.append(before + seen + 0.5)
        ys.append(sums[seen] / counts[seen])
    return (np.concatenate(xs), np.concatenate(ys)) if xs else (np.zeros(0), np.zeros(0))


# -- all figures of a run -------------------------------------------------------------------


def plot_analysis(
    run: Run, analysis: Analysis, out: Path | None = None, digested: Digest | None = None
) -> list[Path]:
    """Write motion.png, tracking.png, winding.png and wound.png (and
    operations.png for a run with operator commands, wire.png for one that
    simulated the wire); return their paths. ``digested``: the run's
    :func:`winder.analysis.metrics.digest_run`, if made already."""
    d = digested if digested is not None else digest_run(run)
    out = output_dir(plots_dir(run.path) if out is None else Path(out))
    # tracking.png compares the commands with the axes' samples: a run
    # without joint samples (a hardware consumer records its own topics) has none to draw
    tracking = ["tracking"] if run.states.t.size else []
    figures = ["motion", *tracking, "winding"] + (["operations"] if run.events else [])
    figures += ["wound"] if run.states.t.size else []  # the cross-section needs the axes' samples
    figures += ["wire"] if len(run.tension) else []  # where the run simulated the wire
    global _JOB
    _JOB = (run, analysis, d, out)
    try:
        return _draw_all(figures)
    finally:
        _JOB = None


#: the run the figures are drawn of, while plot_analysis draws them (the
#: worker processes it forks inherit it: nothing of it is pickled)
_JOB: tuple[Run, Analysis, Digest, Path] | None = None


#: the coils wound.png draws at most (one row each), and the colours of its turns
WOUND_COILS = 4
WOUND_COLOURS = {
    "ok": "tab:blue",
    "gap": "tab:orange",
    "overlap": "tab:purple",
    "offset": "tab:red",
    "flange": "k",
    "crossover": "tab:green",
    "stretched": "m",
    "slack": "gold",
}
#: what the legend calls each colour
WOUND_WORDS = {
    "ok": "laid in place",
    "gap": "gap to the turn before",
    "overlap": "overlaps the turn before",
    "offset": "off its place",
    "flange": "on the flange",
    "crossover": "crossed over outside its zone",
    "stretched": "stretched past the yield",
    "slack": "slack (below the alarm band)",
}
#: the wire's state in a turn (winder.analysis.wound), marked in its colour over
#: the turn's: a ring around a stretched turn, a dot in a slack one (scale: of
#: the wire's diameter)
WIRE_MARKS: dict[str, dict[str, Any]] = {
    "stretched": {
        "scale": 1.0,
        "facecolors": "none",
        "edgecolors": WOUND_COLOURS["stretched"],
        "linewidths": 1.6,
    },
    "slack": {"scale": 0.4, "facecolors": WOUND_COLOURS["slack"], "edgecolors": "k", "linewidths": 0.3},
}


def _wound(run: Run, d: Digest, out: Path) -> Path:
    """wound.png: the cross-section of the winding window, each turn a circle
    of the wire's diameter where the simulated axes laid it (the axial place
    measured, the layer's height), the defects coloured by kind; one row per
    coil (the first WOUND_COILS)."""
    from matplotlib.collections import EllipseCollection
    from matplotlib.patches import Rectangle

    from winder.analysis.wound import as_wound

    wound = as_wound(run, segment_end=d.segment_end)
    assert wound is not None
    wire = wound.wire_m * 1e3
    width = wound.window_m * 1e3
    # a turn with several defects shows the most telling: on the flange, then
    # a gap or overlap (where a loss happened), then an offset (which lasts)
    rank = {"flange": 0, "overlap": 1, "gap": 2, "crossover": 3, "offset": 4}
    kind: dict[tuple[int, int, int], str] = {}
    for defect in sorted((f for f in wound.defects if f.kind in rank), key=lambda f: -rank[f.kind]):
        kind[defect.coil, defect.layer, defect.turn] = defect.kind
    marked = {m: {(f.coil, f.layer, f.turn) for f in wound.defects if f.kind == m} for m in WIRE_MARKS}
    coils = sorted({t.coil for t in wound.turns})[:WOUND_COILS] or [1]
    top = max((t.radial_m * 1e3 for t in wound.turns), default=wire / 2) + wire
    aspect = top / max(width, wire)
    row = min(max(11.5 * aspect + 0.9, 1.7), 6.0)  # inches per coil: the window at equal scale, and its title
    fig, _ = _figure((13, 1.2 + row * len(coils)))
    axes = [fig.add_subplot(len(coils), 1, i + 1) for i in range(len(coils))]
    shown: set[str] = set()
    for ax, coil in zip(axes, coils, strict=True):
        turns = [t for t in wound.turns if t.coil == coil]
        ax.add_patch(Rectangle((0, -wire * 0.6), width, wire * 0.6, color="0.85", lw=0, gid=BACKGROUND))
        for x in (0.0, width):
            ax.axvline(x, color="0.35", lw=2.0, gid=BACKGROUND)
        for name, colour in WOUND_COLOURS.items():
            mine = [t for t in turns if kind.get((t.coil, t.layer, t.turn), "ok") == name]
            if not mine:
                continue
            xy = np.array([[t.axial_m * 1e3, t.radial_m * 1e3] for t in mine])
            size = np.full(len(mine), wire)
            ax.add_collection(
                EllipseCollection(
                    size,
                    size,
                    np.zeros(len(mine)),
                    units="x",
                    offsets=xy,
                    offset_transform=ax.transData,
                    facecolors=colour,
                    edgecolors="white" if name == "ok" else colour,
                    linewidths=0.4,
                    alpha=0.9 if name == "ok" else 1.0,
                )
            )
            shown.add(name)
        for name, style in WIRE_MARKS.items():
            mine = [t for t in turns if (t.coil, t.layer, t.turn) in marked[name]]
            if mine:
                _circles(ax, mine, wire, style)
                shown.add(name)
        ax.set_xlim(-wire, width + wire)
        ax.set_ylim(-wire * 0.8, top + wire * 0.2)
        ax.set_aspect("equal", adjustable="box")
        ax.set_ylabel(f"coil {coil}\nheight (mm)")
        laid = sum(lay.turns_laid for lay in wound.layers if lay.coil == coil)
        planned = sum(lay.turns_planned for lay in wound.layers if lay.coil == coil)
        faults = sum(1 for f in wound.defects if f.coil == coil and f.kind not in WIRE_MARKS)
        wired = {m: sum(1 for c, _, _ in marked[m] if c == coil) for m in WIRE_MARKS}
        ax.set_title(
            f"coil {coil}: {laid} of {planned} turns laid, {faults} defects"
            + (f" (tolerance {wound.tolerance_m * 1e3:g} mm)" if faults else "")
            + "".join(f", {n} turns {m}" for m, n in wired.items() if n),
            fontsize=9,
        )
    axes[-1].set_xlabel("axial place in the window, from the start flange (mm)")
    handles = [_wound_handle(name) for name in WOUND_COLOURS if name in shown]
    height = 1.2 + row * len(coils)
    fig.legend(  # in inches from the top, below the two-line title: a tall window's axes must not lift it
        handles=handles,
        loc="upper left",
        bbox_to_anchor=(0.07, 1 - 0.5 / height),
        ncol=len(handles),
        fontsize=8,
        frameon=False,
    )
    more = len({t.coil for t in wound.turns}) - len(coils)
    fig.suptitle(
        _title(run)
        + f"\nthe coil as wound: each turn where the simulated axes laid it, window {width:g} mm wide"
        + (f" ({more} more coils not drawn)" if more > 0 else ""),
        fontsize=10,
    )
    fig.subplots_adjust(
        left=0.07,
        right=0.985,
        bottom=0.5 / (1.2 + row * len(coils)),
        top=1 - 1.1 / (1.2 + row * len(coils)),
        hspace=0.55,
    )
    return _save(fig, out / "wound.png")


def _circles(ax: Axes, turns: list[Any], wire: float, style: dict[str, Any]) -> None:
    """A mark of WIRE_MARKS' ``style`` (its ``scale`` of the ``wire``'s
    diameter, mm, across) at each of ``turns`` (as laid)."""
    from matplotlib.collections import EllipseCollection

    look = dict(style)
    xy = np.array([[t.axial_m * 1e3, t.radial_m * 1e3] for t in turns])
    sizes = np.full(len(turns), wire * look.pop("scale"))
    ax.add_collection(
        EllipseCollection(
            sizes, sizes, np.zeros(len(turns)), units="x", offsets=xy, offset_transform=ax.transData, **look
        )
    )


def _wound_handle(name: str) -> Line2D:
    """The legend's marker of a kind of turn in wound.png (EllipseCollection
    has no legend handle): a dot of its colour, or its mark."""
    if name not in WIRE_MARKS:
        return Line2D([], [], ls="", marker="o", ms=8, color=WOUND_COLOURS[name], label=WOUND_WORDS[name])
    mark = WIRE_MARKS[name]
    ring = mark["facecolors"] == "none"
    return Line2D(
        [], [], ls="", marker="o", ms=8 if ring else max(8 * mark["scale"], 5), mfc=mark["facecolors"],
        mec=mark["edgecolors"], mew=mark["linewidths"], label=WOUND_WORDS[name],
    )  # fmt: skip


def _draw(name: str) -> Path:
    assert _JOB is not None
    run, analysis, d, out = _JOB
    with matplotlib.rc_context(RC):
        if name == "motion":
            return _motion(run, d, out)
        if name == "tracking":
            return _tracking(run, d, out)
        if name == "winding":
            return _winding(run, analysis, d, out)
        if name == "wound":
            return _wound(run, d, out)
        if name == "wire":
            return _save(wire_figure(run, d), out / "wire.png")
        return _operations(run, d, out)


class FigureError(Exception):
    """Some figures could not be drawn (a bug): those that were, and why the others were not."""

    def __init__(self, drawn: list[Path], failed: list[str]) -> None:
        super().__init__("; ".join(failed))
        self.drawn = drawn
        self.failed = failed


def _draw_all(figures: list[str]) -> list[Path]:
    """Each figure drawn in a process of its own when the machine has cores to
    spare (forked: the run is shared, not copied), else one after another.
    Drawing is matplotlib's Python code, one core per figure."""
    import gc
    import multiprocessing as mp
    import os

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    if cores < 2 or "fork" not in mp.get_all_start_methods():
        drawn, failed = [], []
        for name in figures:
            try:
                drawn.append(_draw(name))
            except (OutputError, OSError):  # the output cannot be written: the caller says so
                raise
            except Exception as exc:  # as below: the others are still drawn
                failed.append(f"{name}.png: {type(exc).__name__}: {exc}")
        if failed:
            raise FigureError(drawn, failed)
        return drawn
    from concurrent.futures import ProcessPoolExecutor

    # a process per figure even on two cores: the figures take unequal times
    # (motion.png the longest), and the system shares the cores out evenly.
    # Frozen, the parent's objects stay out of the children's garbage
    # collections, which would otherwise write to (and so copy) their pages.
    gc.freeze()
    try:
        with ProcessPoolExecutor(len(figures), mp_context=mp.get_context("fork")) as pool:
            futures = {name: pool.submit(_draw, name) for name in figures}
            drawn, failed = [], []
            for name, future in futures.items():
                try:
                    drawn.append(future.result())
                except (OutputError, OSError):  # the output cannot be written: the caller says so
                    raise
                except Exception as exc:  # a bug in one figure: the others are still drawn, and it is named
                    failed.append(f"{name}.png: {type(exc).__name__}: {exc}")
            if failed:
                raise FigureError(drawn, failed)
            return drawn
    finally:
        gc.unfreeze()


# -- identify.png ----------------------------------------------------------------------------


def plot_identification(run: Run, ident: Identification, out: Path | None = None) -> list[Path]:
    """Write identify.png: the MRAS convergence of J and D per axis, the band
    it settles in, least squares and the recorded value."""
    out = output_dir(plots_dir(run.path) if out is None else Path(out))
    with matplotlib.rc_context(RC):
        return [_identification(ident, out)]


def _identification(ident: Identification, out: Path) -> Path:
    fig, _ = _figure((15, 8))
    gs = fig.add_gridspec(2, 3, **MARGINS, top=0.82, hspace=0.32)
    for c, axis in enumerate(AXES):
        a = ident.axes[axis]
        top = fig.add_subplot(gs[0, c])
        for r, (key, true, ls) in enumerate((("J", a.J_true, a.ls_J), ("D", a.D_true, a.ls_D))):
            ax = top if r == 0 else fig.add_subplot(gs[1, c], sharex=top)
            head = f"{axis}: {key} = {true:.4g} {'kg m²' if key == 'J' else 'N m s/rad'}"
            if not a.identifiable:
                why = "\n".join(textwrap.wrap(a.reason, 48))
                ax.text(0.5, 0.5, why, ha="center", va="center", transform=ax.transAxes, fontsize=9)
                ax.set_xticks([])
                ax.set_yticks([])
                ax.set_title(head, fontsize=10)
                continue
            ax.axhspan(0.99, 1.01, color="0.85")
            ax.axhline(1.0, color="k", lw=0.8)
            ax.set_ylabel(f"{key} estimate / recorded {key}")
            tr = a.trajectory
            assert tr is not None
            est = getattr(tr, key) / true
            settled = (a.mras_J if key == "J" else a.mras_D) / true
            lo, hi = (x / true for x in (a.mras_J_band if key == "J" else a.mras_D_band))
            t0 = a.mras_settled_from if a.mras_settled_from is not None else float(tr.t[-1])
            t1 = float(tr.t[-1])
            ok = np.isfinite(est)
            _line(ax, tr.t[ok], est[ok], color=CMD, lw=0.8)
            ax.fill_between([t0, t1], lo, hi, color="tab:green", alpha=0.25, lw=0)
            ax.plot([t0, t1], [settled, settled], color="tab:green", lw=2.0)
            ax.axhline(ls / true, color=ACT, ls="--", lw=1.2)
            if r == 0 and a.mras_time_1pct is not None:
                ax.axvline(a.mras_time_1pct, color="tab:purple", ls=":", lw=1.2)
            # the band, least squares and +-10 % in view; the start from b = 0 runs off it
            ax.set_ylim(min(0.9, lo, ls / true) - 0.02, max(1.1, hi, ls / true) + 0.02)
            spread = f", std {100 * a.mras_spread:.2g} %" if key == "J" else ""
            ax.set_title(
                f"{head}; least squares {100 * (ls / true - 1):+.3f} %\nMRAS settled "
                f"{100 * (settled - 1):+.3g} % (min .. max {100 * (lo - 1):+.3g} .. "
                f"{100 * (hi - 1):+.3g} %{spread})",
                fontsize=9,
            )
        if a.identifiable:
            fig.axes[-1].set_xlabel("time in the run (s)")
        top.tick_params(labelbottom=False)
    handles = [
        Line2D([], [], color=CMD, lw=1.0, label=f"MRAS estimate (gain {ident.gain:g}), from b = 0"),
        Patch(color="tab:green", alpha=0.4, label="its last quarter of updates: min .. max"),
        Line2D([], [], color="tab:green", lw=2.0, label="... and mean (the settled estimate)"),
        Line2D([], [], color=ACT, ls="--", lw=1.2, label="least squares"),
        Patch(color="0.85", label="recorded +-1 %"),
        Line2D([], [], color="tab:purple", ls=":", lw=1.2, label="J within 1 % for good from here"),
    ]
    fig.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, 0.935), ncols=3, fontsize=9)
    fig.suptitle(
        f"{ident.label}: {ident.model} model, joint states at {ident.publish_rate:g} Hz, "
        f"window {ident.window * 1e3:.3g} ms - MRAS (thesis 001 §2.4, Landau's law, extended to D) "
        "vs least squares",
        fontsize=10,
    )
    return _save(fig, out / "identify.png")
