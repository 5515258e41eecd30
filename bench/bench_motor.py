"""Exact linear stepper response against scipy.signal.lsim and control.forced_response,
measured in the same run on the same sample grid, each with its max error against
the closed form (superposed second-order step responses, computed here).

    .venv/bin/python bench/bench_motor.py [--quick]

The command is a feed staircase: N steps of 2.25 deg at irregular times (mean
1 kHz), reversing every 2000 steps (a layer), sampled at N points. lsim and
forced_response see the staircase only at the sample points (zero-order hold /
linear interpolation between them), so a step between two samples is moved to
a sample: that is their error, and the last table shows what refining their grid
costs.
"""

from __future__ import annotations

import math
import sys

import control
import numpy as np
from _common import best_of, table
from scipy import signal

from winder.axis import StepperAxis

AX = StepperAxis.paper()
STEP = AX.full_step


def train(n: int, seed: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(step times, signed angles, sample grid) of an N-step feed."""
    rng = np.random.default_rng(seed)
    times = np.cumsum(rng.uniform(0.5e-3, 1.5e-3, n))
    angles = STEP * np.where((np.arange(n) // 2000) % 2 == 0, 1.0, -1.0)
    grid = np.linspace(0.0, times[-1] + 0.1, n)
    return times, angles, grid


def staircase(times: np.ndarray, angles: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(angles)])[np.searchsorted(times, t, side="right")]


def closed_form(times: np.ndarray, angles: np.ndarray, t: np.ndarray) -> np.ndarray:
    """theta(t) = sum_k angle_k * s(t - t_k), s the textbook underdamped step response.
    Steps older than 60/sigma contribute their angle exactly (e^-60 < 1e-26)."""
    wn, z = AX.natural_frequency, AX.damping_ratio
    sig, wd = z * wn, wn * math.sqrt(1 - z * z)
    cum = np.concatenate([[0], np.cumsum(np.sign(angles).astype(np.int64))])
    out = np.empty(t.size)
    for i, ti in enumerate(t):
        old = int(np.searchsorted(times, ti - 60 / sig, side="right"))
        new = int(np.searchsorted(times, ti, side="right"))
        tau = ti - times[old:new]
        s = 1 - np.exp(-sig * tau) * (np.cos(wd * tau) + sig / wd * np.sin(wd * tau))
        out[i] = cum[old] * STEP + math.fsum(angles[old:new] * s)
    return out


def main() -> None:
    quick = "--quick" in sys.argv
    sizes = [10**4, 10**5] + ([] if quick else [10**6])
    num, den = AX.transfer_function
    lti = signal.lti(num, den)
    tf = control.tf(num, den)
    rows = []
    for n in sizes:
        times, angles, grid = train(n)
        check = np.sort(np.random.default_rng(2).choice(n, 300, replace=False))
        ref = closed_form(times, angles, grid[check])
        u = staircase(times, angles, grid)
        big = n >= 10**6
        ours_t = best_of(lambda t=times, a=angles, g=grid: AX.response(t, a, g), repeat=3 if big else 5)
        ours = AX.response(times, angles, grid)
        lsim_t = best_of(lambda g=grid, u=u: signal.lsim(lti, u, g, interp=False), repeat=1)
        y_lsim = signal.lsim(lti, u, grid, interp=False)[1]
        ctl_t = best_of(lambda g=grid, u=u: control.forced_response(tf, g, u), repeat=1)
        y_ctl = control.forced_response(tf, grid, u).outputs

        def err(y: np.ndarray, ref: np.ndarray = ref, check: np.ndarray = check) -> str:
            return f"{np.max(np.abs(y[check] - ref)) / STEP:.1e}"

        rows.append(
            [
                f"{n:.0e}",
                f"{ours_t * 1e3:8.1f}",
                err(ours),
                f"{lsim_t * 1e3:8.1f}",
                err(y_lsim),
                f"{ctl_t * 1e3:8.1f}",
                err(y_ctl),
                f"{lsim_t / ours_t:6.1f}",
                f"{ctl_t / ours_t:6.1f}",
            ]
        )
    print("Linear stepper response, N steps and N samples (errors in step angles, vs closed form)")
    print(
        table(
            ["N", "ours ms", "ours err", "lsim ms", "lsim err", "control ms", "control err",
             "lsim/ours", "control/ours"],
            rows,
        )
    )  # fmt: skip

    # what it costs lsim to approach the exact answer: refine its grid r times
    n = 10**4
    times, angles, grid = train(n)
    check = np.sort(np.random.default_rng(2).choice(n, 300, replace=False))
    ref = closed_form(times, angles, grid[check])
    ours_t = best_of(lambda: AX.response(times, angles, grid))
    rows = []
    for r in (1, 10, 100):
        fine = np.linspace(grid[0], grid[-1], (n - 1) * r + 1)
        u = staircase(times, angles, fine)
        lt = best_of(lambda f=fine, u=u: signal.lsim(lti, u, f, interp=False), repeat=1)
        y = signal.lsim(lti, u, fine, interp=False)[1][::r]
        rows.append(
            [
                r,
                f"{lt * 1e3:8.1f}",
                f"{np.max(np.abs(y[check] - ref)) / STEP:.1e}",
                f"{lt / ours_t:7.1f}",
            ]
        )
    print(f"\nlsim on a grid r times finer (N = {n:.0e}; ours: {ours_t * 1e3:.1f} ms, exact)")
    print(table(["r", "lsim ms", "lsim err", "lsim/ours"], rows))
    print("target: lsim/ours >= 10 at equal or better accuracy")


if __name__ == "__main__":
    main()
