"""The drives files shipped for users (drives/): each passes the drives-file
check as it is, the socketcan one without a bus being opened, and
docs/DRIVES.md names both."""

from __future__ import annotations

import math

import can
import canopen
import pytest
from support.paths import ROOT

from winder.drives import load_drives
from winder.drives.twin import EDS_PATH
from winder.motion.job import Job

SOCKETCAN = ROOT / "drives" / "example_socketcan.yaml"
TWIN = ROOT / "drives" / "twin.yaml"


@pytest.fixture
def no_bus(monkeypatch: pytest.MonkeyPatch) -> None:
    """Opening a bus fails the test: the check reads files only."""

    def opened(*_args: object, **_kwargs: object) -> None:
        raise AssertionError("a bus was opened")

    monkeypatch.setattr(canopen.Network, "connect", opened)
    monkeypatch.setattr(can, "Bus", opened)


def test_the_socketcan_example_is_a_real_bus_of_three_axes(no_bus: None) -> None:
    cfg = load_drives(SOCKETCAN)
    assert (cfg.bus.interface, cfg.bus.channel, cfg.bus.bitrate) == ("socketcan", "can0", 500_000)
    assert [d.axis for d in cfg.axes] == ["feed", "fork", "pole"]
    assert len({d.node_id for d in cfg.axes}) == 3
    assert cfg.twin_fault is None
    # the EDS placeholders are the twin's (so it parses), each one said to be replaced
    assert {d.eds for d in cfg.axes} == {EDS_PATH}
    placeholders = [ln for ln in SOCKETCAN.read_text().splitlines() if ln.strip().startswith("eds:")]
    assert len(placeholders) == 3 and all("PLACEHOLDER" in ln for ln in placeholders), placeholders
    # at least one count per step of the default job (the run refuses less)
    job = Job()
    steps = (job.feed_step, 2 * math.pi / job.fork_steps_per_rev, 2 * math.pi / job.pole_steps_per_rev)
    for drive, step in zip(cfg.axes, steps, strict=True):
        assert drive.counts_per_unit * step >= 1.0, drive.axis


def test_the_twin_example_is_a_virtual_bus(no_bus: None) -> None:
    cfg = load_drives(TWIN)
    assert cfg.bus.interface == "virtual"
    assert {d.eds for d in cfg.axes} == {EDS_PATH}


def test_the_drives_doc_names_both() -> None:
    doc = (ROOT / "docs" / "DRIVES.md").read_text()
    assert "drives/example_socketcan.yaml" in doc and "drives/twin.yaml" in doc
