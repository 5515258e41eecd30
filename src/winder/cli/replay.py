"""``winder play`` and ``winder resim``: recorded jobs back onto a ROS graph,
and through another motor. Registered into the ``winder`` parser
by :func:`register`; user errors are UserErrors (:mod:`winder.errors`'s BadInputError: one line,
exit status 2).
"""

from __future__ import annotations

import argparse
import math
import sys
from typing import Any

from winder.cli.common import UserError
from winder.cli.exits import EXIT_FAILED, EXIT_OK

__all__ = ["register"]

#: seconds ``winder play`` waits by default for the readers on the graph to match its publishers
WAIT_DEFAULT = 5.0


def _number(name: str, text: str, low: float, high: float, *, low_open: bool = False) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    ok = math.isfinite(value) and (value > low if low_open else value >= low) and value <= high
    if not ok:
        bound = f"({low:g}" if low_open else f"[{low:g}"
        raise UserError(f"{name}={text!r} is invalid: must be a number in {bound}, {high:g}]")
    return value


def cmd_play(args: argparse.Namespace) -> int:
    """Publish a recording's topics onto the graph (see winder.ros.player)."""
    from winder.record.replay import plan_play

    rate = _number("rate", args.rate, 0.001, 1e6)
    offset = _number("start_offset", args.start_offset, 0.0, 1e7)
    delay = _number("delay", args.delay, 0.0, 3600.0)
    # by default a bounded wait for the readers already on the graph (rosbag2 #109); given, it
    # also waits for a first reader to come; --no-wait publishes at once, as ros2 bag play does
    given = args.wait_for_subscribers is not None
    if given and args.no_wait:
        raise UserError("--no-wait and --wait-for-subscribers exclude each other: give one")
    wait = 0.0 if args.no_wait else WAIT_DEFAULT
    if given:
        wait = _number("wait_for_subscribers", args.wait_for_subscribers, 0.0, 3600.0)
    from winder.cli.view import foxglove_port

    fox_port = foxglove_port(args)
    try:
        plan = plan_play(
            args.bag,
            start_offset=offset,
            clock=args.clock,
            topics=args.topics or (),
            exclude=args.exclude or (),
            namespace=args.namespace,
        )
    except OSError as exc:
        raise UserError(f"{exc.filename}: {exc.strerror or exc}") from None
    if fox_port is not None:
        from winder.cli.view import serve_bag

        return serve_bag(args, plan, fox_port, rate)
    from winder.interrupts import Interrupts

    interrupts = Interrupts().install()  # rclpy's own handlers are not used: see winder.interrupts
    try:
        return _play_on_graph(
            args, plan, interrupts, rate=rate, offset=offset, delay=delay, wait=wait, given=given
        )
    finally:
        interrupts.restore()


def _play_on_graph(
    args: argparse.Namespace,
    plan: Any,
    interrupts: Any,
    *,
    rate: float,
    offset: float,
    delay: float,
    wait: float,
    given: bool,
) -> int:
    """``winder play`` onto the ROS graph (not --foxglove): the signals taken by ``interrupts``."""
    from winder.cli.common import Progress, UserError, ros_imports
    from winder.contract.topics import check_namespace

    with ros_imports(interrupts):
        from winder.ros.player import describe, run_player
    from winder.ros.cell import cell_network

    domain, discovery, source = cell_network()
    span = (plan.last_ns - plan.first_ns) / 1e9
    print(
        f"winder play: {plan.raw.path}, {span:.3f} s recorded, from {offset:g} s at x{rate:g}"
        + (", looping" if args.loop else "")
    )
    print(f"  ROS domain {domain} ({source}), discovery {discovery}")
    if args.namespace is not None:
        print(f"  cell namespace {plan.namespace or '/'} -> {check_namespace(args.namespace) or '/'}")
    for line in describe(plan):
        print(line)
    for topic, why in sorted(plan.skipped.items()):
        print(f"  not played: {topic} ({why})")
    import os

    os.environ.setdefault("ROS_DOMAIN_ID", str(domain))
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", discovery)
    from winder.ros.player import CellLiveError

    bar = Progress(1.0, "playing")
    try:
        result = run_player(
            plan,
            rate=rate,
            loop=args.loop,
            start_paused=args.start_paused,
            delay=delay,
            wait_subscribers=wait,
            progress=bar.update,
            keys=True,
            force=args.force,
            first_reader=given,
            interrupts=interrupts,
        )
    except CellLiveError as exc:
        raise UserError(str(exc)) from None
    finally:
        bar.close()
    total = sum(result.published.values())
    print(
        f"  published {total} messages on {len(result.published)} topics in {result.wall_s:.2f} s"
        + (f", {result.loops} passes" if result.loops > 1 else "")
        + (f", held back {result.held_s:.2f} s by slow reliable subscribers" if result.held_s >= 0.05 else "")
    )
    if result.stalled:
        print(f"winder play: {result.stalled}", file=sys.stderr)
        return EXIT_FAILED
    if result.unacked:
        print(
            f"winder play: not every subscriber acknowledged every message on: {', '.join(result.unacked)}",
            file=sys.stderr,
        )
        return EXIT_FAILED
    return EXIT_OK


