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
* ``winding.png`` - the unrolled winding path, a zoom into one stretch of it
  with the signed distance of every commanded step and simulated sample to
  the ideal line, and the per-turn mean deviation (eq. 7) in % of the wire;
* ``identify.png`` - the MRAS estimates of J and D converging, against the
  least-squares estimate and the recorded value.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import numpy.typing as npt

from winder.analysis.digest import ZOOM_STEPS, Digest
from winder.analysis.identify import Identification
from winder.analysis.metrics import Analysis, digest_run, paired_error, winding_samples
from winder.motion.job import AXES
from winder.record.reader import Run

__all__ = ["plot_analysis", "plot_identification", "plots_dir"]

CMD, ACT, IDEAL = "tab:blue", "tab:orange", "k"
#: joint units and the scale to show them in
SHOW = {"feed": (1e3, "mm"), "fork": (1.0, "rad"), "pole": (1.0, "rad")}
MAX_POINTS = 40_000
#: fixed margins (fractions of the figure): matplotlib's constrained layout
#: measured every tick label of every panel and took most of the plotting time
MARGINS = {"left": 0.06, "right": 0.985, "bottom": 0.06, "wspace": 0.22}
#: PNG compression: level 1 writes the figures several times faster than the
#: default 6 for files about a third larger
PNG = {"compress_level": 1}


def plots_dir(run_path: Path) -> Path:
    """Where the figures of the recording at ``run_path`` go (module doc)."""
    p = Path(run_path)
    return p / "plots" if p.is_dir() else p.with_name(p.stem + "_plots")


