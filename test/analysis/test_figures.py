"""winder.analysis.figures.analysis: what the figures keep of the data, where
their legends go, and that every figure of a recorded run is written.

The oracles are loops written here: the samples of each pixel column found one
by one, the occupied pixels of a grid, the data points under a legend in the
axes' own display coordinates.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from winder.analysis.figures.analysis import (
    _figure,
    envelope,
    envelope_indices,
    pixel_points,
    place_legend,
    plot_analysis,
    plot_identification,
)
from winder.contract.eq7 import layer_of_samples
from winder.contract.stream import describe_job, parse_job_description
from winder.motion.job import Job

# -- the envelope: every pixel column keeps its first, last, lowest and highest sample ----------


def cell_by_hand(v: float, lo: float, hi: float, k: int) -> int:
    """The cell of v among k cells of equal width over [lo, hi], one value at a time."""
    v, lo, hi = float(v), float(lo), float(hi)
    if not hi > lo:
        return 0
    if math.isfinite(hi - lo):
        return min(math.floor((v - lo) / (hi - lo) * k), k - 1)
    return min(math.floor((v / 2 - lo / 2) / (hi / 2 - lo / 2) * k), k - 1)  # hi - lo overflows


def columns_by_hand(x: list[float], columns: int) -> list[int]:
    """The pixel column of each sample: columns of equal width over x's range."""
    return [cell_by_hand(v, x[0], x[-1], columns) for v in x]


def check_envelope(x: list[float], y: list[float], columns: int) -> None:
    idx = [int(i) for i in envelope_indices(np.array(x), np.array(y), columns)]
    assert idx == sorted(set(idx)) and all(0 <= i < len(x) for i in idx)  # samples, in their order
    if len(x) <= 4 * columns:
        assert idx == list(range(len(x)))
        return
    col = columns_by_hand(x, columns)
    kept = set(idx)
    for c in sorted(set(col)):
        members = [i for i in range(len(x)) if col[i] == c]
        mine = [i for i in idx if col[i] == c]
        assert members[0] in kept and members[-1] in kept  # where the line enters and leaves
        assert len(mine) <= 4
        finite = [y[i] for i in members if not math.isnan(y[i])]
        if finite:
            shown = [y[i] for i in mine if not math.isnan(y[i])]
            assert min(shown) == min(finite) and max(shown) == max(finite)


