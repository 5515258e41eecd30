"""Foxglove's WebSocket protocol, from the client's side: ``winder run --foxglove``,
``winder view`` and ``winder play --foxglove`` served to a client written here.

The client (:class:`Client`) speaks the protocol as the Foxglove app does, on
the ``websockets`` package: the subprotocol ``foxglove.sdk.v1``, the JSON
``serverInfo`` / ``advertise`` / ``subscribe`` messages, and the binary
message data (opcode 1: subscription id, log time, payload), time (2),
playback state (5) and playback control request (3, sent). The payloads are
decoded as CDR by rclpy (``deserialize_message``) with the type the channel's
schema names, and the values checked against what the cell must send (joint
names, the state's keys); for a recording, against the bag read with rosbags.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib
import json
import math
import re
import socket
import struct
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import websockets
from conftest import BIN, Procs, rosbags_read
from support import wait
from support.paths import ROOT, TEST
from support.ros_probe import spin_until

from winder.contract.topics import cell_state_values, in_namespace
from winder.record.bag import bags_in

pytestmark = pytest.mark.ros

JOINTS = ["feed", "fork", "pole"]
#: a job long enough to be running whatever the machine (400 turns a layer, paced to the wall clock)
LONG = ["--turns-per-layer", "400", "--real-time"]
TINY = ["--turns-per-layer", "4", "--layers", "1", "--poles", "1"]
URL = re.compile(r"ws://127\.0\.0\.1:(\d+)")
#: the topics a live view serves (docs/CONTRACT.md §2: the cell's, but the step streams)
LIVE_TOPICS = {
    "/winder/joint_states": "sensor_msgs/msg/JointState",
    "/winder/joint_commands": "sensor_msgs/msg/JointState",
    "/winder/tension": "geometry_msgs/msg/WrenchStamped",
    "/winder/state": "winder_interfaces/msg/CellState",
    "/winder/progress": "diagnostic_msgs/msg/KeyValue",
    "/winder/path": "trajectory_msgs/msg/JointTrajectory",
    "/winder/control": "winder_interfaces/msg/ControlEvent",
    "/winder/job": "winder_interfaces/msg/JobDescription",
    "/winder/report": "winder_interfaces/msg/JobReport",
    "/winder/sim_config": "std_msgs/msg/String",
    "/winder/profile_config": "std_msgs/msg/String",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
    "/clock": "rosgraph_msgs/msg/Clock",
}


# -- the client -----------------------------------------------------------------------------


@dataclass
class Data:
    topic: str
    log_time: int
    payload: bytes
    msg: Any = None


@dataclass
class Client:
    """One connection to a Foxglove WebSocket server."""

    ws: Any
    info: dict[str, Any] = field(default_factory=dict)
    channels: dict[int, dict[str, Any]] = field(default_factory=dict)  #: by channel id
    subscriptions: dict[int, str] = field(default_factory=dict)  #: subscription id -> topic
    data: list[Data] = field(default_factory=list)
    states: list[dict[str, Any]] = field(default_factory=list)  #: playback states
    times: list[int] = field(default_factory=list)

    def topic_channel(self, topic: str) -> dict[str, Any]:
        found = [c for c in self.channels.values() if c["topic"] == topic]
        assert found, (
            f"{topic} not advertised (advertised: {sorted(c['topic'] for c in self.channels.values())})"
        )
        return found[0]

    async def subscribe(self, topics: list[str]) -> None:
        subs = []
        for topic in topics:
            sid = len(self.subscriptions) + 100
            self.subscriptions[sid] = topic
            subs.append({"id": sid, "channelId": self.topic_channel(topic)["id"]})
        await self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    async def control(self, command: str, speed: float, seek: int | None, request_id: str) -> None:
        """A playback control request (binary opcode 3): play (0) or pause (1), speed, seek."""
        rid = request_id.encode()
        await self.ws.send(
            struct.pack(
                "<BBfBQI", 3, {"play": 0, "pause": 1}[command], speed, seek is not None, seek or 0, len(rid)
            )
            + rid
        )

    def take(self, message: str | bytes) -> None:
        if isinstance(message, str):
            doc = json.loads(message)
            if doc["op"] == "serverInfo":
                self.info = doc
            elif doc["op"] == "advertise":
                self.channels.update({c["id"]: c for c in doc["channels"]})
            return
        op = message[0]
        if op == 1:
            sid, log_time = struct.unpack_from("<IQ", message, 1)
            topic = self.subscriptions[sid]
            self.data.append(
                Data(topic, log_time, bytes(message[13:]), decode(self.topic_channel(topic), message[13:]))
            )
        elif op == 2:
            self.times.append(struct.unpack_from("<Q", message, 1)[0])
        elif op == 5:
            status, current, speed, did_seek, n = struct.unpack_from("<BQfBI", message, 1)
            request_id = bytes(message[19 : 19 + n]).decode()
            self.states.append(
                {
                    "status": status,
                    "time": current,
                    "speed": speed,
                    "did_seek": bool(did_seek),
                    "id": request_id,
                }
            )

    async def _take_one(self, timeout: float) -> None:
        with contextlib.suppress(asyncio.TimeoutError):
            self.take(await asyncio.wait_for(self.ws.recv(), max(timeout, 0.01)))

    async def until(self, cond: Callable[[], bool], timeout: float, what: str) -> None:
        end = time.monotonic() + timeout
        while not cond():
            left = end - time.monotonic()
            if left <= 0:
                raise AssertionError(f"timed out after {timeout} s waiting for {what}")
            await self._take_one(min(left, 0.2))

    async def drain(self, seconds: float) -> None:
        """Take whatever comes for ``seconds``."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            await self._take_one(end - time.monotonic())

    def of(self, topic: str) -> list[Data]:
        return [d for d in self.data if d.topic == topic]


