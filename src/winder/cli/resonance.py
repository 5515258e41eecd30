"""``winder resonance`` and ``winder tune``: what input shaping
does to a move's residual vibration, and the fastest ramp a job's motors
allow without losing a step. Registered into the ``winder`` parser by
:func:`register`; user errors are UserErrors (BadInputErrors: one line, exit status 2), an
output that cannot be written an OutputError (exit status 5).
"""

from __future__ import annotations

import argparse
import json
import math
import os
from pathlib import Path
from typing import Any

from winder.cli.common import UserError, directory_option
from winder.cli.exits import EXIT_OK
from winder.contract.files import OutputError, atomic_file, check_writable, write_text

__all__ = ["register"]

TUNED_KEYS = ("profile", "v_max", "a_max", "j_max", "shaper", "shaper_freq", "shaper_damping")


def _margin(text: str) -> float:
    from winder.analysis.tune import MARGIN_RANGE
    from winder.spec import interval

    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and MARGIN_RANGE[0] <= value < MARGIN_RANGE[1]):
        words = interval(*MARGIN_RANGE, high_open=True)
        raise UserError(f"margin={text!r} is invalid: must be a number in {words}")
    return value


#: damping ratios ``winder resonance`` tabulates, at most (each costs some 15 s)
MAX_ZETAS = 8


def _zetas(text: str) -> list[float]:
    """Damping ratios, each in the range of the ramp's shaper_damping setting."""
    from winder.contract.params import PROFILE_SPECS
    from winder.spec import shorten

    spec = PROFILE_SPECS["shaper_damping"]
    low, high = spec.low or 0.0, spec.high or 0.0
    parts = text.split(",")
    if len(parts) > MAX_ZETAS:
        raise UserError(
            f"zetas={shorten(text)} is invalid: {len(parts)} damping ratios, at most {MAX_ZETAS} "
            "(each is simulated with every shaper and model)"
        )
    out = []
    for part in parts:
        try:
            z = float(part)
        except ValueError:
            z = math.nan
        if not (math.isfinite(z) and low <= z <= high):
            raise UserError(
                f"zetas={shorten(text)} is invalid: must be damping ratios in {spec.range_text()}, "
                "comma-separated"
            )
        out.append(z)
    return out


def cmd_resonance(args: argparse.Namespace) -> int:
    """The residual-vibration table: each shaper against none and the 1/f_n S-curve."""
    from winder.analysis.resonance import (
        ERRORS,
        METHODS,
        TestMove,
        motor_for,
        move_for,
        residual,
        residual_table,
    )
    from winder.cli.common import Progress

    zetas = _zetas(args.zetas)
    if args.json:  # the outputs are written after the table: a path that cannot be is refused first
        check_writable(args.json)
    if not args.no_plots:
        check_writable(directory_option("plots_dir", args.plots_dir), directory=True)
    models = ["linear"] if args.linear_only else ["linear", "nonlinear"]
    move = TestMove()
    bar = Progress(1, "winder resonance")
    rows = residual_table(models, zetas, METHODS, ERRORS, move, progress=lambda d, t: bar.update(d / t))
    bar.close()
    print(
        f"test move: {move.steps} steps of 2 pi/{round(2 * math.pi / move.step_angle)} rad, S-curve "
        f"v_max {move.v_max:g} steps/s, a_max {move.a_max:g} steps/s^2, j_max {move.j_max:g} steps/s^3; "
        f"the paper's motor with D set for each zeta; residual = peak-to-peak tracking error (steps) "
        f"in the {move.settle:g} s after the last step; shapers designed at f_n x (1 + error)"
    )
    head = ["model", "zeta", "method", "move s", "+ms"]
    head += [f"{e:+.0%}" for e in ERRORS] + ["cut at 0", "cut at +-10%", "lost"]
    lines = []
    for r in rows:
        at = dict(zip(ERRORS, r.residuals, strict=True))
        cut0 = r.reference / at[0.0] if at[0.0] > 0 else math.inf
        cut10 = r.reference / max(at[-0.1], at[0.1])
        lines.append(
            [r.model, f"{r.zeta:g}", r.method, f"{r.duration:.4f}", f"{1e3 * r.added:.1f}"]
            + [f"{x:.2f}" for x in r.residuals]
            + [f"{cut0:.1f}x", f"{cut10:.1f}x", str(max(r.lost))]
        )
    widths = [max(len(h), *(len(x[i]) for x in lines)) for i, h in enumerate(head)]
    print("  ".join(h.rjust(w) for h, w in zip(head, widths, strict=True)))
    for x in lines:
        print("  ".join(c.rjust(w) for c, w in zip(x, widths, strict=True)))
    if args.json:
        write_text(args.json, json.dumps([r.__dict__ for r in rows], indent=1))
        print(f"table: {args.json}")
    if not args.no_plots:
        from winder.analysis.figures.resonance import plot_ringing, plot_sensitivity

        out = Path(args.plots_dir)
        z = min(zetas)
        axis = motor_for(z)
        f_n, zeta = axis.natural_frequency / (2 * math.pi), axis.damping_ratio
        traces = {
            m: residual(axis, move_for(move, m, f_n, zeta), move, "linear")
            for m in ("none", "scurve_1/f", "zvd", "ei")
        }
        print(f"plot: {plot_ringing(traces, z, f_n, out / 'resonance_ringing.png')}")
        print(f"plot: {plot_sensitivity(f_n, zeta, out / 'resonance_shapers.png')}")
    return EXIT_OK


