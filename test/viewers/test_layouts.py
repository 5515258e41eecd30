"""The viewer layouts in layouts/ name only what a bag of the real cell holds.

Every Foxglove message path and every PlotJuggler series is resolved on the
messages rosbags decodes from a recorded run (the session's 'trap' bag, see
conftest's ``bag``): Foxglove paths by walking the message path syntax they use
(``.field``, ``[i]``, ``[:]``, ``{field=="text"}``), PlotJuggler series against
the names its ROS parser gives a bag's series (a JointState by joint name, a
DiagnosticArray by hardware id, status name and key, numeric values only).

The layouts' two Foxglove user scripts are TypeScript that runs inside
Foxglove; here their inputs, the JSON keys they read and the premises they
rest on (a command and a state at every sample stamp, step times counted from
the run's clock origin) are checked on the bag.
"""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET
from typing import Any

import numpy as np
import pytest
from conftest import rosbags_read
from support.paths import ROOT

pytestmark = pytest.mark.ros

FOXGLOVE = ROOT / "layouts" / "winder_foxglove.json"
PLOTJUGGLER = ROOT / "layouts" / "winder_plotjuggler.xml"
JOINTS = ("feed", "fork", "pole")

Messages = dict[str, list[tuple[int, Any]]]


@pytest.fixture(scope="module")
def messages(bag: Any) -> Messages:
    """Every message of a recorded run, by topic: [(log time, message)]."""
    return rosbags_read(bag("wire"))


@pytest.fixture(scope="module")
def foxglove() -> dict[str, Any]:
    layout: dict[str, Any] = json.loads(FOXGLOVE.read_text())
    return layout


@pytest.fixture(scope="module")
def plotjuggler() -> ET.Element:
    return ET.parse(PLOTJUGGLER).getroot()


# -- Foxglove message paths ----------------------------------------------------------------

_STEP = re.compile(
    r"\.(?P<field>[A-Za-z_]\w*)|\[(?P<index>-?\d+)\]|(?P<all>\[:\])"
    r'|\{(?P<key>[A-Za-z_]\w*)==(?:"(?P<text>[^"]*)"|(?P<number>-?\d+(?:\.\d+)?))\}'
)


def foxglove_values(path: str, messages: Messages) -> tuple[list[Any], str]:
    """The values a Foxglove message path picks out of every recorded message
    of its topic, and "" or why it picks none."""
    topic = max(
        (t for t in messages if path == t or path.startswith((t + ".", t + "{"))), key=len, default=""
    )
    if not topic:
        return [], f"{path}: no such topic in the bag"
    rest, pos = path[len(topic) :], 0
    nodes: list[Any] = [m for _, m in messages[topic]]
    while pos < len(rest):
        step = _STEP.match(rest, pos)
        if step is None:
            return [], f"{path}: cannot read {rest[pos:]!r}"
        pos = step.end()
        try:
            if step["field"]:
                nodes = [getattr(n, step["field"]) for n in nodes]
            elif step["index"]:
                i = int(step["index"])
                nodes = [n[i] for n in nodes if -len(n) <= i < len(n)]
            elif step["all"]:
                nodes = [x for n in nodes for x in n]
            else:
                want: Any = step["text"] if step["text"] is not None else float(step["number"])
                nodes = [n for n in nodes if getattr(n, step["key"]) == want]
        except (AttributeError, TypeError) as exc:
            return [], f"{path}: {exc}"
    return nodes, "" if nodes else f"{path}: picks nothing in {len(messages[topic])} messages"


def numeric(value: Any) -> bool:
    """A value Foxglove's Plot draws: a number, or a string it reads as one."""
    if isinstance(value, str):
        return re.fullmatch(r"\s*[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?\s*", value) is not None
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


def panel_ids(tree: Any) -> list[str]:
    return [tree] if isinstance(tree, str) else panel_ids(tree["first"]) + panel_ids(tree["second"])


def scripts(layout: dict[str, Any]) -> dict[str, str]:
    """The user scripts of a layout, by output topic: their TypeScript source."""
    out = {}
    for node in layout["userNodes"].values():
        found = re.search(r'export const output = "([^"]+)";', node["sourceCode"])
        assert found, node["name"]
        out[found[1]] = node["sourceCode"]
    return out


