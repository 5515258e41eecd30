"""Operator events on ``winder/control`` as a typed record (ROS-free).

:class:`ControlEvent` is the one place an event is built from or read into
a message: the profile node publishes a winder_interfaces/ControlEvent of
``event.to_fields()``, consumers and the interp node read
``ControlEvent.from_message(msg)``, which refuses anything that is not a
well-formed event (:class:`EventError`, one line naming the field). Older
bags carry the event as JSON in a std_msgs/String
(:meth:`ControlEvent.to_wire`, :meth:`ControlEvent.from_wire`);
``from_message`` reads those too. The fields and their meaning:
docs/CONTRACT.md §3.3.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from numbers import Integral
from typing import Any

from winder.contract.states import EventKind, EventSource
from winder.errors import BadInputError

__all__ = ["EVENT_KINDS", "EVENT_SOURCES", "MAX_EVENT_BYTES", "ControlEvent", "EventError"]

#: the operator events of ``winder/control``
EVENT_KINDS = tuple(EventKind)
#: a control message longer than this is no event
MAX_EVENT_BYTES = 4096


class EventError(BadInputError):
    """A ``winder/control`` message that is not an event of this run, or one
    that contradicts what the run already did (one line, the reason)."""


@dataclass(frozen=True)
class ControlEvent:
    """One operator event as the profile node publishes it when it takes
    effect (CONTRACT.md §3.3): ``t_ns`` when it takes effect, ``t_rest_ns``
    when the axes are at rest (pause, abort), ``steps`` the steps of the run
    up to that rest, ``(segment, step)`` where the rest is, ``factor`` a feed
    override's. The rest annotates it (``None``: not on the wire): who asked
    (``source``), the request's time and latency, the state it braked from
    (``v``, ``a``, ``stop_distance``), an override's ``v_max`` and ``note``.

    :meth:`to_wire` is the JSON text of ``winder/control``, :meth:`from_wire`
    reads one back and checks it: ``from_wire(e.to_wire()) == e``."""

    kind: EventKind
    run_id: str
    t_ns: int
    t_rest_ns: int | None = None
    steps: int | None = None
    segment: int = -1
    step: int = 0
    factor: float | None = None
    job_id: str | None = None
    source: EventSource | None = None
    t_request_ns: int | None = None
    latency_ns: int | None = None
    v: float | None = None
    a: float | None = None
    stop_distance: float | None = None
    v_max: float | None = None
    note: str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "kind", EventKind(self.kind))
        if self.source is not None:
            object.__setattr__(self, "source", EventSource(self.source))

    @property
    def rest_ns(self) -> int:
        """When the axes are at rest (a pause's, an abort's), else ``t_ns``."""
        return self.t_ns if self.t_rest_ns is None else self.t_rest_ns

    def to_wire(self) -> str:
        """The event as ``winder/control`` carries it: a JSON object, keys
        that are None left out (``segment``/``step`` too while unknown)."""
        doc: dict[str, object] = {"event": str(self.kind)}
        if self.source is not None:
            doc["source"] = str(self.source)
        doc["run_id"] = self.run_id
        if self.job_id is not None:
            doc["job_id"] = self.job_id
        doc["t_ns"] = self.t_ns
        optional: dict[str, object] = {
            "t_request_ns": self.t_request_ns,
            "latency_ns": self.latency_ns,
            "t_rest_ns": self.t_rest_ns,
            "steps": self.steps,
        }
        if (self.segment, self.step) != (-1, 0):
            optional.update(segment=self.segment, step=self.step)
        optional.update(
            v=self.v,
            a=self.a,
            stop_distance=self.stop_distance,
            factor=self.factor,
            v_max=self.v_max,
            note=self.note,
        )
        doc.update((k, v) for k, v in optional.items() if v is not None)
        return json.dumps(doc)

    def to_fields(self) -> dict[str, object]:
        """The fields of the event's winder_interfaces/ControlEvent: what is
        not said is -1 (an integer), NaN (a number) or "" (a text)."""
        return {
            "event": str(self.kind),
            "source": str(self.source or ""),
            "run_id": self.run_id,
            "job_id": self.job_id or "",
            "t_ns": self.t_ns,
            "t_rest_ns": _said_int(self.t_rest_ns),
            "steps": _said_int(self.steps),
            "segment": self.segment,
            "step": self.step,
            "factor": _said_float(self.factor),
            "t_request_ns": _said_int(self.t_request_ns),
            "latency_ns": _said_int(self.latency_ns),
            "v": _said_float(self.v),
            "a": _said_float(self.a),
            "stop_distance": _said_float(self.stop_distance),
            "v_max": _said_float(self.v_max),
            "note": self.note or "",
        }

    @classmethod
    def from_message(cls, msg: Any) -> ControlEvent:
        """The event of a ``winder/control`` message: a
        winder_interfaces/ControlEvent (an rclpy message, or one rosbags
        decoded: -1, NaN and "" read as not said), or the JSON text of a
        std_msgs/String (older bags); checked as
        :meth:`from_wire` does (EventError, one line)."""
        if hasattr(msg, "data"):
            return cls.from_wire(str(msg.data))
        doc: dict[str, Any] = {}
        for key in _FIELDS:
            value = getattr(msg, key)
            if isinstance(value, float) and math.isnan(value):
                continue
            if key in _INT_NOT_SAID and value == -1:
                continue
            if key in _TEXT_NOT_SAID and value == "":
                continue
            # rosbags may hand a numpy scalar
            doc[key] = int(value) if isinstance(value, Integral) and not isinstance(value, bool) else value
        return cls.from_doc(doc)

    @classmethod
    def from_wire(cls, text: str) -> ControlEvent:
        """The event in a ``winder/control`` message's JSON text; EventError
        (one line naming the key) for anything that is not a well-formed
        event. The keys that only annotate it (``source``, ``job_id``,
        ``t_request_ns``, ``latency_ns``, ``v``, ``a``, ``stop_distance``,
        ``v_max``, ``note``) read as None when absent or ill-formed: what the
        event does never depends on them. Unknown keys are ignored."""
        if len(text) > MAX_EVENT_BYTES:
            raise EventError(
                f"a control message of {len(text)} bytes is no event (at most {MAX_EVENT_BYTES})"
            )
        try:
            doc = json.loads(text)
        except (ValueError, RecursionError) as exc:
            raise EventError(f"not JSON: {exc}") from None
        if not isinstance(doc, dict):
            raise EventError("not a JSON object")
        return cls.from_doc(doc)

    @classmethod
    def from_doc(cls, doc: Mapping[str, Any], **more: Any) -> ControlEvent:
        """The event of a decoded JSON object (``more``: keys to add or
        replace, as the wire names them), checked as :meth:`from_wire` does.
        For the producer that has the time law's account of a command
        (:meth:`winder.motion.timeline.Timeline.apply`) and adds the run."""
        doc = {**doc, **more}
        kind = doc.get("event")
        if not isinstance(kind, str) or kind not in EVENT_KINDS:
            raise EventError(f"event={kind!r} is invalid: must be one of {', '.join(EVENT_KINDS)}")
        event = EventKind(kind)
        run_id = doc.get("run_id")
        if not isinstance(run_id, str):
            raise EventError(f"run_id={run_id!r} is invalid: must be a string")
        t_ns = _int(doc, "t_ns")
        if t_ns is None or t_ns < 0:
            raise EventError(f"t_ns={doc.get('t_ns')!r} is invalid: must be an integer >= 0")
        rest = _int(doc, "t_rest_ns", t_ns if event.stops else None)
        if rest is not None and rest < t_ns:
            raise EventError(f"t_rest_ns={rest} is invalid: must be >= t_ns ({t_ns})")
        steps = _int(doc, "steps")
        if event.stops and (steps is None or steps < 0):
            raise EventError(
                f"steps={doc.get('steps')!r} is invalid: a {kind} names the steps up to its rest (>= 0)"
            )
        factor = doc.get("factor")
        if event is EventKind.OVERRIDE:
            if isinstance(factor, bool) or not isinstance(factor, (int, float)) or not math.isfinite(factor):
                raise EventError(f"factor={factor!r} is invalid: an override names a finite factor")
            factor = float(factor)
        else:
            factor = None
        segment = _int(doc, "segment", -1)
        step = _int(doc, "step", 0)
        assert segment is not None and step is not None
        source = doc.get("source")
        return cls(
            event,
            run_id,
            t_ns,
            rest,
            steps,
            segment,
            step,
            factor,
            job_id=_text(doc.get("job_id")),
            source=EventSource(source) if source in EVENT_SOURCES else None,
            t_request_ns=_note_int(doc.get("t_request_ns")),
            latency_ns=_note_int(doc.get("latency_ns")),
            v=_note_float(doc.get("v")),
            a=_note_float(doc.get("a")),
            stop_distance=_note_float(doc.get("stop_distance")),
            v_max=_note_float(doc.get("v_max")),
            note=_text(doc.get("note")),
        )


#: the sources of an event (``source``)
EVENT_SOURCES = tuple(EventSource)
#: the fields of a winder_interfaces/ControlEvent (the JSON keys of before: ``event`` too)
_FIELDS = (
    "event", "source", "run_id", "job_id", "t_ns", "t_rest_ns", "steps", "segment", "step", "factor",
    "t_request_ns", "latency_ns", "v", "a", "stop_distance", "v_max", "note",
)  # fmt: skip
#: the integer fields where -1 means "not said" (``segment``'s -1 is its own "not known")
_INT_NOT_SAID = frozenset({"t_rest_ns", "steps", "t_request_ns", "latency_ns"})
_TEXT_NOT_SAID = frozenset({"source", "job_id", "note"})


def _said_int(value: int | None) -> int:
    return -1 if value is None else value


def _said_float(value: float | None) -> float:
    return math.nan if value is None else value


def _int(doc: Mapping[str, Any], key: str, default: int | None = None) -> int | None:
    value = doc.get(key, default)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int):
        raise EventError(f"{key}={value!r} is invalid: must be an integer")
    return value


def _text(value: object) -> str | None:
    return value if isinstance(value, str) else None


def _note_int(value: object) -> int | None:
    return value if isinstance(value, int) and not isinstance(value, bool) else None


def _note_float(value: object) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return None
    return float(value)