def _axes_from(args: argparse.Namespace, sim: dict[str, Any]) -> tuple[dict[str, Any], list[str]]:
    """The sim settings with each axis' J and D from a recording, if one is named."""
    if not args.bag:
        return sim, []
    from winder.analysis.identify import identify
    from winder.record.reader import read_run

    ident = identify(read_run(args.bag))
    out = dict(sim)
    notes = []
    for name, ax in ident.axes.items():
        if ax.identifiable and math.isfinite(ax.ls_J) and ax.ls_J > 0 and math.isfinite(ax.ls_D):
            out[f"{name}.J"], out[f"{name}.D"] = ax.ls_J, max(ax.ls_D, 0.0)
            notes.append(
                f"{name}: J {ax.ls_J:.4g} kg m^2, D {max(ax.ls_D, 0.0):.4g} N m s/rad from {args.bag}"
            )
        else:
            notes.append(f"{name}: not identifiable in {args.bag} ({ax.reason}): the job file's motor")
    return out, notes


def _writable(path: Path) -> tuple[Path, os.stat_result]:
    """The file ``path`` names (a symlink followed) and its status; UserError
    (one line) if it cannot be read or is read-only."""
    import stat

    target = path.resolve()
    try:
        st = target.stat()
    except OSError as exc:
        raise UserError(f"{path}: cannot be read: {exc.strerror or exc}") from None
    if not st.st_mode & (stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH):
        raise UserError(f"{path}: read-only (mode {stat.S_IMODE(st.st_mode):04o}): --apply does not write it")
    return target, st


def _apply(path: Path, ramp: dict[str, Any]) -> list[str]:
    """Write the tuned ramp into the job file, comments kept, atomically
    (:func:`winder.contract.files.atomic_file`), and return the sections written. The file a
    symlink names is the one written (the link stays); its mode is kept; a
    read-only file is refused. The values go where the profile node reads
    them: every section of the file that names it (``profile_node``,
    ``/cell1/profile_node``), and ``/**`` where it already holds one of them;
    with none, a ``profile_node`` section in the namespace of the file's other
    sections. UserError (one line) for a file that cannot be read,
    OutputError for one that cannot be written."""
    from ruamel.yaml import YAML
    from ruamel.yaml.error import YAMLError

    from winder.contract.jobfile import section_node

    target, _ = _writable(path)
    yaml = YAML()
    yaml.preserve_quotes = True
    try:
        doc = yaml.load(target.read_text())
    except (OSError, YAMLError) as exc:
        raise UserError(f"{path}: cannot be read: {str(exc).splitlines()[0]}") from None
    keys = [str(k) for k in doc]
    sections = [k for k in keys if section_node(k) == "profile_node"]
    shared = [
        k for k in keys if k == "/**" and any(t in doc[k].get("ros__parameters", {}) for t in TUNED_KEYS)
    ]
    if not sections:
        prefix = next((k.rsplit("/", 1)[0] + "/" for k in keys if k != "/**" and "/" in k.strip("/")), "")
        sections = [f"{prefix}profile_node"]
    for key in sections + shared:
        section = doc.setdefault(key, {}).setdefault("ros__parameters", {})
        for name in TUNED_KEYS:
            value = ramp[name]
            section[name] = float(f"{value:.6g}") if isinstance(value, float) else value
    try:
        with atomic_file(target) as fh:  # its mode and owner kept
            yaml.dump(doc, fh)
    except OutputError as exc:
        raise OutputError(f"{exc}; the file is unchanged") from None
    return sections + shared


