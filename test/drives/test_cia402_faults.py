"""A drive's fault mid-run, at the node: the real ``cia402_node``, profile
and interp node processes over DDS on a virtual-bus drives file (the node
serves a twin per axis in its own process), the fault injected into one twin
by the drives file's ``twin_fault`` (an EMCY, a jammed motor that the twin's
own following-error monitoring faults, a heartbeat that stops), and the bag
read back.

For each: the run closes incomplete mid-job; the final report's ``faults``
and the node's ERROR say, in one line, the drive, the object and the reason
(the lines of docs/DRIVES.md's fault table); the bag is readable; every twin
ended its quick stop at rest (or, the faulted one, its fault reaction), as
the twins report themselves; and the same node takes the next run and winds
it to the end (the fault reset at its bring-up)."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import Procs, closed_bags
from support import wait

from winder.cli.exits import EXIT_FAILED, EXIT_OK
from winder.record.reader import read_run

pytestmark = pytest.mark.ros

WINDER = Path(sys.executable).with_name("winder")
#: 40 turns of 1024 fork steps at 4096 steps/s: some 10 s paced, 2500 SYNCs of 4 ms
LONG = ("--set", "turns_per_layer=40", "--set", "layers=1", "--set", "poles=1")
#: the next run: 4 turns
SMALL = ("--set", "turns_per_layer=4", "--set", "layers=1", "--set", "poles=1")
#: the SYNC the fault comes at: some 2 s into the first run (its bring-up takes a few SYNCs)
AT_SYNC = 500

DRIVES = """\
bus: {{interface: virtual, channel: faults}}
sync_period: 0.004
sdo_timeout: 0.5
twin_fault: {{axis: {axis}, at_sync: {at_sync}, fault: {fault}}}
axes:
  feed:
    node_id: 1
    eds: twin
    counts_per_unit: 1.0e7
    mode: 8
    following_error: {{window: 20000, time: 20}}
    heartbeat: {{producer: 50, timeout: 300}}
  fork:
    node_id: 2
    eds: twin
    counts_per_unit: 1000
    mode: 8
    following_error: {{window: 2000, time: 20}}
    heartbeat: {{producer: 50, timeout: 300}}
  pole:
    node_id: 3
    eds: twin
    counts_per_unit: 1000
    mode: 8
    following_error: {{window: 20000, time: 20}}
    heartbeat: {{producer: 50, timeout: 300}}
