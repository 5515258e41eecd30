"""The simulated axis: the stepper motor's second-order model (exact linear
response, nonlinear model that loses steps) and the encoder that reads it.
Plain numpy; nothing here knows about ROS, bags or plots."""

from winder.axis.encoder import measured_velocity
from winder.axis.linear import MODAL_ZETA, LinearTracker
from winder.axis.model import G_CM_S2, PAPER, SimResult, StepperAxis
from winder.axis.nonlinear import LoadStep, NonlinearTracker

__all__ = [
    "G_CM_S2",
    "MODAL_ZETA",
    "PAPER",
    "LinearTracker",
    "LoadStep",
    "NonlinearTracker",
    "SimResult",
    "StepperAxis",
    "measured_velocity",
]
