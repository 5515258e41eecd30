"""The ros2_control bridge (winder_bridge's bridge_node), as real processes.

ros2_control cannot be installed here (docs/BRIDGE.md): the controller
manager, the forward position controller, the joint state broadcaster and
the mock hardware are played by ``test/ros2_control_standin.py``, which
behaves as their documentation says (one process, the same node and topic
names). The interp and profile nodes are the real ones.

Oracles: the step rows recorded in the bag (what the profile node sent) and
the job's step lengths, worked with here by hand: the command at each tick
is the last row due times the step length, exactly; the wire helpers are
checked against rclpy's own serialization, the pacer against a loop.
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import Procs, closed_bags, final_report, rosbags_read, spin_until
from hypothesis import given, settings
from hypothesis import strategies as st
from support import wait
from support.paths import BIN, TEST

from winder.motion.axes import AXES
from winder.motion.job import Job

pytestmark = pytest.mark.ros

STANDIN = TEST / "ros2_control_standin.py"
#: the controller's joints, in its order, and the cell axis each drives (not the cell's order)
JOINTS = ["pole_joint", "flyer", "feed_screw"]
AXES_OF = ["pole", "fork", "feed"]
JOB = {"turns_per_layer": 4, "layers": 1, "poles": 2, "fork_steps_per_rev": 512, "job_id": "br"}
#: the ramp; a look-ahead of 0.2 s (not 0.05) so that steps are not late on two busy shared cores
RAMP = {"v_max": "4000.0", "a_max": "40000.0", "j_max": "1000000.0", "lookahead": "0.2"}
COMMANDS = "/forward_position_controller/commands"
#: following-error limits a whole run on the Python stand-in keeps within on two busy cores
#: (fork: 5 rad was passed by 0.007 rad in a fresh-clone run of the suite beside a busy loop,
#: the stand-in's trajectory controller sampling late; these tests are not about the fault)
LOOSE = (
    *("-p", "max_following_error.fork:=10.0", "-p", "max_following_error.pole:=1.0"),
    *("-p", "max_following_error.feed:=0.01"),
)


def start_standin(procs: Procs, *args: str) -> subprocess.Popen[bytes]:
    """The ros2_control stand-in, stopped with the test's other processes."""
    return procs.launch([sys.executable, str(STANDIN), "--joints", ",".join(JOINTS), *args], "standin")


def start_cell(
    procs: Procs,
    bags: Path,
    *bridge_params: str,
    ramp: dict[str, str] | None = None,
    interp: dict[str, str] | None = None,
) -> subprocess.Popen[bytes]:
    """bridge_node (joints mapped out of the cell's order), profile_node (``ramp``,
    else RAMP) and interp_node (autostart; JOB and ``interp``); the bridge process."""
    bridge = procs.start(
        "bridge_node",
        "-p",
        f"bag_dir:={bags}",
        "-p",
        "joint_state_timeout:=0.5",  # the stand-in is a Python process on two busy cores
        "-p",
        f"joints:=[{','.join(JOINTS)}]",
        "-p",
        f"axes:=[{','.join(AXES_OF)}]",
        *bridge_params,
    )
    procs.start("profile_node", *[a for k, v in (ramp or RAMP).items() for a in ("-p", f"{k}:={v}")])
    procs.start(
        "interp_node", *[a for k, v in {**JOB, **(interp or {})}.items() for a in ("-p", f"{k}:={v}")]
    )
    return bridge


def wait_for_bags(bags: Path, n: int, timeout: float = 60.0) -> list[Path]:
    """The first ``n`` closed bags, oldest first."""

    def enough() -> list[Path]:
        done = closed_bags(bags)
        return done if len(done) >= n else []

    return list(
        wait.until(
            enough,
            timeout,
            f"{n} closed bag(s) in {bags}",
            heard=lambda: sorted(b.name for b in bags.iterdir()) if bags.is_dir() else "no bag directory",
        )
    )


def call_start(ros: Any) -> tuple[bool, str]:
    """One call of the interp node's ~/start: (success, its message)."""
    from std_srvs.srv import Trigger

    client = ros.create_client(Trigger, "/interp_node/start")
    spin_until(ros, client.service_is_ready, 30, "interp_node/start")
    future = client.call_async(Trigger.Request())
    spin_until(ros, future.done, 10, "the start reply")
    reply = future.result()
    ros.destroy_client(client)
    return bool(reply.success), str(reply.message)


def start_again(ros: Any) -> str:
    """Call the interp node's ~/start until a run starts (the cell settles
    first); its reply. By the reply's success flag: a refusal's words ("job
    not started: not ready") hold "started" too."""
    replies: list[str] = []

    def taken() -> bool:
        ok, reply = call_start(ros)
        replies.append(reply)
        return ok

    # asked again every 0.5 s: a refusal while the cell settles is no failure
    wait.until(taken, 30, "a start taken by the interp node", heard=lambda: replies[-3:], poll=0.5)
    assert replies[-1].startswith("run "), replies[-1]
    return replies[-1]


def step_rows(raw: dict[str, list[tuple[int, Any]]]) -> np.ndarray:
    chunks = []
    for _, msg in raw["/winder/step_times"]:
        dims = msg.layout.dim
        chunks.append(np.asarray(msg.data, dtype=np.int64).reshape(dims[0].size, dims[1].size))
    return np.vstack(chunks)


def step_lengths() -> np.ndarray:
    """Each joint's travel per step (m or rad), by hand from the job fields."""
    per_axis = {
        "feed": 1e-5,  # feed_step, the default
        "fork": 2 * math.pi / JOB["fork_steps_per_rev"],
        "pole": 2 * math.pi / 1024,  # pole_steps_per_rev, the default
    }
    return np.array([per_axis[a] for a in AXES_OF])


def commands(raw: dict[str, list[tuple[int, Any]]]) -> tuple[np.ndarray, np.ndarray]:
    """Log times (ns) and positions of every command recorded."""
    t = np.array([t for t, _ in raw[COMMANDS]], dtype=np.int64)
    pos = np.array([np.asarray(m.data) for _, m in raw[COMMANDS]])
    return t, pos


def check_commands(
    raw: dict[str, list[tuple[int, Any]]], report: dict[str, str], *, stopped: bool = False
) -> np.ndarray:
    """Every command is the step counts of one row (or the start) times the
    step lengths, exactly; the rows they come from never go back, and never
    lie ahead of the command's time (t_ns <= its run time: log time less
    wall_start_ns). If no step came after its time (the bridge counts them),
    each command is exactly the last row due at its time. ``stopped``: a
    run a servo fault stopped, where the commands end holding the last row
    the bridge took (rows the fault came before are never taken, so never
    counted late, however long they waited): exact up to the first command
    of that row, then that row. The row index (0 = the start) of each command."""
    rows, wall0 = step_rows(raw), sim_config(raw)["wall_start_ns"]
    t_log, pos = commands(raw)
    assert np.all(np.diff(t_log) > 0)
    which = {"feed": 2, "fork": 3, "pole": 4}
    counts = np.vstack([np.zeros((1, 3), np.int64), rows[:, [which[a] for a in AXES_OF]]])
    # (pole, fork) strictly increases from row to row in this job: each command names its row
    index = {tuple(c): k for k, c in enumerate(counts.tolist())}
    steps = np.rint(pos / step_lengths()).astype(np.int64)
    k = np.array([index[tuple(c)] for c in steps.tolist()])
    np.testing.assert_array_equal(pos, counts[k] * step_lengths())  # exact: counts times step length
    due = np.searchsorted(rows[:, 0], t_log - wall0, side="right")  # the last row due at each command
    assert np.all(np.diff(k) >= 0) and np.all(k <= due)  # never back, never ahead of time
    if report["late_steps"] == "0":
        held = int(np.argmax(k == k[-1])) if stopped else len(k)  # the first command of the last row
        np.testing.assert_array_equal(k[: held + 1], due[: held + 1])
        assert np.all(k[held:] == k[-1])
    return k


def sim_config(raw: dict[str, list[tuple[int, Any]]]) -> dict[str, Any]:
    import json

    [(_, msg)] = raw["/winder/sim_config"]
    doc: dict[str, Any] = json.loads(msg.data)
    return doc


