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
* ``sim_node``: the motors (``fork: {J: 2.0e-4, D: 0.03}`` is ``fork.J``,
  ``fork.D``) and the simulation.

:func:`load_job_file` checks every value as the nodes would, and the
sections together (the coil fits, the ramp can plan its moves); an error
names the file, the key path and the allowed range, in one line.
"""

from __future__ import annotations

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

__all__ = ["NODE_SPECS", "JobFileError", "load_job_file"]

#: the sections of a job file and the settings each may hold (job_file itself excluded)
NODE_SPECS: dict[str, dict[str, Spec]] = {
    "interp_node": {n: s for n, s in INTERP_SPECS.items() if n != "job_file"},
    "profile_node": PROFILE_SPECS,
    "sim_node": SIM_SPECS,
}
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


def _read(path: Path) -> Any:
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
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise JobFileError(f"{path}: cannot be read: {str(exc).splitlines()[0]}") from None
    try:
        return YAML(typ="safe", pure=True).load(text)
    except YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise JobFileError(f"{path}: not YAML{where}: {problem}") from None
    except Exception as exc:  # a YAML bomb, a recursion: not a job file
        raise JobFileError(f"{path}: not a job file: {type(exc).__name__}") from None


def _sections(path: Path, doc: Any) -> dict[str, dict[str, Any]]:
    """Section key -> its flattened ros__parameters."""
    if not isinstance(doc, dict) or not doc:
        raise JobFileError(
            f"{path}: a job file is a ROS 2 parameters file: a map of node names "
            "(interp_node, profile_node, sim_node or /**) to their ros__parameters"
        )
    out = {}
    for key, body in doc.items():
        node = str(key).rstrip("/").rsplit("/", 1)[-1] if str(key) != "/**" else "/**"
        if node not in NODE_SPECS and node != "/**":
            raise JobFileError(
                f"{path}: section {key!r}: not a winder node (interp_node, profile_node, sim_node or /**)"
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


def _check(path: Path, where: str, spec: Spec, value: Any) -> Any:
    if isinstance(value, (list, tuple)) or value is None:
        raise JobFileError(f"{path}: {where}: {spec.name}={value!r} is invalid: must be {spec.range_text()}")
    try:
        return spec.check(value)
    except SpecError as exc:
        raise JobFileError(f"{path}: {where}: {exc}") from None


def load_job_file(path: str | Path) -> dict[str, dict[str, Any]]:
    """The settings a job file gives each node, checked: ``{"interp_node":
    {...}, "profile_node": {...}, "sim_node": {...}}`` (only what the file
    sets). Raises :class:`JobFileError` (a ValueError) with a one-line reason."""
    p = Path(path).expanduser()
    sections = _sections(p, _read(p))
    out: dict[str, dict[str, Any]] = {node: {} for node in NODE_SPECS}
    # /** first: a node's own section has the last word, as in ROS
    for key in sorted(sections, key=lambda k: k != "/**"):
        for name, value in sections[key].items():
            where = f"{key}.ros__parameters.{name}"
            if key == "/**":
                takers = [n for n, specs in NODE_SPECS.items() if name in specs]
                if not takers:
                    raise JobFileError(f"{p}: {where}: no winder node has a setting {name!r}")
            else:
                node = key.rstrip("/").rsplit("/", 1)[-1]
                if name not in NODE_SPECS[node]:
                    raise JobFileError(f"{p}: {where}: {node} has no setting {name!r}")
                takers = [node]
            for node in takers:
                out[node][name] = _check(p, where, NODE_SPECS[node][name], value)
    _check_together(p, out)
    return out


def _check_together(path: Path, given: dict[str, dict[str, Any]]) -> None:
    """The cross-field rules of each node, on the file's values over the defaults."""
    checks = {"interp_node": check_interp, "profile_node": check_profile, "sim_node": check_sim}
    for node, check in checks.items():
        values = {n: s.default for n, s in NODE_SPECS[node].items()}
        values.update(given[node])
        if node == "sim_node":
            values["record"] = False  # the bag directory is the sim node's to probe, on its machine
        try:
            check(values)
        except SpecError as exc:
            raise JobFileError(f"{path}: {node}: {exc}") from None
