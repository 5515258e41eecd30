"""The step stream between the nodes, ROS-free: job description, chunk layout
and integrity checking.

A job travels as a description and then as chunks of rows. The description's
canonical form here is a JSON text (:func:`describe_job`, :func:`parse_job_description`);
on ``winder/job`` it is a winder_interfaces/JobDescription
(:func:`description_fields` gives its fields, :func:`description_text` reads one, or
the std_msgs/String of older bags, back into the text).

Step rows are ``[segment, feed, fork, pole]`` (int32, absolute step
positions after the step); timed rows are ``[t_ns, segment, feed, fork, pole]``
(int64, nanoseconds since the job start). A chunk never spans two segments.

:class:`StreamChecker` follows the positions: every row must be exactly one
step (each axis by -1, 0 or +1, at least one axis) from the row before it, so
a dropped, duplicated or reordered chunk shows up at its first row.
"""

from __future__ import annotations

import collections
import json
import math
import re
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from winder.errors import BadInputError
from winder.motion.axes import AXES
from winder.motion.interp import interpolate_pieces, pieces_mismatch
from winder.motion.job import FIELD_SPECS, Job, Segment
from winder.spec import Spec, SpecError, interval, shorten

__all__ = [
    "RUN_FACTS",
    "RUN_FACT_FIELDS",
    "RUN_TEXT_MAX",
    "STEP_COLUMNS",
    "STOP_PAUSE_RANGE",
    "TIMED_COLUMNS",
    "ChunkVerdict",
    "JobPlan",
    "StreamChecker",
    "describe_job",
    "description_fields",
    "description_text",
    "parse_job_description",
    "with_source",
]

STEP_COLUMNS = ("segment", *AXES)
TIMED_COLUMNS = ("t_ns", "segment", *AXES)
FORMAT = "winder.job/1"
#: s the axes may rest at a programmed stop, at least and at most (the interp
#: node's stop_pause setting, and what a job description may say)
STOP_PAUSE_RANGE = (0.0, 3600.0)


#: the longest operator or wire lot (characters): an MES field, a badge or a lot number, with room
RUN_TEXT_MAX = 64
#: what an operator or a wire lot may not hold: control characters (C0, DEL, C1: a NUL cuts a ROS
#: string on its way, an escape rewrites a terminal), the line and paragraph separators and the
#: invisible format marks (Unicode's Cf: soft hyphen, zero-width characters, bidirectional
#: overrides, BOM, tags), lone surrogates (bytes of a command line that are no UTF-8) and every
#: space but the plain one: what ``str.isprintable`` refuses, but private-use and unassigned code
#: points (test/contract/test_run_facts.py holds it to that over every code point)
_NOT_PRINTABLE = (
    "\x00-\x1f\x7f-\xa0\xad\u0600-\u0605\u061c\u06dd\u070f\u0890\u0891\u08e2\u1680\u180e"
    "\u2000-\u200f\u2028-\u202f\u205f-\u206f\u3000\ud800-\udfff\ufeff\ufff9-\ufffb"
    "\U000110bd\U000110cd\U00013430-\U0001343f\U0001bca0-\U0001bca3\U0001d173-\U0001d17a"
    "\U000e0001-\U000e007f"
)
#: printable text, single spaces inside it only, at most :data:`RUN_TEXT_MAX` characters; or empty
RUN_TEXT_PATTERN = rf"(?:(?=[^\n]{{1,{RUN_TEXT_MAX}}}\Z)[^ {_NOT_PRINTABLE}]+(?: [^ {_NOT_PRINTABLE}]+)*)?"
RUN_TEXT_RULE = (
    f"printable text of at most {RUN_TEXT_MAX} characters (no control characters, no leading, "
    "trailing or double space), or empty"
)
#: what a run records of who wound it with what, beside its job (docs/PARTS.md): properties of the
#: run, not of the recipe, so never a job field (the recipe's hash stays the job's); the interp
#: node's settings of these names, carried by the job description into the consumer's part
RUN_FACTS: dict[str, Spec] = {
    "operator": Spec(
        "operator",
        str,
        "",
        "who runs the cell: recorded with each run (its job description, its bag's metadata, its part); "
        "empty: not given",
        pattern=RUN_TEXT_PATTERN,
        pattern_text=RUN_TEXT_RULE,
    ),
    "wire_lot": Spec(
        "wire_lot",
        str,
        "",
        "the lot of the wire on the machine: recorded with each run as operator is; empty: not given",
        pattern=RUN_TEXT_PATTERN,
        pattern_text=RUN_TEXT_RULE,
    ),
}
#: each run fact's field in winder_interfaces' JobDescription and Wind goal (``operator`` is a C++
#: keyword, which no field of a ROS interface may be called: its generated C code does not build)
RUN_FACT_FIELDS = {"operator": "operator_name", "wire_lot": "wire_lot"}


