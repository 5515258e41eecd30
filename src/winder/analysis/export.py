"""``winder export BAG --csv DIR``: a recording as CSV files, the form
spreadsheets and MATLAB (``readtable``, ``readmatrix``) load.

One file per stream, a header row naming each column with its unit, plain
decimal numbers, one row per message or step:

* ``joint_states.csv`` / ``joint_commands.csv``: time (s of simulated time
  since the job's start) and, per axis, position and velocity (feed m and m/s,
  fork and pole rad and rad/s), one row per sample;
* ``step_times.csv``: the step time in ns (exact) and in s, the segment and
  the three axes' positions in steps after the step, one row per step,
  streamed a recorded chunk at a time (memory does not grow with the job);
* ``events.csv``: the operator events (pause, resume, abort, override);
* ``errors.csv``: every ERROR the cell reported during the run;
* ``run.json``: the job, the motor set-up, the ramp and the sim node's final
  report, and the number of rows of each file.

The files are written into a new directory next to ``DIR``, fsync'd and
renamed to ``DIR`` only when all are complete: an interrupted export or a
full disk leaves nothing half-written. ``DIR`` must not exist yet.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import TextIO

import numpy as np

from winder.contract.files import new_directory
from winder.motion.axes import AXES, AXIS_TABLE
from winder.record.reader import Run, Samples

__all__ = ["export_csv"]

UNITS = {a.name: (a.unit, a.velocity_unit) for a in AXIS_TABLE}


def _samples(f: TextIO, s: Samples) -> int:
    head = ["t_s"]
    for axis in AXES:
        head.append(f"{axis}_position_{UNITS[axis][0].replace('/', '_per_')}")
    for axis in AXES:
        head.append(f"{axis}_velocity_{UNITS[axis][1].replace('/', '_per_')}")
    f.write(",".join(head) + "\n")
    if len(s):
        table = np.column_stack([s.t, s.pos, s.vel]) + 0.0  # + 0.0: no "-0" in the files
        np.savetxt(f, table, delimiter=",", fmt=["%.9f"] + ["%.17g"] * 6)
    return len(s)


def _steps(f: TextIO, run: Run) -> int:
    f.write("t_ns,t_s,segment," + ",".join(f"{a}_steps" for a in AXES) + "\n")
    n = 0
    for rows in run.step_rows:
        if rows.shape[0] == 0:
            continue
        t_s = np.char.mod("%.9f", rows[:, 0] / 1e9)
        ints = rows.astype(np.int64).astype(str)
        lines = [",".join((r[0], t, *r[1:])) for r, t in zip(ints, t_s, strict=True)]
        f.write("\n".join(lines) + "\n")
        n += rows.shape[0]
    return n


def _events(f: TextIO, run: Run) -> int:
    keys = ["t_s", "event", "t_rest_s", "steps", "stop_distance_steps", "factor", "source"]
    f.write(",".join(keys) + "\n")
    for e in run.events:
        rest = e.get("t_rest_ns")
        values = [
            f"{e['t_ns'] / 1e9:.9f}",
            str(e.get("event", "")),
            f"{rest / 1e9:.9f}" if isinstance(rest, (int, float)) else "",
            str(e.get("steps", "")),
            str(e.get("stop_distance", "")),
            str(e.get("factor", "")),
            str(e.get("source", "")),
        ]
        f.write(",".join(values) + "\n")
    return len(run.events)


def _errors(f: TextIO, run: Run) -> int:
    f.write("t_s,report\n")
    for e in run.errors:
        t, text = "", e
        if e.startswith("at ") and " s: " in e:
            t, text = e[3:].split(" s: ", 1)
        f.write(f"{t},{json.dumps(text)}\n")  # the text quoted: it may hold commas
    return len(run.errors)


def export_csv(run: Run, out: Path) -> dict[str, int]:
    """Write the CSV files of ``run`` into the new directory ``out``; the rows
    of each file. The directory appears whole or not at all
    (:func:`winder.contract.files.new_directory`): FileExistsError if it
    exists, OutputError (one line) if it cannot be written."""
    rows: dict[str, int] = {}
    with new_directory(out) as tmp:
        for name in ("joint_states.csv", "joint_commands.csv", "step_times.csv", "events.csv", "errors.csv"):
            with open(tmp / name, "w", newline="") as f:
                if name == "joint_states.csv":
                    rows[name] = _samples(f, run.states)
                elif name == "joint_commands.csv":
                    rows[name] = _samples(f, run.commands)
                elif name == "step_times.csv":
                    rows[name] = _steps(f, run)
                elif name == "events.csv":
                    rows[name] = _events(f, run)
                else:
                    rows[name] = _errors(f, run)
        meta = {
            "bag": str(run.path),
            "job_id": run.job_id,
            "run_id": run.run_id,
            "compression": run.compression,
            "job": run.plan.job.to_dict(),
            "sim_config": asdict(run.sim_config) if run.sim_config else None,
            "profile_config": run.profile_config,
            "final_report": run.report,
            "complete": run.complete,
            "notes": list(run.notes),
            "rows": rows,
        }
        (tmp / "run.json").write_text(json.dumps(meta, indent=2) + "\n")
    return rows
