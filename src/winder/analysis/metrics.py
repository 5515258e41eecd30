"""How well a recorded job wound, and how the axes moved: ROS-free.

Input is a :class:`winder.record.reader.Run`; output an :class:`Analysis` that prints
as a table (:func:`format_table`, several runs side by side) or JSON
(:func:`to_json`).

What was run, and how much of it
--------------------------------
The set-up (:func:`setup`: job, ramp limits of its profile, motor model and
each axis' motor from ``winder/sim_config``, joint-state rate, the bag's chunk
compression) is what several runs are compared on: the table marks ``*`` the
rows whose values differ (:func:`setup_differences`, on the recorded values,
not on their rounded text). Steps are counted three ways and never taken one
for another: *simulated* (the sim node's final report, ``steps_done``),
*recorded* (the step rows in the bag) and *in the job*; a note says where the
first two disagree. The sim node's stream counters (gaps, steps missing,
chunks rejected, stalls) and every ERROR status recorded are listed.

Winding accuracy (the 2016 rotor-winding paper, eq. 7)
------------------------------------------------------
Unrolled, a layer is the straight line from its start to (feed distance,
flyer arc) = (x_E, y_E). The deviation of a point is its perpendicular
(Euclidean) distance to that line, |x_E*y - x*y_E| / |OE| (eq. 5), with x in
metres of feed and y in metres of flyer arc; eq. 7 is its mean over the
points of a layer. Two sets of points:

* **command**: the position after every step of the layer (the interpolation
  error; a quarter of the minor-axis step for minimum deviation);
* **axes**: every joint-state sample while a layer is wound (dynamics
  included). A sample is measured against the ideal line of the layer whose
  fork range holds the sample's fork position, not the layer the command is
  in: an axis pair that lags along the line is on the line, and at a corner a
  lagging sample still belongs to the layer it is on.

Per turn: the mean deviation over each turn (fork revolution) of each layer,
as a percentage of the wire diameter; the paper reports under 0.1 % on a real
RW400.

Motion quality
--------------
* **command** velocity, acceleration and jerk come from the step times of each
  segment's major axis. Step k happens when the planned motion reaches k steps,
  so the step times sample the inverse t(k) of the motion exactly at the
  integers; with the derivatives of t(k) by central differences over a stride
  of m steps, v = 1/t' and a = -t''/t'**3; the jerk is the difference of a
  one stride either side over the time between them (the mean jerk there, so
  never beyond the move's largest |jerk|; the closed form 3a**2/v - t'''*v**4
  overshot by 13 % where the jerk jumps from +J to -J). The stride
  is chosen so that it spans at least :data:`STRIDE_TIME` (the ns rounding of
  the step times would otherwise dominate the jerk). The other axes of the
  segment move in proportion (their delta / the major delta): the ideal
  interpolated motion, whose step quantisation is the eq. 7 error above. For
  a profile with jumps in acceleration (trapezoid, exponential) the jerk is
  unbounded; the value shown is the jump divided by the stride time. Each
  move between rests is differentiated on its own: a segment is cut at its
  programmed stops and where a recorded pause or abort brought the axes to
  rest (:func:`rests`), since t(k) jumps across a rest and is singular on
  either side of it, as at a move's start.
* **axes**: the recorded joint velocity, its acceleration and jerk by central
  differences at the publish rate (so the values depend on the rate: the step
  ripple of the motor is seen only as far as it is sampled).
* **tracking error** command - actual position at each sample, in steps and in
  joint units; the final error in steps, and in tooth pitches (net slips).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from winder.analysis.digest import STRIDE_TIME, Digest, SegmentKinematics, digest, turn_index
from winder.analysis.wire import FAULTS, fault, layer_tensions, paid_out
from winder.contract.eq7 import layer_of_samples, sample_deviation
from winder.contract.run import PART_ID_KEY, PART_INDEX_KEY, commands_text, shaper_text, stops_text
from winder.contract.states import EventKind, JobState
from winder.errors import WinderError
from winder.motion.axes import AXES, AXIS_TABLE, FEED, FORK
from winder.motion.profile import LIMITS
from winder.record.parts import INDEX_NAME, PartIndex
from winder.record.reader import Run

__all__ = [
    "STRIDE_TIME",
    "Analysis",
    "AxisMotion",
    "Deviation",
    "LayerDeviation",
    "analyze",
    "axis_deviation",
    "command_deviation",
    "digest_run",
    "format_table",
    "paired_error",
    "run_part",
    "sample_layers",
    "setup",
    "setup_differences",
    "step_kinematics",
    "to_json",
    "winding_samples",
]

FloatArray = npt.NDArray[np.float64]

UNITS = {a.name: a.unit for a in AXIS_TABLE}


@dataclass(frozen=True)
class LayerDeviation:
    segment: int
    pole: int
    layer: int
    points: int
    mean: float  #: m, eq. 7
    max: float  #: m


@dataclass(frozen=True)
class Deviation:
    """Eq. 7 over all layers: mean and maximum distance (m), per layer, per turn."""

    mean: float
    max: float
    rms: float
    points: int
    turn_max: float  #: the worst turn's mean deviation (m)
    turn_max_pct: float  #: ... in % of the wire diameter
    turn_mean_pct: float  #: mean over turns, in % of the wire diameter
    layers: list[LayerDeviation] = field(default_factory=list)


@dataclass(frozen=True)
class AxisMotion:
    """Peak motion of one axis (joint units: m or rad, per s, s^2, s^3) and its
    tracking error. NaN where the recording holds nothing to measure."""

    axis: str
    unit: str
    steps_moved: int
    cmd_v: float
    cmd_a: float
    cmd_j: float
    act_v: float
    act_a: float
    act_j: float
    track_max_steps: float
    track_rms_steps: float
    track_max: float  #: joint units
    final_error_steps: float
    net_slips: int  #: final error in whole tooth pitches (0 without sim_config)


@dataclass(frozen=True)
class Analysis:
    label: str
    path: str
    job_id: str
    run_id: str  #: "" in bags recorded before run ids
    job: str  #: one-line description of the winding (poles, layers, turns, wire)
    profile: str
    ramp: dict[str, float]  #: the recorded ramp limits (steps of the major axis, s); empty if unknown
    model: str
    state: str  #: the sim node's final state ("" if no report)
    complete: bool
    closed: bool
    recovered: bool
    damaged: int  #: chunks skipped as damaged (CRC or compression)
    errors: int  #: ERROR reports recorded during the run
    steps_recorded: int
    steps_total: int
    job_time: float  #: s, time of the last step
    sim_time: float  #: s, last joint sample
    wall_time: float  #: s, from the sim node's report (NaN if none)
    real_time_factor: float
    lost_steps: int  #: full steps lost, from the sim node's report (-1 if unknown)
    command: Deviation
    actual: Deviation | None
    axes: dict[str, AxisMotion]
    notes: list[str] = field(default_factory=list)
    steps_simulated: int = -1  #: steps the sim node simulated, from its report (-1 if unknown)
    #: each axis' motor as the simulation used it: J, D, Zr, L, i_a, motor_step_angle, load_torque (SI)
    motors: dict[str, dict[str, float]] = field(default_factory=dict)
    publish_rate: float = math.nan  #: joint-state rate, Hz of simulated time
    #: the coil as wound (winder.analysis.wound): layers and defects; empty without joint samples
    as_wound: dict[str, Any] = field(default_factory=dict)
    source: str = ""  #: a re-simulation: the bag and run its steps come from
    error_list: list[str] = field(default_factory=list)  #: every ERROR recorded, with its time
    compression: str = ""  #: the bag's MCAP chunk compression ("" if unknown)
    #: the sim node's stream checks at the end (gaps, steps_missing, chunks_rejected,
    #: stalls, errors), as it reported them; empty without a report
    stream: dict[str, int] = field(default_factory=dict)
    #: sha256 of the job file the run's job comes from ("" if none): its recipe
    job_file_sha256: str = ""
    shaper: str = ""  #: the input shaper of the run's ramp ("ZVD shaper at 12.5 Hz"), "" if none
    stops: str = ""  #: the job's programmed stops in one line (winder.contract.run.stops_text), "" if none
    commands: str = ""  #: the operator's commands in one line (commands_text), "" if none
    #: the wire as recorded (winder/tension), where the run simulated it: the tension's least
    #: and peak, the set tension, the bands and how long the tension was outside each (s), the
    #: wire paid out, the tension and stretch per layer wound, its break and slip (winder.analysis.wire)
    wire: dict[str, Any] = field(default_factory=dict)
    #: the run's part where a part index has it (:func:`run_part`): ``part_id``, ``index`` (its
    #: file), ``state``, ``verdict`` (None while running) and ``reasons``; empty if none has it
    part: dict[str, Any] = field(default_factory=dict)


# -- the part --------------------------------------------------------------------------


def run_part(run: Run) -> tuple[dict[str, Any], str]:
    """The run's part in the part index (docs/PARTS.md), and a note ("" if
    none) if an index that should hold it cannot be read. Looked for in the
    index the run's final report names (``part_index``, where it is on this
    host), then in the one beside the bag (``<bag_dir>/parts.sqlite``: a bag
    directory copied whole keeps it). The part is the one the report names
    (``part_id``); a run without that key (killed before its final report, or
    older) is found by its run id, if that part's bag is this bag's name."""
    bag = run.path if run.path.is_dir() else run.path.parent
    named = run.report.get(PART_INDEX_KEY, "")
    candidates = [Path(named)] if named else []
    candidates.append(bag.parent / INDEX_NAME)
    part_id = run.report.get(PART_ID_KEY, "")
    for path in dict.fromkeys(candidates):
        if not path.is_file():
            continue
        try:
            row = PartIndex(path).get(part_id or run.run_id)
        except WinderError as exc:
            return {}, f"the run's part not read: {exc}"
        if row is None or (not part_id and Path(str(row.get("bag") or "")).name != bag.name):
            continue
        reasons = json.loads(row["reasons"]) if row.get("reasons") else []
        return {
            "part_id": row["part_id"],
            "index": str(path),
            "state": row["state"],
            "verdict": row["verdict"],
            "reasons": reasons,
        }, ""
    return {}, ""


# -- eq. 7 -------------------------------------------------------------------------


def _no_deviation(layers: list[LayerDeviation]) -> Deviation:
    nan = math.nan
    return Deviation(nan, nan, nan, 0, nan, nan, nan, layers)


def command_deviation(run: Run, digested: Digest | None = None) -> Deviation:
    """Eq. 7 of the commanded steps: every step row of every layer segment."""
    d = digested if digested is not None else digest_run(run)
    segs = run.plan.segments
    stats = [s for s in d.layers.values() if s.points]
    layers = [
        LayerDeviation(s.segment, segs[s.segment].pole, segs[s.segment].layer, s.points, s.mean, s.max)
        for s in stats
    ]
    if not stats:
        return _no_deviation(layers)
    points = sum(s.points for s in stats)
    tm = np.concatenate([s.turn_means() for s in stats])
    wire = run.plan.job.wire_diameter
    return Deviation(
        mean=sum(s.total for s in stats) / points,
        max=max(s.max for s in stats),
        rms=math.sqrt(sum(s.total_sq for s in stats) / points),
        points=points,
        turn_max=float(tm.max()),
        turn_max_pct=float(100 * tm.max() / wire),
        turn_mean_pct=float(100 * tm.mean() / wire),
        layers=layers,
    )


def _summarise(
    dists: list[FloatArray], turn_ids: list[npt.NDArray[np.int64]], layers: list[LayerDeviation], wire: float
) -> Deviation:
    if not dists or sum(d.size for d in dists) == 0:
        return _no_deviation(layers)
    d = np.concatenate(dists)
    turn_means = []
    for dist, tid in zip(dists, turn_ids, strict=True):
        if dist.size:
            sums = np.bincount(tid, weights=dist)
            counts = np.bincount(tid)
            turn_means.append(sums[counts > 0] / counts[counts > 0])
    tm = np.concatenate(turn_means)
    return Deviation(
        mean=float(d.mean()),
        max=float(d.max()),
        rms=float(np.sqrt(np.mean(d * d))),
        points=int(d.size),
        turn_max=float(tm.max()),
        turn_max_pct=float(100 * tm.max() / wire),
        turn_mean_pct=float(100 * tm.mean() / wire),
        layers=layers,
    )


def sample_layers(run: Run, digested: Digest) -> npt.NDArray[np.int64]:
    """The layer segment each joint sample is measured against
    (:mod:`winder.contract.eq7`), -1 where none; empty if the digest has no
    command segment for the samples."""
    if digested.sample_segment.size != len(run.states):
        return np.zeros(0, np.int64)
    y = run.states.pos[:, FORK.index] / run.plan.joint_step[FORK.index]
    return layer_of_samples(run.plan, digested.sample_segment, y)


def winding_samples(run: Run, digested: Digest) -> tuple[npt.NDArray[np.int64], FloatArray, FloatArray]:
    """The joint samples taken while a layer is wound, each with the layer
    it is measured against (:func:`sample_layers`): (layer segment, x, y), x
    and y in steps of the feed and the fork."""
    js = run.plan.joint_step
    layer = sample_layers(run, digested)
    if not layer.size:
        z = np.zeros(0)
        return np.zeros(0, np.int64), z, z
    keep = layer >= 0
    x = run.states.pos[keep, FEED.index] / js[FEED.index]  # steps, float
    y = run.states.pos[keep, FORK.index] / js[FORK.index]
    return layer[keep], x, y


def axis_deviation(run: Run, digested: Digest | None = None) -> Deviation | None:
    """Eq. 7 of the simulated axes (see module doc); None without joint states or steps."""
    d = digested if digested is not None else digest_run(run)
    plan = run.plan
    if len(run.states) == 0 or d.rows == 0 or not any(s.kind.winds for s in plan.segments):
        return None
    spr = plan.job.fork_steps_per_rev
    seg, x, y = winding_samples(run, d)
    every = sample_deviation(plan, seg, x, y)  # the sim node's live figure is the same function's
    dists, tids, layers = [], [], []
    for i in (int(v) for v in np.unique(seg)):
        m = seg == i
        s = plan.segments[i]
        yr = y[m] - s.start[FORK.index]
        dist = every[m]
        dists.append(dist)
        tids.append(turn_index(np.abs(yr), spr, abs(s.delta[FORK.index]) // spr))
        layers.append(
            LayerDeviation(i, s.pole, s.layer, int(dist.size), float(dist.mean()), float(dist.max()))
        )
    return _summarise(dists, tids, layers, plan.job.wire_diameter)


# -- motion -------------------------------------------------------------------------


def step_kinematics(t_ns: npt.ArrayLike, stride_time: float = STRIDE_TIME) -> tuple[FloatArray, ...]:
    """Velocity, acceleration and jerk of a move from its step times.

    ``t_ns[k]`` is the time (ns) at which the move reached k steps (k = 0 may
    be NaN when the start is unknown; missing steps NaN). Returns (t, v, a, j)
    at the steps where the central stencil fits, in s and steps/s, /s^2, /s^3
    (see module doc). The stencil slides over the step times
    (:class:`winder.analysis.digest.SegmentKinematics`), as in the analysis.
    """
    t = np.asarray(t_ns, dtype=np.float64)
    n = t.size
    out: list[FloatArray] = []
    if n == 0:
        return _EMPTY, _EMPTY, _EMPTY, _EMPTY

    def keep(*x: FloatArray) -> None:
        out.append(np.vstack(x))

    kin = SegmentKinematics(n - 1, keep, stride_time=stride_time)
    kin.add(np.arange(n, dtype=np.int64), t)
    kin.finish()
    if not out:
        return _EMPTY, _EMPTY, _EMPTY, _EMPTY
    w = np.hstack(out)
    return w[0], w[1], w[2], w[3]


_EMPTY = np.zeros(0)


def _peak(x: FloatArray) -> float:
    return float(np.max(np.abs(x))) if x.size else math.nan


def paired_error(run: Run) -> tuple[npt.NDArray[np.intp], FloatArray]:
    """The samples where both the command and the axis position were recorded
    (written in pairs: matched by time): their indices in ``run.states`` and
    command - axis position there, (k, 3) in joint units."""
    st, cm = run.states, run.commands
    ti_s = np.round(st.t * 1e9).astype(np.int64)
    ti_c = np.round(cm.t * 1e9).astype(np.int64)
    _, i_s, i_c = np.intersect1d(ti_s, ti_c, assume_unique=False, return_indices=True)
    diff: FloatArray = cm.pos[i_c] - st.pos[i_s]
    return i_s, diff


def read_back(run: Run) -> str | None:
    """Why the axes' acceleration and jerk are not measured, None when they
    are: a consumer that is no simulator (a hardware driver: its
    configuration names no motor model, :func:`winder.record.reader.read_run`)
    records the positions its drive read back (on a drive, whole steps held
    between reads: a staircase), whose second and third differences are the
    steps' edges over a sample period, not the axes' motion."""
    if run.sim_config is not None or not len(run.states):
        return None
    return (
        "axes' acceleration and jerk not measured: the joint states are the drive's read-back "
        "positions (no motor model: a hardware consumer), steps held between reads, whose "
        "differences are the steps' edges, not motion"
    )


def _axis_motion(run: Run, d: Digest) -> dict[str, AxisMotion]:
    js = run.plan.joint_step
    st = run.states
    _, diff = paired_error(run)
    if st.t.size >= 3 and read_back(run) is None:
        acc = np.gradient(st.vel, st.t, axis=0)
        jerk = np.gradient(acc, st.t, axis=0)
    else:
        acc = jerk = np.zeros((0, len(AXES)))
    out = {}
    for ax, name in enumerate(AXES):
        err = diff[:, ax] / js[ax]
        final = float(err[-1]) if err.size else math.nan
        slips = 0
        if run.sim_config is not None and err.size:
            slips = round(final / run.sim_config.axes[name].pitch_steps)
        tr = d.traces[name]
        out[name] = AxisMotion(
            axis=name,
            unit=UNITS[name],
            steps_moved=d.moved[ax],
            cmd_v=tr.peak_v,
            cmd_a=tr.peak_a,
            cmd_j=tr.peak_j,
            act_v=_peak(st.vel[:, ax]),
            act_a=_peak(acc[:, ax]) if acc.size else math.nan,
            act_j=_peak(jerk[:, ax]) if jerk.size else math.nan,
            track_max_steps=_peak(err),
            track_rms_steps=float(np.sqrt(np.mean(err * err))) if err.size else math.nan,
            track_max=_peak(err) * js[ax] if err.size else math.nan,
            final_error_steps=final,
            net_slips=int(slips),
        )
    return out


def digest_run(run: Run, stride_time: float = STRIDE_TIME) -> Digest:
    """One pass over the run's step rows (:func:`winder.analysis.digest.digest`)."""
    return digest(run.plan, run.step_rows, run.states.t, stride_time, rests(run))


