"""When each step of a job happens: its segments planned with the profile
node's ramp settings (the same values :mod:`winder.contract.params` checks),
split at programmed stops, shaped when a shaper is set, and placed one after
another with the dwell between them. The profile node times a run with it;
``winder run --check``, ``winder tune`` and the interp node's length check
use the same plan, so what they promise is what runs."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from winder.errors import BadInputError
from winder.motion.job import MAX_JOB_SECONDS, Job
from winder.motion.profile import LIMITS, plan
from winder.motion.shaped import Motion, ShapedProfile, shape

__all__ = [
    "MAX_JOB_SECONDS",
    "PACE_POWER",
    "SegmentTiming",
    "plan_job",
    "plan_job_timing",
    "plan_segment",
    "plan_timing",
    "shaping_report",
]


#: how each ramp limit scales when a move is slowed down in time by ``pace``
#: (speed x pace): the power of ``pace`` it takes
PACE_POWER = {"a_max": 2, "j_max": 3, "tau": -1}


def plan_segment(values: dict[str, Any], steps: int, speed: float = 1.0, pace: float = 1.0) -> Motion:
    """The profile of one segment of ``steps`` steps with the profile settings,
    at ``speed`` times ``v_max`` (a layer's share: ``Job.layer_share``), shaped by
    ``shaper`` (absent: none); ValueError (one line) if the limits cannot plan
    it or it would last longer than :data:`MAX_JOB_SECONDS`. ``pace`` < 1
    slows the move down in time (``Job.segment_pace``): the ramp's
    acceleration x pace**2, its jerk x pace**3, an exponential's time
    constant / pace (:data:`PACE_POWER`; the start/stop rate stays)."""
    kind = values["profile"]
    v_max = values["v_max"] * speed
    if values["v_start"] > v_max:
        raise BadInputError(
            f"a layer speed of {speed:g} x v_max (first_layer_speed, layer_speed) is invalid with "
            f"v_max={values['v_max']:g}: the layer's speed {v_max:g} steps/s is below "
            f"v_start={values['v_start']:g} steps/s"
        )
    kw: dict[str, Any] = {"v_max": v_max, "v_start": values["v_start"], "v_end": values["v_start"]}
    kw.update({name: values[name] * pace ** PACE_POWER[name] for name in LIMITS[kind]})
    limits = ", ".join(f"{k}={v:g}" for k, v in kw.items() if k != "v_end")
    if pace != 1.0:  # the limits said are a slowed layer's: say so
        limits += f" (a layer slowed to {pace:g} by layer_speed)"
    far_apart = BadInputError(
        f"profile={kind} with {limits}: the limits are too far apart to plan a {steps}-step move "
        "in floating point"
    )
    if not all(0.0 < kw[name] < math.inf for name in ("v_max", *LIMITS[kind])):
        raise far_apart  # a limit scaled by the layer's speed or pace out of the floats (0, inf)
    profile: Motion
    try:
        profile = plan(kind, float(steps), **kw)
    except (ZeroDivisionError, OverflowError):
        raise far_apart from None
    kind_s = values.get("shaper", "none")
    if kind_s != "none":
        profile = shape(profile, kind_s, values["shaper_freq"], values["shaper_damping"])
    if not math.isfinite(profile.duration) or profile.duration > MAX_JOB_SECONDS:
        raise BadInputError(
            f"profile={kind} with {limits}: a {steps}-step move takes {profile.duration:.3g} s, "
            f"more than a job may last ({MAX_JOB_SECONDS:g} s)"
        )
    return profile


def plan_job(
    values: dict[str, Any], segment_steps: Sequence[int]
) -> tuple[list[Motion], npt.NDArray[np.int64], int]:
    """The profiles of a job's segments, each segment's start time (ns) and the
    job's duration (ns, without the last dwell). Segments of equal length share
    one plan (a job of 10^5 layers plans two or three moves, not 10^5).
    ValueError (one line) if the job would last longer than :data:`MAX_JOB_SECONDS`."""
    plans = {n: plan_segment(values, n) for n in dict.fromkeys(segment_steps)}
    profiles = [plans[n] for n in segment_steps]
    dwell_ns = round(values["dwell"] * 1e9)
    durations = np.array([round(p.duration * 1e9) + dwell_ns for p in profiles], dtype=np.float64)
    total = float(durations.sum()) - dwell_ns
    if total > MAX_JOB_SECONDS * 1e9:
        raise BadInputError(
            f"the job takes {total / 1e9:.4g} s with profile={values['profile']}, v_max={values['v_max']:g}: "
            f"more than a job may last ({MAX_JOB_SECONDS:g} s); raise the limits or split the job"
        )
    t0 = np.zeros(len(profiles), np.int64)
    np.cumsum(durations[:-1].astype(np.int64), out=t0[1:])
    return profiles, t0, int(total)


@dataclass(frozen=True)
class SegmentTiming:
    """When each step of one segment happens: its moves (one, or several
    split at programmed stops, each from and to rest) and the pauses between.

    ``ends``: the step index at which each move ends (the last is the
    segment's step count); ``starts_ns``: each move's start after the
    segment's start ``t0_ns``; ``duration_ns``: to the end of the last move;
    ``speed``: the fraction of ``v_max`` the segment runs at.
    """

    t0_ns: int
    ends: tuple[int, ...]
    profiles: tuple[Motion, ...]
    starts_ns: tuple[int, ...]
    speed: float = 1.0

    @property
    def duration_ns(self) -> int:
        return self.starts_ns[-1] + round(self.profiles[-1].duration * 1e9)

    def times_ns(self, k: npt.NDArray[np.integer[Any]]) -> npt.NDArray[np.int64]:
        """The time (ns since the job's start) of steps ``k`` (1-based) of the segment."""
        if len(self.ends) == 1:  # one move: as before stops existed, bit for bit
            times = self.profiles[0].times_at(k.astype(np.float64))
            return self.t0_ns + np.rint(times * 1e9).astype(np.int64)
        move = np.minimum(np.searchsorted(self.ends, k, side="left"), len(self.ends) - 1)
        before = np.concatenate([[0], self.ends[:-1]])[move]
        out = np.empty(k.shape, np.int64)
        for j in np.unique(move):
            m = move == j
            local = (k[m] - before[m]).astype(np.float64)
            times = self.profiles[int(j)].times_at(local)
            out[m] = self.t0_ns + self.starts_ns[int(j)] + np.rint(times * 1e9).astype(np.int64)
        return out


def plan_timing(
    values: dict[str, Any],
    segment_steps: Sequence[int],
    stops: Sequence[tuple[int, int]] = (),
    pause: float = 0.0,
    speeds: Sequence[float] | None = None,
    paces: Sequence[float] | None = None,
) -> tuple[list[SegmentTiming], int]:
    """The timing of every segment of a job with the ramp ``values``, its
    programmed ``stops`` ((segment, step index) pairs: the axes come to rest
    there, with the same ramp as a segment end, and rest ``pause`` seconds)
    and ``dwell`` between segments; and the job's duration (ns). ``speeds``:
    each segment's fraction of ``v_max`` (:meth:`Job.segment_speed`; absent:
    all 1); ``paces``: each segment's slowing down in time (:func:`plan_segment`;
    absent: all 1). Without stops and speeds the steps' times are :func:`plan_job`'s.
    ValueError (one line) as there."""
    at: dict[int, list[int]] = {}
    for seg, k in stops:
        at.setdefault(seg, []).append(k)
    speed_of = list(speeds) if speeds is not None else [1.0] * len(segment_steps)
    pace_of = list(paces) if paces is not None else [1.0] * len(segment_steps)
    lengths: set[tuple[int, float, float]] = set()
    for i, n in enumerate(segment_steps):
        cuts = [0, *sorted(k for k in at.get(i, ()) if 0 < k < n), n]
        lengths.update((b - a, speed_of[i], pace_of[i]) for a, b in itertools.pairwise(cuts) if b > a)
    plans = {key: plan_segment(values, *key) for key in sorted(lengths)}
    dwell_ns, pause_ns = round(values["dwell"] * 1e9), round(pause * 1e9)
    timings = []
    t0 = 0
    for i, n in enumerate(segment_steps):
        stops_here = sorted(set(at.get(i, ())))
        cuts = [0, *[k for k in stops_here if 0 < k < n], n]
        ends, profiles, starts = [], [], []
        start = 0
        for a, b in itertools.pairwise(cuts):
            move = plans[(b - a, speed_of[i], pace_of[i])]
            ends.append(b)
            profiles.append(move)
            starts.append(start)
            start += round(move.duration * 1e9) + pause_ns
        timing = SegmentTiming(t0, tuple(ends), tuple(profiles), tuple(starts), speed_of[i])
        timings.append(timing)
        rest = pause_ns if n in stops_here else 0  # a stop at a segment's end: the pause after it
        t0 += timing.duration_ns + dwell_ns + rest
        if t0 > MAX_JOB_SECONDS * 1e9:
            raise BadInputError(
                f"the job takes more than {MAX_JOB_SECONDS:g} s with profile={values['profile']}, "
                f"v_max={values['v_max']:g}: more than a job may last; raise the limits or split the job"
            )
    total = timings[-1].t0_ns + timings[-1].duration_ns if timings else 0
    return timings, total


def shaping_report(timings: Sequence[SegmentTiming]) -> dict[str, Any]:
    """What a shaped ramp does to a job, for the ramp configuration it
    publishes: the shaper's impulses and, over every move, the peak velocity,
    acceleration and jerk of the shaped motion (steps/s, /s^2, /s^3: never
    above the ramp's limits, usually below) beside the unshaped plan's. Empty
    for an unshaped ramp."""
    moves = {id(p): p for t in timings for p in t.profiles}.values()
    shaped = [p for p in moves if isinstance(p, ShapedProfile)]
    if not shaped:
        return {}
    first = shaped[0]
    peaks = [p.peaks for p in shaped]
    unshaped = [ShapedProfile(p.base, [1.0], [0.0]).peaks for p in shaped]
    return {
        "shaped": {
            "amplitudes": first.amplitudes.tolist(),
            "times_s": first.times.tolist(),
            "shaper_duration_s": first.shaper_duration,
            "peak": {k: max(q[k] for q in peaks) for k in ("v", "a", "j")},
            "peak_unshaped": {k: max(q[k] for q in unshaped) for k in ("v", "a", "j")},
        }
    }


def plan_job_timing(
    values: dict[str, Any], job: Job, stops: Sequence[tuple[int, int]] = (), pause: float = 0.0
) -> tuple[list[SegmentTiming], int]:
    """:func:`plan_timing` of ``job``'s segments, each at its speed and pace
    (``first_layer_speed``, ``layer_speed``)."""
    segments = job.segments()
    return plan_timing(
        values,
        [s.steps for s in segments],
        stops,
        pause,
        [job.segment_speed(s) for s in segments],
        [job.segment_pace(s) for s in segments],
    )
