"""The part index's cost (issue 56): writing a part against the run it
records, answering on 10^5 parts, bytes per part.

    .venv/bin/python bench/bench_parts.py [--quick] [--parts N]   # --quick: 10^4 parts

(a) **Write.** The default job (``winder run``, every default, ``--parts-db
auto``) runs once, as fast as possible; the anchor is that run's wall time
(its part's ``cycle_time_s``: the run's start to its close, where the
consumer writes the part), the whole command's, and the job's time at real
time (its ``sim_time_s``: what winding it takes a machine). Then the part
itself, ``begin`` and ``close`` with the run's own final report as the
consumer calls them, 200 times into the big index of (b): mean, 99th
percentile and worst (WAL checkpoints fall in the mean), and the mean as a
share of each anchor.

(b) **Read.** An index of N parts (10^5) made from that part: its row
copied with its numbers jittered (Gaussian, a few % of each), one a minute;
recipe A (job rw400) 90 %, recipe B (job rw100) 5 % simulated, recipe A on
real axes 5 %. Each command as a process, best of 3 wall times, against
``winder parts --help`` (the same process and imports, no index read); and
in this process the command's function alone, against ``SELECT *`` of the
95 % simulated rows with sqlite3 (reading them once). What a user asks:
``list`` (the latest 100 of a kind, of a job, a day's real parts since a
time), ``capability`` and ``chart`` of recipe A (its latest 50 completed
parts, ISO 22514-3's study); then, once each, everything at once: ``list``
of all 95 % and ``capability`` over all 90 %.

(c) **Size.** The file's bytes per part at 10^3, 10^4 and 10^5 parts (after
a WAL checkpoint: the file alone).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import random
import shutil
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from _common import best_of, domain, ros_env, table

from winder.record.parts import COLUMNS, PartEnd, PartIndex, PartStart

BIN = Path(sys.executable).parent
RECIPE_A, RECIPE_B = "a1" * 32, "b2" * 32


def default_run(work: Path) -> tuple[dict[str, Any], float]:
    """The default job run once by ``winder run --parts-db auto``: its part's row, the command's wall time."""
    bags = work / "bags"
    cmd = [str(BIN / "winder"), "run", "--bag-dir", str(bags), "--parts-db", "auto"]
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, env=ros_env(domain()), timeout=600, check=False)
    wall = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({r.returncode}): {r.stdout[-2000:]}{r.stderr[-2000:]}")
    [row] = PartIndex(bags / "parts.sqlite").parts()
    return row, wall


def jitter(value: Any, rng: random.Random) -> Any:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return value
    if isinstance(value, int):
        return value
    return value * (1.0 + rng.gauss(0.0, 0.03))


def fill(path: Path, model: dict[str, Any], upto: int, have: int, rng: random.Random) -> None:
    """Parts ``have`` .. ``upto - 1`` added to ``path``, copies of ``model`` (one transaction)."""
    names = [name for name, _, _ in COLUMNS]
    report = json.loads(model["report"])
    t0 = int(model["started_ns"])
    rows = []
    for n in range(have, upto):
        kind = n % 20
        recipe, job, simulated = (
            (RECIPE_B, "rw100", 1)
            if kind == 0
            else (RECIPE_A, "rw400", 0)
            if kind == 1
            else (RECIPE_A, "rw400", 1)
        )
        run = f"{job}_20261129_{n:09d}_1"
        rep = {
            k: (f"{float(v) * (1.0 + rng.gauss(0.0, 0.03)):.6g}" if _is_float(v) else v)
            for k, v in report.items()
        }
        rep.update(run_id=run, part_id=run, job_id=job, bag=f"/bags/{run}")
        row = {k: jitter(model[k], rng) for k in names}
        row.update(
            part_id=run,
            run_id=run,
            job_id=job,
            recipe_sha256=recipe,
            simulated=simulated,
            started_ns=t0 + n * 60 * 10**9,
            ended_ns=t0 + n * 60 * 10**9 + int(model["ended_ns"]) - t0,
            report=json.dumps(rep, sort_keys=True),
            bag=f"/bags/{run}",
            resistance_measured_ohm=12.0 + rng.gauss(0.0, 0.08),
            tolerances=json.dumps({"resistance_ohm": [11.5, 12.5], "cycle_time_s": [None, 60.0]}),
        )
        rows.append([row[k] for k in names])
    con = sqlite3.connect(path, isolation_level=None)
    con.execute("BEGIN IMMEDIATE")
    con.executemany(f"INSERT INTO parts ({', '.join(names)}) VALUES ({', '.join('?' * len(names))})", rows)
    con.execute("COMMIT")
    con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    con.close()


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return "." in text or "e" in text


def day(model: dict[str, Any], total: int) -> str:
    """``--since`` for the last day of the index: its last 1440 parts (one a minute), 72 real."""
    return time.strftime("%Y-%m-%dT%H:%M", time.gmtime(int(model["started_ns"]) / 1e9 + (total - 1440) * 60))


def cli_best(args: list[str], repeat: int = 3) -> float:
    cmd = [str(BIN / "winder"), *args]

    def run() -> None:
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stdin=subprocess.DEVNULL)

    return best_of(run, repeat=repeat)


def in_process(args: list[str], repeat: int = 3) -> float:
    """Best of ``repeat`` of the command's function in this process, its output thrown away."""
    from winder.cli.parts import register

    parser = argparse.ArgumentParser()
    register(parser.add_subparsers(dest="command"))
    ns = parser.parse_args(args)

    def run() -> None:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            ns.func(ns)

    return best_of(run, repeat=repeat)