def _thin(*arrays: npt.NDArray[np.float64], n: int = MAX_POINTS) -> list[npt.NDArray[np.float64]]:
    step = max(1, arrays[0].size // n)
    return [a[::step] for a in arrays]


def _legend(ax: Any, **kw: Any) -> None:
    """The legend in a band above the data (the y range is raised for it),
    in one row: it never hides a curve, however dense the data."""
    handles, labels = ax.get_legend_handles_labels()
    if not handles:
        return
    lo, hi = ax.get_ylim()
    ax.set_ylim(lo, hi + 0.3 * (hi - lo))
    per_row = 3 if sum(len(x) for x in labels) < 90 else 1
    if per_row == 1:
        ax.set_ylim(lo, hi + (0.3 + 0.12 * len(handles)) * (hi - lo))
    ax.legend(loc="upper left", ncol=min(len(handles), per_row), fontsize=8, framealpha=0.9, **kw)


def _title(run: Run) -> str:
    j = run.plan.job
    model = run.sim_config.model if run.sim_config else "?"
    state = "complete" if run.complete else ("cut short, recovered" if run.recovered else "incomplete")
    return (
        f"{run.label}: {j.poles} poles x {j.layers} layers x {j.turns_per_layer} turns, "
        f"{run.profile or '?'} profile, {model} motor model ({state})"
    )


def _first_ramp(
    d: Digest, axis: str, t: npt.NDArray[np.float64], v: npt.NDArray[np.float64]
) -> tuple[float, float] | None:
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


def _mark_events(ax: Any, run: Run, label: bool) -> None:
    """The operator's commands on a time axis: a pause shaded from the moment
    it takes effect to the resume (the rest dotted), an abort and an override
    as lines."""
    end = float(run.states.t[-1]) if len(run.states) else 0.0
    pause: dict[str, Any] | None = None
    for e in run.events:
        t = e["t_ns"] / 1e9
        kind = e.get("event")
        if kind in ("pause", "abort"):
            color = "black" if kind == "pause" else "tab:red"
            ax.axvline(t, color=color, lw=1.0, label=f"{kind} takes effect" if label else None)
            ax.axvline(e.get("t_rest_ns", e["t_ns"]) / 1e9, color=color, lw=0.8, ls=":",
                       label="at rest" if label and kind == "pause" else None)  # fmt: skip
            pause = e if kind == "pause" else None
        elif kind == "resume":
            ax.axvline(t, color="tab:green", lw=1.0, label="resume" if label else None)
            if pause is not None:
                ax.axvspan(pause["t_ns"] / 1e9, t, color="tab:gray", alpha=0.12)
            pause = None
        elif kind == "override":
            ax.axvline(t, color="tab:purple", lw=1.0, ls="--",
                       label=f"override x{e.get('factor', 1.0):g}" if label else None)  # fmt: skip
    if pause is not None:
        ax.axvspan(pause["t_ns"] / 1e9, max(end, pause["t_ns"] / 1e9), color="tab:gray", alpha=0.12)


def _motion(run: Run, d: Digest, out: Path) -> Path:
    st = run.states
    acc = np.asarray(np.gradient(st.vel, st.t, axis=0)) if len(st) >= 3 else np.zeros((0, 3))
    jerk = np.asarray(np.gradient(acc, st.t, axis=0)) if len(st) >= 3 else np.zeros((0, 3))
    fig, axes = plt.subplots(4, 3, figsize=(15, 12))
    fig.subplots_adjust(**MARGINS, top=0.89, hspace=0.4)
    names = ("velocity", "acceleration", "jerk")
    rate = run.sim_config.publish_rate if run.sim_config else math.nan
    for c, axis in enumerate(AXES):
        scale, unit = SHOW[axis]
        tc, vc, _, _ = d.traces[axis].whole_run()
        t, v, a, j = d.traces[axis].first_move()
        ax = axes[0, c]
        if len(st):
            ta, va = _thin(st.t, st.vel[:, c])
            ax.plot(ta, va * scale, color=ACT, lw=0.6, label="simulated axis")
        if vc.size:
            ax.plot(tc, vc * scale, ".", color=CMD, ms=1.0, label="command")
        ax.set_title(f"{axis}: whole run", fontsize=10)
        _mark_events(ax, run, label=c == 0)
        ax.set_ylabel(f"{axis} velocity ({unit}/s)")
        ax.set_xlabel("time (s)")
        window = _first_ramp(d, axis, t, v) if v.size else None
        for r, (cmd, act) in enumerate(((v, st.vel[:, c]), (a, acc[:, c]), (j, jerk[:, c]))):
            ax = axes[r + 1, c]
            if window is None:
                ax.text(0.5, 0.5, f"the {axis} axis does not move", ha="center", transform=ax.transAxes)
                continue
            lo, hi = window
            ms = (st.t >= lo) & (st.t <= hi)
            mc = (t >= lo) & (t <= hi)
            ax.plot(
                st.t[ms],
                act[ms] * scale,
                ".-",
                color=ACT,
                lw=0.7,
                ms=2.5,
                label=f"simulated axis, sampled at {rate:g} Hz",
            )
            ax.plot(t[mc], cmd[mc] * scale, "-", color=CMD, lw=1.4, label="command (from the step times)")
            ax.set_xlim(lo, hi)
            if r == 2 and np.any(mc):
                lim = 2.5 * max(float(np.max(np.abs(cmd[mc]))), 1e-12) * scale
                ax.set_ylim(-lim, lim)
            power = ("/s", "/s²", "/s³")[r]
            ax.set_ylabel(f"{axis} {names[r]} ({unit}{power})")
            if r == 0:
                ax.set_title(f"{axis}: its first acceleration (zoom)", fontsize=10)
        axes[3, c].set_xlabel("time (s)")
    for ax in axes.flat:
        ax.grid(True, lw=0.3)
    _legend(axes[0, 0], markerscale=6)
    _legend(axes[1, 0])
    fig.suptitle(
        _title(run) + "\ncommand: the ideal interpolated motion from each segment's step times (not "
        "estimated over the first and last few steps of a move, where the speed is near 0)\n"
        "axes: the recorded joint velocity and its differences; the rotor rings at every step, so its "
        "acceleration and jerk show the step ripple as far as it is sampled (jerk axis clipped)",
        fontsize=10,
    )
    path = out / "motion.png"
    fig.savefig(path, dpi=100, pil_kwargs=PNG)
    plt.close(fig)
    return path


def _operations(run: Run, d: Digest, out: Path) -> Path:
    """operations.png: the velocity of the moving axes around the operator's
    commands (from half a second before the first to two after the last)."""
    st = run.states
    times = [e["t_ns"] / 1e9 for e in run.events] + [e.get("t_rest_ns", e["t_ns"]) / 1e9 for e in run.events]
    end = float(st.t[-1]) if len(st) else max(times)
    lo, hi = max(min(times) - 0.5, 0.0), min(max(times) + 2.0, end)
    moving = [c for c, axis in enumerate(AXES) if len(st) and np.ptp(st.pos[:, c]) > 0]
    fig, axes = plt.subplots(max(len(moving), 1), 1, figsize=(11, 3.2 * max(len(moving), 1)), squeeze=False)
    for row, c in enumerate(moving):
        axis = AXES[c]
        scale, unit = SHOW[axis]
        ax = axes[row, 0]
        m = (st.t >= lo) & (st.t <= hi)
        ax.plot(st.t[m], st.vel[m, c] * scale, color=ACT, lw=0.7, label="simulated axis")
        tc, vc, _, _ = d.traces[axis].whole_run()
        mc = (tc >= lo) & (tc <= hi)
        ax.plot(tc[mc], vc[mc] * scale, ".", color=CMD, ms=1.5, label="command (from the step times)")
        _mark_events(ax, run, label=row == 0)
        ax.set_xlim(lo, hi)
        ax.set_ylabel(f"{axis} velocity ({unit}/s)")
        ax.grid(True, lw=0.3)
    axes[-1, 0].set_xlabel("time since the run's start (s, simulated)")
    axes[0, 0].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, markerscale=4)
    fig.suptitle(
        _title(run) + "\noperator commands: where each takes effect, the rest it brakes to", fontsize=10
    )
    fig.tight_layout()
    path = out / "operations.png"
    fig.savefig(path, dpi=100, pil_kwargs=PNG)
    plt.close(fig)
    return path


