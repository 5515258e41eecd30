"""``winder ctl``: a running cell driven from the command line, without the
``ros2`` command (which the pip install lacks): start a run, read the cell's
state, a node's parameters and lifecycle, pause, resume, abort, override;
print a topic's messages (``echo``, :mod:`winder.ros.echo`) and an
interface's definition (``interface show``, :mod:`winder.ros.interface_text`).

Each is a client of the standard services and the cell's topics
(:mod:`winder.ros.ctl`), bounded by ``--timeout``; every error is one line
and the exit status of its class (:mod:`winder.cli.exits`): 2 for what the
user can fix (an unknown node or parameter, a bad value, a setting the node
refused, a transition the node's state does not have, a missing job file), 1
when the cell did not answer in time or refused the command, 3 and 1 for a
run followed with ``--wait`` that ended aborted or incomplete, 130 at Ctrl-C.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from pathlib import Path
from typing import Any

from winder.cli.exits import EXIT_ABORTED, EXIT_BAD_INPUT, EXIT_FAILED, EXIT_FAULTED, EXIT_OK
from winder.contract.run import FAULTS_KEY
from winder.contract.states import EventKind, JobState
from winder.errors import BadInputError

__all__ = ["register"]

#: seconds a command waits for the cell by default
TIMEOUT = "10"


def _timeout(args: argparse.Namespace) -> float:
    from winder.cli.common import CELL_SPECS

    return float(CELL_SPECS["timeout"].parse(args.timeout))


def check_node_name(name: str, namespace: str) -> str:
    from winder.contract.topics import check_node_name as check

    return check(name, namespace)


def _namespace(args: argparse.Namespace) -> str:
    from winder.contract.topics import check_namespace

    return check_namespace(args.namespace)


def _ros() -> Any:
    from winder.cli.common import ros_imports

    with ros_imports():
        from winder.ros import ctl
    return ctl


def _fail(args: argparse.Namespace, message: str, code: int) -> int:
    print(f"winder ctl {args.action}: {message}", file=sys.stderr)
    return code


def _guarded(args: argparse.Namespace, body: Any) -> int:
    """Run ``body(ctl)`` and map what it raises to one line and an exit
    status. Its session is closed when it returns: the process may then end
    without the interpreter's teardown (:func:`winder.cli.lifetime.leave_when_done`)."""
    from winder.cli.lifetime import leave_when_done

    ctl = _ros()
    try:
        return int(body(ctl))
    except ctl.UnansweredError as exc:
        return _fail(args, str(exc), EXIT_FAILED)
    except ctl.NoSuchNodeError as exc:
        return _fail(args, str(exc), EXIT_BAD_INPUT)
    except ctl.RefusedError as exc:
        return _fail(args, str(exc), getattr(args, "refused_code", EXIT_BAD_INPUT))
    except BadInputError as exc:  # a bad option, job file or setting; a bare ValueError is a bug
        return _fail(args, str(exc), EXIT_BAD_INPUT)
    finally:
        leave_when_done()


# -- pause, resume, abort, override ----------------------------------------------------------


def cmd_operate(args: argparse.Namespace) -> int:
    """One command to a running cell: EXIT_OK if it was done, EXIT_FAILED if the cell said no."""
    from winder.contract.params import OPERATION_SPECS

    ns = _namespace(args)
    timeout = _timeout(args)
    factor = OPERATION_SPECS["feed_override"].parse(args.value) if args.action == EventKind.OVERRIDE else 0.0

    def body(ctl: Any) -> int:
        with ctl.Session(timeout) as session:  # its answer printed before the session closes
            if args.action == EventKind.OVERRIDE:
                node = f"{ns}/profile_node"
                ok, message = ctl.set_parameter(node, "feed_override", factor, session=session)
            else:
                ok, message = ctl.trigger(f"{ns}/profile_node/{args.action}", session=session)
            if not ok:
                return _fail(args, message, EXIT_FAILED)
            print(message, flush=True)
        return EXIT_OK

    return _guarded(args, body)


def cmd_estop(args: argparse.Namespace) -> int:
    """The consumer's ``~/estop``: EXIT_OK if it stopped the drives, EXIT_FAILED if not."""
    ns = _namespace(args)
    timeout = _timeout(args)

    def body(ctl: Any) -> int:
        with ctl.Session(timeout) as session:
            ok, message = ctl.estop(session, ns)
            if not ok:
                return _fail(args, message, EXIT_FAILED)
            print(message, flush=True)
        return EXIT_OK

    return _guarded(args, body)


