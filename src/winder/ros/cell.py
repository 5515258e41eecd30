"""Run the whole winding cell: the three node executables as separate processes
(what ``ros2 launch winder_sim winder.launch.py`` does on a ROS install), a
progress bar while the job runs, and a summary at the end.

Used by ``winder run``; the nodes' logs go to a file that is shown on failure.
"""

from __future__ import annotations

import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

NODES = {"interp": "interp_node", "profile": "profile_node", "sim": "sim_node"}


@dataclass
class CellResult:
    ok: bool
    summary: dict[str, str] = field(default_factory=dict)
    message: str = ""
    log_dir: Path | None = None


def find_executable(name: str) -> str:
    """The node executable next to this Python (the venv's bin/), else on PATH."""
    here = Path(sys.executable).parent / name
    if here.exists():
        return str(here)
    found = shutil.which(name)
    if found is None:
        raise FileNotFoundError(f"node executable {name!r} not found next to {sys.executable} or on PATH")
    return found


def ros_args(params: dict[str, Any], namespace: str) -> list[str]:
    args = ["--ros-args"]
    if namespace:
        args += ["-r", f"__ns:={namespace}"]
    for k, v in params.items():
        if isinstance(v, bool):
            text = "true" if v else "false"
        elif isinstance(v, str):
            text = v if v else "''"
        else:
            text = repr(v)
        args += ["-p", f"{k}:={text}"]
    return args


def run_cell(
    params: dict[str, dict[str, Any]],
    *,
    namespace: str = "",
    domain: int | None = None,
    timeout: float = 3600.0,
    progress: Any = None,
) -> CellResult:
    """Start the three nodes with ``params[node]`` parameters, wait for the sim
    node to report the job done, stop them with SIGINT, return the summary.
    The nodes' output goes to ``result.log_dir``, removed after a clean run."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import ExternalShutdownException
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_srvs.srv import Trigger

    env = dict(os.environ)
    if domain is None:
        domain = (
            int(env["ROS_DOMAIN_ID"]) if env.get("ROS_DOMAIN_ID", "").isdigit() else random.randint(100, 199)
        )
    env["ROS_DOMAIN_ID"] = str(domain)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    env["PYTHONUNBUFFERED"] = "1"
    log_dir = Path(tempfile.mkdtemp(prefix="winder-cell-"))
    procs: dict[str, subprocess.Popen[bytes]] = {}
    saved = {k: os.environ.get(k) for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")}
    os.environ["ROS_DOMAIN_ID"] = env["ROS_DOMAIN_ID"]
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = env["ROS_AUTOMATIC_DISCOVERY_RANGE"]
    rclpy.init(args=[])
    node = rclpy.create_node("winder_cell", namespace=namespace or "/")
    state: dict[str, Any] = {
        "summary": None,
        "progress": 0.0,
        "errors": [],
        "heard_sim": False,
        "job_seen": False,
    }

    ns = namespace.strip("/")
    sim_status = f"{ns}/sim_node: job" if ns else "sim_node: job"
    interp_status = f"{ns}/interp_node: job" if ns else "interp_node: job"

    def on_diag(msg: DiagnosticArray) -> None:
        for st in msg.status:
            values = {kv.key: kv.value for kv in st.values}
            if st.name == sim_status:
                state["heard_sim"] = True
            if st.name == interp_status and values.get("state") in ("sending", "sent"):
                state["job_seen"] = True  # the start request got through
            if st.name == sim_status and values.get("job_id"):
                state["progress"] = float(values.get("progress", 0.0))
                state["sim_time"] = values.get("sim_time_s", "0")
                if values.get("state") in ("done", "incomplete"):
                    state["summary"] = values
                    state["message"] = st.message
            elif st.level == b"\x02" and st.name.startswith(ns) and st.message not in state["errors"]:
                state["errors"].append(f"{st.name}: {st.message}")

    node.create_subscription(
        DiagnosticArray,
        "/diagnostics",
        on_diag,
        QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE),
    )
    result = CellResult(False, log_dir=log_dir)
    try:
        # the sim node first: the others wait for their readers, so the job starts
        # only when the whole chain is connected
        for key in ("sim", "profile", "interp"):
            exe = find_executable(NODES[key])
            log = open(log_dir / f"{NODES[key]}.log", "wb")  # noqa: SIM115 - closed with the process
            node_params = dict(params.get(key, {}))
            if key == "interp":
                node_params["autostart"] = False  # started below, once we listen
            procs[key] = subprocess.Popen(
                [exe, *ros_args(node_params, namespace)],
                env=env,
                stdout=log,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
            )
        # start the job only when this process hears the sim node's diagnostics
        # and the interp node's start service is up: no report can be missed
        start = node.create_client(Trigger, f"{namespace.rstrip('/')}/interp_node/start")
        t_end = time.monotonic() + timeout
        started: Any = None
        asked = 0.0
        accepted = False
        while state["summary"] is None:
            accepted = accepted or state["job_seen"]
            if not accepted and start.service_is_ready() and state["heard_sim"]:
                if started is None or (not started.done() and time.monotonic() - asked > 5.0):
                    # a DDS service reply can be lost while its topic is still
                    # matching: ask again (a job already started is no error)
                    if started is not None:
                        start.remove_pending_request(started)
                    started, asked = start.call_async(Trigger.Request()), time.monotonic()
                elif started.done():
                    reply = started.result()
                    if reply is not None and (reply.success or "still being sent" in reply.message):
                        accepted = True
                    else:
                        result.message = f"job refused: {reply.message if reply else 'no reply'}"
                        break

            rclpy.spin_once(node, timeout_sec=0.1)
            if progress is not None:
                progress(state["progress"], state.get("sim_time", "0"))
            dead = [k for k, p in procs.items() if p.poll() is not None]
            if dead:
                result.message = f"{NODES[dead[0]]} exited with status {procs[dead[0]].returncode}"
                break
            if time.monotonic() > t_end:
                result.message = f"job did not finish within {timeout:g} s"
                break
        if state["summary"] is not None:
            result.summary = state["summary"]
            result.ok = state["summary"].get("state") == "done"
            result.message = state.get("message", "")
        if state["errors"] and not result.message:
            result.message = state["errors"][0]
    except ExternalShutdownException:
        raise KeyboardInterrupt from None  # Ctrl-C: the caller reports it
    finally:
        for p in procs.values():
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        for p in procs.values():
            try:
                p.wait(timeout=15)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        node.destroy_node()
        rclpy.try_shutdown()
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    if result.ok and not state["errors"] and not int(result.summary.get("errors", "0")):
        # a clean run's logs say nothing the summary does not: leave no litter in /tmp
        shutil.rmtree(log_dir, ignore_errors=True)
        result.log_dir = None
    return result
