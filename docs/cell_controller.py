"""A line controller for a winder cell in a few lines of rclpy: send the cell
a ``Wind`` goal (winder_interfaces/action/Wind on ``winder/wind``), print its
progress, report how the run ended. Ctrl-C cancels the goal: the run is
aborted, the axes braked to rest, the bag closed.

    ROS_DOMAIN_ID=42 python docs/cell_controller.py [NAMESPACE] [TIMEOUT_S] [JOB_FILE]

JOB_FILE: a job file (as ``winder run`` reads one), sent as the goal's
``job``; none: the job set in the cell. Every wait is bounded (TIMEOUT_S,
default 600 s, for the whole run; 60 s to find the cell): a timeout is one
line and exit 2, and a run it gave up waiting on is canceled. Exit status 0 if the run ended complete, 1 otherwise.
"""

import sys
import time
from pathlib import Path

import rclpy
from rclpy.action import ActionClient
from rclpy.signals import SignalHandlerOptions
from winder_interfaces.action import Wind


def main() -> int:
    ns = (sys.argv[1] if len(sys.argv) > 1 else "").strip("/")
    timeout = float(sys.argv[2]) if len(sys.argv) > 2 else 600.0
    job = Path(sys.argv[3]).read_text() if len(sys.argv) > 3 else ""
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)  # Ctrl-C is ours: it cancels the goal
    node = rclpy.create_node("line_controller")
    wind = ActionClient(node, Wind, f"/{ns}/winder/wind" if ns else "/winder/wind")
    t_end = time.monotonic() + timeout

    def spin_until(done, seconds: float, what: str) -> bool:
        deadline = time.monotonic() + seconds
        while not done():
            if time.monotonic() > deadline:
                print(f"cell_controller: no {what} within {seconds:.0f} s")
                return False
            rclpy.spin_once(node, timeout_sec=0.1)
        return True

    shown = {"run_id": "", "coil": 0}

    def on_feedback(msg) -> None:  # twice a second, and at each state
        f = msg.feedback
        if f.run_id and not shown["run_id"]:
            shown["run_id"] = f.run_id
            print(f"started run {f.run_id} ({f.steps_total} steps)", flush=True)
        if f.coil != shown["coil"]:  # one line a coil
            shown["coil"] = f.coil
            print(f"  coil {f.coil}: {f.state}, {f.steps_done}/{f.steps_total} steps", flush=True)

    if not spin_until(wind.server_is_ready, min(60.0, timeout), "winder/wind action server"):
        return 2
    sent = wind.send_goal_async(Wind.Goal(job=job), feedback_callback=on_feedback)
    if not spin_until(sent.done, 30.0, "reply to the goal"):
        return 2
    ending = sent.result().get_result_async()
    try:
        if not spin_until(ending.done, max(t_end - time.monotonic(), 0.0), "end of the run"):
            sent.result().cancel_goal_async()  # nobody waits on the run any more: it is aborted
            spin_until(ending.done, 30.0, "end of the canceled run")
            return 2
    except KeyboardInterrupt:  # Ctrl-C: the run is aborted, the goal ends canceled
        sent.result().cancel_goal_async()
        if not spin_until(ending.done, 60.0, "end of the canceled run"):
            return 2
    result = ending.result().result
    if not result.run_id:  # refused: the reason, in the words `winder ctl start` uses
        print(f"start refused: {result.message}")
        return 1
    print(f"run {result.run_id}: {result.report.state}, {result.message}, bag {result.bag_path}")
    return 0 if result.success else 1


if __name__ == "__main__":
    sys.exit(main())
