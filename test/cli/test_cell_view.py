"""What `winder ctl state` waits for before it prints: the cell view is
complete only with every part heard (no DDS here: the view is filled by hand)."""

from __future__ import annotations

from winder.ros.ctl import CellView, NodeStatus


def _view_with_statuses_and_state() -> CellView:
    view = CellView("")
    for node, role in (("interp_node", "interp"), ("profile_node", "profile"), ("axes", "consumer")):
        name = f"{node}: job"
        view.statuses[name] = NodeStatus(name, {"role": role, "state": "done"}, "")
    view.state = {"state": "done"}
    return view


def test_the_view_is_not_complete_before_both_roles_said_ready() -> None:
    """Latched messages of two publishers arrive at different times: a view
    with the statuses and the state but only the profile's winder/ready is
    not complete (a fresh-clone CI printed `ready  profile ready` so)."""
    view = _view_with_statuses_and_state()
    assert not view.complete()
    view.ready["profile"] = "ready"
    assert not view.complete()
    view.ready["consumer"] = "busy"
    assert view.complete()


def test_the_view_is_not_complete_without_every_role_or_the_state() -> None:
    view = _view_with_statuses_and_state()
    view.ready.update(profile="ready", consumer="ready")
    assert view.complete()
    view.state = {}
    assert not view.complete()
    view.state = {"state": "done"}
    del view.statuses["axes: job"]
    assert not view.complete()
