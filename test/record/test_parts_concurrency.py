"""Many cells, one part index: concurrent writers, a held lock, files that
cannot be written, and the migration from schema version 1.

Real processes on one SQLite file, no mocks: four writers started together
(each has imported and opened the index before any writes, so their writes
overlap, which the test checks from their own clocks); a lock held by this
process while a writer waits behind it; a process that may not write the
index (dropped to an unprivileged user when the tests run as root, whom no
file mode stops).
"""

from __future__ import annotations

import json
import os
import sqlite3
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from support import wait

from winder.errors import WinderError
from winder.record import parts as parts_mod
from winder.record.parts import SCHEMA_VERSION, PartEnd, PartIndex, PartIndexError, PartStart

CELLS, EACH, ROUNDS = 4, 25, 60


def start(run_id: str, *, simulated: bool = True, started_ns: int = 1_795_911_156_000_000_000) -> PartStart:
    return PartStart(
        run_id=run_id,
        job_id="rw400",
        recipe_sha256="ab" * 32,
        recipe_source="job_file",
        software_version="0.1.0",
        consumer="sim_node",
        simulated=simulated,
        steps_total=10,
        started_ns=started_ns,
    )


DONE = {"state": "done", "steps_done": "10", "steps_total": "10"}

WRITER = """
import json, sys, time
from winder.record.parts import PartEnd, PartIndex, PartStart
path, cell, each, ready = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
index = PartIndex(path)
open(ready, "w").close()
sys.stdin.readline()  # every cell at once
first, recovered = time.time_ns(), []
for n in range(each):
    part = index.begin(PartStart(run_id=f"{cell}_20261129_000000000_{n}", job_id=cell,
                                 recipe_sha256="00" * 32, recipe_source="job_text", software_version="0.1.0",
                                 consumer=cell, simulated=True, steps_total=10, started_ns=time.time_ns()))
    recovered += index.recover()  # the other cells' running parts are of live processes
    index.close(part, PartEnd(time.time_ns(), {"state": "done", "steps_done": "10", "steps_total": "10"}))
print(json.dumps({"first": first, "last": time.time_ns(), "recovered": recovered}))
"""


def test_four_cells_writing_at_once_lose_nothing(tmp_path: Path) -> None:
    path = tmp_path / "parts.sqlite"
    ready = [tmp_path / f"ready{c}" for c in range(CELLS)]
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", WRITER, str(path), f"cell{c}", str(EACH), str(ready[c])],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        for c in range(CELLS)
    ]
    try:
        wait.until(lambda: all(r.exists() for r in ready), 120, "every cell's index opened")
        for p in procs:
            assert p.stdin is not None
            p.stdin.write("go\n")
            p.stdin.flush()
        outs = [p.communicate(timeout=300)[0] for p in procs]
    finally:
        for p in procs:
            p.kill()
            p.wait()
    assert [p.returncode for p in procs] == [0] * CELLS, outs
    spans = [json.loads(out.strip().splitlines()[-1]) for out in outs]
    assert max(s["first"] for s in spans) < min(s["last"] for s in spans)  # the writes overlapped
    assert [s["recovered"] for s in spans] == [[]] * CELLS  # no live cell's part marked incomplete
    rows = PartIndex(path).parts()
    expected = {f"cell{c}_20261129_000000000_{n}" for c in range(CELLS) for n in range(EACH)}
    assert {r["part_id"] for r in rows} == expected and len(rows) == CELLS * EACH
    assert {(r["state"], r["verdict"]) for r in rows} == {("done", "ok")}
    with sqlite3.connect(path) as con:
        assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        assert con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"


OPENER = """
import sys
from winder.record.parts import PartIndex, PartIndexError, PartStart
cell = sys.argv[1]
for line in sys.stdin:  # a new index's path, given to every cell at once
    try:
        PartIndex(line.strip()).begin(PartStart(run_id=f"{cell}_20261129_000000000_1", job_id=cell,
                                                recipe_sha256="00" * 32, recipe_source="job_text",
                                                software_version="0.1.0", consumer=cell, simulated=True,
                                                steps_total=10, started_ns=1))
        print("ok", flush=True)
    except PartIndexError as exc:
        print(f"failed {exc}", flush=True)
"""


