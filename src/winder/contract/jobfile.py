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
import math
import re
import sys
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
from winder.contract.stream import RUN_FACT_FIELDS, RUN_FACTS
from winder.errors import BadInputError
from winder.spec import Spec, SpecError

__all__ = [
    "NODE_SPECS",
    "SECTION_ALIASES",
    "JobFileError",
    "check_interp_settings",
    "goal_facts",
    "goal_sha256",
    "load_job_file",
    "load_job_file_hashed",
    "load_job_text",
    "load_node_params",
    "ros_scalar",
    "ros_text",
    "section_node",
]

#: the sections of a job file and the settings each may hold (job_file and
#: its hash excluded: a file cannot name itself; the run's facts too, operator and wire lot: a
#: recipe is the same whoever runs it, and its file's hash with it); the keys of what
#: :func:`load_job_file` returns
NODE_SPECS: dict[str, dict[str, Spec]] = {
    "interp_node": {
        n: s for n, s in INTERP_SPECS.items() if n not in ("job_file", "job_file_sha256", *RUN_FACTS)
    },
    "profile_node": PROFILE_SPECS,
    "consumer": SIM_SPECS,
}
#: other names a section may have: ``sim_node``, the stock consumer's node
#: name (so that ``ros2 run winder_sim sim_node --params-file`` applies it too)
SECTION_ALIASES = {"sim_node": "consumer"}
#: the section names a job file may use, for messages
SECTION_NAMES = "interp_node, profile_node, consumer (or sim_node) or /**"
#: the job field whose map is one value, not settings by their dotted names
TOLERANCES = "tolerances"
#: a job file larger than this is not a job file
MAX_BYTES = 1 << 20


class JobFileError(SpecError):
    """A job file cannot be used; the message names the file and the key, in one line."""


def _flatten(prefix: str, value: Any, out: dict[str, Any]) -> None:
    """``value``'s settings by their dotted names into ``out``; ValueError if one
    is given twice (``max_velocity.fork: 10`` beside ``max_velocity: {fork: 20}``:
    ROS would take one of them, silently). A ``tolerances:`` map stays one
    value: the job field it is (:mod:`winder.motion.tolerances`), its names the part's scalars."""
    if isinstance(value, dict) and prefix != TOLERANCES:
        for k, v in value.items():
            _flatten(f"{prefix}.{k}" if prefix else str(k), v, out)
    elif prefix in out:
        raise BadInputError(f"{prefix} is given twice (once dotted, once as a nested map)")
    else:
        out[prefix] = value


def _read(path: Path, what: str = "job file") -> tuple[Any, str]:
    """The YAML document of the file ``path`` (a ``what``) and its sha256;
    JobFileError (one line) if it cannot be read or is no such file."""

    try:
        size = path.stat().st_size
    except FileNotFoundError:
        raise JobFileError(f"{path}: no such {what}") from None
    except OSError as exc:
        raise JobFileError(f"{path}: cannot be read: {exc.strerror or exc}") from None
    if not path.is_file():
        raise JobFileError(f"{path}: not a file")
    if size > MAX_BYTES:
        raise JobFileError(f"{path}: {size} bytes, more than a {what} holds here ({MAX_BYTES})")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise JobFileError(f"{path}: cannot be read: {str(exc).splitlines()[0]}") from None
    return _document(path, data)


def _document(path: Path, data: bytes) -> tuple[Any, str]:
    """The YAML document of the bytes ``data`` (named ``path`` in errors) and their sha256."""
    from ruamel.yaml.error import YAMLError

    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise JobFileError(f"{path}: cannot be read: {str(exc).splitlines()[0]}") from None
    try:
        doc = _parse(path, text)
    except YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise JobFileError(f"{path}: not YAML{where}: {problem}") from None
    except JobFileError:
        raise
    except Exception as exc:  # anything else the YAML parser raises: not a job file
        raise JobFileError(f"{path}: not a job file: {type(exc).__name__}") from None
    _bounded(path, doc)
    return doc, hashlib.sha256(data).hexdigest()


