"""The step stream between the nodes, ROS-free: job description, chunk layout
and integrity checking.

A job travels as a JSON description (:func:`describe_job`) and then as chunks
of rows. Step rows are ``[segment, feed, fork, pole]`` (int32, absolute step
positions after the step); timed rows are ``[t_ns, segment, feed, fork, pole]``
(int64, nanoseconds since the job start). A chunk never spans two segments.

:class:`StreamChecker` follows the positions: every row must be exactly one
step (each axis by -1, 0 or +1, at least one axis) from the row before it, so
a dropped, duplicated or reordered chunk shows up at its first row.
"""

from __future__ import annotations

import collections
import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from winder.motion.job import AXES, Job

__all__ = [
    "STEP_COLUMNS",
    "TIMED_COLUMNS",
    "ChunkVerdict",
    "JobPlan",
    "StreamChecker",
    "describe_job",
    "parse_job_description",
]

STEP_COLUMNS = ("segment", *AXES)
TIMED_COLUMNS = ("t_ns", "segment", *AXES)
FORMAT = "winder.job/1"


def describe_job(job: Job) -> str:
    """JSON text of a job as the downstream nodes and the bag need it."""
    segs = job.segments()
    doc = {
        "format": FORMAT,
        "job": job.to_dict(),
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


@dataclass(frozen=True)
class SegmentPlan:
    kind: str
    start: tuple[int, ...]
    delta: tuple[int, ...]
    steps: int
    major: int  #: index of the axis with the most steps

    @property
    def end(self) -> tuple[int, ...]:
        return tuple(a + b for a, b in zip(self.start, self.delta, strict=True))


@dataclass(frozen=True)
class JobPlan:
    """A parsed job description."""

    job: Job
    joint_step: tuple[float, ...]
    step_lengths: tuple[float, ...]
    segments: tuple[SegmentPlan, ...]
    total_steps: int
    text: str = field(repr=False)

    @property
    def job_id(self) -> str:
        return self.job.job_id


def parse_job_description(text: str) -> JobPlan:
    """Parse and check :func:`describe_job` output; ValueError if it is not one."""
    try:
        doc: dict[str, Any] = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"job description is not JSON: {exc}") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ValueError(f"job description format is {doc.get('format')!r}, expected {FORMAT!r}")
    job = Job.from_dict(doc["job"])
    segs = []
    for s in doc["segments"]:
        delta = tuple(int(v) for v in s["delta"])
        major = int(np.argmax(np.abs(delta)))
        segs.append(SegmentPlan(s["kind"], tuple(int(v) for v in s["start"]), delta, int(s["steps"]), major))
    expected = job.segments()
    if len(expected) != len(segs) or any(
        e.delta != s.delta or e.start != s.start for e, s in zip(expected, segs, strict=True)
    ):
        raise ValueError("job description segments do not match its job fields")
    return JobPlan(
        job=job,
        joint_step=tuple(float(v) for v in doc["joint_step"]),
        step_lengths=tuple(float(v) for v in doc["step_lengths"]),
        segments=tuple(segs),
        total_steps=int(doc["total_steps"]),
        text=text,
    )


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

    def check(self, segment: int, pos: npt.NDArray[np.integer[Any]]) -> ChunkVerdict:
        """Check one chunk: ``segment`` index and its (n, axes) positions."""
        segs = self.plan.segments
        n = pos.shape[0]
        if n == 0:
            return self._reject("bad", "empty chunk")
        if not 0 <= segment < len(segs):
            return self._reject("bad", f"segment {segment} out of range 0..{len(segs) - 1}")
        seg = segs[segment]
        k = self.step_index(segment, pos)
        # single steps: no axis moves by more than one step per row, and the
        # major axis (which moves on every step) covers n - 1 steps in n - 1
        # rows, so it moves on every row; column by column (a 1-D pass each is
        # much cheaper than one over the strided (n, axes) block)
        if n > 1 and (
            int(k[-1]) - int(k[0]) != n - 1
            or any(not -1 <= int(d.min()) <= int(d.max()) <= 1 for d in map(np.diff, pos.T))
        ):
            return self._reject("bad", f"segment {segment}: rows inside the chunk are not single steps")
        # steps are counted across segments (self._offsets): where the stream
        # stands, and where this chunk starts
        at = int(self.step_index(self.segment, self.position[None, :])[0])
        here, first = self._offsets[self.segment] + at, self._offsets[segment] + int(k[0])
        if first <= here:
            # late if it falls into a gap reported before, else a repeat
            last = self._offsets[segment] + int(k[-1])
            late = any(a <= last and first <= b for a, b in self._gaps)
            kind, why = ("reorder", "arrived late") if late else ("duplicate", "arrived again")
            return self._reject(kind, f"segment {segment} steps {k[0]}..{k[-1]} {why}")
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
                f"step {k[0]} of {seg.steps}",
            )
        self.segment = segment
        self.position = pos[-1].astype(np.int64).copy()
        self.done += n
        return verdict

    def _reject(self, kind: str, message: str) -> ChunkVerdict:
        self.rejected += 1  # the caller adds the chunk's steps to rejected_steps
        return ChunkVerdict(False, kind, 0, message)
