"""The fixtures every test module may use: ``procs`` (a test's processes on
a ROS domain of its own), ``ros`` (a probe node on that domain), ``bag`` (the
session's recorded runs); and the check that a test taking a domain is
marked ``ros``. Plain helpers live in ``test/support/``.

Each test gets its own ROS domain (and localhost-only discovery), so tests
never hear each other or another graph on the machine.
"""

from __future__ import annotations

import os
import signal
import subprocess
from collections.abc import Callable, Generator, Iterator
from pathlib import Path
from typing import Any

import pytest
from hypothesis import settings
from rosbags.highlevel import AnyReader
from support import domains
from support.bags import SessionBags
from support.domains import lock_domain, next_domain, release_domain
from support.paths import BIN
from support.ros_probe import spin_until

from winder.contract.topics import has_role
from winder.procs import Children, signal_state, stop
from winder.ros.dds import use_profile

# no deadline on an example: a property is about values, and its speed is the
# benchmarks' to measure (hypothesis' 200 ms default failed test_interp on a machine at load 15)
settings.register_profile("winder", deadline=None)
settings.load_profile("winder")

__all__ = [  # what test modules import from here besides the fixtures
    "BIN",
    "Procs",
    "bag_closed",
    "closed_bags",
    "final_report",
    "is_consumer",
    "lock_domain",
    "next_domain",
    "release_domain",
    "rosbags_read",
    "spin_until",
]

use_profile()  # this process' probes discover the nodes as fast as the nodes each other


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> None:
    """Whether the test about to run is marked ``ros``: a test that is not
    and takes a ROS domain anyway (so would start nodes or use DDS) fails,
    naming itself; ``pytest -m "not ros"`` never starts a node."""
    domains.current.update(test=item.nodeid, ros=item.get_closest_marker("ros") is not None)


@pytest.hookimpl(wrapper=True)
def pytest_fixture_setup(fixturedef: pytest.FixtureDef[Any]) -> Generator[None, object, object]:
    """The scope of the fixture being set up, for the domains it takes: one a
    function-scoped fixture took must be handed back by its test's end."""
    before = domains.current["scope"]
    domains.current["scope"] = fixturedef.scope
    try:
        return (yield)
    finally:
        domains.current["scope"] = before


@pytest.hookimpl(wrapper=True)
def pytest_runtest_teardown(item: pytest.Item) -> Generator[None, object, object]:
    """A test hands back every ROS domain it took, and at most one stays held
    from one test to the next (:func:`support.domains.check_handed_back`): a
    holder to the session's end wedged ``make test`` on 10 domains."""
    try:
        return (yield)
    finally:
        domains.check_handed_back(item.nodeid)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_call(item: pytest.Item) -> Iterator[None]:
    """A test leaves this process' signal mask as it found it: every process
    a later test starts inherits the mask, and one with SIGINT blocked never
    stops on Ctrl-C (make flakes: 3 of 3 for two tests, never alone)."""
    before = signal.pthread_sigmask(signal.SIG_BLOCK, [])
    yield
    after = signal.pthread_sigmask(signal.SIG_SETMASK, before)
    if after != before:
        names = ", ".join(sorted(signal.Signals(s).name for s in after - before)) or "none"
        raise AssertionError(f"{item.nodeid} left signals blocked in the test process: {names}")


class Procs:
    """Node processes of one test on the test's domain, each logged to
    ``<tag>-<n>.log`` and dying with the test process (:class:`winder.procs.Children`),
    stopped (SIGINT, then kill) at teardown."""

    def __init__(self, domain: int, log_dir: Path) -> None:
        self.domain = domain
        self.log_dir = log_dir
        self.env = {
            **os.environ,
            "ROS_DOMAIN_ID": str(domain),
            "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
            "PYTHONUNBUFFERED": "1",
        }
        self.children = Children(log_dir, self.env)

    @property
    def procs(self) -> list[tuple[subprocess.Popen[bytes], Path | None]]:
        return [(p, log) for p, _, log in self.children.started]

    def start(self, executable: str, *ros_args: str) -> subprocess.Popen[bytes]:
        """One of the venv's node executables, with ``--ros-args`` when given."""
        args = [str(BIN / executable)]
        if ros_args:
            args += ["--ros-args", *ros_args]
        return self.launch(args, executable)

    def launch(self, argv: list[str], tag: str) -> subprocess.Popen[bytes]:
        """Any process of the test's cell (a stand-in, a third-party consumer):
        on the test's domain, logged as ``<tag>-<n>.log``, stopped at teardown."""
        return self.children.start(argv, f"{tag}-{len(self.children.started)}")

    def log(self, p: subprocess.Popen[bytes]) -> str:
        return self.children.log(p)

    def stop(self, p: subprocess.Popen[bytes], sig: int = signal.SIGINT, timeout: float = 20.0) -> int:
        state = signal_state(p.pid)  # before the signal: what it blocks and ignores
        code, stopped = stop(p, sig, timeout)
        if not stopped:  # its log ends with its threads' stacks (winder.procs.kill_telling_where)
            tail = "\n".join(self.log(p).splitlines()[-60:])
            raise AssertionError(
                f"{p.args[0]} did not stop within {timeout} s ({state}); its log ends:\n{tail}"
            )
        return code

    def stop_all(self) -> None:
        self.children.stop_all(signal.SIGINT, 20.0)


@pytest.fixture
def hangup_taken() -> Iterator[None]:
    """SIGHUP at its default action in this process (and so in the processes
    a test starts) for one test: a test of what SIGHUP does. Under ``nohup``
    (``nohup make test &``) it arrives ignored, winder then leaves it so by
    design (``winder.procs.hangup_ignored``), and such a test would try
    nothing (a fresh-clone run under nohup: 3 failures)."""
    before = signal.signal(signal.SIGHUP, signal.SIG_DFL)
    try:
        yield
    finally:
        signal.signal(signal.SIGHUP, before)


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


@pytest.fixture(scope="session")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Callable[[str], Path]]:
    """``bag(name)``: the bag directory of the session's run of configuration
    ``name`` (support.bags.CONFIGS: each runs once per session, a few at a time,
    started when first asked for)."""
    bags = SessionBags(tmp_path_factory.mktemp("winder_bags"))
    try:
        yield bags.get
    finally:
        bags.close()


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
    from winder.record.bag import bags_in

    return [b for b in bags_in(root) if bag_closed(b)]
