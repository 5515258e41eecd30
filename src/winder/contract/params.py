"""The settings of the three nodes, ROS-free: one table per node and one check
per node for the cross-field rules. The nodes declare their ROS parameters
from these tables, and ``winder run`` checks the same values before it starts
anything, so a value is judged the same way wherever it is typed.
"""

from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from winder.contract.files import NAME_MAX, too_long_name
from winder.contract.stream import RUN_FACTS, STOP_PAUSE_RANGE
from winder.contract.topics import check_node_name, check_relative_name, check_service_name
from winder.motion.axes import AXES, FEED, FORK, POLE
from winder.motion.job import FIELD_SPECS, MAX_STEP_RATE, Job, Segment
from winder.motion.limits import NO_LIMIT
from winder.motion.profile import KINDS
from winder.motion.timeline import OVERRIDE_RANGE
from winder.motion.timing import MAX_JOB_SECONDS, plan_job_timing, plan_segment
from winder.spec import Spec, SpecError, shorten
from winder.tension.tensioner import TENSIONER_SPECS

__all__ = [
    "CONSUMER_SPECS",
    "INTERP_SPECS",
    "MANAGED",
    "MOTOR_FIELDS",
    "OPERATION_SPECS",
    "PARTS_DB_NONE",
    "PROFILE_KINDS",
    "PROFILE_SPECS",
    "RAMP_SOURCES",
    "SIM_SPECS",
    "UNSHAPED",
    "bag_directory",
    "check_consumer",
    "check_interp",
    "check_job_duration",
    "check_profile",
    "check_sim",
    "run_ramp",
    "stop_place",
    "stop_points",
]


#: the values of a consumer's ``parts_db`` that keep no part index (``""``: the first phase's "none")
PARTS_DB_NONE = ("none", "")


def _table(*specs: Spec) -> dict[str, Spec]:
    return {s.name: s for s in specs}


#: Both ends of the stream give up on a job that stopped moving: the sim node
#: closes it incomplete (bag closed, final report), the interp node stops
#: sending it, so the next job can run (a node died or was restarted).
STALL_ABORT = Spec(
    "stall_abort",
    float,
    30.0,
    "wall time without progress after which the running job is closed incomplete",
    "s",
    0.1,
    86400.0,
)

#: the setting every winder node has besides its table: ``ManagedNode``'s, read-only (given at start)
MANAGED = Spec(
    "managed",
    bool,
    False,
    "wait, unconfigured, for an orchestrator's configure and activate (lifecycle); "
    "false: configure and activate at start",
)

INTERP_SPECS = {
    **FIELD_SPECS,
    **_table(
        Spec("autostart", bool, True, "start the job as soon as the step stream has a reader"),
        Spec("chunk_steps", int, 8192, "steps per winder/steps message", "", 1, 1 << 20),
        Spec(
            "max_in_flight",
            int,
            1 << 20,
            "steps sent but not yet simulated, at most (when a sim node reports progress)",
            "steps",
            1,
            1 << 30,
        ),
        STALL_ABORT,
    ),
}

PROFILE_KINDS = KINDS
#: the profile node's input shapers: none, or one of winder.shaping.KINDS
SHAPER_CHOICES = ("none", "zv", "mzv", "zvd", "ei", "2hump_ei")
PROFILE_SPECS = _table(
    Spec("profile", str, "scurve", "velocity ramp of every segment", choices=PROFILE_KINDS),
    Spec(
        "v_max",
        float,
        2048.0,
        "peak step rate of the major axis",
        "steps/s",
        0.0,
        MAX_STEP_RATE,
        low_open=True,
    ),
    Spec(
        "a_max",
        float,
        8192.0,
        "acceleration limit (scurve, trapezoid)",
        "steps/s^2",
        0.0,
        1e10,
        low_open=True,
    ),
    Spec("j_max", float, 65536.0, "jerk limit (scurve)", "steps/s^3", 0.0, 1e14, low_open=True),
    Spec("tau", float, 0.1, "time constant of the exponential ramp", "s", 0.0, 100.0, low_open=True),
    Spec(
        "v_start",
        float,
        0.0,
        "start/stop step rate: every segment starts and ends at it",
        "steps/s",
        0.0,
        1e7,
    ),
    Spec("dwell", float, 0.0, "pause between segments", "s", 0.0, 3600.0),
    Spec(
        "shaper",
        str,
        "none",
        "input shaper of every move's time law (winder.shaping): the steps stay where they are, their "
        "times avoid exciting the resonance shaper_freq; the move lasts the shaper's duration longer",
        choices=SHAPER_CHOICES,
    ),
    Spec(
        "shaper_freq",
        float,
        44.5,
        "resonance the shaper is designed for (default: the paper motor's w_n = 279 rad/s)",
        "Hz",
        0.0,
        10000.0,
        low_open=True,
    ),
    Spec(
        "shaper_damping",
        float,
        0.52,
        "damping ratio of that resonance (default: the paper motor's)",
        "",
        0.0,
        0.95,
    ),
)

