"""The drive twin against canopen's own CiA 402 client (``BaseNode402``): its
state machine, its modes, ``homing()``; and what a drive does besides:
software limits, following error, quick stop options, the PP handshake,
injected faults, heartbeat. Every wait is bounded by canopen's own timeouts
or by ``wait.until``."""

from __future__ import annotations

from collections.abc import Iterator

import canopen
import pytest
from canopen.profiles.p402 import BaseNode402
from canopen.sdo.exceptions import SdoCommunicationError
from support import wait
from twin_rig import channel_fixture, master_fixture, twins_fixture  # noqa: F401  (fixtures: a virtual bus, twins on it)

from winder.drives import SimulatedDrive

NODE = 5


@pytest.fixture
def node(twins, master: canopen.Network) -> Iterator[BaseNode402]:
    """Node 5, a twin, as canopen's BaseNode402 sees it: PDOs read by SDO in
    pre-operational, then operational with SYNC."""
    twins.add(NODE)
    node = BaseNode402(NODE, SimulatedDrive.EDS)
    # BaseNode402's own waits (0.2 s for a TPDO, 0.4 s for a transition) are what an idle
    # machine needs; the test machine is shared (load 15 seen): five times each
    for name in ("TIMEOUT_RESET_FAULT", "TIMEOUT_SWITCH_OP_MODE", "TIMEOUT_SWITCH_STATE_FINAL",
                 "TIMEOUT_SWITCH_STATE_SINGLE", "TIMEOUT_CHECK_TPDO"):  # fmt: skip
        setattr(node, name, 5 * getattr(BaseNode402, name))
    master.add_node(node)
    node.nmt.state = "PRE-OPERATIONAL"
    node.setup_402_state_machine(read_pdos=True)
    node.nmt.state = "OPERATIONAL"
    # SYNC every 10 ms: BaseNode402 takes the first TPDO after a controlword for its answer,
    # which holds while the twin is not a SYNC behind (a loaded machine can starve its thread)
    master.sync.start(0.01)
    node.check_statusword(timeout=1.0)
    yield node


def test_state_machine_every_state_basenode402_asks_for(node: BaseNode402, twins) -> None:
    twin = twins.drives[NODE]
    assert node.state == "SWITCH ON DISABLED"  # transition 1 is automatic at power-on
    node.sdo[0x605A].raw = 6  # quick stop: decelerate, then stay in QUICK STOP ACTIVE
    for target in (
        "READY TO SWITCH ON",  # 2
        "SWITCHED ON",  # 3
        "OPERATION ENABLED",  # 4
        "SWITCHED ON",  # 5
        "READY TO SWITCH ON",  # 6
        "OPERATION ENABLED",  # 3 + 4
        "READY TO SWITCH ON",  # 8
        "SWITCH ON DISABLED",  # 7
        "OPERATION ENABLED",
        "QUICK STOP ACTIVE",  # 11
        "OPERATION ENABLED",  # 16
        "QUICK STOP ACTIVE",
        "SWITCH ON DISABLED",  # 12
        "SWITCHED ON",
        "SWITCH ON DISABLED",  # 10
        "OPERATION ENABLED",
        "SWITCH ON DISABLED",  # 9
    ):
        node.state = target
        assert node.state == target
        assert twin.state == target


def test_op_modes_only_supported_ones_mirrored(node: BaseNode402) -> None:
    assert node.sdo[0x6502].raw == 0xA1  # PP, HM, CSP
    for mode in ("CYCLIC SYNCHRONOUS POSITION", "PROFILED POSITION", "HOMING"):
        node.op_mode = mode
        assert node.op_mode == mode
    with pytest.raises(TypeError):
        node.op_mode = "PROFILED VELOCITY"  # not in 0x6502: BaseNode402 refuses it itself
    node.sdo[0x6060].raw = 3  # written all the same: 0x6061 does not follow
    assert node.sdo[0x6061].raw == 6
    assert node.op_mode == "HOMING"


def test_homing_on_current_position(node: BaseNode402, twins) -> None:
    node.sdo[0x6098].raw = 35
    node.sdo[0x607C].raw = 1234
    node.state = "OPERATION ENABLED"
    assert node.homing(timeout=5, restore_op_mode=False)
    assert node.sdo[0x6064].raw == 1234
    assert node.statusword & 0x1400 == 0x1400  # attained, target reached
    node.controlword = 0x0F  # bit 4 low again: the next start is an edge
    node.sdo[0x6098].raw = 37
    node.sdo[0x607C].raw = -50
    assert node.homing(timeout=5)
    assert node.sdo[0x6064].raw == -50


def test_homing_on_the_home_switch(node: BaseNode402, twins) -> None:
    twin = twins.drives[NODE]
    assert twin.home_switch == 1000.0  # the switch is active above 1000 counts from power-on
    node.sdo[0x6098].raw = 19
    node.sdo[0x607C].raw = 0
    node.sdo[0x6099][1].raw = 50_000
    node.sdo[0x6099][2].raw = 2_000
    node.op_mode = "PROFILED POSITION"
    assert node.homing(timeout=10, restore_op_mode=True)
    assert node.op_mode == "PROFILED POSITION"
    # home is where the switch changed state, found coming back: the motor stands there
    assert 990 <= twin.position <= 1010
    wait.until(lambda: abs(node.sdo[0x6064].raw) <= 1, 2, "position actual at home (0x607C = 0)")


def test_homing_method_not_served_is_refused(node: BaseNode402) -> None:
    with pytest.raises(canopen.SdoAbortedError):
        node.sdo[0x6098].raw = 17