# -- start -------------------------------------------------------------------------------------


def run_values(args: argparse.Namespace) -> dict[str, Any]:
    """The values ``~/start_run`` is to set: the job file (its absolute path,
    checked here as the node will check it), each ``--set key=value``,
    checked against the interp node's setting table, and ``--operator`` and
    ``--wire-lot`` (the run's: its part records them)."""
    from winder.contract.jobfile import load_job_file
    from winder.contract.params import interp_setting
    from winder.contract.stream import RUN_FACTS

    values: dict[str, Any] = {}
    if args.job_file:
        path = Path(args.job_file).expanduser().absolute()  # the caller's working directory, not the node's
        load_job_file(path)  # JobFileError (a BadInputError): one line naming the file tried
        values["job_file"] = str(path)
    for item in args.set or ():
        key, value = interp_setting(item, "--set")
        if key == "job_file" and value:
            path = Path(value).expanduser().absolute()
            load_job_file(path)
            value = str(path)
        values[key] = value
    for name, spec in RUN_FACTS.items():
        given = getattr(args, name, None)
        if given is None:
            continue
        flag = "--" + name.replace("_", "-")
        if name in values:
            raise BadInputError(f"{flag} and --set {name}=... both given: give it one way")
        values[name] = spec.parse(given)  # SpecError: "operator='a\x07' is invalid: must be ..."
    return values


def start_code(reason: str) -> int:
    """The exit status of a refused start: the cell busy, not ready or not
    active is the cell's refusal (1); anything else is the settings' (2)."""
    if reason.startswith("job not started") or "start refused, the running job goes on" in reason:
        return EXIT_FAILED
    return EXIT_BAD_INPUT


def cmd_start(args: argparse.Namespace) -> int:
    """Set up and start a run in one call (the interp node's ``~/start_run``)."""
    ns = _namespace(args)
    timeout = _timeout(args)
    run_timeout = _run_timeout(args)

    def body(ctl: Any) -> int:
        values = run_values(args)  # checked before anything goes on the graph
        with ctl.Session(timeout) as session:
            stock = ctl.node_name("interp_node", ns)
            ctl.start_clients(session, stock)  # matched while the graph tells which node is the interp node
            # its winder/ready says when to ask again after "not ready"; with --wait, the run is followed
            view = ctl.watch_cell(session, ns, statuses=args.wait)
            interp = ctl.find_role(session, ns, "interp", "interp node (the publisher of winder/job)")
            if interp != stock:
                ctl.start_clients(session, interp)
            try:
                goal = ctl.start_run(session, interp, values, view)
            except ctl.RefusedError as exc:
                return _fail(args, str(exc), start_code(str(exc)))
            print(f"run {goal.run_id}", flush=True)
            print(f"  {goal.reply}", flush=True)
            if not args.wait:
                return EXIT_OK
            return wait_for_end(args, session, view, goal, run_timeout)

    return _guarded(args, body)


def _run_timeout(args: argparse.Namespace) -> float:
    from winder.cli.common import CELL_SPECS

    return float(CELL_SPECS["timeout"].parse(args.run_timeout))


#: a run's end states in the consumer's final report, and the exit status of each
END_CODES: dict[str, int] = {
    JobState.DONE: EXIT_OK,
    JobState.ABORTED: EXIT_ABORTED,
    JobState.INCOMPLETE: EXIT_FAILED,
}


#: action_msgs/GoalStatus' codes of a goal that ended, as ``ros2 action send_goal`` names them
GOAL_STATUS = {4: "SUCCEEDED", 5: "CANCELED", 6: "ABORTED"}


def result_text(result: Any, status: int) -> str:
    """A Wind goal's result as ``ros2 action send_goal`` prints it: its
    fields under ``Result:``, then the goal's end status."""
    from winder.ros.echo import message_yaml

    body = "".join(f"    {line}\n" for line in message_yaml(result, None).splitlines())
    return f"Result:\n{body}\nGoal finished with status: {GOAL_STATUS.get(status, f'UNKNOWN ({status})')}\n"


