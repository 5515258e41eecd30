"""Every run leaves its part (docs/PARTS.md), and the part is named where a
user looks: ``winder run`` with its defaults adds one row to
``<bag_dir>/parts.sqlite``, its summary names the part and the index, the
bag's final report names both, and ``winder analyze`` on the bag names the
part as the index holds it; ``--parts-db none`` keeps no index at all.

Oracles: the bag the run wrote (read by rosbags), the index read with
Python's own sqlite3 (not winder's reader), and the paths the test chose.
"""

from __future__ import annotations

import json
import re
import shutil
import sqlite3
from pathlib import Path

import pytest
from conftest import Procs, final_report, rosbags_read
from support.cell import SMALL_JOB, job_args, winder_run
from support.cli import run_cli

from winder.record.bag import bags_in

pytestmark = pytest.mark.ros


def rows(index: Path) -> list[sqlite3.Row]:
    with sqlite3.connect(f"{index.as_uri()}?mode=ro", uri=True) as con:
        con.row_factory = sqlite3.Row
        return con.execute("SELECT * FROM parts").fetchall()


def test_a_default_run_leaves_its_part_beside_its_bag(tmp_path: Path, procs: Procs) -> None:
    r = winder_run(tmp_path, procs.domain, *job_args(SMALL_JOB))
    assert r.returncode == 0, r.stdout + r.stderr
    bags = tmp_path / "bags"
    [bag] = bags_in(bags)  # the index beside it is no bag
    index = bags / "parts.sqlite"
    [row] = rows(index)
    final = final_report(rosbags_read(bag))
    assert (row["state"], row["verdict"], row["job_id"]) == ("done", "ok", "small")
    assert row["run_id"] == final["run_id"] == bag.name
    assert row["bag"] == str(bag.resolve())
    # the bag's final report names the part and its index; the summary says both
    assert final["part_id"] == row["part_id"] and final["part_index"] == str(index.resolve())
    lines = r.stdout.splitlines()
    assert f"  part               {row['part_id']}  (winder parts show)" in lines, r.stdout
    assert f"  part index         {index.resolve()}" in lines, r.stdout

    # winder analyze names it, as the index holds it: in its table and its JSON
    a = run_cli("analyze", str(bag), "--no-plots")
    assert a.returncode == 0, a.stdout + a.stderr
    named = [line for line in a.stdout.splitlines() if line.startswith("part ")]
    assert len(named) == 1 and re.fullmatch(rf"part\s+{row['part_id']} \(ok\)", named[0]), a.stdout
    j = run_cli("analyze", str(bag), "--no-plots", "--json")
    assert j.returncode == 0, j.stdout + j.stderr
    [told] = json.loads(j.stdout)
    assert told["part"] == {
        "part_id": row["part_id"],
        "index": str(index.resolve()),
        "state": "done",
        "verdict": "ok",
        "reasons": [],
    }

    # the bag directory moved whole (the index the report names is gone): the index beside the bag
    moved = tmp_path / "moved"
    shutil.move(bags, moved)
    j = run_cli("analyze", str(moved / bag.name), "--no-plots", "--json")
    assert j.returncode == 0, j.stdout + j.stderr
    assert json.loads(j.stdout)[0]["part"]["index"] == str(moved / "parts.sqlite")
    # no index that holds it: no part named
    (moved / "parts.sqlite").unlink()
    a = run_cli("analyze", str(moved / bag.name), "--no-plots")
    assert a.returncode == 0 and not re.search(r"^part ", a.stdout, re.M), a.stdout


def test_parts_db_none_keeps_no_index(tmp_path: Path, procs: Procs) -> None:
    r = winder_run(tmp_path, procs.domain, *job_args(SMALL_JOB), "--parts-db", "none")
    assert r.returncode == 0, r.stdout + r.stderr
    bags = tmp_path / "bags"
    [bag] = bags_in(bags)
    assert sorted(p.name for p in bags.iterdir()) == [bag.name]  # the bag, nothing beside it
    assert not Path("none").exists()  # "none" is no file's name either
    final = final_report(rosbags_read(bag))
    assert "part_id" not in final and "part_index" not in final
    assert not [line for line in r.stdout.splitlines() if line.lstrip().startswith("part")], r.stdout
    a = run_cli("analyze", str(bag), "--no-plots")
    assert a.returncode == 0 and not re.search(r"^part ", a.stdout, re.M), a.stdout
