"""What the trackers (:mod:`winder.axis.linear`, :mod:`winder.axis.nonlinear`)
read of the motor they follow: a :class:`winder.axis.model.StepperAxis`,
named here by its shape so that the model imports the trackers and no
tracker imports the model."""

from __future__ import annotations

from typing import Protocol

from winder.axis._checks import FloatArray

__all__ = ["Motor"]


class Motor(Protocol):
    """The parameters and the exact linear maths of one stepper axis
    (:class:`winder.axis.model.StepperAxis` documents each)."""

    @property
    def J(self) -> float: ...  # noqa: N802 (the model's symbols: J, D, Z_r)

    @property
    def D(self) -> float: ...  # noqa: N802

    @property
    def Zr(self) -> float: ...  # noqa: N802

    @property
    def peak_torque(self) -> float: ...

    @property
    def natural_frequency(self) -> float: ...

    @property
    def damping_ratio(self) -> float: ...

    @property
    def tooth_pitch(self) -> float: ...

    @property
    def steps_per_pitch(self) -> int: ...

    def _transition(self, tau: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]: ...

    def _scan(self, t: FloatArray, b0: FloatArray, b1: FloatArray) -> tuple[FloatArray, FloatArray]: ...
