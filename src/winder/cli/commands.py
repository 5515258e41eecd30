"""The ``winder`` command line.

Every error ends as one line on stderr and the exit status of its class
(:mod:`winder.cli.exits`: 2 bad input, 5 an output not written, ...); no traceback.
The error family (:mod:`winder.errors`) says which: a :class:`BadInputError` is
the user's to fix (2), an exception outside the family a bug (70, its traceback
in a file: :mod:`winder.cli.crash`).
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from winder import __version__
from winder.cli.common import (
    CELL_SPECS,
    Progress,
    UserError,
    add_spec_arguments,
    directory_option,
    given_values,
    job_file,
    job_file_hashed,
    job_from_args,
    ros_imports,
    values_from_args,
)
from winder.cli.exits import (
    EXIT_BAD_INPUT,
    EXIT_FAILED,
    EXIT_INTERNAL,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_OUTPUT,
)
from winder.cli.lifetime import leave_when_done, take_early
from winder.cli.summary import report_run
from winder.contract.params import (
    INTERP_SPECS,
    OPERATION_SPECS,
    PROFILE_SPECS,
    SIM_SPECS,
    bag_directory,
    check_interp,
    check_profile,
    check_sim,
    stop_points,
)
from winder.contract.run import shaper_text
from winder.contract.stream import RUN_FACTS
from winder.contract.topics import check_namespace
from winder.errors import BadInputError, OutputError, RefusedError, UnavailableError
from winder.interrupts import Interrupts, deferred
from winder.motion.axes import AXIS_TABLE, FEED, FORK
from winder.motion.interp import dda, deviation_stats, min_deviation, point_by_point
from winder.motion.job import FIELD_SPECS, Job
from winder.motion.timing import plan_job_timing
from winder.spec import Spec, shorten
from winder.tension.check import add_takeup, add_tension, derated, time_for_check, wire_refusal
from winder.tension.tensioner import TENSIONER_SPECS

__all__ = ["main"]


#: rows ``winder interp`` interpolates at a time: its memory stays flat (about
#: 100 MiB) whatever the job; the job is streamed through in such blocks
INTERP_BLOCK = 1 << 20
#: steps of the one turn ``winder interp`` compares every method on, at most
#: (the DDA and point-by-point paths are made whole, as the paper's figures)
ONE_TURN_MAX = 1 << 22


def cmd_interp(args: argparse.Namespace) -> int:
    """Interpolate a job and print what the interpolation did. The steps
    are made and measured a block (:data:`INTERP_BLOCK`) at a time, each
    layer against its path (its line, or the cam's piece: eq. 7, as
    ``winder analyze`` measures it), so a job of any size runs in flat memory."""
    from winder.contract.eq7 import signed_path_distance
    from winder.motion.interp import interpolate_pieces, line_distance

    job = job_from_args(args, job_file(args)["interp_node"])
    segments = job.segments()
    lx, ly, _ = job.step_lengths
    total = sum(s.steps for s in segments)
    progress = Progress(total, "interpolating")
    t0 = time.perf_counter()
    done = 0
    total_dev = 0.0
    max_dev = 0.0
    layer_points = 0
    position = list(segments[0].start) if segments else [0] * len(AXIS_TABLE)
    for seg in segments:
        for first in range(0, seg.steps, INTERP_BLOCK):
            stop = min(seg.steps, first + INTERP_BLOCK)
            path = interpolate_pieces(seg.start, seg.pieces, first=first, stop=stop)
            if seg.kind.winds and path.shape[0]:
                if len(seg.pieces) > 1:
                    dist = np.abs(
                        signed_path_distance(seg.start, seg.pieces, path[:, 0], path[:, 1], (lx, ly))
                    )
                else:
                    dist = line_distance(
                        path[:, :2],
                        seg.delta[FEED.index],
                        seg.delta[FORK.index],
                        step_lengths=(lx, ly),
                        origin=seg.start[:2],
                    )
                total_dev += float(np.sum(dist))
                max_dev = max(max_dev, float(dist.max()))
                layer_points += dist.size
            if path.shape[0]:
                position = path[-1].tolist()
            done += path.shape[0]
            progress.update(done)
    progress.close()
    elapsed = time.perf_counter() - t0
    if segments and tuple(position) != segments[-1].end:
        raise RuntimeError(f"interpolation ended at {position}, job ends at {segments[-1].end}")
    mean_dev = total_dev / max(layer_points, 1)
    rate = done / elapsed if elapsed > 0 else float("inf")
    print(f"job {job.job_id}: {job.shape}")
    print(f"  segments           {len(segments)}")
    print(f"  steps              {done}  ({rate / 1e6:.1f} M steps/s)")
    print(f"  final position     feed {position[0]}  fork {position[1]}  pole {position[2]} steps")
    print(f"  mean deviation     {mean_dev * 1e6:.3f} um  (eq. 7, all layers)")
    print(f"  max deviation      {max_dev * 1e6:.3f} um")
    # one turn with every method, as the paper compares them
    x1 = round(job.wire_diameter / job.feed_step)
    y1 = job.fork_steps_per_rev
    if max(x1, y1) > ONE_TURN_MAX:
        print(
            f"  one turn, {x1} feed x {y1} fork steps: not compared (more than {ONE_TURN_MAX} steps; "
            "the DDA and point-by-point paths are made whole)"
        )
        return EXIT_OK
    bits = max(10, math.ceil(math.log2(max(x1, y1))))
    methods = {
        "min-deviation": min_deviation(x1, y1),
        f"DDA 2^{bits} half-preloaded": dda(x1, y1, bits),
        f"DDA 2^{bits} plain": dda(x1, y1, bits, preload=False),
        "point-by-point": point_by_point(x1, y1),
    }
    turn = {k: deviation_stats(p, x1, y1, step_lengths=(lx, ly)).mean for k, p in methods.items()}
    print(f"  one turn, {x1} feed x {y1} fork steps, mean deviation (eq. 7):")
    for name, mean in turn.items():
        print(f"    {name:26s} {mean * 1e6:8.3f} um  ({mean / turn['min-deviation']:.2f} x)")
    return EXIT_OK


def cmd_run(args: argparse.Namespace) -> int:
    """Run the whole cell: three node processes, progress, summary."""
    # everything is checked here first: a bad value never starts a node or a bag
    given, digest = job_file_hashed(args)
    job = job_from_args(args, given["interp_node"])
    profile = values_from_args(args, PROFILE_SPECS, given["profile_node"])
    check_profile(profile)
    sim = values_from_args(args, SIM_SPECS, given["consumer"])
    operation = values_from_args(args, OPERATION_SPECS, given["profile_node"])
    # the interp node's other settings in the file (chunk_steps, max_in_flight, stops...) go with the job
    extra = {k: v for k, v in given["interp_node"].items() if k not in FIELD_SPECS and k != "autostart"}
    extra.update(values_from_args(args, STOP_SPECS, given["interp_node"]))
    extra.update(values_from_args(args, RUN_FACTS))  # the run's, never a job file's
    # the wire at the run's speeds: its ramp, its feed override and the overrides its schedule sets
    running, schedule = {**profile, **operation}, str(extra.get("schedule", ""))
    derating = derated(job, running, schedule, sim)
    if derating is not None:  # the layers slowed go to the interp node in layer_speed
        job = derating.job
    segments = job.segments()
    if args.stop_at_turn is not None:
        extra["stops"] = f"1:{args.stop_at_turn}"
    if args.auto_resume is not None:
        extra["stop_pause"] = STOP_SPECS["stop_pause"].parse(args.auto_resume)
    if digest:
        extra["job_file_sha256"] = digest  # the run's bag names its recipe
    stops = stop_points(job, extra["stops"])
    pause = float(extra["stop_pause"])
    _, duration_ns = plan_job_timing(profile, job, stops, pause)  # the job as a whole
    # the interp node's own check of what it will be given (schedule, the ramp it carries, ...)
    check_interp({**{n: s.default for n, s in INTERP_SPECS.items()}, **job.to_dict(), **extra}, job=job)
    external = external_nodes(args)
    drives = drives_file(args, external)  # checked before the bus, before any node
    check_sim({**sim, "record": False} if "sim" in external else sim)  # a remote bag_dir is its host's
    why = wire_refusal(job, running, schedule, sim, derating=derating)
    if why:  # the words of winder check
        raise UserError(why + (derating.still() if derating is not None else ""))
    cell = values_from_args(args, CELL_SPECS)
    args.namespace = check_namespace(args.namespace)
    from winder.cli.view import foxglove_host, foxglove_port, start_live_view

    fox_port = foxglove_port(args)
    if fox_port is not None:
        foxglove_host(args)
    if args.check:
        steps = sum(s.steps for s in segments)
        if derating is not None and derating.words():
            print(f"winder run --check: {derating.words()}")
        print(
            f"winder run --check: job {job.job_id}: {steps} steps in {len(segments)} segments, "
            f"{duration_ns / 1e9:.3f} s with the {profile['profile']} profile; every setting is valid, "
            "nothing was started"
        )
        return EXIT_OK
    interrupts = Interrupts().install()  # rclpy's own handlers are not used: see winder.interrupts
    try:
        with ros_imports(interrupts):
            from winder.ros.cell import cell_network, run_cell
            from winder.ros.dds import DISCOVERY_SERVER_KEY
        bag_dir = bag_directory(sim["bag_dir"]) if "sim" not in external else Path(sim["bag_dir"])
        sim["bag_dir"] = str(bag_dir)
        params = {"interp": {**job.to_dict(), **extra}, "profile": {**profile, **operation}, "sim": sim}
        if drives:  # the drives node in the sim node's place: the consumer's settings and its file
            from winder.contract.params import CONSUMER_SPECS

            params["sim"] = {k: v for k, v in sim.items() if k in CONSUMER_SPECS} | {"drives_file": drives}
        # a node that runs elsewhere is told only what was given (job file, options), through
        # its parameter services before the job starts; it keeps its own values for the rest
        remote_specs = {
            "sim": (SIM_SPECS, given["consumer"]),
            "profile": (PROFILE_SPECS | OPERATION_SPECS, given["profile_node"]),
        }
        for name in external:
            params[name] = given_values(args, *remote_specs[name])
        shaper = shaper_text(profile)
        ramp = (
            "the external profile node's ramp"
            if "profile" in external
            else f"{profile['profile']} profile" + (f", {shaper}" if shaper else "")
        )
        model = "the external step consumer" if "sim" in external else f"{sim['model']} motor model"
        if drives:
            model = f"the CiA 402 drives of {drives}"
        print(f"winder: job {job.job_id}, {job.total_steps} steps, {ramp}, {model}")
        slowed = derating.words() if derating is not None else ""
        if slowed:
            print(f"  {slowed}")
        if digest:
            print(f"  job file           {args.job_file}  (sha256 {digest})")
        facts = ", ".join(f"{name.replace('_', ' ')} {extra[name]}" for name in RUN_FACTS if extra[name])
        if facts:  # recorded with the run: its job description, its bag's metadata, its part
            print(f"  run of             {facts}")
        if external:
            from winder.ros.dds import describe_profile

            names = ", ".join(EXTERNAL[n] for n in sorted(external))
            print(f"  not started here   {names} (--external {','.join(sorted(external))})")
            for name in sorted(external):
                if params[name]:
                    told = ", ".join(f"{k}={v}" for k, v in params[name].items())
                    label = {"sim": "external consumer", "profile": "external profile"}[name]
                    print(f"  {label:<18} {told}  (set through its parameter services before the job)")
            print(f"  DDS profile        {describe_profile()}")
        from winder.record.bag import unclosed_bags, unclosed_line

        local_bags = sim["record"] and "sim" not in external
        if local_bags:
            probe = next(p for p in (bag_dir, *bag_dir.parents) if p.exists())
            free = shutil.disk_usage(probe).free
            room = f"{free / 2**30:.1f} GiB" if free >= 2**30 else f"{free / 2**20:.1f} MiB"
            print(f"  recording into     {bag_dir}  ({room} free)")
        left_before = unclosed_bags(bag_dir) if local_bags else []
        if left_before:  # an earlier run's consumer SIGKILLed, or its disk full
            print(f"  WARNING            {unclosed_line(left_before, 'bag_dir')}")
        domain, discovery, source = cell_network()
        server = os.environ.get(DISCOVERY_SERVER_KEY, "").strip()
        if server:  # Fast DDS makes every participant a client of the server(s) named there
            discovery = f"by the discovery server {server} ({DISCOVERY_SERVER_KEY})"
        print(f"  ROS domain         {domain} ({source}), discovery {discovery}")
        fox_server, view = None, None
        try:
            if fox_port is not None:  # listening before the cell starts: a port in use starts nothing
                # foxglove's server calls Python from Rust, where a KeyboardInterrupt can be lost
                with interrupts.held():
                    fox_server, view = start_live_view(args, fox_port, args.namespace)
            bar = Progress(1.0, "winding")
            t0 = time.monotonic()
            result = run_cell(
                params,
                namespace=args.namespace,
                domain=domain,
                timeout=cell["timeout"],
                start_timeout=cell["start_timeout"],
                external=external,
                progress=lambda frac, sim_t: bar.update(frac, f"sim {float(sim_t):7.2f} s"),
                view=view,
                interrupts=interrupts,
                one_process=args.one_process,
                early=take_early(),
                **({"consumer": DRIVES_NODE} if drives else {}),
            )
        finally:
            if fox_server is not None:
                fox_server.stop()
        if view is None or view.node is None:  # the cell is down, every node of this process destroyed
            leave_when_done()
        bar.close()
        # this run's bag, if its consumer was killed (or its disk filled) before it was closed
        left = [b for b in unclosed_bags(bag_dir) if b not in left_before] if local_bags else []
        code = report_run(result, time.monotonic() - t0, stops=bool(stops), unclosed=left)
        if slowed and result.summary:
            print(f"  derated            {slowed.removeprefix('tension.derate: ')}")
        return code
    finally:
        interrupts.restore()


def cmd_check(args: argparse.Namespace) -> int:
    """The coil as it will be laid: per layer the turns, radius and turn
    length; then turns, build height against the window, fill factor, wire
    length, resistance and the finish side (``--json``: one object). A job
    whose coils do not fit: the report, then one line naming what overflows
    and by how much, exit 2 (the words ``winder run`` and the interp node
    refuse it in)."""
    import json

    from winder.motion.coil import report

    given = job_file(args, check_fit=False)
    job = Job.from_dict(values_from_args(args, FIELD_SPECS, given["interp_node"]), check_fit=False)
    schedule = str(given["interp_node"].get("schedule", ""))
    tensioner = values_from_args(args, TENSIONER_SPECS, given["consumer"])
    ramp = {n: spec.default for n, spec in PROFILE_SPECS.items()} | given["profile_node"]
    derating = derated(job, ramp, schedule, tensioner) if job.winding.fits else None
    if derating is not None:
        job = derating.job
    laid = job.winding
    doc = {"job_id": job.job_id, **report(laid)}
    # the derated job was timed and predicted as it was derated
    timed = derating.timed if derating is not None else time_for_check(job, ramp, schedule)
    add_takeup(job, doc, timed)
    tension_why = add_tension(job, doc, tensioner, timed, wound=derating.wound if derating else None)
    if derating is not None and tension_why:
        tension_why += derating.still()
    if derating is not None:
        doc["wire"]["derated"] = derating.to_doc()
    if tension_why and doc["fits"]:  # the coil fits its bobbin, but its wire would not hold
        doc["fits"], doc["overflow"] = False, tension_why
    limits_why = ""
    if args.limits is not None and not args.limits.strip():
        raise UserError("--limits is empty: give the bridge's parameters file (a bridge_node section)")
    if args.limits:
        doc["limits"], limits_why = axis_limits(job, given["profile_node"], args.limits, given["interp_node"])
    if args.json:
        print(json.dumps(doc, indent=2))
    else:
        for line in check_lines(job, doc):
            print(line)
        if args.limits:
            for line in limit_lines(doc["limits"], args.limits):
                print(line)
    why = laid.overflow() or tension_why or limits_why
    if why:
        print(f"winder check: error: {why}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return EXIT_OK


def axis_limits(
    job: Job, ramp_given: dict[str, Any], path: str, interp_given: dict[str, Any]
) -> tuple[dict[str, Any], str]:
    """``winder check --limits``: the job, timed with the job file's ramp (the
    profile node's defaults where it sets none), against the bridge's limits
    in the parameters file ``path`` (its ``bridge_node`` section), at the
    highest feed override its ``schedule`` (job file, interp_node) sets: each
    axis' travel (from zero, as with job_origin zero), peak velocity and peak
    acceleration over 20 ms beside its limits; and the first one passed, in
    words ("" if none)."""
    from winder.contract.jobfile import JobFileError, load_node_params
    from winder.contract.params import BRIDGE_SPECS, PROFILE_SPECS, check_bridge
    from winder.motion.axes import AXES, AXIS_TABLE
    from winder.motion.limits import NO_LIMIT, highest_override, job_extent, job_limits, travel_past
    from winder.spec import SpecError

    try:
        given = load_node_params(path, "bridge_node", BRIDGE_SPECS)
        values = {n: s.default for n, s in BRIDGE_SPECS.items()} | given
        values["record"] = False  # the bag directory is the bridge's to probe, on its machine
        check_bridge(values)
    except JobFileError as exc:  # it names the file
        raise UserError(f"--limits: {exc}") from None
    except SpecError as exc:
        raise UserError(f"--limits {path}: {exc}") from None
    ramp = {n: s.default for n, s in PROFILE_SPECS.items()} | ramp_given
    try:
        schedule = str(interp_given.get("schedule", ""))
        peaks, why = job_limits(job, ramp, values, schedule=schedule)
    except BadInputError as exc:
        raise UserError(f"the job cannot be ramped: {exc}") from None
    lo, hi = job_extent(job.segments())
    step = np.asarray(job.joint_step)
    travel_lo, travel_hi = lo * step, hi * step
    lows = [values[f"min_position.{a}"] for a in AXES]
    highs = [values[f"max_position.{a}"] for a in AXES]
    past = travel_past(travel_lo, travel_hi, lows, highs) if values["job_origin"] == "zero" else None
    if not why and past is not None:
        axis, unit = AXES[past.index], AXIS_TABLE[past.index].unit
        why = f"the job takes the {axis} axis to {past.at:.6g} {unit}, beyond {past.side}_position.{axis} = "
        why += f"{past.limit:g} {unit}"

    def limit(name: str) -> float | None:  # a limit set, or None (none: +-NO_LIMIT)
        value = float(values[name])
        return None if abs(value) >= NO_LIMIT else value

    out: dict[str, Any] = {}
    for i, ax in enumerate(AXIS_TABLE):
        p, axis = peaks[i], ax.name
        out[axis] = {
            "unit": ax.unit,
            "travel": [float(travel_lo[i]), float(travel_hi[i])],
            "min_position": limit(f"min_position.{axis}"),
            "max_position": limit(f"max_position.{axis}"),
            "peak_velocity": p.velocity,
            "max_velocity": limit(f"max_velocity.{axis}"),
            "peak_acceleration": p.windowed_acceleration,
            "velocity_jump": p.jump,
            "max_acceleration": limit(f"max_acceleration.{axis}"),
        }
    out["job_origin"] = values["job_origin"]
    out["feed_override"] = highest_override(ramp, schedule)
    out["within"] = not why
    return out, why


def limit_lines(doc: dict[str, Any], path: str) -> list[str]:
    """``winder check --limits``' table: each axis' travel, peaks and limits."""
    from winder.motion.axes import AXES

    def lim(x: float | None) -> str:
        return "-" if x is None else f"{x:g}"

    origin = (
        "from zero"
        if doc["job_origin"] == "zero"
        else "from where the joints stand (job_origin start_position)"
    )
    lines = [
        f"  limits ({path}, bridge_node; travel {origin}, feed override {doc['feed_override']:g}):",
        "    axis  unit  travel                       range           peak velocity  max       "
        "peak accel (20 ms)  max",
    ]
    for axis in AXES:
        a = doc[axis]
        travel = f"{a['travel'][0]:.6g} .. {a['travel'][1]:.6g}"
        span = f"[{lim(a['min_position'])}, {lim(a['max_position'])}]"
        lines.append(
            f"    {axis:<5} {a['unit']:<5} {travel:<28} {span:<15} {a['peak_velocity']:<14.6g} "
            f"{lim(a['max_velocity']):<9} {a['peak_acceleration']:<19.6g} {lim(a['max_acceleration'])}"
        )
    lines.append(f"  within limits  {'yes' if doc['within'] else 'NO'}")
    return lines


def _coil_numbers(numbers: Sequence[int]) -> str:
    """1, 2, 3, 5 -> "1-3, 5"."""
    out, start = [], numbers[0]
    for a, b in zip(numbers, [*numbers[1:], None], strict=True):
        if b != a + 1:
            out.append(f"{start}" if start == a else f"{start}-{a}")
            start = b if b is not None else a
    return ", ".join(out)


def check_lines(job: Job, doc: dict[str, Any]) -> list[str]:
    """``winder check``'s text: the report :func:`cmd_check` prints."""
    from winder.motion.coil import mm

    def length(x: float | None, unit: str = "mm") -> str:
        return "-" if x is None else (f"{mm(x)} mm" if unit == "mm" else f"{x:.4g} m")

    b = job.bobbin
    if b.core == "round":
        core = f"a round core of {length(b.core_diameter)}" if b.core_given else "a round core"
    else:
        corners = f", corners r {length(b.core_corner_radius)}" if b.core_corner_radius else ""
        core = (
            f"a rectangular core {length(b.core_width)} x {length(b.core_depth)}{corners}"
            if b.core_given
            else "a rectangular core"
        )
    if not b.core_given:
        core += " (size not given: no turn lengths, wire length or resistance)"

    w, h = doc["window_width_m"], doc["window_height_m"]
    if w and h:
        window = f"window {length(w)} wide x {length(h)} high"
    elif w or h:
        window = (
            f"window {length(w)} wide (height unchecked)"
            if w
            else f"window {length(h)} high (width unchecked)"
        )
    else:
        window = "window unchecked"
    lines = [
        f"job {job.job_id}: {_count(job.poles, 'coil')}, {doc['lay']} lay on {core}",
        f"  wire {mm(job.wire_diameter)} mm ({job.material} {mm(doc['bare_diameter_m'])} mm), {window}, "
        f"radial pitch {mm(doc['radial_pitch_m'])} mm",
    ]
    groups: dict[str, list[int]] = {}
    for coil in doc["coils"]:
        groups.setdefault(json_key(coil["layers"]), []).append(coil["coil"])
    for numbers in groups.values():
        coil = doc["coils"][numbers[0] - 1]
        which = (
            "every coil"
            if len(groups) == 1
            else f"coil{'s' if len(numbers) > 1 else ''} {_coil_numbers(numbers)}"
        )
        lines.append(f"  {which}:")
        lines.append(
            "    layer  turns  radius mm  turn length mm  take-up ratio  flyer rad/s  take-up m/s  "
            "take-up accel m/s2  tension N"
        )
        for layer in coil["layers"]:
            turn = "-" if layer["turn_length_m"] is None else f"{layer['turn_length_m'] * 1e3:.2f}"
            ratio = "-" if layer["takeup_ratio"] is None else f"{layer['takeup_ratio']:.3f}"
            omega = "-" if layer["flyer_speed_rad_s"] is None else f"{layer['flyer_speed_rad_s']:.4g}"
            lo, hi = layer["takeup_speed_min_m_s"], layer["takeup_speed_max_m_s"]
            speed = "-" if lo is None or hi is None else f"{lo:.3g}..{hi:.3g}"
            acc = "-" if layer["takeup_accel_max_m_s2"] is None else f"{layer['takeup_accel_max_m_s2']:.4g}"
            t_lo, t_hi = layer.get("tension_min_n"), layer.get("tension_peak_n")
            tension = "-" if t_lo is None or t_hi is None else f"{t_lo:.3g}..{t_hi:.3g}"
            lines.append(
                f"    {layer['layer']:5d}  {layer['turns']:5d}  {layer['radius_m'] * 1e3:9.3f}  {turn:>14}  "
                f"{ratio:>13}  {omega:>11}  {speed:>11}  {acc:>18}  {tension:>9}"
            )
    height = doc["window_height_m"]
    lines.append(
        f"  turns          {doc['turns_per_coil']} per coil, {doc['total_turns']} in all"
        + ("" if doc["uniform"] else " (coil 1's shown; the coils differ)")
    )
    lines.append(
        f"  build height   {mm(doc['build_height_m'])} mm"
        + (f" of a {mm(height)} mm window" if height else " (window height unchecked)")
    )
    fill = doc["fill_factor"]
    lines.append(f"  fill factor    {'-' if fill is None else f'{fill:.3f}'} (conductor area / window area)")
    wire_m, ohm = doc["wire_length_m"], doc["resistance_ohm"]
    coils = f"all {job.poles} coils" if job.poles > 1 else "1 coil"
    lines.append(f"  wire length    {length(wire_m, 'm')} ({coils})")
    series = " (all coils in series)" if job.poles > 1 else ""
    lines.append(f"  resistance     {'-' if ohm is None else f'{ohm:.4g} ohm'} at 20 C{series}")
    side = {"start": "the start flange", "far": "the far flange"}[doc["finish_side"]]
    lines.append(f"  finish side    {side} ({len(doc['layers'])} layers)")
    w = doc.get("wire")
    if w is not None:
        section = w["max_tension_n"] / w["yield_stress_pa"] * 1e6
        band = w["alarm_band_n"]
        lines.append(
            f"  wire           {w['material']}, max tension {w['max_tension_n']:.4g} N (yield "
            f"{w['yield_stress_pa'] / 1e6:.4g} MPa x bare section {section:.4g} mm2); set "
            f"{w['set_tension_n']:.4g} N, alarm band {band[0]:.4g}..{band[1]:.4g} N, "
            f"{w['tensioner']} tensioner"
        )
        d = w.get("derated")
        if d and d["layers"]:
            shares = sorted(x["speed_share"] for x in d["layers"])
            before, after = d["duration_before_s"], d["duration_after_s"]
            lines.append(
                f"  derated        {_count(len(shares), 'layer')} slowed to "
                f"{shares[0]:.0%}..{shares[-1]:.0%} of v_max (tension.derate): {after:.1f} s instead "
                f"of {before:.1f} s "
                f"(+{(after - before) / max(before, 1e-9):.0%})"
            )
    lines.append(f"  fits           {'yes' if doc['fits'] else 'NO: ' + doc['overflow']}")
    return lines