def decode(channel: dict[str, Any], payload: bytes) -> Any:
    """A message's CDR bytes as the ROS message its channel's schema names (rclpy's deserializer)."""
    from rclpy.serialization import deserialize_message

    assert channel["encoding"] == "cdr" and channel["schemaEncoding"] == "ros2msg", channel
    pkg, kind, name = channel["schemaName"].split("/")
    cls = getattr(importlib.import_module(f"{pkg}.{kind}"), name)
    return deserialize_message(bytes(payload), cls)


async def connect(port: int) -> Client:
    ws = await websockets.connect(
        f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1", "foxglove.websocket.v1"], max_size=None
    )
    client = Client(ws)
    assert ws.subprotocol == "foxglove.sdk.v1"
    await client.until(lambda: bool(client.info) and bool(client.channels), 10, "serverInfo and advertise")
    return client


# -- processes -------------------------------------------------------------------------------


def served_port(procs: Procs, p: subprocess.Popen[bytes], timeout: float = 60.0) -> int:
    """The port a winder command printed in its ``ws://127.0.0.1:PORT`` line (it was given port 0)."""
    found = wait.until(
        lambda: URL.search(procs.log(p)),
        timeout,
        f"ws:// URL printed by {p.args!r}",
        heard=lambda: procs.log(p)[-1500:],
        running=p,
    )
    return int(found[1])


def winder(procs: Procs, *args: str) -> subprocess.Popen[bytes]:
    return procs.launch([str(BIN / "winder"), *args], f"winder-{args[0]}")


def free_port() -> socket.socket:
    """A socket bound and listening on a free port (held: the port is in use)."""
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen()
    return s


# -- checks of decoded messages --------------------------------------------------------------


def check_joint_states(data: list[Data], job_id: str) -> None:
    assert len(data) >= 20, f"only {len(data)} joint states"
    stamps = []
    for d in data:
        m = d.msg
        assert list(m.name) == JOINTS
        assert len(m.position) == 3 and len(m.velocity) == 3
        assert all(math.isfinite(v) for v in (*m.position, *m.velocity))
        assert m.header.frame_id == job_id
        stamps.append(m.header.stamp.sec * 10**9 + m.header.stamp.nanosec)
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps), "joint state stamps not increasing"
    fork = [d.msg.position[1] for d in data]
    assert max(fork) > min(fork), "the fork did not turn"


def check_state(data: list[Data]) -> dict[str, str]:
    assert data, "no winder/state"
    m = data[-1].msg
    values = cell_state_values(m)
    assert {"state", "job_id", "run_id", "coil", "layer", "turn", "sim_time_s"} <= set(values), values
    assert m.node.endswith("sim_node")
    assert values["state"] in ("running", "idle"), values
    return values


