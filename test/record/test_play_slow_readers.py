"""``winder play`` and the readers slower than the replay, each reader a
process of its own over DDS on the test's domain (as a user's node is).

What docs/ANALYSIS.md promises, as written: a reliable reader on the graph
before the replay hears every message, in order and byte for byte, at any
``--rate``, if its history is keep-all (a slower one holds the replay back)
or keep-last with a depth of at least the topic's count; a reader that takes
nothing stops the replay in one line, exit 1, and nothing is published past
it. (A keep-last reader of a smaller depth hears every message only while it
keeps up: its own history drops what it has not taken, which no writer sees.)
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from conftest import BIN, Procs, next_domain, release_domain
from support import wait
from support.bags import rosbags_raw
from support.cli import run_cli

from winder.procs import run
from winder.record.bag import bags_in

pytestmark = pytest.mark.ros

#: 1.4 s of a short job with joint states at 10 kHz: 14,000 messages each on
#: winder/joint_states and winder/joint_commands, more than a reliable keep-all
#: writer and reader of Fast DDS hold between them (5,000 each): a reader slower
#: than the replay fills both, and the player must wait for it
JOB = [
    "--job-id",
    "slow",
    "--turns-per-layer",
    "2",
    "--layers",
    "1",
    "--poles",
    "1",
    "--publish-rate",
    "10000",
]
STATES = "/winder/joint_states"

#: a reader of some topics, in a process of its own: each topic with its QoS and
#: the milliseconds its callback sleeps; counts and a digest of the bytes per
#: topic written to ``out`` every 0.2 s and at SIGINT
READER = """
import hashlib, importlib, json, os, signal, sys, time
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
spec = json.loads(sys.argv[1])
rclpy.init()
node = rclpy.create_node("slow_reader")
counts, digests = {}, {}

def dump():
    out = spec["out"]
    with open(out + ".tmp", "w") as f:
        json.dump({"counts": counts, "digests": {t: d.hexdigest() for t, d in digests.items()}}, f)
    os.replace(out + ".tmp", out)

def taker(topic, pause):
    def take(m):
        counts[topic] = counts.get(topic, 0) + 1
        if counts[topic] == spec.get("freeze_after", {}).get(topic):  # the process stops itself here
            dump()
            os.kill(os.getpid(), signal.SIGSTOP)
        digests.setdefault(topic, hashlib.sha256()).update(bytes(m).rstrip(b"\\0") + b"|")
        if pause:
            time.sleep(pause)
    return take

subs = []
for topic, (msgtype, history, depth, sleep_ms) in spec["topics"].items():
    pkg, kind, name = msgtype.split("/")
    cls = getattr(importlib.import_module(f"{pkg}.{kind}"), name)
    qos = QoSProfile(
        depth=depth,
        history=HistoryPolicy.KEEP_ALL if history == "keep_all" else HistoryPolicy.KEEP_LAST,
        reliability=ReliabilityPolicy.RELIABLE,
    )
    subs.append(node.create_subscription(cls, topic, taker(topic, sleep_ms / 1000), qos, raw=True))

stop = []
signal.signal(signal.SIGINT, lambda *_: stop.append(1))
executor = SingleThreadedExecutor()
executor.add_node(node)
dump()
last = time.monotonic()
while not stop:
    executor.spin_once(timeout_sec=0.05)
    if time.monotonic() - last > 0.2:
        last = time.monotonic()
        dump()
dump()
"""


@pytest.fixture(scope="module")
def slow_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("slow")
    domain = next_domain()
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    try:
        r = subprocess.run(
            [str(BIN / "winder"), "run", *JOB, "--bag-dir", str(root)],
            capture_output=True,
            text=True,
            timeout=240,
            env=env,
            stdin=subprocess.DEVNULL,
        )
    finally:
        release_domain(domain)
    assert r.returncode == 0, r.stdout + r.stderr
    (bag,) = bags_in(root)
    return bag


def owed(bag: Path) -> dict[str, tuple[int, str]]:
    """What a reader on the graph before the replay is owed on each played
    topic (all but /clock), from rosbags: the count and the digest of the bytes, in order."""
    out: dict[str, Any] = {}
    for topic, _, data in rosbags_raw(bag):
        if topic != "/clock":
            n, h = out.setdefault(topic, [0, hashlib.sha256()])
            out[topic][0] = n + 1
            h.update(data.rstrip(b"\0") + b"|")  # CDR's 4-byte end padding aside
    return {t: (n, h.hexdigest()) for t, (n, h) in out.items()}


def types(bag: Path) -> dict[str, str]:
    from winder.record.raw import read_raw

    raw = read_raw(bag, keep=lambda _t: False)
    return {c.topic: c.msgtype for c in raw.connections.values() if c.topic != "/clock"}


class Reader:
    """The reader process: topic -> (history, depth, callback sleep in ms)."""

    def __init__(
        self,
        procs: Procs,
        bag: Path,
        tmp: Path,
        qos: dict[str, tuple[str, int, float]],
        freeze_after: dict[str, int] | None = None,
    ) -> None:
        self.out = tmp / "reader.json"
        kinds = types(bag)
        spec = {
            "out": str(self.out),
            "topics": {t: (kinds[t], *q) for t, q in qos.items()},
            "freeze_after": freeze_after or {},  # topic -> the message after which the reader SIGSTOPs itself
        }
        self.p = procs.launch([sys.executable, "-c", READER, json.dumps(spec)], "reader")
        self.procs = procs
        wait.until(
            self.out.exists, 30, "the reader's subscriptions", heard=lambda: procs.log(self.p), running=self.p
        )

    def heard(self) -> dict[str, Any]:
        try:
            return json.loads(self.out.read_text())  # type: ignore[no-any-return]
        except (OSError, ValueError):  # being replaced
            return {"counts": {}, "digests": {}}

    def until_heard(self, want: dict[str, tuple[int, str]], timeout: float) -> dict[str, Any]:
        """Until the reader has taken ``want``'s count on each topic (it drains its
        backlog after the player has ended); what it took."""

        def done() -> bool:
            counts = self.heard()["counts"]
            return all(counts.get(t, 0) >= n for t, (n, _) in want.items())

        wait.until(
            done, timeout, "the reader to take every message", heard=lambda: self.heard()["counts"], poll=0.5
        )
        return self.heard()


def play(procs: Procs, bag: Path, *args: str, timeout: float = 400) -> subprocess.CompletedProcess[str]:
    """``winder play BAG *args`` on the test's domain (dying with the test process)."""
    return run(
        [str(BIN / "winder"), "play", str(bag), *args],
        env=procs.env,
        capture_output=True,
        text=True,
        timeout=timeout,
        stdin=subprocess.DEVNULL,
    )