def test_cells_that_make_a_new_index_at_once_all_write_to_it(tmp_path: Path) -> None:
    """Four cells' first write to a file none has made yet, at the same moment, 60 times: each
    puts the new file into WAL mode, and SQLite turns all but one away at once, without its
    busy handler (two connections must never wait for each other); the index tries again,
    and every cell's part is in. Without that, about one such start in six lost a part."""
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", OPENER, f"cell{c}"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        for c in range(CELLS)
    ]
    said: list[str] = []
    try:
        for n in range(ROUNDS):
            path = tmp_path / f"new{n}.sqlite"
            for p in procs:
                assert p.stdin is not None
                p.stdin.write(f"{path}\n")
                p.stdin.flush()
            for p in procs:
                assert p.stdout is not None
                said.append(p.stdout.readline().strip())
            assert len(PartIndex(path).parts()) == CELLS, said[-CELLS:]
    finally:
        for p in procs:
            p.kill()
            p.wait()
    assert said == ["ok"] * CELLS * ROUNDS, [s for s in said if s != "ok"]


BLOCKED = """
import sys, time
from winder.record import parts
from winder.record.parts import PartIndex, PartIndexError, PartStart
path, log, timeout_ms = sys.argv[1], sys.argv[2], sys.argv[3]
if timeout_ms != "default":
    parts.BUSY_TIMEOUT_MS = int(timeout_ms)
with open(log, "a") as out:
    print("trying", file=out, flush=True)
    try:
        PartIndex(path).begin(PartStart(run_id="late_20261129_000000000_1", job_id="late",
                                        recipe_sha256="00" * 32, recipe_source="job_text",
                                        software_version="0.1.0", consumer="late", simulated=True,
                                        steps_total=10, started_ns=1))
    except PartIndexError as exc:
        print(f"failed {exc}", file=out, flush=True)
        sys.exit(1)
    print(f"written {time.time_ns()}", file=out, flush=True)
"""


@pytest.fixture
def held(tmp_path: Path) -> Iterator[tuple[Path, sqlite3.Connection]]:
    """An index whose write lock this process holds (BEGIN IMMEDIATE) until the test commits."""
    path = tmp_path / "parts.sqlite"
    PartIndex(path).begin(start("first_20261129_000000000_1"))
    con = sqlite3.connect(path, isolation_level=None)
    con.execute("BEGIN IMMEDIATE")
    try:
        yield path, con
    finally:
        con.close()


def test_a_writer_waits_for_a_held_lock(held: tuple[Path, sqlite3.Connection], tmp_path: Path) -> None:
    """With the index's busy timeout a writer waits behind another's transaction and then writes;
    without one, the same writer fails at once: one line naming the index."""
    path, con = held
    log = tmp_path / "impatient.log"
    r = subprocess.run([sys.executable, "-c", BLOCKED, str(path), str(log), "0"], timeout=120, check=False)
    assert r.returncode == 1
    [_, failed] = log.read_text().splitlines()
    assert failed.startswith(
        f"failed part index {path}: cannot write the start of a part: database is locked"
    )
    log = tmp_path / "patient.log"
    p = subprocess.Popen([sys.executable, "-c", BLOCKED, str(path), str(log), "default"])
    try:
        wait.until(lambda: log.exists() and "trying" in log.read_text(), 120, "the writer's attempt")
        time.sleep(0.5)  # it waits behind the lock meanwhile (the result does not depend on how long)
        released = time.time_ns()
        con.execute("COMMIT")
        assert wait.until_exit(p, 120, "the waiting writer") == 0, log.read_text()
    finally:
        p.kill()
        p.wait()
    [_, written] = log.read_text().splitlines()
    assert int(written.split()[1]) > released
    assert [r["part_id"] for r in PartIndex(path).parts()] == [
        "late_20261129_000000000_1",
        "first_20261129_000000000_1",
    ]


# -- an index this process may not write --------------------------------------------------------

NOBODY = 65534


def as_another_user(fn: Callable[[], Any]) -> Any:
    """``fn()`` in a forked child that may not write what this process made: as root it drops to
    ``nobody`` (root writes through any file mode); its result or its error back as JSON."""
    reader, writer = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: no return from here
        os.close(reader)
        try:
            if os.geteuid() == 0:
                os.setgroups([])
                os.setgid(NOBODY)
                os.setuid(NOBODY)
            try:
                out: dict[str, Any] = {"value": fn()}
            except Exception as exc:
                out = {"error": type(exc).__name__, "winder": isinstance(exc, WinderError), "text": str(exc)}
            os.write(writer, json.dumps(out).encode())
        finally:
            os._exit(0)
    os.close(writer)
    with os.fdopen(reader, "rb") as fh:
        data = fh.read()
    os.waitpid(pid, 0)
    return json.loads(data)


