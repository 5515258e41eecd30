"""``winder parts``: the part index (:mod:`winder.record.parts`, docs/PARTS.md).

``list`` (the default), ``show PART``, ``measure PART resistance_ohm=VALUE``,
``export --csv FILE``, ``capability`` (Cm and Cmk of one recipe's parts,
:mod:`winder.record.capability`) and ``chart --out FILE.png`` (their
control chart), on the index ``--db FILE`` names, else the one in
``--bag-dir`` (``bags``, as ``winder run`` finds it). Simulated parts (the
sim node's, a twin's) and real ones are never shown together unless
``--all`` asks: ``--simulated``, ``--real``; neither, the kind of the latest
part, and the other kind's count said under the table.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from winder.cli.common import UserError
from winder.cli.exits import EXIT_OK
from winder.contract.files import atomic_file, check_writable
from winder.record.capability import MIN_PARTS, READS, STUDY_PARTS, Capability, capability, series, unit_of
from winder.record.parts import COLUMNS, INDEX_NAME, PartIndex, PartIndexError, row_tolerances

__all__ = ["register"]

#: what ``measure`` takes: name -> (column, unit)
MEASURES = {"resistance_ohm": ("resistance_measured_ohm", "ohm")}
#: the run's facts ``list`` and ``export`` choose parts by (``--operator``, ``--wire-lot``: exactly)
RUN_FILTERS = ("operator", "wire_lot")
#: the parts ``list`` shows unless ``--last`` says: the latest that many (a screenful or two;
#: ``export`` writes every part)
LIST_LAST = 100
#: the table of ``list``: header, column (or how the row shows it)
LIST_COLUMNS = (
    "part",
    "started (UTC)",
    "job",
    "recipe",
    "state",
    "steps",
    "cycle s",
    "R ohm",
    "verdict",
    "why",
)


def when(ns: int | None) -> str:
    """A wall time of the index (ns since the epoch) as ISO 8601 UTC, to the millisecond."""
    if ns is None:
        return "-"
    t = datetime.fromtimestamp(ns / 1e9, UTC)
    return t.strftime("%Y-%m-%dT%H:%M:%S.") + f"{t.microsecond // 1000:03d}Z"


def since_ns(text: str) -> int:
    """``--since``: an ISO 8601 date or time (UTC unless it says its zone) as ns since the epoch."""
    try:
        t = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        raise UserError(
            f"--since {text!r} is not an ISO 8601 date or time (2026-11-29, 2026-11-29T08:00)"
        ) from None
    if t.tzinfo is None:
        t = t.replace(tzinfo=UTC)
    return int(t.timestamp() * 1e9)


def index_of(args: argparse.Namespace) -> PartIndex:
    """The index the options name; one line if there is none there."""
    path = Path(args.db).expanduser() if args.db else Path(args.bag_dir).expanduser() / INDEX_NAME
    if not path.is_file():
        where = "--db" if args.db else f"--bag-dir {args.bag_dir}"
        raise UserError(f"no part index at {path} ({where}): no run has recorded a part there")
    index = PartIndex(path)
    try:
        gone = index.recover()
    except PartIndexError as exc:  # a read-only index is still read
        print(f"winder parts: warning: killed runs not marked incomplete: {exc}", file=sys.stderr)
    else:
        if gone:
            print(
                f"winder parts: {len(gone)} part(s) of runs whose process ended without closing them "
                f"marked incomplete: {', '.join(gone)}",
                file=sys.stderr,
            )
    return index


def kind_of(args: argparse.Namespace) -> bool | None:
    return {"simulated": True, "real": False, "all": None}.get(args.kind)


def chosen(
    index: PartIndex, args: argparse.Namespace, last: int | None = None
) -> tuple[list[dict[str, Any]], str, int]:
    """The parts the filters take, oldest first (the latest ``--last``, else
    ``last``, else all), the line that says what kind was left out, and how
    many parts the filters take in all."""
    if args.last is not None and args.last < 1:
        raise UserError(f"--last {args.last} is invalid: expected a count >= 1")
    limit = args.last if args.last is not None else last
    since = since_ns(args.since) if args.since else None
    filters = {"job_id": args.job, "recipe": args.recipe, "verdict": args.verdict, "since_ns": since}
    filters.update({name: getattr(args, name, None) for name in RUN_FILTERS})
    if args.kind is not None:
        simulated = kind_of(args)
        rows = index.parts(simulated=simulated, limit=limit, **filters)
        return rows, "", len(rows) if limit is None else index.count(simulated=simulated, **filters)
    latest = index.parts(limit=1, columns=("simulated",), **filters)
    if not latest:
        return [], "", 0
    simulated = bool(latest[0]["simulated"])
    rows = index.parts(simulated=simulated, limit=limit, **filters)
    total = len(rows) if limit is None else index.count(simulated=simulated, **filters)
    others = index.count(simulated=not simulated, **filters)
    other = "real" if simulated else "simulated"
    note = f"{others} {other} part(s) not shown: --{other}, or --all" if others else ""
    return rows, note, total


def _num(value: float | None, digits: int = 4) -> str:
    return "-" if value is None else f"{value:.{digits}g}"


def table(rows: list[dict[str, Any]]) -> str:
    body = []
    for r in rows:
        reasons = json.loads(r["reasons"]) if r["reasons"] else []
        measured = r["resistance_measured_ohm"]
        resistance = (
            _num(measured) + " (measured)" if measured is not None else _num(r["resistance_predicted_ohm"])
        )
        body.append(
            [
                r["part_id"],
                when(r["started_ns"])[:19],
                r["job_id"],
                r["recipe_sha256"][:12],
                r["state"],
                f"{r['steps_done']}/{r['steps_total']}",
                _num(r["cycle_time_s"]),
                resistance,
                r["verdict"] or "-",
                (reasons[0] + (f" (+{len(reasons) - 1})" if len(reasons) > 1 else "")) if reasons else "",
            ]
        )
    header = list(LIST_COLUMNS)
    widths = [max(len(str(x[i])) for x in [header, *body]) for i in range(len(header))]
    lines = ["  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)).rstrip()]
    lines.append("  ".join("-" * w for w in widths))
    lines += ["  ".join(str(v).ljust(w) for v, w in zip(x, widths, strict=True)).rstrip() for x in body]
    return "\n".join(lines)


def as_json(row: dict[str, Any]) -> dict[str, Any]:
    """A row with its JSON columns read and its times in ISO 8601 beside their ns."""
    out = dict(row)
    for key in ("reasons", "tolerances", "report"):
        out[key] = json.loads(row[key]) if row[key] else None
    out["simulated"] = bool(row["simulated"])
    out["started"], out["ended"] = (
        when(row["started_ns"]),
        (when(row["ended_ns"]) if row["ended_ns"] else None),
    )
    return out


def cmd_list(args: argparse.Namespace) -> int:
    index = index_of(args)
    rows, note, total = chosen(index, args, LIST_LAST)
    more = (
        f"the latest {len(rows)} of {total} part(s) shown: --last N for more, winder parts export for all"
        if total > len(rows)
        else ""
    )
    if args.json:
        if more:
            print(f"winder parts: {more}", file=sys.stderr)
        print(json.dumps([as_json(r) for r in rows], indent=1))
        return EXIT_OK
    if args.kind == "all":
        shown = " (simulated and real)"
    else:
        shown = "" if not rows else (" simulated" if rows[0]["simulated"] else " real")
    print(f"part index {index.path}: {total}{shown} part(s)")
    if rows:
        print(table(rows))
    for line in (more, note):
        if line:
            print(line)
    return EXIT_OK


def the_part(index: PartIndex, part_id: str) -> dict[str, Any]:
    row = index.get(part_id)
    if row is None:
        raise UserError(f"no part {part_id!r} in {index.path} (winder parts list names them)")
    return row


def cmd_show(args: argparse.Namespace) -> int:
    index = index_of(args)
    row = the_part(index, args.part)
    if args.json:
        print(json.dumps(as_json(row), indent=1))
        return EXIT_OK
    shown = as_json(row)
    wide = max(len(name) for name, _, _ in COLUMNS)
    for name, _, _ in COLUMNS:
        value = row[name]
        if name in ("started_ns", "ended_ns"):
            text = f"{when(value)}  ({value})" if value is not None else "-"
        elif name == "simulated":
            text = "yes" if value else "no"
        elif name == "reasons":
            text = "\n".join(f"{'':<{wide}}  - {r}" for r in shown["reasons"] or []).strip() or "-"
        elif name == "report":
            report = shown["report"] or {}
            text = "\n".join(f"{'':<{wide}}  {k}: {v}" for k, v in report.items()).strip() or "-"
        else:
            text = "-" if value is None or value == "" else str(value)
        print(f"{name:<{wide}}  {text}")
    return EXIT_OK


def cmd_measure(args: argparse.Namespace) -> int:
    key, sep, text = args.value.partition("=")
    if not sep or key not in MEASURES:
        raise UserError(f"measure {args.value!r}: expected NAME=VALUE with NAME one of {', '.join(MEASURES)}")
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or value <= 0:
        raise UserError(f"{key}={text} is invalid: expected a finite number > 0 ({MEASURES[key][1]})")
    index = index_of(args)
    the_part(index, args.part)
    row = index.measure(args.part, value)
    reasons = json.loads(row["reasons"]) if row["reasons"] else []
    print(
        f"part {args.part}: {key} {value:g} {MEASURES[key][1]} entered; verdict {row['verdict'] or '-'}"
        + (f": {'; '.join(reasons)}" if reasons else "")
    )
    return EXIT_OK


def cmd_export(args: argparse.Namespace) -> int:
    if not args.csv:
        raise UserError("export: --csv FILE is required")
    index = index_of(args)
    rows, note, _ = chosen(index, args)
    names = [name for name, _, _ in COLUMNS]
    with atomic_file(args.csv, newline="") as fh:
        out = csv.writer(fh)
        out.writerow([*names, "started", "ended"])
        for r in rows:
            out.writerow(
                [*("" if r[n] is None else r[n] for n in names), when(r["started_ns"]), when(r["ended_ns"])]
            )
    print(f"{len(rows)} part(s) written to {args.csv}" + (f"; {note}" if note else ""))
    return EXIT_OK


@dataclass(frozen=True)
class Study:
    """The parts a capability or a chart is taken over: the latest completed
    parts of one recipe, oldest first, of one kind unless ``--all`` asked."""

    recipe: str
    jobs: list[str]
    simulated: bool | None
    rows: list[dict[str, Any]]
    left_out: int  #: runs of the recipe among them that did not complete
    note: str  #: the other kind's parts of the recipe, not taken

    def kind(self) -> str:
        return {True: "simulated", False: "real", None: "simulated and real"}[self.simulated]

    def head(self) -> str:
        """One line: the recipe, its job, how many parts of which kind, from when to when."""
        first, last = self.rows[0], self.rows[-1]
        jobs = ", ".join(self.jobs)
        text = (
            f"recipe {self.recipe[:12]} (job {jobs}): the latest {len(self.rows)} completed {self.kind()} "
            f"part(s), {first['part_id']} to {last['part_id']} "
            f"({when(first['started_ns'])[:16]} to {when(last['started_ns'])[:16]} UTC)"
        )
        if self.left_out:
            text += f"; {self.left_out} run(s) among them not completed, left out"
        return text


def _kind_word(simulated: bool | None) -> str:
    return {True: "simulated ", False: "real ", None: ""}[simulated]


def study(index: PartIndex, args: argparse.Namespace, *, least: int, what: str) -> Study:
    """The parts ``capability`` and ``chart`` take (:class:`Study`): the
    filters of ``list`` but ``--verdict`` (choosing parts by their verdict
    would make any machine capable); one line, exit 2, when they hold more
    than one recipe, or fewer than ``least`` completed parts."""
    if args.verdict is not None:
        raise UserError(
            f"--verdict {args.verdict} cannot choose the parts of a {what}: it takes every completed part "
            "of the recipe, ok or nok, as they were wound"
        )
    for name in RUN_FILTERS:
        if getattr(args, name, None) is not None:
            flag = "--" + name.replace("_", "-")
            raise UserError(
                f"{flag} {getattr(args, name)} cannot choose the parts of a {what}: it takes the "
                "consecutive completed parts of the recipe, whoever wound them with whichever wire "
                "(winder parts list and export take it)"
            )
    if args.last is not None and args.last < least:
        raise UserError(f"--last {args.last} is invalid: a {what} takes at least {least} parts")
    since = since_ns(args.since) if args.since else None
    filters: dict[str, Any] = {"job_id": args.job, "recipe": args.recipe, "since_ns": since}
    if args.kind is not None:
        simulated = kind_of(args)
    else:
        latest = index.parts(limit=1, columns=("simulated",), **filters)
        simulated = bool(latest[0]["simulated"]) if latest else None
    recipes = index.recipes(simulated=simulated, **filters)
    if not recipes:
        given = [
            f"--{k} {v}" for k, v in (("job", args.job), ("recipe", args.recipe), ("since", args.since)) if v
        ]
        raise UserError(
            f"no {_kind_word(simulated)}parts in {index.path} for {' '.join(given) or 'these options'}"
        )
    if len(recipes) > 1:
        named = ", ".join(f"{sha[:12]} ({'/'.join(jobs)}, {n} parts)" for sha, n, jobs in recipes[:5])
        more = f" and {len(recipes) - 5} more" if len(recipes) > 5 else ""
        raise UserError(
            f"the parts chosen hold {len(recipes)} recipes: {named}{more}: "
            f"name one with --recipe SHA256 (a prefix will do), or --job"
        )
    sha, _, jobs = recipes[0]
    filters["recipe"] = sha
    columns = (*READS, "part_id", "started_ns", "verdict", "tolerances")
    last = args.last if args.last is not None else STUDY_PARTS
    rows = index.parts(simulated=simulated, state="done", limit=last, columns=columns, **filters)
    if len(rows) < least:
        raise UserError(
            f"a {what} needs at least {least} completed parts of one recipe: recipe {sha[:12]} "
            f"(job {', '.join(jobs)}) has {len(rows)} {_kind_word(simulated)}part(s) for these options"
        )
    window = {**filters, "since_ns": rows[0]["started_ns"]}
    done = index.count(simulated=simulated, state="done", **window)
    left_out = index.count(simulated=simulated, **window) - done
    note = ""
    if args.kind is None:
        others = index.count(simulated=not simulated, **filters)
        other = "real" if simulated else "simulated"
        note = f"{others} {other} part(s) of this recipe not taken: --{other}, or --all" if others else ""
    return Study(sha, jobs, simulated, rows, left_out, note)


def figures(chosen: Study, names: list[str] | None) -> list[tuple[Capability, list[float | None]]]:
    """Each scalar's figures and values over the study's parts: the named ones
    (``--scalar``), else the recipe's tolerances' (in its order), then every
    other recorded scalar by name."""
    values = series(chosen.rows)
    tolerances = row_tolerances(chosen.rows[-1])
    if names:
        unknown = [n for n in names if n not in values and n not in tolerances]
        if unknown:
            raise UserError(
                f"--scalar {unknown[0]} is not recorded by these parts: "
                f"expected one of {', '.join(sorted(values))}"
            )
        order = list(dict.fromkeys(names))
    else:
        order = [*tolerances, *sorted(n for n in values if n not in tolerances)]
    out = []
    for name in order:
        column = values.get(name, [None] * len(chosen.rows))
        lsl, usl = tolerances.get(name, (None, None))
        out.append((capability(name, [v for v in column if v is not None], lsl, usl), column))
    return out


def _fig(value: float | None, form: str = ".6g") -> str:
    return "-" if value is None else format(value, form)


def cmd_capability(args: argparse.Namespace) -> int:
    index = index_of(args)
    chosen = study(index, args, least=MIN_PARTS, what="capability")
    found = figures(chosen, args.scalar)
    if args.json:
        doc = {
            "index": str(index.path),
            "recipe": chosen.recipe,
            "jobs": chosen.jobs,
            "simulated": chosen.simulated,
            "parts": len(chosen.rows),
            "first_part": chosen.rows[0]["part_id"],
            "last_part": chosen.rows[-1]["part_id"],
            "left_out": chosen.left_out,
            "not_taken": chosen.note,
            "scalars": {c.name: c.to_json() for c, _ in found},
        }
        print(json.dumps(doc, indent=1))
        return EXIT_OK
    print(chosen.head())
    parts = len(chosen.rows)
    still = [
        c
        for c, _ in found
        if not args.scalar and c.lsl is None and c.usl is None and c.sd == 0.0 and c.n == parts
    ]
    shown = [c for c, _ in found if c not in still]
    header = ["scalar", "n", "mean", "sd", "LSL", "USL", "Cm", "Cmk", ""]
    body = [
        [
            c.name,
            str(c.n),
            _fig(c.mean),
            _fig(c.sd, ".4g"),
            _fig(c.lsl),
            _fig(c.usl),
            _fig(c.cm, ".2f"),
            _fig(c.cmk, ".2f"),
            c.note,
        ]
        for c in shown
    ]
    widths = [max(len(row[i]) for row in [header, *body]) for i in range(len(header))]
    for row in [header, ["-" * w for w in widths[:-1]] + [""], *body]:
        cells = [
            v.ljust(w) if i in (0, 8) else v.rjust(w)
            for i, (v, w) in enumerate(zip(row, widths, strict=True))
        ]
        print("  ".join(cells).rstrip())
    if still:
        print("the same in every part, no tolerance: " + ", ".join(f"{c.name} {_fig(c.mean)}" for c in still))
    print("Cm = (USL - LSL) / 6 s, Cmk = min(USL - mean, mean - LSL) / 3 s; s: the sample standard deviation")
    if chosen.note:
        print(chosen.note)
    return EXIT_OK


def cmd_chart(args: argparse.Namespace) -> int:
    if not args.out:
        raise UserError("chart: --out FILE.png is required")
    out = check_writable(Path(args.out).expanduser())
    index = index_of(args)
    chosen = study(index, args, least=2, what="chart")
    if not args.scalar and not row_tolerances(chosen.rows[-1]):
        recorded = ", ".join(sorted(series(chosen.rows)))
        raise UserError(
            f"recipe {chosen.recipe[:12]} has no tolerances to chart: name the scalars with --scalar "
            f"(recorded: {recorded})"
        )
    named = [
        (c, v)
        for c, v in figures(chosen, args.scalar)
        if args.scalar or c.lsl is not None or c.usl is not None
    ]
    found = [(c, v) for c, v in named if c.n]
    unrecorded = [c.name for c, _ in named if not c.n]
    if not found:
        raise UserError(f"no part of these recorded {', '.join(unrecorded)}: nothing to chart")
    nok = [r["verdict"] == "nok" for r in chosen.rows]
    from winder.analysis.figures.parts import ChartSeries, plot_control_chart  # matplotlib: only here

    charts = [ChartSeries(values, nok, c, unit_of(c.name)) for c, values in found]
    title = (
        f"recipe {chosen.recipe[:12]} (job {', '.join(chosen.jobs)}): {len(chosen.rows)} "
        f"{chosen.kind()} parts, {when(chosen.rows[0]['started_ns'])[:16].replace('T', ' ')} to "
        f"{when(chosen.rows[-1]['started_ns'])[:16].replace('T', ' ')} UTC"
    )
    plot_control_chart(charts, title, out)
    print(f"{chosen.head()}\ncontrol chart of {len(charts)} scalar(s) written to {out}")
    if unrecorded:
        print(f"not charted, recorded by none of these parts: {', '.join(unrecorded)}")
    if chosen.note:
        print(chosen.note)
    return EXIT_OK


def _options(p: argparse.ArgumentParser, *, default: Any) -> None:
    """The options every action takes; ``default``: argparse.SUPPRESS on an
    action's parser, so that one given before the action is not undone."""

    def d(value: Any) -> Any:
        return default if default is argparse.SUPPRESS else value

    p.add_argument(
        "--db", default=d(None), metavar="FILE", help="the part index file (default: BAG_DIR/parts.sqlite)"
    )
    p.add_argument(
        "--bag-dir",
        default=d("bags"),
        metavar="DIR",
        help="the bag directory whose index is read (default: bags)",
    )
    kind = p.add_mutually_exclusive_group()
    for name, what in (
        ("simulated", "only simulated parts (the sim node's, a twin's)"),
        ("real", "only parts of real axes"),
        ("all", "simulated and real parts together"),
    ):
        kind.add_argument(
            f"--{name}", dest="kind", action="store_const", const=name, default=d(None), help=what
        )
    p.add_argument("--job", default=d(None), help="only this job id's parts")
    p.add_argument(
        "--recipe",
        default=d(None),
        metavar="SHA256",
        help="only this recipe's parts (a prefix of its sha256)",
    )
    p.add_argument("--verdict", default=d(None), choices=("ok", "nok"), help="only parts of this verdict")
    for name in RUN_FILTERS:
        p.add_argument(
            "--" + name.replace("_", "-"),
            default=d(None),
            metavar="TEXT",
            help=f"only parts whose run gave this {name.replace('_', ' ')} (list, export)",
        )
    p.add_argument(
        "--since", default=d(None), metavar="TIME", help="only parts started since (ISO 8601, UTC)"
    )
    p.add_argument(
        "--last",
        default=d(None),
        type=int,
        metavar="N",
        help=f"only the latest N parts (list: {LIST_LAST} unless given; capability and chart: "
        f"{STUDY_PARTS} completed parts; export: all)",
    )
    p.add_argument("--json", default=d(False), action="store_true", help="print JSON instead of the table")