def _tracking(run: Run, d: Digest, out: Path) -> Path:
    cm, st = run.commands, run.states
    fig, axes = plt.subplots(3, 3, figsize=(15, 9.5))
    fig.subplots_adjust(**MARGINS, top=0.92, hspace=0.32)
    js = run.plan.joint_step
    i_s, diff = paired_error(run)
    for c, axis in enumerate(AXES):
        scale, unit = SHOW[axis]
        ax = axes[0, c]
        t1, p1 = _thin(cm.t, cm.pos[:, c])
        t2, p2 = _thin(st.t, st.pos[:, c])
        ax.plot(t1, p1 * scale, color=CMD, lw=1.2, label="command")
        ax.plot(t2, p2 * scale, color=ACT, lw=0.8, ls="--", label="simulated axis")
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
        ax.set_ylabel(f"{axis} position (steps)")
        ax.set_xlabel("time (s)")
        ax = axes[2, c]
        err = diff[:, c] / js[c]
        te, ee = _thin(st.t[i_s], err)
        ax.plot(te, ee, color="tab:red", lw=0.6)
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
        for a in axes[:, c]:
            a.grid(True, lw=0.3)
    _legend(axes[0, 0])
    _legend(axes[1, 0])
    axes[0, 0].set_xlabel("time (s)")
    fig.suptitle(_title(run), fontsize=10)
    path = out / "tracking.png"
    fig.savefig(path, dpi=100, pil_kwargs=PNG)
    plt.close(fig)
    return path


