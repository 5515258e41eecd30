"""``main`` of every winder node."""

from __future__ import annotations

import contextlib
import ctypes
import logging
import os
import signal
import sys
from collections.abc import Callable, Mapping
from types import FrameType
from typing import TYPE_CHECKING, Any, NoReturn

if TYPE_CHECKING:  # rclpy is imported when a node spins: the signal handling here comes before it
    from rclpy.node import Node

    from winder.spec import Spec

#: glibc's mallopt parameters, and the values a node runs with: blocks up to
#: 32 MiB (glibc's limit) come from the heap, and up to 64 MiB of freed heap
#: stay with the process.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
HEAP_BLOCKS = 32 << 20
HEAP_KEPT = 64 << 20


def keep_freed_memory() -> bool:
    """Let the allocator reuse freed memory for numpy's temporaries (glibc;
    elsewhere nothing changes). A node's arrays of a few hundred kB (a chunk
    of steps, its columns, the tracker's terms) would otherwise each be a
    fresh mmap, zeroed page by page by the kernel and unmapped when freed:
    at 10**7 steps that was a tenth of the sim node's time. True if set."""
    try:  # the process' own symbols, the C library's among them (find_library runs ldconfig: 10 ms)
        mallopt = getattr(ctypes.CDLL(None), "mallopt", None)
    except OSError:
        return False
    if mallopt is None:
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, HEAP_BLOCKS)) and bool(mallopt(_M_TRIM_THRESHOLD, HEAP_KEPT))


#: what a node's own arguments (those before ``--ros-args``) may ask, besides ROS's arguments after it
HELP_OPTIONS = ("-h", "--help")


def answer_help(prog: str, about: str, parameters: Mapping[str, Spec], args: list[str] | None) -> bool:
    """A node executable's ``-h``/``--help``: its usage and ``parameters``
    (the table its node declares; :data:`winder.contract.params.MANAGED`
    besides), printed, True; False (nothing printed) if the arguments
    (``sys.argv`` when None, as rclpy takes them) do not ask for help.
    Called before rclpy or the node's module is imported, which takes half a
    second to a second: the answer comes in a third of that."""
    if not any(a in HELP_OPTIONS for a in own_arguments(sys.argv if args is None else args)):
        return False
    print(node_help(prog, about, parameters))
    return True


def own_arguments(argv: list[str]) -> list[str]:
    """A node's own arguments: those of ``argv[1:]`` outside its ROS arguments,
    each section of which runs from ``--ros-args`` to ``--`` or the end (rcl's rule)."""
    own: list[str] = []
    in_ros = False
    for arg in argv[1:]:
        if arg == "--ros-args":
            in_ros = True
        elif in_ros and arg == "--":
            in_ros = False
        elif not in_ros:
            own.append(arg)
    return own


def node_help(prog: str, about: str, parameters: Mapping[str, Spec]) -> str:
    """The help of a node executable: usage, what it is (``about``'s first
    line), how its parameters are given, and each parameter in one line,
    ``NAME:=DEFAULT`` (as ``-p`` takes it) and its help (what, range)."""
    from winder.contract.params import MANAGED

    table = {**parameters, MANAGED.name: MANAGED}
    shown = {name: f"{name}:={_ros_value(spec.default)}" for name, spec in table.items()}
    width = max(map(len, shown.values()))
    lines = [
        f"usage: {prog} [-h] [--ros-args [-p NAME:=VALUE ...] [--params-file FILE] [-r FROM:=TO ...]]",
        "",
        (about.strip().splitlines() or [prog])[0],
        "",
        "A ROS 2 node: it runs until stopped (Ctrl-C, SIGTERM). Its parameters are given at its",
        "start after --ros-args, each with -p NAME:=VALUE, or from a parameters file (a job file)",
        "with --params-file FILE; at run time with `winder ctl param set` (`ros2 param set`).",
        f"Example: {prog} --ros-args -p use_sim_time:=true -r __ns:=/cell1",
        "",
        "parameters (NAME:=DEFAULT  what it is; the values it takes):",
        *(f"  {shown[name]:<{width}}  {s.description}; {s.range_text()}" for name, s in table.items()),
        "  and rclpy's own: use_sim_time (false), start_type_description_service (true)",
        "",
        "options:",
        "  -h, --help  show this help and exit (the node is not started)",
    ]
    return "\n".join(lines)