def rests(run: Run) -> list[tuple[int, int]]:
    """Where the operator's commands brought the axes to rest within a segment:
    (segment, steps of it done) of each recorded pause and abort."""
    return [
        (e["segment"], e["step"])
        for e in run.events
        if e.get("event") in (EventKind.PAUSE, EventKind.ABORT)
        and isinstance(e.get("segment"), int)
        and isinstance(e.get("step"), int)
    ]


#: the profile node's settings shown as the ramp (winder/profile_config)
RAMP_KEYS = ("v_max", "a_max", "j_max", "tau", "v_start", "dwell", "feed_override")
#: the sim node's stream counters (its job status) shown as stream faults
STREAM_KEYS = ("gaps", "steps_missing", "chunks_rejected", "stalls", "errors")


def _num(report: dict[str, str], key: str, default: float = math.nan) -> float:
    try:
        return float(report[key])
    except (KeyError, ValueError):
        return default


def analyze(run: Run, stride_time: float = STRIDE_TIME, digested: Digest | None = None) -> Analysis:
    """Winding accuracy and motion quality of one recorded run (module doc).
    ``digested``: the run's :func:`digest_run` with ``stride_time``, if made already."""
    d = digested if digested is not None else digest_run(run, stride_time)
    job = run.plan.job
    notes = list(run.notes)
    staircase = read_back(run)
    if staircase is not None:
        notes.append(staircase)
    if d.rows == 0:
        notes.append("no steps recorded")
    elif not d.increasing:
        notes.append(
            "step times do not increase everywhere: the recording holds repeated or reordered chunks"
        )
    if run.damaged:
        notes.append(
            f"damaged recording: {len(run.damaged)} chunk(s) skipped, their messages are missing "
            f"from every figure (first: {run.damaged[0]})"
        )
    for e in run.events:
        notes.append(_event_note(e))
    if run.report.get("state") == JobState.ABORTED and run.closed and not run.damaged:
        notes.append(
            f"run aborted: it ended at rest after {run.report.get('steps_done', '?')} steps; "
            "the figures cover those"
        )
    elif not run.complete:
        why = (
            "damaged"
            if run.damaged and run.closed
            else "cut short and recovered"
            if run.recovered
            else f"sim state {run.report.get('state', 'unknown')}"
        )
        mend = ""
        if run.recovered and not run.closed:
            from winder.record.bag import being_written

            mend = (
                "; it is still being recorded"
                if being_written(run.path)
                else f"; it was left unclosed (its writer killed, or its disk full): `winder bag recover "
                f"{run.path}` writes a closed copy with its index (every reader opens it as it is)"
            )
        notes.append(f"incomplete recording ({why}): figures cover what was recorded{mend}")
    simulated = int(_num(run.report, "steps_done", -1))
    reported_total = int(_num(run.report, "steps_total", -1))
    if 0 <= reported_total != run.plan.total_steps:
        notes.append(
            f"the sim node reported a job of {reported_total} steps, the recorded job has "
            f"{run.plan.total_steps}"
        )
    if 0 <= simulated != d.rows:
        notes.append(
            f"the sim node simulated {simulated} steps, the recording holds {d.rows} step rows: "
            + (
                f"{d.rows - simulated} recorded steps were never simulated"
                if simulated < d.rows
                else f"{simulated - d.rows} simulated steps are missing from the recording"
            )
        )
    if d.lost_stencils:
        notes.append(
            f"{d.lost_stencils} command kinematics points left out: the move sped up faster "
            "than the analysis keeps step times for"
        )
    part, unread = run_part(run)
    if unread:
        notes.append(unread)
    state = run.report.get("state", "")
    lost = int(_num(run.report, "lost_steps", -1))
    sim_time = float(run.states.t[-1]) if len(run.states) else math.nan
    return Analysis(
        label=run.label,
        path=str(run.path),
        job_id=run.job_id,
        run_id=run.run_id,
        job=(
            f"{job.shape}, "
            f"wire {job.wire_diameter * 1e3:g} mm"
            + (f", coils {job.coil_overrides}" if job.coil_overrides else "")
        ),
        profile=run.profile or "unknown",
        ramp={
            k: float(v)
            for k, v in run.profile_config.items()
            if k in RAMP_KEYS and isinstance(v, (int, float))
        },
        model=run.sim_config.model if run.sim_config else "unknown",
        state=state,
        complete=run.complete,
        closed=run.closed,
        recovered=run.recovered,
        damaged=len(run.damaged),
        errors=len(run.errors),
        steps_recorded=d.rows,
        steps_total=run.plan.total_steps,
        job_time=d.last_t / 1e9 if d.last_t is not None else math.nan,
        sim_time=sim_time,
        wall_time=_num(run.report, "wall_time_s"),
        real_time_factor=_num(run.report, "real_time_factor"),
        lost_steps=lost,
        command=command_deviation(run, d),
        actual=axis_deviation(run, d),
        axes=_axis_motion(run, d),
        notes=notes,
        steps_simulated=simulated,
        motors={
            axis: {k: getattr(a, k) for k in ("J", "D", "Zr", "L", "i_a", "motor_step_angle", "load_torque")}
            for axis, a in (run.sim_config.axes.items() if run.sim_config else ())
        },
        publish_rate=run.sim_config.publish_rate if run.sim_config else math.nan,
        as_wound=_as_wound(run, d),
        source=(
            f"{run.sim_config.source_bag} (run {run.sim_config.source_run_id or '-'})"
            if run.sim_config and run.sim_config.source_bag
            else ""
        ),
        error_list=list(run.errors),
        compression=run.compression,
        stream={k: int(_num(run.report, k)) for k in STREAM_KEYS if math.isfinite(_num(run.report, k))},
        job_file_sha256=run.plan.job_file_sha256,
        shaper=shaper_text(run.profile_config),
        stops=stops_text(run.plan),
        commands=commands_text(run.events, run.plan),
        wire=_wire(run, d),
        part=part,
    )