def _winding(run: Run, analysis: Analysis, d: Digest, out: Path) -> Path:
    plan = run.plan
    lx, ly = plan.step_lengths[0], plan.step_lengths[1]
    js = plan.joint_step
    spr = plan.job.fork_steps_per_rev
    fig = plt.figure(figsize=(15, 9.5))
    gs = fig.add_gridspec(2, 2, **MARGINS, top=0.92, hspace=0.3)
    ax0 = fig.add_subplot(gs[0, 0])
    ax1 = fig.add_subplot(gs[0, 1])
    ax2 = fig.add_subplot(gs[1, :])
    layers = [(i, s) for i, s in enumerate(plan.segments) if s.kind == "layer"]
    # overview: eq. 7 of every layer (the whole path unrolled is a solid band at this scale)
    per_layer = [("command", CMD, analysis.command.layers)]
    if analysis.actual is not None:
        per_layer.append(("simulated axes", ACT, analysis.actual.layers))
    for k, (label, color, rows) in enumerate(per_layer):
        if not rows:
            continue
        x = np.arange(len(rows)) + (k - 0.5) * 0.15
        ax0.plot(x, [r.mean * 1e6 for r in rows], "o", color=color, ms=4, label=f"{label}: mean")
        ax0.plot(x, [r.max * 1e6 for r in rows], "^", color=color, ms=4, mfc="none", label=f"{label}: max")
        ax0.set_xticks(np.arange(len(rows)), [f"{r.pole + 1}:{r.layer + 1}" for r in rows], fontsize=7)
    ax0.set_xlabel("coil:layer, in winding order")
    ax0.set_ylabel("distance to the ideal line (um)")
    ax0.set_title("eq. 7 of each layer: mean and max distance of steps and samples", fontsize=10)
    ax0.set_ylim(bottom=0)
    _legend(ax0)
    ax0.grid(True, lw=0.3)
    # zoom: a quarter turn in the middle of the first layer, signed distance to the line
    if layers:
        i, s = layers[0]
        norm = math.hypot(s.delta[0] * lx, s.delta[1] * ly)
        zoom = d.layers[i].zoom
        assert zoom is not None
        y_lo, y_hi = zoom
        if d.layers[i].zoom_rows:
            fork, dist = np.hstack(d.layers[i].zoom_rows)
            ax1.plot(fork / spr, dist * 1e6, ".-", color=CMD, lw=0.5, ms=3, label="commanded steps")
        st = run.states
        if len(st):
            x = st.pos[:, 0] / js[0] - s.start[0]
            y = st.pos[:, 1] / js[1] - s.start[1]
            m = (y + s.start[1] >= y_lo) & (y + s.start[1] <= y_hi)
            dist = (s.delta[0] * y[m] - x[m] * s.delta[1]) * lx * ly / norm
            ax1.plot(
                (y[m] + s.start[1]) / spr, dist * 1e6, "o-", color=ACT, ms=3, lw=0.8, label="simulated axes"
            )
        ax1.axhline(0, color=IDEAL, lw=0.8, label="ideal line")
        ax1.set_xlabel("fork position (turns)")
        ax1.set_ylabel("signed distance to the ideal line (um)")
        ax1.set_title(
            f"zoom: 1/8 turn in the middle of layer 1 (a feed step is {lx * 1e6:g} um)", fontsize=10
        )
        _legend(ax1)
        ax1.grid(True, lw=0.3)
    # per turn: eq. 7 over each turn, in % of the wire diameter
    wire = plan.job.wire_diameter
    for label, color, per_turn in (
        ("command", CMD, _per_turn_command(d)),
        ("simulated axes", ACT, _per_turn_axes(run, d)),
    ):
        if per_turn.size:
            ax2.plot(
                np.arange(1, per_turn.size + 1),
                100 * per_turn / wire,
                ".-",
                color=color,
                ms=3,
                lw=0.8,
                label=f"{label}: worst {100 * per_turn.max() / wire:.4f} %, "
                f"mean {100 * per_turn.mean() / wire:.4f} %",
            )
    ax2.axhline(0.1, color="k", ls=":", lw=0.8, label="0.1 % (the paper's RW400 measurement)")
    ax2.set_xlabel("turn (all layers of all coils in winding order)")
    ax2.set_ylabel("mean deviation of the turn (% of wire diameter)")
    c = analysis.command
    a = analysis.actual
    ax2.set_title(
        f"eq. 7 per turn; whole job: command mean {c.mean * 1e6:.3f} um, max {c.max * 1e6:.3f} um"
        + (f"; axes mean {a.mean * 1e6:.3f} um, max {a.max * 1e6:.3f} um" if a else ""),
        fontsize=10,
    )
    ax2.set_ylim(bottom=0)
    _legend(ax2)
    ax2.grid(True, lw=0.3)
    fig.suptitle(_title(run), fontsize=10)
    path = out / "winding.png"
    fig.savefig(path, dpi=100, pil_kwargs=PNG)
    plt.close(fig)
    return path