#: The shaper settings of an unshaped ramp: what a ramp written before
#: shapers existed (a job description, a job file, a bag) means.
UNSHAPED = {name: PROFILE_SPECS[name].default for name in ("shaper", "shaper_freq", "shaper_damping")}

#: The profile node's operation settings, beside its ramp: they act on a run
#: while it goes on and never travel with a job.
OPERATION_SPECS = _table(
    Spec(
        "feed_override",
        float,
        1.0,
        "scales v_max of the running job (and the next ones) from the moment it is set, with a "
        "jerk-limited change of speed (a CNC's feed override)",
        "",
        *OVERRIDE_RANGE,
    ),
    Spec(
        "lookahead",
        float,
        0.05,
        "in real-time runs, how far ahead of the axes' clock steps are timed and sent: a pause, "
        "abort or override takes effect within it",
        "s",
        0.001,
        10.0,
    ),
)

#: Per-axis motor settings of the sim node: ``<axis>.<field>``. Defaults: the
#: 2012 paper's motor, 1/32 microstep of its 2.25 deg full step.
MOTOR_FIELDS = _table(
    Spec("Zr", float, 40.0, "rotor teeth", "", 1.0, 1000.0),
    Spec("L", float, 0.01005, "phase inductance", "H", 0.0, 10.0, low_open=True),
    Spec("i_a", float, 1.0, "phase current", "A", 0.0, 100.0, low_open=True),
    Spec("J", float, 1.05 * 9.80665e-5, "rotor + load inertia", "kg m^2", 0.0, 100.0, low_open=True),
    Spec("D", float, 0.03, "viscous damping", "N m s/rad", 0.0, 100.0),
    Spec(
        "motor_step_angle",
        float,
        2 * math.pi / 5120,
        "motor angle per commanded step",
        "rad",
        0.0,
        1.0,
        low_open=True,
    ),
    Spec("load_torque", float, 0.0, "constant load torque (nonlinear model)", "N m", -100.0, 100.0),
)

#: MCAP chunk compressions of the sim node's bags (see winder.record.bag).
BAG_COMPRESSIONS = ("zstd", "lz4", "none")

#: The settings every step consumer has (winder.ros.consumer.StepConsumer):
#: recording and the stall watch.
CONSUMER_SPECS = _table(
    Spec("bag_dir", str, "bags", "directory for recordings", pattern=r".+", pattern_text="a directory path"),
    Spec("record", bool, True, "record each job into an MCAP bag"),
    Spec(
        "bag_compression",
        str,
        "lz4",
        "MCAP chunk compression of the bag (lz4: fast, about a third of the size; zstd: a tenth, "
        "at twice the CPU)",
        choices=BAG_COMPRESSIONS,
    ),
    Spec("stall_timeout", float, 2.0, "wall time without steps before a stall is reported", "s", 0.1, 3600.0),
    STALL_ABORT,
    Spec(
        "parts_db",
        str,
        "auto",
        "the part index each run adds its part to (SQLite, docs/PARTS.md): auto, <bag_dir>/parts.sqlite "
        "when recording; none (or ''), no index; else this file",
    ),
)

