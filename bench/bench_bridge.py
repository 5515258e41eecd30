"""What the ros2_control bridge costs: CPU of bridge_node at 1 kHz, idle and
during a run (issue: under 5 % of a core at 1 kHz, near 0 idle).

The cell: bridge_node (rate 1000 Hz), the real profile and interp nodes, and
the ros2_control stand-in of the tests (test/ros2_control_standin.py: the
forward position controller, the joint state broadcaster at 100 Hz, mock
hardware). The bridge runs with following-error limits for the stand-in's
lag (fork 5 rad): this is about CPU, not the servo. CPU time (user + system, /proc/<pid>/stat; psutil is not
installed) over a window with no job (the broadcaster still publishing), then
over a window in the middle of a real-time run. The anchors, in the same
run and at the same time: bare rclpy processes publishing the same
std_msgs/Float64MultiArray (3 positions, prebuilt) at 1 kHz to a subscriber
(a third bare process), one from an rclpy timer on the steady clock (what
``winder.ros.timers.steady_timer`` does) and one from a thread that sleeps to
each tick (what the bridge does): their CPU is what rclpy and DDS cost for
the bare publishing; and a bare rclpy subscriber of the same joint_states
(what watching them costs at least, with an executor).

    .venv/bin/python bench/bench_bridge.py [--quick]   # --quick: 4 s windows, else 10 s
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from _common import domain, ros_env, table

from winder.procs import popen, stop_all
from winder.record.bag import bags_in

BIN = Path(sys.executable).parent
ROOT = Path(__file__).resolve().parents[1]
STANDIN = ROOT / "test" / "ros2_control_standin.py"
#: the anchors: 1 kHz publishing of a prebuilt 3-value Float64MultiArray, by an rclpy timer and by a thread
ANCHOR = """
import sys, threading, time
import rclpy
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64MultiArray
from sensor_msgs.msg import JointState
rclpy.init()
node = rclpy.create_node("anchor_" + sys.argv[1])
pub = node.create_publisher(Float64MultiArray, "anchor_" + sys.argv[1] + "/commands", 10)
raw = serialize_message(Float64MultiArray(data=[0.0, 0.0, 0.0]))
if sys.argv[1] == "states":
    node.create_subscription(JointState, "joint_states", lambda raw: None, 10, raw=True)
elif sys.argv[1] == "sink":  # the anchors' commands are delivered, as the bridge's are
    for name in ("timer", "thread"):
        node.create_subscription(Float64MultiArray, f"anchor_{name}/commands", lambda raw: None, 10, raw=True)
elif sys.argv[1] == "timer":
    node.create_timer(0.001, lambda: pub.publish(raw), clock=Clock(clock_type=ClockType.STEADY_TIME))
else:
    def loop():
        due = time.monotonic_ns()
        while True:
            due += 1_000_000
            wait = due - time.monotonic_ns()
            if wait > 0:
                time.sleep(wait / 1e9)
            pub.publish(raw)
    threading.Thread(target=loop, daemon=True).start()
rclpy.spin(node)
"""


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def window(procs: dict[str, subprocess.Popen[bytes]], seconds: float) -> dict[str, float]:
    """Each process' CPU over ``seconds`` of wall time, as a fraction of one core."""
    before = {name: cpu_seconds(p.pid) for name, p in procs.items()}
    t0 = time.monotonic()
    time.sleep(seconds)
    dt = time.monotonic() - t0
    return {name: (cpu_seconds(p.pid) - before[name]) / dt for name, p in procs.items()}


def final_status(bags: Path) -> dict[str, str]:
    """The bridge's last job status in the run's bag (rosbags; winder's reader takes a sim's bags)."""
    from rosbags.highlevel import AnyReader

    values: dict[str, str] = {}
    for bag in bags_in(bags):
        with AnyReader([bag]) as reader:
            conns = [c for c in reader.connections if c.topic == "/diagnostics"]
            for conn, _, raw in reader.messages(connections=conns):
                msg: Any = reader.deserialize(raw, conn.msgtype)
                for st in msg.status:
                    kv = {k.key: k.value for k in st.values}
                    if kv.get("role") == "consumer" and "commands_sent" in kv:
                        values = kv
    return values


def start(cmds: dict[str, list[str]], env: dict[str, str], log: Any) -> dict[str, subprocess.Popen[bytes]]:
    return {
        name: popen(
            cmd,
            env=env,
            stdout=log if name.startswith("bridge") else subprocess.DEVNULL,
            stderr=subprocess.STDOUT,
        )
        for name, cmd in cmds.items()
    }


