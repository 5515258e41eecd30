"""Build a ROS 2 interface package (ament_cmake: msg/srv/action) into a venv holding the Jazzy wheels.

    python build_interfaces.py <package_dir> <venv_dir> [--build-dir DIR]

Run it with the venv's python. Skips the build when the definitions are unchanged (a hash stamp in
<venv>/share/<pkg>/) and the generated Python package still imports; otherwise configures, builds and
installs into the venv (nothing to source afterwards). Exit 0: done or up to date; 1: the build failed
(the log's tail is printed); 2: cmake or a compiler is missing.
"""

from __future__ import annotations

import argparse
import fcntl
import hashlib
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

STAMP = ".winder_build_stamp"
KINDS = ("msg", "srv", "action")


def missing_tools() -> list[str]:
    """Debian packages to install for what is missing: cmake, make, a C and a C++ compiler."""
    need = []
    if not shutil.which("cmake"):
        need.append("cmake")
    if not shutil.which("make"):
        need.append("make")
    if not (shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc") or shutil.which("clang")):
        need.append("gcc")
    if not (shutil.which(os.environ.get("CXX", "c++")) or shutil.which("g++") or shutil.which("clang++")):
        need.append("g++")
    return need


def definitions_hash(pkg: Path) -> str:
    files = [pkg / "package.xml", pkg / "CMakeLists.txt"]
    for kind in KINDS:
        files += sorted(p for p in (pkg / kind).glob("*") if p.is_file())
    h = hashlib.sha256()
    for f in files:
        if f.is_file():
            h.update(f.relative_to(pkg).as_posix().encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()


def imports(python: Path, name: str, pkg: Path) -> bool:
    """In a fresh process: import each generated subpackage and load one type's C type support."""
    code = [f"import {name}"]
    for kind in KINDS:
        if any((pkg / kind).glob(f"*.{kind}")):
            code.append(
                f"import {name}.{kind} as m; t = getattr(m, sorted(n for n in dir(m) "
                f"if n[0].isupper())[0]); t.__class__.__import_type_support__()"
            )
    res = subprocess.run([str(python), "-c", "\n".join(code)], capture_output=True, cwd=python.parent)
    return res.returncode == 0


def run(cmd: list[str], log: Path, env: dict[str, str]) -> bool:
    with log.open("a") as out:
        out.write("\n$ " + " ".join(cmd) + "\n")
        out.flush()
        return subprocess.run(cmd, stdout=out, stderr=subprocess.STDOUT, env=env).returncode == 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("package_dir", type=Path)
    ap.add_argument("venv_dir", type=Path)
    ap.add_argument("--build-dir", type=Path, help="cmake build directory (default <venv>/build/<pkg>)")
    args = ap.parse_args()
    pkg, venv = args.package_dir.resolve(), args.venv_dir.resolve()
    name = ET.parse(pkg / "package.xml").getroot().findtext("name", "").strip()
    python = venv / "bin" / "python"
    build = (args.build_dir.resolve() / name) if args.build_dir else venv / "build" / name

    need = missing_tools()
    if need:
        print(
            f"{name}: cannot build the ROS interfaces: missing {', '.join(need)} "
            f"(apt-get install {' '.join(need)})"
        )
        return 2

    stamp = venv / "share" / name / STAMP
    digest = definitions_hash(pkg)
    build.mkdir(parents=True, exist_ok=True)
    with (build / ".lock").open("w") as lock:  # parallel callers (test workers) build once, in turn
        fcntl.flock(lock, fcntl.LOCK_EX)
        if stamp.is_file() and stamp.read_text().strip() == digest and imports(python, name, pkg):
            print(f"{name}: up to date in {venv}")
            return 0
        print(f"{name}: building into {venv} (cmake, about a minute; log {build / 'build.log'})", flush=True)
        stamp.unlink(missing_ok=True)
        log = build / "build.log"
        log.write_text("")
        # the venv alone: no sourced ROS install or foreign PYTHONPATH mixed in
        env = {
            k: v
            for k, v in os.environ.items()
            if k not in ("AMENT_PREFIX_PATH", "CMAKE_PREFIX_PATH", "PYTHONPATH", "COLCON_PREFIX_PATH")
        }
        env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"
        steps = {
            "configure": [
                "cmake",
                "-S",
                str(pkg),
                "-B",
                str(build),
                f"-DCMAKE_PREFIX_PATH={venv}",
                f"-DCMAKE_INSTALL_PREFIX={venv}",
                f"-DPython3_EXECUTABLE={python}",
                "-DBUILD_TESTING=OFF",
            ],
            "build": ["cmake", "--build", str(build), "-j2"],
            "install": ["cmake", "--install", str(build)],
        }
        for phase, cmd in steps.items():
            if not run(cmd, log, env):
                tail = log.read_text(errors="replace").splitlines()[-40:]
                print("\n".join(tail), file=sys.stderr)
                print(f"{name}: {phase} failed; full log: {log}", file=sys.stderr)
                return 1
        if not imports(python, name, pkg):
            print(f"{name}: installed, but `import {name}` fails with {python}", file=sys.stderr)
            return 1
        stamp.write_text(digest + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
