"""winder.record.parts, the part index, and winder.motion.tolerances, the verdict.

No ROS: the index is a plain SQLite file. The expected values are the
inputs given (a report's keys, a tolerance's ends), the kill is a real
SIGKILL of a real process that began a part, the concurrency four real
processes writing one file, and the verdict's oracle a plain restatement
of the rule (complete, no faults, every scalar within its range).
"""

from __future__ import annotations

import json
import math
import os
import signal
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from winder.errors import BadInputError
from winder.motion.tolerances import check_tolerances, verdict
from winder.record import parts as parts_mod
from winder.record.parts import SCHEMA_VERSION, PartEnd, PartIndex, PartIndexError, PartStart

RUN = "rw400_20261129_001236875_1"


def start(run_id: str = RUN, **kw: object) -> PartStart:
    base: dict[str, object] = {
        "run_id": run_id,
        "job_id": "rw400",
        "recipe_sha256": "ab" * 32,
        "recipe_source": "job_file",
        "software_version": "0.1.0",
        "consumer": "sim_node",
        "simulated": True,
        "steps_total": 40960,
        "started_ns": 1_795_911_156_000_000_000,
        "bag": f"/bags/{run_id}",
        "turns_commanded": 400,
        "resistance_predicted_ohm": 12.0,
    }
    base.update(kw)
    return PartStart(**base)  # type: ignore[arg-type]


def report(state: str = "done", **kw: str) -> dict[str, str]:
    base = {
        "state": state,
        "job_id": "rw400",
        "run_id": RUN,
        "steps_done": "40960" if state == "done" else "6559",
        "steps_total": "40960",
        "tension_peak_n": "2.5",
        "tension_min_n": "0.8",
        "wire_taken_m": "31.25",
        "tension_outside_warning_s": "0.000",
        "tension_outside_alarm_s": "0.000",
        "max_tracking_error_steps": "0.4000",
        "bag": f"/bags/{RUN}",
    }
    base.update(kw)
    return base


END_NS = 1_795_911_166_500_000_000  # 10.5 s after the start


def test_a_part_is_running_then_closed_with_its_report(tmp_path: Path) -> None:
    index = PartIndex(tmp_path / "parts.sqlite")
    part_id = index.begin(start())
    assert part_id == RUN
    row = index.get(part_id)
    assert row is not None
    assert (row["state"], row["verdict"], row["ended_ns"], row["simulated"]) == ("running", None, None, 1)
    assert row["pid"] == os.getpid()
    closed = index.close(part_id, PartEnd(END_NS, report()))
    row = index.get(part_id)
    assert row == {k: closed[k] for k in row}
    assert row["state"] == "done" and row["verdict"] == "ok" and json.loads(row["reasons"]) == []
    assert row["cycle_time_s"] == pytest.approx(10.5)
    assert (row["steps_done"], row["steps_total"]) == (40960, 40960)
    assert (row["wire_length_m"], row["tension_max_n"], row["tension_min_n"]) == (31.25, 2.5, 0.8)
    assert (row["breaks"], row["slips"]) == (0, 0)
    erred = index.close(index.begin(start()), PartEnd(END_NS, report(errors="1")))
    assert (erred["verdict"], json.loads(erred["reasons"])) == ("nok", ["1 error(s) in the run's report"])
    assert json.loads(row["report"]) == report()
    with sqlite3.connect(tmp_path / "parts.sqlite") as con:
        assert con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        assert con.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION


def test_a_run_id_taken_by_another_cell_gets_a_suffix(tmp_path: Path) -> None:
    index = PartIndex(tmp_path / "parts.sqlite")
    assert [index.begin(start()) for _ in range(3)] == [RUN, f"{RUN}-2", f"{RUN}-3"]


def test_a_wire_break_is_nok_with_its_reasons(tmp_path: Path) -> None:
    index = PartIndex(tmp_path / "parts.sqlite")
    fault = "wire break at coil 1 layer 2 turn 30 (1.250 s into the run): the tension fell"
    part_id = index.begin(start(tolerances={"tension_max_n": (0.0, 2.0)}))
    row = index.close(part_id, PartEnd(END_NS, report("incomplete", faults=fault)))
    assert row["verdict"] == "nok" and row["breaks"] == 1 and row["slips"] == 0
    reasons = json.loads(row["reasons"])
    assert reasons[0] == "run not completed: incomplete"
    assert fault in reasons[1]
    assert reasons[2] == "tension_max_n 2.5 outside [0, 2]"


