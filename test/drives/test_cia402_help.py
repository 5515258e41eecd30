"""``cia402_node --help``: the executable as a user starts it answers with every
parameter the node declares (``DriverNode.parameters(DrivesBackend)``, the one
table), starts no node, and loads neither canopen nor python-can nor the
drives' backend and twin on the way (they took half of the answer's time)."""

from __future__ import annotations

import subprocess
import sys

from support.paths import BIN

from winder.ros.cia402_node import DrivesBackend
from winder.ros.driver import DriverNode

#: a help that has not come by then is a node running (it would run until killed)
HELP_TIMEOUT_S = 60.0


def test_cia402_node_help_lists_every_parameter_it_declares() -> None:
    r = subprocess.run(
        [str(BIN / "cia402_node"), "--help"],
        capture_output=True,
        text=True,
        timeout=HELP_TIMEOUT_S,
        stdin=subprocess.DEVNULL,
        check=False,
    )
    assert (r.returncode, r.stderr) == (0, ""), r.stdout + r.stderr
    assert r.stdout.startswith("usage: cia402_node [-h] [--ros-args"), r.stdout
    listed = {
        line.split(":=", 1)[0].strip()
        for line in r.stdout.splitlines()
        if line.startswith("  ") and ":=" in line.split()[0]
    }
    assert listed == {*DriverNode.parameters(DrivesBackend), "managed"}, r.stdout
    [drives_file] = [line.split() for line in r.stdout.splitlines() if line.startswith("  drives_file:=")]
    assert drives_file[:4] == ["drives_file:=''", "the", "drives", "file"], drives_file


def test_the_help_loads_no_can_library() -> None:
    code = (
        "import sys\n"
        "from winder.ros.cia402_node import main\n"
        "main(['cia402_node', '--help'])\n"
        "heavy = ('canopen', 'can', 'winder.drives.backend', 'winder.drives.twin')\n"
        "print(sorted(m for m in heavy if m in sys.modules))\n"
    )
    r = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=HELP_TIMEOUT_S, check=True
    )
    assert r.stdout.splitlines()[-1] == "[]", r.stdout