#: the layout's topics a live view cannot serve: the step stream (read by the layout's progress
#: script; a view must not read it) and the outputs of the layout's own user scripts
NOT_LIVE = {"/winder/step_times", "/studio_script/winder_progress", "/studio_script/winder_tracking_error"}


def layout_topics() -> set[str]:
    """The topics layouts/winder_foxglove.json names (message paths, script inputs)."""
    text = (ROOT / "layouts" / "winder_foxglove.json").read_text()
    return set(re.findall(r'"(/(?:winder|diagnostics|clock|studio_script)[A-Za-z_/]*)', text))


def check_advertised(client: Client, ns: str = "") -> None:
    advertised = {c["topic"]: c["schemaName"] for c in client.channels.values()}
    assert advertised == {(t if t == "/diagnostics" else ns + t): kind for t, kind in LIVE_TOPICS.items()}
    if not ns:  # the layout names the root namespace's topics
        named = layout_topics()
        assert "/winder/joint_states" in named and "/winder/job" in named  # the pattern finds what it must
        assert named - NOT_LIVE <= set(advertised), (
            f"the layout names topics a live cell does not serve: {named}"
        )
    schema = client.topic_channel(f"{ns}/winder/joint_states")["schema"]
    # the whole definition, its dependencies included, as rosbag2 writes it: Foxglove decodes with it alone
    assert schema.startswith("std_msgs/Header header\nstring[] name\nfloat64[] position")
    assert "MSG: std_msgs/Header" in schema and "MSG: builtin_interfaces/Time" in schema


async def watch_live(port: int, job_id: str, ns: str = "") -> Client:
    """Connect, check the channels, subscribe to joint states, state, job and
    diagnostics of the cell in ``ns``, and check what they bring."""
    client = await connect(port)
    await client.until(lambda: len(client.channels) >= len(LIVE_TOPICS), 10, "every channel advertised")
    assert "playbackControl" not in client.info["capabilities"]
    check_advertised(client, ns)
    states, state, job = f"{ns}/winder/joint_states", f"{ns}/winder/state", f"{ns}/winder/job"
    await client.subscribe([states, state, job, "/diagnostics"])
    await client.until(
        lambda: len(client.of(states)) >= 50 and bool(client.of(job)) and bool(client.of("/diagnostics")),
        60,
        "50 joint states, the job and a status",
    )
    await client.drain(0.5)
    check_joint_states(client.of(states), job_id)
    values = check_state(client.of(state))
    description = client.of(job)[-1].msg  # a winder_interfaces/JobDescription
    assert description.job_id == job_id and description.run_id == values["run_id"]
    names = {s.name for d in client.of("/diagnostics") for s in d.msg.status}
    assert all(in_namespace(n, ns) for n in names), f"statuses of another namespace served: {names}"
    await client.ws.close()
    return client


# -- the tests -------------------------------------------------------------------------------


def test_run_foxglove_serves_the_live_cell(procs: Procs, ros: Any, tmp_path: Path) -> None:
    """``winder run --foxglove 0``: a client subscribes to joint states and
    state, and decodes them; the view is no part of the cell (one consumer on
    the graph: the sim node)."""
    from winder.ros.graph import consumers

    run = winder(procs, "run", *LONG, "--bag-dir", str(tmp_path / "bags"), "--foxglove", "0")
    port = served_port(procs, run)
    asyncio.run(watch_live(port, "rw400"))
    # the probe's graph is what it has discovered so far: wait for the consumer, then count them
    spin_until(ros, lambda: bool(consumers(ros, "")), 10, "the cell's consumer on the graph")
    assert consumers(ros, "") == [("sim_node", "/")]
    assert run.poll() is None, procs.log(run)
    procs.stop(run)
    assert "Traceback" not in procs.log(run)