def test_a_driver_without_wire_has_no_break_count(tmp_path: Path) -> None:
    index = PartIndex(tmp_path / "parts.sqlite")
    part_id = index.begin(start(simulated=False, consumer="cell1/driver"))
    bare = {k: v for k, v in report().items() if not k.startswith(("tension", "wire"))}
    row = index.close(part_id, PartEnd(END_NS, bare))
    assert (row["breaks"], row["slips"], row["wire_length_m"], row["simulated"]) == (None, None, None, 0)
    assert row["verdict"] == "ok"


def test_measure_takes_the_verdict_again(tmp_path: Path) -> None:
    index = PartIndex(tmp_path / "parts.sqlite")
    part_id = index.begin(start(tolerances={"resistance_ohm": (11.5, 12.5)}))
    row = index.close(part_id, PartEnd(END_NS, report()))
    assert row["verdict"] == "ok"  # the predicted 12.0 ohm
    row = index.measure(part_id, 13.0)
    assert row["verdict"] == "nok"
    assert json.loads(row["reasons"]) == ["resistance_ohm 13 outside [11.5, 12.5]"]
    stored = index.get(part_id)
    assert stored is not None and (stored["verdict"], stored["resistance_measured_ohm"]) == ("nok", 13.0)
    assert index.measure(part_id, 12.2)["verdict"] == "ok"
    with pytest.raises(BadInputError, match="no part 'nope'"):
        index.measure("nope", 1.0)


def test_an_unmeasured_resistance_is_judged_by_its_prediction_and_said_so(tmp_path: Path) -> None:
    index = PartIndex(tmp_path / "parts.sqlite")
    part_id = index.begin(start(tolerances={"resistance_ohm": (13.0, 14.0), "turns_error": (0.0, 0.0)}))
    row = index.close(part_id, PartEnd(END_NS, report()))
    assert json.loads(row["reasons"]) == [
        "resistance_ohm (predicted; not measured yet) 12 outside [13, 14]",
        "turns_error not recorded: its tolerance [0, 0] cannot be checked",
    ]


KILLED = """
import os, signal, sys
from winder.record.parts import PartIndex, PartStart
index = PartIndex(sys.argv[1])
index.begin(PartStart(run_id=sys.argv[2], job_id="rw400", recipe_sha256="00" * 32, recipe_source="job_text",
                      software_version="0.1.0", consumer="sim_node", simulated=True, steps_total=10,
                      started_ns=1))
os.kill(os.getpid(), signal.SIGKILL)
"""


def test_a_killed_run_is_found_incomplete_and_a_live_one_is_left_alone(tmp_path: Path) -> None:
    path = tmp_path / "parts.sqlite"
    index = PartIndex(path)
    live = index.begin(start("live_20261129_000000000_1"))  # this process: alive
    r = subprocess.run([sys.executable, "-c", KILLED, str(path), RUN], timeout=60, check=False)
    assert r.returncode == -signal.SIGKILL
    killed = index.get(RUN)
    assert killed is not None and killed["state"] == "running"
    assert index.recover() == [RUN]
    row = index.get(RUN)
    assert row is not None and (row["state"], row["verdict"]) == ("incomplete", "nok")
    assert "ended without closing it" in json.loads(row["reasons"])[0]
    assert index.recover() == []  # said once
    still = index.get(live)
    assert still is not None and still["state"] == "running"


WRITER = """
import sys
from winder.record.parts import PartEnd, PartIndex, PartStart
index = PartIndex(sys.argv[1])
for n in range(int(sys.argv[3])):
    run = f"{sys.argv[2]}_20261129_000000000_{n}"
    part = index.begin(PartStart(run_id=run, job_id=sys.argv[2], recipe_sha256="00" * 32,
                                 recipe_source="job_text", software_version="0.1.0", consumer=sys.argv[2],
                                 simulated=True, steps_total=10, started_ns=n))
    index.close(part, PartEnd(n + 1, {"state": "done", "steps_done": "10", "steps_total": "10"}))
"""


def test_four_cells_writing_one_index_lose_nothing(tmp_path: Path) -> None:
    path = tmp_path / "parts.sqlite"
    each = 25
    procs = [
        subprocess.Popen([sys.executable, "-c", WRITER, str(path), f"cell{c}", str(each)]) for c in range(4)
    ]
    assert [p.wait(timeout=300) for p in procs] == [0, 0, 0, 0]
    rows = PartIndex(path).parts()
    assert len(rows) == 4 * each
    assert {r["state"] for r in rows} == {"done"} and {r["verdict"] for r in rows} == {"ok"}
    with sqlite3.connect(path) as con:
        assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"