def cmd_tune(args: argparse.Namespace) -> int:
    """The fastest ramp with zero lost steps and the torque margin (winder.analysis.tune)."""
    from winder.analysis.tune import axes_of, lost_steps, tune
    from winder.cli.common import Progress, job_file
    from winder.contract.params import PROFILE_SPECS
    from winder.motion.job import Job
    from winder.motion.timing import plan_timing

    margin = _margin(args.margin)
    if args.apply and not args.job_file:
        raise UserError("--apply needs a JOB_FILE to write the tuned ramp into")
    if args.apply:
        _writable(Path(args.job_file))  # before the tuning, not after it
    if not args.no_plots:
        check_writable(directory_option("plots_dir", args.plots_dir), directory=True)
    given = job_file(args)
    job = Job.from_dict(given["interp_node"])
    sim, notes = _axes_from(args, given["consumer"])
    axes = axes_of(sim)
    bar = Progress(1, "winder tune")
    result = tune(job, given["profile_node"], axes, margin=margin, progress=lambda d, t: bar.update(d / t))
    bar.close()
    for note in notes:
        print(f"motor: {note}")
    head = f"{'axis':6} {'J kg m^2':>10} {'D N m s/rad':>12} {'f_n Hz':>7} {'zeta':>6} {'T_m N m':>8}"
    print(f"{head} {'step rad':>9}")
    for ax in axes:
        print(
            f"{ax.name:6} {ax.motor.J:10.4g} {ax.motor.D:12.4g} {ax.f_n:7.2f} {ax.zeta:6.3f} "
            f"{ax.motor.peak_torque:8.4g} {ax.step_angle:9.3g}"
        )
    current = {n: s.default for n, s in PROFILE_SPECS.items()}
    current.update(given["profile_node"])
    print(f"\ntorque margin {margin:.0%} below pull-out; 0 lost steps in the nonlinear model required")
    print(f"{'':12} {'current':>14} {'tuned':>14}")
    for key in TUNED_KEYS:
        a, b = current.get(key), result.ramp[key]
        fa = f"{a:.6g}" if isinstance(a, float) else str(a)
        fb = f"{b:.6g}" if isinstance(b, float) else str(b)
        print(f"{key:12} {fa:>14} {fb:>14}")
    print(f"{'job time s':12} {result.current_time:14.3f} {result.job_time:14.3f}")
    print(f"{'lost steps':12} {result.current_lost:14d} {0:14d}")
    speedup = result.current_time / result.job_time
    print(f"\nthe job winds {speedup:.2f}x as fast ({len(result.checked)} candidate(s) simulated)")
    if not args.no_plots:
        from winder.analysis.figures.resonance import plot_limits_sweep

        segments = [s.steps for s in job.segments()]
        scales = [0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 2.5, 3.0, 4.0]
        times, lost = [], []
        for k in scales:
            ramp = dict(result.ramp)
            for key in ("v_max", "a_max", "j_max"):
                ramp[key] = min(ramp[key] * k, PROFILE_SPECS[key].high or math.inf)
            times.append(plan_timing(ramp, segments)[1] / 1e9)
            lost.append(lost_steps(job, ramp, axes))
        path = plot_limits_sweep(
            scales, times, lost, result.current_time, Path(args.plots_dir) / "tune_limits.png"
        )
        print(f"plot: {path}")
    if args.apply:
        written = _apply(Path(args.job_file), result.ramp)
        print(f"applied: {args.job_file} ({', '.join(written)}: {', '.join(TUNED_KEYS)})")
    return EXIT_OK


def register(sub: Any) -> None:
    p = sub.add_parser(
        "resonance", help="residual vibration of a move with each input shaper (linear and nonlinear model)"
    )
    p.add_argument("--zetas", default="0.52,0.05", help="damping ratios of the motor (default 0.52,0.05)")
    p.add_argument("--linear-only", action="store_true", help="only the linear model (fast)")
    p.add_argument("--json", default=None, metavar="FILE", help="also write the table as JSON")
    p.add_argument("--plots-dir", default="figures", help="where the PNG figures go (default ./figures)")
    p.add_argument("--no-plots", action="store_true", help="no figures")
    p.set_defaults(func=cmd_resonance)

    p = sub.add_parser("tune", help="the fastest ramp the motors allow without losing a step")
    p.add_argument("job_file", nargs="?", metavar="JOB_FILE", help="the job file (default: the default job)")
    p.add_argument(
        "--margin", default="0.3", help="torque margin below the pull-out torque, in [0, 1) (default 0.3)"
    )
    p.add_argument("--bag", default=None, help="take each axis' J and D from `winder identify` on this bag")
    p.add_argument("--apply", action="store_true", help="write the tuned ramp into JOB_FILE")
    p.add_argument("--plots-dir", default="figures", help="where the PNG figure goes (default ./figures)")
    p.add_argument("--no-plots", action="store_true", help="no figure")
    p.set_defaults(func=cmd_tune)