def script_inputs(source: str) -> list[str]:
    found = re.search(r"export const inputs = (\[[^\]]*\]);", source)
    assert found, source[:200]
    inputs: list[str] = json.loads(found[1])
    return inputs


def script_fields(source: str) -> set[str]:
    """The fields of a script's output message: its ``type Output = {...}``."""
    found = re.search(r"type Output = \{([^}]*)\};", source)
    assert found, source[:200]
    return set(re.findall(r"(\w+): number", found[1]))


def json_reads(source: str) -> dict[str, set[str]]:
    """The keys a script reads from a topic's JSON text (or typed message),
    by topic: after ``event.topic === "T"``, ``PARSE.KEY`` or ``NAME.KEY``
    of a ``const NAME = PARSE``, where PARSE is
    ``JSON.parse(event.message.data)`` or ``jobOf(event.message)`` (the
    job's fields, typed or JSON)."""
    reads: dict[str, set[str]] = {}
    topic, parsed = "", ""
    parse = r"(?:JSON\.parse\(event\.message\.data\)|jobOf\(event\.message\))"
    token = re.compile(
        r'event\.topic === "(?P<topic>[^"]+)"'
        rf"|const (?P<name>\w+) = {parse};"
        rf"|{parse}\.(?P<key>\w+)"
        r"|\b(?P<obj>\w+)\.(?P<attr>\w+)"
    )
    for m in token.finditer(source):
        if m["topic"]:
            topic, parsed = m["topic"], ""
        elif m["name"]:
            parsed = m["name"]
        elif m["key"]:
            reads.setdefault(topic, set()).add(m["key"])
        elif m["obj"] and m["obj"] == parsed:
            reads.setdefault(topic, set()).add(m["attr"])
    return reads


def test_every_foxglove_path_resolves_on_a_recorded_run(foxglove: dict[str, Any], messages: Messages) -> None:
    outputs = scripts(foxglove)
    checked = 0
    for panel, cfg in foxglove["configById"].items():
        kind = panel.split("!")[0]
        paths = [p["value"] for p in cfg.get("paths", [])]
        paths += [cfg[k] for k in ("topicPath", "topicToRender") if k in cfg]
        assert paths, panel
        for path in paths:
            topic, _, field = path.partition(".")
            if topic in outputs:  # a user script's output: a field of its message type
                assert field in script_fields(outputs[topic]), path
                continue
            values, why = foxglove_values(path, messages)
            assert why == "", why
            if kind == "Plot":
                assert all(numeric(v) for v in values), f"{path}: not all numeric: {values[:3]}"
            checked += 1
    # 12 joint curves, the sim node's progress, the cell state, the diagnostics, the motor set-up,
    # the wire's tension, supply and dancer
    assert checked == 19
    # every panel the layout tree shows is configured, and every configured panel is shown
    assert sorted(panel_ids(foxglove["layout"])) == sorted(foxglove["configById"])


def test_foxglove_states_and_progress_pick_what_the_panels_show(
    foxglove: dict[str, Any], messages: Messages
) -> None:
    (state,) = foxglove["configById"]["StateTransitions!state"]["paths"]
    values, _ = foxglove_values(state["value"], messages)
    assert values == [m.state for _, m in messages["/winder/state"]]
    assert values[0] == "running" and values[-1] == "done"
    progress = foxglove["configById"]["Plot!progress"]["paths"][1]["value"]
    values, _ = foxglove_values(progress, messages)
    assert float(values[-1]) == 1.0  # one status per report: the sim node's own