def _per_turn_command(d: Digest) -> npt.NDArray[np.float64]:
    """Mean distance of the commanded steps per turn, in winding order."""
    means = [d.layers[i].turn_means() for i in sorted(d.layers) if d.layers[i].points]
    return np.concatenate(means) if means else np.zeros(0)


def _per_turn_axes(run: Run, d: Digest) -> npt.NDArray[np.float64]:
    """Mean distance of the joint samples per turn, in winding order, each
    measured against the layer whose fork range holds it."""
    plan = run.plan
    lx, ly = plan.step_lengths[0], plan.step_lengths[1]
    spr = plan.job.fork_steps_per_rev
    seg, x, y = winding_samples(run, d)
    out = []
    for i in (int(v) for v in np.unique(seg)):
        s = plan.segments[i]
        m = seg == i
        xr, yr = x[m] - s.start[0], y[m] - s.start[1]
        dist = (
            np.abs(s.delta[0] * yr - xr * s.delta[1]) * lx * ly / math.hypot(s.delta[0] * lx, s.delta[1] * ly)
        )
        turns = abs(s.delta[1]) // spr  # this layer's (its coil's)
        tid = np.clip(np.ceil(np.abs(yr) / spr) - 1, 0, turns - 1).astype(np.int64)
        sums, counts = np.bincount(tid, weights=dist), np.bincount(tid)
        out.append(sums[counts > 0] / counts[counts > 0])
    return np.concatenate(out) if out else np.zeros(0)


def plot_analysis(
    run: Run, analysis: Analysis, out: Path | None = None, digested: Digest | None = None
) -> list[Path]:
    """Write motion.png, tracking.png and winding.png; return their paths.
    ``digested``: the run's :func:`winder.analysis.metrics.digest_run`, if made already."""
    d = digested if digested is not None else digest_run(run)
    out = plots_dir(run.path) if out is None else Path(out)
    out.mkdir(parents=True, exist_ok=True)
    figures = ["motion", "tracking", "winding"] + (["operations"] if run.events else [])
    global _JOB
    _JOB = (run, analysis, d, out)
    try:
        return _draw_all(figures)
    finally:
        _JOB = None


#: the run the figures are drawn of, while plot_analysis draws them (the
#: worker processes it forks inherit it: nothing of it is pickled)
_JOB: tuple[Run, Analysis, Digest, Path] | None = None


def _draw(name: str) -> Path:
    assert _JOB is not None
    run, analysis, d, out = _JOB
    if name == "motion":
        return _motion(run, d, out)
    if name == "tracking":
        return _tracking(run, d, out)
    if name == "winding":
        return _winding(run, analysis, d, out)
    return _operations(run, d, out)


