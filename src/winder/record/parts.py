"""The part index: one row per wound part, in an SQLite file beside the bags.

Every run of a consumer is a part (docs/PARTS.md). Its row is written
``running`` when the run starts (:meth:`PartIndex.begin`) and completed when
the run closes (:meth:`PartIndex.close`), each in one transaction, so the
index never holds a half-written part. A process killed during its run
leaves its row ``running``: the next :meth:`PartIndex.recover` (a consumer's
start, ``winder parts``) marks it ``incomplete``, verdict ``nok``, once it
knows the process is gone (its pid on this host no longer the process that
wrote it), never a row of a run still going in another process or host.

The file is SQLite (the standard library's ``sqlite3``): WAL mode, so
readers never block the writer; a busy timeout, so several cells writing one
index wait for each other instead of failing; the schema's version in
``PRAGMA user_version``, brought up to :data:`SCHEMA_VERSION` by the
functions of :data:`MIGRATIONS` in one transaction. An index of a newer
winder is refused, never written. An index this process may not write is
still read (read-only). Every failure is a :class:`PartIndexError`, one line
naming the file. A :class:`PartIndex` that has written keeps a connection
open (:meth:`PartIndex._hold`), so that a write is not followed by a
checkpoint of the whole WAL.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import random
import re
import socket
import sqlite3
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from winder.contract.stream import JobPlan
from winder.errors import BadInputError, OutputError
from winder.motion.tolerances import NOK, Tolerances, parse_tolerances, verdict

__all__ = [
    "COLUMNS",
    "FROM_REPORT",
    "INDEX_NAME",
    "MIGRATIONS",
    "SCHEMA_VERSION",
    "PartEnd",
    "PartIndex",
    "PartIndexError",
    "PartStart",
    "index_path",
    "part_scalars",
    "part_start",
    "recipe_sha256",
    "report_numbers",
    "row_tolerances",
]

#: the index's file name in a bag directory
INDEX_NAME = "parts.sqlite"
#: how long a write waits for another process' write to end (ms)
BUSY_TIMEOUT_MS = 30_000

#: the columns a final report's key fills under another name: column -> report key
FROM_REPORT = {"wire_length_m": "wire_taken_m", "tension_max_n": "tension_peak_n"}

#: the columns of ``parts`` (schema version 1): name, SQL type, meaning (docs/PARTS.md's table)
COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("part_id", "TEXT PRIMARY KEY", "the part's id: its run id (a suffix -2, -3 if another cell took it)"),
    ("run_id", "TEXT NOT NULL", "the run that wound it (its bag's name)"),
    ("job_id", "TEXT NOT NULL", "the job's id"),
    ("recipe_sha256", "TEXT NOT NULL", "SHA-256 of the job file, or of the canonical job text"),
    ("recipe_source", "TEXT NOT NULL", "job_file or job_text: what recipe_sha256 hashes"),
    ("software_version", "TEXT NOT NULL", "winder's version that ran it"),
    ("consumer", "TEXT NOT NULL", "the consumer node, namespace first"),
    ("simulated", "INTEGER NOT NULL", "1: a simulator or a twin wound it; 0: real axes"),
    ("host", "TEXT NOT NULL", "the host of the consumer's process"),
    ("pid", "INTEGER NOT NULL", "the consumer's process id"),
    ("pid_start", "TEXT NOT NULL", "that process' start time (Linux clock ticks; '' elsewhere)"),
    ("operator", "TEXT", "who ran it: the run's operator (NULL: not given)"),
    ("wire_lot", "TEXT", "the wire's lot: the run's wire_lot (NULL: not given)"),
    ("started_ns", "INTEGER NOT NULL", "UTC wall time of the run's start (ns since the epoch)"),
    ("ended_ns", "INTEGER", "UTC wall time of its close (NULL while running)"),
    ("cycle_time_s", "REAL", "wall time from start to close (s)"),
    ("state", "TEXT NOT NULL", "running, done, aborted or incomplete"),
    ("steps_done", "INTEGER", "steps executed"),
    ("steps_total", "INTEGER NOT NULL", "steps of the job"),
    ("turns_commanded", "INTEGER", "turns of the job (every coil)"),
    ("turns_counted", "INTEGER", "turns counted on the part (NULL: no counter reported them)"),
    ("wire_length_m", "REAL", "wire paid out (m; the final report's wire_taken_m)"),
    ("tension_mean_n", "REAL", "mean tension (N; NULL: not reported)"),
    ("tension_sd_n", "REAL", "tension's standard deviation (N; NULL: not reported)"),
    ("tension_min_n", "REAL", "least tension (N)"),
    ("tension_max_n", "REAL", "peak tension (N; the final report's tension_peak_n)"),
    ("tension_outside_warning_s", "REAL", "time outside the warning band (s)"),
    ("tension_outside_alarm_s", "REAL", "time outside the alarm band (s)"),
    ("breaks", "INTEGER", "wire breaks (from the run's faults)"),
    ("slips", "INTEGER", "wire slips (from the run's faults)"),
    ("resistance_predicted_ohm", "REAL", "resistance at 20 C from the job (NULL: bobbin not sized)"),
    ("resistance_measured_ohm", "REAL", "measured later (winder parts measure)"),
    ("faults", "TEXT", "what the axes or the wire did that was not commanded"),
    ("verdict", "TEXT", "ok or nok (NULL while running)"),
    ("reasons", "TEXT", "JSON list: every reason of a nok"),
    ("tolerances", "TEXT", "JSON map name: [min, max] the verdict was taken against (null: no limit)"),
    ("report", "TEXT", "JSON: the run's final report, every key as the bag has it"),
    ("bag", "TEXT", "the bag's path"),
)


#: the numeric columns that are a part's scalars (docs/PARTS.md): every number but the process'
NUMBER_COLUMNS = tuple(
    name
    for name, kind, _ in COLUMNS
    if kind.startswith(("REAL", "INTEGER")) and name not in ("simulated", "pid")
)


def _schema_v1(con: sqlite3.Connection) -> None:
    body = ",\n  ".join(f"{name} {kind}" for name, kind, _ in COLUMNS)
    con.execute(f"CREATE TABLE parts (\n  {body}\n)")
    con.execute("CREATE INDEX parts_job ON parts (job_id, started_ns)")
    con.execute("CREATE INDEX parts_recipe ON parts (recipe_sha256, started_ns)")
    con.execute("CREATE INDEX parts_started ON parts (started_ns)")
    con.execute("CREATE INDEX parts_state ON parts (state)")


def _kind_indexes_v2(con: sqlite3.Connection) -> None:
    """Version 2: the indexes a reader of one kind (simulated or real, never
    mixed unless asked) needs on 10^5 parts: the latest parts and their count
    by kind; a recipe's parts by kind in time order, with their job and state
    in the index, so that the recipes of a selection and the completed parts
    among them are counted without reading a row."""
    con.execute("CREATE INDEX parts_kind ON parts (simulated, started_ns)")
    con.execute(
        "CREATE INDEX parts_kind_recipe ON parts (simulated, recipe_sha256, started_ns, job_id, state)"
    )


#: version -> the function that brings an index of the version before it to it
MIGRATIONS: dict[int, Callable[[sqlite3.Connection], None]] = {1: _schema_v1, 2: _kind_indexes_v2}
SCHEMA_VERSION = max(MIGRATIONS)


class PartIndexError(OutputError):
    """The part index cannot be read or written: one line naming the file."""


@dataclass(frozen=True)
class PartStart:
    """What a part's row holds from its run's start."""

    run_id: str
    job_id: str
    recipe_sha256: str
    recipe_source: str
    software_version: str
    consumer: str
    simulated: bool
    steps_total: int
    started_ns: int
    bag: str = ""
    turns_commanded: int | None = None
    resistance_predicted_ohm: float | None = None
    tolerances: Tolerances = field(default_factory=dict)
    operator: str | None = None
    wire_lot: str | None = None


@dataclass(frozen=True)
class PartEnd:
    """What a part's row gets at its run's close: the final report's key/values."""

    ended_ns: int
    report: Mapping[str, str]


