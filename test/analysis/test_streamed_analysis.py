"""The analysis streams the step rows: the same numbers however the step
rows are cut into chunks, and memory that does not grow with the job.

* the sliding kinematics stencil against a whole-array implementation written
  here (the one the analysis used before it streamed), over random moves and
  random cuts (hypothesis);
* the identification's integrals, bit for bit, whatever the event batches;
* ``analyze`` and ``identify`` of recorded runs (bags of the real nodes, ros
  marked) against the same run with its rows held in memory and handed out
  in chunks of 1, 7, 1000 rows and all at once;
* a synthetic 4-million-step run, generated chunk by chunk and never held
  whole (160 MB of rows): ``analyze`` and ``identify`` allocate a small
  fraction of that at their peak (tracemalloc, which numpy reports to).
"""

from __future__ import annotations

import dataclasses
import json
import math
import tracemalloc
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from winder.analysis.digest import END_STRIDES, STRIDE_TIME, SegmentKinematics
from winder.analysis.identify import AxisRecord, equations, identify
from winder.analysis.metrics import analyze, to_json
from winder.contract.stream import describe_job, parse_job_description
from winder.motion.interp import min_deviation
from winder.motion.job import Job
from winder.record.reader import AxisConfig, Run, Samples, SimConfig, StepArray, read_run

F = npt.NDArray[np.float64]


# -- the kinematics stencil ------------------------------------------------------------