@pytest.mark.parametrize(
    ("sig", "after"),
    [("SIGTERM", 0.2), ("SIGINT", 0.8), ("SIGTERM", 1.4), ("SIGINT", 2.0), ("SIGINT", 3.0)],
)
def test_a_signal_at_any_moment_ends_run_foxglove(
    procs: Procs, tmp_path: Path, sig: str, after: float
) -> None:
    """``winder run --foxglove``: a signal while it loads, starts the server,
    rclpy, the view's thread or the nodes, or while the job runs: 'interrupted',
    status 130, no traceback, every bag closed. With rclpy's own handlers,
    which shut the context down from their thread under the view's, a signal
    in the middle of creating the view's subscriptions ended with a
    traceback (2 of 40 under load)."""
    import signal

    from winder.procs import in_mask

    bags = tmp_path / "bags"
    run = winder(procs, "run", *LONG, "--bag-dir", str(bags), "--foxglove", "0")
    # from the moment it takes SIGTERM: before it, the interpreter is still starting and the
    # signal's default action ends it (-15, 0.2 s after the start on a machine at load 15)
    wait.until(
        lambda: in_mask(run.pid, "SigCgt", signal.SIGTERM) or run.poll() is not None, 30, "its handlers"
    )
    time.sleep(after)  # the signal's moment is the subject (any moment of the start): not a wait
    run.send_signal(getattr(signal, sig))
    run.wait(timeout=30)
    log = procs.log(run)
    assert run.returncode == 130, log
    assert "interrupted" in log and "Traceback" not in log, log
    for bag in bags_in(bags):
        assert (bag / "metadata.yaml").is_file(), sorted(bag.iterdir())


@pytest.mark.parametrize("ns", ["", "/c1"], ids=["root", "namespace"])
def test_view_serves_a_cell_started_without_it(procs: Procs, ros: Any, tmp_path: Path, ns: str) -> None:
    """``winder view`` beside a running cell: the latched job, path and state
    reach a client that connects mid-run; the cell goes on; Ctrl-C ends the view, exit 0."""
    from winder.ros.graph import consumers

    run = winder(procs, "run", *LONG, "--bag-dir", str(tmp_path / "bags"), "--namespace", ns)
    wait.spin_until(
        ros,
        lambda: f"{ns}/winder/state" in [n for n, _ in ros.get_topic_names_and_types()],
        60,
        f"{ns}/winder/state on the graph",
        heard=lambda: (sorted(n for n, _ in ros.get_topic_names_and_types()), procs.log(run)[-1000:]),
    )
    view = winder(procs, "view", "--port", "0", "--namespace", ns)
    port = served_port(procs, view)
    client = asyncio.run(watch_live(port, "rw400", ns))
    assert client.of(f"{ns}/winder/job")[0].log_time > 0
    spin_until(ros, lambda: bool(consumers(ros, ns)), 10, "the cell's consumer on the graph")
    assert consumers(ros, ns) == [("sim_node", ns or "/")]
    assert procs.stop(view) == 0
    out = procs.log(view)
    assert re.search(r"served \d+ messages", out) and "Traceback" not in out, out
    assert run.poll() is None, "the cell stopped with the view"


INTRUDER = TEST / "consumers" / "intruder.py"


def forged(d: Data) -> bool:
    """Whether a message served is one of the intruder's (test/consumers/intruder.py)."""
    m = d.msg
    if d.topic.endswith("/winder/joint_states"):
        return list(m.name) != JOINTS
    if d.topic.endswith("/winder/state"):
        return m.message == "forged"
    if d.topic.endswith("/winder/job"):
        return bool(m.run_id.endswith("_99"))  # the intruder's forgery of the run's description
    if d.topic == "/diagnostics":
        return any(
            st.message == "forged ERROR" or any(kv.value == "/FAKE" for kv in st.values) for st in m.status
        )
    raise AssertionError(f"no forgery check for {d.topic}")


