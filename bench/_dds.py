"""Helpers of bench_e2e: the raw DDS pair (two plain rclpy processes) and a
watcher of child processes' memory.

    python bench/_dds.py pub --rows N    # publisher of the raw pair
    python bench/_dds.py sub --rows N    # subscriber of the raw pair
    python bench/_dds.py relay --rows N  # middle of the raw chain (see below)

The publisher sends ceil(N / 8192) Int32MultiArray chunks of (8192, 4) int32
(what winder/steps carries) and as many Int64MultiArray chunks of (8192, 5)
int64 (winder/step_times), the last chunk partial, through the same reliable
keep-all QoS as the cell's stream topics, either as message objects
(``--form message``: rclpy serializes them) or serialized once beforehand and
published as bytes (``--form bytes``, as the nodes publish them). The subscriber takes them with
``raw=True`` (serialized bytes, no Python message objects) and counts bytes.
Each prints one JSON line with its monotonic time stamps (one clock for all
processes of the machine) and its peak resident memory (VmHWM).

The raw chain is the DDS work of a cell with no work of its own: ``pub
--steps-only`` sends the step chunks, ``relay`` takes each one and publishes
a pre-serialized step-time chunk of as many rows (what the profile node does
around its timing), ``sub --timed-only`` takes those (what the sim node takes).
Its throughput is the most any cell of three processes and these two topics
could reach on the machine.

ROS_DOMAIN_ID and ROS_AUTOMATIC_DISCOVERY_RANGE come from the environment.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

CHUNK = 8192
TOPIC_STEPS = "raw/steps"
TOPIC_TIMED = "raw/step_times"


# -- memory of processes -------------------------------------------------------
def proc_status_kb(pid: int, key: str) -> int | None:
    """``VmHWM`` / ``VmRSS`` of a process in KiB, None if it is gone."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith(key + ":"):
                return int(line.split()[1])
    except (OSError, ValueError):
        return None
    return None