def recipe_sha256(plan: JobPlan) -> tuple[str, str]:
    """The recipe's SHA-256 and what it hashes: the job file's bytes
    (``job_file``) if the run came from one, else the canonical text of the
    job's fields (``job_text``: sorted keys, no spaces), the same for the
    same job however it was given."""
    if plan.job_file_sha256:
        return plan.job_file_sha256, "job_file"
    text = json.dumps(plan.job.to_dict(), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode("utf-8")).hexdigest(), "job_text"


def part_start(
    plan: JobPlan,
    *,
    consumer: str,
    simulated: bool,
    software_version: str,
    started_ns: int,
    bag: str,
) -> PartStart:
    """A run's part as it starts, from its plan (its job's tolerances too,
    and who ran it with which wire, as its job description says)."""
    sha, source = recipe_sha256(plan)
    winding = plan.job.winding
    return PartStart(
        run_id=plan.run_id or plan.job_id,
        job_id=plan.job_id,
        recipe_sha256=sha,
        recipe_source=source,
        software_version=software_version,
        consumer=consumer,
        simulated=simulated,
        steps_total=plan.total_steps,
        started_ns=started_ns,
        bag=bag,
        turns_commanded=winding.total_turns,
        resistance_predicted_ohm=winding.resistance,
        tolerances=parse_tolerances(plan.job.tolerances),
        operator=plan.operator or None,  # NULL: not given (the run's, never the recipe's)
        wire_lot=plan.wire_lot or None,
    )


