"""What can be checked of a documented command without running it.

Some of the docs' commands cannot run here: they need a ROS install
(``ros2 run``, ``ros2 launch``, ``ros2 service call``: ros2cli and launch are
not wheels), a second host, a cut-short recording or many minutes. What
they say of winder can still be wrong, and a reader pastes them as shown.
:func:`problems` reads such a command and names every part of it that
winder does not have, each in one line:

* ``winder SUBCOMMAND ...`` must parse with winder's own argument parser
  (an unknown option, a missing argument, a bad choice);
* a winder node (``interp_node``, ``.venv/bin/sim_node``, ``ros2 run
  winder_sim sim_node``): the package and executable exist, and every
  ``-p name:=value`` is a parameter the node declares, its value in range
  where it is a number or a boolean;
* ``ros2 launch winder_sim winder.launch.py name:=value``: the launch file
  declares the argument;
* ``ros2 service call /[ns/]node/service TYPE``: the node offers that
  service with that type, and the type is installed;
* ``make TARGET``: the Makefile has the target; ``pytest PATH``: the path
  exists;
* ``VAR="command ..." ...``: the command in the variable is checked too (a
  consumer's command line handed to the conformance suite).

Commands of other projects (``xacro``, ``robot_state_publisher``,
``controller_manager``) and shell built-ins are not winder's to check:
:func:`problems` returns None for them.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import re
import shlex
from pathlib import Path

from support.paths import ROOT
from winder.contract.params import (
    BRIDGE_SPECS,
    INTERP_SPECS,
    OPERATION_SPECS,
    PROFILE_SPECS,
    SIM_SPECS,
)
from winder.spec import Spec, SpecError

__all__ = ["NODE_SPECS", "problems"]

#: each winder node executable, its package and the parameters it declares (bar those below)
NODE_SPECS: dict[str, tuple[str, dict[str, Spec]]] = {
    "interp_node": ("winder_interp", INTERP_SPECS),
    "profile_node": ("winder_profile", {**PROFILE_SPECS, **OPERATION_SPECS}),
    "sim_node": ("winder_sim", SIM_SPECS),
    "bridge_node": ("winder_bridge", BRIDGE_SPECS),
}
#: parameters every winder node has: ManagedNode's and rclpy's own
EVERY_NODE = {"managed", "use_sim_time", "start_type_description_service"}
#: services every winder node has: the lifecycle's and the parameters'
EVERY_NODE_SERVICES = {
    "change_state": "lifecycle_msgs/srv/ChangeState",
    "get_state": "lifecycle_msgs/srv/GetState",
    "get_available_states": "lifecycle_msgs/srv/GetAvailableStates",
    "get_available_transitions": "lifecycle_msgs/srv/GetAvailableTransitions",
    "get_transition_graph": "lifecycle_msgs/srv/GetAvailableTransitions",
    "get_parameters": "rcl_interfaces/srv/GetParameters",
    "set_parameters": "rcl_interfaces/srv/SetParameters",
    "set_parameters_atomically": "rcl_interfaces/srv/SetParametersAtomically",
    "list_parameters": "rcl_interfaces/srv/ListParameters",
    "describe_parameters": "rcl_interfaces/srv/DescribeParameters",
    "get_parameter_types": "rcl_interfaces/srv/GetParameterTypes",
}
#: the message packages the node modules import service types from
SERVICE_PACKAGES = {"Trigger": "std_srvs", "SetParametersAtomically": "rcl_interfaces"}
#: words before a command that leave it the same command
PREFIXES = {"nice", "env", "exec", "time", "sudo"}
#: shell words that are not a command of their own to check
SHELL = {"export", "cd", "source", "set", "echo", "kill", "wait", "sleep", "ls", "cat"}


def problems(text: str) -> list[str] | None:
    """What is wrong in the command line ``text`` (empty if nothing is), or
    None if it is not a winder command (nothing checked)."""
    try:
        words = shlex.split(text, comments=True)
    except ValueError as exc:
        return [f"not a shell command line: {exc}"]
    found: list[str] = []
    checked = False
    while words and "=" in words[0] and re.match(r"^[A-Za-z_]\w*=", words[0]):
        value = words.pop(0).split("=", 1)[1]
        inner = problems(value) if value.split() else None
        if inner is not None:  # a command handed over in a variable
            checked = True
            found += inner
    while words and Path(words[0]).name in PREFIXES:
        words.pop(0)
        while words and words[0].startswith("-"):  # nice -n 5
            words.pop(0)
            if words and words[0].lstrip("-").isdigit():
                words.pop(0)
    if not words or words[0] in SHELL:
        return found if checked else None
    program, rest = Path(words[0]).name, words[1:]
    if program == "winder":
        return found + _winder(rest)
    if program in NODE_SPECS:
        return found + _node(program, rest)
    if program == "ros2":
        mine = _ros2(rest)
        return found + mine if mine is not None else (found if checked else None)
    if program == "make":
        return found + _make(rest)
    if program == "python" and rest[:2] == ["-m", "pytest"]:
        return found + _pytest(rest[2:])
    return found if checked else None


def _winder(args: list[str]) -> list[str]:
    from winder.cli.commands import build_parser

    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            build_parser().parse_args(args)
    except SystemExit as exc:
        if exc.code not in (0, None):
            last = err.getvalue().strip().splitlines()
            return [f"winder {' '.join(args)}: {last[-1] if last else 'refused'}"]
    return []


def _params(args: list[str]) -> list[tuple[str, str]]:
    """The ``-p name:=value`` pairs of a node's ``--ros-args``."""
    out = []
    for i, word in enumerate(args):
        if word in ("-p", "--param") and i + 1 < len(args) and ":=" in args[i + 1]:
            name, value = args[i + 1].split(":=", 1)
            out.append((name, value))
    return out


