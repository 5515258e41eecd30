"""A line controller for a winder cell in a few lines of rclpy: send the cell
a ``Wind`` goal (winder_interfaces/action/Wind on ``winder/wind``), print its
progress, report how the run ended. Ctrl-C (SIGINT) or SIGTERM (a
supervisor's stop), even where the process was started with them ignored (a
shell's ``cmd &``), cancels the goal: the run is aborted, the axes braked to
rest, the bag closed; the controller waits for that and exits 128 + the
signal's number (130, 143).

    ROS_DOMAIN_ID=42 python docs/cell_controller.py [NAMESPACE] [TIMEOUT_S] [JOB_FILE]

JOB_FILE: a job file (as ``winder run`` reads one), sent as the goal's
``job``; none: the job set in the cell. Every wait is bounded (TIMEOUT_S,
default 600 s, for the whole run; 60 s to find the cell; 30 s for each answer
of the cell; 60 s for a canceled run to end): a timeout is one line and exit 2
(or 130/143 once stopped), and a run it gave up waiting on is canceled. Exit
status 0 if the run ended complete, 1 otherwise.
"""

import hashlib
import signal
import sys
import time
from pathlib import Path

import rclpy
from action_msgs.srv import CancelGoal
from rclpy.action import ActionClient
from rclpy.signals import SignalHandlerOptions

from winder_interfaces.action import Wind


def main() -> int:
    ns = (sys.argv[1] if len(sys.argv) > 1 else "").strip("/")
    timeout = float(sys.argv[2]) if len(sys.argv) > 2 else 600.0
    job = Path(sys.argv[3]).read_text() if len(sys.argv) > 3 else ""
    stop: list[int] = []  # the stop signal, once one came
    for sig in (signal.SIGINT, signal.SIGTERM):  # taken even if inherited ignored (a shell's `cmd &`)
        signal.signal(sig, lambda signum, _frame: stop.append(signum))
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)  # the signals are ours: they cancel the goal
    node = rclpy.create_node("line_controller")
    wind = ActionClient(node, Wind, f"/{ns}/winder/wind" if ns else "/winder/wind")
    t_end = time.monotonic() + timeout

    def spin_until(done, seconds: float, what: str, stoppable: bool = True) -> bool:
        """Spin until done() or (if stoppable) a stop signal: False after `seconds`."""
        deadline = time.monotonic() + seconds
        while not done() and not (stoppable and stop):
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
    if stop:  # nothing sent yet: nothing to cancel
        return 128 + stop[0]
    # the goal's hash: a job cut on its way (a NUL byte ends a ROS string) is refused, not wound
    goal = Wind.Goal(job=job, goal_sha256=hashlib.sha256(job.encode()).hexdigest())
    sent = wind.send_goal_async(goal, feedback_callback=on_feedback)
    # a goal sent is waited for even once stopped: a goal known can be canceled
    if not spin_until(sent.done, 30.0, "reply to the goal", stoppable=False):
        return 2
    goal = sent.result()
    ending = goal.get_result_async()
    in_time = spin_until(ending.done, max(t_end - time.monotonic(), 0.0), "end of the run")
    code = 128 + stop[0] if stop else 0 if in_time else 2  # stopped (130, 143), or gave up waiting (2)
    if not ending.done():  # then nobody waits on the run any more: it is canceled (aborted), its end awaited
        if stop:
            print(f"{signal.Signals(stop[0]).name}: canceling the goal", flush=True)
        answer = goal.cancel_goal_async()
        if not spin_until(answer.done, 30.0, "answer to the cancel", stoppable=False):
            return code
        if answer.result().return_code == CancelGoal.Response.ERROR_REJECTED:  # the cell's log says why
            print("cell_controller: the cell refused the cancel: its run goes on")
            return code
        if not spin_until(ending.done, 60.0, "end of the canceled run", stoppable=False):
            return code
    result = ending.result().result
    if not result.run_id:  # refused: the reason, in the words `winder ctl start` uses
        print(f"start refused: {result.message}")
        return code or 1
    part = f", part {result.part_id}" if result.part_id else ""  # its record in the part index (PARTS.md)
    print(f"run {result.run_id}: {result.report.state}, {result.message}, bag {result.bag_path}{part}")
    return code or (0 if result.success else 1)


if __name__ == "__main__":
    sys.exit(main())
