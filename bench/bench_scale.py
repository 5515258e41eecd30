"""Scale-out: start-up, many cells on one graph, a cell across
hosts. Each figure is a ratio against an anchor measured in the same run.

    .venv/bin/python bench/bench_scale.py [--quick] [--parts startup,cells,hosts] [--cells 1,2,4,8]
        [--one-process]   # part 2: each cell one winder_container process

1. Start-up. ``winder run`` of a one-layer job, spawn to first step (the sim
   node's ``wall_start_ns`` in ``winder/sim_config``, the wall clock when the
   job started there, minus the wall clock just before the spawn), and the
   whole command, against two bare rclpy processes (a publisher and a
   subscriber, spawned together: spawn to the first message received). Best
   and median of several runs.
2. Many cells. N cells (N = 1, 2, 4, 8: ``winder run --namespace /cK``, all
   on one ROS domain at once), each a job of 164 608 steps: every one must
   complete with every step and record only its own topics; aggregate steps/s
   (all steps / first spawn to last exit) against N = 1, and each cell's
   spawn-to-first-step.
3. Across hosts. Two network namespaces joined by a veth link (bench/_netns.py;
   skipped, with the reason, where the machine forbids it): the sim node on
   host b, ``winder run --external sim`` (interp and profile nodes) on host a,
   discovery by static peers, so the step times cross the link over UDP.
   Steady steps/s (the sim node's job time) against raw DDS over the same link
   (bench/_dds.py: publisher on a, subscriber on b, the same chunks and QoS),
   clean and with packet loss (0.1 %, 1 %), a 100 Mbit/s rate limit and 1 ms
   and 5 ms one-way delay (netem where the kernel has it, else a delay line:
   TUN devices and a relay process, bench/_delayline.py); the stream
   checker's figures (missing steps, gaps) from the run.
The fourth scale-out figure, end-to-end throughput at 10^7 steps on one
host, is bench/bench_e2e.py's.
"""

from __future__ import annotations

import itertools
import json
import math
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from _common import domains, ros_env, table
from _netns import Hosts

from winder.procs import popen

HERE = Path(__file__).resolve().parent
BIN = Path(sys.executable).parent
QUICK = "--quick" in sys.argv


def _option(name: str) -> str:
    return sys.argv[sys.argv.index(name) + 1] if name in sys.argv[:-1] else ""


#: --cells 2,2,8: the cell counts of part 2 (default 1,2,4,8; --quick 1,2,4)
CELLS = tuple(int(c) for c in _option("--cells").split(",") if c)
#: --parts startup,cells,hosts: which parts run (default all three)
PARTS = set(_option("--parts").split(",")) - {""} or {"startup", "cells", "hosts"}
#: --one-process: the cells of part 2 each run as one winder_container process (winder run --one-process)
ONE_PROCESS = ["--one-process"] if "--one-process" in sys.argv else []
#: ROS domains of this benchmark, one after the other (_common.domains, cycling)
DOMAINS = itertools.cycle(domains())
FAST = ["--v-max", "1e6", "--a-max", "1e9", "--j-max", "1e12"]


def summary_of(out: str) -> dict[str, str]:
    """The figures of ``winder run``'s summary lines."""
    got: dict[str, str] = {}
    m = re.search(r"steps\s+(\d+) of (\d+)\s+\(missing (\d+), gaps (\d+)\)", out)
    if m:
        got.update(done=m[1], total=m[2], missing=m[3], gaps=m[4])
    m = re.search(r"bag\s+(\S+)", out)
    if m:
        got["bag"] = m[1]
    m = re.search(r"ERROR reports\s+(.+)", out) or re.search(r"^winder run: (.+)$", out, re.M)
    if m:
        got["why"] = m[1].strip()
    return got


def wall_start(bag: str) -> int:
    """wall_start_ns of the run: when the job started at the sim node."""
    from winder.record.reader import read_run

    cfg = read_run(bag).sim_config
    return cfg.wall_start_ns if cfg else 0


