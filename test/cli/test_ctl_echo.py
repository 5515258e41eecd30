"""`winder ctl echo`, `winder ctl interface show` and the Wind result of
`winder ctl start --wait`: ros2's everyday verbs on the pip install (issue 54,
item 4), against real node processes over DDS.

Oracles: the bag the run recorded (its final report, read with the reader,
not through DDS), the `.msg`/`.action` files of the repository's
winder_interfaces (read here line by line), and the exit-code table.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml
from conftest import Procs, closed_bags
from support.paths import ROOT

from winder.cli.exits import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK
from winder.record.reader import read_run

WINDER = Path(sys.executable).with_name("winder")
INTERFACES = ROOT / "winder_interfaces"
TINY = """\
interp_node:
  ros__parameters:
    job_id: tiny
    turns_per_layer: 4
    layers: 1
    poles: 1
    fork_steps_per_rev: 512
"""


def ctl(
    procs: Procs | None, *words: str, cwd: Path | None = None, timeout: float = 120
) -> tuple[int, str, str]:
    out = subprocess.run(
        [str(WINDER), "ctl", *words],
        env=procs.env if procs is not None else None,
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=cwd,
    )
    return out.returncode, out.stdout, out.stderr


def one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def blocks(out: str) -> list[dict[str, Any]]:
    """The messages `ros2 topic echo` prints: YAML blocks, each ended by a `---` line."""
    assert out.endswith("---\n"), out
    return [yaml.safe_load(b) for b in out.split("---\n")[:-1]]


# -- interface show: no cell needed ---------------------------------------------------------


def _fields(path: Path) -> list[str]:
    """A definition's lines without comments or blank lines (how a nested type is shown)."""
    lines = (ln.split("#", 1)[0].rstrip() for ln in path.read_text().splitlines())
    return [ln for ln in lines if ln]


def test_interface_show_prints_the_definition_and_expands_nested_types() -> None:
    code, out, err = ctl(None, "interface", "show", "winder_interfaces/msg/CellState")
    assert code == EXIT_OK, err
    text = (INTERFACES / "msg" / "CellState.msg").read_text().rstrip().splitlines()
    lines = out.rstrip("\n").splitlines()
    # the file's own lines, comments and all; its stamp's type expanded below it, a tab deeper
    stamp = text.index(next(ln for ln in text if ln.startswith("builtin_interfaces/Time stamp")))
    assert lines[: stamp + 1] == text[: stamp + 1], out
    assert lines[stamp + 1 : stamp + 3] == ["\tint32 sec", "\tuint32 nanosec"], out
    assert lines[stamp + 3 :] == text[stamp + 1 :], out
    # the action: its three parts, the result's report expanded from JobReport.msg, its
    # key-values a tab deeper again
    code, out, err = ctl(None, "interface", "show", "winder_interfaces/action/Wind")
    assert code == EXIT_OK, err
    lines = out.splitlines()
    assert lines.count("---") == 2, out
    at = lines.index("winder_interfaces/JobReport report")
    report = _fields(INTERFACES / "msg" / "JobReport.msg")
    shown = [ln for ln in lines[at + 1 :] if ln.startswith("\t") and not ln.startswith("\t\t")]
    assert shown[: len(report)] == ["\t" + ln for ln in report], out
    assert "\t\tstring key" in lines and "\t\tstring value" in lines, out


def test_interface_show_refuses_an_unknown_type_in_one_line() -> None:
    code, _, err = ctl(None, "interface", "show", "winder_interfaces/msg/NoSuchType")
    line = one_line(err)
    assert code == EXIT_BAD_INPUT and "NoSuchType" in line and "msg/CellState" in line, err
    code, _, err = ctl(None, "interface", "show", "no_such_package/msg/X")
    assert code == EXIT_BAD_INPUT and "no_such_package" in one_line(err), err
    code, _, err = ctl(None, "interface", "show", "CellState")
    assert code == EXIT_BAD_INPUT and "PACKAGE/KIND/NAME" in one_line(err), err


# -- echo and the Wind result: a real cell ---------------------------------------------------


@pytest.mark.ros
def test_echo_without_a_cell_ends_in_time_and_a_bad_name_at_once(procs: Procs) -> None:
    code, out, err = ctl(procs, "echo", "/winder/report", "--once", "--timeout", "2")
    assert code == EXIT_FAILED and out == "" and "/winder/report" in one_line(err), out + err
    code, _, err = ctl(procs, "echo", "winder//report", "--once")
    assert code == EXIT_BAD_INPUT and "winder//report" in one_line(err), err


@pytest.mark.ros
def test_a_finished_run_echoed_and_its_typed_result(procs: Procs, tmp_path: Path) -> None:
    """`ctl start --wait` prints the Wind goal's typed result; after the run,
    `echo /winder/report --once` prints the last report (a latched topic),
    `echo winder/state --once` the cell's typed state, and a topic that is
    not the cell's is read with its publishers' QoS (/rosout, kept by each
    node for a late reader: a volatile reader would wait for a new log line)."""
    bags = tmp_path / "bags"
    procs.start("sim_node", "-p", f"bag_dir:={bags}", "-r", "__ns:=/cell1")
    procs.start("profile_node", "-r", "__ns:=/cell1")
    procs.start("interp_node", "-p", "autostart:=false", "-r", "__ns:=/cell1")
    (tmp_path / "tiny.yaml").write_text(TINY)
    code, out, err = ctl(
        procs, "start", "tiny.yaml", "--wait", "--namespace", "/cell1", "--timeout", "60", cwd=tmp_path
    )
    assert code == EXIT_OK, out + err
    [bag] = closed_bags(bags)
    run = read_run(bag)
    # the result as ros2 action send_goal prints it: its fields under "Result:", then the status
    lines = out.splitlines()
    at = lines.index("Result:")
    end = lines.index("Goal finished with status: SUCCEEDED")
    result = yaml.safe_load("\n".join(ln.removeprefix("    ") for ln in lines[at + 1 : end]))
    assert result["success"] is True and result["run_id"] == run.plan.run_id, out
    assert result["bag_path"] == str(bag) and result["report"]["state"] == "done", out
    assert result["report"]["steps_done"] == int(run.report["steps_done"]) == run.plan.job.total_steps
    assert lines[-1] == f"run {run.plan.run_id}: done, bag {bag}", out

    # the last report, from the latched topic, long after it was sent
    code, out, err = ctl(procs, "echo", "/cell1/winder/report", "--once")
    assert code == EXIT_OK, err
    [report] = blocks(out)
    assert report["run_id"] == run.plan.run_id and report["state"] == "done", out
    assert report["bag"] == str(bag), out
    assert report["steps_done"] == int(run.report["steps_done"]), out
    assert set(report["stamp"]) == {"sec", "nanosec"}, out  # a nested message: its own block
    # a relative name, in the namespace; a typed message of winder_interfaces
    code, out, err = ctl(procs, "echo", "winder/state", "--once", "--namespace", "/cell1")
    assert code == EXIT_OK, err
    [state] = blocks(out)
    assert state["state"] == "done" and state["run_id"] == run.plan.run_id, out
    # not the cell's topic: its publishers keep their logs (transient-local), the reader too
    code, out, err = ctl(procs, "echo", "/rosout", "--once", "--timeout", "20")
    assert code == EXIT_OK, err
    [log] = blocks(out)
    assert {"stamp", "level", "name", "msg"} <= set(log), out