def wait_for_end(args: argparse.Namespace, session: Any, view: Any, goal: Any, run_timeout: float) -> int:
    """Follow the run of ``goal`` to its end: a line each time the
    consumer's status of it changes, then how it ended. Only the cell's own
    nodes are believed (``view`` holds what they said): the run ends with
    the goal's result (the Wind action's answer to this command's own
    request) or the final status of the cell's consumer, the node the graph
    shows in that part, never with a status that merely names it."""
    from winder.ros import ctl
    from winder.ros.ctl import one_line

    run_id = goal.run_id

    def status(role: str) -> dict[str, str]:
        """The values of ``role``'s job status of this run ({} until heard)."""
        st = view.statuses.get(role)
        return dict(st.values) if st is not None and st.values.get("run_id") == run_id else {}

    def ended(state: str, bag: str, faults: str = "") -> int:
        """How the run ended: the goal's typed result (waited for up to
        the session's timeout after the consumer's final status), who was
        not believed on the way, then one line."""
        session.renew()
        with contextlib.suppress(ctl.UnansweredError):
            session.until(goal.result.done, f"result of the goal of run {run_id}")
        if goal.result.done():
            answer = goal.result.result()
            print(result_text(answer.result, answer.status), end="", flush=True)
        else:
            print(f"  no result of the goal within {session.timeout:g} s (the run's report said it ended)")
        ignored = view.ignored()
        if ignored:
            print(f"  ignored, foreign  {ignored}", flush=True)
        print(f"run {run_id}: {state}" + (f", bag {bag}" if bag else ""), flush=True)
        if state not in (JobState.DONE, JobState.ABORTED):
            return _fail(args, f"run {run_id} ended {state}", END_CODES[state])
        if not faults and goal.result.done():
            extra = goal.result.result().result.report.extra
            faults = next((kv.value for kv in extra if kv.key == FAULTS_KEY), "")
        if faults:  # every step executed, but the axes did not do what was commanded: as winder run
            return _fail(args, f"run {run_id} ended {state} with faults: {one_line(faults)}", EXIT_FAULTED)
        if state != JobState.DONE:
            return _fail(args, f"run {run_id} ended {state}", END_CODES[state])
        return EXIT_OK

    end = time.monotonic() + run_timeout
    heard = time.monotonic()  # when the cell last said anything of the run
    last_line = ""
    given_up = 0.0  # when the interp node gave the run up (a consumer that died sends no report)
    seen = view.changed
    while True:
        session.spin(0.1)
        now = time.monotonic()
        if view.changed != seen:
            seen = view.changed
            heard = now
        mine = status("consumer")
        if mine:
            line = (
                f"  {mine.get('state', '-'):<10} steps {mine.get('steps_done', '?')} of "
                f"{mine.get('steps_total', '?')}  ({100 * float(mine.get('progress') or 0):.1f} %)"
            )
            if line != last_line:
                print(line, flush=True)
                last_line = line
            if mine.get("state") in END_CODES:
                return ended(mine["state"], mine.get("bag", ""), mine.get(FAULTS_KEY, ""))
        if goal.result.done():
            result = goal.result.result().result
            if result.report.state in END_CODES:
                return ended(result.report.state, result.bag_path)
            return _fail(
                args,
                f"run {run_id}: {one_line(result.message) or 'the goal ended with no report'}",
                EXIT_FAILED,
            )
        theirs = status("interp")
        if theirs.get("state") in (JobState.INCOMPLETE, JobState.ABORTED) and not given_up:
            given_up = now
        if given_up and now - given_up > 5.0:
            return _fail(
                args,
                f"run {run_id}: the interp node says {theirs.get('state')}, the consumer sent no "
                "final report (is it still running?)",
                EXIT_FAILED,
            )
        if now - heard > session.timeout:
            return _fail(
                args,
                f"run {run_id}: nothing heard from the cell for {session.timeout:g} s (its statuses on "
                "/diagnostics, winder/state): did a node stop?",
                EXIT_FAILED,
            )
        if now > end:
            return _fail(
                args,
                f"run {run_id} did not end within {run_timeout:g} s (--run-timeout); it goes on",
                EXIT_FAILED,
            )


# -- state -------------------------------------------------------------------------------------


def _ago(view: Any, sent: int, now_ns: int) -> str:
    return f"{view.age(sent, now_ns):.1f} s ago"