def test_the_live_view_serves_only_the_cells_own(procs: Procs, tmp_path: Path) -> None:
    """A foreign node in the cell's namespace forges its joint states, state,
    job and statuses while ``winder run --foxglove`` serves the live cell:
    the client gets the cell's messages of each and none of the forger's;
    the view names the forger once (a WARN) and the summary counts it."""
    bags = tmp_path / "bags"
    # the default job paced at 7 x the wall clock: 12 s
    real_time = ["--real-time", "--real-time-factor", "7"]
    run = winder(procs, "run", *real_time, "--bag-dir", str(bags), "--foxglove", "0")
    port = served_port(procs, run)
    intruder = procs.launch(
        [sys.executable, str(INTRUDER), "--forge", "joints,state,job,diagnostics", "--period", "0.05"],
        "intruder",
    )
    topics = ["/winder/joint_states", "/winder/state", "/winder/job", "/diagnostics"]

    async def watch() -> Client:
        client = await connect(port)
        await client.until(lambda: len(client.channels) >= len(LIVE_TOPICS), 10, "every channel advertised")
        await client.subscribe(topics)
        await client.until(lambda: "forging" in procs.log(intruder), 60, "the intruder to forge")
        await client.drain(3.0)  # 60 forgeries of each kind
        await client.ws.close()
        return client

    client = asyncio.run(watch())
    for topic in topics:
        assert client.of(topic), f"nothing of the cell's on {topic}"
    served = [d for d in client.data if forged(d)]
    assert not served, f"{len(served)} forged messages served, first: {served[0]}"
    assert run.wait(timeout=120) == 0, procs.log(run)
    out = procs.log(run)
    # the view's node says so once, whatever it refused of the intruder's
    said = re.findall(r"\[winder_view\]: \S+: messages from /intruder ignored .*", out)
    assert len(said) == 1 and "only the cell's own nodes show in the live view" in said[0], out
    found = re.search(r"ignored, foreign +(.*)", out)
    assert found and "live view: /intruder (" in found[1], out
    assert "Traceback" not in out


def test_view_serves_a_replay_where_no_cell_runs(
    procs: Procs, tmp_path: Path, bag: Callable[[str], Path]
) -> None:
    """``winder view`` with no cell in the namespace serves what ``winder
    play`` publishes there: a recording replayed is shown as it comes (the
    player is no cell's node, and no cell is there to misrepresent)."""
    recorded = bag("pole1")
    view = winder(procs, "view", "--port", "0")
    port = served_port(procs, view)
    states, job = "/winder/joint_states", "/winder/job"

    async def watch() -> Client:
        client = await connect(port)
        await client.until(lambda: len(client.channels) >= len(LIVE_TOPICS), 10, "every channel advertised")
        await client.subscribe([states, job])
        winder(procs, "play", str(recorded), "--loop")
        await client.until(lambda: len(client.of(states)) >= 20 and bool(client.of(job)), 60, "the replay")
        await client.ws.close()
        return client

    client = asyncio.run(watch())
    assert all(list(d.msg.name) == JOINTS for d in client.of(states))
    assert client.of(job)[-1].msg.job_id == "pole1"
    assert procs.stop(view) == 0
    out = procs.log(view)
    assert "ignored, foreign" not in out and "Traceback" not in out, out