# -- scalars as ROS reads them ------------------------------------------------------------
#
# A job file is a ROS 2 parameters file, and ROS reads one with its own rules
# (rcl_yaml_param_parser, for --params-file and every -p name:=value): an
# unquoted scalar is a bool if it is one of its words (yes/no/on/off/y/n as
# well as true/false), else an integer if C's strtol(text, 0) takes all of it
# (017 is octal 15, 0x1F is 31; 0o17 and 1_000 are not), else a double if
# strtod takes all of it without overflow (1e3, .5, inf, 0x1p3, 08), else a
# string; a quoted scalar or one tagged !!str is a string; ~ and null are the
# strings they spell; aliases and empty values are refused. YAML 1.2 (ruamel's
# default) reads 017 as 17, 0o17 as 15, 1_000 as 1000 and yes as a string: a
# file checked that way winds another coil than the node given the same file.
# The loader reads every scalar with ROS's rules instead, so ``winder run
# --check``, the job_file parameter and ``--params-file`` see the same values.

_TRUE = frozenset(["Y", "y", "yes", "Yes", "YES", "true", "True", "TRUE", "on", "On", "ON"])
_FALSE = frozenset(["N", "n", "no", "No", "NO", "false", "False", "FALSE", "off", "Off", "OFF"])
_SPECIAL_FLOATS = {
    **dict.fromkeys((".nan", ".NaN", ".NAN"), math.nan),
    **dict.fromkeys((".inf", ".Inf", ".INF"), math.inf),
    **dict.fromkeys(("-.inf", "-.Inf", "-.INF"), -math.inf),
}
_STRTOL = re.compile(r"\s*([+-]?)(0[xX][0-9a-fA-F]+|0[0-7]*|[1-9][0-9]*)")
_STRTOD_DEC = re.compile(r"\s*[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
_STRTOD_HEX = re.compile(r"\s*([+-]?)(0[xX](?:[0-9a-fA-F]+\.?[0-9a-fA-F]*|\.[0-9a-fA-F]+)(?:[pP][+-]?\d+)?)")
_STRTOD_WORD = re.compile(r"\s*([+-]?)(inf|infinity|nan(\([0-9A-Za-z_]*\))?)", re.IGNORECASE)
_INT64 = (-(2**63), 2**63 - 1)
STR_TAG = "tag:yaml.org,2002:str"


def _strtol(text: str) -> int | None:
    m = _STRTOL.fullmatch(text)
    if m is None:
        return None
    digits = m.group(2)
    base = 16 if digits[:2] in ("0x", "0X") else 8 if digits[0] == "0" else 10
    value = int(digits, base)
    value = -value if m.group(1) == "-" else value
    return value if _INT64[0] <= value <= _INT64[1] else None  # else ERANGE: not an integer


def _strtod(text: str) -> float | None:
    if text in _SPECIAL_FLOATS:
        return _SPECIAL_FLOATS[text]
    if _STRTOD_DEC.fullmatch(text):
        value = float(text)
    elif m := _STRTOD_HEX.fullmatch(text):
        value = float.fromhex(m.group(1) + m.group(2))
    elif m := _STRTOD_WORD.fullmatch(text):
        return float(m.group(1) + ("nan" if m.group(2).lower().startswith("nan") else "inf"))
    else:
        return None
    if math.isinf(value) or 0.0 < abs(value) < sys.float_info.min:
        return None  # overflow or underflow: strtod's ERANGE, a string to ROS
    return value


def ros_scalar(text: str, *, quoted: bool = False, tag: str | None = None) -> Any:
    """A scalar of a parameters file as ROS reads it (rcl_yaml_param_parser):
    bool, int, float or str (see the rules above)."""
    if quoted or tag in (STR_TAG, "!!str"):
        return text
    if text in _TRUE:
        return True
    if text in _FALSE:
        return False
    as_int = _strtol(text)
    if as_int is not None:
        return as_int
    as_float = _strtod(text)
    return as_float if as_float is not None else text


def ros_text(value: bool | int | float | str) -> str:
    """A checked setting as the text of ``-p name:=TEXT`` that ROS reads back
    as exactly ``value`` (:func:`ros_scalar`'s inverse): a string is quoted
    (``job_id: "yes"`` stays the text yes, not true; ``"017"`` stays 017)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return "'" + value.replace("'", "''") + "'"
    if isinstance(value, float) and not math.isfinite(value):
        return ".nan" if math.isnan(value) else ".inf" if value > 0 else "-.inf"
    return repr(value)


def _parse(path: Path, text: str) -> Any:
    """The document as ROS reads it: maps, lists and :func:`ros_scalar` values,
    built from the parser's events (no YAML resolver, no constructor). An
    alias, an empty value, a key that is not a plain text or given twice and
    a second document are refused in one line, as ROS refuses them or cannot
    mean them."""
    from ruamel.yaml import YAML
    from ruamel.yaml.events import (
        AliasEvent,
        DocumentStartEvent,
        MappingEndEvent,
        MappingStartEvent,
        ScalarEvent,
        SequenceEndEvent,
        SequenceStartEvent,
    )

    def line(event: Any) -> str:
        return f"line {event.start_mark.line + 1}"

    stack: list[Any] = []  # open maps and lists; for a map, the key waiting for its value
    keys: list[str | None] = []
    root: Any = None
    documents = 0

    def add(value: Any, event: Any) -> None:
        nonlocal root
        if not stack:
            root = value
            return
        top = stack[-1]
        if isinstance(top, list):
            top.append(value)
        elif keys[-1] is None:
            if not isinstance(value, str) or isinstance(event, (MappingStartEvent, SequenceStartEvent)):
                raise JobFileError(f"{path}: {line(event)}: a key must be a name")
            if value in top:
                raise JobFileError(f"{path}: {line(event)}: key {value!r} given twice in one map")
            keys[-1] = value
        else:
            top[keys[-1]] = value
            keys[-1] = None

    for event in YAML(typ="safe", pure=True).parse(text):
        if isinstance(event, DocumentStartEvent):
            documents += 1
            if documents > 1:
                raise JobFileError(f"{path}: {line(event)}: a second YAML document: a job file has one")
        elif isinstance(event, AliasEvent):
            raise JobFileError(
                f"{path}: {line(event)}: an alias (*{event.anchor}): ROS 2 parameters files have none "
                "(ROS refuses them); write the value out"
            )
        elif isinstance(event, ScalarEvent):
            quoted = event.style in ("'", '"')
            if stack and isinstance(stack[-1], dict) and keys[-1] is None:
                add(event.value, event)  # a key: its text, as ROS takes it
            elif event.value == "" and not quoted and event.tag is None and event.style is None:
                where = f" for {keys[-1]!r}" if stack and isinstance(stack[-1], dict) else ""
                raise JobFileError(
                    f"{path}: {line(event)}: no value{where} (ROS refuses an empty value; write '' for "
                    "an empty text)"
                )
            else:
                add(ros_scalar(event.value, quoted=quoted, tag=event.tag), event)
        elif isinstance(event, (MappingStartEvent, SequenceStartEvent)):
            if len(stack) >= MAX_DEPTH:
                raise JobFileError(f"{path}: not a job file: nested deeper than {MAX_DEPTH} levels")
            container: Any = {} if isinstance(event, MappingStartEvent) else []
            add(container, event)
            stack.append(container)
            keys.append(None)
        elif isinstance(event, (MappingEndEvent, SequenceEndEvent)):
            stack.pop()
            keys.pop()
    return root


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
        try:
            _flatten("", params, flat)
        except ValueError as exc:
            raise JobFileError(f"{path}: section {key!r}: {exc}") from None
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


def check_interp_settings(values: dict[str, Any]) -> None:
    """The interp node's whole check of its settings (SpecError):
    :func:`~winder.contract.params.check_interp`, and the job file it names,
    read as a change to ``job_file`` would read it: a file that cannot be
    used is refused with its reason."""
    check_interp(values)
    if values.get("job_file"):
        load_job_file(values["job_file"])


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
    return _settings(p, doc, check_fit), digest


def goal_sha256(
    job: str, overrides: list[str] | tuple[str, ...] = (), *, operator: str = "", wire_lot: str = ""
) -> str:
    """The hash a ``Wind`` goal carries (``goal_sha256``): the SHA-256, hex,
    of its job text and each override after it on a line of its own, as
    UTF-8; its ``operator`` and ``wire_lot``, those given, count as the
    overrides ``operator=...`` and ``wire_lot=...`` after the others (a goal
    without them hashes as before they were fields). A ROS string ends at
    its first NUL byte on its way (rcl's C strings): a goal cut there
    arrives as another, valid one, and only its hash tells."""
    lines = [job, *overrides, *goal_facts(operator, wire_lot)]
    return hashlib.sha256("\n".join(lines).encode("utf-8")).hexdigest()


def goal_facts(operator: str, wire_lot: str) -> list[str]:
    """A ``Wind`` goal's ``operator`` and ``wire_lot`` fields as the
    overrides they stand for (``operator=NAME``), those given (not "")."""
    return [f"{name}={value}" for name, value in (("operator", operator), ("wire_lot", wire_lot)) if value]


def load_job_text(
    text: str, *, name: str = "job", check_fit: bool = True
) -> tuple[dict[str, dict[str, Any]], str]:
    """:func:`load_job_file_hashed` of a job file's text (a Wind goal's
    ``job``), named ``name`` in its errors: the settings it gives each node,
    checked, and the sha256 of its UTF-8 bytes (what the file's would be)."""
    data = text.encode("utf-8")
    if len(data) > MAX_BYTES:
        raise JobFileError(f"{name}: {len(data)} bytes, more than a job file holds here ({MAX_BYTES})")
    p = Path(name)
    doc, digest = _document(p, data)
    return _settings(p, doc, check_fit), digest


def _settings(p: Path, doc: Any, check_fit: bool) -> dict[str, dict[str, Any]]:
    """The settings of a job file's document, each checked by its node's table."""
    sections = _sections(p, doc)
    out: dict[str, dict[str, Any]] = {node: {} for node in NODE_SPECS}
    names = {node: node for node in NODE_SPECS}  # each node's section as the file names it
    names.update({section_node(k): _written(k) for k in sections if k != "/**"})
    # /** first: a node's own section has the last word, as in ROS
    for key in sorted(sections, key=lambda k: k != "/**"):
        for name, value in sections[key].items():
            where = f"{key}.ros__parameters.{name}"
            if name in RUN_FACTS:
                raise JobFileError(
                    f"{p}: {where}: {name} is the run's, not the recipe's: give it to the run "
                    f"(winder run --{name.replace('_', '-')}, winder ctl start --{name.replace('_', '-')}, "
                    f"the Wind goal's {RUN_FACT_FIELDS[name]}): the recipe, and its hash, are the same "
                    "whoever runs it"
                )
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
    return out


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


def load_node_params(path: str | Path, node: str, specs: dict[str, Spec]) -> dict[str, Any]:
    """The settings a ROS 2 parameters file gives the node ``node`` (its own
    section, a namespace in front allowed, over ``/**``), each checked with
    ``specs``; other nodes' sections are passed over (the file may be a
    whole cell's, the controller manager's beside it). JobFileError (one
    line) if the file cannot be read, the node has no section, or a value
    is bad."""
    p = Path(path).expanduser()
    doc, _ = _read(p, "parameters file")
    if not isinstance(doc, dict):
        raise JobFileError(f"{p}: a ROS 2 parameters file is a map of node names to their ros__parameters")
    out: dict[str, Any] = {}
    keys = [k for k in doc if _written(str(k)) in (node, "/**")]
    own = [str(k) for k in keys if _written(str(k)) == node]
    if not own:
        raise JobFileError(f"{p}: no section for {node} (a map {node}: {{ros__parameters: ...}})")
    if len(own) > 1:
        raise JobFileError(
            f"{p}: sections {', '.join(own)} all name {node}: which cell's is meant is not clear "
            "(give one file per cell)"
        )
    for key in sorted(keys, key=lambda k: _written(str(k)) != "/**"):  # the node's own section last
        body = doc[key]
        if not isinstance(body, dict) or not isinstance(body.get("ros__parameters"), dict):
            raise JobFileError(f"{p}: section {key!r} must hold a map ros__parameters")
        flat: dict[str, Any] = {}
        try:
            _flatten("", body["ros__parameters"], flat)
        except ValueError as exc:
            raise JobFileError(f"{p}: section {key!r}: {exc}") from None
        for name, value in flat.items():
            if name not in specs:
                if key == "/**":
                    continue
                raise JobFileError(f"{p}: {key}.ros__parameters.{name}: {node} has no setting {name!r}")
            where = f"{key}.ros__parameters.{name}"
            if isinstance(value, list):  # a string array (joints, axes): its spec says if it takes one
                try:
                    out[name] = specs[name].check(value)
                except SpecError as exc:
                    raise JobFileError(f"{p}: {where}: {exc}") from None
            else:
                out[name] = _check(p, where, specs[name], value)
    return out
