"""A job's tension as it will be wound: every coil's layers in sequence with
the flyer's exact motion (:func:`winder.tension.predict.predict_coil`), from
the job's segments timed once with the ramp at the highest feed override
the run will have (:func:`winder.motion.limits.time_job`). Coils laid alike are worked
out once (their flyer starts each at a whole turn: the same phase against
the core's corners).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from winder.errors import BadInputError
from winder.motion.axes import FORK
from winder.motion.job import Job
from winder.motion.limits import TimedJob, time_job
from winder.tension.predict import (
    Bounds,
    CoilMove,
    LayerTension,
    predict_coil,
    predict_layer,
    wider,
)
from winder.tension.tensioner import Tensioner

__all__ = ["MAX_SAMPLES", "Derating", "derate", "wound_tension"]

#: samples a coil is worked out in, at most (the rate drops for a longer coil)
MAX_SAMPLES = 400_000
#: samples a second at least, and per turn of the flyer at its top speed at least
RATE, PER_TURN = 2000.0, 40.0
#: derating: a layer's predicted swing may fill this share of the room its bounds leave (the
#: prediction follows the commanded flyer; the axes' own dynamics swing it a little further)
TARGET = 0.9
#: a layer is never slowed below this share of v_max; at most ROUNDS rounds
MIN_SHARE, ROUNDS = 0.05, 8


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


@dataclass(frozen=True)
class Derating:
    """A job slowed layer by layer until its predicted tension keeps within
    its bounds (``tension.derate``): ``job`` carries the layers' new speeds
    in ``layer_speed``; ``slowed`` maps each slowed ``(coil, layer)`` (from
    1) to the share of ``v_max`` it now runs at; the job's duration before
    and after (s, at feed override 1); ``why``: what still does not keep
    ("" if every layer does)."""

    job: Job
    slowed: dict[tuple[int, int], float]
    before_s: float
    after_s: float
    why: str = ""
    #: the derated job as timed, and its layers' tension as wound (``(coil, layer)`` from 1):
    #: what its check reads again
    timed: TimedJob | None = None
    wound: dict[tuple[int, int], LayerTension] | None = None

    def to_doc(self) -> dict[str, Any]:
        """``winder check --json``'s ``wire.derated``."""
        return {
            "layers": [
                {"coil": c, "layer": k, "speed_share": v} for (c, k), v in sorted(self.slowed.items())
            ],
            "duration_before_s": self.before_s,
            "duration_after_s": self.after_s,
        }

    def still(self) -> str:
        """What a refusal of the derated job adds: that derating was tried."""
        shares = sorted(self.slowed.values())
        tried = (
            f"slowed {len(shares)} layers to {shares[0]:.0%} of v_max and more" if shares else "slowed none"
        )
        return f" (tension.derate {tried}: the prediction still does not keep)"

    def words(self) -> str:
        """The summary's line ("" if nothing was slowed)."""
        if not self.slowed:
            return ""
        shares = sorted(self.slowed.values())
        low, high = f"{shares[0]:.0%}", f"{shares[-1]:.0%}"
        span = low if low == high else f"{low}..{high}"
        longer = self.after_s - self.before_s
        return (
            f"tension.derate: {len(self.slowed)} layer{'s' if len(self.slowed) > 1 else ''} slowed to "
            f"{span} of v_max to keep the wire's tension within its limit; the job takes "
            f"{self.after_s:.1f} s instead of {self.before_s:.1f} s "
            f"(+{longer:.1f} s, +{longer / max(self.before_s, 1e-9):.0%})"
        )


