"""``winder parts``: list, show, measure and export on a part index.

The index is written with :mod:`winder.record.parts` as a consumer writes it
(begin, then close with a final report); the command runs as a real
``winder`` process. The expected values are the ones written, never the
command's own output. One node test: a real ``winder run`` writes its part,
read back against the final report in the run's bag.
"""

from __future__ import annotations

import csv
import hashlib
import json
import signal
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import Procs, bag_closed, final_report, rosbags_read
from support.cell import winder_run
from support.cli import assert_one_line_error, run_cli

from winder import __version__
from winder.cli.exits import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OUTPUT
from winder.record.bag import bags_in
from winder.record.parts import COLUMNS, PartEnd, PartIndex, PartStart

T0 = 1_795_911_156_000_000_000


def rid(n: int) -> str:
    return f"rw400_20261129_00000{n:04d}_1"


def add(index: PartIndex, n: int, *, simulated: bool, state: str = "done", faults: str = "") -> str:
    run_id = rid(n)
    part = index.begin(
        PartStart(
            run_id=run_id,
            job_id="rw400" if n % 2 == 0 else "rw100",
            recipe_sha256=f"{n:02d}" * 32,
            recipe_source="job_file",
            software_version="0.1.0",
            consumer="sim_node" if simulated else "cell1/driver",
            simulated=simulated,
            steps_total=1000,
            started_ns=T0 + n * 60 * 10**9,
            bag=f"/bags/{run_id}",
            turns_commanded=400,
            resistance_predicted_ohm=12.0,
            tolerances={"resistance_ohm": (11.5, 12.5)},
        )
    )
    report = {"state": state, "steps_done": "1000" if state == "done" else "10", "steps_total": "1000"}
    if faults:
        report["faults"] = faults
    index.close(part, PartEnd(T0 + n * 60 * 10**9 + 12 * 10**9, report))
    return part


@pytest.fixture
def index(tmp_path: Path) -> PartIndex:
    """Bags/parts.sqlite: parts 0, 1 simulated (1 incomplete), 2 real, 3 simulated (the latest)."""
    (tmp_path / "bags").mkdir()
    idx = PartIndex(tmp_path / "bags" / "parts.sqlite")
    add(idx, 0, simulated=True)
    add(idx, 1, simulated=True, state="incomplete")
    add(idx, 2, simulated=False)
    add(idx, 3, simulated=True)
    return idx


def ids(out: str) -> list[str]:
    return [line.split()[0] for line in out.splitlines() if line.startswith("rw400_")]


def test_list_shows_one_kind_unless_asked(index: PartIndex) -> None:
    db = ["--db", str(index.path)]
    r = run_cli("parts", *db)
    assert r.returncode == 0, r.stderr
    assert ids(r.stdout) == [rid(0), rid(1), rid(3)]
    assert "3 simulated part(s)" in r.stdout and "1 real part(s) not shown" in r.stdout
    r = run_cli("parts", "list", "--real", *db)
    assert ids(r.stdout) == [rid(2)] and "2 simulated part(s) not shown" not in r.stdout
    r = run_cli("parts", "--all", "list", *db)
    assert len(ids(r.stdout)) == 4
    r = run_cli("parts", "list", "--all", "--verdict", "nok", *db)
    assert ids(r.stdout) == [rid(1)]
    assert "run not completed: incomplete" in r.stdout
    r = run_cli("parts", "list", "--all", "--job", "rw100", "--json", *db)
    rows = json.loads(r.stdout)
    assert [(p["part_id"], p["simulated"], p["reasons"]) for p in rows] == [
        (rid(1), True, ["run not completed: incomplete"]),
        (rid(3), True, []),
    ]
    since = "2026-11-29T00:14:36"  # part 2's start (T0 + 120 s)
    r = run_cli("parts", "list", "--all", "--since", since, "--last", "1", *db)
    assert ids(r.stdout) == [rid(3)]


def test_the_index_is_found_in_the_bag_dir(index: PartIndex) -> None:
    r = run_cli("parts", "list", "--bag-dir", str(index.path.parent), "--real")
    assert r.returncode == 0 and ids(r.stdout) == [rid(2)], r.stderr


def test_show_names_every_field(index: PartIndex) -> None:
    r = run_cli("parts", "show", rid(1), "--db", str(index.path))
    assert r.returncode == 0, r.stderr
    names = [line.split()[0] for line in r.stdout.splitlines() if line and not line.startswith(" ")]
    assert names == [name for name, _, _ in COLUMNS]
    assert "- run not completed: incomplete" in r.stdout
    assert f"/bags/{rid(1)}" in r.stdout
    r = run_cli("parts", "show", rid(1), "--json", "--db", str(index.path))
    assert json.loads(r.stdout)["started"] == "2026-11-29T00:13:36.000Z"


