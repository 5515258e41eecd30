"""Reading big recordings back: ``winder analyze`` and ``winder identify`` on
bags of 1e6 and 1e7 steps (they stream the step rows).

The bags are recorded by the three real nodes (the end-to-end benchmark's
jobs: FAST ramp, joint states at 200 Hz, lz4 chunks). Each command runs as
its own process; its wall time and peak resident memory (``wait4``) are
printed. The anchor, in the same run: the ``mcap`` library reading every
message of the same file (decompression and record parsing, no decoding),
best of 3. The target of the issue: peak memory under 300 MB at 1e7 steps and
flat from 1e6 up; time linear in the bag (the ratio to the anchor constant).

    .venv/bin/python bench/bench_analysis.py [--quick]   # --quick: 1e5 and 1e6
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from _common import best_of, domain, table
from bench_e2e import CHUNK_STEPS, FAST, PUBLISH_RATE, SIZES

from winder.motion.job import Job
from winder.procs import popen

COMMANDS = {
    "analyze --no-plots": ["analyze", "--no-plots"],
    "analyze (with plots)": ["analyze"],
    "identify --no-plots": ["identify", "--no-plots"],
}


def record(label: str, job_fields: dict[str, Any], work: Path, domain: int) -> Path:
    from winder.ros.cell import run_cell

    params = {
        "interp": {**Job(**job_fields).to_dict(), "chunk_steps": CHUNK_STEPS},
        "profile": dict(FAST),
        "sim": {"publish_rate": PUBLISH_RATE, "bag_dir": str(work), "record": True},
    }
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    res = run_cell(params, domain=domain, timeout=900)
    if not res.summary or res.summary.get("state") != "done":
        raise SystemExit(f"{label}: the recording run failed: {res.message}")
    return Path(res.summary["bag"])


def measure(args: list[str], bag: Path, plots: Path) -> tuple[float, float]:
    """Wall time (s) and peak RSS (MiB) of ``winder ARGS BAG``."""
    exe = Path(sys.executable).with_name("winder")
    cmd = [str(exe), *args, str(bag)]
    if "--no-plots" not in args:
        cmd += ["--plots-dir", str(plots)]
    t0 = time.perf_counter()
    proc = popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    dt = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        err = proc.stderr.read().decode() if proc.stderr else ""
        raise SystemExit(f"{' '.join(cmd)} failed: {err.strip()}")
    return dt, usage.ru_maxrss / 1024


def mcap_read(bag: Path) -> float:
    from mcap.reader import make_reader

    files = sorted(bag.glob("*.mcap"))

    def read() -> None:
        for f in files:
            with f.open("rb") as fh:
                for _ in make_reader(fh).iter_messages():
                    pass

    return best_of(read, repeat=3)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    sizes = [s for s in SIZES if s[0] in (("1e5", "1e6") if args.quick else ("1e5", "1e6", "1e7"))]
    work = Path(tempfile.mkdtemp(prefix="winder-bench-analysis-"))
    rows = []
    before: dict[str, tuple[int, float]] = {}
    try:
        for n, (label, job_fields) in enumerate(sizes):
            bag = record(label, job_fields, work / "bags", domain(n))
            size = sum(f.stat().st_size for f in bag.iterdir()) / 2**20
            anchor = mcap_read(bag)
            steps = Job(**job_fields).total_steps
            for name, cmd in COMMANDS.items():
                dt, rss = measure(cmd, bag, work / "plots")
                prev = before.get(name)
                # the time each further million steps adds (start-up and fixed costs cancel)
                per = f"{(dt - prev[1]) / (steps - prev[0]) * 1e6:.2f}" if prev else "-"
                before[name] = (steps, dt)
                cells = [label, f"{size:.0f}", name, f"{dt:.2f}", per, f"{rss:.0f}", f"{anchor:.2f}"]
                rows.append([*cells, f"{dt / anchor:.1f}"])
            shutil.rmtree(bag)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print("Reading recordings back: wall time and peak RSS of each command (its own process)")
    print("anchor: the mcap library iterating every message of the same file (best of 3)")
    heads = ["steps", "bag MiB", "command", "s", "s per 1e6 more", "peak MiB", "anchor s", "time / anchor"]
    print(table(heads, rows))
    print("target: peak < 300 MB at 1e7 and flat from 1e6; time linear: s per 1e6 more constant")


if __name__ == "__main__":
    main()
