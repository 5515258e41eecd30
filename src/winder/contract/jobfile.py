"""Job files: a winding job as a file a user writes and versions (ROS-free).

A job file is a ROS 2 parameters file, so one file serves every way a cell is
started::

    ros2 run winder_sim sim_node --ros-args --params-file jobs/rw400.yaml   # each node its section
    winder run jobs/rw400.yaml                                            # the whole cell
    ros2 param set /interp_node job_file jobs/rw400.yaml                  # the job and its ramp

Sections, one per node (a namespace in front is allowed: ``/cell1/sim_node``;
``/**`` gives values to every node that has them), each with the standard
``ros__parameters`` map:

* ``interp_node``: the coil (wire, turns per layer, layers, poles, coil
  length) and the machine's resolution (fork and pole steps per revolution,
  feed step, flyer radius);
* ``profile_node``: the ramp;
* ``consumer`` (or ``sim_node``, its stock node name; not both): the step
  consumer's settings, the motors (``fork: {J: 2.0e-4, D: 0.03}`` is
  ``fork.J``, ``fork.D``) and the simulation. The section is the consumer's
  by its role, whatever the consumer's node name: :func:`load_job_file`
  returns it under ``"consumer"``, and ``winder run`` gives it to the
  consumer it starts, or sets it on an external one (``--external sim``)
  through that node's parameter services.

``ros2 run ... --params-file`` is ROS's own loader: it applies only the
sections named after the node (or ``/**``). A ``consumer:`` section is
applied by ``winder run`` only; for ``ros2 run`` name the section after the
node (``sim_node:``, as the files in ``jobs/`` do), or use ``/**`` for a
consumer running under another name (``-r __node:=axes``; a section named
``axes:`` is not a winder section and is refused here).

:func:`load_job_file` checks every value as the nodes would, and the
sections together (the coil fits, the ramp can plan its moves); an error
names the file, the key path and the allowed range, in one line.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

from winder.contract.params import (
    INTERP_SPECS,
    PROFILE_SPECS,
    SIM_SPECS,
    check_interp,
    check_profile,
    check_sim,
)
from winder.spec import Spec, SpecError

__all__ = [
    "NODE_SPECS",
    "SECTION_ALIASES",
    "JobFileError",
    "load_job_file",
    "load_job_file_hashed",
    "section_node",
]

#: the sections of a job file and the settings each may hold (job_file and
#: its hash excluded: a file cannot name itself); the keys of what :func:`load_job_file` returns
NODE_SPECS: dict[str, dict[str, Spec]] = {
    "interp_node": {n: s for n, s in INTERP_SPECS.items() if n not in ("job_file", "job_file_sha256")},
    "profile_node": PROFILE_SPECS,
    "consumer": SIM_SPECS,
}
#: other names a section may have: ``sim_node``, the stock consumer's node
#: name (so that ``ros2 run winder_sim sim_node --params-file`` applies it too)
SECTION_ALIASES = {"sim_node": "consumer"}
#: the section names a job file may use, for messages
SECTION_NAMES = "interp_node, profile_node, consumer (or sim_node) or /**"
#: a job file larger than this is not a job file
MAX_BYTES = 1 << 20


class JobFileError(SpecError):
    """A job file cannot be used; the message names the file and the key, in one line."""


def _flatten(prefix: str, value: Any, out: dict[str, Any]) -> None:
    if isinstance(value, dict):
        for k, v in value.items():
            _flatten(f"{prefix}.{k}" if prefix else str(k), v, out)
    else:
        out[prefix] = value


def _read(path: Path) -> tuple[Any, str]:
    from ruamel.yaml import YAML
    from ruamel.yaml.error import YAMLError

    try:
        size = path.stat().st_size
    except FileNotFoundError:
        raise JobFileError(f"{path}: no such job file") from None
    except OSError as exc:
        raise JobFileError(f"{path}: cannot be read: {exc.strerror or exc}") from None
    if not path.is_file():
        raise JobFileError(f"{path}: not a file")
    if size > MAX_BYTES:
        raise JobFileError(f"{path}: {size} bytes, more than a job file holds ({MAX_BYTES})")
    try:
        data = path.read_bytes()
        text = data.decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise JobFileError(f"{path}: cannot be read: {str(exc).splitlines()[0]}") from None
    try:
        doc = YAML(typ="safe", pure=True).load(text)
    except YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise JobFileError(f"{path}: not YAML{where}: {problem}") from None
    except Exception as exc:  # a YAML bomb, a recursion: not a job file
        raise JobFileError(f"{path}: not a job file: {type(exc).__name__}") from None
    _bounded(path, doc)
    return doc, hashlib.sha256(data).hexdigest()


#: what a job file may hold once its aliases are expanded: values in all,
#: and maps or lists nested in one another (a job file has a few dozen
#: settings, three levels deep)
MAX_VALUES = 10_000
MAX_DEPTH = 16


def _bounded(path: Path, doc: Any) -> None:
    """JobFileError unless the document, its aliases expanded, is a tree of
    at most MAX_VALUES values and MAX_DEPTH levels: an alias that refers to
    a map holding it (a cycle) or aliases nested into a bomb, anywhere in
    the file, are refused before anything walks them."""
    seen = 0
    stack: list[tuple[Any, int, frozenset[int]]] = [(doc, 0, frozenset())]
    while stack:
        node, depth, above = stack.pop()
        seen += 1
        if seen > MAX_VALUES:
            raise JobFileError(
                f"{path}: not a job file: more than {MAX_VALUES} values once its aliases are expanded"
            )
        if not isinstance(node, (dict, list)):
            continue
        if id(node) in above:
            raise JobFileError(
                f"{path}: not a job file: an alias refers to a map or list that holds it (a cycle)"
            )
        if depth >= MAX_DEPTH:
            raise JobFileError(f"{path}: not a job file: nested deeper than {MAX_DEPTH} levels")
        inner = above | {id(node)}
        children = node.values() if isinstance(node, dict) else node
        stack.extend((child, depth + 1, inner) for child in children)


def _sections(path: Path, doc: Any) -> dict[str, dict[str, Any]]:
    """Section key -> its flattened ros__parameters."""
    if not isinstance(doc, dict) or not doc:
        raise JobFileError(
            f"{path}: a job file is a ROS 2 parameters file: a map of node names "
            f"({SECTION_NAMES}) to their ros__parameters"
        )
    out = {}
    consumer: list[str] = []  # the consumer's sections, as written
    for key, body in doc.items():
        node = section_node(str(key))
        if node not in NODE_SPECS and node != "/**":
            raise JobFileError(f"{path}: section {key!r}: not a winder node ({SECTION_NAMES})")
        if node == "consumer":
            consumer.append(str(key))
            written = {_written(k) for k in consumer}
            if len(written) > 1:
                raise JobFileError(
                    f"{path}: sections {consumer[0]!r} and {consumer[-1]!r} both hold the step consumer's "
                    "settings: keep one (consumer, or sim_node)"
                )
        if not isinstance(body, dict) or set(body) != {"ros__parameters"}:
            raise JobFileError(f"{path}: section {key!r} must hold exactly one key, ros__parameters")
        params = body["ros__parameters"]
        if not isinstance(params, dict):
            raise JobFileError(f"{path}: {key}.ros__parameters must be a map of settings")
        flat: dict[str, Any] = {}
        _flatten("", params, flat)
        out[str(key)] = flat
    return out


def _written(key: str) -> str:
    """The node name a section key names (``/cell1/sim_node``: ``sim_node``)."""
    return key.rstrip("/").rsplit("/", 1)[-1] if key != "/**" else "/**"


def section_node(key: str) -> str:
    """The key of :data:`NODE_SPECS` a section key stands for (``/**`` for itself)."""
    node = _written(key)
    return SECTION_ALIASES.get(node, node)


def _check(path: Path, where: str, spec: Spec, value: Any) -> Any:
    if isinstance(value, (list, tuple)) or value is None:
        raise JobFileError(f"{path}: {where}: {spec.name}={value!r} is invalid: must be {spec.range_text()}")
    try:
        return spec.check(value)
    except SpecError as exc:
        raise JobFileError(f"{path}: {where}: {exc}") from None


def load_job_file(path: str | Path, *, check_fit: bool = True) -> dict[str, dict[str, Any]]:
    """The settings a job file gives each node, checked: ``{"interp_node":
    {...}, "profile_node": {...}, "consumer": {...}}`` (only what the file
    sets; the consumer's from its ``consumer`` or ``sim_node`` section).
    Raises :class:`JobFileError` (a ValueError) with a one-line reason.
    ``check_fit=False``: a coil that does not fit its window is not refused
    (``winder check`` reports it first)."""
    return load_job_file_hashed(path, check_fit=check_fit)[0]


def load_job_file_hashed(
    path: str | Path, *, check_fit: bool = True
) -> tuple[dict[str, dict[str, Any]], str]:
    """:func:`load_job_file`, and the sha256 (hex) of the bytes it was read
    from: the recipe a run is traced to (``job_file_sha256`` in its bag)."""
    p = Path(path).expanduser()
    doc, digest = _read(p)
    sections = _sections(p, doc)
    out: dict[str, dict[str, Any]] = {node: {} for node in NODE_SPECS}
    names = {node: node for node in NODE_SPECS}  # each node's section as the file names it
    names.update({section_node(k): _written(k) for k in sections if k != "/**"})
    # /** first: a node's own section has the last word, as in ROS
    for key in sorted(sections, key=lambda k: k != "/**"):
        for name, value in sections[key].items():
            where = f"{key}.ros__parameters.{name}"
            if key == "/**":
                takers = [n for n, specs in NODE_SPECS.items() if name in specs]
                if not takers:
                    raise JobFileError(f"{p}: {where}: no winder node has a setting {name!r}")
            else:
                node = section_node(key)
                if name not in NODE_SPECS[node]:
                    raise JobFileError(f"{p}: {where}: {_written(key)} has no setting {name!r}")
                takers = [node]
            for node in takers:
                out[node][name] = _check(p, where, NODE_SPECS[node][name], value)
    _check_together(p, out, names, check_fit)
    return out, digest


def _check_together(
    path: Path, given: dict[str, dict[str, Any]], names: dict[str, str], check_fit: bool = True
) -> None:
    """The cross-field rules of each node, on the file's values over the defaults."""

    def interp(values: dict[str, Any]) -> None:
        check_interp(values, check_fit=check_fit)

    checks = {"interp_node": interp, "profile_node": check_profile, "consumer": check_sim}
    for node, check in checks.items():
        values = {n: s.default for n, s in NODE_SPECS[node].items()}
        values.update(given[node])
        if node == "consumer":
            values["record"] = False  # the bag directory is the consumer's to probe, on its machine
        try:
            check(values)
        except SpecError as exc:
            raise JobFileError(f"{path}: {names[node]}: {exc}") from None