SIM_SPECS = {
    **_table(
        Spec("model", str, "linear", "motor model", choices=("linear", "nonlinear")),
        Spec("publish_rate", float, 200.0, "joint state rate", "Hz of simulated time", 1.0, 1e5),
        Spec("real_time", bool, False, "pace simulated time to the wall clock"),
        Spec(
            "real_time_factor", float, 1.0, "simulated seconds per wall second when real_time", "", 1e-3, 1e3
        ),
        Spec("settle_time", float, 0.05, "simulated time after the last step", "s", 0.0, 60.0),
    ),
    **CONSUMER_SPECS,
    **{
        f"{axis}.{name}": Spec(
            f"{axis}.{name}",
            s.kind,
            s.default,
            f"{axis} axis: {s.description}",
            s.unit,
            s.low,
            s.high,
            s.low_open,
        )
        for axis in AXES
        for name, s in MOTOR_FIELDS.items()
    },
    # the tensioner and the free span (winder.tension): `winder check` predicts each
    # layer's tension with them
    **TENSIONER_SPECS,
    # faults of the wire, injected for tests and operator training (winder.tension.watch catches them)
    **_table(
        Spec(
            "wire_check",
            bool,
            True,
            "refuse, as a run starts, a job whose wire would not hold (winder check's words); false: "
            "wind it and let the simulated wire show what happens (training, tests)",
        ),
        Spec(
            "fault.wire_break_turn",
            int,
            0,
            "the wire breaks as the flyer starts this turn of the job (counted from 1 over its coils; "
            "0: never)",
            "",
            0,
            10**9,
        ),
        Spec(
            "fault.slip_turn",
            int,
            0,
            "the supply's counter slips over this turn of the job (from 1; 0: never)",
            "",
            0,
            10**9,
        ),
        Spec(
            "fault.slip_length",
            float,
            0.02,
            "how much wire the counter misses over the slipping turn",
            "m",
            0.0,
            100.0,
            True,
        ),
    ),
}


#: Where a run's ramp comes from: the profile node's own settings, or the
#: interp node's ``ramp.*`` settings, carried with the job (one node holds the
#: whole set-up of a run, and one call sets it and starts it: ``~/start_run``).
RAMP_SOURCES = ("profile_node", "job")

#: a list of programmed stops: ``coil:turn`` pairs, comma-separated
STOPS_PATTERN = r"^\s*(\d+\s*:\s*\d+\s*(,\s*\d+\s*:\s*\d+\s*)*)?$"

INTERP_SPECS.update(
    {
        "stops": Spec(
            "stops",
            str,
            "",
            "programmed stops: the axes come to rest after turn T of coil C (counted over the coil's "
            "layers, from 1), rest stop_pause seconds and go on",
            pattern=STOPS_PATTERN,
            pattern_text='coil:turn pairs separated by commas ("1:40,3:10"), or empty',
        ),
        "stop_pause": Spec(
            "stop_pause",
            float,
            1.0,
            "simulated time the axes rest at each programmed stop before the job goes on",
            "s",
            *STOP_PAUSE_RANGE,
        ),
        "stop_resume": Spec(
            "stop_resume",
            str,
            "auto",
            "how the job goes on after a programmed stop: auto (after stop_pause) or call (on the "
            "profile node's ~/resume, then after stop_pause)",
            choices=("auto", "call"),
        ),
        "schedule": Spec(
            "schedule",
            str,
            "",
            "operator commands at simulated times since the run's start, for scripts and tests: "
            "pause@S, resume@S, abort@S, override@S=FACTOR, comma-separated (live: the profile "
            "node's ~/pause, ~/resume, ~/abort and feed_override)",
            pattern=r"^[a-z0-9@=.,\s]*$",
            pattern_text='commands such as "pause@1.5,resume@3,override@4=0.5", or empty',
        ),
        "job_file": Spec(
            "job_file",
            str,
            "",
            "a job file (see winder.contract.jobfile): setting it sets the job from its interp_node "
            "section and the ramp the run brings from its profile_node section",
            pattern=r"^[^\x00]*$",
            pattern_text="a file path, or empty",
        ),
        "job_file_sha256": Spec(
            "job_file_sha256",
            str,
            "",
            "sha256 of the job file's bytes the job comes from (set with job_file, and by winder run): "
            "carried in the job description into the run's bag; a change of the job's fields without "
            "a job file clears it",
            pattern=r"([0-9a-f]{64})?",
            pattern_text="64 lower-case hex digits, or empty",
        ),
        # who runs the cell and the wire's lot: the run's, never the job's (a job file cannot give them)
        **RUN_FACTS,
        "ramp.source": Spec(
            "ramp.source",
            str,
            "profile_node",
            "where a run's ramp comes from: the profile node's settings, or the ramp.* settings here, "
            "carried with the job",
            choices=RAMP_SOURCES,
        ),
        **{
            f"ramp.{name}": Spec(
                f"ramp.{name}",
                s.kind,
                s.default,
                f"ramp carried with the job (ramp.source job): {s.description}",
                s.unit,
                s.low,
                s.high,
                s.low_open,
                choices=s.choices,
            )
            for name, s in PROFILE_SPECS.items()
        },
    }
)


