"""Foxglove on the command line: ``winder view``, and the ``--foxglove [PORT]``
option of ``winder run`` and ``winder play`` (:mod:`winder.record.foxglove`,
:mod:`winder.ros.view`). User errors are SpecErrors: one line, exit status 2.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from typing import Any

from winder.cli.exits import EXIT_OK

__all__ = [
    "add_foxglove_arguments",
    "foxglove_host",
    "foxglove_port",
    "register",
    "serve_bag",
    "start_live_view",
]

DEFAULT_HOST = "127.0.0.1"


def add_foxglove_arguments(group: Any, what: str) -> None:
    """``--foxglove [PORT]`` and ``--foxglove-host`` on a parser (argument group)."""
    from winder.record.foxglove import DEFAULT_PORT

    group.add_argument(
        "--foxglove",
        nargs="?",
        const=str(DEFAULT_PORT),
        default=None,
        metavar="PORT",
        help=f"serve {what} to Foxglove over its WebSocket protocol on PORT (default {DEFAULT_PORT}; "
        "0: any free port, printed); open ws://HOST:PORT in Foxglove, then layouts/winder_foxglove.json",
    )
    group.add_argument(
        "--foxglove-host",
        default=DEFAULT_HOST,
        metavar="HOST",
        help=f"address the Foxglove server listens on (default {DEFAULT_HOST}: this host only; "
        "0.0.0.0: every interface)",
    )


def foxglove_port(args: argparse.Namespace, option: str = "--foxglove") -> int | None:
    """The port of ``--foxglove`` checked (None: not given)."""
    from winder.record.foxglove import port_spec

    text = getattr(args, option.lstrip("-").replace("-", "_"))
    return None if text is None else int(port_spec(option).parse(text))


def foxglove_host(args: argparse.Namespace, option: str = "--foxglove-host") -> str:
    """The address of ``option`` checked as the server will take it: a name
    or address this host resolves (``winder run --check`` starts no server,
    and says so before a run would refuse it). SpecError (one line) otherwise."""
    import socket

    from winder.spec import SpecError, shorten

    host = str(getattr(args, option.lstrip("-").replace("-", "_")))
    try:
        socket.getaddrinfo(host, None, type=socket.SOCK_STREAM)
    except (OSError, UnicodeError) as exc:
        why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise SpecError(
            f"{option}={shorten(host)} is invalid: cannot be resolved ({why}); must be an address of this "
            f"host (default {DEFAULT_HOST}; 0.0.0.0: every interface)"
        ) from None
    return host


def _url(server: Any, host: str) -> str:
    shown = "127.0.0.1" if host in ("0.0.0.0", "::") else host
    return f"ws://{shown}:{server.port}"


def _announce(server: Any, host: str) -> None:
    print(
        f"  foxglove           {_url(server, host)}  (Foxglove: Open connection, Foxglove WebSocket)",
        flush=True,
    )


def start_live_view(args: argparse.Namespace, port: int, namespace: str) -> tuple[Any, Any]:
    """``winder run --foxglove``: the server (listening: a bad port ends the
    command before the cell starts) and the view :func:`winder.ros.cell.run_cell` attaches."""
    from winder.record.foxglove import Channels, start_server
    from winder.ros.view import LiveView

    channels = Channels()
    view = LiveView(channels, namespace)  # its channels first: a client sees them all at once
    server = start_server(
        name=f"winder {namespace or '/'}",
        host=args.foxglove_host,
        port=port,
        option="--foxglove",
        listener=channels,
    )
    _announce(server, args.foxglove_host)
    return server, view


def serve_bag(args: argparse.Namespace, plan: Any, port: int, rate: float) -> int:
    """``winder play BAG --foxglove``: the recording to Foxglove with its
    playback controls, until Ctrl-C. ROS is not needed."""
    from winder.cli.common import Progress
    from winder.record.foxglove import BagPlayback, start_server

    playback = BagPlayback(plan, speed=rate)
    server = start_server(
        name=f"winder play {plan.raw.path.name}",
        host=args.foxglove_host,
        port=port,
        option="--foxglove",
        listener=playback,
        playback_range=playback.time_range,
    )
    span = (plan.last_ns - plan.first_ns) / 1e9
    print(f"winder play: {plan.raw.path}, {span:.3f} s recorded, served to Foxglove (paused at the start)")
    for topic in sorted(plan.topics.values(), key=lambda t: t.name):
        print(f"  {topic.name:32s} {topic.count:8d}  {topic.msgtype}")
    for topic, why in sorted(plan.skipped.items()):
        print(f"  not served: {topic} ({why})")
    _announce(server, args.foxglove_host)
    print("  the player's controls play, pause, seek and set the speed; Ctrl-C ends", flush=True)
    bar = Progress(1.0, "serving")
    import signal

    old_term = signal.signal(signal.SIGTERM, lambda *_: playback.stop())  # ends as Ctrl-C does
    try:
        playback.serve(server, progress=bar.update)
    except KeyboardInterrupt:
        pass  # the way a served recording ends
    finally:
        signal.signal(signal.SIGTERM, old_term)
        playback.stop()
        bar.close()
        server.stop()
    total = sum(playback.channels.counts.values())
    print(f"  served {total} messages, {playback.seeks} seeks")
    return EXIT_OK


def cmd_view(args: argparse.Namespace) -> int:
    """A live cell's topics to Foxglove, until Ctrl-C."""
    from winder.contract.topics import check_namespace
    from winder.record.foxglove import Channels, start_server

    namespace = check_namespace(args.namespace)
    port = foxglove_port(args, "--port")
    assert port is not None
    from winder.cli.common import ros_imports

    with ros_imports():
        from winder.ros.view import LiveView, run_view
    domain = os.environ.get("ROS_DOMAIN_ID", "")
    where = f"{domain} (ROS_DOMAIN_ID)" if domain else "0 (ROS's default: set ROS_DOMAIN_ID to the cell's)"
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")  # as winder run's cells
    channels = Channels()
    view = LiveView(channels, namespace)
    server = start_server(
        name=f"winder view {namespace or '/'}", host=args.host, port=port, option="--port", listener=channels
    )
    print(f"winder view: the cell in {namespace or '/'}, live")
    print(f"  ROS domain         {where}, discovery {os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE']}")
    print(f"  topics             {', '.join(view.names.values())}")
    print(f"  foxglove           {_url(server, args.host)}  (Foxglove: Open connection, Foxglove WebSocket)")
    print("  Ctrl-C ends", flush=True)
    t0 = time.monotonic()
    try:
        run_view(view)
    finally:
        server.stop()
    total = sum(channels.counts.values())
    busy = sorted(((n, t) for t, n in channels.counts.items() if n), reverse=True)
    print(
        f"winder view: served {total} messages in {time.monotonic() - t0:.1f} s"
        + (f" ({', '.join(f'{t} {n}' for n, t in busy)})" if busy else ""),
        file=sys.stdout,
    )
    if view.ignored:
        print(f"  ignored, foreign   {view.ignored} (not the cell's nodes: docs/SECURITY.md)")
    return EXIT_OK


def register(sub: argparse._SubParsersAction[Any]) -> None:
    """Add ``view`` to the ``winder`` subcommands."""
    from winder.record.foxglove import DEFAULT_PORT

    p = sub.add_parser(
        "view",
        help="serve a running cell's topics live to Foxglove (WebSocket), without joining the cell",
        description="Listen to a running cell (on this process' ROS_DOMAIN_ID) and serve its joint "
        "states and commands, state, progress, path, control events, job and configs, diagnostics "
        "and clock to Foxglove over its WebSocket protocol (ros2msg schemas, the CDR bytes as DDS "
        "delivered them). The node only subscribes: it plays no part in the cell and reads neither "
        "step stream. Ctrl-C ends it.",
    )
    p.add_argument("--namespace", default="", help="ROS namespace of the cell (/name[/name...])")
    p.add_argument(
        "--port",
        default=str(DEFAULT_PORT),
        help=f"TCP port of the WebSocket server; [0, 65535], 0: any free port; default {DEFAULT_PORT}",
    )
    p.add_argument(
        "--host",
        default=DEFAULT_HOST,
        help=f"address to listen on (default {DEFAULT_HOST}: this host only; 0.0.0.0: every interface)",
    )
    p.set_defaults(func=cmd_view)
