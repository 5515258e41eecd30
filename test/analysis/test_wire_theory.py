"""The wire's figures (winder.analysis.figures.wire_theory, ``winder figures``):
what they mark is true of the code they draw from. The take-up's least and
greatest are where the closed forms say, as many times a turn as the core
has flats and corners; the tension over a turn is predict_layer's, its
extremes the same; the job they draw is jobs/ortho_rect.yaml's."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from support.paths import ROOT

from winder.analysis.figures import wire_theory as wt
from winder.cli.commands import FIGURES
from winder.contract.jobfile import load_job_file


def test_the_figures_job_is_ortho_rect() -> None:
    params = load_job_file(ROOT / "jobs" / "ortho_rect.yaml")
    assert params["interp_node"] == wt.ORTHO_RECT
    assert params["profile_node"]["v_max"] == wt.V_MAX


@pytest.mark.parametrize(
    ("core", "least", "dips", "greatest"),
    [("round", 0, 0, 0), ("rectangle 2:1", 2, 2, 4), ("square", 4, 0, 4)],
)
def test_the_takeup_marks_its_flats_and_corners(core: str, least: int, dips: int, greatest: int) -> None:
    omega = wt.top_speed(wt.job_on())
    got = wt.takeup(core, omega)
    c = got.contour
    assert (got.minima.size, got.dips.size, got.maxima.size) == (least, dips, greatest)
    step = float(np.max(np.abs(np.diff(got.speed))))
    assert float(got.speed.min()) == pytest.approx(omega * c.h_min, abs=step)
    assert float(got.speed.max()) == pytest.approx(omega * c.h_max, abs=step)
    # a turn's wire is the contour's length, on every core the same: the mean speed
    assert float(got.speed.mean()) == pytest.approx(omega * c.length / (2 * math.pi), rel=1e-4)
    assert c.length == pytest.approx(wt.layer_one(wt.job_on(wt.CORES["round"])).length, rel=1e-12)
    # the minima half a turn apart on a rectangle, a quarter on a square (the maxima pairwise so)
    if least:
        gaps = np.diff(np.append(got.minima, got.minima[0] + 2 * math.pi))
        assert np.allclose(gaps, 2 * math.pi / least, atol=4 * math.pi / wt.GRID)


def test_the_tension_over_a_turn_is_predict_layers() -> None:
    turns = wt.tension_turns(wt.job_on())
    assert list(turns) == ["dancer", "servo"]
    for runs in turns.values():
        assert [t.omega for t in runs] == pytest.approx([12.2718, 24.5437], rel=1e-4)
        for t in runs:
            assert t.psi.size == t.tension.size
            assert float(t.tension.max()) == t.predicted.peak
            assert max(float(t.tension.min()), 0.0) == t.predicted.minimum
            assert t.tension[0] == pytest.approx(t.tension[-1], abs=1e-9)  # the periodic steady state


def test_winder_figures_writes_them(tmp_path: Path) -> None:
    assert "wire_theory" in FIGURES
    paths = wt.make(tmp_path / "figs")
    assert [p.name for p in paths] == ["wire_takeup.png", "wire_tension.png"]
    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
