"""The ROS domains a test session may use (``WINDER_TEST_DOMAINS=A-B``),
each locked by a file in the temp directory while a test uses it, so two
pytest runs on one machine never share one."""

from __future__ import annotations

import fcntl
import itertools
import os
import tempfile
import time
from pathlib import Path
from typing import Any

import pytest

from support import wait


def _pool() -> range:
    """The ROS domains this test session may use: ``WINDER_TEST_DOMAINS=A-B``
    (inclusive; 20-219 unless set). Every test takes its domains from here,
    the conformance suite too."""
    text = os.environ.get("WINDER_TEST_DOMAINS", "20-219")
    try:
        low, high = (int(v) for v in text.split("-"))
    except ValueError:
        raise pytest.UsageError(f"WINDER_TEST_DOMAINS={text!r}: expected A-B, e.g. 20-219") from None
    if not 0 <= low <= high <= 232 or high - low < 9:
        raise pytest.UsageError(f"WINDER_TEST_DOMAINS={text!r}: need 10 or more domains within 0-232")
    return range(low, high + 1)


_held: dict[int, Any] = {}
#: the test being set up or run, and whether it is marked ``ros`` (set by conftest)
current: dict[str, Any] = {"test": "", "ros": True}
_cursor = itertools.count(os.getpid() * 7)


#: a domain handed back rests this long before anyone takes it again: a process
#: killed in it stays on the graph for the DDS lease (10 s, fastdds_profile.xml),
#: and the next test there would find its nodes (make flakes: ctl took another
#: test's fake profile node for the interp node)
QUIET_S = 12.0


def _lock_path(domain: int, kind: str) -> Path:
    return Path(tempfile.gettempdir()) / f"winder-{kind}-domain-{domain}.lock"


def lock_domain(domain: int, kind: str) -> Any:
    """The open lock file of ``domain`` for tests of ``kind`` (locked: no other
    process holds it until it is closed), or None if another process holds it
    or it was handed back less than :data:`QUIET_S` ago."""
    path = _lock_path(domain, kind)
    try:
        if time.time() - path.stat().st_mtime < QUIET_S:
            return None
    except FileNotFoundError:
        pass
    lock = path.open("a")  # not "w": opening must not touch the time it was handed back
    try:
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        lock.close()
        return None
    return lock


def next_domain(timeout: float = 120.0) -> int:
    """A ROS domain no other test process on this machine holds (a lock file
    per domain in the temp directory), held until :func:`release_domain` or
    the end of this process. Two pytest runs side by side never share one, so
    their nodes never hear each other."""
    if not current["ros"]:
        raise RuntimeError(
            f"{current['test']} takes a ROS domain but is not marked ros: "
            "mark it (@pytest.mark.ros), so that pytest -m 'not ros' starts no node"
        )
    pool = _pool()

    def free() -> list[int]:  # one look at every domain of the pool: the first free one, taken ([] if none)
        for _ in range(len(pool)):
            domain = pool[next(_cursor) % len(pool)]
            if domain in _held:
                continue
            lock = lock_domain(domain, "test")
            if lock is None:
                continue
            _held[domain] = lock
            return [domain]
        return []

    # a domain another test process releases; asked again every 0.5 s (each look opens lock files)
    what = f"free ROS domain in {pool} (all held by other test processes)"
    [domain] = wait.until(free, timeout, what, poll=0.5)
    return int(domain)


def release_domain(domain: int) -> None:
    """Hand a domain of :func:`next_domain` back (its processes are stopped)."""
    lock = _held.pop(domain, None)
    if lock is not None:
        os.utime(lock.fileno())  # handed back now: it rests QUIET_S (see lock_domain)
        lock.close()


def long_lived_domain() -> int:
    """A domain for processes that outlive one test (the session's bag runs):
    held until the end of the session."""
    return next_domain()