def proc_cpu_s(pid: int) -> float | None:
    """User + system CPU seconds of a process, None if it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return None


def children_named(parent: int, names: tuple[str, ...]) -> dict[str, int]:
    """Children of ``parent`` whose command line mentions one of ``names``."""
    found: dict[str, int] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            ppid = int(stat.rsplit(")", 1)[1].split()[1])
            if ppid != parent:
                continue
            cmd = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except (OSError, ValueError, IndexError):
            continue
        for name in names:
            if name in cmd:
                found[name] = int(entry.name)
    return found


@dataclass
class Track:
    pid: int
    hwm_kb: int = 0  #: last VmHWM read while the process lived (its peak so far)
    cpu_s: float = 0.0  #: user + system CPU time at the last read
    samples: list[tuple[float, int, float]] = field(default_factory=list)  #: (monotonic, VmRSS KiB, CPU s)


class ChildWatch:
    """Polls the children of this process named ``names`` every ``period`` s:
    their VmRSS over time and their VmHWM, the last read taken just before
    they exit (VmHWM only grows, so that read is the peak of the whole run to
    within one period)."""

    def __init__(self, names: tuple[str, ...], period: float = 0.1) -> None:
        self.names = names
        self.period = period
        self.tracks: dict[str, Track] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> ChildWatch:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()

    def _run(self) -> None:
        me = os.getpid()
        while not self._stop.is_set():
            if len(self.tracks) < len(self.names):
                for name, pid in children_named(me, self.names).items():
                    if name not in self.tracks:
                        self.tracks[name] = Track(pid)
            now = time.monotonic()
            for tr in self.tracks.values():
                hwm = proc_status_kb(tr.pid, "VmHWM")
                rss = proc_status_kb(tr.pid, "VmRSS")
                cpu = proc_cpu_s(tr.pid)
                if hwm is not None and rss is not None and cpu is not None:
                    tr.hwm_kb = max(tr.hwm_kb, hwm)
                    tr.cpu_s = max(tr.cpu_s, cpu)
                    tr.samples.append((now, rss, cpu))
            self._stop.wait(self.period)

    def at(self, name: str, t: float) -> tuple[int, float] | None:
        """(VmRSS KiB, CPU s) of ``name`` at the last poll at or before ``t``."""
        tr = self.tracks.get(name)
        if tr is None:
            return None
        before = [(r, c) for s, r, c in tr.samples if s <= t]
        return before[-1] if before else None

    def rss_at(self, name: str, t: float) -> int | None:
        got = self.at(name, t)
        return got[0] if got else None

    def cpu_between(self, name: str, t0: float, t1: float) -> float | None:
        """CPU seconds ``name`` used between two times (to within a poll)."""
        a, b = self.at(name, t0), self.at(name, t1)
        return None if a is None or b is None else b[1] - a[1]


# -- the raw DDS pair ------------------------------------------------------------
def chunk_rows(rows: int) -> list[int]:
    full, rest = divmod(rows, CHUNK)
    return [CHUNK] * full + ([rest] if rest else [])


def _messages(n: int, form: str) -> tuple[object, object]:
    """The two chunks of n rows: message objects (rclpy serializes them on
    publish) or bytes serialized once beforehand (what the nodes publish)."""
    import numpy as np

    from winder.ros.chunks import STEPS_CDR, TIMED_CDR, pack_steps, pack_timed

    steps = np.zeros((n, 4), np.int32)
    steps[:, 2] = np.arange(1, n + 1)
    timed = np.zeros((n, 5), np.int64)
    timed[:, 0] = np.arange(1, n + 1) * 1000
    timed[:, 1:] = steps
    if form == "bytes":
        return STEPS_CDR.encode(steps), TIMED_CDR.encode(timed)
    return pack_steps(steps), pack_timed(timed)


def run_pub(
    rows: int, timeout: float, form: str = "message", timed_only: bool = False, steps_only: bool = False
) -> dict[str, float | int]:
    import rclpy
    from rclpy.duration import Duration
    from std_msgs.msg import Int32MultiArray, Int64MultiArray

    from winder.ros.qos import QOS_STREAM

    t_proc = time.monotonic()
    rclpy.init(args=[])
    node = rclpy.create_node("raw_pub")
    try:
        p32 = node.create_publisher(Int32MultiArray, TOPIC_STEPS, QOS_STREAM)
        p64 = node.create_publisher(Int64MultiArray, TOPIC_TIMED, QOS_STREAM)
        sizes = chunk_rows(rows)
        built = {n: _messages(n, form) for n in set(sizes)}  # built once: DDS cost only
        t_end = time.monotonic() + timeout
        while (p32.get_subscription_count() == 0 and not timed_only) or (
            p64.get_subscription_count() == 0 and not steps_only
        ):
            if time.monotonic() > t_end:
                raise TimeoutError("no subscriber")
            rclpy.spin_once(node, timeout_sec=0.01)
        t_start, cpu0 = time.monotonic(), time.process_time()
        for n in sizes:
            m32, m64 = built[n]
            if not timed_only:
                p32.publish(m32)
            if not steps_only:
                p64.publish(m64)
        t_sent = time.monotonic()
        left = max(t_end - time.monotonic(), 1.0)
        acked = p32.wait_for_all_acked(Duration(seconds=left)) and p64.wait_for_all_acked(
            Duration(seconds=left)
        )
        return {
            "t_proc": t_proc,
            "t_start": t_start,
            "t_sent": t_sent,
            "t_acked": time.monotonic(),
            "acked": int(acked),
            "cpu_s": time.process_time() - cpu0,  # all threads, publishing to all acknowledged
            "hwm_kb": proc_status_kb(os.getpid(), "VmHWM") or 0,
        }
    finally:
        node.destroy_node()  # type: ignore[no-untyped-call]
        rclpy.try_shutdown()  # type: ignore[attr-defined]


def run_sub(rows: int, timeout: float, timed_only: bool = False) -> dict[str, float | int]:
    import rclpy
    from std_msgs.msg import Int32MultiArray, Int64MultiArray

    from winder.ros.qos import QOS_STREAM

    t_proc = time.monotonic()
    rclpy.init(args=[])
    node = rclpy.create_node("raw_sub")
    want = len(chunk_rows(rows))
    got = {"n32": 0, "n64": 0, "bytes": 0, "first": 0.0, "last": 0.0, "cpu0": 0.0, "cpu1": 0.0}

    def on_msg(key: str, raw: Any) -> None:  # raw=True: the serialized bytes
        now = time.monotonic()
        if got["first"] == 0.0:
            got["first"], got["cpu0"] = now, time.process_time()
        got["last"], got["cpu1"] = now, time.process_time()
        got[key] += 1
        got["bytes"] += len(raw)

    try:
        if not timed_only:
            node.create_subscription(
                Int32MultiArray, TOPIC_STEPS, lambda r: on_msg("n32", r), QOS_STREAM, raw=True
            )
        node.create_subscription(
            Int64MultiArray, TOPIC_TIMED, lambda r: on_msg("n64", r), QOS_STREAM, raw=True
        )
        t_end = time.monotonic() + timeout
        while (got["n32"] < want and not timed_only) or got["n64"] < want:
            if time.monotonic() > t_end:
                break
            rclpy.spin_once(node, timeout_sec=0.05)
        return {
            "t_proc": t_proc,
            "first": got["first"],
            "last": got["last"],
            "t_done": time.monotonic(),
            "chunks": int(got["n32"] + got["n64"]),
            "chunks_expected": want if timed_only else 2 * want,
            "bytes": int(got["bytes"]),
            "cpu_s": got["cpu1"] - got["cpu0"],  # all threads, first to last chunk
            "hwm_kb": proc_status_kb(os.getpid(), "VmHWM") or 0,
        }
    finally:
        node.destroy_node()  # type: ignore[no-untyped-call]
        rclpy.try_shutdown()  # type: ignore[attr-defined]


def run_relay(rows: int, timeout: float) -> dict[str, float | int]:
    """Take each step chunk and publish a pre-serialized step-time chunk of as
    many rows (the chunks queued behind it taken in one go, as the nodes do)."""
    import rclpy
    from rclpy.duration import Duration
    from std_msgs.msg import Int32MultiArray, Int64MultiArray

    from winder.ros.chunks import waiting
    from winder.ros.qos import QOS_STREAM

    t_proc = time.monotonic()
    rclpy.init(args=[])
    node = rclpy.create_node("raw_relay")
    sizes = chunk_rows(rows)
    timed = {n: _messages(n, "bytes")[1] for n in set(sizes)}
    got = {"n": 0, "cpu0": 0.0, "cpu1": 0.0}
    try:
        p64 = node.create_publisher(Int64MultiArray, TOPIC_TIMED, QOS_STREAM)

        def relay(raw: Any) -> None:
            if got["n"] == 0:
                got["cpu0"] = time.process_time()
            for _ in (raw, *waiting(sub)):
                if got["n"] < len(sizes):
                    p64.publish(timed[sizes[int(got["n"])]])
                got["n"] += 1
            got["cpu1"] = time.process_time()

        t_end = time.monotonic() + timeout
        while p64.get_subscription_count() == 0 and time.monotonic() < t_end:
            rclpy.spin_once(node, timeout_sec=0.01)  # the subscriber first: the publisher waits for us
        sub = node.create_subscription(Int32MultiArray, TOPIC_STEPS, relay, QOS_STREAM, raw=True)
        while got["n"] < len(sizes) and time.monotonic() < t_end:
            rclpy.spin_once(node, timeout_sec=0.05)
        acked = p64.wait_for_all_acked(Duration(seconds=max(t_end - time.monotonic(), 1.0)))
        return {
            "t_proc": t_proc,
            "relayed": int(got["n"]),
            "acked": int(acked),
            "cpu_s": got["cpu1"] - got["cpu0"],
            "hwm_kb": proc_status_kb(os.getpid(), "VmHWM") or 0,
        }
    finally:
        node.destroy_node()  # type: ignore[no-untyped-call]
        rclpy.try_shutdown()  # type: ignore[attr-defined]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("role", choices=("pub", "sub", "relay"))
    ap.add_argument("--rows", type=int, required=True)
    ap.add_argument("--timeout", type=float, default=300.0)
    ap.add_argument("--form", choices=("message", "bytes"), default="message")
    ap.add_argument(
        "--timed-only",
        action="store_true",
        help="only the step-time chunks (what crosses hosts in a split cell)",
    )
    ap.add_argument("--steps-only", action="store_true", help="only the step chunks (to a relay)")
    args = ap.parse_args()
    if args.role == "pub":
        out = run_pub(args.rows, args.timeout, args.form, args.timed_only, args.steps_only)
    elif args.role == "relay":
        out = run_relay(args.rows, args.timeout)
    else:
        out = run_sub(args.rows, args.timeout, args.timed_only)
    print(json.dumps(out), flush=True)
    sys.exit(0)


if __name__ == "__main__":
    main()