def test_measure_takes_the_verdict_again(index: PartIndex) -> None:
    part = rid(3)
    r = run_cli("parts", "measure", part, "resistance_ohm=12.9", "--db", str(index.path))
    assert r.returncode == 0, r.stderr
    assert "verdict nok: resistance_ohm 12.9 outside [11.5, 12.5]" in r.stdout
    row = index.get(part)
    assert row is not None and (row["resistance_measured_ohm"], row["verdict"]) == (12.9, "nok")
    r = run_cli("parts", "measure", part, "resistance_ohm=12.1", "--db", str(index.path))
    assert "verdict ok" in r.stdout
    row = index.get(part)
    assert row is not None and row["verdict"] == "ok"


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["measure", rid(3), "resistance_ohm=abc"], ["resistance_ohm=abc is invalid"]),
        (["measure", rid(3), "resistance_ohm=-2"], ["resistance_ohm=-2 is invalid", "> 0"]),
        (["measure", rid(3), "turns=3"], ["'turns=3'", "resistance_ohm"]),
        (["measure", "nope", "resistance_ohm=12"], ["no part 'nope'"]),
        (["show", "nope"], ["no part 'nope'"]),
        (["list", "--since", "yesterday"], ["--since 'yesterday'"]),
        (["list", "--last", "0"], ["--last 0 is invalid"]),
        (["export"], ["--csv FILE is required"]),
    ],
)
def test_bad_input_is_one_line(index: PartIndex, args: list[str], needles: list[str]) -> None:
    before = index.get(rid(3))
    assert_one_line_error(run_cli("parts", *args, "--db", str(index.path)), *needles, code=EXIT_BAD_INPUT)
    assert index.get(rid(3)) == before


def test_no_index_is_one_line(tmp_path: Path) -> None:
    r = run_cli("parts", "--bag-dir", str(tmp_path))
    assert_one_line_error(r, f"no part index at {tmp_path / 'parts.sqlite'}", code=EXIT_BAD_INPUT)


def test_export_writes_every_column(index: PartIndex, tmp_path: Path) -> None:
    out = tmp_path / "parts.csv"
    r = run_cli("parts", "export", "--csv", str(out), "--all", "--db", str(index.path))
    assert r.returncode == 0, r.stderr
    with out.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    stored = index.parts()
    assert [r["part_id"] for r in rows] == [s["part_id"] for s in stored]
    for got, want in zip(rows, stored, strict=True):
        for name, _, _ in COLUMNS:
            assert got[name] == ("" if want[name] is None else str(want[name])), name
    (tmp_path / "file").write_text("")
    r = run_cli("parts", "export", "--csv", str(tmp_path / "file" / "x.csv"), "--db", str(index.path))
    assert_one_line_error(r, "file is a file", code=EXIT_OUTPUT)


KILLED = """
import os, signal, sys
from winder.record.parts import PartIndex, PartStart
PartIndex(sys.argv[1]).begin(PartStart(run_id="killed_20261129_000000000_1", job_id="killed",
    recipe_sha256="00" * 32, recipe_source="job_text", software_version="0.1.0", consumer="sim_node",
    simulated=True, steps_total=10, started_ns=1_795_911_999_000_000_000))
os.kill(os.getpid(), signal.SIGKILL)
"""


def test_list_marks_a_killed_run_incomplete_and_says_so(index: PartIndex) -> None:
    r = subprocess.run([sys.executable, "-c", KILLED, str(index.path)], timeout=60, check=False)
    assert r.returncode == -signal.SIGKILL
    r = run_cli("parts", "list", "--db", str(index.path))
    assert "1 part(s) of runs whose process ended without closing them marked incomplete" in r.stderr
    line = next(x for x in r.stdout.splitlines() if x.startswith("killed_"))
    assert " incomplete " in line and " nok " in line
    r = run_cli("parts", "list", "--db", str(index.path))
    assert r.stderr == ""  # said once


# -- a real run writes its part ---------------------------------------------------------------

TINY_JOB = """\
interp_node:
  ros__parameters:
    job_id: tiny
    turns_per_layer: 3
    layers: 2
    poles: 1
    fork_steps_per_rev: 256
    tolerances:
      max_tracking_error_steps: [0, 1000000000]
      steps_done: [0, 1]
"""