#: a run id: ``<job_id>_<UTC date>_<UTC time with ms>_<n>`` (:func:`make_run_id`)
RUN_ID = re.compile(r"^[A-Za-z0-9_\-]+_\d{8}_\d{9}_\d+$")
#: what a re-simulation (winder resim) adds to the job id in its run id, so its bag's
#: name reads as one: ``<job_id>_resim_<date>_<time>_<n>``
RESIM_TAG = "_resim"


def make_run_id(job_id: str, counter: int, now: float | None = None) -> str:
    """A run's identity: the job id, the UTC time of the start to the
    millisecond and the start's number in this node's life. Unique across
    restarts of the nodes (a restart takes longer than a millisecond) and
    usable as a file name (the sim node names the run's bag after it)."""
    t = time.time() if now is None else now
    ms = int(t * 1000) % 1000
    return f"{job_id}_{time.strftime('%Y%m%d_%H%M%S', time.gmtime(t))}{ms:03d}_{counter}"


#: the crossover's cam law: written for every orthocyclic job; one described without it (before
#: the law could be chosen) crossed over linearly
CROSSOVER_LAW, ORTHO = "lay.crossover_law", "orthocyclic"
#: job fields added after the description's format was fixed (written only when set)
LATER_FIELDS = frozenset(
    {
        "bobbin.core_corner_radius",
        "layer_speed",
        "wire.material",
        "wire.yield_stress",
        "wire.modulus",
        "wire.density",
        "wire.resistivity",
        "tension.set",
        "tension.warning",
        "tension.alarm",
        "tension.max_share",
        "tension.derate",
        "tension.slip_tolerance",
        "lay.crossover_law",
        "tolerances",
    }
)


def describe_job(
    job: Job,
    run_id: str = "",
    ramp: dict[str, Any] | None = None,
    stops: Sequence[tuple[int, int]] = (),
    stop_pause: float = 0.0,
    stop_resume: str = "auto",
    schedule: str = "",
    job_file_sha256: str = "",
    *,
    operator: str = "",
    wire_lot: str = "",
) -> str:
    """JSON text of a job as the downstream nodes and the bag need it; the
    run it starts (``run_id``) travels with it, the ramp to time it with
    when the run brings its own (else null: the profile node's settings), and
    its programmed stops ((segment, step index): rest ``stop_pause`` s there);
    the sha256 of the job file it comes from ("" if none), so that the
    run's bag names its recipe; and who runs it with which wire
    (:data:`RUN_FACTS`, "" if not given), for its part."""
    segs = job.segments()
    doc = {
        "format": FORMAT,
        "run_id": run_id,
        "ramp": ramp,
        "stops": [list(s) for s in stops],
        "stop_pause": stop_pause,
        "stop_resume": stop_resume,
        "schedule": schedule,
        "job_file_sha256": job_file_sha256,
        # who ran it and the wire's lot go out only when given: a run without them is
        # described as before them, also to a node of an earlier winder
        **{name: value for name, value in (("operator", operator), ("wire_lot", wire_lot)) if value},
        # a field added to the job later goes out only when set: a description of a job
        # without it reads as before, also by a node of an earlier winder (which refuses
        # a field it does not know)
        "job": {
            k: v
            for k, v in job.to_dict().items()
            if k not in LATER_FIELDS
            or v != FIELD_SPECS[k].default
            or (k == CROSSOVER_LAW and job.lay == ORTHO)
        },
        "axes": list(AXES),
        "joint_step": list(job.joint_step),
        "step_lengths": list(job.step_lengths),
        "total_steps": sum(s.steps for s in segs),
        "segments": [
            {
                "kind": s.kind,
                "start": list(s.start),
                "delta": list(s.delta),
                "steps": s.steps,
                "pole": s.pole,
                "layer": s.layer,
            }
            for s in segs
        ],
    }
    return json.dumps(doc, separators=(",", ":"))


