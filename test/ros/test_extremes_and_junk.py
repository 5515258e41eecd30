"""Hardening: values inside the documented ranges that the system
cannot simulate, bad namespaces and bag directories are refused before
anything starts, in one line, exit 2; the sim node's samples come in bounded
batches and still equal the exact response; no node outlives `winder run`."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import BIN, Procs, closed_bags, is_consumer, rosbags_read
from hypothesis import given, settings
from hypothesis import strategies as st
from support import wait
from support.cell import SMALL_JOB, job_args, only_bag, timed_rows, winder_run
from support.ros_probe import heard_diagnostics, start_job

from winder.axis import StepperAxis
from winder.cli import commands as cli
from winder.contract.params import SIM_SPECS, bag_directory
from winder.motion.timing import MAX_JOB_SECONDS
from winder.procs import popen, signal_state
from winder.record.bag import bags_in
from winder.spec import SpecError

# (arguments, what the one line must name): each value is inside its own
# documented range; together with the others it is not something the cell can
# represent or simulate (each crashed a node before)
EXTREMES = [
    (["--feed-step", "5e-324"], "feed_step="),
    (["--feed-step", "1e-310"], "feed_step="),
    (["--a-max", "1e-300"], "a_max=1e-300"),
    (["--profile", "exponential", "--tau", "1e-300"], "tau=1e-300"),
    (["--v-max", "1e-6"], "v_max=1e-06"),
    (["--j-max", "1e-300"], "j_max=1e-300"),
    (["--profile", "trapezoid", "--a-max", "1e-12"], "a_max=1e-12"),
    # 3.7e13 steps: refused from its turns, before it is timed (issue 53)
    (["--turns-per-layer", "100000", "--layers", "1000", "--poles", "360"], "a job may have at most"),
]


def run_cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, list[str]]:
    code = cli.main(["run", *args])
    return code, capsys.readouterr().err.strip().splitlines()


@pytest.mark.parametrize(("args", "named"), EXTREMES, ids=[" ".join(a) for a, _ in EXTREMES])
def test_extreme_in_range_values_are_refused_in_one_line(
    args: list[str], named: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, lines = run_cli([*args, "--bag-dir", str(tmp_path / "bags")], capsys)
    assert code == 2
    assert len(lines) == 1, lines
    assert lines[0].startswith("winder run: error: ") and named in lines[0]
    assert not (tmp_path / "bags").exists()  # nothing started, nothing written


def test_a_job_as_long_as_allowed_is_not_refused_for_its_length() -> None:
    from winder.contract.params import PROFILE_SPECS
    from winder.motion.timing import plan_job

    values = {k: s.default for k, s in PROFILE_SPECS.items()}
    # 1e6 steps at 2 steps/s: 5e5 s, under a week; 2e6 steps: over it
    values["v_max"] = 2.0
    _, t0, total = plan_job(values, [10**6])
    assert t0.tolist() == [0] and 5e5 * 1e9 <= total <= MAX_JOB_SECONDS * 1e9
    with pytest.raises(ValueError, match="more than a job may last"):
        plan_job(values, [10**6, 10**6])


@pytest.mark.parametrize("namespace", ["a b", "1cell", "/cell//x", "/cell1/", "cell-1", "/ä"])
def test_bad_namespace_is_refused_in_one_line(
    namespace: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, lines = run_cli(["--namespace", namespace, "--bag-dir", str(tmp_path / "bags")], capsys)
    assert code == 2 and len(lines) == 1, lines
    assert lines[0].startswith(f"winder run: error: namespace={namespace!r} is invalid")


def bad_bag_dirs(tmp_path: Path) -> list[str]:
    loop = tmp_path / "loop"
    loop.symlink_to(loop)
    plain = tmp_path / "file"
    plain.write_text("")
    return ["/dev/null", "/proc/winder", str(loop / "x"), str(plain / "x"), "/sys/kernel/winder"]


def test_unwritable_bag_dir_is_refused_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for bad in bad_bag_dirs(tmp_path):
        code, lines = run_cli(["--bag-dir", bad], capsys)
        assert code == 2 and len(lines) == 1, (bad, lines)
        assert lines[0].startswith(f"winder run: error: bag_dir={bad!r} is invalid"), lines
        with pytest.raises(SpecError):  # the sim node's check is the same function
            bag_directory(bad)


def test_bag_dir_expands_home_and_is_not_created_by_the_check(tmp_path: Path) -> None:
    assert bag_directory("~/winder-bags-x") == Path.home() / "winder-bags-x"
    target = tmp_path / "a" / "b"
    assert bag_directory(str(target)) == target
    assert not (tmp_path / "a").exists() and list(tmp_path.iterdir()) == []
    assert SIM_SPECS["bag_dir"].default == "bags"


@pytest.mark.ros
def test_samples_in_bounded_batches_equal_the_exact_response(tmp_path: Path, procs: Procs) -> None:
    """At 20 kHz the small job has more samples than one batch of the sim
    node: the fork axis' recorded states must still be the exact linear
    response to its recorded steps at every sample."""
    from winder_sim.sim_node import SAMPLE_BATCH

    rate = 20000.0
    r = winder_run(tmp_path, procs.domain, *job_args(SMALL_JOB), "--publish-rate", str(rate))
    assert r.returncode == 0, r.stdout + r.stderr
    bag = rosbags_read(only_bag(tmp_path))
    rows = timed_rows(bag)
    states = bag["/winder/joint_states"]
    assert len(states) > 2 * SAMPLE_BATCH  # the job spans several batches
    t = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for _, m in states])
    fork = np.array([m.position[1] for _, m in states])
    d = np.diff(np.concatenate([[0], rows[:, 3]]))
    moved = d != 0
    angle = float(SIM_SPECS["fork.motor_step_angle"].default)
    axis = StepperAxis(**{k: float(SIM_SPECS[f"fork.{k}"].default) for k in ("Zr", "L", "i_a", "J", "D")})
    theta = axis.response(rows[moved, 0] / 1e9, d[moved] * angle, t)
    joint_step = 2 * np.pi / SMALL_JOB["fork_steps_per_rev"]
    expected = theta / angle * joint_step
    assert np.max(np.abs(fork - expected)) <= 1e-9 * joint_step * max(1.0, float(np.max(np.abs(rows[:, 3]))))


def children_of(pid: int) -> list[int]:
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


@pytest.mark.ros
def test_no_node_outlives_a_killed_winder_run(tmp_path: Path, procs: Procs) -> None:
    env = {**os.environ, "ROS_DOMAIN_ID": str(procs.domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    p = popen(
        [str(BIN / "winder"), "run", "--bag-dir", str(tmp_path / "bags"), "--real-time"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        stdin=subprocess.DEVNULL,
    )

    def three() -> list[int]:
        found = children_of(p.pid)
        return found if len(found) >= 3 else []

    try:
        kids = wait.until(
            three,
            30,
            "the three nodes started by winder run",
            heard=lambda: children_of(p.pid),
            running=p,
            poll=0.1,  # each look reads all of /proc
        )
        p.send_signal(signal.SIGKILL)
        p.wait()

        def alive() -> list[int]:
            return [k for k in kids if Path(f"/proc/{k}").exists() and not _zombie(k)]

        def said() -> list[str]:  # which process lives on, and what it does with its signals
            out = []
            for k in alive():
                with contextlib.suppress(OSError):
                    argv = Path(f"/proc/{k}/cmdline").read_bytes().replace(b"\0", b" ").decode()[-120:]
                    out.append(f"{k} {argv} ({signal_state(k)})")
            return out

        wait.until(lambda: not alive(), 20, "the end of the nodes of the killed winder run", heard=said)
    finally:
        if p.poll() is None:
            p.kill()


def _zombie(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z"
    except OSError:
        return False


# -- malformed messages from a neighbour on the graph, through real DDS ---------

CHUNK_FAULTS = [
    "empty",
    "span",
    "shift",
    "negate",
    "int32",
    "past_end",
    "huge_time",
    "negative_time",
    "wrapping_time",
]


def damage(chunks: list[np.ndarray], fault: str, job: Any) -> tuple[list[np.ndarray], bool]:
    """The stream with one damaged chunk; True if the damage replaces the last
    chunk's times (its steps then count as missing: the job must still close)."""
    out = [c.copy() for c in chunks]
    good = out[2]
    bad = good.copy()
    if fault == "empty":
        bad = bad[:0]
    elif fault == "span":
        bad[-1, 1] += 1
    elif fault == "shift":
        bad[:, 3] += 10**5
    elif fault == "negate":
        seg = job.segments()[int(good[0, 1])]
        major = int(np.argmax(np.abs(seg.delta)))
        bad[:, 2 + major] = -bad[:, 2 + major]
    elif fault == "int32":
        bad[-1, 4] = 2**31 - 1
    elif fault == "past_end":
        bad[:, 2:] += 10**6
    else:  # step times out of range on the job's last chunk
        last = out[-1]
        if fault == "wrapping_time":
            # from 1.5 * 2**62 to -1.5 * 2**62 in one step: a difference of the
            # times wraps around to +2**62 in int64, the times decrease
            half = last.shape[0] // 2
            last[:half, 0] += 3 * 2**61
            last[half:, 0] -= 3 * 2**61
        else:
            last[:, 0] = last[:, 0] + 2**62 if fault == "huge_time" else -last[:, 0]
        return out, True
    out.insert(3, bad)  # an extra chunk beside the good ones
    return out, False