def state_lines(view: Any, now_ns: int | None = None) -> list[str]:
    """The cell's state as a few lines: the cell, the start handshake, a
    line for each role (its node's job status, or which node was not heard
    from and why); each with how long ago its node said it (at ``now_ns``,
    wall clock), a node that has left the graph shown as gone, one whose
    once-a-second messages are overdue as silent, a status that does not
    show the cell as its state does with why (:meth:`CellView.behind`:
    the query heard nothing newer within its bound); then what was not
    believed, by sender."""
    from winder.contract.topics import ROLES
    from winder.contract.trust import ROLE_NAMES

    now_ns = time.time_ns() if now_ns is None else now_ns
    s = view.state
    ns = view.namespace or "/"
    lines = []
    if s:
        where = _where(s)
        run = f"run {s['run_id']} (job {s.get('job_id') or '-'})" if s.get("run_id") else "no run yet"
        sim = f"  sim {float(s['sim_time_s']):.3f} s" if s.get("sim_time_s") and s.get("run_id") else ""
        when = _ago(view, view.state_ns, now_ns)
        if view.gone(view.state_by):
            when += f"; {view.state_by}, which said it, has left the graph"
        lines.append(
            f"cell {ns}  {s.get('state', '-')}  {run}" + (f"  {where}" if where else "") + f"{sim}  ({when})"
        )
    elif view.holders.get("consumer"):
        lines.append(f"cell {ns}  (no winder/state heard from {', '.join(sorted(view.holders['consumer']))})")
    else:
        lines.append(f"cell {ns}  (no winder/state heard: no consumer on the graph)")
    said = []
    for role, value in sorted(view.ready.items()):
        sent = view.ready_ns.get(role, 0)
        if view.ready_gone(role):
            said.append(f"{role} gone (said {value} {_ago(view, sent, now_ns)})")
        elif view.silent(sent, now_ns):
            said.append(f"{role} {value} ({_ago(view, sent, now_ns)}: silent)")
        else:
            said.append(f"{role} {value} ({_ago(view, sent, now_ns)})")
    lines.append(f"  ready     {', '.join(said) or '-'}")
    for role in ROLES:
        st = view.statuses.get(role)
        held = sorted(view.holders.get(role, ()))
        if st is None:
            if len(held) > 1:
                lines.append(
                    f"  no job status taken from the {role}: {len(held)} nodes play its part "
                    f"({', '.join(held)}), none of them the cell's alone"
                )
            elif held:
                lines.append(f"  no job status heard from the {role} {held[0]} (on the graph; held up?)")
            else:
                lines.append(
                    f"  no {role} on the graph: no job status heard from the "
                    f"{ROLE_NAMES[role]} (gone, not started, or held up)"
                )
            continue
        v = st.values
        node = st.name.split(":", 1)[0]
        total = v.get("steps_total") or "0"
        steps = ""
        if total != "0":
            share = 100 * float(v.get("progress") or 0)
            steps = f"  steps {v.get('steps_done', '0')}/{total} ({share:.1f} %)"
        sim = f"  sim {float(v['sim_time_s']):.3f} s" if v.get("sim_time_s") and v.get("run_id") else ""
        state = v.get("state", "-")
        when = _ago(view, st.sent_ns, now_ns)
        behind = view.behind(role)
        if view.gone(st.node):
            when = f"left the graph; it said {state} {when}"
            state = "gone"
        elif view.silent(st.sent_ns, now_ns):
            when += ": silent"
        if behind and state != "gone":
            when += f"; {behind}: nothing newer came"
        lines.append(f"  {node:<22} {role:<9} {state:<10} {v.get('run_id') or '-'}{steps}{sim}  ({when})")
    ignored = view.ignored()
    if ignored:
        lines.append(f"  ignored, foreign  {ignored}")
    return lines


def _where(state: dict[str, str]) -> str:
    """Coil, layer and turn of a run's state ("" before any run)."""
    if not state.get("run_id"):
        return ""
    return " ".join(f"{k} {state[k]}" for k in ("coil", "layer", "turn") if state.get(k))


