"""Quadrotor identification toolkit: the workflows of five published quadrotor studies.

* :mod:`~arxid.quadrotor.mixer` -- motor speeds to pseudo-torques and thrust (a published quadrotor
  study, Sarıoğlu & Kural)
* :mod:`~arxid.quadrotor.motor` -- motor model with battery voltage (a published grey-box study of a
  Crazyflie's motor and rotational dynamics; Sarıoğlu & Kural)
* :mod:`~arxid.quadrotor.rotational` -- grey-box roll/pitch model with delay (the grey-box Crazyflie study)
* :mod:`~arxid.quadrotor.thrust` -- battery-aware total thrust model class (Staub & Franchi,
  ICRA 2015)
* :mod:`~arxid.quadrotor.setmembership` -- LP parameter bounds with bounded error (the set-membership
  study "Robust Identification of Quadrocopter Model for Control Purposes")
* :mod:`~arxid.quadrotor.physical` -- thrust/torque coefficients and inertias by LS (a published
  study estimating a Newton-Euler quadrotor model's parameters with neural networks)
"""

from .mixer import CHANNELS, Mixer, mix
from .motor import MotorFit, MotorModel, fit_percent, identify_motor, speeds_from_pwm
from .physical import LeastSquaresEstimate, inertia_from_rotation, structured_lstsq, thrust_torque_coefficients
from .rotational import RotationalFit, RotationalModel, RotationalScore, identify_rotational
from .setmembership import (
    EmptyFeasibleSetError,
    InertiaIntervals,
    ParameterBox,
    RotatedBox,
    inertia_intervals,
    levels_box,
    linear_in_voltage_box,
    parameter_box,
    rotated_box,
    smallest_epsilon,
)
from .thrust import (
    SEED001_MODEL_IDS,
    ThrustClassRow,
    ThrustClassTable,
    ThrustModel,
    fit_thrust_model,
    thrust_from_accelerometer,
    thrust_model_class,
)

__all__ = [
    "CHANNELS",
    "Mixer",
    "mix",
    "MotorFit",
    "MotorModel",
    "fit_percent",
    "identify_motor",
    "speeds_from_pwm",
    "LeastSquaresEstimate",
    "inertia_from_rotation",
    "structured_lstsq",
    "thrust_torque_coefficients",
    "RotationalFit",
    "RotationalModel",
    "RotationalScore",
    "identify_rotational",
    "EmptyFeasibleSetError",
    "InertiaIntervals",
    "ParameterBox",
    "RotatedBox",
    "inertia_intervals",
    "levels_box",
    "linear_in_voltage_box",
    "parameter_box",
    "rotated_box",
    "smallest_epsilon",
    "SEED001_MODEL_IDS",
    "ThrustClassRow",
    "ThrustClassTable",
    "ThrustModel",
    "fit_thrust_model",
    "thrust_from_accelerometer",
    "thrust_model_class",
]