def test_csp_target_clamped_to_software_limits(node: BaseNode402, twins) -> None:
    twin = twins.drives[NODE]
    node.sdo[0x607D][1].raw = -100
    node.sdo[0x607D][2].raw = 300
    node.sdo[0x6065].raw = 0xFFFFFFFF  # following error monitoring off: the jump is allowed here
    node.op_mode = "CYCLIC SYNCHRONOUS POSITION"
    node.state = "OPERATION ENABLED"
    node.sdo[0x607A].raw = 250
    wait.until(lambda: node.sdo[0x6064].raw == 250, 2, "position 250 inside the limits")
    assert not node.statusword & 0x0800
    node.sdo[0x607A].raw = 5000
    wait.until(lambda: node.sdo[0x6064].raw == 300, 2, "position clamped at 300")
    assert node.sdo[0x6041].raw & 0x0800  # internal limit active
    assert twin.demand == 300


def test_following_error_faults_with_emcy_8611(node: BaseNode402, twins) -> None:
    node.sdo[0x6065].raw = 100
    node.sdo[0x6066].raw = 5
    node.op_mode = "CYCLIC SYNCHRONOUS POSITION"
    node.state = "OPERATION ENABLED"
    node.sdo[0x607A].raw = 100_000  # a jump the motor cannot follow
    err = node.emcy.wait(0x8611, timeout=2)
    assert err is not None and err.code == 0x8611
    wait.until(lambda: node.statusword & 0x4F == 0x08, 2, "FAULT after the fault reaction")
    assert node.sdo[0x603F].raw == 0x8611
    node.sdo[0x607A].raw = node.sdo[0x6064].raw  # nothing more to follow
    node.reset_from_fault()
    assert node.state == "OPERATION ENABLED"
    assert node.sdo[0x603F].raw == 0


@pytest.mark.parametrize(("option", "rest_state"), [(2, 0x40), (6, 0x07), (0, 0x40)])
def test_quick_stop_options(node: BaseNode402, twins, option: int, rest_state: int) -> None:
    twin = twins.drives[NODE]
    node.sdo[0x605A].raw = option
    node.sdo[0x6065].raw = 0xFFFFFFFF
    node.sdo[0x6081].raw = 200_000
    node.op_mode = "PROFILED POSITION"
    node.state = "OPERATION ENABLED"
    node.sdo[0x607A].raw = 1_000_000
    node.controlword = 0x3F  # new set-point, at once
    wait.until(lambda: twin.demand_v >= 100_000, 2, "the profile under way")
    node.controlword = 0x02  # quick stop
    # at rest: SWITCH ON DISABLED (options 0, 2), or QUICK STOP ACTIVE with bit 10 (option 6)
    rest = rest_state | (0x0400 if option == 6 else 0)
    wait.until(lambda: node.sdo[0x6041].raw & 0x046F == rest, 2, f"at rest, statusword & 0x046F = 0x{rest:X}")
    assert twin.demand_v == 0.0
    assert twin.position_actual < 1_000_000  # stopped short of the target
    if option == 6:  # stays in QUICK STOP ACTIVE, and enable operation leads back (transition 16)
        assert node.sdo[0x6041].raw & 0x0400
        node.controlword = 0x0F
        wait.until(lambda: node.sdo[0x6041].raw & 0x6F == 0x27, 2, "OPERATION ENABLED again")


def test_profile_position_set_point_handshake(node: BaseNode402, twins) -> None:
    node.op_mode = "PROFILED POSITION"
    node.state = "OPERATION ENABLED"
    node.sdo[0x6067].raw = 5
    node.sdo[0x607A].raw = 4000
    assert not node.sdo[0x6041].raw & 0x1000
    node.controlword = 0x1F  # bit 4: new set-point
    assert node.sdo[0x6041].raw & 0x1000  # acknowledged
    node.controlword = 0x0F
    assert not node.sdo[0x6041].raw & 0x1000
    wait.until(lambda: node.sdo[0x6041].raw & 0x0400, 5, "target reached (bit 10)")
    assert abs(node.sdo[0x6064].raw - 4000) <= 5
    node.sdo[0x607A].raw = -1000
    node.controlword = 0x5F  # relative: 1000 counts back
    node.controlword = 0x0F
    wait.until(lambda: node.sdo[0x6041].raw & 0x0400, 5, "target reached again")
    wait.until(lambda: node.sdo[0x6064].raw == 3000, 5, "settled at 3000")


def test_injected_fault_and_reset(node: BaseNode402, twins) -> None:
    node.state = "OPERATION ENABLED"
    twins.drives[NODE].inject_fault(0x2310)
    assert node.emcy.wait(0x2310, timeout=2) is not None
    wait.until(lambda: node.is_faulted(), 2, "FAULT")
    assert node.sdo[0x603F].raw == 0x2310
    node.reset_from_fault()
    assert node.state == "OPERATION ENABLED"


def test_heartbeat_production(node: BaseNode402, twins) -> None:
    node.sdo[0x1017].raw = 20
    assert node.nmt.wait_for_heartbeat(timeout=1) == "OPERATIONAL"
    twins.drives[NODE].stop_heartbeat()
    with pytest.raises(canopen.nmt.NmtError):
        node.nmt.wait_for_heartbeat(timeout=0.2)


def test_a_hung_sdo_server_answers_nothing_until_a_client_aborts(twins, master: canopen.Network) -> None:
    """``hang_sdo``: a request times out at the client, whose abort of it (canopen's
    client sends one on its timeout) frees the server; the next request is answered."""
    twin = twins.add(NODE)
    node = master.add_node(NODE, SimulatedDrive.EDS)
    node.sdo.RESPONSE_TIMEOUT = 0.2
    modes = node.sdo[0x6502].raw
    twin.hang_sdo()
    with pytest.raises(SdoCommunicationError):
        node.sdo[0x6502].raw  # noqa: B018 - the read is the test
    assert node.sdo[0x6502].raw == modes