def register(sub: argparse._SubParsersAction[Any]) -> None:
    """Add ``parts`` to the ``winder`` subcommands."""
    p = sub.add_parser(
        "parts",
        help="the part index: a row per wound part, its recipe, its record and its verdict",
        description="Read the part index each run adds its part to when its consumer's parts_db names one "
        "(winder run --parts-db auto; docs/PARTS.md). Simulated and real "
        "parts are never shown together unless --all asks.",
    )
    _options(p, default=None)
    p.set_defaults(func=cmd_list)
    actions = p.add_subparsers(dest="action", metavar="ACTION", parser_class=type(p))
    a = actions.add_parser("list", help="the parts, a table (the default)")
    _options(a, default=argparse.SUPPRESS)
    a.set_defaults(func=cmd_list)
    a = actions.add_parser("show", help="every field of one part, its verdict's reasons, its bag")
    a.add_argument("part", metavar="PART", help="the part's id (winder parts list)")
    _options(a, default=argparse.SUPPRESS)
    a.set_defaults(func=cmd_show)
    a = actions.add_parser("measure", help="enter a part's measured resistance: its verdict is taken again")
    a.add_argument("part", metavar="PART", help="the part's id")
    a.add_argument("value", metavar="resistance_ohm=VALUE", help="the measured resistance at 20 C (ohm)")
    _options(a, default=argparse.SUPPRESS)
    a.set_defaults(func=cmd_measure)
    a = actions.add_parser("export", help="the parts as a CSV file, a column per field")
    a.add_argument("--csv", default=None, metavar="FILE", help="the CSV file to write")
    _options(a, default=argparse.SUPPRESS)
    a.set_defaults(func=cmd_export)
    a = actions.add_parser(
        "capability",
        help="Cm and Cmk of each scalar over the latest completed parts of one recipe (ISO 22514-3)",
        description="Machine capability over the latest completed parts of one recipe "
        f"(at least {MIN_PARTS}; --last N takes the latest N, --since a start): per scalar n, mean, sd, "
        "the tolerance's limits, Cm and Cmk (docs/PARTS.md).",
    )
    _scalar_option(a)
    _options(a, default=argparse.SUPPRESS)
    a.set_defaults(func=cmd_capability)
    a = actions.add_parser(
        "chart",
        help="a control chart (PNG) of each scalar over the latest completed parts of one recipe",
        description="A control chart per scalar of one recipe's completed parts: each part's value, "
        "the mean, mean ± 3 s, the tolerance band, the nok parts marked (docs/PARTS.md).",
    )
    a.add_argument("--out", default=None, metavar="FILE.png", help="the PNG file to write")
    _scalar_option(a)
    _options(a, default=argparse.SUPPRESS)
    a.set_defaults(func=cmd_chart)


def _scalar_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--scalar",
        action="append",
        default=None,
        metavar="NAME",
        help="only this scalar (again for more; default: capability every recorded scalar, the chart "
        "those of the recipe's tolerances)",
    )
