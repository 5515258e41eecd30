"""Cia402Backend on three drive twins: the bring-up, a step stream executed
exactly (every SYNC's targets watched on the bus), and the faults that stop
every axis with a one-line reason. The backend opens its own bus from the
drives file (python-can's virtual interface, a channel per test)."""

from __future__ import annotations

import math
import struct
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import can
import canopen
import numpy as np
import pytest
from support import wait
from twin_rig import channel_fixture, twins_fixture  # noqa: F401  (fixtures: a virtual bus, twins on it)

from winder.drives import Cia402Backend, DriveError, SimulatedDrive, load_drives
from winder.motion.axes import AXIS_TABLE
from winder.ros.driver import Backend, RunStart

#: joint units per step (feed m, fork rad, pole rad), as a job would have them
JOINT_STEP = (1e-5, 2 * math.pi / 3200, 2 * math.pi / 1600)
#: the drives file's counts per joint unit; counts per step: 100, 9.8174..., 11.99...
COUNTS_PER_UNIT = (1e7, 5000.0, 3054.0)
DIRECTION = (1, -1, 1)
PERIOD_NS = 4_000_000


def drives_yaml(channel: str, **extra: dict[str, str]) -> str:
    """A drives file for nodes 1-3 on ``channel``; ``extra``: settings per axis (name -> YAML value)."""
    text = f"bus: {{interface: virtual, channel: {channel}}}\nsync_period: 0.004\nsdo_timeout: 0.5\naxes:\n"
    for i, axis in enumerate(AXIS_TABLE):
        settings = {
            "node_id": str(i + 1),
            "eds": "twin",
            "counts_per_unit": str(COUNTS_PER_UNIT[i]),
            "direction": str(DIRECTION[i]),
            "mode": "8",
            "following_error": "{window: 5000, time: 10}",
            "heartbeat": "{producer: 20, timeout: 200}",
            **extra.get(axis.name, {}),
        }
        text += f"  {axis.name}:\n" + "".join(f"    {k}: {v}\n" for k, v in settings.items())
    return text


def run_start(settings: dict[str, Any] | None = None) -> RunStart:
    values = {"real_time": False, "require_homing": False, **(settings or {})}
    return RunStart("job", "run", AXIS_TABLE, JOINT_STEP, np.zeros(3, np.int64), 1000, values)


class RpdoWatch(can.Listener):
    """Every RPDO1 target (0x607A, bytes 2-5) each node is sent, and the SYNCs, in bus order;
    and every RPDO1 with its controlword (0x6040, bytes 0-1)."""

    def __init__(self) -> None:
        self.frames: list[tuple[int, int]] = []  # (node, target) or (0, 0) for a SYNC
        self.rpdos: list[tuple[int, int, int]] = []  # (node, controlword, target)

    def on_message_received(self, msg: can.Message) -> None:
        if msg.arbitration_id == 0x80:
            self.frames.append((0, 0))
        elif 0x201 <= msg.arbitration_id <= 0x203:
            word, target = struct.unpack_from("<Hi", msg.data)
            self.frames.append((msg.arbitration_id - 0x200, target))
            self.rpdos.append((msg.arbitration_id - 0x200, word, target))

    def syncs(self) -> int:
        return sum(1 for node, _ in list(self.frames) if not node)

    def targets_at_syncs(self) -> dict[int, list[int]]:
        """Each node's target in force at each SYNC."""
        out: dict[int, list[int]] = {1: [], 2: [], 3: []}
        last: dict[int, int] = {}
        for node, target in self.frames:
            if node:
                last[node] = target
            else:
                for n in out:
                    out[n].append(last[n])
        return out


@pytest.fixture
def rig(tmp_path: Path, channel: str, twins) -> Iterator[dict[str, Any]]:
    for node in (1, 2, 3):
        twins.add(node)
    bus = can.Bus(interface="virtual", channel=channel)
    watch = RpdoWatch()
    notifier = can.Notifier(bus, [watch], timeout=0.05)
    made: list[Cia402Backend] = []

    def backend(**extra: dict[str, str]) -> Cia402Backend:
        path = tmp_path / "drives.yaml"
        path.write_text(drives_yaml(channel, **extra))
        b = Cia402Backend(path)
        made.append(b)
        return b

    yield {"backend": backend, "twins": twins.drives, "watch": watch}
    for b in made:
        b.close()
    notifier.stop()
    bus.shutdown()