def _recorded_sim(run: Any) -> dict[str, Any]:
    """The sim node's settings the recording says the run had."""
    from winder.contract.params import MOTOR_FIELDS

    cfg = run.sim_config
    if cfg is None:
        return {}
    base: dict[str, Any] = {
        "model": cfg.model,
        "publish_rate": cfg.publish_rate,
        "settle_time": cfg.settle_time,
    }
    for axis, a in cfg.axes.items():
        for key in MOTOR_FIELDS:  # the fields the sim node records per axis
            base[f"{axis}.{key}"] = getattr(a, key)
    return base


def cmd_resim(args: argparse.Namespace) -> int:
    """A recording's step times through the sim node again, with other motor settings."""
    import time
    from pathlib import Path

    from winder.cli.common import Progress, UserError, ros_imports, values_from_args
    from winder.cli.summary import report_run
    from winder.contract.params import SIM_SPECS, bag_directory, check_sim
    from winder.contract.topics import (
        TOPIC_JOB,
        TOPIC_PATH,
        TOPIC_PROFILE_CONFIG,
        TOPIC_STEP_TIMES,
        check_namespace,
    )
    from winder.record.reader import read_run
    from winder.record.replay import plan_play

    if args.namespace is not None:
        check_namespace(args.namespace)
    try:
        run = read_run(args.bag, args.namespace)
        # the cell's nodes start in the recorded namespace: one ROS takes (a bag may come from anywhere)
        ns = check_namespace(run.namespace, "the recorded namespace")
        wanted = [f"{ns}/{t}" for t in (TOPIC_JOB, TOPIC_PATH, TOPIC_PROFILE_CONFIG, TOPIC_STEP_TIMES)]
        plan = plan_play(args.bag, topics=[t for t in wanted if run.counts.get(t)])
    except OSError as exc:
        raise UserError(f"{exc.filename}: {exc.strerror or exc}") from None
    recorded = _recorded_sim(run)
    sim = values_from_args(args, SIM_SPECS, recorded)
    check_sim(sim)
    changed = [k for k in SIM_SPECS if k in recorded and sim[k] != recorded[k]]
    sim["bag_dir"] = str(bag_directory(sim["bag_dir"]))
    first: dict[str, bytes] = {}
    for topic, _t, data in plan.messages():
        if not topic.recorded.endswith(TOPIC_STEP_TIMES):
            first.setdefault(topic.recorded, data)
    with ros_imports():
        from winder.ros.cell import cell_network
        from winder.ros.resim import Recorded, resimulate
    rec = Recorded(
        path=first.get(f"{ns}/{TOPIC_PATH}"),
        profile_config=first.get(f"{ns}/{TOPIC_PROFILE_CONFIG}"),
        events=run.events,
        plan=plan,
        step_topic=f"{ns}/{TOPIC_STEP_TIMES}",
    )
    source = str(Path(run.path).resolve())
    what = ", ".join(
        f"{k} {recorded[k]:g} -> {sim[k]:g}"
        if isinstance(sim[k], float)
        else f"{k} {recorded[k]} -> {sim[k]}"
        for k in changed
    )
    print(f"winder resim: {run.path} (run {run.plan.run_id or '-'}), {run.plan.total_steps} steps")
    print(f"  changed            {what or 'nothing: the recorded settings'}")
    domain, discovery, dsource = cell_network()
    print(f"  ROS domain         {domain} ({dsource}), discovery {discovery}")
    from winder.ros.player import CellLiveError

    bar = Progress(1.0, "re-simulating")
    t0 = time.monotonic()
    try:
        _, result = resimulate(
            rec,
            run.plan.text,
            source,
            sim,
            namespace=ns,
            domain=domain,
            progress=lambda frac, sim_t: bar.update(frac, f"sim {float(sim_t):7.2f} s"),
        )
    except CellLiveError as exc:  # refused as winder play refuses it
        raise UserError(str(exc)) from None
    finally:
        bar.close()
    print(f"  source             {source}")
    return report_run(result, time.monotonic() - t0, "resim")


