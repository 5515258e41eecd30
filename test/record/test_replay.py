"""``winder play`` and ``winder resim`` on a bag written by the real nodes.

The player runs as its own process (the command a user types) on the test's
ROS domain; a real rclpy subscriber in this process takes every message of
every topic, serialized, and each topic's list is compared, in order and byte
for byte, with the bag as rosbags reads it. The re-simulation runs the real
sim node; its bag is checked against the source bag (the step times) and
against the closed-form step response of the linear model (the joint states).
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import BIN, Procs, final_report, next_domain, release_domain, rosbags_read, spin_until
from ruamel.yaml import YAML
from support import wait
from support.bags import joint_arrays, rewrite, rosbags_raw, step_rows
from support.cli import assert_one_line_error, run_cli
from support.oracles import params, superpose

from winder.contract.qos import qos_of
from winder.procs import in_mask
from winder.record.bag import bags_in
from winder.record.raw import read_raw
from winder.record.reader import read_run

pytestmark = pytest.mark.ros

#: a short job with an operator pause, resume and override: every topic of the cell has messages
OPS = ["--job-id", "ops", "--turns-per-layer", "2", "--poles", "2", "--layers", "1"]
SCHEDULE = "pause@0.8,resume@1.2,override@1.6=0.8"
LATCHED = ("/winder/job", "/winder/path", "/winder/sim_config", "/winder/profile_config", "/winder/state")
TYPES = {
    "std_msgs/msg/String": ("std_msgs.msg", "String"),
    "trajectory_msgs/msg/JointTrajectory": ("trajectory_msgs.msg", "JointTrajectory"),
    "std_msgs/msg/Int64MultiArray": ("std_msgs.msg", "Int64MultiArray"),
    "sensor_msgs/msg/JointState": ("sensor_msgs.msg", "JointState"),
    "rosgraph_msgs/msg/Clock": ("rosgraph_msgs.msg", "Clock"),
    "geometry_msgs/msg/WrenchStamped": ("geometry_msgs.msg", "WrenchStamped"),
    "diagnostic_msgs/msg/DiagnosticArray": ("diagnostic_msgs.msg", "DiagnosticArray"),
    "diagnostic_msgs/msg/DiagnosticStatus": ("diagnostic_msgs.msg", "DiagnosticStatus"),
    "winder_interfaces/msg/CellState": ("winder_interfaces.msg", "CellState"),
    "winder_interfaces/msg/ControlEvent": ("winder_interfaces.msg", "ControlEvent"),
    "winder_interfaces/msg/JobDescription": ("winder_interfaces.msg", "JobDescription"),
    "winder_interfaces/msg/JobReport": ("winder_interfaces.msg", "JobReport"),
}


@pytest.fixture(scope="module")
def ops_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The ops run's bag, made once for the module. Its domain is handed back
    as the run ends: the tests play the bag on domains of their own."""
    root = tmp_path_factory.mktemp("ops")
    domain = next_domain()
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    try:
        r = subprocess.run(
            [str(BIN / "winder"), "run", *OPS, "--schedule", SCHEDULE, "--bag-dir", str(root)],
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


def msgtypes(bag: Path) -> dict[str, str]:
    raw = read_raw(bag, keep=lambda _t: False)
    return {c.topic: c.msgtype for c in raw.connections.values()}


def message_class(msgtype: str) -> Any:
    import importlib

    module, name = TYPES[msgtype]
    return getattr(importlib.import_module(module), name)


class Taker:
    """Raw subscriptions on every topic of a bag (as the player names them):
    reliable and keep-all (latched: transient-local), so no message may be lost."""

    def __init__(self, node: Any, bag: Path, prefix: str = "", topics: tuple[str, ...] | None = None) -> None:
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        self.got: dict[str, list[bytes]] = {}
        self.subs = []
        for topic, msgtype in msgtypes(bag).items():
            if topics is not None and topic not in topics:
                continue
            name = topic if topic == "/diagnostics" else prefix + topic
            latched = topic in LATCHED or topic.endswith("/control")
            qos = QoSProfile(
                depth=100 if latched else 1,
                reliability=ReliabilityPolicy.RELIABLE,
                durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
                history=HistoryPolicy.KEEP_LAST if latched else HistoryPolicy.KEEP_ALL,
            )
            self.got[topic] = []
            self.subs.append(
                node.create_subscription(
                    message_class(msgtype),
                    name,
                    lambda m, t=topic: self.got[t].append(bytes(m)),
                    qos,
                    raw=True,
                )
            )


def expected(bag: Path, start_offset: float = 0.0) -> dict[str, list[bytes]]:
    """What a subscriber is owed, from rosbags: every message from the start
    on, and for each latched topic the last one before it."""
    msgs = rosbags_raw(bag)
    first = min(t for _, t, _ in msgs)
    start = first + round(start_offset * 1e9)
    out: dict[str, list[bytes]] = {}
    before: dict[str, bytes] = {}
    for topic, t, data in msgs:
        out.setdefault(topic, [])
        if t >= start:
            out[topic].append(data)
        elif topic in LATCHED or topic.endswith("/control"):
            before[topic] = data
    for topic, data in before.items():
        out[topic].insert(0, data)
    return out


def play(procs: Procs, bag: Path, *args: str) -> subprocess.Popen[str]:
    """``winder play`` as a process of the test's domain (stopped at teardown if the test fails)."""
    p: subprocess.Popen[str] = procs.children.start(
        [str(BIN / "winder"), "play", str(bag), *args],
        "winder-play",
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    return p


def spin_while(node: Any, p: subprocess.Popen[str], timeout: float) -> tuple[str, str]:
    spin_until(node, lambda: p.poll() is not None, timeout, "winder play to end")
    out, err = p.communicate()
    assert p.returncode == 0, out + err
    assert "Traceback" not in err
    return out, err


def taken(node: Any, taker: Taker, want: dict[str, list[bytes]]) -> dict[str, list[bytes]]:
    """What ``taker`` took, once it has taken as many messages as ``want``
    holds on every topic (30 s at most). The player ends when every reader
    has acknowledged every message, which means the message is in the
    reader's queue, not yet taken by its callback: on a loaded machine a
    look right after the player's end found 586 of 811 /clock messages."""
    spin_until(
        node,
        lambda: all(len(taker.got.get(t, [])) >= len(w) for t, w in want.items()),
        30,
        "every message taken from the readers' queues",
    )
    return taker.got


def same(got: dict[str, list[bytes]], want: dict[str, list[bytes]]) -> None:
    """Every topic's messages, in order, byte for byte (CDR's 4-byte end padding aside)."""
    assert set(got) == set(want)
    for topic in want:
        g = [d.rstrip(b"\0") for d in got[topic]]
        w = [d.rstrip(b"\0") for d in want[topic]]
        assert len(g) == len(w), f"{topic}: {len(g)} messages received, {len(w)} recorded"
        bad = next((i for i, (a, b) in enumerate(zip(g, w, strict=True)) if a != b), None)
        assert bad is None, f"{topic}: message {bad} differs"


# -- the bag as rosbag2 tools see it ------------------------------------------------------


def test_metadata_records_the_qos_and_type_hash_the_nodes_offer(
    ops_bag: Path, procs: Procs, ros: Any
) -> None:
    """Each topic's offered_qos_profiles and type_description_hash in
    metadata.yaml equal what the live nodes' publishers offer on the graph."""
    for node in ("sim_node", "profile_node", "interp_node"):
        procs.start(node, "-p", "autostart:=false") if node == "interp_node" else procs.start(node)
    meta = YAML(typ="safe").load((ops_bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    topics = {t["topic_metadata"]["name"]: t["topic_metadata"] for t in meta["topics_with_message_count"]}
    live = [t for t in topics if t not in ("/diagnostics",)]
    spin_until(
        ros,
        lambda: all(ros.get_publishers_info_by_topic(t) for t in live),
        30,
        "a publisher on every recorded topic",
    )
    for topic in live:
        recorded = topics[topic]
        assert recorded["offered_qos_profiles"], f"{topic}: no QoS recorded"
        (q,) = recorded["offered_qos_profiles"]
        # the graph carries reliability and durability (DDS discovery does not
        # tell history and depth: rosbag2 itself records them "unknown")
        for info in ros.get_publishers_info_by_topic(topic):
            offered = info.qos_profile
            for key in ("reliability", "durability"):
                assert getattr(offered, key).name.lower() == q[key], (
                    topic,
                    key,
                    getattr(offered, key),
                    q[key],
                )
            assert str(info.topic_type_hash) == recorded["type_description_hash"], topic
    assert all(qos_of(t) is not None for t in topics)


# -- winder play ---------------------------------------------------------------------------


@pytest.mark.parametrize(("compression", "rate"), [("lz4", "1"), ("none", "20"), ("zstd", "20")])
def test_play_delivers_every_message_in_order(
    ops_bag: Path, procs: Procs, ros: Any, tmp_path: Path, compression: str, rate: str
) -> None:
    bag = ops_bag if compression == "lz4" else rewrite(read_raw(ops_bag), tmp_path / "b", compression)
    """Every message of every topic, byte for byte, in order; and --clock
    drives a use_sim_time node (this one) to the recorded simulated time."""
    from rclpy.parameter import Parameter

    ros.set_parameters([Parameter("use_sim_time", Parameter.Type.BOOL, True)])
    taker = Taker(ros, bag)
    p = play(procs, bag, "--rate", rate, "--clock", "--wait-for-subscribers", "20")
    out, _ = spin_while(ros, p, 120)
    want = expected(bag)
    same(taken(ros, taker, want), want)
    total = sum(len(v) for v in want.values())
    assert f"published {total} messages on {len(want)} topics" in out
    stamps = sorted(m.clock.sec * 10**9 + m.clock.nanosec for _, m in rosbags_read(bag)["/clock"])
    now = ros.get_clock().now().nanoseconds
    assert now in stamps and now >= stamps[len(stamps) // 2], now


def test_a_reader_on_the_graph_before_play_hears_the_first_message(
    ops_bag: Path, procs: Procs, ros: Any
) -> None:
    """rosbag2 #109: without any option the player waits (bounded) until the
    subscribers already on the graph match its publishers, so the volatile
    topics' first messages reach them too, not only the latched ones.
    ``--force`` skips the 1 s look for a live cell, which alone gave
    discovery time enough; with ``--force --no-wait`` this reader got none
    of the 6 /diagnostics messages."""
    volatile = ("/winder/joint_states", "/winder/joint_commands", "/winder/step_times", "/diagnostics")
    taker = Taker(ros, ops_bag, topics=volatile)
    spin_until(ros, lambda: True, 0.2, "")
    p = play(procs, ops_bag, "--rate", "20", "--force")
    _, err = spin_while(ros, p, 120)
    assert "unmatched" not in err, err
    want = {t: m for t, m in expected(ops_bag).items() if t in volatile}
    assert all(want.values())
    same(taken(ros, taker, want), want)


def test_no_wait_plays_at_once_and_a_bounded_wait_names_what_it_missed(
    ops_bag: Path, procs: Procs, tmp_path: Path
) -> None:
    """--no-wait skips the wait; --wait-for-subscribers S with no reader ends
    its wait after S s, says so in one line and plays anyway."""
    t0 = time.monotonic()
    p = play(procs, ops_bag, "--rate", "1000", "--no-wait", "--topics", "/winder/state")
    out, err = p.communicate(timeout=60)
    assert p.returncode == 0 and "published" in out, out + err
    p = play(procs, ops_bag, "--rate", "1000", "--wait-for-subscribers", "1.5", "--topics", "/winder/state")
    out, err = p.communicate(timeout=60)
    assert p.returncode == 0 and "published" in out, out + err
    assert "after 1.5 s still unmatched (playing anyway): no subscriber on any played topic" in err, err
    assert time.monotonic() - t0 < 30
    p = play(procs, ops_bag, "--no-wait", "--wait-for-subscribers", "2")
    _, err = p.communicate(timeout=60)
    assert p.returncode == 2 and "--no-wait" in err and len(err.strip().splitlines()) == 1, err


def test_start_offset_keeps_the_latched_topics(ops_bag: Path, procs: Procs, ros: Any) -> None:
    """From 2 s on: every message from there, and the job, path, configs,
    cell state and operator events as they stood at 2 s."""
    taker = Taker(ros, ops_bag)
    p = play(procs, ops_bag, "--rate", "10", "--start-offset", "2", "--clock", "--wait-for-subscribers", "20")
    spin_while(ros, p, 120)
    want = expected(ops_bag, 2.0)
    same(taken(ros, taker, want), want)
    full = expected(ops_bag)
    assert len(want["/winder/joint_states"]) < len(full["/winder/joint_states"]) * 0.8
    assert want["/winder/job"] == full["/winder/job"]


def test_a_late_subscriber_gets_the_latched_job(ops_bag: Path, procs: Procs, ros: Any) -> None:
    """A subscriber that joins after the job went out still gets the job, the
    path and the configs (transient-local, as recorded)."""
    early = Taker(ros, ops_bag, topics=("/winder/joint_states",))
    p = play(procs, ops_bag, "--rate", "1", "--wait-for-subscribers", "20")
    spin_until(ros, lambda: len(early.got["/winder/joint_states"]) >= 20, 60, "joint states from the player")
    late = Taker(
        ros, ops_bag, topics=("/winder/job", "/winder/path", "/winder/sim_config", "/winder/profile_config")
    )
    spin_until(ros, lambda: all(late.got.values()), 20, "the latched topics at the late subscriber")
    want = expected(ops_bag)
    for topic, got in late.got.items():
        assert [d.rstrip(b"\0") for d in got] == [d.rstrip(b"\0") for d in want[topic][-1:]], topic
    spin_while(ros, p, 120)


def test_namespace_pause_step_and_resume(ops_bag: Path, procs: Procs, ros: Any) -> None:
    """--namespace moves the cell; started paused, ~/play_next publishes one
    message at a time (in log-time order), ~/resume the rest."""
    from std_srvs.srv import Trigger

    taker = Taker(ros, ops_bag, prefix="/replayed")
    p = play(
        procs,
        ops_bag,
        "--namespace",
        "/replayed",
        "--start-paused",
        "--clock",
        "--wait-for-subscribers",
        "20",
    )
    calls = {k: ros.create_client(Trigger, f"/replayed/winder_player/{k}") for k in ("play_next", "resume")}
    spin_until(ros, lambda: all(c.service_is_ready() for c in calls.values()), 30, "the player's services")
    order = sorted(rosbags_raw(ops_bag), key=lambda m: m[1])  # log-time order (stable)
    for i in range(3):
        fut = calls["play_next"].call_async(Trigger.Request())
        spin_until(ros, fut.done, 10, "play_next")
        assert fut.result().success, fut.result().message
        spin_until(ros, lambda i=i: sum(map(len, taker.got.values())) >= i + 1, 10, "one message")
        wait.spin_for(ros, 0.3)  # the subject is what does not happen: no second message for one call
        assert sum(map(len, taker.got.values())) == i + 1  # one message per call, no more
        topic, _, data = order[i]
        assert taker.got[topic][-1].rstrip(b"\0") == data.rstrip(b"\0")
    fut = calls["resume"].call_async(Trigger.Request())
    spin_until(ros, fut.done, 10, "resume")
    assert fut.result().success
    spin_while(ros, p, 120)
    same(taken(ros, taker, expected(ops_bag)), expected(ops_bag))


def flip_in_a_chunk(bag: Path, out: Path) -> Path:
    shutil.copytree(bag, out)
    mcap = next(out.glob("*.mcap"))
    data = bytearray(mcap.read_bytes())
    pos, chunks = 8, []
    while data[pos] != 0x0F:
        length = int.from_bytes(data[pos + 1 : pos + 9], "little")
        if data[pos] == 0x06:
            chunks.append((pos, length))
        pos += 9 + length
    at, length = chunks[len(chunks) // 2]
    data[at + 9 + length // 2] ^= 0x10
    mcap.write_bytes(bytes(data))
    return out


def test_damaged_bags_and_bad_options_are_refused(ops_bag: Path, tmp_path: Path, bag: Any) -> None:
    """Nothing is played from a recording with a gap: one line, exit 2, as `winder analyze` words it."""
    lin2k = bag("lin2k")  # several chunks
    several = flip_in_a_chunk(lin2k, tmp_path / "several")
    assert_one_line_error(run_cli("play", str(several)), "damaged recording: 1 chunk(s) skipped")
    # the small bag is one chunk: its damage leaves nothing
    damaged = flip_in_a_chunk(ops_bag, tmp_path / "damaged")
    assert_one_line_error(run_cli("play", str(damaged)), "damaged", "chunk(s) skipped")
    cut = tmp_path / "cut"
    cut.mkdir()
    mcap = next(lin2k.glob("*.mcap"))
    (cut / mcap.name).write_bytes(mcap.read_bytes()[: mcap.stat().st_size * 2 // 3])
    assert_one_line_error(run_cli("play", str(cut)), "cut short", "winder bag recover")
    assert_one_line_error(run_cli("resim", str(damaged)), "damaged", "chunk(s) skipped")
    assert_one_line_error(run_cli("play", str(tmp_path / "missing")), "no such file")
    for args, needle in [
        (["--rate", "0"], "rate='0' is invalid"),
        (["--rate", "nan"], "rate='nan' is invalid"),
        (["--start-offset", "-1"], "start_offset='-1' is invalid"),
        (["--start-offset", "1e6"], "the recording lasts"),
        (["--topics", "/nope"], "no topic of the recording matches"),
        (["--topics", "("], "is invalid"),
        (["--namespace", "/a//b"], "namespace='/a//b' is invalid"),
    ]:
        assert_one_line_error(run_cli("play", str(ops_bag), *args), needle)
    assert_one_line_error(run_cli("resim", str(ops_bag), "--fork.J", "-1"), "fork.J")
    assert not any(tmp_path.glob("**/*_resim*"))


# -- winder resim --------------------------------------------------------------------------


def test_resim_with_another_inertia(ops_bag: Path, procs: Procs, tmp_path: Path) -> None:
    """The recorded step times through the sim node with twice the fork's
    inertia: the same step times to the nanosecond, the same operator events,
    other joint states, and those equal the closed-form response of the new
    motor; the new bag names its source."""
    source = read_run(ops_bag)
    fork = source.sim_config.axes["fork"] if source.sim_config else None
    assert fork is not None
    new_j = 2 * fork.J
    r = subprocess.run(
        [
            str(BIN / "winder"),
            "resim",
            str(ops_bag),
            "--fork.J",
            repr(new_j),
            "--bag-dir",
            str(tmp_path / "out"),
        ],
        capture_output=True,
        text=True,
        timeout=240,
        env=procs.env,
        stdin=subprocess.DEVNULL,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    assert f"fork.J {fork.J:g} -> {new_j:g}" in r.stdout
    (new,) = bags_in(tmp_path / "out")
    old_msgs, new_msgs = rosbags_read(ops_bag), rosbags_read(new)
    # the step times, every row, exactly
    np.testing.assert_array_equal(
        step_rows(new_msgs["/winder/step_times"]), step_rows(old_msgs["/winder/step_times"])
    )

    # the operator events, but for the run id
    def events(msgs: dict[str, list[tuple[int, Any]]]) -> list[dict[str, Any]]:
        # winder_interfaces/ControlEvent, as rosbags reads it: its fields (NaN, not said, as None)
        fields = [f for _, m in msgs["/winder/control"][:1] for f in m.__dataclass_fields__ if f.islower()]
        return [
            {f: None if getattr(m, f) != getattr(m, f) else getattr(m, f) for f in fields if f != "run_id"}
            for _, m in msgs["/winder/control"]
        ]

    assert events(new_msgs) == events(old_msgs) and events(old_msgs)
    config = json.loads(new_msgs["/winder/sim_config"][0][1].data)
    old_run = old_msgs["/winder/job"][0][1].run_id
    assert config["source_bag"] == str(ops_bag.resolve()) and config["source_run_id"] == old_run
    assert (
        config["axes"]["fork"]["J"] == new_j
        and config["axes"]["feed"] == json.loads(old_msgs["/winder/sim_config"][0][1].data)["axes"]["feed"]
    )
    new_job, old_job = new_msgs["/winder/job"][0][1], old_msgs["/winder/job"][0][1]
    new_run = new_job.run_id
    assert new_run != old_run and new.name == new_run
    # the same job, named a re-simulation of the recorded run
    assert (new_job.source_bag, new_job.source_run_id) == (str(ops_bag.resolve()), old_run)
    assert [(kv.key, kv.value) for kv in new_job.job] == [(kv.key, kv.value) for kv in old_job.job]
    assert [list(s.delta) for s in new_job.segments] == [list(s.delta) for s in old_job.segments]
    # the path and the ramp are recorded too, for the new run
    assert new_msgs["/winder/path"][0][1].header.frame_id == new_run
    ramp = json.loads(new_msgs["/winder/profile_config"][0][1].data)
    old_ramp = json.loads(old_msgs["/winder/profile_config"][0][1].data)
    assert ramp["run_id"] == new_run and {**ramp, "run_id": old_run} == old_ramp
    report = final_report(new_msgs)
    assert report["state"] == "done" and report["steps_done"] == report["steps_total"]
    # other joint states: the fork lags more
    t_old, pos_old, _ = joint_arrays(old_msgs["/winder/joint_states"])
    t_new, pos_new, _ = joint_arrays(new_msgs["/winder/joint_states"])
    np.testing.assert_array_equal(t_new, t_old)
    plan = read_run(new).plan
    assert np.max(np.abs(pos_new[:, 1] - pos_old[:, 1])) > 0.1 * plan.joint_step[1]  # a tenth of a step
    np.testing.assert_array_equal(pos_new[:, 0], pos_old[:, 0])  # the feed's motor did not change
    # the fork's joint states are the closed-form response of the new motor to the recorded steps
    rows = step_rows(new_msgs["/winder/step_times"])
    fork_pos = np.concatenate([[plan.segments[0].start[1]], rows[:, 3]])
    moved = np.nonzero(np.diff(fork_pos))[0]
    times = rows[moved, 0] / 1e9
    angles = np.diff(fork_pos)[moved] * fork.motor_step_angle
    wn, zeta, _ = params(fork.Zr, fork.L, fork.i_a, new_j, fork.D)
    pick = np.linspace(0, t_new.size - 1, 150).astype(int)
    theta, _ = superpose(wn, zeta, times, angles, t_new[pick])
    expected_pos = (plan.segments[0].start[1] + theta / fork.motor_step_angle) * plan.joint_step[1]
    scale = np.abs(angles).sum() / fork.motor_step_angle * plan.joint_step[1]
    assert np.max(np.abs(pos_new[pick, 1] - expected_pos)) <= 1e-9 * scale
    assert not math.isclose(wn, params(fork.Zr, fork.L, fork.i_a, fork.J, fork.D)[0])


def test_resim_of_a_resim_names_each_source(ops_bag: Path, procs: Procs, tmp_path: Path) -> None:
    """A re-simulation is a recording like any other: it plays and re-simulates again."""
    out = tmp_path / "a"
    for src, model in ((ops_bag, "nonlinear"), (None, "linear")):
        bag = src if src is not None else bags_in(out)[0]
        r = subprocess.run(
            [
                str(BIN / "winder"),
                "resim",
                str(bag),
                "--model",
                model,
                "--bag-dir",
                str(out if src else tmp_path / "b"),
            ],
            capture_output=True,
            text=True,
            timeout=240,
            env=procs.env,
            stdin=subprocess.DEVNULL,
        )
        assert r.returncode == 0, r.stdout + r.stderr
    (second,) = bags_in(tmp_path / "b")
    (first,) = bags_in(out)
    config = json.loads(rosbags_read(second)["/winder/sim_config"][0][1].data)
    assert config["source_bag"] == str(first.resolve()) and config["model"] == "linear"


@pytest.mark.parametrize("sig", ["SIGTERM", "SIGINT"])
@pytest.mark.parametrize("mode", [["--start-paused"], ["--rate", "1"]])
def test_a_signal_ends_the_player_paused_or_playing(
    ops_bag: Path, procs: Procs, ros: Any, sig: str, mode: list[str]
) -> None:
    """SIGTERM or SIGINT, paused or playing: the player ends at once with
    'interrupted' (status 130), no traceback."""
    import signal

    from std_srvs.srv import Trigger

    taker = Taker(ros, ops_bag)
    p = play(procs, ops_bag, *mode)
    if "--start-paused" in mode:  # paused: one message asked for shows the player in its loop, paused
        step = ros.create_client(Trigger, "/winder_player/play_next")
        spin_until(ros, step.service_is_ready, 60, "the player's play_next service")
        reply = step.call_async(Trigger.Request())
        spin_until(ros, reply.done, 30, "the play_next reply")
        assert reply.result().success, reply.result().message
    spin_until(  # the player plays (or has played the message asked for)
        ros,
        lambda: any(taker.got.values()),
        60,
        "a message from the player",
        heard=lambda: p.poll(),
    )
    t0 = time.monotonic()
    p.send_signal(getattr(signal, sig))
    out, err = p.communicate(timeout=20)
    assert time.monotonic() - t0 < 5.0
    assert p.returncode == 130, out + err
    assert "interrupted" in err and "Traceback" not in err, err


def catches(pid: int, signum: int) -> bool:
    """Whether process ``pid`` has a handler of its own for ``signum`` (its SigCgt mask)."""
    return in_mask(pid, "SigCgt", signum)


@pytest.mark.parametrize(
    ("sig", "after"), [("SIGTERM", 0.1), ("SIGINT", 0.6), ("SIGTERM", 1.1), ("SIGINT", 1.6)]
)
def test_a_signal_at_any_moment_of_the_start_ends_the_player(
    ops_bag: Path, procs: Procs, sig: str, after: float
) -> None:
    """A signal while the command loads, reads the bag, starts rclpy or looks
    at the graph: 'interrupted', status 130, no traceback. rclpy's own
    handlers once shut the context down under the player's service thread
    (SIGSEGV, about 1 Ctrl-C in 15 on a loaded machine, caught by CI), and a
    signal between rclpy's init and the node ended with a traceback.
    ``after`` counts from the moment the command's first line has run (it
    catches SIGTERM): before it, the interpreter itself is starting, and a
    SIGTERM there kills any Python program (0.1 s after the spawn was that
    moment on a loaded machine, fresh-clone CI)."""
    import signal

    p = play(procs, ops_bag, "--start-paused")
    wait.until(lambda: catches(p.pid, signal.SIGTERM), 30, "the command's handlers", running=p)
    time.sleep(after)  # the signal's moment is the subject (any moment of the start): not a wait
    p.send_signal(getattr(signal, sig))
    out, err = p.communicate(timeout=20)
    assert p.returncode == 130, out + err
    assert "interrupted" in err and "Traceback" not in err, err
