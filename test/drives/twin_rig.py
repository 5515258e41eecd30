"""Fixtures of the drives tests (imported by the test modules that use them: a
conftest.py here would be a second module named ``conftest`` beside test/conftest.py,
which the other directories import from): a CAN bus of the test's own (python-can's
``virtual`` interface passes frames between the buses of one channel name in
this process; a channel per test keeps tests apart) with drive twins on it."""

from __future__ import annotations

import itertools
import os
from collections.abc import Iterator
from typing import Any

import canopen
import pytest

from winder.drives import SimulatedDrive

_ids = itertools.count()
#: how long a network's receive thread may take to see it is stopped (s; canopen's default is 1)
QUICK_CLOSE = 0.05


@pytest.fixture(name="channel")
def channel_fixture() -> str:
    """A virtual CAN channel no other test uses."""
    return f"winder-test-{os.getpid()}-{next(_ids)}"


class Twins:
    """Drive twins on their own network (the drives' side of the bus)."""

    def __init__(self, channel: str) -> None:
        self.network = canopen.Network()
        self.network.NOTIFIER_CYCLE = QUICK_CLOSE
        self.network.connect(interface="virtual", channel=channel)
        self.drives: dict[int, SimulatedDrive] = {}

    def add(self, node_id: int, **kwargs: Any) -> SimulatedDrive:
        self.drives[node_id] = SimulatedDrive(self.network, node_id, **kwargs)
        return self.drives[node_id]

    def close(self) -> None:
        for drive in self.drives.values():
            drive.stop()
        self.network.disconnect()


@pytest.fixture(name="twins")
def twins_fixture(channel: str) -> Iterator[Twins]:
    t = Twins(channel)
    yield t
    t.close()


@pytest.fixture(name="master")
def master_fixture(channel: str) -> Iterator[canopen.Network]:
    """The controller's side of the test's bus."""
    network = canopen.Network()
    network.NOTIFIER_CYCLE = QUICK_CLOSE
    network.connect(interface="virtual", channel=channel)
    yield network
    network.sync.stop()
    network.disconnect()