def run_ramp(values: dict[str, Any]) -> dict[str, Any] | None:
    """The ramp the interp node's settings carry with a job, or None when the
    profile node's own settings ramp it (``ramp.source``)."""
    if values.get("ramp.source", "profile_node") != "job":
        return None
    return {name: values[f"ramp.{name}"] for name in PROFILE_SPECS}


def stop_points(job: Job, text: str) -> list[tuple[int, int]]:
    """The programmed stops ``text`` (``"coil:turn,..."``) of ``job`` as
    (segment, step index) pairs, sorted: the axes come to rest after step k of
    layer segment s, exactly where the fork completes the turn. Answered by
    the job's segments (:class:`winder.motion.job.Segment`: the layer that
    holds the coil's turn, and where in it the turn ends). SpecError (one
    line) for a coil or turn the job does not have, a stop given twice, or a
    stop inside a layer whose major axis is not the fork (its turns do not
    fall on step indices)."""
    out: list[tuple[int, int]] = []
    items = [t for t in text.replace(" ", "").split(",") if t]
    if not items:
        return []
    layers_of: dict[int, list[Segment]] = {}  # per coil (from 0), its layer segments in order
    for s in job.segments():
        if s.kind.winds:
            layers_of.setdefault(s.pole, []).append(s)
    seen: dict[tuple[int, int], str] = {}
    for item in items:
        try:
            coil, turn = (int(x) for x in item.split(":"))
        except ValueError:
            raise SpecError(
                f"stops={shorten(text)} is invalid: {shorten(item)} must be COIL:TURN (two whole numbers)"
            ) from None
        if not 1 <= coil <= job.poles:
            raise SpecError(
                f"stops={shorten(text)} is invalid: coil {coil} is not in [1, {job.poles}] (poles)"
            )
        wound = job.coil(coil - 1)
        layers = layers_of.get(coil - 1, [])
        per_coil = layers[-1].last_turn if layers else 0
        if not 1 <= turn <= per_coil:
            raise SpecError(
                f"stops={shorten(text)} is invalid: turn {turn} of coil {coil} is not in [1, {per_coil}] "
                f"({wound.layers} layers of {wound.turns_per_layer} turns)"
            )
        if (coil, turn) in seen:
            raise SpecError(
                f"stops={shorten(text)} is invalid: {coil}:{turn} is given twice ({seen[coil, turn]} and "
                f"{item}); each stop once"
            )
        seen[coil, turn] = item
        seg = next(s for s in layers if s.first_turn < turn <= s.last_turn)
        within = turn - seg.first_turn  # the turn within its layer, from 1
        if within < seg.turns and not seg.stops_inside:
            raise SpecError(
                f"stops={shorten(text)} is invalid: turn {turn} ends inside a layer whose feed steps "
                f"({abs(seg.delta[FEED.index])}) outnumber its fork steps: stop at a layer's end instead"
            )
        # a turn's end; the layer's last: its end (its last step, whichever axis leads, after the dwell)
        out.append((seg.index, seg.turn_end(within)))
    return sorted(out)


def interp_setting(item: str, where: str) -> tuple[str, Any]:
    """One ``KEY=VALUE`` setting of the interp node for a run (``winder ctl
    start --set``, a Wind goal's ``overrides``): its name and its value,
    parsed and checked by its spec; SpecError naming ``where`` otherwise."""
    key, eq, text = item.partition("=")
    key = key.strip()
    if not eq or not key:
        raise SpecError(f"{where} {item!r} is invalid: must be key=value ({where} turns_per_layer=40)")
    spec = INTERP_SPECS.get(key)
    if spec is None or key == "job_file_sha256":
        raise SpecError(
            f"{where} {key}: the interp node has no setting {key!r} (winder run --help and "
            "winder ctl param list interp_node name them; the ramp is ramp.profile, ramp.v_max, ...)"
        )
    return key, spec.parse(text)  # SpecError: "turns_per_layer='0' is invalid: must be ... in [1, ...]"