def _count(n: int, what: str) -> str:
    return f"{n} {what}{'s' if n != 1 else ''}"


def json_key(value: Any) -> str:
    import json

    return json.dumps(value, sort_keys=True)


#: the consumer ``winder run --drives`` starts in the sim node's place (winder.ros.cia402_node)
DRIVES_NODE = "cia402_node"


def drives_file(args: argparse.Namespace, external: frozenset[str]) -> str:
    """``--drives FILE``: its absolute path, the file checked as the drives
    node will read it (:func:`winder.drives.load_drives`: one line, exit 2);
    "" without the option."""
    given = getattr(args, "drives", None)
    if given is None:
        return ""
    if "sim" in external:
        raise UserError(
            "--drives with --external sim is invalid: --drives starts the step consumer here; "
            "leave out one of the two"
        )
    if args.one_process:
        raise UserError(
            f"--drives with --one-process is invalid: the drives node ({DRIVES_NODE}) runs as a process "
            "of its own; leave out one of the two"
        )
    from winder.drives import load_drives

    path = Path(given).expanduser().absolute()  # the caller's working directory, not the node's
    load_drives(path)  # DrivesFileError, a BadInputError
    return str(path)


#: the parts of the cell ``winder run --external`` may leave to another host, in words
#: (each found there by its role, whatever its node name)
EXTERNAL = {"profile": "profile node", "sim": "step consumer"}