"""

#: (axis, fault, the one line of docs/DRIVES.md's fault table: its start, its end)
CASES = {
    "emcy": (
        "pole",
        "0x2310",
        "pole drive (node 3): EMCY 0x2310 (continuous overcurrent); every axis quick-stopped",
        "",
    ),
    "following error": (
        "fork",
        "jam",
        "fork drive (node 2): EMCY 0x8611 (following error); every axis quick-stopped",
        "",
    ),
    "heartbeat lost": (
        "feed",
        "heartbeat",
        "feed drive (node 1): heartbeat lost (none for ",
        " s, timeout 0.3 s); every axis quick-stopped",
    ),
}


def ctl(procs: Procs, *words: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(WINDER), "ctl", *words], env=procs.env, capture_output=True, text=True, timeout=180
    )


@pytest.mark.parametrize("case", list(CASES))
def test_a_drive_fault_mid_run_stops_every_axis_and_the_next_run_goes(
    procs: Procs, tmp_path: Path, case: str
) -> None:
    axis, fault, starts, ends = CASES[case]
    drives = tmp_path / "drives.yaml"
    drives.write_text(DRIVES.format(axis=axis, at_sync=AT_SYNC, fault=fault))
    bags = tmp_path / "bags"
    node = procs.start(
        "cia402_node", "-p", f"drives_file:={drives}", "-p", f"bag_dir:={bags}", "-p", "real_time:=true"
    )
    procs.start("profile_node", "-p", "v_max:=4096.0")
    procs.start("interp_node", "-p", "autostart:=false")

    first = ctl(procs, "start", *LONG, "--wait", "--timeout", "60")
    assert first.returncode == EXIT_FAILED, first.stdout + first.stderr
    [bag] = closed_bags(bags)
    run = read_run(bag)  # readable, closed, the run's report in it
    assert run.closed and run.report["state"] == "incomplete", run.report
    line = run.report["faults"]
    assert line.startswith(starts) and line.endswith(ends) and "\n" not in line, line
    assert 0 < int(run.report["steps_done"]) < run.plan.total_steps  # mid-run: stopped short
    # the node's ERROR, the same line
    errors = [ln for ln in procs.log(node).splitlines() if "ERROR" in ln and line in ln]
    assert errors and errors[0].endswith(f"{line}; the run stops"), procs.log(node)[-3000:]
    # every twin at rest: a quick stop ended (option 2: then disabled), the faulted drive's fault reaction
    twins = ast.literal_eval(run.report["twin_states"])
    for name, state in twins.items():
        if name == axis and fault != "heartbeat":
            assert state == "FAULT (from FAULT REACTION ACTIVE)", (name, state)
        else:
            assert state == "SWITCH ON DISABLED (from QUICK STOP ACTIVE)", (name, state)

    # the next run: the same node, its drives brought up again (the fault reset first), done
    second = ctl(procs, "start", *SMALL, "--wait", "--timeout", "60")
    assert second.returncode == EXIT_OK, second.stdout + second.stderr
    wait.until(lambda: len(closed_bags(bags)) == 2, 30, "the second run's bag closed", heard=lambda: bags)
    [again] = [b for b in closed_bags(bags) if b != bag]
    run2 = read_run(again)
    assert run2.complete and "faults" not in run2.report, run2.report
    assert run2.report["steps_done"] == str(run2.plan.total_steps)
    assert node.poll() is None


def start_cell(procs: Procs, tmp_path: Path, twin_fault: str) -> tuple[subprocess.Popen[bytes], Path]:
    """The node on the faults drives file with this ``twin_fault``, and the profile and interp nodes."""
    drives = tmp_path / "drives.yaml"
    text = DRIVES.format(axis="feed", at_sync=1, fault="jam")
    drives.write_text(text.replace("twin_fault: {axis: feed, at_sync: 1, fault: jam}", twin_fault))
    bags = tmp_path / "bags"
    node = procs.start(
        "cia402_node", "-p", f"drives_file:={drives}", "-p", f"bag_dir:={bags}", "-p", "real_time:=true"
    )
    procs.start("profile_node", "-p", "v_max:=4096.0")
    procs.start("interp_node", "-p", "autostart:=false")
    return node, bags


def one_new_bag(bags: Path, known: list[Path]) -> Path:
    wait.until(
        lambda: len(closed_bags(bags)) == len(known) + 1, 30, "the run's bag closed", heard=lambda: bags
    )
    [bag] = [b for b in closed_bags(bags) if b not in known]
    return bag


def assert_said_once(procs: Procs, node: subprocess.Popen[bytes], line: str) -> None:
    """The node's ERROR is the run's one line, and nothing it logged is a traceback."""
    log = procs.log(node)
    errors = [ln for ln in log.splitlines() if "ERROR" in ln and line in ln]
    assert errors and errors[0].endswith(f"{line}; the run stops"), log[-3000:]
    assert "Traceback" not in log and "Exception in thread" not in log, log[-3000:]


def test_an_sdo_not_answered_at_bring_up_fails_the_run_before_it_moves(procs: Procs, tmp_path: Path) -> None:
    """A drive whose SDO server hangs (``twin_fault: sdo``, from the first SYNC of the
    first run, which needs no SDO after its bring-up): the next run's bring-up fails
    on its first SDO, the run closes incomplete before any step with the axis, the
    node, the object and the timeout in one line; the drives were quick-stopped by
    SDO, never enabled; the node takes the run after, the drive answering again."""
    node, bags = start_cell(procs, tmp_path, "twin_fault: {axis: feed, at_sync: 1, fault: sdo}")
    first = ctl(procs, "start", *SMALL, "--wait", "--timeout", "60")
    assert first.returncode == EXIT_OK, first.stdout + first.stderr
    done = [one_new_bag(bags, [])]

    second = ctl(procs, "start", *SMALL, "--wait", "--timeout", "60")
    assert second.returncode == EXIT_FAILED, second.stdout + second.stderr
    bag = one_new_bag(bags, done)
    run = read_run(bag)  # readable, closed, the run's report in it
    assert run.closed and run.report["state"] == "incomplete", run.report
    line = (
        "feed drive (node 1): SDO read of 0x6502 not answered within 0.5 s (sdo_timeout); "
        "every axis quick-stopped"
    )
    assert run.report["faults"] == line
    assert run.report["steps_done"] == "0" and len(run.states.t) == 0  # nothing commanded, nothing moved
    assert_said_once(procs, node, line)
    # the quick stop by SDO (the drives pre-operational) took each from SWITCHED ON, where the
    # first run left it, to SWITCH ON DISABLED: none was enabled for this run
    twins = ast.literal_eval(run.report["twin_states"])
    assert twins == dict.fromkeys(("feed", "fork", "pole"), "SWITCH ON DISABLED (from SWITCHED ON)")

    third = ctl(procs, "start", *SMALL, "--wait", "--timeout", "60")
    assert third.returncode == EXIT_OK, third.stdout + third.stderr
    run3 = read_run(one_new_bag(bags, [*done, bag]))
    assert run3.complete and run3.report["steps_done"] == str(run3.plan.total_steps), run3.report
    assert node.poll() is None


def test_the_bus_unplugged_mid_run_closes_it_and_the_next_run_opens_it_again(
    procs: Procs, tmp_path: Path
) -> None:
    """The master's bus shut down under it mid-run (``twin_fault: unplugged``: as an
    adapter pulled out, python-can raises on send and receive): the run closes
    incomplete mid-job naming the bus and the reason in one line, which says the
    quick stop could not go out on it; the bag is readable; no traceback; the twins,
    which nothing reached, hold enabled; the node opens the bus again for the next
    run, which winds to the end."""
    node, bags = start_cell(procs, tmp_path, f"twin_fault: {{at_sync: {AT_SYNC}, fault: unplugged}}")
    first = ctl(procs, "start", *LONG, "--wait", "--timeout", "60")
    assert first.returncode == EXIT_FAILED, first.stdout + first.stderr
    bag = one_new_bag(bags, [])
    run = read_run(bag)
    assert run.closed and run.report["state"] == "incomplete", run.report
    line = "bus virtual faults: Cannot operate on a closed bus; the quick stop could not be completed on it"
    assert run.report["faults"] == line
    assert 0 < int(run.report["steps_done"]) < run.plan.total_steps  # mid-run: stopped short
    assert_said_once(procs, node, line)
    twins = ast.literal_eval(run.report["twin_states"])
    assert twins == dict.fromkeys(("feed", "fork", "pole"), "OPERATION ENABLED (from SWITCHED ON)")

    second = ctl(procs, "start", *SMALL, "--wait", "--timeout", "60")
    assert second.returncode == EXIT_OK, second.stdout + second.stderr
    run2 = read_run(one_new_bag(bags, [bag]))
    assert run2.complete and run2.report["steps_done"] == str(run2.plan.total_steps), run2.report
    assert "the bus is opened again" in procs.log(node)
    assert node.poll() is None