def stop_place(job: Job, segment: Segment, k: int) -> tuple[int, int, int]:
    """(coil, layer, turn), from 1, of a programmed stop after step ``k`` of
    the layer ``segment``: the inverse of :func:`stop_points` (the turn is
    counted over the coil's layers: :meth:`Segment.turn_at`). ``job``: the
    segment's (kept for the callers; the segment knows its turns)."""
    return segment.pole + 1, segment.layer + 1, segment.turn_at(k)


def check_interp(values: dict[str, Any], *, check_fit: bool = True, job: Job | None = None) -> None:
    """Cross-field check of the interp node's settings (SpecError): the job
    (its coils fit their window, unless ``check_fit`` is False: a job that
    does not fit is then not laid out, and its stops and length are not
    checked), its stops, schedule (:func:`winder.motion.timeline.check_schedule`),
    ramp and length. ``job``: the job of ``values``, made already (``winder
    run --check``). The node's ``job_file`` is checked by
    :func:`winder.contract.jobfile.check_interp_settings`, which reads it."""
    if job is None:
        job = Job.from_dict({k: v for k, v in values.items() if k in FIELD_SPECS}, check_fit=check_fit)
    if values.get("schedule"):
        from winder.motion.timeline import check_schedule

        check_schedule(values["schedule"])
    ramp = run_ramp(values)
    if ramp is not None:
        check_profile(ramp)
    if not job.winding.fits:  # check_fit=False (winder check): not laid out, refused for its fit later
        return
    if values.get("stops"):
        stop_points(job, values["stops"])
    check_job_duration(job, values)


def check_job_duration(job: Job, values: dict[str, Any]) -> None:
    """SpecError (one line) if ``job`` would last longer than a job may
    (:data:`MAX_JOB_SECONDS`), as ``winder run --check`` refuses it: timed
    with the ramp the interp node's settings carry (``ramp.source`` job),
    exactly as the profile node will time it; with the profile node's own
    ramp, which the interp node does not know, at the fastest any profile
    node takes (every major-axis step at the highest ``v_max``), a bound no
    ramp beats. The interp node applies it at start and to every change
    (``~/start_run`` included), so it never starts a job no cell can run."""
    segments = job.segments()
    steps = [s.steps for s in segments]
    stops = stop_points(job, values["stops"]) if values.get("stops") else []
    pause = float(values.get("stop_pause", 0.0))
    ramp = run_ramp(values)
    if ramp is not None:
        try:
            plan_job_timing(ramp, job, stops, pause)
        except ValueError as exc:
            raise SpecError(f"job {job.job_id} ({job.total_steps} steps) is too long: {exc}") from None
        return
    top = float(PROFILE_SPECS["v_max"].high or math.inf)
    fastest = sum(n / (top * job.segment_speed(s)) for n, s in zip(steps, segments, strict=True))
    fastest += len(stops) * pause
    if fastest > MAX_JOB_SECONDS:
        raise SpecError(
            f"job {job.job_id} ({job.total_steps} steps) is too long: even at the highest v_max a profile "
            f"node takes ({top:g} steps/s) it lasts {fastest:.4g} s, more than a job may last "
            f"({MAX_JOB_SECONDS:g} s); wind fewer turns_per_layer, layers or poles per job"
        )


def check_profile(values: dict[str, Any]) -> None:
    """Cross-field check: the limits must make a plannable move."""
    try:
        plan_segment(values, 1000)
    except ValueError as exc:
        raise SpecError(str(exc)) from None


#: the longest path the system takes (Linux PATH_MAX, the terminating NUL counted)
PATH_MAX = 4095
#: how much deeper than ``bag_dir`` a bag's files go, at most: its staging name
#: ``.<run id>.opening-<pid>`` (a run id: a job_id of up to 64 characters, a
#: date, a counter) and a file in it (``<run id>_0.mcap``, ``metadata.yaml``)
BAG_NAME_ROOM = 256