def test_foxglove_plots_use_log_time(foxglove: dict[str, Any], messages: Messages) -> None:
    """The joints' header stamps are simulated time from the run's clock
    origin, those of /diagnostics wall-clock time: only the log (receive)
    time puts both on one axis, so every series is plotted against it."""
    methods = {p["timestampMethod"] for cfg in foxglove["configById"].values() for p in cfg.get("paths", [])}
    assert methods == {"receiveTime"}
    config = json.loads(messages["/winder/sim_config"][0][1].data)
    first_state = messages["/winder/joint_states"][0][1].header.stamp
    first_diag = messages["/diagnostics"][0][1].header.stamp
    assert first_state.sec * 10**9 + first_state.nanosec == config["clock_origin_ns"]
    assert abs(first_diag.sec * 10**9 + first_diag.nanosec - config["wall_start_ns"]) < 60 * 10**9
    assert abs(config["wall_start_ns"] - config["clock_origin_ns"]) > 365 * 86400 * 10**9


def test_foxglove_scripts_read_what_the_bag_holds(foxglove: dict[str, Any], messages: Messages) -> None:
    outputs = scripts(foxglove)
    assert set(outputs) == {"/studio_script/winder_tracking_error", "/studio_script/winder_progress"}
    assert all(t in messages for src in outputs.values() for t in script_inputs(src))
    assert script_fields(outputs["/studio_script/winder_tracking_error"]) == set(JOINTS)
    assert script_fields(outputs["/studio_script/winder_progress"]) == {
        "steps_done",
        "steps_total",
        "progress",
    }
    reads: dict[str, set[str]] = {}
    for source in outputs.values():
        for topic, keys in json_reads(source).items():
            reads.setdefault(topic, set()).update(keys)
    assert reads == {
        "/winder/job": {"axes", "joint_step", "total_steps"},
        "/winder/sim_config": {"clock_origin_ns"},
    }
    config = json.loads(messages["/winder/sim_config"][0][1].data)
    assert reads["/winder/sim_config"] <= set(config)
    job = messages["/winder/job"][0][1]  # a winder_interfaces/JobDescription: the keys are its fields
    assert all(hasattr(job, key) for key in reads["/winder/job"])
    assert list(job.axes) == list(JOINTS) and len(job.joint_step) == 3 and job.total_steps > 0


def test_the_foxglove_scripts_premises_hold_in_the_bag(messages: Messages) -> None:
    """What the scripts rest on, on the recorded run: every joint state has the
    command of its stamp, logged before it (the tracking error pairs them);
    the step stream's first column is t_ns, strictly increasing, and counted
    from the run's clock origin, so that at the last sample every step of the
    job is done and at the first none (the progress counts them)."""

    def stamps(topic: str) -> list[tuple[int, int, int]]:
        return [(m.header.stamp.sec, m.header.stamp.nanosec, t) for t, m in messages[topic]]

    commands = {(s, ns): t for s, ns, t in stamps("/winder/joint_commands")}
    states = stamps("/winder/joint_states")
    assert len(states) > 100 and all(commands.get((s, ns), t + 1) <= t for s, ns, t in states)
    step_times = [m for _, m in messages["/winder/step_times"]]
    assert all(m.layout.dim[1].label.startswith("t_ns,") for m in step_times)
    t_ns = np.concatenate([np.asarray(m.data).reshape(-1, m.layout.dim[1].size)[:, 0] for m in step_times])
    assert np.all(np.diff(t_ns) > 0)
    total = int(messages["/winder/job"][0][1].total_steps)  # a winder_interfaces/JobDescription
    origin = json.loads(messages["/winder/sim_config"][0][1].data)["clock_origin_ns"]
    first, last = states[0], states[-1]
    done = np.searchsorted(t_ns, [s * 10**9 + ns - origin for s, ns, _ in (first, last)], side="right")
    assert done.tolist() == [0, total] and len(t_ns) == total


def test_the_foxglove_resolver_reports_wrong_paths(messages: Messages) -> None:
    for wrong in (
        "/winder/joint_states.positions[0]",  # no such field
        "/winder/joint_states.position[7]",  # three joints
        "/winder/nope.data",  # no such topic
        "/winder/state.stat",  # no such field
        '/diagnostics.status[:]{name=="sim_node: jobs"}.values[:]{key=="progress"}.value',
        "/winder/joint_states.position[0].@derivative",  # not read here: reported, not skipped
    ):
        assert foxglove_values(wrong, messages)[1] != "", wrong


# -- PlotJuggler series --------------------------------------------------------------------

_DOUBLE = re.compile(r"\s*[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?\s*")


