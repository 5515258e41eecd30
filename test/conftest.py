"""Fixtures for tests that start the real node processes over DDS.

Each test gets its own ROS domain (and localhost-only discovery), so tests
never hear each other or another graph on the machine.
"""

from __future__ import annotations

import fcntl
import itertools
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from rosbags.highlevel import AnyReader

from winder.contract.topics import has_role
from winder.ros.dds import use_profile

use_profile()  # this process' probes discover the nodes as fast as the nodes each other

BIN = Path(sys.executable).parent


def _pool() -> range:
    """The ROS domains this test session may use: ``WINDER_TEST_DOMAINS=A-B``
    (inclusive; 20-219 unless set). Domains 1-19 belong to the conformance
    suite, which locks them the same way."""
    text = os.environ.get("WINDER_TEST_DOMAINS", "20-219")
    try:
        low, high = (int(v) for v in text.split("-"))
    except ValueError:
        raise pytest.UsageError(f"WINDER_TEST_DOMAINS={text!r}: expected A-B, e.g. 20-219") from None
    if not 0 <= low <= high <= 232 or high - low < 9:
        raise pytest.UsageError(f"WINDER_TEST_DOMAINS={text!r}: need 10 or more domains within 0-232")
    return range(low, high + 1)


_held: dict[int, Any] = {}
_cursor = itertools.count(os.getpid() * 7)


def lock_domain(domain: int, kind: str) -> Any:
    """The open lock file of ``domain`` for tests of ``kind`` (locked: no other
    process holds it until it is closed), or None if another process holds it."""
    lock = (Path(tempfile.gettempdir()) / f"winder-{kind}-domain-{domain}.lock").open("w")
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
    pool = _pool()
    end = time.monotonic() + timeout
    while True:
        for _ in range(len(pool)):
            domain = pool[next(_cursor) % len(pool)]
            if domain in _held:
                continue
            lock = lock_domain(domain, "test")
            if lock is None:
                continue
            _held[domain] = lock
            return domain
        if time.monotonic() > end:
            raise RuntimeError(f"every ROS domain of {pool} held by other test processes for {timeout} s")
        time.sleep(0.5)


def release_domain(domain: int) -> None:
    """Hand a domain of :func:`next_domain` back (its processes are stopped)."""
    lock = _held.pop(domain, None)
    if lock is not None:
        lock.close()


def long_lived_domain() -> int:
    """A domain for processes that outlive one test (the session's bag runs):
    held until the end of the session."""
    return next_domain()


class Procs:
    """Node processes of one test, stopped (SIGINT, then kill) at teardown."""

    def __init__(self, domain: int, log_dir: Path) -> None:
        self.domain = domain
        self.log_dir = log_dir
        self.env = {
            **os.environ,
            "ROS_DOMAIN_ID": str(domain),
            "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
            "PYTHONUNBUFFERED": "1",
        }
        self.procs: list[tuple[subprocess.Popen[bytes], Path]] = []

    def start(self, executable: str, *ros_args: str) -> subprocess.Popen[bytes]:
        """One of the venv's node executables, with ``--ros-args`` when given."""
        args = [str(BIN / executable)]
        if ros_args:
            args += ["--ros-args", *ros_args]
        return self.launch(args, executable)

    def launch(self, argv: list[str], tag: str) -> subprocess.Popen[bytes]:
        """Any process of the test's cell (a stand-in, a third-party consumer):
        on the test's domain, logged as ``<tag>-<n>.log``, stopped at teardown."""
        log = self.log_dir / f"{tag}-{len(self.procs)}.log"
        p = subprocess.Popen(
            argv,
            env=self.env,
            stdout=log.open("wb"),
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
        )
        self.procs.append((p, log))
        return p

    def log(self, p: subprocess.Popen[bytes]) -> str:
        for q, path in self.procs:
            if q is p:
                return path.read_text(errors="replace")
        raise KeyError(p)

    def stop(self, p: subprocess.Popen[bytes], sig: int = signal.SIGINT, timeout: float = 20.0) -> int:
        if p.poll() is None:
            p.send_signal(sig)
        try:
            return p.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
            raise AssertionError(f"{p.args[0]} did not stop within {timeout} s") from None

    def stop_all(self) -> None:
        for p, _ in self.procs:
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        for p, _ in self.procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


@pytest.fixture
def procs(tmp_path: Path) -> Iterator[Procs]:
    log_dir = tmp_path / "logs"
    log_dir.mkdir()
    ps = Procs(next_domain(), log_dir)
    try:
        yield ps
    finally:
        ps.stop_all()
        release_domain(ps.domain)


@pytest.fixture
def ros(procs: Procs) -> Iterator[object]:
    """An rclpy context and node in the test's domain, for probing the nodes."""
    import rclpy
    from rclpy.context import Context

    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    ctx = Context()
    rclpy.init(context=ctx, domain_id=procs.domain)
    node = rclpy.create_node("winder_test_probe", context=ctx)
    try:
        yield node
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)


def spin_until(node: object, cond: object, timeout: float, what: str) -> None:
    """Spin ``node`` until ``cond()`` is true, or fail naming ``what``."""
    from rclpy.executors import SingleThreadedExecutor

    ex = SingleThreadedExecutor(context=node.context)  # type: ignore[attr-defined]
    ex.add_node(node)
    t_end = time.monotonic() + timeout
    try:
        while not cond():  # type: ignore[operator]
            if time.monotonic() > t_end:
                raise AssertionError(f"timed out after {timeout} s waiting for {what}")
            ex.spin_once(timeout_sec=0.05)
    finally:
        ex.remove_node(node)


# -- independent reading of the bags the nodes wrote ---------------------------------


def rosbags_read(path: Path) -> dict[str, list[tuple[int, Any]]]:
    """Every message of a bag, decoded by rosbags: topic -> [(log time, message)]."""
    out: dict[str, list[tuple[int, Any]]] = {}
    with AnyReader([path]) as reader:
        for conn, t, raw in reader.messages():
            out.setdefault(conn.topic, []).append((t, reader.deserialize(raw, conn.msgtype)))
    return out


def is_consumer(name: str, values: dict[str, str], namespace: str | None = "") -> bool:
    """A job status of the step consumer of the cell in ``namespace`` (None:
    of any cell), found by its role: the values say ``role: consumer`` (one
    that names no role: the stock node name, sim_node)."""
    if namespace is None:
        namespace = name.split(":", 1)[0].rpartition("/")[0]
    return has_role(name, values, "consumer", namespace)


def final_report(bag: dict[str, list[tuple[int, Any]]], namespace: str = "") -> dict[str, str]:
    """The values of the consumer's last job status recorded on /diagnostics."""
    return [
        values
        for _, arr in bag["/diagnostics"]
        for st in arr.status
        if is_consumer(st.name, values := {kv.key: kv.value for kv in st.values}, namespace)
    ][-1]


def bag_closed(bag: Path) -> bool:
    """Whether the consumer closed ``bag``: its metadata.yaml says
    ``winder_bag: closed``. (metadata.yaml exists from a run's first moment,
    saying ``recording``, so that a bag is readable whatever stops it.)"""
    try:
        return "winder_bag: closed" in (bag / "metadata.yaml").read_text()
    except OSError:
        return False


def closed_bags(root: Path) -> list[Path]:
    """The bag directories under ``root`` the consumer has closed, oldest name first."""
    if not root.is_dir():
        return []
    return sorted(b for b in root.iterdir() if b.is_dir() and bag_closed(b))
