"""Waiting on events, each with a bound, each failure saying what it waited
for and what it heard meanwhile: the only way a test waits.

A fixed ``time.sleep`` never decides a result: on a busy machine discovery,
a node's start or a callback can take many times longer than on a quiet one,
and a test that guessed a time fails by luck. These wait for the event
itself and fail loudly at the bound::

    wait.until(lambda: log.exists(), 30, "the sim node's log")
    wait.spin_until(ros, lambda: heard, 10, "running from profile_node", heard=lambda: states)
    wait.matched(ros, pub, 30, "the sim node's subscription on winder/step_times")
    wait.node_gone(ros, "sim_node", 30)
    wait.log_has(lambda: procs.log(p), "run armed", 60, "the bridge's run", running=p)

Plain functions only (no rclpy at import): a test that starts no node may use them too.
"""

from __future__ import annotations

import subprocess
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

__all__ = [
    "WaitTimeoutError",
    "child",
    "log_has",
    "matched",
    "node_gone",
    "node_on_graph",
    "spin_for",
    "spin_until",
    "until",
    "until_exit",
]

#: the pause between two looks of a polling wait (s): fine enough for any test's event
POLL = 0.02


class WaitTimeoutError(AssertionError):
    """A wait's bound passed before its event; the message names both, and what was heard."""


def _message(what: str, timeout: float, heard: Callable[[], object] | None, why: str = "") -> str:
    text = f"no {what} " + (why or f"within {timeout:g} s")
    if heard is not None:
        try:
            seen = heard()
        except Exception as exc:  # a report of what was heard must not hide the timeout
            seen = f"(could not tell: {exc!r})"
        text += f"; heard: {_short(seen)}"
    return text


def _short(seen: object, limit: int = 1500) -> str:
    text = repr(seen) if not isinstance(seen, str) else seen
    return text if len(text) <= limit else text[:limit] + f"... ({len(text)} characters)"


def until(
    cond: Callable[[], object],
    timeout: float,
    what: str,
    *,
    heard: Callable[[], object] | None = None,
    poll: float = POLL,
    running: subprocess.Popen[Any] | None = None,
) -> Any:
    """Poll ``cond()`` until it is true (returned), at most ``timeout`` s;
    :class:`WaitTimeoutError` naming ``what`` and ``heard()`` after it. With
    ``running`` (the process the event is to come from): fails at once, with
    its exit status, if that process ends first."""
    end = time.monotonic() + timeout
    while True:
        ended = running is not None and running.poll() is not None
        value = cond()  # looked at after the exit check: what the process did before it ended counts
        if value:
            return value
        if ended:
            assert running is not None
            why = f"before {running.args!r} ended (status {running.returncode})"
            raise WaitTimeoutError(_message(what, timeout, heard, why))
        if time.monotonic() > end:
            raise WaitTimeoutError(_message(what, timeout, heard))
        time.sleep(poll)


def spin_until(
    node: Any,
    cond: Callable[[], object],
    timeout: float,
    what: str,
    *,
    heard: Callable[[], object] | None = None,
) -> Any:
    """Spin ``node`` (its callbacks run here) until ``cond()`` is true (returned);
    :class:`WaitTimeoutError` naming ``what`` and ``heard()`` after ``timeout`` s."""
    from rclpy.executors import SingleThreadedExecutor

    ex = SingleThreadedExecutor(context=node.context)
    ex.add_node(node)
    end = time.monotonic() + timeout
    try:
        while True:
            value = cond()
            if value:
                return value
            if time.monotonic() > end:
                raise WaitTimeoutError(_message(what, timeout, heard))
            ex.spin_once(timeout_sec=0.05)
    finally:
        ex.remove_node(node)


def spin_for(node: Any, seconds: float) -> None:
    """Serve ``node``'s callbacks for ``seconds``: for a test whose subject is
    what does *not* happen in a time (no message comes, nothing changes), never
    to let something happen."""
    end = time.monotonic() + seconds
    spin_until(node, lambda: time.monotonic() >= end, seconds + 30, f"the end of {seconds} s of spinning")


def matched(node: Any, endpoint: Any, timeout: float, what: str, count: int = 1) -> None:
    """Until a publisher has ``count`` matched subscriptions, or a subscription
    ``count`` matched publishers (``what`` names the other side)."""
    get = getattr(endpoint, "get_subscription_count", None) or endpoint.get_publisher_count
    spin_until(node, lambda: get() >= count, timeout, what, heard=lambda: f"{get()} matched")


def _graph(node: Any) -> list[str]:
    return sorted(
        ("/" + ns.strip("/") + "/" + name).replace("//", "/")
        for name, ns in node.get_node_names_and_namespaces()
    )


def node_on_graph(node: Any, name: str, timeout: float) -> None:
    """Until the graph shows a node called ``name`` (fully qualified, or a bare name in any namespace)."""
    spin_until(
        node, lambda: _named(node, name), timeout, f"node {name} on the graph", heard=lambda: _graph(node)
    )


def node_gone(node: Any, name: str, timeout: float) -> None:
    """Until the graph shows no node called ``name`` (its process ended and its participant left)."""
    spin_until(
        node,
        lambda: not _named(node, name),
        timeout,
        f"departure of {name} from the graph",
        heard=lambda: _graph(node),
    )


def _named(node: Any, name: str) -> bool:
    names = _graph(node)
    if name.startswith("/"):
        return name in names
    return any(n.rsplit("/", 1)[-1] == name for n in names)


def until_exit(p: subprocess.Popen[Any], timeout: float, what: str = "") -> int:
    """Until process ``p`` ends; its exit code."""
    try:
        return p.wait(timeout)
    except subprocess.TimeoutExpired:
        raise WaitTimeoutError(f"no exit of {what or p.args!r} within {timeout:g} s") from None


def log_has(
    path: Path | Callable[[], str],
    texts: str | Iterable[str],
    timeout: float,
    what: str = "",
    *,
    running: subprocess.Popen[Any] | None = None,
) -> str:
    """Until the file at ``path`` (or the text ``path()`` reads, such as
    ``lambda: procs.log(p)``) holds every one of ``texts``; its text. With
    ``running``: fails at once if that process ends without them."""
    wanted = [texts] if isinstance(texts, str) else list(texts)

    def read() -> str:
        if callable(path):
            return path()
        try:
            return path.read_text(errors="replace")
        except FileNotFoundError:
            return ""

    return str(
        until(
            lambda: (lambda t: t if all(w in t for w in wanted) else "")(read()),
            timeout,
            what or f"{wanted!r} in {getattr(path, 'name', 'the output')}",
            heard=lambda: read()[-1500:],
            running=running,
        )
    )


def child(parent: int, name: str, timeout: float) -> int:
    """Until process ``parent`` has a child whose command line holds ``name``; its pid."""

    def find() -> int:
        for task in Path(f"/proc/{parent}/task").glob("*"):
            try:
                kids = (task / "children").read_text().split()
            except OSError:
                continue
            for pid in kids:
                try:
                    argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
                except OSError:
                    continue
                if any(name.encode() in a for a in argv):
                    return int(pid)
        return 0

    def kids() -> list[str]:
        return sorted(
            Path(f"/proc/{k}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")[:120]
            for t in Path(f"/proc/{parent}/task").glob("*")
            for k in (t / "children").read_text().split()
            if Path(f"/proc/{k}").exists()
        )

    return int(until(find, timeout, f"child {name} of process {parent}", heard=kids))
