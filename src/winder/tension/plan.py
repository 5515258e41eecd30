"""A job's tension as it will be wound: every coil's layers in sequence with
the flyer's exact motion (:func:`winder.tension.predict.predict_coil`), from
the job's segments timed once with the ramp at the highest feed override
the run will have (:func:`winder.motion.limits.time_job`). Coils laid alike are worked
out once (their flyer starts each at a whole turn: the same phase against
the core's corners).
"""

from __future__ import annotations

import math
from typing import Any

from winder.motion.axes import FORK
from winder.motion.limits import TimedJob
from winder.tension.predict import CoilMove, LayerTension, predict_coil
from winder.tension.tensioner import Tensioner

__all__ = ["MAX_SAMPLES", "wound_tension"]

#: samples a coil is worked out in, at most (the rate drops for a longer coil)
MAX_SAMPLES = 400_000
#: samples a second at least, and per turn of the flyer at its top speed at least
RATE, PER_TURN = 2000.0, 40.0


def wound_tension(timed: TimedJob, tensioner: Tensioner) -> dict[tuple[int, int], LayerTension]:
    """Each layer's tension as wound, ``(coil, layer)`` from 1, from the job
    as ``timed`` (see the module doc)."""
    job = timed.job
    if not job.bobbin.core_given:
        return {}
    k = timed.override
    turn = 2 * math.pi / job.fork_steps_per_rev
    coils: dict[int, list[CoilMove]] = {}
    starts: dict[int, int] = {}
    top = 0.0
    for i, (seg, timing) in enumerate(zip(timed.segments, timed.timings, strict=True)):
        base = starts.setdefault(seg.pole, timing.t0_ns)
        winds = seg.kind.winds and seg.steps > 0
        contour = job.bobbin.contour(job.winding.coils[seg.pole].layers[seg.layer].radius) if winds else None
        coils.setdefault(seg.pole, []).append(
            CoilMove(
                (timing.t0_ns - base) / 1e9 / k,
                tuple(x / 1e9 for x in timing.starts_ns),
                timing.profiles,
                seg.delta[FORK.index] / seg.steps * turn if winds else 0.0,
                k,
                seg.start[FORK.index] * turn,
                contour,
                seg.layer + 1 if winds else 0,
            )
        )
        if winds:
            top = max(top, timed.fork_peak(i))
    out: dict[tuple[int, int], LayerTension] = {}
    done: dict[tuple[Any, ...], dict[int, LayerTension]] = {}
    for pole, moves in coils.items():
        key = tuple(
            (m.t0, m.starts, tuple(id(x) for x in m.moves), m.rad_per_step, m.contour, m.layer) for m in moves
        )
        if key not in done:
            duration = moves[-1].t0 + (moves[-1].starts[-1] + moves[-1].moves[-1].duration) / k
            rate = max(RATE, PER_TURN * top / (2 * math.pi))
            rate = min(rate, MAX_SAMPLES / max(duration, 1e-9))
            done[key] = predict_coil(moves, job.flyer_radius, tensioner, job.wire, rate)
        for layer, got in done[key].items():
            out[(pole + 1, layer)] = got
    return out
