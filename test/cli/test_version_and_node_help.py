"""The habits of a CLI and of a ROS package (issue 54, item 3), run as a user
runs them, from the venv's bin directory:

* ``winder --version`` prints ``winder <version>`` and exits 0; the version is
  the package's (its metadata says the same), and the one the parser's
  ``--version`` prints;
* every bag's metadata.yaml and every final report (the /diagnostics status
  and the typed ``winder/report``) carry it as ``winder_version``;
* each node executable answers ``-h`` and ``--help`` with its usage and
  every parameter its node declares, ``NAME:=DEFAULT`` one a line, and exits
  0 without starting a node (a node runs until it is stopped: the bounded
  wait below would end it and the test would fail).

The parameters expected are the tables the docs' command checker names for
each executable (``support.doc_commands.NODE_SPECS``), not the help's own.
"""

from __future__ import annotations

import importlib.metadata
import subprocess
import sys
from typing import Any

import pytest
import yaml
from conftest import final_report, rosbags_read
from support.doc_commands import NODE_SPECS
from support.paths import BIN

import winder
from winder.contract.params import CONSUMER_SPECS
from winder.ros.driver import DRIVER_SPECS
from winder.ros.mock_backend import MockBackend
from winder.spec import Spec

#: a help that has not come by then is a node running (it would run until killed)
HELP_TIMEOUT_S = 60.0

#: each node executable as a user starts it, and the parameters its node declares
EXECUTABLES: dict[str, tuple[list[str], dict[str, Spec]]] = {
    **{name: ([str(BIN / name)], specs) for name, (_, specs) in NODE_SPECS.items()},
    "mock driver": (
        [sys.executable, "-m", "winder.ros.mock_backend"],
        {**CONSUMER_SPECS, **DRIVER_SPECS, **MockBackend.specs},
    ),
}


def _run(argv: list[str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        argv, capture_output=True, text=True, timeout=HELP_TIMEOUT_S, stdin=subprocess.DEVNULL, check=False
    )


def test_winder_version_prints_the_packages_version() -> None:
    r = _run([str(BIN / "winder"), "--version"])
    assert (r.returncode, r.stdout, r.stderr) == (0, f"winder {winder.__version__}\n", "")
    assert importlib.metadata.version("winder") == winder.__version__  # the metadata reads the constant
    # the parser's --version (listed in `winder --help`) says the same
    parsed = _run([sys.executable, "-c", "from winder.cli.commands import main; main(['--version'])"])
    assert (parsed.returncode, parsed.stdout) == (0, r.stdout), parsed.stderr
    assert "--version" in _run([str(BIN / "winder"), "--help"]).stdout


def _shown(value: str, spec: Spec) -> Any:
    """A ``NAME:=VALUE`` value as ROS would take it, for comparing with a default."""
    if spec.kind is bool:
        return {"true": True, "false": False}.get(value, value)
    if isinstance(spec.default, (list, tuple)):
        return [v.strip() for v in value.strip("[]").split(",")] if value != "[]" else []
    if spec.kind is str:
        return value[1:-1] if value[:1] == value[-1:] == "'" and len(value) > 1 else value
    return float(value)


@pytest.mark.parametrize("option", ["-h", "--help"])
@pytest.mark.parametrize("executable", sorted(EXECUTABLES))
def test_a_node_executable_answers_help_with_its_parameters(executable: str, option: str) -> None:
    argv, specs = EXECUTABLES[executable]
    r = _run([*argv, option])
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stderr == "", r.stderr  # no node's log: none was started
    lines = r.stdout.splitlines()
    assert lines[0].startswith("usage: ") and "--ros-args" in lines[0], lines[0]
    assert "-p NAME:=VALUE" in r.stdout and "--params-file" in r.stdout
    listed = {}
    for line in lines:
        name, sep, rest = line.strip().partition(":=")
        if line.startswith("  ") and sep and " " not in name:
            listed[name] = rest.split("  ", 1)[0].strip()
    expected = {**specs, "managed": None}
    assert sorted(listed) == sorted(expected), r.stdout
    for name, spec in specs.items():
        want = [str(v) for v in spec.default] if isinstance(spec.default, (list, tuple)) else spec.default
        assert _shown(listed[name], spec) == want, f"{name}: {listed[name]!r}, default {spec.default!r}"
    assert listed["managed"] == "false"


def test_a_nodes_own_arguments_are_those_outside_its_ros_arguments() -> None:
    """rcl's rule: ROS arguments run from ``--ros-args`` to ``--`` or the end;
    a ``-h`` among them is ROS's (a value), not a request for the node's help."""
    from winder.ros.spin import own_arguments

    assert own_arguments(["x_node", "--ros-args", "-p", "job_id:=-h", "-r", "__ns:=/c"]) == []
    assert own_arguments(["x_node", "-h", "--ros-args", "-p", "a:=1"]) == ["-h"]
    assert own_arguments(["x_node", "--ros-args", "-p", "a:=1", "--", "--help", "--ros-args", "-h"]) == [
        "--help"
    ]


@pytest.mark.ros
def test_the_bag_and_the_final_report_name_the_winder_that_wrote_them(bag: Any) -> None:
    path = bag("lin2k")  # a real `winder run`, its bag as the sim node wrote it
    meta = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["custom_data"]["winder_version"] == winder.__version__, meta["custom_data"]
    read = rosbags_read(path)
    assert final_report(read)["winder_version"] == winder.__version__
    [(_, typed)] = read["/winder/report"]
    assert {kv.key: kv.value for kv in typed.extra}["winder_version"] == winder.__version__
