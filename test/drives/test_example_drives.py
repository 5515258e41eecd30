"""The drives files shipped for users (``winder.drives.EXAMPLES``, package data
that pip and colcon install with the package; the checkout's ``drives/`` links
there): each passes the drives-file check as it is, the socketcan one without a
bus being opened, and docs/DRIVES.md names both, where they are in a checkout
and where an install has them."""

from __future__ import annotations

import ast
import math

import can
import canopen
import pytest
import tomllib
from support.paths import ROOT

from winder.drives import EXAMPLES, load_drives
from winder.drives.twin import EDS_PATH
from winder.motion.job import Job

SOCKETCAN = EXAMPLES / "example_socketcan.yaml"
TWIN = EXAMPLES / "twin.yaml"
#: the package's directory: package data patterns are relative to it
PACKAGE = ROOT / "src" / "winder"


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
    assert "winder.drives.EXAMPLES" in doc  # where an installed winder has them


def test_the_examples_are_package_data_for_pip_and_colcon() -> None:
    """Each example matches a package-data pattern of ``winder`` in pyproject.toml
    (pip) and in src/setup.py (colcon), globbed from the package as setuptools does;
    the checkout's ``drives/`` is the same directory."""
    examples = {p.relative_to(PACKAGE).as_posix() for p in EXAMPLES.glob("*.yaml")}
    assert examples == {"drives/examples/example_socketcan.yaml", "drives/examples/twin.yaml"}
    pip = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    [setup] = [
        node
        for node in ast.walk(ast.parse((ROOT / "src" / "setup.py").read_text()))
        if isinstance(node, ast.keyword) and node.arg == "package_data"
    ]
    colcon = ast.literal_eval(setup.value)
    for name, patterns in (("pyproject.toml", pip["winder"]), ("src/setup.py", colcon["winder"])):
        installed = {p.relative_to(PACKAGE).as_posix() for pattern in patterns for p in PACKAGE.glob(pattern)}
        assert examples <= installed, (name, patterns)
    assert (ROOT / "drives").resolve() == EXAMPLES.resolve()
