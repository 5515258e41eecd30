"""Profile planning and step timing, against anchors measured in the same run.

* plan(): median time per S-curve move over random problems, against ruckig's
  ``calculate`` (C++, called from Python) on the same problems (goal: at most
  2 x), with the largest relative difference of the durations; and a
  segment's whole timing (plan, then step_times(100));
* step_times(): steps per second for n = 1e4 .. 1e7 against an ``np.cumsum``
  of the same n float64 values (a memory-bound single pass).

    .venv/bin/python bench/bench_profile.py [--quick]
"""

from __future__ import annotations

import contextlib
import math
import random
import statistics
import sys
import time

import numpy as np
import ruckig
from _common import best_of, table

from winder.motion.profile import plan


def problems(count: int, seed: int = 1) -> list[tuple[float, ...]]:
    """Random feasible S-curve problems over several decades (durations < 5e3 s for ruckig)."""
    rng = random.Random(seed)
    out: list[tuple[float, ...]] = []
    while len(out) < count:
        V, A, J = (10 ** rng.uniform(-2, 2) for _ in range(3))
        v0 = V * rng.choice([0.0, 1.0, rng.random()])
        v1 = V * rng.choice([0.0, 1.0, rng.random()])
        D = 10 ** rng.uniform(-3, 3)
        try:
            p = plan("scurve", D, v_max=V, a_max=A, j_max=J, v_start=v0, v_end=v1)
        except ValueError:
            continue
        if p.duration < 5e3:
            out.append((D, v0, v1, V, A, J))
    return out


def ruckig_input(D: float, v0: float, v1: float, V: float, A: float, J: float) -> ruckig.InputParameter:
    """The 1-DoF ruckig problem of plan("scurve", D, ...): rest acceleration at both
    ends, no reverse motion."""
    inp = ruckig.InputParameter(1)
    inp.current_position, inp.current_velocity, inp.current_acceleration = [0.0], [v0], [0.0]
    inp.target_position, inp.target_velocity, inp.target_acceleration = [D], [v1], [0.0]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [V], [A], [J]
    inp.min_velocity = [0.0]
    return inp


def time_plans(probs: list[tuple[float, ...]], repeat: int = 5) -> tuple[list[float], list[float]]:
    """Per-problem best-of-``repeat`` times (s) for winder.motion.profile.plan and ruckig."""
    ours = [math.inf] * len(probs)
    theirs = [math.inf] * len(probs)
    otg = ruckig.Ruckig(1)
    traj = ruckig.Trajectory(1)
    inputs = [ruckig_input(*p) for p in probs]
    clock = time.perf_counter
    for _ in range(repeat):
        for i, (D, v0, v1, V, A, J) in enumerate(probs):
            t0 = clock()
            plan("scurve", D, v_max=V, a_max=A, j_max=J, v_start=v0, v_end=v1)
            ours[i] = min(ours[i], clock() - t0)
        for i, inp in enumerate(inputs):
            t0 = clock()
            with contextlib.suppress(ruckig.RuckigError):
                otg.calculate(inp, traj)
            theirs[i] = min(theirs[i], clock() - t0)
    return ours, theirs


def max_duration_difference(probs: list[tuple[float, ...]]) -> tuple[float, int, int, float]:
    """Largest relative duration difference to ruckig, how many ruckig solved,
    how many differ by more than 1e-12 relative and the largest absolute
    difference (s) of those."""
    otg = ruckig.Ruckig(1)
    traj = ruckig.Trajectory(1)
    worst, solved, over, worst_abs = 0.0, 0, 0, 0.0
    for D, v0, v1, V, A, J in probs:
        inp = ruckig_input(D, v0, v1, V, A, J)
        try:
            otg.calculate(inp, traj)
        except ruckig.RuckigError:
            continue
        solved += 1
        ours = plan("scurve", D, v_max=V, a_max=A, j_max=J, v_start=v0, v_end=v1).duration
        rel = abs(ours - traj.duration) / traj.duration
        worst = max(worst, rel)
        if rel > 1e-12:
            over += 1
            worst_abs = max(worst_abs, abs(ours - traj.duration))
    return worst, solved, over, worst_abs


