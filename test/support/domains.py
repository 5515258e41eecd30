"""The ROS domains a test session may use (``WINDER_TEST_DOMAINS=A-B``),
each locked by a file in the temp directory while a test uses it, so two
pytest runs on one machine never share one.

A domain is held only while processes run on it: a test hands back every
domain it took (conftest checks it after each test, :func:`check_handed_back`),
and a fixture that outlives a test keeps what its processes made (a bag is a
file), not their domain; only :data:`BETWEEN_TESTS` domain may stay held from
one test to the next. So the pytest workers of ``make test`` (4) never hold
the whole pool between them, and the documented minimum of 10 domains is
enough (one worker once held all 10 for its session bags, and every later
node test failed "no free ROS domain")."""

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
#: who took each domain held: the test, and the scope of the fixture that took it ("function": the test)
_takers: dict[int, tuple[str, str]] = {}
#: the test being set up or run, whether it is marked ``ros``, and the scope
#: of the fixture being set up ("function" outside one) (set by conftest)
current: dict[str, Any] = {"test": "", "ros": True, "scope": "function"}
#: domains a process may hold from one test to the next: a module fixture's
#: whose processes serve every test of the module (test_docs_commands'
#: checkout); four workers then hold four at most between tests
BETWEEN_TESTS = 1
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


def take_domain() -> int | None:
    """A ROS domain no other test process on this machine holds, taken (as
    :func:`next_domain`), or None at once if each is held or resting: one
    look at every domain of the pool, each look opening its lock file."""
    if not current["ros"]:
        raise RuntimeError(
            f"{current['test']} takes a ROS domain but is not marked ros: "
            "mark it (@pytest.mark.ros), so that pytest -m 'not ros' starts no node"
        )
    pool = _pool()
    for _ in range(len(pool)):
        domain = pool[next(_cursor) % len(pool)]
        if domain in _held:
            continue
        lock = lock_domain(domain, "test")
        if lock is None:
            continue
        _held[domain] = lock
        _takers[domain] = (current["test"], current["scope"])
        return domain
    return None


def next_domain(timeout: float = 120.0) -> int:
    """A ROS domain no other test process on this machine holds (a lock file
    per domain in the temp directory), held until :func:`release_domain`
    (by the end of the test that took it, or of the fixture). Two pytest runs
    side by side never share one, so their nodes never hear each other."""

    def free() -> list[int]:  # the domain taken, in a list (domain 0 is false)
        domain = take_domain()
        return [] if domain is None else [domain]

    # a domain another test process releases; asked again every 0.5 s (each look opens lock files)
    what = f"free ROS domain in {_pool()} (all held by other test processes)"
    [domain] = wait.until(free, timeout, what, poll=0.5, heard=lambda: f"this process holds {held()}")
    return int(domain)


def release_domain(domain: int) -> None:
    """Hand a domain of :func:`next_domain` back (its processes are stopped)."""
    lock = _held.pop(domain, None)
    _takers.pop(domain, None)
    if lock is not None:
        os.utime(lock.fileno())  # handed back now: it rests QUIET_S (see lock_domain)
        lock.close()


def held() -> dict[int, tuple[str, str]]:
    """The domains this process holds: who took each (the test, the scope)."""
    return dict(_takers)


def check_handed_back(test: str) -> None:
    """After ``test`` and its teardown: every domain it or a function-scoped
    fixture of it took is handed back, and no more than
    :data:`BETWEEN_TESTS` stay held by wider fixtures. A domain the test left
    held is handed back here, and AssertionError names the test and what it
    held: a domain held past its test is one fewer for every worker to the
    end of the session."""
    left = sorted(d for d, who in held().items() if who == (test, "function"))
    for domain in left:
        release_domain(domain)
    wider = held()
    problems = [f"{left} that it took, not handed back (released now)"] if left else []
    if len(wider) > BETWEEN_TESTS:
        problems.append(f"{wider} (domain: test, scope) taken by fixtures, more than {BETWEEN_TESTS}")
    if problems:
        raise AssertionError(f"{test} left ROS domains held: " + "; ".join(problems))