def derate(job: Job, ramp: dict[str, Any], schedule: str, tensioner: Tensioner) -> Derating:
    """``job`` with each layer whose predicted tension passes :data:`TARGET`
    of the room its bounds leave (the alarm band, the wire's maximum x
    ``tension.max_share``, the tensioner's reach: :func:`overshoot`) slowed
    in time (``layer_speed`` s: its speed x s, its ramp's acceleration x
    s**2) until it keeps, round by round, its prediction taken steady and
    as wound with the ramps; never below :data:`MIN_SHARE` of ``v_max``
    (``why`` says what still does not keep). BadInputError (one line) if the
    ramp cannot plan it."""
    bounds = Bounds(job.set_tension, job.tension_alarm, job.tension_limit)
    wire = job.wire
    first = timed = _timed(job, ramp, schedule)
    given = dict(job.layer_speeds)
    shares = dict(given)
    why = ""
    for round_ in range(ROUNDS + 1):
        wound = wound_tension(timed, tensioner)
        slower: dict[tuple[int, int], float] = {}
        why = ""
        for (pole, layer), omega in timed.flyer_speeds().items():
            radius = job.winding.coils[pole].layers[layer].radius
            contour = job.bobbin.contour(radius)
            if contour is None or omega <= 0:
                continue
            steady = predict_layer(contour, job.flyer_radius, omega, tensioner, wire)
            got = wider(steady, wound.get((pole + 1, layer + 1), steady))
            over = overshoot(got, bounds, tensioner)
            if over <= TARGET:
                continue
            where = f"coil {pole + 1} layer {layer + 1}"
            breach = got.breach(bounds, wire) or tensioner.limit_words(got.peak, got.coordinate)
            share = job.layer_share(pole, layer)
            if over == math.inf or share <= MIN_SHARE:
                why = why or (
                    f"{where}: {breach or 'too close to its bounds'} "
                    + ("at any flyer speed" if over == math.inf else f"even at {share:.0%} of v_max")
                )
                continue
            # the swing about the set tension grows with the take-up's acceleration (the square of
            # the pace for the dancer's inertia, about the pace for the servo): slowed by the
            # square root of how far it passes the target, a round at a time
            factor = 0.99 * math.sqrt(TARGET / over)
            slower[(pole, layer)] = max(factor, MIN_SHARE / share)
            why = why or f"{where} at {omega:.4g} rad/s: {breach or 'too close to its bounds'}"
        if not slower or round_ == ROUNDS:
            break
        for key, factor in slower.items():
            shares[key] = math.floor(shares.get(key, 1.0) * factor * 1e4) / 1e4
        text = ";".join(f"{p + 1}:{k + 1}={v:g}" for (p, k), v in sorted(shares.items()))
        job = Job.from_dict({**job.to_dict(), "layer_speed": text})
        timed = _timed(job, ramp, schedule)
    slowed = {(p + 1, k + 1): job.layer_share(p, k) for (p, k), v in shares.items() if v != given.get((p, k))}
    return Derating(job, slowed, first.duration_ns / 1e9, timed.duration_ns / 1e9, why, timed, wound)


def overshoot(got: LayerTension, bounds: Bounds, tensioner: Tensioner) -> float:
    """How far a layer's predicted swing passes the room it has (1: just
    within): the tension's bounds (:meth:`LayerTension.overshoot`), the
    dancer's stroke (its travel against half its stroke) and the servo's
    force limit (its peak's rise against the limit's)."""
    over = got.overshoot(bounds)
    if tensioner.kind == "dancer":
        return max(over, got.coordinate / (tensioner.stroke / 2))
    room = tensioner.force_limit - bounds.set_tension
    rise = got.peak - bounds.set_tension
    return max(over, rise / room if room > 0 else (math.inf if rise > 0 else 0.0))


def _timed(job: Job, ramp: dict[str, Any], schedule: str) -> TimedJob:
    """:func:`time_job`, its refusal said as tension.derate's where the layers it slowed made it."""
    try:
        return time_job(job, ramp, schedule)
    except BadInputError as exc:
        if not job.layer_speed:
            raise
        raise BadInputError(
            f"tension.derate: the layers slowed ({job.layer_speed}) cannot be run: {exc}"
        ) from None
