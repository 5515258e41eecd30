"""The wire's check of a job, before it runs (ROS-free): each layer's
take-up and predicted tension at the run's speeds, in ``winder check``'s
report (``doc``: :func:`winder.motion.coil.report`'s), and the one line
that refuses a job whose wire would not hold; ``tension.derate``'s slowing.
``winder check``, ``winder run`` and the sim node use the same, so they
refuse a job in the same words.

``ramp`` is the run's full ramp (the profile node's settings, its
``feed_override`` among them); ``schedule`` the run's operator schedule;
``consumer`` the consumer's ``tensioner.*`` settings (defaults where absent).
"""

from __future__ import annotations

from typing import Any

from winder.errors import BadInputError
from winder.motion.coil import report
from winder.motion.job import Job
from winder.motion.limits import TimedJob, time_job
from winder.motion.takeup import layer_takeup
from winder.tension.plan import Derating, derate, wound_tension
from winder.tension.predict import Bounds, LayerTension, fastest_within, predict_layer, wider
from winder.tension.tensioner import tensioner_of

__all__ = ["add_takeup", "add_tension", "derated", "time_for_check", "wire_refusal"]


def wire_refusal(
    job: Job,
    ramp: dict[str, Any],
    schedule: str,
    consumer: dict[str, Any],
    *,
    as_wound: bool = True,
    derating: Derating | None = None,
) -> str:
    """Why the job's wire would not hold at the run's speeds, in ``winder
    check``'s words ("" if it holds, or the job does not give its core).
    ``as_wound=False``: each layer's steady swing at its top speed alone (a
    few ms a layer; the coil as wound with its ramps takes a second or
    more). ``derating``: the job's, whose timing and prediction it reads."""
    if not job.bobbin.core_given:
        return ""
    doc = report(job.winding)
    timed = derating.timed if derating is not None and derating.timed else time_for_check(job, ramp, schedule)
    add_takeup(job, doc, timed)
    wound = derating.wound if derating is not None else None
    return add_tension(job, doc, consumer, timed, as_wound=as_wound, wound=wound)


def derated(job: Job, ramp: dict[str, Any], schedule: str, consumer: dict[str, Any]) -> Derating | None:
    """With ``tension.derate``, the job with the layers whose predicted
    tension would pass its bounds slowed until it keeps (winder.tension.plan);
    None without it, without a core to predict on, or where no speed helps
    (a tensioner that oscillates or cannot hold the set tension: refused as
    such)."""
    if not (job.tension_derate and job.bobbin.core_given):
        return None
    tensioner = tensioner_of(consumer, job.wire.stiffness_per_length, job.set_tension)
    if tensioner.unstable() or tensioner.cannot_hold():
        return None
    return derate(job, ramp, schedule, tensioner)


def time_for_check(job: Job, ramp: dict[str, Any], schedule: str) -> TimedJob | None:
    """The job timed as it will run (its ramp, at the highest feed override
    it will run at); None if the ramp cannot plan it (said where the job is run)."""
    try:
        return time_job(job, ramp, schedule)
    except BadInputError:
        return None


def add_takeup(job: Job, doc: dict[str, Any], timed: TimedJob | None) -> None:
    """Each layer's take-up at the job's speeds (``timed``): the flyer's top
    speed and the wire's least and greatest speed and greatest acceleration
    over a turn (winder.motion.takeup)."""
    speeds = timed.flyer_speeds() if timed is not None else {}
    b = job.bobbin
    for coil_doc in [{"coil": 1, "layers": doc["layers"]}, *doc["coils"]]:
        for layer in coil_doc["layers"]:
            omega = speeds.get((coil_doc["coil"] - 1, layer["layer"] - 1))
            layer["flyer_speed_rad_s"] = omega
            contour = b.contour(layer["radius_m"]) if omega is not None else None
            layer.update(layer_takeup(contour, job.flyer_radius, omega or 0.0))


