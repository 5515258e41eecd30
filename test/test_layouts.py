"""The viewer layouts shipped in layouts/ name only topics and fields that a
bag of the real cell holds: every Foxglove message path and PlotJuggler
series is resolved on messages rosbags decodes from a recorded run."""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest
import test_reader
from conftest import rosbags_read

pytestmark = pytest.mark.ros

ROOT = Path(__file__).resolve().parents[1]
FOXGLOVE = ROOT / "layouts" / "winder_foxglove.json"
PLOTJUGGLER = ROOT / "layouts" / "winder_plotjuggler.xml"
_STEP = re.compile(r"\.([A-Za-z_]\w*)|\[(\d+)\]")


@pytest.fixture(scope="module")
def messages(
    tmp_path_factory: pytest.TempPathFactory, request: pytest.FixtureRequest
) -> dict[str, list[Any]]:
    """Every message of a recorded run (the session's 'trap' bag), by topic."""
    path = test_reader.bags(tmp_path_factory, request).get("trap")
    return {topic: [m for _, m in msgs] for topic, msgs in rosbags_read(path).items()}


def foxglove_path(path: str, messages: dict[str, list[Any]]) -> str:
    """ "" if a Foxglove message path (``/topic.field[i].field``) resolves on
    the recorded messages, else why not."""
    topic = max((t for t in messages if path == t or path.startswith(t + ".")), key=len, default=None)
    if topic is None:
        return f"{path}: no such topic in the bag"
    rest, pos = path[len(topic) :], 0
    values: list[Any] = list(messages[topic])
    while pos < len(rest):
        m = _STEP.match(rest, pos)
        if m is None:
            return f"{path}: cannot parse {rest[pos:]!r}"
        field, index = m.groups()
        try:
            values = [getattr(v, field) for v in values] if field else [v[int(index)] for v in values]
        except (AttributeError, IndexError, TypeError) as exc:
            return f"{path}: {exc}"
        pos = m.end()
    return "" if values else f"{path}: no message"


def plotjuggler_series(name: str, messages: dict[str, list[Any]], snippets: set[str]) -> str:
    """ "" if a PlotJuggler series exists for a recorded run, else why not:
    JointState as ``/topic/<joint name>/<position|velocity>``, DiagnosticArray
    as ``/topic/<hardware id>/<status name>/<key>`` (numeric values only), a
    custom function by its name."""
    if name in snippets:
        return ""
    for topic, msgs in messages.items():
        if not name.startswith(topic + "/"):
            continue
        parts = name[len(topic) + 1 :]
        kind = type(msgs[0]).__name__
        if kind.endswith("JointState"):
            joint, _, field = parts.rpartition("/")
            ok = field in ("position", "velocity") and all(joint in m.name for m in msgs)
            return "" if ok else f"{name}: no joint {joint!r} field {field!r} in {topic}"
        if kind.endswith("DiagnosticArray"):
            hw, _, rest = parts.partition("/")
            status, _, key = rest.rpartition("/")
            found = [
                kv.value
                for m in msgs
                for st in m.status
                if st.hardware_id == hw and st.name == status
                for kv in st.values
                if kv.key == key
            ]
            try:
                return "" if found and [float(v) for v in found] else f"{name}: no such status key"
            except ValueError:
                return f"{name}: {key} is not numeric"
    return f"{name}: no such topic or series in the bag"


def foxglove_paths(layout: dict[str, Any]) -> tuple[list[str], list[str], str]:
    """(message paths of the panels, the user script's input topics, its output topic)."""
    paths = []
    for cfg in layout["configById"].values():
        paths += [p["value"] for p in cfg.get("paths", [])]
        paths += [cfg[k] for k in ("topicPath", "topicToRender") if k in cfg]
    (script,) = layout["userNodes"].values()
    inputs = json.loads(re.search(r"inputs = (\[.*?\]);", script["sourceCode"]).group(1))
    output = re.search(r'output = "([^"]+)"', script["sourceCode"]).group(1)
    return paths, inputs, output


def test_every_foxglove_path_resolves_on_a_recorded_run(messages: dict[str, list[Any]]) -> None:
    layout = json.loads(FOXGLOVE.read_text())
    paths, inputs, output = foxglove_paths(layout)
    derived = [p for p in paths if p.startswith(output + ".")]
    recorded = [p for p in paths if not p.startswith(output + ".")]
    assert len(recorded) >= 13 and len(derived) == 3  # 12 joint curves, the state, diagnostics, config
    assert [foxglove_path(p, messages) for p in recorded] == [""] * len(recorded)
    assert all(t in messages for t in inputs)
    # the script's fields: the joint steps of the job description, the joints' positions
    assert len(json.loads(messages["/winder/job"][0].data)["joint_step"]) == 3
    assert {p.rsplit(".", 1)[1] for p in derived} == set(messages["/winder/joint_states"][0].name)
    # the resolver can fail: a wrong field, index and topic are each reported
    for wrong in (
        "/winder/joint_states.positions[0]",
        "/winder/joint_states.position[7]",
        "/winder/nope.data",
    ):
        assert foxglove_path(wrong, messages) != ""


def test_every_plotjuggler_series_exists_in_a_recorded_run(messages: dict[str, list[Any]]) -> None:
    root = ET.parse(PLOTJUGGLER).getroot()
    snippets = {s.get("name", "") for s in root.iter("snippet")}
    curves = [c.get("name", "") for c in root.iter("curve")]
    assert len(curves) >= 16 and snippets == {
        "feed_tracking_error",
        "fork_tracking_error",
        "pole_tracking_error",
    }
    assert [plotjuggler_series(c, messages, snippets) for c in curves] == [""] * len(curves)
    sources = [
        e.text or "" for s in root.iter("snippet") for e in s.iter() if e.tag in ("linked_source", "v1")
    ]
    assert len(sources) == 6 and all(plotjuggler_series(s, messages, set()) == "" for s in sources)
    topics = [t.get("name", "") for t in root.iter("topic")]
    assert topics and all(t in messages for t in topics)
    for wrong in ("/winder/joint_states/spindle/position", "/diagnostics/winder_sim/sim_node: job/state"):
        assert plotjuggler_series(wrong, messages, snippets) != ""
