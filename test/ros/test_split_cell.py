"""A cell split across two hosts: network namespaces joined by a veth link
(bench/_netns.py), the sim node on one, ``winder run --external sim`` on the
other, discovery by static peers, so the step stream crosses the link over
UDP as between machines: clean, at 1 % packet loss, and over a link that
delays every packet 5 ms one way. Where the machine forbids network namespaces the
tests say so and skip; two cells on one graph are tested always
(test_faults)."""

from __future__ import annotations

import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from conftest import BIN, Procs, final_report, rosbags_read
from support.cell import only_bag
from support.paths import ROOT

from winder.motion.job import Job
from winder.procs import popen
from winder.ros.dds import LAN_PROFILE, PROFILE

sys.path.insert(0, str(ROOT / "bench"))
from _netns import Hosts, available

pytestmark = pytest.mark.ros

JOB = ["--job-id", "split", "--turns-per-layer", "10", "--poles", "2", "--layers", "2"]


def linked_hosts(tag: str, delay_ms: float = 0.0) -> Iterator[Hosts]:
    """Two hosts, up for the test and down after it; the test is skipped,
    with the reason, where the machine cannot make them."""
    why = available()
    if why:
        pytest.skip(f"this machine cannot make network namespaces: {why}")
    h = Hosts(tag)
    why = h.up()
    if not why and delay_ms:  # netem where the kernel has it, else a delay line
        why = h.shape(delay_ms=delay_ms)
        if why:
            h.down()
            h = Hosts(tag + "d", delay_ms=delay_ms)
            why = h.up()
    if why:
        h.down()
        pytest.skip(why)
    try:
        yield h
    finally:
        h.down()


@pytest.fixture
def hosts() -> Iterator[Hosts]:
    yield from linked_hosts("t")


def split_run(hosts: Hosts, procs: Procs, tmp_path: Path, extra: dict[str, str], *args: str) -> Any:
    """The sim node on host b, the rest of the cell on host a: (winder run's result, the bag, link bytes)."""
    bags = tmp_path / "bags"
    env_b = {**hosts.env("b", procs.env), **extra}
    env_a = {**hosts.env("a", procs.env), **extra}
    # one of the test's processes: stopped with them (a process left running in a namespace taken
    # down lives on, its shared-memory ports held, until the test worker ends)
    procs.children.start(
        hosts.command("b", [str(BIN / "sim_node"), "--ros-args", "-p", f"bag_dir:={bags}"]), "sim", env=env_b
    )
    rx = hosts.rx_bytes("b")
    r = subprocess.run(
        hosts.command(
            "a", [str(BIN / "winder"), "run", "--external", "sim", *JOB, *args, "--timeout", "120"]
        ),
        env=env_a,
        capture_output=True,
        text=True,
        timeout=200,
        stdin=subprocess.DEVNULL,
    )
    return r, bags, hosts.rx_bytes("b") - rx


