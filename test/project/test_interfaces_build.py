"""winder_interfaces' build into the venv (winder_interfaces/build_into_venv.py,
run by make): a machine without cmake or a compiler gets one line naming what
to install, and the build is skipped while the definitions are unchanged
and the generated package imports."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from support.paths import ROOT

SCRIPT = ROOT / "winder_interfaces" / "build_into_venv.py"
VENV = Path(sys.executable).parent.parent


def test_without_cmake_or_a_compiler_one_line_says_what_to_install(tmp_path: Path) -> None:
    out = subprocess.run(
        [sys.executable, str(SCRIPT), str(ROOT / "winder_interfaces"), str(tmp_path / "venv")],
        env={"PATH": str(tmp_path)},  # nothing on it: no cmake, make, cc or c++
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2, out.stdout + out.stderr
    lines = (out.stdout + out.stderr).strip().splitlines()
    assert len(lines) == 1, lines
    assert "cannot build the ROS interfaces: missing cmake, make, gcc, g++" in lines[0], lines[0]
    assert not (tmp_path / "venv").exists()  # nothing half-made


def test_unchanged_definitions_are_not_built_again() -> None:
    out = subprocess.run(
        [sys.executable, str(SCRIPT), str(ROOT / "winder_interfaces"), str(VENV)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.strip() == f"winder_interfaces: up to date in {VENV}", out.stdout


def test_the_contract_shows_each_interface_as_its_file_says() -> None:
    """docs/CONTRACT.md shows `ros2 interface show` of each winder_interfaces
    type: the definition file's text, as it is."""
    contract = (ROOT / "docs" / "CONTRACT.md").read_text()
    package = ROOT / "winder_interfaces"
    files = sorted([*package.glob("msg/*.msg"), *package.glob("action/*.action")])
    assert files
    for f in files:
        shown = f"$ ros2 interface show winder_interfaces/{f.parent.name}/{f.stem}\n{f.read_text()}"
        assert shown in contract, f"docs/CONTRACT.md does not show {f.relative_to(ROOT)} as it is"


def test_integrating_names_each_interface_and_where_the_contract_shows_it() -> None:
    """docs/INTEGRATING.md lists every winder_interfaces type with a link to
    the CONTRACT.md section that shows its text, and each link's anchor is a
    heading of CONTRACT.md that holds that text."""
    import re

    integrating = (ROOT / "docs" / "INTEGRATING.md").read_text()
    contract = (ROOT / "docs" / "CONTRACT.md").read_text()
    sections: dict[str, str] = {}  # GitHub's anchor of each heading -> the section's text
    for part in re.split(r"^(?=#{2,4} )", contract, flags=re.M):
        heading = part.splitlines()[0].lstrip("#").strip() if part.startswith("#") else ""
        anchor = re.sub(r"[^\w\- ]", "", heading.lower()).replace(" ", "-")
        sections[anchor] = part
    package = ROOT / "winder_interfaces"
    for f in sorted([*package.glob("msg/*.msg"), *package.glob("action/*.action")]):
        row = next(
            (
                r
                for r in integrating.splitlines()
                if r.startswith("| `winder_interfaces/")
                and (f"winder_interfaces/{f.parent.name}/{f.stem}`" in r or f"`{f.stem}`" in r)
            ),
            None,
        )
        assert row, f"docs/INTEGRATING.md does not list {f.stem}"
        [anchor] = re.findall(r"\(CONTRACT\.md#([^)]+)\)", row)
        assert anchor in sections, f"{f.stem}: no heading of CONTRACT.md has the anchor {anchor}"
        assert f"$ ros2 interface show winder_interfaces/{f.parent.name}/{f.stem}\n" in sections[anchor], (
            f.stem
        )
