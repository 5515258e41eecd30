"""The summary ``winder run`` and ``winder resim`` print when a run ends,
and the exit status it means (:mod:`winder.cli.exits`)."""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from winder.cli.exits import (
    EXIT_ABORTED,
    EXIT_BAD_INPUT,
    EXIT_FAILED,
    EXIT_FAULTED,
    EXIT_NODE_DIED,
    EXIT_OK,
)
from winder.contract.run import PART_INDEX_KEY, JobReport, commands_text, stops_text
from winder.contract.states import JobState

__all__ = ["report_run"]


def _number(summary: dict[str, str], key: str, fmt: str, scale: float = 1.0) -> str:
    """A report's number as text, "-" if it is missing or not a number."""
    try:
        return format(float(summary[key]) * scale, fmt)
    except (KeyError, ValueError):
        return "-"


def _told_by_bag(bag: str) -> tuple[str, str]:
    """The programmed stops and the operator's commands of the run recorded in
    ``bag``, each in one line ("" if none, or if the bag is not on this host or
    cannot be read: the summary then says nothing of them)."""
    if not bag or not Path(bag).is_dir():
        return "", ""
    from winder.record.reader import read_run

    try:
        run = read_run(bag)
    except (OSError, ValueError):
        return "", ""
    return stops_text(run.plan), commands_text(run.events, run.plan)


def report_run(
    result: Any, wall: float, command: str = "run", *, stops: bool = True, unclosed: Sequence[Path] = ()
) -> int:
    """The summary of a finished run (``winder run``, ``winder resim``) and
    the exit status (:mod:`winder.cli.exits`): done, aborted cleanly, a node
    died before the run ended, failed (with errors, or no final report), or
    faulted (every step executed, but the axes did not do what was commanded:
    the report's ``faults``). Every figure names its unit: a step count is in
    commanded steps (a microstep of the drive, ``motor_step_angle``), lost
    steps in the motor's full steps as well.
    ``stops``: the job has programmed stops (else the bag is read for the
    summary's stops and commands only when the consumer booked commands).
    ``unclosed``: the run's bag, if its consumer left it unclosed (killed, a
    full disk: :func:`winder.record.bag.unclosed`), named with what mends it."""
    s = result.summary
    if not s:
        from winder.record.bag import unclosed_line

        left = f"; {unclosed_line(unclosed)}" if unclosed else ""
        logs = f"(node logs in {result.log_dir})"
        print(f"winder {command}: the cell did not finish: {result.message} {logs}{left}", file=sys.stderr)
        if getattr(result, "occupied", False) or getattr(result, "refused", False):
            return EXIT_BAD_INPUT  # another cell in the namespace, or a setting or start refused: nothing ran
        return EXIT_NODE_DIED if result.node_died else EXIT_FAILED
    r = JobReport.from_values(s)
    x = r.extra  # beyond the contract's keys, what the consumer reports (a hardware driver's may not)
    print(f"  run                {r.run_id or '-'}")
    print(f"  state              {r.state}")
    print(
        f"  steps              {r.steps_done} of {r.steps_total}  (missing {r.steps_missing}, gaps {r.gaps})"
    )
    simulated = "lost_steps" in x  # the simulator's report; a hardware consumer's runs in real time
    if "sim_time_s" in s:
        print(f"  {'simulated time' if simulated else 'run time':<18} {r.sim_time_s:.3f} s")
    if simulated:
        rtf = f"{r.real_time_factor:.1f}" if math.isfinite(r.real_time_factor) else "-"
        print(f"  real-time factor   {rtf} x  (simulation), run took {wall:.1f} s")
    else:
        print(f"  run took           {wall:.1f} s")
    if "mean_deviation_command_m" in x or "mean_deviation_actual_m" in x:
        print(
            f"  mean deviation     command {_number(x, 'mean_deviation_command_m', '.3f', 1e6)} um, "
            f"axes {_number(x, 'mean_deviation_actual_m', '.3f', 1e6)} um  (eq. 7)"
        )
    if "max_tracking_error_steps" in x:
        axis = f" ({x['max_tracking_error_axis']})" if x.get("max_tracking_error_axis") else ""
        print(f"  max tracking error {_number(x, 'max_tracking_error_steps', '.3f')} commanded steps{axis}")
    if "lost_steps" in x:  # the nonlinear model's slips, in the motor's full steps (CONTRACT 3.7)
        commanded = f" ({x['lost_commanded_steps']} commanded steps)" if "lost_commanded_steps" in x else ""
        print(f"  lost steps         {x['lost_steps']} full steps{commanded}")
    if "tension_peak_n" in x:  # the simulated wire
        outside = float(x.get("tension_outside_alarm_s") or 0)
        span = f"{x.get('tension_min_n', '-')}..{x['tension_peak_n']} N"
        if outside > 0:
            print(f"  WARNING wire       tension {span}, {outside:g} s outside the alarm band")
        else:
            print(f"  wire tension       {span}")
    if r.faults:  # every step executed, but not as commanded: the part is not the job's
        print(f"  WARNING faults     {r.faults}")
    if "late_steps" in x:  # steps that came behind the consumer's clock, executed at it
        behind = _number(x, "late_steps_behind_max_ms", ".3f")
        print(f"  late steps         {x['late_steps']}  (up to {behind} ms behind the clock, executed at it)")
    if r.stalls:
        # a stall of the producers: as fast as possible nothing waits on the steps, so one that
        # ends with every step done is a warning; in real time the axes ran out of steps (ERROR)
        longest = x.get("longest_stall_s")
        print(
            f"  WARNING stalls     {r.stalls}, the step stream stood still"
            + (f" up to {longest} s" if longest else "")
            + (", nothing lost" if r.state == JobState.DONE and not r.steps_missing else "")
        )
    # the stops and commands come from the bag: read only when the run had some (reading a
    # large bag takes a while; the final report counts the operator's events)
    had = stops or "operator_events" in x
    stops_line, commands = _told_by_bag(r.bag) if had else ("", "")
    if stops_line:
        print(f"  programmed stops   {stops_line}")
    if commands:
        print(f"  operator commands  {commands}")
    print(f"  bag                {r.bag or '-'}")
    if r.part_id:  # the run's part, and the index that holds it (docs/PARTS.md)
        print(f"  part               {r.part_id}  (winder parts show)")
        if x.get(PART_INDEX_KEY):
            print(f"  part index         {x[PART_INDEX_KEY]}")
    if result.errors:
        print(f"  ERROR reports      {len(result.errors)}, first: {result.errors[0]}")
    # messages from nodes that are not the cell's, refused: by each node of the cell, and this command
    # (the cell's own nodes left out: winder.ros.cell; the consumer's report is read only by a
    # caller whose result does not say, so that what was left out does not come back through it)
    foreign = result.intruders if hasattr(result, "intruders") else x.get("intruders", "")
    if foreign:
        print(f"  ignored, foreign   {foreign}")
    if r.errors or result.errors or (not result.ok and r.state != JobState.ABORTED):
        logs = f" (node logs in {result.log_dir})" if result.log_dir else ""
        print(f"winder {command}: {result.message}{logs}", file=sys.stderr)
        return EXIT_FAILED
    if r.faults:  # done (or aborted at rest) with every step executed, but the axes did not follow
        print(f"winder {command}: {result.message}", file=sys.stderr)
        return EXIT_FAULTED
    if r.state == JobState.ABORTED:
        print(f"winder {command}: {result.message}", file=sys.stderr)
        return EXIT_ABORTED
    return EXIT_OK