@pytest.mark.ros
@pytest.mark.parametrize("fault", CHUNK_FAULTS)
def test_sim_node_reports_a_malformed_chunk_and_closes_the_job(
    tmp_path: Path, procs: Procs, ros: Any, fault: str
) -> None:
    from support.cell import FakeProfile

    from winder.motion.job import Job

    job = Job(job_id="hostile", turns_per_layer=2, layers=2, poles=1, fork_steps_per_rev=256)
    sim = procs.start("sim_node", "-p", f"bag_dir:={tmp_path / 'bags'}", "-p", "stall_timeout:=60.0")
    fake = FakeProfile(ros, job)
    chunks, last_dropped = damage(fake.chunks(100), fault, job)
    fake.send(chunks)
    from conftest import spin_until

    def closed() -> dict[str, str] | None:
        ends = [
            v
            for _, name, v in fake.statuses
            if is_consumer(name.split(" | ")[0], v) and v.get("state") in ("done", "incomplete")
        ]
        return ends[-1] if ends else None

    spin_until(ros, lambda: closed() is not None, 30, "the job to close")
    end = closed()
    assert end is not None
    errors = [text for level, text, _ in fake.statuses if level == 2 and "sim_node" in text]
    assert errors, "no ERROR report"
    assert all("\n" not in e for e in errors)
    assert int(end["errors"]) >= 1
    if last_dropped:
        assert int(end["steps_missing"]) == chunks[-1].shape[0]
    else:
        assert int(end["steps_missing"]) == 0 and int(end["steps_done"]) == job.total_steps
    assert sim.poll() is None, "the sim node died"
    log = procs.log(sim)
    assert "Traceback" not in log
    status = final_status_of(only_bag(tmp_path))
    assert status["state"] == end["state"]


def final_status_of(bag_dir: Path) -> dict[str, str]:
    from conftest import final_report

    return final_report(rosbags_read(bag_dir))