def _wire(run: Run, d: Digest) -> dict[str, Any]:
    """The recorded tension against the job's bands, per layer wound, the wire
    paid out and its faults (:mod:`winder.analysis.wire`); empty where no wire
    was simulated."""
    t, tension = run.tension.t, run.tension.tension
    if not t.size:
        return {}
    job = run.plan.job
    set_n = job.set_tension
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    out: dict[str, Any] = {
        "tension_min_n": float(tension.min()),
        "tension_peak_n": float(tension.max()),
        "set_tension_n": set_n,
        "max_tension_n": job.tension_limit,
    }
    for band, frac in (("warning", job.tension_warning), ("alarm", job.tension_alarm)):
        low, high = set_n * (1 - frac), set_n * (1 + frac)
        out[f"{band}_band_n"] = [low, high]
        out[f"outside_{band}_s"] = int(np.count_nonzero((tension < low) | (tension > high))) * dt
    out.update(
        paid_out_m=paid_out(run),
        tension_set_n=set_n,
        tension_max_n=float(tension.max()),
        layers=[lay.to_json() for lay in layer_tensions(run, sample_layers(run, d))],
        **{kind: fault(run, kind) for kind in FAULTS},
    )
    return out


# -- output ---------------------------------------------------------------------------


def _clean(x: Any) -> Any:
    if isinstance(x, float):
        return None if not math.isfinite(x) else x
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_clean(v) for v in x]
    return x


