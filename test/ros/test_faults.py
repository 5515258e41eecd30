"""Behaviour under faults: signals, a broken step stream, a dead upstream node,
two cells on one graph, and a long job. Real processes over DDS throughout."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import Procs, bag_closed, is_consumer, rosbags_read, spin_until
from support.bags import job_doc
from support.cell import SMALL_JOB, FakeProfile, expected_end, job_args, only_bag, timed_rows, winder_run
from support.ros_probe import heard_diagnostics, under_way

from winder.motion.job import Job
from winder.procs import popen

pytestmark = pytest.mark.ros


def final_status(bag: dict[str, list[tuple[int, Any]]], prefix: str = "") -> dict[str, str]:
    """The consumer's last job status in the bag (of the cell in the namespace ``prefix``)."""
    finals = [
        values
        for _, m in bag["/diagnostics"]
        for s in m.status
        if is_consumer(s.name, values := {kv.key: kv.value for kv in s.values}, prefix) and "state" in values
    ]
    assert finals, "no status of the step consumer in the bag"
    return finals[-1]


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_mid_job_closes_the_bag(tmp_path: Path, procs: Procs, ros: Any, sig: int) -> None:
    seen = heard_diagnostics(ros)
    bags = tmp_path / "bags"
    sim = procs.start(
        "sim_node", "-p", f"bag_dir:={bags}", "-p", "real_time:=true", "-p", "real_time_factor:=4.0"
    )
    procs.start("profile_node")
    procs.start("interp_node", "-p", "turns_per_layer:=40")
    # mid-job: the sim node says its run is running with steps executed
    spin_until(ros, lambda: under_way(seen), 60, "the sim node's run under way", heard=lambda: seen[-5:])
    assert procs.stop(sim, sig) == 0
    bag_dir = only_bag(tmp_path)
    assert bag_closed(bag_dir)
    bag = rosbags_read(bag_dir)
    assert final_status(bag)["state"] == "incomplete"
    assert "Traceback" not in procs.log(sim)