@pytest.fixture
def shared() -> Iterator[Path]:
    """A directory every user may enter (pytest's own are private to their owner)."""
    top = Path(tempfile.mkdtemp(prefix="winder_parts_ro_"))
    top.chmod(0o755)
    try:
        yield top
    finally:
        for p in [top, *top.rglob("*")]:
            p.chmod(0o755 if p.is_dir() else 0o644)
        subprocess.run(["rm", "-rf", str(top)], check=True)


def refused(out: dict[str, Any], path: Path) -> None:
    """A :class:`PartIndexError`, a WinderError (what a consumer catches: its run goes on, ERROR
    and all), one line naming the index."""
    assert out.get("error") == "PartIndexError" and out["winder"], out
    assert out["text"].startswith(f"part index {path}: cannot write") and "\n" not in out["text"], out


def test_a_read_only_directory_refuses_a_new_index_in_one_line(shared: Path) -> None:
    cell = shared / "cell"
    cell.mkdir()
    cell.chmod(0o555)
    path = cell / "parts.sqlite"
    refused(as_another_user(lambda: PartIndex(path).begin(start("a_20261129_000000000_1"))), path)
    assert list(cell.iterdir()) == []


@pytest.mark.parametrize("where", ["file", "directory"])
def test_a_read_only_index_refuses_writes_in_one_line_and_is_still_read(shared: Path, where: str) -> None:
    """A read-only file in a writable directory, or a whole index in a read-only directory: no
    write goes in, the file is as it was, and its parts are read all the same (``winder parts``
    looks for killed runs' parts there too, without writing when there is none)."""
    cell = shared / "cell"
    cell.mkdir(mode=0o777)
    cell.chmod(0o777)
    path = cell / "parts.sqlite"
    index = PartIndex(path)
    part = index.begin(start("b_20261129_000000000_1"))
    if where == "file":
        path.chmod(0o444)
    else:
        path.chmod(0o644)
        cell.chmod(0o555)
    before = path.read_bytes()
    refused(as_another_user(lambda: PartIndex(path).begin(start("c_20261129_000000000_1"))), path)
    refused(as_another_user(lambda: PartIndex(path).close(part, PartEnd(2, DONE))), path)
    assert path.read_bytes() == before
    read = as_another_user(lambda: [r["part_id"] for r in PartIndex(path).parts()])
    assert read == {"value": [part]}
    # nothing to mark incomplete (this process, which began the part, lives): looked for, not written
    assert as_another_user(lambda: PartIndex(path).recover()) == {"value": []}
    assert path.read_bytes() == before


# -- from schema version 1 ----------------------------------------------------------------------


def test_an_index_of_version_1_is_migrated_with_its_parts(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Version 1 (phase 1's schema) written by the code of version 1; the next write brings it to
    the current version: its parts as they were, the kind indexes made and used."""
    path = tmp_path / "parts.sqlite"
    with monkeypatch.context() as m:
        m.setattr(parts_mod, "MIGRATIONS", {1: parts_mod.MIGRATIONS[1]})
        m.setattr(parts_mod, "SCHEMA_VERSION", 1)
        old = PartIndex(path)
        for n, simulated in enumerate((True, False, True)):
            old.close(
                old.begin(start(f"v1_20261129_000000000_{n}", simulated=simulated, started_ns=n)),
                PartEnd(n + 1, DONE),
            )
        before = old.parts()

    def indexes() -> set[str]:
        with sqlite3.connect(path) as con:
            return {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'index'")}

    with sqlite3.connect(path) as con:
        assert con.execute("PRAGMA user_version").fetchone()[0] == 1
    assert not indexes() & {"parts_kind", "parts_kind_recipe"}
    index = PartIndex(path)
    with pytest.raises(PartIndexError, match=f"schema version 1, expected {SCHEMA_VERSION}"):
        index.parts()  # a reader does not write
    assert index.recover() == []  # a writer migrates
    with sqlite3.connect(path) as con:
        assert con.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
        assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        plan = " ".join(
            str(r[-1])
            for r in con.execute(
                "EXPLAIN QUERY PLAN SELECT * FROM parts WHERE simulated = 1 AND recipe_sha256 GLOB 'ab*'"
                " AND state = 'done' ORDER BY started_ns DESC LIMIT 50"
            )
        )
        counted = " ".join(
            str(r[-1])
            for r in con.execute("EXPLAIN QUERY PLAN SELECT count(*) FROM parts WHERE simulated = 0")
        )
    assert {"parts_kind", "parts_kind_recipe"} <= indexes()
    assert "parts_kind_recipe" in plan and "COVERING INDEX parts_kind" in counted, (plan, counted)
    assert index.parts() == before
    assert index.count(simulated=True) == 2 and index.recipes(simulated=False) == [("ab" * 32, 1, ["rw400"])]