def register(sub: argparse._SubParsersAction[Any]) -> None:
    """Add ``play`` and ``resim`` to the ``winder`` subcommands."""
    p = sub.add_parser(
        "play",
        help="publish a recording's topics onto the ROS graph (like ros2 bag play, every message delivered)",
        description="Publish the topics of a winder recording in log-time order, each with the QoS it "
        "was recorded with (job, path and configs latched: a late subscriber still gets them, also "
        "with --start-offset), reliably: the player drops nothing at any rate, and a reliable reader "
        "whose history is keep-all (or keep-last as deep as the topic's count) hears every message; "
        "a slower one holds the replay back, one that takes nothing for 5 s stops it. While playing: "
        "the space bar pauses and resumes, n plays the next message, + and - double and halve the "
        "rate; the node winder_player offers ~/pause, ~/resume, ~/toggle_paused, ~/play_next "
        "(std_srvs/Trigger) and the parameter rate.",
    )
    p.add_argument("bag", metavar="BAG", help="bag directory or .mcap file")
    p.add_argument("--rate", default="1", help="playback speed factor (default 1; 0.001 to 1e6)")
    p.add_argument("--loop", action="store_true", help="play again from the start when done (Ctrl-C ends)")
    p.add_argument(
        "--start-offset",
        default="0",
        metavar="S",
        help="start S seconds into the recording; the latched topics' last messages before it still go out",
    )
    p.add_argument(
        "--clock",
        action="store_true",
        help="publish the recorded simulated clock (/clock of the cell), so use_sim_time nodes follow it",
    )
    p.add_argument("--topics", nargs="+", metavar="TOPIC", help="only these topics (names or regexes)")
    p.add_argument("--exclude", nargs="+", metavar="TOPIC", help="leave these topics out (names or regexes)")
    p.add_argument(
        "--namespace",
        default=None,
        help="publish the cell's topics in this namespace instead of the recorded one (/name[/name...])",
    )
    p.add_argument("--start-paused", action="store_true", help="start paused (space, ~/resume to go)")
    p.add_argument(
        "--force",
        action="store_true",
        help="play even where a live cell runs in the namespace played into (refused otherwise: "
        "its run would take the recording for its own)",
    )
    p.add_argument("--delay", default="0", metavar="S", help="wait S seconds before the first message")
    p.add_argument(
        "--wait-for-subscribers",
        default=None,
        metavar="S",
        help="wait up to S seconds until a subscriber has come and every subscriber on the graph is "
        "matched, then play (start the player before the readers); without it the player waits up to "
        "5 s for the subscribers already on the graph to match, so they hear the first message",
    )
    p.add_argument(
        "--no-wait",
        action="store_true",
        help="publish the first message at once, matched or not (as ros2 bag play does: a reader may "
        "miss the first messages)",
    )
    from winder.cli.view import add_foxglove_arguments

    add_foxglove_arguments(
        p,
        "the recording (not onto the ROS graph) with Foxglove's playback controls: play, pause, "
        "seek, speed; --topics, --exclude, --namespace, --clock, --start-offset and --rate apply;",
    )
    p.set_defaults(func=cmd_play)

    from winder.cli.common import add_spec_arguments
    from winder.contract.params import SIM_SPECS

    p = sub.add_parser(
        "resim",
        help="re-simulate a recording's step times with another motor model or motor parameters",
        description="Run the recorded winder/step_times of a job through the sim node again, with the "
        "settings given here (the others as recorded), into a new bag that names its source bag "
        "and run. The step times are the recorded ones to the nanosecond; the sim node checks the "
        "stream and simulates exactly as in a live run.",
    )
    p.add_argument("bag", metavar="BAG", help="bag directory or .mcap file")
    p.add_argument("--namespace", default=None, help="the cell's ROS namespace, if the bag holds several")
    add_spec_arguments(
        p, SIM_SPECS, "sim node (default: as recorded; motor per axis: --feed.J, --fork.D, ...)"
    )
    p.set_defaults(func=cmd_resim)