def stop(procs: list[subprocess.Popen[bytes]]) -> None:
    stop_all(procs, signal.SIGINT, 10.0)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument(
        "--no-record", action="store_true", help="the bridge records no bag (what recording costs)"
    )
    ap.add_argument(
        "--interface",
        choices=("forward", "trajectory"),
        default="forward",
        help="forward: a command each ms to a ForwardCommandController (default); trajectory: a "
        "JointTrajectory of 1 ms points every 20 ms to a JointTrajectoryController",
    )
    args = ap.parse_args()
    quick = args.quick
    trajectory = args.interface == "trajectory"
    span = 4.0 if quick else 10.0
    work = Path(tempfile.mkdtemp(prefix="winder-bench-bridge-"))
    env = {**ros_env(domain()), "PYTHONUNBUFFERED": "1"}
    log = (work / "bridge.log").open("wb")
    # a job of one layer of 60 turns (15 s at 4096 steps/s) or two: longer than warm-up + window
    layers = 1 if quick else 2
    cell = {
        "bridge_node (1 kHz)": [
            str(BIN / "bridge_node"),
            "--ros-args",
            "-p",
            f"bag_dir:={work / 'bags'}",
            # the stand-in is a Python process on shared cores: limits for its lag, not a drive's
            *("-p", "max_following_error.fork:=5.0", "-p", "joint_state_timeout:=0.5"),
            *(("-p", "record:=false") if args.no_record else ()),
            *(
                ("-p", "interface:=trajectory", "-p", "controller:=joint_trajectory_controller")
                if trajectory
                else ()
            ),
        ],
        "ros2_control stand-in": [
            sys.executable,
            str(STANDIN),
            "--joints",
            "feed,fork,pole",
            "--rate",
            "100",
            *(("--interface", "trajectory") if trajectory else ()),
        ],
        "profile_node": [
            str(BIN / "profile_node"),
            *("--ros-args", "-p", "v_max:=4096.0"),
        ],
    }
    anchors = {
        "anchor: rclpy timer 1 kHz": [sys.executable, "-c", ANCHOR, "timer"],
        "anchor: thread 1 kHz": [sys.executable, "-c", ANCHOR, "thread"],
        "anchor: joint_states subscriber": [sys.executable, "-c", ANCHOR, "states"],
        "(the anchors' subscriber)": [sys.executable, "-c", ANCHOR, "sink"],
    }
    procs = start(cell, env, log)
    others: list[subprocess.Popen[bytes]] = []
    try:
        time.sleep(4.0)  # start-up and discovery
        idle = window(procs, span)
        job = ["-p", "turns_per_layer:=60", "-p", f"layers:={layers}", "-p", "poles:=1"]
        interp = popen(
            [str(BIN / "interp_node"), "--ros-args", *job],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        others.append(interp)
        t_end = time.monotonic() + 60
        while b"armed" not in (work / "bridge.log").read_bytes() and time.monotonic() < t_end:
            time.sleep(0.1)
        if b"armed" not in (work / "bridge.log").read_bytes():
            raise SystemExit("bench_bridge: the run did not start:\n" + (work / "bridge.log").read_text())
        time.sleep(1.0)
        run = window(procs, span)

        def ended() -> bool:
            if args.no_record:
                return b": complete," in (work / "bridge.log").read_bytes()
            # metadata.yaml is there from the run's first moment; it says closed at the end
            return any("winder_bag: closed" in m.read_text() for m in (work / "bags").glob("*/metadata.yaml"))

        while not ended() and time.monotonic() < t_end + 120:
            time.sleep(0.2)
        # the anchors, with the cell idle again (its stand-in still publishing joint states)
        extra = start(anchors, env, log)
        others += list(extra.values())
        time.sleep(4.0)
        bare = window(extra, span)
    finally:
        stop([*procs.values(), *others])
    timer, thread = bare["anchor: rclpy timer 1 kHz"], bare["anchor: thread 1 kHz"]
    states = bare["anchor: joint_states subscriber"]
    rows = [
        [name, f"{100 * idle[name]:.2f}", f"{100 * run[name]:.2f}", f"{run[name] / timer:.2f}"]
        for name in cell
    ] + [[name, "", f"{100 * bare[name]:.2f}", f"{bare[name] / timer:.2f}"] for name in anchors]
    print(
        f"CPU of each process, % of one core, over {span:g} s windows: the cell idle, the cell in a "
        "real-time run, then the anchors (the cell idle)"
    )
    print(table(["process", "idle %", "run %", "/ timer anchor"], rows))
    status = {} if args.no_record else final_status(work / "bags")
    sent = "trajectories (1 ms points, 20 ms apart)" if trajectory else "commands"
    print(
        f"bridge ({args.interface}): {status.get('commands_sent', '?')} {sent} in "
        f"{status.get('wall_time_s', '?')} s, "
        f"largest gap {status.get('max_command_gap_ms', '?')} ms, "
        f"late steps {status.get('late_steps', '?')}, "
        f"run state {status.get('state', '?')}"
    )
    share = run["bridge_node (1 kHz)"]
    print(
        f"target: bridge under 5 % of a core at 1 kHz: {100 * share:.2f} % "
        f"({share / timer:.2f} x the bare timer anchor; {share / (thread + states):.2f} x the floor: "
        f"bare thread + bare joint_states subscriber, {100 * (thread + states):.2f} %); "
        f"idle {100 * idle['bridge_node (1 kHz)']:.2f} % with joint_states at 100 Hz"
    )


if __name__ == "__main__":
    main()
