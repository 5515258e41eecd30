"""``winder parts capability`` and ``chart``, and ``list``'s page on a big index.

The index is written with :mod:`winder.record.parts` as a consumer writes
it (begin, close with a final report, a measurement entered); the commands
run as real ``winder`` processes. The expected figures are computed here
from the values written, by the standard library's ``statistics`` and the
definitions (ISO 22514-3), never taken from the command's output.
"""

from __future__ import annotations

import csv
import json
import math
import statistics
from pathlib import Path

import pytest
from support.cli import assert_one_line_error, run_cli

from winder.cli.exits import EXIT_BAD_INPUT, EXIT_OUTPUT
from winder.motion.tolerances import Tolerances
from winder.record.parts import PartEnd, PartIndex, PartStart

T0 = 1_795_911_156_000_000_000
A, B = "a1" * 32, "b2" * 32
TOLERANCES: Tolerances = {"resistance_ohm": (11.5, 12.5), "tension_max_n": (None, 3.0)}
INCOMPLETE, OUT_OF_BAND = 17, 40


def resistance(n: int) -> float:
    return 12.6 if n == OUT_OF_BAND else 12.0 + 0.1 * math.sin(1.7 * n)


def tension(n: int) -> float:
    return round(2.5 + 0.2 * math.cos(0.9 * n), 4)


def cycle(n: int) -> float:
    return 10.0 + 0.25 * math.sin(0.37 * n)