def _as_wound(run: Run, d: Digest) -> dict[str, Any]:
    from winder.analysis.wound import as_wound

    wound = as_wound(run, segment_end=d.segment_end)
    return wound.to_json() if wound is not None else {}


def to_json(analyses: list[Analysis]) -> str:
    """JSON text: a list with one object per run (NaN written as null); each
    object's ``setup_differs`` names the set-up values (:func:`setup`) in
    which the runs differ, the rows the table marks ``*``."""
    differs = setup_differences(analyses)
    return json.dumps([_clean({**asdict(a), "setup_differs": differs}) for a in analyses], indent=2)


def setup(a: Analysis) -> dict[str, Any]:
    """A run's set-up as flat key -> value: what two runs are compared on
    (job, ramp limits of its profile, motor model and each axis' motor,
    joint-state rate, compression, source of a re-simulation)."""
    out: dict[str, Any] = {
        "job_id": a.job_id,
        "job": a.job,
        "source": a.source,
        "profile": a.profile,
        "shaper": a.shaper,
        "model": a.model,
    }
    shown = ("v_max", *LIMITS.get(a.profile, ()), "v_start", "dwell", "feed_override")
    out.update({f"ramp.{k}": a.ramp[k] for k in shown if k in a.ramp})
    for axis, motor in a.motors.items():
        out.update({f"{axis}.{k}": v for k, v in motor.items()})
    out["publish_rate"] = a.publish_rate
    out["compression"] = a.compression
    return out