@pytest.mark.ros
def test_nodes_survive_junk_jobs_chunks_and_receipts(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """Junk on winder/job, winder/steps, winder/step_times and winder/progress
    from nodes that are not the cell's (one topic each, so none looks like one
    of the cell's parts): every node refuses it, says so once naming the
    sender, and stays alive; a good job runs after. (Junk from the cell's own
    part reaches the checks behind: test_sim_node_reports_a_malformed_chunk...)"""
    from conftest import spin_until
    from diagnostic_msgs.msg import DiagnosticArray, KeyValue
    from std_msgs.msg import Int32MultiArray, Int64MultiArray

    from winder.ros.chunks import pack_steps, pack_timed
    from winder.ros.qos import QOS_LATCHED, QOS_STATE, QOS_STREAM
    from winder_interfaces.msg import JobDescription

    seen: list[str] = []
    ros.create_subscription(
        DiagnosticArray, "/diagnostics", lambda m: seen.extend(f"{s.name}|{s.message}" for s in m.status), 100
    )
    bags = tmp_path / "bags"
    nodes = [
        procs.start("sim_node", "-p", f"bag_dir:={bags}"),
        procs.start("profile_node"),
        procs.start("interp_node", "-p", "autostart:=false", "-p", "turns_per_layer:=2", "-p", "poles:=1"),
    ]
    import rclpy

    topics = ("job", "steps", "times", "progress")
    junk = {t: rclpy.create_node(f"junk_{t}", context=ros.context) for t in topics}
    pub_job = junk["job"].create_publisher(JobDescription, "/winder/job", QOS_LATCHED)
    pub_steps = junk["steps"].create_publisher(Int32MultiArray, "/winder/steps", QOS_STREAM)
    pub_times = junk["times"].create_publisher(Int64MultiArray, "/winder/step_times", QOS_STREAM)
    pub_progress = junk["progress"].create_publisher(KeyValue, "/winder/progress", QOS_STATE)
    # every junk writer matched by its readers (the job's: the profile and sim nodes), so no junk is lost
    pubs = {
        "job": (pub_job, 2),
        "steps": (pub_steps, 1),
        "times": (pub_times, 1),
        "progress": (pub_progress, 1),
    }
    spin_until(
        ros,
        lambda: all(pub.get_subscription_count() >= n for pub, n in pubs.values()),
        30,
        "the nodes' subscriptions on each junk topic",
        heard=lambda: {t: pub.get_subscription_count() for t, (pub, _) in pubs.items()},
    )
    for description in [
        JobDescription(),  # no format
        JobDescription(format=JobDescription.FORMAT),  # no segments
        JobDescription(format=JobDescription.FORMAT, job=[KeyValue(key="layers", value="x")]),
        JobDescription(format=JobDescription.FORMAT, job=[KeyValue(key="no_such_field", value="1")]),
        JobDescription(format=JobDescription.FORMAT, job_id="a", job=[KeyValue(key="job_id", value="b")]),
    ]:
        pub_job.publish(description)
        # paced, not a wait: a latched writer keeps one message, so each junk job goes out alone
        time.sleep(0.2)
    pub_steps.publish(pack_steps(np.zeros((0, 4), np.int32)))
    pub_times.publish(pack_timed(np.zeros((0, 5), np.int64)))
    pub_progress.publish(KeyValue(key="rw400", value="lots"))
    pub_progress.publish(KeyValue(key="rw400", value="-5"))
    # each refused, named once: the job by the profile and sim nodes, the steps by the
    # profile node, the timed steps by the sim node, the receipts by the interp node
    refusals = [
        ("sim", "/junk_job"), ("profile", "/junk_job"), ("profile", "/junk_steps"),
        ("sim", "/junk_times"), ("interp", "/junk_progress"),
    ]  # fmt: skip
    names = dict(zip(("sim", "profile", "interp"), nodes, strict=True))

    def unsaid() -> list[tuple[str, str]]:
        return [
            (n, sender)
            for n, sender in refusals
            if f"messages from {sender} ignored" not in procs.log(names[n])
        ]

    wait.until(
        lambda: not unsaid(),
        30,
        "each node's refusal of the junk",
        heard=lambda: (
            f"not said: {unsaid()}",
            f"ended: {[n for n, p in names.items() if p.poll() is not None]}",
        ),
    )
    wait.spin_for(ros, 1.0)  # and once only: no second line for the rest of the junk in a further second
    assert all(p.poll() is None for p in nodes), [procs.log(p) for p in nodes if p.poll() is not None]
    logs = {name: procs.log(p) for name, p in names.items()}
    for name, sender in refusals:
        assert logs[name].count(f"messages from {sender} ignored") == 1, (name, sender, logs[name])
    assert not any("job description rejected" in s for s in seen), "junk from a stranger was acted on"
    # a good job still runs through the same three nodes
    reply = start_job(ros)
    assert reply.success, reply.message
    try:
        spin_until(
            ros, lambda: any(s.startswith("sim_node: job|job rw400: complete") for s in seen), 60, "the job"
        )
    except AssertionError:
        raise AssertionError("\n".join(sorted(set(seen)))) from None
    for p in nodes:
        assert "Traceback" not in procs.log(p)


@pytest.mark.ros
@pytest.mark.parametrize("victim", ["profile_node", "sim_node"])
def test_a_restarted_node_leaves_the_cell_able_to_run_the_next_job(
    tmp_path: Path, procs: Procs, ros: Any, victim: str
) -> None:
    """A node killed mid-job and started again, and the next start runs a
    whole job through the same cell. A killed profile node: the sim node
    closes the job incomplete (bag closed, final report), the interp node
    gives it up. A killed sim node: its bag is cut short, the interp node
    gives the job up, and the restarted sim node never takes the dead run's
    description for a new run of its own."""
    from conftest import spin_until
    from std_srvs.srv import Trigger

    seen = heard_diagnostics(ros)
    bags = tmp_path / "bags"
    abort = ["-p", "stall_abort:=2.0"]
    args = {
        "sim_node": ["-p", f"bag_dir:={bags}", "-p", "stall_timeout:=1.0", *abort],
        "profile_node": [],
    }
    nodes = {name: procs.start(name, *args[name]) for name in ("sim_node", "profile_node")}
    procs.start(
        "interp_node",
        "-p",
        "turns_per_layer:=200",
        "-p",
        "max_in_flight:=16384",
        "-p",
        "autostart:=false",
        *abort,
    )
    client = ros.create_client(Trigger, "/interp_node/start")
    spin_until(ros, client.service_is_ready, 30, "the start service")
    spin_until(ros, lambda: any(is_consumer(n, v) for n, _, v in seen), 30, "the sim node")
    reply = start_job(ros)
    assert reply.success, reply.message
    spin_until(ros, lambda: any(v.get("state") == "running" for _, _, v in seen), 60, "the job to run")
    first_run = next(v["run_id"] for _, _, v in seen if v.get("state") == "running" and v.get("run_id"))
    nodes[victim].kill()
    nodes[victim].wait()
    killed = time.monotonic()
    nodes[victim] = procs.start(victim, *args[victim])

    def closed() -> bool:
        return any(is_consumer(n, v) and v.get("state") == "incomplete" for n, _, v in seen)

    def aborted() -> bool:
        # its words for a job it gives up after stall_abort: "job ... given up, incomplete: ..."
        return any(n == "interp_node: job" and "given up" in m for n, m, _ in seen)

    from winder.analysis.metrics import analyze
    from winder.record.reader import read_run

    if victim == "sim_node":
        spin_until(ros, aborted, 60, "the interp node to drop the job")
        # the subject is what does not happen: longer than stall_abort, a stale run would
        # have been taken and closed by now (its statuses heard meanwhile)
        wait.spin_for(ros, 3.0)
        assert not closed(), "the restarted sim node took the dead run's description for a run"
        assert not any(is_consumer(n, v) and v.get("state") == "running" for n, _, v in seen[-20:])
        # the killed node's bag is cut short (SIGKILL: whatever reached the disk), or,
        # killed while it was still opening it, only its hidden staging directory is
        # left (the next bag opened there removes it); the restarted node opened none
        # of its own for the dead run; killed sooner still, before it made the bag
        # directory at all, there is none (and the restarted node made none either)
        entries = sorted(bags.iterdir()) if bags.exists() else []
        visible = [b.name for b in bags_in(bags)]
        assert visible in ([first_run], []), entries
        staging = [b.name for b in entries if b.name not in visible]
        assert all(name.startswith(f".{first_run}.opening-") for name in staging), staging
    else:
        spin_until(
            ros, lambda: closed() and aborted(), 60, "the sim node to close the job, the interp to drop it"
        )
        # the bag of the sim node that saw the stall is closed, with its final report
        finished = wait.until(
            lambda: closed_bags(bags), 30, f"a closed bag in {bags}", heard=lambda: sorted(bags.iterdir())
        )
        assert final_status_of(finished[-1])["state"] == "incomplete"
        # the stall's ERROR reports are in the bag, and winder analyze says so
        run = read_run(finished[-1])
        assert any("stalled" in e for e in run.errors), run.errors
        assert any("stalled" in e for e in analyze(run).error_list)  # listed after the table
    # the next job runs through the same (restarted) cell: at once when the killed
    # process's endpoints are gone from the graph; a SIGKILLed process says no goodbye,
    # so they stay until its lease expires (10 s in winder's DDS profile), and until then
    # the restarted node, the same name in another process, is not taken for the cell's
    # (a second cell's node would look just so)
    replies: list[str] = []
    # a small next job: the 2 s stall_abort that ends the first run quickly gives a big job up
    # on a loaded machine, where the consumer computes one batch of steps for longer than that
    # without a receipt (seen in a fresh-clone CI run: given up at 770304/786688 steps)
    from support.ros_probe import set_params

    [res] = set_params(ros, "interp_node", {"turns_per_layer": 3})
    assert res.successful, res.reason

    def taken() -> bool:
        seen.clear()
        future = client.call_async(Trigger.Request())
        spin_until(ros, future.done, 30, "the start reply")
        reply = future.result()
        replies.append(reply.message)
        assert reply.success or "not ready" in reply.message, reply.message
        return bool(reply.success)

    # asked again each second while the cell is "not ready"
    first_ask = time.monotonic()
    wait.until(taken, 30, "a start taken by the restarted cell", heard=lambda: replies[-3:], poll=1.0)
    if first_ask - killed < 8.0:  # the killed process' endpoints stay on the graph for its 10 s lease
        # meanwhile the part has two nodes, the dead one the cell's: a start is not taken (one
        # taken went to the dead profile node, and the run stalled: make flakes)
        # (the dead node's "ready" gone stale, or, still fresh, two nodes in the part)
        role = "profile" if victim == "profile_node" else "consumer"
        assert "not ready" in replies[0] and role in replies[0], replies
    spin_until(
        ros, lambda: any(v.get("state") == "done" for n, _, v in seen if is_consumer(n, v)), 120, "job 2"
    )
    assert all(p.poll() is None for p in nodes.values())


@pytest.mark.ros
def test_a_namespaced_cell_keeps_its_clock_in_its_namespace(tmp_path: Path, procs: Procs) -> None:
    """Two cells on one graph must not both drive /clock: a cell in /cell9
    publishes and records /cell9/clock, never /clock."""
    r = winder_run(tmp_path, procs.domain, "--namespace", "/cell9", *job_args(SMALL_JOB))
    assert r.returncode == 0, r.stdout + r.stderr
    bag = rosbags_read(only_bag(tmp_path))
    assert "/clock" not in bag
    clock = np.array([m.clock.sec * 10**9 + m.clock.nanosec for _, m in bag["/cell9/clock"]])
    assert clock.size == len(bag["/cell9/winder/joint_states"]) and np.all(np.diff(clock) > 0)


def small_disk(
    tmp_path: Path, procs: Procs, sim_args: list[str], want: str
) -> tuple[str, subprocess.Popen[bytes]]:
    """A sim node whose bag directory fills up after about 1 MiB: a 1 MiB
    tmpfs where this machine lets the test mount one, else the same node under
    a 1 MiB file size limit (RLIMIT_FSIZE: writes fail with EFBIG as a full
    disk fails them with ENOSPC); ``want="fsize"`` takes the limit anyway.
    Returns (the kind used, the process)."""
    disk = tmp_path / "small"
    disk.mkdir()
    mounted = (
        subprocess.run(
            ["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(disk)], capture_output=True
        ).returncode
        == 0
    )
    cmd = [str(BIN / "sim_node"), "--ros-args", "-p", f"bag_dir:={disk / 'bags'}", *sim_args]
    if not mounted:
        cmd = ["prlimit", f"--fsize={1 << 20}", *cmd]
    p = procs.children.start(cmd, "sim_node-small-disk")
    return ("tmpfs" if mounted else "fsize"), p


@pytest.mark.ros
@pytest.mark.parametrize("want", ["tmpfs", "fsize"])
def test_a_full_disk_mid_job_closes_the_job_and_keeps_what_was_written(
    tmp_path: Path, procs: Procs, ros: Any, want: str
) -> None:
    from conftest import spin_until

    from winder.record.reader import read_run

    seen = heard_diagnostics(ros)
    kind, sim = small_disk(tmp_path, procs, ["-p", "bag_compression:=none"], want)
    try:
        procs.start("profile_node")
        procs.start("interp_node")  # the default job: far more than 1 MiB of bag

        def closed() -> dict[str, str] | None:
            ends = [(m, v) for n, m, v in seen if is_consumer(n, v) and v.get("state") == "incomplete"]
            return ends[-1] if ends else None

        spin_until(ros, lambda: closed() is not None, 120, f"the job to close on the full disk ({kind})")
        message, _ = closed()  # type: ignore[misc]
        assert "recording stopped" in message and ("disk full" in message or "file size limit" in message)
        # no promise a full disk cannot keep: the bag is not closed, and the message says what mends it
        assert "stays readable" not in message and "`winder bag recover " in message, message
        assert sim.poll() is None, "the sim node died"
        wait.spin_for(ros, 1.0)  # the subject is what does not happen: the node does not die a moment later
        assert sim.poll() is None
        bags = bags_in(tmp_path / "small" / "bags")
        assert len(bags) == 1
        run = read_run(bags[0])  # readable: what reached the file, flagged as not complete
        assert not run.complete
        assert run.steps.shape[0] > 0
        assert "Traceback" not in procs.log(sim)
    finally:
        procs.stop_all()
        subprocess.run(["umount", str(tmp_path / "small")], capture_output=True)


# values inside each parameter's own range that the cell cannot simulate,
# through ROS parameters: at start (--ros-args -p) and at run time, one
# parameter per call (a ROS parameter call sets each parameter on its own);
# (name, value, refused): a kind is switched first where a limit needs it
ROS_EXTREMES: dict[str, list[tuple[str, Any, bool]]] = {
    "interp_node": [
        ("feed_step", 1e-310, True),
        ("feed_step", 5e-324, True),
        ("feed_step", 1e-9, False),
        ("turns_per_layer", 100000, True),
    ],
    "profile_node": [
        ("a_max", 1e-300, True),
        ("v_max", 1e-6, True),
        ("j_max", 1e-300, True),
        ("a_max", 8192.0, False),  # valid again: the start override blocked the node till now
        ("profile", "trapezoid", False),
        ("a_max", 1e-12, True),
        ("profile", "exponential", False),
        ("tau", 1e-300, True),
    ],
}


@pytest.mark.ros
@pytest.mark.parametrize("executable", list(ROS_EXTREMES))
def test_extreme_in_range_parameters_are_refused_and_the_node_lives(
    procs: Procs, ros: Any, executable: str
) -> None:
    from support.ros_probe import set_params

    from winder.ros.cell import ros_args

    name, value, _ = ROS_EXTREMES[executable][0]
    start = {name: value, **({"autostart": False} if executable == "interp_node" else {})}
    p = procs.start(executable, *ros_args(start, "")[1:])
    # the node logs the refused override as it starts: wait for that line before
    # the calls (a full `make test` once read the log before it was there)
    wait.until(lambda: procs.log(p).strip(), 30, f"{executable}'s first log line", running=p)
    for name, value, refused in ROS_EXTREMES[executable]:
        [result] = set_params(ros, executable, {name: value})
        assert result.successful != refused, (name, value, result.reason)
        if refused:
            assert "\n" not in result.reason and name in result.reason, result.reason
    assert p.poll() is None
    log = procs.log(p)
    # the start override is refused in one line naming it: as a value no job can
    # use ("settings rejected at start"), or as text that is no number
    first_line = log.splitlines()[0]
    assert ROS_EXTREMES[executable][0][0] in first_line, log
    assert "rejected at start" in first_line or "holds the default" in first_line, log
    assert "Traceback" not in log


# -- every numeric setting on both sides of each bound, and at its extremes -------------


def _bound_cases() -> list[tuple[str, str, bool]]:
    """(name, value text, inside the setting's own range) for every numeric
    setting of the job, the three nodes' tables and the cell runner: each bound
    and the nearest representable value on either side of it."""
    import math

    from winder.cli.commands import CELL_SPECS
    from winder.contract.params import INTERP_SPECS, PROFILE_SPECS

    specs = {**INTERP_SPECS, **PROFILE_SPECS, **SIM_SPECS, **CELL_SPECS}
    cases = []
    for name, spec in specs.items():
        if spec.kind not in (int, float) or spec.low is None or spec.high is None:
            continue
        for bound, toward_inside, open_ in (
            (spec.low, math.inf, spec.low_open),
            (spec.high, -math.inf, False),
        ):
            if spec.kind is int:
                step = 1 if toward_inside > 0 else -1
                inside, outside = int(bound) + (step if open_ else 0), int(bound) - step
            else:
                b = float(bound)
                inside = math.nextafter(b, toward_inside) if open_ else b
                outside = b if open_ else math.nextafter(b, -toward_inside)
            cases += [(name, repr(inside), True), (name, repr(outside), False)]
    return cases


BOUND_CASES = _bound_cases()


def test_bound_matrix_covers_every_numeric_setting() -> None:
    names = {n for n, _, _ in BOUND_CASES}
    assert {"feed_step", "v_max", "a_max", "j_max", "tau", "fork.J", "publish_rate", "timeout"} <= names
    assert len(BOUND_CASES) >= 4 * len(names)


NODE_ONLY = {"autostart", "chunk_steps", "max_in_flight"}  # interp node settings, no winder run option
# the interp node's ramp.* settings are the profile node's, carried with a job:
# winder run sets the profile node's (same specs, same cases)
CLI_BOUND_CASES = [c for c in BOUND_CASES if c[0] not in NODE_ONLY and not c[0].startswith("ramp.")]


@pytest.mark.parametrize(
    ("name", "text", "inside"), CLI_BOUND_CASES, ids=[f"{n}={t}" for n, t, _ in CLI_BOUND_CASES]
)
def test_cli_at_every_bound(
    name: str, text: str, inside: bool, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`winder run --check` with one setting at or beside a bound: outside the
    range it is refused naming it; inside, the job is either valid or refused
    jointly in one line; never a traceback, nothing started or written."""
    code = cli.main(
        ["run", "--check", f"--{name.replace('_', '-')}={text}", "--bag-dir", str(tmp_path / "b")]
    )
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    if inside and code == 0:
        assert "every setting is valid" in out
    else:
        assert code == 2 and len(lines) == 1, (code, out, err)
        assert lines[0].startswith("winder run: error: ")
        if not inside:
            assert lines[0].startswith(f"winder run: error: {name}="), lines[0]
    assert not (tmp_path / "b").exists()


@pytest.mark.ros
@pytest.mark.parametrize("executable", ["interp_node", "profile_node", "sim_node"])
def test_ros_parameters_at_every_bound(tmp_path: Path, procs: Procs, ros: Any, executable: str) -> None:
    """The same bound matrix through set_parameters on the running node: outside
    a range refused naming the parameter, inside accepted or refused in one
    line; accepted values are set back; the node lives through all of it."""
    from support.ros_probe import set_params

    from winder.contract.params import INTERP_SPECS, PROFILE_SPECS

    specs = {"interp_node": INTERP_SPECS, "profile_node": PROFILE_SPECS, "sim_node": SIM_SPECS}[executable]
    extra = {"interp_node": ["-p", "autostart:=false"], "sim_node": ["-p", f"bag_dir:={tmp_path / 'b'}"]}
    p = procs.start(executable, *extra.get(executable, []))
    cases = [(n, t, inside) for n, t, inside in BOUND_CASES if n in specs]
    assert len(cases) >= 4
    outcomes: dict[str, int] = {"accepted": 0, "refused": 0}
    for name, text, inside in cases:
        value = specs[name].kind(float(text)) if specs[name].kind is int else float(text)
        [result] = set_params(ros, executable, {name: value})
        if result.successful:
            assert inside, f"{name}={text} accepted outside its range"
            outcomes["accepted"] += 1
            [back] = set_params(ros, executable, {name: specs[name].default})
            assert back.successful, back.reason
        else:
            outcomes["refused"] += 1
            assert result.reason and "\n" not in result.reason, result.reason
            if not inside:
                assert name in result.reason, result.reason
    assert outcomes["accepted"] and outcomes["refused"], outcomes
    assert p.poll() is None
    assert "Traceback" not in procs.log(p)


@settings(max_examples=500, deadline=None)
@given(
    st.floats(5e-324, 1e300),
    st.floats(5e-324, 1e300),
    st.floats(5e-324, 1e300),
    st.floats(5e-324, 1e300),
    st.floats(0, 1e300),
)
def test_any_positive_motor_is_a_model_or_a_one_line_error(
    Zr: float, L: float, i_a: float, J: float, D: float
) -> None:
    """Over the whole positive float range: a StepperAxis with finite derived
    quantities, or a ValueError naming the values, never another exception."""
    import math

    try:
        ax = StepperAxis(Zr, L, i_a, J, D)
    except ValueError as exc:
        assert "\n" not in str(exc) and "Zr=" in str(exc)
        return
    assert 0 < ax.stiffness < math.inf and 0 < ax.natural_frequency < math.inf
    assert math.isfinite(ax.damping_ratio)


@pytest.mark.ros
def test_a_new_real_time_factor_changes_the_rate_not_the_time_elapsed(
    tmp_path: Path, procs: Procs, ros: Any
) -> None:
    """real_time_factor set mid-job: the clock goes on from where it was,
    never faster than the new rate (it jumped from 1.5 s to 15 s when the new
    factor rescaled the time already elapsed). How fast it goes on a loaded
    machine is a speed, not a check here: only bounds that hold on any
    machine are asserted (a lower bound on the rate failed on a starved one)."""
    from conftest import spin_until
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock
    from support.ros_probe import set_params

    ticks: list[tuple[float, float]] = []  # (wall s, simulated s)
    ros.create_subscription(
        Clock,
        "/clock",
        lambda m: ticks.append((time.monotonic(), m.clock.sec + m.clock.nanosec * 1e-9)),
        QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT),
    )
    procs.start("sim_node", "-p", f"bag_dir:={tmp_path / 'b'}", "-p", "real_time:=true")
    procs.start("profile_node")
    procs.start("interp_node")
    spin_until(ros, lambda: bool(ticks) and ticks[-1][1] > 1.5, 60, "1.5 s of simulated time")
    t_first = next(w for w, s in ticks if s > 0.0)
    spin_until(ros, lambda: ticks[-1][0] > t_first + 1.2, 30, "a second of ticks at 1 x")
    t_before, before = ticks[-1]
    [res] = set_params(ros, "sim_node", {"real_time_factor": 10.0})
    assert res.successful, res.reason
    changed = time.monotonic()
    spin_until(ros, lambda: ticks[-1][0] > changed + 1.0, 30, "a second at the new rate")
    sim = np.array([s for w, s in ticks if w >= changed])
    walls = np.array([w for w, s in ticks if w >= changed])
    # never backwards (a real-time sim waiting for steps says the same time again: sim_node.CLOCK_REPEAT)
    assert np.all(np.diff(np.array([s for _, s in ticks])) >= 0)
    # the first ticks after the change continue from `before` (no jump to 10x the
    # elapsed time), and never faster than the new factor since (0.5 s of slack: a
    # tick's wall time is when it was received); what a starved machine gives below
    # the factor is its own
    assert sim[0] < before + 10.0 * (walls[0] - changed) + 1.0, (before, sim[0])
    assert sim[-1] - before <= 10.0 * (walls[-1] - t_before) + 0.5, (before, sim[-1], walls[-1] - t_before)


@pytest.mark.ros
def test_pacing_a_real_time_job_is_not_a_stall(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """A job that fits within max_in_flight sits in the sim node while it is
    paced to the wall clock: no step arrives for seconds, yet nothing stalled."""
    from conftest import spin_until

    seen = heard_diagnostics(ros)
    procs.start(
        "sim_node", "-p", f"bag_dir:={tmp_path / 'b'}", "-p", "real_time:=true", "-p", "stall_timeout:=0.5"
    )
    procs.start("profile_node")
    procs.start("interp_node", *SMALL_INTERP)  # all of it in flight at once

    def final() -> dict[str, str] | None:
        ends = [v for n, _, v in seen if is_consumer(n, v) and v.get("state") == "done"]
        return ends[-1] if ends else None

    spin_until(ros, lambda: final() is not None, 60, "the job to finish")
    report = final()
    assert report is not None and report["stalls"] == "0", report


SMALL_INTERP = ["-p", "turns_per_layer:=3", "-p", "layers:=1", "-p", "poles:=1", "-p", "chunk_steps:=512"]


@pytest.mark.ros
def test_a_cell_with_use_sim_time_completes_its_job(tmp_path: Path, procs: Procs) -> None:
    """use_sim_time:=true on all three nodes (what a simulated cell's launch
    file sets): their loops run on the steady clock, not on the /clock they
    produce, so the job runs through (it deadlocked silently)."""
    from conftest import final_report

    sim_time = ["-p", "use_sim_time:=true"]
    procs.start("sim_node", "-p", f"bag_dir:={tmp_path / 'bags'}", *sim_time)
    procs.start("profile_node", *sim_time)
    procs.start("interp_node", *SMALL_INTERP, *sim_time)
    bags = wait.until(
        lambda: closed_bags(tmp_path / "bags"),
        60,
        "a closed bag of the use_sim_time cell",
        heard=lambda: [procs.log(p)[-300:] for p, _ in procs.procs],
    )
    report = final_report(rosbags_read(bags[0]))
    assert report["state"] == "done" and report["steps_done"] == report["steps_total"], report


@pytest.mark.ros
def test_a_start_while_a_job_runs_is_refused_and_the_job_completes(
    tmp_path: Path, procs: Procs, ros: Any
) -> None:
    """~/start during a run: success = false with the reason, the running job
    untouched (it was closed incomplete and neither job completed); a start
    after it ends runs the job again into a second complete bag."""
    from conftest import final_report, spin_until
    from std_srvs.srv import Trigger

    seen = heard_diagnostics(ros)
    bags = tmp_path / "bags"
    procs.start("sim_node", "-p", f"bag_dir:={bags}", "-p", "real_time:=true", "-p", "real_time_factor:=4.0")
    procs.start("profile_node")
    # 20 turns, 20480 steps: about 11 s of motion, under 3 s at 4x real time
    procs.start("interp_node", *SMALL_INTERP, "-p", "turns_per_layer:=20", "-p", "autostart:=false")
    client = ros.create_client(Trigger, "/interp_node/start")
    spin_until(ros, client.service_is_ready, 30, "the start service")
    spin_until(ros, lambda: any(is_consumer(n, v) for n, _, v in seen), 30, "the sim node")

    def start() -> Any:
        future = client.call_async(Trigger.Request())
        spin_until(ros, future.done, 30, "the start reply")
        return future.result()

    def done_count() -> int:
        return sum(1 for n, _, v in seen if is_consumer(n, v) and v.get("state") == "done")

    first = start_job(ros)
    assert first.success, first.message
    spin_until(
        ros, lambda: any(v.get("state") == "running" for n, _, v in seen if is_consumer(n, v)), 30, "run"
    )
    second = start()
    assert not second.success and "is running" in second.message, second.message
    spin_until(ros, lambda: done_count() >= 1, 60, "the first job to complete")
    replies: list[str] = []

    def third() -> bool:
        reply = start()
        replies.append(reply.message)
        assert reply.success or "not ready" in reply.message, reply.message
        return bool(reply.success)

    # "done" and the sim node's "ready" travel on two topics: the interp node may hear
    # the one after this test heard the other; the contract is to ask again
    wait.until(third, 30, "a start taken after the first job", heard=lambda: replies[-3:], poll=0.2)
    spin_until(ros, lambda: len(closed_bags(bags)) == 2, 60, "the second bag")
    for done in closed_bags(bags):
        report = final_report(rosbags_read(done))
        assert report["state"] == "done" and report["steps_done"] == report["steps_total"], report


@pytest.mark.ros
def test_a_plain_reader_is_not_the_sim(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """A subscriber on winder/step_times started before the sim node does not
    start the job (it took the chunks and the sim node, started later, waited
    for ever); the sim node started 5 s later announces itself ready on
    winder/ready and records the whole job."""
    from conftest import final_report, spin_until
    from std_msgs.msg import Int64MultiArray

    from winder.ros.qos import QOS_STREAM

    heard: list[Any] = []
    ros.create_subscription(Int64MultiArray, "/winder/step_times", heard.append, QOS_STREAM)
    procs.start("profile_node")
    procs.start("interp_node", *SMALL_INTERP)  # autostart on
    wait.spin_for(ros, 5.0)  # the subject is what does not happen: no job for a plain reader in 5 s
    assert not heard, "the job started for a plain reader"
    bags = tmp_path / "bags"
    procs.start("sim_node", "-p", f"bag_dir:={bags}")
    spin_until(ros, lambda: bool(closed_bags(bags)), 60, "the job recorded by the sim node")
    [done] = closed_bags(bags)
    report = final_report(rosbags_read(done))
    assert report["state"] == "done" and report["steps_done"] == report["steps_total"] == "3072", report
    assert (
        sum(np.frombuffer(bytes(m.data), np.int64).size for m in heard) // 5 == 3072
    )  # the reader saw it too


@pytest.mark.ros
def test_an_integer_for_a_double_setting_stays_a_double(procs: Procs, ros: Any) -> None:
    """-p v_max:=3000 at start and v_max=4000 at run time: the parameter keeps
    the DOUBLE type its descriptor declares (it became an INTEGER parameter)."""
    from rcl_interfaces.msg import ParameterType
    from support.ros_probe import get_param_values, set_params

    procs.start("profile_node", "-p", "v_max:=3000")

    def v_max() -> Any:  # asked again if a reply is lost while the reply topic matches
        return get_param_values(ros, "profile_node", ["v_max"])[0]

    first = v_max()
    assert (first.type, first.double_value) == (ParameterType.PARAMETER_DOUBLE, 3000.0)
    [res] = set_params(ros, "profile_node", {"v_max": 4000})
    assert res.successful, res.reason
    second = v_max()
    assert (second.type, second.double_value) == (ParameterType.PARAMETER_DOUBLE, 4000.0)


#: a job of 4.1e11 steps: 4.1e4 s at the highest v_max a profile node takes
#: (a bound the interp node can apply to any ramp), 4.1e6 s at 1e5 steps/s
LONG_JOB = {"turns_per_layer": 100_000, "layers": 1_000, "poles": 4}


@pytest.mark.ros
def test_the_interp_node_refuses_a_job_too_long_as_check_does(procs: Procs, ros: Any) -> None:
    """A job longer than a week, as winder run --check refuses it: given at
    start, the interp node stays up and refuses to start it (one line naming
    the job and the limit); through ~/start_run with the ramp carried, it is
    refused and nothing is set; a job that fits then runs."""
    from conftest import spin_until
    from rclpy.task import Future
    from std_srvs.srv import Trigger
    from support.ros_probe import get_params, start_run

    from winder.contract.params import PROFILE_SPECS

    # past a week even at v_max 1e7: every layer a first layer, at a thousandth of v_max (3.7e10
    # steps, within a job's steps: a job of more is refused from its turns before it is timed)
    huge = {**LONG_JOB, "layers": 1, "poles": 360, "first_layer_speed": 0.001}
    flags = [f"--{k.replace('_', '-')}={v}" for k, v in huge.items()]
    check = subprocess.run([str(BIN / "winder"), "run", "--check", *flags], capture_output=True, text=True)
    assert check.returncode == 2 and "more than a job may last" in check.stderr, check.stderr
    procs.start("sim_node", "-p", "record:=false")
    procs.start("profile_node")
    params = [a for k, v in huge.items() for a in ("-p", f"{k}:={v}")]
    node = procs.start("interp_node", "-p", "autostart:=false", *params)
    client = ros.create_client(Trigger, "/interp_node/start")
    spin_until(ros, client.service_is_ready, 30, "the start service")
    future: Future = client.call_async(Trigger.Request())
    spin_until(ros, future.done, 30, "the start reply")
    reply = future.result()
    assert not reply.success and "is too long" in reply.message, reply.message
    assert f"more than a job may last ({MAX_JOB_SECONDS:g} s)" in reply.message, reply.message
    assert len(reply.message.splitlines()) == 1 and node.poll() is None

    # the ramp carried with the job: timed exactly, as --check times it with that ramp
    ramp = {f"ramp.{k}": s.default for k, s in PROFILE_SPECS.items()} | {"ramp.v_max": 1e5}
    flags = [f"--{k.replace('_', '-')}={v}" for k, v in LONG_JOB.items()]
    check = subprocess.run(
        [str(BIN / "winder"), "run", "--check", *flags, "--v-max", "1e5"], capture_output=True, text=True
    )
    assert check.returncode == 2 and "more than a job may last" in check.stderr, check.stderr
    refused = start_run(ros, {**LONG_JOB, "first_layer_speed": 1.0, **ramp, "ramp.source": "job"})
    assert not refused.successful and "is too long" in refused.reason, refused.reason
    assert "v_max=100000: more than a job may last" in refused.reason, refused.reason
    assert get_params(ros, "interp_node", ["poles", "ramp.source"]) == [360, "profile_node"]  # nothing set
    started = start_run(ros, {"turns_per_layer": 2, "layers": 1, "poles": 1, "first_layer_speed": 1.0})
    assert started.successful, started.reason
    assert node.poll() is None and "Traceback" not in procs.log(node)
