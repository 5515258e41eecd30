"""The twins' fault hook: the drives file's ``twin_fault`` (a virtual bus
only, refused elsewhere in one line) and the twin's jammed motor, which the
twin's own following-error monitoring faults and a fault reset frees."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_backend import drives_yaml, rig, run_start  # noqa: F401  (rig: the fixture)
from twin_rig import channel_fixture, twins_fixture  # noqa: F401  (fixtures: a virtual bus, twins on it)

from winder.drives import Cia402Backend, DrivesFileError, load_drives
from winder.drives.config import TwinFault


def drives(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "drives.yaml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("given", "fault"), [("jam", "jam"), ("heartbeat", "heartbeat"), ("sdo", "sdo"), ("0x2310", 0x2310)]
)
def test_twin_fault_is_read_on_a_virtual_bus(tmp_path: Path, given: str, fault: object) -> None:
    text = drives_yaml("ch") + f"twin_fault: {{axis: fork, at_sync: 500, fault: {given}}}\n"
    assert load_drives(drives(tmp_path, text)).twin_fault == TwinFault("fork", 500, fault)  # type: ignore[arg-type]
    assert load_drives(drives(tmp_path, drives_yaml("ch"))).twin_fault is None


def test_unplugged_is_the_bus_not_a_twin(tmp_path: Path) -> None:
    text = drives_yaml("ch") + "twin_fault: {at_sync: 500, fault: unplugged}\n"
    assert load_drives(drives(tmp_path, text)).twin_fault == TwinFault("", 500, "unplugged")
    path = drives(tmp_path, text.replace("{at_sync", "{axis: fork, at_sync"))
    with pytest.raises(DrivesFileError) as err:
        load_drives(path)
    assert str(err.value) == (
        f"{path}: twin_fault.axis='fork' is invalid: must be absent for fault unplugged "
        "(the bus fails, no twin)"
    )


@pytest.mark.parametrize(
    ("change", "line"),
    [
        (
            ("interface: virtual", "interface: socketcan"),
            "twin_fault={'axis': 'fork', 'at_sync': 500, 'fault': 'jam'} is invalid: must be absent unless "
            "bus.interface is virtual (the twins' bus)",
        ),
        (
            ("axis: fork", "axis: spindle"),
            "twin_fault.axis='spindle' is invalid: must be one of feed, fork, pole",
        ),
        (
            ("axis: fork, ", ""),
            "twin_fault.axis is missing (required)",
        ),
        (
            ("at_sync: 500", "at_sync: 0"),
            "twin_fault.at_sync=0 is invalid: must be an integer in [1, 2147483647]",
        ),
        (
            ("fault: jam", "fault: melt"),
            "twin_fault.fault='melt' is invalid: must be jam, heartbeat, sdo, unplugged or an EMCY error "
            "code (0x1000-0xFFFF)",
        ),
        (
            ("fault: jam", "fault: 0x10"),
            "twin_fault.fault=16 is invalid: must be jam, heartbeat, sdo, unplugged or an EMCY error code "
            "(0x1000-0xFFFF)",
        ),
    ],
)
def test_a_bad_twin_fault_is_refused_in_one_line(tmp_path: Path, change: tuple[str, str], line: str) -> None:
    text = drives_yaml("ch") + "twin_fault: {axis: fork, at_sync: 500, fault: jam}\n"
    path = drives(tmp_path, text.replace(*change))
    with pytest.raises(DrivesFileError) as err:
        load_drives(path)
    assert str(err.value) == f"{path}: {line}"


def test_a_jammed_motor_is_a_following_error_and_a_fault_reset_frees_it(rig) -> None:  # noqa: F811
    backend: Cia402Backend = rig["backend"](fork={"following_error": "{window: 300, time: 10}"})
    twins = rig["twins"]
    backend.begin(run_start())
    rows = np.array([[t * 1_000_000, 0, t, t, t] for t in range(1, 400)], np.int64)
    backend.write(int(rows[99, 0]), rows[:100])
    assert backend.fault() == ""
    twins[2].jam()
    stuck = twins[2].position_actual
    backend.write(int(rows[-1, 0]), rows[100:])
    assert backend.fault() == "fork drive (node 2): EMCY 0x8611 (following error); every axis quick-stopped"
    assert twins[2].state == "FAULT" and twins[2].error_code == 0x8611
    assert twins[2].position_actual == stuck  # the motor never moved after the jam
    assert twins[2].came_from == "FAULT REACTION ACTIVE"  # the fault reaction ended, the demand at rest
    assert [twins[n].came_from for n in (1, 3)] == ["QUICK STOP ACTIVE"] * 2
    # the next run resets the fault: the motor free where it was blocked, and it follows again
    backend.begin(run_start())
    assert backend.fault() == ""
    assert twins[2].position_actual == stuck
    again = np.array([[t * 1_000_000, 0, 0, -t, 0] for t in range(1, 200)], np.int64)
    backend.write(int(again[-1, 0]) + 100_000_000, again)
    assert backend.fault() == ""
    moved = twins[2].position_actual - stuck
    # 199 steps down, the fork drive counting the other way (direction -1): counts up
    assert moved == pytest.approx(199 * backend.drives[1].counts_per_step, abs=2)
