"""Drawing the figures of a recorded run: the plots of ``winder analyze`` and
``winder identify`` (target: under a second for the default job).

    .venv/bin/python bench/bench_plots.py [--quick] [--bag BAG ...]

The bags: the default job (``winder run``, every default) recorded by the
three real nodes with joint states at 200 Hz and at 2 kHz (``--quick``: 200 Hz
only), or the bags given. Each is read and digested once (not timed); then,
best of 3:

* ``plot_analysis`` as ``winder analyze`` calls it (with two or more cores a
  process per figure: wall time);
* the same in one process (CPU time of this process), and each figure alone;
* ``plot_identification`` (one figure, this process).

The anchor, in the same run: one figure of the motion figure's size (15 x 12
in, 100 dpi) holding one axes with a plain line through as many points as the
run has joint states, drawn and saved the same way (Agg, PNG level 1): what
drawing the run's largest array once costs. Every figure is a ratio to it.
Last, ``winder analyze BAG`` as a process with and without ``--no-plots``
(best of 3 wall times): what the plots cost a user, with the import of
matplotlib (about 0.35 s) that only the plots need.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from _common import best_of, table

BIN = Path(sys.executable).parent


def record(rate: float, work: Path) -> Path:
    """The default job with joint states at ``rate`` Hz, recorded by ``winder run``."""
    out = work / f"bags_{rate:g}"
    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    cmd = [str(BIN / "winder"), "run", "--publish-rate", f"{rate:g}", "--bag-dir", str(out)]
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300, stdin=subprocess.DEVNULL)
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed: {r.stdout[-2000:]}{r.stderr[-2000:]}")
    from winder.record.bag import bags_in

    (bag,) = bags_in(out)
    return bag


def cpu_best(fn: Callable[[], object], repeat: int = 3) -> float:
    """Smallest CPU time of this process over ``repeat`` calls."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best


def anchor(points: int, out: Path) -> float:
    """One figure of 15 x 12 in with one plain line of ``points`` points, saved as PNG."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    t = np.arange(points) / 200.0
    y = np.sin(t) + 0.01 * np.sin(300 * t)

    def draw() -> None:
        fig = Figure(figsize=(15, 12), dpi=100)
        FigureCanvasAgg(fig)
        fig.add_subplot().plot(t, y, lw=0.6)
        fig.savefig(out / "anchor.png", dpi=100, pil_kwargs={"compress_level": 1})

    draw()
    return best_of(draw, repeat=5)


def cli(bag: Path, plots: Path, no_plots: bool) -> float:
    cmd = [str(BIN / "winder"), "analyze", str(bag)] + (
        ["--no-plots"] if no_plots else ["--plots-dir", str(plots)]
    )

    def run() -> None:
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stdin=subprocess.DEVNULL)

    return best_of(run, repeat=3)


def measure(bag: Path, out: Path) -> tuple[list[list[str]], list[list[str]]]:
    from winder.analysis.figures import analysis as fa
    from winder.analysis.identify import identify
    from winder.analysis.metrics import analyze, digest_run
    from winder.record.reader import read_run

    run = read_run(bag)
    d = digest_run(run)
    res = analyze(run, digested=d)
    ident = identify(run)
    samples = len(run.states)
    label = f"{run.sim_config.publish_rate if run.sim_config else 0:g} Hz"
    base = anchor(samples, out)
    fa.plot_analysis(run, res, out, digested=d)  # warm: fonts, caches
    as_run = best_of(lambda: fa.plot_analysis(run, res, out, digested=d), repeat=3)
    parts: list[tuple[str, float, str]] = [("plot_analysis, as winder analyze runs it", as_run, "wall")]
    fa._JOB = (run, res, d, out)
    try:
        one = {name: cpu_best(lambda name=name: fa._draw(name)) for name in ("motion", "tracking", "winding")}
    finally:
        fa._JOB = None
    parts.append(("plot_analysis in one process", sum(one.values()), "CPU"))
    parts += [(f"  {name}.png alone", t, "CPU") for name, t in one.items()]
    parts.append(("plot_identification", cpu_best(lambda: fa.plot_identification(run, ident, out)), "CPU"))
    rows = [
        [label, str(samples), what, kind, f"{t:.3f}", f"{base:.3f}", f"{t / base:.1f}"]
        for what, t, kind in parts
    ]
    with_plots = cli(bag, out / "cli", no_plots=False)
    without = cli(bag, out / "cli", no_plots=True)
    cli_rows = [[label, f"{with_plots:.2f}", f"{without:.2f}", f"{with_plots - without:.2f}"]]
    return rows, cli_rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--bag", nargs="*", default=None, help="measure these bags instead of recording")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="winder-bench-plots-"))
    rows: list[list[str]] = []
    cli_rows: list[list[str]] = []
    try:
        bags = (
            [Path(b) for b in args.bag]
            if args.bag
            else [record(r, work) for r in ([200.0] if args.quick else [200.0, 2000.0])]
        )
        for bag in bags:
            out = work / "plots"
            out.mkdir(exist_ok=True)
            r, c = measure(bag, out)
            rows += r
            cli_rows += c
    finally:
        shutil.rmtree(work, ignore_errors=True)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    print(f"Figures of the default job ({cores} cores; best of 3; bag read and digested beforehand)")
    print("anchor: one 15 x 12 in figure with a plain line through as many points as the run's joint states")
    print(table(["joint states", "samples", "what", "time", "s", "anchor s", "time / anchor"], rows))
    print()
    print("winder analyze BAG as a process (best of 3 wall times)")
    print(table(["joint states", "with plots s", "--no-plots s", "plots cost s"], cli_rows))
    print("target: the plots of the default job under 1 s")


if __name__ == "__main__":
    main()