def bag_directory(text: str) -> Path:
    """``bag_dir`` as an absolute path (``~`` expanded, symlinks resolved);
    SpecError (one line) unless it is a directory this process can write
    into, or one it can create. Checked by writing: a probe directory is made
    and removed in it (or in its nearest existing parent), which also catches
    read-only mounts and pseudo file systems such as /proc."""
    shown = shorten(text, 200)  # a path is shown whole up to a few lines' worth
    try:
        path = Path(text).expanduser().resolve()
    except (OSError, RuntimeError) as exc:  # a symlink loop, an unreadable link
        raise SpecError(f"bag_dir={shown} is invalid: {exc}") from None
    if too_long_name(path) is not None:
        raise SpecError(
            f"bag_dir={shown} is invalid: a name in it is longer than {NAME_MAX} bytes, the most a "
            "file system takes"
        )
    deepest = len(os.fsencode(path)) + BAG_NAME_ROOM
    if deepest > PATH_MAX:
        raise SpecError(
            f"bag_dir={shown} is invalid: {len(os.fsencode(path))} bytes long, at most "
            f"{PATH_MAX - BAG_NAME_ROOM}: a bag's files go up to {BAG_NAME_ROOM} bytes deeper, and the "
            f"system takes paths of up to {PATH_MAX}"
        )
    try:
        probe = path
        while not probe.exists() and probe != probe.parent:
            probe = probe.parent
        if probe != path:  # the rest is made later: each name in it must be one the system takes
            os.stat(path)
    except FileNotFoundError:
        pass
    except OSError as exc:  # a name longer than the file system takes
        raise SpecError(f"bag_dir={shown} is invalid: {exc.strerror or exc}") from None
    if not probe.is_dir():
        raise SpecError(f"bag_dir={shown} is invalid: {probe} is not a directory")
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".winder-probe-", dir=probe))
    except OSError as exc:
        raise SpecError(f"bag_dir={shown} is invalid: cannot write in {probe} ({exc.strerror})") from None
    return path


def check_consumer(values: dict[str, Any]) -> None:
    """Cross-field check of every consumer: the bag directory must be
    writable when recording; a part index named by its path must be a file
    in a directory (the index itself is created by the first run)."""
    if values["record"]:
        bag_directory(values["bag_dir"])
    parts_db = values.get("parts_db", "auto")
    if parts_db not in (*PARTS_DB_NONE, "auto"):
        path = Path(parts_db).expanduser()
        if path.is_dir():
            raise SpecError(f"parts_db={shorten(parts_db)} is invalid: it is a directory, not a file")
        if not path.parent.is_dir():
            raise SpecError(f"parts_db={shorten(parts_db)} is invalid: {path.parent} is not a directory")


def check_sim(values: dict[str, Any]) -> None:
    """Cross-field check: each axis must be a valid motor; the bag directory
    must be writable when recording."""
    from winder.axis import StepperAxis

    check_consumer(values)

    for axis in AXES:
        try:
            StepperAxis(**{k: values[f"{axis}.{k}"] for k in ("Zr", "L", "i_a", "J", "D")})
        except ValueError as exc:
            raise SpecError(f"{axis} axis: {exc}") from None


# -- the ros2_control bridge (winder_bridge) ----------------------------------------------


@dataclass(frozen=True)
class _NamesSpec(Spec):
    """A setting that is a list of names (a ROS string array parameter):
    non-empty, each name non-empty and without blanks, no name twice, each
    one of ``choices`` if given. ``kind`` stays ``str`` (the parameter is
    declared with dynamic typing, so it holds the string array it is given)."""

    def range_text(self) -> str:
        each = f"one of {', '.join(self.choices)}" if self.choices else "a name without blanks"
        return f"a list of distinct names (string array), each {each}"

    def check(self, value: Any) -> Any:
        must = f"must be {self.range_text()}"
        if isinstance(value, str) or not isinstance(value, (list, tuple)) or not value:
            raise SpecError(f"{self.name}={value!r} is invalid: {must}")
        seen: set[str] = set()
        for item in value:
            if not isinstance(item, str) or not item or any(c.isspace() for c in item):
                why = f"{item!r} is no name"
            elif self.choices and item not in self.choices:
                why = f"{item!r} is not one of {', '.join(self.choices)}"
            elif item in seen:
                why = f"{item!r} is given twice"
            else:
                seen.add(item)
                continue
            raise SpecError(f"{self.name}={list(value)!r} is invalid: {why}; {must}")
        return list(value)

    def parse(self, text: str) -> Any:
        """Comma-separated names, as typed on a command line."""
        return self.check([t.strip() for t in text.split(",")] if text.strip() else [])


#: The unit, default and largest value of each axis' following-error limit
#: (winder.motion.job: feed in m, fork and pole in rad).
_FOLLOWING_ERROR = {
    "feed": (FEED.unit, 1e-3, 1.0),
    "fork": (FORK.unit, 0.2, 100.0),
    "pole": (POLE.unit, 0.05, 100.0),
}

