"""A ``winder`` command as a user runs it, and its one-line errors."""

from __future__ import annotations

import subprocess

from support.paths import BIN
from winder.procs import run


def run_cli(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    """``winder *args`` (in ``env``: this process' environment if None), dying with the test process."""
    return run(
        [str(BIN / "winder"), *args],
        capture_output=True,
        text=True,
        timeout=120,
        stdin=subprocess.DEVNULL,
        env=env,
    )


def assert_one_line_error(r: subprocess.CompletedProcess[str], *needles: str, code: int = 2) -> None:
    """One line on stderr holding every needle, no traceback, exit ``code`` (2: bad input)."""
    assert r.returncode == code, r.stdout + r.stderr
    assert "Traceback" not in r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    for n in needles:
        assert n in lines[0], lines[0]
