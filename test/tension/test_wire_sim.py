"""winder.tension.sim, the wire of a simulated run, against scipy's lsim of
the same tensioner driven by the take-up speed (its input linear between
samples), and the wire's conservation: what the coil took = what the supply
paid out + what the span and the tensioner hold."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal

from winder.motion.takeup import Contour
from winder.tension.sim import WireSim
from winder.tension.tensioner import Tensioner


@pytest.mark.parametrize(("kind", "spool"), [("servo", "driven"), ("dancer", "driven"), ("dancer", "braked")])
def test_the_wire_of_a_run_is_lsims_and_conserved(kind: str, spool: str) -> None:
    tensioner = Tensioner(kind, 2e4, 4.0, supply=spool)
    rect = Contour(0.03, 0.012, 0.002)
    contours: dict[int, Contour | None] = {0: rect, 1: None, 2: rect}
    rate = 2000.0
    t = np.arange(6000) / rate
    # the flyer: ramps up, cruises, ramps down, an index move (segment 1), winds back the other way
    omega = np.interp(t, [0, 0.5, 1.0, 1.2, 1.4, 2.0, 2.5, 3.0], [0, 40, 40, 0, 0, -30, -30, 0])
    psi = np.concatenate([[0.0], np.cumsum((omega[1:] + omega[:-1]) / 2 / rate)])
    seg = np.where(t < 1.2, 0, np.where(t < 1.4, 1, 2))
    sim = WireSim(tensioner, contours, 0.08, 1 / rate)
    parts = [sim.advance(psi[a:b], omega[a:b], seg[a:b]) for a, b in ((0, 1000), (1000, 1001), (1001, 6000))]
    tension = np.concatenate([p.tension for p in parts])
    supply = np.concatenate([p.supply for p in parts])
    v = np.concatenate([p.takeup for p in parts])
    # the take-up: |omega| h(psi), mirrored for the coil wound the other way, none while indexing
    want_v = np.where(seg == 1, 0.0, np.abs(omega) * rect.lever(np.where(omega >= 0, psi, -psi), 0.08))
    assert np.allclose(v, want_v, rtol=1e-12, atol=1e-15)
    a, b, c, d = tensioner.matrices()
    _, y, x = scipy.signal.lsim((a, b[:, None], c, d[:, None]), want_v, t)
    assert np.allclose(tension, np.maximum(4.0 + y[:, 0], 0.0), rtol=1e-7, atol=1e-7)
    taken = np.concatenate([[0.0], np.cumsum((want_v[1:] + want_v[:-1]) / 2 / rate)])
    held = x[:, 0] / 2e4 if kind == "servo" else x[:, 0] + 2 * x[:, 1]
    assert np.allclose(supply, taken - held, rtol=1e-7, atol=1e-9)
    if spool == "braked":  # what the spool paid out is what it turned: its speed's integral
        turned = np.concatenate([[0.0], np.cumsum((x[1:, 3] + x[:-1, 3]) / 2 / rate)])
        assert np.allclose(supply, turned, rtol=1e-6, atol=1e-6 * taken[-1])
    assert math.isclose(sim.peak, float(tension.max())) and math.isclose(sim.least, float(tension.min()))


def test_a_round_core_at_constant_speed_holds_the_set_tension() -> None:
    round_ = Contour(0.02, 0.02, 0.01)
    sim = WireSim(Tensioner("dancer", 3e4, 2.0), {0: round_}, 0.05, 1e-3)
    omega = np.full(3000, 25.0)
    psi = 25.0 * np.arange(3000) * 1e-3
    sim.advance(psi[:1], np.zeros(1), np.zeros(1, np.int64))  # from rest
    out = sim.advance(psi[1:], omega[1:], np.zeros(2999, np.int64))
    # a step of the take-up speed at the start, then steady: the tension settles back to the set
    assert abs(out.tension[-1] - 2.0) < 1e-6 and abs(out.coordinate[-1]) < 1e-6
    assert math.isclose(out.takeup[-1], 25.0 * 0.01, rel_tol=1e-12)


def test_a_coil_as_wound_is_lsims_of_its_commanded_flyer() -> None:
    """winder.tension.predict.predict_coil: a layer (one S-curve move of the
    flyer), a dwell, a layer wound back; against scipy's lsim of the take-up
    worked out here from the move's own samples, on a grid 8 times finer."""
    from winder.motion.timing import plan_segment
    from winder.tension.predict import CoilMove, predict_coil

    values = {
        "profile": "scurve", "v_max": 3000.0, "a_max": 3e4, "j_max": 1e6, "v_start": 0.0,
        "tau": 0.0, "dwell": 0.0, "shaper": "none", "shaper_freq": 50.0, "shaper_zeta": 0.0,
    }  # fmt: skip
    move = plan_segment(values, 6 * 512)
    rect = Contour(0.03, 0.012, 0.002)
    rad = 2 * math.pi / 512
    t1 = move.duration + 0.2  # the second layer after a 0.2 s dwell
    coil = [
        CoilMove(0.0, (0.0,), (move,), rad, 1.0, 0.0, rect, 1),
        CoilMove(t1, (0.0,), (move,), -rad, 1.0, 6 * 2 * math.pi, Contour(0.031, 0.013, 0.0025), 2),
    ]
    tensioner = Tensioner("dancer", 2e4, 4.0)
    from winder.motion.material import MATERIALS, Wire

    wire = Wire(MATERIALS["copper"], 0.45e-3)
    rate = 4000.0
    got = predict_coil(coil, 0.08, tensioner, wire, rate)
    # here: the flyer's angle and speed from the move, the take-up, lsim on a finer grid
    fine = 8 * rate
    t = np.arange(0, math.floor((t1 + move.duration) * fine) + 1) / fine
    v = np.zeros(t.size)
    layer = np.zeros(t.size, int)
    for seg in coil:
        local = t - seg.t0
        on = (local >= 0) & (local <= move.duration)
        p, w, _, _ = move.sample(local[on])
        psi = seg.psi0 + p * seg.rad_per_step
        assert seg.contour is not None
        v[on] = np.abs(w * seg.rad_per_step) * seg.contour.lever(psi if seg.rad_per_step > 0 else -psi, 0.08)
        layer[on] = seg.layer
    a, b, c, d = tensioner.matrices()
    _, y, _ = scipy.signal.lsim((a, b[:, None], c, d[:, None]), v, t)
    tension = 4.0 + y[:, 0]
    for n in (1, 2):
        want_peak, want_min = tension[layer == n].max(), tension[layer == n].min()
        swing = want_peak - want_min
        assert abs(got[n].peak - want_peak) < 0.02 * swing, (n, got[n], want_peak)
        assert abs(got[n].minimum - want_min) < 0.02 * swing, (n, got[n], want_min)