#: The settings of the ros2_control bridge (winder_bridge's bridge_node): the
#: consumer's, and how it drives a forward_command_controller and watches the
#: joint states. Read when a run starts; a change applies from the next run.
BRIDGE_SPECS = {
    **_table(
        Spec(
            "rate", float, 1000.0, "rate of the position commands sent to the controller", "Hz", 10.0, 10000.0
        ),
        Spec(
            "controller",
            str,
            "forward_position_controller",
            "the forward_command_controller/ForwardCommandController the commands go to: topic "
            "<controller>/commands, relative to this node's namespace (the controller manager's)",
            pattern=r"[A-Za-z][A-Za-z0-9_]*",
            pattern_text="a controller name (letters, digits and _, starting with a letter)",
        ),
        Spec(
            "broadcaster",
            str,
            "joint_state_broadcaster",
            "the node whose joint_states the bridge trusts (ros2_control's joint_state_broadcaster): its "
            "name in this node's namespace, or its full name /ns/name; joint states from any other "
            "publisher are ignored, counted and warned about once",
            pattern=r"/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*",
            pattern_text="a node name, or its full name /ns/name (letters, digits and _)",
        ),
        Spec(
            "load_cell",
            str,
            "",
            "the force_torque_sensor_broadcaster of the wire's load cell (force.x = the tension, N): its "
            "controller name; the bridge watches <load_cell>/wrench, relative to this node's namespace, "
            "trusting only that node's messages, and a wire break stops the run. Empty: no load cell",
            pattern=r"([A-Za-z][A-Za-z0-9_]*)?",
            pattern_text="empty (no load cell), or a controller name (letters, digits and _, starting with a "
            "letter)",
        ),
        Spec(
            "interface",
            str,
            "forward",
            "how the positions go to ros2_control: forward = a std_msgs/Float64MultiArray on "
            "<controller>/commands at rate Hz (forward_command_controller/ForwardCommandController); "
            "trajectory = a trajectory_msgs/JointTrajectory on <controller>/joint_trajectory every batch "
            "seconds, a point every 1/rate s for the next four batches "
            "(joint_trajectory_controller/JointTrajectoryController)",
            choices=("forward", "trajectory"),
        ),
        Spec(
            "batch",
            float,
            0.02,
            "interface trajectory: how often a trajectory goes out (each holds the points of the next four "
            "batches, so a tick up to three batches late costs nothing)",
            "s",
            0.001,
            1.0,
        ),
        _NamesSpec(
            "joints",
            str,
            list(AXES),
            "the controller's joints, in its order: each command holds their positions in that order",
        ),
        _NamesSpec(
            "axes",
            str,
            list(AXES),
            "the cell axis each of joints drives (same length as joints, every axis once)",
            choices=AXES,
        ),
        Spec(
            "job_origin",
            str,
            "zero",
            "where a job's step 0 is: zero = joint position 0 (commands are steps times step length; a "
            "run starts only with the joints at the job's start); start_position = where the joints are "
            "measured when the run starts (commands are that plus the steps since the start times step "
            "length)",
            choices=("zero", "start_position"),
        ),
        Spec(
            "joint_state_timeout",
            float,
            0.1,
            "a run without a measured position of a joint (joint_states) for this long is a servo fault",
            "s",
            0.005,
            10.0,
        ),
        Spec(
            "command_delay",
            float,
            0.02,
            "how long a command takes to show in the measured position (transport both ways, the "
            "controller manager's cycle, the drive's dead time): a measured position among the positions "
            "commanded over this stretch before its stamp has no following error",
            "s",
            0.0,
            1.0,
        ),
        Spec(
            "settle_time",
            float,
            0.2,
            "after the last step, the final position is commanded (and watched) this long before the run "
            "closes",
            "s",
            0.0,
            60.0,
        ),
    ),
    **{
        f"max_following_error.{axis}": Spec(
            f"max_following_error.{axis}",
            float,
            _FOLLOWING_ERROR[axis][1],
            f"{axis} axis: the largest following error (how far the measured position is from the "
            "positions commanded over command_delay before its stamp) before the run stops with a servo "
            "fault",
            _FOLLOWING_ERROR[axis][0],
            0.0,
            _FOLLOWING_ERROR[axis][2],
            low_open=True,
        )
        for axis in AXES
    },
    **{
        f"{side}_position.{axis}": Spec(
            f"{side}_position.{axis}",
            float,
            sign * NO_LIMIT,
            f"{axis} axis: soft limit, the {'lowest' if side == 'min' else 'highest'} position a run may "
            f"command (the joint's position, {unit}); a run whose job would pass it is refused before its "
            f"first command. {sign * NO_LIMIT:g} = none",
            unit,
            -NO_LIMIT,
            NO_LIMIT,
        )
        for axis in AXES
        for side, sign in (("min", -1.0), ("max", 1.0))
        for unit in (_FOLLOWING_ERROR[axis][0],)
    },
    **{
        f"max_{kind}.{axis}": Spec(
            f"max_{kind}.{axis}",
            float,
            NO_LIMIT,
            f"{axis} axis: the highest {kind} a run may command ({unit}); a job that would pass it is "
            f"refused before its first command, and steps that would pass it stop the run before they are "
            f"due (measured over 20 ms). {NO_LIMIT:g} = none",
            unit,
            0.0,
            NO_LIMIT,
            low_open=True,
        )
        for axis in AXES
        for kind, unit in (
            ("velocity", f"{_FOLLOWING_ERROR[axis][0]}/s"),
            ("acceleration", f"{_FOLLOWING_ERROR[axis][0]}/s^2"),
        )
    },
    **_table(
        Spec(
            "require_homing",
            bool,
            False,
            "a run is refused until the axes are homed (~/home) since the node started or since the "
            "broadcaster was last lost; without it the broadcaster's positions are taken as absolute",
        ),
        Spec(
            "homing_service",
            str,
            "",
            "the std_srvs/Trigger service ~/home calls to home the axes (relative to this node's namespace, "
            "or /full/name); empty: the axes are referenced where they stand (absolute encoders)",
            pattern=r"(/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*)?",
            pattern_text="a service name, or empty",
        ),
        Spec(
            "homing_timeout",
            float,
            120.0,
            "how long ~/home waits for homing_service to answer before it says homing failed (the axes "
            "stay unhomed)",
            "s",
            0.0,
            3600.0,
            low_open=True,
        ),
    ),
    **CONSUMER_SPECS,
}


