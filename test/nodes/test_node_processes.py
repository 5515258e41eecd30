"""The three nodes as real processes over DDS, and the bags they write.

Bags are read here with rosbags directly (not through winder's own reader),
and expected positions are worked out from the job fields in the test.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import BIN, Procs, bag_closed, final_report, is_consumer, rosbags_read, spin_until
from support import wait
from support.bags import job_doc
from support.cell import SMALL_JOB, expected_end, job_args, only_bag, timed_rows, winder_run
from support.paths import ROOT
from support.ros_probe import heard_diagnostics, set_params, under_way

from winder.procs import popen

#: the venv the suite runs in (its ROS wheels: what colcon builds winder_interfaces against)
VENV = BIN.parent

pytestmark = pytest.mark.ros


@pytest.mark.parametrize("profile", ["scurve", "trapezoid", "exponential"])
def test_cell_records_every_step_once_in_order(tmp_path: Path, procs: Procs, profile: str) -> None:
    r = winder_run(tmp_path, procs.domain, *job_args(SMALL_JOB), "--profile", profile)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "Traceback" not in r.stderr
    assert not list((tmp_path / "tmp").iterdir())  # a clean run leaves no node logs behind
    bag_dir = only_bag(tmp_path)
    assert bag_dir.name.startswith("small_")
    assert bag_closed(bag_dir)
    bag = rosbags_read(bag_dir)
    rows = timed_rows(bag)
    t, seg, pos = rows[:, 0], rows[:, 1], rows[:, 2:]

    # every step exactly once, in order: each row one step from the last
    steps = np.diff(np.vstack([[0, 0, 0], pos]), axis=0)
    assert np.all(np.abs(steps) <= 1)
    assert np.all(np.any(steps != 0, axis=1))
    fork = SMALL_JOB["fork_steps_per_rev"]
    turns, layers, poles = SMALL_JOB["turns_per_layer"], SMALL_JOB["layers"], SMALL_JOB["poles"]
    feed_layer = round(turns * 2.5e-3 / 1e-5)
    n_layer = max(feed_layer, turns * fork)
    assert rows.shape[0] == poles * layers * n_layer + (poles - 1) * round(1024 / poles)
    assert tuple(pos[-1]) == expected_end(SMALL_JOB)
    # segments in order, times strictly increasing within and across segments
    assert np.all(np.diff(seg) >= 0)
    assert np.all(np.diff(t) > 0)
    assert t[0] > 0

    # the job, path and motor set-up travel with the recording
    job = job_doc(bag["/winder/job"][0][1])
    assert job["job"]["job_id"] == "small"
    assert job["run_id"].startswith("small_")  # the run's identity travels with its job
    path = bag["/winder/path"][0][1]
    assert path.header.frame_id == job["run_id"]
    assert list(path.joint_names) == ["feed", "fork", "pole"]
    end = np.array(path.points[-1].positions)
    assert end == pytest.approx(np.array(expected_end(SMALL_JOB)) * np.array(job["joint_step"]))
    config = json.loads(bag["/winder/sim_config"][0][1].data)
    assert config["model"] == "linear"
    ramp = json.loads(bag["/winder/profile_config"][0][1].data)
    assert ramp["profile"] == profile and ramp["job_id"] == "small" and ramp["run_id"] == job["run_id"]
    # the path's corners carry the time each is reached: 0 at the start, the
    # planned job duration at the end, in order
    reach = np.array([p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in path.points])
    assert reach[0] == 0 and np.all(np.diff(reach) > 0)
    assert reach[-1] == pytest.approx(ramp["job_duration_s"], abs=1e-9)

    # the clock never goes backwards and joint states come with it
    clock = np.array([m.clock.sec * 10**9 + m.clock.nanosec for _, m in bag["/clock"]])
    assert np.all(np.diff(clock) > 0)
    assert len(bag["/winder/joint_states"]) == len(clock) == len(bag["/winder/joint_commands"])
    assert clock[-1] >= t[-1]
    last_cmd = bag["/winder/joint_commands"][-1][1]
    assert np.array(last_cmd.position) == pytest.approx(end)
    last_state = bag["/winder/joint_states"][-1][1]
    # after the settle time the axes sit close to the command (well under a step)
    assert np.abs(np.array(last_state.position) - end) == pytest.approx(0, abs=0.5 * max(job["joint_step"]))

    # diagnostics report completion, in the bag and in the summary printed
    finals = [
        s
        for _, m in bag["/diagnostics"]
        for s in m.status
        if is_consumer(s.name, v := {kv.key: kv.value for kv in s.values}) and v.get("state") == "done"
    ]
    assert finals, "no completion report in the bag"
    values = {kv.key: kv.value for kv in finals[-1].values}
    assert int(values["steps_done"]) == rows.shape[0]
    assert int(values["steps_missing"]) == 0 and int(values["gaps"]) == 0
    assert f"steps              {rows.shape[0]} of {rows.shape[0]}" in r.stdout
    assert str(bag_dir) in r.stdout


def test_bad_job_on_the_command_line_starts_nothing(tmp_path: Path, procs: Procs) -> None:
    r = winder_run(tmp_path, procs.domain, "--poles", "0")
    assert r.returncode == 2
    assert r.stderr.strip() == "winder run: error: poles=0 is invalid: must be in [1, 360]"
    assert not (tmp_path / "bags").exists() or not any((tmp_path / "bags").iterdir())


@pytest.mark.parametrize(
    ("executable", "name", "value", "reason"),
    [
        ("interp_node", "poles", 0, "Parameter poles out of range. Min: 1, Max: 360, value: 0"),
        ("interp_node", "poles", 2.5, "poles=2.5 is invalid: must be an integer in [1, 360]"),
        ("interp_node", "wire_diameter", "thick", "wire_diameter='thick' is invalid: must be a number"),
        ("interp_node", "bobbin.window_width", 0.01, "10.0 mm wide: 40.0 mm over (at most 4 turns fit)"),
        (
            "profile_node",
            "profile",
            "sine",
            "profile='sine' is invalid: must be one of scurve, trapezoid, exponential",
        ),
        ("profile_node", "a_max", -1.0, "out of range"),
        ("profile_node", "j_max", float("nan"), "j_max"),
        ("sim_node", "fork.J", 0, "fork.J=0 is invalid: must be in (0, 100] kg m^2"),
        ("sim_node", "model", "quantum", "model='quantum' is invalid"),
    ],
)
def test_bad_parameter_is_rejected_and_node_keeps_running(
    tmp_path: Path, procs: Procs, ros: Any, executable: str, name: str, value: Any, reason: str
) -> None:
    p = (
        procs.start(executable, "-p", "autostart:=false")
        if executable == "interp_node"
        else procs.start(executable, "-p", f"bag_dir:={tmp_path / 'bags'}")
        if executable == "sim_node"
        else procs.start(executable)
    )
    [res] = set_params(ros, executable, {name: value})
    assert not res.successful
    assert reason in res.reason
    assert name in res.reason or "the window is" in res.reason  # a coil too wide: its words name the window
    assert p.poll() is None, "node died on a bad parameter"
    # a good value is still accepted afterwards
    good = {
        "poles": 3,
        "wire_diameter": 0.002,
        "bobbin.window_width": 0.05,
        "profile": "trapezoid",
        "a_max": 100.0,
        "j_max": 1000.0,
        "fork.J": 2e-4,
        "model": "nonlinear",
    }[name]
    [res] = set_params(ros, executable, {name: good})
    assert res.successful, res.reason
    assert p.poll() is None
    assert "Traceback" not in procs.log(p)


@pytest.mark.parametrize(
    ("executable", "override", "message"),
    [
        ("interp_node", "poles:=0", "poles=0 is invalid: must be in [1, 360]"),
        ("interp_node", "turns_per_layer:=2.5", "turns_per_layer=2.5 is invalid: must be an integer"),
        ("profile_node", "v_max:=-5.0", "v_max"),
        ("sim_node", "feed.D:=-1.0", "feed.D"),
    ],
)
def test_bad_override_at_start_is_reported_not_fatal(
    procs: Procs, executable: str, override: str, message: str
) -> None:
    p = procs.start(executable, "-p", override)
    wait.log_has(lambda: procs.log(p), message, 30, f"{executable}'s report of {override}", running=p)
    assert p.poll() is None, procs.log(p)
    assert message in procs.log(p)
    assert procs.stop(p) == 0
    assert "Traceback" not in procs.log(p)


def test_bad_job_at_start_never_starts_and_leaves_no_bag(tmp_path: Path, procs: Procs, ros: Any) -> None:
    from diagnostic_msgs.msg import DiagnosticArray

    seen: list[str] = []
    ros.create_subscription(
        DiagnosticArray, "/diagnostics", lambda m: seen.extend(s.message for s in m.status), 50
    )
    bags = tmp_path / "bags"
    procs.start("sim_node", "-p", f"bag_dir:={bags}")
    procs.start("profile_node")
    interp = procs.start("interp_node", "-p", "poles:=0")
    spin_until(
        ros,
        lambda: any("settings rejected at start" in s for s in seen),
        30,
        "the interp node's error report",
    )
    wait.spin_for(ros, 1.0)  # the subject is what does not happen: no run, no bag, in a second after it
    assert interp.poll() is None
    assert not bags.exists() or not any(bags.iterdir())


def test_sigint_mid_job_leaves_a_readable_bag(tmp_path: Path, procs: Procs, ros: Any) -> None:
    seen = heard_diagnostics(ros)
    bags = tmp_path / "bags"
    sim = procs.start(
        "sim_node", "-p", f"bag_dir:={bags}", "-p", "real_time:=true", "-p", "real_time_factor:=2.0"
    )
    procs.start("profile_node")
    procs.start("interp_node", "-p", "turns_per_layer:=50", "-p", "job_id:=cut")
    # mid-job: the sim node says its run is running with steps executed (the whole job
    # takes over a minute of simulated time)
    spin_until(ros, lambda: under_way(seen), 60, "the sim node's run under way", heard=lambda: seen[-5:])
    assert procs.stop(sim, signal.SIGINT) == 0
    bag_dir = only_bag(tmp_path)
    assert bag_closed(bag_dir)
    bag = rosbags_read(bag_dir)
    rows = timed_rows(bag)
    assert rows.shape[0] > 0
    # the simulation (paced at 2x real time) was cut well before the job's end;
    # the steps were sent no further than the look-ahead (and one step) ahead of it
    clock = [m.clock.sec + m.clock.nanosec * 1e-9 for _, m in bag["/clock"]]
    duration = json.loads(bag["/winder/profile_config"][0][1].data)["job_duration_s"]
    assert 0 < clock[-1] < duration / 2
    assert rows[-1, 0] * 1e-9 <= clock[-1] + 0.05 + 0.01
    values = final_report(bag)
    assert values["state"] == "incomplete"
    assert "Traceback" not in procs.log(sim)


def test_colcon_build_installs_runnable_executables(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """What `ros2 run <pkg> <exe>` does: ament index -> prefix/lib/pkg/exe."""
    repo = ROOT
    ws = tmp_path / "ws"
    r = subprocess.run(
        [
            str(BIN / "colcon"),
            "--log-base",
            str(ws / "log"),
            "build",
            "--base-paths",
            str(repo),
            "--build-base",
            str(ws / "build"),
            "--install-base",
            str(ws / "install"),
            # winder_interfaces (ament_cmake) against the venv's ROS wheels, as a ROS install
            # sourced would give it: the wheels' prefix, their python, no tests of its own
            "--cmake-args",
            f"-DCMAKE_PREFIX_PATH={VENV}",
            f"-DPython3_EXECUTABLE={BIN / 'python'}",
            "-DBUILD_TESTING=OFF",
        ],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=ws.parent,
        stdin=subprocess.DEVNULL,
        env={**os.environ, "AMENT_PREFIX_PATH": str(VENV)},
    )
    assert r.returncode == 0, r.stdout + r.stderr
    assert "6 packages finished" in r.stdout
    # the interfaces as colcon installed them: generated, with the action among them
    share = ws / "install" / "winder_interfaces" / "share" / "winder_interfaces"
    assert (share / "action" / "Wind.action").is_file() and (share / "msg" / "JobReport.msg").is_file()
    # the cell's data beside its launch file: what params_file:= and the viewers take
    share = ws / "install" / "winder_sim" / "share" / "winder_sim"
    for d, pattern in (("jobs", "*.yaml"), ("layouts", "winder_*")):
        want = sorted(f.name for f in (repo / d).glob(pattern))
        assert want and sorted(f.name for f in (share / d).iterdir()) == want, d
    assert (share / "launch" / "winder.launch.py").is_file()

    from ament_index_python.packages import get_package_prefix

    os.environ["AMENT_PREFIX_PATH"] = os.pathsep.join(
        str(ws / "install" / p)
        for p in ("winder", "winder_interp", "winder_profile", "winder_sim", "winder_bridge")
    )
    for pkg, exe in [
        ("winder_interp", "interp_node"),
        ("winder_profile", "profile_node"),
        ("winder_sim", "sim_node"),
        ("winder_bridge", "bridge_node"),
    ]:
        prefix = Path(get_package_prefix(pkg))
        path = prefix / "lib" / pkg / exe
        assert path.exists(), path
        env = {
            **procs.env,
            "PYTHONPATH": str(
                ws
                / "install"
                / "winder"
                / "lib"
                / f"python{sys.version_info.major}.{sys.version_info.minor}"
                / "site-packages"
            ),
        }
        p = popen([str(path)], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, cwd=tmp_path)
        started(ros, p, exe)
        assert p.poll() is None, p.stdout.read().decode() if p.stdout else ""
        p.send_signal(signal.SIGINT)
        out, _ = p.communicate(timeout=20)
        assert p.returncode == 0, out.decode()
        assert b"Traceback" not in out


def started(ros: Any, p: subprocess.Popen[bytes], name: str) -> None:
    """Until process ``p``'s node ``name`` is on the graph (it started), or ``p`` ended."""
    wait.spin_until(
        ros,
        lambda: p.poll() is not None or name in [n for n, _ in ros.get_node_names_and_namespaces()],
        60,
        f"the installed {name} on the graph",
        heard=ros.get_node_names_and_namespaces,
    )