def select_all(path: Path, simulated: int) -> float:
    def run() -> None:
        con = sqlite3.connect(path)
        con.execute("SELECT * FROM parts WHERE simulated = ? ORDER BY started_ns", (simulated,)).fetchall()
        con.close()

    return best_of(run, repeat=3)


def writes(path: Path, model: dict[str, Any], times: int) -> list[float]:
    """``begin`` + ``close`` of the model part, ``times`` times, each timed (s)."""
    index = PartIndex(path)
    report = json.loads(model["report"])
    tolerances = {k: (lo, hi) for k, (lo, hi) in json.loads(model["tolerances"] or "{}").items()}
    spent = []
    for n in range(times):
        start = PartStart(
            run_id=f"bench_{n}",
            job_id=model["job_id"],
            recipe_sha256=model["recipe_sha256"],
            recipe_source=model["recipe_source"],
            software_version=model["software_version"],
            consumer=model["consumer"],
            simulated=bool(model["simulated"]),
            steps_total=model["steps_total"],
            started_ns=time.time_ns(),
            bag=model["bag"],
            turns_commanded=model["turns_commanded"],
            resistance_predicted_ohm=model["resistance_predicted_ohm"],
            tolerances=tolerances,
        )
        t0 = time.perf_counter()
        part = index.begin(start)
        index.close(part, PartEnd(time.time_ns(), report))
        spent.append(time.perf_counter() - t0)
    return spent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="10^4 parts")
    ap.add_argument("--parts", type=int, default=None, help="parts of the big index (default 10^5)")
    a = ap.parse_args()
    total = a.parts or (10**4 if a.quick else 10**5)
    work = Path(tempfile.mkdtemp(prefix="bench_parts_"))
    try:
        model, command_wall = default_run(work)
        run_wall = float(model["cycle_time_s"])
        real_time = float(json.loads(model["report"])["sim_time_s"])
        print(
            f"default job: {model['steps_total']} steps, {real_time:.1f} s at real time; run as fast as "
            f"possible {run_wall:.2f} s (its part's cycle_time_s), the whole command {command_wall:.2f} s; "
            f"report {len(model['report'])} bytes of JSON\n"
        )

        # (c) size, while (b)'s index is filled
        big = work / "big.sqlite"
        PartIndex(big).recover()  # the schema
        rng = random.Random(56)
        sizes, have = [], 0
        for upto in (10**3, 10**4, 10**5, total):
            if upto > total or upto <= have:
                continue
            t0 = time.perf_counter()
            fill(big, model, upto, have, rng)
            made = time.perf_counter() - t0
            have = upto
            size = big.stat().st_size
            sizes.append([f"{upto:,}", f"{size / 2**20:.1f}", f"{size / upto:.0f}", f"{made:.1f}"])
        print("(c) the file's size")
        print(table(["parts", "MiB", "bytes/part", "made in s"], sizes))

        # (b) reads
        db = ["--db", str(big)]
        base_cli = cli_best(["parts", "--help"])
        floor = select_all(big, 1)
        cases = [
            ("list (the latest 100 simulated)", ["parts", "list", *db], 3),
            ("list --job rw100 (the latest 100)", ["parts", "list", "--job", "rw100", *db], 3),
            (
                "list --real --since (a day: 72)",
                ["parts", "list", "--real", "--since", day(model, total), *db],
                3,
            ),
            ("capability --recipe A (the latest 50)", ["parts", "capability", "--recipe", "a1a1", *db], 3),
            ("chart --recipe A (the latest 50)", ["parts", "chart", "--recipe", "a1a1", *db], 3),
            (f"list --last {total} (all 95 %)", ["parts", "list", "--last", str(total), *db], 1),
            (
                f"capability --last {total} (all 90 %)",
                ["parts", "capability", "--recipe", "a1", "--last", str(total), *db],
                1,
            ),
        ]
        rows = []
        for label, args, repeat in cases:
            if args[1] == "chart":
                args = [*args, "--out", str(work / "chart.png")]
            inner = in_process(args, repeat)
            outer = cli_best(args, repeat)
            rows.append(
                [label, f"{inner:.3f}", f"{inner / floor:.2f}", f"{outer:.2f}", f"{outer - base_cli:+.2f}"]
            )
        print(
            f"\n(b) answers on {total:,} parts; anchors: SELECT * of the 95 % simulated rows {floor:.3f} s, "
            f"winder parts --help {base_cli:.2f} s (best of 3 each)"
        )
        print(table(["command", "in-process s", "x SELECT *", "process s", "over --help s"], rows))

        # (a) writes, into the big index
        spent = writes(big, model, 200)
        mean = statistics.fmean(spent)
        p99 = sorted(spent)[int(0.99 * len(spent)) - 1]
        real_time = float(json.loads(model["report"])["sim_time_s"])
        print(f"\n(a) writing a part (begin + close, 200 times into the {total:,}-part index)")
        print(
            table(
                [
                    "mean ms",
                    "p99 ms",
                    "worst ms",
                    "mean / run",
                    "mean / whole command",
                    "mean / job at real time",
                ],
                [
                    [
                        f"{mean * 1e3:.2f}",
                        f"{p99 * 1e3:.2f}",
                        f"{max(spent) * 1e3:.2f}",
                        f"{100 * mean / run_wall:.3f} %",
                        f"{100 * mean / command_wall:.3f} %",
                        f"{100 * mean / real_time:.4f} %",
                    ]
                ],
            )
        )
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    main()