def plotjuggler_series(messages: Messages) -> set[str]:
    """The numeric series PlotJuggler's ROS parser makes of the bag's
    JointState, WrenchStamped and DiagnosticArray topics: ``/topic/<joint>/<position|velocity>``,
    ``/topic/wrench/<force|torque>/<x|y|z>``
    when the field has one value per joint; ``/topic/<hardware id>/<status
    name>/<key>`` (without the hardware id when it is empty) when the value
    reads as a number."""
    series: set[str] = set()
    for topic, msgs in messages.items():
        for _, m in msgs:
            kind = getattr(m, "__msgtype__", "")
            if kind == "sensor_msgs/msg/JointState":
                for field in ("position", "velocity", "effort"):
                    if len(getattr(m, field)) == len(m.name):
                        series.update(f"{topic}/{joint}/{field}" for joint in m.name)
            elif kind == "geometry_msgs/msg/WrenchStamped":
                series.update(f"{topic}/wrench/{v}/{a}" for v in ("force", "torque") for a in "xyz")
            elif kind == "diagnostic_msgs/msg/DiagnosticArray":
                for st in m.status:
                    prefix = f"{topic}/{st.hardware_id}/{st.name}" if st.hardware_id else f"{topic}/{st.name}"
                    series.update(f"{prefix}/{kv.key}" for kv in st.values if _DOUBLE.fullmatch(kv.value))
    return series


def test_every_plotjuggler_series_exists_in_a_recorded_run(
    plotjuggler: ET.Element, messages: Messages
) -> None:
    series = plotjuggler_series(messages)
    snippets = {s.get("name", ""): s for s in plotjuggler.iter("snippet")}
    assert set(snippets) == {f"{j}_tracking_error" for j in JOINTS}
    curves = [c.get("name", "") for c in plotjuggler.iter("curve")]
    assert len(curves) == 19
    assert [c for c in curves if c not in series and c not in snippets] == []
    sources = [
        e.text or "" for s in snippets.values() for e in s.iter() if e.tag == "linked_source" or e.tag == "v1"
    ]
    assert len(sources) == 6 and [s for s in sources if s not in series] == []
    # a live subscription delivers what the curves and functions read, and no more
    (subscriber,) = [p for p in plotjuggler.iter("plugin") if p.get("ID") == "ROS2 Topic Subscriber"]
    topics, stamp = subscriber.find("selected_topics"), subscriber.find("use_header_stamp")
    assert topics is not None and stamp is not None
    selected = topics.get("value", "").split(";")
    used = {
        t for name in curves + sources for t in messages if name.startswith(t + "/") and name not in snippets
    }
    assert (
        set(selected)
        == used
        == {
            "/winder/joint_commands",
            "/winder/joint_states",
            "/winder/tension",
            "/diagnostics",
        }
    )
    assert stamp.get("value") == "false"  # see test_foxglove_plots_use_log_time


def test_plotjuggler_docking_is_consistent(plotjuggler: ET.Element) -> None:
    splitters = list(plotjuggler.iter("DockSplitter"))
    assert splitters
    for s in splitters:
        children = [c for c in s if c.tag in ("DockSplitter", "DockArea")]
        sizes = [float(x) for x in s.get("sizes", "").split(";")]
        assert int(s.get("count", "0")) == len(children) == len(sizes)
        assert abs(sum(sizes) - 1) < 1e-5 and s.get("orientation") in ("-", "|")


def test_the_plotjuggler_resolver_reports_wrong_series(messages: Messages) -> None:
    series = plotjuggler_series(messages)
    assert "/winder/joint_states/fork/position" in series
    assert "/diagnostics/winder_sim/sim_node: job/progress" in series
    for wrong in (
        "/winder/joint_states/spindle/position",  # no such joint
        "/winder/joint_states/position[0]",  # PlotJuggler names a JointState's joints
        "/winder/joint_states/fork/effort",  # effort is not published
        "/diagnostics/winder_sim/sim_node: job/state",  # text, not a series
        "/diagnostics/winder_interp/sim_node: job/progress",  # the sim node's hardware id is winder_sim
    ):
        assert wrong not in series, wrong
