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


@pytest.mark.parametrize("kind", ["servo", "dancer"])
def test_the_wire_of_a_run_is_lsims_and_conserved(kind: str) -> None:
    tensioner = Tensioner(kind, 2e4, 4.0)
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