#: the segments of a job plan are its job's own :class:`winder.motion.job.Segment`
#: records (this name: the plan's segment type before there was one type)
SegmentPlan = Segment


@dataclass(frozen=True)
class JobPlan:
    """A parsed job description. ``segments``: its job's, laid out once
    (:meth:`Job.segments`, the same tuple)."""

    job: Job
    joint_step: tuple[float, ...]
    step_lengths: tuple[float, ...]
    segments: tuple[Segment, ...]
    total_steps: int
    text: str = field(repr=False)
    run_id: str = ""  #: the run this job description started ("" in bags before run ids)
    #: the ramp settings the run brings (checked by the profile node), None: the profile node's own
    ramp: dict[str, Any] | None = None
    #: programmed stops: (segment, step index) after which the axes rest ``stop_pause`` s
    stops: tuple[tuple[int, int], ...] = ()
    stop_pause: float = 0.0
    #: "auto": the job goes on after stop_pause; "call": it waits for ~/resume first
    stop_resume: str = "auto"
    #: operator commands at simulated times (winder.motion.timeline.parse_schedule)
    schedule: str = ""
    #: a re-simulation (``winder resim``): the recording its steps come from, and that run's id
    source_bag: str = ""
    source_run_id: str = ""
    #: sha256 of the job file the job comes from ("" if none, and in bags before it)
    job_file_sha256: str = ""
    #: who ran it, and the wire's lot (:data:`RUN_FACTS`; "" if not given, and in bags before them)
    operator: str = ""
    wire_lot: str = ""

    @property
    def job_id(self) -> str:
        return self.job.job_id


def _expect(doc: dict[str, Any], key: str, kind: type | tuple[type, ...], what: str) -> Any:
    value = doc.get(key)
    if not isinstance(value, kind) or isinstance(value, bool):
        raise BadInputError(f"job description: {key!r} is {json.dumps(value)[:40]}, expected {what}")
    return value


def parse_job_description(text: str) -> JobPlan:
    """Parse and check :func:`describe_job` output; ValueError (one line) if it
    is not one. Only the job's fields are taken from the text: the segments,
    step sizes and step count are derived from them again and must match what
    the text says, so a description that lies about its job is refused."""
    try:
        doc = json.loads(text)
    except (json.JSONDecodeError, RecursionError) as exc:
        raise BadInputError(f"job description is not JSON: {str(exc).splitlines()[0]}") from None
    if not isinstance(doc, dict):
        raise BadInputError(f"job description is a JSON {type(doc).__name__}, expected an object")
    if doc.get("format") != FORMAT:
        raise BadInputError(
            f"job description format is {json.dumps(doc.get('format'))[:40]}, expected {FORMAT!r}"
        )
    run_id = doc.get("run_id", "")
    if not isinstance(run_id, str) or (run_id and not RUN_ID.match(run_id)):
        raise BadInputError(
            f"job description: run_id {json.dumps(run_id)[:60]} is not a run id (<job_id>_<date>_<time>_<n>)"
        )
    ramp = doc.get("ramp")
    if ramp is not None and not isinstance(ramp, dict):
        raise BadInputError(
            f"job description: ramp {json.dumps(ramp)[:60]} is not an object of ramp settings"
        )
    fields = _expect(doc, "job", dict, "an object of job fields")
    if fields.get("lay") == ORTHO and CROSSOVER_LAW not in fields:
        fields = {**fields, CROSSOVER_LAW: "linear"}  # written before the key: its crossovers were linear
    try:
        job = Job.from_dict(fields)
    except TypeError as exc:  # a field missing or of another shape
        raise BadInputError(f"job description: bad job fields: {exc}") from None
    expected = job.segments()
    listed = _expect(doc, "segments", list, "a list of segments")
    if len(listed) != len(expected):
        raise BadInputError(f"job description lists {len(listed)} segments, its job has {len(expected)}")
    for e, s in zip(expected, listed, strict=True):
        if not isinstance(s, dict) or (s.get("kind"), s.get("start"), s.get("delta"), s.get("steps")) != (
            e.kind,
            list(e.start),
            list(e.delta),
            e.steps,
        ):
            raise BadInputError(f"job description: segment {e.index} does not match its job fields")
    stops, stop_pause = _stops(doc, expected)
    stop_resume = doc.get("stop_resume", "auto")
    if stop_resume not in ("auto", "call"):
        raise BadInputError(
            f"job description: stop_resume {json.dumps(stop_resume)[:40]} is not auto or call"
        )
    schedule = doc.get("schedule", "")
    if not isinstance(schedule, str):
        raise BadInputError(f"job description: schedule {json.dumps(schedule)[:40]} is not a text")
    if schedule:
        from winder.motion.timeline import parse_schedule

        try:
            parse_schedule(schedule)
        except ValueError as exc:
            raise BadInputError(f"job description: {exc}") from None
    source_bag, source_run_id = _source(doc)
    digest = doc.get("job_file_sha256", "")
    if not isinstance(digest, str) or not re.fullmatch(r"([0-9a-f]{64})?", digest):
        raise BadInputError(
            f"job description: job_file_sha256 {json.dumps(digest)[:72]} is not a sha256 (hex)"
        )
    facts = {}
    for name, spec in RUN_FACTS.items():
        value = doc.get(name, "")
        if not isinstance(value, str):
            raise BadInputError(f"job description: {name} {json.dumps(value)[:40]} is not a text")
        try:
            facts[name] = spec.check(value)
        except SpecError as exc:
            raise BadInputError(f"job description: {exc}") from None
    total = sum(e.steps for e in expected)
    derived = {
        "total_steps": total,
        "joint_step": list(job.joint_step),
        "step_lengths": list(job.step_lengths),
    }
    for key, value in derived.items():
        if doc.get(key) != value:
            raise BadInputError(
                f"job description: {key} {json.dumps(doc.get(key))[:40]} does not match its job"
            )
    return JobPlan(
        job=job,
        joint_step=tuple(job.joint_step),
        step_lengths=tuple(job.step_lengths),
        segments=expected,
        total_steps=total,
        text=text,
        run_id=run_id,
        ramp=ramp,
        stops=stops,
        stop_pause=stop_pause,
        stop_resume=stop_resume,
        schedule=schedule,
        source_bag=source_bag,
        source_run_id=source_run_id,
        job_file_sha256=digest,
        **facts,
    )