# -- the wire helpers and the pacer, against independent oracles ---------------


def test_payloads_are_what_rclpy_serializes() -> None:
    from rclpy.serialization import deserialize_message, serialize_message
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from winder.contract.cdr import CommandPayload, JointStateReader, clock_payload

    cmd = CommandPayload(3)
    cmd.values[:] = [1.5, -2.25, math.pi]
    theirs, ours = serialize_message(Float64MultiArray(data=[1.5, -2.25, math.pi])), cmd.bytes()
    assert len(ours) == len(theirs) and ours[20:] == theirs[20:]  # 16..20: padding (left unset by rclpy)
    assert ours[:16] == theirs[:16] and ours[16:20] == bytes(4)
    assert list(deserialize_message(ours, Float64MultiArray).data) == [1.5, -2.25, math.pi]
    msg = Clock()
    msg.clock.sec, msg.clock.nanosec = 12, 345_678_901
    assert clock_payload(12_345_678_901) == serialize_message(msg)

    reader = JointStateReader(JOINTS)
    for frame, names in [("", ["feed_screw", "x", "flyer", "pole_joint"]), ("base_link", ["flyer", "yy"])]:
        js = JointState(name=names, position=[float(i) + 0.5 for i in range(len(names))])
        js.header.frame_id = frame
        js.header.stamp.sec, js.header.stamp.nanosec = 7, 9
        for _ in range(2):  # the layout parsed, then reused
            got = reader.read(serialize_message(js))
            assert got is not None
            stamp, pos = got
            assert stamp == 7_000_000_009
            want = [names.index(j) + 0.5 if j in names else math.nan for j in JOINTS]
            np.testing.assert_array_equal(pos, want)
    assert reader.read(serialize_message(JointState(name=["flyer"], position=[]))) is None


@settings(max_examples=200, deadline=None)
@given(
    names=st.lists(st.sampled_from(["feed_screw", "flyer", "pole_joint", "x", "yy"]), unique=True),
    values=st.lists(st.floats(allow_infinity=False) | st.just(math.nan), min_size=5, max_size=5),
    frame=st.text(max_size=7),
)
def test_the_plain_python_read_is_the_numpy_read_where_every_joint_is_measured(
    names: list[str], values: list[float], frame: str
) -> None:
    """JointStateReader.read_all (the bridge's per-message path, no numpy)
    gives what read gives when the message measures every wanted joint, and
    None otherwise (a joint not named or NaN: the bridge then takes read)."""
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState

    from winder.contract.cdr import JointStateReader

    js = JointState(name=names, position=values[: len(names)])
    js.header.frame_id = frame
    raw = serialize_message(js)
    reader = JointStateReader(JOINTS)
    for _ in range(2):  # the layout parsed, then reused
        got, fast = reader.read(raw), reader.read_all(raw)
        assert got is not None
        measured = [values[names.index(j)] if j in names else math.nan for j in JOINTS]
        if any(math.isnan(v) for v in measured):
            assert fast is None
        else:
            assert fast is not None and fast[0] == got[0]
            assert fast[1] == measured == got[1].tolist()


def test_the_load_cell_and_velocity_reads_are_rclpy_s_messages() -> None:
    """The bridge's readers of a WrenchStamped (stamp, force.x) and of one
    joint's velocity in a JointState, against messages rclpy serializes:
    frame ids of every padding, a layout read again after a change, a
    message without velocities or without the joint (None), not a message
    (None)."""
    from geometry_msgs.msg import WrenchStamped
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState
    from winder_bridge.bridge_node import VelocityPick, wrench_force_x

    for frame in ["", "a", "ab", "abc", "load_cell", "load_cell_frame"]:
        msg = WrenchStamped()
        msg.header.stamp.sec, msg.header.stamp.nanosec = 1_795_000_000, 123_456_789
        msg.header.frame_id = frame
        msg.wrench.force.x, msg.wrench.force.y, msg.wrench.torque.x = 169.125, -2.0, 7.0
        assert wrench_force_x(serialize_message(msg)) == (1_795_000_000_123_456_789, 169.125)
    assert wrench_force_x(b"\x00\x01\x00\x00" + bytes(8)) is None

    pick = VelocityPick("flyer")
    cases = [
        (JOINTS, [1.0, 2.0, 3.0], [0.5, -49.0, 0.25], "", -49.0),
        (JOINTS, [1.5, 2.5, 3.5], [0.5, 12.0, 0.25], "", 12.0),  # the layout kept: the values read
        (["flyer", "x"], [1.0, 2.0], [3.5, 4.0], "frame", 3.5),  # another layout
        (JOINTS, [1.0, 2.0, 3.0], [], "", None),  # no velocities
        (["feed_screw", "x"], [1.0, 2.0], [3.0, 4.0], "", None),  # not the joint
        (JOINTS, [1.0, 2.0, 3.0], [0.5, math.nan, 0.25], "", None),  # NaN: not measured
        (JOINTS, [1.0, 2.0, 3.0], [0.5, -49.0, 0.25], "", -49.0),
    ]
    for names, pos, vel, frame, want in cases:
        js = JointState(name=names, position=pos, velocity=vel)
        js.header.frame_id = frame
        for _ in range(2):  # parsed, then reused
            assert pick.read(serialize_message(js)) == want, (names, vel)
    assert pick.read(b"\x00\x01\x00\x00") is None


def test_trajectory_payloads_read_back_in_rclpy_and_rosbags() -> None:
    """The bridge's JointTrajectory bytes: rclpy and rosbags read the same
    message back (rclpy's own serializer leaves bytes past the end, which a
    bag reader refuses: the reason for an encoder of our own)."""
    from rclpy.serialization import deserialize_message
    from rosbags.typesys import Stores, get_typestore
    from trajectory_msgs.msg import JointTrajectory

    from winder.contract.cdr import trajectory_payload

    names = ["pole_joint", "flyer", "feed_screw"]
    pos = np.array([[0.5, -1.25, 1e-5], [0.75, math.pi, 2e-5], [1.0, 7.0, -3e-5]])
    offsets = [1_000_000, 2_000_000, 1_500_000_000]
    frames = ["br_20261126_010203004_1", "", "a", "ab", "abc", "abcd"]  # the first point padded or not
    for frame in frames:
        raw = trajectory_payload(1_795_000_000_123_456_789, frame, names, offsets, pos)
        ros = deserialize_message(raw, JointTrajectory)
        bag = get_typestore(Stores.ROS2_JAZZY).deserialize_cdr(raw, "trajectory_msgs/msg/JointTrajectory")
        check_trajectory(ros, frame, names, offsets, pos)
        check_trajectory(bag, frame, names, offsets, pos)


def check_trajectory(msg: Any, frame: str, names: list[str], offsets: list[int], pos: np.ndarray) -> None:
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1_795_000_000, 123_456_789)
    assert msg.header.frame_id == frame and list(msg.joint_names) == names
    assert [p.time_from_start.sec * 10**9 + p.time_from_start.nanosec for p in msg.points] == offsets
    np.testing.assert_array_equal([list(p.positions) for p in msg.points], pos)
    assert all(len(p.velocities) == len(p.accelerations) == len(p.effort) == 0 for p in msg.points)