def _node(executable: str, args: list[str]) -> list[str]:
    _, specs = NODE_SPECS[executable]
    found = []
    for name, value in _params(args):
        spec = specs.get(name)
        if spec is None:
            if name not in EVERY_NODE:
                found.append(f"{executable}: no parameter {name!r}")
            continue
        if "$" not in value and not value.startswith("["):  # a list is the node's to parse
            try:
                spec.parse(value)
            except SpecError as exc:
                found.append(f"{executable}: {exc}")
    if "--params-file" in args:
        i = args.index("--params-file")
        path = args[i + 1] if i + 1 < len(args) else ""
        if path.startswith("jobs/") and not (ROOT / path).is_file():
            found.append(f"{executable}: no parameters file {path}")
    return found


def _entry_points(package: str) -> set[str]:
    setup = (ROOT / package / "setup.py").read_text()
    return set(re.findall(r'"(\w+)\s*=\s*[\w.]+:\w+"', setup))


def _ros2(args: list[str]) -> list[str] | None:
    verb = args[0] if args else ""
    packages = {pkg for pkg, _ in NODE_SPECS.values()}
    if verb == "run" and len(args) >= 3:
        package, executable = args[1], args[2]
        if package not in packages:
            return None  # another project's node
        if executable not in _entry_points(package):
            return [f"ros2 run {package} {executable}: {package} has no executable {executable!r}"]
        return _node(executable, args[3:])
    if verb == "launch" and len(args) >= 3:
        if args[1] not in packages:
            return None
        launch = ROOT / args[1] / "launch" / args[2]
        if not launch.is_file():
            return [f"ros2 launch {args[1]} {args[2]}: no such launch file"]
        declared = _launch_arguments()
        return [
            f"ros2 launch {args[1]} {args[2]}: no argument {name!r}"
            for name in (w.split(":=", 1)[0] for w in args[3:] if ":=" in w)
            if name not in declared
        ]
    if verb == "service" and len(args) >= 4 and args[1] == "call":
        return _service(args[2], args[3])
    if verb == "action" and len(args) >= 4 and args[1] == "send_goal":
        rest = [a for a in args[2:] if not a.startswith("--")]
        return _action(*rest[:3]) if len(rest) >= 2 else None
    if verb == "interface" and len(args) >= 3 and args[1] == "show":
        return _interface(args[2])
    if verb == "param" and len(args) >= 4 and args[1] in ("get", "set", "describe"):
        node = args[2].strip("/").split("/")[-1]
        if node not in NODE_SPECS:
            return None
        pair = [f"{args[3]}:={args[4]}"] if args[1] == "set" and len(args) >= 5 else [f"{args[3]}:=$"]
        return _node(node, ["-p", *pair])
    return None