def _setting_text(value: Any) -> str:
    """A job's or a ramp's setting as a KeyValue carries it: a text as it is,
    anything else as JSON (``0.0025``, ``20``, ``true``)."""
    return value if isinstance(value, str) else json.dumps(value)


def _setting_value(key: str, text: str, specs: Mapping[str, Spec]) -> Any:
    """The inverse of :func:`_setting_text`: ``text`` as the type its
    setting in ``specs`` has: a text as it is; a number or a truth value as
    JSON, or else as a job file or ``--set`` writes it (``.5``, ``+4``,
    ``yes``); what is neither stays the text (``auto``), which the job's own
    check takes or refuses. A key no setting has: JSON if it is, else the text."""
    spec = specs.get(key)
    if spec is not None and spec.kind is str:
        return text
    try:
        return json.loads(text)
    except (ValueError, RecursionError):
        pass
    if spec is not None:
        try:
            return spec.parse(text)
        except SpecError:
            pass
    return text


def description_fields(text: str) -> dict[str, Any]:
    """The fields of a winder_interfaces/JobDescription for a description's
    JSON text (:func:`describe_job`'s, :func:`with_source`'s, or one
    recorded before the typed message): plain values; the job's and the
    ramp's settings as (key, value text) pairs; the stops and segments as
    dicts of their messages' fields. The ROS side makes the message of them
    (winder.ros.interfaces); :func:`description_text` reads it back into
    the same text. BadInputError (one line) for a text that is no JSON object."""
    try:
        doc = json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise BadInputError(f"job description is not JSON: {str(exc).splitlines()[0]}") from None
    if not isinstance(doc, dict):
        raise BadInputError(f"job description is a JSON {type(doc).__name__}, expected an object")
    ramp = doc.get("ramp")
    job = dict(doc.get("job") or {})
    given = doc.get("source")
    source: dict[str, Any] = given if isinstance(given, dict) else {}
    return {
        "format": str(doc.get("format", "")),
        "run_id": str(doc.get("run_id", "")),
        "job_id": str(job.get("job_id", "")),
        "job": [(k, _setting_text(v)) for k, v in job.items()],
        "has_ramp": ramp is not None,
        "ramp": [(k, _setting_text(v)) for k, v in dict(ramp or {}).items()],
        "stops": [{"segment": int(seg), "step": int(step)} for seg, step in doc.get("stops", [])],
        "stop_pause": float(doc.get("stop_pause", 0.0)),
        "stop_resume": str(doc.get("stop_resume", "auto")),
        "schedule": str(doc.get("schedule", "")),
        "job_file_sha256": str(doc.get("job_file_sha256", "")),
        **{field: str(doc.get(name, "")) for name, field in RUN_FACT_FIELDS.items()},
        "source_bag": str(source.get("bag", "")),
        "source_run_id": str(source.get("run_id", "")),
        "axes": [str(a) for a in doc.get("axes", [])],
        "joint_step": [float(x) for x in doc.get("joint_step", [])],
        "step_lengths": [float(x) for x in doc.get("step_lengths", [])],
        "total_steps": int(doc.get("total_steps", 0)),
        "segments": [
            {
                "kind": str(s.get("kind", "")),
                "start": [int(x) for x in s.get("start", [])],
                "delta": [int(x) for x in s.get("delta", [])],
                "steps": int(s.get("steps", 0)),
                "pole": int(s.get("pole", 0)),
                "layer": int(s.get("layer", 0)),
            }
            for s in doc.get("segments", [])
        ],
    }