def index_path(parts_db: str, bag_dir: Path | None) -> Path | None:
    """The index a consumer writes (its ``parts_db`` setting): ``auto``, the
    bag directory's :data:`INDEX_NAME` (none when it does not record:
    ``bag_dir`` None); ``""``, none; else that file."""
    if parts_db == "auto":
        return None if bag_dir is None else bag_dir / INDEX_NAME
    return Path(parts_db).expanduser() if parts_db else None


def _float(text: object) -> float | None:
    try:
        value = float(str(text))
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def report_numbers(report: Mapping[str, str]) -> dict[str, float]:
    """The final report's keys whose value is a finite number."""
    out = {}
    for key, text in report.items():
        value = _float(text)
        if value is not None:
            out[key] = value
    return out


def part_scalars(row: Mapping[str, Any]) -> tuple[dict[str, float | None], dict[str, str]]:
    """A part's scalars by name, as tolerances name them (docs/PARTS.md):
    the report's numbers, then the row's numeric columns over them,
    ``resistance_ohm`` (measured, else predicted) and ``turns_error``; and
    the words a reason adds to a name (``resistance_ohm`` "(predicted)")."""
    report = json.loads(row["report"]) if row.get("report") else {}
    scalars: dict[str, float | None] = dict(report_numbers(report))
    for name in NUMBER_COLUMNS:
        value = row.get(name)
        scalars[name] = None if value is None else float(value)
    notes: dict[str, str] = {}
    measured, predicted = row.get("resistance_measured_ohm"), row.get("resistance_predicted_ohm")
    scalars["resistance_ohm"] = measured if measured is not None else predicted
    if measured is None and predicted is not None:
        notes["resistance_ohm"] = "(predicted; not measured yet)"
    commanded, counted = row.get("turns_commanded"), row.get("turns_counted")
    scalars["turns_error"] = None if commanded is None or counted is None else float(counted - commanded)
    return scalars, notes


def row_tolerances(row: Mapping[str, Any]) -> Tolerances:
    """The tolerances a part's row was judged against (None: no limit on that side)."""
    doc = json.loads(row.get("tolerances") or "{}")
    return {
        k: (None if lo is None else float(lo), None if hi is None else float(hi))
        for k, (lo, hi) in doc.items()
    }


def judge(row: Mapping[str, Any]) -> tuple[str, list[str]]:
    """A closed part's verdict and reasons from its row."""
    tolerances = row_tolerances(row)
    scalars, notes = part_scalars(row)
    errors = int(scalars.get("errors") or 0)
    return verdict(str(row["state"]), scalars, tolerances, str(row.get("faults") or ""), notes, errors)


def _busy(exc: sqlite3.Error) -> bool:
    """Whether SQLite refused for a lock another connection holds (SQLITE_BUSY, any of its kinds)."""
    code = getattr(exc, "sqlite_errorcode", None)
    return (code & 0xFF == sqlite3.SQLITE_BUSY) if code is not None else "database is locked" in str(exc)