def setup_differences(analyses: list[Analysis]) -> list[str]:
    """The :func:`setup` keys whose values are not the same in every run
    (a key some run lacks counts as different); empty for one run."""
    setups = [setup(a) for a in analyses]
    keys = list(dict.fromkeys(k for s in setups for k in s))
    return [k for k in keys if len({repr(s.get(k)) for s in setups}) > 1]


def _g(x: float, scale: float = 1.0, digits: int = 4) -> str:
    """A number for the table in ``digits`` significant digits; 0, never -0."""
    return "-" if not math.isfinite(x) else f"{x * scale + 0.0:.{digits}g}"  # -0.0 + 0.0 is 0.0


def _f(x: float, scale: float = 1.0, decimals: int = 3) -> str:
    """A number for the table; a value that rounds to zero is 0, never -0."""
    if not math.isfinite(x):
        return "-"
    text = f"{x * scale:.{decimals}f}"
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text


def _event_note(e: dict[str, Any]) -> str:
    """One line for an operator event of the run."""
    t = f"{e['t_ns'] / 1e9:.3f} s"
    kind = e.get("event", "?")
    if kind in (EventKind.PAUSE, EventKind.ABORT):
        return (
            f"operator {kind} at {t} ({e.get('source', 'call')}): at rest at "
            f"{e.get('t_rest_ns', e['t_ns']) / 1e9:.3f} s after {e.get('steps', '?')} steps, "
            f"stop distance {float(e.get('stop_distance', 0.0)):.1f} steps"
        )
    if kind == EventKind.OVERRIDE:
        return f"operator feed override x{e.get('factor', '?')} at {t}: {e.get('note', '')}"
    return f"operator {kind} at {t}"


