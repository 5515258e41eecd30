"""``winder parts``: the part index (:mod:`winder.record.parts`, docs/PARTS.md).

``list`` (the default), ``show PART``, ``measure PART resistance_ohm=VALUE``
and ``export --csv FILE``, on the index ``--db FILE`` names, else the one in
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
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from winder.cli.common import UserError
from winder.cli.exits import EXIT_OK
from winder.contract.files import atomic_file
from winder.record.parts import COLUMNS, INDEX_NAME, PartIndex, PartIndexError

__all__ = ["register"]

#: what ``measure`` takes: name -> (column, unit)
MEASURES = {"resistance_ohm": ("resistance_measured_ohm", "ohm")}
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


def chosen(index: PartIndex, args: argparse.Namespace) -> tuple[list[dict[str, Any]], str]:
    """The parts the filters take, oldest first, and the line that says what was left out."""
    if args.last is not None and args.last < 1:
        raise UserError(f"--last {args.last} is invalid: expected a count >= 1")
    since = since_ns(args.since) if args.since else None
    filters = {"job_id": args.job, "recipe": args.recipe, "verdict": args.verdict, "since_ns": since}
    if args.kind is not None:
        return index.parts(simulated=kind_of(args), limit=args.last, **filters), ""
    latest = index.parts(limit=1, **filters)
    if not latest:
        return [], ""
    simulated = bool(latest[0]["simulated"])
    rows = index.parts(simulated=simulated, limit=args.last, **filters)
    others = len(index.parts(simulated=not simulated, **filters))
    other = "real" if simulated else "simulated"
    note = f"{others} {other} part(s) not shown: --{other}, or --all" if others else ""
    return rows, note


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
    rows, note = chosen(index, args)
    if args.json:
        print(json.dumps([as_json(r) for r in rows], indent=1))
        return EXIT_OK
    if args.kind == "all":
        shown = " (simulated and real)"
    else:
        shown = "" if not rows else (" simulated" if rows[0]["simulated"] else " real")
    print(f"part index {index.path}: {len(rows)}{shown} part(s)")
    if rows:
        print(table(rows))
    if note:
        print(note)
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
    rows, note = chosen(index, args)
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
    p.add_argument(
        "--since", default=d(None), metavar="TIME", help="only parts started since (ISO 8601, UTC)"
    )
    p.add_argument("--last", default=d(None), type=int, metavar="N", help="only the latest N parts")
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