def test_a_slow_keep_all_reader_holds_the_replay_back_and_hears_every_message(
    procs: Procs, slow_bag: Path, tmp_path: Path
) -> None:
    """A reliable keep-all reader whose callback sleeps 1 ms per message (a
    tenth of the pace ``--rate 10`` asks for): the replay waits for it
    (before: a publish failed, "cannot publish data", exit 70), ends exit 0,
    says how long it was held back, and the reader hears every message of
    every topic, in order, byte for byte."""
    want = owed(slow_bag)
    qos = {t: ("keep_all", 1, 1.0 if t == STATES else 0.0) for t in want}
    reader = Reader(procs, slow_bag, tmp_path, qos)
    r = play(procs, slow_bag, "--rate", "10")
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stdout + r.stderr
    assert "held back" in r.stdout.splitlines()[-1], r.stdout
    got = reader.until_heard(want, 120)
    assert {t: (got["counts"][t], got["digests"][t]) for t in want} == want


def test_a_keep_last_reader_deep_enough_for_the_topic_hears_every_message(
    procs: Procs, slow_bag: Path, tmp_path: Path
) -> None:
    """A reliable keep-last reader whose depth is the topic's count, slower
    than ``--rate 10`` (rclpy takes a few thousand messages a second; the
    replay asks for 200,000): it hears every message, its history never
    drops one."""
    want = owed(slow_bag)
    qos = {t: ("keep_last", max(n, 1), 0.0) for t, (n, _) in want.items()}
    reader = Reader(procs, slow_bag, tmp_path, qos)
    r = play(procs, slow_bag, "--rate", "10")
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stdout + r.stderr
    got = reader.until_heard(want, 120)
    assert {t: (got["counts"][t], got["digests"][t]) for t in want} == want


def test_a_reader_that_takes_nothing_stops_the_replay_in_one_line(
    procs: Procs, slow_bag: Path, tmp_path: Path
) -> None:
    """A keep-all reader that stops (SIGSTOP, by itself) after its first
    joint state: the player waits for it, then stops after STALL_S with one
    line naming the topic and where in the recording, exit 1; it published no
    message past the one it could not (it counts less than the recording)."""
    from winder.ros.player import STALL_S

    want = owed(slow_bag)
    qos = {t: ("keep_all", 1, 0.0) for t in want}
    reader = Reader(procs, slow_bag, tmp_path, qos, freeze_after={STATES: 1})
    try:
        r = play(procs, slow_bag, "--rate", "10", timeout=120)
        assert reader.heard()["counts"][STATES] == 1  # it did stop there
    finally:
        os.kill(reader.p.pid, signal.SIGCONT)
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stdout + r.stderr
    [line] = [x for x in r.stderr.splitlines() if x.startswith("winder play: stopped at")]
    assert f"took no message for {STALL_S:g} s" in line and "/winder/joint_" in line, r.stderr
    published = int(r.stdout.splitlines()[-1].split("published ")[1].split()[0])
    assert 0 < published < sum(n for n, _ in want.values())


def test_play_says_which_readers_are_best_effort(procs: Procs, slow_bag: Path) -> None:
    """A best-effort reader may lose any message, unseen by the writer: the
    player names it in one line before it plays (reliable readers, whose
    history the graph does not show, are not named)."""
    script = (
        "import rclpy, time\n"
        "from rclpy.qos import qos_profile_sensor_data\n"
        "from sensor_msgs.msg import JointState\n"
        "rclpy.init(); n = rclpy.create_node('lossy_reader')\n"
        f"n.create_subscription(JointState, '{STATES}', lambda m: None, qos_profile_sensor_data)\n"
        "print('ready', flush=True)\n"
        "rclpy.spin(n)\n"
    )
    lossy = procs.launch([sys.executable, "-c", script], "lossy")
    wait.log_has(lambda: procs.log(lossy), "ready", 30, running=lossy)
    r = run_cli("play", str(slow_bag), "--rate", "100", env=procs.env)
    assert r.returncode == 0, r.stdout + r.stderr
    [line] = [x for x in r.stderr.splitlines() if "best-effort" in x]
    assert f"{STATES}: /lossy_reader" in line and "/winder/joint_commands" not in line, line
