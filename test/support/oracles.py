"""Reference computations shared by several test modules: ruckig's
time-optimal stops (test_time_law_commands, test_operator_commands) and the
stepper's textbook step responses (test_stepper_model, test_replay)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import ruckig

_RK = ruckig.Ruckig(1)


def ruckig_change_traj(v: float, a: float, v_to: float, A: float, J: float) -> Any:
    """ruckig's time-optimal velocity-mode change from (v, a) to (v_to, 0).
    ruckig refuses a current acceleration at its limit to the last bit (the
    states on a planned move sit there): the limit a hair above, 1e-12 of it;
    and for a few states well inside the limits it refuses that hair (step 1
    finds no profile: v = 532.58, a = 0, A = 10**4.75, J = 10**6.78125, found
    by hypothesis on a fresh clone): then the limit itself."""
    inp = ruckig.InputParameter(1)
    inp.control_interface = ruckig.ControlInterface.Velocity
    inp.current_position, inp.current_velocity, inp.current_acceleration = [0.0], [v], [a]
    inp.target_velocity, inp.target_acceleration = [v_to], [0.0]
    inp.max_velocity, inp.max_jerk = [1e12], [J]
    for limit in (A * (1 + 1e-12), A):
        inp.max_acceleration = [limit]
        traj = ruckig.Trajectory(1)
        try:
            result = _RK.calculate(inp, traj)
        except ruckig.RuckigError:
            continue
        assert result in (ruckig.Result.Working, ruckig.Result.Finished)
        return traj
    raise AssertionError(f"ruckig found no change from v={v!r}, a={a!r} to {v_to!r} (A={A!r}, J={J!r})")


def ruckig_stop(v: float, a: float, v_end: float, A: float, J: float) -> tuple[float, float]:
    """Duration and distance of ruckig's time-optimal stop to ``v_end`` from (v, a)."""
    traj = ruckig_change_traj(v, a, v_end, A, J)
    return traj.duration, float(traj.at_time(traj.duration)[0][0])


def ruckig_change(v: float, a: float, v_to: float, A: float, J: float) -> float:
    """Distance of ruckig's time-optimal change from (v, a) to (v_to, 0)."""
    traj = ruckig_change_traj(v, a, v_to, A, J)
    return float(traj.at_time(traj.duration)[0][0])


def params(Zr: float, L: float, i_a: float, J: float, D: float) -> tuple[float, float, float]:
    """(w_n, zeta, K) from the paper's eq. 12, computed here."""
    K = 0.5 * Zr**2 * L * i_a**2
    return math.sqrt(K / J), D / (2 * math.sqrt(K * J)), K


def textbook_step(wn: float, zeta: float, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit step response s(tau) of w_n^2/(s^2 + 2 zeta w_n s + w_n^2) and its derivative."""
    tau = np.asarray(tau, dtype=float)
    if zeta < 1:
        wd = wn * math.sqrt(1 - zeta**2)
        ex = np.exp(-zeta * wn * tau)
        s = 1 - ex * (np.cos(wd * tau) + zeta * wn / wd * np.sin(wd * tau))
        ds = wn**2 / wd * ex * np.sin(wd * tau)
    elif zeta == 1:
        ex = np.exp(-wn * tau)
        s = 1 - ex * (1 + wn * tau)
        ds = wn**2 * tau * ex
    else:
        r = math.sqrt(zeta**2 - 1)
        p1, p2 = -wn * (zeta - r), -wn * (zeta + r)
        s = 1 - (p2 * np.exp(p1 * tau) - p1 * np.exp(p2 * tau)) / (p2 - p1)
        ds = p1 * p2 * (np.exp(p2 * tau) - np.exp(p1 * tau)) / (p2 - p1)
    return s, ds


def superpose(
    wn: float, zeta: float, times: np.ndarray, angles: np.ndarray, t: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """theta(t), omega(t): sum of the step responses, one per step (step at t applied)."""
    th = np.zeros(t.size)
    om = np.zeros(t.size)
    for tk, a in zip(times, angles, strict=True):
        on = t >= tk
        s, ds = textbook_step(wn, zeta, t[on] - tk)
        th[on] += a * s
        om[on] += a * ds
    return th, om
