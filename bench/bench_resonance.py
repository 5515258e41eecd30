"""Issue 15's costs, against anchors measured in the same run.

* shaped step timing: steps per second of ``ShapedProfile.step_times`` (ZVD,
  three impulses; safeguarded Newton on the sum of the plan's samples)
  against the unshaped ``Profile.step_times`` of the same move;
* ``winder tune`` on the default job (grid of ramps, exact job times,
  nonlinear check of the fastest), against one nonlinear simulation of the
  default job's longest move with the file's own ramp (what a user would run
  to check a ramp by hand);
* ``winder resonance`` (linear rows) against the same anchor.

    .venv/bin/python bench/bench_resonance.py [--quick]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from _common import best_of, table

from winder.analysis.resonance import METHODS, residual_table
from winder.analysis.tune import axes_of, lost_steps, tune
from winder.contract.jobfile import load_job_file
from winder.motion.job import Job
from winder.motion.profile import plan
from winder.motion.shaped import shape

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    quick = "--quick" in sys.argv
    rows = []
    for n in [10**5] if quick else [10**5, 10**6]:
        base = plan("scurve", float(n), v_max=2e4, a_max=1e6, j_max=1e9)
        shaped = shape(base, "zvd", 44.5, 0.05)
        t_plain = best_of(lambda b=base, n=n: b.step_times(n), 3)
        t_shaped = best_of(lambda s=shaped, n=n: s.step_times(n), 3)
        rows.append(
            [
                f"{n:.0e}",
                f"{n / t_plain / 1e6:6.2f}",
                f"{n / t_shaped / 1e6:6.2f}",
                f"{t_shaped / t_plain:5.1f}",
            ]
        )
    print("Shaped step timing (ZVD) against the plan's own (same move)")
    print(table(["steps", "plain M steps/s", "shaped M steps/s", "shaped / plain time"], rows))

    given = load_job_file(ROOT / "jobs" / "rw400.yaml")
    job = Job.from_dict(given["interp_node"])
    axes = axes_of(given["consumer"])
    ramp = dict(given["profile_node"])
    ramp.setdefault("shaper", "none")
    from winder.contract.params import PROFILE_SPECS

    full = {n: s.default for n, s in PROFILE_SPECS.items()}
    full.update(ramp)
    anchor = best_of(lambda: lost_steps(job, full, axes), 3)
    t0 = time.perf_counter()
    first = tune(job, given["profile_node"], axes)
    t_tune = time.perf_counter() - t0
    second = tune(job, given["profile_node"], axes)
    same = first.ramp == second.ramp and first.job_time == second.job_time
    t_res = best_of(lambda: residual_table(("linear",), (0.52, 0.05), METHODS), 1)
    print("\nwinder tune and winder resonance, against a nonlinear check of the default job's moves")
    print(
        table(
            ["task", "s", "/ anchor"],
            [
                ["anchor: nonlinear check of rw400's moves, its own ramp", f"{anchor:.3f}", "1.0"],
                [f"tune rw400 ({len(first.checked)} simulated, same answer twice: {same})", f"{t_tune:.3f}",
                 f"{t_tune / anchor:.1f}"],
                ["resonance table, linear rows", f"{t_res:.3f}", f"{t_res / anchor:.1f}"],
            ],
        )
    )  # fmt: skip
    print(f"tuned job time {first.job_time:.3f} s against {first.current_time:.3f} s with the file's ramp")


if __name__ == "__main__":
    main()