def _draw_all(figures: list[str]) -> list[Path]:
    """Each figure drawn in a process of its own when the machine has cores to
    spare (forked: the run is shared, not copied), else one after another.
    Drawing is matplotlib's Python code, one core per figure."""
    import multiprocessing as mp
    import os

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    if cores < 2 or "fork" not in mp.get_all_start_methods():
        return [_draw(name) for name in figures]
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(min(cores, len(figures)), mp_context=mp.get_context("fork")) as pool:
        return list(pool.map(_draw, figures))


def plot_identification(run: Run, ident: Identification, out: Path | None = None) -> list[Path]:
    """Write identify.png: the MRAS convergence of J and D per axis."""
    out = plots_dir(run.path) if out is None else Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(2, 3, figsize=(15, 7.5), sharex="col")
    fig.subplots_adjust(**MARGINS, top=0.9, hspace=0.15)
    for c, axis in enumerate(AXES):
        a = ident.axes[axis]
        for r, (key, true, ls) in enumerate((("J", a.J_true, a.ls_J), ("D", a.D_true, a.ls_D))):
            ax = axes[r, c]
            ax.axhspan(0.99, 1.01, color="0.85", label="+-1 %")
            ax.axhline(1.0, color="k", lw=0.8)
            if not a.identifiable:
                ax.text(
                    0.5,
                    0.5,
                    a.reason.replace(": ", ":\n", 1),
                    ha="center",
                    va="center",
                    transform=ax.transAxes,
                    fontsize=9,
                    wrap=True,
                )
                ax.set_ylim(0.9, 1.1)
            else:
                tr = a.trajectory
                assert tr is not None
                est = getattr(tr, key)
                ax.plot(
                    tr.t, est / true, color=CMD, lw=1.0, label=f"MRAS (gain {ident.gain:g}): {key} / recorded"
                )
                settled = a.mras_J if key == "J" else a.mras_D
                band = a.mras_J_band if key == "J" else a.mras_D_band
                t0 = float(tr.t[tr.t.size - max(1, tr.t.size // 4)]) if tr.t.size else 0.0
                ax.fill_between(
                    [t0, float(tr.t[-1]) if tr.t.size else 0.0],
                    band[0] / true,
                    band[1] / true,
                    color=CMD,
                    alpha=0.2,
                    label=f"last quarter: mean {100 * (settled / true - 1):+.2f} %, "
                    f"{100 * (band[0] / true - 1):+.1f}..{100 * (band[1] / true - 1):+.1f} %",
                )
                ax.axhline(
                    ls / true,
                    color=ACT,
                    ls="--",
                    lw=1.2,
                    label=f"least squares: {100 * (ls / true - 1):+.3f} %",
                )
                final = est[-1] / true
                lo = min(0.9, final - 0.02, ls / true - 0.02)
                hi = max(1.1, final + 0.02, ls / true + 0.02)
                ax.set_ylim(lo, hi)
                if r == 0 and a.mras_time_1pct is not None:
                    ax.axvline(
                        a.mras_time_1pct,
                        color="tab:green",
                        ls=":",
                        lw=1.0,
                        label=f"within 1 % from update {a.mras_iterations_1pct}",
                    )
                _legend(ax)
            ax.set_ylabel(f"{key} estimate / recorded {key}")
            ax.grid(True, lw=0.3)
        axes[0, c].set_title(f"{axis}: J = {a.J_true:.4g} kg m², D = {a.D_true:.4g} N m s/rad", fontsize=10)
        axes[1, c].set_xlabel("time in the run (s)")
    fig.suptitle(
        f"{ident.label}: {ident.model} model, joint states at {ident.publish_rate:g} Hz, "
        f"window {ident.window * 1e3:.3g} ms - MRAS (thesis 001 §2.4, Landau's law, extended to D) "
        "from b = 0 vs least squares",
        fontsize=10,
    )
    path = out / "identify.png"
    fig.savefig(path, dpi=100, pil_kwargs=PNG)
    plt.close(fig)
    return [path]
