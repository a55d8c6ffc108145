"""Quadrotor identification toolkit: the workflows of arxid's five seed papers.

* :mod:`~arxid.quadrotor.mixer` -- motor speeds to pseudo-torques and thrust (seed 004)
* :mod:`~arxid.quadrotor.motor` -- motor model with battery voltage (seeds 003, 004)
* :mod:`~arxid.quadrotor.rotational` -- grey-box roll/pitch model with delay (seed 003)
* :mod:`~arxid.quadrotor.thrust` -- battery-aware total thrust model class (seed 001)
* :mod:`~arxid.quadrotor.setmembership` -- LP parameter bounds with bounded error (seed 000)
* :mod:`~arxid.quadrotor.physical` -- thrust/torque coefficients and inertias by LS (seed 002)
"""

from .mixer import CHANNELS, Mixer, mix
from .motor import MotorFit, MotorModel, fit_percent, identify_motor, speeds_from_pwm

__all__ = [
    "CHANNELS", "Mixer", "mix",
    "MotorFit", "MotorModel", "fit_percent", "identify_motor", "speeds_from_pwm",
]
