"""Programmed stops (with automatic resume): the axes come
to rest after turn N exactly, with the same ramp as a segment end, rest the
pause and go on; the step positions are the uninterrupted job's.

Oracles: the planner's own moves are checked against closed forms in
test_profile.py; here a stop's timing is rebuilt from two separately planned
moves and the pause, and the uninterrupted run is the reference for the
positions and eq. 7.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import Procs, closed_bags, is_consumer, rosbags_read
from hypothesis import given, settings
from hypothesis import strategies as st

from winder.analysis.metrics import analyze
from winder.contract.params import PROFILE_SPECS, stop_place, stop_points
from winder.contract.topics import cell_state_values
from winder.motion.job import Job
from winder.motion.timing import plan_job, plan_segment, plan_timing
from winder.record.bag import bags_in
from winder.record.reader import read_run
from winder.spec import SpecError

RAMP = {k: s.default for k, s in PROFILE_SPECS.items()}
WINDER = Path(sys.executable).with_name("winder")


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(1, 50_000), min_size=1, max_size=8), st.floats(0, 2))
def test_without_stops_the_timing_is_plan_jobs_to_the_nanosecond(steps: list[int], dwell: float) -> None:
    ramp = {**RAMP, "dwell": dwell}
    profiles, t0, total = plan_job(ramp, steps)
    timing, total2 = plan_timing(ramp, steps)
    assert total2 == total
    for n, p, t, tm in zip(steps, profiles, t0, timing, strict=True):
        k = np.unique(np.linspace(1, n, 50).astype(np.int64))
        want = int(t) + np.rint(p.times_at(k.astype(np.float64)) * 1e9).astype(np.int64)
        assert np.array_equal(tm.times_ns(k), want)


@settings(max_examples=60, deadline=None)
@given(st.integers(10, 50_000), st.data(), st.floats(0, 5))
def test_a_stop_is_two_moves_from_and_to_rest_and_the_pause(
    n: int, data: st.DataObject, pause: float
) -> None:
    k_stop = data.draw(st.integers(1, n - 1))
    [timing], total = plan_timing(RAMP, [n], [(0, k_stop)], pause)
    a, b = plan_segment(RAMP, k_stop), plan_segment(RAMP, n - k_stop)
    k = np.arange(1, n + 1)
    t = timing.times_ns(k)
    first = np.rint(a.times_at(k[:k_stop].astype(np.float64)) * 1e9).astype(np.int64)
    start_b = round(a.duration * 1e9) + round(pause * 1e9)
    second = start_b + np.rint(b.times_at((k[k_stop:] - k_stop).astype(np.float64)) * 1e9).astype(np.int64)
    assert np.array_equal(t, np.concatenate([first, second]))
    assert np.all(np.diff(t) > 0)
    assert total == start_b + round(b.duration * 1e9)


def test_stop_points_fall_on_turn_boundaries() -> None:
    job = Job(turns_per_layer=20, layers=2, poles=4, fork_steps_per_rev=1024)
    # coil 1 turn 10: layer 0, 10 turns in; coil 2 turn 40: the end of its second layer
    assert stop_points(job, "1:10, 2:40") == [(0, 10 * 1024), (4, 20 * 1024)]
    for bad, why in (("5:1", "coil 5 is not in [1, 4]"), ("1:41", "turn 41 of coil 1 is not in [1, 40]")):
        with pytest.raises(SpecError, match=why.replace("[", r"\[").replace("]", r"\]")):
            stop_points(job, bad)
    # a layer whose feed steps outnumber its fork steps: its turns do not fall on step indices
    feedy = Job(turns_per_layer=4, layers=1, poles=1, fork_steps_per_rev=16, feed_step=1e-5)
    with pytest.raises(SpecError, match="outnumber its fork steps"):
        stop_points(feedy, "1:2")
    assert stop_points(feedy, "1:4") == [(0, max(abs(d) for d in feedy.segments()[0].delta))]

    # stop_place is their inverse: (coil, layer, turn) of each stop, as the sim node reports it
    for j, text in ((job, "1:10"), (job, "2:40"), (job, "3:21"), (feedy, "1:4")):
        [(seg, k)] = stop_points(j, text)
        coil, turn = (int(x) for x in text.split(":"))
        layer = (turn - 1) // j.turns_per_layer + 1
        assert stop_place(j, j.segments()[seg], k) == (coil, layer, turn), text


def stopped_layer_times(n: int, k_stop: int, pause: float) -> np.ndarray:
    """The step times (ns) of an n-step layer stopped after step k_stop: a
    k_stop-step move to rest, the pause, and the rest as another move."""
    one, two = plan_segment(RAMP, k_stop), plan_segment(RAMP, n - k_stop)
    k = np.arange(1, n + 1, dtype=np.float64)
    first = np.rint(one.times_at(k[:k_stop]) * 1e9)
    second = round(one.duration * 1e9) + round(pause * 1e9) + np.rint(two.times_at(k[k_stop:] - k_stop) * 1e9)
    return np.concatenate([first, second]).astype(np.int64)


SMALL = ["--turns-per-layer", "4", "--layers", "1", "--poles", "2", "--fork-steps-per-rev", "512"]


@pytest.mark.ros
def test_a_run_stopped_at_turn_2_has_the_uninterrupted_steps(tmp_path: Path, procs: Procs) -> None:
    """winder run --stop-at-turn 2 --auto-resume 0.5 through the real nodes:
    every step position as in the uninterrupted run, eq. 7 unchanged, no step
    lost; the steps up to the stop timed as a 1024-step move to rest, the rest
    after the pause as another; the bag records the paused and resumed states."""
    env = procs.env

    def run(tag: str, *extra: str) -> Path:
        out = subprocess.run(
            [str(WINDER), "run", *SMALL, "--bag-dir", str(tmp_path / tag), *extra],
            env=env,
            capture_output=True,
            text=True,
            timeout=180,
        )
        assert out.returncode == 0, out.stdout + out.stderr
        [bag] = bags_in(tmp_path / tag)
        return bag

    plain = read_run(run("plain"))
    stopped_bag = run("stopped", "--stop-at-turn", "2", "--auto-resume", "0.5")
    stopped = read_run(stopped_bag)
    assert stopped.complete and plain.complete
    a, b = plain.steps, stopped.steps
    assert np.array_equal(a[:, 1:], b[:, 1:])  # every position, in order
    ra, rb = analyze(plain), analyze(stopped)
    assert rb.command.mean == ra.command.mean and rb.command.max == ra.command.max
    assert rb.lost_steps == 0
    # the first layer: 2048 steps of fork; the stop after 1024 (turn 2 of 512-step turns)
    layer = b[b[:, 1] == 0]
    want = stopped_layer_times(layer.shape[0], 2 * 512, 0.5)
    assert np.array_equal(layer[:, 0], want)
    # the paused and resumed transitions are in the bag, in that order
    raw = rosbags_read(stopped_bag)
    states = [
        values
        for _, m in raw["/diagnostics"]
        for s in m.status
        if is_consumer(s.name, values := {kv.key: kv.value for kv in s.values})
    ]
    marks = [(v["state"], v.get("stop")) for v in states if v.get("stop")]
    assert marks == [("paused", "1:2"), ("running", "1:2")], marks
    # and the cell's state topic, one message per transition, with where the axes are
    cell = [cell_state_values(m) for _, m in raw["/winder/state"]]
    assert [c["state"] for c in cell] == ["running", "paused", "running", "done"], cell
    assert (cell[1]["coil"], cell[1]["layer"], cell[1]["turn"]) == ("1", "1", "2")
    assert all(c["run_id"] == stopped.run_id for c in cell)


@pytest.mark.ros
def test_a_stop_that_waits_for_resume_holds_until_winder_ctl_resume(
    tmp_path: Path, procs: Procs, ros: object
) -> None:
    """stop_resume:=call: the axes rest at the stop until `winder ctl resume`,
    however long (here 4 s of wall time with a 1 s stall timeout: no stall is
    reported, nothing moves); then the job goes on with the step times of the
    automatic resume, and completes. A resume when nothing waits says so."""
    from conftest import spin_until
    from diagnostic_msgs.msg import DiagnosticArray
    from support.ros_probe import ros_spin

    seen: list[dict[str, str]] = []

    ros.create_subscription(  # type: ignore[attr-defined]
        DiagnosticArray,
        "/diagnostics",
        lambda m: seen.extend(
            {"name": s.name, "level": str(s.level[0]), **{kv.key: kv.value for kv in s.values}}
            for s in m.status
        ),
        100,
    )
    bags = tmp_path / "bags"
    procs.start("sim_node", "-p", f"bag_dir:={bags}", "-p", "stall_timeout:=1.0")
    procs.start("profile_node")
    job = ["-p", "turns_per_layer:=4", "-p", "layers:=1", "-p", "poles:=2", "-p", "fork_steps_per_rev:=512"]
    stop = ["-p", "stops:=1:2", "-p", "stop_pause:=0.5", "-p", "stop_resume:=call"]
    procs.start("interp_node", *job, *stop)

    def sim_state() -> str:
        states = [v.get("state", "") for v in seen if is_consumer(v["name"], v)]
        return states[-1] if states else ""

    spin_until(ros, lambda: sim_state() == "paused", 60, "the sim node to rest at the stop")
    done_before = max(int(v.get("steps_done", 0)) for v in seen if is_consumer(v["name"], v))
    ros_spin(ros, 4.0)
    assert sim_state() == "paused"
    assert not [v for v in seen if v["name"] == "sim_node: stream"], (
        "a stall was reported at a programmed stop"
    )
    assert max(int(v.get("steps_done", 0)) for v in seen if is_consumer(v["name"], v)) == done_before
    out = subprocess.run(
        [str(WINDER), "ctl", "resume"], env=procs.env, capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 0 and "resumed after the stop" in out.stdout, out.stdout + out.stderr
    t_end = time.monotonic() + 60
    while not closed_bags(bags) and time.monotonic() < t_end:
        ros_spin(ros, 0.2)
    [meta] = [b / "metadata.yaml" for b in closed_bags(bags)]
    run = read_run(meta.parent)
    assert run.complete and not run.errors, run.errors
    layer = run.steps[run.steps[:, 1] == 0]
    want = stopped_layer_times(layer.shape[0], 2 * 512, 0.5)
    assert np.array_equal(layer[:, 0], want)  # the automatic resume's times: the wait is wall time only
    again = subprocess.run(
        [str(WINDER), "ctl", "resume"], env=procs.env, capture_output=True, text=True, timeout=60
    )
    assert again.returncode == 1 and "nothing to resume" in again.stderr, again.stdout + again.stderr