@pytest.mark.parametrize("fault", ["drop", "duplicate", "reorder"])
def test_stream_fault_is_detected_and_reported(tmp_path: Path, procs: Procs, ros: Any, fault: str) -> None:
    job = Job(job_id="faulty", turns_per_layer=2, layers=2, poles=1, fork_steps_per_rev=256)
    bags = tmp_path / "bags"
    procs.start("sim_node", "-p", f"bag_dir:={bags}", "-p", "stall_timeout:=60.0")
    fake = FakeProfile(ros, job)
    chunks = fake.chunks(100)
    assert len(chunks) >= 8
    if fault == "drop":
        del chunks[3]
    elif fault == "duplicate":
        chunks.insert(4, chunks[3])
    else:
        chunks[3], chunks[4] = chunks[4], chunks[3]
    fake.send(chunks)
    words = {
        "drop": "gap in the step stream",
        "duplicate": "arrived again",
        "reorder": "arrived late",
    }
    spin_until(
        ros,
        lambda: any(words[fault] in text for _, text, _ in fake.statuses),
        30,
        f"a report of the {fault}",
    )
    level = next(lv for lv, text, _ in fake.statuses if words[fault] in text)
    assert level == 2  # ERROR
    if fault == "drop":
        # the job still completes (the stream continued), and says what it lost
        spin_until(ros, lambda: any(v.get("state") == "done" for _, _, v in fake.statuses), 30, "the job end")
        done = [v for _, _, v in fake.statuses if v.get("state") == "done"][-1]
        assert int(done["steps_missing"]) == 100
        assert int(done["gaps"]) == 1
        bag = rosbags_read(only_bag(tmp_path))
        assert int(final_status(bag)["steps_missing"]) == 100
        # winder analyze lists the recorded ERROR, at the simulated time the bag logged it
        wall0 = json.loads(bag["/winder/sim_config"][0][1].data)["wall_start_ns"]
        logged = next(t for t, arr in bag["/diagnostics"] for st in arr.status if words[fault] in st.message)
        out = subprocess.run(
            [str(Path(sys.executable).parent / "winder"), "analyze", str(only_bag(tmp_path)), "--no-plots"],
            capture_output=True,
            text=True,
            timeout=120,
        ).stdout
        line = next((ln for ln in out.splitlines() if ln.startswith("ERROR ") and words[fault] in ln), out)
        assert f"at {(logged - wall0) / 1e9:.3f} s: sim_node: stream:" in line, line
        # ... and the stream's own count of the fault, and what it cost, from the recorded report
        report = final_status(bag)
        total = fake.chunks(100)
        rows = sum(len(m.data) // 5 for _, m in bag["/winder/step_times"])
        faults = next(ln for ln in out.splitlines() if ln.startswith("stream faults"))
        assert faults.endswith(f"{report['gaps']} gap(s), {report['steps_missing']} steps missing"), faults
        steps = next(ln for ln in out.splitlines() if ln.startswith("steps "))
        assert steps.endswith(
            f"{report['steps_done']} simulated, {rows} recorded, of {sum(c.shape[0] for c in total)} "
            f"(done, {report['steps_missing']} steps never arrived)"
        ), steps


def test_killed_profile_node_is_reported_as_a_stall(tmp_path: Path, procs: Procs, ros: Any) -> None:
    from diagnostic_msgs.msg import DiagnosticArray

    seen: list[str] = []
    ros.create_subscription(
        DiagnosticArray, "/diagnostics", lambda m: seen.extend(s.message for s in m.status), 100
    )
    bags = tmp_path / "bags"
    procs.start("sim_node", "-p", f"bag_dir:={bags}", "-p", "stall_timeout:=1.0")
    profile = procs.start("profile_node")
    # a small window: the interp node waits for the sim node's receipts, so the
    # profile node dies with most of the job still to come
    procs.start("interp_node", "-p", "turns_per_layer:=200", "-p", "max_in_flight:=16384")
    spin_until(ros, lambda: any("running" in s for s in seen), 60, "the job to start")
    profile.kill()
    profile.wait()
    spin_until(ros, lambda: any("step stream stalled" in s for s in seen), 30, "a stall report")


def test_a_slow_run_set_up_is_no_stall(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """A consumer whose set-up of a run takes 3 s (test/consumers/slow_start.py:
    a sim node whose ``begin`` sleeps, as a starved host made the real one
    take over 2 s) with a 1 s ``stall_timeout``: the steps that came during
    the set-up are work at hand, the watch counts from the end of it, and
    the run ends done with no stall reported. (Counting from before the
    set-up, 8 cells on 2 cores reported stalls 46 ms into their runs.)"""
    from support.paths import TEST
    from support.ros_probe import heard_diagnostics

    seen = heard_diagnostics(ros)
    bags = tmp_path / "bags"
    slow = TEST / "consumers" / "slow_start.py"
    procs.launch(
        [sys.executable, str(slow), "--ros-args", "-p", f"bag_dir:={bags}", "-p", "stall_timeout:=1.0"],
        "slow_start",
    )
    procs.start("profile_node")
    procs.start("interp_node", "-p", "turns_per_layer:=4", "-p", "layers:=1", "-p", "poles:=1")

    def final() -> dict[str, str] | None:
        done = [v for n, _, v in seen if is_consumer(n, v) and v.get("state") in ("done", "incomplete")]
        return done[-1] if done else None

    spin_until(ros, lambda: final() is not None, 90, "the run's final report")
    report = final()
    assert report is not None and report["state"] == "done", report
    assert report["stalls"] == "0", report
    assert not [m for _, m, _ in seen if "stalled" in m], [m for _, m, _ in seen if "stalled" in m]


def test_two_cells_in_two_namespaces_do_not_interfere(tmp_path: Path, procs: Procs) -> None:
    import subprocess

    from conftest import BIN

    jobs = {
        "cell1": {**SMALL_JOB, "job_id": "one", "turns_per_layer": 2},
        "cell2": {**SMALL_JOB, "job_id": "two", "turns_per_layer": 4, "poles": 3},
    }
    runs = {}
    for ns, job in jobs.items():
        (tmp_path / ns).mkdir()
        runs[ns] = popen(
            [
                str(BIN / "winder"),
                "run",
                "--namespace",
                f"/{ns}",
                "--bag-dir",
                str(tmp_path / ns / "bags"),
                *job_args(job),
            ],
            env=procs.env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
    for ns, p in runs.items():
        out, err = p.communicate(timeout=300)
        assert p.returncode == 0, out + err
        bag = rosbags_read(only_bag(tmp_path / ns))
        job = job_doc(bag[f"/{ns}/winder/job"][0][1])
        assert job["job"]["job_id"] == jobs[ns]["job_id"]
        rows = timed_rows(bag, f"/{ns}/winder/step_times")
        assert rows.shape[0] == job["total_steps"]  # nothing from the other cell
        assert tuple(rows[-1, 2:]) == expected_end(jobs[ns])
        assert int(final_status(bag, f"{ns}/")["steps_missing"]) == 0


def test_a_million_step_job_completes_with_nothing_lost(tmp_path: Path, procs: Procs) -> None:
    job = {"job_id": "long", "turns_per_layer": 123, "layers": 2, "poles": 4}
    total = Job(**{k: v for k, v in job.items()}).total_steps
    assert total >= 10**6
    r = winder_run(
        tmp_path,
        procs.domain,
        *job_args(job),
        "--v-max",
        "20000",
        "--a-max",
        "200000",
        "--j-max",
        "4000000",
        "--publish-rate",
        "20",
        timeout=600,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    bag = rosbags_read(only_bag(tmp_path))
    rows = timed_rows(bag)
    assert rows.shape[0] == total
    steps = np.diff(np.vstack([[0, 0, 0], rows[:, 2:]]), axis=0)
    assert np.all(np.abs(steps) <= 1) and np.all(np.any(steps != 0, axis=1))
    assert np.all(np.diff(rows[:, 0]) > 0)
    status = final_status(bag)
    assert status["state"] == "done" and int(status["steps_missing"]) == 0 and int(status["gaps"]) == 0