def description_text(msg: Any) -> str:
    """The JSON text of a ``winder/job`` message, for
    :func:`parse_job_description` (which checks it): a
    winder_interfaces/JobDescription (by its fields: an rclpy message, or
    one rosbags decoded) made back into :func:`describe_job`'s text, or the
    text of a std_msgs/String (older bags)."""
    if hasattr(msg, "data"):
        return str(msg.data)
    job = {kv.key: _setting_value(kv.key, kv.value, FIELD_SPECS) for kv in msg.job}
    own = job.get("job_id", FIELD_SPECS["job_id"].default)  # the job's, as Job.from_dict takes it
    if msg.job_id != own:
        raise BadInputError(
            f"job description: job_id {shorten(msg.job_id)} is not its job's ({shorten(str(own))})"
        )
    doc: dict[str, Any] = {
        "format": msg.format,
        "run_id": msg.run_id,
        "ramp": (
            # the ramp's texts are words (profile, shaper: never JSON), its numbers JSON
            {kv.key: _setting_value(kv.key, kv.value, {}) for kv in msg.ramp} if msg.has_ramp else None
        ),
        "stops": [[int(s.segment), int(s.step)] for s in msg.stops],
        "stop_pause": float(msg.stop_pause),
        "stop_resume": msg.stop_resume,
        "schedule": msg.schedule,
        "job_file_sha256": msg.job_file_sha256,
        # a JobDescription recorded before them has neither (read with its bag's own definition);
        # in the text only when given, as describe_job writes them
        **{name: value for name, field in RUN_FACT_FIELDS.items() if (value := getattr(msg, field, ""))},
        "job": job,
        "axes": list(msg.axes),
        "joint_step": [float(x) for x in msg.joint_step],
        "step_lengths": [float(x) for x in msg.step_lengths],
        "total_steps": int(msg.total_steps),
        "segments": [
            {
                "kind": s.kind,
                "start": [int(x) for x in s.start],
                "delta": [int(x) for x in s.delta],
                "steps": int(s.steps),
                "pole": int(s.pole),
                "layer": int(s.layer),
            }
            for s in msg.segments
        ],
    }
    if msg.source_bag or msg.source_run_id:
        doc["source"] = {"bag": msg.source_bag, "run_id": msg.source_run_id}
    return json.dumps(doc, separators=(",", ":"))


def _source(doc: dict[str, Any]) -> tuple[str, str]:
    """The recording a re-simulated job's steps come from (``source``:
    ``{"bag": path, "run_id": id}``), ("", "") for a job of its own."""
    source = doc.get("source")
    if source is None:
        return "", ""
    bag = source.get("bag") if isinstance(source, dict) else None
    run = source.get("run_id", "") if isinstance(source, dict) else None
    if not isinstance(bag, str) or not bag or len(bag) > 4096 or not isinstance(run, str):
        raise BadInputError(f"job description: source {json.dumps(source)[:60]} is not {{bag, run_id}}")
    if run and not RUN_ID.match(run):
        raise BadInputError(f"job description: source run_id {json.dumps(run)[:60]} is not a run id")
    return bag, run