def external_nodes(args: argparse.Namespace) -> frozenset[str]:
    """The nodes named by ``--external`` (they run elsewhere on the graph).
    Their settings given here (job file sections, options) are not dropped:
    ``winder run`` sets them on those nodes through their parameter services
    before the job starts (:class:`winder.ros.cell.RemoteSettings`)."""
    text = getattr(args, "external", None) or ""
    names = frozenset(n.strip() for n in text.split(",") if n.strip())
    if names and getattr(args, "one_process", False):
        raise UserError(
            f"--one-process with external={text!r} is invalid: one process holds the whole cell; "
            "leave out one of the two"
        )
    bad = sorted(names - set(EXTERNAL))
    if bad:
        raise UserError(
            f"external={text!r} is invalid: {bad[0]!r} is not a node winder run can leave to another "
            f"host (choose from {', '.join(EXTERNAL)}, comma-separated; the interp node holds the job)"
        )
    return names


#: Settings of ``winder discovery-server``: the ranges Fast DDS's server takes
#: (a port below 1025 it refuses with its whole usage text)
SERVER_SPECS: dict[str, Spec] = {
    "port": Spec("port", int, 11811, "UDP port the server listens on", "", 1025, 65535),
    "id": Spec("id", int, 0, "the server's id (its place in ROS_DISCOVERY_SERVER's list)", "", 0, 255),
}


