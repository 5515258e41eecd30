"""The settings of the three nodes, ROS-free: one table per node and one check
per node for the cross-field rules. The nodes declare their ROS parameters
from these tables, and ``winder run`` checks the same values before it starts
anything, so a value is judged the same way wherever it is typed.
"""

from __future__ import annotations

import math
from typing import Any

from winder.motion.job import AXES, FIELD_SPECS, Job
from winder.motion.profile import KINDS, LIMITS, plan
from winder.spec import Spec, SpecError

__all__ = [
    "INTERP_SPECS",
    "MOTOR_FIELDS",
    "PROFILE_KINDS",
    "PROFILE_SPECS",
    "SIM_SPECS",
    "check_interp",
    "check_profile",
    "check_sim",
    "plan_segment",
]


def _table(*specs: Spec) -> dict[str, Spec]:
    return {s.name: s for s in specs}


INTERP_SPECS = {
    **FIELD_SPECS,
    **_table(
        Spec("autostart", bool, True, "start the job as soon as the step stream has a reader"),
        Spec("chunk_steps", int, 8192, "steps per winder/steps message", "", 1, 1 << 20),
        Spec(
            "max_in_flight",
            int,
            1 << 18,
            "steps sent but not yet simulated, at most (when a sim node reports progress)",
            "steps",
            1,
            1 << 30,
        ),
    ),
}

PROFILE_KINDS = KINDS
PROFILE_SPECS = _table(
    Spec("profile", str, "scurve", "velocity ramp of every segment", choices=PROFILE_KINDS),
    Spec("v_max", float, 2048.0, "peak step rate of the major axis", "steps/s", 0.0, 1e7, low_open=True),
    Spec(
        "a_max",
        float,
        8192.0,
        "acceleration limit (scurve, trapezoid)",
        "steps/s^2",
        0.0,
        1e10,
        low_open=True,
    ),
    Spec("j_max", float, 65536.0, "jerk limit (scurve)", "steps/s^3", 0.0, 1e14, low_open=True),
    Spec("tau", float, 0.1, "time constant of the exponential ramp", "s", 0.0, 100.0, low_open=True),
    Spec(
        "v_start",
        float,
        0.0,
        "start/stop step rate: every segment starts and ends at it",
        "steps/s",
        0.0,
        1e7,
    ),
    Spec("dwell", float, 0.0, "pause between segments", "s", 0.0, 3600.0),
)

#: Per-axis motor settings of the sim node: ``<axis>.<field>``. Defaults: the
#: 2012 paper's motor, 1/32 microstep of its 2.25 deg full step.
MOTOR_FIELDS = _table(
    Spec("Zr", float, 40.0, "rotor teeth", "", 1.0, 1000.0),
    Spec("L", float, 0.01005, "phase inductance", "H", 0.0, 10.0, low_open=True),
    Spec("i_a", float, 1.0, "phase current", "A", 0.0, 100.0, low_open=True),
    Spec("J", float, 1.05 * 9.80665e-5, "rotor + load inertia", "kg m^2", 0.0, 100.0, low_open=True),
    Spec("D", float, 0.03, "viscous damping", "N m s/rad", 0.0, 100.0),
    Spec(
        "motor_step_angle",
        float,
        2 * math.pi / 5120,
        "motor angle per commanded step",
        "rad",
        0.0,
        1.0,
        low_open=True,
    ),
    Spec("load_torque", float, 0.0, "constant load torque (nonlinear model)", "N m", -100.0, 100.0),
)

#: MCAP chunk compressions of the sim node's bags (see winder.record.bag).
BAG_COMPRESSIONS = ("zstd", "lz4", "none")

SIM_SPECS = {
    **_table(
        Spec("model", str, "linear", "motor model", choices=("linear", "nonlinear")),
        Spec("publish_rate", float, 200.0, "joint state rate", "Hz of simulated time", 1.0, 1e5),
        Spec("real_time", bool, False, "pace simulated time to the wall clock"),
        Spec(
            "real_time_factor", float, 1.0, "simulated seconds per wall second when real_time", "", 1e-3, 1e3
        ),
        Spec(
            "bag_dir", str, "bags", "directory for recordings", pattern=r".+", pattern_text="a directory path"
        ),
        Spec("record", bool, True, "record each job into an MCAP bag"),
        Spec(
            "bag_compression",
            str,
            "lz4",
            "MCAP chunk compression of the bag (lz4: fast, about a third of the size; zstd: a tenth, "
            "at twice the CPU)",
            choices=BAG_COMPRESSIONS,
        ),
        Spec("settle_time", float, 0.05, "simulated time after the last step", "s", 0.0, 60.0),
        Spec(
            "stall_timeout",
            float,
            2.0,
            "wall time without steps before a stall is reported",
            "s",
            0.1,
            3600.0,
        ),
    ),
    **{
        f"{axis}.{name}": Spec(
            f"{axis}.{name}",
            s.kind,
            s.default,
            f"{axis} axis: {s.description}",
            s.unit,
            s.low,
            s.high,
            s.low_open,
        )
        for axis in AXES
        for name, s in MOTOR_FIELDS.items()
    },
}


def check_interp(values: dict[str, Any]) -> None:
    """Cross-field check of the interp node's settings (SpecError)."""
    Job(**{k: v for k, v in values.items() if k in FIELD_SPECS})


def plan_segment(values: dict[str, Any], steps: int) -> Any:
    """The profile of one segment of ``steps`` steps with the profile settings."""
    kind = values["profile"]
    kw: dict[str, Any] = {"v_max": values["v_max"], "v_start": values["v_start"], "v_end": values["v_start"]}
    kw.update({name: values[name] for name in LIMITS[kind]})
    return plan(kind, float(steps), **kw)


def check_profile(values: dict[str, Any]) -> None:
    """Cross-field check: the limits must make a plannable move."""
    try:
        plan_segment(values, 1000)
    except ValueError as exc:
        raise SpecError(str(exc)) from None


def check_sim(values: dict[str, Any]) -> None:
    """Cross-field check: each axis must be a valid motor."""
    from winder.axis import StepperAxis

    for axis in AXES:
        try:
            StepperAxis(**{k: values[f"{axis}.{k}"] for k in ("Zr", "L", "i_a", "J", "D")})
        except ValueError as exc:
            raise SpecError(f"{axis} axis: {exc}") from None