def change_line(view: Any) -> str:
    """One line of what ``--watch`` prints on a change."""
    s = view.state
    roles = view.roles()
    c = roles["consumer"].values if "consumer" in roles else {}
    where = _where(s)
    progress = ""
    if c.get("steps_total") not in (None, "", "0"):
        progress = (
            f"  steps {c.get('steps_done')}/{c['steps_total']} ({100 * float(c.get('progress') or 0):.1f} %)"
        )
    ready = ", ".join(f"{k} {v}" for k, v in sorted(view.ready.items()))
    run = s.get("run_id") or c.get("run_id") or "-"
    now_ns = time.time_ns()
    gone = sorted({st.node for st in view.statuses.values() if view.gone(st.node)})
    silent = sorted(
        {
            st.node
            for st in view.statuses.values()
            if not view.gone(st.node) and view.silent(st.sent_ns, now_ns)
        }
    )
    foreign = view.peers.intruders.senders() if view.peers is not None else []
    return (
        f"{s.get('state', '-'):<9} {run}"
        + (f"  {where}" if where else "")
        + progress
        + (f"  ready: {ready}" if ready else "")
        + (f"  gone: {', '.join(gone)}" if gone else "")
        + (f"  silent: {', '.join(silent)}" if silent else "")
        + (f"  ignored, foreign: {', '.join(foreign)}" if foreign else "")
    )


def cmd_state(args: argparse.Namespace) -> int:
    """Print the cell's state; with ``--watch`` a line on every change until Ctrl-C."""
    ns = _namespace(args)
    timeout = _timeout(args)

    def body(ctl: Any) -> int:
        with ctl.Session(timeout) as session:
            view = ctl.cell_state(session, ns)
            for line in state_lines(view):
                print(line, flush=args.watch)
            if not args.watch:
                return EXIT_OK
            last = ""
            for _ in ctl.follow(session, view):
                line = change_line(view)
                if line != last:
                    print(f"{time.strftime('%H:%M:%S')}  {line}", flush=True)
                    last = line
            return EXIT_OK  # not reached: Ctrl-C ends it

    return _guarded(args, body)


# -- param -------------------------------------------------------------------------------------


def _job_file_value(name: str, value: str) -> str:
    """A job_file given on the command line: absolute, against the caller's
    working directory (the node would read a relative one from its own)."""
    if name == "job_file" and value and not Path(value).expanduser().is_absolute():
        return str(Path(value).expanduser().absolute())
    return value


def cmd_param(args: argparse.Namespace) -> int:
    """Get, set or list a node's parameters through its parameter services."""
    ns = _namespace(args)
    timeout = _timeout(args)

    def body(ctl: Any) -> int:
        node = check_node_name(args.node, ns)  # as ROS takes it, or one line (exit 2)
        with ctl.Session(timeout) as session:
            ctl.parameter_clients(session, node)  # matched while the graph fills
            session.find_node(node)
            if args.verb == "get":
                print(ctl.get_parameter(session, node, args.name))
            elif args.verb == "list":
                rows = ctl.list_parameters(session, node)
                wide = max((len(n) for n, _ in rows), default=0)
                for name, value in rows:
                    print(f"{name:<{wide}}  {value}")
            else:
                text = _job_file_value(args.name, args.value)
                values = ctl.set_parameters(session, node, {args.name: text})
                print(f"{node}: {args.name} = {ctl.parameter_text_py(values[args.name])}")
        return EXIT_OK

    args.action = f"param {args.verb}"
    return _guarded(args, body)


# -- lifecycle ---------------------------------------------------------------------------------


def cmd_lifecycle(args: argparse.Namespace) -> int:
    """A lifecycle transition of a node, or its state (``get``)."""
    ns = _namespace(args)
    timeout = _timeout(args)
    args.action = f"lifecycle {args.transition}"
    args.refused_code = EXIT_FAILED  # a transition the node tried and refused: the cell said no

    def body(ctl: Any) -> int:
        node = check_node_name(args.node, ns)  # as ROS takes it, or one line (exit 2)
        with ctl.Session(timeout) as session:
            ctl.lifecycle_clients(session, node)  # matched while the graph fills
            session.find_node(node)
            if args.transition == "get":
                print(f"{node}: {ctl.lifecycle_state(session, node)}")
                return EXIT_OK
            before, after = ctl.lifecycle_transition(session, node, args.transition)
            print(f"{node}: {args.transition}: {before} -> {after}")
        return EXIT_OK

    return _guarded(args, body)


# -- echo, interface show ----------------------------------------------------------------------


