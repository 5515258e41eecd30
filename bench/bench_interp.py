"""Interpolation throughput against the memory-bound limit: a plain numpy fill
of the same (N, 2) int64 output, measured in the same run.

    .venv/bin/python bench/bench_interp.py [--quick]
"""

from __future__ import annotations

import sys

import numpy as np
from _common import best_of, table

from winder.motion.interp import dda, min_deviation, point_by_point


def main() -> None:
    quick = "--quick" in sys.argv
    sizes = [10**4, 10**5, 10**6, 10**7] + ([] if quick else [2 * 10**7])
    rows = []
    for n in sizes:
        minor = int(n * 0.3827) | 1  # an awkward ratio, no short period
        fill = best_of(lambda n=n: np.full((n, 2), 1, dtype=np.int64))
        md = best_of(lambda n=n, m=minor: min_deviation(n, m))
        pbp = best_of(lambda n=n, m=minor: point_by_point(n, m), repeat=3)
        rows.append(
            [
                f"{n:.0e}",
                f"{n / md / 1e6:8.1f}",
                f"{n / fill / 1e6:8.1f}",
                f"{fill / md:5.2f}",
                f"{(n + minor) / pbp / 1e6:8.1f}",
            ]
        )
    print("min-deviation interpolation vs a plain numpy fill of the same (N, 2) int64 output")
    print(
        table(
            ["N", "min-dev Msteps/s", "fill Mrows/s", "speed / fill", "point-by-point Msteps/s"],
            rows,
        )
    )
    bits = 20
    n = 2**bits
    d = best_of(lambda: dda(n - 1, n // 3, bits))
    m = best_of(lambda: min_deviation(n - 1, n // 3))
    print(f"\nDDA 2^{bits} register: {n / d / 1e6:.1f} M iterations/s ({m / d:.2f} x min-deviation)")
    print("target: speed / fill >= 0.5 at N = 2e7")


if __name__ == "__main__":
    main()