def check_complete(r: Any, bags: Path, link_bytes: int) -> None:
    assert r.returncode == 0, r.stdout + r.stderr
    assert "not started here   step consumer (--external sim)" in r.stdout
    bag = rosbags_read(only_bag(bags.parent))
    rows = sum(len(m.data) // 5 for _, m in bag["/winder/step_times"])
    final = final_report(bag)
    assert final["state"] == "done" and int(final["steps_missing"]) == 0 and int(final["gaps"]) == 0
    assert rows == int(final["steps_total"])
    # the step times crossed the link: at least their payload (8 bytes x 5 columns per step)
    assert link_bytes >= rows * 40


def test_a_cell_split_over_two_hosts(hosts: Hosts, procs: Procs, tmp_path: Path) -> None:
    r, bags, link = split_run(hosts, procs, tmp_path, {})
    check_complete(r, bags, link)


def test_a_split_cell_over_a_lossy_link_with_the_lan_profile(
    hosts: Hosts, procs: Procs, tmp_path: Path
) -> None:
    """1 % packet loss both ways: with the LAN profile (datagrams within one
    MTU) every step arrives, in order, the stream checker finds nothing missing."""
    why = hosts.shape(loss=0.01)
    if why:
        pytest.skip(why)
    r, bags, link = split_run(hosts, procs, tmp_path, {"FASTRTPS_DEFAULT_PROFILES_FILE": str(LAN_PROFILE)})
    check_complete(r, bags, link)


DELAY_MS = 5.0


@pytest.fixture
def delayed_hosts() -> Iterator[Hosts]:
    """Two hosts joined by a link that delays every packet 5 ms one way: netem
    where the kernel has it, else TUN devices and a relay (bench/_delayline.py)."""
    yield from linked_hosts("tn", DELAY_MS)


ECHO = """
import socket, sys
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
s.bind(("0.0.0.0", 9931))
print("up", flush=True)
for _ in range(int(sys.argv[1])):
    data, peer = s.recvfrom(100)
    s.sendto(data, peer)
"""

PING = """
import socket, sys, time
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
s.settimeout(5)
for k in range(int(sys.argv[2])):
    t = time.monotonic_ns()
    s.sendto(str(k).encode(), (sys.argv[1], 9931))
    assert s.recvfrom(100)[0] == str(k).encode()
    print(time.monotonic_ns() - t)
"""


def test_the_delayed_link_delays_every_packet(delayed_hosts: Hosts) -> None:
    """Every UDP round trip over the link takes at least twice the one-way delay."""
    n = 20
    echo = popen(
        delayed_hosts.command("b", [sys.executable, "-c", ECHO, str(n)]), stdout=subprocess.PIPE, text=True
    )
    try:
        assert echo.stdout is not None and echo.stdout.readline().strip() == "up"
        r = subprocess.run(
            delayed_hosts.command("a", [sys.executable, "-c", PING, delayed_hosts.addr["b"], str(n)]),
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert r.returncode == 0, r.stderr
        rtts = [int(x) / 1e6 for x in r.stdout.split()]
        assert len(rtts) == n and min(rtts) >= 2 * DELAY_MS, rtts
    finally:
        echo.kill()
        echo.wait()


def test_a_split_cell_over_a_delayed_link(delayed_hosts: Hosts, procs: Procs, tmp_path: Path) -> None:
    """5 ms each way between the planner and the axes' node: the flow control's
    window covers the round trip, every step arrives, nothing missing."""
    r, bags, link = split_run(delayed_hosts, procs, tmp_path, {})
    check_complete(r, bags, link)


LOAD = """
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import String
rclpy.init()
node = rclpy.create_node("profile_probe")
node.create_publisher(String, "probe", QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
node.create_subscription(String, "probe", lambda m: None, 10)
print("created")
"""


def load_profile(procs: Procs, profile: Path) -> subprocess.CompletedProcess[str]:
    """A bare rclpy process that loads ``profile`` and makes a reliable writer and a reader."""
    return subprocess.run(
        [sys.executable, "-c", LOAD],
        env={**procs.env, "FASTRTPS_DEFAULT_PROFILES_FILE": str(profile)},
        capture_output=True,
        text=True,
        timeout=60,
        stdin=subprocess.DEVNULL,
    )


@pytest.mark.parametrize("profile", [PROFILE, LAN_PROFILE], ids=["default", "lan"])
def test_winder_dds_profiles_load_without_errors(profile: Path, procs: Procs) -> None:
    """Fast DDS reads each profile whole: a misspelt element or a bad value is
    an XMLPARSER error on stderr, and the profile (the heartbeat period with
    it) would silently not apply."""
    r = load_profile(procs, profile)
    said = r.stdout + r.stderr  # Fast DDS logs to either, depending on its consumer
    assert r.returncode == 0 and r.stdout.strip().endswith("created"), said
    assert "XMLPARSER" not in said and "Error" not in said, said


def test_a_misspelt_profile_is_reported(procs: Procs, tmp_path: Path) -> None:
    """The check above can fail: the same profile with one element misspelt."""
    bad = tmp_path / "bad.xml"
    bad.write_text(PROFILE.read_text().replace("heartbeatPeriod>", "heartbeatPeriode>"))
    r = load_profile(procs, bad)
    said = r.stdout + r.stderr
    assert "XMLPARSER" in said and "heartbeatPeriode" in said, said


@pytest.mark.parametrize(
    ("profile", "said"),
    [(None, "winder's default (UDP only, on one host its loopback; 64 kB datagrams); on a network that "
            "loses packets"),
     (LAN_PROFILE, "winder's LAN profile (UDP only, datagrams within one MTU)")],
    ids=["default", "lan"],
)  # fmt: skip
def test_external_sim_that_never_comes_is_named(procs: Procs, profile: Path | None, said: str) -> None:
    """``winder run --external sim`` with no sim node on the graph: the DDS
    profile in force is printed, and the run ends in one line naming what it
    waited for, not a bare timeout."""
    from support.cli import assert_one_line_error

    env = dict(procs.env)
    if profile is not None:
        env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(profile)
    r = subprocess.run(
        [str(BIN / "winder"), "run", "--external", "sim", *JOB, "--start-timeout", "3"],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        stdin=subprocess.DEVNULL,
    )
    assert f"  DDS profile        {said}" in r.stdout, r.stdout
    assert_one_line_error(
        r,
        "the job did not start within 3 s",
        "the step consumer (sim_node or a hardware driver), which",
        code=1,  # the run failed: its job never started (winder.cli.exits)
    )


class DiscoveryServer:
    """``winder discovery-server`` as a process (in a host of ``hosts``, or here)."""

    def __init__(self, env: dict[str, str], address: str, port: int, hosts: Hosts | None = None) -> None:
        argv = [str(BIN / "winder"), "discovery-server", "--address", address, "--port", str(port)]
        self.p = popen(
            hosts.command("b", argv) if hosts else argv,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            stdin=subprocess.DEVNULL,
        )
        assert self.p.stdout is not None
        self.said = [self.p.stdout.readline() for _ in range(3)]  # winder's two lines, the server's first
        assert "Server is running" in self.said[2], self.said

    def stop(self) -> None:
        self.p.send_signal(signal.SIGINT)
        self.p.wait(timeout=20)


def test_a_cell_found_by_a_discovery_server(procs: Procs, tmp_path: Path) -> None:
    """Discovery through Fast DDS's discovery server (ROS_DISCOVERY_SERVER): the
    cell completes; with the server gone the same cell cannot find itself, so
    it was the server that joined the nodes."""
    port = 11811 + procs.domain
    server = DiscoveryServer(procs.env, "127.0.0.1", port)
    assert server.said[1].strip() == f"export ROS_DISCOVERY_SERVER='127.0.0.1:{port}'", server.said
    env = {**procs.env, "ROS_DISCOVERY_SERVER": f"127.0.0.1:{port}"}
    run = [str(BIN / "winder"), "run", *JOB, "--bag-dir", str(tmp_path / "bags")]
    options: dict[str, Any] = {"env": env, "capture_output": True, "text": True, "timeout": 200}
    try:
        r = subprocess.run(run, stdin=subprocess.DEVNULL, **options)
    finally:
        server.stop()
    assert r.returncode == 0, r.stdout + r.stderr
    assert f"discovery by the discovery server 127.0.0.1:{port} (ROS_DISCOVERY_SERVER)" in r.stdout
    bag = rosbags_read(only_bag(tmp_path))
    total = Job(job_id="split", turns_per_layer=10, poles=2, layers=2).total_steps
    assert sum(len(m.data) // 5 for _, m in bag["/winder/step_times"]) == total

    from support.cli import assert_one_line_error

    alone = subprocess.run([*run, "--start-timeout", "5"], stdin=subprocess.DEVNULL, **options)
    assert_one_line_error(alone, "the job did not start within 5 s", code=1)  # the run failed


def test_a_split_cell_found_by_a_discovery_server(hosts: Hosts, procs: Procs, tmp_path: Path) -> None:
    """Two hosts, no static peers, no multicast: the discovery server on the
    axes' host joins them."""
    port = 11811 + procs.domain
    server = DiscoveryServer(hosts.env("b", procs.env), hosts.addr["b"], port, hosts)
    try:
        extra = {"ROS_STATIC_PEERS": "", "ROS_DISCOVERY_SERVER": f"{hosts.addr['b']}:{port}"}
        r, bags, link = split_run(hosts, procs, tmp_path, extra)
    finally:
        server.stop()
    check_complete(r, bags, link)


def test_discovery_server_settings_are_checked() -> None:
    from support.cli import assert_one_line_error, run_cli

    assert_one_line_error(run_cli("discovery-server", "--port", "0"), "port=0 is invalid", "[1025, 65535]")
    assert_one_line_error(run_cli("discovery-server", "--id", "256"), "id=256 is invalid", "[0, 255]")
    assert_one_line_error(run_cli("discovery-server", "--address", "host"), "address='host' is invalid")


def test_external_takes_only_nodes_that_can_run_elsewhere(tmp_path: Path) -> None:
    from support.cli import assert_one_line_error, run_cli

    assert_one_line_error(run_cli("run", "--external", "interp", "--check"), "external='interp' is invalid")
    # settings of an external node are set on it (test_nodes_under_other_names.py), checked here as any
    bad = run_cli("run", "--external", "sim", "--fork.J", "-1", "--check")
    assert_one_line_error(bad, "fork.J=-1.0 is invalid")
    given = ["--fork.J", "2e-4", "--v-max", "900"]
    for options in (["--external", "sim,profile"], ["--external", "sim,profile", *given]):
        ok = run_cli("run", *options, "--check")
        assert ok.returncode == 0, ok.stderr