def _ramp(a: Analysis) -> str:
    r = a.ramp
    if not r:
        return "not recorded"
    names = {"v_max": "v", "a_max": "a", "j_max": "j", "tau": "tau"}
    parts = [f"{names[k]} {r[k]:g}" for k in ("v_max", *LIMITS.get(a.profile, ())) if k in r]
    if r.get("v_start"):
        parts.append(f"v_start {r['v_start']:g}")
    if r.get("dwell"):
        parts.append(f"dwell {r['dwell']:g}")
    if r.get("feed_override", 1.0) != 1.0:
        parts.append(f"override x{r['feed_override']:g}")
    return ", ".join(parts) + " (steps/s^n, s)"


def _steps(a: Analysis) -> str:
    """Steps simulated (the sim node's count), recorded (step rows in the bag)
    and in the job, and why the first falls short of the last."""
    if a.steps_simulated < 0:
        cut = "cut short, " if a.recovered else ""
        return f"{a.steps_recorded} recorded, of {a.steps_total} ({cut}no report of the step consumer)"
    text = f"{a.steps_simulated} simulated, {a.steps_recorded} recorded, of {a.steps_total}"
    if a.steps_simulated >= a.steps_total:
        return text
    missing = a.stream.get("steps_missing", 0)
    why = [
        "aborted at rest" if a.state == JobState.ABORTED else a.state or "no state",
        *([f"{missing} steps never arrived"] if missing else []),
    ]
    return f"{text} ({', '.join(why)})"


def _stream(a: Analysis) -> str:
    """The stream faults the sim node counted, "none" if it counted none."""
    if not a.stream:
        return "-"
    s = a.stream
    parts = []
    if s.get("gaps"):
        parts.append(f"{s['gaps']} gap(s), {s.get('steps_missing', 0)} steps missing")
    elif s.get("steps_missing"):
        parts.append(f"{s['steps_missing']} steps missing")
    if s.get("chunks_rejected"):
        parts.append(f"{s['chunks_rejected']} chunk(s) rejected (repeated or late)")
    if s.get("stalls"):
        parts.append(f"{s['stalls']} stall(s)")
    return ", ".join(parts) or "none"


