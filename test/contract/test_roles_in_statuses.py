"""Nodes found by their role, not their node name (core, ROS-free).

Every node's job status names its part in the cell (``role``: interp,
profile, consumer) right after the common keys; a controller, ``winder run``
and the reader find the step consumer (the sim node, or a hardware driver
under any node name) by it, and by the stock name ``sim_node`` in statuses
recorded before roles existed. The bags here are written with rosbags, so
each case holds exactly the statuses it is about.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

from winder.contract.stream import describe_job
from winder.contract.topics import ROLE_KEY, ROLES, STATUS_KEYS, has_role, status_values
from winder.motion.job import Job
from winder.record.msgtypes import jazzy_store
from winder.record.reader import read_run

STORE = jazzy_store()  # Jazzy's types and winder's own (winder_interfaces/msg/CellState)
RUN = "tiny_20260101_000000000_1"


def test_the_role_follows_the_common_keys() -> None:
    values = status_values("running", "j", RUN, 3, 4, role="consumer", bag="b")
    assert list(values)[: len(STATUS_KEYS) + 2] == [*STATUS_KEYS, ROLE_KEY, "bag"]
    assert values[ROLE_KEY] == "consumer" and ROLES == ("interp", "profile", "consumer")
    assert ROLE_KEY not in status_values("idle")  # no role given: none said
    with pytest.raises(ValueError, match=r"role='driver' is invalid: must be one of interp, profile"):
        status_values("idle", role="driver")


@pytest.mark.parametrize(
    ("name", "values", "namespace", "nodes", "want"),
    [
        ("axes: job", {"role": "consumer"}, "", (), True),  # any name, by its role
        ("cell1/axes: job", {"role": "consumer"}, "/cell1", (), True),
        ("cell1/axes: job", {"role": "consumer"}, "", (), False),  # another cell's
        ("c1/deeper/axes: job", {"role": "consumer"}, "c1", (), False),  # a deeper namespace's
        ("axes: stream", {"role": "consumer"}, "", (), False),  # not its job status
        ("sim_node: job", {"role": "profile"}, "", (), False),  # the role says, not the name
        ("sim_node: job", {}, "", (), True),  # before roles: the stock name
        ("axes: job", {}, "", (), False),  # no role, another name: unknown
        ("axes: job", {}, "", {"axes"}, True),  # ... unless known by other means (graph, winder/state)
        ("axes: job", {"role": "interp"}, "", {"axes"}, False),  # a role said wins over what is known
    ],
)
def test_has_role(name: str, values: dict[str, str], namespace: str, nodes: Any, want: bool) -> None:
    assert has_role(name, values, "consumer", namespace, nodes) is want


def _status(name: str, values: dict[str, object], level: int = 0, message: str = "") -> Any:
    KeyValue = STORE.types["diagnostic_msgs/msg/KeyValue"]
    Status = STORE.types["diagnostic_msgs/msg/DiagnosticStatus"]
    kvs = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
    return Status(level=level, name=name, message=message, hardware_id="test", values=kvs)


def _array(*statuses: Any) -> Any:
    Header = STORE.types["std_msgs/msg/Header"]
    Time = STORE.types["builtin_interfaces/msg/Time"]
    Array = STORE.types["diagnostic_msgs/msg/DiagnosticArray"]
    return Array(header=Header(stamp=Time(sec=0, nanosec=0), frame_id=""), status=list(statuses))


def write_bag(path: Path, ns: str, diagnostics: list[Any], states: tuple[Any, ...] = ()) -> Path:
    """A bag of one cell in ``ns``: its job, the /diagnostics arrays and the winder/state statuses given."""
    job = Job(job_id="tiny", turns_per_layer=1, layers=1, poles=1)
    String = STORE.types["std_msgs/msg/String"]
    text = String(data=describe_job(job, RUN))
    msgs: list[tuple[str, str, Any]] = [(f"{ns}/winder/job", "std_msgs/msg/String", text)]
    kinds = {True: "winder_interfaces/msg/CellState", False: "diagnostic_msgs/msg/DiagnosticStatus"}
    msgs += [(f"{ns}/winder/state", kinds[hasattr(s, "node")], s) for s in states]
    msgs += [("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", a) for a in diagnostics]
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns: dict[str, Any] = {}
        for t, (topic, msgtype, msg) in enumerate(msgs):
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=STORE)
            w.write(conns[topic], 1000 + t, STORE.serialize_cdr(msg, msgtype))
    return path


def final(state: str, role: str = "", **extra: object) -> dict[str, object]:
    return status_values(state, "tiny", RUN, 5, 5, role=role, **extra)


def test_the_reader_takes_the_consumers_report_by_its_role(tmp_path: Path) -> None:
    """A consumer named ``axes`` that says its role: its last job status is
    the report, not the interp or profile node's, not another cell's, not
    a status of another task."""
    bag = write_bag(
        tmp_path / "role",
        "",
        [
            _array(_status("axes: job", final("running", "consumer"))),
            _array(
                _status("interp_node: job", final("done", "interp")),
                _status("profile_node: job", final("done", "profile", profile="trapezoid")),
            ),
            _array(_status("axes: job", final("done", "consumer", bag="here", lost_steps=0))),
            _array(_status("c1/axes: job", final("incomplete", "consumer"))),  # another cell's consumer
            _array(_status("axes: stream", {"state": "incomplete"})),  # another task of the consumer
        ],
    )
    run = read_run(bag)
    assert run.report["state"] == "done" and run.report["bag"] == "here"
    assert run.report[ROLE_KEY] == "consumer"
    assert run.profile == "trapezoid"  # the profile node's status, found by its role too
    assert run.complete


def test_the_reader_takes_older_bags_by_the_stock_name(tmp_path: Path) -> None:
    """Before roles: the status of ``sim_node``, in the cell's namespace."""
    old = final("done", bag="old")
    bag = write_bag(
        tmp_path / "old",
        "/cell1",
        [
            _array(_status("cell1/sim_node: job", old)),
            _array(_status("cell1/interp_node: job", final("running"))),  # no role, not the consumer's name
            _array(_status("cell2/sim_node: job", final("incomplete"))),
        ],
    )
    run = read_run(bag)
    assert run.report["bag"] == "old" and ROLE_KEY not in run.report