def add_tension(
    job: Job,
    doc: dict[str, Any],
    consumer: dict[str, Any],
    timed: TimedJob | None,
    *,
    as_wound: bool = True,
    wound: dict[tuple[int, int], LayerTension] | None = None,
) -> str:
    """The wire (``doc["wire"]``) and each layer's predicted tension with the
    consumer's tensioner:
    the periodic steady state at its flyer's top speed and the layer as
    wound with the ramp, its transients included (winder.tension); the first
    layer that does not keep within the wire's maximum or the alarm band, in
    one line naming it, the prediction, the limit and what keeps it ("" if
    every layer does)."""
    wire = job.wire
    top = job.tension_limit
    tensioner = tensioner_of(consumer, wire.stiffness_per_length, job.set_tension)
    bounds = Bounds(job.set_tension, job.tension_alarm, top)
    m = wire.material
    doc["wire"] = {
        "material": m.name,
        "bare_diameter_m": wire.bare_diameter,
        "yield_stress_pa": m.yield_stress,
        "modulus_pa": m.modulus,
        "density_kg_m3": m.density,
        "resistivity_ohm_m": m.resistivity,
        "max_tension_n": wire.max_tension,
        "set_tension_n": job.set_tension,
        "warning_band_n": [
            job.set_tension * (1 - job.tension_warning),
            job.set_tension * (1 + job.tension_warning),
        ],
        "alarm_band_n": [bounds.low, bounds.high],
        "max_share": job.tension_max_share,
        "derate": job.tension_derate,
        "tensioner": tensioner.kind,
        "span_stiffness_n_m": tensioner.stiffness,
    }
    # a tensioner that oscillates, or cannot hold the set tension at all: no prediction holds
    why = tensioner.unstable() or tensioner.cannot_hold()
    if why:
        for coil_doc in [{"layers": doc["layers"]}, *doc["coils"]]:
            for layer in coil_doc["layers"]:
                layer.update(tension_peak_n=None, tension_min_n=None)
        return why
    if wound is None:  # as wound, unless known already (derating worked it out for this job)
        wound = wound_tension(timed, tensioner) if timed is not None and as_wound else {}
    seen: dict[tuple[float, float], LayerTension] = {}  # coils laid alike: each layer worked out once
    for coil_doc in [{"coil": 1, "layers": doc["layers"]}, *doc["coils"]]:
        for layer in coil_doc["layers"]:
            omega = layer["flyer_speed_rad_s"]
            contour = job.bobbin.contour(layer["radius_m"])
            if omega is None or contour is None:
                layer.update(tension_peak_n=None, tension_min_n=None)
                continue
            key = (layer["radius_m"], omega)
            if key not in seen:
                seen[key] = predict_layer(contour, job.flyer_radius, omega, tensioner, wire)
            steady = seen[key]
            wound_layer = wound.get((coil_doc["coil"], layer["layer"]))
            got = steady if wound_layer is None else wider(steady, wound_layer)
            layer.update(tension_peak_n=got.peak, tension_min_n=got.minimum)
            breach = got.breach(bounds, wire) or tensioner.limit_words(got.peak, got.coordinate)
            if breach and not why:
                which = (
                    f"coil {coil_doc['coil']} layer {layer['layer']}"
                    if job.poles > 1
                    else f"layer {layer['layer']}"
                )
                if steady.breach(bounds, wire) or tensioner.limit_words(steady.peak, steady.coordinate):
                    keep = fastest_within(contour, job.flyer_radius, omega, tensioner, wire, bounds)
                    cure = (
                        f"the highest flyer speed at which its steady swing keeps it is {keep:.4g} rad/s, "
                        f"{keep / omega:.0%} of it"
                    )
                else:  # only as the flyer ramps up, down or reverses: the ramp, not the speed
                    cure = "at full speed it keeps; the ramps and reversals do not: lower a_max or j_max"
                why = f"{which} at {omega:.4g} rad/s: {breach}; {cure} ({tensioner.kind} tensioner)"
    return why