#: the topics a bridge's ``controller`` names (relative to the bridge's namespace)
CONTROLLER_TOPICS = ("/commands", "/joint_trajectory")


def check_bridge(values: dict[str, Any], namespace: str | None = None) -> None:
    """Cross-field check of the bridge: ``joints`` and ``axes`` pair up one to
    one and name every axis of the cell once; the bag directory must be
    writable when recording; with the bridge node's ``namespace``, the
    topics ``controller`` names are names ROS takes there
    (:func:`winder.contract.topics.check_relative_name`: a 300-character
    controller ended the node in rcl), and so is ``homing_service``
    (:func:`winder.contract.topics.check_service_name`: a 250-character one
    was taken, and ``~/home`` then failed in rcl)."""
    if namespace is not None:
        try:
            check_relative_name("controller", values["controller"], namespace, CONTROLLER_TOPICS)
            if "broadcaster" in values:
                check_node_name(values["broadcaster"], namespace, "broadcaster")
            if values.get("homing_service"):
                check_service_name("homing_service", values["homing_service"], namespace)
        except ValueError as exc:
            raise SpecError(str(exc)) from None
    check_consumer(values)
    if values.get("interface") == "trajectory" and values["batch"] * values["rate"] < 1.0:
        raise SpecError(
            f"batch={values['batch']:g} is invalid with rate={values['rate']:g}: a trajectory must hold at "
            f"least one point (batch >= 1/rate = {1 / values['rate']:g} s)"
        )
    for axis in AXES:
        lo, hi = values.get(f"min_position.{axis}", -NO_LIMIT), values.get(f"max_position.{axis}", NO_LIMIT)
        if not lo < hi:
            raise SpecError(
                f"min_position.{axis}={lo:g} is invalid with max_position.{axis}={hi:g}: the soft limits "
                "must leave a range (min < max)"
            )
    joints, axes = values["joints"], values["axes"]
    if len(axes) != len(joints):
        raise SpecError(
            f"axes={axes!r} is invalid: must name one axis for each of joints ({len(joints)}: {joints!r})"
        )
    missing = [a for a in AXES if a not in axes]
    if missing:
        raise SpecError(
            f"axes={axes!r} is invalid: every axis of the cell ({', '.join(AXES)}) must be driven; "
            f"{', '.join(missing)} is not"
        )