def test_a_grid_of_times_is_what_advancing_to_each_gives() -> None:
    """Pacer.advance_grid and CommandHistory.push_many, against advance and
    push one time at a time (the trajectory interface's points)."""
    from winder.contract.pacing import CommandHistory, Pacer

    rng = np.random.default_rng(7)
    rows = np.zeros((500, 5), np.int64)
    rows[:, 0] = np.cumsum(rng.integers(1, 3_000_000, 500))
    rows[:, 2:] = np.cumsum(rng.integers(-1, 2, (500, 3)), axis=0)
    one, grid = (Pacer([4, 3, 2], np.array([5, 6, 7]), np.array([0.5, 1e-3, 2.0])) for _ in range(2))
    one.add(rows[:300]), grid.add(rows[:300])
    h_one, h_grid = (CommandHistory(np.zeros(3), size=64) for _ in range(2))
    for lo in range(0, 1_200_000_000, 37_000_000):
        times = np.arange(lo, lo + 37_000_000, 1_000_000, dtype=np.int64)
        if lo == 444_000_000:
            one.add(rows[300:]), grid.add(rows[300:])
        want = []
        for t in times.tolist():
            one.advance(t)
            want.append(one.position.copy())
            h_one.push(t, one.position.copy())
        got = grid.advance_grid(times)
        h_grid.push_many(times, got)
        np.testing.assert_array_equal(got, np.array(want))
        assert grid.take_due() == one.take_due() and grid.held == one.held
        for a, b in [(lo - 5_000_000, lo + 3_000_000), (lo + 10_000_000, lo + 30_000_000)]:
            for x, y in zip(h_one.span(a, b), h_grid.span(a, b), strict=True):
                np.testing.assert_array_equal(x, y)


def test_pacer_commands_the_last_row_due() -> None:
    from winder.contract.pacing import Pacer

    rng = np.random.default_rng(3)
    n = 5000
    rows = np.zeros((n, 5), np.int64)
    rows[:, 0] = np.cumsum(rng.integers(1, 2_000_000, n))
    rows[:, 2:] = np.cumsum(rng.integers(-1, 2, (n, 3)), axis=0)
    cols, lengths = [4, 3, 2], step_lengths()  # pole, fork, feed: AXES_OF
    pacer = Pacer(cols, np.zeros(3, np.int64), lengths, capacity=64)
    ticks = np.sort(rng.integers(0, int(rows[-1, 0]) + 10, 3000))
    fed, executed = 0, 0
    for t in ticks:
        while fed < n and rows[fed, 0] <= t + 3_000_000:  # rows arrive a little ahead, in chunks of 7
            pacer.add(rows[fed : fed + 7])
            fed = min(fed + 7, n)
        pacer.advance(int(t))
        executed += pacer.take_due()
        due = [i for i in range(fed) if rows[i, 0] <= t]  # the oracle: a loop over the rows
        want = rows[due[-1], cols] if due else np.zeros(3, np.int64)
        assert executed == len(due)
        assert list(pacer.position) == [int(s) * float(k) for s, k in zip(want, lengths, strict=True)]


# -- the cell with the stand-in ---------------------------------------------------