def _ros_value(value: object) -> str:
    """A default as a ``-p NAME:=VALUE`` writes it (YAML: ``true``, ``''``, ``[a, b]``)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_ros_value(v) for v in value) + "]"
    if isinstance(value, str):
        return value if value and value.strip() == value and " " not in value else repr(value)
    return repr(value)


#: a signal came (one entry each): one before ``rclpy.init`` installs its handlers ends the node too
_signalled: list[bool] = []


def signalled() -> bool:
    """A signal that ends the process has come."""
    return bool(_signalled)


def _stop_quietly(signum: int, frame: FrameType | None) -> None:
    """The Python side of SIGINT and SIGTERM in a node: nothing. rclpy's own
    handler (which calls this one after it) shuts the context down, and spin
    returns once the callback that runs has ended. Python's default, a
    KeyboardInterrupt raised wherever the main thread happens to be, could
    land between a bag's creation and the line that keeps it (which once left a
    0-byte .mcap and no metadata.yaml)."""
    del signum, frame
    _signalled.append(True)


def _hangup(signum: int, frame: FrameType | None) -> None:
    """SIGHUP (the terminal went away) ends the node as SIGTERM does, which
    rclpy handles; by default it would kill the node outright, its bag open."""
    del signum, frame
    os.kill(os.getpid(), signal.SIGTERM)


#: SIGHUP was ignored when the node started (nohup): a restart leaves it so
_nohup: list[bool] = []


def install_signal_handlers() -> None:
    """Signals that end a node let it finish its callback and close its bag
    (see :func:`_stop_quietly`); installed before ``rclpy.init``, which chains
    its handlers to these."""
    from winder.procs import hangup_ignored

    signal.signal(signal.SIGINT, _stop_quietly)
    signal.signal(signal.SIGTERM, _stop_quietly)
    if hangup_ignored():  # under nohup a node outlives its terminal
        _nohup.append(True)
    else:
        signal.signal(signal.SIGHUP, _hangup)
    sys.unraisablehook = _quiet_rclpy_finalisers


def _quiet_rclpy_finalisers(unraisable: Any) -> None:
    """A signal that shuts rclpy's context down while a node or its executor
    is being made (rclpy's handler runs in a thread of its own, so no mask
    of the main thread keeps it out) leaves half-made rclpy objects whose
    finalisers raise at exit ("Exception ignored in ... __del__",
    "'SenderExecutor' object has no attribute '_sigint_gc'"): the signal's
    doing, not an error, and not printed. Anything else goes to Python's
    own hook."""
    where = getattr(getattr(unraisable, "object", None), "__module__", None) or ""
    if _signalled and where.startswith("rclpy."):
        return
    sys.__unraisablehook__(unraisable)


def spin(factory: Callable[[], Node], args: list[str] | None = None) -> None:
    """``main`` of every winder node: init, spin, and on Ctrl-C / SIGTERM /
    SIGHUP / external shutdown run the node's ``shutdown()`` hook (close the
    bag) with further signals ignored, then destroy the node."""
    spin_all([factory], args)


def spin_all(factories: list[Callable[[], Node]], args: list[str] | None = None) -> None:
    """:func:`spin` for several nodes in one process, one executor (what
    ``winder_container`` runs: a whole cell in one process, as a ROS 2
    component container holds several nodes): each made in turn, each
    one's ``shutdown()`` hook run at the end, the process' exit status the
    first node's that has one."""
    import rclpy
    from rclpy._rclpy_pybind11 import RCLError
    from rclpy.executors import ExternalShutdownException

    from winder.procs import parent_gone, stacks_on_signal, take_stop_signals
    from winder.ros import rejoin
    from winder.ros.dds import use_profile
    from winder.ros.managed import ManagedNode
    from winder.ros.sender import SenderExecutor

    use_profile()
    keep_freed_memory()
    stacks_on_signal()  # kill -USR1: every thread's stack on stderr (where a node hangs)
    take_stop_signals()  # none blocked (a node's handlers below replace an ignored one)
    install_signal_handlers()
    if parent_gone():  # its death signal may have been lost while Python started (winder.procs)
        return
    ManagedNode.restart = restart = rejoin.restart_of_this_process()
    rclpy.init(args=args)
    nodes: list[Node] = []
    executor: SenderExecutor | None = None
    again: dict[str, dict[str, Any]] = {}  # a restart's parameters, per node (winder.ros.rejoin)
    active: list[str] = []  # the nodes active at a restart
    carried: dict[str, Any] = {}  # what each node hands over to its restarted self
    try:
        if _signalled:  # before rclpy's handlers were there to shut the context down
            return
        for factory in factories:
            nodes.append(factory())
        if restart is not None:  # the nodes have read the parameters file
            with contextlib.suppress(OSError):
                os.unlink(restart.params)
        executor = SenderExecutor()  # takes attributed subscriptions with their publisher (winder.ros.sender)
        for node in nodes:
            executor.add_node(node)
        # a signal that came inside rclpy.init before its handlers were in
        # reaches _stop_quietly only at the main thread's next Python call
        # (the nodes' making), after the check above: the context was never
        # shut down, and the node spun on (1 start in 150, SIGINT sent at
        # once; CI). By now that handler has run.
        if _signalled:
            return
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        # a signal shut the context down while a callback was using it (an
        # RCLError from a publish, an invalid handle): the shutdown's doing
        if rclpy.ok():
            raise
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        signal.signal(signal.SIGHUP, signal.SIG_IGN)
        if any(getattr(node, "restarting", "") for node in nodes) and not _signalled:
            managed = [n for n in nodes if isinstance(n, ManagedNode)]
            again = {n.get_fully_qualified_name(): n.parameters_now() for n in managed}
            active = [n.get_fully_qualified_name() for n in nodes if getattr(n, "active", False)]
        if executor is not None:
            with contextlib.suppress(Exception):  # never in the way of the hooks (the bags' closing)
                executor.shutdown(timeout_sec=0)  # it lets go of the entities it was waiting on
        for node in nodes:
            hook = getattr(node, "shutdown", None)
            if callable(hook):
                hook()
            handover = getattr(node, "handover", None)
            if again and callable(handover) and (told := handover()) is not None:
                carried[node.get_fully_qualified_name()] = told
            node.destroy_node()
        # the signal handler may shut the context down at this very moment
        with contextlib.suppress(RCLError):
            rclpy.try_shutdown()
    code = next((c for c in (getattr(node, "exit_code", 0) for node in nodes) if c), 0)
    if again and not code and not _signalled:
        _restart(nodes, again, active, carried)
    # a node whose making a signal cut short (its context shut down under it)
    # was never destroyed, and only the interpreter's teardown takes its DDS
    # participant down: without it the node stayed on the graph for the whole
    # lease (10 s), where a restarted node would have been taken for a second one;
    # every node made, none is half made and unknown to the clean-up above
    if len(nodes) == len(factories) and all(getattr(node, "let_go", True) for node in nodes):
        leave(code)
    if code:  # a node still holds an entity: the interpreter's teardown removes the participant
        raise SystemExit(code)