def _launch_arguments() -> set[str]:
    """The arguments winder.launch.py declares: its COMMON table, each node's specs, and its own two."""
    source = (ROOT / "winder_sim" / "launch" / "winder.launch.py").read_text()
    common = set(re.findall(r'^    "(\w+)": Spec\(', source, re.M))
    names = {"namespace", "params_file", *common}
    for executable in ("sim_node", "profile_node", "interp_node"):
        names |= set(NODE_SPECS[executable][1])
    return names


def _services(executable: str) -> dict[str, str]:
    """The services a winder node offers, name -> type (``pkg/srv/Type``), from its module's source."""
    package, _ = NODE_SPECS[executable]
    source = (ROOT / package / package / f"{executable}.py").read_text()
    out = dict(EVERY_NODE_SERVICES)
    for kind, name in re.findall(r'create_service\(\s*(\w+),\s*"~/(\w+)"', source):
        out[name] = f"{SERVICE_PACKAGES.get(kind, '?')}/srv/{kind}"
    return out


def _service(name: str, kind: str) -> list[str] | None:
    parts = name.strip("/").split("/")
    if len(parts) < 2 or parts[-2] not in NODE_SPECS:
        return None  # not a winder node's service
    offered = _services(parts[-2]).get(parts[-1])
    if offered is None:
        return [f"ros2 service call {name}: {parts[-2]} offers no service {parts[-1]!r}"]
    if kind != offered:
        return [f"ros2 service call {name} {kind}: the service's type is {offered}"]
    if not _installed(kind):
        return [f"ros2 service call {name} {kind}: that type is not installed"]
    return []


def _installed(kind: str) -> bool:
    """Whether the ROS type ``pkg/srv|msg|action/Type`` is installed here."""
    package, group, type_name = kind.split("/")
    try:
        getattr(importlib.import_module(f"{package}.{group}"), type_name)
    except (ImportError, AttributeError):
        return False
    return True


def _interface(kind: str) -> list[str] | None:
    """``ros2 interface show pkg/kind/Type``: one of winder_interfaces', installed."""
    if not kind.startswith("winder_interfaces/"):
        return None
    if kind.count("/") != 2 or not _installed(kind):
        return [f"ros2 interface show {kind}: winder_interfaces has no such type"]
    return []


def _action(name: str, kind: str, goal: str = "") -> list[str] | None:
    """``ros2 action send_goal`` to the cell's Wind action: its name and type,
    and the goal's overrides, each a setting of the interp node in range."""
    from winder.contract.params import interp_setting

    if not name.rstrip("/").endswith("winder/wind"):
        return None
    found = _interface(kind) or []
    if kind != "winder_interfaces/action/Wind":
        found.append(f"ros2 action send_goal {name}: the action's type is winder_interfaces/action/Wind")
    for item in re.findall(r"'([^']*)'", goal.partition("overrides:")[2]):
        if "$" in item:
            continue  # the reader's own path
        try:
            interp_setting(item, "overrides")
        except SpecError as exc:
            found.append(f"ros2 action send_goal {name}: {exc}")
    return found


def _make(args: list[str]) -> list[str]:
    targets = set(re.findall(r"^([\w-]+):", (ROOT / "Makefile").read_text(), re.M))
    wanted = [a for a in args if not a.startswith("-") and "=" not in a]
    return [f"make {t}: the Makefile has no target {t!r}" for t in wanted if t not in targets]


def _pytest(args: list[str]) -> list[str]:
    parser = argparse.ArgumentParser(add_help=False)
    for option in ("-k", "-m", "-p", "-n"):
        parser.add_argument(option)
    _, rest = parser.parse_known_args(args)
    paths = [a.split("::", 1)[0] for a in rest if not a.startswith("-")]
    return [f"pytest {p}: no such test path" for p in paths if not (ROOT / p).exists()]
