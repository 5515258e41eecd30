"""What makes `winder ctl state`'s output one picture (no DDS here: the
view is filled by hand, as test_cell_view.py fills it): a node's status
said before the cell's state, of another run, or (the consumer's) in a
state that contradicts it is waited for, and shown marked if nothing
newer came; every part has its line; what was not believed is named."""

from __future__ import annotations

from types import SimpleNamespace

from winder.cli.ctl import change_line, state_lines
from winder.contract.trust import Intruders
from winder.ros.ctl import CellView, NodeStatus

NOW_NS = 1_800_000_000_000_000_000  #: the wall clock of the query (ns)


def _paused_view() -> CellView:
    """A cell paused 0.5 s ago, each node's status said after that, each of the run."""
    view = CellView("")
    for node, role, state, ago in (
        ("interp_node", "interp", "running", 0.2),
        ("profile_node", "profile", "paused", 0.3),
        ("sim_node", "consumer", "paused", 0.1),
    ):
        values = {"state": state, "run_id": "r_1", "steps_done": "1864", "steps_total": "20480"}
        view.statuses[role] = NodeStatus(f"{node}: job", values, "", NOW_NS - int(ago * 1e9))
    view.state = {"state": "paused", "run_id": "r_1", "job_id": "j"}
    view.state_ns, view.state_by = NOW_NS - 500_000_000, "/sim_node"
    view.ready.update(consumer="busy", profile="ready")
    view.ready_ns.update(consumer=NOW_NS - 100_000_000, profile=NOW_NS - 300_000_000)
    view.graph = {"/interp_node", "/profile_node", "/sim_node"}
    view.holders = {"interp": {"/interp_node"}, "profile": {"/profile_node"}, "consumer": {"/sim_node"}}
    return view


def test_a_picture_whose_statuses_follow_the_state_is_settled() -> None:
    view = _paused_view()
    assert all(not view.behind(role) for role in view.statuses)
    assert view.settled(view.graph_changed, NOW_NS)
    assert not any("nothing newer came" in ln for ln in state_lines(view, NOW_NS))


def test_a_status_said_before_the_state_is_waited_for_then_marked() -> None:
    """The issue's ``sim_node running 1101/20480`` under ``paused``: the
    consumer's status from before the pause is not its word on the pause."""
    view = _paused_view()
    old = view.statuses["consumer"]
    values = {**old.values, "state": "running", "steps_done": "1101"}
    view.statuses["consumer"] = NodeStatus(old.name, values, "", NOW_NS - 900_000_000)
    assert view.behind("consumer") == "said before the cell's state"
    assert any("/sim_node" in w for w in view.awaited(NOW_NS))
    assert not view.settled(view.graph_changed + 10, NOW_NS)
    [row] = [ln for ln in state_lines(view, NOW_NS) if ln.split()[:1] == ["sim_node"]]
    assert row.endswith("(0.9 s ago; said before the cell's state: nothing newer came)"), row


def test_a_consumer_that_contradicts_the_state_is_waited_for() -> None:
    """The issue's ``cell / done`` above ``sim_node consumer running 3047/4096``:
    the consumer sends both; a status of it that says otherwise than its own
    winder/state is not yet its last word."""
    view = _paused_view()
    view.state = {**view.state, "state": "done"}
    assert view.behind("consumer") == "says paused, the cell done"
    assert not view.behind("profile")  # the other nodes' words are their own view of the run
    assert not view.settled(view.graph_changed + 10, NOW_NS)
    for cell, said in (
        ("running", "stalled"),
        ("failed", "incomplete"),
        ("done", "blocked"),
        ("idle", "idle"),
    ):
        view.state = {**view.state, "state": cell}
        view.statuses["consumer"].values["state"] = said
        assert not view.behind("consumer"), (cell, said)


def test_a_status_of_another_run_is_waited_for() -> None:
    view = _paused_view()
    view.statuses["profile"].values["run_id"] = "r_0"
    assert view.behind("profile") == "of run r_0, the cell's is r_1"
    assert not view.settled(view.graph_changed + 10, NOW_NS)


def test_a_node_gone_is_not_waited_for() -> None:
    view = _paused_view()
    view.statuses["profile"].sent_ns = NOW_NS - 2_000_000_000
    view.graph = {"/interp_node", "/sim_node"}
    view.holders["profile"] = set()
    # (its name still awaited on the graph: a message can come before its node's name)
    assert not any(w.startswith(("a newer status of", "a status of")) for w in view.awaited(NOW_NS))


def test_every_part_has_its_line() -> None:
    """Not heard from: named with the node the graph shows, or as no node
    on the graph; two nodes in a part: both named, neither believed."""
    view = _paused_view()
    del view.statuses["interp"]
    del view.statuses["profile"]
    view.holders["profile"] = set()
    view.holders["interp"] = {"/interp_node", "/other/interp_node"}
    lines = state_lines(view, NOW_NS)
    assert any(
        ln.startswith("  no profile on the graph: no job status heard from the profile node") for ln in lines
    )
    assert any(
        ln.startswith(
            "  no job status taken from the interp: 2 nodes play its part (/interp_node, /other/interp_node)"
        )
        for ln in lines
    ), lines
    assert len(lines) == 5, lines


def test_what_was_not_believed_is_named() -> None:
    view = _paused_view()
    refused = Intruders()
    refused.count("/ty/intruder", "/diagnostics")
    refused.count("/ty/intruder", "/ty/winder/state")
    view.peers = SimpleNamespace(intruders=refused)
    lines = state_lines(view, NOW_NS)
    assert lines[-1] == "  ignored, foreign  /ty/intruder (1 on /diagnostics, 1 on /ty/winder/state)", lines
    assert change_line(view).endswith("  ignored, foreign: /ty/intruder")
