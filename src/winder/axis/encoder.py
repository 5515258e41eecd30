"""The encoder that reads the axis: the velocity a controller computes from
its (optionally quantised) angle readings (:func:`measured_velocity`)."""

from __future__ import annotations

import numpy as np

from winder.axis._checks import ArrayLike, FloatArray, _positive, _vector

__all__ = ["measured_velocity"]


def measured_velocity(theta: ArrayLike, period: float, *, resolution: float | None = None) -> FloatArray:
    """Velocity as a controller reads it from an encoder (rad/s).

    ``theta`` are true angles (rad) sampled every ``period`` s. With
    ``resolution`` (rad per count) the encoder reports floor(theta/resolution)
    counts. Returns the backward difference of the readings over one period, the
    same length as ``theta``; the first value is 0 (no earlier reading; the axis
    starts at rest). It estimates the mean velocity over the last period, so it
    lags the true velocity by period/2.
    """
    th = _vector("theta", theta)
    p = _positive("period", period, "s")
    if resolution is not None:
        r = _positive("resolution", resolution, "rad per count")
        th = np.floor(th / r) * r
    v = np.zeros(th.size)
    v[1:] = np.diff(th) / p
    return v