def _part_text(a: Analysis) -> str:
    """The run's part in a few words: its id, its verdict (or its state while it is
    running) and its index where that is not the one beside the bag; "none" if no index has it."""
    if not a.part:
        return "none"
    p = a.part
    where, bag = Path(p["index"]).resolve(), Path(a.path).resolve()
    beside = where.parent == (bag if bag.is_dir() else bag.parent).parent
    return f"{p['part_id']} ({p['verdict'] or p['state']})" + ("" if beside else f" in {where}")


def _rows(a: Analysis) -> list[tuple[str, str]]:
    state = a.state or "no report"
    state += ", closed" if a.closed else (", cut short (recovered)" if a.recovered else ", not closed")
    if a.damaged:
        state += f", DAMAGED ({a.damaged} chunks skipped)"
    if a.errors:
        state += f", {a.errors} ERROR reports"
    rows = [
        ("job id", a.job_id),
        ("job", a.job),
        ("run", a.run_id or "-"),
        ("part", _part_text(a)),
        ("job file sha256", a.job_file_sha256 or "-"),
        ("re-simulation of", a.source or "-"),
        ("profile / motor model", f"{a.profile}{', ' + a.shaper if a.shaper else ''} / {a.model}"),
        ("ramp limits (major axis)", _ramp(a)),
    ]
    for name, motor in a.motors.items():
        load = f", load {motor['load_torque']:.4g} N m" if motor.get("load_torque") else ""
        rows.append((f"{name}: motor J, D", f"{motor['J']:.5g} kg m^2, {motor['D']:.5g} N m s/rad{load}"))
        rows.append(
            (
                f"{name}: motor Zr, L, i_a",
                f"{motor['Zr']:g} teeth, {motor['L']:.4g} H, {motor['i_a']:.4g} A, "
                f"{motor['motor_step_angle']:.4g} rad/step",
            )
        )
    rows += [
        ("joint-state rate", f"{a.publish_rate:g} Hz" if math.isfinite(a.publish_rate) else "-"),
        ("bag compression", a.compression or "-"),
        ("state", state),
        ("steps", _steps(a)),
        ("stream faults", _stream(a)),
        ("programmed stops", a.stops or "none"),
        ("operator commands", a.commands or "none"),
        ("job time (last step)", f"{_f(a.job_time)} s"),
        ("simulated / wall time", f"{_f(a.sim_time)} s / {_f(a.wall_time)} s"),
        ("real-time factor", f"{_f(a.real_time_factor, decimals=1)} x"),
        ("lost steps (sim node)", f"{a.lost_steps} full steps" if a.lost_steps >= 0 else "-"),
        *_wire_rows(a.wire),
        ("eq.7 mean, command", f"{_f(a.command.mean, 1e6)} um"),
        ("eq.7 max, command", f"{_f(a.command.max, 1e6)} um"),
        ("worst turn, command", f"{_f(a.command.turn_max_pct, decimals=4)} % of wire"),
    ]
    act = a.actual
    rows += [
        ("eq.7 mean, axes", f"{_f(act.mean, 1e6)} um" if act else "-"),
        ("eq.7 max, axes", f"{_f(act.max, 1e6)} um" if act else "-"),
        ("worst turn, axes", f"{_f(act.turn_max_pct, decimals=4)} % of wire" if act else "-"),
    ]
    rows += _wound_rows(a.as_wound)
    for name, m in a.axes.items():
        u = m.unit
        rows += [
            (f"{name}: steps moved", str(m.steps_moved)),
            (f"{name}: peak v cmd | axis", f"{_g(m.cmd_v)} | {_g(m.act_v)} {u}/s"),
            (f"{name}: peak a cmd | axis", f"{_g(m.cmd_a)} | {_g(m.act_a)} {u}/s^2"),
            (f"{name}: peak jerk cmd | axis", f"{_g(m.cmd_j)} | {_g(m.act_j)} {u}/s^3"),
            (f"{name}: tracking max | rms", f"{_f(m.track_max_steps)} | {_f(m.track_rms_steps)} steps"),
            (f"{name}: final error", f"{_f(m.final_error_steps)} steps ({m.net_slips} pitches)"),
        ]
    return rows


def _wire_rows(w: dict[str, Any]) -> list[tuple[str, str]]:
    """The wire: its tension in one row; what the supply paid out, how far it
    was stretched and its faults where there are any."""
    if not w:
        return [("wire tension", "-")]
    rows = [
        (
            "wire tension",
            f"{w['tension_min_n']:.4g}..{w['tension_max_n']:.4g} N (set {w['tension_set_n']:.4g} N), "
            f"{w['outside_alarm_s']:.3f} s outside the alarm band",
        )
    ]
    paid = w.get("paid_out_m")
    rows.append(("wire paid out", f"{paid:.4g} m" if paid is not None else "-"))
    stretched = [lay for lay in w.get("layers", []) if lay["stretch"] > 0]
    worst = max(stretched, key=lambda lay: lay["stretch"], default=None)
    said = "none"
    if worst:
        said = (
            f"in {len(stretched)} of {len(w['layers'])} layers, most {100 * worst['stretch']:.3g} % in coil "
            f"{worst['coil']} layer {worst['layer']} (resistance +{100 * worst['resistance_rise']:.3g} %)"
        )
    rows.append(("wire stretched", said))
    rows += [(f"wire {kind}", _fault_text(w[kind]) if w.get(kind) else "none") for kind in ("break", "slip")]
    return rows