def test_a_migration_runs_from_the_version_before(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """An index of this version brought to a (test's) next version keeps its parts and gets the
    new column (test/record/test_parts_concurrency.py: version 1 to 2, the real migration)."""
    path = tmp_path / "parts.sqlite"
    index = PartIndex(path)
    first = index.begin(start())
    now, nxt = SCHEMA_VERSION, SCHEMA_VERSION + 1

    def added(con: sqlite3.Connection) -> None:
        con.execute("ALTER TABLE parts ADD COLUMN shift TEXT")

    monkeypatch.setattr(parts_mod, "MIGRATIONS", {**parts_mod.MIGRATIONS, nxt: added})
    monkeypatch.setattr(parts_mod, "SCHEMA_VERSION", nxt)
    with pytest.raises(PartIndexError, match=f"schema version {now}, expected {nxt}"):
        index.get(first)  # a reader does not write
    assert index.recover() == []  # a writer brings it up to date
    row = index.get(first)
    assert row is not None and row["shift"] is None and row["run_id"] == RUN
    with sqlite3.connect(path) as con:
        assert con.execute("PRAGMA user_version").fetchone()[0] == nxt


def test_an_index_of_a_newer_winder_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "parts.sqlite"
    with sqlite3.connect(path) as con:
        con.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    before = path.read_bytes()
    with pytest.raises(PartIndexError, match=f"schema version {SCHEMA_VERSION + 1} is newer"):
        PartIndex(path).begin(start())
    assert path.read_bytes() == before  # not even put in WAL mode


def test_an_index_that_cannot_be_written_is_one_line_naming_it(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("")
    path = tmp_path / "file" / "parts.sqlite"
    with pytest.raises(PartIndexError) as err:
        PartIndex(path).begin(start())
    assert str(path) in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(PartIndexError, match="no such file"):
        PartIndex(tmp_path / "none.sqlite").parts()


# -- tolerances and the verdict ---------------------------------------------------------


@pytest.mark.parametrize(
    ("doc", "needle"),
    [
        ([1, 2], "tolerances is [1, 2]: expected a map"),
        ({"resistance_ohm": [2, 1]}, "tolerances.resistance_ohm=[2, 1] is invalid"),
        ({"resistance_ohm": [1]}, "tolerances.resistance_ohm=[1] is invalid"),
        ({"resistance_ohm": [1, "x"]}, 'tolerances.resistance_ohm=[1, "x"] is invalid'),
        ({"resistance_ohm": [math.inf, 5]}, "tolerances.resistance_ohm=[Infinity, 5] is invalid"),
        ({"resistance_ohm": [0, -math.inf]}, "tolerances.resistance_ohm=[0, -Infinity] is invalid"),
        ({"resistance_ohm": [None, None]}, "tolerances.resistance_ohm=[null, null] is invalid"),
        ({"resistance_ohm": [True, 2]}, "tolerances.resistance_ohm=[true, 2] is invalid"),
        ({"Bad-Name": [0, 1]}, "tolerances.Bad-Name is not a scalar's name"),
    ],
)
def test_bad_tolerances_are_refused_in_one_line(doc: object, needle: str) -> None:
    with pytest.raises(BadInputError) as err:
        check_tolerances(doc)
    assert needle in str(err.value) and "\n" not in str(err.value)


finite = st.floats(-1e6, 1e6, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(
    state=st.sampled_from(["done", "aborted", "incomplete"]),
    faults=st.sampled_from(["", "emergency stop"]),
    checks=st.dictionaries(
        st.sampled_from(["resistance_ohm", "tension_max_n", "cycle_time_s", "turns_error"]),
        st.tuples(finite, finite, st.one_of(st.none(), finite)),
        max_size=4,
    ),
)
def test_the_verdict_is_ok_iff_complete_without_faults_and_within_every_tolerance(
    state: str, faults: str, checks: dict[str, tuple[float, float, float | None]]
) -> None:
    tolerances = {k: (min(a, b), max(a, b)) for k, (a, b, _) in checks.items()}
    scalars = {k: v for k, (_, _, v) in checks.items()}
    held = [v is not None and tolerances[k][0] <= v <= tolerances[k][1] for k, v in scalars.items()]
    expect_ok = state == "done" and not faults and all(held)
    said, reasons = verdict(state, scalars, tolerances, faults)
    assert said == ("ok" if expect_ok else "nok")
    assert len(reasons) == (state != "done") + bool(faults) + held.count(False)
    assert check_tolerances({k: list(v) for k, v in tolerances.items()}) == tolerances


def test_no_tolerances_is_ok_iff_complete() -> None:
    assert verdict("done", {}, {}) == ("ok", [])
    assert verdict("done", {}, {}, errors=2) == ("nok", ["2 error(s) in the run's report"])
    assert verdict("aborted", {}, {}) == ("nok", ["run not completed: aborted"])
    assert check_tolerances(None) == {}


def test_the_docs_schema_table_names_every_column() -> None:
    """The schema table of docs/PARTS.md lists the columns of the code's table, in order."""
    doc = (Path(__file__).parents[2] / "docs" / "PARTS.md").read_text()
    schema = doc.split("\n## The schema\n", 1)[1].split("\n## ", 1)[0]
    listed = [line.split("`")[1] for line in schema.splitlines() if line.startswith("| `")]
    assert listed == [name for name, _, _ in parts_mod.COLUMNS]


# -- the recipe's tolerances, through the job and its description to the part -------------------

TOLERANCE_JOB = """\
interp_node:
  ros__parameters:
    job_id: tol
    turns_per_layer: 4
    layers: 1
    poles: 1
    bobbin: {window_width: 0.012, core_diameter: 0.02}
    tolerances:
      resistance_ohm: [0.001, 100]
      tension_max_n: [0, 50]
"""


def test_a_job_files_tolerances_reach_the_part(tmp_path: Path) -> None:
    from winder.contract.jobfile import load_job_file_hashed
    from winder.contract.stream import describe_job, parse_job_description
    from winder.motion.job import Job
    from winder.record.parts import part_start

    path = tmp_path / "tol.yaml"
    path.write_text(TOLERANCE_JOB)
    doc, sha = load_job_file_hashed(path)
    job = Job.from_dict(doc["interp_node"])
    plan = parse_job_description(describe_job(job, "tol_20261129_000000000_1", job_file_sha256=sha))
    part = part_start(
        plan, consumer="sim_node", simulated=True, software_version="0.1.0", started_ns=1, bag=""
    )
    assert part.tolerances == {"resistance_ohm": (0.001, 100.0), "tension_max_n": (0.0, 50.0)}
    assert (part.recipe_sha256, part.recipe_source) == (sha, "job_file")
    assert part.resistance_predicted_ohm is not None and part.turns_commanded == 4


def test_the_canonical_job_text_is_the_recipe_without_a_file() -> None:
    from winder.contract.stream import describe_job, parse_job_description
    from winder.motion.job import Job
    from winder.record.parts import recipe_sha256

    def sha(job: Job, run: str) -> tuple[str, str]:
        return recipe_sha256(parse_job_description(describe_job(job, run)))

    a = sha(Job.from_dict({"job_id": "a", "layers": 1, "poles": 1}), "a_20261129_000000000_1")
    b = sha(Job.from_dict({"poles": 1, "job_id": "a", "layers": 1}), "a_20261129_000000001_2")
    c = sha(Job.from_dict({"job_id": "a", "layers": 1, "poles": 2}), "a_20261129_000000002_3")
    assert a == b and a[1] == "job_text" and len(a[0]) == 64 and c[0] != a[0]


def test_a_job_without_tolerances_describes_as_before() -> None:
    from winder.contract.stream import describe_job
    from winder.motion.job import Job

    assert '"tolerances"' not in describe_job(Job())
    assert '"tolerances"' in describe_job(Job.from_dict({"tolerances": {"turns_error": [0, 0]}}))


@pytest.mark.parametrize(
    ("value", "needle"),
    [
        ("xx", 'tolerances="xx" is invalid: not a JSON map'),
        ('{"r": [3, 1]}', "tolerances.r=[3, 1] is invalid"),
        (5, "tolerances='5' is invalid"),
        ("[1, 2]", "tolerances is [1, 2]: expected a map"),
    ],
)
def test_a_bad_tolerances_field_is_one_line(value: object, needle: str) -> None:
    from winder.motion.job import Job, JobError

    with pytest.raises(JobError) as err:
        Job.from_dict({"tolerances": value})
    assert needle in str(err.value) and "\n" not in str(err.value)


def test_parts_db_names_the_index(tmp_path: Path) -> None:
    from winder.contract.params import CONSUMER_SPECS
    from winder.record.parts import index_path

    assert CONSUMER_SPECS["parts_db"].default == "auto"  # every run leaves its part beside its bag
    assert index_path("", tmp_path) is None
    assert index_path("auto", tmp_path) == tmp_path / "parts.sqlite"
    assert index_path("auto", None) is None  # a consumer that does not record
    assert index_path("~/x.sqlite", None) == Path.home() / "x.sqlite"