# -- 1. start-up -----------------------------------------------------------------------
PAIR = """
import sys, time, rclpy
from std_msgs.msg import String
rclpy.init()
n = rclpy.create_node(sys.argv[1])
if sys.argv[1] == "pub":
    p = n.create_publisher(String, "ping", 10)
    while True:
        p.publish(String(data="x")); rclpy.spin_once(n, timeout_sec=0.01)
else:
    got = []
    n.create_subscription(String, "ping", lambda m: got.append(time.time_ns()), 10)
    while not got:
        rclpy.spin_once(n, timeout_sec=0.01)
    print(got[0])
"""


def bare_pair(domain: int) -> float:
    """Spawn to the first message between two bare rclpy processes (s)."""
    env = ros_env(domain)
    t0 = time.time_ns()
    pub = popen([sys.executable, "-c", PAIR, "pub"], env=env, stdout=subprocess.DEVNULL)
    sub = subprocess.run([sys.executable, "-c", PAIR, "sub"], env=env, capture_output=True, text=True)
    pub.kill()
    pub.wait()
    return (int(sub.stdout.strip()) - t0) / 1e9


def winder_start(domain: int, bags: Path, job: list[str]) -> tuple[float, float]:
    """``winder run``: (spawn to first step, whole command) in s."""
    t0 = time.time_ns()
    r = subprocess.run(
        [str(BIN / "winder"), "run", *job, "--bag-dir", str(bags)],
        env=ros_env(domain),
        capture_output=True,
        text=True,
        timeout=300,
    )
    t1 = time.time_ns()
    if r.returncode != 0:
        raise RuntimeError(r.stdout + r.stderr)
    return (wall_start(summary_of(r.stdout)["bag"]) - t0) / 1e9, (t1 - t0) / 1e9