def _process_start(pid: int) -> str:
    """The start time of process ``pid`` (clock ticks since boot, Linux), "" if unknown:
    with the pid, it tells a process from a later one given the same pid."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return ""
    return stat.rsplit(")", 1)[-1].split()[19]  # field 22, counted after the command's name


def _alive(pid: int, started: str) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass  # another user's process: it exists
    return not started or _process_start(pid) in ("", started)


class PartIndex:
    """The part index in ``path`` (created with its schema on first use)."""

    def __init__(self, path: Path | str) -> None:
        self.path = Path(path)
        self._held: sqlite3.Connection | None = None  #: see :meth:`_hold`

    def fail(self, doing: str, exc: BaseException) -> PartIndexError:
        return PartIndexError(
            f"part index {self.path}: cannot {doing}: {str(exc).splitlines()[0] if str(exc) else exc}"
        )

    @contextmanager
    def _connect(self, doing: str, *, write: bool) -> Iterator[sqlite3.Connection]:
        """A connection with the index at :data:`SCHEMA_VERSION`, in one
        transaction (:meth:`_begun`); committed at the end, rolled back on an error."""
        if not write and not self.path.exists():
            raise PartIndexError(f"part index {self.path}: cannot {doing}: no such file")
        con = self._begun(doing, write)
        try:
            try:
                yield con
            except BaseException:
                con.execute("ROLLBACK")
                raise
            con.execute("COMMIT")
            if write:
                self._hold()
        except sqlite3.Error as exc:
            raise self.fail(doing, exc) from None
        finally:
            con.close()

    def _begun(self, doing: str, write: bool) -> sqlite3.Connection:
        """A connection in its transaction (BEGIN IMMEDIATE for a write: the
        lock taken at once), the schema brought up to date for a write. Two
        waits, both up to :data:`BUSY_TIMEOUT_MS`: SQLite's busy handler, for
        a lock another connection holds; and this loop, for the locks SQLite
        refuses at once rather than wait for (SQLITE_BUSY without its
        handler, so that two connections never wait for each other: cells
        that put a new file into WAL mode at the same moment, one of them
        turned away), the whole beginning tried again after a pause. Once
        the write lock is taken nothing of the transaction can be refused so
        (WAL), so the body never has to be tried again."""
        deadline = time.monotonic() + BUSY_TIMEOUT_MS / 1000
        pause = 0.002
        while True:
            try:
                con = self._open(write)
            except sqlite3.Error as exc:
                raise self.fail(doing, exc) from None
            try:
                con.row_factory = sqlite3.Row
                con.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
                self._not_newer(con)  # before anything is written to it, WAL mode too
                if write:
                    if con.execute("PRAGMA journal_mode").fetchone()[0] != "wal":
                        con.execute("PRAGMA journal_mode = WAL")
                    con.execute("PRAGMA synchronous = NORMAL")  # WAL: a commit survives a process' kill
                con.execute("BEGIN IMMEDIATE" if write else "BEGIN")
                try:
                    self._migrate(con, write)
                except BaseException:
                    con.execute("ROLLBACK")
                    raise
                return con
            except sqlite3.Error as exc:
                con.close()
                if not _busy(exc) or time.monotonic() >= deadline:
                    raise self.fail(doing, exc) from None
            except BaseException:
                con.close()
                raise
            time.sleep(pause * random.uniform(0.5, 1.5))  # apart, not in step with another cell
            pause = min(2 * pause, 0.05)

    def _hold(self) -> None:
        """After this instance's first write, a connection held open while it
        lives: the last connection to a WAL file to close checkpoints every
        page of the WAL into the file, syncs it and deletes the WAL, what a
        writer that opens a connection a transaction would do at each part
        (2 ms of CPU and two syncs on a loaded disk, where the part's own
        write costs less). Held, the pages go in by SQLite's checkpoint every
        1000 pages of WAL instead, and at this process' end. It reads the
        schema's version once (a connection enters WAL mode on its first
        read), and nothing after that: it holds no lock between reads."""
        if self._held is not None:
            return
        try:
            held = sqlite3.connect(self.path, check_same_thread=False)
            held.execute("PRAGMA user_version").fetchone()
        except sqlite3.Error:
            return  # the write is in: holding only spares the next ones some time
        self._held = held

    def _open(self, write: bool) -> sqlite3.Connection:
        """A connection to the index. A read of an index in a directory this
        process may not write (read-only media, another user's) opens it
        read-only, and immutable when it has no ``-wal`` file (every write in
        the file): a WAL reader needs a ``-shm`` file beside it, which SQLite
        cannot make there."""
        if write or os.access(self.path.parent, os.W_OK):
            return sqlite3.connect(self.path, timeout=BUSY_TIMEOUT_MS / 1000, isolation_level=None)
        wal = self.path.with_name(self.path.name + "-wal")
        flags = "mode=ro" if wal.exists() else "mode=ro&immutable=1"
        return sqlite3.connect(
            f"{self.path.resolve().as_uri()}?{flags}",
            uri=True,
            timeout=BUSY_TIMEOUT_MS / 1000,
            isolation_level=None,
        )

    def _not_newer(self, con: sqlite3.Connection) -> int:
        """The index's schema version; :class:`PartIndexError` if a newer winder wrote it."""
        version = int(con.execute("PRAGMA user_version").fetchone()[0])
        if version > SCHEMA_VERSION:
            raise PartIndexError(
                f"part index {self.path}: schema version {version} is newer than this winder's "
                f"{SCHEMA_VERSION}: use the winder that wrote it"
            )
        return version

    def _migrate(self, con: sqlite3.Connection, write: bool) -> None:
        version = self._not_newer(con)  # again, in the transaction: another process may have written
        if version == SCHEMA_VERSION:
            return
        if not write:
            raise PartIndexError(
                f"part index {self.path}: schema version {version}, expected {SCHEMA_VERSION}: "
                "it is brought up to date by the next run or winder parts command"
            )
        for step in range(version + 1, SCHEMA_VERSION + 1):
            MIGRATIONS[step](con)
        con.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")

    # -- writes ------------------------------------------------------------------------
    def begin(self, part: PartStart) -> str:
        """A run starts: its part's row, ``running``; returns the part id."""
        with self._connect("write the start of a part", write=True) as con:
            part_id, n = part.run_id, 1
            while con.execute("SELECT 1 FROM parts WHERE part_id = ?", (part_id,)).fetchone():
                n += 1
                part_id = f"{part.run_id}-{n}"
            pid = os.getpid()
            con.execute(
                "INSERT INTO parts (part_id, run_id, job_id, recipe_sha256, recipe_source,"
                " software_version, consumer, simulated, host, pid, pid_start, operator, wire_lot,"
                " started_ns, state, steps_done, steps_total, turns_commanded, resistance_predicted_ohm,"
                " tolerances, bag)"
                " VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, 'running', 0, ?, ?, ?, ?, ?)",
                (
                    part_id,
                    part.run_id,
                    part.job_id,
                    part.recipe_sha256,
                    part.recipe_source,
                    part.software_version,
                    part.consumer,
                    int(part.simulated),
                    socket.gethostname(),
                    pid,
                    _process_start(pid),
                    part.operator,
                    part.wire_lot,
                    part.started_ns,
                    part.steps_total,
                    part.turns_commanded,
                    part.resistance_predicted_ohm,
                    json.dumps({k: list(v) for k, v in part.tolerances.items()}),
                    part.bag,
                ),
            )
        return part_id

    def close(self, part_id: str, end: PartEnd) -> dict[str, Any]:
        """A run closed: its part's row completed from its final report, with
        its verdict, in one transaction; returns the row."""
        report = dict(end.report)
        faults = report.get("faults", "")
        numbers = report_numbers(report)
        with self._connect(f"write the close of part {part_id}", write=True) as con:
            row = con.execute("SELECT * FROM parts WHERE part_id = ?", (part_id,)).fetchone()
            if row is None:
                raise PartIndexError(f"part index {self.path}: no part {part_id} to close")
            values: dict[str, Any] = {
                "ended_ns": end.ended_ns,
                "cycle_time_s": (end.ended_ns - int(row["started_ns"])) / 1e9,
                "state": report.get("state", "incomplete") or "incomplete",
                "steps_done": int(numbers.get("steps_done", 0)),
                "wire_length_m": numbers.get(FROM_REPORT["wire_length_m"]),
                "tension_min_n": numbers.get("tension_min_n"),
                "tension_max_n": numbers.get(FROM_REPORT["tension_max_n"]),
                "tension_outside_warning_s": numbers.get("tension_outside_warning_s"),
                "tension_outside_alarm_s": numbers.get("tension_outside_alarm_s"),
                # counted in the wire's fault words: a run without a wire (a drive's) has none to count
                "breaks": faults.count("wire break at") if "tension_peak_n" in report else None,
                "slips": faults.count("wire slip at") if "tension_peak_n" in report else None,
                "faults": faults,
                "report": json.dumps(report, sort_keys=True),
                "bag": report.get("bag") or row["bag"],
            }
            merged = {**dict(row), **values}
            values["verdict"], reasons = judge(merged)
            values["reasons"] = json.dumps(reasons)
            sets = ", ".join(f"{k} = ?" for k in values)
            con.execute(f"UPDATE parts SET {sets} WHERE part_id = ?", (*values.values(), part_id))
            return {**merged, **values}

    def measure(self, part_id: str, resistance_ohm: float) -> dict[str, Any]:
        """A measured resistance entered: the part's verdict taken again with it."""
        with self._connect(f"enter a measurement of part {part_id}", write=True) as con:
            row = con.execute("SELECT * FROM parts WHERE part_id = ?", (part_id,)).fetchone()
            if row is None:
                raise BadInputError(f"part index {self.path}: no part {part_id!r}")
            merged = {**dict(row), "resistance_measured_ohm": resistance_ohm}
            if merged["state"] == "running":
                con.execute(
                    "UPDATE parts SET resistance_measured_ohm = ? WHERE part_id = ?",
                    (resistance_ohm, part_id),
                )
                return merged
            ok, reasons = judge(merged)
            con.execute(
                "UPDATE parts SET resistance_measured_ohm = ?, verdict = ?, reasons = ? WHERE part_id = ?",
                (resistance_ohm, ok, json.dumps(reasons), part_id),
            )
            return {**merged, "verdict": ok, "reasons": json.dumps(reasons)}

    def recover(self) -> list[str]:
        """The parts left ``running`` by a process of this host that is gone,
        marked ``incomplete`` (verdict ``nok``, the reason said); their ids.
        Looked for in a read first: the write (and its lock, which every
        consumer's start and every ``winder parts`` would otherwise take, and
        which an index this process may not write refuses) only when there is
        one to mark, or an older schema to bring up to date, or no file yet."""
        host = socket.gethostname()
        try:
            with self._connect("look for the parts of killed runs", write=False) as con:
                if not self._gone(con, host):
                    return []
        except PartIndexError:
            pass  # no file, an older schema, a newer one: the write below makes, migrates or refuses
        with self._connect("mark the parts of killed runs incomplete", write=True) as con:
            rows = self._gone(con, host)
            gone = [r["part_id"] for r in rows]
            for part_id, pid in ((r["part_id"], r["pid"]) for r in rows):
                reasons = [f"run not completed: its process (pid {pid} on {host}) ended without closing it"]
                con.execute(
                    "UPDATE parts SET state = 'incomplete', verdict = ?, reasons = ? WHERE part_id = ?",
                    (NOK, json.dumps(reasons), part_id),
                )
        return gone

    @staticmethod
    def _gone(con: sqlite3.Connection, host: str) -> list[sqlite3.Row]:
        """The running parts of ``host`` whose process is gone."""
        rows = con.execute(
            "SELECT part_id, pid, pid_start FROM parts WHERE state = 'running' AND host = ?", (host,)
        ).fetchall()
        return [r for r in rows if not _alive(int(r["pid"]), str(r["pid_start"]))]

    # -- reads -------------------------------------------------------------------------
    def get(self, part_id: str) -> dict[str, Any] | None:
        with self._connect(f"read part {part_id}", write=False) as con:
            row = con.execute("SELECT * FROM parts WHERE part_id = ?", (part_id,)).fetchone()
        return None if row is None else dict(row)

    def parts(
        self,
        *,
        simulated: bool | None = None,
        job_id: str | None = None,
        recipe: str | None = None,
        verdict: str | None = None,
        since_ns: int | None = None,
        state: str | None = None,
        limit: int | None = None,
        columns: Sequence[str] | None = None,
        operator: str | None = None,
        wire_lot: str | None = None,
    ) -> list[dict[str, Any]]:
        """The parts, oldest first, filtered (None: any; ``recipe``: a prefix
        of its SHA-256, hex digits; ``operator``, ``wire_lot``: exactly that);
        ``limit``: the latest that many; ``columns``: only those (default
        every one)."""
        chosen = "*" if columns is None else ", ".join(_known(columns))
        with self._connect("list the parts", write=False) as con:
            where, args = _where(
                con, simulated, job_id, recipe, verdict, since_ns, state, operator=operator, wire_lot=wire_lot
            )
            sql = f"SELECT {chosen} FROM parts{where} ORDER BY started_ns DESC, part_id DESC"
            if limit is not None:
                sql += f" LIMIT {int(limit)}"
            rows = [dict(r) for r in con.execute(sql, args)]
        return rows[::-1]

    def count(
        self,
        *,
        simulated: bool | None = None,
        job_id: str | None = None,
        recipe: str | None = None,
        verdict: str | None = None,
        since_ns: int | None = None,
        state: str | None = None,
        operator: str | None = None,
        wire_lot: str | None = None,
    ) -> int:
        """How many parts the filters of :meth:`parts` take."""
        with self._connect("count the parts", write=False) as con:
            where, args = _where(
                con, simulated, job_id, recipe, verdict, since_ns, state, operator=operator, wire_lot=wire_lot
            )
            return int(con.execute(f"SELECT count(*) FROM parts{where}", args).fetchone()[0])

    def recipes(
        self,
        *,
        simulated: bool | None = None,
        job_id: str | None = None,
        recipe: str | None = None,
        since_ns: int | None = None,
    ) -> list[tuple[str, int, list[str]]]:
        """The recipes of the parts the filters take: SHA-256, parts, job ids; most parts first."""
        found: list[tuple[str, int, list[str]]] = []
        with self._connect("list the recipes", write=False) as con:
            for sha in _recipes(con, recipe):
                where, args = _where(con, simulated, job_id, sha, None, since_ns, None)
                sql = f"SELECT job_id, count(*) FROM parts{where} GROUP BY job_id"
                jobs = con.execute(sql, args).fetchall()
                if jobs:
                    found.append((sha, sum(int(n) for _, n in jobs), sorted(j for j, _ in jobs)))
        return sorted(found, key=lambda r: (-r[1], r[0]))


#: what a recipe filter may be: a prefix of a SHA-256 in hex
RECIPE_PREFIX = re.compile(r"^[0-9a-f]{1,64}$")
#: the most recipes a prefix may stand for
MAX_RECIPES = 1000


def _known(columns: Sequence[str]) -> list[str]:
    names = {name for name, _, _ in COLUMNS}
    unknown = [c for c in columns if c not in names]
    if unknown:
        raise ValueError(f"no column {', '.join(unknown)} in the part index")
    return list(columns)


def _recipes(con: sqlite3.Connection, recipe: str | None) -> list[str]:
    """The recipes' SHA-256 a prefix stands for (None: every recipe), each
    found by one seek in the recipe's index: a filter on whole hashes lets
    the kind and recipe index give the parts in time order, where a prefix's
    range would have them sorted."""
    prefix = (recipe or "").lower()
    if not RECIPE_PREFIX.match(prefix) and recipe is not None:
        raise BadInputError(f"recipe {recipe!r} is invalid: expected a prefix of a SHA-256 (hex digits)")
    if len(prefix) == 64:
        return [prefix]
    found: list[str] = []
    while len(found) < MAX_RECIPES:
        row = con.execute(
            "SELECT recipe_sha256 FROM parts WHERE recipe_sha256 GLOB ? AND recipe_sha256 > ?"
            " ORDER BY recipe_sha256 LIMIT 1",
            (prefix + "*", found[-1] if found else ""),
        ).fetchone()
        if row is None:
            break
        found.append(str(row[0]))
    return found


def _where(
    con: sqlite3.Connection,
    simulated: bool | None,
    job_id: str | None,
    recipe: str | None,
    verdict: str | None,
    since_ns: int | None,
    state: str | None,
    *,
    operator: str | None = None,
    wire_lot: str | None = None,
) -> tuple[str, list[Any]]:
    """The WHERE clause of the filters (None: any) and its arguments; a
    recipe's prefix as the whole hashes it stands for (:func:`_recipes`)."""
    where: list[str] = []
    args: list[Any] = []
    for column, value in (
        ("simulated", simulated),
        ("job_id", job_id),
        ("verdict", verdict),
        ("state", state),
        ("operator", operator),
        ("wire_lot", wire_lot),
    ):
        if value is not None:
            where.append(f"{column} = ?")
            args.append(int(value) if isinstance(value, bool) else value)
    if recipe is not None:
        shas = _recipes(con, recipe)
        where.append(
            "recipe_sha256 = ?" if len(shas) == 1 else f"recipe_sha256 IN ({', '.join('?' * len(shas))})"
        )
        args += shas
    if since_ns is not None:
        where.append("started_ns >= ?")
        args.append(since_ns)
    return (" WHERE " + " AND ".join(where) if where else ""), args
