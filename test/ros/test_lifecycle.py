"""The managed-node (lifecycle) interface: an orchestrator
brings the three real nodes up in its order through rclpy's lifecycle
services; until then the cell takes no run. Plain start (every other node
test, `winder run`) is unchanged: the nodes activate themselves.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from conftest import Procs, closed_bags
from support import wait

from winder.record.reader import read_run

pytestmark = pytest.mark.ros

NODES = ("sim_node", "profile_node", "interp_node")


class Lifecycle:
    """rclpy's lifecycle client side: ~/get_state and ~/change_state of a node."""

    def __init__(self, ros: Any) -> None:
        from lifecycle_msgs.srv import ChangeState, GetState

        self.ros = ros
        self.get = {n: ros.create_client(GetState, f"/{n}/get_state") for n in NODES}
        self.change = {n: ros.create_client(ChangeState, f"/{n}/change_state") for n in NODES}

    def call(self, client: Any, request: Any) -> Any:
        from conftest import spin_until

        spin_until(self.ros, client.service_is_ready, 30, f"service {client.srv_name}")
        future = client.call_async(request)
        spin_until(self.ros, future.done, 30, f"reply of {client.srv_name}")
        return future.result()

    def state(self, node: str) -> str:
        from lifecycle_msgs.srv import GetState

        return str(self.call(self.get[node], GetState.Request()).current_state.label)

    def transition(self, node: str, name: str) -> bool:
        from lifecycle_msgs.msg import Transition
        from lifecycle_msgs.srv import ChangeState

        ids = {
            "configure": Transition.TRANSITION_CONFIGURE,
            "activate": Transition.TRANSITION_ACTIVATE,
            "deactivate": Transition.TRANSITION_DEACTIVATE,
            "cleanup": Transition.TRANSITION_CLEANUP,
            "shutdown": Transition.TRANSITION_UNCONFIGURED_SHUTDOWN,
        }
        req = ChangeState.Request()
        req.transition.id = ids[name]
        return bool(self.call(self.change[node], req).success)


def started(procs: Procs, bags: Path) -> None:
    """Until the cell's run has started: its bag directory has an entry."""
    wait.until(lambda: list(bags.glob("*")), 60, f"the run's bag in {bags}", heard=lambda: logs(procs))


def closed(procs: Procs, bags: Path) -> list[Path]:
    """The closed bags in ``bags``, once there is one (the run ended)."""
    return list(
        wait.until(lambda: closed_bags(bags), 60, f"a closed bag in {bags}", heard=lambda: logs(procs))
    )


def logs(procs: Procs) -> list[str]:
    """The last lines of each node's log."""
    return [procs.log(p)[-300:] for p, _ in procs.procs]


def test_an_orchestrator_brings_the_cell_up_in_order(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """managed:=true: the nodes wait unconfigured and the cell refuses a run;
    configured and activated one by one (sim, profile, interp), the job
    autostarts and completes into a bag; a deactivate during the run is
    refused (the run goes on), after it accepted; then cleanup and shutdown."""
    from std_srvs.srv import Trigger

    bags = tmp_path / "bags"
    managed = ("-p", "managed:=true")
    sim = ("-p", f"bag_dir:={bags}", "-p", "real_time:=true", "-p", "real_time_factor:=2.0")
    procs.start("sim_node", *managed, *sim)
    procs.start("profile_node", *managed)
    procs.start("interp_node", *managed, "-p", "turns_per_layer:=8", "-p", "poles:=1", "-p", "layers:=1")
    lc = Lifecycle(ros)
    assert [lc.state(n) for n in NODES] == ["unconfigured"] * 3
    start = ros.create_client(Trigger, "/interp_node/start")
    reply = lc.call(start, Trigger.Request())
    assert not reply.success and "not active" in reply.message, reply.message

    for node in NODES:  # the orchestrator's order: the consumer first
        assert lc.transition(node, "configure")
        assert lc.state(node) == "inactive"
    wait.spin_for(ros, 1.0)  # the subject is what does not happen: no run while the nodes are inactive
    assert not list(bags.glob("*")), "a run started before the nodes were active"
    for node in NODES:
        assert lc.transition(node, "activate")
        assert lc.state(node) == "active"

    # the run autostarts once all three are active; while it goes on it cannot be deactivated
    started(procs, bags)
    assert not lc.transition("sim_node", "deactivate")
    assert lc.state("sim_node") == "active"
    [meta] = [b / "metadata.yaml" for b in closed(procs, bags)]
    run = read_run(meta.parent)
    assert run.complete and not run.errors, run.errors

    # after the run: deactivated, the cell refuses a start again; then cleanup and shutdown
    wait.until(  # the sim node ends its run's report first: asked again every 0.2 s
        lambda: lc.transition("sim_node", "deactivate"), 30, "sim_node's deactivation after its run", poll=0.2
    )
    reply = lc.call(start, Trigger.Request())
    assert not reply.success and "consumer inactive" in reply.message, reply.message
    for node in NODES[1:]:
        assert lc.transition(node, "deactivate")
    for node in NODES:
        assert lc.transition(node, "cleanup")
        assert lc.state(node) == "unconfigured"
    for node in NODES:
        assert lc.transition(node, "shutdown")
        assert lc.state(node) == "finalized"
    assert all(p.poll() is None for p, _ in procs.procs), "a node died"


def test_a_transition_the_state_does_not_have_is_refused_and_every_node_lives_on(
    tmp_path: Path, procs: Procs, ros: Any
) -> None:
    """configure an active node, activate one twice, cleanup an active one, a
    label that is no transition: each ~/change_state replies failure (with the
    reason in the node's log) and leaves the state as it was, mid-run too;
    rclpy's own handler let rcl's "Transition is not registered" end the node."""
    from lifecycle_msgs.srv import ChangeState

    bags = tmp_path / "bags"
    sim = ("-p", f"bag_dir:={bags}", "-p", "real_time:=true", "-p", "real_time_factor:=1.0")
    procs.start("sim_node", *sim)
    procs.start("profile_node")
    procs.start("interp_node", "-p", "turns_per_layer:=8", "-p", "poles:=1", "-p", "layers:=1")
    lc = Lifecycle(ros)
    assert [lc.state(n) for n in NODES] == ["active"] * 3
    started(procs, bags)
    assert not closed_bags(bags), "no run going on"
    for node in NODES:  # mid-run
        assert not lc.transition(node, "configure")
        assert not lc.transition(node, "activate")
        assert not lc.transition(node, "cleanup")
        req = ChangeState.Request()
        req.transition.label = "explode"
        assert not lc.call(lc.change[node], req).success
        assert lc.state(node) == "active"
    assert all(p.poll() is None for p, _ in procs.procs), "a node died"
    [meta] = [b / "metadata.yaml" for b in closed(procs, bags)]
    assert read_run(meta.parent).complete  # the run went on to its end
    for node, p in zip(NODES, (p for p, _ in procs.procs), strict=True):
        assert "transition 'explode' refused: not valid from state active" in procs.log(p), node
