"""The flake finder (``make flakes``): the node tests (``-m ros``) ``--rounds``
times (default 3), each round beside a busy loop pinned to one core at
``nice 10``, then each test that failed with the number of rounds it failed
in. No retry: a failure counts as a failure.

Exit status: 0 when no test failed in any round, 1 otherwise, 2 on bad options.
Each round's JUnit XML and pytest output are kept under ``--out`` (default: a
new directory in the temp directory), named in the summary.

Not a test module (its name does not start with ``test_``): pytest does not collect it.
"""

from __future__ import annotations

import argparse
import collections
import os
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BUSY = "import os\nos.nice(10)\nwhile True:\n    pass\n"


def busy_loop() -> subprocess.Popen[bytes]:
    """A CPU-bound process at nice 10 on the first core this process may use."""
    core = min(os.sched_getaffinity(0))
    p = subprocess.Popen([sys.executable, "-c", BUSY], stdin=subprocess.DEVNULL)
    os.sched_setaffinity(p.pid, {core})
    return p


def failures(junit: Path) -> tuple[int, list[str]]:
    """The number of tests of a round and the ids of those that failed or errored."""
    root = ET.parse(junit).getroot()
    total, failed = 0, []
    for case in root.iter("testcase"):
        total += 1
        if case.find("failure") is not None or case.find("error") is not None:
            failed.append(f"{case.get('classname', '')}::{case.get('name', '')}")
    return total, failed


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="flakes", description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=3, help="rounds of the node tests (default 3)")
    ap.add_argument("--workers", type=int, default=4, help="pytest-xdist workers (default 4)")
    ap.add_argument("--out", type=Path, default=None, help="where each round's output goes")
    ap.add_argument("-k", dest="select", default="", help="only tests matching this pytest -k expression")
    ap.add_argument("paths", nargs="*", help="test files or directories (default: the whole suite)")
    args = ap.parse_args(argv)
    if not 1 <= args.rounds <= 100:
        print(f"flakes: --rounds={args.rounds} is out of range: must be in [1, 100]", file=sys.stderr)
        return 2
    if not 1 <= args.workers <= 32:
        print(f"flakes: --workers={args.workers} is out of range: must be in [1, 32]", file=sys.stderr)
        return 2
    out = args.out or Path(tempfile.mkdtemp(prefix="winder-flakes-"))
    out.mkdir(parents=True, exist_ok=True)
    counts: collections.Counter[str] = collections.Counter()
    print(f"flakes: {args.rounds} round(s) of the node tests beside a busy loop, {args.workers} workers")
    for r in range(1, args.rounds + 1):
        junit = out / f"round-{r}.xml"
        select = ["-k", args.select] if args.select else []
        cmd = [sys.executable, "-m", "pytest", "-m", "ros", "-n", str(args.workers), "--dist", "loadfile"]
        cmd += ["-q", "-p", "no:cacheprovider", f"--junitxml={junit}", *select, *args.paths]
        loop = busy_loop()
        t0 = time.monotonic()
        try:
            with (out / f"round-{r}.log").open("wb") as log:
                code = subprocess.call(
                    cmd, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL
                )
        finally:
            loop.kill()
            loop.wait()
        took = time.monotonic() - t0
        if not junit.exists():
            print(f"  round {r}: pytest wrote no report (exit {code}); see {out / f'round-{r}.log'}")
            counts["<round without a report>"] += 1
            continue
        total, failed = failures(junit)
        counts.update(failed)
        print(f"  round {r}: {total} tests, {len(failed)} failed, {took / 60:.1f} min")
    print(f"flakes: output in {out}")
    if not counts:
        print(f"flakes: no test failed in {args.rounds} round(s)")
        return 0
    print(f"flakes: {len(counts)} test(s) failed:")
    for test, n in counts.most_common():
        print(f"  {n} of {args.rounds}  {test}")
    return 1


if __name__ == "__main__":
    sys.exit(main())
