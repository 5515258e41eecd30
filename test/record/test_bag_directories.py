"""What a bag in a bag directory is (winder.record.bag.bags_in): its
subdirectories but the hidden ones. The part index that every run now
leaves beside its bags (parts.sqlite, with SQLite's -wal and -shm while it
is open), a staging directory of a bag being opened and any stray file are
no bag; and the index named as a bag (``winder analyze bags/*``) is refused
in one line that says what it is.

No ROS: the directories are made here, the index by Python's sqlite3 in WAL
mode as the consumer makes it, and held open so that its -wal and -shm are
there too.
"""

from __future__ import annotations

import sqlite3
from pathlib import Path

from support.cli import assert_one_line_error, run_cli

from winder.record.bag import bags_in, unclosed_bags


def test_a_bag_directory_lists_its_bags_and_nothing_else(tmp_path: Path) -> None:
    bags = tmp_path / "bags"
    for name in ("rw400_20261129_000000000_2", "rw400_20261129_000000000_1", ".x.opening-123"):
        (bags / name).mkdir(parents=True)
        (bags / name / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (bags / "notes.txt").write_text("not a bag\n")
    con = sqlite3.connect(bags / "parts.sqlite")  # held open: its -wal and -shm stay beside it
    try:
        con.execute("PRAGMA journal_mode = WAL")
        con.execute("CREATE TABLE parts (part_id TEXT)")
        con.execute("INSERT INTO parts VALUES ('a')")
        con.commit()
        names = sorted(p.name for p in bags.iterdir())
        assert {"parts.sqlite", "parts.sqlite-wal", "parts.sqlite-shm"} <= set(names), names
        assert [p.name for p in bags_in(bags)] == ["rw400_20261129_000000000_1", "rw400_20261129_000000000_2"]
        assert bags_in(tmp_path / "none") == []  # no directory, no bags
        assert unclosed_bags(bags) == []  # the index is not looked into as a bag either
    finally:
        con.close()


def test_the_part_index_named_as_a_bag_is_refused_saying_what_it_is(tmp_path: Path) -> None:
    index = tmp_path / "parts.sqlite"
    with sqlite3.connect(index) as con:
        con.execute("CREATE TABLE parts (part_id TEXT)")
    r = run_cli("analyze", str(index), "--no-plots")
    assert_one_line_error(r, f"{index}: an SQLite file (the part index?), not a bag", f"--db {index}")