def whole_array_kinematics(t_ns: F, stride_time: float = STRIDE_TIME) -> tuple[F, ...]:
    """Velocity, acceleration and jerk from the step times of a whole move at
    once (second-order central differences over a stride of m steps spanning
    at least stride_time, END_STRIDES strides from either end; the jerk the
    difference quotient of the acceleration a stride either side)."""
    t = np.asarray(t_ns, dtype=np.float64)
    n = t.size
    empty = np.zeros(0)
    if n < 2 * END_STRIDES + 1:
        return empty, empty, empty, empty
    k = np.arange(n)
    local = np.full(n, np.nan)
    local[1:-1] = (t[2:] - t[:-2]) / 2e9
    local[0], local[-1] = (t[1] - t[0]) / 1e9, (t[-1] - t[-2]) / 1e9
    with np.errstate(invalid="ignore", divide="ignore"):
        m = np.ceil(stride_time / local)
    m = np.where(np.isfinite(m), np.clip(m, 1, max(1, (n - 1) // (2 * END_STRIDES + 1))), 1).astype(np.int64)
    fits = (k >= END_STRIDES * m) & (k <= n - 1 - END_STRIDES * m)
    k, m = k[fits], m[fits]
    mf = m.astype(np.float64)
    t0, tp, tm, tp2, tm2 = t[k], t[k + m], t[k - m], t[k + 2 * m], t[k - 2 * m]
    d1 = (tp - tm) / (2 * mf) * 1e-9
    d2 = (tp - 2 * t0 + tm) / mf**2 * 1e-9
    # the jerk: the difference quotient of the acceleration a stride either side
    d1p, d2p = (tp2 - t0) / (2 * mf) * 1e-9, (tp2 - 2 * tp + t0) / mf**2 * 1e-9
    d1m, d2m = (t0 - tm2) / (2 * mf) * 1e-9, (t0 - 2 * tm + tm2) / mf**2 * 1e-9
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        v = 1.0 / d1
        a = -d2 / d1**3
        j = (d2m / d1m**3 - d2p / d1p**3) / ((tp - tm) * 1e-9)
    good = np.isfinite(v) & np.isfinite(a) & np.isfinite(j)
    return t0[good] * 1e-9, v[good], a[good], j[good]


@st.composite
def moves(draw: Any) -> tuple[F, list[int]]:
    """Step times (ns) of a move: a random piecewise-constant-acceleration speed
    profile between 10 and 2e6 steps/s, some steps missing (NaN), and random
    cuts of the step indices into pieces."""
    n = draw(st.integers(1, 40_000))
    pieces = draw(st.integers(1, 6))
    v0 = draw(st.floats(10, 2e6))
    speeds = [v0]
    for _ in range(pieces):
        speeds.append(float(np.clip(speeds[-1] * draw(st.floats(0.05, 20)), 10, 2e6)))
    v = np.interp(np.linspace(0, pieces, n), np.arange(pieces + 1), speeds)
    t = np.concatenate([[0.0], np.cumsum(np.rint(1e9 / v))])[:n]
    holes = draw(st.lists(st.integers(0, n - 1), max_size=5))
    t[holes] = np.nan
    cuts = sorted(set(draw(st.lists(st.integers(1, max(n - 1, 1)), max_size=12))))
    return t, cuts


@settings(max_examples=150, deadline=None)
@given(moves())
def test_the_sliding_stencil_gives_what_the_whole_array_gives(move: tuple[F, list[int]]) -> None:
    t, cuts = move
    got: list[F] = []
    kin = SegmentKinematics(t.size - 1, lambda *x: got.append(np.vstack(x)))
    for lo, hi in zip([0, *cuts], [*cuts, t.size], strict=True):
        kin.add(np.arange(lo, hi, dtype=np.int64), t[lo:hi])
    kin.finish()
    want = np.vstack(whole_array_kinematics(t))
    have = np.hstack(got) if got else np.zeros((4, 0))
    assert kin.lost == 0
    assert have.shape == want.shape
    assert np.array_equal(have, want)


def test_a_stencil_reaching_behind_the_buffer_is_counted_not_guessed() -> None:
    """600 000 steps at 1 kHz, then at 100 MHz: the stride jumps from 2 to
    117 647 steps (the clip for a 2e6-step move), and the stencils of the fast
    part reach behind the step times kept. Those points are left out and
    counted; every point given is the whole-array one."""
    n = 2_000_000
    period = np.where(np.arange(n) < 600_000, 1e6, 10.0)
    t = np.concatenate([[0.0], np.cumsum(period)])[:n]
    got: list[F] = []
    kin = SegmentKinematics(n - 1, lambda *x: got.append(np.vstack(x)))
    for lo in range(0, n, 8192):
        kin.add(np.arange(lo, min(lo + 8192, n), dtype=np.int64), t[lo : lo + 8192])
    kin.finish()
    want = np.vstack(whole_array_kinematics(t))
    have = np.hstack(got)
    assert kin.lost > 0
    assert have.shape[1] + kin.lost == want.shape[1]
    idx = np.searchsorted(want[0], have[0])
    assert np.array_equal(want[:, idx], have)


# -- the identification's integrals ------------------------------------------------------


def _axis(model: str) -> AxisRecord:
    rng = np.random.default_rng(3)
    angle = 2 * math.pi / 5120
    steps = np.cumsum(rng.uniform(1e-4, 3e-3, 4000))
    t = np.arange(0, steps[-1] + 0.05, 1 / 500)
    theta = np.interp(t, steps, np.arange(1, steps.size + 1) * angle) + rng.normal(0, 1e-4, t.size)
    omega = np.gradient(theta, t)
    cfg = AxisConfig(50.0, 0.01, 1.2, 1e-4, 0.02, angle, 0.01)
    return AxisRecord("fork", t, theta, omega, steps, np.arange(1, steps.size + 1) * angle, 0.0, cfg, model)


@pytest.mark.parametrize("model", ["linear", "nonlinear"])
@pytest.mark.parametrize("batch", [1, 3, 97, 4000])
def test_the_integrals_do_not_depend_on_the_event_batches(model: str, batch: int) -> None:
    rec = _axis(model)
    whole = equations(dataclasses.replace(rec, source=lambda: [(rec.step_t, rec.command)]))

    def batches() -> Iterator[tuple[F, F]]:
        for i in range(0, rec.step_t.size, batch):
            yield rec.step_t[i : i + batch], rec.command[i : i + batch]

    cut = equations(dataclasses.replace(rec, source=batches))
    assert np.array_equal(cut.q, whole.q) and np.array_equal(cut.moving, whole.moving)
    assert cut.steps_moved == whole.steps_moved == rec.step_t.size
    # and the integral of a constant command over a sample interval is the plain sum of pieces
    assert np.all(np.isfinite(cut.q))


# -- recorded runs, cut every way --------------------------------------------------------


def same(a: Any, b: Any, path: str = "") -> None:
    """``a`` and ``b`` (decoded JSON) equal, floats to 1e-12 relative (sums
    taken in another order round differently)."""
    assert type(a) is type(b) or {type(a), type(b)} <= {int, float}, path
    if isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for k in a:
            same(a[k], b[k], f"{path}/{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            same(x, y, f"{path}[{i}]")
    elif isinstance(a, float):
        assert math.isclose(a, b, rel_tol=1e-12, abs_tol=1e-18), (path, a, b)
    else:
        assert a == b, (path, a, b)


@pytest.mark.ros
@pytest.mark.parametrize("name", ["lin2k", "nlns", "trap"])
def test_analyze_and_identify_do_not_depend_on_the_chunks(bag: Any, name: str) -> None:
    run = read_run(bag(name))
    rows = run.steps
    assert rows.shape[0] == run.steps_recorded > 0
    streamed_a = json.loads(to_json([analyze(run)]))
    streamed_i = identify(run)
    for chunk in (1, 7, 1000, rows.shape[0]):
        cut = dataclasses.replace(run, step_rows=StepArray(rows, chunk))
        same(json.loads(to_json([analyze(cut)])), streamed_a, f"chunk {chunk}")
        ident = identify(cut)
        for axis, a in ident.axes.items():
            b = streamed_i.axes[axis]
            assert (a.ls_J, a.ls_D, a.mras_J, a.steps_moved) == (b.ls_J, b.ls_D, b.mras_J, b.steps_moved)


# -- memory -------------------------------------------------------------------------------


class LongLayer:
    """The step rows of one long layer at a constant 1e6 steps/s, made chunk by
    chunk each time they are iterated (never all in memory)."""

    def __init__(self, plan: Any, chunk: int = 65536) -> None:
        self.seg = plan.segments[0]
        self.chunk = chunk

    def __len__(self) -> int:
        return int(self.seg.steps)

    def __iter__(self) -> Iterator[npt.NDArray[np.int64]]:
        s = self.seg
        for lo in range(0, s.steps, self.chunk):
            hi = min(lo + self.chunk, s.steps)
            xy = min_deviation(s.delta[0], s.delta[1], start=lo, stop=hi)
            rows = np.empty((hi - lo, 5), np.int64)
            rows[:, 0] = (np.arange(lo, hi) + 1) * 1000
            rows[:, 1] = 0
            rows[:, 2] = s.start[0] + xy[:, 0]
            rows[:, 3] = s.start[1] + xy[:, 1]
            rows[:, 4] = s.start[2]
            yield rows


def long_run(turns: int) -> Run:
    """A one-layer job of ``turns`` turns of 10240 fork steps, wound at 1e6
    steps/s; joint samples at 200 Hz that follow the command."""
    job = Job(job_id="long", turns_per_layer=turns, layers=1, poles=1, fork_steps_per_rev=10240)
    plan = parse_job_description(describe_job(job))
    steps = LongLayer(plan)
    seg = plan.segments[0]
    assert seg.kind == "layer" and seg.steps == turns * 10240
    t = np.arange(0, seg.steps * 1e-6 + 0.05, 1 / 200)
    k = np.clip(np.rint(t * 1e6), 0, seg.steps)
    pos = np.column_stack(
        [k * seg.delta[0] / seg.steps * plan.joint_step[0], k * plan.joint_step[1], np.zeros_like(k)]
    )
    vel = np.gradient(pos, t, axis=0)
    angle = 2 * math.pi / 5120
    motor = AxisConfig(50.0, 0.01, 1.2, 1e-4, 0.02, angle)
    cfg = SimConfig("linear", dict.fromkeys(("feed", "fork", "pole"), motor), 200.0, 0.0)
    return Run(
        path=Path("long"),
        namespace="",
        plan=plan,
        sim_config=cfg,
        step_rows=steps,
        commands=Samples(t, pos, vel),
        states=Samples(t, pos, vel),
        report={"state": "done"},
        profile="scurve",
        closed=True,
        recovered=False,
        counts={},
    )


def peaks(run: Run) -> tuple[int, int]:
    """Peak bytes allocated (tracemalloc) by analyze and by identify of ``run``."""
    tracemalloc.start()
    try:
        res = analyze(run)
        _, peak_analyze = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        ident = identify(run)
        _, peak_identify = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert res.steps_recorded == res.command.points == len(run.step_rows)
    assert ident.axes["fork"].steps_moved == run.plan.segments[0].delta[1]
    return peak_analyze, peak_identify


def test_analyze_and_identify_hold_the_same_memory_for_1e6_and_4e6_steps() -> None:
    small, large = long_run(100), long_run(400)
    rows_bytes = len(large.step_rows) * 5 * 8  # 164 MB
    a1, i1 = peaks(small)
    a4, i4 = peaks(large)
    # flat: four times the steps, the same peak (a chunk, the stencil's buffer, the kept traces)
    assert a4 < 1.2 * a1 + 2e6, f"analyze: {a1 / 1e6:.0f} MB at 1e6 steps, {a4 / 1e6:.0f} MB at 4e6"
    assert i4 < 1.2 * i1 + 2e6, f"identify: {i1 / 1e6:.0f} MB at 1e6 steps, {i4 / 1e6:.0f} MB at 4e6"
    assert max(a4, i4) < rows_bytes / 4, f"{max(a4, i4) / 1e6:.0f} MB"
