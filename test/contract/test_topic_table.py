"""One row per topic (issue 57): winder.contract.topic_table.TOPICS is the
only table of the cell's topics; the QoS table, trust's owners and signs,
the recorded topics of every consumer, the simulator and the drivers, and
the live view's channels are made from it, and docs/CONTRACT.md §2 says
the same."""

from __future__ import annotations

import re
import subprocess
import sys

from support.paths import ROOT

from winder.contract.topic_table import EVERY, PACED, SIM, TOPICS

CONTRACT = ROOT / "docs" / "CONTRACT.md"


def contract_rows() -> dict[str, list[str]]:
    """CONTRACT.md §2's topic table: topic -> its cells."""
    text = CONTRACT.read_text()
    section = text[text.index("| topic | type | QoS |") :]
    table = section[: section.index("\n\n")]
    rows: dict[str, list[str]] = {}
    for line in table.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        m = re.fullmatch(r"`([^`]+)`", cells[0]) if line.startswith("| `") else None
        if m:
            rows[m.group(1)] = cells[1:]
    return rows


def test_the_contracts_topic_table_is_the_codes() -> None:
    """Each row of CONTRACT.md §2 (topic, type, QoS, publisher, bag) is the
    row of TOPICS, in the same order, and no topic is missing on either side."""
    rows = contract_rows()
    assert list(rows) == [t.name for t in TOPICS]
    for t in TOPICS:
        kind, qos, publisher, _subscriber, bag = rows[t.name]
        package, _, name = t.type.partition("/msg/")
        assert re.match(rf"`{package}/{name}`", kind), (t.name, kind)
        assert qos == t.qos, (t.name, qos)
        if t.owner:
            assert publisher.split()[0] == t.owner, (t.name, publisher)
        else:  # several publish it, each saying who it is
            assert publisher.split()[0] in ("every", "consumer"), (t.name, publisher)
        assert bag.startswith("yes") == bool(t.key), (t.name, bag)


def test_every_recorded_topic_is_held_by_its_recordings() -> None:
    """The consumer's, the simulator's and a driver's recorded topics are the table's."""
    from winder_sim.sim_node import SIM_TOPICS

    from winder.ros.consumer import CONSUMER_TOPICS
    from winder.ros.driver import DriverNode

    every = {t.key: (t.name, t.type) for t in TOPICS if t.kept == EVERY}
    paced = {t.key: (t.name, t.type) for t in TOPICS if t.kept == PACED}
    sim = {t.key: (t.name, t.type) for t in TOPICS if t.kept == SIM}
    assert every == CONSUMER_TOPICS
    assert paced == DriverNode.TOPICS
    assert {**paced, **sim} == SIM_TOPICS


#: run in a fresh interpreter: one row added to the table before anything reads it
THROWAWAY = """
from winder.contract import topic_table as table
row = table.Topic(
    "winder/throwaway", "std_msgs/msg/String", "latched", "consumer", True, True, "throwaway", "every"
)
table.TOPICS = (*table.TOPICS, row)
from winder.contract.qos import LATCHED, TOPIC_QOS, qos_of
from winder.contract.trust import OWNERS, SHOWN
from winder.ros.consumer import CONSUMER_TOPICS
from winder.ros.view import VIEW_TOPICS
assert TOPIC_QOS["winder/throwaway"] == LATCHED and qos_of("/cell1/winder/throwaway") == LATCHED
assert OWNERS["winder/throwaway"] == "consumer" and SHOWN["winder/throwaway"] == "consumer"
assert CONSUMER_TOPICS["throwaway"] == ("winder/throwaway", "std_msgs/msg/String")
assert any(v.name == "winder/throwaway" and v.qos == LATCHED for v in VIEW_TOPICS)
print("one row")
"""


def test_a_topic_is_one_row() -> None:
    """A throwaway topic added as one row of TOPICS is in the QoS table, is
    trusted from its owner only, shown by the live view and recorded in every
    consumer's bag: nothing else to edit (docs/ARCHITECTURE.md's change table)."""
    done = subprocess.run([sys.executable, "-c", THROWAWAY], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stdout.strip() == "one row", done.stdout + done.stderr
