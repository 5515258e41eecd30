"""Step bookkeeping shared by both trackers (:class:`~winder.axis.linear.LinearTracker`,
:class:`~winder.axis.nonlinear.NonlinearTracker`): the steps no sample has
reached yet and the order rules of their ``advance``."""

from __future__ import annotations

import math

import numpy as np

from winder.axis._checks import FloatArray, _angles, _vector


class _StepQueue:
    """The steps a tracker was given that no sample has reached yet, and the
    order rules of ``advance`` (see :class:`LinearTracker`), shared by both
    trackers."""

    def __init__(self) -> None:
        self.t = np.empty(0)  # pending step times (s)
        self.a = np.empty(0)  # their angles (rad)
        self.last_step = -math.inf
        self.last_sample = -math.inf

    def check(
        self, step_times: object, step_angles: object, t_samples: object
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Validated (step_times, step_angles, t_samples) of one advance() call."""
        return _check_chunk(step_times, step_angles, t_samples, self.last_step, self.last_sample)

    def due(self, st: FloatArray, sa: FloatArray, ts: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Queue the checked steps; return (times, angles) of those at or before
        the last sample (all of them to apply now), the rest stay pending."""
        if st.size:
            self.last_step = float(st[-1])
        ev_t = np.concatenate([self.t, st]) if self.t.size else st
        ev_a = np.concatenate([self.a, sa]) if self.a.size else sa
        if ts.size == 0:
            self.t, self.a = ev_t, ev_a
            return ev_t[:0], ev_a[:0]
        self.last_sample = float(ts[-1])
        n = int(np.searchsorted(ev_t, ts[-1], side="right"))
        self.t, self.a = ev_t[n:], ev_a[n:]
        return ev_t[:n], ev_a[:n]


def _check_chunk(
    step_times: object,
    step_angles: object,
    t_samples: object,
    last_step: float,
    last_sample: float,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Validated (step_times, step_angles, t_samples) of one advance() call."""
    st = _vector("step_times", step_times, sorted_=True)
    sa = _angles(step_angles, st.size)
    if st.size and st[0] < last_step:
        raise ValueError(
            f"step_times[0]={float(st[0])!r} is invalid: must be >= the last step time already "
            f"given ({last_step!r} s)"
        )
    if st.size and st[0] < last_sample:
        raise ValueError(
            f"step_times[0]={float(st[0])!r} is invalid: must be >= the last sample time already "
            f"returned ({last_sample!r} s)"
        )
    ts = _vector("t_samples", t_samples, sorted_=True)
    if ts.size and ts[0] < last_sample:
        raise ValueError(
            f"t_samples[0]={float(ts[0])!r} is invalid: must be >= the last sample time already "
            f"returned ({last_sample!r} s)"
        )
    return st, sa, ts