def add(index: PartIndex, n: int, *, recipe: str = A, simulated: bool = True, tolerances: bool = True) -> str:
    job = "rw400" if recipe == A else "rw100"
    run = f"{job}_20261129_{n:09d}_{int(simulated)}"
    started = T0 + n * 60 * 10**9
    part = index.begin(
        PartStart(
            run_id=run,
            job_id=job,
            recipe_sha256=recipe,
            recipe_source="job_file",
            software_version="0.1.0",
            consumer="sim_node" if simulated else "cell1/driver",
            simulated=simulated,
            steps_total=1000,
            started_ns=started,
            turns_commanded=400,
            resistance_predicted_ohm=12.0,
            tolerances=TOLERANCES if tolerances else {},
        )
    )
    state = "incomplete" if n == INCOMPLETE and recipe == A and simulated else "done"
    report = {"state": state, "steps_done": "1000", "steps_total": "1000", "tension_peak_n": f"{tension(n)}"}
    index.close(part, PartEnd(started + round(cycle(n) * 1e9), report))
    index.measure(part, resistance(n))
    return part


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Recipe B's 5 simulated parts, recipe A's 60 simulated ones (part 17 incomplete, part 40's
    resistance out of its band), then 3 of recipe A on real axes, older than the latest simulated."""
    path = tmp_path_factory.mktemp("study") / "parts.sqlite"
    index = PartIndex(path)
    for n in range(-10, -5):
        add(index, n, recipe=B, tolerances=False)
    for n in range(60):
        add(index, n)
    for n in (20, 21, 22):
        add(index, n, simulated=False)
    return path


def expected(ns: list[int]) -> dict[str, dict[str, float | None]]:
    """The figures by the definitions over parts ``ns``."""
    out: dict[str, dict[str, float | None]] = {}
    for name, values in (
        ("resistance_ohm", [resistance(n) for n in ns]),
        ("tension_max_n", [tension(n) for n in ns]),
    ):
        lsl, usl = TOLERANCES[name]
        mean, sd = statistics.mean(values), statistics.stdev(values)
        sides = [
            s
            for s in ((usl - mean) if usl is not None else None, (mean - lsl) if lsl is not None else None)
            if s is not None
        ]
        out[name] = {
            "n": len(values),
            "mean": mean,
            "sd": sd,
            "lsl": lsl,
            "usl": usl,
            "cm": None if lsl is None or usl is None else (usl - lsl) / (6 * sd),
            "cmk": min(sides) / (3 * sd),
        }
    return out


def close_to(got: dict[str, object], want: dict[str, float | None]) -> None:
    for key, value in want.items():
        if value is None:
            assert got[key] is None, key
        else:
            assert got[key] == pytest.approx(value, rel=1e-12), key


def test_capability_takes_the_latest_50_completed_parts_of_one_kind(study: Path) -> None:
    r = run_cli("parts", "capability", "--recipe", "a1a1", "--json", "--db", str(study))
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    completed = [n for n in range(60) if n != INCOMPLETE]
    latest = completed[-50:]
    assert (doc["recipe"], doc["jobs"], doc["simulated"], doc["parts"]) == (A, ["rw400"], True, 50)
    assert (doc["first_part"], doc["last_part"]) == (
        f"rw400_20261129_{latest[0]:09d}_1",
        "rw400_20261129_000000059_1",
    )
    assert doc["left_out"] == 1  # part 17, among them, not completed
    for name, want in expected(latest).items():
        close_to(doc["scalars"][name], want)
    assert doc["scalars"]["tension_max_n"]["note"] == "one-sided: Cmk of the upper limit only"
    r = run_cli("parts", "capability", "--recipe", "a1", "--last", "59", "--json", "--db", str(study))
    doc = json.loads(r.stdout)
    assert doc["parts"] == 59 and doc["left_out"] == 1
    close_to(doc["scalars"]["resistance_ohm"], expected(completed)["resistance_ohm"])
    assert (
        doc["scalars"]["cycle_time_s"]["n"] == 59 and doc["scalars"]["cycle_time_s"]["cm"] is None
    )  # no tolerance


def test_capability_prints_a_table_and_what_it_left_out(study: Path) -> None:
    r = run_cli("parts", "capability", "--job", "rw400", "--db", str(study))
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert lines[0].startswith("recipe a1a1a1a1a1a1 (job rw400): the latest 50 completed simulated part(s)")
    assert "1 run(s) among them not completed, left out" in lines[0]
    want = expected([n for n in range(60) if n != INCOMPLETE][-50:])["resistance_ohm"]
    row = next(line.split() for line in lines if line.startswith("resistance_ohm "))
    assert row[1:] == [
        "50",
        f"{want['mean']:.6g}",
        f"{want['sd']:.4g}",
        "11.5",
        "12.5",
        f"{want['cm']:.2f}",
        f"{want['cmk']:.2f}",
    ]
    tension_row = next(line for line in lines if line.startswith("tension_max_n "))
    assert " - " in tension_row and tension_row.endswith("one-sided: Cmk of the upper limit only")
    assert "3 real part(s) of this recipe not taken: --real, or --all" in lines


def test_twin_and_real_parts_are_mixed_only_when_asked(study: Path) -> None:
    db = ["--db", str(study)]
    r = run_cli("parts", "capability", "--recipe", "a1", "--all", "--last", "62", "--json", *db)
    doc = json.loads(r.stdout)
    assert doc["simulated"] is None and doc["parts"] == 62  # 59 simulated and 3 real, completed
    r = run_cli("parts", "capability", "--recipe", "a1", "--real", *db)
    assert_one_line_error(
        r, "recipe a1a1a1a1a1a1 (job rw400) has 3 real part(s)", "at least 30", code=EXIT_BAD_INPUT
    )


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        ([], ["the parts chosen hold 2 recipes", "a1a1a1a1a1a1 (rw400, 60 parts)", "--recipe SHA256"]),
        (
            ["--job", "rw100"],
            ["at least 30 completed parts", "b2b2b2b2b2b2 (job rw100) has 5 simulated part(s)"],
        ),
        (["--recipe", "a1", "--verdict", "ok"], ["--verdict ok cannot choose the parts of a capability"]),
        (["--recipe", "a1", "--last", "20"], ["--last 20 is invalid: a capability takes at least 30 parts"]),
        (["--recipe", "xyz"], ["recipe 'xyz' is invalid: expected a prefix of a SHA-256"]),
        (["--recipe", "a1", "--scalar", "nope"], ["--scalar nope is not recorded", "resistance_ohm"]),
        (["--recipe", "c3"], ["no parts in", "for --recipe c3"]),
    ],
)
def test_capability_refuses_in_one_line(study: Path, args: list[str], needles: list[str]) -> None:
    assert_one_line_error(
        run_cli("parts", "capability", *args, "--db", str(study)), *needles, code=EXIT_BAD_INPUT
    )


def test_chart_draws_the_toleranced_scalars(study: Path, tmp_path: Path) -> None:
    out = tmp_path / "chart.png"
    r = run_cli("parts", "chart", "--recipe", "a1", "--out", str(out), "--db", str(study))
    assert r.returncode == 0, r.stderr
    assert f"control chart of 2 scalar(s) written to {out}" in r.stdout
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    r = run_cli("parts", "chart", "--job", "rw100", "--out", str(tmp_path / "b.png"), "--db", str(study))
    assert_one_line_error(
        r, "recipe b2b2b2b2b2b2 has no tolerances to chart", "--scalar", code=EXIT_BAD_INPUT
    )
    r = run_cli(
        "parts",
        "chart",
        "--job",
        "rw100",
        "--scalar",
        "cycle_time_s",
        "--out",
        str(tmp_path / "b.png"),
        "--db",
        str(study),
    )
    assert r.returncode == 0 and (tmp_path / "b.png").exists(), r.stderr
    (tmp_path / "file").write_text("")
    r = run_cli(
        "parts", "chart", "--recipe", "a1", "--out", str(tmp_path / "file" / "c.png"), "--db", str(study)
    )
    assert_one_line_error(r, "c.png", code=EXIT_OUTPUT)
    assert_one_line_error(
        run_cli("parts", "chart", "--db", str(study)), "--out FILE.png is required", code=EXIT_BAD_INPUT
    )


def test_list_shows_the_latest_page_and_export_every_part(tmp_path: Path) -> None:
    index = PartIndex(tmp_path / "parts.sqlite")
    for n in range(105):
        index.close(
            index.begin(
                PartStart(
                    run_id=f"p_20261129_{n:09d}_1",
                    job_id="p",
                    recipe_sha256=A,
                    recipe_source="job_file",
                    software_version="0.1.0",
                    consumer="sim_node",
                    simulated=True,
                    steps_total=1,
                    started_ns=T0 + n,
                )
            ),
            PartEnd(T0 + n + 1, {"state": "done", "steps_done": "1"}),
        )
    db = ["--db", str(index.path)]
    r = run_cli("parts", "list", *db)
    shown = [line.split()[0] for line in r.stdout.splitlines() if line.startswith("p_")]
    assert shown == [f"p_20261129_{n:09d}_1" for n in range(5, 105)]
    assert "part index" in r.stdout and ": 105 simulated part(s)" in r.stdout
    assert "the latest 100 of 105 part(s) shown: --last N for more, winder parts export for all" in r.stdout
    r = run_cli("parts", "list", "--json", *db)
    assert len(json.loads(r.stdout)) == 100 and "the latest 100 of 105" in r.stderr
    assert len(json.loads(run_cli("parts", "list", "--json", "--last", "105", *db).stdout)) == 105
    r = run_cli("parts", "export", "--csv", str(tmp_path / "all.csv"), *db)
    with (tmp_path / "all.csv").open(newline="") as fh:
        assert len(list(csv.DictReader(fh))) == 105


def test_chart_names_a_toleranced_scalar_no_part_recorded(tmp_path: Path) -> None:
    index = PartIndex(tmp_path / "parts.sqlite")
    for n in range(3):
        start = PartStart(
            run_id=f"t_20261129_{n:09d}_1",
            job_id="t",
            recipe_sha256=A,
            recipe_source="job_file",
            software_version="0.1.0",
            consumer="sim_node",
            simulated=True,
            steps_total=1,
            started_ns=T0 + n * 10**9,
            tolerances={"turns_error": (0.0, 0.0), "cycle_time_s": (None, 5.0)},
        )
        index.close(index.begin(start), PartEnd(T0 + n * 10**9 + (n + 1) * 10**8, {"state": "done"}))
    out = tmp_path / "t.png"
    r = run_cli("parts", "chart", "--out", str(out), "--db", str(index.path))
    assert r.returncode == 0, r.stderr
    assert f"control chart of 1 scalar(s) written to {out}" in r.stdout
    assert "not charted, recorded by none of these parts: turns_error" in r.stdout
    r = run_cli("parts", "chart", "--scalar", "turns_error", "--out", str(out), "--db", str(index.path))
    assert_one_line_error(r, "no part of these recorded turns_error: nothing to chart", code=EXIT_BAD_INPUT)
