"""Operating a running cell through the real nodes: pause,
resume, abort and feed override, scheduled in simulated time (as fast as
possible) and live through `winder ctl` (real time), checked in the bags.

Oracles: the step positions of the uninterrupted job (a run without commands,
and the interpolation itself), the uninterrupted plan's times before a
command, ruckig's time-optimal stop from the plan's state at the request (the
stop distance), and the step intervals against v_max * override.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import Procs, closed_bags, rosbags_read
from support.bags import control_docs
from support.oracles import ruckig_stop

from winder.analysis.metrics import analyze
from winder.contract.params import PROFILE_SPECS
from winder.contract.topics import cell_state_values
from winder.motion.interp import interpolate
from winder.motion.job import Job
from winder.motion.retime import motion_state
from winder.motion.timing import plan_segment
from winder.procs import popen
from winder.record.bag import bags_in
from winder.record.reader import read_run

pytestmark = pytest.mark.ros

RAMP = {k: s.default for k, s in PROFILE_SPECS.items()}
WINDER = Path(sys.executable).with_name("winder")
JOB = {"turns_per_layer": 8, "layers": 1, "poles": 2, "fork_steps_per_rev": 512}
ARGS = [a for k, v in JOB.items() for a in (f"--{k.replace('_', '-')}", str(v))]
LAYER = 8 * 512  # fork steps of a layer: the major axis


def winder_run(tmp: Path, tag: str, env: dict[str, str], *extra: str, code: int = 0) -> Path:
    out = subprocess.run(
        [str(WINDER), "run", *ARGS, "--bag-dir", str(tmp / tag), *extra],
        env=env,
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert out.returncode == code, out.stdout + out.stderr
    [bag] = bags_in(tmp / tag)
    return bag


def positions() -> np.ndarray:
    """Every step position of the uninterrupted job, by the interpolation."""
    job = Job(**JOB)
    return np.concatenate([interpolate(s.start, s.delta) for s in job.segments()])


def events(raw: dict[str, list[tuple[int, Any]]]) -> list[dict[str, Any]]:
    return control_docs(raw.get("/winder/control", []))


def cell_states(raw: dict[str, list[tuple[int, Any]]]) -> list[dict[str, str]]:
    return [cell_state_values(m) for _, m in raw["/winder/state"]]


def check_stop(event: dict[str, Any], t_s: float) -> None:
    """The stop of a command at ``t_s`` in the first layer: where the axes come
    to rest is the closed-form minimum from the plan's state there."""
    prof = plan_segment(RAMP, LAYER)
    p, v, a = motion_state(prof, t_s)
    _, dist = ruckig_stop(v, a, 0.0, RAMP["a_max"], RAMP["j_max"])
    assert event["segment"] == 0
    assert abs(event["stop_distance"] - dist) < 1e-6 * max(dist, 1.0)
    assert abs(event["steps"] - (p + dist)) <= 1.0  # to one step