finite_y = st.floats(-1e6, 1e6, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(
    st.lists(st.tuples(st.floats(0, 1e3), st.one_of(finite_y, st.just(math.nan))), min_size=1, max_size=300),
    st.integers(1, 40),
)
@example([(0.0, 1.0), (1e-320, 2.0), (2e-320, -1.0), (3e-320, 0.5)] * 3, 2)  # a subnormal time range
@example([(-1.7e308, 1.0), (0.0, 2.0), (1.7e308, -1.0)] * 5, 3)  # a range beyond the largest float
def test_envelope_keeps_each_columns_extremes(samples: list[tuple[float, float]], columns: int) -> None:
    x = sorted(s[0] for s in samples)  # a time: it does not decrease (equal values allowed)
    y = [s[1] for s in samples]
    check_envelope(x, y, columns)


@settings(max_examples=100, deadline=None)
@given(st.integers(200, 3000), st.integers(1, 30), st.integers(0, 2**31))
def test_envelope_of_a_sampled_signal_with_spikes(n: int, columns: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.exponential(1.0, n))
    y = np.sin(t / 7) + 0.01 * rng.standard_normal(n)
    y[rng.integers(0, n, 3)] = rng.choice([-50.0, 50.0], 3)
    check_envelope(t.tolist(), y.tolist(), columns)


def test_a_spike_one_sample_wide_survives() -> None:
    """The stride-thinned traces lost such a spike; the envelope never does."""
    t = np.arange(1_000_000) / 2000.0
    y = np.zeros(t.size)
    y[777_777] = 3.5
    xe, ye = envelope(t, y, 450)
    assert ye.max() == 3.5 and xe[np.argmax(ye)] == t[777_777]
    assert xe.size <= 4 * 450


def test_envelope_refuses_what_it_cannot_cut() -> None:
    with pytest.raises(ValueError, match="must not decrease"):
        envelope_indices(np.array([0.0, 2.0, 1.0] * 10), np.zeros(30), 2)
    with pytest.raises(ValueError, match="columns"):
        envelope_indices(np.zeros(3), np.zeros(3), 0)


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.tuples(finite_y, finite_y), min_size=2, max_size=400),
    st.integers(1, 20),
    st.integers(1, 20),
)
@example([(0.0, 0.0), (0.0, 2.225073858507e-311)] * 3, 1, 1)  # a subnormal range (k / range overflowed)
@example([(0.0, 0.0), (1e-320, 3e-320), (5e-321, 0.0)] * 2, 2, 3)
@example([(-1.7e308, 0.0), (1.7e308, 1.0), (0.0, 0.5)] * 2, 2, 2)  # a range beyond the largest float
def test_pixel_points_keep_one_dot_per_occupied_pixel(
    pts: list[tuple[float, float]], nx: int, ny: int
) -> None:
    x = np.array([p[0] for p in pts])
    y = np.array([p[1] for p in pts])
    idx = [int(i) for i in pixel_points(x, y, nx, ny)]
    assert idx == sorted(set(idx))
    if len(pts) <= nx * ny // 4:
        assert idx == list(range(len(pts)))
        return

    cells = [
        (cell_by_hand(a, x.min(), x.max(), nx), cell_by_hand(b, y.min(), y.max(), ny))
        for a, b in zip(x, y, strict=True)
    ]
    first: dict[tuple[int, int], int] = {}
    for i, c in enumerate(cells):
        first.setdefault(c, i)
    assert idx == sorted(first.values())


# -- legends ------------------------------------------------------------------------------------


def points_under(ax: Any, leg: Any, renderer: Any) -> int:
    """Data points of the axes' lines inside the legend's box (display pixels)."""
    box = leg.get_window_extent(renderer)
    n = 0
    for line in ax.lines:
        xy = ax.transData.transform(np.asarray(line.get_xydata()))
        inside = (xy[:, 0] >= box.x0) & (xy[:, 0] <= box.x1) & (xy[:, 1] >= box.y0) & (xy[:, 1] <= box.y1)
        n += int(np.count_nonzero(inside))
    return n


def test_a_legend_takes_the_free_corner() -> None:
    fig, renderer = _figure((6, 4))
    ax = fig.add_subplot()
    t = np.linspace(0, 10, 4000)
    # a line along the top and one down the left side: only the lower right is free
    ax.plot(t, 10 + 0.2 * np.sin(40 * t), lw=0.5, label="along the top")
    ax.plot(0.3 + 0.1 * np.sin(40 * t), t, lw=0.5, label="down the left")
    leg = place_legend(ax, renderer)
    assert leg is not None
    assert points_under(ax, leg, renderer) == 0
    assert leg.get_window_extent(renderer).x0 > ax.bbox.x0 + 0.5 * ax.bbox.width  # the right half
    assert leg.get_window_extent(renderer).y1 < ax.bbox.y0 + 0.5 * ax.bbox.height  # the lower half