def server_address(address: str, port: int) -> None:
    """UserError (one line) unless the discovery server can listen on
    ``address``:``port``: an IPv4 address of this host (or 0.0.0.0, all of
    them), neither multicast nor broadcast, and the UDP port free there.
    Asked of the system by binding a socket there and closing it: Fast DDS
    runs a server on an address that is not the host's, reachable by no one,
    and says a port taken in a few lines of its own log."""
    import errno
    import ipaddress
    import socket

    rule = "must be an IPv4 address of this host (0.0.0.0: all of them)"
    try:
        ip = ipaddress.IPv4Address(address)
    except ValueError:
        raise UserError(f"address={shorten(address)} is invalid: {rule}") from None
    if ip.is_multicast or ip == ipaddress.IPv4Address("255.255.255.255"):
        raise UserError(f"address={address} is invalid: a multicast or broadcast address; {rule}")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.bind((address, port))
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                raise UserError(
                    f"port={port} is invalid: UDP port {port} on {address} is in use (another discovery "
                    f"server?); must be a free UDP port in {SERVER_SPECS['port'].range_text()}"
                ) from None
            why = "no interface of this host has it" if exc.errno == errno.EADDRNOTAVAIL else exc.strerror
            raise UserError(f"address={address} is invalid: {why or exc}; {rule}") from None