def _launch(given: dict[str, str]) -> tuple[list[Any], list[dict[str, Any]]]:
    """launch/launch_ros cannot be installed here (they are no wheels), so the launch
    file runs against minimal stand-ins that record what it asks for: its
    declared arguments, and the nodes it makes for the arguments ``given``
    (its OpaqueFunction called with a context holding them, as launch does)."""
    import importlib.util
    import types

    made: list[dict[str, Any]] = []

    class Recorder:
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            self.args, self.kwargs = args, kwargs

    class NodeStandIn(Recorder):
        def __init__(self, **kwargs: Any) -> None:
            super().__init__(**kwargs)
            made.append(kwargs)

    fakes = {
        "launch": types.SimpleNamespace(LaunchDescription=Recorder),
        "launch.actions": types.SimpleNamespace(DeclareLaunchArgument=Recorder, OpaqueFunction=Recorder),
        "launch_ros.actions": types.SimpleNamespace(Node=NodeStandIn),
    }
    saved = {k: sys.modules.get(k) for k in fakes}
    sys.modules.update(fakes)  # type: ignore[arg-type]
    try:
        path = ROOT / "winder_sim" / "launch" / "winder.launch.py"
        spec = importlib.util.spec_from_file_location("winder_launch", path)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        desc = module.generate_launch_description()
        actions = desc.args[0]
        declared = [a for a in actions if a.kwargs.get("default_value") is not None]
        (opaque,) = [a for a in actions if "function" in a.kwargs]
        configurations = {a.args[0]: a.kwargs["default_value"] for a in declared}  # launch fills defaults in
        configurations.update(given)
        opaque.kwargs["function"](types.SimpleNamespace(launch_configurations=configurations))
    finally:
        for k, v in saved.items():
            if v is None:
                sys.modules.pop(k, None)
            else:
                sys.modules[k] = v
    return declared, made


