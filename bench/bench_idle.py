"""What an idle cell costs: CPU of each node while no job runs.

The three nodes are started as a cell starts them (the interp node without
autostart), left to connect for 3 s, then their CPU time (user + system,
from /proc/<pid>/stat) is read over a 10 s window with no job. The anchor, in
the same run: a bare rclpy node that only spins (no timers), started the same
way; its CPU is what rclpy and DDS cost by themselves. Target: each node
below 1 % of a core.

    .venv/bin/python bench/bench_idle.py [--quick]   # --quick: a 4 s window
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import domain, table

from winder.procs import popen, stop_all

BIN = Path(sys.executable).parent
BARE = "import rclpy; rclpy.init(); rclpy.spin(rclpy.create_node('bare_node'))"


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    window = 4.0 if ap.parse_args().quick else 10.0
    work = Path(tempfile.mkdtemp(prefix="winder-bench-idle-"))
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain()), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    cmds = {
        "sim_node": [str(BIN / "sim_node"), "--ros-args", "-p", f"bag_dir:={work}"],
        "profile_node": [str(BIN / "profile_node")],
        "interp_node": [str(BIN / "interp_node"), "--ros-args", "-p", "autostart:=false"],
        "bare rclpy node (anchor)": [sys.executable, "-c", BARE],
    }
    procs = {
        name: popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for name, cmd in cmds.items()
    }
    try:
        time.sleep(3.0)  # start-up and discovery
        before = {name: cpu_seconds(p.pid) for name, p in procs.items()}
        t0 = time.monotonic()
        time.sleep(window)
        dt = time.monotonic() - t0
        after = {name: cpu_seconds(p.pid) for name, p in procs.items()}
    finally:
        stop_all(procs.values(), signal.SIGINT, 10.0)
    anchor = (after["bare rclpy node (anchor)"] - before["bare rclpy node (anchor)"]) / dt
    rows = []
    for name in cmds:
        share = (after[name] - before[name]) / dt
        rows.append([name, f"{100 * share:.2f}", f"{share / anchor:.1f}" if anchor > 0 else "-"])
    print(f"Idle cell: CPU of each node over {dt:.1f} s with no job (% of one core)")
    print(table(["node", "CPU %", "/ bare node"], rows))
    print("target: each node below 1 % of a core")


if __name__ == "__main__":
    main()
