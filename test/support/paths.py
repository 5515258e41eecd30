"""Where things are: the repository, the test tree, the venv's executables."""

from __future__ import annotations

import sys
from pathlib import Path

#: the repository's root
ROOT = Path(__file__).resolve().parents[2]
#: the test tree (test/)
TEST = ROOT / "test"
#: the venv's executables (winder, the node executables)
BIN = Path(sys.executable).parent
