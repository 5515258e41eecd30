"""``winder analyze``, ``winder identify`` and ``winder bag recover``: the
commands that read recordings back. Registered into the ``winder``
parser by :func:`register`; errors are BadInputErrors (a BadBagError for a
recording that cannot be used, :mod:`winder.errors`), which ``winder``'s main
prints as one line with exit status 2.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from winder.cli.common import UserError, directory_option
from winder.cli.exits import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK
from winder.contract.states import FINAL_JOB_STATES
from winder.errors import BadBagError, BadInputError

__all__ = ["register"]


def _os_error(exc: OSError) -> str:
    why = exc.strerror or str(exc)
    return f"{exc.filename}: {why}" if exc.filename else why


def _plots_dir(args: argparse.Namespace) -> Path | None:
    """``--plots-dir`` checked before any recording is read (None: each bag's own ``plots``)."""
    return None if args.plots_dir is None else directory_option("plots_dir", args.plots_dir)


def _plots_for(bag: Path, plots_dir: Path | None, several: bool) -> Path | None:
    if plots_dir is None:
        return None
    return plots_dir / bag.name if several else plots_dir


def _say(lines: list[str], to_stderr: bool) -> None:
    for line in lines:
        print(line, file=sys.stderr if to_stderr else sys.stdout)


def cmd_analyze(args: argparse.Namespace) -> int:
    """Winding accuracy and motion quality of one or more recordings, as one table."""
    from winder.analysis.metrics import analyze, digest_run, format_table, to_json
    from winder.record.reader import read_run

    plots_dir = _plots_dir(args)
    try:
        runs = [read_run(b, args.namespace) for b in args.bags]
        digests = [digest_run(r) for r in runs]
        results = [analyze(r, digested=d) for r, d in zip(runs, digests, strict=True)]
        print(to_json(results) if args.json else format_table(results))
        if not args.no_plots:
            from winder.analysis.figures.analysis import FigureError, plot_analysis

            written: list[str] = []
            failed: list[str] = []
            for run, res, d in zip(runs, results, digests, strict=True):
                out = _plots_for(run.path, plots_dir, len(runs) > 1)
                try:
                    paths = plot_analysis(run, res, out, digested=d)
                except FigureError as exc:
                    paths, failed = exc.drawn, failed + [f"{run.path.name}: {f}" for f in exc.failed]
                written += [f"plot: {p}" for p in paths]
            _say(written, args.json)
            if failed:  # a bug in winder: said in one line, the rest of the output stands
                print(f"winder analyze: a figure could not be drawn: {'; '.join(failed)}", file=sys.stderr)
                return EXIT_FAILED
    except OSError as exc:
        raise UserError(_os_error(exc)) from None
    return EXIT_OK


def cmd_identify(args: argparse.Namespace) -> int:
    """J and D of every axis by MRAS and least squares, against the recorded values."""
    from winder.analysis.identify import IDENTIFY_SPECS, format_identification, identification_json, identify
    from winder.record.reader import read_run

    # every number and name checked before a recording is read
    gain = IDENTIFY_SPECS["gain"].parse(args.gain)
    window = IDENTIFY_SPECS["window"].parse(args.window) / 1e3
    plots_dir = _plots_dir(args)
    try:
        runs = [read_run(bag, args.namespace) for bag in args.bags]  # every bag readable, or none is done
        idents = [identify(run, gain=gain, window=window) for run in runs]
        if args.json:
            print(identification_json(idents))
        else:
            print("\n\n".join(format_identification(ident) for ident in idents))
        if not args.no_plots:
            from winder.analysis.figures.analysis import plot_identification

            for run, ident in zip(runs, idents, strict=True):
                out = _plots_for(run.path, plots_dir, len(runs) > 1)
                _say([f"plot: {p}" for p in plot_identification(run, ident, out)], args.json)
    except OSError as exc:
        raise UserError(_os_error(exc)) from None
    return EXIT_OK


#: the job states a consumer's final report ends a run with
FINAL_STATES = FINAL_JOB_STATES


def _run_told(path: str) -> tuple[str, bool | None, int]:
    """What a recording holds of its winder run, in words, whether the run's
    final report is in it (None: not a winder run, nothing to tell), and the
    wall-clock time (ns) the simulated job started at (0 if unknown)."""
    from winder.record.reader import read_run

    try:
        run = read_run(path)
    except BadInputError:  # not a winder bag, or several cells: only its messages are told
        return "", None, 0
    state = run.report.get("state", "")
    final = state in FINAL_STATES
    told = f"run {run.run_id or run.job_id}: {run.steps_recorded} of {run.plan.total_steps} steps recorded, "
    wall0 = run.sim_config.wall_start_ns if run.sim_config is not None else 0
    return told + (f"final report: {state}" if final else "no final report"), final, wall0


def _log_time(t_ns: int) -> str:
    """A bag's log time (ns since the Unix epoch) as a UTC date."""
    import datetime

    when = datetime.datetime.fromtimestamp(t_ns / 1e9, tz=datetime.timezone.utc)
    return when.strftime("%Y-%m-%d %H:%M:%S.%f")[:-3] + " UTC"


def _recovered_up_to(last_ns: int, wall0_ns: int) -> str:
    """How far a recovered recording goes, in words. A winder bag's log time is
    the wall-clock time the job started plus the simulated time since then
    (the sim node's docstring): told as that simulated time, and as the date
    the log time stands for; without the job's start, only the date."""
    if wall0_ns > 0 and last_ns >= wall0_ns:
        return (
            f"up to t = {(last_ns - wall0_ns) / 1e9:.3f} s of simulated time since the job's start "
            f"(log time {_log_time(last_ns)}: the job's wall-clock start plus simulated time)"
        )
    return f"up to log time {_log_time(last_ns)}"


def cmd_bag_recover(args: argparse.Namespace) -> int:
    """Write the readable part of a cut-short or damaged recording as a closed
    bag, and say what it holds and why it is incomplete. Complete means: the
    file whole, no damaged chunk, and (a winder run) the run's final report."""
    from winder.record.bag import being_written
    from winder.record.reader import read_raw, recover

    output = None if args.output is None else directory_option("output", args.output)
    try:
        raw = read_raw(args.bag)
        if being_written(raw.path):
            raise BadBagError(
                f"{raw.path}: still being recorded (its writer holds it): recover it once its writer "
                "has ended"
            )
        told, final, wall0 = _run_told(args.bag)
        total = sum(raw.counts.values())
        if raw.closed and not raw.recovered and not raw.damaged:
            if final is False:
                print(
                    f"{raw.path}: incomplete: the file is whole ({total} messages), but {told}: "
                    "the recording ended before the run did; nothing more to recover"
                )
            else:
                what = f"{total} messages" + (f"; {told}" if told else "")
                print(f"{raw.path}: the file is whole ({what}): nothing to recover")
            return EXIT_OK
        out, saved = recover(args.bag, output)
    except OSError as exc:
        raise UserError(_os_error(exc)) from None
    last = max((t for _, t, _ in raw.messages), default=0)
    for note in raw.notes:
        print(f"note: {note}")
    for damage in raw.damaged:
        print(f"damaged: {damage}")
    print(
        f"recovered {saved} messages on {len(raw.topics())} topics, {_recovered_up_to(last, wall0)}, "
        f"into {out}"
    )
    why = []
    if raw.recovered or not raw.closed:
        why.append("the file was cut short")
    if raw.damaged:
        why.append(f"{len(raw.damaged)} damaged chunk(s) skipped")
    if told:
        why.append(told)
    print(f"incomplete: {'; '.join(why)}")
    return EXIT_OK


def cmd_export(args: argparse.Namespace) -> int:
    """A recording as CSV files (winder.analysis.export)."""
    from winder.analysis.export import export_csv
    from winder.record.reader import read_run

    csv = None if args.csv is None else directory_option("csv", args.csv)
    try:
        run = read_run(args.bag, args.namespace)
        if run.damaged:
            raise BadBagError(
                f"{run.path}: damaged recording: {len(run.damaged)} chunk(s) skipped (first: "
                f"{run.damaged[0]}); exported rows would hide the gap, so nothing is written"
            )
        if run.recovered:
            raise BadBagError(
                f"{run.path}: the recording was cut short; `winder bag recover {run.path}` writes its "
                "whole messages as a complete bag, which exports"
            )
        out = csv if csv is not None else Path(f"{run.path}_csv")
        rows = export_csv(run, out)
    except OSError as exc:
        raise UserError(_os_error(exc)) from None
    for name, n in rows.items():
        print(f"{out / name}  {n} row{'' if n == 1 else 's'}")
    print(f"{out / 'run.json'}  job, motors, ramp, final report")
    return EXIT_OK


def _bag_help(parser: argparse.ArgumentParser) -> int:
    parser.print_help()
    return EXIT_BAD_INPUT


def register(sub: argparse._SubParsersAction[Any]) -> None:
    """Add ``analyze``, ``identify`` and ``bag`` to the ``winder`` subcommands."""
    p = sub.add_parser(
        "analyze",
        help="winding accuracy (eq. 7) and motion quality of recorded runs",
        description="Read winder recordings (bag directories or .mcap files) and print one table: "
        "winding accuracy, peak velocity/acceleration/jerk, tracking error, lost steps.",
    )
    p.add_argument("bags", nargs="+", metavar="BAG", help="bag directory or .mcap file (several: compared)")
    p.add_argument("--json", action="store_true", help="print JSON instead of the table")
    p.add_argument("--no-plots", action="store_true", help="do not write the PNG figures")
    p.add_argument("--plots-dir", default=None, help="where the figures go (default: BAG/plots)")
    p.add_argument("--namespace", default=None, help="the cell's ROS namespace, if the bag holds several")
    p.set_defaults(func=cmd_analyze)

    p = sub.add_parser(
        "identify",
        help="identify each axis' inertia J and damping D (MRAS and least squares)",
        description="Estimate J and D of every axis from a recording and compare them with the values "
        "the simulation used. Record with --publish-rate 2000 for 0.1 % accuracy (200 Hz: about 2 %).",
    )
    p.add_argument(
        "bags", nargs="+", metavar="BAG", help="bag directory or .mcap file (several: one after another)"
    )
    p.add_argument("--gain", default="3", help="MRAS adaptation gain beta, dimensionless (default 3)")
    p.add_argument("--window", default="5", help="equation window in ms (default 5; at least one sample)")
    p.add_argument("--json", action="store_true", help="print JSON instead of the table")
    p.add_argument("--no-plots", action="store_true", help="do not write the convergence figure")
    p.add_argument("--plots-dir", default=None, help="where the figure goes (default: BAG/plots)")
    p.add_argument("--namespace", default=None, help="the cell's ROS namespace, if the bag holds several")
    p.set_defaults(func=cmd_identify)

    p = sub.add_parser(
        "export",
        help="a recording as CSV files (joint states, commands, step times, events) for spreadsheets, MATLAB",
        description="Write a winder recording as CSV files, one per stream, with a header row naming "
        "each column and its unit, plus run.json (job, motors, ramp, final report). Times are seconds "
        "of simulated time since the job's start; step times also in exact ns.",
    )
    p.add_argument("bag", metavar="BAG", help="bag directory or .mcap file")
    p.add_argument(
        "--csv", metavar="DIR", default=None, help="new directory for the files (default: BAG_csv)"
    )
    p.add_argument("--namespace", default=None, help="the cell's ROS namespace, if the bag holds several")
    p.set_defaults(func=cmd_export)

    p = sub.add_parser("bag", help="bag tools: recover a recording cut short")
    bag_sub = p.add_subparsers(dest="bag_command", metavar="BAG_COMMAND", parser_class=type(p))
    p.set_defaults(func=lambda _args, _p=p: _bag_help(_p))
    r = bag_sub.add_parser(
        "recover",
        help="write the whole messages of a cut-short recording as a complete bag",
        description="Read a recording whose MCAP file was cut short (no summary and footer: its "
        "writer was SIGKILLed, crashed or lost its power, or its disk filled; its metadata.yaml, if "
        "any, still says winder_bag: recording) up to its first incomplete record and write every "
        "whole message into a new, closed rosbag2 directory BAG_recovered, which ros2 bag, Foxglove "
        "and rosbags open. A bag closed at SIGINT or SIGTERM needs none of this.",
    )
    r.add_argument("bag", metavar="BAG", help="bag directory or .mcap file")
    r.add_argument("--output", default=None, help="the new bag directory (default: BAG_recovered)")
    r.set_defaults(func=cmd_bag_recover)