def cmd_discovery_server(args: argparse.Namespace) -> int:
    """Fast DDS's discovery server from this install, in the foreground: the
    alternative to multicast and static peers for a cell across hosts. Its
    settings are checked before it starts (:func:`server_address`): the
    server's own refusals are its usage text or a log."""
    from winder.ros.dds import DISCOVERY_SERVER_KEY, discovery_server_command

    port = SERVER_SPECS["port"].parse(args.port)
    server_id = SERVER_SPECS["id"].parse(args.id)
    server_address(args.address, port)
    try:
        argv, env = discovery_server_command(args.address, port, server_id)
    except FileNotFoundError as exc:
        raise UserError(f"this install has no Fast DDS discovery server ({exc}); run 'make demo'") from None
    host = "<this host's address>" if args.address == "0.0.0.0" else args.address
    print(
        f"winder: discovery server {server_id} on {args.address}:{port}; on every host of the cell:\n"
        f"  export {DISCOVERY_SERVER_KEY}='{';' * server_id}{host}:{port}'",
        flush=True,
    )
    os.execve(argv[0], argv, env)  # the server itself from here on: signals reach it directly
    return EXIT_OK  # not reached


FIGURES = ("interp", "profile", "motor", "wire_theory")


def cmd_figures(args: argparse.Namespace) -> int:
    """Reproduce the papers' figures with this code (PNG files)."""
    import importlib

    out = directory_option("outdir", args.outdir)
    for name in FIGURES:
        module = importlib.import_module(f"winder.analysis.figures.{name}")
        for path in module.make(out):
            print(path)
    return EXIT_OK


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (``--help`` still shows the usage)."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


