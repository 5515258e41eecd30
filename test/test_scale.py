"""A cell split across two hosts: network namespaces joined by a veth link
(bench/_netns.py), the sim node on one, ``winder run --external sim`` on the
other, discovery by static peers, so the step stream crosses the link over
UDP as between machines. Where the machine forbids network namespaces the
tests say so and skip; two cells on one graph are tested always
(test_reliability)."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from conftest import BIN, Procs, rosbags_read
from test_nodes import only_bag

from winder.ros.dds import LAN_PROFILE

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from _netns import Hosts, available

pytestmark = pytest.mark.ros

JOB = ["--job-id", "split", "--turns-per-layer", "10", "--poles", "2", "--layers", "2"]


@pytest.fixture
def hosts() -> Iterator[Hosts]:
    why = available()
    if why:
        pytest.skip(f"this machine cannot make network namespaces: {why}")
    h = Hosts("t")
    why = h.up()
    if why:
        pytest.skip(why)
    try:
        yield h
    finally:
        h.down()


def split_run(hosts: Hosts, procs: Procs, tmp_path: Path, extra: dict[str, str], *args: str) -> Any:
    """The sim node on host b, the rest of the cell on host a: (winder run's result, the bag, link bytes)."""
    bags = tmp_path / "bags"
    env_b = {**hosts.env("b", procs.env), **extra}
    env_a = {**hosts.env("a", procs.env), **extra}
    sim = subprocess.Popen(
        hosts.command("b", [str(BIN / "sim_node"), "--ros-args", "-p", f"bag_dir:={bags}"]),
        env=env_b,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    procs.procs.append((sim, tmp_path / "sim.log"))  # type: ignore[arg-type]
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
    assert "not started here   sim_node (--external)" in r.stdout
    bag = rosbags_read(only_bag(bags.parent))
    rows = sum(len(m.data) // 5 for _, m in bag["/winder/step_times"])
    final = [
        {kv.key: kv.value for kv in st.values}
        for _, arr in bag["/diagnostics"]
        for st in arr.status
        if st.name == "sim_node: job"
    ][-1]
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


def test_external_takes_only_nodes_that_can_run_elsewhere(tmp_path: Path) -> None:
    from test_reader import assert_one_line_error, run_cli

    assert_one_line_error(run_cli("run", "--external", "interp", "--check"), "external='interp' is invalid")
    assert_one_line_error(
        run_cli("run", "--external", "sim", "--fork.J", "2e-4", "--check"),
        "fork.J is a setting of the sim_node, which runs elsewhere",
    )
    ok = run_cli("run", "--external", "sim,profile", "--check")
    assert ok.returncode == 0, ok.stderr
