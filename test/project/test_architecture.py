"""The import rules of docs/ARCHITECTURE.md, read from the code itself.

* Arrows only go down the layers: ``errors`` < ``procs`` < ``interrupts`` < ``spec`` < ``shaping`` <
  ``motion`` < ``axis`` < ``tension`` < ``drives`` < ``contract`` < ``record`` < ``analysis`` <
  ``ros`` < ``cli``; a module may import its own layer and those below, never one above.
* No circles: no module of the library imports, through any chain of
  imports (those inside functions and under ``TYPE_CHECKING`` too), a module
  that imports it.
* Nothing under ``winder/`` imports a node package.
* Only ``winder.ros`` (and the node packages) import rclpy or ROS message
  packages; only ``winder.analysis.figures`` imports matplotlib.
* Importing every other module leaves rclpy out of ``sys.modules`` (the core
  stays usable without a ROS install).
"""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest
from support.paths import ROOT

SRC = ROOT / "src" / "winder"
LAYERS = (
    "errors",
    "procs",
    "interrupts",
    "spec",
    "shaping",
    "motion",
    "axis",
    "tension",
    "drives",
    "contract",
    "record",
    "analysis",
    "ros",
    "cli",
)
NODE_PACKAGES = ("winder_interp", "winder_profile", "winder_sim")
ROS_PACKAGES = (
    "rclpy",
    "rcl_interfaces",
    "std_msgs",
    "std_srvs",
    "sensor_msgs",
    "trajectory_msgs",
    "diagnostic_msgs",
    "rosgraph_msgs",
    "builtin_interfaces",
    "launch",
    "launch_ros",
)


def module_name(path: Path) -> str:
    parts = path.relative_to(SRC.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> list[tuple[str, Path]]:
    return sorted((module_name(p), p) for p in SRC.rglob("*.py"))


def imports(path: Path) -> set[str]:
    """Every module name imported anywhere in the file (also inside functions)."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
            found.update(f"{node.module}.{a.name}" for a in node.names)
    return found


def layer(name: str) -> str | None:
    """The layer of a ``winder`` module name (None: the package root)."""
    parts = name.split(".")
    return parts[1] if len(parts) > 1 and parts[0] == "winder" else None


def test_every_module_is_in_a_layer() -> None:
    for name, _ in modules():
        assert name == "winder" or layer(name) in LAYERS, f"{name} is in no layer of {LAYERS}"


@pytest.mark.parametrize(("name", "path"), modules(), ids=[n for n, _ in modules()])
def test_imports_only_go_down(name: str, path: Path) -> None:
    own = layer(name)
    rank = LAYERS.index(own) if own in LAYERS else -1
    for imp in imports(path):
        top = imp.split(".")[0]
        assert top not in NODE_PACKAGES, f"{name} imports the node package {imp}"
        if top in ROS_PACKAGES:
            assert own == "ros", f"{name} imports {imp}: only winder.ros may import ROS packages"
        if top == "matplotlib":
            assert name.startswith("winder.analysis.figures"), f"{name} imports matplotlib"
        target = layer(imp)
        if top == "winder" and target in LAYERS:
            assert LAYERS.index(target) <= rank, f"{name} ({own}) imports {imp} ({target}), a layer above"


def import_graph() -> dict[str, set[str]]:
    """Module -> the library's modules it imports (a name imported from a
    module is that module; a package's ``__init__`` is a module too)."""
    known = {name for name, _ in modules()}
    graph: dict[str, set[str]] = {}
    for name, path in modules():
        targets = set()
        for imp in imports(path):
            while imp and imp not in known:
                imp = imp.rpartition(".")[0]
            if imp and imp != name:
                targets.add(imp)
        graph[name] = targets
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected parts of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            part = []
            while True:
                w = stack.pop()
                on.discard(w)
                part.append(w)
                if w == v:
                    break
            if len(part) > 1:
                found.append(sorted(part))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_circles_are_found() -> None:
    """The oracle of the next test: a loop is found, a chain is not."""
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert circles({"a": {"b"}, "b": {"c"}, "c": set()}) == []


def test_no_module_imports_itself_through_others() -> None:
    """Each concern in one place, arrows only downward: a circle of imports
    (even one closed inside a function or for type checking only) means two
    modules hold one concern between them."""
    graph = import_graph()
    loops = circles(graph)
    ties = ["; ".join(f"{a} -> {b}" for a in loop for b in sorted(graph[a]) if b in loop) for loop in loops]
    assert not loops, f"import circles: {ties}"


def test_the_core_imports_without_rclpy() -> None:
    core = [n for n, _ in modules() if layer(n) != "ros" and not n.endswith("__main__")]
    code = (
        "import importlib, sys\n"
        f"for m in {core!r}:\n"
        "    importlib.import_module(m)\n"
        "bad = sorted(m for m in sys.modules if m.split('.')[0] in "
        f"{ROS_PACKAGES!r})\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "", f"importing the core pulled in ROS modules: {out.stdout.strip()}"


#: rosdep keys of the Python libraries the code imports (ROS packages are their own key)
PYTHON_KEYS = {
    "numpy": "python3-numpy",
    "matplotlib": "python3-matplotlib",
    "ruamel": "python3-ruamel.yaml",
    "lz4": "python3-lz4",
    "zstandard": "python3-zstandard",
    "can": "python3-can",
}
#: pip packages with no rosdep key, named in the core's package.xml comment instead
PIP_ONLY = {"mcap", "rosbags", "backports", "foxglove", "canopen"}
#: the standard library of later Pythons (zstd is ``compression.zstd`` from 3.14)
LATER_STDLIB = {"compression"}


def _top_imports(root: Path) -> set[str]:
    """Top-level modules imported anywhere under ``root`` (setup.py aside)."""
    names: set[str] = set()
    for path in root.rglob("*.py"):
        if path.name == "setup.py" or "egg-info" in str(path):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names |= {a.name.split(".")[0] for a in node.names}
                if any(a.name.startswith("rclpy.lifecycle") for a in node.names):
                    names.add("lifecycle_msgs")
            elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                names.add(node.module.split(".")[0])
                if node.module.startswith("rclpy.lifecycle"):
                    names.add("lifecycle_msgs")  # rclpy's lifecycle nodes speak it
    return names


@pytest.mark.parametrize("package", ["src", "winder_interp", "winder_profile", "winder_sim", "winder_bridge"])
def test_package_xml_lists_what_the_code_imports(package: str) -> None:
    """A colcon or rosdep user gets every dependency from package.xml: each
    module the package's code imports, beyond the standard library and the
    package itself, is an exec_depend (ROS packages by name, Python
    libraries by their python3-* key); mcap and rosbags, which rosdep has no
    key for, are named in a comment."""
    xml = (ROOT / package / "package.xml").read_text()
    depends = set(re.findall(r"<exec_depend>([^<]+)</exec_depend>", xml))
    own = "winder" if package == "src" else package
    code = ROOT / package / ("winder" if package == "src" else package)
    launch = ROOT / package / "launch"
    imported = _top_imports(code) | (_top_imports(launch) if launch.is_dir() else set())
    imported -= {*sys.stdlib_module_names, *LATER_STDLIB, own, "__future__"}
    missing = []
    for name in sorted(imported):
        if name in PIP_ONLY:
            assert name in xml, f"{package}/package.xml: {name} (pip) is not named"
            continue
        key = PYTHON_KEYS.get(name, name)
        if key not in depends:
            missing.append(key)
    assert not missing, f"{package}/package.xml lacks exec_depend {missing}"
    assert "example.com" not in xml and "winder@users.noreply.github.com" in xml
