"""`winder run --one-process`: the three nodes in one `winder_container`
process. The oracle is the same cell as three processes: the same job and
settings give the same timed step stream, row for row, and each node's own
settings take effect in the container as in its own process. Real
processes over DDS in a locked domain; the bags read back by rosbags."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import bag_closed, final_report, next_domain, release_domain, rosbags_read
from support import wait
from support.bags import mcap_size

from winder.motion.job import Job
from winder.record.bag import bags_in

pytestmark = pytest.mark.ros

BIN = Path(sys.executable).parent
JOB = ["--turns-per-layer", "6", "--layers", "1", "--poles", "2", "--fork-steps-per-rev", "256"]
# a setting for each node, each visible in the bag: the job (interp), the ramp (profile), a motor (sim),
# and a pause and resume of the operation (profile and consumer)
SETTINGS = [*JOB, "--v-max", "3000", "--fork.J", "0.002", "--schedule", "pause@0.4,resume@0.7"]


@pytest.fixture(scope="module")
def env() -> Iterator[dict[str, str]]:
    domain = next_domain()
    try:
        yield {**os.environ, "ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    finally:
        release_domain(domain)


def run(env: dict[str, str], bags: Path, *args: str, code: int = 0) -> subprocess.CompletedProcess[str]:
    out = subprocess.run(
        [str(BIN / "winder"), "run", *args, "--bag-dir", str(bags)],
        env=env,
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert out.returncode == code, out.stdout + out.stderr
    return out


def stream(bag: dict[str, list[tuple[int, Any]]]) -> np.ndarray:
    rows = [np.asarray(m.data, np.int64) for _, m in bag["/winder/step_times"]]
    return np.concatenate(rows)


@pytest.mark.parametrize("namespace", ["", "/wc/line2"])
def test_one_process_runs_the_same_cell_as_three(env: dict[str, str], tmp_path: Path, namespace: str) -> None:
    """In a namespace too: rcl's node-prefixed ``-p node:name:=value`` reaches
    no namespaced node, and the container's cell once ran the default job
    there, every setting dropped."""
    ns = ["--namespace", namespace] if namespace else []
    run(env, tmp_path / "three", *SETTINGS, *ns)
    out = run(env, tmp_path / "one", *SETTINGS, *ns, "--one-process")
    [three] = bags_in(tmp_path / "three")
    [one] = bags_in(tmp_path / "one")
    a, b = rosbags_read(three), rosbags_read(one)
    a, b = ({t.removeprefix(namespace): m for t, m in bag.items()} for bag in (a, b))
    steps = Job(turns_per_layer=6, layers=1, poles=2, fork_steps_per_rev=256).total_steps
    for bag in (a, b):
        report = final_report(bag, namespace)
        assert report["state"] == "done", report
        assert int(report["steps_done"]) == steps and report["steps_missing"] == "0", report
    # the same timed rows, to the nanosecond: the settings reached the same nodes
    np.testing.assert_array_equal(stream(b), stream(a))
    # each node's own settings took effect in the container
    profile = json.loads(b["/winder/profile_config"][-1][1].data)
    sim = json.loads(b["/winder/sim_config"][-1][1].data)
    theirs = json.loads(a["/winder/profile_config"][-1][1].data)
    assert profile.pop("run_id") != theirs.pop("run_id")  # two runs
    assert profile == theirs
    assert "3000" in json.dumps(profile), profile
    assert "0.002" in json.dumps(sim), sim
    # and the three nodes were one process: their statuses name one pid
    pids = {
        kv.value for _, arr in b["/diagnostics"] for st in arr.status for kv in st.values if kv.key == "pid"
    }
    assert len(pids) == 1, pids
    assert "done" in out.stdout


def test_one_process_and_external_are_refused_together(env: dict[str, str], tmp_path: Path) -> None:
    out = run(env, tmp_path, *JOB, "--one-process", "--external", "sim", code=2)
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "--one-process" in lines[0] and "'sim'" in lines[0], out.stderr
    assert "Traceback" not in out.stderr


@pytest.mark.parametrize(
    ("args", "says"),
    [
        ([], "no node to run"),
        (["winder_sim.sim_node"], "must be MODULE:CLASS"),
        (["winder_sim.no_such_module:SimNode"], "cannot be imported"),
        (["winder_sim.sim_node:AxisSim"], "has no node class 'AxisSim'"),
        (["json:loads"], "has no node class 'loads'"),
    ],
)
def test_the_container_refuses_what_it_cannot_run_in_one_line(
    env: dict[str, str], args: list[str], says: str
) -> None:
    out = subprocess.run(
        [str(BIN / "winder_container"), *args], env=env, capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 2, out.stdout + out.stderr
    assert says in out.stderr.splitlines()[0], out.stderr
    assert "Traceback" not in out.stderr


def test_ctrl_c_mid_run_closes_the_one_process_cells_bag(env: dict[str, str], tmp_path: Path) -> None:
    """Ctrl-C to `winder run --one-process` mid-run: status 130, no
    traceback, the container gone and the run's bag closed (incomplete),
    as with three processes."""
    big = ["--turns-per-layer", "1200", "--bag-dir", str(tmp_path)]
    p = subprocess.Popen(
        [str(BIN / "winder"), "run", "--one-process", *big],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    # in the run: its bag's file holds its first chunks
    wait.until(lambda: mcap_size(tmp_path) > 30_000, 60, "the run's first 30 kB in its bag", running=p)
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=60)
    assert p.returncode == 130, out + err
    assert "Traceback" not in err and "interrupted" in err, err
    [bag] = bags_in(tmp_path)
    assert bag_closed(bag)
    report = final_report(rosbags_read(bag))
    assert report["state"] == "incomplete", report


# -- the container started before the command has read its arguments (winder.ros.early) --------


def tagged_processes(tag: str) -> list[int]:
    """The live processes whose environment carries ``WINDER_TEST_TAG=tag``."""
    found = []
    for environ in Path("/proc").glob("[0-9]*/environ"):
        try:
            if f"WINDER_TEST_TAG={tag}".encode() in environ.read_bytes().split(b"\0"):
                found.append(int(environ.parent.name))
        except OSError:
            continue  # gone meanwhile, or not ours to read
    return found


def container_started(tag: str) -> bool:
    """The early container of the command tagged ``tag`` is running."""
    for pid in tagged_processes(tag):
        try:
            if b"winder_container" in Path(f"/proc/{pid}/cmdline").read_bytes():
                return True
        except OSError:
            continue
    return False


@pytest.mark.parametrize(
    "how",
    ["bad value", "bad job file", "SIGINT at 0.0 s", "SIGTERM at 0.1 s", "SIGINT at 0.25 s"],
)
def test_a_run_that_starts_no_cell_leaves_no_container(env: dict[str, str], tmp_path: Path, how: str) -> None:
    """``winder run --one-process`` starts its container before it reads its
    arguments. A command that ends before the cell starts (refused input, a
    signal while it loads) leaves no container running and no log
    directory behind, and says why in one line."""
    tag = f"{os.getpid()}-{how.replace(' ', '_')}"
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    run_env = {**env, "WINDER_TEST_TAG": tag, "TMPDIR": str(tmp)}
    args = [*JOB, "--one-process", "--bag-dir", str(tmp_path / "bags")]
    if how == "bad value":
        args += ["--v-max", "-5"]
    elif how == "bad job file":
        (tmp_path / "job.yaml").write_text("interp_node:\n  layers: [\n")
        args += ["--job-file", str(tmp_path / "job.yaml")]
    p = subprocess.Popen(
        [str(BIN / "winder"), "run", *args],
        env=run_env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    if how.startswith("SIG"):
        # the signal comes ``after`` s after the container was started: winder's
        # own code runs by then (before it, Python's start is no part of winder)
        sig, after = how.split(" at ")
        wait.until(
            lambda: container_started(tag) or p.poll() is not None, 30, "the early container", poll=0.005
        )
        time.sleep(float(after.removesuffix(" s")))  # the signal's moment is the subject: not a wait
        p.send_signal(getattr(signal, sig))
    out, err = p.communicate(timeout=60)
    if how.startswith("SIG"):
        assert p.returncode in (0, 130), out + err  # 0: the tiny job may have been wound already
    else:
        assert p.returncode == 2, out + err
        assert len(err.strip().splitlines()) == 1 and "error" in err, err
    assert "Traceback" not in err, err
    wait.until(  # a container told to leave has a moment to do so
        lambda: not tagged_processes(tag),
        10,
        f"the end of every process of the command ({how})",
        heard=lambda: tagged_processes(tag),
        poll=0.05,
    )
    assert list(tmp.iterdir()) == [], f"{how}: left behind {list(tmp.iterdir())}"


def test_the_container_takes_its_arguments_on_stdin(tmp_path: Path) -> None:
    """``winder_container --args-on-stdin``: the environment and the
    ``--ros-args`` it reads take effect (started outside any ROS domain
    setting, it joins the one it is told, in the namespace it is told);
    empty input ends it quietly; invalid input is refused in one line."""
    import rclpy
    from rclpy.context import Context

    from winder.ros.early import ARGS_ON_STDIN, CELL_CLASSES

    argv = [str(BIN / "winder_container"), ARGS_ON_STDIN, *CELL_CLASSES.values()]
    bare = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}
    bare["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    for given, code, says in [
        (b"", 0, ""),
        (b"{not json", 2, "is invalid"),
        (b'{"env": {}}', 2, "is invalid"),
    ]:
        out = subprocess.run(argv, input=given, env=bare, capture_output=True, timeout=60)
        assert out.returncode == code, out
        err = out.stderr.decode()
        assert (says in err and len(err.strip().splitlines()) == 1) if says else err == "", err
    domain = next_domain()
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    probe = rclpy.create_node("winder_test_probe", context=ctx)
    told = {
        "env": {"ROS_DOMAIN_ID": str(domain)},
        "ros_args": [
            "--ros-args",
            "-r",
            "__ns:=/told",
            "-p",
            "autostart:=false",
            "-p",
            f"bag_dir:={tmp_path}",
        ],
    }
    p = subprocess.Popen(argv, stdin=subprocess.PIPE, env=bare, stderr=subprocess.PIPE)
    try:
        assert p.stdin is not None
        p.stdin.write(json.dumps(told).encode())
        p.stdin.close()
        want = {(n, "/told") for n in ("interp_node", "profile_node", "sim_node")}
        wait.until(  # the probe's graph is kept by DDS' threads: no spinning needed
            lambda: want <= set(probe.get_node_names_and_namespaces()),
            60,
            "the container's three nodes in /told",
            heard=lambda: (
                probe.get_node_names_and_namespaces(),
                p.stderr.read() if p.poll() is not None and p.stderr else "",  # read once it ended: no block
            ),
            running=p,
        )
        p.send_signal(signal.SIGINT)
        assert p.wait(timeout=30) == 0
    finally:
        if p.poll() is None:
            p.kill()
        probe.destroy_node()
        rclpy.try_shutdown(context=ctx)
        release_domain(domain)


def test_a_container_that_cannot_load_its_nodes_is_reported(env: dict[str, str], tmp_path: Path) -> None:
    """The early container ends before the command hands it its arguments (a
    node module that fails to import, here a broken ``winder_sim`` first on
    PYTHONPATH): the command reports the container's exit and where its log
    is, instead of dying of SIGPIPE on the closed pipe."""
    broken = tmp_path / "broken" / "winder_sim"
    broken.mkdir(parents=True)
    (broken / "__init__.py").write_text("")
    (broken / "sim_node.py").write_text("raise ImportError('a broken install')\n")
    run_env = {**env, "PYTHONPATH": str(tmp_path / "broken")}
    out = subprocess.run(
        [str(BIN / "winder"), "run", *JOB, "--one-process", "--bag-dir", str(tmp_path / "bags")],
        env=run_env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    said = out.stdout + out.stderr
    assert out.returncode not in (0, -signal.SIGPIPE, 128 + signal.SIGPIPE), said
    assert "winder_container exited with status 2" in said, said
    assert "Traceback" not in out.stderr, said
    [logs] = [Path(p) for p in re.findall(r"node logs in (\S+?)\)", said)]
    assert "cannot be imported" in (logs / "winder_container.log").read_text()
    shutil.rmtree(logs)
