"""Shared helpers of the benchmarks: best-of timing and a plain table."""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence


def domains() -> range:
    """The ROS domains the benchmarks may use: ``WINDER_BENCH_DOMAINS=A-B``
    (inclusive; 221-232 unless set: clear of the tests' default 20-219, of
    ``winder run``'s random 100-199; Fast DDS allows 0-232). The benchmarks
    run one at a time, each taking its domains in order from the first."""
    text = os.environ.get("WINDER_BENCH_DOMAINS", "221-232")
    try:
        low, high = (int(v) for v in text.split("-"))
    except ValueError:
        raise SystemExit(f"WINDER_BENCH_DOMAINS={text!r}: expected A-B, e.g. 221-232") from None
    if not 0 <= low <= high <= 232:
        raise SystemExit(f"WINDER_BENCH_DOMAINS={text!r}: need domains within 0-232")
    return range(low, high + 1)


def domain(i: int = 0) -> int:
    """The ``i``-th domain of :func:`domains` (cycling when there are fewer)."""
    pool = domains()
    return pool[i % len(pool)]


def ros_env(domain: int) -> dict[str, str]:
    """The environment of a process on ROS ``domain`` with localhost discovery
    and winder's Fast DDS profile: the cell's nodes load it themselves, and the
    bare rclpy processes of an anchor get it here, so that both run on the
    same middleware settings (discovery timing, heartbeat period)."""
    from winder.ros.dds import use_profile

    env = {**os.environ, "ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    use_profile(env)
    return env


def best_of(fn: Callable[[], object], repeat: int = 5, min_time: float = 0.0) -> float:
    """Smallest wall time of ``repeat`` calls (the least disturbed by a noisy machine)."""
    best = float("inf")
    spent = 0.0
    runs = 0
    while runs < repeat or spent < min_time:
        t0 = time.perf_counter()
        fn()
        dt = time.perf_counter() - t0
        best = min(best, dt)
        spent += dt
        runs += 1
    return best


def table(headers: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    cells = [[str(h) for h in headers]] + [[str(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(headers))]
    lines = ["  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)