def test_the_reader_takes_a_renamed_consumer_that_names_no_role_by_the_cell_state(tmp_path: Path) -> None:
    """A consumer running as ``axes`` that does not say its role yet: it is
    the node that announced the cell's state on winder/state, which only the
    consumer publishes, so its report is found all the same."""
    diagnostics = [
        _array(_status("interp_node: job", final("done", "interp"))),
        _array(_status("axes: job", final("done", bag="renamed"))),
    ]
    bag = write_bag(tmp_path / "renamed", "", diagnostics, (_status("axes: state", {"state": "done"}),))
    assert read_run(bag).report["bag"] == "renamed"  # an older bag: a DiagnosticStatus
    CellState = STORE.types["winder_interfaces/msg/CellState"]
    Time = STORE.types["builtin_interfaces/msg/Time"]
    typed = CellState(
        stamp=Time(sec=0, nanosec=0),
        node="axes",
        state="done",
        job_id="tiny",
        run_id=RUN,
        coil=1,
        layer=1,
        turn=1,
        sim_time_s=1.0,
        message="done",
    )
    bag = write_bag(tmp_path / "typed", "", diagnostics, (typed,))
    assert read_run(bag).report["bag"] == "renamed"  # a CellState names its node
    # without winder/state nothing says axes is the consumer: no report, and analyze says so
    bare = write_bag(tmp_path / "bare", "", diagnostics)
    assert read_run(bare).report == {}
