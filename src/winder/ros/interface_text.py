"""``winder ctl interface show``: an interface's definition as ``ros2
interface show`` prints it, on the pip install that has no ``ros2`` command.

The text is the installed ``.msg``, ``.srv`` or ``.action`` file (under
``share/<package>/`` of a prefix on ``AMENT_PREFIX_PATH``, or of this
Python's environment, where the venv build installs ``winder_interfaces``);
below each field of a message type its definition follows, indented by a
tab, without its comments, as ``ros2 interface show`` expands a nested type.
Nothing here needs rclpy.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from winder.errors import BadInputError

__all__ = ["KINDS", "definition_path", "interface_lines"]

#: the kinds of interface, each its folder and file suffix
KINDS = ("msg", "srv", "action")
#: rosidl's primitive types: a field of one of these has no definition to expand
PRIMITIVES = frozenset(
    {"bool", "byte", "char", "float32", "float64", "string", "wstring"}
    | {f"{sign}int{bits}" for sign in ("", "u") for bits in (8, 16, 32, 64)}
)


def prefixes() -> list[Path]:
    """Where installed packages are: ``AMENT_PREFIX_PATH`` (a sourced ROS
    install or colcon workspace) first, then this Python's environment."""
    found = [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    return list(dict.fromkeys([*found, Path(sys.prefix)]))


def definition_path(type_name: str) -> Path:
    """The file of ``package/kind/Name`` (``winder_interfaces/msg/CellState``);
    :class:`BadInputError` in one line naming what was not found and what
    there is instead."""
    parts = type_name.split("/")
    if len(parts) != 3 or parts[1] not in KINDS or not all(parts):
        raise BadInputError(
            f"TYPE={type_name!r} is invalid: must be PACKAGE/KIND/NAME with KIND one of "
            f"{', '.join(KINDS)} (winder_interfaces/msg/CellState)"
        )
    package, kind, name = parts
    shares = [p / "share" / package for p in prefixes() if (p / "share" / package).is_dir()]
    if not shares:
        raise BadInputError(f"unknown package {package!r} (looked in {', '.join(map(str, prefixes()))})")
    for share in shares:
        path = share / kind / f"{name}.{kind}"
        if path.is_file():
            return path
    have = sorted({f"{p.parent.name}/{p.stem}" for s in shares for k in KINDS for p in s.glob(f"{k}/*.{k}")})
    raise BadInputError(f"unknown type {type_name!r}: {package} has {', '.join(have) or 'no interfaces'}")


def _field_type(line: str, package: str) -> str | None:
    """The message type a definition line's field is of (``pkg/msg/Name``),
    None for a comment, a constant, a separator or a primitive field."""
    words = line.split("#", 1)[0].split()
    if len(words) < 2 or "=" in words[1] or "=" in words[0]:
        return None
    base = words[0].split("[", 1)[0].split("<=", 1)[0]
    if base in PRIMITIVES:
        return None
    pkg, _, name = base.rpartition("/")
    return f"{pkg or package}/msg/{name}"


def interface_lines(type_name: str, *, comments: str = "top", depth: int = 0) -> list[str]:
    """The lines ``ros2 interface show TYPE`` prints: the file's, and each
    nested message type's below its field, a tab deeper. ``comments``:
    ``top`` keeps the top file's comments (the nested types' are left out),
    ``all`` keeps every comment, ``none`` leaves them all out."""
    package = type_name.split("/", 1)[0]
    text = definition_path(type_name).read_text(encoding="utf-8")
    keep = comments == "all" or (comments == "top" and depth == 0)
    out = []
    for raw in text.rstrip().splitlines():
        line = raw.rstrip() if keep else raw.split("#", 1)[0].rstrip()
        if not keep and not line:
            continue
        out.append("\t" * depth + line if line else "")
        nested = _field_type(raw, package)
        if nested is not None:
            out += interface_lines(nested, comments=comments, depth=depth + 1)
    return out