def test_a_legend_over_dense_data_gets_a_band_of_its_own() -> None:
    """Noise over the whole panel: no corner is free, so the y range grows a
    band above the data and the legend goes there; loc='best' covers data."""

    def dense() -> tuple[Any, Any]:
        fig, renderer = _figure((6, 4))
        ax = fig.add_subplot()
        rng = np.random.default_rng(1)
        t = np.arange(20_000) / 100.0
        ax.plot(t, rng.uniform(-1, 1, t.size), lw=0.3, label="noise")
        ax.plot(t, np.sin(t), lw=1.0, label="a sine")
        ax.plot(t[::50], rng.uniform(-1, 1, t[::50].size), ".", ms=2, label="dots")
        ax.get_xlim(), ax.get_ylim()  # autoscaled now, as when the figure is drawn
        return ax, renderer

    ax, renderer = dense()
    assert points_under(ax, ax.legend(loc="best"), renderer) > 0  # matplotlib's own choice
    ax, renderer = dense()
    lo, hi = ax.get_ylim()
    leg = place_legend(ax, renderer)
    assert leg is not None
    assert ax.get_ylim()[1] > hi and ax.get_ylim()[0] == lo
    assert points_under(ax, leg, renderer) == 0


# -- the settled MRAS estimate is in test_identify.py; eq. 7 of a coil wound backward ----------


def test_a_coil_wound_backward_is_measured_against_its_own_layer() -> None:
    """Coil 3 winds its fork backward over the fork range of coil 2's second
    layer: a sample taken while it is wound belongs to it (its layer starts
    after the others, so a search by start alone gave it to coil 2)."""
    job = Job(turns_per_layer=5, poles=3, coil_overrides="2:turns_per_layer=8;3:direction=ccw,layers=1")
    plan = parse_job_description(describe_job(job))
    seg, ys, want = [], [], []
    for i, s in enumerate(plan.segments):
        if s.kind != "layer":
            continue
        for f in np.linspace(0.02, 0.98, 25):
            seg.append(i)
            ys.append(s.start[1] + f * s.delta[1])
            want.append(i)
    assert plan.segments[want[-1]].delta[1] < 0  # the backward coil is there
    got = layer_of_samples(plan, np.array(seg), np.array(ys))
    assert got.tolist() == want


# -- every figure of a recorded run ----------------------------------------------------------------


def _looked_at(path: Path) -> None:
    import matplotlib.image as mpimg

    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    img = mpimg.imread(path)
    assert img.shape[0] >= 700 and img.shape[1] >= 1200
    assert np.std(img) > 0.05  # not a blank canvas


@pytest.mark.ros
@pytest.mark.parametrize(
    ("name", "figures"),
    [
        ("trap", ["motion", "tracking", "winding", "wound"]),
        ("lin2k", ["motion", "tracking", "winding", "wound"]),  # 2 kHz: the envelope cuts the long lines
        ("abort", ["motion", "tracking", "winding", "operations", "wound"]),  # an operator's command
        ("pole1", ["motion", "tracking", "winding", "wound"]),  # an axis that never moves
    ],
)
@pytest.mark.parametrize("processes", ["forked", "one"])
def test_plots_are_written(
    bag: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, name: str, figures: list[str], processes: str
) -> None:
    from winder.analysis import identify as ident
    from winder.analysis.figures import analysis as fa
    from winder.analysis.metrics import analyze, digest_run
    from winder.record.reader import read_run

    if processes == "one":
        monkeypatch.setattr(fa, "_draw_all", lambda names: [fa._draw(n) for n in names])
    run = read_run(bag(name))
    d = digest_run(run)
    paths = plot_analysis(run, analyze(run, digested=d), tmp_path, digested=d)
    assert paths == [tmp_path / f"{f}.png" for f in figures]
    for p in paths:
        _looked_at(p)
    (p,) = plot_identification(run, ident.identify(run), tmp_path)
    assert p == tmp_path / "identify.png"
    _looked_at(p)


def test_a_figure_that_fails_is_named_and_the_others_are_still_drawn() -> None:
    """A bug in one figure (here: drawn with no run set up) ends in
    FigureError naming each figure and its error; winder analyze prints it in
    one line and exits 1 instead of a traceback."""
    from winder.analysis.figures import analysis as figures

    assert figures._JOB is None
    with pytest.raises(figures.FigureError) as err:
        figures._draw_all(["motion", "wound"])
    assert err.value.drawn == [] and len(err.value.failed) == 2
    assert err.value.failed[0].startswith("motion.png: AssertionError")
