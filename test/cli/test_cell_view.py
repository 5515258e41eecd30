"""What `winder ctl state` waits for before it prints, and what it prints:
the cell view is complete only with every part heard; each part is shown
with its age, a node off the graph as gone, one overdue as silent (no DDS
here: the view is filled by hand)."""

from __future__ import annotations

from winder.cli.ctl import change_line, state_lines
from winder.ros.ctl import FRESH, SETTLE, SILENT, CellView, NodeStatus


def _view_with_statuses_and_state() -> CellView:
    view = CellView("")
    for node, role in (("interp_node", "interp"), ("profile_node", "profile"), ("axes", "consumer")):
        name = f"{node}: job"
        view.statuses[role] = NodeStatus(name, {"state": "done"}, "")
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
    del view.statuses["consumer"]
    assert not view.complete()


# -- how old each part is, and a node that has left the graph -----------------------------

NOW_NS = 1_800_000_000_000_000_000  #: the wall clock of the query (ns)


def _heard_view() -> CellView:
    """A running cell as heard: winder/state sent 35.2 s ago, each role's
    ready and job status a moment ago, every node on the graph."""
    view = CellView("")
    for node, role, ago in (
        ("interp_node", "interp", 0.4),
        ("profile_node", "profile", 0.6),
        ("sim_node", "consumer", 0.1),
    ):
        name = f"{node}: job"
        values = {"state": "running", "run_id": "r_1", "sim_time_s": "35.1"}
        view.statuses[role] = NodeStatus(name, values, "", NOW_NS - int(ago * 1e9))
    view.state = {"state": "running", "run_id": "r_1", "job_id": "j", "sim_time_s": "0.000000"}
    view.state_ns, view.state_by = NOW_NS - 35_200_000_000, "/sim_node"
    view.ready.update(consumer="busy", profile="ready")
    view.ready_ns.update(consumer=NOW_NS - 300_000_000, profile=NOW_NS - 500_000_000)
    view.graph = {"/interp_node", "/profile_node", "/sim_node"}
    view.holders = {"interp": {"/interp_node"}, "profile": {"/profile_node"}, "consumer": {"/sim_node"}}
    return view


def test_state_says_how_long_ago_each_part_was_said() -> None:
    """The transition on winder/state is as old as its sending (35.2 s), not
    as the query; each status and ready message has its own age."""
    lines = state_lines(_heard_view(), NOW_NS)
    assert lines[0].startswith("cell /  running  run r_1 (job j)") and lines[0].endswith("(35.2 s ago)"), (
        lines
    )
    assert lines[1] == "  ready     consumer busy (0.3 s ago), profile ready (0.5 s ago)", lines
    rows = {ln.split()[0]: ln for ln in lines[2:]}
    assert rows["interp_node"].endswith("(0.4 s ago)") and rows["profile_node"].endswith("(0.6 s ago)"), lines
    assert "sim 35.100 s" in rows["sim_node"] and rows["sim_node"].endswith("(0.1 s ago)"), lines
    assert not any("gone" in ln or "silent" in ln for ln in lines), lines


def test_a_node_that_left_the_graph_is_shown_gone_not_as_its_last_word() -> None:
    """The consumer killed: the graph no longer shows it. Its last status,
    its latched winder/state and its ready are shown as its last word, the
    node as gone."""
    view = _heard_view()
    view.graph = {"/interp_node", "/profile_node"}
    view.holders["consumer"] = set()
    lines = state_lines(view, NOW_NS)
    assert "/sim_node, which said it, has left the graph" in lines[0], lines
    assert "consumer gone (said busy 0.3 s ago)" in lines[1], lines
    [row] = [ln for ln in lines if ln.split()[:1] == ["sim_node"]]
    assert row.split()[:3] == ["sim_node", "consumer", "gone"] and "left the graph; it said running" in row, (
        row
    )
    assert "gone: /sim_node" in change_line(view)


def test_a_node_whose_once_a_second_status_is_overdue_is_shown_silent() -> None:
    """A node held up (SIGSTOP) stays on the graph but says nothing: its
    status and ready grow old past SILENT and are marked so."""
    view = _heard_view()
    later = NOW_NS + int((SILENT + 1) * 1e9)
    lines = state_lines(view, later)
    assert all(ln.endswith("s ago: silent)") for ln in lines[2:]), lines
    assert "(4.3 s ago: silent)" in lines[1] and lines[0].endswith("(39.2 s ago)"), lines


def test_a_missing_part_is_named_with_what_the_graph_shows() -> None:
    view = _heard_view()
    del view.statuses["consumer"]
    said = "  no job status heard from the consumer /sim_node (on the graph; held up?)"
    assert said in state_lines(view, NOW_NS)
    view.graph, view.holders["consumer"] = {"/interp_node", "/profile_node"}, set()
    view.state, view.state_by = {}, ""
    lines = state_lines(view, NOW_NS)
    assert lines[0] == "cell /  (no winder/state heard: no consumer on the graph)", lines
    assert lines[-1].startswith("  no consumer on the graph"), lines


def test_a_query_ends_when_what_the_graph_shows_is_heard() -> None:
    """settled(): not before every node heard is named on the graph (a
    message can come before its node's name) and its status is its last
    (fresh: the ones a node keeps for a newcomer come oldest first); at once
    when the cell is complete; with a part missing only once the graph has
    not changed for SETTLE s and nothing it shows is still unheard."""
    view = _heard_view()
    t = view.graph_changed
    assert view.settled(t, NOW_NS)
    view.graph = {"/interp_node", "/profile_node"}  # the consumer heard, not yet named on the graph
    assert not view.settled(t + 10, NOW_NS)
    view.graph = {"/interp_node", "/profile_node", "/sim_node"}
    old = view.statuses["profile"]
    view.statuses["profile"] = NodeStatus(old.name, old.values, "", NOW_NS - int((FRESH + 7) * 1e9))
    assert not view.settled(t + 10, NOW_NS)  # the first of the profile node's kept statuses: more to come
    view.statuses["profile"] = old
    del view.statuses["consumer"]  # on the graph, in its role, its status not heard yet
    assert not view.settled(t + 10, NOW_NS)
    view.holders["consumer"], view.graph = set(), {"/interp_node", "/profile_node"}
    view.state, view.state_by = {}, ""
    del view.ready["consumer"]
    assert not view.settled(t + SETTLE / 2, NOW_NS)  # no consumer on the graph yet: it may still show up
    assert view.settled(t + SETTLE, NOW_NS)


def test_the_wait_for_a_missing_part_follows_the_dds_profile() -> None:
    """SETTLE counts DDS announcement periods: dds.ANNOUNCEMENT must be the
    period winder's Fast DDS profiles announce a participant with (and
    dds.LEASE, after which a held node restarts itself, their lease)."""
    import re

    from winder.ros.dds import ANNOUNCEMENT, LAN_PROFILE, LEASE, PROFILE

    for profile in (PROFILE, LAN_PROFILE):
        text = profile.read_text()
        found = re.search(
            r"<leaseAnnouncement><sec>(\d+)</sec>(?:<nanosec>(\d+)</nanosec>)?</leaseAnnouncement>", text
        )
        assert found, profile
        assert int(found.group(1)) + int(found.group(2) or 0) / 1e9 == ANNOUNCEMENT, profile
        lease = re.search(r"<leaseDuration><sec>(\d+)</sec></leaseDuration>", text)
        assert lease and float(lease.group(1)) == LEASE, profile
    assert SETTLE >= 2 * ANNOUNCEMENT