def cmd_echo(args: argparse.Namespace) -> int:
    """A topic's messages as ``ros2 topic echo`` prints them (:mod:`winder.ros.echo`)."""
    ns = _namespace(args)
    timeout = _timeout(args)

    def body(ctl: Any) -> int:
        from winder.ros.echo import echo, topic_name

        full = topic_name(args.topic, ns)  # as rcl takes it, or one line (exit 2)
        with ctl.Session(timeout) as session:

            def write(text: str) -> None:
                sys.stdout.write(text)
                sys.stdout.flush()

            echo(
                session,
                full,
                once=args.once,
                truncate=None if args.full_length else args.truncate,
                write=write,
            )
        return EXIT_OK

    return _guarded(args, body)


def cmd_interface(args: argparse.Namespace) -> int:
    """An interface's definition as ``ros2 interface show`` prints it (:mod:`winder.ros.interface_text`)."""
    from winder.ros.interface_text import interface_lines

    args.action = "interface show"
    comments = "all" if args.all_comments else "none" if args.no_comments else "top"
    try:
        lines = interface_lines(args.type, comments=comments)
    except BadInputError as exc:
        return _fail(args, str(exc), EXIT_BAD_INPUT)
    print("\n".join(lines))
    return EXIT_OK


# -- the parser --------------------------------------------------------------------------------


def _common(p: argparse.ArgumentParser, timeout: str = TIMEOUT) -> None:
    p.add_argument("--namespace", default="", help="ROS namespace of the cell (/name[/name...])")
    p.add_argument(
        "--timeout",
        default=timeout,
        metavar="S",
        help=f"seconds to wait for the cell (the node, its service, its reply; default {timeout})",
    )