def with_source(text: str, run_id: str, bag: str) -> str:
    """A recorded job description made the description of a re-simulation:
    a new ``run_id``, and the recording and run its steps come from."""
    doc = json.loads(text)
    old = doc.get("run_id", "")
    doc["run_id"] = run_id
    doc["source"] = {"bag": bag, "run_id": old}
    return json.dumps(doc, separators=(",", ":"))


def _stops(doc: dict[str, Any], segments: Sequence[Segment]) -> tuple[tuple[tuple[int, int], ...], float]:
    """The programmed stops of a job description, checked against its segments."""
    listed = doc.get("stops", [])
    pause = doc.get("stop_pause", 0.0)
    if not isinstance(listed, list) or not isinstance(pause, (int, float)) or isinstance(pause, bool):
        raise BadInputError("job description: stops must be a list and stop_pause a number")
    if not (math.isfinite(pause) and STOP_PAUSE_RANGE[0] <= pause <= STOP_PAUSE_RANGE[1]):
        raise BadInputError(
            f"job description: stop_pause {pause!r} is not in {interval(*STOP_PAUSE_RANGE)} s"
        )
    out = []
    for item in listed:
        ok = isinstance(item, list) and len(item) == 2 and all(type(x) is int for x in item)
        if not ok or not 0 <= item[0] < len(segments):
            raise BadInputError(f"job description: stop {json.dumps(item)[:40]} is not [segment, step]")
        seg = segments[item[0]]
        if not seg.kind.winds or not 1 <= item[1] <= seg.steps:
            raise BadInputError(f"job description: stop {item} is not a step of a layer segment")
        out.append((item[0], item[1]))
    return tuple(sorted(set(out))), float(pause)


@dataclass(frozen=True)
class ChunkVerdict:
    """What a chunk did to the stream. ``accept`` tells whether to use it."""

    accept: bool
    kind: str  #: "ok", "gap", "duplicate", "reorder", "bad"
    missing: int = 0  #: steps skipped before this chunk (gap)
    message: str = ""