#: the interp node's programmed-stop and schedule settings, which winder run takes too
STOP_SPECS = {name: INTERP_SPECS[name] for name in ("stops", "stop_pause", "stop_resume", "schedule")}

JOB_FILE_HELP = (
    "a job file (a ROS 2 parameters file: interp_node, profile_node and consumer (or sim_node) "
    "sections; see jobs/); options given here override its values"
)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="winder", description="winder: coil and rotor winding cell tools")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    p = sub.add_parser("interp", help="interpolate a winding job and print a summary")
    p.add_argument("job_file", nargs="?", metavar="JOB_FILE", help=JOB_FILE_HELP)
    add_spec_arguments(p, FIELD_SPECS, "winding job (defaults: the RW400 paper set-up)")
    p.set_defaults(func=cmd_interp)

    p = sub.add_parser("run", help="run the whole cell (three node processes) on a job")
    p.add_argument("job_file", nargs="?", metavar="JOB_FILE", help=JOB_FILE_HELP)
    add_spec_arguments(p, FIELD_SPECS, "winding job (defaults: the RW400 paper set-up)")
    add_spec_arguments(p, PROFILE_SPECS, "profile node (rates in steps of each segment's major axis)")
    add_spec_arguments(p, OPERATION_SPECS, "operation (see docs/OPERATING.md: Operating the cell)")
    add_spec_arguments(p, SIM_SPECS, "sim node (motor settings per axis: --feed.J, --fork.D, ...)")
    add_spec_arguments(p, STOP_SPECS, "programmed stops (see docs/OPERATING.md: Operating the cell)")
    add_spec_arguments(p, RUN_FACTS, "the run (recorded in its part: docs/PARTS.md)")
    add_spec_arguments(p, CELL_SPECS, "cell")
    g = p.add_argument_group("cell")
    g.add_argument("--namespace", default="", help="ROS namespace of the cell (/name[/name...])")
    g.add_argument(
        "--external",
        default=None,
        metavar="NODES",
        help="nodes that run elsewhere on the graph (another host) and are not started here: sim (the "
        "step consumer: the sim node or a hardware driver, found by its role whatever its node name), "
        "profile or both, comma-separated. Their settings given here (options, the job file's consumer "
        "or sim_node and profile_node sections) are set on them through their parameter services "
        "before the job starts; a setting they refuse ends the run unstarted, naming it (see "
        "docs/DEPLOYING.md)",
    )
    g.add_argument(
        "--drives",
        default=None,
        metavar="FILE",
        help="wind on CiA 402 drives over CANopen: start cia402_node with this drives file as the "
        "step consumer, in the sim node's place (interface: virtual winds on drive twins in that "
        "process; see docs/DRIVES.md). The file is checked before anything starts",
    )
    g.add_argument(
        "--one-process",
        action="store_true",
        help="run the three nodes in one process (winder_container, as a ROS 2 component container, "
        "started while the command reads its arguments): the job starts about 0.5 s sooner and many "
        "cells on one host run faster, but the three share one core (a 10^7-step job ran 10-20 %% "
        "slower, docs/BENCHMARKS.md). Not with --external",
    )
    g.add_argument(
        "--check",
        action="store_true",
        help="check the job and every setting, print the plan, start nothing",
    )
    g.add_argument(
        "--stop-at-turn",
        type=int,
        default=None,
        metavar="N",
        help="a programmed stop: the axes come to rest after turn N of the first coil (--stops 1:N)",
    )
    g.add_argument(
        "--auto-resume",
        default=None,
        metavar="S",
        help="seconds of simulated time the axes rest at each programmed stop (--stop-pause S)",
    )
    from winder.cli.view import add_foxglove_arguments

    add_foxglove_arguments(g, "the cell's topics, live,")
    p.set_defaults(func=cmd_run)

    p = sub.add_parser(
        "check",
        help="lay out a job's coil in its bobbin: turns per layer, build height, fill factor, wire "
        "length, resistance, finish side, the wire's take-up and tension; a coil that does not fit, or "
        "whose wire would not hold, exits 2",
    )
    p.add_argument("job_file", nargs="?", metavar="JOB_FILE", help=JOB_FILE_HELP)
    add_spec_arguments(p, FIELD_SPECS, "winding job (defaults: the RW400 paper set-up)")
    add_spec_arguments(p, TENSIONER_SPECS, "the tensioner (the consumer's settings: a job file's sim_node)")
    p.add_argument("--json", action="store_true", help="print the report as one JSON object")
    p.add_argument(
        "--limits",
        metavar="PARAMS_FILE",
        help="also check the job, timed with its ramp, against the bridge's soft limits in this ROS 2 "
        "parameters file (its bridge_node section: min/max_position, max_velocity, max_acceleration "
        "per axis); a job past one exits 2",
    )
    p.set_defaults(func=cmd_check)

    p = sub.add_parser(
        "discovery-server",
        help="run Fast DDS's discovery server for a cell across hosts (see docs/DEPLOYING.md)",
    )
    p.add_argument("--address", default="0.0.0.0", help="IPv4 address to listen on (default: all)")
    p.add_argument("--port", default="11811", help="UDP port; [1025, 65535]; default 11811")
    p.add_argument("--id", default="0", help="server id; [0, 255]; default 0")
    p.set_defaults(func=cmd_discovery_server)

    p = sub.add_parser("figures", help="reproduce the source papers' figures as PNG files")
    p.add_argument(
        "outdir",
        nargs="?",
        default="figures",
        help="where the PNG files go (default ./figures; `make figures` renews the README's, docs/img)",
    )
    p.set_defaults(func=cmd_figures)

    from winder.cli.analysis import register  # analyze, identify, bag recover

    register(sub)
    from winder.cli.replay import register as register_replay  # play, resim

    register_replay(sub)
    from winder.cli.ctl import register as register_ctl  # ctl: start, state, param, lifecycle, pause...

    register_ctl(sub)
    from winder.cli.resonance import register as register_resonance  # resonance, tune

    register_resonance(sub)
    from winder.cli.view import register as register_view  # view; run/play --foxglove

    register_view(sub)
    from winder.cli.parts import register as register_parts  # parts: list, show, measure, export

    register_parts(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    import signal

    # `winder analyze BAG | head`: a closed pipe ends the command quietly, as
    # it does any Unix filter, instead of an "error: Broken pipe"
    if hasattr(signal, "SIGPIPE"):
        signal.signal(signal.SIGPIPE, signal.SIG_DFL)
    with deferred():  # the parser's options load modules (lazily): no signal among them
        parser = build_parser()
        args = parser.parse_args(argv)
    func: Callable[[argparse.Namespace], int] | None = getattr(args, "func", None)
    if func is None:
        parser.print_help()
        return EXIT_BAD_INPUT
    try:
        return func(args)
    except KeyboardInterrupt:
        print(f"winder {args.command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as exc:  # one line and the exit status of its kind; a bug's traceback to a file
        code, line = error_exit(args.command, exc, argv)
        print(line, file=sys.stderr)
        return code


#: the input an OSError names that a user gave (a path that is not there, or not
#: what it must be): the user's to fix, as a BadInputError
USER_PATH_ERRORS = (FileNotFoundError, IsADirectoryError, NotADirectoryError)


def error_exit(command: str, exc: Exception, argv: Sequence[str] | None = None) -> tuple[int, str]:
    """The exit status and the one line of an exception a command raised: the
    error family's kinds (:mod:`winder.errors`) by what the user must do; any
    other exception is an internal error (a bug), its traceback written to a
    file the line names (:mod:`winder.cli.crash`)."""
    head = f"winder {command}: error:"
    if isinstance(exc, OutputError):
        return EXIT_OUTPUT, f"{head} {exc}"
    if isinstance(exc, BadInputError):
        return EXIT_BAD_INPUT, f"{head} {exc}"
    if isinstance(exc, USER_PATH_ERRORS):
        what = f"{exc.filename}: {exc.strerror}" if exc.filename and exc.strerror else _one_line(exc)
        return EXIT_BAD_INPUT, f"{head} {what}"
    if isinstance(exc, (RefusedError, UnavailableError)):
        return EXIT_FAILED, f"{head} {exc}"
    from winder.cli.crash import internal_error_line

    return EXIT_INTERNAL, internal_error_line(command, exc, None if argv is None else ["winder", *argv])


def _one_line(exc: BaseException) -> str:
    lines = [s.strip() for s in str(exc).splitlines() if s.strip()]
    return lines[0] if lines else type(exc).__name__


if __name__ == "__main__":
    sys.exit(main())