def test_launch_file_takes_every_node_parameter_and_a_params_file() -> None:
    """The three executables, downstream first; one argument per parameter
    (stall_abort, which two nodes have, once), plus managed, use_sim_time,
    params_file and namespace; an argument left out is not passed (the
    params file's value or the node's default stands), one given is typed
    and goes to every node that has it, after the params file."""
    from winder.contract.params import INTERP_SPECS, OPERATION_SPECS, PROFILE_SPECS, SIM_SPECS

    declared, made = _launch({})
    names = [a.args[0] for a in declared]
    assert len(names) == len(set(names)), sorted(n for n in names if names.count(n) > 1)
    want = {*INTERP_SPECS, *PROFILE_SPECS, *OPERATION_SPECS, *SIM_SPECS}
    want |= {"managed", "use_sim_time", "params_file", "namespace"}
    assert set(names) == want
    assert {"feed_override", "lookahead", "stall_abort", "fork.J"} <= set(names)
    assert [(n["package"], n["executable"]) for n in made] == [
        ("winder_sim", "sim_node"),
        ("winder_profile", "profile_node"),
        ("winder_interp", "interp_node"),
    ]
    assert [n["parameters"] for n in made] == [[{}], [{}], [{}]]

    given = {
        "params_file": "jobs/stator_12.yaml",
        "namespace": "cell1",
        "turns_per_layer": "40",
        "fork.J": "2e-4",
        "stall_abort": "5",
        "feed_override": "0.5",
        "lookahead": "0.1",
        "managed": "true",
        "use_sim_time": "true",
    }
    _, made = _launch(given)
    sim, profile, interp = (n["parameters"] for n in made)
    common = {"managed": True, "use_sim_time": True}
    assert sim == ["jobs/stator_12.yaml", {**common, "fork.J": 2e-4, "stall_abort": 5.0}]
    assert profile == ["jobs/stator_12.yaml", {**common, "feed_override": 0.5, "lookahead": 0.1}]
    assert interp == ["jobs/stator_12.yaml", {**common, "turns_per_layer": 40, "stall_abort": 5.0}]
    assert {n["namespace"] for n in made} == {"cell1"}
    with pytest.raises(ValueError, match="lookahead"):
        _launch({"lookahead": "soon"})