def plan_and_time(probs: list[tuple[float, ...]], n: int, repeat: int) -> float:
    """Median per-problem best time (s) of a segment's whole timing: plan, then step_times(n)."""
    best = [math.inf] * len(probs)
    clock = time.perf_counter
    for _ in range(repeat):
        for i, (D, v0, v1, V, A, J) in enumerate(probs):
            t0 = clock()
            plan("scurve", D, v_max=V, a_max=A, j_max=J, v_start=v0, v_end=v1).step_times(n)
            best[i] = min(best[i], clock() - t0)
    return statistics.median(best)


def main() -> None:
    quick = "--quick" in sys.argv
    probs = problems(500 if quick else 3000)
    ours, theirs = time_plans(probs, repeat=3 if quick else 5)
    med_o, med_t = statistics.median(ours), statistics.median(theirs)
    worst, solved, over, worst_abs = max_duration_difference(probs)
    seg_100 = plan_and_time(probs[:200], 100, repeat=3)
    kinds = []
    for kind, kw in (("trapezoid", {"a_max": 0.5}), ("exponential", {"tau": 1 / 0.85})):
        kinds.append((kind, best_of(lambda kw=kw, kind=kind: plan(kind, 240.0, v_max=8.0, **kw), repeat=200)))
    print(f"plan(): {len(probs)} random S-curve problems, per-problem best of repeats, median")
    print(
        table(
            ["planner", "median us/plan", "ratio to ruckig"],
            [
                ["winder.motion.profile.plan('scurve')", f"{med_o * 1e6:6.2f}", f"{med_o / med_t:5.2f}"],
                ["ruckig.Ruckig.calculate", f"{med_t * 1e6:6.2f}", "1.00"],
                *[[f"winder.motion.profile.plan('{k}')", f"{t * 1e6:6.2f}", ""] for k, t in kinds],
            ],
        )
    )
    print(f"largest |duration - ruckig| / ruckig over {solved} solved: {worst:.2e}", end="")
    print(f"; {over} above 1e-12 (by at most {worst_abs:.1e} s: ruckig's resolution, test_profile.py)")
    print(f"a segment's whole timing, plan + step_times(100): {seg_100 * 1e6:.1f} us median")
    met = "met" if med_o <= 2 * med_t else "NOT met"
    print(f"goal: <= 2 x ruckig per plan: {med_o / med_t:.2f} x, {met}\n")

    sizes = [10**4, 10**5, 10**6] + ([] if quick else [10**7])
    profs = {
        "scurve 240 (paper)": plan("scurve", 240.0, v_max=8.0, a_max=0.5, j_max=0.05),
        "scurve 8e6 (1e6 s)": plan("scurve", 8e6, v_max=8.0, a_max=0.5, j_max=0.05),
        "exponential 400": plan("exponential", 400.0, v_max=20.0, tau=1 / 0.85),
    }
    rows = []
    for n in sizes:
        ones = np.ones(n)
        anchor = best_of(lambda ones=ones: np.cumsum(ones), repeat=5)
        row = [f"{n:.0e}", f"{n / anchor / 1e6:8.1f}"]
        for prof in profs.values():
            t = best_of(lambda prof=prof, n=n: prof.step_times(n), repeat=3 if n >= 10**7 else 5)
            row += [f"{n / t / 1e6:8.1f}", f"{anchor / t:5.2f}"]
        rows.append(row)
    head = ["n", "cumsum M/s"]
    for name in profs:
        head += [f"{name} Msteps/s", "speed / cumsum"]
    print("step_times(n) against np.cumsum of n float64 values")
    print(table(head, rows))
    print("target: >= 10 Msteps/s")


if __name__ == "__main__":
    main()