@pytest.mark.ros
def test_a_run_writes_its_part_as_its_bag_reports_it(tmp_path: Path, procs: Procs) -> None:
    """``winder run --parts-db auto`` of a tiny job: one part, its fields those of the bag's
    final report, its verdict the job's tolerances' (``steps_done`` held to [0, 1]: nok)."""
    job = tmp_path / "tiny.yaml"
    job.write_text(TINY_JOB)
    r = winder_run(tmp_path, procs.domain, str(job), "--parts-db", "auto")
    assert r.returncode == 0, r.stdout + r.stderr
    [bag] = bags_in(tmp_path / "bags")
    final = final_report(rosbags_read(bag))
    [row] = PartIndex(tmp_path / "bags" / "parts.sqlite").parts(simulated=None)
    assert final["state"] == "done" and final["part_id"] == row["part_id"] == final["run_id"]
    assert f"  part               {row['part_id']}  (winder parts show)" in r.stdout.splitlines()
    assert (row["run_id"], row["job_id"], row["state"]) == (final["run_id"], "tiny", "done")
    assert (row["steps_done"], row["steps_total"]) == (int(final["steps_done"]), int(final["steps_total"]))
    assert row["bag"] == final["bag"] == str(bag.resolve())
    assert (row["simulated"], row["consumer"], row["software_version"]) == (1, "sim_node", __version__)
    assert (row["recipe_sha256"], row["recipe_source"]) == (
        hashlib.sha256(job.read_bytes()).hexdigest(),
        "job_file",
    )
    assert row["turns_commanded"] == 3 * 2 * 1
    assert row["ended_ns"] > row["started_ns"] and row["cycle_time_s"] > 0
    report = json.loads(row["report"])
    assert report == {k: final[k] for k in report}
    assert row["verdict"] == "nok"
    assert json.loads(row["reasons"]) == [f"steps_done {int(final['steps_done']):.6g} outside [0, 1]"]
    if "tension_peak_n" in final:
        assert row["tension_max_n"] == float(final["tension_peak_n"])
        assert row["wire_length_m"] == float(final["wire_taken_m"])


@pytest.mark.ros
def test_two_operators_runs_of_one_recipe_are_one_recipes_parts(tmp_path: Path, procs: Procs) -> None:
    """``winder run JOB --operator --wire-lot``, twice, by two operators (the
    second without a wire lot): each part names its operator and wire lot,
    as the run's summary, its bag's job description and metadata do, and
    both are parts of one recipe, the job file's SHA-256 (issue 56);
    ``winder parts list --operator`` takes the one operator's part."""
    import yaml

    job = tmp_path / "tiny.yaml"
    job.write_text(TINY_JOB)
    runs = []
    for facts in (["--operator", "Jane Doe", "--wire-lot", "L-2026/7"], ["--operator", "john"]):
        r = winder_run(tmp_path, procs.domain, str(job), *facts)
        assert r.returncode == 0, r.stdout + r.stderr
        runs.append(r.stdout)
    assert "  run of             operator Jane Doe, wire lot L-2026/7" in runs[0].splitlines(), runs[0]
    assert "  run of             operator john" in runs[1].splitlines(), runs[1]
    with sqlite3.connect(tmp_path / "bags" / "parts.sqlite") as con:
        rows = con.execute(
            "SELECT operator, wire_lot, recipe_sha256, bag FROM parts ORDER BY started_ns"
        ).fetchall()
    sha = hashlib.sha256(job.read_bytes()).hexdigest()
    assert [row[:3] for row in rows] == [("Jane Doe", "L-2026/7", sha), ("john", None, sha)]
    jane, john = (Path(row[3]) for row in rows)
    [(_, described)] = rosbags_read(jane)["/winder/job"]
    assert (described.operator_name, described.wire_lot) == ("Jane Doe", "L-2026/7")
    custom = yaml.safe_load((john / "metadata.yaml").read_text())["rosbag2_bagfile_information"][
        "custom_data"
    ]
    assert custom["winder_operator"] == "john" and "winder_wire_lot" not in custom
    listed = run_cli("parts", "list", "--bag-dir", str(tmp_path / "bags"), "--operator", "john", "--json")
    assert listed.returncode == 0, listed.stderr
    assert [p["bag"] for p in json.loads(listed.stdout)] == [str(john)]


def test_a_parts_db_that_cannot_be_one_is_refused_before_a_run(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("")
    for value, needle in (
        (str(tmp_path / "file" / "parts.sqlite"), "file is not a directory"),
        (str(tmp_path), "it is a directory, not a file"),
    ):
        r = run_cli("run", "--check", "--parts-db", value, "--bag-dir", str(tmp_path / "bags"))
        assert_one_line_error(r, "parts_db=", needle, code=EXIT_BAD_INPUT)


@pytest.mark.ros
def test_an_index_that_cannot_be_written_costs_the_run_its_part_only(tmp_path: Path, procs: Procs) -> None:
    """An index of a newer winder (it refuses to write one): the run completes, its bag is closed
    whole, its report counts the ERROR that names the index, and the index is left as it was."""
    db = tmp_path / "newer.sqlite"
    with sqlite3.connect(db) as con:
        con.execute("PRAGMA user_version = 99")
    before = db.read_bytes()
    job = tmp_path / "tiny.yaml"
    job.write_text(TINY_JOB)
    r = winder_run(tmp_path, procs.domain, str(job), "--parts-db", str(db))
    assert r.returncode == EXIT_FAILED, r.stdout + r.stderr  # a run with an error
    [bag] = bags_in(tmp_path / "bags")
    assert bag_closed(bag)
    msgs = rosbags_read(bag)
    final = final_report(msgs)
    assert final["state"] == "done" and int(final["errors"]) == 1 and "part_id" not in final
    said = [st.message for _, arr in msgs["/diagnostics"] for st in arr.status if st.level == 2]
    assert any(f"part index {db}" in m and "schema version 99 is newer" in m for m in said), said
    assert db.read_bytes() == before