def test_play_foxglove_plays_pauses_and_seeks(procs: Procs, tmp_path: Path) -> None:
    """``winder play BAG --foxglove 0``: the recording's range in serverInfo,
    paused until the client plays; the messages are the bag's, at their log
    times; pause stops them, a seek starts again there with the latched job first."""
    done = subprocess.run(
        [str(BIN / "winder"), "run", *TINY, "--bag-dir", str(tmp_path / "bags")],
        env=procs.env,
        capture_output=True,
        text=True,
        timeout=300,
        stdin=subprocess.DEVNULL,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    (bag,) = bags_in(tmp_path / "bags")
    recorded = rosbags_read(bag)
    states = recorded["/winder/joint_states"]
    first = min(t for msgs in recorded.values() for t, _ in msgs)
    last = max(t for msgs in recorded.values() for t, _ in msgs)

    play = winder(procs, "play", str(bag), "--foxglove", "0")
    port = served_port(procs, play)
    second = subprocess.run(  # the port is the first one's now: one line, exit 2
        [str(BIN / "winder"), "play", str(bag), "--foxglove", str(port)],
        env=procs.env,
        capture_output=True,
        text=True,
        timeout=120,
        stdin=subprocess.DEVNULL,
    )
    assert second.returncode == 2 and len(second.stderr.strip().splitlines()) == 1, second.stderr
    assert f"--foxglove={port} is invalid" in second.stderr and "in use" in second.stderr

    async def scenario() -> None:
        client = await connect(port)
        info = client.info
        assert {"playbackControl", "time"} <= set(info["capabilities"])
        start = info["dataStartTime"]["sec"] * 10**9 + info["dataStartTime"]["nsec"]
        end = info["dataEndTime"]["sec"] * 10**9 + info["dataEndTime"]["nsec"]
        assert (start, end) == (first, last)
        await client.subscribe(["/winder/joint_states", "/winder/job"])
        await client.drain(0.5)
        assert not client.data, "data before the client played"

        await client.control("play", 4.0, None, "play-1")
        await client.until(lambda: len(client.of("/winder/joint_states")) >= 30, 30, "30 joint states")
        assert client.states[0] == {
            "status": 0,
            "time": start,
            "speed": 4.0,
            "did_seek": False,
            "id": "play-1",
        }
        by_time = {t: m for t, m in states}
        for d in client.of("/winder/joint_states"):
            assert d.log_time in by_time, "a log time the bag does not have"
            assert list(d.msg.position) == list(by_time[d.log_time].position)
        times = [d.log_time for d in client.of("/winder/joint_states")]
        assert times == sorted(times)
        assert client.times and client.times[-1] <= last

        await client.control("pause", 4.0, None, "pause-1")
        await client.until(lambda: any(s["id"] == "pause-1" for s in client.states), 10, "the pause's state")
        assert client.states[-1]["status"] == 1
        await client.drain(0.3)
        n = len(client.data)
        await client.drain(1.0)
        assert len(client.data) == n, "messages while paused"

        middle = states[len(states) // 2][0]
        client.data.clear()
        await client.control("play", 4.0, middle, "seek-1")
        await client.until(
            lambda: len(client.of("/winder/joint_states")) >= 10, 30, "joint states after the seek"
        )
        seek = next(s for s in client.states if s["id"] == "seek-1")
        assert seek["did_seek"] and seek["time"] == middle and seek["status"] == 0
        assert all(d.log_time >= middle for d in client.of("/winder/joint_states"))
        (job,) = client.of("/winder/job")  # latched: its last message before the seek, sent first
        assert job.log_time < middle and job.msg.job_id == "rw400"

        await client.control("play", 100.0, None, "fast")
        await client.until(lambda: any(s["status"] == 3 for s in client.states), 60, "the end (Ended)")
        # the state goes on the SDK's control plane, the data on its data plane: Ended may come first
        await client.until(
            lambda: client.of("/winder/joint_states")[-1].log_time == states[-1][0],
            10,
            "the last joint state",
        )
        await client.ws.close()

    asyncio.run(scenario())
    assert procs.stop(play) == 0
    out = procs.log(play)
    assert "served" in out and "1 seeks" in out and "Traceback" not in out, out


@pytest.mark.parametrize(
    ("argv", "option"),
    [
        (["run", *TINY, "--foxglove", "70000"], "--foxglove=70000 is invalid"),
        (["run", *TINY, "--foxglove", "x"], "--foxglove='x' is invalid"),
        (["view", "--port", "-1"], "--port=-1 is invalid"),
    ],
)
def test_a_port_out_of_range_is_one_line(procs: Procs, tmp_path: Path, argv: list[str], option: str) -> None:
    r = subprocess.run(
        [str(BIN / "winder"), *argv, *(["--bag-dir", str(tmp_path / "bags")] if argv[0] == "run" else [])],
        env=procs.env,
        capture_output=True,
        text=True,
        timeout=120,
        stdin=subprocess.DEVNULL,
    )
    assert r.returncode == 2, r.stdout + r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and option in lines[0] and "[0, 65535]" in lines[0], r.stderr
    assert not (tmp_path / "bags").exists()


@pytest.mark.parametrize("command", ["run", "view"])
def test_a_port_in_use_is_one_line_and_starts_nothing(procs: Procs, tmp_path: Path, command: str) -> None:
    held = free_port()
    port = str(held.getsockname()[1])
    argv = {
        "run": ["run", *TINY, "--bag-dir", str(tmp_path / "bags"), "--foxglove", port],
        "view": ["view", "--port", port],
    }[command]
    try:
        r = subprocess.run(
            [str(BIN / "winder"), *argv],
            env=procs.env,
            capture_output=True,
            text=True,
            timeout=120,
            stdin=subprocess.DEVNULL,
        )
    finally:
        held.close()
    assert r.returncode == 2, r.stdout + r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    option = "--port" if command == "view" else "--foxglove"
    assert f"{option}={port} is invalid" in lines[0] and "in use" in lines[0], lines[0]
    assert not (tmp_path / "bags").exists(), "the cell started"