def register(sub: argparse._SubParsersAction[Any]) -> None:
    """Add ``ctl`` and its commands to the ``winder`` subcommands."""
    ctl = sub.add_parser(
        "ctl",
        help="drive a running cell: start, state, param, lifecycle, pause, resume, abort, estop, override X, "
        "echo, interface show",
        description="Commands to a running cell on this ROS_DOMAIN_ID, through the standard ROS 2 "
        "services and the cell's topics (what ros2 service call, ros2 param, ros2 lifecycle, ros2 topic "
        "echo and ros2 interface show do, "
        "on the pip install). Each waits at most --timeout seconds and names what it waited for.",
    )
    from winder.contract.params import OPERATION_SPECS

    factors = OPERATION_SPECS["feed_override"].range_text()  # OVERRIDE_RANGE, winder.motion.timeline
    verbs = ctl.add_subparsers(dest="action", metavar="ACTION", parser_class=type(ctl))
    verbs.required = True
    for action, text in (
        ("pause", "brake to rest (feed hold)"),
        ("resume", "go on after a pause, or a programmed stop that waits for a call"),
        ("abort", "brake to rest and end the run"),
        ("override", f"scale v_max by X in {factors} from now on (the profile node's feed_override)"),
    ):
        p = verbs.add_parser(action, help=text, description=text)
        if action == "override":
            p.add_argument("value", metavar="X", help=f"the override factor, in {factors}")
        _common(p)
        p.set_defaults(func=cmd_operate)

    text = (
        "emergency stop: the drives' quick stop, then disable (the consumer's ~/estop); the run "
        'closes incomplete with the reason "emergency stop"'
    )
    p = verbs.add_parser("estop", help=text, description=text)
    _common(p)
    p.set_defaults(func=cmd_estop)

    p = verbs.add_parser(
        "start",
        help="set up and start a run in one call (the interp node's ~/start_run); prints the run id",
        description="Start a run on a running cell: the job file's job and ramp, and the values given "
        "with --set, are set on the interp node all together or not at all, and the run starts with "
        "them. A relative JOB_FILE is taken from this command's working directory (its absolute path "
        "is sent; the interp node must be able to read it there). Asks again while the cell says it "
        "is not ready, up to --timeout.",
    )
    p.add_argument("job_file", nargs="?", metavar="JOB_FILE", help="a job file (see jobs/)")
    p.add_argument(
        "--set",
        action="append",
        metavar="KEY=VALUE",
        help="an interp node setting for this run (turns_per_layer=40, ramp.profile=trapezoid, ...); "
        "repeatable; wins over the job file's value",
    )
    from winder.contract.stream import RUN_FACTS

    for name, spec in RUN_FACTS.items():  # --set operator=NAME too
        p.add_argument("--" + name.replace("_", "-"), default=None, metavar="TEXT", help=spec.help())
    p.add_argument("--wait", action="store_true", help="follow the run and print how it ended")
    p.add_argument(
        "--run-timeout",
        default="3600",
        metavar="S",
        help="with --wait: give up following after S seconds (default 3600; the run goes on)",
    )
    _common(p)
    p.set_defaults(func=cmd_start)

    p = verbs.add_parser(
        "state",
        help="print the cell's state: winder/state, the start handshake, each node's job status",
    )
    p.add_argument("--watch", action="store_true", help="then print a line on every change, until Ctrl-C")
    _common(p)
    p.set_defaults(func=cmd_state)

    p = verbs.add_parser("param", help="get, set or list a node's parameters (ros2 param)")
    kinds = p.add_subparsers(dest="verb", metavar="VERB", parser_class=type(p))
    kinds.required = True
    q = kinds.add_parser("get", help="print a parameter's value")
    q.add_argument("node", metavar="NODE", help="node name (in --namespace), or its full name /ns/name")
    q.add_argument("name", metavar="NAME")
    _common(q)
    q = kinds.add_parser(
        "set",
        help="set a parameter (read as a parameters file reads it, made the declared type); "
        "a relative job_file is taken from this command's working directory",
    )
    q.add_argument("node", metavar="NODE", help="node name (in --namespace), or its full name /ns/name")
    q.add_argument("name", metavar="NAME")
    q.add_argument("value", metavar="VALUE")
    _common(q)
    q = kinds.add_parser("list", help="every parameter of a node, with its value")
    q.add_argument("node", metavar="NODE", help="node name (in --namespace), or its full name /ns/name")
    _common(q)
    p.set_defaults(func=cmd_param)

    from winder.ros.echo import TRUNCATE

    p = verbs.add_parser(
        "echo",
        help="print a topic's messages as ros2 topic echo does (field: value blocks and ---)",
        description="Print the messages of TOPIC (any topic on the graph; its type is the one the graph "
        "shows) as ros2 topic echo prints them. A topic of the cell is read with the cell's own QoS "
        "(a latched one, winder/report or winder/state, gives its last message at once); any other "
        "with its publishers'. Follows until Ctrl-C; --once ends after the first message.",
    )
    p.add_argument("topic", metavar="TOPIC", help="/full/name, or a name in --namespace (winder/report)")
    p.add_argument("--once", action="store_true", help="print the first message and end (exit 1 if none "
                   "came within --timeout)")  # fmt: skip
    p.add_argument(
        "--truncate",
        type=int,
        default=TRUNCATE,
        metavar="N",
        help=f"cut strings and arrays after N characters or items (default {TRUNCATE}, as ros2 topic echo)",
    )
    p.add_argument("--full-length", action="store_true", help="print strings and arrays in full")
    _common(p)
    p.set_defaults(func=cmd_echo)

    p = verbs.add_parser("interface", help="print an interface's definition (ros2 interface show)")
    kinds = p.add_subparsers(dest="verb", metavar="VERB", parser_class=type(p))
    kinds.required = True
    q = kinds.add_parser(
        "show",
        help="an interface's definition, nested types expanded (winder_interfaces/msg/CellState)",
        description="Print the definition of TYPE (PACKAGE/msg|srv|action/NAME) as ros2 interface show "
        "does: the installed file, each nested message type's fields below its field, a tab deeper.",
    )
    q.add_argument("type", metavar="TYPE", help="PACKAGE/KIND/NAME, e.g. winder_interfaces/action/Wind")
    which = q.add_mutually_exclusive_group()
    which.add_argument("--all-comments", action="store_true", help="the nested types' comments too")
    which.add_argument("--no-comments", action="store_true", help="no comments at all")
    q.set_defaults(func=cmd_interface)

    p = verbs.add_parser("lifecycle", help="a node's lifecycle transition, or its state (ros2 lifecycle)")
    p.add_argument("node", metavar="NODE", help="node name (in --namespace), or its full name /ns/name")
    p.add_argument(
        "transition", choices=("configure", "activate", "deactivate", "cleanup", "shutdown", "get")
    )
    _common(p)
    p.set_defaults(func=cmd_lifecycle)