@dataclass
class StreamChecker:
    """Follows a job's step stream chunk by chunk (see module doc)."""

    plan: JobPlan
    position: npt.NDArray[np.int64] = field(init=False)
    segment: int = field(init=False, default=0)
    done: int = field(init=False, default=0)  #: steps accepted
    gaps: int = field(init=False, default=0)
    missing: int = field(init=False, default=0)
    rejected: int = field(init=False, default=0)  #: chunks refused
    rejected_steps: int = field(init=False, default=0)  #: steps in refused chunks

    def __post_init__(self) -> None:
        # step count before each segment, and the recent gaps in that count:
        # a refused chunk inside one arrived late, anywhere else it is a repeat
        self._offsets = np.concatenate([[0], np.cumsum([s.steps for s in self.plan.segments])]).tolist()
        self._gaps: collections.deque[tuple[int, int]] = collections.deque(maxlen=64)
        self.position = np.zeros(len(self.plan.segments[0].start) if self.plan.segments else 3, np.int64)
        if self.plan.segments:
            self.position[:] = self.plan.segments[0].start

    @property
    def complete(self) -> bool:
        return self.done + self.missing >= self.plan.total_steps and self.at_end

    @property
    def at_end(self) -> bool:
        segs = self.plan.segments
        return not segs or tuple(self.position) == segs[-1].end

    def step_index(self, seg: int, pos: npt.NDArray[np.integer[Any]]) -> npt.NDArray[np.integer[Any]]:
        """1-based index of each row's step within segment ``seg``."""
        s = self.plan.segments[seg]
        index: npt.NDArray[np.integer[Any]] = np.abs(pos[:, s.major] - s.start[s.major])
        return index

    def check_rows(self, rows: npt.NDArray[np.integer[Any]], columns: tuple[str, ...]) -> ChunkVerdict:
        """Check a chunk as it came off the wire: rows of ``columns``
        (:data:`STEP_COLUMNS` or :data:`TIMED_COLUMNS`). Besides :meth:`check`,
        a chunk must hold rows and name one segment in all of them."""
        col = columns.index("segment")
        if rows.ndim != 2 or rows.shape[0] == 0:
            return self._reject("bad", "empty chunk")
        segment = rows[:, col]
        if np.any(segment != segment[0]):
            return self._reject("bad", f"a chunk spans segments {int(segment.min())}..{int(segment.max())}")
        return self.check(int(segment[0]), rows[:, col + 1 :])

    def continues(self, rows: npt.NDArray[np.integer[Any]], columns: tuple[str, ...]) -> bool:
        """Whether a chunk (rows of ``columns``) starts beyond where the stream
        stands, on a segment of its job: steps still to come of this stream,
        not a repeat and not another job's. Read only (nothing counted)."""
        col = columns.index("segment")
        if rows.ndim != 2 or rows.shape[0] == 0:
            return False
        segment, pos = int(rows[0, col]), rows[:, col + 1 :]
        if not 0 <= segment < len(self.plan.segments):
            return False
        seg = self.plan.segments[segment]
        if pos.shape[1] != len(seg.start):
            return False
        k0 = (int(pos[0, seg.major]) - seg.start[seg.major]) * (1 if seg.delta[seg.major] > 0 else -1)
        if not 1 <= k0 <= seg.steps:
            return False
        at = int(self.step_index(self.segment, self.position[None, :])[0])
        return bool(self._offsets[segment] + k0 > self._offsets[self.segment] + at)

    def check(self, segment: int, pos: npt.NDArray[np.integer[Any]]) -> ChunkVerdict:
        """Check one chunk: ``segment`` index and its (n, axes) positions."""
        segs = self.plan.segments
        n = pos.shape[0]
        if n == 0:
            return self._reject("bad", "empty chunk")
        if not 0 <= segment < len(segs):
            return self._reject("bad", f"segment {segment} out of range 0..{len(segs) - 1}")
        seg = segs[segment]
        if pos.ndim != 2 or pos.shape[1] != len(seg.start):
            return self._reject(
                "bad", f"segment {segment}: rows have {pos.shape[1:]} axes, expected {len(seg.start)}"
            )
        # every row must be the job's own step: the major axis gives the step's
        # index k in the segment, and the row must equal the minimum-deviation
        # path's k-th position exactly (a shifted, negated or invented row is
        # refused, not simulated)
        s_major = 1 if seg.delta[seg.major] > 0 else -1
        k0 = (int(pos[0, seg.major]) - seg.start[seg.major]) * s_major
        if not 1 <= k0 <= seg.steps - n + 1:
            return self._reject(
                "bad", f"segment {segment}: {n} rows from step {k0} lie outside its steps 1..{seg.steps}"
            )
        pieces = seg.pieces or (seg.delta,)
        if pieces_mismatch(seg.start, pieces, k0 - 1, pos) >= 0:  # the closed form, row by row
            path = interpolate_pieces(seg.start, pieces, first=k0 - 1, stop=k0 - 1 + n)
            off = np.flatnonzero(np.any(pos != path, axis=1))
            i = int(off[0])
            return self._reject(
                "bad",
                f"segment {segment} step {k0 + i}: position {pos[i].tolist()} is not on the job's path "
                f"({path[i].tolist()} expected); {off.size} of {n} rows off",
            )
        k_last = k0 + n - 1
        # steps are counted across segments (self._offsets): where the stream
        # stands, and where this chunk starts
        at = int(self.step_index(self.segment, self.position[None, :])[0])
        here, first = self._offsets[self.segment] + at, self._offsets[segment] + k0
        if first <= here:
            # late if it falls into a gap reported before, else a repeat
            last = self._offsets[segment] + k_last
            late = any(a <= last and first <= b for a, b in self._gaps)
            kind, why = ("reorder", "arrived late") if late else ("duplicate", "arrived again")
            return self._reject(kind, f"segment {segment} steps {k0}..{k_last} {why}")
        verdict = ChunkVerdict(True, "ok")
        # steps skipped: rest of the current segment, whole segments between, head of this one
        missing = first - here - 1
        if missing:
            self._gaps.append((here + 1, first - 1))
            self.gaps += 1
            self.missing += missing
            verdict = ChunkVerdict(
                True,
                "gap",
                missing,
                f"gap in the step stream: {missing} steps missing before segment {segment} "
                f"step {k0} of {seg.steps}",
            )
        self.segment = segment
        self.position = pos[-1].astype(np.int64).copy()
        self.done += n
        return verdict

    def _reject(self, kind: str, message: str) -> ChunkVerdict:
        self.rejected += 1  # the caller adds the chunk's steps to rejected_steps
        return ChunkVerdict(False, kind, 0, message)
