"""The emergency stop of :class:`winder.drives.Cia402Backend` (the node's
``~/estop``) on three drive twins: every axis quick-stopped then disabled,
the run's fault "emergency stop", the twins' positions held afterwards (the
bus' SYNCs go on, the motors do not move), and the next run brought up again."""

from __future__ import annotations

import canopen
import numpy as np
import pytest
from support import wait
from test_backend import expected_counts, rig, run_start  # noqa: F401  (rig: the fixture)
from twin_rig import channel_fixture, master_fixture, twins_fixture  # noqa: F401  (fixtures: a virtual bus, twins on it)

from winder.drives import Cia402Backend


def test_estop_mid_run_stops_and_holds_every_axis(rig, master: canopen.Network) -> None:  # noqa: F811
    backend: Cia402Backend = rig["backend"]()
    backend.begin(run_start())
    rows = np.array([[t * 1_000_000, 0, t, 2 * t, t] for t in range(1, 200)], np.int64)
    backend.write(int(rows[99, 0]), rows[:100])
    assert backend.fault() == ""
    twins = rig["twins"]
    assert all(twins[n].velocity != 0.0 for n in (1, 2, 3))  # moving when the stop comes
    assert backend.estop() == "every axis quick-stopped"  # what ~/estop answers
    assert backend.fault() == "emergency stop; every axis quick-stopped"
    for n, twin in twins.items():
        assert twin.state == "SWITCH ON DISABLED", n  # quick stop option 2: decelerated, then disabled
        assert twin.demand_v == 0.0, n

    def settled() -> list[int]:
        """The positions, once 20 SYNCs more leave them as they were (the motors ring out)."""
        before = [twins[n].position_actual for n in (1, 2, 3)]
        count = twins[1].sync_count
        for _ in range(20):
            master.sync.transmit()
        wait.until(lambda: twins[1].sync_count >= count + 20, 10, "the twins stepped on the SYNCs")
        after = [twins[n].position_actual for n in (1, 2, 3)]
        return after if after == before else []

    held = wait.until(settled, 30, "the axes at rest after the quick stop")
    for _ in range(5):  # and there they stay, the bus going on
        assert settled() == held
    for i, n in enumerate((1, 2, 3)):  # stopped short of the run's end, not carried on to it
        assert abs(held[i]) < abs(expected_counts(rows[-1, 2:], i)[i]) * 0.75, n
    executed = backend.total_syncs
    backend.write(int(rows[-1, 0]), rows[100:])  # nothing more goes out after the stop
    assert backend.total_syncs == executed
    backend.begin(run_start())  # the next run: brought up again where the axes stand
    assert backend.fault() == ""
    assert [twins[n].state for n in (1, 2, 3)] == ["OPERATION ENABLED"] * 3


@pytest.mark.parametrize("homing", [False, True], ids=["idle", "homing configured"])
def test_home_is_a_step_of_its_own(rig, homing: bool) -> None:  # noqa: F811
    """Homing before the run (the node calls it at its start): the drives are
    left SWITCHED ON, and begin() does not home again."""
    extra = {"fork": {"homing": "{method: 35, offset: 500}"}} if homing else {}
    backend: Cia402Backend = rig["backend"](**extra)
    backend.home()
    twins = rig["twins"]
    assert [twins[n].state for n in (1, 2, 3)] == ["SWITCHED ON"] * 3
    assert twins[2].position_actual == (500 if homing else 0)
    rows = np.array([[t * 4_000_000, 0, 0, t, 0] for t in range(1, 20)], np.int64)
    backend.begin(run_start())
    backend.write(int(rows[-1, 0]), rows)
    moved = twins[2].position_actual
    home = 500 if homing else 0
    assert abs(moved - home) > 100  # it went 19 steps (186 counts) from home
    backend.begin(run_start())  # a second run: the fork is not homed again (homing 35 would set 500)
    assert abs(twins[2].position_actual - moved) < 30  # where it stood, its motor ringing out


def test_estop_on_a_lost_bus_says_the_stop_did_not_go_out(rig, channel: str) -> None:  # noqa: F811
    """The adapter unplugged, then the emergency stop: it answers that the
    quick stop could not be completed and why, not "every axis quick-stopped"
    (what ``winder ctl estop`` prints), and the run's fault says the same."""
    backend: Cia402Backend = rig["backend"]()
    backend.begin(run_start())
    rows = np.array([[t * 1_000_000, 0, t, 2 * t, t] for t in range(1, 200)], np.int64)
    backend.write(int(rows[99, 0]), rows[:100])
    backend.network.bus.shutdown()  # unplugged, nothing sent since
    said = backend.estop()
    assert said.startswith("the quick stop could not be completed: bus virtual"), said
    assert "closed bus" in said, said
    assert backend.fault() == f"emergency stop; {said}"