def _fault_text(f: dict[str, Any]) -> str:
    """Where and when a wire fault happened, as far as its status says."""
    where = [f"{k} {f[k]}" for k in ("coil", "layer", "turn") if f.get(k) is not None]
    when = [f"at {f['t_s']:.3f} s"] if f.get("t_s") is not None else []
    return " ".join(where + when) or "where not recorded (see its ERROR below)"


def _wound_rows(w: dict[str, Any]) -> list[tuple[str, str]]:
    """The coil as wound, in three rows (winder.analysis.wound)."""
    if not w:
        return [("as wound", "- (no joint samples)")]
    per_coil = w["turns_per_layer"]
    same = all(c == per_coil[0] for c in per_coil)
    laid = f"{'/'.join(map(str, per_coil[0]))} per layer" + (
        f", each of {len(per_coil)} coils" if same else f" in coil 1 ({len(per_coil)} coils differ)"
    )
    errors = [lay["max_axial_error_m"] for lay in w["layers"] if lay["max_axial_error_m"] is not None]
    worst = max(errors) if errors else math.nan
    defects = w["defects"]
    if defects:
        from winder.analysis.wound import DEFECT_KINDS

        kinds = {k: sum(1 for x in defects if x["kind"] == k) for k in DEFECT_KINDS}
        first = defects[0]
        said = ", ".join(f"{n} {k}" for k, n in kinds.items() if n)
        found = (
            f"{len(defects)} ({said}); first: {first['kind']} at coil {first['coil']} layer "
            f"{first['layer']} turn {first['turn']}, {first['t_s']:.2f} s"
        )
    else:
        found = f"none (tolerance {w['tolerance_m'] * 1e3:g} mm)"
    return [
        ("as wound: turns laid", laid),
        ("as wound: max axial error", f"{_f(worst, 1e3, decimals=4)} mm"),
        ("as wound: defects", found),
    ]


#: the set-up rows of the table and the :func:`setup` keys each shows ("x." for
#: every key under x); several runs side by side, rows whose keys differ are marked
SETUP_ROWS: dict[str, tuple[str, ...]] = {
    "job id": ("job_id",),
    "job": ("job",),
    "re-simulation of": ("source",),
    "profile / motor model": ("profile", "shaper", "model"),
    "ramp limits (major axis)": ("ramp.",),
    **{f"{ax}: motor J, D": (f"{ax}.J", f"{ax}.D", f"{ax}.load_torque") for ax in AXES},
    **{
        f"{ax}: motor Zr, L, i_a": (f"{ax}.Zr", f"{ax}.L", f"{ax}.i_a", f"{ax}.motor_step_angle")
        for ax in AXES
    },
    "joint-state rate": ("publish_rate",),
    "bag compression": ("compression",),
}


#: rows left out of the table where every run says "none"
TOLD_IF_ANY = ("part", "programmed stops", "operator commands", "wire stretched", "wire break", "wire slip")


def _shows(row: str, key: str) -> bool:
    return any(key == k or (k.endswith(".") and key.startswith(k)) for k in SETUP_ROWS.get(row, ()))


def format_table(analyses: list[Analysis]) -> str:
    """One readable table, one column per run; with several runs, the set-up
    rows (job, ramp, motors, rates) in which they differ are marked ``*``."""
    cols = [_rows(a) for a in analyses]
    # the stops, the commands and the wire's faults are told when a run had any
    told = {n for c in cols for n, v in c if n in TOLD_IF_ANY and v != "none"}
    cols = [[(n, v) for n, v in c if n in told or n not in TOLD_IF_ANY] for c in cols]
    # runs side by side may not have the same rows (one without joint samples has one "as
    # wound" row, not three): every row any run has, in the order they come, "-" where a run has none
    names = list(dict.fromkeys(n for c in cols for n, _ in c))
    values = [dict(c) for c in cols]
    header = ["", *[a.label for a in analyses]]
    body = [[n, *[v.get(n, "-") for v in values]] for n in names]
    differs = setup_differences(analyses)
    if len(analyses) > 1:
        for r in body:
            mark = any(_shows(r[0], k) for k in differs)
            r[0] = ("* " if mark else "  ") + r[0]
    widths = [max(len(r[i]) for r in [header, *body]) for i in range(len(header))]
    lines = ["  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)).rstrip()]
    lines.append("  ".join("-" * w for w in widths))
    for r in body:
        lines.append("  ".join(v.ljust(w) for v, w in zip(r, widths, strict=True)).rstrip())
    if differs:
        lines.append("* the runs differ in this setting")
    for a in analyses:
        who = f" ({a.label})" if len(analyses) > 1 else ""
        for n in a.notes:
            lines.append(f"note{who}: {n}")
        for e in a.error_list:
            lines.append(f"ERROR{who} {e}")
    return "\n".join(lines)