def test_scheduled_pause_resume_override_keep_every_step(tmp_path: Path, procs: Procs) -> None:
    """pause@0.8, resume@1.5, override@2.0=0.5 as fast as possible: the same
    positions and eq. 7 as the uninterrupted run, no step lost, the times before
    the pause unchanged, the stop where the closed form puts it, the speed
    within v_max * 0.5 after the override's transition, every transition in the
    bag."""
    plain_bag = winder_run(tmp_path, "plain", procs.env)
    bag = winder_run(tmp_path, "ops", procs.env, "--schedule", "pause@0.8,resume@1.5,override@2.0=0.5")
    plain, ops = read_run(plain_bag), read_run(bag)
    assert plain.complete and ops.complete and not ops.errors
    a, b = plain.steps, ops.steps
    assert np.array_equal(b[:, 2:], positions()) and np.array_equal(a[:, 2:], b[:, 2:])
    ra, rb = analyze(plain), analyze(ops)
    assert (rb.command.mean, rb.command.max) == (ra.command.mean, ra.command.max)
    assert rb.lost_steps == 0 and ops.report["steps_missing"] == "0" and ops.report["gaps"] == "0"
    t = b[:, 0]
    assert np.all(np.diff(t) > 0)
    before = a[:, 0] <= 800_000_000
    assert np.array_equal(t[before], a[before, 0])

    raw = rosbags_read(bag)
    pause, resume, override = events(raw)
    assert [e["event"] for e in (pause, resume, override)] == ["pause", "resume", "override"]
    check_stop(pause, 0.8)
    n = pause["steps"]
    assert t[n - 1] <= pause["t_rest_ns"] and t[n] > 1_500_000_000  # at rest until the resume
    # after the override's transition (at most the time to brake from v_max to half
    # of it), the step rate of the layer's major axis is within v_max * 0.5
    layer = b[:, 1] == 0
    settle = 2.0 + (RAMP["v_max"] / 2) / RAMP["a_max"] + RAMP["a_max"] / RAMP["j_max"]
    late = layer & (t > settle * 1e9)
    rate = 1e9 / np.diff(t[late])
    assert rate.size > 100 and rate.max() <= RAMP["v_max"] * 0.5 * (1 + 1e-6)
    states = [s["state"] for s in cell_states(raw)]
    assert states == ["running", "pausing", "paused", "running", "done"], states


def test_scheduled_abort_ends_at_rest_with_the_status_aborted(tmp_path: Path, procs: Procs) -> None:
    """abort@1.0: `winder run` exits 3; the bag is closed with the state
    aborted, its steps are the uninterrupted job's first ones up to the rest
    (where the closed form puts it), the axes at rest at the end."""
    bag = winder_run(tmp_path, "abort", procs.env, "--schedule", "abort@1.0", code=3)
    run = read_run(bag)
    assert run.closed and not run.damaged and run.report["state"] == "aborted"
    raw = rosbags_read(bag)
    [abort] = events(raw)
    check_stop(abort, 1.0)
    steps = run.steps
    assert steps.shape[0] == abort["steps"] == int(run.report["steps_done"])
    assert np.array_equal(steps[:, 2:], positions()[: steps.shape[0]])
    assert [s["state"] for s in cell_states(raw)] == ["running", "aborting", "aborted"]
    # a controlled stop, not a jump: the last step came at a crawl, the axes end at rest
    t = steps[:, 0]
    assert 1e9 / (t[-1] - t[-2]) < 0.05 * RAMP["v_max"]
    assert np.abs(run.states.vel[-1]).max() < 0.05 * np.abs(run.states.vel).max()


