"""winder.analysis.identify: J and D of the axes, against the values the simulation used.

The reference values are read from the bag's winder/sim_config with json here
(not through winder.record.reader), or set by the test for records synthesised with
winder.axis's exact linear response and its nonlinear integrator.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import rosbags_read
from support.cli import assert_one_line_error, run_cli

from winder.analysis.identify import AxisRecord, identify, identify_axis, with_noise
from winder.axis import StepperAxis
from winder.record.reader import AxisConfig, read_run

AXES = ("feed", "fork", "pole")


def recorded(path: Path) -> dict[str, dict[str, float]]:
    ref = rosbags_read(path)
    topic = next(k for k in ref if k.endswith("/winder/sim_config"))
    axes: dict[str, dict[str, float]] = json.loads(ref[topic][0][1].data)["axes"]
    return axes


@pytest.mark.ros
def test_recorded_j_and_d_within_1_percent(bag: Any) -> None:
    for name in ("lin2k", "nlns", "slip"):
        path = bag(name)
        truth = recorded(path)
        ident = identify(read_run(path))
        assert ident.publish_rate == 2000.0
        for axis in AXES:
            a = ident.axes[axis]
            J, D = truth[axis]["J"], truth[axis]["D"]
            assert a.identifiable, (name, axis, a.reason)
            assert a.J_true == J and a.D_true == D
            # least squares on the exactly integrated model: far better than 1 %
            assert abs(a.ls_J / J - 1) < 1e-3, (name, axis, a.ls_J / J)
            assert abs(a.ls_D / D - 1) < 1e-4, (name, axis, a.ls_D / D)
            assert a.ls_J_err == pytest.approx(a.ls_J / J - 1, rel=1e-12)
            # MRAS from b = 0 with the default gain
            # the last update within 1 %; the settled mean (the last quarter of the updates)
            # within 2 %: on an axis with few windows (the pole's 133) it still holds the approach
            assert abs(a.mras_J_last / J - 1) < 0.01, (name, axis, a.mras_J_last / J)
            assert abs(a.mras_D_last / D - 1) < 0.01, (name, axis, a.mras_D_last / D)
            assert abs(a.mras_J / J - 1) < 0.02, (name, axis, a.mras_J / J)
            assert abs(a.mras_D / D - 1) < 0.02, (name, axis, a.mras_D / D)
            assert a.mras_iterations_1pct is not None and a.mras_iterations_1pct <= a.mras_iterations
            tr = a.trajectory
            assert tr is not None and tr.J[-1] == a.mras_J_last and tr.D[-1] == a.mras_D_last
            # the settled figure: mean, min and max over the last quarter of the updates, by hand
            for est, mean, band in ((tr.J, a.mras_J, a.mras_J_band), (tr.D, a.mras_D, a.mras_D_band)):
                tail = [float(x) for x in est[len(est) - max(1, len(est) // 4) :] if math.isfinite(x)]
                assert mean == pytest.approx(sum(tail) / len(tail), rel=1e-12)
                assert band == (min(tail), max(tail))
            ok = np.isfinite(tr.J)  # J is NaN while the estimate of 1/J = b/T_s is not yet positive
            np.testing.assert_allclose(tr.b[ok], ident.window / tr.J[ok], rtol=1e-12)  # the thesis' b = T_s/J
            assert np.all(tr.b[~ok] <= 0)
    # the non-default values of nlns are found, not the defaults
    nlns = identify(read_run(bag("nlns")))
    assert nlns.axes["fork"].ls_J == pytest.approx(2e-4, rel=1e-3)
    assert nlns.axes["pole"].ls_J == pytest.approx(5e-5, rel=1e-3)
    assert nlns.axes["feed"].ls_D == pytest.approx(0.01, rel=1e-4)


@pytest.mark.ros
def test_the_thesis_j_only_law_is_far_off_with_damping(bag: Any) -> None:
    """D = 0.03 (damping ratio 0.52) is not negligible: the J-only MRAS of the
    thesis misses J by far more than the law extended to D."""
    ident = identify(read_run(bag("lin2k")))
    for a in ident.axes.values():
        assert abs(a.paper_mras_J_err) > 0.2
        assert abs(a.paper_mras_J_err) > 10 * abs(a.mras_J_err)


@pytest.mark.ros
def test_default_200_hz_sampling(bag: Any) -> None:
    """At the default publish rate the Hermite interpolation between samples
    limits J to about 2 % (D stays within 0.1 %)."""
    path = bag("trap")
    truth = recorded(path)
    ident = identify(read_run(path))
    assert ident.publish_rate == 200.0
    assert any("200 Hz" in n for n in ident.notes)
    for axis in AXES:
        a = ident.axes[axis]
        assert abs(a.ls_J / truth[axis]["J"] - 1) < 0.025, axis
        assert abs(a.ls_D / truth[axis]["D"] - 1) < 1e-3, axis


@pytest.mark.ros
def test_measurement_noise_bounds(bag: Any) -> None:
    """The bounds stated in docs/ANALYSIS.md, on lin2k (2 kHz, 5 ms windows)."""
    run = read_run(bag("lin2k"))
    truth = recorded(bag("lin2k"))
    from winder.analysis.identify import axis_record

    worst: dict[str, np.ndarray] = {}
    for case, kw in {
        "encoder 2^16": {"counts_per_rev": 2**16},
        "encoder 2^18": {"counts_per_rev": 2**18},
        "speed noise 0.1 %": {"omega_sigma": 1e-3},
    }.items():
        w = np.zeros(4)
        for seed in range(4):
            for axis in AXES:
                rec = axis_record(run, axis)
                if "omega_sigma" in kw:
                    noisy = with_noise(rec, omega_sigma=1e-3 * float(np.max(np.abs(rec.omega))), seed=seed)
                else:
                    noisy = with_noise(rec, seed=seed, **kw)
                a = identify_axis(noisy)
                assert a.identifiable, (case, axis, a.reason)
                J, D = truth[axis]["J"], truth[axis]["D"]
                w = np.maximum(
                    w, np.abs([a.ls_J / J - 1, a.ls_D / D - 1, a.mras_J / J - 1, a.mras_D / D - 1])
                )
        worst[case] = w
    assert worst["encoder 2^16"][0] < 0.02 and worst["encoder 2^16"][1] < 1e-3
    assert worst["encoder 2^18"][0] < 0.005 and worst["encoder 2^18"][1] < 1e-4
    assert worst["speed noise 0.1 %"][0] < 0.06 and worst["speed noise 0.1 %"][1] < 1e-4
    # MRAS, a recursive gradient law on noisy regressors, is far more sensitive
    assert worst["encoder 2^18"][2] < 0.25
    assert worst["encoder 2^16"][2] > worst["encoder 2^16"][0]


@pytest.mark.ros
def test_an_axis_that_does_not_move_is_not_identified(bag: Any) -> None:
    path = bag("pole1")
    ident = identify(read_run(path))
    pole = ident.axes["pole"]
    assert not pole.identifiable
    assert pole.reason.startswith("not identifiable: too little excitation")
    assert math.isnan(pole.ls_J) and math.isnan(pole.mras_J)
    assert ident.axes["fork"].identifiable and ident.axes["feed"].identifiable
    r = run_cli("identify", str(path), "--no-plots")
    assert r.returncode == 0, r.stderr
    assert "pole  not identifiable: too little excitation (the pole axis moved 0 steps" in r.stdout
    j = run_cli("identify", str(path), "--json", "--no-plots")
    assert j.returncode == 0, j.stderr
    out = json.loads(j.stdout)[0]["axes"]
    assert out["pole"]["identifiable"] is False and out["pole"]["ls_J"] is None
    assert out["fork"]["identifiable"] is True and len(out["fork"]["mras_trajectory"]["J"]) > 10


@pytest.mark.ros
def test_cli_rejects_bad_settings(bag: Any) -> None:
    path = str(bag("pole1"))
    assert_one_line_error(
        run_cli("identify", path, "--gain", "0"), "gain=0.0 is invalid: must be in [1e-06, 1e+06]"
    )
    assert_one_line_error(run_cli("identify", path, "--window", "abc"), "window='abc' is invalid")


# -- synthetic records: winder.axis's responses, no nodes -----------------------------------


def _record(model: str, J: float, D: float, load: float, rate: float) -> AxisRecord:
    """A ramp to 3000 steps/s at 4e4 steps/s^2, cruise, stop without ramp; 1/32 microsteps."""
    a, v = 4.0e4, 3000.0
    k = np.arange(1, 3001)
    k_ramp = v * v / (2 * a)
    t_steps = np.where(k <= k_ramp, np.sqrt(2 * k / a), v / a + (k - k_ramp) / v)
    angle = 2 * math.pi / 5120
    motor = StepperAxis(40.0, 0.01005, 1.0, J, D)
    t = np.arange(0, round((t_steps[-1] + 0.1) * rate)) / rate
    if model == "linear":
        theta, omega = motor.response(t_steps, angle, t, velocity=True)
    else:
        res = motor.simulate(t_steps, angle, t, load=load, model="nonlinear")
        theta, omega = res.theta, res.omega
    cfg = AxisConfig(40.0, 0.01005, 1.0, J, D, angle, load)
    return AxisRecord("fork", t, theta, omega, t_steps, k * angle, 0.0, cfg, model)


@pytest.mark.parametrize(
    ("model", "J", "D", "load"),
    [("linear", 2.3e-4, 0.011, 0.0), ("nonlinear", 6.0e-5, 0.02, 0.05), ("nonlinear", 1.5e-4, 0.004, 0.0)],
)
def test_synthetic_records(model: str, J: float, D: float, load: float) -> None:
    a = identify_axis(_record(model, J, D, load, 5000.0))
    assert a.identifiable, a.reason
    assert a.ls_J == pytest.approx(J, rel=1e-3)
    assert a.ls_D == pytest.approx(D, rel=1e-4)
    assert a.mras_J_last == pytest.approx(J, rel=0.01)
    assert a.mras_D_last == pytest.approx(D, rel=0.01)
    # the settled figure is the last quarter's mean and band: on a move this short (3000
    # steps) the estimate is still approaching there, and the band says so
    assert a.mras_J_band[0] <= a.mras_J <= a.mras_J_band[1]
    assert a.mras_J_band[0] <= a.mras_J_last <= a.mras_J_band[1]


def test_the_settled_estimate_is_the_last_quarter_by_hand() -> None:
    """The settled MRAS figure of the table, the JSON and the figure: the mean
    of the estimate over the last quarter of its updates, its min and max
    there, its relative standard deviation, the time that quarter starts, and
    the error of the mean against the recorded J, all computed here from the
    estimate series with a plain loop."""
    from winder.analysis.identify import Identification, identification_json

    J, D = 1.5e-4, 0.004
    a = identify_axis(_record("nonlinear", J, D, 0.0, 2000.0))
    tr = a.trajectory
    assert a.identifiable and tr is not None
    n = len(tr.J)
    start = n - max(1, n // 4)
    for series, mean, band, true, err in (
        (tr.J, a.mras_J, a.mras_J_band, J, a.mras_J_err),
        (tr.D, a.mras_D, a.mras_D_band, D, a.mras_D_err),
    ):
        tail = [float(series[i]) for i in range(start, n) if math.isfinite(series[i])]
        by_hand = sum(tail) / len(tail)
        assert mean == pytest.approx(by_hand, rel=1e-12)
        assert band == (min(tail), max(tail))
        assert err == pytest.approx(by_hand / true - 1, rel=1e-9)
    tail_j = [float(tr.J[i]) for i in range(start, n)]
    m = sum(tail_j) / len(tail_j)
    std = math.sqrt(sum((x - m) ** 2 for x in tail_j) / len(tail_j))
    assert a.mras_spread == pytest.approx(std / m, rel=1e-9)
    assert a.mras_settled_from == float(tr.t[start])
    assert a.mras_J_last == float(tr.J[-1])
    # the JSON carries the same figures
    ident = Identification("x", "x", "nonlinear", 2000.0, 0.005, 3.0, True, {"fork": a})
    out = json.loads(identification_json([ident]))[0]["axes"]["fork"]
    assert out["mras_J"] == a.mras_J and out["mras_J_band"] == list(a.mras_J_band)
    assert out["mras_settled_from"] == a.mras_settled_from and out["mras_spread"] == a.mras_spread
    assert out["mras_J_err"] == a.mras_J_err


def test_an_error_that_rounds_to_zero_prints_without_a_sign() -> None:
    from winder.analysis.identify import _pct

    assert [_pct(x) for x in (-1e-9, 0.0, 1e-9, -2e-5, 0.01234, math.nan)] == [
        "0.000 %",
        "0.000 %",
        "0.000 %",
        "-0.002 %",
        "+1.234 %",
        "-",
    ]


def test_the_settled_estimate_of_a_known_series() -> None:
    """Eight updates, one not yet a positive 1/J (NaN): the last two are the quarter."""
    from winder.analysis.identify import Mras

    t = np.arange(8.0)
    J = np.array([np.nan, 5.0, 4.0, 3.0, 2.0, 1.1, 0.9, 1.2])
    tr = Mras(t, J, 0.5 * J, np.zeros(8), 3.0)
    assert tr.settle_start == 6
    assert tr.settled[:3] == pytest.approx((1.05, 0.9, 1.2))
    assert tr.spread == pytest.approx(0.15 / 1.05)
    one = Mras(t[:3], J[:3], J[:3], np.zeros(3), 3.0)  # fewer than four updates: the last one
    assert one.settle_start == 2 and one.settled[0] == 4.0


@pytest.mark.ros
def test_cli_identifies_several_bags_one_after_another(bag: Any) -> None:
    """`winder identify bags/rw400_*` with two bags: a table for each (it was
    'unrecognized arguments'); the help shows percent signs, not '%%'."""
    a, b = str(bag("pole1")), str(bag("trap"))
    r = run_cli("identify", a, b, "--no-plots")
    assert r.returncode == 0, r.stderr
    assert r.stdout.count("not identifiable: too little excitation") >= 1
    j = run_cli("identify", a, b, "--json", "--no-plots")
    assert j.returncode == 0, j.stderr
    assert [Path(x["path"]).name for x in json.loads(j.stdout)] == [Path(a).name, Path(b).name]
    h = run_cli("identify", "--help")
    assert "0.1 % accuracy" in h.stdout.replace("\n", " ") and "%%" not in h.stdout


# -- the window and the gain bounded (issue 53) --------------------------------------------------------


def test_a_window_longer_than_the_recording_holds_no_equation() -> None:
    """``winder identify --window 1e308`` was an internal error: the window's
    samples (1e308 / the sample interval) were a dimension numpy refused."""
    from winder.analysis.identify import equations

    rec = _record("linear", 2.3e-4, 0.011, 0.0, 2000.0)
    for window in (1e308, 10.0, float(rec.t[-1] - rec.t[0]) * 2):
        eq = equations(rec, window)
        assert eq.q.size == eq.dw.size == eq.t.size == 0, window
    a = identify_axis(rec, window=10.0)
    assert not a.identifiable and a.reason.startswith("not identifiable: too little excitation")


@pytest.mark.parametrize(("gain", "window"), [(1e308, 0.005), (1e-308, 0.005), (0.0, 0.005), (3.0, 1.5)])
def test_identify_refuses_a_gain_or_window_out_of_its_range(gain: float, window: float) -> None:
    from winder.analysis.identify import GAIN_RANGE, WINDOW_MAX, Equations, mras
    from winder.errors import BadInputError

    assert GAIN_RANGE == (1e-6, 1e6) and WINDOW_MAX == 1.0
    empty = np.zeros(0)
    with pytest.raises(BadInputError) as err:
        if window > WINDOW_MAX:
            identify(None, gain=gain, window=window)  # type: ignore[arg-type]
        else:
            mras(Equations(empty, empty, empty, empty, 0.005, np.zeros(0, dtype=bool), 0), gain)
    text = str(err.value)
    assert "\n" not in text and ("must be in [1e-06, 1e+06]" in text or "must be in (0, 1] s" in text), text


@pytest.mark.parametrize("gain", [1e-6, 1e6])
def test_the_mras_law_at_either_end_of_its_gains_overflows_nothing(gain: float) -> None:
    """Landau's law formed beta x phi x e before dividing: at beta 1e308 it
    overflowed (numpy's warnings, and an exit status of 0). Formed as
    phi e / (1/beta + phi.phi) no product leaves the floats; at the highest
    gain it is the normalised projection law, and still finds J."""
    import warnings

    J, D = 2.3e-4, 0.011
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        a = identify_axis(_record("linear", J, D, 0.0, 5000.0), gain=gain)
    assert a.identifiable, a.reason
    if gain > 1:
        assert a.mras_J_last == pytest.approx(J, rel=0.05)