def _restart(
    nodes: list[Node], again: dict[str, dict[str, Any]], active: list[str], carried: dict[str, Any]
) -> NoReturn:
    """Run the process again (:mod:`winder.ros.rejoin`): its nodes are
    destroyed, their parameters in ``again``; the stop signals get back what
    the process started with, for the new one to take them as it did."""
    from winder.ros import rejoin

    held = max(float(getattr(node, "held", 0.0)) for node in nodes)
    params = rejoin.save_parameters(again)
    _flush()
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if not _nohup:
        signal.signal(signal.SIGHUP, signal.SIG_DFL)
    rejoin.exec_again(held, params, active, carried)


def leave(code: int) -> NoReturn:
    """End a ROS process whose work is done and whose DDS participant is
    gone (its nodes destroyed, the context shut down): flush what Python
    still buffers and exit at once, without the interpreter's teardown.
    That teardown took 0.15 s a process, 0.1 s of it a fixed sleep in Fast
    DDS's exit handler (strace: one 100 ms ``clock_nanosleep`` after the
    last participant left), and a cell's runner waits for its nodes."""
    _flush()
    os._exit(code)


def _flush() -> None:
    """What Python, rcl's logging and C stdio still buffer, written."""
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    _finish_ros_logging()
    with contextlib.suppress(Exception):
        ctypes.CDLL(None).fflush(None)  # C stdio: rcutils' console output when buffered


def _finish_ros_logging() -> None:
    """rcl's logging ended, its log file flushed, as rclpy's context does
    when it shuts down: a context shut down by rclpy's signal handler skips
    that. Nothing if rclpy was never loaded or has done it."""
    context = sys.modules.get("rclpy.context")
    if context is None:
        return
    with contextlib.suppress(Exception), context.g_logging_configure_lock:
        if context.g_logging_ref_count > 0:
            from rclpy.impl.implementation_singleton import rclpy_implementation

            rclpy_implementation.rclpy_logging_fini()
            setattr(context, "g_logging_ref_count", 0)  # noqa: B010 - a module global of rclpy