def test_whole_job_commands_the_exact_steps_in_time(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """A whole job: done, the commands and measured states in the bag, each
    command the steps of the last row due at its time times the step
    lengths, exactly (so never ahead of its time and never back), the last
    one the job's end; the cell's clock from 0, increasing. A second run of
    the job, with the joints at the first one's end (job_origin zero), does
    not start: no command, a servo fault saying where the joints are."""
    bags = tmp_path / "bags"
    standin = start_standin(procs)
    bridge = start_cell(
        procs,
        bags,
        *LOOSE,
    )
    [bag] = wait_for_bags(bags, 1)
    raw = rosbags_read(bag)
    report = final_report(raw)
    assert report["state"] == "done", report["servo_fault"] or report
    assert report["errors"] == "0" and report["servo_fault"] == "", report
    assert report["steps_done"] == report["steps_total"] == str(Job(**JOB).total_steps)

    k = check_commands(raw, report)
    assert k[-1] == step_rows(raw).shape[0]  # the job's last row, held while settling
    t_log, pos = commands(raw)
    job = Job(**JOB)
    end = job.segments()[-1]
    final = [end.start[i] + end.delta[i] for i in (2, 1, 0)]  # pole, fork, feed
    assert pos[-1].tolist() == [s * k for s, k in zip(final, step_lengths().tolist(), strict=True)]
    assert len(t_log) > 50  # commanded tick by tick (its rate is a speed: bench/, not a check here)

    states = raw["/joint_states"]
    assert len(states) > 50
    assert list(states[-1][1].name) == JOINTS
    np.testing.assert_allclose(states[-1][1].position, pos[-1], rtol=0, atol=1e-12)  # the mock follows
    clock = np.array([m.clock.sec * 10**9 + m.clock.nanosec for _, m in raw["/clock"]])
    assert sim_config(raw)["clock_origin_ns"] == 0  # the node's first run
    assert clock[0] == 0 and np.all(np.diff(clock) > 0)  # from the arming tick on
    for p in (bridge, standin):
        assert p.poll() is None
    assert "Traceback" not in procs.log(bridge)
    assert "does not match number of interfaces" not in procs.log(standin)
    # winder's own reader and winder analyze take the bridge's bag: no motor
    # model in its sim_config (said in a note), the consumer's final report
    from winder.analysis.metrics import analyze
    from winder.record.reader import read_run

    run = read_run(bag)
    assert run.sim_config is None and any("no motor model" in n for n in run.notes), run.notes
    assert run.report["state"] == "done" and run.report["role"] == "consumer" and run.closed
    assert analyze(run).error_list == []

    start_again(ros)
    second = wait_for_bags(bags, 2)[1]
    raw2 = rosbags_read(second)
    report2 = final_report(raw2)
    assert report2["state"] == "incomplete" and report2["steps_done"] == "0", report2
    assert (
        "the run cannot start: joint flyer (fork axis) is at 50.2655 rad, the job starts at 0 rad"
        in (report2["servo_fault"])
    ), report2
    assert not raw2.get(COMMANDS) and not raw2.get("/clock")  # nothing commanded, the clock not started


def test_a_trajectory_controller_gets_every_point_exact_in_batches(
    tmp_path: Path, procs: Procs, ros: Any
) -> None:
    """interface trajectory: a JointTrajectory every batch to a
    JointTrajectoryController (the stand-in's, from its documented
    behaviour); every point, one every 1/rate s of run time for four batches
    ahead, is the step counts of the last row due at its time times the step
    lengths, exactly; points sent twice (the overlap) agree; the joints end
    at the job's end; the job is done."""
    bags = tmp_path / "bags"
    standin = start_standin(procs, "--interface", "trajectory", "--rate", "500")
    bridge = start_cell(
        procs,
        bags,
        *("-p", "interface:=trajectory", "-p", "controller:=joint_trajectory_controller"),
        *LOOSE,
        ramp={**RAMP, "lookahead": "0.02"},  # less than the bridge asks for: its ask must win
    )
    [bag] = wait_for_bags(bags, 1)
    raw = rosbags_read(bag)
    report = final_report(raw)
    assert report["state"] == "done", report["servo_fault"] or report
    assert report["steps_done"] == report["steps_total"] == str(Job(**JOB).total_steps)
    config = sim_config(raw)
    # the profile node sent the steps as far ahead as the bridge asked, not its own 20 ms: the
    # last row of each chunk lies that far beyond the chunk's log time (run time: less wall_start_ns)
    lead = [
        int(np.asarray(m.data, np.int64).reshape(m.layout.dim[0].size, m.layout.dim[1].size)[-1, 0])
        - (t - config["wall_start_ns"])
        for t, m in raw["/winder/step_times"]
    ]
    assert np.median(lead) >= 0.1e9, np.median(lead)
    assert config["interface"] == "trajectory" and config["batch"] == 0.02
    assert config["lookahead_min_s"] == pytest.approx(0.12)  # the steps come six batches ahead
    msgs = [m for _, m in raw["/joint_trajectory_controller/joint_trajectory"]]
    assert len(msgs) > 10 and all(list(m.joint_names) == JOINTS for m in msgs)
    stamp = np.array([m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in msgs], np.int64)
    assert np.all(np.diff(stamp) > 0)
    rows = step_rows(raw)
    which = {"feed": 2, "fork": 3, "pole": 4}
    counts = np.vstack([np.zeros((1, 3), np.int64), rows[:, [which[a] for a in AXES_OF]]])
    seen: dict[int, list[float]] = {}
    for m, s0 in zip(msgs, stamp, strict=True):
        for p in m.points:
            t_run = int(s0 - stamp[0]) + p.time_from_start.sec * 10**9 + p.time_from_start.nanosec
            assert t_run % 1_000_000 == 0  # on the 1 kHz grid of the run's time
            want = counts[int(np.searchsorted(rows[:, 0], t_run, side="right"))] * step_lengths()
            if report["late_steps"] == "0":  # else a starved tick (two busy cores) held some points
                np.testing.assert_array_equal(np.asarray(p.positions), want)
            assert seen.setdefault(t_run, list(p.positions)) == list(p.positions)  # the overlap agrees
    end = Job(**JOB).segments()[-1]
    final = np.array([end.start[i] + end.delta[i] for i in (2, 1, 0)]) * step_lengths()
    states = raw["/joint_states"]
    np.testing.assert_allclose(states[-1][1].position, final, rtol=0, atol=1e-12)  # the controller got there
    for proc in (bridge, standin):
        assert proc.poll() is None
    assert "Traceback" not in procs.log(bridge)
    assert "are not the controller's" not in procs.log(standin)


@pytest.mark.parametrize(
    ("fault", "joint", "words", "words2"),
    [
        (("--stuck", "feed_screw"), "feed_screw", "following error", "following error"),
        (("--silent-after", "0.4"), "", "joint_state_timeout", ""),
    ],
    ids=["stuck_joint", "silent_joint_states"],
)
def test_servo_fault_stops_the_cell(
    tmp_path: Path, procs: Procs, ros: Any, fault: tuple[str, str], joint: str, words: str, words2: str
) -> None:
    """A stuck joint (or a broadcaster gone quiet): an ERROR naming the joint,
    the run closed incomplete with a readable bag, the commands held from
    the fault on, the profile node told to abort, the interp node ready for
    a new start, and that next run clean (no stale step of the first).
    ``words2``: the fault of that next run (the joint still stuck); "": the
    broadcaster stays quiet, so the cell refuses to start until the hardware
    is back, and then runs the job to the end."""
    bags = tmp_path / "bags"
    standin = start_standin(procs, *fault)
    bridge = start_cell(
        procs,
        bags,
        *("-p", "max_following_error.fork:=5.0", "-p", "max_following_error.pole:=1.0"),
        *("-p", "job_origin:=start_position"),
        # the stuck joint's limit is the feed's default; a run meant to end (the silent case's
        # second) gets the tolerance of the other whole-run tests: a fresh Python stand-in
        # on two busy cores once lagged 5.9 mm behind its commands in a CI run
        *(() if words2 else ("-p", "max_following_error.feed:=0.01")),
    )
    [bag] = wait_for_bags(bags, 1)
    raw = rosbags_read(bag)
    report = final_report(raw)
    assert report["state"] == "incomplete", report
    assert 0 < int(report["steps_done"]) < int(report["steps_total"])
    fault_text = report["servo_fault"]
    assert words in fault_text and "servo fault: joint" in fault_text, fault_text
    if joint:
        assert f"joint {joint} (feed axis)" in fault_text
        assert "max_following_error.feed = 0.001 m" in fault_text
    servo = [
        st
        for _, arr in raw["/diagnostics"]
        for st in arr.status
        if st.name == "bridge_node: servo" and st.level == 2
    ]
    assert len(servo) == 1 and servo[0].message == fault_text
    assert "\n" not in fault_text
    assert [m.state for _, m in raw["/winder/state"]] == ["running", "failed"]
    # no jump up to the fault (the job starts at 0, where the stand-in's joints are): every
    # command is the steps of a row due at its time; then they hold
    check_commands(raw, report, stopped=True)

    log = wait.log_has(lambda: procs.log(bridge), "profile_node/abort: run", 30, "the bridge's abort call")
    # the bridge closes its run, then asks for the abort: the profile node answers either (what
    # it heard first) with the abort's braking, or that the run is closed and nothing more is sent
    assert "/profile_node/abort: run" in log, log
    assert "aborting" in log or "closed by its consumer already (failed)" in log, log

    if not words2:
        # no joint_states for a second: the bridge says it waits for the hardware, and a start
        # is refused (not taken, to fail 2 s later); a new broadcaster, and the cell starts again
        from diagnostic_msgs.msg import KeyValue
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        said: dict[str, str] = {}
        latched = QoSProfile(
            depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
        )
        sub = ros.create_subscription(
            KeyValue, "/winder/ready", lambda m: said.update({m.key: m.value}), latched
        )
        spin_until(ros, lambda: said.get("consumer") == "waiting", 20, "the bridge's winder/ready: waiting")
        ros.destroy_subscription(sub)
        assert "waiting for the hardware: no /joint_states" in procs.log(bridge).split(fault_text)[-1]
        ok, reply = call_start(ros)
        assert not ok and "not ready" in reply and "consumer" in reply, reply
        procs.stop(standin)
        standin = start_standin(procs)
        wait.log_has(
            lambda: procs.log(standin), "stand-in up", 30, "the new stand-in's start", running=standin
        )
    # the interp node stopped sending: a new start is taken
    start_again(ros)
    # that run (from where the joints stopped: job_origin start_position) faults the same way or
    # runs to the end, with a clean stream: the first run's late chunks were not taken for it
    second = wait_for_bags(bags, 2)[1]
    report2 = final_report(rosbags_read(second))
    if words2:
        assert report2["state"] == "incomplete" and words2 in report2["servo_fault"], report2
    else:
        assert report2["state"] == "done" and report2["steps_done"] == report2["steps_total"], report2
    assert (report2["gaps"], report2["chunks_rejected"], report2["steps_missing"]) == ("0", "0", "0"), report2
    assert "Traceback" not in procs.log(bridge)


def test_a_joint_the_broadcaster_never_names_keeps_the_run_from_starting(
    tmp_path: Path, procs: Procs, ros: Any
) -> None:
    """joint_states come, but never for one of the bridge's joints (a
    broadcaster configured for other joints): the cell is ready (the
    hardware talks), the run is taken and then refused within 2 s, naming
    that joint; nothing is commanded; the next start is taken again."""
    bags = tmp_path / "bags"
    procs.launch([sys.executable, str(STANDIN), "--joints", ",".join(JOINTS[:2])], "standin")
    bridge = start_cell(procs, bags)  # interp_node starts the job by itself
    [bag] = wait_for_bags(bags, 1)
    raw = rosbags_read(bag)
    report = final_report(raw)
    assert report["state"] == "incomplete" and report["steps_done"] == "0", report
    assert "the run cannot start: no joint_states for feed_screw within 2 s" in report["servo_fault"], report
    assert not raw.get(COMMANDS) and not raw.get("/clock")  # nothing commanded, the clock not started
    start_again(ros)
    second = wait_for_bags(bags, 2)[1]
    assert "no joint_states for feed_screw" in final_report(rosbags_read(second))["servo_fault"]
    assert "Traceback" not in procs.log(bridge)


def test_bad_settings_are_refused_in_one_line(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """Bad values at start: each reported in one line naming the setting, the
    value and what is allowed (the node runs on, blocked); at run time:
    refused with such a reason, cross-field rules included."""
    from support.ros_probe import set_params

    bad = {
        "rate": "0.5",
        "controller": "9lives",
        "joints": "[flyer,flyer,pole_joint]",
        "axes": "[feed,fork,spindle]",
        "max_following_error.feed": "-0.001",
        "joint_state_timeout": "0.0",
        "command_delay": "2.0",
    }
    args = [a for k, v in bad.items() for a in ("-p", f"{k}:={v}")]
    p = procs.start("bridge_node", "-p", f"bag_dir:={tmp_path / 'bags'}", *args)
    wait.log_has(lambda: procs.log(p), [f"{n}=" for n in bad], 30, "a line for each bad setting", running=p)
    lines = procs.log(p).splitlines()
    for name in bad:
        [line] = [x for x in lines if f"{name}=" in x and "invalid" in x]
        assert "must" in line or "is not" in line, line
    assert any("given twice" in x for x in lines)
    assert any("'spindle' is not one of feed, fork, pole" in x for x in lines)

    for values in (
        {"rate": 20000.0},
        {"joints": ["a", "b"]},  # two joints for three axes
        {"axes": ["feed", "feed", "pole"]},
        {"joints": "flyer"},  # not a list
        {"max_following_error.fork": 0.0},
        # its topics would be longer than ROS allows a name: the node died on this (RCLError)
        {"controller": "x" * 300},
    ):
        [res] = set_params(ros, "bridge_node", values)
        [name] = values
        assert not res.successful, values
        assert name in res.reason and "\n" not in res.reason, res.reason
    [res] = set_params(ros, "bridge_node", {"joints": ["j_pole", "j_fork", "j_feed"]})
    assert res.successful, res.reason
    [res] = set_params(ros, "bridge_node", {"controller": "x" * 200})  # within the bound: taken
    assert res.successful, res.reason
    assert p.poll() is None and "Traceback" not in procs.log(p)
    assert not (tmp_path / "bags").exists()


def test_sigint_mid_run_closes_a_readable_bag(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """Ctrl-C during a run: the process exits 0, the bag is closed (metadata
    written) with the run incomplete and every command sent so far in it."""
    from rosgraph_msgs.msg import Clock

    from winder.ros.qos import QOS_CLOCK

    clock: list[int] = []  # the run's time as the bridge's /clock tells it (ns)
    ros.create_subscription(
        Clock, "/clock", lambda m: clock.append(m.clock.sec * 10**9 + m.clock.nanosec), QOS_CLOCK
    )
    bags = tmp_path / "bags"
    start_standin(procs)
    bridge = start_cell(procs, bags, *LOOSE)
    wait.log_has(lambda: procs.log(bridge), "run armed", 60, "the bridge's run", running=bridge)
    # mid-run: the run's clock has gone 0.15 s (150 commands at 1 kHz) of its 0.65 s
    spin_until(
        ros,
        lambda: clock and clock[-1] >= 150_000_000,  # the first run's clock starts at 0
        60,
        "0.15 s of the run on the bridge's /clock",
        heard=lambda: clock[-3:],
    )
    assert procs.stop(bridge) == 0
    [bag] = wait_for_bags(bags, 1, timeout=5)
    raw = rosbags_read(bag)
    report = final_report(raw)
    assert report["state"] == "incomplete" and 0 < int(report["steps_done"]) < int(report["steps_total"])
    # every command sent is in the bag; how many went out in the run's first 0.15 s depends on
    # the machine (the command thread goes on from now when it falls behind: 90 under load)
    assert int(report["commands_sent"]) == len(raw[COMMANDS]) > 10
    assert "Traceback" not in procs.log(bridge)


STRANGER = TEST / "consumers" / "stranger.py"


def test_joint_states_from_another_node_change_nothing(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """A neighbour publishes joint states for the bridge's joints on the same
    topic, 100 rad and infinity in turn at 200 Hz, from before the cell
    starts (issue 41: with job_origin start_position it became the run's
    origin in 2 of 5 tries, a first command of 100 rad or inf, and any such
    message stopped a run with a servo fault). Only the broadcaster counts:
    the run is done, every command is the job's steps from the stand-in's
    zero (exact), the neighbour's messages are counted in the report and
    named in one warning."""
    bags = tmp_path / "bags"
    neighbour = procs.launch([sys.executable, str(STRANGER), "--joints", ",".join(JOINTS)], "neighbour")
    wait.log_has(lambda: procs.log(neighbour), "neighbour up", 30, running=neighbour)
    start_standin(procs)
    bridge = start_cell(
        procs,
        bags,
        *LOOSE,
        *("-p", "job_origin:=start_position"),
    )
    [bag] = wait_for_bags(bags, 1)
    raw = rosbags_read(bag)
    report = final_report(raw)
    assert report["state"] == "done", report["servo_fault"] or report
    check_commands(raw, report)  # from zero, exactly the steps: the neighbour was never the origin
    _, pos = commands(raw)
    assert np.isfinite(pos).all() and np.abs(pos).max() < 60.0
    assert int(report["foreign_joint_states"]) > 10, report
    assert report["foreign_joint_state_publishers"] == "/neighbour", report
    warned = [ln for ln in procs.log(bridge).splitlines() if "joint states from /neighbour" in ln]
    assert len(warned) == 1 and "WARN" in warned[0] and "/joint_state_broadcaster" in warned[0], warned
    assert all(list(m.name) == JOINTS and max(m.position) < 60 for _, m in raw["/joint_states"])


def test_a_broken_measurement_from_the_broadcaster_is_a_fault(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """The broadcaster itself reports infinity (a broken encoder word) 0.3 s
    into the run: a servo fault that says so (the joint, the value, the
    broadcaster), nothing commanded from it; between runs the bridge says
    the hardware is not ready, with the same reason, and refuses a start."""
    bags = tmp_path / "bags"
    start_standin(procs, "--corrupt-after", "0.3")
    bridge = start_cell(procs, bags, "-p", "job_origin:=start_position")
    [bag] = wait_for_bags(bags, 1)
    raw = rosbags_read(bag)
    report = final_report(raw)
    assert report["state"] == "incomplete", report
    fault = report["servo_fault"]
    assert "measured at inf" in fault and "not finite" in fault and "/joint_state_broadcaster" in fault, fault
    _, pos = commands(raw)
    assert np.isfinite(pos).all()
    wait.log_has(lambda: procs.log(bridge), "waiting for the hardware: joint", 30, running=bridge)
    ok, reply = call_start(ros)
    assert not ok and "not ready" in reply, reply
    assert "Traceback" not in procs.log(bridge)


def test_a_job_beyond_a_soft_limit_is_refused_before_any_command(
    tmp_path: Path, procs: Procs, ros: Any
) -> None:
    """max_position.feed 5 mm; the job's feed travels 1000 steps of 10 um
    (10 mm, worked out from the job here): the run is refused when it would
    be armed, in one line naming the joint, where the job takes it and the
    limit; no command, no clock. Within the limits the same job runs."""
    job = Job(**JOB)
    travel = max(s.start[0] + s.delta[0] for s in job.segments()) * job.feed_step
    assert travel == pytest.approx(0.01)
    bags = tmp_path / "bags"
    start_standin(procs)
    bridge = start_cell(procs, bags, "-p", "max_position.feed:=0.005", "-p", "min_position.feed:=-0.001")
    refused_before_any_command(
        procs,
        bridge,
        bags,
        f"the run cannot start: the job takes joint feed_screw (feed axis) to {travel:.6g} m, beyond "
        "max_position.feed = 0.005 m (soft limit)",
    )


def refused_before_any_command(procs: Procs, bridge: subprocess.Popen[bytes], bags: Path, want: str) -> None:
    """The run's bag: closed incomplete with no step done, its servo fault
    saying ``want``, no command and no clock sent; no traceback."""
    [bag] = wait_for_bags(bags, 1)
    raw = rosbags_read(bag)
    report = final_report(raw)
    assert report["state"] == "incomplete" and report["steps_done"] == "0", report
    assert want in report["servo_fault"], report["servo_fault"]
    assert not raw.get(COMMANDS) and not raw.get("/clock")
    assert "Traceback" not in procs.log(bridge)


def test_bad_soft_limits_are_refused_in_one_line(tmp_path: Path, procs: Procs) -> None:
    """min_position above max_position: the node refuses the setting and says
    which, in one line (it stays up, blocked)."""
    bridge = procs.start("bridge_node", "-p", "min_position.fork:=2.0", "-p", "max_position.fork:=1.0")
    log = wait.log_has(
        lambda: procs.log(bridge),
        "min_position.fork=2 is invalid with max_position.fork=1",
        30,
        running=bridge,
    )
    assert "Traceback" not in log


def test_a_run_waits_for_homing_when_it_is_required(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """require_homing, the stand-in's homing controller as homing_service,
    the joints somewhere unknown at first (feed 2 mm off the job's start):
    the bridge says it waits ("not homed") and the interp node does not
    start; ~/home calls the homing controller (the joints go to their
    zero) and says so; the run then starts on its own (autostart) and is
    done, every command exact from zero."""
    from std_srvs.srv import Trigger

    bags = tmp_path / "bags"
    start_standin(procs, "--homing", "--initial", "feed_screw=0.002")
    bridge = start_cell(
        procs,
        bags,
        *("-p", "require_homing:=true", "-p", "homing_service:=homing_controller/home"),
        *LOOSE,
        *("-p", "max_position.feed:=0.02"),
    )
    wait.log_has(lambda: procs.log(bridge), "the axes are not homed (require_homing)", 30, running=bridge)
    assert not closed_bags(bags)  # nothing started
    client = ros.create_client(Trigger, "/bridge_node/home")
    spin_until(ros, client.service_is_ready, 30, "/bridge_node/home")
    future = client.call_async(Trigger.Request())
    spin_until(ros, future.done, 30, "the reply of ~/home")
    reply = future.result()
    assert reply.success, reply.message
    assert reply.message.startswith("homed by /homing_controller/home; "), reply.message
    assert "soft limits: feed [-1e+09, 0.02] m" in reply.message, reply.message
    [bag] = wait_for_bags(bags, 1)
    raw = rosbags_read(bag)
    report = final_report(raw)
    assert report["state"] == "done", report["servo_fault"] or report
    check_commands(raw, report)
    assert "Traceback" not in procs.log(bridge)


def test_a_homing_service_that_never_answers_fails_homing_and_wedges_nothing(
    tmp_path: Path, procs: Procs, ros: Any
) -> None:
    """The homing controller never answers (a hung drive), homing_timeout 2 s:
    ~/home answers "home failed: no answer ... within 2 s" and the axes stay
    unhomed; while it waits the bridge's other services answer (its
    parameters read); a second ~/home meanwhile is refused at once. (Before:
    the node's other callbacks stopped for good, parameters and statuses too.)"""
    from std_srvs.srv import Trigger
    from support.ros_probe import get_params

    bags = tmp_path / "bags"
    start_standin(procs, "--homing-silent")
    bridge = start_cell(
        procs,
        bags,
        *("-p", "require_homing:=true", "-p", "homing_service:=homing_controller/home"),
        *("-p", "homing_timeout:=2.0"),
    )
    wait.log_has(lambda: procs.log(bridge), "the axes are not homed (require_homing)", 30, running=bridge)
    client = ros.create_client(Trigger, "/bridge_node/home")
    spin_until(ros, client.service_is_ready, 30, "/bridge_node/home")
    first = client.call_async(Trigger.Request())
    # while ~/home waits for the homing controller, the node serves the rest
    assert get_params(ros, "bridge_node", ["homing_timeout"]) == [2.0]
    second = client.call_async(Trigger.Request())
    spin_until(ros, lambda: second.done() and first.done(), 30, "the replies of ~/home")
    replies = sorted([first.result().message, second.result().message])
    assert replies[1] == "home refused: homing is under way", replies
    assert replies[0] == (
        "home failed: no answer from /homing_controller/home within 2 s (homing_timeout); "
        "the axes are not homed"
    ), replies
    assert not first.result().success and not second.result().success
    assert not closed_bags(bags)  # still not homed: nothing started
    assert "Traceback" not in procs.log(bridge)


def test_require_homing_switched_on_at_run_time_holds_the_next_start(
    tmp_path: Path, procs: Procs, ros: Any
) -> None:
    """require_homing set while the bridge runs (a parameter change, not a
    start-up value): no run moves the axes unhomed. A start taken before the
    bridge said it waits is refused by the bridge before its first command,
    naming ~/home; the bridge then says it waits ("not homed") and no start is
    taken until ~/home has run; after it a run is done. (Before: the bridge
    read require_homing from the last run's settings, and the next run went
    unhomed to its end.)"""
    from std_srvs.srv import Trigger
    from support.ros_probe import ready_states, set_params

    bags = tmp_path / "bags"
    start_standin(procs)
    bridge = start_cell(procs, bags, *LOOSE, interp={"autostart": "false"})
    ready = ready_states(ros)
    spin_until(
        ros,
        lambda: ready.get("consumer") == "ready" and ready.get("profile") == "ready",
        60,
        "the bridge and the profile node ready (winder/ready)",
    )
    [result] = set_params(ros, "bridge_node", {"require_homing": True})
    assert result.successful, result.reason
    want = "the axes are not homed (require_homing): call /bridge_node/home"
    ok, reply = call_start(ros)  # at once: the bridge may not have said "waiting" yet
    runs = 0
    if ok:  # the run is taken: the bridge refuses it before any command
        runs += 1
        refused_before_any_command(
            procs, bridge, bags, f"the run cannot start: {want}; nothing was commanded"
        )
    else:
        assert "not ready" in reply, reply
    wait.log_has(lambda: procs.log(bridge), f"waiting for the hardware: {want}", 30, running=bridge)
    spin_until(ros, lambda: ready.get("consumer") == "waiting", 10, "the bridge waiting (winder/ready)")
    ok, reply = call_start(ros)
    assert not ok and "not ready" in reply, reply
    client = ros.create_client(Trigger, "/bridge_node/home")
    spin_until(ros, client.service_is_ready, 30, "/bridge_node/home")
    future = client.call_async(Trigger.Request())
    spin_until(ros, future.done, 30, "the reply of ~/home")
    assert future.result().success, future.result().message
    assert future.result().message.startswith("homed where they stand: "), future.result().message
    start_again(ros)
    bag = wait_for_bags(bags, runs + 1)[-1]
    raw = rosbags_read(bag)
    report = final_report(raw)
    assert report["state"] == "done", report["servo_fault"] or report
    check_commands(raw, report)
    assert "Traceback" not in procs.log(bridge)


def start_unstepped_run(procs: Procs, ros: Any, bags: Path, *bridge_params: str) -> tuple[Any, Any]:
    """The stand-in, the bridge and a fake planner (test/support/cell.py) that
    sends a job description and never a step: (the bridge process, the fake)
    once the bridge's run is on."""

    from support.cell import FakeProfile
    from support.ros_probe import ready_states

    start_standin(procs)
    bridge = procs.start(
        "bridge_node",
        *(
            "-p",
            f"bag_dir:={bags}",
            "-p",
            f"joints:=[{','.join(JOINTS)}]",
            "-p",
            f"axes:=[{','.join(AXES_OF)}]",
        ),
        *bridge_params,
    )
    fake = FakeProfile(ros, Job(**JOB))
    ready = ready_states(ros)
    spin_until(ros, lambda: ready.get("consumer") == "ready", 60, "the bridge ready (winder/ready)")
    spin_until(ros, lambda: fake.pub_job.get_subscription_count() > 0, 30, "the bridge's job reader")
    fake.publish_job()
    wait.log_has(lambda: procs.log(bridge), "run -: job br", 30, "the bridge's run", running=bridge)
    return bridge, fake


def test_a_run_whose_steps_never_come_closes_as_a_stall(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """A run gets its description and no step (a planner that died, or its
    steps lost): nothing is commanded, the stall is reported after
    stall_timeout and the run closed incomplete after stall_abort. (Before:
    waiting to arm counted as work, so the stall watch never looked, and the
    run waited for ever.)"""
    bags = tmp_path / "bags"
    bridge, _ = start_unstepped_run(procs, ros, bags, "-p", "stall_timeout:=0.5", "-p", "stall_abort:=3.0")
    [bag] = wait_for_bags(bags, 1, timeout=30)
    raw = rosbags_read(bag)
    report = final_report(raw)
    assert report["state"] == "incomplete" and report["steps_done"] == "0", report
    assert "step stream stalled" in procs.log(bridge)
    assert not raw.get(COMMANDS)


def test_an_abort_before_the_run_is_armed_closes_it_at_once(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """The run waits for its steps, and an abort comes (its rest at step 0):
    the run closes at once, aborted, nothing commanded; not after the stall
    (stall_abort 60 s here). (Before: 'aborting' for as long as one waited.)"""

    bags = tmp_path / "bags"
    bridge, fake = start_unstepped_run(procs, ros, bags, "-p", "stall_abort:=60.0")
    from winder.contract.events import ControlEvent
    from winder.ros.interfaces import control_event_msg
    from winder.ros.qos import QOS_EVENTS
    from winder_interfaces.msg import ControlEvent as ControlEventMsg

    abort = ControlEvent("abort", "", 0, 0, 0, job_id="br")
    # as the profile node's
    control = fake.node.create_publisher(ControlEventMsg, "/winder/control", QOS_EVENTS)
    spin_until(ros, lambda: control.get_subscription_count() > 0, 30, "the bridge's control reader")
    control.publish(control_event_msg(abort))
    [bag] = wait_for_bags(bags, 1, timeout=20)
    raw = rosbags_read(bag)
    report = final_report(raw)
    assert report["steps_done"] == "0" and report["state"] in ("aborted", "incomplete"), report
    assert "run aborted before it started: nothing was commanded" in procs.log(bridge)
    assert not raw.get(COMMANDS)


#: the fork's peak in the bridge tests' job: RAMP's v_max (4000 steps/s, reached in a
#: 2048-step layer: 0.1 s and 200 steps of ramp at a_max 40000) of 512 steps a turn
FORK_PEAK = 4000 * 2 * math.pi / JOB["fork_steps_per_rev"]


def test_a_job_faster_than_a_velocity_limit_is_refused_before_any_command(
    tmp_path: Path, procs: Procs, ros: Any
) -> None:
    """max_velocity.fork 40 rad/s; the job's layers cruise at 49.1 rad/s
    (worked out here from RAMP and the job): the run is refused when it
    would be armed, in one line naming the axis, the job's peak and the
    limit; no command, no clock."""
    bags = tmp_path / "bags"
    start_standin(procs)
    bridge = start_cell(procs, bags, *LOOSE, "-p", "max_velocity.fork:=40.0")
    refused_before_any_command(
        procs,
        bridge,
        bags,
        f"the run cannot start: the job drives the fork axis at up to {FORK_PEAK:.6g} rad/s, beyond "
        "max_velocity.fork = 40 rad/s (soft limit); nothing was commanded",
    )


def windowed_speed(t_ns: np.ndarray, pos: np.ndarray, window_ns: int) -> float:
    """The highest mean speed over ``window_ns`` of a position held from each
    time to the next (a brute-force loop: each sample against the last one
    at least a window before it)."""
    best = 0.0
    for i in range(len(t_ns)):
        j = i
        while j > 0 and t_ns[i] - t_ns[j] < window_ns:
            j -= 1
        if t_ns[i] - t_ns[j] >= window_ns:
            best = max(best, abs(pos[i] - pos[j]) / (window_ns / 1e9))
    return best


def test_steps_past_a_velocity_limit_stop_the_run_before_they_are_due(
    tmp_path: Path, procs: Procs, ros: Any
) -> None:
    """max_velocity.fork 55 rad/s, the job's peak 49.1: the run starts. It
    rests at a programmed stop (stop_resume call) while the feed override is
    set to 1.5 there, then resumes: the steps after the stop would drive
    the fork at 73.6 rad/s. The bridge stops the run with a servo fault
    naming the joint, the speed and the limit before they are due; no
    command it sent moves the fork faster than the limit over 20 ms, beyond
    what whole steps add (3 steps over the window)."""
    from support.ros_probe import set_params

    bags = tmp_path / "bags"
    start_standin(procs)
    bridge = start_cell(
        procs,
        bags,
        *LOOSE,
        "-p",
        "max_velocity.fork:=55.0",
        interp={"stops": "1:2", "stop_pause": "0.1", "stop_resume": "call"},
    )
    profile = next(p for p, _ in procs.procs if str(p.args[0]).endswith("profile_node"))
    wait.log_has(lambda: procs.log(bridge), "run armed", 60, "the bridge's run", running=bridge)
    wait.log_has(lambda: procs.log(profile), "waiting for ~/resume", 60, "the run at its stop")
    [result] = set_params(ros, "profile_node", {"feed_override": 1.5})
    assert result.successful, result.reason
    out = subprocess.run(
        [str(BIN / "winder"), "ctl", "resume"], env=procs.env, capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 0, out.stdout + out.stderr
    [bag] = wait_for_bags(bags, 1)
    raw = rosbags_read(bag)
    report = final_report(raw)
    assert report["state"] == "incomplete", report
    fault = report["servo_fault"]
    assert "the steps would drive joint flyer (fork axis) at " in fault, fault
    assert "beyond max_velocity.fork = 55 rad/s (soft limit); stopped before they were due" in fault, fault
    # the steps commanded (to the last one sent), on their own times: never faster than the limit.
    # (The commands' send times are not held to it: a command thread that falls behind, as this
    # Python one does on a loaded machine, catches up in one command; max_command_gap_ms says so.)
    rows, k = step_rows(raw), check_commands(raw, report, stopped=True)
    fork = rows[: k.max(), 2 + AXES.index("fork")] * (2 * math.pi / JOB["fork_steps_per_rev"])
    step = 2 * math.pi / JOB["fork_steps_per_rev"]
    assert int(report["steps_done"]) >= 2 * 512  # it ran to the stop at turn 2, within the limit
    assert windowed_speed(rows[: k.max(), 0], fork, 20_000_000) <= 55.0 + 3 * step / 0.02


# -- the wire's load cell -----------------------------------------------------------
#: the load cell's force_torque_sensor_broadcaster (the stand-in's, from its documented behaviour)
LOAD_CELL = "load_cell"
WRENCHES = f"/{LOAD_CELL}/wrench"


def wire_statuses(raw: dict[str, list[tuple[int, Any]]]) -> list[Any]:
    return [
        st
        for _, arr in raw["/diagnostics"]
        for st in arr.status
        if st.name == "bridge_node: wire" and st.level == 2
    ]


def test_a_wire_break_stops_the_run_where_the_flyer_was(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """The stand-in's load cell (a force_torque_sensor_broadcaster, as
    documented: WrenchStamped on ~/wrench, force.x the tension) reads the
    job's set tension, then 0 from the moment the flyer reaches 2.2 turns
    into coil 2 (the wire breaks while it turns). The bridge stops the run
    as at a servo fault: one ``wire`` ERROR status naming coil 2, layer 1,
    turn 3 (worked out here from the job: 4 turns a coil, fork_steps_per_rev
    512 steps a turn of 2 pi rad), which is also where the commands recorded
    had taken the fork at the fault's time; commands held from there (every
    one exact, none after the fault), the profile node told to abort, the
    run closed incomplete, the final report naming the break; the load
    cell's readings in the bag under its topic."""
    job = Job(**JOB)
    set_n = job.set_tension
    per_coil = JOB["turns_per_layer"] * JOB["layers"]
    into_coil = 2.2  # turns into coil 2 when the wire breaks
    drop = (per_coil + into_coil) * 2 * math.pi  # the flyer's joint (rad): a turn is 2 pi
    want = int((per_coil + into_coil) // per_coil) + 1, 1, int(into_coil) + 1  # (coil, layer, turn)
    assert want == (2, 1, 3)
    bags = tmp_path / "bags"
    standin = start_standin(
        procs, "--load-cell", LOAD_CELL, "--tension", repr(set_n), "--tension-drop", f"flyer={drop!r}"
    )
    bridge = start_cell(procs, bags, *LOOSE, "-p", f"load_cell:={LOAD_CELL}")
    [bag] = wait_for_bags(bags, 1)
    raw = rosbags_read(bag)
    report = final_report(raw)
    assert report["state"] == "incomplete", report
    assert 0 < int(report["steps_done"]) < int(report["steps_total"]), report
    fault = report["wire_fault"]
    coil, layer, turn = want
    assert fault.startswith(f"wire break at coil {coil} layer {layer} turn {turn} ("), report
    assert report["servo_fault"] == "" and "\n" not in fault
    [status] = wire_statuses(raw)
    values = {kv.key: kv.value for kv in status.values}
    assert status.message == fault
    assert (values["fault"], values["coil"], values["layer"], values["turn"]) == ("break", "2", "1", "3")
    assert values["load_cell"] == f"/{LOAD_CELL}" and values["job_id"] == "br", values
    [job_status] = [
        st for _, arr in raw["/diagnostics"] for st in arr.status if st.name == "bridge_node: job"
    ][-1:]
    assert job_status.level == 2 and fault in job_status.message, job_status.message
    assert [m.state for _, m in raw["/winder/state"]] == ["running", "failed"]

    # where the commands had taken the fork at the fault's time (run time = log time - wall_start_ns)
    check_commands(raw, report)  # every command exact, from the job's start
    t_log, pos = commands(raw)
    t_run = t_log - sim_config(raw)["wall_start_ns"]
    t_fault = float(values["t_s"])
    fork = pos[np.searchsorted(t_run, t_fault * 1e9, side="right") - 1, AXES_OF.index("fork")]
    turns = fork / (2 * math.pi) - per_coil  # into coil 2
    assert into_coil - 0.01 <= turns < turn, (turns, t_fault)
    # commands hold from the fault: the job's last 1.8 turns (0.23 s at 7.8 turns/s) and its
    # settle_time (0.2 s) were never commanded; 0.3 s leaves the watch's sight of the break
    # (BREAK_TIME, the stand-in's 4 ms updates, transport) room on a loaded machine
    assert t_run[-1] / 1e9 < t_fault + 0.3, (t_run[-1] / 1e9, t_fault)

    wrenches = [m.wrench.force.x for _, m in raw[WRENCHES]]
    assert len(wrenches) > 10 and wrenches[0] == set_n and wrenches[-1] == 0.0
    assert report["tension_peak_n"] == f"{set_n:.4g}" and report["tension_min_n"] == "0", report
    assert int(report["tension_samples"]) > 10 and report["foreign_wrenches"] == "0", report
    log = wait.log_has(lambda: procs.log(bridge), "profile_node/abort: run", 30, "the bridge's abort call")
    assert "Traceback" not in log
    assert standin.poll() is None


def test_a_neighbour_on_the_load_cell_s_topic_changes_nothing(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """Another node (the stand-in's ``impostor``) publishes 0 N on the load
    cell's topic at the broadcaster's rate throughout, while the load cell
    reads the set tension: were it trusted, the run would stop at the
    flyer's first turn. The run is done; the impostor's wrenches are counted
    in the report and named in one warning; the bag holds only the load
    cell's; the tension stayed in its bands."""
    set_n = Job(**JOB).set_tension
    bags = tmp_path / "bags"
    start_standin(procs, "--load-cell", LOAD_CELL, "--tension", repr(set_n), "--impostor", "impostor")
    bridge = start_cell(procs, bags, *LOOSE, "-p", f"load_cell:={LOAD_CELL}")
    [bag] = wait_for_bags(bags, 1)
    raw = rosbags_read(bag)
    report = final_report(raw)
    assert report["state"] == "done", report["wire_fault"] or report["servo_fault"] or report
    assert report["wire_fault"] == "" and not wire_statuses(raw), report
    assert int(report["foreign_wrenches"]) > 10, report
    assert report["foreign_wrench_publishers"] == "/impostor", report
    assert int(report["tension_samples"]) > 10, report
    assert report["tension_peak_n"] == report["tension_min_n"] == f"{set_n:.4g}", report
    assert report["tension_outside_warning_s"] == report["tension_outside_alarm_s"] == "0.000", report
    assert all(m.wrench.force.x == set_n for _, m in raw[WRENCHES])
    warned = [ln for ln in procs.log(bridge).splitlines() if "a wrench from /impostor" in ln]
    assert len(warned) == 1 and "WARN" in warned[0] and f"the load cell /{LOAD_CELL}" in warned[0], warned
    assert "Traceback" not in procs.log(bridge)


def test_the_load_cell_s_tension_is_read_back_in_the_run_s_time(
    tmp_path: Path, procs: Procs, ros: Any
) -> None:
    """The stand-in's load cell reads a steady tension (not the job's set
    tension: nothing may take one for the other) and drops to 0 N
    ``drop_after`` s after the first command it gets (a known step; the
    bridge stops the run at the break). ``read_run`` gives the readings the
    bag holds under the load cell's topic, in the order recorded, each at
    its log time less the run's wall-clock start: in time order, none
    before the run's start, the steady ones before the step and the first
    0 N not before the drop (the first command's run time plus
    ``drop_after``, as the stand-in measures it). ``winder analyze --json``
    gives their least and peak as the wire's; its table the wire row."""
    import json

    from support.cli import run_cli

    from winder.record.reader import read_run

    set_n = Job(**JOB).set_tension
    steady = 0.9 * set_n  # within the job's bands: only the step is a fault
    drop_after = 0.8  # s: mid-job (the job's steps take about 1.6 s)
    bags = tmp_path / "bags"
    start_standin(
        procs, "--load-cell", LOAD_CELL, "--tension", repr(steady), "--tension-drop-after", repr(drop_after)
    )
    start_cell(procs, bags, *LOOSE, "-p", f"load_cell:={LOAD_CELL}")
    [bag] = wait_for_bags(bags, 1)
    raw = rosbags_read(bag)
    report = final_report(raw)
    assert report["wire_fault"].startswith("wire break at "), report
    # what the stand-in published, as recorded: steady, then 0 N from the drop on
    published = np.array([m.wrench.force.x for _, m in raw[WRENCHES]])
    step = int(np.argmax(published == 0.0))
    assert step > 10 and published.size > step + 1, published
    assert (published[:step] == steady).all() and (published[step:] == 0.0).all(), published

    run = read_run(bag)
    t, tension = run.tension.t, run.tension.tension
    np.testing.assert_array_equal(tension, published)
    assert t.size == published.size and (np.diff(t) >= 0).all()
    wall0 = sim_config(raw)["wall_start_ns"]
    t_end = (max(logged for msgs in raw.values() for logged, _ in msgs) - wall0) / 1e9
    assert t[0] >= 0.0 and t[-1] <= t_end, (t[0], t[-1], t_end)
    t_first_command = (commands(raw)[0][0] - wall0) / 1e9
    # the drop is read at the bridge's next look (5 ms) after it came; a command's time is its tick's (1 ms)
    assert t_first_command + drop_after - 0.01 <= t[step] < t_first_command + drop_after + 0.3, (
        t[step],
        t_first_command,
    )
    assert t[step - 1] <= t[step] and t[step - 1] < t_first_command + drop_after + 0.3

    r = run_cli("analyze", "--json", "--no-plots", str(bag))
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stdout + r.stderr
    [doc] = json.loads(r.stdout)
    wire = doc["wire"]
    assert (wire["tension_min_n"], wire["tension_peak_n"]) == (published.min(), published.max()), wire
    assert wire["set_tension_n"] == set_n, wire
    r = run_cli("analyze", "--no-plots", str(bag))
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stdout + r.stderr
    [row] = [ln for ln in r.stdout.splitlines() if ln.startswith("wire tension")]
    assert f"{published.min():.4g}..{published.max():.4g} N (set {set_n:.4g} N)" in row, row


def test_a_bad_load_cell_is_refused_in_one_line(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """load_cell is a controller name or empty: a bad one at start is
    refused in one line naming the parameter, the value and the form (the
    node runs on, blocked); at run time too, a name whose topic would be
    longer than ROS allows included."""
    from support.ros_probe import set_params

    p = procs.start("bridge_node", "-p", f"bag_dir:={tmp_path / 'bags'}", "-p", "load_cell:=9cell")
    log = wait.log_has(lambda: procs.log(p), "load_cell=", 30, "the line for load_cell", running=p)
    [line] = [x for x in log.splitlines() if "load_cell=" in x]
    assert (
        "load_cell='9cell' is invalid: must be empty (no load cell), or a controller name (letters, "
        "digits and _, starting with a letter)" in line
    ), line
    for value in ("a/b", "-x", "x" * 300):
        [res] = set_params(ros, "bridge_node", {"load_cell": value})
        assert not res.successful, value
        assert res.reason.startswith("load_cell=") and "invalid" in res.reason, res.reason
        assert "\n" not in res.reason
    for value in ("fts_broadcaster", "x" * 200, ""):
        [res] = set_params(ros, "bridge_node", {"load_cell": value})
        assert res.successful, res.reason
    assert p.poll() is None and "Traceback" not in procs.log(p)