def ctl(procs: Procs, *words: str) -> str:
    out = subprocess.run(
        [str(WINDER), "ctl", *words], env=procs.env, capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 0, out.stdout + out.stderr
    return out.stdout


def test_live_pause_override_resume_abort_in_real_time(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """A real-time run driven by `winder ctl`: each command takes effect within
    the look-ahead plus one sample period (plus one step interval) of the
    request; the clock runs on while paused and nothing is reported stalled;
    the abort closes the bag aborted with the uninterrupted job's first steps."""
    from conftest import spin_until
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from winder_interfaces.msg import CellState

    states: list[str] = []
    latched = QoSProfile(
        depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )
    # a late joiner hears the state the cell is in
    ros.create_subscription(CellState, "/winder/state", lambda m: states.append(m.state), latched)
    bags = tmp_path / "bags"
    procs.start("sim_node", "-p", f"bag_dir:={bags}", "-p", "real_time:=true", "-p", "stall_timeout:=1.0")
    procs.start("profile_node", "-p", "lookahead:=0.05")
    job = [a for k, v in {**JOB, "turns_per_layer": 40}.items() for a in ("-p", f"{k}:={v}")]
    procs.start("interp_node", *job)
    spin_until(ros, lambda: "running" in states, 60, "the run to start")
    time.sleep(1.0)
    assert "pausing" in ctl(procs, "pause")
    spin_until(ros, lambda: states[-1:] == ["paused"], 30, "the axes to rest")
    time.sleep(1.5)
    assert "feed_override = 0.5" in ctl(procs, "override", "0.5")
    assert "resuming" in ctl(procs, "resume")
    spin_until(ros, lambda: states[-1:] == ["running"], 30, "the resume")
    time.sleep(1.0)
    assert "aborting" in ctl(procs, "abort")
    t_end = time.monotonic() + 60
    while not closed_bags(bags) and time.monotonic() < t_end:
        time.sleep(0.2)
    [meta] = [b / "metadata.yaml" for b in closed_bags(bags)]
    run = read_run(meta.parent)
    assert run.report["state"] == "aborted" and not run.errors, run.errors
    raw = rosbags_read(meta.parent)
    evs = events(raw)
    assert [e["event"] for e in evs] == ["pause", "override", "resume", "abort"]
    for e in evs:  # within the look-ahead, a sample at 200 Hz and one step at the speed of the moment
        bound = 0.05e9 + 1e9 / 200 + 1e9 / max(float(e.get("v", 2048.0)), 1.0)
        if e["event"] != "override":  # while paused, an override waits for the resume
            assert 0 <= e["latency_ns"] <= bound, e
    pause, resume = evs[0], evs[2]
    assert (resume["t_ns"] - pause["t_rest_ns"]) / 1e9 > 1.5  # the clock went on while paused
    steps = run.steps
    assert steps.shape[0] == evs[3]["steps"]
    job_all = np.concatenate(
        [interpolate(s.start, s.delta) for s in Job(**{**JOB, "turns_per_layer": 40}).segments()]
    )
    assert np.array_equal(steps[:, 2:], job_all[: steps.shape[0]])
    assert np.all(np.diff(steps[:, 0]) > 0)
    # winder analyze counts the steps simulated and recorded, not the job's total
    rows = sum(len(m.data) // 5 for _, m in raw["/winder/step_times"])
    out = subprocess.run(
        [str(Path(sys.executable).parent / "winder"), "analyze", str(meta.parent), "--no-plots"],
        capture_output=True,
        text=True,
        timeout=120,
    ).stdout
    simulated = int(run.report["steps_done"])
    assert simulated == evs[3]["steps"] < job_all.shape[0]
    assert f"{simulated} simulated, {rows} recorded, of {job_all.shape[0]}" in out, out
    assert not any(s.name.endswith("stream") for _, m in raw["/diagnostics"] for s in m.status), (
        "a stall was reported while paused"
    )
    assert math.isclose(float(json.loads(raw["/winder/sim_config"][0][1].data)["real_time_factor"]), 1.0)


def test_winder_run_takes_keys_on_a_terminal(tmp_path: Path, procs: Procs) -> None:
    """`winder run` with a terminal on stdin: the space bar pauses and resumes,
    `a` aborts (exit status 3); the bag records the three commands."""
    import os
    import pty

    master, slave = pty.openpty()
    bags = tmp_path / "bags"
    job = ["--turns-per-layer", "20", "--layers", "1", "--poles", "1", "--real-time"]
    run = popen(
        [str(WINDER), "run", *job, "--bag-dir", str(bags)],
        env=procs.env,
        stdin=slave,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    os.close(slave)
    try:
        t_end = time.monotonic() + 60
        while not list(bags.glob("*")) and time.monotonic() < t_end:
            time.sleep(0.1)
        for key in (b" ", b" ", b"a"):  # pause, resume, abort, a second and a half apart
            time.sleep(1.5)
            os.write(master, key)
        out, err = run.communicate(timeout=60)
    finally:
        os.close(master)
        if run.poll() is None:
            run.kill()
    assert run.returncode == 3, out + err
    assert "keys: space pause/resume" in err and "pause: run" in err and "abort: run" in err, err
    [bag] = bags_in(bags)
    kinds = [(e["event"], e["source"]) for e in events(rosbags_read(bag))]
    assert kinds == [("pause", "call"), ("resume", "call"), ("abort", "call")], kinds