def stream() -> np.ndarray:
    """Rows [t_ns, segment, feed, fork, pole]: steps at uneven times, several within
    one SYNC period, reversals, one axis still while the others move."""
    rows, pos, t = [], [0, 0, 0], 0
    rng = np.random.default_rng(7)
    for k in range(400):
        t += int(rng.integers(200_000, 1_500_000))
        axis = k % 3
        pos[axis] += 1 if (k // 60) % 3 != 2 or axis == 2 else -1
        rows.append([t, k // 100, *pos])
    return np.array(rows, np.int64)


def expected_counts(steps: np.ndarray, i: int) -> np.ndarray:
    """The drives file's rule: counts = direction * round(steps * joint_step * counts_per_unit)."""
    return DIRECTION[i] * np.round(steps * JOINT_STEP[i] * COUNTS_PER_UNIT[i]).astype(np.int64)


def test_backend_is_a_winder_backend(rig) -> None:
    assert isinstance(rig["backend"](), Backend)


@pytest.mark.parametrize("real_time", [False, True], ids=["as-fast-as-possible", "paced"])
def test_three_twins_execute_the_stream_exactly(rig, real_time: bool) -> None:
    backend = rig["backend"]()
    rows = stream()
    config = backend.begin(run_start({"real_time": real_time}))
    assert config["axes"]["fork"]["counts_per_step"] == pytest.approx(JOINT_STEP[1] * COUNTS_PER_UNIT[1])
    bring_up = backend.total_syncs  # the SYNCs of the bring-up come first on the bus
    for chunk in np.array_split(rows, 37):  # as a node hands rows over: in bundles, each due by its last
        backend.write(int(chunk[-1, 0]), chunk)
        assert backend.fault() == ""
    end_ns = int(rows[-1, 0]) + 200_000_000  # the settling: SYNCs go on, the targets held
    positions = backend.read(end_ns)
    assert backend.fault() == ""
    # each SYNC k (at k * 4 ms of run time) carried the counts of the last row due by then
    grid = np.arange(0, end_ns + 1, PERIOD_NS)
    watch = rig["watch"]
    wait.until(
        lambda: watch.syncs() == backend.total_syncs, 5, "every SYNC seen on the bus", heard=watch.syncs
    )
    sent = {node: targets[bring_up:] for node, targets in watch.targets_at_syncs().items()}
    for i in range(3):
        due = np.searchsorted(rows[:, 0], grid, side="right") - 1
        steps = np.where(due >= 0, rows[np.maximum(due, 0), 2 + i], 0)
        assert sent[i + 1] == expected_counts(steps, i).tolist(), AXIS_TABLE[i].name
    final = (
        expected_counts(rows[-1, 2:], 0)[0],
        expected_counts(rows[-1, 2:], 1)[1],
        expected_counts(rows[-1, 2:], 2)[2],
    )
    assert [rig["twins"][n].position_actual for n in (1, 2, 3)] == list(final)
    assert positions == pytest.approx(rows[-1, 2:], abs=0.5 / min(np.abs(expected_counts(np.ones(3), 1))))
    backend.end()
    assert [rig["twins"][n].state for n in (1, 2, 3)] == ["SWITCHED ON"] * 3


def test_homing_before_the_run(rig) -> None:
    backend = rig["backend"](fork={"homing": "{method: 35, offset: 500}"})
    backend.begin(run_start())
    assert rig["twins"][2].position_actual == 500  # home where it stood
    assert rig["twins"][2].mode == 8  # back to the run's mode
    with pytest.raises(DriveError, match="require_homing: the drives file has no homing for feed, pole"):
        backend.begin(run_start({"require_homing": True}))


def test_a_drive_in_fault_is_reset_at_bring_up(rig) -> None:
    rig["twins"][3].inject_fault(0x4210)
    backend = rig["backend"]()
    said: list[str] = []
    backend.log = said.append
    backend.begin(run_start())
    assert rig["twins"][3].state == "OPERATION ENABLED"
    assert said == [
        "pole drive (node 3) is in FAULT, 0x603F = 0x4210 (drive temperature too high): fault reset"
    ]


def assert_every_axis_stopped(rig, reason: str, backend: Cia402Backend) -> None:
    text = backend.fault()
    assert text == f"{reason}; every axis quick-stopped"
    assert "\n" not in text
    for node, twin in rig["twins"].items():
        assert twin.state in ("SWITCH ON DISABLED", "FAULT"), node
        assert twin.demand_v == 0.0, node


def test_following_error_stops_every_axis(rig) -> None:
    backend = rig["backend"](fork={"following_error": "{window: 50, time: 2}"})
    backend.begin(run_start())
    rows = np.array([[t * 1_000_000, 0, t // 4, 40 * t, t // 4] for t in range(1, 100)], np.int64)
    backend.write(int(rows[-1, 0]), rows)  # the fork: 40 steps (393 counts) a ms: no motor follows
    assert_every_axis_stopped(rig, "fork drive (node 2): EMCY 0x8611 (following error)", backend)
    assert rig["twins"][2].state == "FAULT"
    assert rig["twins"][2].error_code == 0x8611
    executed = backend.total_syncs
    backend.write(int(rows[-1, 0]) + 100_000_000, rows[-1:])  # nothing more goes out after a fault
    assert backend.total_syncs == executed
    # the next run: the fork's fault is reset at its bring-up, and the run starts where the axes stand
    backend.begin(run_start())
    assert backend.fault() == ""
    assert [rig["twins"][n].state for n in (1, 2, 3)] == ["OPERATION ENABLED"] * 3
    assert backend.read(0) == pytest.approx([0, 0, 0], abs=1e-9)


def test_emcy_stops_every_axis(rig) -> None:
    backend = rig["backend"]()
    backend.begin(run_start())
    rows = np.array([[t * 1_000_000, 0, t, t, t] for t in range(1, 60)], np.int64)
    backend.write(int(rows[29, 0]), rows[:30])
    assert backend.fault() == ""
    rig["twins"][3].inject_fault(0x2310)
    backend.write(int(rows[-1, 0]), rows[30:])
    assert_every_axis_stopped(rig, "pole drive (node 3): EMCY 0x2310 (continuous overcurrent)", backend)


def test_software_limit_stops_every_axis(rig) -> None:
    backend = rig["backend"](feed={"limits": "{min: -1000, max: 1000}"})
    backend.begin(run_start())
    rows = np.array([[t * 4_000_000, 0, t, 0, 0] for t in range(1, 30)], np.int64)  # feed: 100 counts a step
    backend.write(int(rows[-1, 0]), rows)
    assert backend.fault().startswith(
        "feed drive (node 1): internal limit active (statusword bit 11): target 1100"
    )
    assert_every_axis_stopped(rig, backend.fault().removesuffix("; every axis quick-stopped"), backend)


def test_heartbeat_lost_stops_every_axis(rig) -> None:
    backend = rig["backend"]()
    backend.begin(run_start())
    rig["twins"][1].stop_heartbeat()
    t = [0]

    def tick() -> str:
        t[0] += 10_000_000
        backend.read(t[0])
        return backend.fault()

    text = wait.until(tick, 5, "the heartbeat loss said")
    assert text.startswith("feed drive (node 1): heartbeat lost (none for ")
    assert text.endswith("timeout 0.2 s); every axis quick-stopped")


def test_a_drive_that_does_not_answer(rig) -> None:
    rig["twins"][2].stop()
    backend = rig["backend"]()
    with pytest.raises(DriveError) as err:
        backend.begin(run_start())
    assert str(err.value) == "fork drive (node 2): SDO read of 0x6502 not answered within 0.5 s (sdo_timeout)"
    # the quick stop went to every drive by SDO (none was operational): the silent one is named
    assert backend.fault() == (
        f"{err.value}; every axis quick-stopped but fork drive (node 2), which did not answer"
    )


def test_a_bus_lost_mid_run_is_said_and_the_next_run_opens_it_again(
    rig, channel: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The adapter unplugged mid-run (python-can raises on send and in the receive
    thread): the run's fault names the bus and says the quick stop could not go out;
    the receive thread ends without a traceback; the next run opens the bus again and
    brings the drives up where they stand."""
    died: list[Any] = []
    monkeypatch.setattr(threading, "excepthook", died.append)
    twins = rig["twins"]
    backend = rig["backend"]()
    backend.begin(run_start())
    rows = np.array([[t * 1_000_000, 0, t, t, t] for t in range(1, 200)], np.int64)
    backend.write(int(rows[99, 0]), rows[:100])
    backend.read(int(rows[99, 0]) + 200_000_000)  # SYNCs on, the targets held: the motors settle
    assert backend.fault() == ""
    old = backend.network
    old.bus.shutdown()  # unplugged
    backend.write(int(rows[99, 0]) + 400_000_000, rows[100:])
    assert backend.fault() == (
        f"bus virtual {channel}: Cannot operate on a closed bus; the quick stop could not be completed on it"
    )
    # nothing reached the drives after it: each holds its last target, enabled
    assert [twins[n].state for n in (1, 2, 3)] == ["OPERATION ENABLED"] * 3
    held = [twins[n].position_actual for n in (1, 2, 3)]
    wait.until(lambda: backend.bus_lost, 5, "the receive thread's error heard")

    def still_out(*_args: object, **_kwargs: object) -> None:
        raise can.CanOperationError("No such device")

    with pytest.MonkeyPatch.context() as m:  # the adapter still out: said, no run taken
        m.setattr(canopen.Network, "connect", still_out)
        assert backend.missing() == f"bus virtual {channel}: cannot be opened: No such device"
    # the next run: the bus opened again (the old one closed, its receive thread joined)
    assert backend.missing() == ""
    assert backend.network is not old
    assert died == []  # the old receive thread took the error and ended quietly
    backend.begin(run_start())
    assert backend.fault() == ""
    assert [twins[n].position_actual for n in (1, 2, 3)] == held  # brought up where they stand
    again = np.array([[t * 1_000_000, 0, t, t, t] for t in range(1, 50)], np.int64)
    backend.write(int(again[-1, 0]) + 100_000_000, again)
    assert backend.fault() == ""
    assert backend.read(0) == pytest.approx(again[-1, 2:], abs=0.1)


def test_a_drive_found_enabled_is_sent_its_own_place(rig) -> None:
    """A master started again (or a bus opened again) finds its drives enabled in
    CSP where the last one left them: its first RPDOs keep each drive enabled at its
    own position (read by SDO at the bring-up), never a target of its own making."""
    twins = rig["twins"]
    first = rig["backend"]()
    first.begin(run_start())
    rows = np.array([[t * 1_000_000, 0, 3 * t, 2 * t, t] for t in range(1, 100)], np.int64)
    first.write(int(rows[-1, 0]), rows)
    first.read(int(rows[-1, 0]) + 200_000_000)  # the motors settle on their last targets
    assert first.fault() == ""
    first.close()  # gone without a word: the drives stay enabled, holding
    assert [twins[n].state for n in (1, 2, 3)] == ["OPERATION ENABLED"] * 3
    where = {n: twins[n].position_actual for n in (1, 2, 3)}
    assert all(where.values())
    watch = rig["watch"]
    seen = len(watch.rpdos)
    second = rig["backend"]()
    second.begin(run_start())
    assert second.fault() == ""
    sent = watch.rpdos[seen:]
    assert sent, "no RPDO of the bring-up seen"
    for node, word, target in sent:
        assert (word, target) == (0x0F, where[node]), (node, hex(word), target)
    assert {n: twins[n].position_actual for n in (1, 2, 3)} == where


def test_the_twin_eds_is_the_drives_file_default(tmp_path: Path, channel: str) -> None:
    path = tmp_path / "drives.yaml"
    path.write_text(drives_yaml(channel))
    assert {d.eds for d in load_drives(path).axes} == {SimulatedDrive.EDS}
