"""The drives file: each kind of bad value refused, in one line naming the
key, the value and the range, before any bus is opened."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import canopen
import pytest
from ruamel.yaml import YAML

from winder.drives import Cia402Backend, DrivesFileError, load_drives
from winder.drives.twin import EDS_PATH


def good() -> dict[str, Any]:
    axis = {
        "eds": "twin",
        "counts_per_unit": 1000.0,
        "mode": 8,
        "following_error": {"window": 2000, "time": 10},
        "limits": {"min": -100, "max": 100000},
        "quick_stop_option": 6,
        "homing": {"method": 35, "offset": 0, "speeds": {"switch": 1000, "zero": 100}, "timeout": 10},
        "heartbeat": {"producer": 100, "timeout": 500},
    }
    return {
        "bus": {"interface": "virtual", "channel": "never-opened", "bitrate": 500000},
        "sync_period": 0.004,
        "axes": {
            name: {**copy.deepcopy(axis), "node_id": i + 1} for i, name in enumerate(("feed", "fork", "pole"))
        },
    }


@pytest.fixture
def no_bus(monkeypatch: pytest.MonkeyPatch) -> None:
    """Opening a bus fails the test: every refusal must come before one."""

    def opened(*_args: object, **_kwargs: object) -> None:
        raise AssertionError("a bus was opened")

    monkeypatch.setattr(canopen.Network, "connect", opened)


def write(tmp_path: Path, doc: object) -> Path:
    path = tmp_path / "drives.yaml"
    with path.open("w") as f:
        YAML(typ="safe").dump(doc, f)
    return path


def test_a_good_file(tmp_path: Path, no_bus: None) -> None:
    cfg = load_drives(write(tmp_path, good()))
    assert [(d.axis, d.node_id, d.eds) for d in cfg.axes] == [
        ("feed", 1, EDS_PATH),
        ("fork", 2, EDS_PATH),
        ("pole", 3, EDS_PATH),
    ]
    assert cfg.bus.kwargs() == {"interface": "virtual", "channel": "never-opened", "bitrate": 500000}


def setting(doc: dict[str, Any], key: str, value: object) -> None:
    *path, last = key.split(".")
    for part in path:
        doc = doc[part]
    if value is DELETE:
        del doc[last]
    else:
        doc[last] = value


DELETE = object()

#: (key, bad value, the refusal's text after "<file>: ")
BAD = [
    (
        "bus.interface",
        "canbus9000",
        "bus.interface='canbus9000' is invalid: must be one of python-can's interfaces (",
    ),
    (
        "bus.channel",
        [1],
        "bus.channel=[1] is invalid: must be a channel name or number (can0, PCAN_USBBUS1, 0)",
    ),
    (
        "bus.bitrate",
        333333,
        "bus.bitrate=333333 is invalid: must be one of 10000, 20000, 50000, 125000, 250000,",
    ),
    ("bus.frobnicate", 1, "bus.frobnicate is not a setting: must be one of interface, channel, bitrate,"),
    (
        "bus.receive_own_messages",
        [True],
        "bus.receive_own_messages=[True] is invalid: must be a string, number",
    ),
    ("sync_period", 0.0001, "sync_period=0.0001 is invalid: must be a number in [0.0005, 0.1] s"),
    ("sync_period", 0.0041234, "sync_period=0.0041234 is invalid: must be a period 0x60C2 can hold"),
    ("sync_period", "4 ms", "sync_period='4 ms' is invalid: must be a number in [0.0005, 0.1] s"),
    ("sdo_timeout", 0, "sdo_timeout=0 is invalid: must be a number in (0, 10] s"),
    ("axes.spindle", {}, "axes.spindle is not a setting: must be one of feed, fork, pole"),
    ("axes.pole", DELETE, "axes.pole is missing (required)"),
    ("axes.feed.node_id", 128, "axes.feed.node_id=128 is invalid: must be an integer in [1, 127]"),
    ("axes.feed.node_id", True, "axes.feed.node_id=True is invalid: must be an integer in [1, 127]"),
    ("axes.fork.node_id", 1, "axes.fork.node_id=1 is invalid: must be unique (axes.feed has it too)"),
    (
        "axes.feed.eds",
        "nowhere.eds",
        "axes.feed.eds='nowhere.eds' is invalid: must be an EDS/DCF file that exists",
    ),
    (
        "axes.feed.counts_per_unit",
        0,
        "axes.feed.counts_per_unit=0 is invalid: must be a number in (0, 1e+12]",
    ),
    (
        "axes.feed.counts_per_unit",
        float("nan"),
        "axes.feed.counts_per_unit=nan is invalid: must be a number in",
    ),
    ("axes.feed.direction", 0, "axes.feed.direction=0 is invalid: must be 1 or -1"),
    (
        "axes.feed.mode",
        7,
        "axes.feed.mode=7 is invalid: must be 8 (cyclic synchronous position) or 1 (profile",
    ),
    ("axes.feed.following_error", DELETE, "axes.feed.following_error is missing (required)"),
    (
        "axes.feed.following_error.window",
        -1,
        "axes.feed.following_error.window=-1 is invalid: must be an integer in [0, 4294967295] counts",
    ),
    (
        "axes.feed.following_error.time",
        70000,
        "axes.feed.following_error.time=70000 is invalid: must be an integer in [0, 65535] ms",
    ),
    (
        "axes.feed.limits.min",
        2**31,
        "axes.feed.limits.min=2147483648 is invalid: must be an integer in [-2147483648, 2147483647] counts",
    ),
    ("axes.feed.limits.max", -100, "axes.feed.limits.max=-100 is invalid: must be above limits.min (-100)"),
    (
        "axes.feed.quick_stop_option",
        3,
        "axes.feed.quick_stop_option=3 is invalid: must be one of 0, 1, 2, 5, 6",
    ),
    ("axes.feed.homing.method", 36, "axes.feed.homing.method=36 is invalid: must be a CiA 402 homing method"),
    ("axes.feed.homing.offset", 1.5, "axes.feed.homing.offset=1.5 is invalid: must be an integer in"),
    (
        "axes.feed.homing.speeds.zero",
        0,
        "axes.feed.homing.speeds.zero=0 is invalid: must be an integer in [1, 4294967295] counts/s",
    ),
    ("axes.feed.homing.timeout", 0, "axes.feed.homing.timeout=0 is invalid: must be a number in (0, 600] s"),
    (
        "axes.feed.heartbeat.producer",
        -5,
        "axes.feed.heartbeat.producer=-5 is invalid: must be an integer in [0, 65535] ms (0: none)",
    ),
    (
        "axes.feed.heartbeat.timeout",
        100,
        "axes.feed.heartbeat.timeout=100 is invalid: must be longer than heartbeat.producer (100 ms)",
    ),
    (
        "axes.feed.profile",
        {"velocity": 0},
        "axes.feed.profile.velocity=0 is invalid: must be an integer in [1, 4294967295]",
    ),
    ("axes.feed.node", 1, "axes.feed.node is not a setting: must be one of node_id, eds,"),
]


#: test ids the same in every pytest worker (DELETE's repr holds its address)
BAD_IDS = [f"{k}=deleted" if v is DELETE else f"{k}={v!r}" for k, v, _ in BAD]


@pytest.mark.parametrize(("key", "value", "said"), BAD, ids=BAD_IDS)
def test_each_bad_value_is_refused_before_the_bus(
    tmp_path: Path, no_bus: None, key: str, value: object, said: str
) -> None:
    doc = good()
    setting(doc, key, value)
    path = write(tmp_path, doc)
    with pytest.raises(DrivesFileError) as err:
        Cia402Backend(path)
    text = str(err.value)
    assert text.startswith(f"{path}: {said}"), text
    assert "\n" not in text


def test_an_eds_without_the_objects_used(tmp_path: Path, no_bus: None) -> None:
    eds = Path(EDS_PATH).read_text()
    lean = eds.replace("[60F4]", "[60F4_removed]")
    (tmp_path / "lean.eds").write_text(lean)
    doc = good()
    doc["axes"]["fork"]["eds"] = "lean.eds"  # relative to the drives file
    path = write(tmp_path, doc)
    with pytest.raises(
        DrivesFileError,
        match=r"axes\.fork\.eds='.*lean\.eds' is invalid: must be the EDS of a "
        r"CiA 402 drive with the objects used \(it lacks 0x60F4\)$",
    ):
        Cia402Backend(path)


def test_not_yaml_and_not_a_file(tmp_path: Path, no_bus: None) -> None:
    path = tmp_path / "drives.yaml"
    path.write_text("bus: [unclosed\n")
    with pytest.raises(DrivesFileError, match=r"drives\.yaml: not YAML at line \d+: "):
        Cia402Backend(path)
    with pytest.raises(DrivesFileError, match=r"missing\.yaml: cannot be read: "):
        Cia402Backend(tmp_path / "missing.yaml")
    path.write_text("- a list\n")
    with pytest.raises(
        DrivesFileError, match=r"drives file=\['a list'\] is invalid: must be a mapping of bus,"
    ):
        Cia402Backend(path)


def test_the_package_is_ros_free() -> None:
    """``winder.drives`` imports neither rclpy nor anything of winder.ros (a later node holds it)."""
    import subprocess
    import sys

    code = (
        "import sys, winder.drives\n"
        "from winder.drives import Cia402Backend, SimulatedDrive\n"
        "bad = sorted(m for m in sys.modules if m.split('.')[0] == 'rclpy' or m.startswith('winder.ros'))\n"
        "print(bad)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    assert out.stdout.strip() == "[]"