def startup(tmp: Path) -> None:
    reps = 3 if QUICK else 7
    domain = next(DOMAINS)
    pair = [bare_pair(domain) for _ in range(reps)]
    small = ["--turns-per-layer", "2", "--poles", "1", "--layers", "1"]
    modes: list[tuple[str, list[str]]] = [("", []), (" --one-process", ["--one-process"])]
    runs: dict[str, list[tuple[float, float]]] = {}
    for mode, _ in modes:
        runs[f"1 layer{mode}"], runs[f"default job{mode}"] = [], []
    for i in range(reps):
        for mode, extra in modes:  # alternated, run by run
            runs[f"1 layer{mode}"].append(winder_start(domain, tmp / "startup", [*small, *extra]))
            if i < max(3, reps // 2):
                runs[f"default job{mode}"].append(winder_start(domain, tmp / "startup", extra))
    anchor = statistics.median(pair)
    rows = [["bare rclpy pair: spawn -> first message", f"{min(pair):.3f}", f"{anchor:.3f}", "1.00"]]
    for what, got in runs.items():
        rows.append([f"winder run, {what}: spawn -> first step", *_stats([s for s, _ in got], anchor)])
        rows.append([f"winder run, {what}: whole command", *_stats([w for _, w in got], anchor)])
    print(f"1. start-up ({reps} runs each; ratio of medians against the bare pair)")
    print(table(["what", "best s", "median s", "x pair"], rows))


def _stats(xs: list[float], anchor: float) -> list[str]:
    med = statistics.median(xs)
    return [f"{min(xs):.3f}", f"{med:.3f}", f"{med / anchor:.2f}"]


# -- 2. many cells ---------------------------------------------------------------------
def many_cells(tmp: Path) -> None:
    from winder.record.raw import read_raw
    from winder.record.reader import read_run

    counts = CELLS or ((1, 2, 4) if QUICK else (1, 2, 4, 8))
    job = ["--turns-per-layer", "100", "--poles", "4", "--layers", "2", *FAST]  # 819 200 steps each
    rows = []
    base = 0.0
    for n in counts:
        domain = next(DOMAINS)
        bags = ["--bag-dir", str(tmp / f"n{n}")]
        t0 = time.time_ns()
        procs = [
            popen(
                [str(BIN / "winder"), "run", "--namespace", f"/c{k}", *job, *ONE_PROCESS, *bags],
                env=ros_env(domain),
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                text=True,
            )
            for k in range(n)
        ]
        outs = [p.communicate(timeout=900)[0] for p in procs]
        steps, starts, spans, problems = 0, [], [], []
        for k, (p, out) in enumerate(zip(procs, outs, strict=True)):
            s = summary_of(out)
            if p.returncode != 0 or s.get("done") != s.get("total") or s.get("missing") != "0":
                why = (
                    s.get("why")
                    or f"{s.get('done', '?')} of {s.get('total', '?')} steps, missing {s.get('missing')}"
                )
                problems.append(f"/c{k}: exit {p.returncode}: {why}")
                continue
            steps += int(s["done"])
            run = read_run(s["bag"])
            start = run.sim_config.wall_start_ns if run.sim_config else t0
            starts.append((start - t0) / 1e9)
            spans.append((start, start + float(run.report.get("wall_time_s", "nan")) * 1e9))
            foreign = [t for t in read_raw(s["bag"], keep=lambda _t: False).topics() if not _own(t, k)]
            if foreign:
                problems.append(f"/c{k}: its bag holds other cells' topics {foreign}")
        busy = (max(e for _, e in spans) - min(b for b, _ in spans)) / 1e9 if spans else math.nan
        rate = steps / busy
        base = base or rate
        rows.append(
            [
                n,
                f"{steps}",
                f"{rate / 1e6:.2f}",
                f"{rate / base:.2f}",
                f"{min(starts):.2f}-{max(starts):.2f}" if starts else "-",
                "ok" if not problems else "; ".join(problems),
            ]
        )
    how = ", each cell one process (--one-process)" if ONE_PROCESS else ""
    print(f"\n2. many cells on one graph (819 200 steps each, fast ramp; aggregate over the jobs' span{how})")
    heads = ["cells", "steps", "M steps/s", "x 1 cell", "spawn->first step s", "every step, own topics"]
    print(table(heads, rows))


def _own(topic: str, k: int) -> bool:
    return topic == "/diagnostics" or topic.startswith(f"/c{k}/")


# -- 3. across hosts -------------------------------------------------------------------
def across_hosts(tmp: Path) -> None:
    hosts = Hosts("bs")
    why = hosts.up()
    print("\n3. a cell across two hosts (network namespaces, veth link, static peers)")
    if why:
        print(f"   skipped: {why}")
        return
    try:
        steps = 1 << 19 if QUICK else 1 << 21
        layers = steps // (100 * 1024 * 4)
        job = ["--turns-per-layer", "100", "--poles", "4", "--layers", str(max(layers, 1)), *FAST]
        cases: list[tuple[str, dict[str, float]]] = [
            ("clean link", {}),
            ("loss 0.1 %", {"loss": 0.001}),
            ("loss 1 %", {"loss": 0.01}),
            ("100 Mbit/s", {"rate_mbit": 100}),
            ("delay 1 ms", {"delay_ms": 1}),
            ("delay 5 ms", {"delay_ms": 5}),
        ]

        rows = []
        for name, shaping in cases:
            why = hosts.shape(**shaping)
            link = hosts
            if why and "delay_ms" in shaping:  # no netem here: a link through a delay line instead
                link = Hosts("bd", delay_ms=shaping["delay_ms"])
                why = link.up()
                name += " (delay line)"
            if why:
                rows.append([name, "-", "-", "-", "-", "-", why])
                continue
            try:
                rows += _across_rows(link, name, steps, job, tmp)
            finally:
                if link is not hosts:
                    link.down()
        heads = ["link", "profile", "raw DDS M rows/s", "cell M steps/s", "x raw", "stream checker", "note"]
        print(table(heads, rows))
    finally:
        hosts.down()


def _across_rows(hosts: Hosts, name: str, steps: int, job: list[str], tmp: Path) -> list[list[str]]:
    """Raw DDS and the cell over ``hosts``' link, with each profile: one row each."""
    from winder.ros.dds import LAN_PROFILE, PROFILE

    rows = []
    for label, profile in (("default", PROFILE), ("lan", LAN_PROFILE)):
        extra = {"FASTRTPS_DEFAULT_PROFILES_FILE": str(profile)}
        raw = raw_across(hosts, steps, extra)
        cell = cell_across(hosts, job, tmp, extra)
        ratio = cell["rate"] / raw if raw else float("nan")
        rows.append(
            [
                name,
                label,
                f"{raw / 1e6:.2f}" if raw else "incomplete",
                f"{cell['rate'] / 1e6:.2f}",
                f"{ratio:.2f}",
                f"{cell['done']}/{cell['total']}, missing {cell['missing']}, gaps {cell['gaps']}",
                f"{cell['link_mb']:.0f} MB over the link",
            ]
        )
    return rows


def raw_across(hosts: Hosts, rows: int, extra: dict[str, str]) -> float:
    """Raw DDS rows/s from host a to host b (first publish to last chunk in)."""
    domain = next(DOMAINS)
    dds = [sys.executable, str(HERE / "_dds.py")]
    sub = popen(
        hosts.command("b", [*dds, "sub", "--rows", str(rows), "--timeout", "120", "--timed-only"]),
        env={**hosts.env("b", ros_env(domain)), **extra},
        stdout=subprocess.PIPE,
        text=True,
    )
    pub = subprocess.run(
        hosts.command(
            "a", [*dds, "pub", "--rows", str(rows), "--timeout", "120", "--form", "bytes", "--timed-only"]
        ),
        env={**hosts.env("a", ros_env(domain)), **extra},
        capture_output=True,
        text=True,
        timeout=300,
    )
    out = json.loads(sub.communicate(timeout=300)[0].strip().splitlines()[-1])
    start = json.loads(pub.stdout.strip().splitlines()[-1])["t_start"]
    if out["chunks"] != out["chunks_expected"]:
        return 0.0
    return rows / (out["last"] - start)


def cell_across(hosts: Hosts, job: list[str], tmp: Path, extra: dict[str, str]) -> dict[str, Any]:
    """The sim node on host b, the rest of the cell on host a; steady steps/s."""
    domain = next(DOMAINS)
    bags = tmp / f"across{domain}"
    sim = popen(
        hosts.command("b", [str(BIN / "sim_node"), "--ros-args", "-p", f"bag_dir:={bags}"]),
        env={**hosts.env("b", ros_env(domain)), **extra},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        rx0 = hosts.rx_bytes("b")
        r = subprocess.run(
            hosts.command("a", [str(BIN / "winder"), "run", "--external", "sim", *job, "--timeout", "120"]),
            env={**hosts.env("a", ros_env(domain)), **extra},
            capture_output=True,
            text=True,
            timeout=600,
        )
        link = hosts.rx_bytes("b") - rx0
    finally:
        sim.send_signal(2)
        sim.wait(timeout=30)
    s = summary_of(r.stdout)
    if "done" not in s or "bag" not in s:  # the run did not finish (winder run --timeout)
        why = (r.stderr.strip().splitlines() or ["no summary"])[-1][:60]
        return {"done": "0", "total": "?", "missing": "?", "gaps": why, "rate": 0.0, "link_mb": link / 1e6}
    from winder.record.reader import read_run

    run = read_run(s["bag"])
    job_s = float(run.report.get("wall_time_s", "nan"))
    return {**s, "rate": int(s["done"]) / job_s, "link_mb": link / 1e6}


def main() -> None:
    with tempfile.TemporaryDirectory(prefix="winder-scale-") as d:
        tmp = Path(d)
        for name, part in (("startup", startup), ("cells", many_cells), ("hosts", across_hosts)):
            if name in PARTS:
                part(tmp)


if __name__ == "__main__":
    main()
